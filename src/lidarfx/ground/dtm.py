"""Digital terrain model raster and height above ground from ground points."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..cloud import PointCloud
from ..crs import cloud_crs
from ..errors import LidarfxError
from ..surface.raster import Raster, grid_layout
from ..surface.tin import TIN_TILE_POINTS, tin_interpolate

__all__ = ["dtm", "height_above_ground", "ground_mask_of"]

GROUND_CLASS = 2


def ground_mask_of(cloud: PointCloud, ground: Any = None) -> np.ndarray:
    """The ground mask: ``ground`` itself (bool, length n) or ``classification == 2``."""
    if ground is None:
        if "classification" not in cloud:
            raise LidarfxError(
                "no ground given and the cloud has no classification; "
                "run classify_ground (lidarfx ground) first or pass a ground mask"
            )
        return np.asarray(cloud["classification"]) == GROUND_CLASS
    mask = np.asarray(ground)
    if mask.dtype != bool or mask.shape != (len(cloud),):
        raise LidarfxError(f"ground must be a boolean mask of length {len(cloud)}, got {mask.dtype} {mask.shape}")
    return mask


MAX_CELLS = 400_000_000
"""Largest DTM (cells) :func:`dtm` makes."""

MAX_RESOLUTION = 1e9
"""Largest DTM cell (map units) :func:`dtm` accepts."""


def check_resolution(resolution: Any) -> None:
    """Refuse a DTM cell size that is not a positive number up to :data:`MAX_RESOLUTION`."""
    try:
        ok = float(resolution) > 0 and math.isfinite(float(resolution))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise LidarfxError(f"resolution must be a positive number, got {resolution!r}")
    if float(resolution) > MAX_RESOLUTION:  # squared distances to such cell centres overflow
        raise LidarfxError(f"resolution {resolution:g} is larger than any survey (at most {MAX_RESOLUTION:g} map units)")


def _as_cloud(source: Any) -> tuple[np.ndarray, np.ndarray | None, PointCloud | None]:
    if isinstance(source, PointCloud):
        return source.xyz, None, source
    arr = np.asarray(source, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise LidarfxError(f"expected a PointCloud or an (n, 3) array of ground points, got shape {arr.shape}")
    return arr, np.ones(len(arr), dtype=bool), None


def dtm(
    source: Any,
    resolution: float = 1.0,
    *,
    ground: Any = None,
    bounds: tuple[float, float, float, float] | None = None,
    crs: dict[str, Any] | None = None,
    units: str = "auto",
) -> Raster:
    """DTM raster by linear (TIN) interpolation of the ground points at the cell centres.

    Parameters
    ----------
    source:
        A :class:`~lidarfx.PointCloud` (ground = ``ground`` mask, default its
        class 2 points; the raster covers the whole cloud) or an ``(n, 3)``
        array that holds ground points only (the raster covers them).
    resolution:
        Cell edge (default 1.0): metres for a PointCloud source, converted to the map unit
        when its LAS CRS names another linear unit (US survey feet, feet; ``units="native"``:
        map units as given); map units for an array source (it has no CRS).
    ground:
        Boolean ground mask for a PointCloud source.
    bounds:
        ``(xmin, ymin, xmax, ymax)`` to cover instead of the points' extent.
    crs:
        CRS dict (``wkt``/``epsg``) for the raster; default: from the LAS header.

    Returns
    -------
    Raster
        Grid aligned to multiples of ``resolution`` (so adjacent tiles line
        up), row 0 = north; ``Raster.resolution`` is in map units.  A cell is the TIN height at its centre; cells
        outside the convex hull of the ground points take the height of the
        nearest ground point (so every cell has a value).
    """
    check_resolution(resolution)
    xyz, mask, cloud = _as_cloud(source)
    if cloud is not None:
        from ..crs import length_to_units

        resolution = length_to_units(cloud, float(resolution), units)  # metres -> map units
        mask = ground_mask_of(cloud, ground)
        if crs is None:
            crs = cloud_crs(cloud)
    assert mask is not None
    finite = np.isfinite(xyz).all(axis=1)  # points with NaN / infinite coordinates are left out
    g = xyz[mask & finite]
    if len(g) == 0:
        raise LidarfxError("no ground points: cannot build a DTM (classify the ground first)")
    if bounds is None:
        lo = xyz[finite].min(axis=0)[:2]
        hi = xyz[finite].max(axis=0)[:2]
    else:
        lo = np.array(bounds[:2], dtype=np.float64)
        hi = np.array(bounds[2:], dtype=np.float64)
        if not np.all(hi >= lo):
            raise LidarfxError(f"bounds must be (xmin, ymin, xmax, ymax), got {bounds!r}")
    r = float(resolution)
    x0, y0, rows, cols = grid_layout(lo, hi, r, max_cells=MAX_CELLS, what="DTM")
    ytop = y0 + rows * r
    # local frame: origin at the south-west corner of the grid
    cx = (np.arange(cols) + 0.5) * r
    cy = ytop - y0 - (np.arange(rows) + 0.5) * r  # row 0 = north
    qx, qy = np.meshgrid(cx, cy)
    zref = float(g[:, 2].min())
    vals = tin_interpolate(
        np.column_stack([g[:, 0] - x0, g[:, 1] - y0]),
        g[:, 2] - zref,
        np.column_stack([qx.ravel(), qy.ravel()]),
        max_points=TIN_TILE_POINTS,
    )
    array = (vals + zref).reshape(rows, cols).astype(np.float32)
    return Raster(array, (x0, ytop), r, crs, meta={"ground_points": int(len(g)), "method": "tin"})


def height_above_ground(cloud: Any, ground: Any = None) -> np.ndarray:
    """Height of every point above the ground surface under it (float32, metres).

    Parameters
    ----------
    cloud:
        A :class:`~lidarfx.PointCloud` (or an ``(n, 3)`` array, then
        ``ground`` must be given).
    ground:
        ``None`` → the cloud's class 2 points; a boolean mask of ground points;
        or a :class:`Raster` DTM (sampled bilinearly).

    The ground surface is the Delaunay TIN of the ground points (linear
    interpolation in the triangle under the point); outside the convex hull of
    the ground points the nearest ground point's height is used.  Ground
    points themselves get ≈ 0.  NaN everywhere when there is no ground point, and
    NaN for points with NaN or infinite coordinates (they are never ground).
    """
    if isinstance(cloud, PointCloud):
        xyz = cloud.xyz
    else:
        xyz = np.asarray(cloud, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise LidarfxError(f"expected a PointCloud or an (n, 3) array, got shape {xyz.shape}")
        if ground is None:
            raise LidarfxError("height_above_ground of a bare array needs a ground mask or a DTM raster")
    if isinstance(ground, Raster):
        return (xyz[:, 2] - ground.sample(xyz[:, 0], xyz[:, 1])).astype(np.float32)
    if isinstance(cloud, PointCloud):
        mask = ground_mask_of(cloud, ground)
    else:
        mask = np.asarray(ground)
        if mask.dtype != bool or mask.shape != (len(xyz),):
            raise LidarfxError(f"ground must be a boolean mask of length {len(xyz)}")
    finite = np.isfinite(xyz).all(axis=1)
    mask = mask & finite
    if not mask.any():
        return np.full(len(xyz), np.nan, dtype=np.float32)
    if finite.all():
        local = xyz - xyz.min(axis=0)
        surf = tin_interpolate(local[mask, :2], local[mask, 2], local[:, :2], max_points=TIN_TILE_POINTS)
        return (local[:, 2] - surf).astype(np.float32)
    out = np.full(len(xyz), np.nan, dtype=np.float32)
    out[finite] = height_above_ground(xyz[finite], ground=mask[finite])
    return out
