"""Turning a command's results into report sections: its JSON summary into key figures and
tables, its output files into links and pictures, its polylines into viewer layers, and the
names of the categorical attributes lidarfx writes."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Mapping, Sequence


def known_labels(cloud) -> dict[str, dict[int, str]]:
    """Names of the values of the categorical attributes lidarfx writes: ASPRS classes, structure labels."""
    from ..io import ASPRS_CLASSES
    from ..structures import LABELS

    out: dict[str, dict[int, str]] = {}
    if "classification" in cloud:
        out["classification"] = dict(ASPRS_CLASSES)
    if "structure" in cloud:
        out["structure"] = dict(LABELS)
    return out


RECORD_FIELDS = frozenset({
    "intensity", "return_number", "number_of_returns", "synthetic", "key_point", "withheld", "overlap",
    "scanner_channel", "scan_direction_flag", "edge_of_flight_line", "user_data", "scan_angle", "scan_angle_rank",
    "point_source_id", "gps_time", "red", "green", "blue", "nir", "wavepacket_index", "wavepacket_offset",
    "wavepacket_size", "return_point_wave_location", "x_t", "y_t", "z_t"})
"""The LAS point-record fields; every other attribute is a product or an extra-bytes dimension."""


def product_first(cloud, colour_by: str | None = None) -> list[str]:
    """The attributes a command's report shows, products first: ``colour_by``, then the attributes
    that are not LAS record fields (what the command computed), then the record fields (at most
    the viewer's limit; :func:`lidarfx.report.viewer_attributes`)."""
    from . import viewer_attributes

    products = [n for n in cloud.names if n not in RECORD_FIELDS]
    return viewer_attributes(cloud, first=[n for n in (colour_by, *products) if n])


def line_layer(layer: Sequence) -> tuple[list, list[dict] | None]:
    """``(arrays, properties)`` of a layer of polylines (``vertices`` and ``properties()``) or arrays."""
    import numpy as np

    arrays, props = [], []
    for item in layer:
        v = getattr(item, "ring", None) if getattr(item, "closed", False) else None  # closed: back to the start
        v = np.asarray(getattr(item, "vertices", item) if v is None else v, dtype=np.float64).reshape(-1, 3)
        if len(v) < 2 or not np.isfinite(v).all():  # not a line the viewer can draw
            continue
        arrays.append(v)
        p = getattr(item, "properties", None)
        props.append(p() if callable(p) else {})
    return arrays, (props if any(props) else None)


def _scalar(v: Any) -> bool:
    return v is None or isinstance(v, (str, bool, int, float))


def _cell(v: Any) -> Any:
    """A table cell: scalars as they are (non-finite floats empty), short lists joined, the rest as text."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if _scalar(v):
        return v
    if isinstance(v, (list, tuple)) and all(_scalar(x) for x in v):
        return ", ".join("" if x is None else (f"{x:g}" if isinstance(x, float) else str(x)) for x in v)
    from .. import _json

    return _json.dumps(v)


def summary_sections(summary: Mapping[str, Any]) -> tuple[dict, list[tuple[str, list[dict]]]]:
    """Split a command's JSON summary into key figures (numbers, texts, short lists) and tables:
    a list of records is one table, a mapping of scalars a name / value table, a mapping of
    mappings one row per key.  ``outputs`` is left to :func:`output_files`."""
    figures: dict[str, Any] = {}
    tables: list[tuple[str, list[dict]]] = []
    for key, v in summary.items():
        if key == "outputs":
            continue
        title = key.replace("_", " ")
        if _scalar(v) or (isinstance(v, (list, tuple)) and all(_scalar(x) for x in v) and len(v) <= 12):
            figures[key] = _cell(v)
        elif isinstance(v, (list, tuple)):
            rows = [({k: _cell(x) for k, x in r.items()} if isinstance(r, Mapping) else {"value": _cell(r)}) for r in v]
            if rows:
                tables.append((title, rows))
        elif isinstance(v, Mapping):
            if v and all(isinstance(x, Mapping) for x in v.values()):
                tables.append((title, [{"name": str(k), **{c: _cell(x) for c, x in r.items()}} for k, r in v.items()]))
            elif v:
                tables.append((title, [{"name": str(k), "value": _cell(x)} for k, x in v.items()]))
    return figures, tables


def output_files(summary: Mapping[str, Any]) -> list[tuple[str, str]]:
    """``(name, path)`` of the files the command wrote (its ``outputs`` and ``output``)."""
    out: list[tuple[str, str]] = []
    outputs = summary.get("outputs")
    if isinstance(outputs, Mapping):
        out += [(str(k), str(v)) for k, v in outputs.items() if isinstance(v, (str, os.PathLike)) and v]
    single = summary.get("output")
    if isinstance(single, (str, os.PathLike)) and single:
        out.append(("output", str(single)))
    return out


def output_pictures(summary: Mapping[str, Any]) -> list[tuple[str, str]]:
    """The PNG files among the outputs, captioned with their names."""
    return [(p, f"{name}: {Path(p).name}") for name, p in output_files(summary) if p.lower().endswith(".png")]
