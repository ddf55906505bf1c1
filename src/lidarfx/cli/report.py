"""``lidarfx report IN OUTDIR``: an HTML page with the cloud's summary, a 3-D viewer and a picture."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, check_output_dir, columns_of, emit_summary
from ._report import command_line

EPILOG = """examples:
  lidarfx report scan.laz scan_report/                         # summary, 3-D view, picture
  lidarfx report scan.laz out/ --features eigen,plane -r 0.5   # with features to colour by and pick
  lidarfx report tls.laz out/ --attributes intensity,classification --max-points 2000000
  lidarfx report scan.laz out/ --json -q                       # JSON summary on stdout

OUTDIR/index.html is one file: open it in a browser (no network needed).  The
viewer carries --attributes (default: classification, the computed features,
then the other attributes, at most 16) and at most --max-points points (a
random subsample, --seed, beyond).  In the view: drag to rotate, right-drag
or shift-drag to pan, wheel to zoom, click a point for its values.
docs/report.md.
"""


def register(sub) -> None:
    p = sub.add_parser(
        "report",
        help="an HTML report with a 3-D viewer of the cloud (one file, opens offline)",
        description="Write OUTDIR/index.html: the cloud's summary, an interactive 3-D viewer (colour by any "
                    "attribute, pick points) and a picture, optionally with features computed first. Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.pts/.npy/.npz)")
    p.add_argument("outdir", help="output folder (created; index.html is written in it)")
    p.add_argument("-f", "--features", default=None,
                   help="compute these features first (groups or names as in lidarfx features, e.g. eigen,plane); "
                        "needs -r")
    p.add_argument("-r", "--radius", type=float, action="append",
                   help="neighbourhood radius of the features, m (repeat for multi-scale); "
                        "alone it computes the default features (eigen,plane,density)")
    p.add_argument("--attributes", default=None, metavar="A,B,C",
                   help="attributes carried by the viewer, in this order (default: classification, the computed "
                        "features, then the others, at most 16)")
    p.add_argument("--colour-by", default=None, metavar="NAME",
                   help="attribute shown first (default: classification if present, else z)")
    p.add_argument("--max-points", type=int, default=1_000_000,
                   help="points in the viewer at most (random subsample beyond), default %(default)s")
    p.add_argument("--seed", type=int, default=0, help="seed of the subsample, default %(default)s")
    p.add_argument("--title", default=None, help="page title (default: the input file name)")
    p.add_argument("--no-picture", action="store_true", help="leave out the picture (drawing it takes a few seconds)")
    add_columns(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def _picture(cloud, names: list[str], title: str, labels: dict) -> bytes:
    """A PNG of the cloud from the top (or the front when it is taller than wide), one panel
    per attribute of ``names`` (z when empty)."""
    import tempfile
    import warnings

    import numpy as np

    from ..cloud import PointCloud
    from ..render import feature_views

    shown = {n: cloud[n] for n in names} if names else {"z": cloud.z}
    ext = np.ptp(cloud.xyz, axis=0) if len(cloud) else np.ones(3)
    view = "top" if ext[2] <= max(ext[0], ext[1]) else "front"
    with tempfile.TemporaryDirectory(prefix="lidarfx-report-") as tmp:
        path = Path(tmp) / "views.png"
        with warnings.catch_warnings():  # a thin strip of a cloud leaves matplotlib no room for margins
            warnings.filterwarnings("ignore", message="Tight layout not applied")
            feature_views(PointCloud(cloud.xyz, shown), list(shown), path, view=view, title=title, labels=labels)
        return path.read_bytes()


def run(args) -> int:
    from .. import io
    from ..errors import LidarfxError, check_int
    from ..features import compute_features, resolve
    from ..features.api import radii_list
    from ..report import Report, viewer_attributes
    from ..report.sections import known_labels

    # every option before the cloud is read
    out = check_output_dir(args.outdir, files=("index.html",))  # the page is its one file
    check_int("--max-points", args.max_points, 1, 50_000_000)
    radii = radii_list(None, args.radius) if args.radius else []
    if args.features is not None and not radii:
        raise LidarfxError("--features needs a radius: -r 0.5 (repeat -r for several scales)")
    request = resolve(args.features) if radii else None
    wanted = [a.strip() for a in args.attributes.split(",")] if args.attributes else None
    if wanted is not None and not all(wanted):
        raise LidarfxError(f"--attributes must be comma-separated names, got {args.attributes!r}")
    progress = False if args.quiet else None

    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    if len(cloud) == 0:
        raise LidarfxError(f"{args.input}: the point cloud is empty")
    t1 = time.perf_counter()
    features: list[str] = []
    if request is not None:
        cloud = compute_features(cloud, args.features, radii=radii, seed=args.seed, progress=progress)
        features = list(cloud.meta.get("features", []))
    t2 = time.perf_counter()
    attributes = wanted if wanted is not None else viewer_attributes(cloud, first=features)
    name = Path(args.input).name
    report = Report(args.title or name, command=command_line(args), max_points=args.max_points, seed=args.seed)
    summary_items = {"input": str(args.input), "points": len(cloud)}
    if features:
        summary_items["features"] = ", ".join(features)
        summary_items["radii"] = ", ".join(f"{r:g}" for r in radii)
    report.add_summary(summary_items)
    labels = known_labels(cloud)
    report.add_cloud(cloud, attributes, labels=labels, colour_by=args.colour_by)
    t3 = time.perf_counter()
    picture_names: list[str] = []
    if not args.no_picture:
        first = report.cloud_summary["colour_by"]
        picture_names = [n for n in [first, *features[:2]] if n in cloud and n != "z"]
        picture_names = list(dict.fromkeys(picture_names))
        report.add_picture(_picture(cloud, picture_names, name, labels),
                           f"{name}: {', '.join(picture_names) or 'z'} (at most 200,000 points)")
    t4 = time.perf_counter()
    page = report.write(out)
    t5 = time.perf_counter()
    c = report.cloud_summary
    summary = {
        "input": str(args.input),
        "output": str(page),
        "points": len(cloud),
        "shown": c["shown"],
        "attributes": attributes,
        "left_out": c["left_out"],
        "features": features,
        "bytes": page.stat().st_size,
        "seconds": {"read": round(t1 - t0, 3), "features": round(t2 - t1, 3), "encode": round(t3 - t2, 3),
                    "picture": round(t4 - t3, 3), "write": round(t5 - t4, 3)},
    }
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    import sys

    sec = s["seconds"]
    shown = f"{s['shown']:,} of {s['points']:,}" if s["shown"] < s["points"] else f"{s['points']:,}"
    print(f"{shown} points, {len(s['attributes'])} attributes -> {s['output']} ({s['bytes'] / 1e6:.1f} MB)",
          file=sys.stderr)
    if s["left_out"]:
        print(f"not in the viewer: {', '.join(s['left_out'])}", file=sys.stderr)
    print(f"read {sec['read']:.2f} s, features {sec['features']:.2f} s, encode {sec['encode']:.2f} s, "
          f"picture {sec['picture']:.2f} s, write {sec['write']:.2f} s", file=sys.stderr)
