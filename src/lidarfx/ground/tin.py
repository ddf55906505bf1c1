"""Linear interpolation on a Delaunay TIN with a fast point location.

``scipy.spatial.Delaunay.find_simplex`` walks from an arbitrary start for
every query and becomes very slow for hundreds of thousands of queries.  Here
each walk starts at a triangle of the query's nearest vertex (one k-d tree
query), so it is a few steps long.
"""
from __future__ import annotations

import numba as nb
import numpy as np
from scipy.spatial import Delaunay, QhullError, cKDTree

__all__ = ["tin_interpolate"]


@nb.njit(cache=True)
def _walk(px, py, simp, neigh, vals, qx, qy, start, max_steps, out):
    n = qx.shape[0]
    for k in range(n):
        t = start[k]
        x = qx[k]
        y = qy[k]
        out[k] = np.nan
        rot = k
        for _ in range(max_steps):  # a query outside the hull and collinear with a hull
            # edge can circle a hull corner for ever: give up (NaN -> nearest)
            a = simp[t, 0]
            b = simp[t, 1]
            c = simp[t, 2]
            xa = px[a]
            ya = py[a]
            xb = px[b]
            yb = py[b]
            xc = px[c]
            yc = py[c]
            det = (yb - yc) * (xa - xc) + (xc - xb) * (ya - yc)
            if det == 0.0:
                break
            l0 = ((yb - yc) * (x - xc) + (xc - xb) * (y - yc)) / det
            l1 = ((yc - ya) * (x - xc) + (xa - xc) * (y - yc)) / det
            l2 = 1.0 - l0 - l1
            if l0 >= -1e-12 and l1 >= -1e-12 and l2 >= -1e-12:
                out[k] = l0 * vals[a] + l1 * vals[b] + l2 * vals[c]
                break
            # stochastic visibility walk: cross the first edge (from a rotating
            # start) whose opposite coordinate is negative; it terminates even
            # on degenerate (cocircular) triangulations
            rot = (rot * 1103515245 + 12345) & 0x7FFFFFFF  # tiny LCG
            e = -1
            for s in range(3):
                q = ((rot >> 16) + s) % 3
                lq = l0 if q == 0 else (l1 if q == 1 else l2)
                if lq < -1e-12:
                    e = q
                    break
            nt = neigh[t, e]
            if nt < 0:
                break  # outside the convex hull
            t = nt


def tin_interpolate(xy: np.ndarray, values: np.ndarray, query: np.ndarray, *, nearest_outside: bool = True, joggle: bool = False
) -> np.ndarray:
    """Linear (TIN) interpolation of ``values`` known at ``xy`` (n×2) at ``query`` (m×2).

    Queries outside the convex hull get the value of the nearest known point
    when ``nearest_outside`` (else NaN).  Fewer than 3 points or collinear
    points fall back to the nearest value everywhere.  Coordinates should be
    local (small numbers) for accuracy.  ``joggle`` triangulates with
    Qhull's ``QJ`` option: about twice as fast on regular grids (many
    cocircular points), for inputs without duplicate xy.
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    values = np.ascontiguousarray(values, dtype=np.float64)
    query = np.ascontiguousarray(query, dtype=np.float64)
    out = np.full(len(query), np.nan)
    if len(xy) == 0 or len(query) == 0:
        return out
    tree = cKDTree(xy)
    _, nn = tree.query(query)
    tri = None
    if len(xy) >= 3:
        try:
            tri = Delaunay(xy, qhull_options="Qbb Qc Qz Q12 QJ" if joggle else None)
        except (QhullError, ValueError):
            tri = None
    if tri is not None and len(tri.simplices):
        v2s = tri.vertex_to_simplex.astype(np.int64)
        if len(tri.coplanar):  # duplicate / coplanar points: start at the facet they fell into
            v2s[tri.coplanar[:, 0]] = tri.coplanar[:, 1]
        start = v2s[nn]
        start[start < 0] = 0
        max_steps = 200 + 4 * int(np.sqrt(len(tri.simplices)))
        _walk(
            np.ascontiguousarray(tri.points[:, 0]),
            np.ascontiguousarray(tri.points[:, 1]),
            tri.simplices.astype(np.int64),
            tri.neighbors.astype(np.int64),
            values,
            query[:, 0].copy(),
            query[:, 1].copy(),
            start,
            max_steps,
            out,
        )
    if nearest_outside:
        bad = ~np.isfinite(out)
        out[bad] = values[nn[bad]]
    return out
