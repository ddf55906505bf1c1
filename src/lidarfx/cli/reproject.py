"""``lidarfx reproject IN OUT --to EPSG:CODE [--from EPSG:CODE]``: coordinates into another CRS with PROJ."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from ._args import add_columns, check_output, columns_of, emit_summary
from ._ops import add_chunk_options, chunked, print_chunked, run_chunked
from ._tiles import TILE_HELP, inputs_of

EPILOG = """examples:
  lidarfx reproject scan.laz scan_wgs84.laz --to EPSG:4326                   # longitude, latitude (degrees)
  lidarfx reproject utm32.laz etrs.laz --to EPSG:25832
  lidarfx reproject navd_ft.laz navd_m.laz --from EPSG:6318+6360 --to EPSG:6318+5703   # heights ft -> m
  lidarfx reproject scan.xyz scan.laz --from EPSG:2154 --to EPSG:3857 --columns x,y,z,intensity
  lidarfx reproject tiles/ tiles_4326/ --to EPSG:4326                        # a folder of tiles, in chunks

PDAL: filters.reprojection (out_srs, in_srs); lidR: st_transform();
CloudCompare: no built-in reprojection; LAStools: las2las -target_epsg.

CRSs: EPSG:CODE, EPSG:H+V (compound: horizontal + vertical), a WKT or PROJ
string.  The source is the file's CRS (WKT, else GeoTIFF keys), or --from.
Heights are transformed when both CRSs have a vertical axis (compound, or 3-D
geographic such as EPSG:4979).  PROJ's best operation is used; when it needs a
grid (geoid, datum shift) that is not installed here the run stops naming it
(lidarfx never downloads: projsync --file NAME).  When PROJ only knows a
ballpark operation (heights or a datum shift left out) the run stops too
unless --ballpark.  The header's CRS records are rewritten (LAS 1.4: WKT;
1.0-1.3: GeoTIFF keys and WKT); scales keep the file's resolution in metres
(rounded down to a power of ten: 0.01 m -> 1e-08 degree), offsets fit the new
coordinates; --scale overrides.  docs/everyday.md#reproject.

""" + TILE_HELP


def register(sub) -> None:
    p = sub.add_parser(
        "reproject",
        help="transform coordinates into another CRS (PROJ; compound / vertical where the grids are here)",
        description="Reproject a point cloud into another coordinate reference system with PROJ (no network).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud, a folder of LAS/LAZ tiles or a quoted pattern")
    p.add_argument("output", help="output point cloud (format from the extension), or a folder for tiles")
    p.add_argument("--to", required=True, metavar="CRS", help="target CRS, e.g. EPSG:4326 or EPSG:2154+5720")
    p.add_argument("--from", dest="source", default=None, metavar="CRS",
                   help="the input's CRS when the file has none or a wrong one")
    p.add_argument("--scale", default=None, metavar="S[,SY,SZ]", help="output coordinate scale(s) (default: see below)")
    p.add_argument("--ballpark", action="store_true",
                   help="accept PROJ's ballpark operation when it knows no other (heights or datum shift left out)")
    add_columns(p)
    add_chunk_options(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def _scale(text):
    from ..errors import LidarfxError

    if text is None:
        return None
    try:
        vals = [float(v) for v in text.replace(" ", "").split(",")]
    except ValueError:
        raise LidarfxError(f"--scale must be one number or three (x,y,z), got {text!r}") from None
    if len(vals) not in (1, 3):
        raise LidarfxError(f"--scale must be one number or three (x,y,z), got {text!r}")
    return vals if len(vals) == 3 else vals[0]


def run(args) -> int:
    from .. import io
    from ..reproject import check_scale, parse_crs, reproject

    to = parse_crs(args.to, "--to")  # an unknown CRS before any work
    source = parse_crs(args.source, "--from") if args.source is not None else None
    scale = _scale(args.scale)
    check_scale(scale)
    if chunked(args, "reproject"):
        from ..tiles.proc_ops import reproject_options

        o = reproject_options(inputs_of(args.input), to, source=source, scale=scale, ballpark=args.ballpark)
        s = run_chunked(args, "reproject", o, extra={"from": o["source_label"], "to": o["target_label"],
                                                      "scales": o["scales"], "offsets": o["offsets"]})
        emit_summary(args, s, lambda s: print_chunked(s, f"reproject {s['from']} -> {s['to']}"))
        return 0
    t0 = time.perf_counter()
    check_output(args.input, args.output)
    progress = False if args.quiet else None
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    out = reproject(cloud, to, source=source, scale=scale, ballpark=args.ballpark, progress=progress)
    t2 = time.perf_counter()
    io.write(out, args.output, progress=progress)
    t3 = time.perf_counter()
    summary = {"input": str(args.input), "output": str(args.output), "points": len(out), **out.meta["reproject"],
               "seconds": {"read": round(t1 - t0, 3), "reproject": round(t2 - t1, 3), "write": round(t3 - t2, 3)}}
    if io.FORMATS.get(Path(args.output).suffix.lower()) != "las":
        summary["note"] = "the output format stores no CRS"
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    acc = f", accuracy {s['accuracy_m']:g} m" if s.get("accuracy_m") is not None else ""
    print(f"{s['points']:,} points {s['from']} -> {s['to']} ({s['operation']}{acc}); {s['vertical']} -> {s['output']}",
          file=sys.stderr)
    print(f"scales {', '.join(f'{v:g}' for v in s['scales'])}; offsets {', '.join(f'{v:.10g}' for v in s['offsets'])}"
          + (f"; {s['note']}" if s.get("note") else ""), file=sys.stderr)
