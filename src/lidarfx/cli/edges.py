"""``lidarfx edges IN lines.geojson``: 3-D building edge lines from the structure classes."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, add_line_outputs, columns_of, emit_summary, line_output_paths
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx edges roofs.laz lines.geojson                              # radius from the point spacing
  lidarfx edges roofs.laz lines.geojson --dxf lines.dxf --csv --picture lines.png
  lidarfx edges roofs.laz lines.geojson -r 1.5 --min-length 2
  lidarfx eigenclass roofs.laz struct.laz -r 1.5 && \\
    lidarfx edges struct.laz lines.geojson -r 1.5 --use-structure    # reuse the classes
  lidarfx edges roofs.laz lines.geojson --cloud candidates.laz       # points with structure, edge_candidate

steps: structure classes (lidarfx eigenclass) -> plane border, edge and corner
points -> connected components -> RANSAC line segments -> each segment placed
with the cloud around it (two planes intersected, or one plane's border) ->
collinear segments merged -> chained into 3-D polylines -> Douglas-Peucker.
outputs: GeoJSON LineString Z (CRS of the LAS header), optional DXF 3-D
polylines (layers EDGE, BORDER), CSV table (one row per line: length, support,
RMS, ends ...) and JSON with the vertices, a plan-view picture.
Lengths (-r, --threshold, --link, ...) are metres, converted for files in
feet; their defaults are multiples of the radius; docs/edges.md.
"""


def register(sub) -> None:
    p = sub.add_parser(
        "edges",
        help="3-D building edge lines (ridges, eaves, steps) as GeoJSON / DXF / CSV",
        description="Extract 3-D edge lines from border and edge points (see docs/edges.md). Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("output", help="lines as GeoJSON (.geojson or .json)")
    p.add_argument("-r", "--radius", type=float, default=None, help="radius of classification and refinement, m (default: from the point spacing)")
    add_line_outputs(p, "lines", picture="also draw the lines over the points (plan view)",
                     cloud="also write the cloud with structure and edge_candidate")
    p.add_argument("--use-structure", action="store_true", help="use the input's structure attribute (from lidarfx eigenclass)")
    p.add_argument("--references", default="trained", help="references of the classification (see lidarfx eigenclass)")
    p.add_argument("--labels", default="plane_border,edge,corner", help="structure labels of the candidate points, default %(default)s")
    p.add_argument("--min-length", type=float, default=None, help="shortest line kept, m (default: the radius)")
    p.add_argument("--min-points", type=int, default=8, help="fewest candidate points of a segment, default %(default)s")
    p.add_argument("--threshold", type=float, default=None, help="RANSAC inlier distance, m (default: 0.5 × radius)")
    p.add_argument("--link", type=float, default=None, help="link distance of the components, m (default: 0.5 × radius)")
    p.add_argument("--join", type=float, default=None, help="largest gap between segment ends that are chained, m (default: the radius)")
    p.add_argument("--simplify", type=float, default=None, help="Douglas-Peucker tolerance, m (default: 0.1 × radius)")
    p.add_argument("--no-refine", action="store_true", help="keep the band lines, do not place them with the cloud")
    p.add_argument("--keep-unrefined", action="store_true", help="keep segments whose placement failed")
    p.add_argument("--keep-cloud-border", action="store_true", help="keep lines along the cloud's outer boundary")
    p.add_argument("--seed", type=int, default=0, help="seed of the RANSAC draws, default %(default)s")
    add_columns(p)
    add_report_option(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import io
    from ..edges import extract_edges
    from ..crs import cloud_crs, unit_to_metre
    from ..vector import export_lines

    paths = line_output_paths(args, "lines")
    report = ReportJob(args)
    labels = [s.strip() for s in args.labels.split(",") if s.strip()]
    progress = False if args.quiet else None
    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    res = extract_edges(cloud, args.radius, labels=labels, use_structure=args.use_structure, references=args.references,
                        link=args.link, threshold=args.threshold, min_points=args.min_points, min_length=args.min_length,
                        refine=not args.no_refine, keep_unrefined=args.keep_unrefined,
                        keep_cloud_border=args.keep_cloud_border, join=args.join, simplify=args.simplify,
                        seed=args.seed, progress=progress)
    t2 = time.perf_counter()
    meta = {k: v for k, v in res.meta.items() if k != "seconds"}
    meta["input"] = str(args.input)
    written = export_lines(res.lines, geojson=paths["geojson"], dxf=paths["dxf"], csv=paths["csv"], json=paths["json"],
                           crs=cloud_crs(cloud), meta=meta)
    if paths["cloud"]:
        io.write(res.cloud, paths["cloud"], progress=progress)
        written["cloud"] = paths["cloud"]
    picture = paths["picture"] or (report.picture("lines.png") if report.wanted else None)
    if picture:
        from ..render import lines_view

        lines_view(res.cloud, res.lines, picture,
                   title=f"{Path(args.input).name}: {len(res.lines)} edge lines, r = {res.meta['radius']:g} m")
        if paths["picture"]:
            written["picture"] = paths["picture"]
    t3 = time.perf_counter()
    u = unit_to_metre(cloud)  # lengths of the summary in metres (docs/conventions.md)
    kinds: dict[str, dict[str, float]] = {}
    for pl in res.lines:
        k = kinds.setdefault(pl.kind, {"lines": 0, "length": 0.0})
        k["lines"] += 1
        k["length"] = round(k["length"] + pl.length * u, 3)
    summary = {
        "input": str(args.input),
        "outputs": written,
        "points": len(cloud),
        "radius": res.meta["radius"],
        "candidates": res.meta["candidates"],
        "components": res.meta["components"],
        "segments": res.meta["segments"],
        "refined_segments": res.meta["refined_segments"],
        "lines": len(res.lines),
        "total_length": res.meta["total_length"],
        "kinds": kinds,
        "longest": [{"kind": pl.kind, "length": round(pl.length * u, 3), "support": pl.support,
                     "rms": None if pl.rms != pl.rms else round(pl.rms * u, 4), "vertices": pl.n_vertices}
                    for pl in res.lines[:10]],
        "parameters": res.meta["parameters"],
        "seconds": {"read": round(t1 - t0, 3), **res.meta["seconds"], "write": round(t3 - t2, 3)},
    }
    page = report.write(f"Edge lines of {Path(args.input).name}", summary, cloud=res.cloud, colour_by="structure",
                        lines={"edge lines": res.lines}, pictures=[(picture, "edge lines over the points (plan view)")]
                        if picture else ())
    if page:
        written["report"] = page
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=True)
    console.print(f"[bold]{s['lines']:,}[/] lines, {s['total_length']:,.1f} m in total, from {s['candidates']:,} "
                  f"candidate points of {s['points']:,} (r = {s['radius']:g} m) -> {s['outputs']['geojson']}")
    if s["longest"]:
        t = Table(title=f"longest {len(s['longest'])} lines", title_justify="left")
        for col in ("kind", "length m", "points", "RMS m", "vertices"):
            t.add_column(col, justify="left" if col == "kind" else "right")
        for r in s["longest"]:
            t.add_row(r["kind"], f"{r['length']:.2f}", f"{r['support']:,}", "" if r["rms"] is None else f"{r['rms']:.3f}",
                      str(r["vertices"]))
        console.print(t)
    others = [v for k, v in s["outputs"].items() if k != "geojson"]
    if others:
        console.print("also: " + ", ".join(others))
    sec = s["seconds"]
    console.print("  ".join(f"{k} {v:.2f} s" for k, v in sec.items()))
