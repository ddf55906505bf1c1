"""``lidarfx ground`` in chunks: the SMRF ground filter (classification 2 / 1) and, with
``hag``, the height above the ground TIN, per chunk with a buffer.

The filter is not local: its progressive opening reaches about twice the largest window, an
object region's step check and the inpainting of empty cells reach as far as the region or the
gap.  Each chunk therefore filters its buffered cloud on the cells of the whole cloud's grid
(anchored at the minimum of all points: the in-memory run anchors it at the minimum of the
points the filter uses, the same unless ignored classes or earlier returns lie below or west
of them; the same inpainting jitter), and keeps its own points.  With
the default buffer (:func:`ground_buffer`) nearly every point's class equals the in-memory
run's; the points that differ lie in object regions or gaps wider than the buffer
(docs/scaling.md gives the measured agreement).  The height above ground is the TIN of the
chunk's ground points in the whole cloud's local frame: bit-identical wherever the ground
points around a point are.
"""
from __future__ import annotations

import math

import numpy as np

from ..crs import inputs_unit_to_metre as unit_to_metre_of  # noqa: F401 - importable from here as before
from ..errors import LidarfxError
from .processors import Processor

MIN_BUFFER = 50.0
"""Smallest default buffer (m)."""
BUFFER_WINDOWS = 4.0
"""The default buffer in largest opening windows (``window``)."""

_PARAMS = ("cell", "slope", "window", "threshold", "scalar", "edge_step", "edge_share")


def ground_options(params: dict, *, ignore_classes, hag: bool, inputs=None) -> dict:
    """The JSON-able options of a chunked ``ground`` run from the SMRF parameters (``last_returns``
    included) and the ignored classes; ``inputs`` (the run's inputs) gives ``unit_to_metre``,
    the metres per coordinate unit of the first input's CRS (the buffer is in coordinate units)."""
    from ..ground import DEFAULTS

    o = {k: float(params.get(k, DEFAULTS[k])) for k in _PARAMS}
    o["last_returns"] = bool(params.get("last_returns", True))
    o["ignore_classes"] = [int(c) for c in (ignore_classes or [])]
    o["hag"] = bool(hag)
    if inputs is not None:
        o["unit_to_metre"] = unit_to_metre_of(inputs)
    return o


def ground_buffer(o: dict, density: float) -> tuple[float, bool]:
    """Four times the largest opening window rounded up to 50 m (100 m for the default 21 m),
    at least :data:`MIN_BUFFER` (not exact: the filter has no bounded reach); in coordinate
    units (``unit_to_metre``).  Measured (docs/scaling.md): on the steep ISPRS sample 53 in
    chunks of 100 m, a 50 m buffer left 0.47 % of the points in another class than the
    in-memory run, 90 m 0.17 %, 100 m 0.05 %."""
    from ..ground import DEFAULTS

    w = float(o.get("window", DEFAULTS["window"]))
    metres = max(MIN_BUFFER, 50.0 * math.ceil(BUFFER_WINDOWS * w / 50.0))
    u = float(o.get("unit_to_metre") or 1.0)
    return float(f"{metres / u:.3g}") if u != 1.0 else metres, False


def check_ground_options(o: dict) -> None:
    """The in-memory run's checks of the SMRF parameters and the ignored classes."""
    from ..ground import DEFAULTS, check_params, check_ignore_classes

    unknown = set(o) - set(_PARAMS) - {"last_returns", "ignore_classes", "hag", "unit_to_metre"}
    if unknown:
        raise LidarfxError(f"unknown ground options: {', '.join(sorted(unknown))}")
    p = {}
    for k in _PARAMS:
        v = o.get(k, DEFAULTS[k])
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise LidarfxError(f"{k} must be a number, got {v!r}")
        p[k] = float(v)
    check_params(p)
    check_ignore_classes(o.get("ignore_classes", []))
    u = o.get("unit_to_metre", 1.0)
    if isinstance(u, bool) or not isinstance(u, (int, float)) or not (math.isfinite(u) and u > 0):
        raise LidarfxError(f"unit_to_metre must be a positive number, got {u!r}")


def ground_process(chunk, ctx, o: dict):
    """The owned points with ``classification`` 2 / 1 (ignored classes kept) and, with ``hag``,
    ``height_above_ground``."""
    from ..ground import DEFAULTS, apply_ground_classification, classify_ground
    from ..surface.tin import TIN_TILE_POINTS, tin_interpolate

    cloud, own = chunk.cloud, chunk.own
    params = {k: float(o.get(k, DEFAULTS[k])) for k in _PARAMS}
    ign = list(o.get("ignore_classes", []))
    origin = np.asarray(ctx.mins, dtype=np.float64)
    mask = classify_ground(cloud, ignore_classes=ign, last_returns=bool(o.get("last_returns", True)),
                           progress=False, origin=origin, **params)
    result = apply_ground_classification(cloud.subset(own), mask[own], ignore_classes=ign, **params)
    result.meta.pop("source", None)
    result.meta.pop("ground", None)  # its count is the chunk's
    if o.get("hag"):
        # as height_above_ground: the TIN of the ground points in the frame of the whole cloud's
        # minimum (the same local coordinates, so the same triangles give the same bits)
        local = cloud.xyz - origin
        if mask.any():
            surf = tin_interpolate(local[mask, :2], local[mask, 2], local[own, :2], max_points=TIN_TILE_POINTS)
            hag = (local[own, 2] - surf).astype(np.float32)
        else:
            hag = np.full(int(own.sum()), np.nan, dtype=np.float32)
        result["height_above_ground"] = hag
    return result


PROCESSORS = {"ground": Processor(ground_buffer, ground_process, check_ground_options, identical=False,
                                  metres=True)}
