"""Raster helpers of the ground filter: cell grids, minimum surface, inpainting,
disk morphology, bilinear sampling and gradients.

Grids are ``(ny, nx)`` float64 arrays in *local* coordinates: cell ``(i, j)``
covers ``x ∈ [j·c, (j+1)·c)``, ``y ∈ [i·c, (i+1)·c)`` with its centre at
``((j+½)c, (i+½)c)``; row 0 is the *south* edge (the raster writer flips rows).
Empty cells are NaN.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np
from scipy import ndimage

from .tin import tin_interpolate

__all__ = [
    "GridSpec",
    "cell_index",
    "min_surface",
    "inpaint",
    "open_disk",
    "bilinear",
    "gradient_slope",
]


class GridSpec:
    """Geometry of a cell grid over local xy: cell size and shape."""

    __slots__ = ("cell", "nx", "ny")

    def __init__(self, xy: np.ndarray, cell: float) -> None:
        self.cell = float(cell)
        if len(xy):
            hi = xy.max(axis=0)
        else:
            hi = np.zeros(2)
        self.nx = int(math.floor(hi[0] / self.cell)) + 1
        self.ny = int(math.floor(hi[1] / self.cell)) + 1

    @property
    def shape(self) -> tuple[int, int]:
        return (self.ny, self.nx)


def cell_index(xy: np.ndarray, spec: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of each local xy point (clipped into the grid)."""
    j = np.clip(np.floor(xy[:, 0] / spec.cell).astype(np.int64), 0, spec.nx - 1)
    i = np.clip(np.floor(xy[:, 1] / spec.cell).astype(np.int64), 0, spec.ny - 1)
    return i, j


@nb.njit(cache=True)
def _min_kernel(i, j, z, ny, nx):
    out = np.full((ny, nx), np.nan)
    arg = np.full((ny, nx), -1, dtype=np.int64)
    for k in range(z.shape[0]):
        a = i[k]
        b = j[k]
        if arg[a, b] < 0 or z[k] < out[a, b]:
            out[a, b] = z[k]
            arg[a, b] = k
    return out, arg


def min_surface(i: np.ndarray, j: np.ndarray, z: np.ndarray, spec: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    """Lowest z per cell (NaN where empty) and the index of that point (-1 where empty)."""
    return _min_kernel(i, j, np.ascontiguousarray(z, dtype=np.float64), spec.ny, spec.nx)


INPAINT_JITTER = 1e-3
"""Known cell centres are moved by up to ± half this many cells (a fixed pseudo-random offset
per cell) before they are triangulated, so that the Delaunay triangulation is unique."""


def _cell_jitter(i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A fixed pseudo-random offset in [−½, ½)² per cell (row ``i``, column ``j``).

    It depends on the cell alone (a splitmix64 hash of its row and column), not on
    which other cells are triangulated with it.
    """
    with np.errstate(over="ignore"):
        h = (i.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)) ^ (j.astype(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F))
        h ^= h >> np.uint64(31)
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(29)
        a = (h >> np.uint64(11)).astype(np.float64) / 2.0**53
        h *= np.uint64(0x94D049BB133111EB)
        h ^= h >> np.uint64(32)
        b = (h >> np.uint64(11)).astype(np.float64) / 2.0**53
    return a - 0.5, b - 0.5


def inpaint(grid: np.ndarray, spec: GridSpec, *, all_known: bool = False,
            offset: tuple[int, int] = (0, 0)) -> np.ndarray:
    """Fill the NaN cells of ``grid`` by linear (TIN) interpolation of the known cells.

    ``offset``: (row, column) of this grid's cell (0, 0) in a larger grid it is cut from (a
    chunk of a tiled run): the jitter is that of the larger grid's cells, so that the same
    cells triangulate alike in both.

    The known values sit at the cell centres, each moved by at most
    :data:`INPAINT_JITTER` / 2 cells (:func:`_cell_jitter`): a regular grid has
    cocircular points everywhere, and its Delaunay triangulation would otherwise
    split them arbitrarily.  Cells outside the convex hull of the known cells take
    the value of the nearest known cell.  Known cells keep their values.

    Only the *border* cells are triangulated: known cells with an empty cell
    among their 8 neighbours or on the edge of the grid.  The answer is the same
    as from all known cells (``all_known=True``, for tests).  Proof: let a known
    cell v have 8 known neighbours and let an empty cell e lie in a Delaunay
    triangle with corner v.  e is at least 2 cells from v (not √2: that is why
    all 8 neighbours, not 4, must be known), so the triangle's
    circumcircle, which passes through v and holds e, has a radius R ≥ 1 cell.
    A neighbour at distance 1 in the direction within 45° of the circle's centre
    (angle θ) lies inside it, since 1 < 2R·cos θ — the triangle is not Delaunay.
    So the triangles that cover empty cells have border corners only, and are
    Delaunay among the border cells too.  Likewise a nearest known cell of an
    empty cell outside the hull is a border cell (a neighbour would be nearer),
    and the hull's corners are border cells.  The jitter keeps these margins.
    """
    known = np.isfinite(grid)
    nk = int(known.sum())
    if nk == 0 or nk == grid.size:
        return grid.copy()
    use = known
    if not all_known:
        near = ndimage.binary_dilation(~known, structure=np.ones((3, 3), dtype=bool))
        near[0, :] = near[-1, :] = near[:, 0] = near[:, -1] = True
        use = known & near
    ii, jj = np.nonzero(use)
    di, dj = _cell_jitter(ii + int(offset[0]), jj + int(offset[1]))
    pts = np.column_stack([(jj + 0.5 + INPAINT_JITTER * dj) * spec.cell, (ii + 0.5 + INPAINT_JITTER * di) * spec.cell])
    out = grid.copy()
    mi, mj = np.nonzero(~known)
    q = np.column_stack([(mj + 0.5) * spec.cell, (mi + 0.5) * spec.cell])
    out[mi, mj] = tin_interpolate(pts, grid[use], q)
    return out


def _disk_halfwidths(r: int) -> np.ndarray:
    """Half-width of a digital disk of radius ``r`` cells at each row offset −r..r."""
    dy = np.arange(-r, r + 1)
    return np.floor(np.sqrt(np.maximum(r * r - dy * dy, 0)) + 1e-9).astype(int)


def _disk_filter(grid: np.ndarray, r: int, op: str) -> np.ndarray:
    """Min (``op="min"``) or max filter of ``grid`` over a disk of radius ``r`` cells.

    The disk is decomposed into rows: a 1-D running filter along x per distinct
    half-width (O(n) each), then the row offsets are combined.  Cells outside
    the grid are ignored.
    """
    if r <= 0:
        return grid.copy()
    f1 = ndimage.minimum_filter1d if op == "min" else ndimage.maximum_filter1d
    comb = np.minimum if op == "min" else np.maximum
    hw = _disk_halfwidths(r)
    rows = {int(h): f1(grid, 2 * int(h) + 1, axis=1, mode="nearest") for h in np.unique(hw)}
    out = rows[int(hw[r])].copy()
    ny = grid.shape[0]
    for k, dy in enumerate(range(-r, r + 1)):
        if dy == 0 or abs(dy) >= ny:
            continue
        src = rows[int(hw[k])]
        if dy > 0:  # out[i] combines src[i + dy]
            comb(out[: ny - dy], src[dy:], out=out[: ny - dy])
        else:
            comb(out[-dy:], src[: ny + dy], out=out[-dy:])
    return out


def open_disk(grid: np.ndarray, r: int) -> np.ndarray:
    """Morphological opening (erosion then dilation) with a disk of radius ``r`` cells."""
    return _disk_filter(_disk_filter(grid, r, "min"), r, "max")


def bilinear(grid: np.ndarray, spec: GridSpec, xy: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of a filled grid (values at cell centres) at local xy."""
    c = spec.cell
    fx = np.clip(xy[:, 0] / c - 0.5, 0.0, spec.nx - 1.0)
    fy = np.clip(xy[:, 1] / c - 0.5, 0.0, spec.ny - 1.0)
    j0 = np.minimum(np.floor(fx).astype(np.int64), max(spec.nx - 2, 0))
    i0 = np.minimum(np.floor(fy).astype(np.int64), max(spec.ny - 2, 0))
    j1 = np.minimum(j0 + 1, spec.nx - 1)
    i1 = np.minimum(i0 + 1, spec.ny - 1)
    tx = fx - j0
    ty = fy - i0
    top = grid[i0, j0] * (1 - tx) + grid[i0, j1] * tx
    bot = grid[i1, j0] * (1 - tx) + grid[i1, j1] * tx
    return top * (1 - ty) + bot * ty


def gradient_slope(grid: np.ndarray, cell: float) -> np.ndarray:
    """Slope (rise over run, dimensionless) of a filled grid by central differences."""
    if min(grid.shape) < 2:
        return np.zeros_like(grid)
    gy, gx = np.gradient(grid, cell)
    return np.hypot(gx, gy)
