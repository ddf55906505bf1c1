"""``lidarfx info``: points, bounds, density, classes, returns, attributes and CRS of files."""
from __future__ import annotations

import argparse
from typing import Any

from .. import _json
from ._args import add_columns, read_clouds

EPILOG = """examples:
  lidarfx info scan.laz                  # a table per file
  lidarfx info a.laz b.las --json        # JSON: one object per file (a list for several)
  lidarfx info als.skops                 # a classifier model file (as: lidarfx classify info)

density: points per m² = n / number of occupied 1 m x 1 m cells (plan view), and
n / xy bounding-box area; feet-based CRSs are converted to metres.  When a file holds
virtual (return number 0, e.g. IGN class 66), withheld or synthetic points, the density
of the measured points alone is shown too: the points the classifier and its density
check use.
"""


def register(subparsers: Any) -> None:
    """Add the ``info`` sub-command."""
    p = subparsers.add_parser(
        "info",
        help="summarise point-cloud files (points, bounds, density, classes, CRS)",
        description="Summarise point-cloud files: points, bounds, density, classes with ASPRS names,\n"
        "returns, attributes, CRS and LAS header facts.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="LAS/LAZ, PLY, text or NumPy point clouds")
    add_columns(p)
    p.add_argument("--json", action="store_true", help="print JSON instead of tables")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the summary of every file; returns the exit code."""
    from ..io import info

    if any(str(f).lower().endswith(".skops") for f in args.files):  # a classifier model file
        from .classify import run_info

        if len(args.files) > 1:
            from ..errors import LidarfxError

            raise LidarfxError("give one model file at a time (or use: lidarfx classify info MODEL)")
        return run_info(argparse.Namespace(model=args.files[0], json=args.json))
    results = [{**info(c), "file": str(f)} for f, c in zip(args.files, read_clouds(args.files, args))]
    if args.json:
        print(_json.dumps(results[0] if len(results) == 1 else results, indent=2))
        return 0
    from rich.console import Console

    console = Console()
    for res in results:
        console.print(_table(res))
    return 0


def _fmt_xyz(values: list[float]) -> str:
    return "  ".join(f"{v:,.3f}" for v in values)


def _table(res: dict[str, Any]):
    from rich.table import Table

    title = res["file"] or "(cloud)"
    las = res.get("las")
    if las:
        title += f"  —  LAS {las['version']}, point format {las['point_format']}" + (
            ", compressed" if las["compressed"] else ""
        )
    table = Table(title=title, show_header=False, title_justify="left")
    table.add_column(style="bold")
    table.add_column()
    table.add_row("points", f"{res['points']:,}")
    if res["bounds"]:
        lo, hi = res["bounds"]["min"], res["bounds"]["max"]
        table.add_row("min x y z", _fmt_xyz(lo))
        table.add_row("max x y z", _fmt_xyz(hi))
        table.add_row("extent", _fmt_xyz([b - a for a, b in zip(lo, hi)]))
    d = res["density"]
    if d:
        bbox = f"{d['per_m2_bbox']:,.2f}" if d["per_m2_bbox"] is not None else "n/a"
        note = " (units assumed metres)" if d["unit_assumed"] else ""
        text = (f"{d['per_m2_occupied_cells']:,.2f} pts/m² over {d['occupied_cells']:,} occupied 1 m cells; "
                f"{bbox} pts/m² over the bounding box{note}")
        m = d.get("measured")
        if m:
            text += (f"\nmeasured points only ({m['points']:,}; no virtual / withheld / synthetic points): "
                     f"{m['per_m2_occupied_cells']:,.2f} pts/m² over {m['occupied_cells']:,} cells")
        table.add_row("density", text)
    elif res["bounds"] and (res.get("crs") or {}).get("geographic"):
        table.add_row("density", "n/a (geographic coordinates)")
    crs = res.get("crs")
    if crs:
        parts = [f"EPSG:{crs['epsg']}" if crs["epsg"] else "no EPSG code"]
        if crs["linear_unit"]:
            parts.append(f"unit {crs['linear_unit']} ({crs['unit_to_metre']:.10g} m)")
        parts.append("from " + " + ".join(crs["sources"]))
        if crs["wkt"]:
            wkt = crs["wkt"]
            parts.append(wkt if len(wkt) <= 80 else wkt[:77] + "...")
        table.add_row("CRS", "\n".join(parts))
    else:
        table.add_row("CRS", "none")
    if res["classes"]:
        n = max(res["points"], 1)
        lines = [
            f"{c['code']:>3}  {c['name'] or 'user defined / reserved':<26} {c['count']:>12,}  {100 * c['count'] / n:5.1f} %"
            for c in res["classes"]
        ]
        table.add_row("classes", "\n".join(lines))
    for name, hist in (res["returns"] or {}).items():
        table.add_row(name, "  ".join(f"{k}: {v:,}" for k, v in hist.items()))
    attrs = res["attributes"]
    table.add_row("attributes", ", ".join(f"{k} ({v})" for k, v in attrs.items()) or "none")
    if las:
        table.add_row("scales", "  ".join(f"{s:g}" for s in las["scales"]))
        table.add_row("offsets", "  ".join(f"{o:,.3f}" for o in las["offsets"]))
        vlrs = [f"{v['user_id']} {v['record_id']}: {v['description']}" for v in las["vlrs"] + las["evlrs"]]
        table.add_row("VLRs", "\n".join(vlrs) or "none")
    return table
