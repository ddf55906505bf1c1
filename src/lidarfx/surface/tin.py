"""Linear interpolation on a Delaunay TIN with a fast point location.

``scipy.spatial.Delaunay.find_simplex`` walks from an arbitrary start for
every query and becomes very slow for hundreds of thousands of queries.  Here
each walk starts at a triangle of the query's nearest vertex (one k-d tree
query), so it is a few steps long.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numba as nb
import numpy as np
from scipy.spatial import ConvexHull, Delaunay, QhullError, cKDTree

__all__ = ["tin_interpolate", "TIN_TILE_POINTS", "TIN_TILE_WORKERS"]

TIN_TILE_POINTS = 4_000_000
"""With ``max_points``, more known points than this are triangulated tile by tile (bounded memory:
Qhull needs about 0.6 kB per point)."""

TIN_TILE_WORKERS = max(1, min(2, int(nb.config.NUMBA_NUM_THREADS)))
"""Tiles triangulated at the same time (threads: Qhull and the walk release the GIL): 2, or 1 when
numba may use one thread only (one core, or ``NUMBA_NUM_THREADS=1``).  The tiles hold about
``max_points / 4`` points each, so two at a time hold what one tile of ``max_points / 2`` would; the
results do not depend on the number of threads."""


@nb.njit(cache=True, inline="always")
def _bary(px, py, a, b, c, x, y):
    """Barycentric coordinates (l0, l1) of (x, y) in triangle a, b, c and the determinant (0: flat)."""
    xa = px[a]
    ya = py[a]
    xb = px[b]
    yb = py[b]
    xc = px[c]
    yc = py[c]
    det = (yb - yc) * (xa - xc) + (xc - xb) * (ya - yc)
    if det == 0.0:
        return 0.0, 0.0, det
    l0 = ((yb - yc) * (x - xc) + (xc - xb) * (y - yc)) / det
    l1 = ((yc - ya) * (x - xc) + (xa - xc) * (y - yc)) / det
    return l0, l1, det


@nb.njit(cache=True, nogil=True)
def _walk(px, py, simp, neigh, vals, qx, qy, start, max_steps, out, found):
    n = qx.shape[0]
    for k in range(n):
        t = start[k]
        x = qx[k]
        y = qy[k]
        out[k] = np.nan
        found[k] = -1
        rot = k
        for _ in range(max_steps):  # a query outside the hull and collinear with a hull
            # edge can circle a hull corner for ever: give up (NaN -> nearest)
            a = simp[t, 0]
            b = simp[t, 1]
            c = simp[t, 2]
            l0, l1, det = _bary(px, py, a, b, c, x, y)
            if det == 0.0:
                break
            l2 = 1.0 - l0 - l1
            if l0 >= -1e-12 and l1 >= -1e-12 and l2 >= -1e-12:
                # the value from the vertices in index order: the same triangle then gives the
                # same bits whatever order the triangulation lists it in (tiles, see tin_interpolate)
                if a > b:
                    a, b = b, a
                if b > c:
                    b, c = c, b
                if a > b:
                    a, b = b, a
                l0, l1, det = _bary(px, py, a, b, c, x, y)
                out[k] = l0 * vals[a] + l1 * vals[b] + (1.0 - l0 - l1) * vals[c]
                found[k] = t
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


def tin_interpolate(xy: np.ndarray, values: np.ndarray, query: np.ndarray, *, nearest_outside: bool = True,
                    max_points: int | None = None, workers: int | None = None) -> np.ndarray:
    """Linear (TIN) interpolation of ``values`` known at ``xy`` (n×2) at ``query`` (m×2).

    Queries outside the convex hull get the value of the nearest known point
    when ``nearest_outside`` (else NaN).  Fewer than 3 points or collinear
    points fall back to the nearest value everywhere.  Coordinates should be
    local (small numbers) for accuracy.  Regular grids, with their many
    cocircular points, are better jittered first (:func:`lidarfx.surface.grid.inpaint`):
    Qhull is then about twice as fast and the triangulation unique.

    ``max_points``: with more known points than this, the queries are answered
    tile by tile from the Delaunay triangulation of the known points in the tile
    and a margin (bounded memory).  A query's answer is accepted only when it is
    provably the one of the whole triangulation: the circumcircle of its triangle
    lies inside the triangulated area (so the triangle is Delaunay for all points),
    or, outside the convex hull of all points, the circle through its nearest
    point does (only the part of a circle inside the extent of all points
    counts).  Other queries are retried on a larger area that holds the circles
    they need; the last resort is all points.  The result
    equals the one-piece interpolation, except where four or more known points lie
    on one circle: there both triangulations are valid and may split differently.
    ``workers`` tiles are triangulated at the same time in threads (default
    :data:`TIN_TILE_WORKERS`); the tiling, and so the result, does not depend on it.
    """
    xy = np.ascontiguousarray(xy, dtype=np.float64)
    values = np.ascontiguousarray(values, dtype=np.float64)
    query = np.ascontiguousarray(query, dtype=np.float64)
    if max_points is not None and len(xy) > max(int(max_points), 3) and len(query):
        return _tin_tiled(xy, values, query, nearest_outside, int(max_points),
                          TIN_TILE_WORKERS if workers is None else max(int(workers), 1))
    return _tin_one(xy, values, query, nearest_outside)[0]


def _tin_one(xy: np.ndarray, values: np.ndarray, query: np.ndarray, nearest_outside: bool,
             box: tuple[float, float, float, float] | None = None, hull: tuple | None = None,
             extent: tuple[np.ndarray, np.ndarray] | None = None,
             ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """One triangulation.  With ``box`` (x0, y0, x1, y1: the area whose known points are all in
    ``xy``) also a mask of the answers that equal the whole triangulation's (see
    :func:`tin_interpolate`) and, per query, the box (x0, y0, x1, y1) an answer would need
    (the bounding box of its circle, cut to ``extent`` = (lo, hi) of all points: no point lies
    beyond); ``hull``: the convex hull of all points (:func:`_hull_of`)."""
    out = np.full(len(query), np.nan)
    need = np.column_stack([query, query]) if box is not None else None
    if len(xy) == 0 or len(query) == 0:
        return out, (np.zeros(len(query), bool) if box is not None else None), need
    tree = cKDTree(xy)
    dist, nn = tree.query(query)
    tri = None
    if len(xy) >= 3:
        tri = _delaunay(xy)
    found = np.full(len(query), -1, dtype=np.int64)
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
            found,
        )
    bad = ~np.isfinite(out)
    if nearest_outside:
        out[bad] = values[nn[bad]]
    if box is None:
        return out, None, None
    x0, y0, x1, y1 = box
    # a circle (centre, radius) per query: its triangle's circumcircle, or (outside every triangle)
    # the circle through the nearest point, which decides the answer outside the hull of all points
    cx, cy = query[:, 0].copy(), query[:, 1].copy()
    r = dist * (1 + 1e-9) + 1e-9
    hit = np.flatnonzero(found >= 0)
    if len(hit):
        p = tri.points[tri.simplices[found[hit]]]  # (h, 3, 2)
        ax, ay, bx, by, qx, qy = p[:, 0, 0], p[:, 0, 1], p[:, 1, 0], p[:, 1, 1], p[:, 2, 0], p[:, 2, 1]
        d = 2.0 * (ax * (by - qy) + bx * (qy - ay) + qx * (ay - by))
        with np.errstate(divide="ignore", invalid="ignore"):
            a2, b2, c2 = ax * ax + ay * ay, bx * bx + by * by, qx * qx + qy * qy
            ux = (a2 * (by - qy) + b2 * (qy - ay) + c2 * (ay - by)) / d
            uy = (a2 * (qx - bx) + b2 * (ax - qx) + c2 * (bx - ax)) / d
            rr = np.hypot(ax - ux, ay - uy) * (1 + 1e-9) + 1e-9
        good = np.isfinite(rr)
        cx[hit[good]], cy[hit[good]], r[hit[good]] = ux[good], uy[good], rr[good]
    if extent is None:
        need = np.column_stack([cx - r, cy - r, cx + r, cy + r])
    else:  # only the part of the circle inside the extent matters (slivers along a straight edge of
        # the data have huge circles that reach little but empty space): a box around circle ∩ extent
        (ex0, ey0), (ex1, ey1) = extent
        hx = np.sqrt(np.maximum(r * r - (np.clip(cy, ey0, ey1) - cy) ** 2, 0.0))  # widest chord in the y band
        hy = np.sqrt(np.maximum(r * r - (np.clip(cx, ex0, ex1) - cx) ** 2, 0.0))
        need = np.column_stack([np.maximum(cx - hx, ex0), np.maximum(cy - hy, ey0),
                                np.minimum(cx + hx, ex1), np.minimum(cy + hy, ey1)])
    inside = (need[:, 0] >= x0) & (need[:, 1] >= y0) & (need[:, 2] <= x1) & (need[:, 3] <= y1)
    ok = np.zeros(len(query), dtype=bool)
    ok[hit] = inside[hit]
    if hull is not None and nearest_outside:
        miss = np.flatnonzero(bad)
        miss = miss[_outside_hull(hull, query[miss])]  # outside all points: the nearest one decides
        ok[miss] = inside[miss]
    return out, ok, need


_THIN_ROWS = 8.0
"""A point set fewer than about this many mean spacings wide across its main axis is *thin*."""


def _delaunay(xy: np.ndarray) -> Delaunay | None:
    """The Delaunay triangulation of ``xy`` (n×2, n >= 3), None when Qhull finds none (collinear).

    A thin set (a strip a few rows wide, e.g. 10 km of two scan rows 1 mm apart) makes Qhull's
    default facet merging quadratic: minutes for 40 000 points.  Such a set is triangulated without
    premerging (Qhull option ``Q0``: under a second), and with the default options only if that
    fails on a precision problem."""
    if len(xy) > 16:
        c = xy - xy.mean(axis=0)
        _, vec = np.linalg.eigh(c.T @ c)
        width, length = np.ptp(c @ vec, axis=0)  # ascending eigenvalues: minor axis first
        if np.isfinite(length) and len(xy) * width < _THIN_ROWS ** 2 * length:
            try:
                return Delaunay(xy, qhull_options="Qbb Qc Qz Q12 Q0")
            except (QhullError, ValueError):
                pass
    try:
        return Delaunay(xy)
    except (QhullError, ValueError):
        return None


def _hull_of(xy: np.ndarray) -> tuple | None:
    """Edges (a, b, c: a x + b y + c <= 0 inside) and coordinate scale of the convex hull of ``xy``;
    None when the hull is degenerate."""
    try:
        hull = ConvexHull(xy)
    except (QhullError, ValueError):
        return None
    return hull.equations, float(np.abs(xy).max()) + 1.0


def _outside_hull(hull: tuple | None, query: np.ndarray) -> np.ndarray:
    """Queries strictly outside the hull (all False for a degenerate hull)."""
    out = np.zeros(len(query), dtype=bool)
    if hull is None or not len(query):
        return out
    eq, scale = hull
    for a, b, c in eq:
        out |= a * query[:, 0] + b * query[:, 1] + c > 1e-9 * scale
    return out


_FEW = 64  # when at most this many queries of a tile are left, they are retried on the area they need


def _tin_tiled(xy: np.ndarray, values: np.ndarray, query: np.ndarray, nearest_outside: bool,
               max_points: int, workers: int = 1) -> np.ndarray:
    out = np.full(len(query), np.nan)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    area = max(float(np.prod(np.maximum(hi - lo, 1e-9))), 1e-12)
    # ~ max_points / 4 known points per tile: two tiles at a time (TIN_TILE_WORKERS) hold about as many
    # points as one tile of max_points / 2 would.  The tiling does not depend on ``workers``, so neither
    # does the result (ties between cocircular points are split by the tile's triangulation)
    side = max(float(np.sqrt(area * max_points / (4.0 * len(xy)))), 1e-6)
    hull = _hull_of(xy)
    qlo = query.min(axis=0)
    tij = np.floor((query - qlo) / side).astype(np.int64)
    key = tij[:, 0] * (int(tij[:, 1].max()) + 1) + tij[:, 1]
    order = np.argsort(key, kind="stable")

    def tile(todo: np.ndarray) -> None:  # writes only out[todo]: tiles may run at the same time
        x0, y0 = qlo + tij[todo[0]] * side
        box = (x0 - side / 8, y0 - side / 8, x0 + 1.125 * side, y0 + 1.125 * side)  # a margin of side / 8
        whole_tile = True
        while len(todo):
            if box[0] <= lo[0] and box[1] <= lo[1] and box[2] >= hi[0] and box[3] >= hi[1]:
                out[todo] = _tin_one(xy, values, query[todo], nearest_outside)[0]  # all points
                break
            sel = np.flatnonzero((xy[:, 0] >= box[0]) & (xy[:, 0] <= box[2])
                                 & (xy[:, 1] >= box[1]) & (xy[:, 1] <= box[3]))
            v, ok, need = _tin_one(xy[sel], values[sel], query[todo], nearest_outside, box, hull, (lo, hi))
            out[todo[ok]] = v[ok]
            todo, need = todo[~ok], need[~ok]
            if whole_tile and 0 < len(todo) <= _FEW:  # a few left (circles reaching beyond the tile): next
                # the area their circles need (and a margin), not the whole tile again; from there on it grows
                b = (need[:, 0].min(), need[:, 1].min(), need[:, 2].max(), need[:, 3].max())
                r = max(b[2] - b[0], b[3] - b[1], side) / 8
                box = (b[0] - r, b[1] - r, b[2] + r, b[3] + r)
                whole_tile = False
                continue
            whole_tile = False
            if len(todo):  # the next area: every circle still needed, and more than this one
                w = max(box[2] - box[0], box[3] - box[1]) / 2
                grow = np.array([need[:, 0].min() - w / 4, need[:, 1].min() - w / 4,
                                 need[:, 2].max() + w / 4, need[:, 3].max() + w / 4])
                box = (min(grow[0], box[0] - w / 4), min(grow[1], box[1] - w / 4),
                       max(grow[2], box[2] + w / 4), max(grow[3], box[3] + w / 4))

    tiles = np.split(order, np.flatnonzero(np.diff(key[order])) + 1)
    if workers > 1 and len(tiles) > 1:
        with ThreadPoolExecutor(max_workers=min(workers, len(tiles))) as pool:
            list(pool.map(tile, tiles))  # list(): re-raises a tile's exception here
    else:
        for todo in tiles:
            tile(todo)
    return out
