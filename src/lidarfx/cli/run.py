"""``lidarfx run PIPELINE.json``: several steps in one process on one in-memory cloud."""
from __future__ import annotations

import argparse
import sys

EPILOG = """examples:
  lidarfx run pipeline.json                        # validate everything, then run the steps
  lidarfx run pipeline.json --dry-run              # validate and print the plan; nothing is written
  lidarfx run pipeline.json --input a.laz --output a_out.laz --json   # the same pipeline on another file
  lidarfx run pipeline.json --chunk-size 250       # in chunks on Dask: cloud steps fused per chunk
  lidarfx run pipeline.json --input tiles/ --output out/ --workers 4   # a folder of tiles, one output per tile
  lidarfx run --steps                              # the steps and their keys

pipeline.json:
  {"pipeline": [
    {"type": "read", "path": "in.laz"},
    {"type": "ground", "hag": true},
    {"type": "features", "radius": 1.0, "features": "eigen,plane"},
    {"type": "classify", "model": "default"},
    {"type": "write", "path": "out.laz"}
  ]}

Each step is a lidarfx command without its file arguments: the keys are the
command's long options (edge-step or edge_step), lengths are metres as
everywhere.  The whole file is checked before the first step runs: every step,
key and value, the inputs, and the outputs (format, folder, not an input, not
existing unless --force); nothing in it is executed as code.  Steps run in
memory, one after the other, on the same cloud; with a chunk option (or a
folder of tiles, or an input larger than memory) the cloud steps between the
read and the one write run fused per chunk on Dask.  docs/pipelines.md.
"""


def register(sub) -> None:
    p = sub.add_parser(
        "run",
        help="run a pipeline file: several steps in one process on one in-memory cloud",
        description="Run a JSON pipeline: read, any cloud steps (ground, features, classify, select, thin, ...), "
                    "product steps (edges, dtm, render, ...) and writes, on one in-memory cloud. "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("pipeline", nargs="?", help="pipeline file (.json)")
    p.add_argument("--dry-run", action="store_true", help="check everything and print the plan; run nothing")
    p.add_argument("-i", "--input", default=None, metavar="IN", help="read this file instead of the read step's path")
    p.add_argument("-o", "--output", default=None, metavar="OUT",
                   help="write this file instead of the last write step's path")
    p.add_argument("--steps", action="store_true", help="list the steps and their keys, then exit")
    p.add_argument("--markdown", action="store_true", help="with --steps: the reference of docs/pipelines.md")
    p.add_argument("--json", action="store_true", help="print the summary (or, with --dry-run, the plan) as JSON")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress lines or bars")
    from ._tiles import add_tile_options

    add_tile_options(p)
    p.set_defaults(func=run)


def _list_steps(markdown: bool) -> int:
    from ..pipeline import STEPS, steps_markdown

    if markdown:
        sys.stdout.write(steps_markdown())
        return 0
    for s in STEPS.values():
        keys = ", ".join(k.name + ("*" if k.required else "") for k in s.keys)
        print(f"{s.name:11s} {s.help}\n{'':11s} keys: {keys}")
    print("(* required)")
    return 0


def run(args) -> int:
    from .. import _json
    from ..errors import LidarfxError
    from ..pipeline import Pipeline

    if args.steps:
        return _list_steps(args.markdown)
    if not args.pipeline:
        raise LidarfxError("run needs a pipeline file (see lidarfx run --help)")
    pipe = Pipeline.from_json(args.pipeline, input=args.input, output=args.output)
    chunked = _chunked(args, pipe)
    if args.dry_run:
        pipe.check(chunked=chunked)
        if args.json:
            _json.dump({"pipeline": args.pipeline, "valid": True, "steps": pipe.plan()}, sys.stdout, indent=2)
            print()
        else:
            print(f"{args.pipeline}: {len(pipe.steps)} steps, valid{' in chunks' if chunked else ''} "
                  "(dry run: nothing run, nothing written)")
            print(pipe.plan_text())
        return 0

    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    if chunked:
        return _run_chunked(args, pipe, log)
    pipe.run(progress=False if args.quiet else None, log=None if args.quiet else log)
    summary = pipe.summary
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not args.quiet:
        print(f"{summary['points']:,} points, {len(summary['steps'])} steps in {summary['seconds']:.2f} s -> "
              f"{', '.join(summary['outputs'])}", file=sys.stderr)
    return 0


def _chunked(args, pipe) -> bool:
    """In chunks as the per-point commands decide it (:func:`lidarfx.cli._tiles.wants_tiles`: a chunk
    option, a folder or pattern in, a folder out, or an input larger than one chunk may hold — the
    last only when the pipeline can run in chunks), for the read and the last write step's paths."""
    import argparse

    from ._tiles import wants_tiles

    if pipe.steps[0][0].kind != "read" or pipe.steps[-1][0].kind != "write":
        return False
    paths = argparse.Namespace(**{**vars(args), "input": pipe.steps[0][1]["path"], "output": pipe.steps[-1][1]["path"]})
    return wants_tiles(paths, "run", by_size=pipe.chunk_problem() is None)


def _run_chunked(args, pipe, log) -> int:
    from .. import _json

    summary = pipe.run_chunked(chunk_size=args.chunk_size, buffer=args.buffer, workers=args.workers,
                               scheduler=args.scheduler, resume=args.resume, work_dir=args.work_dir,
                               progress=False if args.quiet else None, log=None if args.quiet else log)
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not args.quiet:
        n = len(summary["steps"])
        for r in summary["steps"]:
            extra = (f", {r['ground_points']:,} ground" if "ground_points" in r else "") + \
                (", " + ", ".join(f"class {c} {k:,}" for c, k in r["classes"].items()) if r.get("classes") else "")
            log(f"[{r['step']}/{n + 2}] {r['type']}: {r['points']:,} points{extra}")
        c = summary["chunks"]
        log(f"{summary['points']:,} of {summary['points_read']:,} points, {n} steps in {c['chunks']} chunks of "
            f"{c['chunk_size']:g} m (buffer {c['buffer']:g} m, {c['workers']} workers) in {summary['seconds']:.2f} s "
            f"-> {', '.join(summary['outputs'][:3])}{' ...' if len(summary['outputs']) > 3 else ''}")
    return 0
