"""``lidarfx powerlines IN OUTDIR``: wires, catenaries, spans, pylons, clearances, load cases."""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from ._args import add_columns, check_output_dir, columns_of, emit_summary
from ._report import ReportJob, add_report_option

EPILOG = """examples:
  lidarfx powerlines corridor.laz out/                        # ground = class 2 (else the ground filter)
  lidarfx powerlines corridor.laz out/ --load-case temp=80 --load-case ice=10,temp=-5 --conductor 264-AL1/34-ST1A
  lidarfx powerlines corridor.laz out/ --load-case wind_speed=30 --survey-temp 15 --json
  lidarfx powerlines corridor.laz out/ -r 2 --min-height 6 --cloud-format las
  lidarfx powerlines --conductors                             # the built-in conductor types

steps: height above ground -> linear, near-horizontal points -> clusters cut at
supports (slope drops) -> pieces joined across gaps -> held by pylons or the data
edge, hanging free -> grown along their curves -> bundles split into sub-conductors
-> one robust catenary z(s) = c + a*cosh((s - s0)/a) per conductor and span.
outputs in OUTDIR: cloud.laz (wires 14, pylons 15, conductor_id / span_id /
pylon_id extra bytes), wires.csv + wires.json (a, s0, c, RMSE, sag, length, lowest
point, clearances), wires.geojson + wires.dxf (catenaries as 3-D polylines, a vertex
every 0.5 m), load_cases.csv with --load-case, wires.png.  docs/powerlines.md.
load cases: temp=C, ice=MM (radial), ice_load=N/m, wind=PA, wind_speed=M/S,
combined with commas; docs/powerline-loads.md.
"""


def register(sub) -> None:
    p = sub.add_parser(
        "powerlines",
        help="power-line wires: catenaries per conductor and span, sag, clearances, load cases",
        description="Extract the wires of an ALS power-line corridor and fit one catenary per conductor and span "
                    "(see docs/powerlines.md). Lengths are metres; files in feet are converted.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("input", nargs="?", help="input point cloud (.las/.laz/.ply/.xyz/.txt/.csv/.npz)")
    p.add_argument("outdir", nargs="?", help="output folder (created if missing)")
    p.add_argument("-r", "--radius", type=float, default=None, help="neighbourhood radius of the linearity test, m (default 1.5)")
    p.add_argument("--min-height", type=float, default=None, help="lowest wire height above ground, m (default 4)")
    p.add_argument("--linearity", type=float, default=None, help="lowest linearity of a wire point (default 0.7)")
    p.add_argument("--min-length", type=float, default=None, help="shortest wire run, m (default 30)")
    p.add_argument("--max-gap", type=float, default=None, help="largest gap in the returns along a wire, m (default 40)")
    p.add_argument("--pylon-radius", type=float, default=None, help="reach of a pylon around a wire end, m (default 10)")
    p.add_argument("--tube", type=float, default=None, help="radius of a wire's tube of points, m (default 0.5)")
    p.add_argument("--step", type=float, default=0.5, help="vertex spacing of the exported curves, m (default %(default)s)")
    p.add_argument("--load-case", action="append", default=[], metavar="SPEC",
                   help="predict each span under this load case (repeatable), e.g. temp=80 or ice=10,temp=-5")
    p.add_argument("--conductor", default="264-AL1/34-ST1A",
                   help="conductor type of the load cases: a built-in name or mass=..,area=..,diameter=..,modulus=..,alpha=.. "
                        "(default %(default)s)")
    p.add_argument("--survey-temp", type=float, default=10.0, help="conductor temperature at the survey, °C (default %(default)s)")
    p.add_argument("--conductors", action="store_true", help="list the built-in conductor types and exit")
    p.add_argument("--cloud-format", choices=("laz", "las", "none"), default="laz", help="format of the classified cloud (default %(default)s)")
    p.add_argument("--no-picture", action="store_true", help="do not draw wires.png")
    add_columns(p)
    add_report_option(p)
    p.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars, no summary")
    p.set_defaults(func=run)


def _list_conductors(args) -> int:
    from ..powerlines.loads import CONDUCTORS

    rows = [{"name": c.name, "diameter_mm": round(c.diameter * 1000, 2), "area_mm2": c.area, "mass_kg_m": c.mass,
             "modulus_N_mm2": c.modulus, "alpha_per_K": c.alpha, "rated_strength_kN": c.rated_strength, "source": c.source}
            for c in CONDUCTORS.values()]
    if args.json:
        emit_summary(args, {"conductors": rows}, lambda s: None)
        return 0
    from rich.console import Console
    from rich.table import Table

    t = Table(title="built-in conductor types")
    for col in ("name", "d mm", "A mm²", "kg/m", "E N/mm²", "α 1/K", "RTS kN"):
        t.add_column(col, justify="left" if col == "name" else "right")
    for r in rows:
        t.add_row(r["name"], f"{r['diameter_mm']:g}", f"{r['area_mm2']:g}", f"{r['mass_kg_m']:g}", f"{r['modulus_N_mm2']:g}",
                  f"{r['alpha_per_K']:.3g}", "" if r["rated_strength_kN"] is None else f"{r['rated_strength_kN']:g}")
    Console().print(t)
    return 0


def run(args) -> int:
    from .. import io
    from .._atomic import check_not_same_file
    from ..errors import LidarfxError
    from ..crs import cloud_crs
    from ..powerlines import extract_powerlines
    from ..powerlines.loads import conductor, parse_load_case
    from ..powerlines.output import load_case_records, write_tables

    if args.conductors:
        return _list_conductors(args)
    if not args.input or not args.outdir:
        raise LidarfxError("powerlines needs IN and OUTDIR (or --conductors)")
    if not (args.step > 0 and args.step < 1e4):
        raise LidarfxError(f"--step must be a positive length, got {args.step!r}")
    cases = [parse_load_case(c) for c in args.load_case]  # refuse bad specs before any work
    cond = conductor(args.conductor) if cases else None
    out = check_output_dir(args.outdir)
    report = ReportJob(args)
    cloud_path = out / f"cloud.{args.cloud_format}" if args.cloud_format != "none" else None
    if cloud_path is not None:
        check_not_same_file(args.input, cloud_path)
    params = {k: v for k, v in (("radius", args.radius), ("min_height", args.min_height), ("linearity", args.linearity),
                                ("min_length", args.min_length), ("max_gap", args.max_gap),
                                ("pylon_radius", args.pylon_radius), ("tube", args.tube), ("step", args.step))
              if v is not None}
    progress = False if args.quiet else None
    t0 = time.perf_counter()
    cloud = io.read(args.input, columns=columns_of(args), progress=progress)
    t1 = time.perf_counter()
    res = extract_powerlines(cloud, progress=progress, **params)
    t2 = time.perf_counter()
    lc = load_case_records(res, args.load_case, cond, survey_temperature=args.survey_temp, step=args.step) if cases else []
    out.mkdir(exist_ok=True)
    if cloud_path is not None:  # first: an attribute the format cannot store is refused before any table exists
        io.write(res.cloud, cloud_path, progress=progress)
    written = write_tables(res, out, crs=cloud_crs(cloud), step=args.step, load_cases=lc,
                           meta={"input": str(args.input), "conductor": cond.name if cond else None,
                                 "survey_temperature": args.survey_temp if cases else None})
    if cloud_path is not None:
        written["cloud"] = str(cloud_path)
    picture = out / "wires.png" if not args.no_picture else (report.picture("wires.png") if report.wanted else None)
    if picture:
        from ..render import powerline_view

        powerline_view(res, picture, title=f"{Path(args.input).name}: {len(res.conductors)} conductors, "
                       f"{len(res.spans)} spans, {len(res.pylons)} pylons")
        if not args.no_picture:
            written["picture"] = str(picture)
    t3 = time.perf_counter()
    import math

    rmse = sorted(cd.measures["rmse"] for cd in res.conductors if math.isfinite(cd.measures["rmse"]))
    summary = {
        "input": str(args.input),
        "outputs": written,
        "points": len(cloud),
        **{k: res.meta[k] for k in ("candidates", "wire_points", "pylon_points", "conductors", "bundles", "spans", "pylons",
                                    "ground_source")},
        "median_rmse": round(rmse[len(rmse) // 2], 4) if rmse else None,
        "conductor_table": [{"id": cd.id, "span": cd.span_id, "bundle": f"{cd.bundle_id}.{cd.bundle_index}",
                             "points": int(len(cd.index)), "length": round(cd.length, 2),
                             "a": None if cd.measures["a"] is None else round(cd.measures["a"], 1),
                             "rmse": round(cd.measures["rmse"], 4), "sag": round(cd.measures["sag"], 3),
                             "ground_clearance": round(cd.measures["ground_clearance"], 2),
                             "object_clearance": None if cd.measures["object_clearance"] is None
                             else round(cd.measures["object_clearance"], 2)} for cd in res.conductors],
        "load_cases": [{k: r.get(k) for k in ("conductor_id", "load_case", "sag", "vertical_sag", "swing_deg",
                                              "ground_clearance", "object_clearance")} for r in lc],
        "parameters": res.meta["parameters"],
        "seconds": {"read": round(t1 - t0, 3), **res.meta["seconds"], "write": round(t3 - t2, 3)},
    }
    if report.wanted:
        from ..powerlines.output import conductor_polylines

        page = report.write(f"Power lines of {Path(args.input).name}", summary, cloud=res.cloud,
                            colour_by="classification", lines={"catenaries": conductor_polylines(res, args.step)},
                            pictures=[(picture, "wires, catenaries and profiles")] if picture else ())
        written["report"] = page
    emit_summary(args, summary, _print_summary)
    return 0


def _print_summary(s: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(stderr=True)
    console.print(f"[bold]{s['conductors']}[/] conductors in {s['spans']} spans, {s['pylons']} pylons; "
                  f"{s['wire_points']:,} wire points of {s['points']:,}; median RMSE {s['median_rmse']} m -> "
                  f"{Path(s['outputs']['csv']).parent}")
    if s["conductor_table"]:
        t = Table(title="conductors", title_justify="left")
        for col in ("id", "span", "bundle", "points", "length m", "a m", "RMSE m", "sag m", "ground m", "objects m"):
            t.add_column(col, justify="right")
        for r in s["conductor_table"][:40]:
            t.add_row(str(r["id"]), str(r["span"]), r["bundle"], f"{r['points']:,}", f"{r['length']:.1f}",
                      "" if r["a"] is None else f"{r['a']:.0f}", f"{r['rmse']:.3f}", f"{r['sag']:.2f}",
                      f"{r['ground_clearance']:.1f}", "" if r["object_clearance"] is None else f"{r['object_clearance']:.1f}")
        console.print(t)
    if s["load_cases"]:
        t = Table(title="load cases", title_justify="left")
        for col in ("conductor", "load case", "sag m", "vertical sag m", "swing °", "ground m", "objects m"):
            t.add_column(col, justify="right")
        for r in s["load_cases"][:60]:
            t.add_row(str(r["conductor_id"]), str(r["load_case"]), *("" if r.get(k) is None else f"{r[k]:.2f}"
                      for k in ("sag", "vertical_sag", "swing_deg", "ground_clearance", "object_clearance")))
        console.print(t)
    console.print("  ".join(f"{k} {v:.2f} s" for k, v in s["seconds"].items()))
