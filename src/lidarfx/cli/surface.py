"""``lidarfx dsm`` and ``lidarfx chm``: surface and canopy height rasters (docs/surfaces.md)."""
from __future__ import annotations

import argparse
import sys
import time

from ._args import add_columns, columns_of, emit_summary
from .ground import _int_list

DSM_EPILOG = """examples:
  lidarfx dsm tile.laz dsm.tif                      # highest return per 1 m cell
  lidarfx dsm tile.laz dsm.tif -r 0.5 --first-returns
  lidarfx dsm tile.laz dsm.asc --max-gap 0          # ESRI ASCII grid (+ .prj); no filling
  lidarfx dsm tile.laz dsm.tif --exclude-classes none --json

A cell is the largest z of the points in it (float32).  Cells: column
floor((x - x0) / r), row floor((y - y0) / r) from the south, (x0, y0) the
cloud's minimum snapped down to a multiple of r (the grid of lidarfx dtm and
chm).  Noise classes 7 and 18 are left out.  Empty cells in gaps narrower than
--max-gap (default 5 m, at least 2 cells) are filled from the TIN of the
filled cells; cells in wider gaps are no data (NaN; -9999 in .asc).

Lengths are metres; files in feet are converted (-r, --max-gap).  GeoTIFF is
written with rasterio when installed, else by the built-in writer
(uncompressed float32 + GeoTIFF keys + .tfw world file).  The whole cloud is
held in memory (at most 100 M cells): cut larger areas first.  docs/surfaces.md
"""

CHM_EPILOG = """examples:
  lidarfx chm tile.laz chm.tif -r 0.5               # pit-free, ground = class 2 (else SMRF)
  lidarfx chm tile.laz chm.tif -r 0.5 --ground smrf # run the ground filter
  lidarfx chm tile.laz chm.tif --no-pit-free        # plain: highest first return per cell
  lidarfx chm tile.laz chm.tif --thresholds 0,2,5,10,15,20,25 --freeze-distance 1.5

Canopy height = z minus the ground TIN under each first return (the DSM minus
the DTM, per point), highest per cell, negative heights clipped to 0.
Pit-free (Khosravipour et al. 2014): partial CHMs from the first returns at or
above 0, 2, 5, 10, 15 m, ... (every 5 m up to the highest), each with its gaps
narrower than the freeze distance filled from the TIN of its cells, combined
by their maximum; returns that went deep into a crown no longer leave pits.
Default freeze distance: 3 mean first-return spacings or 3 cells, the larger.
Ground: --ground auto (default) takes class 2 when the file has any, else runs
the ground filter (SMRF with its defaults; tune it with lidarfx ground first).

Lengths are metres; files in feet are converted (-r, --thresholds,
--freeze-distance, --max-gap); heights are in the file's unit.  Same grid,
gap rule, formats and memory limit as lidarfx dsm (docs/surfaces.md).
"""


def _numbers(text: str) -> list[float]:
    try:
        return [float(v) for v in text.replace(" ", "").split(",") if v]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated heights in metres, got {text!r}") from None


def _common(p) -> None:
    p.add_argument("input", help="input point cloud")
    p.add_argument("output", help="output raster (.tif, .tiff or .asc)")
    p.add_argument("-r", "--resolution", type=float, default=1.0, help="cell, m, default 1.0")
    p.add_argument("--max-gap", type=float, default=None, metavar="M",
                   help="fill empty cells in gaps up to M metres wide (default 5, at least 2 cells; 0 = none, "
                        "inf = all)")
    p.add_argument("--exclude-classes", type=_int_list, default=[7, 18], metavar="C[,C...]",
                   help="classes left out (default 7,18: noise; 'none' for none)")
    add_columns(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars or messages")


def register(sub) -> None:
    d = sub.add_parser(
        "dsm",
        help="DSM raster (GeoTIFF / ESRI ASCII): the highest return per cell",
        description="Write a digital surface model: the highest return in every cell, small gaps filled. "
                    "Lengths are metres; files in feet are converted.",
        epilog=DSM_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _common(d)
    d.add_argument("--first-returns", action="store_true", help="only first returns (default: every return)")
    d.set_defaults(func=run_dsm)

    c = sub.add_parser(
        "chm",
        help="canopy height model raster (pit-free): first returns above the ground",
        description="Write a canopy height model: the highest first return's height above the ground per cell, "
                    "pit-free by default. Lengths are metres; files in feet are converted.",
        epilog=CHM_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    _common(c)
    c.add_argument("--ground", choices=("auto", "class", "smrf"), default="auto",
                   help="ground points: class 2, the ground filter (smrf), or class 2 when present (auto, default)")
    c.add_argument("--pit-free", action=argparse.BooleanOptionalAction, default=True,
                   help="combine partial CHMs above height thresholds (default) or not")
    c.add_argument("--thresholds", type=_numbers, default=None, metavar="H[,H...]",
                   help="heights (m) of the partial CHMs (default 0,2,5,10,15 and every 5 m above)")
    c.add_argument("--freeze-distance", type=float, default=None, metavar="D",
                   help="widest gap (m) a partial CHM above 0 fills (default 3 first-return spacings, "
                        "at least 3 cells)")
    c.add_argument("--all-returns", action="store_true", help="every return, not only first returns")
    c.set_defaults(func=run_chm)


def _early_checks(args, **options) -> None:
    """Before any work: the output (extension, folder, an existing file without --force, the
    .prj / .tfw beside it, not the input) and the options; for LAS/LAZ input also the raster's
    size from the header's bounds."""
    from pathlib import Path

    from .._atomic import check_not_same_file
    from ..errors import LidarfxError
    from ..surface.models import check_options
    from ..surface.raster import RASTER_EXTENSIONS
    from .ground import _check_raster_path

    check_not_same_file(args.input, args.output)
    if Path(args.output).suffix.lower() not in RASTER_EXTENSIONS:
        raise LidarfxError(f"{args.output}: the {args.command.upper()} is a raster; give a path ending in "
                           f"{', '.join(RASTER_EXTENSIONS)}")
    _check_raster_path(args.output)  # the checks of lidarfx dtm: folder, existing files, .prj / .tfw
    check_options(resolution=args.resolution, max_gap=args.max_gap, exclude_classes=args.exclude_classes, **options)
    _check_size(args.input, args.resolution, args.command.upper())


def _check_size(path: str, resolution: float, what: str) -> None:
    """Refuse a raster above the cell limit from a LAS/LAZ header, before reading the points."""
    from pathlib import Path

    from ..errors import LidarfxError
    from ..surface.models import MAX_CELLS
    from ..surface.raster import grid_layout

    if Path(path).suffix.lower() not in (".las", ".laz") or not Path(path).is_file():
        return
    try:
        from ..crs import unit_to_metre
        from ..io.las import read_header

        header = read_header(Path(path))
        lo, hi = header.mins[:2], header.maxs[:2]
        r = float(resolution) / unit_to_metre(header)
    except Exception:  # the reader's own error comes when the points are read
        return
    try:
        grid_layout(lo, hi, r, max_cells=MAX_CELLS, what=what)
    except LidarfxError:
        raise
    except Exception:  # header bounds that are not numbers: the reader decides
        return


def _summary(args, raster, cloud, seconds: dict) -> dict:
    from ..crs import units_summary

    return {
        "input": args.input,
        "output": args.output,
        "product": raster.meta.get("product"),
        "shape": list(raster.shape),
        "resolution": args.resolution,
        "cell_map_units": raster.resolution,
        "origin": list(raster.origin),
        "epsg": (raster.crs or {}).get("epsg"),
        **{k: v for k, v in raster.meta.items() if k != "product"},
        "units": units_summary(cloud),
        "seconds": seconds,
    }


def _print(summary: dict) -> None:
    rows, cols = summary["shape"]
    what = summary["product"].upper()
    extra = f", ground {summary['ground']}" if "ground" in summary else ""
    print(f"{what} {cols}x{rows} cells of {summary['resolution']:g} m -> {summary['output']} "
          f"({summary['cells_with_points']:,} with points, {summary['filled_cells']:,} filled, "
          f"{summary['nodata_cells']:,} no data{extra})", file=sys.stderr)


def _run(args, make) -> int:
    from .. import io

    progress = False if args.quiet else None
    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    raster = make(cloud, progress)
    t2 = time.perf_counter()
    raster.write(args.output)
    t3 = time.perf_counter()
    seconds = {"read": round(t1 - t0, 3), "compute": round(t2 - t1, 3), "write": round(t3 - t2, 3)}
    emit_summary(args, _summary(args, raster, cloud, seconds), _print)
    return 0


def run_dsm(args) -> int:
    from ..surface.models import dsm

    _early_checks(args)
    return _run(args, lambda cloud, progress: dsm(
        cloud, args.resolution, first_returns=args.first_returns, exclude_classes=args.exclude_classes,
        max_gap=args.max_gap, progress=progress))


def run_chm(args) -> int:
    from ..surface.models import chm

    _early_checks(args, freeze_distance=args.freeze_distance, thresholds=args.thresholds)
    return _run(args, lambda cloud, progress: chm(
        cloud, args.resolution, ground=args.ground, pit_free=args.pit_free, thresholds=args.thresholds,
        freeze_distance=args.freeze_distance, max_gap=args.max_gap, first_returns=not args.all_returns,
        exclude_classes=args.exclude_classes, progress=progress))
