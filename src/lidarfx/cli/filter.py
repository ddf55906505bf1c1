"""``lidarfx filter IN OUT --outliers statistical|radius``: classify or drop noise points."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ._args import add_columns, check_output, columns_of, emit_summary
from ._ops import add_chunk_options, chunked, print_chunked, run_chunked
from ._tiles import TILE_HELP, inputs_of

EPILOG = """examples:
  lidarfx filter scan.laz clean.laz --outliers statistical                     # k 8, std 2.0: class 7
  lidarfx filter scan.laz clean.laz --outliers statistical --k 12 --std 3 --action drop
  lidarfx filter scan.laz clean.laz --outliers radius --radius 1.0 --min-neighbours 3
  lidarfx filter scan.laz clean.laz --outliers radius --radius 0.5 --min-neighbours 2 --class 18
  lidarfx filter tiles/ clean/ --outliers statistical                          # a folder of tiles, in chunks

statistical  mean distance d of each point to its --k nearest other points;
             outlier when d > mean(d) + --std x sample std(d) over the cloud
             (PDAL filters.outlier method=statistical mean_k / multiplier;
             CloudCompare SOR; lidR classify_noise(sor(k, m))).
radius       outlier when fewer than --min-neighbours other points lie within
             --radius m (PDAL method=radius: min_k = --min-neighbours + 1).
--action classify (default) sets class --class (7, low noise) on the outliers
and keeps every other class; drop leaves them out.  In chunks the result is the
in-memory one, bit for bit (the statistical filter reads the input twice: its
threshold belongs to the whole cloud).  docs/everyday.md#filter.

""" + TILE_HELP


def register(sub) -> None:
    p = sub.add_parser(
        "filter",
        help="statistical or radius outliers: classify as noise (class 7) or drop",
        description="Find outliers (noise) by the statistical (SOR) or the radius rule and classify or drop them. "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud, a folder of LAS/LAZ tiles or a quoted pattern")
    p.add_argument("output", help="output point cloud (format from the extension), or a folder for tiles")
    p.add_argument("--outliers", required=True, choices=("statistical", "radius"), help="the outlier rule")
    p.add_argument("--k", type=int, default=None, help="statistical: neighbours, default 8")
    p.add_argument("--std", type=float, default=None, help="statistical: standard deviations above the mean, default 2.0")
    p.add_argument("--radius", type=float, default=None, metavar="R", help="radius: search radius, m")
    p.add_argument("--min-neighbours", "--min-neighbors", type=int, default=None, metavar="N",
                   help="radius: fewest other points within R for a point not to be an outlier")
    p.add_argument("--action", choices=("classify", "drop"), default="classify",
                   help="classify the outliers (default) or drop them")
    p.add_argument("--class", dest="cls", type=int, default=7, metavar="CODE",
                   help="class of the outliers with --action classify, default 7 (low noise; 18: high noise)")
    add_columns(p)
    add_chunk_options(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def _options(args) -> dict:
    from ..outliers import check_options

    if args.outliers == "statistical":
        return check_options("statistical", 8 if args.k is None else args.k, 2.0 if args.std is None else args.std,
                             args.radius, args.min_neighbours, args.action, args.cls)
    if args.k is not None or args.std is not None:
        from ..errors import LidarfxError

        raise LidarfxError("--k and --std belong to --outliers statistical; radius takes --radius and --min-neighbours")
    return check_options("radius", radius=args.radius, min_neighbours=args.min_neighbours, action=args.action,
                         cls=args.cls)


def _check_class_fits(inputs, cls: int) -> None:
    from ..errors import LidarfxError
    from ..io.las import LEGACY_MAX_CLASS, read_header
    from ..tiles.catalog import expand_inputs

    if cls <= LEGACY_MAX_CLASS:
        return
    for p in expand_inputs(inputs):
        if read_header(p).point_format.id < 6:
            raise LidarfxError(f"{p}: point format {read_header(p).point_format.id} stores classes 0-31; in chunks give "
                               f"--class 0-31, or run in memory (--chunk-size 0), which writes the LAS 1.4 format")


def run(args) -> int:
    from .. import io
    from ..outliers import apply_action, outlier_mask

    o = _options(args)
    if chunked(args, "filter"):
        if o["action"] == "classify":
            _check_class_fits(inputs_of(args.input), o["class"])
        s = run_chunked(args, "filter", o)
        emit_summary(args, s, lambda s: print_chunked(s, f"filter ({o['method']}, {o['action']})"))
        return 0
    t0 = time.perf_counter()
    check_output(args.input, args.output)
    progress = False if args.quiet else None
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    mask, facts = outlier_mask(cloud, o["method"], k=o.get("k", 8), std=o.get("std", 2.0), radius=o.get("radius"),
                               min_neighbours=o.get("min_neighbours"), progress=progress)
    out = apply_action(cloud, mask, o["action"], o["class"])
    t2 = time.perf_counter()
    opts = {}
    if o["action"] == "classify" and io.input_format(args.input) == "las":
        from ..io.las import format_for_classes

        pf = format_for_classes(cloud.header, o["class"])
        if pf is not None and io.FORMATS.get(Path(args.output).suffix.lower()) == "las":
            opts["point_format"] = pf
    io.write(out, args.output, progress=progress, **opts)
    t3 = time.perf_counter()
    summary = {"input": str(args.input), "output": str(args.output), **facts, "action": o["action"],
               **({"class": o["class"]} if o["action"] == "classify" else {}),
               "kept": len(out), "seconds": {"read": round(t1 - t0, 3), "filter": round(t2 - t1, 3),
                                             "write": round(t3 - t2, 3)}}
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    n, k = s["points"], s["outliers"]
    share = f" ({100 * k / n:.2f} %)" if n else ""
    rule = (f"mean distance to {s['k']} neighbours > {s['threshold']:.4g} (mean {s['mean_distance']:.4g} + "
            f"{s['std']:g} x {s['sigma']:.4g})" if s["method"] == "statistical"
            else f"fewer than {s['min_neighbours']} other points within {s['radius']:g} m")
    done = f"classified {s['class']}" if s["action"] == "classify" else "dropped"
    print(f"{k:,} of {n:,} points are outliers{share} ({rule}): {done} -> {s['output']}", file=sys.stderr)
