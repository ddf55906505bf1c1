"""``lidarfx run PIPELINE.json``: several steps in one process on one in-memory cloud."""
from __future__ import annotations

import argparse
import sys

EPILOG = """examples:
  lidarfx run pipeline.json                        # validate everything, then run the steps
  lidarfx run pipeline.json --dry-run              # validate and print the plan; nothing is written
  lidarfx run pipeline.json --input a.laz --output a_out.laz --json   # the same pipeline on another file
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
memory, one after the other, on the same cloud.  docs/pipelines.md.
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
    if args.dry_run:
        pipe.check()
        if args.json:
            _json.dump({"pipeline": args.pipeline, "valid": True, "steps": pipe.plan()}, sys.stdout, indent=2)
            print()
        else:
            print(f"{args.pipeline}: {len(pipe.steps)} steps, valid (dry run: nothing run, nothing written)")
            print(pipe.plan_text())
        return 0

    def log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    pipe.run(progress=False if args.quiet else None, log=None if args.quiet else log)
    summary = pipe.summary
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not args.quiet:
        print(f"{summary['points']:,} points, {len(summary['steps'])} steps in {summary['seconds']:.2f} s -> "
              f"{', '.join(summary['outputs'])}", file=sys.stderr)
    return 0
