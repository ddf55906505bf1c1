"""``lidarfx section IN OUT --from x,y --to x,y --width 0.2``: the points of a slab, in profile coordinates."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, check_output, check_picture_path, columns_of, emit_summary, finite_numbers
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx section tower.laz cut.laz --from 0,-5 --to 0,5 --width 0.2 --image cut.png
  lidarfx section tower.laz cut.laz --from -4,0 --to 4,0 --width 0.1 --image cut.png --by classification
  lidarfx section tower_fx.laz cut.laz --from -4,0 --to 4,0 --width 0.2 --image cut.png --by plane_std
  lidarfx section tower.laz cut.laz --from -4,0 --to 4,0 --width 0.2 --image cut.png --by eigenvalue1 -r 0.1
  lidarfx section tower.laz cut.laz --from 0,0,20 --to 3,0,20 --normal 0,0,1 --width 0.1   # plan slice at 20 m
  lidarfx section scan.laz cut.csv --from 515380,4918350 --to 515395,4918375 --width 0.3 --json

the cut: by default the vertical plane through from -> to (z of the ends may be
left out; given, z of --from is the zero of h).  With --normal NX,NY,NZ the plane
through --from (x,y,z) with that normal; s runs along from -> to projected into
the plane.  Kept: |d| <= width/2 and 0 <= s <= length, faces and ends included.
OUT gets every attribute of the kept points plus section_s (along the section,
0 at --from), section_h (height: z, or up in an inclined plane) and section_d
(signed offset, > 0 on the right looking from --from to --to; along the normal
when given); LAS as float32 extra bytes.
--image: s to the right, h up, equal scales, coloured by --by (any numeric
attribute, x/y/z, or class); colour range the 2-98 % percentiles (or --range).
A --by that the file lacks but that is a feature (lidarfx features --list) is
computed for the slab points with neighbours from the whole cloud around them
(sphere of -r); --features adds more to OUT.  LAS/LAZ input is read in chunks
and only the points near the slab are kept.  docs/tower.md#section-projection.
Lengths are metres; files in feet are converted (--width, -r); --from, --to
are positions in the file's coordinates, and section_s/h/d are in its unit.
"""


_position = finite_numbers((2, 3), "a position x,y[,z]")
_normal = finite_numbers((3,), "a normal nx,ny,nz")


def register(sub) -> None:
    p = sub.add_parser(
        "section",
        help="section projection: the points of a slab around a cut plane with along / height / offset, and a picture",
        description="Cut a slab out of a point cloud along a line (vertical or inclined cut plane) and project it: "
                    "section_s, section_h, section_d per point, and a profile picture coloured by an attribute. "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz read in chunks; .ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("output", help="the section's points (format from the extension)")
    p.add_argument("--from", dest="start", type=_position, required=True, metavar="X,Y[,Z]", help="start of the section line")
    p.add_argument("--to", dest="end", type=_position, required=True, metavar="X,Y[,Z]", help="end of the section line")
    p.add_argument("--width", type=float, required=True, help="slab width across the cut plane (m); half on each side")
    p.add_argument("--normal", type=_normal, default=None, metavar="NX,NY,NZ",
                   help="normal of an inclined cut plane through --from (default: the vertical plane through the line)")
    p.add_argument("--image", "--picture", dest="image", default=None, metavar="PNG", help="also draw the profile into this PNG")
    p.add_argument("--by", default="section_d", metavar="ATTRIBUTE",
                   help="colour of the picture: a numeric attribute, x/y/z, class, or a feature name (default %(default)s)")
    p.add_argument("--cmap", default="viridis", help="matplotlib colour map of the picture (default %(default)s)")
    p.add_argument("--range", default=None, metavar="LO,HI", help="values at the ends of the colour map (default: 2nd-98th percentile)")
    p.add_argument("--features", default=None, metavar="LIST",
                   help="also compute these features (groups or names, as lidarfx features) for the slab points")
    p.add_argument("-r", "--radius", type=float, default=None, help="sphere radius of computed features (m)")
    add_columns(p)
    add_report_option(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import io
    from .._atomic import check_not_same_file
    from ..colour import check_cmap
    from ..errors import LidarfxError, check_number
    from ..features import compute_features, resolve
    from ..features.api import MIN_RADIUS
    from ..section import ATTRIBUTES, cut_section, read_near_section, section_frame, slab_indices
    from .colour import _parse_range

    from ..crs import file_unit_to_metre

    unit = file_unit_to_metre(args.input)  # --width and -r are metres, --from / --to coordinates
    frame = section_frame(args.start, args.end, args.width, args.normal, unit=unit)
    check_output(args.input, args.output)
    report = ReportJob(args)
    by = args.by.strip() if args.by else ""
    if not by:
        raise LidarfxError("--by needs an attribute name, x, y, z or class")
    value_range = _parse_range(args.range)
    if args.image:
        check_picture_path(args.image)
        check_not_same_file(args.input, args.image)
        check_cmap(args.cmap)
    features = list(resolve(args.features).names) if args.features else []
    by_feature = None
    if args.image and by not in ATTRIBUTES and by not in ("x", "y", "z", "class", "classification"):
        try:
            by_feature = resolve([by]).names
        except LidarfxError:
            by_feature = None  # an attribute of the file, checked once it is read
    radius = None
    if args.radius is not None:
        radius = check_number("radius", args.radius, MIN_RADIUS, 1e6)
    if features and radius is None:
        raise LidarfxError("--features needs -r RADIUS (the sphere of the neighbourhoods, m)")
    progress = False if args.quiet else None

    t0 = time.perf_counter()
    margin = radius if radius is not None else 0.0  # m, as the width
    near = read_near_section(args.input, frame, margin, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    compute = list(features)
    if by_feature and by not in near:
        if radius is None:
            raise LidarfxError(f"--by {by}: the file has no {by!r}; it is a feature: give -r RADIUS to compute it")
        compute += [n for n in by_feature if n not in compute]
    cut = cut_section(near, frame)
    if not len(cut):
        raise LidarfxError(f"no point lies in the section (length {frame.length * unit:.3f} m, width {args.width:g} m); "
                           f"check --from / --to against `lidarfx info {args.input}`")
    if compute:
        import numpy as np

        inside = np.zeros(len(near), bool)
        inside[slab_indices(near.xyz, frame)] = True
        fx = compute_features(near, compute, radius=radius, query=inside, progress=progress)
        cut.update({n: fx[n] for n in compute})
    if args.image and by not in cut and by not in ("x", "y", "z", "class", "classification"):
        have = ", ".join(["x", "y", "z", "class", *cut.names])
        raise LidarfxError(f"--by {by}: no such attribute; the section has: {have}")
    t2 = time.perf_counter()
    io.write(cut, args.output, progress=progress)
    t3 = time.perf_counter()
    if args.image:
        from ..render.section import section_view

        try:
            section_view(cut, args.image, by=by, cmap=args.cmap, value_range=value_range,
                         title=f"{Path(args.input).name}: section coloured by {by}")
        except BaseException:  # no output is left behind after an error
            Path(args.output).unlink(missing_ok=True)
            raise
    t4 = time.perf_counter()
    summary = {
        "input": str(args.input),
        "output": str(args.output),
        "image": args.image,
        "points": len(cut),
        "points_read_near": len(near),
        "frame": frame.describe(),
        "by": by if args.image else None,
        "features": compute,
        "radius": radius,
        "seconds": {"read": round(t1 - t0, 3), "section": round(t2 - t1, 3), "write": round(t3 - t2, 3),
                    "image": round(t4 - t3, 3)},
    }
    page = report.write(f"Section of {Path(args.input).name}", summary, cloud=cut,
                        colour_by=by if by in cut else ("classification" if by == "class" else None),
                        pictures=[(args.image, f"section coloured by {by}")] if args.image else ())
    if page:
        summary["report"] = page
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console

    console = Console(stderr=True)
    f = s["frame"]
    console.print(f"[bold]{s['points']:,}[/] points in the {'vertical' if f['vertical'] else 'inclined'} section, "
                  f"{f['length']:.2f} m long, {f['width']:g} m wide -> {s['output']}")
    if s["features"]:
        console.print(f"computed: {', '.join(s['features'])} (r = {s['radius']:g} m)")
    if s["image"]:
        console.print(f"picture: {s['image']} (coloured by {s['by']})")
    sec = s["seconds"]
    console.print("  ".join(f"{k} {v:.2f} s" for k, v in sec.items()))
