"""``lidarfx ground``, ``lidarfx ground-eval`` and ``lidarfx dtm``: ground filter, its accuracy, DTM rasters."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .. import _json
from ._args import add_columns, check_output, columns_of
from ._report import ReportJob, add_report_option
from ._tiles import TILE_HELP, add_tile_options, inputs_of, run_tiles, wants_tiles

GROUND_EPILOG = """examples:
  lidarfx ground in.laz out.laz                        # class 2 = ground, 1 = other (noise 7/18 kept)
  lidarfx ground in.laz out.laz --hag --dtm dtm.tif    # + height_above_ground attribute + 1 m DTM
  lidarfx ground in.laz out.laz --slope 0.2 --window 24 --json
  lidarfx ground tiles/ out/ --hag                     # a folder of tiles, in chunks
  lidarfx ground big.laz out.laz --hag --chunk-size 500 --workers 4 --resume

Method: SMRF (Pingel, Clarke & McBride 2013) with one default parameter set
tuned on the ISPRS filter-test samples (docs/ground.md).  Only last returns
are used where return numbers exist; classes 7, 18 and 66 are ignored and keep
their class.  Every other point is set to 2 (ground) or 1 (unclassified).

Lengths are metres; files in feet are converted (the SMRF lengths, -r,
--chunk-size, --buffer; docs/conventions.md).

In chunks the filter sees each chunk with a buffer (default: 4 x --window
rounded up to 50 m, i.e. 100 m): the filter
is not local, so a few points near chunk borders may get another class than
in one in-memory run (docs/scaling.md); --dtm needs --chunk-size 0 (or
lidarfx dtm on the output).

""" + TILE_HELP

EVAL_EPILOG = """examples:
  lidarfx ground-eval samp11-utm.laz --reference-class 2
  lidarfx ground-eval samp*-utm.laz --json              # every file + the mean

The reference is the file's own classification (REFERENCE_CLASS = ground,
every other class = object); the filter sees only x, y, z and the return
numbers.  Points of --ignore-classes are removed before filtering and scoring.
Errors as in Sithole & Vosselman (2004): type I = ground rejected / ground,
type II = object accepted / object, total = misclassified / all points.
"""

DTM_EPILOG = """examples:
  lidarfx dtm ground.laz dtm.tif                 # from the class 2 points, 1 m cells
  lidarfx dtm in.laz dtm.tif --classify -r 0.5   # run the ground filter first
  lidarfx dtm ground.laz dtm.asc                 # ESRI ASCII grid (+ .prj)

Lengths are metres; files in feet are converted (-r, the SMRF lengths): a
file in US feet gets cells of -r metres in feet.  GeoTIFF is written with
rasterio when installed, else by the built-in writer
(uncompressed float32 + GeoTIFF keys + .tfw world file).  The DTM is the
linear TIN of the ground points sampled at the cell centres; cells outside
their convex hull take the nearest ground height.
"""


def _int_list(text: str) -> list[int]:
    text = text.strip()
    if not text or text.lower() == "none":
        return []
    try:
        return [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated class codes, got {text!r}") from None


def _add_params(p) -> None:
    from ..ground import DEFAULTS, IGNORE_CLASSES

    g = p.add_argument_group("SMRF parameters (defaults: the tuned set, docs/ground.md)")
    g.add_argument("--cell", type=float, default=DEFAULTS["cell"], help="grid cell (m), default %(default)s")
    g.add_argument("--slope", type=float, default=DEFAULTS["slope"], help="opening slope (rise/run), default %(default)s")
    g.add_argument("--window", type=float, default=DEFAULTS["window"], help="largest opening radius (m), default %(default)s")
    g.add_argument("--threshold", type=float, default=DEFAULTS["threshold"], help="final elevation threshold (m), default %(default)s")
    g.add_argument("--scalar", type=float, default=DEFAULTS["scalar"], help="threshold per unit DTM slope (m), default %(default)s")
    g.add_argument("--edge-step", type=float, default=DEFAULTS["edge_step"], help="step height (m) on object boundaries, default %(default)s")
    g.add_argument("--edge-share", type=float, default=DEFAULTS["edge_share"], help="boundary share of steps to stay an object (0 = plain SMRF), default %(default)s")
    g.add_argument("--all-returns", action="store_true", help="use every return, not only last returns")
    g.add_argument(
        "--ignore-classes",
        type=_int_list,
        default=list(IGNORE_CLASSES),
        help="classes never used nor made ground (default %s; 'none' for none)" % ",".join(map(str, IGNORE_CLASSES)),
    )


def _params(args) -> dict:
    """The SMRF options, checked at once (also where they go unused: ``dtm`` without ``--classify``)."""
    from ..ground import check_params, check_ignore_classes

    p = {
        "cell": args.cell,
        "slope": args.slope,
        "window": args.window,
        "threshold": args.threshold,
        "scalar": args.scalar,
        "edge_step": args.edge_step,
        "edge_share": args.edge_share,
    }
    check_params(p)
    check_ignore_classes(args.ignore_classes)
    return {**p, "last_returns": not args.all_returns}


def register(sub) -> None:
    p = sub.add_parser(
        "ground",
        help="classify ground points (SMRF); optional DTM and height above ground",
        description="Classify ground points (class 2) of ALS data with SMRF and write the cloud. "
                    "Lengths are metres; files in feet are converted.",
        epilog=GROUND_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud")
    p.add_argument("output", help="output point cloud (format from the extension)")
    _add_params(p)
    p.add_argument("--hag", action="store_true", help="add the height_above_ground attribute")
    p.add_argument("--dtm", default=None, metavar="RASTER", help="also write a DTM raster (.tif or .asc)")
    p.add_argument("-r", "--resolution", type=float, default=1.0, help="DTM cell, m, default 1.0")
    add_columns(p)
    add_report_option(p)
    add_tile_options(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars or messages")
    p.set_defaults(func=run_ground)

    e = sub.add_parser(
        "ground-eval",
        help="type I / II / total error of the ground filter against a reference class",
        description="Evaluate the ground filter against the files' own reference classification. "
                    "Lengths are metres; files in feet are converted.",
        epilog=EVAL_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    e.add_argument("inputs", nargs="+", metavar="IN", help="labelled point cloud(s)")
    e.add_argument("--reference-class", type=_int_list, default=[2], metavar="C[,C...]",
                   help="ground class(es) of the reference, e.g. 2 or 2,9 (default 2)")
    _add_params(e)
    add_columns(e)
    e.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    e.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    e.set_defaults(func=run_eval)

    d = sub.add_parser(
        "dtm",
        help="DTM raster (GeoTIFF / ESRI ASCII) from ground points",
        description="Write a DTM raster interpolated (TIN) from the ground points of a cloud. "
                    "Lengths are metres; files in feet are converted.",
        epilog=DTM_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    d.add_argument("input", help="input point cloud")
    d.add_argument("output", help="output raster (.tif, .tiff or .asc)")
    d.add_argument("-r", "--resolution", type=float, default=1.0, help="cell, m, default 1.0")
    d.add_argument("--classify", action="store_true", help="run the ground filter first (else class 2 is ground)")
    _add_params(d)
    add_columns(d)
    d.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    d.add_argument("-q", "--quiet", action="store_true", help="no progress bars or messages")
    d.set_defaults(func=run_dtm)


def _check_raster_path(path: str) -> None:
    from pathlib import Path

    from .._atomic import check_output_folder
    from ..errors import LidarfxError
    from ..surface.raster import RASTER_EXTENSIONS

    if Path(path).suffix.lower() not in RASTER_EXTENSIONS:
        raise LidarfxError(f"{path}: DTM output must end in {', '.join(RASTER_EXTENSIONS)}")
    check_output_folder(path)
    import importlib.util

    from .._atomic import check_new_file

    # the files written beside it: the CRS of an ESRI grid, the world file of the built-in GeoTIFF writer
    if Path(path).suffix.lower() == ".asc":
        check_new_file(Path(path).with_suffix(".prj"))
    elif importlib.util.find_spec("rasterio") is None:
        check_new_file(Path(path).with_suffix(".tfw"))


def run_ground(args) -> int:
    from .. import io
    from ..crs import units_summary
    from ..ground import (
        apply_ground_classification,
        classify_ground,
        dtm,
        height_above_ground,
    )
    from ..ground.dtm import check_resolution

    params = _params(args)
    if wants_tiles(args, "ground"):
        if args.dtm:
            from ..errors import LidarfxError

            raise LidarfxError("--dtm is not written in chunks: run lidarfx dtm on the output (its class 2 points), "
                               "or use --chunk-size 0")
        from ..tiles.proc_ground import ground_options

        return run_tiles(args, "ground", ground_options(params, ignore_classes=args.ignore_classes, hag=args.hag,
                                                        inputs=inputs_of(args.input)))
    check_output(args.input, args.output)
    report = ReportJob(args)
    if args.dtm:
        _check_raster_path(args.dtm)
        check_resolution(args.resolution)
    progress = False if args.quiet else None
    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    mask = classify_ground(cloud, ignore_classes=args.ignore_classes, progress=progress, **params)
    out = apply_ground_classification(cloud, mask, ignore_classes=args.ignore_classes, **params)
    t2 = time.perf_counter()
    if args.hag:
        out["height_above_ground"] = height_above_ground(out, mask)
    raster = None
    if args.dtm:
        if not mask.any():
            from ..errors import LidarfxError

            raise LidarfxError("no ground point found: no DTM written")
        raster = dtm(out, args.resolution, ground=mask)
    t3 = time.perf_counter()
    io.write(out, args.output, progress=progress)
    if raster is not None:
        raster.write(args.dtm)
    t4 = time.perf_counter()
    summary = {
        "input": args.input,
        "output": args.output,
        "points": len(out),
        "ground_points": int(mask.sum()),
        "ground_share": round(float(mask.mean()), 6) if len(out) else None,
        "parameters": {**params, "ignore_classes": args.ignore_classes},
        "dtm": None if raster is None else {"path": args.dtm, "shape": list(raster.shape), "resolution": args.resolution,
                                            "cell_map_units": raster.resolution},
        "units": units_summary(cloud),
        "seconds": {
            "read": round(t1 - t0, 3),
            "classify": round(t2 - t1, 3),
            "hag_dtm": round(t3 - t2, 3),
            "write": round(t4 - t3, 3),
        },
    }
    page = report.write(f"Ground of {Path(args.input).name}", summary, cloud=out, colour_by="classification")
    if page:
        summary["report"] = page
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not args.quiet:
        print(
            f"{len(out):,} points, {int(mask.sum()):,} ground -> {args.output}"
            + (f", DTM {raster.shape[1]}x{raster.shape[0]} -> {args.dtm}" if raster is not None else "")
            + f" (classify {t2 - t1:.2f} s)",
            file=sys.stderr,
        )
    return 0


def evaluate_file(path: str, reference_class, ignore_classes, params: dict, progress=None,
                  columns: list[str] | None = None) -> dict:
    """Read ``path`` (text with the ``columns`` spec), hide its classes from the filter, score
    against ``reference_class`` (a class code or a list of them: the reference ground)."""
    import numpy as np

    from .. import io
    from ..cloud import PointCloud
    from ..errors import LidarfxError
    from ..ground import classify_ground, ground_errors

    cloud = io.read(path, columns=columns, progress=progress)
    if "classification" not in cloud:
        raise LidarfxError(f"{path}: no classification to use as reference")
    cls = np.asarray(cloud["classification"])
    keep = ~np.isin(cls, list(ignore_classes or []))
    if not keep.any():
        raise LidarfxError(f"{path}: no points to evaluate"
                           + (f" (classes {sorted(set(ignore_classes))} ignored)" if len(cloud) else ""))
    attrs = {k: cloud[k][keep] for k in ("return_number", "number_of_returns") if k in cloud}
    # xyz and returns only, no classes; the header's CRS gives the unit (metre lengths on feet data)
    bare = PointCloud(cloud.xyz[keep], attrs, header=cloud.header, meta=cloud.meta)
    t0 = time.perf_counter()
    pred = classify_ground(bare, ignore_classes=None, progress=progress, **params)
    sec = time.perf_counter() - t0
    res = ground_errors(pred, np.isin(cls[keep], np.atleast_1d(reference_class)))
    res.update(file=path, ignored_points=int((~keep).sum()), seconds=round(sec, 3))
    return res


def run_eval(args) -> int:
    import numpy as np

    from ..errors import LidarfxError

    progress = False if args.quiet else None
    params = _params(args)
    if not args.reference_class:
        raise LidarfxError("--reference-class needs at least one class code, e.g. 2 or 2,9")
    for c in args.reference_class:
        if not 0 <= c <= 255:
            raise LidarfxError(f"--reference-class must be a class code 0..255, got {c}")
    rows = [evaluate_file(f, args.reference_class, args.ignore_classes, params, progress, columns_of(args))
            for f in args.inputs]
    mean = {k: float(np.mean([r[k] for r in rows])) for k in ("type_i", "type_ii", "total")}
    if args.json:
        _json.dump(
            {"reference_class": args.reference_class, "parameters": {**params, "ignore_classes": args.ignore_classes},
             "files": rows, "mean": mean},
            sys.stdout,
            indent=2,
        )
        print()
        return 0
    w = max([len(r["file"]) for r in rows] + [4])  # whole paths: a table never cuts a file name
    print(f"{'file':{w}s} {'points':>8s} {'type I %':>9s} {'type II %':>9s} {'total %':>8s}")
    for r in rows:
        print(f"{r['file']:{w}s} {r['n_points']:8d} {100 * r['type_i']:9.2f} {100 * r['type_ii']:9.2f} {100 * r['total']:8.2f}")
    if len(rows) > 1:
        print(f"{'mean':{w}s} {'':8s} {100 * mean['type_i']:9.2f} {100 * mean['type_ii']:9.2f} {100 * mean['total']:8.2f}")
    return 0


def run_dtm(args) -> int:
    from .. import io
    from ..crs import units_summary
    from ..errors import LidarfxError
    from ..ground import classify_ground, dtm
    from ..ground.dtm import check_resolution

    _check_raster_path(args.output)
    params = _params(args)
    check_resolution(args.resolution)
    progress = False if args.quiet else None
    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    if args.classify:
        mask = classify_ground(cloud, ignore_classes=args.ignore_classes, progress=progress, **params)
    else:
        if "classification" not in cloud:
            raise LidarfxError(f"{args.input}: no classification; use --classify to run the ground filter")
        mask = cloud["classification"] == 2
    if not mask.any():
        raise LidarfxError(f"{args.input}: no ground points (class 2); use --classify")
    raster = dtm(cloud, args.resolution, ground=mask)
    raster.write(args.output)
    sec = time.perf_counter() - t0
    summary = {
        "input": args.input,
        "output": args.output,
        "ground_points": int(mask.sum()),
        "shape": list(raster.shape),
        "resolution": args.resolution,
        "cell_map_units": raster.resolution,
        "units": units_summary(cloud),
        "origin": list(raster.origin),
        "epsg": (raster.crs or {}).get("epsg"),
        "seconds": round(sec, 3),
    }
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not args.quiet:
        print(f"DTM {raster.shape[1]}x{raster.shape[0]} cells of {args.resolution:g} m -> {args.output}", file=sys.stderr)
    return 0
