"""Ground classification (SMRF), DTM rasters, height above ground and filter accuracy.

Public API
----------
:func:`classify_ground`            bool mask of ground points (SMRF, Pingel et al. 2013)
:func:`apply_ground_classification` copy of a cloud with ``classification`` 2 / 1 set
:func:`dtm`                        DTM :class:`Raster` (TIN of the ground points)
:func:`height_above_ground`        z minus the ground surface under each point
:func:`ground_errors`              type I / type II / total error (Sithole & Vosselman 2004)

See ``docs/ground.md`` for the method, the parameters and their tuning.
"""
from __future__ import annotations

from typing import Any, Iterable

import numpy as np

from .. import progress as _progress
from ..cloud import PointCloud
from ..errors import LidarfxError
from ..crs import check_units, cloud_crs, unit_to_metre
from .dtm import dtm, height_above_ground
from .params import DEFAULTS
from .evaluate import ground_errors
from ..surface.raster import Raster

__all__ = [
    "DEFAULTS",
    "IGNORE_CLASSES",
    "classify_ground",
    "apply_ground_classification",
    "candidate_mask",
    "check_ignore_classes",
    "dtm",
    "height_above_ground",
    "ground_errors",
    "Raster",
    "cloud_crs",
]

IGNORE_CLASSES: tuple[int, ...] = (7, 18, 66)
"""Classes never used and never made ground: low noise 7, high noise 18, IGN virtual points 66."""

GROUND_CLASS = 2
NON_GROUND_CLASS = 1
MAX_CELLS = 400_000_000
MAX_CELLS_PER_POINT = 1000
"""Most grid cells per candidate point (beyond a million cells): real surveys have about one point
per cell, and a corridor across its bounding box a hundred cells per point; thousands mean a few
points scattered over kilometres (stray points, a damaged file) and a grid of gigabytes."""


def _xyz_attrs(cloud: Any) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    if isinstance(cloud, PointCloud):
        return cloud.xyz, cloud.attrs
    xyz = np.asarray(cloud, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise LidarfxError(f"expected a PointCloud or an (n, 3) array, got shape {xyz.shape}")
    return xyz, {}


def candidate_mask(
    cloud: Any, *, last_returns: bool = True, ignore_classes: Iterable[int] | None = IGNORE_CLASSES
) -> np.ndarray:
    """Points the filter uses: not in ``ignore_classes`` and, when return
    information is present (``return_number`` and ``number_of_returns`` both
    > 0), last returns only (``return_number == number_of_returns``)."""
    xyz, attrs = _xyz_attrs(cloud)
    cand = np.all(np.isfinite(xyz), axis=1)
    ign = check_ignore_classes(ignore_classes)
    if ign and "classification" in attrs:
        cand &= ~np.isin(attrs["classification"], ign)
    if last_returns and "return_number" in attrs and "number_of_returns" in attrs:
        rn = np.asarray(attrs["return_number"]).astype(np.int64)
        nr = np.asarray(attrs["number_of_returns"]).astype(np.int64)
        known = (rn > 0) & (nr > 0)
        cand &= ~known | (rn == nr)
    return cand


def check_params(p: dict[str, float]) -> None:
    for name in ("cell", "window"):
        if not (np.isfinite(p[name]) and p[name] > 0):
            raise LidarfxError(f"{name} must be a positive number, got {p[name]!r}")
    for name in ("slope", "threshold", "scalar", "edge_step", "edge_share"):
        if not (np.isfinite(p[name]) and p[name] >= 0):
            raise LidarfxError(f"{name} must be a non-negative number, got {p[name]!r}")
    if p["edge_share"] > 1:
        raise LidarfxError(f"edge_share is a share of the boundary from 0 to 1 (0 = off), got {p['edge_share']!r}")


def check_ignore_classes(classes: Iterable[int] | None) -> list[int]:
    """``ignore_classes`` as a list of class codes 0..255 (``None`` = none)."""
    if classes is None:
        return []
    if isinstance(classes, (str, bytes)):
        raise LidarfxError(f"ignore_classes must be class codes from 0 to 255, got {classes!r}")
    try:
        values = list(classes)
    except TypeError:
        raise LidarfxError(f"ignore_classes must be class codes from 0 to 255, got {classes!r}") from None
    out = []
    for c in values:
        try:
            ok = not isinstance(c, (bool, np.bool_)) and int(c) == c and 0 <= int(c) <= 255
        except (TypeError, ValueError, OverflowError):
            ok = False
        if not ok:
            raise LidarfxError(f"ignore_classes must be class codes from 0 to 255, got {c!r}")
        out.append(int(c))
    return out


def classify_ground(
    cloud: Any,
    *,
    cell: float = DEFAULTS["cell"],
    slope: float = DEFAULTS["slope"],
    window: float = DEFAULTS["window"],
    threshold: float = DEFAULTS["threshold"],
    scalar: float = DEFAULTS["scalar"],
    edge_step: float = DEFAULTS["edge_step"],
    edge_share: float = DEFAULTS["edge_share"],
    last_returns: bool = True,
    ignore_classes: Iterable[int] | None = IGNORE_CLASSES,
    units: str = "auto",
    progress: bool | None = None,
    origin: Any = None,
) -> np.ndarray:
    """Ground mask of an ALS point cloud by SMRF (Pingel, Clarke & McBride 2013).

    Parameters
    ----------
    cloud:
        :class:`~lidarfx.PointCloud` or an ``(n, 3)`` array of coordinates.
    cell, slope, window, threshold, scalar, edge_step, edge_share:
        SMRF parameters, defaults :data:`DEFAULTS` (see docs/ground.md).
    last_returns:
        Use only last returns where return information exists; other returns
        are never ground.
    ignore_classes:
        Classes (of an existing ``classification``) that are neither used nor
        made ground; default :data:`IGNORE_CLASSES` (noise 7, 18; virtual 66).
    units:
        ``"auto"``: the lengths ``cell``, ``window``, ``threshold``, ``scalar``
        and ``edge_step`` are metres and are converted to the coordinate unit
        when the LAS header's CRS names another linear unit (e.g. US feet);
        ``"native"``: they are in coordinate units as given.
    progress:
        Progress bar: ``True``/``False``, or ``None`` for large clouds on a terminal.
    origin:
        ``None``: the filter's grid starts at the candidates' minimum x, y (and z).
        An ``(x, y, z)`` point: the grid's cells are those of a grid that starts there
        (a chunk of a larger cloud filtered with that cloud's origin, lidarfx.tiles).

    Returns
    -------
    numpy.ndarray
        Boolean mask, ``True`` = ground.
    """
    from ..surface.grid import GridSpec
    from .smrf import smrf, window_radius

    params = {"cell": float(cell), "slope": float(slope), "window": float(window),
              "threshold": float(threshold), "scalar": float(scalar),
              "edge_step": float(edge_step), "edge_share": float(edge_share)}
    check_params(params)
    if check_units(units) == "auto" and isinstance(cloud, PointCloud):
        u = unit_to_metre(cloud)
        if abs(u - 1.0) > 1e-9:
            for name in ("cell", "window", "threshold", "scalar", "edge_step"):
                params[name] /= u
    cell = params["cell"]
    window = params["window"]
    xyz, _ = _xyz_attrs(cloud)
    cand = candidate_mask(cloud, last_returns=last_returns, ignore_classes=ignore_classes)
    mask = np.zeros(len(xyz), dtype=bool)
    idx = np.nonzero(cand)[0]
    if len(idx) == 0:
        return mask
    local = xyz[idx]  # a copy (fancy indexing), made local in place
    offset = (0, 0)
    if origin is None:
        local -= local.min(axis=0)
    else:  # cells aligned to the origin's grid, (row, column) offset of this grid's first cell
        o = np.asarray(origin, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(o)):
            raise LidarfxError(f"origin must be a finite point (x, y, z), got {origin!r}")
        k = np.floor((local[:, :2].min(axis=0) - o[:2]) / cell)
        local -= o
        local[:, :2] -= k * cell
        offset = (int(k[1]), int(k[0]))
    ext = local.max(axis=0)
    cells = (ext[0] / cell + 1) * (ext[1] / cell + 1)
    if cells > MAX_CELLS:
        raise LidarfxError(
            f"the cloud spans {ext[0]:g} x {ext[1]:g} m: {cells:.3g} cells of {cell:g} m is too many; "
            "cut it into tiles or use a larger cell"
        )
    if cells > MAX_CELLS_PER_POINT * len(idx) + 1_000_000:  # a grid of gigabytes for a few points
        raise LidarfxError(
            f"the {len(idx):,} points spread over {ext[0]:g} x {ext[1]:g} m: {cells:.3g} cells of {cell:g} m, "
            f"more than {MAX_CELLS_PER_POINT:,} per point; crop the cloud or remove stray points far from the rest"
        )
    spec = GridSpec(local[:, :2], cell)
    radius = window_radius(window, cell, spec.nx, spec.ny)
    with _progress.bar("ground (SMRF)", radius, _progress.wanted(progress)) as advance:
        ground, _ = smrf(local, advance=advance, offset=offset, **params)
    mask[idx] = ground
    return mask


def apply_ground_classification(
    cloud: PointCloud,
    ground: np.ndarray | None = None,
    *,
    ignore_classes: Iterable[int] | None = IGNORE_CLASSES,
    **params: Any,
) -> PointCloud:
    """A copy of ``cloud`` with ``classification`` set from the ground filter.

    Ground points get class 2; every other point gets class 1 (unclassified),
    except points whose existing class is in ``ignore_classes`` (noise 7/18
    and virtual points 66 by default), which keep it.  Any other earlier class
    (including an old 2) is overwritten.  ``ground`` is a precomputed mask;
    otherwise :func:`classify_ground` runs with ``ignore_classes`` and
    ``**params`` (with a precomputed mask, ``**params`` only documents how it
    was made).  The parameters go to ``meta["ground"]``.
    """
    if not isinstance(cloud, PointCloud):
        raise LidarfxError("apply_ground_classification needs a PointCloud")
    ign = check_ignore_classes(ignore_classes)  # before the filter runs
    if ground is None:
        ground = classify_ground(cloud, ignore_classes=ignore_classes, **params)
    params = {k: v for k, v in params.items() if k in DEFAULTS}
    ground = np.asarray(ground, dtype=bool)
    if ground.shape != (len(cloud),):
        raise LidarfxError(f"ground mask must have length {len(cloud)}")
    out = cloud.copy()
    old = out.get("classification")
    dtype = old.dtype if old is not None else np.uint8
    cls = np.full(len(out), NON_GROUND_CLASS, dtype=dtype)
    if old is not None and ign:
        keep = np.isin(old, ign)
        cls[keep] = old[keep]
    cls[ground] = GROUND_CLASS
    out["classification"] = cls
    used = {**DEFAULTS, **{k: float(v) for k, v in params.items() if k in DEFAULTS}}
    out.meta = {**out.meta, "ground": {"method": "smrf", **used, "ignore_classes": ign,
                                       "ground_points": int(ground.sum())}}
    return out
