"""Connected components of a point set under a distance link (single-linkage clusters).

Two points belong to the same component when a chain of points joins them in
which every step is at most ``distance`` long (3-D); with per-point directions,
a step also needs the directions of its two points to lie within ``max_angle``
of each other (sign ignored: region growing by direction, so that crossing or
meeting lines stay apart).  The neighbour walk uses
the sorted column grid of :mod:`lidarfx.neighbors` with ``distance`` as the cell,
and a union-find merges the pairs as they are met: no pair list is ever built,
so a roof of 10⁶ points at 80 pts/m² costs memory for the points only.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..errors import LidarfxError
from ..neighbors import NeighborIndex, column_ranges, ring_buffer_size

__all__ = ["linked_components"]


@nb.njit(cache=True, inline="always")
def _find(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@nb.njit(cache=True)
def _link_kernel(pts, cstart, cend, ckey, table, nx, ny, cell, radius, nbuf, dirs, cos_min, parent):
    """Union-find over the pairs within ``radius``; with ``dirs`` (n, 3 unit vectors, rows in
    the order of ``pts``; an empty array for none) only pairs with |dᵢ·dⱼ| >= ``cos_min``."""
    n = pts.shape[0]
    use_dirs = dirs.shape[0] == n
    lo = np.empty(nbuf, np.int64)
    hi = np.empty(nbuf, np.int64)
    r2 = radius * radius
    for i in range(n):
        qx, qy, qz = pts[i, 0], pts[i, 1], pts[i, 2]
        nr = column_ranges(pts, cstart, cend, ckey, table, nx, ny, cell, qx, qy, qz, radius, radius, lo, hi)
        ri = _find(parent, i)
        for k in range(nr):
            for j in range(lo[k], hi[k]):
                if j <= i:
                    continue
                dx = pts[j, 0] - qx
                dy = pts[j, 1] - qy
                dz = pts[j, 2] - qz
                if dx * dx + dy * dy + dz * dz <= r2:
                    if use_dirs and abs(dirs[i, 0] * dirs[j, 0] + dirs[i, 1] * dirs[j, 1]
                                        + dirs[i, 2] * dirs[j, 2]) < cos_min:
                        continue
                    rj = _find(parent, j)
                    if rj != ri:
                        if rj < ri:  # the smaller root wins: the result does not depend on timing
                            parent[ri] = rj
                            ri = rj
                        else:
                            parent[rj] = ri
    for i in range(n):
        parent[i] = _find(parent, i)


def linked_components(xyz: np.ndarray, distance: float, directions: np.ndarray | None = None,
                      max_angle: float | None = None) -> np.ndarray:
    """Component id (0 … k−1) of every point: points closer than ``distance`` (3-D,
    inclusive) are linked, and components are the closure of the links.  Ids are
    numbered in the order of each component's first point in ``xyz``.

    ``directions`` (n, 3; e.g. the principal axes of the points' neighbourhoods) and
    ``max_angle`` (degrees, 0–90): two points are linked only when their directions
    also lie within ``max_angle`` of each other (axes: the sign does not matter)."""
    from ..errors import check_number

    xyz = np.asarray(xyz, dtype=np.float64)
    if not (distance > 0 and math.isfinite(distance)):
        raise LidarfxError(f"link distance must be a positive number of metres, got {distance!r}")
    n = len(xyz)
    if (directions is None) != (max_angle is None):
        raise LidarfxError("give both directions and max_angle, or neither")
    dirs = np.zeros((0, 3))
    cos_min = -1.0
    if directions is not None:
        cos_min = math.cos(math.radians(check_number("max_angle", max_angle, 0.0, 90.0))) - 1e-12  # 90°: all
        d = np.asarray(directions, dtype=np.float64)
        if d.shape != (n, 3):
            raise LidarfxError(f"directions must have shape ({n}, 3), got {d.shape}")
        norm = np.linalg.norm(d, axis=1)
        if not (np.isfinite(norm).all() and (norm > 0).all()):
            raise LidarfxError("directions must be finite non-zero vectors")
        dirs = d / norm[:, None]
    if n == 0:
        return np.zeros(0, np.int64)
    idx = NeighborIndex(xyz, cell=float(distance))
    g = idx.grid
    parent = np.arange(n, dtype=np.int64)
    if len(dirs):
        dirs = np.ascontiguousarray(dirs[idx.order])  # the kernel walks the index's sorted order
    _link_kernel(*g, float(distance), ring_buffer_size(float(distance), g.cell), dirs, cos_min, parent)
    root = np.empty(n, np.int64)
    root[idx.order] = idx.order[parent]  # roots as original indices
    _, first, inv = np.unique(root, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inv.ravel()]
