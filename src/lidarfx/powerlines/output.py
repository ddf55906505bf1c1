"""Tables, vector files, load cases and the classified cloud of :func:`extract_powerlines`.

Files in the output folder (docs/powerlines.md §3):

``wires.csv`` / ``wires.json``
    one row / record per conductor and span (attachment points, a, s0, c, RMSE,
    points, sag and where, conductor length, lowest point, clearances and where);
    the JSON adds the pylons, the spans, the parameters and the load cases.
``wires.geojson`` / ``wires.dxf``
    the catenaries as 3-D polylines, a vertex every ``step`` (0.5 m) of horizontal
    distance (GeoJSON LineString Z with the cloud's CRS; DXF layer WIRE), through
    :func:`lidarfx.vector.export_lines`.
``load_cases.csv``
    per conductor and load case: the predicted catenary, sag, swing and clearances.
``cloud.laz``
    the input points, wires class 14, pylons 15, with ``conductor_id``, ``span_id``
    and ``pylon_id`` as extra bytes.
``wires.png``
    plan view and one profile per span.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._atomic import atomic_path
from ..errors import LidarfxError
from ..vector import Polyline
from .extract import Conductor, PowerLines

__all__ = ["conductor_record", "conductor_polylines", "load_case_records", "write_tables", "write_load_cases"]

XYZ = ("x", "y", "z")


def _r(v: Any, nd: int = 4) -> Any:
    if v is None:
        return None
    v = float(v)
    return round(v, nd) if math.isfinite(v) else None


def _pt(p: Any, nd: int = 3) -> list[float] | None:
    return None if p is None else [_r(q, nd) for q in p]


def conductor_record(cd: Conductor) -> dict[str, Any]:
    """The JSON record of one conductor: coordinates and lengths (the catenary's a, s0 and c, sag,
    clearances) in the cloud's coordinate unit — metres, or feet for a cloud in feet, as
    ``meta["units"]`` of ``wires.json`` says — so that the curve can be drawn in the file's CRS."""
    m = cd.measures
    az = (math.degrees(math.atan2(cd.direction[0], cd.direction[1])) + 360.0) % 360.0
    return {
        "id": cd.id, "span_id": cd.span_id, "bundle_id": cd.bundle_id, "bundle_index": cd.bundle_index,
        "bundle_size": cd.bundle_size, "points": int(len(cd.index)),
        "start": _pt(cd.start), "end": _pt(cd.end), "start_held_by": cd.end_kinds[0], "end_held_by": cd.end_kinds[1],
        "azimuth": _r(az, 3), "horizontal_length": _r(cd.length, 3),
        "a": _r(m.get("a"), 3), "s0": _r(m.get("s0"), 3), "c": _r(m.get("c"), 3), "rmse": _r(m.get("rmse")),
        "sag": _r(m.get("sag")), "sag_point": _pt(m.get("sag_point")), "conductor_length": _r(m.get("conductor_length"), 3),
        "lowest_point": _pt(m.get("lowest_point")),
        "ground_clearance": _r(m.get("ground_clearance"), 3), "ground_clearance_at": _pt(m.get("ground_clearance_at")),
        "object_clearance": _r(m.get("object_clearance"), 3), "object_clearance_at": _pt(m.get("object_clearance_at")),
        "object_point": _pt(m.get("object_point")),
    }


def _flat(rec: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in rec.items():
        if isinstance(v, list):
            for ax, q in zip(XYZ, v):
                out[f"{k}_{ax}"] = q
        elif v is None and k.endswith(("_at", "_point", "start", "end")):
            for ax in XYZ:
                out[f"{k}_{ax}"] = None
        else:
            out[k] = v
    return out


def conductor_polylines(res: PowerLines, step: float = 0.5) -> list[Polyline]:
    """The catenaries as :class:`~lidarfx.vector.Polyline` (kind ``wire``), one vertex every ``step``
    (m, converted to the cloud's unit as the extraction's lengths: ``res.meta["unit_to_metre"]``).
    The attributes sag, conductor_length and the clearances are metres (as the lines' lengths in
    the vector files); the catenary's a, s0 and c stay in the coordinate unit."""
    step = _step_in_units(res, step)
    u = res.meta.get("unit_to_metre") or 1.0
    out = []
    for cd in res.conductors:
        rec = conductor_record(cd)
        attrs = {k: rec[k] for k in ("id", "span_id", "bundle_id", "bundle_index", "bundle_size", "a", "s0", "c",
                                     "sag", "conductor_length", "ground_clearance", "object_clearance")}
        attrs["conductor_id"] = attrs.pop("id")
        for k in ("sag", "conductor_length", "ground_clearance", "object_clearance"):  # metres, like length
            if attrs[k] is not None and u != 1.0:
                attrs[k] = round(attrs[k] * u, 4)
        out.append(Polyline(cd.curve(step), support=int(len(cd.index)), rms=float(cd.measures.get("rmse", math.nan)),
                            kind="wire", attrs=attrs))
    return out


def _step_in_units(res: PowerLines, step: float) -> float:
    """A vertex spacing in metres in the coordinate unit of the extraction's cloud."""
    u = res.meta.get("unit_to_metre") or 1.0
    return float(step) / float(u)


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    from .._tables import write_csv_rows

    write_csv_rows(path, rows)


def write_tables(res: PowerLines, folder: str | Path, *, crs: Any = None, step: float = 0.5,
                 load_cases: list[dict[str, Any]] | None = None, meta: dict[str, Any] | None = None) -> dict[str, str]:
    """``wires.csv``, ``wires.json``, ``wires.geojson``, ``wires.dxf`` (and ``load_cases.csv``) in ``folder``."""
    from .._json import dump
    from ..vector import export_lines

    folder = Path(folder)
    recs = [conductor_record(cd) for cd in res.conductors]
    info = {**res.meta, **(meta or {})}
    info.pop("seconds", None)
    from ..crs import unit_name

    unit = res.meta.get("unit_to_metre") or 1.0
    info["units"] = {"lengths": unit_name(unit), "coordinates": unit_name(unit), "unit_to_metre": unit}
    written = export_lines(conductor_polylines(res, step), geojson=folder / "wires.geojson", dxf=folder / "wires.dxf",
                           crs=crs, meta={k: v for k, v in info.items() if isinstance(v, (int, float, str))})
    _write_csv(folder / "wires.csv", [_flat(r) for r in recs])
    written["csv"] = str(folder / "wires.csv")
    doc = {"meta": info, "pylons": [{k: (_pt(v) if k == "position" else v) for k, v in p.items() if k != "ends"}
                                    for p in res.pylons],
           "spans": res.spans, "conductors": recs, "load_cases": load_cases or []}
    with atomic_path(folder / "wires.json") as tmp, open(tmp, "w", encoding="utf-8") as fh:
        dump(doc, fh, indent=1)
    written["json"] = str(folder / "wires.json")
    if load_cases:
        write_load_cases(load_cases, folder / "load_cases.csv")
        written["load_cases"] = str(folder / "load_cases.csv")
    return written


def write_load_cases(records: list[dict[str, Any]], path: str | Path) -> Path:
    """One row per conductor and load case."""
    _write_csv(Path(path), [_flat(r) for r in records])
    return Path(path)


def load_case_records(res: PowerLines, cases: Sequence[Any], conductor: Any, *, survey_temperature: float = 10.0,
                      step: float = 0.5) -> list[dict[str, Any]]:
    """Each conductor's span under each load case (:func:`lidarfx.powerlines.loads.predict_span`):
    catenary parameter, swing, sag and the clearances to ground and to objects of the loaded curve."""
    from scipy.spatial import cKDTree

    from .loads import conductor as get_conductor
    from .loads import parse_load_case, predict_span

    cond = get_conductor(conductor)
    parsed = [c if not isinstance(c, str) else parse_load_case(c) for c in cases]
    tree = cKDTree(res.objects) if res.objects is not None and len(res.objects) else None
    out = []
    for lc, text in zip(parsed, cases):
        name = text if isinstance(text, str) else (lc.name or repr(lc))
        for cd in res.conductors:
            rec: dict[str, Any] = {"conductor_id": cd.id, "span_id": cd.span_id, "load_case": name, "conductor": cond.name}
            if not (cd.fit.u > 0 and cd.length > 0):
                rec["note"] = "no catenary (straight or concave fit)"
                out.append(rec)
                continue
            h = float(cd.end[2] - cd.start[2])
            try:
                st = predict_span(cd.a, cd.length, h, cond, lc, survey_temperature)
            except LidarfxError as e:
                rec["note"] = str(e)
                out.append(rec)
                continue
            curve = st.curve(cd.start, cd.end, _step_in_units(res, step))
            clear = curve[:, 2] - res.ground_z(curve[:, :2]) if res.ground_z is not None else None
            rec.update({
                "temperature": _r(st.temperature2, 2), "a": _r(st.a2, 3), "swing_deg": _r(st.swing_deg, 3),
                "sag": _r(st.sag2), "vertical_sag": _r(st.vertical_sag2), "lateral_displacement": _r(st.lateral_displacement),
                "horizontal_tension_survey": _r(st.H1, 1), "horizontal_tension": _r(st.H2, 1),
                "max_tension": _r(st.T2_max, 1), "utilisation": _r(st.utilisation),
                "exceeds_rated_strength": bool(st.exceeds_rated_strength),
                "sag_change": _r(st.vertical_sag2 - st.sag1),
            })
            if clear is not None:
                k = int(np.nanargmin(clear))
                rec["ground_clearance"] = _r(clear[k], 3)
                rec["ground_clearance_at"] = _pt(curve[k])
            if tree is not None:
                d, j = tree.query(curve, k=1)
                k = int(np.argmin(d))
                rec["object_clearance"] = _r(d[k], 3)
                rec["object_clearance_at"] = _pt(curve[k])
                rec["object_point"] = _pt(res.objects[j[k]])
            out.append(rec)
    return out
