"""Writers (and a GeoJSON reader) for :class:`~lidarfx.vector.polyline.Polyline` lists.

GeoJSON (3-D LineStrings with the legacy ``crs`` member GDAL and QGIS honour), DXF
(3-D POLYLINEs, one layer per kind), CSV (one row per line, or one row per vertex)
and plain JSON.  Every writer checks the output folder first, writes to a temporary
file beside the target and renames it at the end: a failed write leaves nothing.
:func:`export_lines` writes several formats all-or-nothing.
"""
from __future__ import annotations

import contextlib
import csv as _csv
import json
import math
import os
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from .._atomic import atomic_path, check_output_folder
from .._json import dumps, jsonable
from ..errors import LidarfxError, check_int
from .polyline import Polyline

__all__ = [
    "crs_name",
    "write_geojson",
    "read_geojson",
    "write_dxf",
    "write_csv",
    "write_vertices_csv",
    "write_json",
    "export_lines",
    "MAX_GEOJSON_BYTES",
]

MAX_GEOJSON_BYTES = 200 * 1024 * 1024
"""Largest GeoJSON file :func:`read_geojson` reads (it is parsed in memory)."""

_EPSG_URN = "urn:ogc:def:crs:EPSG::{}"

# properties Polyline.properties() computes itself: never taken into attrs on reading
_BUILTIN = ("kind", "n_vertices", "length", "length_2d", "support", "rms", "z_min", "z_max", "closed")

_CSV_COLUMNS = ("id", "kind", "n_vertices", "length", "length_2d", "support", "rms", "z_min", "z_max",
                "closed", "x_start", "y_start", "z_start", "x_end", "y_end", "z_end")

# AutoCAD colour indices, distinct and readable on a dark or light background (7 = white/black last)
_DXF_COLOURS = (1, 3, 5, 6, 4, 2, 30, 140, 200, 40, 160, 220, 90, 180, 240, 8, 7)
_DXF_BAD_CHARS = set('<>/\\":;?*|=`')  # AutoCAD's reserved characters (ezdxf's and '|')


# ------------------------------------------------------------------ CRS
def crs_name(crs: Any) -> str | None:
    """The name for the GeoJSON ``crs`` member from a :func:`lidarfx.crs.cloud_crs` dict.

    EPSG code known → ``"urn:ogc:def:crs:EPSG::<code>"``; only a WKT → its EPSG code
    by pyproj (confidence ≥ 70 %) as URN, else the WKT itself (GDAL
    reads any SRS text there); ``None`` → ``None``.  A string is returned as it is
    (e.g. the name :func:`read_geojson` gives back), an int taken as an EPSG code.
    """
    if crs is None:
        return None
    if isinstance(crs, str):
        return crs.strip() or None
    if isinstance(crs, (int, np.integer)) and not isinstance(crs, bool):
        return _EPSG_URN.format(int(crs))
    if not isinstance(crs, Mapping):
        raise LidarfxError(f"crs must be a dict as cloud_crs gives, an EPSG code or a name, got {type(crs).__name__}")
    epsg = crs.get("epsg")
    if epsg is not None and not isinstance(epsg, bool):
        try:
            code = int(epsg)
        except (TypeError, ValueError):
            code = 0
        if code > 0:
            return _EPSG_URN.format(code)
    wkt = crs.get("wkt")
    if not isinstance(wkt, str) or not wkt.strip():
        return None
    wkt = wkt.strip()
    import pyproj

    try:
        code = pyproj.CRS.from_wkt(wkt).to_epsg(min_confidence=70)
    except Exception:  # pyproj cannot parse it: GDAL may still
        code = None
    return _EPSG_URN.format(code) if code else wkt


# ------------------------------------------------------------------ helpers
def _as_lines(lines: Any) -> list[Polyline]:
    if isinstance(lines, Polyline):
        raise LidarfxError("lines must be a list of Polyline, got a single Polyline")
    try:
        out = list(lines)
    except TypeError:
        raise LidarfxError(f"lines must be a list of Polyline, got {type(lines).__name__}") from None
    for i, line in enumerate(out):
        if not isinstance(line, Polyline):
            raise LidarfxError(f"lines[{i}] is a {type(line).__name__}, not a Polyline")
    return out


def _check_precision(precision: Any) -> int:
    return check_int("precision", precision, 0, 12)


def _check_meta(meta: Any) -> dict[str, Any]:
    if meta is None:
        return {}
    if not isinstance(meta, Mapping):
        raise LidarfxError(f"meta must be a dict, got {type(meta).__name__}")
    return jsonable(meta)


def _check_reserved(lines: list[Polyline], reserved: Iterable[str], fmt: str) -> None:
    names = set(reserved)
    for i, line in enumerate(lines):
        bad = names.intersection(line.attrs)
        if bad:
            raise LidarfxError(f"lines[{i}]: attribute {sorted(bad)[0]!r} clashes with a {fmt} column; rename it")


def _round(a: np.ndarray, precision: int) -> list:
    return (np.round(np.asarray(a, dtype=np.float64), precision) + 0.0).tolist()  # + 0.0: no "-0.0"


def _rnd(v: float, precision: int) -> float:
    return round(float(v), precision) + 0.0


def _unit_of(crs: Any) -> float:
    """Metres per coordinate unit of ``crs`` (a :func:`lidarfx.crs.cloud_crs` dict), 1.0 otherwise."""
    u = crs.get("unit_to_metre") if isinstance(crs, Mapping) else None
    try:
        u = float(u)
    except (TypeError, ValueError):
        return 1.0
    return u if math.isfinite(u) and u > 0 else 1.0


def _records(lines: list[Polyline], unit: float = 1.0) -> list[dict[str, Any]]:
    """``{"id": i, **properties}`` per line (the attrs clash check is in properties()); with
    ``unit`` (metres per coordinate unit) ≠ 1 the lengths and the rms are converted to metres —
    lengths in tables are metres (docs/conventions.md), z_min / z_max stay coordinates."""
    out = [{"id": i, **line.properties()} for i, line in enumerate(lines)]
    if unit != 1.0:
        for rec in out:
            for k in ("length", "length_2d", "rms"):
                if rec.get(k) is not None:
                    rec[k] = round(rec[k] * unit, 4)
    return out


def _with_units(meta: Any, unit: float) -> Any:
    """``meta`` with a ``units`` entry when the coordinates are not metres."""
    if unit == 1.0:
        return meta
    from ..crs import unit_name

    return {**(meta or {}), "units": {"lengths": "m", "coordinates": unit_name(unit), "unit_to_metre": unit}}


# ------------------------------------------------------------------ GeoJSON
def write_geojson(lines: Iterable[Polyline], path: str | os.PathLike, *, crs: Any = None, precision: int = 3,
                  meta: Mapping[str, Any] | None = None) -> Path:
    """A GeoJSON FeatureCollection: one 3-D LineString Feature per line (closed lines repeat
    their first vertex), coordinates rounded to ``precision`` decimals, properties
    ``{"id", **line.properties()}`` (NaN → null), the legacy ``crs`` member when
    :func:`crs_name` gives a name, ``meta`` as top-level ``"lidarfx"`` member."""
    p = Path(path)
    check_output_folder(p)
    with atomic_path(p) as tmp:
        _write_geojson_to(tmp, _as_lines(lines), crs=crs, precision=precision, meta=meta)
    return p


def _write_geojson_to(tmp: Path, lines: list[Polyline], *, crs: Any, precision: int, meta: Any) -> None:
    precision = _check_precision(precision)
    _check_reserved(lines, ("id",), "GeoJSON")
    name = crs_name(crs)
    unit = _unit_of(crs)
    meta = _with_units(meta, unit)
    head: dict[str, Any] = {"type": "FeatureCollection"}
    if name is not None:
        head["crs"] = {"type": "name", "properties": {"name": name}}
    if meta is not None:
        head["lidarfx"] = _check_meta(meta)
    with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(dumps(head)[:-1])  # without the closing brace
        fh.write(', "features": [')
        for i, (line, props) in enumerate(zip(lines, _records(lines, unit))):
            feature = {"type": "Feature", "properties": props,
                       "geometry": {"type": "LineString", "coordinates": _round(line.ring, precision)}}
            fh.write(("," if i else "") + "\n" + dumps(feature))
        fh.write("\n]}\n" if lines else "]}\n")


def read_geojson(path: str | os.PathLike) -> tuple[list[Polyline], str | None]:
    """The polylines of a GeoJSON FeatureCollection and its ``crs`` name (or ``None``).

    LineString and MultiLineString features are read (one Polyline per part; other
    geometries are skipped); 2-D positions get z = 0.0 and ``attrs["z_missing"] = True``;
    a ring whose last position equals the first is ``closed`` without the repeat; kind,
    support and rms come from the properties, other scalar properties go to ``attrs``.
    """
    p = Path(path)
    if not p.exists():
        raise LidarfxError(f"GeoJSON file not found: {p}")
    if not p.is_file():
        raise LidarfxError(f"{p} is not a file")
    size = p.stat().st_size
    if size > MAX_GEOJSON_BYTES:
        raise LidarfxError(f"{p} is {size / 2**20:.0f} MB; GeoJSON files over {MAX_GEOJSON_BYTES // 2**20} MB "
                           "are not read (use another format)")
    try:
        with open(p, "rb") as fh:
            data = json.loads(fh.read().decode("utf-8-sig"))
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:  # JSONDecodeError is a ValueError
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise LidarfxError(f"{p} is not a JSON file: {msg}") from None
    except OSError as exc:
        raise LidarfxError(f"cannot read {p}: {exc.strerror or exc}") from None
    if not isinstance(data, dict) or data.get("type") != "FeatureCollection":
        raise LidarfxError(f"{p} is not a GeoJSON FeatureCollection")
    features = data.get("features", [])
    if not isinstance(features, list):
        raise LidarfxError(f"{p}: 'features' is not a list")

    name = None
    crs = data.get("crs")
    if isinstance(crs, dict) and isinstance(crs.get("properties"), dict):
        n = crs["properties"].get("name")
        if isinstance(n, str) and n.strip():
            name = n.strip()

    out: list[Polyline] = []
    for i, feature in enumerate(features):
        if not isinstance(feature, dict):
            raise LidarfxError(f"{p}: feature {i} is not an object")
        geom = feature.get("geometry")
        if not isinstance(geom, dict):
            continue  # null geometry
        gtype = geom.get("type")
        coords = geom.get("coordinates")
        if gtype == "LineString":
            parts = [coords]
        elif gtype == "MultiLineString":
            if not isinstance(coords, list):
                raise LidarfxError(f"{p}: feature {i}: MultiLineString coordinates are not a list")
            parts = coords
        else:
            continue
        props = feature.get("properties")
        props = props if isinstance(props, dict) else {}
        try:
            kind, support, rms, attrs = _fields(props)
            for part in parts:
                out.append(_polyline(part, kind, support, rms, attrs))
        except LidarfxError as exc:
            raise LidarfxError(f"{p}: feature {i}: {exc}") from None
    return out, name


def _fields(props: dict[str, Any]) -> tuple[str, int, float, dict[str, Any]]:
    kind = props.get("kind", "line")
    kind = "line" if kind is None or isinstance(kind, (dict, list)) else str(kind)
    support = props.get("support")
    if support is None:
        support = 0
    else:
        if isinstance(support, bool) or not isinstance(support, (int, float)) or support != int(support) \
                or support < 0:
            raise LidarfxError(f"support must be a non-negative integer, got {support!r}")
        support = int(support)
    rms = props.get("rms")
    if rms is None:
        rms = math.nan
    elif isinstance(rms, bool) or not isinstance(rms, (int, float)):
        raise LidarfxError(f"rms must be a number, got {rms!r}")
    else:
        rms = float(rms)
    attrs = {k: v for k, v in props.items()
             if k != "id" and k not in _BUILTIN and (v is None or isinstance(v, (str, int, float, bool)))}
    return kind, support, rms, attrs


def _polyline(coords: Any, kind: str, support: int, rms: float, attrs: dict[str, Any]) -> Polyline:
    if not isinstance(coords, list) or not all(isinstance(c, list) for c in coords):
        raise LidarfxError("LineString coordinates must be a list of positions")
    rows = []
    z_missing = False
    for c in coords:
        if len(c) < 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in c[:3]):
            raise LidarfxError(f"bad position {c!r}")
        if len(c) == 2:
            z_missing = True
            rows.append((float(c[0]), float(c[1]), 0.0))
        else:
            rows.append((float(c[0]), float(c[1]), float(c[2])))
    v = np.array(rows, dtype=np.float64).reshape(-1, 3)
    closed = len(v) >= 3 and bool(np.array_equal(v[0], v[-1]))
    if closed:
        v = v[:-1]
    a = dict(attrs)
    if z_missing:
        a["z_missing"] = True
    return Polyline(v, support=support, rms=rms, kind=kind, closed=closed, attrs=a)


# ------------------------------------------------------------------ DXF
def _layer_name(kind: str) -> str:
    name = "".join("_" if (ch in _DXF_BAD_CHARS or not ch.isprintable()) else ch for ch in str(kind).upper())
    name = name.strip()[:255]
    return name or "LINE"


def write_dxf(lines: Iterable[Polyline], path: str | os.PathLike, *, layer: str | None = None) -> Path:
    """A DXF (R2010) drawing: one 3-D POLYLINE per line on layer ``layer`` (default: the
    line's kind upper-cased, made a valid layer name), one colour per layer, units metres."""
    p = Path(path)
    check_output_folder(p)
    with atomic_path(p) as tmp:
        _write_dxf_to(tmp, _as_lines(lines), layer=layer)
    return p


def _write_dxf_to(tmp: Path, lines: list[Polyline], *, layer: str | None) -> None:
    import ezdxf

    if layer is not None:
        if not isinstance(layer, str) or not layer.strip() or len(layer) > 255 or layer != layer.strip() \
                or any(ch in _DXF_BAD_CHARS or not ch.isprintable() for ch in layer):
            raise LidarfxError(f"{layer!r} is not a valid DXF layer name (1 to 255 characters, none of <>/\\\":;?*|=`)")
    doc = ezdxf.new("R2010")
    doc.header["$INSUNITS"] = 6  # metres
    doc.header["$MEASUREMENT"] = 1  # metric
    msp = doc.modelspace()
    colours: dict[str, int] = {}
    for line in lines:
        name = layer if layer is not None else _layer_name(line.kind)
        key = name.upper()  # DXF layer names are case-insensitive
        if key not in colours:
            colours[key] = _DXF_COLOURS[len(colours) % len(_DXF_COLOURS)]
            if name not in doc.layers:
                doc.layers.add(name, color=colours[key])
        msp.add_polyline3d(line.vertices.tolist(), close=bool(line.closed), dxfattribs={"layer": name})
    doc.saveas(tmp)


# ------------------------------------------------------------------ CSV
def _cell(v: Any) -> Any:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (float, np.floating)):
        return "" if not math.isfinite(float(v)) else float(v)
    if isinstance(v, (int, np.integer, str)):
        return v
    return dumps(v)


def write_csv(lines: Iterable[Polyline], path: str | os.PathLike, *, precision: int = 3, unit: float = 1.0) -> Path:
    """One row per line: id, kind, n_vertices, length, length_2d, support, rms, z_min, z_max,
    closed, start and end vertex, then every attrs key met (first-seen order, empty cell
    where a line lacks it).  Lengths and rms as :meth:`Polyline.properties` rounds them,
    coordinates to ``precision`` decimals."""
    p = Path(path)
    check_output_folder(p)
    with atomic_path(p) as tmp:
        _write_csv_to(tmp, _as_lines(lines), precision=precision, unit=unit)
    return p


def _write_csv_to(tmp: Path, lines: list[Polyline], *, precision: int, unit: float = 1.0) -> None:
    precision = _check_precision(precision)
    _check_reserved(lines, _CSV_COLUMNS, "CSV")
    extra: dict[str, None] = {}
    for line in lines:
        for k in line.attrs:
            extra.setdefault(str(k), None)
    with open(tmp, "w", encoding="utf-8", newline="") as fh:
        w = _csv.writer(fh)
        w.writerow([*_CSV_COLUMNS, *extra])
        for line, props in zip(lines, _records(lines, unit)):
            v = line.vertices
            first, last = v[0], v[-1]
            row = [props["id"], props["kind"], props["n_vertices"], props["length"], props["length_2d"],
                   props["support"], props["rms"], _rnd(v[:, 2].min(), precision), _rnd(v[:, 2].max(), precision),
                   props["closed"], *(_rnd(c, precision) for c in first), *(_rnd(c, precision) for c in last)]
            attrs = {str(k): a for k, a in line.attrs.items()}
            row += [attrs.get(k) for k in extra]
            w.writerow([_cell(c) for c in row])


def write_vertices_csv(lines: Iterable[Polyline], path: str | os.PathLike, *, precision: int = 3) -> Path:
    """One row per vertex: id, vertex, x, y, z (a closed line's first vertex is not repeated)."""
    p = Path(path)
    check_output_folder(p)
    with atomic_path(p) as tmp:
        _write_vertices_csv_to(tmp, _as_lines(lines), precision=precision)
    return p


def _write_vertices_csv_to(tmp: Path, lines: list[Polyline], *, precision: int) -> None:
    precision = _check_precision(precision)
    with open(tmp, "w", encoding="utf-8", newline="") as fh:
        w = _csv.writer(fh)
        w.writerow(["id", "vertex", "x", "y", "z"])
        for i, line in enumerate(lines):
            for j, (x, y, z) in enumerate(_round(line.vertices, precision)):
                w.writerow([i, j, x, y, z])


# ------------------------------------------------------------------ JSON
def write_json(lines: Iterable[Polyline], path: str | os.PathLike, *, meta: Mapping[str, Any] | None = None,
               precision: int = 3, unit: float = 1.0) -> Path:
    """``{"meta": meta or {}, "lines": [{"id", **properties, "vertices": [[x, y, z], …]}]}``
    (a closed line's first vertex is not repeated: ``"closed"`` says so)."""
    p = Path(path)
    check_output_folder(p)
    with atomic_path(p) as tmp:
        _write_json_to(tmp, _as_lines(lines), meta=meta, precision=precision, unit=unit)
    return p


def _write_json_to(tmp: Path, lines: list[Polyline], *, meta: Any, precision: int, unit: float = 1.0) -> None:
    precision = _check_precision(precision)
    _check_reserved(lines, ("id", "vertices"), "JSON")
    m = _check_meta(_with_units(meta, unit))
    with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
        fh.write('{"meta": ' + dumps(m) + ', "lines": [')
        for i, (line, props) in enumerate(zip(lines, _records(lines, unit))):
            rec = {**props, "vertices": _round(line.vertices, precision)}
            fh.write(("," if i else "") + "\n" + dumps(rec))
        fh.write("\n]}\n" if lines else "]}\n")


# ------------------------------------------------------------------ all at once
def export_lines(lines: Iterable[Polyline], *, geojson: str | os.PathLike | None = None,
                 dxf: str | os.PathLike | None = None, csv: str | os.PathLike | None = None,
                 json: str | os.PathLike | None = None, crs: Any = None,
                 meta: Mapping[str, Any] | None = None) -> dict[str, str]:
    """Write every format whose path is given; ``{format: path}`` of the files written.

    All output folders are checked before anything is written, and the formats are
    written to temporary files first and renamed only when all succeeded: a failure
    leaves none of the outputs behind.  ``crs`` goes to GeoJSON, ``meta`` to GeoJSON
    and JSON; when ``crs`` (a :func:`lidarfx.crs.cloud_crs` dict) has coordinates in feet, the
    lengths and rms of every format are metres and ``meta`` gains a ``units`` entry.
    """
    items = _as_lines(lines)
    unit = _unit_of(crs)
    targets = {k: Path(v) for k, v in (("geojson", geojson), ("dxf", dxf), ("csv", csv), ("json", json))
               if v is not None}
    for p in targets.values():
        check_output_folder(p)
    seen: dict[str, str] = {}
    for fmt, p in targets.items():
        key = os.path.normcase(os.path.abspath(p))
        if key in seen:
            raise LidarfxError(f"the {seen[key]} and {fmt} outputs are the same file {p}; give distinct paths")
        seen[key] = fmt
    writers = {
        "geojson": lambda tmp: _write_geojson_to(tmp, items, crs=crs, precision=3, meta=meta),
        "dxf": lambda tmp: _write_dxf_to(tmp, items, layer=None),
        "csv": lambda tmp: _write_csv_to(tmp, items, precision=3, unit=unit),
        "json": lambda tmp: _write_json_to(tmp, items, meta=meta, precision=3, unit=unit),
    }
    with contextlib.ExitStack() as stack:  # every temp file renamed only after all were written
        for fmt, p in targets.items():
            writers[fmt](stack.enter_context(atomic_path(p)))
    return {fmt: str(p) for fmt, p in targets.items()}
