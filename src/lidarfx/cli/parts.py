"""``lidarfx parts IN OUTDIR``: bolts, rivets, insulators and corona rings of a lattice tower."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, check_output_dir, columns_of, emit_summary
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx parts tower.laz out/                          # bolts, insulators, corona rings
  lidarfx parts tower.laz out/ -r 0.04 --threshold 2.5  # narrow flanges: smaller planes, stricter standoff
  lidarfx parts tower.laz out/ --max-size 0.05 --no-compact --json
  lidarfx synth tower t.laz -p insulators=true && lidarfx parts t.laz out/ --truth t.laz.truth.json

steps: point spacing h -> compact parts (connected components under 6 h that
are not the main structure and at most --max-compact-size across) -> robust
local planes (MSAC within -r, in the cloud thinned to one point per cube of h)
-> points farther from their plane than --threshold x the noise -> dense groups
of them linked into clusters (two touching bolts cut apart, points on the
minority side dropped) -> bolts: clusters of --min-points with a size in
[--min-size, --max-size] -> kinds of the compact parts from the eigenvalues of
their covariance (insulator: long and round; corona ring: flat, round, hollow).
outputs in OUTDIR: parts.csv + parts.json (id, kind, centroid, size, principal
extents and eigenvalues, points, mean score, standoff, axis), cloud.laz
(part_id, part_kind, part_score), parts.png (front and side views).
docs/tower.md.
"""


def register(sub) -> None:
    from ..tower.parts import DEFAULTS as D

    p = sub.add_parser(
        "parts",
        help="small parts of a lattice tower: bolts and rivets, insulators, corona rings",
        description="Find the bolts and rivets (points standing off their local plane) and the compact parts "
                    "(insulators, corona rings) of a steel lattice tower scanned by TLS. "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("outdir", help="output folder (created if missing)")
    p.add_argument("-r", "--radius", type=float, default=D["radius"],
                   help="radius of the local planes, m: a few bolt sizes, below a flange's width (default %(default)s)")
    p.add_argument("--threshold", type=float, default=D["threshold"],
                   help="a point stands off its plane beyond this many times the noise (default %(default)s)")
    p.add_argument("--noise", type=float, default=None, help="noise of the surfaces, m (default: from the data)")
    p.add_argument("--min-points", type=int, default=D["min_points"], help="smallest part, points (default %(default)s)")
    p.add_argument("--min-size", type=float, default=D["min_size"], help="smallest bolt, m (default %(default)s)")
    p.add_argument("--max-size", type=float, default=D["max_size"], help="largest bolt, m (default %(default)s)")
    p.add_argument("--link", type=float, default=None,
                   help="link distance of the off-plane points, m (default: 2.5 x their spacing)")
    p.add_argument("--no-compact", action="store_true", help="bolts only: no insulators, corona rings, other compact parts")
    p.add_argument("--compact-link", type=float, default=None,
                   help="gap that separates a compact part from the structure, m (default: 6 x the point spacing)")
    p.add_argument("--max-compact-size", type=float, default=D["max_compact_size"],
                   help="largest compact part, m (default %(default)s)")
    p.add_argument("--truth", default=None, metavar="TRUTH.json",
                   help="truth of a synthetic tower (lidarfx synth tower OUT writes OUT.truth.json): recall and precision")
    p.add_argument("--cloud-format", choices=("laz", "las", "none"), default="laz", help="format of the output cloud (default %(default)s)")
    p.add_argument("--no-picture", action="store_true", help="do not draw parts.png")
    add_columns(p)
    add_report_option(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def _read_truth(path: str) -> dict:
    import json

    from ..errors import LidarfxError

    try:
        with open(path, encoding="utf-8") as fh:
            truth = json.load(fh)
    except (OSError, UnicodeDecodeError) as exc:
        raise LidarfxError(f"truth {path}: {getattr(exc, 'strerror', None) or exc}") from None
    except (ValueError, RecursionError) as exc:  # RecursionError: nested too deeply
        raise LidarfxError(f"truth {path}: not JSON ({exc})") from None
    if not isinstance(truth, dict) or not isinstance(truth.get("bolts"), list):
        raise LidarfxError(f"truth {path}: not the truth of a tower (no list of bolts); "
                           "lidarfx synth tower OUT writes OUT.truth.json")
    return truth


def run(args) -> int:
    from .. import io
    from .._atomic import check_not_same_file
    from ..tower.parts import KINDS, check_options, detect_small_parts, draw_picture, evaluate_parts, write_tables

    out = check_output_dir(args.outdir)
    report = ReportJob(args)
    params = dict(radius=args.radius, threshold=args.threshold, noise=args.noise, min_points=args.min_points,
                  min_size=args.min_size, max_size=args.max_size, link=args.link, compact=not args.no_compact,
                  compact_link=args.compact_link, max_compact_size=args.max_compact_size)
    check_options(**params)
    truth = _read_truth(args.truth) if args.truth is not None else None
    cloud_path = out / f"cloud.{args.cloud_format}" if args.cloud_format != "none" else None
    if cloud_path is not None:
        check_not_same_file(args.input, cloud_path)
    progress = False if args.quiet else None
    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    res = detect_small_parts(cloud, progress=progress, **params)
    t2 = time.perf_counter()
    evaluation = evaluate_parts(res, truth) if truth is not None else None
    out.mkdir(exist_ok=True)
    if cloud_path is not None:  # first: an attribute the format cannot store is refused before any table exists
        io.write(res.cloud, cloud_path, progress=progress)
    written = write_tables(res, out, meta={"input": str(args.input)}, evaluation=evaluation)
    if cloud_path is not None:
        written["cloud"] = str(cloud_path)
    if not args.no_picture:
        written["picture"] = draw_picture(res, out / "parts.png", title=Path(args.input).name)
    elif report.wanted:
        draw_picture(res, report.picture("parts.png"), title=Path(args.input).name)
    t3 = time.perf_counter()
    m = res.meta
    summary = {
        "input": str(args.input),
        "outputs": written,
        "points": m["points"],
        "counts": m["counts"],
        "part_points": m["part_points"],
        "spacing": round(m["spacing"], 5),
        "noise": round(m["noise"], 6),
        "off_plane_points": m["off_plane_points"],
        "parameters": m["parameters"],
        "seconds": {"read": round(t1 - t0, 3), **m["seconds"], "write": round(t3 - t2, 3)},
    }
    if evaluation is not None:
        summary["evaluation"] = {k: {kk: (round(vv, 4) if isinstance(vv, float) else vv) for kk, vv in v.items()}
                                 for k, v in evaluation.items()}
    if report.wanted:
        pictures = [] if not args.no_picture else [(report.picture("parts.png"), "parts")]
        written["report"] = report.write(f"Small parts of {Path(args.input).name}", summary, cloud=res.cloud,
                                         colour_by="part_kind", pictures=pictures,
                                         labels={"part_kind": {v: k for k, v in KINDS.items()} | {-1: "none"}})
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=True)
    c = s["counts"]
    console.print(f"[bold]{c['bolt']}[/] bolts, {c['insulator']} insulators, {c['corona_ring']} corona rings, "
                  f"{c['other']} other compact parts in {s['points']:,} points (spacing {s['spacing'] * 1000:.1f} mm, "
                  f"noise {s['noise'] * 1000:.2f} mm) -> {Path(s['outputs']['parts_csv']).parent}")
    if "evaluation" in s:
        t = Table(title="against the truth", title_justify="left")
        for col in ("kind", "true", "found", "matched", "recall", "precision", "mean offset mm"):
            t.add_column(col, justify="right")
        for k, v in s["evaluation"].items():
            t.add_row(k, str(v["true"]), str(v["found"]), str(v["matched"]), f"{v['recall']:.3f}",
                      f"{v['precision']:.3f}" if v["precision"] == v["precision"] else "-",
                      f"{v['mean_offset'] * 1000:.1f}" if v["mean_offset"] == v["mean_offset"] else "-")
        console.print(t)
    console.print("  ".join(f"{k} {v:.2f} s" for k, v in s["seconds"].items()))
