"""``lidarfx colour IN OUT``: RGB from morphology (aspect, slope, shading), an attribute, joint sets or classes."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, check_picture_path, emit_summary, numbers, read_input, xyz
from ._tiles import TILE_HELP, add_tile_options, inputs_of, run_tiles, wants_tiles

EPILOG = """examples:
  lidarfx colour face.laz face_rgb.laz                          # morphology: hue aspect, saturation slope, value shading
  lidarfx colour face.laz face_rgb.laz --sun-azimuth 200 --sun-altitude 50 --picture face.png
  lidarfx colour scan.laz rgb.laz -r 0.3 --scanner 12.5,-3.0,1.7  # normals in 0.3 m spheres
  lidarfx colour feat.laz rgb.laz --by planarity --cmap magma --range 0,1
  lidarfx colour dtm.laz rgb.laz --by z --cmap terrain --range -5,120
  lidarfx colour joints.laz rgb.laz --by set --picture sets.png  # set_id of the discontinuities command
  lidarfx colour als.laz rgb.laz --by class --view top --picture classes.png
  lidarfx colour tiles/ rgb/ -r 0.3 --chunk-size 100             # a folder of tiles, in chunks

--by morphology (default), with the normal n flipped up (n_z >= 0):
  hue        = aspect / 360, aspect = atan2(n_x, n_y) mod 360 (clockwise from North)
  saturation = slope / 90,   slope  = arccos(n_z)
  value      = max(0, n . L), L = (cos alt sin az, cos alt cos az, sin alt): the sun
Normals are the cloud's normal_x/y/z when present, else computed in spheres of
--radius (default: max(0.10, 2.5 x the median distance to the 8th neighbour)).
Points without a normal are black.  --by ATTRIBUTE maps any numeric attribute
(x, y, z included) through --cmap over --range (default its 2-98 % range; NaN
grey); --by set colours set_id (-1 grey), --by class the ASPRS classification.
OUT gets red/green/blue (uint16, 0-65535), every other attribute unchanged.
docs/colour.md.

In chunks, what the in-memory run takes from the whole cloud is settled first:
--by ATTRIBUTE without --range reads the inputs once more for the exact 2-98 %
range; --by morphology needs --radius unless the inputs carry normals; no
--picture (it draws every point in memory).

""" + TILE_HELP


def register(sub) -> None:
    p = sub.add_parser(
        "colour",
        help="RGB colours from morphology (aspect, slope, sun shading), an attribute, joint sets or classes",
        description="Write RGB colours (LAS red/green/blue) from the surface morphology in HSV, a numeric attribute, "
                    "the joint sets or the classes, and optionally a picture. Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("output", help="output point cloud (format from the extension)")
    p.add_argument("--by", default="morphology", metavar="WHAT",
                   help="morphology (default), set, class, or the name of a numeric attribute")
    p.add_argument("-r", "--radius", type=float, default=None,
                   help="morphology: radius of the normals (m) when the cloud has none; default from the point spacing")
    p.add_argument("--scanner", type=xyz, default=None, help="morphology: scanner position x,y,z for the normals (TLS)")
    p.add_argument("--sun-azimuth", type=float, default=315.0,
                   help="morphology: sun azimuth, degrees clockwise from North, default %(default)s")
    p.add_argument("--sun-altitude", type=float, default=45.0,
                   help="morphology: sun altitude above the horizon, 0-90 degrees, default %(default)s")
    p.add_argument("--cmap", default="viridis", help="--by ATTRIBUTE: matplotlib colour map, default %(default)s")
    p.add_argument("--range", default=None, metavar="LO,HI",
                   help="--by ATTRIBUTE: values mapped to the ends of the colour map (default: 2nd-98th percentile)")
    p.add_argument("--picture", default=None, metavar="PNG", help="also draw the coloured points into this PNG")
    p.add_argument("--view", choices=("auto", "top", "front", "side"), default="auto",
                   help="view of the picture: top, front (from the South), side (from the East) or auto "
                        "(along the smallest-variance axis), default %(default)s")
    add_columns(p)
    add_tile_options(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def _parse_range(text: str | None):
    from ..colour import check_value_range
    from ..errors import LidarfxError

    if text is None:
        return None
    try:
        vals = numbers(text, 2, "--range")
    except ValueError as exc:
        raise LidarfxError(f"{exc} (LO,HI)") from None
    return check_value_range(vals)


def run(args) -> int:
    from .. import io
    from ..colour import check_cmap, check_radius, check_sun, colour_cloud, colour_picture
    from ..errors import LidarfxError

    # every option before the cloud is read
    if not args.by or not args.by.strip():
        raise LidarfxError("--by needs morphology, set, class or an attribute name")
    by = args.by.strip()
    check_sun(args.sun_azimuth, args.sun_altitude)
    check_cmap(args.cmap)
    value_range = _parse_range(args.range)
    check_radius(args.radius)
    if args.picture:
        check_picture_path(args.picture)
        from .._atomic import check_not_same_file

        check_not_same_file(args.input, args.picture)
    if wants_tiles(args, "colour", by_size=by != "morphology" or args.radius is not None):
        from ..tiles.proc_colour import colour_options

        if args.picture:
            raise LidarfxError("--picture draws every point in memory; leave it out in chunks, or use --chunk-size 0")
        return run_tiles(args, "colour", colour_options(
            inputs_of(args.input), by, radius=args.radius, scanner=args.scanner, sun_azimuth=args.sun_azimuth,
            sun_altitude=args.sun_altitude, cmap=args.cmap, value_range=value_range))
    t0 = time.perf_counter()
    cloud, progress = read_input(args)
    t1 = time.perf_counter()
    out = colour_cloud(cloud, by, radius=args.radius, scanner=args.scanner, sun_azimuth=args.sun_azimuth,
                       sun_altitude=args.sun_altitude, cmap=args.cmap, value_range=value_range, progress=progress)
    t2 = time.perf_counter()
    io.write(out, args.output, progress=progress)
    t3 = time.perf_counter()
    if args.picture:
        import numpy as np

        rgb = np.column_stack([out["red"], out["green"], out["blue"]])
        colour_picture(out, rgb, args.picture, view=args.view, title=f"{Path(args.input).name}: colour by {by}")
    t4 = time.perf_counter()
    summary = {
        "input": str(args.input),
        "output": str(args.output),
        "picture": args.picture,
        "points": len(out),
        "colour": out.meta["colour"],
        "seconds": {"read": round(t1 - t0, 3), "colour": round(t2 - t1, 3), "write": round(t3 - t2, 3),
                    "picture": round(t4 - t3, 3)},
    }
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=True)
    c = s["colour"]
    by = c["by"]
    console.print(f"[bold]{s['points']:,}[/] points coloured by {by} -> {s['output']}")
    if by == "morphology":
        src = "from the cloud's normal_x/y/z" if c["normals"] == "attributes" else \
            f"computed, radius {c['radius']:.3f} m ({c['radius_source']})"
        console.print(f"normals {src}; sun azimuth {c['sun_azimuth']:g}°, altitude {c['sun_altitude']:g}°; "
                      f"{c['no_normal']:,} points without a normal (black)")
    elif by in ("set", "class"):
        rows = c["sets"] if by == "set" else c["classes"]
        t = Table(title="sets" if by == "set" else "classes", title_justify="left")
        for col in (("set",) if by == "set" else ("code", "name")) + ("points", "colour"):
            t.add_column(col, justify="left" if col in ("name", "colour") else "right")
        for r in rows[:40]:
            head = (str(r["id"]) if r["id"] >= 0 else "none",) if by == "set" else (str(r["code"]), r["name"])
            t.add_row(*head, f"{r['points']:,}", f"[{r['colour']}]■[/] {r['colour']}")
        console.print(t)
    else:
        lo, hi = c["range"]
        console.print(f"{c['attribute']} {lo:.6g} .. {hi:.6g} ({c['range_source']}) through {c['cmap']}; "
                      f"{c['no_value']:,} NaN points grey")
    if s["picture"]:
        console.print(f"picture: {s['picture']}")
    sec = s["seconds"]
    console.print(f"read {sec['read']:.2f} s, colour {sec['colour']:.2f} s, write {sec['write']:.2f} s"
                  + (f", picture {sec['picture']:.2f} s" if s["picture"] else ""))
