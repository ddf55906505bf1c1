"""``lidarfx render IN OUT.png``: a fast z-buffered picture of a point cloud (top, front or side view)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, check_picture_path, columns_of, emit_summary

EPILOG = """examples:
  lidarfx render als.laz als_z.png                                  # top view coloured by z, eye-dome lighting
  lidarfx render als.laz classes.png --by class --shading hillshade  # ASPRS classes, relief from the depth buffer
  lidarfx render facade.laz front.png --by rgb --view front --size 2400x1600
  lidarfx render feat.laz planarity.png --by planarity_r0.50 --range 0,1 --cmap magma
  lidarfx render face.laz face.png --by morphology --view side --title "rock face"
  lidarfx render scan.laz z.png --by z --point-size 2 --shading none --json -q

views: top (x East right, y North up, the highest point in front), front (seen
from the South: x right, z up, the smallest y in front), side (seen from the
East: y right, z up, the largest x in front).  Every point is a disc of
--point-size pixels radius (default: 1.5 x the median distance to the 4th
neighbour in the picture, 1 to 12) and each pixel shows the nearest point.
--by: an attribute (x, y, z or any numeric one) through --cmap over --range
(default its 2-98 % range, NaN grey) with a colour bar; class (ASPRS colours,
a legend of the classes present); rgb (the red/green/blue fields, 16- or 8-bit);
morphology (hue aspect, saturation slope; the cloud's normal_x/y/z or normals
computed at an automatic radius); set (joint sets, set_id).
--shading: edl (eye-dome lighting: outlines where something is in front),
hillshade (the depth buffer as a relief under a NW sun) or none.
OUT is a PNG of exactly --size pixels: the picture at one pixel per pixel, a
title, the key, a scale bar and, in the top view, a north arrow.  docs/render.md.
"""


def register(sub) -> None:
    p = sub.add_parser(
        "render",
        help="picture of a point cloud: z-buffered point splats, eye-dome lighting or hillshade, key and scale bar",
        description="Render a point cloud into a PNG: a top, front or side view of z-buffered point discs, coloured by "
                    "an attribute, the classes, the RGB fields or the morphology, shaded by eye-dome lighting or a "
                    "hillshade, with a colour bar or class legend, a scale bar and a north arrow.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("output", help="output picture (.png)")
    p.add_argument("--by", default="z", metavar="WHAT",
                   help="an attribute name (default %(default)s), class, rgb, morphology or set")
    p.add_argument("--view", choices=("top", "front", "side"), default="top",
                   help="top (from above), front (from the South) or side (from the East), default %(default)s")
    p.add_argument("--size", default="1600x1200", metavar="WxH",
                   help="picture size in pixels, default %(default)s (each 160 to 16000)")
    p.add_argument("--shading", choices=("edl", "hillshade", "none"), default="edl",
                   help="eye-dome lighting, hillshade of the depth buffer, or none; default %(default)s")
    p.add_argument("--point-size", type=float, default=None, metavar="PX",
                   help="disc radius of every point in pixels, 0 to 50 (0 = one pixel); default from the point spacing")
    p.add_argument("--range", default=None, metavar="LO,HI",
                   help="--by ATTRIBUTE: values at the ends of the colour map (default: 2nd-98th percentile)")
    p.add_argument("--cmap", default="viridis", help="--by ATTRIBUTE: matplotlib colour map, default %(default)s")
    p.add_argument("--title", default=None, help="title of the picture (default: the input file and --by)")
    add_columns(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def run(args) -> int:
    import os

    from .. import io
    from .._atomic import check_not_same_file, check_output_folder
    from ..colour import check_cmap
    from ..errors import LidarfxError
    from ..render.splat import (
        _PICTURE_LIMITS,
        _check_point_size,
        parse_size,
        render_picture,
    )
    from .colour import _parse_range

    # every option and the output before the cloud is read
    by = (args.by or "").strip()
    if not by:
        raise LidarfxError("--by needs an attribute name, class, rgb or morphology")
    size = parse_size(args.size, _PICTURE_LIMITS)
    _check_point_size(args.point_size)
    value_range = _parse_range(args.range)
    check_cmap(args.cmap)
    check_picture_path(args.output)
    check_not_same_file(args.input, args.output)
    folder = check_output_folder(args.output)
    if not os.access(folder, os.W_OK):
        raise LidarfxError(f"output folder is not writable: {folder}")
    progress = False if args.quiet else None

    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    title = args.title if args.title is not None else f"{Path(args.input).name}: {by}"
    _, summary = render_picture(cloud, args.output, by=by, view=args.view, size=size, shading=args.shading,
                                point_size=args.point_size, cmap=args.cmap, value_range=value_range, title=title,
                                progress=progress)
    summary = {"input": str(args.input), **summary}
    summary["seconds"] = {"read": round(t1 - t0, 3), **summary["seconds"]}
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console

    console = Console(stderr=True)
    f = s["frame"]
    console.print(f"[bold]{s['drawn']:,}[/] points, {s['view']} view by {s['by']} -> {s['output']} "
                  f"({s['size'][0]}x{s['size'][1]})")
    console.print(f"{f['metres_per_pixel']:.4g} m per pixel, points {s['point_size']:g} px "
                  f"({s['point_size_source']}), {s['covered']:.0%} of the picture covered, shading {s['shading']}")
    c = s["colour"]
    if c.get("range") is not None:
        lo, hi = c["range"]
        console.print(f"{c['attribute']} {lo:.6g} .. {hi:.6g} ({c['range_source']}) through {c['cmap']}; "
                      f"{c['no_value']:,} NaN points grey")
    elif c.get("classes"):
        console.print("classes: " + ", ".join(f"{r['code']} {r['name']} ({r['points']:,})" for r in c["classes"][:20]))
    console.print("  ".join(f"{k} {v:.2f} s" for k, v in s["seconds"].items()))
