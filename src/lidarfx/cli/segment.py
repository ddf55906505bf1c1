"""``lidarfx segment IN OUT``: plane segmentation by surface growing (LIS parameters)."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .. import _json
from ._args import add_columns, check_picture_path, read_input, xyz
from ._tiles import inputs_of
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx segment scan.laz seg.laz                       # LIS defaults (dense TLS)
  lidarfx segment scan.laz seg.laz --min-width 0.15       # drop thin strips along edges
  lidarfx segment scan.laz seg.laz --scanner 12.5,-3.0,1.7 --min-size 100
  lidarfx segment als.laz seg.laz --normal-radius 1.5 --max-distance 0.2 \\
      --growing-radius 1.2 --max-angle 15 --min-size 30 --min-width 1.2   # ALS roofs, ~3 pts/m²
  lidarfx segment scan.laz seg.laz --table planes --json  # planes.csv + planes.json

parameters (LIS defaults, German names from the LIS slides):
  --normal-radius   0.10 m  Suchradius (local plane: normal, plane_std)
  --max-distance    0.10 m  maximaler Abstand zum Flächensegment
  --growing-radius  0.15 m  Suchradius zur Flächenverdichtung (region growing)
  --max-angle       15°     maximale Abweichung vom Normalvektor
  --min-size        30      smaller segments are released (segment_id -1)
  --min-width       0 (off) narrower segments (sqrt(12 λ2), m) are released too

outputs: OUT with segment_id (int32, -1 = none, 0 = largest) and segment_size
(int32), plus the per-segment table OUT.segments.csv and OUT.segments.json
(id, size, centroid, normal, dip, dip direction, RMS, convex-hull area in the
plane).  Follow up with e.g.
  lidarfx select seg.laz big.laz --where "segment_id >= 0 and segment_size > 500"

chunks: segment does not run in chunks (docs/scaling.md): surface growing is not
local (a plane grows across chunk borders; seeds, the size filter and the ids
ordered by size are the whole cloud's).  Run it on one file; cut a large input
to size first (lidarfx select).
"""


def register(sub) -> None:
    from ..segment import DEFAULTS

    p = sub.add_parser(
        "segment",
        help="plane segmentation by surface growing (segment_id, per-segment table)",
        description="Segment a point cloud into planes by surface growing against the segment plane. "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("output", help="output point cloud (format from the extension)")
    p.add_argument("--normal-radius", type=float, default=DEFAULTS["normal_radius"], help="radius of the local plane fit giving normals (m), default %(default)s")
    p.add_argument("--max-distance", type=float, default=DEFAULTS["max_distance"], help="max distance to the segment plane (m), default %(default)s")
    p.add_argument("--growing-radius", type=float, default=DEFAULTS["growing_radius"], help="neighbour radius of the growing (m), default %(default)s")
    p.add_argument("--max-angle", type=float, default=DEFAULTS["max_angle"], help="max normal deviation (degrees), default %(default)s")
    p.add_argument("--min-size", type=int, default=DEFAULTS["min_size"], help="minimum points per segment, default %(default)s")
    p.add_argument("--min-width", type=float, default=DEFAULTS["min_width"], help="release segments narrower than this (m; sqrt(12*lambda2)); 0 = off, default %(default)s")
    p.add_argument("--scanner", type=xyz, default=None, help="scanner position x,y,z for the normals (TLS)")
    p.add_argument("--keep-features", action="store_true", help="also write normal_x/y/z and plane_std")
    p.add_argument("--table", default=None, metavar="PATH", help="table path stem: writes PATH.csv and PATH.json (default OUT.segments)")
    p.add_argument("--no-table", action="store_true", help="do not write the per-segment table")
    p.add_argument("--picture", default=None, metavar="PNG", help="also draw the segments (top view, one colour each) into this PNG")
    p.add_argument("--top", type=int, default=10, help="segments listed in the summary, default %(default)s")
    add_columns(p)
    add_report_option(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def _table_paths(args) -> tuple[str, str]:
    stem = args.table if args.table else f"{args.output}.segments"
    for ext in (".csv", ".json"):
        if stem.lower().endswith(ext):
            stem = stem[: -len(ext)]
    return stem + ".csv", stem + ".json"


def run(args) -> int:
    from .. import io
    from ..segment import (
        segment_planes,
        segments_table,
        write_segments_csv,
        write_segments_json,
    )

    if args.top < 0:
        from ..errors import LidarfxError

        raise LidarfxError(f"--top is the number of segments listed, 0 or more; got {args.top}")
    if args.picture:
        check_picture_path(args.picture)
    if not args.no_table:
        from .._atomic import check_output_folder

        for path in _table_paths(args):
            check_output_folder(path)
    report = ReportJob(args)
    from ..segment.planes import check_params

    # the library's checks, before reading the cloud
    check_params(args.normal_radius, args.max_distance, args.growing_radius, args.max_angle, args.min_size,
                  args.min_width)
    if isinstance(inputs_of(args.input), list) or Path(args.input).is_dir():
        from ..errors import LidarfxError

        raise LidarfxError("segment does not run in chunks: surface growing is not local (a plane grows across "
                           "chunk borders; its seeds, size filter and ids are the whole cloud's); give one file")
    t0 = time.perf_counter()
    cloud, progress = read_input(args)
    t1 = time.perf_counter()
    out = segment_planes(
        cloud,
        normal_radius=args.normal_radius,
        max_distance=args.max_distance,
        growing_radius=args.growing_radius,
        max_angle=args.max_angle,
        min_size=args.min_size,
        min_width=args.min_width,
        scanner=args.scanner,
        keep_features=args.keep_features,
        inplace=True,
        progress=progress,
    )
    if out.meta["segmentation"]["segments"] == 0:  # stop: an empty segmentation is a wrong setting
        from ..errors import LidarfxError
        from ..segment.planes import no_segments_hint

        raise LidarfxError(no_segments_hint(out))
    t2 = time.perf_counter()
    rows = segments_table(out)
    t3 = time.perf_counter()
    io.write(out, args.output, progress=progress)
    meta = dict(out.meta["segmentation"])
    meta["input"] = str(args.input)
    csv_path = json_path = None
    if not args.no_table:
        csv_path, json_path = _table_paths(args)
        write_segments_csv(rows, csv_path)
        write_segments_json(rows, json_path, meta)
    picture = args.picture or (report.picture("segments.png") if report.wanted else None)
    if picture:
        from ..render import segment_view

        segment_view(out, picture, height_panel=True, title=f"{Path(args.input).name}: {len(rows)} segments")
    t4 = time.perf_counter()

    n = len(out)
    nseg_pts = meta["segmented_points"]
    top = rows[: args.top]
    summary = {
        "input": str(args.input),
        "output": str(args.output),
        "table_csv": csv_path,
        "table_json": json_path,
        "picture": args.picture,
        "points": n,
        "segments": len(rows),
        "segmented_points": nseg_pts,
        "segmented_share": round(nseg_pts / n, 6) if n else 0.0,
        "parameters": meta["parameters"],
        "largest": [
            {k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items() if k in ("id", "size", "dip", "dip_direction", "rms", "area")}
            for r in top
        ],
        "seconds": {"read": round(t1 - t0, 3), "segment": round(t2 - t1, 3), "table": round(t3 - t2, 3), "write": round(t4 - t3, 3)},
    }
    page = report.write(f"Plane segments of {Path(args.input).name}", summary, cloud=out, colour_by="segment_id",
                        pictures=[(picture, "segments")] if picture else ())
    if page:
        summary["report"] = page
    if args.json:
        _json.dump(summary, sys.stdout, indent=2)
        print()
    elif not args.quiet:
        _print_summary(summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=True)
    console.print(
        f"[bold]{s['segments']:,}[/] plane segments; {s['segmented_points']:,} of {s['points']:,} points "
        f"segmented ({100 * s['segmented_share']:.1f} %) -> {s['output']}"
    )
    if s["largest"]:
        t = Table(title=f"largest {len(s['largest'])} segments", title_justify="left")
        for col, just in (("id", "right"), ("points", "right"), ("dip °", "right"), ("dip dir °", "right"), ("RMS m", "right"), ("area m²", "right")):
            t.add_column(col, justify=just)
        for r in s["largest"]:
            t.add_row(
                str(r["id"]), f"{r['size']:,}", f"{r['dip']:.1f}", f"{r['dip_direction']:.1f}", f"{r['rms']:.3f}", f"{r['area']:.1f}"
            )
        console.print(t)
    if s["table_csv"]:
        console.print(f"table: {s['table_csv']}, {s['table_json']}")
    sec = s["seconds"]
    console.print(f"read {sec['read']:.2f} s, segment {sec['segment']:.2f} s, table {sec['table']:.2f} s, write {sec['write']:.2f} s")
