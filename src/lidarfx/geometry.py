"""Geometry shared by every module: orientations, frames, plane fits.

Conventions (docs/conventions.md): x = East, y = North, z = Up; angles in degrees.
Dip = angle of the plane from horizontal, dip direction = azimuth (clockwise
from North) of the down-dip direction, strike = dip direction − 90° (right-hand
rule).  Normals are flipped up before converting.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .errors import LidarfxError

EX = np.array([1.0, 0.0, 0.0])
EY = np.array([0.0, 1.0, 0.0])
EZ = np.array([0.0, 0.0, 1.0])


def unit(v: Any) -> np.ndarray:
    """``v`` scaled to length 1 (error on a zero vector)."""
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if n == 0:
        raise LidarfxError("zero-length direction vector")
    return v / n


def normal_from_dip(dip: Any, dip_direction: Any) -> np.ndarray:
    """Upward unit normal(s) ``(sin d sin a, sin d cos a, cos d)`` of planes given in degrees.

    Scalars give shape (3,), arrays give (n, 3).  Inverse of :func:`dip_from_normal`.
    """
    d = np.radians(np.asarray(dip, dtype=np.float64))
    a = np.radians(np.asarray(dip_direction, dtype=np.float64))
    return np.stack([np.sin(d) * np.sin(a), np.sin(d) * np.cos(a), np.cos(d)], axis=-1)


def dip_from_normal(normal: Any) -> tuple[Any, Any]:
    """``(dip, dip_direction)`` in degrees of the plane(s) with these normals (flipped up).

    One normal (3,) gives two floats; an (n, 3) array gives two arrays.  The
    dip direction of a horizontal plane is 0 by convention.
    """
    n = np.asarray(normal, dtype=np.float64)
    single = n.ndim == 1
    n = np.atleast_2d(n)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    if np.any(norm == 0):
        raise LidarfxError("zero-length normal")
    n = n / norm
    n = np.where(n[:, 2:3] < 0, -n, n) + 0.0  # + 0.0: a flipped -0.0 is 0.0 (atan2(-0, -0) = -180°)
    dip = np.degrees(np.arccos(np.clip(n[:, 2], -1.0, 1.0)))
    ddir = np.degrees(np.arctan2(n[:, 0], n[:, 1])) % 360.0
    ddir = np.where(ddir >= 360.0, 0.0, ddir)  # a tiny negative angle mod 360 rounds to 360.0
    if single:
        return float(dip[0]), float(ddir[0])
    return dip, ddir


def plane_basis(normal: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal right-handed ``(e1, e2, n)`` of a plane: ``e1`` strike, ``e2`` up-dip.

    ``e1`` is the horizontal strike direction (right-hand rule: azimuth = dip
    direction − 90°), ``e2 = n × e1`` lies in the plane pointing up-dip, and
    ``e1 × e2 = n``.  For a horizontal plane ``e1 = x``.
    """
    e1, e2, n = plane_bases(unit(normal)[None, :])
    return e1[0], e2[0], n[0]


def plane_bases(normals: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`plane_basis` of every row of an ``(n, 3)`` array of unit normals: ``(e1, e2, n)``."""
    n = np.asarray(normals, dtype=np.float64)
    h = np.cross(EZ, n)  # horizontal, perpendicular to n: the strike direction
    hn = np.linalg.norm(h, axis=1, keepdims=True)
    e1 = np.where(hn < 1e-12, EX, h / np.maximum(hn, 1e-300))
    e2 = np.cross(n, e1)
    return e1, e2, n


def perpendicular_frame(axis: Any) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane perpendicular to ``axis`` (first one horizontal if possible)."""
    d = unit(axis)
    h = np.cross(d, EZ)
    e1 = EX.copy() if np.linalg.norm(h) < 1e-9 else unit(h)
    e2 = np.cross(d, e1)
    return e1, e2


def fit_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares plane by PCA: ``(centroid, unit normal flipped up, eigenvalues λ1 ≥ λ2 ≥ λ3)``.

    The RMS distance of the points to the plane is ``sqrt(λ3)``.
    """
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 3:
        raise LidarfxError("a plane needs at least 3 points")
    c = p.mean(axis=0)
    w, v = np.linalg.eigh(np.cov((p - c).T, bias=True))
    n = v[:, 0]
    if n[2] < 0:
        n = -n
    return c, n, np.clip(w[::-1], 0.0, None)


def hull_area_in_plane(points: np.ndarray, normal: Any) -> float:
    """Area (m²) of the 2-D convex hull of ``points`` projected onto the plane with ``normal``."""
    p = np.asarray(points, dtype=np.float64)
    if len(p) < 3:
        return 0.0
    e1, e2, _ = plane_basis(normal)
    uv = np.c_[(p - p.mean(axis=0)) @ e1, (p - p.mean(axis=0)) @ e2]
    return float(group_hull_areas(uv, np.zeros(len(uv), np.int64))[0])


def group_hull_areas(xy: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Area (m²) of the 2-D convex hull of each group of points: ``groups`` holds ids
    0 … k−1 per point, the result one area per id (0 for fewer than three points or
    collinear ones).  Coordinates are taken relative to each group's first point."""
    from ._hullkernel import hull_areas

    xy = np.asarray(xy, dtype=np.float64)
    groups = np.asarray(groups, dtype=np.int64)
    if xy.ndim != 2 or xy.shape[1] < 2 or len(groups) != len(xy):
        raise LidarfxError("group_hull_areas needs (n, 2) coordinates and one group id per point")
    k = int(groups.max()) + 1 if len(groups) else 0
    order = np.lexsort((xy[:, 1], xy[:, 0], groups))
    g = groups[order]
    starts = np.searchsorted(g, np.arange(k), side="left")
    ends = np.searchsorted(g, np.arange(k), side="right")
    first = order[np.minimum(starts, max(len(order) - 1, 0))] if len(order) else order
    x = xy[order, 0] - xy[first, 0][g]
    y = xy[order, 1] - xy[first, 1][g]
    return hull_areas(x, y, starts.astype(np.int64), ends.astype(np.int64))


def ransac_plane(points: np.ndarray, threshold: float, *, iterations: int = 200, seed: int = 0,
                 alive: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The dominant plane of a small point set by MSAC: ``(centroid, unit normal flipped up,
    inlier mask)`` or ``None`` (fewer than 3 points).

    ``iterations`` random triples propose planes scored by Σ min(e², t²) (Torr &
    Zisserman 2000); the best one's inliers (distance ≤ ``threshold``) are refitted
    by PCA twice.  ``alive`` restricts the search to those points.  Meant for the
    few hundred to few thousand points around a line or a patch.
    """
    if not (threshold > 0 and math.isfinite(threshold)):
        raise LidarfxError(f"plane inlier distance must be a positive number, got {threshold!r}")
    p = np.asarray(points, dtype=np.float64)
    idx = np.flatnonzero(np.ones(len(p), bool) if alive is None else np.asarray(alive, bool))
    if len(idx) < 3:
        return None
    o = p[idx].mean(axis=0)
    q = p[idx] - o
    rng = np.random.default_rng(seed)
    tri = rng.integers(0, len(idx), size=(int(iterations), 3))
    a, b, c = q[tri[:, 0]], q[tri[:, 1]], q[tri[:, 2]]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-12
    if not ok.any():
        return None
    n = n[ok] / norm[ok, None]
    a = a[ok]
    t2 = threshold * threshold
    best, best_cost = 0, np.inf
    for h0 in range(0, len(n), 64):  # blocks bound the (hypotheses × points) matrix
        e = (q @ n[h0:h0 + 64].T) - (a[h0:h0 + 64] * n[h0:h0 + 64]).sum(axis=1)
        cost = np.minimum(e * e, t2).sum(axis=0)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best, best_cost = h0 + k, float(cost[k])
    normal, point = n[best], a[best]
    inl = np.zeros(len(p), bool)
    centroid = point + o
    for _ in range(2):
        d = np.abs((p[idx] - o - point) @ normal)
        sel = idx[d <= threshold]
        if len(sel) < 3:
            return None
        inl[:] = False
        inl[sel] = True
        centroid, normal, _ = fit_plane(p[sel] - o)
        point = centroid
        centroid = centroid + o
    d = np.abs((p[idx] - centroid) @ normal)
    inl[:] = False
    inl[idx[d <= threshold]] = True
    return centroid, normal, inl


def intersect_planes(c1: Any, n1: Any, c2: Any, n2: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """Line of two planes (point, normal each): ``(point nearest to the midpoint of c1 and c2,
    unit direction)``, or ``None`` for (nearly) parallel planes (< 1° apart)."""
    c1, n1, c2, n2 = (np.asarray(v, dtype=np.float64) for v in (c1, n1, c2, n2))
    n1, n2 = unit(n1), unit(n2)
    d = np.cross(n1, n2)
    s = float(np.linalg.norm(d))
    if s < math.sin(math.radians(1.0)):
        return None
    d = d / s
    # the point x minimising |x - m|² subject to n1·x = n1·c1, n2·x = n2·c2
    m = 0.5 * (c1 + c2)
    a = np.array([n1, n2, d])
    rhs = np.array([n1 @ c1, n2 @ c2, d @ m])
    return np.linalg.solve(a, rhs), d
