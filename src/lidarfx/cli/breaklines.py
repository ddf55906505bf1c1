"""``lidarfx breaklines IN lines.geojson``: 3-D structure lines of the terrain (dike crests and toes, ditch edges)."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, check_picture_path, columns_of, emit_summary
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx breaklines als.laz lines.geojson                            # ground = class 2 (else the ground filter)
  lidarfx breaklines als.laz lines.geojson --dxf lines.dxf --csv --picture lines.png
  lidarfx breaklines lake.laz shore.geojson --classes 2,9             # ground and water points
  lidarfx breaklines als.laz lines.geojson --approximations rough.geojson   # 2-D approximations given
  lidarfx breaklines als.laz lines.geojson -r 2.5 --min-angle 10 --min-length 20 --json

steps: quadric curvature per ground point -> start points (high |k_max|, low
|k_min|; convex and concave apart) with their 2-D direction -> left and right
planar patches fitted with robust weights (off-terrain points lose their weight)
-> their intersection line with sigma from the adjustment -> grown forward and
backward while the intersection angle, the support and the fit hold -> parts
connected, short lines dropped, 3-D Douglas-Peucker.
outputs: GeoJSON LineString Z (CRS of the LAS header; properties form, mean angle,
mean sigma and per-vertex sigma_xy, sigma_z, angle), optional DXF 3-D polylines,
CSV (one row per line) + a per-vertex CSV with sigma and angle, a hillshade
picture.  docs/breaklines.md.
"""


def _classes(text: str):
    if text.strip().lower() in ("all", "none"):
        return None
    try:
        out = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--classes is a list of class codes like 2,9 (or all), got {text!r}") from None
    if not out or any(not 0 <= c <= 255 for c in out):
        raise argparse.ArgumentTypeError(f"--classes is a list of class codes 0-255 like 2,9, got {text!r}")
    return out


def register(sub) -> None:
    from ..breaklines import DEFAULTS as D

    p = sub.add_parser(
        "breaklines",
        help="3-D terrain structure lines (dike crests and toes, ditch and bank edges) with sigma per vertex",
        description="Extract structure lines (breaklines) from ALS ground points (after Mandlburger & Briese 2009). "
                    "Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("output", help="lines as GeoJSON (.geojson or .json)")
    p.add_argument("--dxf", default=None, metavar="DXF", help="also write the lines as DXF 3-D polylines")
    p.add_argument("--csv", nargs="?", const="", default=None, metavar="CSV",
                   help="also write the per-line table (default path: OUTPUT with .csv) and the per-vertex table (.vertices.csv)")
    p.add_argument("--picture", default=None, metavar="PNG", help="also draw the lines on a hillshade of the DTM")
    p.add_argument("--classes", type=_classes, default=list(D["classes"]), metavar="CODES",
                   help="ground classes, e.g. 2 or 2,9 (default 2; the ground filter runs when none is present; all = every point)")
    p.add_argument("--approximations", default=None, metavar="FILE",
                   help="2-D approximations of the lines (GeoJSON LineStrings or a shapefile of polylines)")
    p.add_argument("-r", "--radius", type=float, default=None, help="curvature radius, m (default: about 60 ground points)")
    p.add_argument("--min-curvature", type=float, default=None, help="start points: |k_max| at least this, 1/m (default: 6 robust sigma)")
    p.add_argument("--patch-length", type=float, default=None, help="patch length along the line, m (default 12 x the point spacing)")
    p.add_argument("--patch-width", type=float, default=None, help="largest patch width each side, m (default 5 x the point spacing)")
    p.add_argument("--gap", type=float, default=None, help="gap either side of the line, m (default 0.6 x the point spacing)")
    p.add_argument("--step", type=float, default=None, help="vertex spacing of the growing, m (default 4 x the point spacing)")
    p.add_argument("--min-angle", type=float, default=D["min_angle"], help="smallest intersection angle, degrees (default %(default)s)")
    p.add_argument("--min-points", type=int, default=D["min_points"], help="fewest points per patch (default %(default)s)")
    p.add_argument("--max-rms", type=float, default=None, help="largest patch RMS, m (default: 3 x the ground noise)")
    p.add_argument("--min-length", type=float, default=D["min_length"], help="shortest line kept, m (default %(default)s)")
    p.add_argument("--join", type=float, default=None, help="largest gap between parts that are connected, m (default 8 x the point spacing)")
    p.add_argument("--simplify", type=float, default=D["simplify"], help="Douglas-Peucker tolerance, m (default %(default)s)")
    add_columns(p)
    add_report_option(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def _read_approximations(path: str):
    from ..errors import LidarfxError

    pth = Path(path)
    if not pth.is_file():
        raise LidarfxError(f"approximations file not found: {path}")
    if pth.suffix.lower() == ".shp":
        try:
            import shapefile
        except ImportError:
            raise LidarfxError("reading a shapefile needs pyshp (pip install pyshp); or give GeoJSON") from None
        try:
            shapes = shapefile.Reader(str(pth)).shapes()
        except Exception as exc:  # pyshp raises many kinds
            raise LidarfxError(f"{path}: not a readable shapefile ({exc})") from None
        out = []
        for sh in shapes:
            parts = list(sh.parts) + [len(sh.points)]
            for a, b in zip(parts[:-1], parts[1:]):
                if b - a >= 2:
                    out.append([list(p) for p in sh.points[a:b]])
        return out
    from ..vector import read_geojson

    lines, _ = read_geojson(pth)
    return [ln.vertices for ln in lines]


def _vertex_rows(lines):
    rows = []
    for i, ln in enumerate(lines):
        for j, (x, y, z) in enumerate(ln.vertices):
            rows.append({"id": i, "vertex": j, "x": round(float(x), 3), "y": round(float(y), 3), "z": round(float(z), 3),
                         "sigma_xy": ln.attrs["sigma_xy"][j], "sigma_z": ln.attrs["sigma_z"][j], "angle": ln.attrs["angle"][j]})
    return rows


def run(args) -> int:
    from .. import io
    from .._atomic import check_output_folder
    from .._tables import write_csv_rows
    from ..breaklines import extract_breaklines
    from ..errors import LidarfxError
    from ..crs import cloud_crs
    from ..vector import export_lines

    out = Path(args.output)
    if out.suffix.lower() not in (".geojson", ".json"):
        raise LidarfxError(f"output {out}: lines are written as GeoJSON; give a path ending in .geojson")
    check_output_folder(out)
    if args.picture:
        check_picture_path(args.picture)
    csv_path = None
    if args.csv is not None:
        csv_path = Path(args.csv) if args.csv else out.with_suffix(".csv")
        check_output_folder(csv_path)
        check_output_folder(csv_path.with_suffix(".vertices.csv"))
    if args.dxf:
        check_output_folder(args.dxf)
    report = ReportJob(args)
    approx = _read_approximations(args.approximations) if args.approximations else None
    params = dict(radius=args.radius, min_curvature=args.min_curvature, patch_length=args.patch_length,
                  patch_width=args.patch_width, gap=args.gap, step=args.step, min_angle=args.min_angle,
                  min_points=args.min_points, max_rms=args.max_rms, min_length=args.min_length, join=args.join,
                  simplify=args.simplify, classes=args.classes, approximations=approx)
    progress = False if args.quiet else None
    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    res = extract_breaklines(cloud, progress=progress, **params)
    t2 = time.perf_counter()
    info = {k: v for k, v in res.meta.items() if isinstance(v, (int, float, str))}
    written = export_lines(res.lines, geojson=out, dxf=args.dxf, csv=csv_path, crs=cloud_crs(cloud), meta=info)
    if csv_path is not None:
        vpath = csv_path.with_suffix(".vertices.csv")
        write_csv_rows(vpath, _vertex_rows(res.lines), ["id", "vertex", "x", "y", "z", "sigma_xy", "sigma_z", "angle"])
        written["vertices_csv"] = str(vpath)
    picture = args.picture or (report.picture("breaklines.png") if report.wanted else None)
    if picture and res.ground.any():
        from ..ground.dtm import dtm
        from ..render import breakline_view

        from ..crs import unit_to_metre

        spacing = (1.0 / max(res.meta["density"], 1e-9)) ** 0.5  # m
        cell = float(f"{max(0.5, 2.0 * spacing):.2g}") / unit_to_metre(cloud)  # the DTM of an array: map units
        raster = dtm(cloud.xyz[res.ground], resolution=cell)
        breakline_view(raster, res.lines, picture,
                       title=f"{Path(args.input).name}: {len(res.lines)} structure lines, {res.meta['total_length']:,.0f} m")
        if args.picture:
            written["picture"] = str(args.picture)
    t3 = time.perf_counter()
    summary = {
        "input": str(args.input),
        "outputs": written,
        **{k: res.meta[k] for k in ("points", "ground_points", "start_points", "seeds_tried", "parts", "lines")},
        "total_length": round(res.meta["total_length"], 2),
        "noise": round(res.meta["noise"], 4),
        "lines_table": [{"id": i, "form": ln.attrs["form"], "length": round(ln.length_2d * (res.meta.get("unit_to_metre") or 1.0), 2),
                         "vertices": ln.n_vertices,
                         "mean_angle": ln.attrs["mean_angle"], "mean_sigma_xy": ln.attrs["mean_sigma_xy"],
                         "mean_sigma_z": ln.attrs["mean_sigma_z"]} for i, ln in enumerate(res.lines)],
        "parameters": res.meta["parameters"],
        "seconds": {"read": round(t1 - t0, 3), **res.meta["seconds"], "write": round(t3 - t2, 3)},
    }
    import numpy as np

    shown = cloud.copy()
    shown["breakline_ground"] = np.asarray(res.ground, dtype=np.uint8)
    page = report.write(f"Breaklines of {Path(args.input).name}", summary, cloud=shown, colour_by="z",
                        lines={"breaklines": res.lines},
                        pictures=[(picture, "structure lines over the shaded DTM")] if picture else ())
    if page:
        written["report"] = page
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=True)
    console.print(f"[bold]{s['lines']}[/] structure lines, {s['total_length']:,.1f} m, from {s['ground_points']:,} ground "
                  f"points (noise {s['noise']:.3f} m) -> {s['outputs'].get('geojson')}")
    if s["lines_table"]:
        t = Table(title="longest lines", title_justify="left")
        for col in ("id", "form", "length m", "vertices", "angle °", "σ xy m", "σ z m"):
            t.add_column(col, justify="right")
        for r in s["lines_table"][:20]:
            t.add_row(str(r["id"]), r["form"], f"{r['length']:.1f}", str(r["vertices"]), f"{r['mean_angle']:.1f}",
                      f"{r['mean_sigma_xy']:.3f}", f"{r['mean_sigma_z']:.3f}")
        console.print(t)
    console.print("  ".join(f"{k} {v:.2f} s" for k, v in s["seconds"].items()))
