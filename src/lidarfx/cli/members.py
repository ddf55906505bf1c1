"""``lidarfx members IN lines.geojson``: the members of a lattice tower as straight 3-D lines."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, add_line_outputs, columns_of, emit_summary, line_output_paths
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx members tower.laz members.geojson
  lidarfx members tower.laz members.geojson --dxf members.dxf --csv --picture members.png
  lidarfx members tower.laz members.geojson -r 0.5 --threshold 0.15   # wider profiles
  lidarfx members tower.laz members.geojson --cloud tower_members.laz  # points with member_id, member_label

steps: linear points (eigen features at the radius) -> clusters of points with
the same direction -> RANSAC line segments, collinear pieces merged over the
joints -> refitted on the points along each member -> ends grown over the
joints and placed where two members meet -> labels leg / brace / arm / other.
Each line is the centroid axis of the member's points (for an angle profile of
flange width w, (w/4)(e1 + e2) from the heel of the L); docs/tower.md.
outputs: GeoJSON LineString Z (CRS of the LAS header), optional DXF 3-D
polylines (layer MEMBER), CSV table (one row per member: length, support, RMS,
ends, label, inclination, azimuth, direction) and JSON with the vertices, a
picture (front, side and oblique views, members coloured by label).
"""


def register(sub) -> None:
    p = sub.add_parser(
        "members",
        help="lattice tower members (legs, braces, arms) as 3-D lines: GeoJSON / DXF / CSV",
        description="Vectorise the straight members of a lattice tower scanned by TLS. Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("output", help="members as GeoJSON (.geojson or .json)")
    # defaults (None): lidarfx.tower.members.DEFAULTS, filled in by check_parameters
    p.add_argument("-r", "--radius", type=float, default=None,
                   help="radius of the eigen features, larger than the profiles' width (m), default 0.4")
    p.add_argument("--threshold", type=float, default=None,
                   help="largest distance of a member's points from its line (m; about 0.8 x the widest flange), "
                        "default 0.1")
    p.add_argument("--min-linearity", type=float, default=None, help="linearity of a line point, default 0.8")
    p.add_argument("--max-angle", type=float, default=None,
                   help="largest angle between the directions of linked line points (degrees), default 15")
    p.add_argument("--min-points", type=int, default=None, help="fewest line points of a member, default 15")
    p.add_argument("--min-length", type=float, default=None, help="shortest member (m), default 0.5")
    p.add_argument("--link", type=float, default=None,
                   help="link distance of the clusters of line points (m; default: radius / 2, or the threshold)")
    p.add_argument("--max-gap", type=float, default=None,
                   help="largest gap between collinear pieces merged into one member, m (default: 6 x radius)")
    p.add_argument("--join", type=float, default=None,
                   help="how far a member reaches beyond its line points to grow and meet others, m (default: 4 x radius)")
    p.add_argument("--seed", type=int, default=0, help="seed of the RANSAC draws, default %(default)s")
    add_line_outputs(p, "members", picture="also draw the members over the points",
                     cloud="also write the cloud with member_id and member_label")
    add_columns(p)
    add_report_option(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import io
    from ..crs import cloud_crs, unit_to_metre
    from ..tower.members import check_parameters, vectorise_members
    from ..vector import export_lines

    given = {k: getattr(args, k) for k in ("radius", "threshold", "min_linearity", "max_angle", "min_points",
                                           "min_length", "link", "max_gap", "join", "seed") if getattr(args, k) is not None}
    prm = check_parameters(**given)
    paths = line_output_paths(args, "members")
    report = ReportJob(args)
    progress = False if args.quiet else None
    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    res = vectorise_members(cloud, prm["radius"], threshold=prm["threshold"], min_linearity=prm["min_linearity"],
                            max_angle=prm["max_angle"], min_points=prm["min_points"], min_length=prm["min_length"],
                            link=prm["link"], max_gap=prm["max_gap"], join=prm["join"], seed=prm["seed"],
                            progress=progress)
    t2 = time.perf_counter()
    meta = {k: v for k, v in res.meta.items() if k != "seconds"}
    meta["input"] = str(args.input)
    meta["line"] = "centroid axis of each member's points"
    written = export_lines(res.lines, geojson=paths["geojson"], dxf=paths["dxf"], csv=paths["csv"], json=paths["json"],
                           crs=cloud_crs(cloud), meta=meta)
    if paths["cloud"]:
        out = cloud.copy()
        out["member_id"] = res.member_id
        out["member_label"] = res.member_label
        io.write(out, paths["cloud"], progress=progress)
        written["cloud"] = paths["cloud"]
    picture = paths["picture"] or (report.picture("members.png") if report.wanted else None)
    if picture:
        from ..render.members import members_view

        members_view(cloud.xyz, res.lines, picture,
                     title=f"{Path(args.input).name}: {len(res.lines)} members, {res.meta['total_length']:,.1f} m "
                           f"(r = {res.meta['radius']:g} m)")
        if paths["picture"]:
            written["picture"] = paths["picture"]
    t3 = time.perf_counter()
    u = unit_to_metre(cloud)  # lengths of the summary in metres (docs/conventions.md)
    labels: dict[str, dict[str, float]] = {}
    for pl in res.lines:
        k = labels.setdefault(str(pl.attrs["label"]), {"members": 0, "length": 0.0})
        k["members"] += 1
        k["length"] = round(k["length"] + pl.length * u, 3)
    summary = {
        "input": str(args.input),
        "outputs": written,
        "points": len(cloud),
        "radius": res.meta["radius"],
        "line_points": res.meta["line_points"],
        "clusters": res.meta["clusters"],
        "segments": res.meta["segments"],
        "members": len(res.lines),
        "member_points": res.meta["member_points"],
        "nodes": res.meta["nodes"],
        "total_length": res.meta["total_length"],
        "labels": labels,
        "longest": [{"label": pl.attrs["label"], "length": round(pl.length * u, 3), "support": pl.support,
                     "rms": None if pl.rms != pl.rms else round(pl.rms * u, 4), "inclination": pl.attrs["inclination"]}
                    for pl in res.lines[:10]],
        "parameters": res.meta["parameters"],
        "seconds": {"read": round(t1 - t0, 3), **res.meta["seconds"], "write": round(t3 - t2, 3)},
    }
    if report.wanted:
        shown = cloud.copy()
        shown["member_id"] = res.member_id
        shown["member_label"] = res.member_label
        from ..tower.members import LABELS

        page = report.write(f"Tower members of {Path(args.input).name}", summary, cloud=shown, colour_by="member_label",
                            labels={"member_label": {v: k for k, v in LABELS.items()} | {-1: "none"}},
                            lines={"members": res.lines}, pictures=[(picture, "members")] if picture else ())
        written["report"] = page
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=True)
    console.print(f"[bold]{s['members']:,}[/] members, {s['total_length']:,.1f} m in total, from "
                  f"{s['line_points']:,} line points of {s['points']:,} (r = {s['radius']:g}) -> {s['outputs']['geojson']}")
    if s["labels"]:
        console.print("  ".join(f"{k} {v['members']} ({v['length']:,.1f} m)" for k, v in s["labels"].items()))
    if s["longest"]:
        t = Table(title=f"longest {len(s['longest'])} members", title_justify="left")
        for col in ("label", "length m", "points", "RMS m", "inclination °"):
            t.add_column(col, justify="left" if col == "label" else "right")
        for r in s["longest"]:
            t.add_row(r["label"], f"{r['length']:.2f}", f"{r['support']:,}", "" if r["rms"] is None else f"{r['rms']:.3f}",
                      f"{r['inclination']:.1f}")
        console.print(t)
    others = [v for k, v in s["outputs"].items() if k != "geojson"]
    if others:
        console.print("also: " + ", ".join(others))
    console.print("  ".join(f"{k} {v:.2f} s" for k, v in s["seconds"].items()))
