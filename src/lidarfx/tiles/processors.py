"""The per-point commands that run in chunks: what buffer each needs and how it computes one
chunk.  A processor takes a :class:`~lidarfx.tiles.engine.Chunk` (the buffered cloud, the
points it owns, their global indices) and returns the owned points with the command's results.

``identical``: every point's values equal a single in-memory run's, bit for bit (tested).
``metres``: the options' lengths are metres (docs/conventions.md); :func:`lidarfx.tiles.run_tiled`
adds ``unit_to_metre`` (metres per coordinate unit of the first input) to the options, and the
buffer and the processing convert with it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..errors import LidarfxError


@dataclass(frozen=True)
class Processor:
    buffer: Callable[[dict, float], tuple[float, bool]]
    process: Callable[[Any, Any, dict], Any]
    check: Callable[[dict], None] = lambda o: None
    identical: bool = True
    metres: bool = False


def unit_of(o: dict) -> float:
    """Metres per coordinate unit of a run (``o["unit_to_metre"]``, 1.0 when absent)."""
    u = o.get("unit_to_metre") or 1.0
    if isinstance(u, bool) or not isinstance(u, (int, float)) or not (math.isfinite(u) and u > 0):
        raise LidarfxError(f"unit_to_metre must be a positive number, got {u!r}")
    return float(u)


# --------------------------------------------------------------------------- features
def features_buffer(o: dict, density: float) -> tuple[float, bool]:
    """The largest radius (exact; metres in the options, coordinate units here).  kNN without a
    radius cap has no fixed reach: three times the radius holding k points at the mean 2-D
    ``density``, and every chunk checks that its points' k-th neighbours lie within (else a
    one-line error with the buffer needed).  Returns ``(buffer, exact)``."""
    rs = [float(r) / unit_of(o) for r in o.get("radii") or []]
    if o.get("neighbourhood") == "knn" and not rs:
        rk = math.sqrt(int(o.get("k") or 1) / (math.pi * max(density, 1e-12)))
        return float(f"{3.0 * rk:.2g}"), False
    return (float(max(rs)) if rs else 0.0), True


def _knn_cell(ctx, k: int) -> float:
    """The kNN column size of the whole cloud (``neighbors.default_cell_for_knn`` of all points)."""
    ext = np.asarray(ctx.maxs[:2]) - np.asarray(ctx.mins[:2]) if ctx.points > 1 else np.ones(2)
    area = max(float(ext[0]) * float(ext[1]), 1e-6)
    return max(math.sqrt(area * k / max(ctx.points, 1)), 1e-3)


def check_features_options(o: dict) -> None:
    """The checks of the in-memory run, once, before any chunk (and ``ground`` refused: the
    ground filter is not local)."""
    from ..features.api import check_options, radii_list
    from ..features.registry import resolve

    req = resolve(o.get("features"))
    if "height_above_ground" in req.point:
        raise LidarfxError("the ground feature group runs the ground filter, which is not local: in chunks, run "
                           "lidarfx ground --hag first (it writes height_above_ground), or use --chunk-size 0")
    rs = radii_list(None, o.get("radii") or []) if req.slots else []
    check_options(req, rs, o.get("neighbourhood", "sphere"), o.get("k"), o.get("convention", "default"),
                  o.get("hist_bins", 10), o.get("height"), d_max=o.get("d_max", 0.10), msac_threshold=None,
                  msac_iterations=100, seed=o.get("seed", 0), scanner=o.get("scanner"))


def chunk_feature_arrays(chunk, ctx, req, radii, *, neighbourhood: str = "sphere", k: int | None = None,
                         unit: float = 1.0, **opts) -> dict[str, np.ndarray]:
    """:func:`lidarfx.features.api.feature_arrays` of a chunk's owned points, with the whole
    cloud's index layout (origin = the global minimum, the global kNN cell) and global indices
    (MSAC's per-point random draws): the whole cloud's values, bit for bit.  ``opts`` go to
    ``feature_arrays``.  kNN without a radius cap checks that every k-th neighbour lies within
    the buffer (``unit``: metres per coordinate unit, for its message).  ``radii`` and the lengths
    of ``opts`` are in coordinate units."""
    from ..features.api import feature_arrays, feature_index

    cloud, own = chunk.cloud, chunk.own
    index = feature_index(cloud.xyz, neighbourhood, k, radii, req, origin=np.asarray(ctx.mins, dtype=np.float64),
                          knn_cell=_knn_cell(ctx, int(k)) if neighbourhood == "knn" else None)
    q = cloud.xyz[own]
    arrays = feature_arrays(cloud.xyz, req, radii=radii, neighbourhood=neighbourhood, k=k, query_xyz=q,
                            query_ids=chunk.ids[own], progress=False, index=index, **opts)
    if neighbourhood == "knn" and not radii:
        _check_knn_reach(chunk, ctx, index, q, int(k), unit)
    return arrays


def features_process(chunk, ctx, o: dict):
    """The features of the owned points (:func:`chunk_feature_arrays`) and the per-point ones."""
    from ..features.api import point_feature, radii_list
    from ..features.registry import resolve

    from ..features.api import scale_names

    cloud, own = chunk.cloud, chunk.own
    req = resolve(o.get("features"))
    result = cloud.subset(own)
    result.meta.pop("source", None)
    result.update({name: point_feature(name, cloud)[own] for name in req.point})
    if req.slots:
        u = unit_of(o)  # the options are metres (as compute_features takes them)
        rs = radii_list(None, o.get("radii") or [])
        rs_units = [r / u for r in rs]
        height = o.get("height")
        arrays = chunk_feature_arrays(
            chunk, ctx, req, rs_units, neighbourhood=o.get("neighbourhood", "sphere"),
            k=o.get("k"), scanner=o.get("scanner"), height=None if height is None else float(height) / u,
            convention=o.get("convention", "default"), d_max=float(o.get("d_max", 0.10)) / u,
            hist_bins=o.get("hist_bins", 10), seed=o.get("seed", 0), unit=u)
        rename = scale_names(list(arrays), rs_units, rs, o.get("neighbourhood", "sphere"))
        result.update({rename.get(n, n): v for n, v in arrays.items()})
    return result


def _check_knn_reach(chunk, ctx, index, q: np.ndarray, k: int, unit: float = 1.0) -> None:
    """Every owned point's k-th neighbour must lie within the buffer: else a one-line error
    with the buffer needed."""
    bx0, by0, bx1, by1 = chunk.square(ctx)
    room = np.minimum.reduce([q[:, 0] - (bx0 - ctx.grid.buffer), (bx1 + ctx.grid.buffer) - q[:, 0],
                              q[:, 1] - (by0 - ctx.grid.buffer), (by1 + ctx.grid.buffer) - q[:, 1]])
    kk = min(k, len(chunk.cloud))
    _, kd = index.knn(q, kk)
    reach = np.where(np.isfinite(kd), kd, np.inf).max(axis=1)
    bad = reach > room
    if bad.any():
        need = float((reach[bad] - room[bad]).max() + ctx.grid.buffer) * unit  # metres
        raise LidarfxError(f"the {k} nearest neighbours reach {need:.2f} m beyond the chunk; give --buffer {math.ceil(need)}")


PROCESSORS: dict[str, Processor] = {
    "features": Processor(features_buffer, features_process, check_features_options, metres=True),
}
"""Commands that run in chunks, by name (those of other modules are added by :func:`get`)."""

_MODULES = {"ground": "proc_ground", "eigenclass": "proc_classes", "classify": "proc_classes",
            "colour": "proc_colour", "crop": "proc_ops", "filter": "proc_ops", "outliers-stats": "proc_ops",
            "reproject": "proc_ops", "select": "proc_ops", "pipeline": "proc_pipeline"}


def get(command: str) -> Processor:
    """The processor of ``command``; a one-line error when it does not run in chunks."""
    if command not in PROCESSORS and command in _MODULES:
        import importlib

        PROCESSORS.update(importlib.import_module(f"{__package__}.{_MODULES[command]}").PROCESSORS)
    if command not in PROCESSORS:
        raise LidarfxError(f"{command} does not run in chunks")
    return PROCESSORS[command]
