"""``lidarfx discontinuities IN OUTDIR``: joint sets of a rock face on a Schmidt net, spacing, overhangs."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, check_output_dir, columns_of, emit_summary, xyz
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx discontinuities face.laz out/                               # radius from the point spacing
  lidarfx discontinuities face.laz out/ --scanner 5,-25,1.5 --scanner 15,-25,1.5   # normals towards the scanners,
                                                                      # reference horizon at their height
  lidarfx discontinuities face.laz out/ -r 0.10 --max-distance 0.10 --growing-radius 0.15   # the LIS parameters
  lidarfx discontinuities face.laz out/ --sets 4 --reference-plane horizontal@1.5 --json
  lidarfx discontinuities face.laz out/ --reference-plane 10,0,5,0,-1,0.2   # plane x,y,z,nx,ny,nz

steps: local planes (normal, planarity; per-point dip / dip direction) -> plane
segments by surface growing -> the LIS selection (segment > 50 points, planarity
> 0.5) -> joint sets from the density peaks of the segment poles, refined by
spherical k-means on axial data (the number of sets from the data) -> Fisher
mean, kappa, alpha95 per set -> set id per segment and per point -> spacing of
the parallel planes of a set, trace length and area per segment -> signed
distance to the reference plane, overhang flag (outward normal pointing down).
outputs in OUTDIR: cloud.laz (dip, dip_direction, normal_x/y/z, planarity,
segment_id, segment_size, selected, set_id, reference_distance, overhang),
sets.csv + sets.json, segments.csv, stereonet.png (lower hemisphere, equal area,
Kamb contours), rose.png (strikes), sets.png (the cloud by set).
docs/discontinuities.md.
"""


def _sets(text: str):
    if text.strip().lower() == "auto":
        return None
    try:
        k = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sets is auto or a whole number of sets, got {text!r}") from None
    if not 1 <= k <= 50:
        raise argparse.ArgumentTypeError(f"--sets must be from 1 to 50, got {k}")
    return k


def register(sub) -> None:
    from ..discontinuities import DEFAULTS as D

    p = sub.add_parser(
        "discontinuities",
        help="rock faces: discontinuity orientations, joint sets (Fisher), stereonet, spacing, overhangs",
        description="Find the discontinuities and joint sets of a rock face. Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("outdir", help="output folder (created if missing)")
    p.add_argument("-r", "--radius", type=float, default=None, help="normal radius, m (default: about 40 points on a plane)")
    p.add_argument("--scanner", type=xyz, action="append", default=None, metavar="X,Y,Z",
                   help="scanner position (repeatable): normals point towards the scanners")
    p.add_argument("--max-distance", type=float, default=None, help="largest distance to the segment plane, m (default: 3 x the surface roughness)")
    p.add_argument("--growing-radius", type=float, default=None, help="growing radius, m (default 1.5 x the radius)")
    p.add_argument("--max-angle", type=float, default=D["max_angle"], help="largest normal deviation in a segment, degrees (default %(default)s)")
    p.add_argument("--min-segment-size", type=int, default=D["min_segment_size"], help="a discontinuity has more points than this (default %(default)s)")
    p.add_argument("--min-planarity", type=float, default=D["min_planarity"], help="selected points have a higher planarity (default %(default)s)")
    p.add_argument("--min-width", type=float, default=None, help="release segments narrower than this, m (default: the growing radius; 0 = off)")
    p.add_argument("--sets", type=_sets, default=None, metavar="auto|K", help="number of joint sets (default auto: from the data)")
    p.add_argument("--cone", type=float, default=D["cone"], help="largest angle of a pole to its set mean, degrees (default %(default)s)")
    p.add_argument("--separation", type=float, default=D["separation"], help="closest two set means, degrees (default %(default)s)")
    p.add_argument("--min-share", type=float, default=D["min_share"], help="smallest share of a set (default %(default)s)")
    p.add_argument("--reference-plane", default=None, metavar="SPEC",
                   help="fit | horizontal@Z | horizontal | x,y,z,nx,ny,nz (default: horizontal at the scanner height, else fit)")
    p.add_argument("--overhang-angle", type=float, default=D["overhang_angle"],
                   help="a point overhangs when its outward normal points this far below horizontal, degrees (default %(default)s)")
    p.add_argument("--cloud-format", choices=("laz", "las", "none"), default="laz", help="format of the output cloud (default %(default)s)")
    p.add_argument("--no-picture", action="store_true", help="do not draw stereonet.png, rose.png and sets.png")
    add_columns(p)
    add_report_option(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import io
    from .._atomic import check_not_same_file
    from ..discontinuities import analyse_discontinuities, parse_reference_plane
    from ..discontinuities.output import draw_pictures, write_tables

    out = check_output_dir(args.outdir)
    report = ReportJob(args)
    import numpy as np

    parse_reference_plane(args.reference_plane, None if args.scanner is None else np.asarray(args.scanner))
    cloud_path = out / f"cloud.{args.cloud_format}" if args.cloud_format != "none" else None
    if cloud_path is not None:
        check_not_same_file(args.input, cloud_path)
    params = dict(radius=args.radius, scanner=args.scanner, max_distance=args.max_distance,
                  growing_radius=args.growing_radius, max_angle=args.max_angle, min_segment_size=args.min_segment_size,
                  min_planarity=args.min_planarity, min_width=args.min_width, n_sets=args.sets, cone=args.cone,
                  separation=args.separation, min_share=args.min_share, reference_plane=args.reference_plane,
                  overhang_angle=args.overhang_angle)
    progress = False if args.quiet else None
    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    res = analyse_discontinuities(cloud, progress=progress, **params)
    t2 = time.perf_counter()
    out.mkdir(exist_ok=True)
    if cloud_path is not None:  # first: an attribute the format cannot store is refused before any table exists
        io.write(res.cloud, cloud_path, progress=progress)
    written = write_tables(res, out, meta={"input": str(args.input)})
    if cloud_path is not None:
        written["cloud"] = str(cloud_path)
    if not args.no_picture:
        written.update(draw_pictures(res, out, name=Path(args.input).name))
    t3 = time.perf_counter()
    m = res.meta
    summary = {
        "input": str(args.input),
        "outputs": written,
        "points": m["points"],
        "segments": m["segments"],
        "selected_points": m["selected_points"],
        "sets": [{k: (round(v, 3) if isinstance(v, float) else v) for k, v in s.items()
                  if k in ("id", "dip", "dip_direction", "strike", "kappa", "alpha95", "segments", "points", "share",
                           "spacing_mean", "mean_trace_length")} for s in res.sets],
        "set_points": m["set_points"],
        "overhang_points": m["overhang_points"],
        "reference_plane": res.reference,
        "parameters": m["parameters"],
        "seconds": {"read": round(t1 - t0, 3), **m["seconds"], "write": round(t3 - t2, 3)},
    }
    if report.wanted:
        pictures = [] if not args.no_picture else [  # drawn in OUTDIR already, else for the report
            (p, Path(p).stem) for p in draw_pictures(res, report.scratch(), name=Path(args.input).name).values()]
        page = report.write(f"Discontinuities of {Path(args.input).name}", summary, cloud=res.cloud, colour_by="set_id",
                            pictures=pictures)
        written["report"] = page
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=True)
    console.print(f"[bold]{len(s['sets'])}[/] joint sets from {s['segments']} segments; {s['selected_points']:,} selected "
                  f"points of {s['points']:,}; {s['overhang_points']:,} overhanging -> {Path(s['outputs']['sets_csv']).parent}")
    if s["sets"]:
        t = Table(title="joint sets (dip / dip direction of the mean plane)", title_justify="left")
        for col in ("set", "dip °", "dip dir °", "strike °", "κ", "α95 °", "segments", "points", "share", "spacing m", "trace m"):
            t.add_column(col, justify="right")

        def f(v, fmt):
            return "" if v is None or v != v else (fmt.format(v) if v != float("inf") else "inf")

        for r in s["sets"]:
            t.add_row(str(r["id"]), f(r["dip"], "{:.1f}"), f(r["dip_direction"], "{:.1f}"), f(r["strike"], "{:.1f}"),
                      f(r["kappa"], "{:.3g}"), f(r["alpha95"], "{:.2f}"), str(r["segments"]), f"{r['points']:,}",
                      f(r["share"], "{:.1%}"), f(r["spacing_mean"], "{:.2f}"), f(r["mean_trace_length"], "{:.2f}"))
        console.print(t)
    console.print("  ".join(f"{k} {v:.2f} s" for k, v in s["seconds"].items()))
