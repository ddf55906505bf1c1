"""Object-size rule after the per-point prediction: small "building" clusters are errors.

A building is a large object.  Points predicted *building* are linked into
components (3-D distance ≤ :data:`LINK` m, single linkage,
:func:`lidarfx.segment.components.linked_components`); a component whose plan
footprint (2-D convex hull) is smaller than the minimum area is given, point by
point, the most probable of the other classes.  A component that reaches the edge
of the classified data (within :data:`EDGE_RING` cells of :data:`EDGE_CELL` m of
an empty cell or of the data's bounding box) is kept whatever its size: a building
cut by a tile edge cannot be measured.  docs/classification.md §2,
docs/classification-record.md §7.

A component large enough to be judged (footprint at least the minimum area) in
which more than a given share of the points come from pulses with several
returns also takes its next class: a roof stops the laser, a tree crown lets it
through (the default share, 0.5, is
:data:`lidarfx.classify.model.DEFAULT_MAX_MULTI_RETURN_SHARE`;
docs/classification-record.md §8).  Clouds without ``number_of_returns`` are not tested.

Clouds sparser than the default's link can bridge (mean spacing above half of
it) get a longer link and larger edge cells: ``max(LINK, 2 / √density)``.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import LidarfxError
from ..geometry import group_hull_areas

__all__ = ["BUILDING_CODE", "LINK", "EDGE_CELL", "EDGE_RING", "building_class", "edge_mask", "link_for",
           "check_area", "check_share", "drop_small_objects"]

BUILDING_CODE = 6
"""LAS code of buildings: the rule acts on the class holding it."""
LINK = 1.0
"""Link distance (m) between points of one object."""
EDGE_CELL = 1.0
"""Cell (m) of the occupancy grid that finds the edge of the data."""
EDGE_RING = 2
"""Cells from an empty cell within which a point counts as at the edge."""


def building_class(classes) -> int | None:
    """Index of the class of a :class:`~lidarfx.classify.ClassMap` that holds LAS code 6, or None
    (also when it is the only class)."""
    if len(classes) < 2:
        return None
    for i, group in enumerate(classes.groups):
        if BUILDING_CODE in group:
            return i
    return None


def link_for(density: float | None) -> float:
    """Link distance and edge cell (m) for a cloud of ``density`` points per m²."""
    if not density or not math.isfinite(density) or density <= 0:
        return LINK
    return max(LINK, 2.0 / math.sqrt(density))


def edge_mask(xy: np.ndarray, cell: float = EDGE_CELL, ring: int = EDGE_RING) -> np.ndarray:
    """True for the points whose ``cell`` square lies within ``ring`` cells (Chebyshev) of an
    empty square or of the outside of the points' bounding box.  Works on the occupied
    squares only (sorted keys), so a sparse extent costs no dense grid."""
    xy = np.asarray(xy, dtype=np.float64)
    if not len(xy):
        return np.zeros(0, bool)
    ij = np.floor((xy[:, :2] - xy[:, :2].min(axis=0)) / cell).astype(np.int64) + ring + 1
    w = int(ij[:, 1].max()) + ring + 2  # a margin of empty cells on every side
    key = ij[:, 0] * w + ij[:, 1]
    cells, inv = np.unique(key, return_inverse=True)
    near = np.zeros(len(cells), bool)
    for dx in range(-ring, ring + 1):
        for dy in range(-ring, ring + 1):
            if dx == 0 and dy == 0:
                continue
            k2 = cells + dx * w + dy
            pos = np.minimum(np.searchsorted(cells, k2), len(cells) - 1)
            near |= cells[pos] != k2
    return near[inv.ravel()]


def check_area(area: float) -> float:
    """``area`` as a float number of m² >= 0 (0 = no rule), or a one-line error."""
    area = float(area)
    if not (area >= 0 and math.isfinite(area)):
        raise LidarfxError(f"the minimum building area must be a number of m² >= 0, got {area!r}")
    return area


def check_share(share: float) -> float:
    """``share`` as a float in (0, 1], or a one-line error."""
    share = float(share)
    if not (0 < share <= 1):
        raise LidarfxError(f"the largest multi-return share must lie in (0, 1] (1 = no test), got {share!r}")
    return share


def drop_small_objects(labels: np.ndarray, alternative: np.ndarray, xyz: np.ndarray, target: int,
                       min_area: float, *, link: float = LINK, cell: float | None = None,
                       ring: int = EDGE_RING, returns: np.ndarray | None = None,
                       max_multi_return_share: float = 1.0, stats: dict | None = None) -> np.ndarray:
    """Apply the building-cluster rule: a copy of ``labels`` (class index per point) in
    which the components of class ``target`` smaller than ``min_area`` m² (plan convex
    hull) that do not reach the data's edge take ``alternative`` (per point: its most
    probable other class).  So do the components of at least ``min_area`` m² in which
    more than ``max_multi_return_share`` of the points have ``returns`` (their pulse's
    number of returns, per point) above 1; without ``returns`` (or with every value 0:
    no return information), or with a share of 1, there is no such test
    (``stats["see_through_untested"]`` is 1 when a share below 1 could not be tested).
    ``min_area`` 0 switches both off.  ``xyz`` in metres; every point given is part of
    the data (its footprint defines the edge).  ``stats``, when
    given, receives the numbers of components found, kept at the edge and relabelled
    (small ones, see-through ones), and of points relabelled."""
    labels = np.asarray(labels)
    min_area = check_area(min_area)
    share = check_share(max_multi_return_share)
    out = labels.copy()
    b = np.flatnonzero(labels == target)
    # number_of_returns all 0 (e.g. AHN4 exports): no return information, nothing to test
    tested = returns is not None and share < 1 and bool(np.any(np.asarray(returns) > 0))
    if stats is not None:
        stats.update({"components": 0, "kept_at_edge": 0, "relabelled_components": 0, "relabelled_points": 0,
                      "see_through_components": 0, "see_through_points": 0,
                      "see_through_untested": int(min_area > 0 and share < 1 and not tested)})
    if min_area == 0 or not len(b):
        return out
    from ..segment.components import linked_components  # numba: loaded on first use

    xyz = np.asarray(xyz, dtype=np.float64)
    comp = linked_components(xyz[b], link)
    area = group_hull_areas(xyz[b, :2], comp)
    k = len(area)
    touches = np.bincount(comp, weights=edge_mask(xyz, cell or link, ring)[b], minlength=k) > 0
    small = (area < min_area) & ~touches
    see_through = np.zeros(k, bool)
    if tested:
        multi = np.asarray(returns)[b] > 1
        see_through = (area >= min_area) & (np.bincount(comp, weights=multi, minlength=k)
                                            > share * np.bincount(comp, minlength=k))
    drop = b[(small | see_through)[comp]]
    out[drop] = np.asarray(alternative)[drop]
    if stats is not None:
        stats.update({"components": int(k), "kept_at_edge": int((touches & (area < min_area)).sum()),
                      "relabelled_components": int(small.sum()),
                      "relabelled_points": int(small[comp].sum()),
                      "see_through_components": int(see_through.sum()),
                      "see_through_points": int(see_through[comp].sum())})
    return out
