"""``lidarfx eigenclass IN OUT``: unsupervised structure classes (docs/structures.md), and
``lidarfx eigenclass-references OUT.json``: make the reference signatures again."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ._args import add_columns, check_output, check_picture_path, emit_summary, read_input
from ._tiles import TILE_HELP, add_tile_options, inputs_of, run_tiles, wants_tiles
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx eigenclass roofs.laz roofs_struct.laz                 # radius from the point spacing
  lidarfx eigenclass roofs.laz roofs_struct.laz -r 1.5 --picture struct.png
  lidarfx eigenclass tls.laz tls_struct.laz -r 0.1 -r 0.2       # two scales, distances combined
  lidarfx eigenclass scan.laz out.laz -r 0.5 --references analytic --weighting uniform
  lidarfx eigenclass scan.laz out.laz -r 0.5 --references my_refs.json
  lidarfx eigenclass scan.laz out.laz -r 0.5 --json             # summary with the count per label

labels (int32 extra bytes 'structure'):
  -1 unclassified  nearest reference farther than --reject
   0 isolated      fewer than --min-neighbours points in the sphere
   1 plane         2 plane_border   3 edge   4 corner
   5 line          6 line_end       7 volume
also written: structure_confidence (float32, 0-1) and structure_distance
(float32, RMS distance to the nearest reference in its standard deviations).
The references are signatures (e1, e2, e3, centroid offset) of synthetic ideal
structures made with lidarfx's own neighbourhood code; docs/structures.md.

  lidarfx eigenclass tiles/ out/ -r 1.5                        # a folder of tiles, in chunks
  lidarfx eigenclass big.laz out.laz -r 1.5 --chunk-size 200 --workers 4 --resume
(in chunks give -r: the default radius comes from the whole cloud's point spacing)

""" + TILE_HELP

REF_EPILOG = """examples:
  lidarfx eigenclass-references refs.json                 # the shipped references again (about a minute)
  lidarfx eigenclass-references refs.json --samples 500 --noise 0,0.02,0.05
  lidarfx eigenclass scan.laz out.laz -r 0.5 --references refs.json

The shipped file (lidarfx/data/structure_references.json) is what this command
writes with its defaults.
"""


def _floats(text: str, what: str) -> list[float]:
    try:
        return [float(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be comma-separated numbers, got {text!r}") from None


def register(sub) -> None:
    from ..structures import DEFAULT_MIN_NEIGHBOURS, DEFAULT_REJECT

    p = sub.add_parser(
        "eigenclass",
        help="unsupervised structure classes: plane, border, edge, corner, line, volume ...",
        description="Label every point with the ideal structure whose eigenvalue signature is nearest. "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("output", help="output point cloud (format from the extension)")
    p.add_argument("-r", "--radius", type=float, action="append",
                   help="sphere radius, m (repeat for several scales); default: about 40 points on a plane")
    p.add_argument("--references", default="trained",
                   help="trained (default), analytic (closed forms) or a file from lidarfx eigenclass-references")
    p.add_argument("--weighting", choices=["structure", "uniform"], default="structure",
                   help="spread per reference and component (default) or one for all")
    p.add_argument("--reject", type=float, default=DEFAULT_REJECT,
                   help="unclassified beyond this RMS distance in reference standard deviations, default %(default)s")
    p.add_argument("--min-neighbours", type=int, default=DEFAULT_MIN_NEIGHBOURS,
                   help="isolated below this many points in the sphere, default %(default)s")
    p.add_argument("--keep-signature", action="store_true", help="also write e1, e2, e3, centroid_offset, n_neighbours")
    p.add_argument("--picture", default=None, metavar="PNG", help="also draw a plan-view map of the labels")
    add_columns(p)
    add_report_option(p)
    add_tile_options(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)

    r = sub.add_parser(
        "eigenclass-references",
        help="generate the reference signatures of the structure classes",
        description="Generate the reference signatures of lidarfx eigenclass on synthetic ideal structures.",
        epilog=REF_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from ..structures.references import COUNT_LEVELS, EDGE_ANGLES, NOISE_LEVELS, SAMPLES

    r.add_argument("output", help="references file to write (.json)")
    r.add_argument("--samples", type=int, default=SAMPLES, help="samples per structure and count level, default %(default)s")
    r.add_argument("--counts", type=lambda t: _floats(t, "--counts"), default=list(COUNT_LEVELS),
                   help=f"points per neighbourhood of the levels, default {','.join(map(str, COUNT_LEVELS))}")
    r.add_argument("--noise", type=lambda t: _floats(t, "--noise"), default=list(NOISE_LEVELS),
                   help=f"noise σ as shares of the radius, default {','.join(map(str, NOISE_LEVELS))}")
    r.add_argument("--edge-angles", type=lambda t: _floats(t, "--edge-angles"), default=list(EDGE_ANGLES),
                   help=f"dihedral angles of the edge prototypes (degrees), default {','.join(f'{a:g}' for a in EDGE_ANGLES)}")
    r.add_argument("--seed", type=int, default=0, help="seed, default %(default)s")
    r.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar, no summary")
    r.set_defaults(func=run_references)


def run(args) -> int:
    from .. import io
    from ..structures import LABELS, classify_structures
    from ..structures import check_min_neighbours, check_reject
    from ..structures.references import resolve_references

    tiled = wants_tiles(args, "eigenclass", by_size=args.radius is not None)  # checks a chunked run's output
    if not tiled:
        check_output(args.input, args.output)  # outputs are checked before anything else
    if args.picture:
        check_picture_path(args.picture)
    report = ReportJob(args)
    check_reject(args.reject)
    check_min_neighbours(args.min_neighbours)
    refs, kind = resolve_references(args.references)  # a bad file is refused before reading the cloud
    refs.tables(kind, args.weighting)
    if tiled:
        from ..errors import LidarfxError
        from ..tiles.proc_classes import eigenclass_options

        if args.picture:
            raise LidarfxError("--picture draws the whole cloud, not in chunks: leave it out or use --chunk-size 0")
        return run_tiles(args, "eigenclass", eigenclass_options(
            args.radius, args.references, args.weighting, args.reject, args.min_neighbours, args.keep_signature,
            inputs=inputs_of(args.input)))
    t0 = time.perf_counter()
    cloud, progress = read_input(args)
    t1 = time.perf_counter()
    out = classify_structures(cloud, radii=args.radius, references=refs if kind == "trained" else kind,
                              weighting=args.weighting, reject=args.reject, min_neighbours=args.min_neighbours,
                              keep_signature=args.keep_signature, progress=progress, inplace=True)
    t2 = time.perf_counter()
    io.write(out, args.output, progress=progress)
    picture = args.picture or (report.picture("structure.png") if report.wanted else None)
    if picture:
        import numpy as np

        from ..render import class_map

        names = [LABELS[k] for k in range(0, 8)]
        class_map(out.xyz[:, :2] - out.xyz[:, :2].min(axis=0), out.xyz[:, 2], np.asarray(out["structure"]), names,
                  picture, title=f"{Path(args.input).name}: structure classes, r = {', '.join(f'{r:g}' for r in out.meta['structures']['radii'])}")
    t3 = time.perf_counter()
    meta = out.meta["structures"]
    n = max(len(out), 1)
    summary = {
        "input": str(args.input),
        "output": str(args.output),
        "picture": args.picture,
        "points": len(out),
        "radii": meta["radii"],
        "references": args.references,
        "weighting": args.weighting,
        "reject": meta["reject"],
        "min_neighbours": meta["min_neighbours"],
        "counts": meta["counts"],
        "shares": {k: round(v / n, 6) for k, v in meta["counts"].items()},
        "seconds": {"read": round(t1 - t0, 3), "classify": round(t2 - t1, 3), "write": round(t3 - t2, 3)},
    }
    page = report.write(f"Structure classes of {Path(args.input).name}", summary, cloud=out, colour_by="structure",
                        pictures=[(picture, "structure classes (plan view)")] if picture else ())
    if page:
        summary["report"] = page
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=True)
    console.print(f"[bold]{s['points']:,}[/] points, r = {', '.join(f'{r:g}' for r in s['radii'])} -> {s['output']}")
    t = Table(title="structure classes", title_justify="left")
    for col, just in (("label", "left"), ("points", "right"), ("share", "right")):
        t.add_column(col, justify=just)
    for k, v in s["counts"].items():
        t.add_row(k, f"{v:,}", f"{100 * s['shares'][k]:.1f} %")
    console.print(t)
    sec = s["seconds"]
    console.print(f"read {sec['read']:.2f} s, classify {sec['classify']:.2f} s, write {sec['write']:.2f} s")


def run_references(args) -> int:
    from ..errors import LidarfxError
    from ..structures.references import generate_references

    if Path(args.output).suffix.lower() != ".json":
        raise LidarfxError(f"references file {args.output}: give a path ending in .json")
    from .._atomic import check_output_folder

    check_output_folder(args.output)
    t0 = time.perf_counter()
    refs = generate_references(counts=args.counts, noise=args.noise,
                               edge_angles=args.edge_angles, samples=args.samples, seed=args.seed,
                               progress=False if args.quiet else None)
    refs.save(args.output)
    summary = {"output": str(args.output), "prototypes": refs.names, "counts": [int(c) for c in refs.counts],
               "parameters": refs.parameters, "seconds": round(time.perf_counter() - t0, 2)}
    emit_summary(args, summary, lambda s: print(f"{len(s['prototypes'])} prototypes × {len(s['counts'])} count levels "
                                                f"-> {s['output']} ({s['seconds']:.1f} s)", file=sys.stderr))
    return 0
