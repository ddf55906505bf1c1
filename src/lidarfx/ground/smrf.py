"""Simple Morphological Filter (SMRF), Pingel, Clarke & McBride (2013).

Steps (paper section numbers in brackets):

1. minimum surface: the lowest point per ``cell`` × ``cell`` grid cell [2.1];
   empty cells are inpainted (here: linear TIN interpolation of the filled
   cells, nearest value outside their hull; the paper uses spring inpainting);
2. low outliers: cells far *below* their neighbours are found by the same
   progressive filter run on the negated surface (slope 5, radius 1 cell, as
   in PDAL's ``filters.smrf``) and dropped;
3. progressive morphological opening with a disk of radius 1, 2, … up to
   ``window``/``cell`` cells [2.2]; at radius r a cell is an object when the
   previous (less opened) surface exceeds the newly opened one by more than
   ``slope · r · cell``;
4. provisional DTM: the minimum surface without object, low-outlier and empty
   cells, inpainted [2.3];
4a. (lidarfx addition) step check: a connected region of object cells is an
   object only if at least ``edge_share`` of its boundary drops by more than
   ``edge_step`` to the neighbouring non-object cells; a region without such
   steps is a smooth terrain convexity (dike, ridge, terrace crest) that the
   opening removed, and goes back to the terrain.  Buildings, bridges and
   trees are bounded by steps;
5. final classification [2.4]: a point is ground when its vertical distance to
   the provisional DTM (bilinear) is at most ``threshold + scalar · g``, g
   being the DTM gradient (rise / run) in the point's cell.
"""
from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numpy as np

from scipy import ndimage

from .params import DEFAULTS
from ..surface.grid import GridSpec, bilinear, cell_index, gradient_slope, inpaint, min_surface, open_disk

__all__ = ["progressive_objects", "provisional_dtm", "smrf", "SmrfSurface", "window_radius"]

LOW_OUTLIER_SLOPE = 5.0
"""Slope of the low-outlier pass (on the negated minimum surface), as PDAL."""
LOW_OUTLIER_RADIUS = 1
"""Radius (cells) of the low-outlier pass."""


class SmrfSurface(NamedTuple):
    """The provisional DTM of SMRF and the grid it lives on."""

    grid: np.ndarray  # (ny, nx) filled provisional DTM, local z
    spec: GridSpec
    kept: np.ndarray  # (ny, nx) bool: cells whose minimum survived (not object/low/empty)
    seeds: np.ndarray  # indices of the minimum points of the kept cells


def progressive_objects(
    zfill: np.ndarray,
    cell: float,
    slope: float,
    max_radius: int,
    advance: Callable[[int], None] | None = None,
) -> np.ndarray:
    """Cells flagged as objects by the progressive opening of ``zfill`` (no NaN)."""
    obj = np.zeros(zfill.shape, dtype=bool)
    last = zfill
    for r in range(1, max_radius + 1):
        opened = open_disk(last, r)
        obj |= (last - opened) > slope * r * cell
        last = opened
        if advance is not None:
            advance(1)
    return obj


def step_check(obj: np.ndarray, zfill: np.ndarray, step: float, share: float) -> np.ndarray:
    """Object cells that belong to a region bounded by steps (see module doc, 4a).

    For every 8-connected region of ``obj`` the boundary pairs (object cell,
    4-neighbour non-object cell) are counted, and those where the object cell
    is more than ``step`` higher in ``zfill``; regions with a share of such
    pairs below ``share`` (or with no boundary at all) are dropped.
    """
    if share <= 0 or not obj.any():
        return obj
    lab, nlab = ndimage.label(obj, structure=np.ones((3, 3), dtype=bool))
    total = np.zeros(nlab + 1)
    steps = np.zeros(nlab + 1)
    ny, nx = obj.shape
    for di, dj in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        a = (slice(max(0, -di), ny - max(0, di)), slice(max(0, -dj), nx - max(0, dj)))
        b = (slice(max(0, di), ny - max(0, -di)), slice(max(0, dj), nx - max(0, -dj)))
        edge = obj[a] & ~obj[b]
        la = lab[a][edge]
        total += np.bincount(la, minlength=nlab + 1)
        steps += np.bincount(la, weights=(zfill[a][edge] - zfill[b][edge]) > step, minlength=nlab + 1)
    is_object = steps >= share * np.maximum(total, 1)
    is_object &= total > 0
    is_object[0] = False
    return obj & is_object[lab]


def window_radius(window: float, cell: float, nx: int, ny: int) -> int:
    """The largest opening radius (cells) SMRF runs: ``window / cell``, but no more than the
    grid's diagonal: a disk that covers the whole grid opens it to its minimum, and larger
    disks flag nothing more (so a huge ``window`` gives the same result, quickly)."""
    r = max(1, round(min(window / cell, 1e12)))
    return min(r, int(math.ceil(math.hypot(nx - 1, ny - 1))) + 1)


def provisional_dtm(
    xyz: np.ndarray,
    *,
    cell: float,
    slope: float,
    window: float,
    edge_step: float = DEFAULTS["edge_step"],
    edge_share: float = DEFAULTS["edge_share"],
    advance: Callable[[int], None] | None = None,
    offset: tuple[int, int] = (0, 0),
) -> SmrfSurface:
    """Steps 1–4 of SMRF on local coordinates ``xyz`` (n×3); ``offset``: see :func:`smrf`."""
    spec = GridSpec(xyz[:, :2], cell)
    i, j = cell_index(xyz[:, :2], spec)
    zmin, arg = min_surface(i, j, xyz[:, 2], spec)
    empty = ~np.isfinite(zmin)
    zfill = inpaint(zmin, spec, offset=offset)
    low = progressive_objects(-zfill, cell, LOW_OUTLIER_SLOPE, LOW_OUTLIER_RADIUS) & ~empty
    if low.any():
        z2 = zmin.copy()
        z2[low] = np.nan
        zfill = inpaint(z2, spec, offset=offset)
    radius = window_radius(window, cell, spec.nx, spec.ny)
    obj = progressive_objects(zfill, cell, slope, radius, advance)
    obj = step_check(obj, zfill, edge_step, edge_share)
    kept = ~(obj | empty | low)
    if not kept.any():  # nothing survived (e.g. a single roof): keep the lowest cell
        kept = np.zeros_like(kept)
        kept.flat[int(np.nanargmin(zmin))] = True
    zpro = np.where(kept, zmin, np.nan)
    zpro = inpaint(zpro, spec, offset=offset)
    return SmrfSurface(zpro, spec, kept, arg[kept])


POINT_CHUNK = 1_000_000
"""The final per-point test runs over this many points at a time (its temporaries: ~100 bytes per point)."""


def smrf(
    xyz: np.ndarray,
    *,
    cell: float = DEFAULTS["cell"],
    slope: float = DEFAULTS["slope"],
    window: float = DEFAULTS["window"],
    threshold: float = DEFAULTS["threshold"],
    scalar: float = DEFAULTS["scalar"],
    edge_step: float = DEFAULTS["edge_step"],
    edge_share: float = DEFAULTS["edge_share"],
    advance: Callable[[int], None] | None = None,
    offset: tuple[int, int] = (0, 0),
) -> tuple[np.ndarray, SmrfSurface]:
    """SMRF ground mask of local points ``xyz`` (n×3) and the provisional DTM.

    ``offset``: (row, column) of the local grid's cell (0, 0) in the grid of a larger cloud
    that ``xyz`` is cut from (a chunk of a tiled run; only the inpainting jitter uses it)."""
    surf = provisional_dtm(
        xyz, cell=cell, slope=slope, window=window, edge_step=edge_step, edge_share=edge_share, advance=advance,
        offset=offset,
    )
    g = gradient_slope(surf.grid, cell)
    ground = np.empty(len(xyz), dtype=bool)
    for a in range(0, len(xyz), POINT_CHUNK):  # bounded temporaries on large clouds
        part = xyz[a:a + POINT_CHUNK]
        i, j = cell_index(part[:, :2], surf.spec)
        z = bilinear(surf.grid, surf.spec, part[:, :2])
        ground[a:a + POINT_CHUNK] = np.abs(part[:, 2] - z) <= threshold + scalar * g[i, j]
    return ground, surf
