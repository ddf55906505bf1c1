"""``lidarfx features IN OUT``: per-point neighbourhood features."""
from __future__ import annotations

import argparse
import sys
import time

from .. import _json
from ._args import add_columns, check_output, read_input, xyz
from ._tiles import TILE_HELP, add_tile_options, run_tiles, wants_tiles
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx features in.laz out.laz -r 0.5 --features eigen,plane,density
  lidarfx features in.laz out.laz -r 0.1 -r 0.3 -r 0.5 --features eigen   # multi-scale: planarity_r0.10 ...
  lidarfx features tls.laz out.laz -r 0.1 --scanner 12.5,-3.0,1.7 --features plane,curvature
  lidarfx features in.laz out.laz --neighbourhood knn -k 20 --features eigen
  lidarfx features --list                                                  # groups and names

feature groups: eigen, westin, plane, msac, density, height, histogram,
distribution, curvature, quadric, eigenvectors, count, echo, ground
(height above the SMRF ground), all (without ground) — or single names
(slope, planarity, ...).  Features are written as float32 extra-bytes
dimensions (LAS/LAZ) or attributes (PLY, text, npz); NaN = not computable.
When more than half of a feature is NaN, a warning names the likely cause
(a radius below the point spacing) and a radius that works.

units: lengths are metres; files in feet are converted (-r, --height,
--d-max, --chunk-size, --buffer; docs/conventions.md).  --scanner is a
position in the file's coordinates; the features are in the file's unit.

  lidarfx features tiles/ out/ -r 0.5 --features eigen,plane,density       # a folder of tiles, in chunks
  lidarfx features big.laz out.laz -r 0.5 --chunk-size 200 --workers 4 --resume

""" + TILE_HELP


def register(sub) -> None:
    p = sub.add_parser(
        "features",
        help="compute per-point neighbourhood features",
        description="Compute per-point neighbourhood features (see docs/features.md) and write them as attributes. "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", nargs="?", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.pts/.npy/.npz)")
    p.add_argument("output", nargs="?", help="output point cloud (format from the extension)")
    p.add_argument("-r", "--radius", type=float, action="append", help="neighbourhood radius, m (repeat for multi-scale)")
    p.add_argument("-f", "--features", default=None,
                   help="comma-separated groups or names; -NAME takes one out of what came before it, "
                   "e.g. all,-quadric (default: eigen,plane,density)")
    p.add_argument("-n", "--neighbourhood", "--neighborhood", choices=["sphere", "cylinder", "knn"], default="sphere",
                   help="sphere of each radius (default), vertical cylinder of each radius, or the k nearest points")
    p.add_argument("-k", type=int, default=None, help="neighbours for --neighbourhood knn (a radius then caps the search)")
    p.add_argument("--scanner", type=xyz, default=None, help="scanner position x,y,z: orient normals towards it (TLS)")
    p.add_argument("--height", type=float, default=None, help="half-height limit of the vertical cylinder, m")
    p.add_argument("--convention", choices=["default", "cloudcompare", "pdal"], default="default")
    p.add_argument("--d-max", type=float, default=0.10, help="plane inlier distance, m, default 0.10")
    p.add_argument("--bins", type=int, default=10, help="bins of the height-difference histogram")
    p.add_argument("--seed", type=int, default=0, help="seed of the MSAC generator")
    add_columns(p)
    add_tile_options(p)
    add_report_option(p)
    p.add_argument("--list", action="store_true", help="list feature groups and names, then exit")
    p.add_argument("--json", action="store_true", help="print a JSON summary (timings, NaN shares) on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..errors import LidarfxError
    from ..features import available

    if args.list:
        for group, names in available().items():
            print(f"{group:13s} {', '.join(names)}")
        return 0
    if not args.input or not args.output:
        raise LidarfxError("features needs INPUT and OUTPUT (see lidarfx features --help)")
    import numpy as np

    from .. import io
    from ..crs import units_summary
    from ..features import stream_features

    radii = args.radius or []
    tiled = wants_tiles(args, "features")
    if not tiled:
        check_output(args.input, args.output)  # outputs are checked before anything else
    report = ReportJob(args)
    if args.neighbourhood != "knn" and not radii:
        raise LidarfxError("give a radius: -r 0.5 (repeat -r for several scales)")
    if tiled:
        return run_tiles(args, "features", {
            "features": args.features, "radii": radii, "neighbourhood": args.neighbourhood, "k": args.k,
            "scanner": args.scanner, "height": args.height, "convention": args.convention, "d_max": args.d_max,
            "hist_bins": args.bins, "seed": args.seed})
    t0 = time.perf_counter()
    cloud, progress = read_input(args)
    t1 = time.perf_counter()
    names, fill = stream_features(
        cloud,
        args.features,
        radii=radii,
        neighbourhood=args.neighbourhood,
        k=args.k,
        scanner=args.scanner,
        height=args.height,
        convention=args.convention,
        d_max=args.d_max,
        hist_bins=args.bins,
        seed=args.seed,
    )
    # the features are computed chunk by chunk while the output is written
    # (LAS/LAZ), so they never exist in memory for the whole file at once
    placeholder = np.broadcast_to(np.float32(np.nan), len(cloud))
    for name in names:
        cloud[name] = placeholder
    nan_count = dict.fromkeys(names, 0)
    # the report's points keep their feature values as the chunks go by
    shown = report.sample(len(cloud)) if report.wanted else None
    kept = {name: np.full(len(shown), np.nan, np.float32) for name in names} if shown is not None else {}

    def counted(start: int, stop: int) -> dict:
        values = fill(start, stop)
        for name, v in values.items():
            nan_count[name] += int(np.count_nonzero(np.isnan(v)))
        if shown is not None:
            a, b = np.searchsorted(shown, [start, stop])
            for name, v in values.items():
                kept[name][a:b] = np.asarray(v)[shown[a:b] - start]
        return values

    t2 = time.perf_counter()
    io.write(cloud, args.output, progress=progress, fill=counted)
    t3 = time.perf_counter()
    n = max(len(cloud), 1)
    summary = {
        "input": args.input,
        "output": args.output,
        "points": len(cloud),
        "radii": sorted(radii),
        "units": units_summary(cloud),
        "neighbourhood": args.neighbourhood,
        "features": names,
        "nan_share": {name: round(c / n, 6) for name, c in nan_count.items()},
        "warnings": list(getattr(fill, "warnings", [])),
        "seconds": {"read": round(t1 - t0, 3), "index": round(t2 - t1, 3), "features_and_write": round(t3 - t2, 3)},
    }
    if shown is not None:
        from pathlib import Path

        sub = cloud.subset(shown)
        sub.update(kept)
        summary["report"] = report.write(f"Features of {Path(args.input).name}", summary, cloud=sub, points=len(cloud),
                                         attributes=[n for n in ("classification",) if n in sub] + names[:15],
                                         colour_by=names[0] if names else None)
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not args.quiet:
        print(
            f"{len(cloud):,} points, {len(names)} features -> {args.output} "
            f"(read {t1 - t0:.2f} s, index {t2 - t1:.2f} s, features + write {t3 - t2:.2f} s)",
            file=sys.stderr,
        )
    return 0
