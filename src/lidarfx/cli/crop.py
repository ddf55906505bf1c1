"""``lidarfx crop IN OUT --bounds ... | --polygon area.geojson``: keep the points inside a box or polygons."""
from __future__ import annotations

import argparse
import sys
import time

from ._args import add_columns, check_output, columns_of, emit_summary
from ._ops import add_chunk_options, chunked, print_chunked, run_chunked
from ._tiles import TILE_HELP, inputs_of

EPILOG = """examples:
  lidarfx crop scan.laz tile.laz --bounds 770500,6277500,770540,6277540          # a box (x, y)
  lidarfx crop scan.laz slab.laz --bounds 770500,6277500,770540,6277540,20,35    # with z limits
  lidarfx crop scan.laz park.laz --polygon park.geojson                          # Polygon / MultiPolygon, holes
  lidarfx crop scan.laz lake.laz --polygon lake.shp --buffer 5                   # 5 m around the lake
  lidarfx crop scan.laz rest.laz --polygon buildings.shp --invert                # everything outside
  lidarfx crop tiles/ park/ --polygon park.geojson                               # a folder of tiles, in chunks

PDAL: filters.crop (bounds / polygon, outside=true for --invert);
lidR: clip_rectangle(), clip_roi(); CloudCompare: Edit > Crop, Segment with a polygon.

The box is closed (points on a face are inside).  Polygons come from GeoJSON
(a geometry, Feature or FeatureCollection of Polygon / MultiPolygon) or a
polygon shapefile (its .prj gives the CRS); all polygons of the file together
are the area, holes left out, tested exactly in plan (points on the boundary
are inside).  When the area and the cloud both have a CRS they must agree.
--buffer M widens the area by M metres (exact distances; negative shrinks it).
A crop that keeps no point is an error (exit 2, nothing written) unless
--allow-empty, which writes an empty file.  docs/everyday.md#crop.

""" + TILE_HELP


def register(sub) -> None:
    p = sub.add_parser(
        "crop",
        help="keep the points inside a box or polygons (GeoJSON, shapefile), with a buffer",
        description="Keep the points inside a box or polygon area (or outside with --invert). "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud, a folder of LAS/LAZ tiles or a quoted pattern")
    p.add_argument("output", help="output point cloud (format from the extension), or a folder for tiles")
    area = p.add_mutually_exclusive_group(required=True)
    area.add_argument("--bounds", default=None, metavar="XMIN,YMIN,XMAX,YMAX[,ZMIN,ZMAX]",
                      help="a box in the cloud's coordinates")
    area.add_argument("--polygon", default=None, metavar="FILE", help="polygons: .geojson / .json or .shp")
    p.add_argument("--buffer", type=float, default=0.0, metavar="M",
                   help="widen the area by this many metres (negative: shrink), default 0")
    p.add_argument("--invert", action="store_true", help="keep the points outside instead")
    p.add_argument("--allow-empty", action="store_true", help="write an empty file when no point is kept")
    add_columns(p)
    add_chunk_options(p, with_buffer=False)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def _empty_message(args, area_bounds, cloud_bounds=None) -> str:
    where = "outside" if args.invert else "inside"
    what = f"the polygons of {args.polygon}" if args.polygon else "the box"
    tail = ""
    if area_bounds is not None:
        tail = f" (area x {area_bounds[0]:.10g}..{area_bounds[2]:.10g}, y {area_bounds[1]:.10g}..{area_bounds[3]:.10g}"
        if cloud_bounds is not None:
            lo, hi = cloud_bounds
            tail += f"; cloud x {lo[0]:.10g}..{hi[0]:.10g}, y {lo[1]:.10g}..{hi[1]:.10g}"
        tail += ")"
    return f"no point of {args.input} lies {where} {what}{tail}; nothing written (--allow-empty writes an empty file)"


def run(args) -> int:
    from .. import io
    from ..crop import crop_mask, parse_bounds, read_area

    bounds = parse_bounds(args.bounds) if args.bounds is not None else None
    area = read_area(args.polygon) if args.polygon is not None else None  # a bad polygon file before any work
    area_bounds = area.geometry.bounds if area is not None else (bounds[:4] if bounds else None)
    if chunked(args, "crop", with_buffer=False):
        from ..tiles.proc_ops import crop_options

        opts = crop_options(inputs_of(args.input), bounds=bounds, polygon=area, buffer=args.buffer, invert=args.invert)
        s = run_chunked(args, "crop", opts, allow_empty=args.allow_empty, empty_message=_empty_message(args, area_bounds),
                        with_buffer=False)
        emit_summary(args, s, lambda s: print_chunked(s, "crop"))
        return 0
    t0 = time.perf_counter()
    check_output(args.input, args.output)
    progress = False if args.quiet else None
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    mask = crop_mask(cloud, bounds=bounds, polygon=area, buffer=args.buffer, invert=args.invert)
    kept = int(mask.sum())
    if kept == 0 and not args.allow_empty:
        from ..errors import LidarfxError

        lo = cloud.xyz.min(axis=0) if len(cloud) else None
        hi = cloud.xyz.max(axis=0) if len(cloud) else None
        raise LidarfxError(_empty_message(args, area_bounds, (lo, hi) if lo is not None else None))
    t2 = time.perf_counter()
    io.write(cloud.subset(mask), args.output, progress=progress)
    t3 = time.perf_counter()
    summary = {
        "input": str(args.input), "output": str(args.output),
        "area": ({"polygon": str(args.polygon), "polygons": area.polygons,
                  "crs": None if area.crs is None else area.crs.name} if area is not None
                 else {"bounds": list(bounds)}),
        "buffer_m": float(args.buffer), "invert": bool(args.invert),
        "points": len(cloud), "kept": kept, "share_kept": round(kept / len(cloud), 6) if len(cloud) else None,
        "seconds": {"read": round(t1 - t0, 3), "crop": round(t2 - t1, 3), "write": round(t3 - t2, 3)},
    }
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    share = f" ({100 * s['share_kept']:.2f} %)" if s["share_kept"] is not None else ""
    a = s["area"]
    what = f"{a['polygons']} polygon{'s' if a['polygons'] != 1 else ''} of {a['polygon']}" if "polygon" in a else "the box"
    side = "outside" if s["invert"] else "inside"
    buf = f" + {s['buffer_m']:g} m" if s["buffer_m"] else ""
    print(f"kept {s['kept']:,} of {s['points']:,} points{share} {side} {what}{buf} -> {s['output']}", file=sys.stderr)
