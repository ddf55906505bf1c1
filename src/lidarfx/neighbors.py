"""One spatial index for every neighbourhood kind: a sorted column grid.

Points (already in local coordinates) are sorted by their 2-D grid column
``(ix, iy)`` and, inside a column, by z.  A column is therefore one contiguous
run of the sorted arrays, and the part of a column inside a z window is found
with two binary searches.  This answers

* spheres of radius r (3-D): the (2m+1)² columns around the query, z window ±r;
* vertical cylinders (2-D distance; unbounded, or ±h with a height limit);
* k nearest neighbours (rings of columns, two-pointer walk from the query's z);
* kNN capped by a radius;

and every radius of a multi-scale run, because one scan of the largest radius
visits every smaller neighbourhood too.  Kernels walk neighbours in place
(``for j in range(lo, hi)``): no per-point lists are ever built.

Only numpy arrays go into the numba kernels.  The Python class
:class:`NeighborIndex` owns them and offers convenience queries
(:meth:`NeighborIndex.query_radius`, :meth:`NeighborIndex.knn`, ...).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from . import _parallel as parallel
from .errors import LidarfxError

__all__ = ["NeighborIndex", "Grid", "default_cell_for_knn", "default_radius", "check_grid"]


class Grid(NamedTuple):
    """The numba-side view of the index (a tuple of arrays and scalars)."""

    pts: np.ndarray  # (n, 3) float64, local coordinates, sorted by (column, z)
    cstart: np.ndarray  # (ncols,) int64 first sorted index of each non-empty column
    cend: np.ndarray  # (ncols,) int64 one past the last
    ckey: np.ndarray  # (ncols,) int64 column key ix*ny+iy, ascending
    table: np.ndarray  # dense key -> column number (-1 empty), or empty when sparse
    nx: int
    ny: int
    cell: float


# ----------------------------------------------------------------------------
# numba primitives shared by every kernel that walks neighbours
# ----------------------------------------------------------------------------
@nb.njit(cache=True, inline="always")
def column_of(ckey, table, ny, ix, iy):
    """Column number of grid cell (ix, iy), or -1 when empty (bounds checked by caller)."""
    key = ix * ny + iy
    if table.shape[0] > 0:
        return table[key]
    lo = 0
    hi = ckey.shape[0]
    while lo < hi:
        mid = (lo + hi) >> 1
        if ckey[mid] < key:
            lo = mid + 1
        else:
            hi = mid
    if lo < ckey.shape[0] and ckey[lo] == key:
        return lo
    return -1


@nb.njit(cache=True, inline="always")
def lower_bound_z(pts, lo, hi, zval):
    """First sorted index in [lo, hi) whose z >= zval."""
    while lo < hi:
        mid = (lo + hi) >> 1
        if pts[mid, 2] < zval:
            lo = mid + 1
        else:
            hi = mid
    return lo


@nb.njit(cache=True)
def column_ranges(pts, cstart, cend, ckey, table, nx, ny, cell, qx, qy, qz, radius, zhalf, lo_out, hi_out):
    """Fill ``lo_out/hi_out`` with the sorted-index runs that can hold neighbours.

    Every point within 2-D distance ``radius`` of (qx, qy) and with
    ``|z - qz| <= zhalf`` lies in one of the returned runs (``zhalf = inf``
    for an unbounded cylinder).  Columns entirely farther than ``radius`` are
    skipped.  Returns the number of runs; the buffers need (2m+1)² entries,
    m = ceil(radius / cell).
    """
    m = int(math.ceil(radius / cell))
    cx = int(math.floor(qx / cell))
    cy = int(math.floor(qy / cell))
    r2 = radius * radius
    nr = 0
    for gx in range(cx - m, cx + m + 1):
        if gx < 0 or gx >= nx:
            continue
        x0 = gx * cell
        ddx = 0.0
        if qx < x0:
            ddx = x0 - qx
        elif qx > x0 + cell:
            ddx = qx - x0 - cell
        if ddx * ddx > r2:
            continue
        for gy in range(cy - m, cy + m + 1):
            if gy < 0 or gy >= ny:
                continue
            y0 = gy * cell
            ddy = 0.0
            if qy < y0:
                ddy = y0 - qy
            elif qy > y0 + cell:
                ddy = qy - y0 - cell
            if ddx * ddx + ddy * ddy > r2:
                continue
            c = column_of(ckey, table, ny, gx, gy)
            if c < 0:
                continue
            a = cstart[c]
            b = cend[c]
            if zhalf < np.inf:
                a = lower_bound_z(pts, a, b, qz - zhalf)
                b = lower_bound_z(pts, a, b, np.nextafter(qz + zhalf, np.inf))
            if a < b:
                if nr > 0 and hi_out[nr - 1] == a:
                    hi_out[nr - 1] = b  # adjacent in memory: one longer run
                else:
                    lo_out[nr] = a
                    hi_out[nr] = b
                    nr += 1
    return nr


# rows of the buffer filled by ``gather``
G_DX, G_DY, G_DZ = 0, 1, 2


@nb.njit(cache=True)
def gather(pts, lo, hi, nr, qx, qy, qz, r2, zhalf, cylinder, buf):
    """Copy the neighbours found in the runs into ``buf`` relative to the query point.

    Neighbours are the points within squared radius ``r2`` of (qx, qy, qz) —
    in 3-D, or in 2-D with ``|dz| <= zhalf`` when ``cylinder``.  ``buf`` is a
    (5, capacity) array with rows dx, dy, dz, d², h² (``G_*`` constants);
    the loop is branch-free (every candidate is written, the count advances
    when inside).  Returns ``(buf, count)``; ``buf`` is replaced by a larger
    array when the runs hold more candidates than it can take.
    """
    need = 0
    for k in range(nr):
        need += hi[k] - lo[k]
    if need > buf.shape[1]:
        buf = np.empty((3, 2 * need))
    cnt = 0
    for k in range(nr):
        for j in range(lo[k], hi[k]):
            dx = pts[j, 0] - qx
            dy = pts[j, 1] - qy
            dz = pts[j, 2] - qz
            h2 = dx * dx + dy * dy
            d2 = h2 + dz * dz
            buf[G_DX, cnt] = dx
            buf[G_DY, cnt] = dy
            buf[G_DZ, cnt] = dz
            if cylinder:
                cnt += h2 <= r2 and abs(dz) <= zhalf
            else:
                cnt += d2 <= r2
    return buf, cnt


def ring_buffer_size(radius_max: float, cell: float) -> int:
    m = int(math.ceil(radius_max / cell))
    return (2 * m + 1) ** 2


# ----------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------
@nb.njit(cache=True, nogil=True)
def _radius_kernel(lo_q, hi_q, pts, cstart, cend, ckey, table, nx, ny, cell, q, radius, cylinder, zhalf, nbuf,
                   collect, offsets, out_idx, out_d, counts):
    """Count the neighbours of queries ``lo_q:hi_q`` into ``counts``; with ``collect`` also
    write them (sorted-order indices and distances) into the CSR arrays at ``offsets``."""
    lo = np.empty(nbuf, np.int64)
    hi = np.empty(nbuf, np.int64)
    for i in range(lo_q, hi_q):
        qx, qy, qz = q[i, 0], q[i, 1], q[i, 2]
        r = radius[i] if radius.shape[0] > 1 else radius[0]
        r2 = r * r
        zh = zhalf if cylinder else r
        nr = column_ranges(pts, cstart, cend, ckey, table, nx, ny, cell, qx, qy, qz, r, zh, lo, hi)
        w = offsets[i] if collect else 0
        cnt = 0
        for k in range(nr):
            for j in range(lo[k], hi[k]):
                dx = pts[j, 0] - qx
                dy = pts[j, 1] - qy
                d2 = dx * dx + dy * dy
                if not cylinder:
                    dz = pts[j, 2] - qz
                    d2 += dz * dz
                if d2 <= r2:
                    if collect:
                        out_idx[w + cnt] = j
                        out_d[w + cnt] = math.sqrt(d2)
                    cnt += 1
        counts[i] = cnt


@nb.njit(cache=True, inline="always")
def _sift_down(hd, hi_, size, d2, j):
    """Put (d2, j) at the root of the max-heap of ``size`` entries and sift it down."""
    pos = 0
    while True:
        c = 2 * pos + 1
        if c >= size:
            break
        if c + 1 < size and hd[c + 1] > hd[c]:
            c += 1
        if hd[c] <= d2:
            break
        hd[pos] = hd[c]
        hi_[pos] = hi_[c]
        pos = c
    hd[pos] = d2
    hi_[pos] = j


@nb.njit(cache=True, inline="always")
def _heap_push(hd, hi_, size, k, d2, j):
    """Max-heap of the k best (smallest d2).  Returns the new size."""
    if size == k:
        if d2 < hd[0]:  # replace the root (the worst kept)
            _sift_down(hd, hi_, size, d2, j)
        return size
    # insert at the end and sift up
    pos = size
    while pos > 0:
        p = (pos - 1) >> 1
        if hd[p] >= d2:
            break
        hd[pos] = hd[p]
        hi_[pos] = hi_[p]
        pos = p
    hd[pos] = d2
    hi_[pos] = j
    return size + 1


@nb.njit(cache=True, inline="always")
def _heap_pop(hd, hi_, size):
    """Remove the root of the max-heap of ``size`` entries (its last entry sifts down)."""
    _sift_down(hd, hi_, size - 1, hd[size - 1], hi_[size - 1])


@nb.njit(cache=True, parallel=True)
def _knn_kernel(pts, cstart, cend, ckey, table, nx, ny, cell, q, k, rmax, out_idx, out_d):
    """k nearest neighbours (3-D) by rings of columns; ``rmax`` caps the search (inf = none).

    Rows with fewer than k neighbours inside ``rmax`` are padded with -1 / inf.  The one kernel
    still compiled with numba's ``parallel=True`` (and called from Python only): the same loop as
    a ``nogil`` kernel on threads (lidarfx._parallel) ran three times slower per query.
    """
    m = q.shape[0]
    nchunk = (m + 255) // 256
    rmax2 = rmax * rmax
    for ch in nb.prange(nchunk):
        hd = np.empty(k, np.float64)
        hj = np.empty(k, np.int64)
        for i in range(ch * 256, min(m, ch * 256 + 256)):
            qx, qy, qz = q[i, 0], q[i, 1], q[i, 2]
            cx = int(math.floor(qx / cell))
            cy = int(math.floor(qy / cell))
            # distance from the query to the border of its own cell
            inner = min(qx - cx * cell, (cx + 1) * cell - qx, qy - cy * cell, (cy + 1) * cell - qy)
            if inner < 0.0:
                inner = 0.0
            size = 0
            ring = 0
            maxring = max(nx, ny) + abs(cx) + abs(cy) + 1
            while True:
                for gx in range(cx - ring, cx + ring + 1):
                    if gx < 0 or gx >= nx:
                        continue
                    edge_x = gx == cx - ring or gx == cx + ring
                    step = 1 if edge_x else 2 * ring
                    gy = cy - ring
                    while gy <= cy + ring:
                        if gy >= 0 and gy < ny:
                            c = column_of(ckey, table, ny, gx, gy)
                            if c >= 0:
                                a = cstart[c]
                                b = cend[c]
                                # walk up and down from the query height
                                s = lower_bound_z(pts, a, b, qz)
                                up = s
                                dn = s - 1
                                while up < b or dn >= a:
                                    worst = hd[0] if size == k else rmax2
                                    if worst > rmax2:
                                        worst = rmax2
                                    if up < b:
                                        dz = pts[up, 2] - qz
                                        if dz * dz > worst:
                                            up = b
                                        else:
                                            dx = pts[up, 0] - qx
                                            dy = pts[up, 1] - qy
                                            d2 = dx * dx + dy * dy + dz * dz
                                            if d2 <= rmax2:
                                                size = _heap_push(hd, hj, size, k, d2, up)
                                            up += 1
                                    if dn >= a:
                                        dz = qz - pts[dn, 2]
                                        worst = hd[0] if size == k else rmax2
                                        if worst > rmax2:
                                            worst = rmax2
                                        if dz * dz > worst:
                                            dn = a - 1
                                        else:
                                            dx = pts[dn, 0] - qx
                                            dy = pts[dn, 1] - qy
                                            d2 = dx * dx + dy * dy + dz * dz
                                            if d2 <= rmax2:
                                                size = _heap_push(hd, hj, size, k, d2, dn)
                                            dn -= 1
                        gy += step
                covered = ring * cell + inner
                ring += 1
                if size == k and hd[0] <= covered * covered:
                    break
                if covered >= rmax:
                    break
                if ring > maxring:
                    break
            # heap -> ascending: take the largest off the max-heap, from the back
            for t in range(size - 1, -1, -1):
                out_idx[i, t] = hj[0]
                out_d[i, t] = math.sqrt(hd[0])
                _heap_pop(hd, hj, t + 1)
            for t in range(size, k):
                out_idx[i, t] = -1
                out_d[i, t] = np.inf


# ----------------------------------------------------------------------------
# Python side
# ----------------------------------------------------------------------------
@nb.njit(cache=True)
def _counting_sort(key, z, ncells):
    """Order by column key (counting sort, O(n)).  Returns the order, the z values in
    that order and the run starts; :func:`_sort_runs_by_z` then sorts each run by z.

    The caller runs :func:`_sort_runs_by_z` over the runs on threads (:mod:`lidarfx._parallel`)."""
    n = key.shape[0]
    start = np.zeros(ncells + 1, np.int64)
    for i in range(n):
        start[key[i] + 1] += 1
    for c in range(ncells):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    zs = np.empty(n)
    for i in range(n):
        k = key[i]
        order[fill[k]] = i
        zs[fill[k]] = z[i]
        fill[k] += 1
    return order, zs, start


@nb.njit(cache=True)
def _merge_sort_run(zs, order, a, b):
    """Stable sort of ``zs[a:b]`` carrying ``order[a:b]`` along (bottom-up merge sort)."""
    n = b - a
    za = zs[a:b].copy()
    oa = order[a:b].copy()
    zb = np.empty(n)
    ob = np.empty(n, order.dtype)
    width = 1
    while width < n:
        for lo in range(0, n, 2 * width):
            mid = min(lo + width, n)
            hi = min(lo + 2 * width, n)
            i, j, t = lo, mid, lo
            while i < mid and j < hi:
                if za[j] < za[i]:
                    zb[t] = za[j]
                    ob[t] = oa[j]
                    j += 1
                else:
                    zb[t] = za[i]
                    ob[t] = oa[i]
                    i += 1
                t += 1
            while i < mid:
                zb[t] = za[i]
                ob[t] = oa[i]
                i += 1
                t += 1
            while j < hi:
                zb[t] = za[j]
                ob[t] = oa[j]
                j += 1
                t += 1
        za, zb = zb, za
        oa, ob = ob, oa
        width *= 2
    zs[a:b] = za
    order[a:b] = oa


@nb.njit(cache=True, nogil=True)
def _sort_runs_by_z(lo_c, hi_c, order, zs, start):
    """Sort runs ``lo_c:hi_c`` (run c is [start[c], start[c+1])) by ``zs`` (the z values in run
    order), carrying ``order`` along: insertion sort for short runs, merge sort otherwise."""
    for c in range(lo_c, hi_c):
        a = start[c]
        b = start[c + 1]
        if b - a <= 1:
            continue
        if b - a > 48:
            _merge_sort_run(zs, order, a, b)
            continue
        for t in range(a + 1, b):
            v = order[t]
            zv = zs[t]
            u = t - 1
            while u >= a and zs[u] > zv:
                order[u + 1] = order[u]
                zs[u + 1] = zs[u]
                u -= 1
            order[u + 1] = v
            zs[u + 1] = zv


@nb.njit(cache=True)
def _column_keys(xyz, origin, cell, ny):
    """Column key floor((x - ox) / cell) * ny + floor((y - oy) / cell) of every point."""
    n = xyz.shape[0]
    key = np.empty(n, np.int64)
    for i in range(n):
        key[i] = np.int64(math.floor((xyz[i, 0] - origin[0]) / cell)) * ny + np.int64(
            math.floor((xyz[i, 1] - origin[1]) / cell)
        )
    return key


@nb.njit(cache=True, nogil=True)
def _sorted_local(lo, hi, xyz, origin, order, pts):
    """Rows ``lo:hi`` of the points in index order, made local: pts = xyz[order] - origin,
    without temporaries."""
    for i in range(lo, hi):
        j = order[i]
        pts[i, 0] = xyz[j, 0] - origin[0]
        pts[i, 1] = xyz[j, 1] - origin[1]
        pts[i, 2] = xyz[j, 2] - origin[2]


MAX_GRID_CELLS = 2**62
"""Most cells of a grid whose int64 cell key (``ix * ny + iy``, ``(ix * ny + iy) * nz + iz``) cannot overflow."""


def check_grid(shape, cell: float, option: str = "radius", grid: str = "the index", unit: str = "columns") -> None:
    """Refuse a grid of ``shape`` cells (counts per axis, ints or floats, ``inf`` included) of edge
    ``cell`` when its int64 cell keys would overflow (Python ints do not), with the one-line error
    "the OPTION is too small for the cloud's extent: GRID would need NX × NY UNIT of CELL"."""
    total = 1.0
    for v in shape:
        total *= float(v)
    if not total < MAX_GRID_CELLS:  # NaN too
        dims = " × ".join(f"{v:.3g}" for v in shape)
        raise LidarfxError(f"the {option} is too small for the cloud's extent: {grid} would need "
                           f"{dims} {unit} of {cell:g}; use a larger {option}")


def _build(xyz: np.ndarray, origin: np.ndarray, cell: float):
    """Sort the points into columns of ``cell`` (x, y made local by ``origin``), by z
    inside each column.  Returns the sorted local points, the order and the column
    tables.  Memory: one key and one order array besides the result."""
    n = xyz.shape[0]
    if n:
        hi = xyz.max(axis=0)
        nx = int(math.floor((hi[0] - origin[0]) / cell)) + 1
        ny = int(math.floor((hi[1] - origin[1]) / cell)) + 1
    else:
        nx = ny = 1
    check_grid((nx, ny), cell)
    key = _column_keys(xyz, origin, cell, ny)
    ncells = nx * ny
    dense = ncells <= 4 * n + 4096
    if dense:
        order, zs, start = _counting_sort(key, xyz[:, 2], ncells)
        parallel.run(_sort_runs_by_z, ncells, order, zs, start, grain=4096)  # z order = local z order
        del zs, start
    else:
        # sparse grid (huge extent for the cell size): sort by z, then stably by column
        oz = np.argsort(xyz[:, 2], kind="stable")
        order = oz[np.argsort(key[oz], kind="stable")]
        del oz
    skey = key[order]
    del key
    if n:
        brk = np.flatnonzero(np.diff(skey)) + 1
        cstart = np.concatenate(([0], brk)).astype(np.int64)
        cend = np.concatenate((brk, [n])).astype(np.int64)
        ckey = skey[cstart]
    else:
        cstart = cend = ckey = np.zeros(0, np.int64)
    del skey
    if dense:
        table = np.full(ncells, -1, np.int64)
        table[ckey] = np.arange(ckey.shape[0], dtype=np.int64)
    else:
        table = np.zeros(0, np.int64)
    pts = np.empty((n, 3))
    parallel.run(_sorted_local, n, xyz, origin, order, pts, grain=65536)
    return pts, order, cstart, cend, ckey, table, nx, ny


def default_cell_for_knn(pts_local: np.ndarray, k: int) -> float:
    """A column size holding about k points per column on average (2-D density; along the
    longer side when the plan view is a line, e.g. a vertical wall: millimetre columns there
    made every query walk thousands of empty rings)."""
    n = max(pts_local.shape[0], 1)
    ext = np.ptp(pts_local[:, :2], axis=0) if n > 1 else np.ones(2)
    area = max(float(ext[0]) * float(ext[1]), 1e-6)
    return max(math.sqrt(area * k / n), k * float(ext.max()) / n, 1e-3)


class NeighborIndex:
    """Sorted column grid over a point cloud (local coordinates).

    Parameters
    ----------
    xyz:
        (n, 3) coordinates.  They are made local by subtracting ``origin``
        (default: the per-axis minimum), so UTM-sized coordinates give the
        same neighbourhoods as the cloud shifted to 0.
    cell:
        Column size in metres; the largest query radius is the natural choice
        (a sphere then scans 3×3 columns).
    origin:
        Local origin; pass the same origin to compare indexes of shifted clouds.
    """

    def __init__(self, xyz: np.ndarray, cell: float, origin: np.ndarray | None = None) -> None:
        xyz = np.asarray(xyz, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise LidarfxError("xyz must have shape (n, 3)")
        if not np.isfinite(xyz).all():
            raise LidarfxError("coordinates contain NaN or infinite values")
        if not (cell > 0 and math.isfinite(cell)):
            raise LidarfxError(f"cell size must be positive, got {cell}")
        self.origin = xyz.min(axis=0) if (origin is None and len(xyz)) else np.asarray(
            origin if origin is not None else np.zeros(3), dtype=np.float64
        )
        if len(xyz) and (xyz.min(axis=0) < self.origin).any():
            raise LidarfxError("origin must not exceed the minimum coordinate")
        self.cell = float(cell)
        pts, order, cstart, cend, ckey, table, nx, ny = _build(xyz, self.origin, self.cell)
        self.order = order  # sorted position -> original index
        self.grid = Grid(pts, cstart, cend, ckey, table, nx, ny, self.cell)

    def __len__(self) -> int:
        return self.grid.pts.shape[0]

    def to_local(self, q: np.ndarray) -> np.ndarray:
        """Query coordinates in this index's local frame (C-contiguous float64)."""
        return np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, 3) - self.origin)

    def _radius_array(self, radius, m: int) -> np.ndarray:
        r = np.atleast_1d(np.asarray(radius, dtype=np.float64))
        if r.shape[0] not in (1, m):
            raise LidarfxError("radius must be a scalar or one value per query point")
        if (r < 0).any() or not np.isfinite(r).all():
            raise LidarfxError("radius must be finite and >= 0")
        return np.ascontiguousarray(r)

    def count(self, q: np.ndarray, radius, cylinder: bool = False, height: float | None = None) -> np.ndarray:
        """Number of points within ``radius`` of each query (sphere, or vertical cylinder)."""
        ql = self.to_local(q)
        r = self._radius_array(radius, len(ql))
        return self._walk(ql, r, cylinder, height)

    def _walk(self, ql, r, cylinder, height, offsets=None):
        g = self.grid
        zhalf = np.inf if height is None else float(height)
        nbuf = ring_buffer_size(float(r.max(initial=0)), g.cell)
        if offsets is None:
            empty = np.zeros(0, np.int64)
            counts = np.zeros(len(ql), np.int64)
            parallel.run(_radius_kernel, len(ql), *g, ql, r, cylinder, zhalf, nbuf, False, empty, empty,
                         np.zeros(0), counts, grain=1024)
            return counts
        idx = np.empty(offsets[-1], np.int64)
        dist = np.empty(offsets[-1], np.float64)
        parallel.run(_radius_kernel, len(ql), *g, ql, r, cylinder, zhalf, nbuf, True, offsets, idx, dist,
                     np.zeros(len(ql), np.int64), grain=1024)
        return idx, dist

    def query_radius(self, q: np.ndarray, radius, cylinder: bool = False, height: float | None = None):
        """Neighbours within ``radius`` as CSR: ``(offsets, indices, distances)``.

        ``indices[offsets[i]:offsets[i+1]]`` are original point indices of query
        i's neighbours (unordered).  Materialises the lists: meant for tests,
        small queries and tools; feature kernels walk neighbours in place.
        """
        ql = self.to_local(q)
        r = self._radius_array(radius, len(ql))
        counts = self._walk(ql, r, cylinder, height)
        offsets = np.zeros(len(ql) + 1, np.int64)
        np.cumsum(counts, out=offsets[1:])
        idx, dist = self._walk(ql, r, cylinder, height, offsets)
        return offsets, self.order[idx], dist

    def knn(self, q: np.ndarray, k: int, max_radius: float | None = None):
        """k nearest neighbours (3-D): ``(indices, distances)`` of shape (m, k), ascending.

        With ``max_radius`` only neighbours within it are returned; missing
        entries are -1 / inf.  The query point itself is included when it is
        part of the indexed cloud (distance 0).
        """
        if k < 1:
            raise LidarfxError("k must be >= 1")
        ql = self.to_local(q)
        g = self.grid
        idx = np.empty((len(ql), k), np.int64)
        dist = np.empty((len(ql), k), np.float64)
        rmax = np.inf if max_radius is None else float(max_radius)
        _knn_kernel(*g, ql, int(k), rmax, idx, dist)
        out = np.where(idx >= 0, self.order[np.maximum(idx, 0)], -1)
        return out, dist


def default_radius(cloud, *, neighbours: int = 40, sample: int = 10_000, seed: int = 0) -> float:
    """A sphere radius holding about ``neighbours`` points on a planar part of the cloud:
    √2 × the median distance to the 20th nearest neighbour (over a seeded sample of at
    most ``sample`` points; for points on a plane the 20th neighbour lies at
    √(20 / (π ρ)), so the radius holds about 40), with two significant digits."""
    from .errors import check_int

    neighbours = check_int("neighbours", neighbours, 1, 100_000)
    sample = check_int("sample", sample, 1, 10**9)
    xyz = np.asarray(getattr(cloud, "xyz", cloud), dtype=np.float64)
    if len(xyz) < 2:
        raise LidarfxError("the point cloud has fewer than 2 points; give a radius")
    k = min(21, len(xyz))  # the point itself and 20 neighbours
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(xyz), size=min(sample, len(xyz)), replace=False)
    local = xyz - xyz.min(axis=0)
    index = NeighborIndex(xyz, default_cell_for_knn(local, k))
    _, d = index.knn(xyz[pick], k)
    dk = d[:, -1]
    dk = dk[np.isfinite(dk) & (dk > 0)]
    if not len(dk):
        raise LidarfxError("cannot estimate a radius: the points coincide; give a radius")
    r = math.sqrt(neighbours / 20.0) * float(np.median(dk))
    return float(f"{r:.2g}")
