"""Tables and pictures of a discontinuity analysis: sets.csv / sets.json, segments.csv, stereonet, rose, sets."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from .analyse import Discontinuities

__all__ = ["SET_COLUMNS", "SEGMENT_COLUMNS", "write_tables", "draw_pictures"]

SET_COLUMNS = ["id", "dip", "dip_direction", "strike", "pole_trend", "pole_plunge", "kappa", "alpha95", "spread",
               "segments", "points", "share", "selected_share", "area", "mean_trace_length", "spacing_mean",
               "spacing_median", "spacing_count", "overhang_segments"]
"""Columns of ``sets.csv`` (angles in degrees, lengths in m, areas in m²)."""

SEGMENT_COLUMNS = ["id", "set_id", "points", "selected_points", "centroid_x", "centroid_y", "centroid_z",
                   "normal_x", "normal_y", "normal_z", "dip", "dip_direction", "strike", "angle_to_set", "rms",
                   "planarity", "area", "trace_length", "strike_length", "dip_length", "reference_distance",
                   "overhang"]
"""Columns of ``segments.csv`` (normals outwards; dip and dip direction of the plane)."""


def _round(rec: dict[str, Any], nd: int = 4) -> dict[str, Any]:
    out = {}
    for k, v in rec.items():
        if isinstance(v, (float, np.floating)):
            v = float(v)
            out[k] = round(v, nd) if math.isfinite(v) else (None if math.isnan(v) else v)
        else:
            out[k] = v
    return out


def write_tables(res: Discontinuities, folder: str | Path, *, meta: dict[str, Any] | None = None) -> dict[str, str]:
    """``sets.csv``, ``sets.json`` (sets, reference plane, parameters, counts) and ``segments.csv`` in ``folder``."""
    from .._tables import write_csv_rows, write_json_doc

    folder = Path(folder)
    sets = [_round(s) for s in res.sets]
    segs = [_round(s) for s in res.segments]
    write_csv_rows(folder / "sets.csv", sets, SET_COLUMNS)
    write_csv_rows(folder / "segments.csv", segs, SEGMENT_COLUMNS)
    info = {k: v for k, v in res.meta.items() if k != "seconds"}
    doc = {"columns": SET_COLUMNS, "sets": sets, "reference_plane": res.reference, "meta": {**info, **(meta or {})}}
    write_json_doc(folder / "sets.json", doc)
    return {"sets_csv": str(folder / "sets.csv"), "sets_json": str(folder / "sets.json"),
            "segments_csv": str(folder / "segments.csv")}


def draw_pictures(res: Discontinuities, folder: str | Path, *, name: str = "", max_poles: int = 20000,
                  seed: int = 0) -> dict[str, str]:
    """``stereonet.png`` (poles of the selected points, Kamb contours, set planes), ``rose.png`` (strikes of
    the segments, weighted by area) and ``sets.png`` (the cloud coloured by set, seen along the face normal)."""
    from ..render.stereonet import rose_view, set_view, stereonet_view

    folder = Path(folder)
    c = res.cloud
    sel = np.flatnonzero((np.asarray(c["selected"]) > 0) & np.isfinite(c["dip"]))
    if len(sel) > max_poles:
        sel = np.sort(np.random.default_rng(seed).choice(sel, size=max_poles, replace=False))
    prefix = f"{name}: " if name else ""
    written = {}
    sets = [{k: s[k] for k in ("id", "dip", "dip_direction", "kappa", "alpha95", "share")} for s in res.sets]
    if len(sel):
        stereonet_view(np.asarray(c["dip"])[sel], np.asarray(c["dip_direction"])[sel], folder / "stereonet.png",
                       set_ids=np.asarray(c["set_id"])[sel], sets=sets,
                       title=f"{prefix}{len(sets)} joint sets; poles of the selected points")
        written["stereonet"] = str(folder / "stereonet.png")
    segs = [s for s in res.segments if s["selected_points"] >= 3]
    if segs:
        rose_view(np.array([s["strike"] for s in segs]), folder / "rose.png",
                  weights=np.array([s["area"] for s in segs]), set_ids=np.array([s["set_id"] for s in segs]),
                  title=f"{prefix}strikes of the segments, weighted by area (m²)")
        written["rose"] = str(folder / "rose.png")
    set_view(c.xyz, np.asarray(c["set_id"]), folder / "sets.png", view_normal=np.asarray(res.meta["face_normal"]),
             title=f"{prefix}points by joint set")
    written["sets_picture"] = str(folder / "sets.png")
    return written
