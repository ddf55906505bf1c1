"""3-D building edge lines from the structure classes (after ISPRS 2016; docs/edges.md).

The points the unsupervised structure classification labels *plane border*,
*edge* or *corner* (:func:`lidarfx.classify_structures`) form bands a few point
spacings wide along every roof eave, ridge, step and wall top.  They are turned
into 3-D polylines in six steps (docs/edges.md §1 in full):

1. **candidates** — those points, except within ``radius`` of the cloud's plan
   convex hull (a tile's edges are borders of every surface they cut);
2. **components** and **segments** — single-linkage clusters of the candidates
   (:func:`lidarfx.segment.components.linked_components`, link ``link``) and
   sequential RANSAC lines in each (:func:`lidarfx.vector.lines.extract_segments`,
   inlier distance ``threshold``), collinear pieces merged and refitted;
3. **placement** — each segment, best supported first, with all points of the
   cloud within ``radius`` of it: an *edge* segment (most of its points labelled
   edge or corner) becomes the intersection line of the two dominant planes
   there when they form a crease (:func:`_edge_line`); otherwise the dominant
   plane's border is placed by the convex hull of its points (direction) and a
   maximum-likelihood fit of an even spread cut off at the border and blurred by
   the noise (:func:`_border_line`).  The placement repeats around its own result
   until it settles; it may move a segment by at most :data:`MAX_MOVE` radii and
   turn it by at most :data:`MAX_TURN`.  A placed segment grows along its line
   over the candidates that continue it, is placed again, and claims them; later
   segments that duplicate it are dropped, and so are segments that cannot be
   placed (``keep_unrefined`` keeps them);
4. **merge** — collinear placed segments (:func:`~lidarfx.vector.lines.merge_collinear`);
5. **polylines** — segment ends that meet are chained; a corner vertex is the
   closest point of the two lines (:func:`~lidarfx.vector.lines.chain_segments`);
6. **simplify** — 3-D Douglas–Peucker (:func:`~lidarfx.vector.lines.douglas_peucker`);
   polylines shorter than ``min_length`` are dropped.

Every polyline carries its length, point support (candidate points of its
segments), RMS distance of those points to it, ``kind`` (``edge`` or ``border``,
by the larger share of its length), ``edge_share``, ``segments`` and ``slope``.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError, check_int
from .vector.lines import (
    LineSegment,
    chain_segments,
    douglas_peucker,
    extract_segments,
    merge_collinear,
    point_polyline_distance,
)
from .vector.polyline import Polyline

EDGE_LABELS = ("plane_border", "edge", "corner")
"""Structure labels whose points become edge-line candidates by default."""

FACTORS = {"link": 0.5, "threshold": 0.5, "join": 1.0, "simplify": 0.1, "plane_threshold": 0.1, "min_length": 1.0}
"""Defaults of the length parameters as multiples of the radius."""

MAX_MOVE = 0.75
"""A refinement may move a segment's midpoint by at most this many radii (a band of edge
points is about one radius wide, so a band's own line can sit half a radius off)."""
MAX_TURN = 25.0
"""A refinement may turn a segment by at most this many degrees."""
CONVERGED = 0.05
"""A refinement has settled when a round moves the segment's ends by less than this many radii."""
GROW_ROUNDS = 3
"""Grow-and-place rounds of a placed segment."""
MIN_BAND_SUPPORT = 0.7
"""A placed segment is kept when candidate points lie within the RANSAC threshold of at least
this share of its length."""
GROW_DRIFT = 1.0
"""Growth along a placed line stops where the candidates' mean offset from it changes by more
than this many RANSAC thresholds (a curved band leaving the line)."""
BORDER_BAND = 0.5
"""Width (radii) of the band of plane points inside a border whose mean places the border."""
BORDER_OUTSIDE = 0.05
"""A border may have at most this share of its plane's points beyond it (more than 3 σ)."""
CREASE_BALANCE = 0.2
"""The smaller of the two planes of an edge needs at least this share of the larger's points
(ALS sees walls sparsely: a roof over a few wall points is placed by its border)."""
CREASE_OUTSIDE = 0.1
"""Two planes make an edge only where each lies on one side of their intersection line: at
most this share of a plane's points may lie beyond the line (else: the border of one plane,
e.g. a roof eave over the wall-roof line)."""

__all__ = ["EDGE_LABELS", "EdgeLines", "extract_edges", "refine_segment"]


@dataclass
class EdgeLines:
    """Result of :func:`extract_edges`: the polylines, the segments before chaining, the cloud
    with ``structure`` (and ``edge_candidate``) attributes, and the run's parameters,
    counts and timings in ``meta``."""

    lines: list[Polyline]
    segments: list[LineSegment]
    cloud: PointCloud
    meta: dict[str, Any] = field(default_factory=dict)


def _length(name: str, value: Any, default: float) -> float:
    if value is None:
        return float(default)
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if not (v > 0 and math.isfinite(v)):
        raise LidarfxError(f"{name} must be a positive length in metres, got {value!r}")
    return v


def check_edge_options(radius: Any = None, *, labels: Sequence[str] = EDGE_LABELS, min_points: Any = 8, seed: Any = 0,
                       merge_angle: Any = 5.0, **lengths: Any) -> tuple[int, int]:
    """Every option check of :func:`extract_edges`, before any work: the labels, ``min_points``,
    ``seed``, ``merge_angle``, and ``radius`` and the ``lengths`` (``link``, ``threshold``,
    ``max_gap``, ``join``, ``simplify``, ``plane_threshold``, ``min_length``; None = the default)
    positive.  Returns ``(min_points, seed)`` as integers."""
    from .structures import LABELS

    names = {v: k for k, v in LABELS.items()}
    bad = [lab for lab in labels if lab not in names]
    if bad or not labels:
        raise LidarfxError(f"labels must be structure names ({', '.join(n for n in names if n != 'unclassified')}), "
                           f"got {', '.join(map(str, bad)) or 'none'}")
    min_points = check_int("min_points", min_points, 2, 1_000_000)
    seed = check_int("seed", seed, 0, 2**32 - 1)
    if not (isinstance(merge_angle, (int, float)) and not isinstance(merge_angle, bool) and 0 < merge_angle <= 45):
        raise LidarfxError(f"merge_angle must be in (0, 45] degrees, got {merge_angle!r}")
    for name, value in {"radius": radius, **lengths}.items():
        if value is not None:
            _length(name, value, 0.0)
    return min_points, seed


def extract_edges(
    cloud: PointCloud,
    radius: float | None = None,
    *,
    labels: Sequence[str] = EDGE_LABELS,
    use_structure: bool = False,
    references: Any = "trained",
    link: float | None = None,
    threshold: float | None = None,
    min_points: int = 8,
    min_length: float | None = None,
    max_gap: float | None = None,
    refine: bool = True,
    keep_unrefined: bool = False,
    keep_cloud_border: bool = False,
    plane_threshold: float | None = None,
    merge_angle: float = 5.0,
    join: float | None = None,
    simplify: float | None = None,
    seed: int = 0,
    progress: bool | None = None,
    units: str = "auto",
) -> EdgeLines:
    """3-D edge lines of a point cloud (module docstring for the steps).

    Parameters
    ----------
    cloud:
        The point cloud.
    radius:
        Radius of the structure classification and of the placement (m).
        Default: :func:`lidarfx.structures.default_radius`.
    labels:
        Structure labels whose points are candidates (default: plane_border, edge, corner).
    use_structure:
        Use the cloud's own ``structure`` attribute (from ``lidarfx eigenclass``)
        instead of classifying again.
    references:
        References of the classification (see :func:`lidarfx.classify_structures`).
    link, threshold, max_gap, join, simplify, plane_threshold, min_length:
        Lengths (m): link distance of the components (default 0.5 r),
        RANSAC inlier distance (0.5 r), largest gap along a segment (3 ×
        threshold), largest distance of two segment ends that are joined (r),
        Douglas–Peucker tolerance (0.1 r), plane inlier distance of the
        refinement (0.1 r), shortest polyline kept (r).
    min_points:
        Fewest candidate points of a segment.
    refine, keep_unrefined:
        Place the segments with the whole cloud (step 3); by default a segment whose
        refinement fails is dropped (``keep_unrefined`` keeps it with its band's line).
    keep_cloud_border:
        Keep candidates within ``radius`` of the boundary of the cloud's plan convex hull
        (by default they are dropped: a tile's edges are borders of every surface they cut).
    merge_angle:
        Largest angle (degrees) between collinear segments that are merged.
    seed:
        Seed of the RANSAC draws (results are deterministic).
    units:
        ``"auto"`` (default): the radius and the lengths are metres, converted when the LAS
        header's CRS names another linear unit (US survey feet, feet); ``"native"``: coordinate
        units as given.  ``meta`` gives them in metres; the lines are in the cloud's coordinates.
    """
    from .crs import metres_per_unit
    from .segment.components import linked_components
    from .structures import LABELS, classify_structures, default_radius

    if not isinstance(cloud, PointCloud):
        raise LidarfxError("extract_edges expects a PointCloud (see lidarfx.read)")
    names = {v: k for k, v in LABELS.items()}
    min_points, seed = check_edge_options(radius, labels=labels, min_points=min_points, seed=seed,
                                          merge_angle=merge_angle, link=link, threshold=threshold, max_gap=max_gap,
                                          join=join, simplify=simplify, plane_threshold=plane_threshold,
                                          min_length=min_length)
    if len(cloud) == 0:
        raise LidarfxError("the point cloud is empty")
    if use_structure and "structure" not in cloud:
        raise LidarfxError("the cloud has no 'structure' attribute; run lidarfx eigenclass first or classify here")
    t0 = time.perf_counter()
    u = metres_per_unit(cloud, units)  # lengths in metres -> coordinate units (defaults are already)
    r = _length("radius", radius, 0.0) / u if radius is not None else default_radius(cloud)
    link = _length("link", link, FACTORS["link"] * r * u) / u
    threshold = _length("threshold", threshold, FACTORS["threshold"] * r * u) / u
    max_gap = _length("max_gap", max_gap, 3.0 * threshold * u) / u
    join = _length("join", join, FACTORS["join"] * r * u) / u
    simplify = _length("simplify", simplify, FACTORS["simplify"] * r * u) / u
    plane_threshold = _length("plane_threshold", plane_threshold, FACTORS["plane_threshold"] * r * u) / u
    min_length = _length("min_length", min_length, FACTORS["min_length"] * r * u) / u

    if use_structure:
        work = PointCloud(cloud.xyz, dict(cloud.attrs), cloud.header, cloud.meta)
    else:
        work = classify_structures(cloud, r, references=references, progress=progress, units="native")
    t1 = time.perf_counter()
    struct = np.asarray(work["structure"]).astype(np.int64)
    is_cand = np.isin(struct, [names[lab] for lab in labels])
    xyz = work.xyz
    origin = xyz.min(axis=0)
    if not keep_cloud_border:  # the tile's own edges are borders of every surface they cut
        is_cand &= _hull_distance(xyz[:, :2] - origin[:2], is_cand) > r
    cand_ids = np.flatnonzero(is_cand)
    work["edge_candidate"] = is_cand.astype(np.uint8)
    local = xyz - origin
    cand = local[cand_ids]
    edge_like = np.isin(struct[cand_ids], [names["edge"], names["corner"]])

    segments: list[LineSegment] = []
    comp_count = 0
    if len(cand):
        comp = linked_components(cand, link)
        order = np.argsort(comp, kind="stable")
        bounds = np.flatnonzero(np.diff(comp[order])) + 1
        rng = np.random.default_rng(seed)
        for ids in np.split(order, bounds):
            if len(ids) < min_points:
                continue
            comp_count += 1
            for s in extract_segments(cand[ids], threshold=threshold, min_points=min_points,
                                      min_length=0.5 * min_length, max_gap=max_gap, seed=int(rng.integers(2**31))):
                s.index = ids[s.index]  # indices into the candidates
                segments.append(s)
    # collinear pieces of one band (split by gaps or found as parallel lines) become one segment,
    # refitted on all their points, before the refinement looks at the cloud around it
    segments = merge_collinear(segments, cand, angle=merge_angle, offset=threshold, gap=join)
    t2 = time.perf_counter()
    for s in segments:
        s.label = "edge" if edge_like[s.index].mean() >= 0.5 else "border"
    refined = 0
    if refine and segments:
        segments, refined = _refine_all(segments, cand, local, r, threshold, max_gap, plane_threshold, seed)
    t3 = time.perf_counter()
    # refined segments of the same line (a band found twice) merge once more
    if refine and not keep_unrefined:
        segments = [s for s in segments if s.fixed]
    merged = merge_collinear(segments, None, angle=merge_angle, offset=0.5 * threshold, gap=join)
    merged_kind = [s.label for s in merged]
    chains = chain_segments(merged, join=join, offset=threshold)
    lines: list[Polyline] = []
    for verts, seg_ids, closed in chains:
        v = douglas_peucker(verts, simplify, closed=closed)
        if closed and len(v) < 3:
            closed = False
        if len(v) < 2:
            continue
        support_ids = np.unique(np.concatenate([merged[i].index for i in seg_ids]))
        seg_len = np.array([merged[i].length for i in seg_ids])
        edge_len = sum(L for L, i in zip(seg_len, seg_ids) if merged_kind[i] == "edge")
        share = float(edge_len / seg_len.sum()) if seg_len.sum() > 0 else 0.0
        d = point_polyline_distance(cand[support_ids], np.vstack([v, v[:1]]) if closed else v)
        pl = Polyline(v + origin, support=len(support_ids), rms=float(np.sqrt(np.mean(d * d))) if len(d) else math.nan,
                      kind="edge" if share >= 0.5 else "border", closed=closed,
                      attrs={"edge_share": round(share, 3), "segments": len(seg_ids), "slope": round(_slope(v), 2)})
        if pl.length >= min_length:
            lines.append(pl)
    lines.sort(key=lambda p: -p.length)
    for s in merged:
        s.start = s.start + origin
        s.end = s.end + origin
    t4 = time.perf_counter()
    meta = {
        "radius": r * u,
        "labels": list(labels),
        "lengths": "m" if units == "auto" else "coordinate units",
        "unit_to_metre": u if units == "auto" else None,
        "parameters": {"link": link * u, "threshold": threshold * u, "max_gap": max_gap * u, "join": join * u,
                       "simplify": simplify * u, "plane_threshold": plane_threshold * u,
                       "min_length": min_length * u, "min_points": min_points,
                       "merge_angle": float(merge_angle), "refine": bool(refine),
                       "keep_unrefined": bool(keep_unrefined), "keep_cloud_border": bool(keep_cloud_border), "seed": seed},
        "candidates": int(len(cand_ids)),
        "components": comp_count,
        "segments": len(segments),
        "refined_segments": refined,
        "merged_segments": len(merged),
        "lines": len(lines),
        "total_length": round(float(sum(p.length for p in lines)) * u, 3),
        "seconds": {"classify": round(t1 - t0, 3), "segments": round(t2 - t1, 3), "refine": round(t3 - t2, 3),
                    "polylines": round(t4 - t3, 3)},
    }
    if "structures" in work.meta:
        meta["structures"] = work.meta["structures"]
    return EdgeLines(lines, merged, work, meta)


def _refine_all(segments: list[LineSegment], cand: np.ndarray, local: np.ndarray, r: float, threshold: float,
                max_gap: float, plane_threshold: float, seed: int) -> tuple[list[LineSegment], int]:
    """Refine the segments greedily, the best supported first.  A refined (fixed) segment
    grows along its line over the candidate points within ``threshold`` that continue it
    without a gap over ``max_gap`` (a band's ends bend into the neighbouring band near
    corners, where RANSAC leaves short crooked pieces) and claims them.  A later segment is
    dropped before its refinement when half of its points are claimed, or lie within ``r``
    of a fixed segment running within 20° of it: the rest of a band that is already placed.
    Returns the kept segments and how many were refined."""
    from .neighbors import NeighborIndex

    index = NeighborIndex(local, cell=r, origin=np.zeros(3))
    cand_index = NeighborIndex(cand, cell=max(threshold, 1e-6), origin=np.zeros(3))
    claimed = np.zeros(len(cand), bool)
    keep: list[LineSegment] = []
    cos20 = math.cos(math.radians(20.0))

    class _Lines:
        """Fixed segments as arrays, for the duplicate test."""

        def __init__(self) -> None:
            self.segs: list[LineSegment] = []
            self.mid = np.zeros((0, 3))
            self.dir = np.zeros((0, 3))
            self.len = np.zeros(0)

        def add(self, f: LineSegment) -> None:
            self.segs.append(f)
            self.mid = np.vstack([self.mid, 0.5 * (f.start + f.end)])
            self.dir = np.vstack([self.dir, f.direction])
            self.len = np.r_[self.len, f.length]

        def duplicates(self, s: LineSegment) -> bool:
            """Half of ``s``'s points within ``r`` of a segment running within 20° of it."""
            if not self.segs:
                return False
            mid = 0.5 * (s.start + s.end)
            near = (np.abs(self.dir @ s.direction) >= cos20) & (
                np.linalg.norm(self.mid - mid, axis=1) <= 0.5 * (s.length + self.len) + r)
            if not near.any():
                return False
            p = cand[s.index]
            return any(np.mean(point_polyline_distance(p, np.array([self.segs[i].start, self.segs[i].end])) <= r) >= 0.5
                       for i in np.flatnonzero(near))

    fixed = _Lines()
    order = sorted(range(len(segments)), key=lambda i: (-segments[i].support, i))
    for k in order:
        s = segments[k]
        if claimed[s.index].mean() >= 0.5:
            continue
        if fixed.duplicates(s):
            continue
        new = refine_segment(s, s.label, local, index, r, plane_threshold, seed=seed + k)
        if new is not None:
            kind0 = s.label
            s.start, s.end, s.label = new
            s.fixed = True
            placed = (s.start.copy(), s.end.copy(), s.label)
            for _ in range(GROW_ROUNDS):
                # grow, then place the grown line again with all its length (a short piece
                # could only move, not turn; a grown line must still be where the data put it)
                L0 = s.length
                _grow(s, cand, cand_index, threshold, max_gap)
                if s.length <= 1.1 * L0 + 1e-9:
                    s.start, s.end, s.label = placed  # hardly grown: keep the placed line
                    break
                again = refine_segment(s, kind0, local, index, r, plane_threshold, seed=seed + k)
                if again is None:  # the grown line is not confirmed: keep the last placed one
                    s.start, s.end, s.label = placed
                    break
                s.start, s.end, s.label = again
                placed = (s.start.copy(), s.end.copy(), s.label)
            run = _grow(s, cand, cand_index, threshold, max_gap, extend=False)
            s.index = np.unique(np.r_[s.index, run]).astype(np.int64)
            claimed[run] = True
            fixed.add(s)
        keep.append(s)
    # duplicates: pieces met before the line they belong to was placed, and second lines
    # placed within a radius of a better supported one (not resolvable at this radius)
    out: list[LineSegment] = []
    kept_fixed = _Lines()
    for s in sorted(keep, key=lambda s: (not s.fixed, -s.support)):
        if not s.fixed and claimed[s.index].mean() >= 0.5:
            continue
        if s.fixed and _band_support(s, cand_index, threshold) < MIN_BAND_SUPPORT:
            continue  # placed where the band is not: a line cutting across a plane
        if kept_fixed.duplicates(s):
            continue
        out.append(s)
        if s.fixed:
            kept_fixed.add(s)
    return out, len(kept_fixed.segs)


def _along(s: LineSegment, step: float, before: float = 0.0, after: float = 0.0) -> np.ndarray:
    """Points on the line of ``s`` from ``before`` ahead of its start to ``after`` past its end,
    at most ``step`` apart (both ends included)."""
    span = s.length + before + after
    n = max(int(math.ceil(span / step)), 1) + 1
    return s.start + np.linspace(-before, s.length + after, n)[:, None] * s.direction


def _band_support(s: LineSegment, cand_index, threshold: float) -> float:
    """Share of the segment's length (sampled every ``threshold / 2``) with a candidate point
    within ``threshold``."""
    return float(np.mean(cand_index.count(_along(s, 0.5 * threshold), threshold) > 0))


def _grow(s: LineSegment, cand: np.ndarray, cand_index, threshold: float, max_gap: float, *,
          extend: bool = True) -> np.ndarray:
    """Extend ``s`` (in place) over the candidate points within ``threshold`` of its line that
    continue it: walking out from each end in windows of ``threshold``, growth stops at a
    gap over ``max_gap`` or where the points' mean offset from the line differs from that
    along ``s`` by more than :data:`GROW_DRIFT` × ``threshold`` (a curved band leaves the line).  Returns
    the indices of the points along the grown segment (``extend=False``: along ``s`` as it is)."""
    d = s.direction
    L = s.length
    reach = max(L, 10.0 * max_gap) if extend else 0.0
    _, ids, _ = cand_index.query_radius(_along(s, threshold, reach, reach), 1.5 * threshold)
    ids = np.unique(ids)
    q = cand[ids] - s.start
    t = q @ d
    res = q - t[:, None] * d[None, :]
    near = np.sqrt((res * res).sum(axis=1)) <= threshold
    ids, t, res = ids[near], t[near], res[near]
    inside = (t >= 0) & (t <= L)
    if not inside.any():
        return ids[:0]
    ref = res[inside].mean(axis=0)
    lo, hi = 0.0, L
    for sign in ((-1.0, 1.0) if extend else ()):
        edge = 0.0 if sign < 0 else L
        beyond = t < 0 if sign < 0 else t > L
        tb = np.abs(t[beyond] - edge)
        rb = res[beyond]
        order = np.argsort(tb)
        tb, rb = tb[order], rb[order]
        pos, last = 0.0, 0.0
        k = 0
        while k < len(tb):
            if tb[k] - last > max_gap:
                break
            w_end = tb[k] + threshold
            j = int(np.searchsorted(tb, w_end, side="right"))
            if np.linalg.norm(rb[k:j].mean(axis=0) - ref) > GROW_DRIFT * threshold:
                break
            last = tb[j - 1]
            pos = last
            k = j
        if sign < 0:
            lo = -pos
        else:
            hi = L + pos
    s.start, s.end = s.start + lo * d, s.start + hi * d
    return ids[(t >= lo) & (t <= hi)]


def _hull_distance(xy: np.ndarray, which: np.ndarray) -> np.ndarray:
    """Plan distance of the points ``which`` to the boundary of the convex hull of all ``xy``
    (+inf elsewhere, and everywhere when the hull is degenerate)."""
    from scipy.spatial import ConvexHull, QhullError

    out = np.full(len(xy), np.inf)
    try:
        hull = ConvexHull(xy)
    except (QhullError, ValueError):
        return out
    # inside a convex polygon the distance to its boundary is the smallest distance to the
    # lines of its edges: -(a·x + b·y + c) for the outward unit normals (a, b) of qhull
    eq = hull.equations
    p = xy[which]
    out[which] = (-(p @ eq[:, :2].T + eq[:, 2])).min(axis=1)
    return out


def _slope(v: np.ndarray) -> float:
    """Length-weighted mean elevation angle (degrees) of the polyline's segments."""
    d = np.diff(v, axis=0)
    L = np.linalg.norm(d, axis=1)
    if L.sum() == 0:
        return 0.0
    ang = np.degrees(np.arctan2(np.abs(d[:, 2]), np.linalg.norm(d[:, :2], axis=1)))
    return float((ang * L).sum() / L.sum())


def _tube(seg: LineSegment, local: np.ndarray, index, r: float) -> np.ndarray:
    """Indices of the cloud's points within ``r`` of the segment (its ends extended by r/2)."""
    L = seg.length
    d = seg.direction
    offsets, ids, _ = index.query_radius(_along(seg, 0.5 * r, 0.5 * r, 0.5 * r) + index.origin, r)
    ids = np.unique(ids)
    q = local[ids] - seg.start
    tt = q @ d
    perp = np.sqrt(np.maximum((q * q).sum(axis=1) - tt * tt, 0.0))
    keep = (perp <= r) & (tt >= -0.5 * r) & (tt <= L + 0.5 * r)
    return ids[keep]


def refine_segment(seg: LineSegment, kind: str, local: np.ndarray, index, r: float, plane_threshold: float, *,
                   seed: int = 0, rounds: int = 4) -> tuple[np.ndarray, np.ndarray, str] | None:
    """The refined ends of a segment (in the coordinates of ``local``) and what it turned out
    to be, ``(start, end, "edge" | "border")``, or ``None`` when the refinement fails its
    checks (module docstring, step 3).  ``kind`` ``"edge"`` tries the plane intersection
    first, then the border.  The refinement is repeated around its own result (up to
    ``rounds`` times, until it moves less than 5 % of the radius): a band's line that
    crosses the band at an angle sees the border only partly the first time.  A line that
    has not settled after ``rounds`` is refused."""
    d0 = seg.direction
    mid0 = 0.5 * (seg.start + seg.end)
    cur = LineSegment(seg.start.copy(), seg.end.copy())
    how = kind
    done = converged = False
    for k in range(rounds):
        ids = _tube(cur, local, index, r)
        if len(ids) < 6:
            break
        pts = local[ids]
        line, how_k = None, "edge"
        if kind == "edge":
            line = _edge_line(pts, plane_threshold, seed + k)
            if line is not None:  # a crease must also be one in the tube around itself
                p, d = line
                if d @ d0 < 0:
                    d = -d
                around = LineSegment(p + ((cur.start - p) @ d) * d, p + ((cur.end - p) @ d) * d)
                ids2 = _tube(around, local, index, r)
                if len(ids2) < 6 or _edge_line(local[ids2], plane_threshold, seed + k) is None:
                    line = None
        if line is None:
            line, how_k = _border_line(pts, cur, plane_threshold, r, seed + k), "border"
        if line is None:
            break
        p, d = line
        if d @ d0 < 0:
            d = -d
        if d @ d0 < math.cos(math.radians(MAX_TURN)):
            break
        foot = p + ((mid0 - p) @ d) * d  # the original midpoint must stay close to the new line
        if np.linalg.norm(foot - mid0) > MAX_MOVE * r:
            break
        a = p + ((seg.start - p) @ d) * d
        b = p + ((seg.end - p) @ d) * d
        moved = max(float(np.linalg.norm(a - cur.start)), float(np.linalg.norm(b - cur.end))) if done else math.inf
        cur, how, done = LineSegment(a, b), how_k, True
        if moved < CONVERGED * r:
            converged = True
            break
    # a line that still moves is not where the data put it (a border estimate from a band
    # line crossing the plane drifts from round to round)
    return (cur.start, cur.end, how) if done and converged else None


def _edge_line(pts: np.ndarray, thr: float, seed: int):
    """Intersection of the two dominant planes of ``pts`` (each ≥ 6 inliers, ≥ 15° apart)."""
    from .geometry import fit_plane, intersect_planes, ransac_plane

    first = ransac_plane(pts, thr, seed=seed)
    if first is None or first[2].sum() < 6:
        return None
    second = ransac_plane(pts, thr, seed=seed + 1, alive=~first[2])
    if second is None or second[2].sum() < 6:
        return None
    c1, n1, in1 = first
    c2, n2, in2 = second
    for _ in range(2):  # each point to the nearer plane; points close to both (at the edge) to neither
        e1 = np.abs((pts - c1) @ n1)
        e2 = np.abs((pts - c2) @ n2)
        in1 = (e1 <= thr) & ((e2 > thr) | (e1 < 0.5 * e2))
        in2 = (e2 <= thr) & ((e1 > thr) | (e2 < 0.5 * e1))
        if in1.sum() < 6 or in2.sum() < 6:
            return None
        c1, n1, _ = fit_plane(pts[in1])
        c2, n2, _ = fit_plane(pts[in2])
    if abs(float(n1 @ n2)) > math.cos(math.radians(15.0)):
        return None
    if min(in1.sum(), in2.sum()) < CREASE_BALANCE * max(in1.sum(), in2.sum()):  # a few wall points under a roof: its border
        return None
    line = intersect_planes(c1, n1, c2, n2)
    if line is None:
        return None
    p, d = line
    for n, inl in ((n1, in1), (n2, in2)):
        u = np.cross(n, d)
        w = (pts[inl] - p) @ u
        if np.median(w) < 0:
            w = -w
        if np.mean(w < -2.0 * thr) > CREASE_OUTSIDE:  # the plane reaches across the line: no crease
            return None
    return line


def _border_line(pts: np.ndarray, seg: LineSegment, thr: float, r: float, seed: int):
    """The boundary line of the dominant plane of ``pts`` near the segment."""
    from .geometry import ransac_plane

    found = ransac_plane(pts, thr, seed=seed)
    if found is None or found[2].sum() < 6:
        return None
    c, n, inl = found
    d = seg.direction - (seg.direction @ n) * n
    if np.linalg.norm(d) < 0.5:  # the segment is far from lying in this plane
        return None
    d = d / np.linalg.norm(d)
    u = np.cross(n, d)
    a = seg.start - ((seg.start - c) @ n) * n  # the segment start projected onto the plane
    L = seg.length
    q = pts[inl] - a
    t = q @ d
    w = q @ u
    side = 1.0 if np.median(w) >= 0 else -1.0  # the plane lies on this side of the border
    # the border's direction from the plane points' convex hull: its edges away from the tube
    # wall (where the tube, not the plane, ends) follow the border even when the band's line
    # crosses it at an angle
    qs = pts[inl] - seg.start
    ts = qs @ seg.direction
    perp = np.sqrt(np.maximum((qs * qs).sum(axis=1) - ts * ts, 0.0))
    # (a radius away from the segment's ends, where another border may turn the hull)
    trim = min(r, 0.25 * L)
    mid_part = (ts >= trim) & (ts <= L - trim)
    wall = (perp > 0.85 * r) | (ts < trim + 0.15 * r) | (ts > L - trim - 0.15 * r)
    # (a chord shorter than two radii turns more than it helps: short pieces keep their
    # direction, move only, and are placed again once they have grown)
    hull = _hull_border(t[mid_part], w[mid_part], wall[mid_part], 2.0 * r) if L - 2 * trim >= 2.0 * r else None
    if hull is not None:
        (dt, dw), side = hull
        d = dt * d + dw * u
        d = d / np.linalg.norm(d)
        if d @ seg.direction < 0:
            d, side = -d, -side
        u = np.cross(n, d)
        t = q @ d
        w = q @ u
    wo = -side * w  # outward coordinate: the border is at its maximum
    n_sl = max(2, int(L / (0.5 * r)))
    edges_t = np.linspace(0.0, L, n_sl + 1)
    which = np.searchsorted(edges_t, t, side="right") - 1
    tm, wm = [], []
    for k in range(n_sl):
        sel = which == k
        if sel.sum() >= 2:
            j = np.argmax(np.where(sel, wo, -np.inf))
            tm.append(t[j])
            wm.append(wo[j])
    if len(tm) < 2:
        return None
    tm, wm = np.asarray(tm), np.asarray(wm)
    short = L - 2 * trim < 2.0 * r  # too short for a direction: keep the band's, fit the offset only
    if short:
        beta, alpha = 0.0, float(np.median(wm))
    else:
        beta, alpha = np.polyfit(tm, wm, 1)
    # Band mean: for points spread evenly over the plane, those within b inside the border
    # (and every point beyond it) have the mean position border − b/2, whatever the noise
    # across the border (it moves as many points out as in).  A linear regression of the
    # outward coordinate on t over that band gives border − b/2 along the whole segment;
    # iterate from the outermost points' line until the band stops changing.
    b = BORDER_BAND * r
    # near the segment's ends another border or edge crosses the band (a roof corner):
    # the border is placed with the points a radius away from both ends (the middle half
    # of a short segment)
    inside = (t >= trim) & (t <= L - trim)
    sel = None
    for _ in range(20):
        new = inside & (wo >= alpha + beta * t - b)
        if new.sum() < 4:
            return None
        if sel is not None and (new == sel).all():
            break
        sel = new
        if short:
            beta, alpha = 0.0, float(wo[sel].mean()) + 0.5 * b
        else:
            beta, a0 = np.polyfit(t[sel], wo[sel], 1)
            alpha = float(a0) + 0.5 * b
    # the offset by maximum likelihood: the band's points beyond lo = border − b (the window
    # fixed now) come from an even spread cut off at the border and blurred by the noise σ
    # across it (σ = the plane fit's RMS); for σ → 0 this is the outermost point, for a
    # noisy border it weighs every point near it
    sigma = max(float(np.sqrt(np.mean(((pts[inl] - c) @ n) ** 2))), 1e-3 * r)
    alpha, beta = _border_mle(t[inside], wo[inside], alpha, beta, b, sigma, L, fit_direction=not short)
    # a border has the plane on one side only: hardly any plane point lies beyond it (a line
    # across the plane, from a band's line cutting the band at an angle, has many)
    beyond = wo[inside] > alpha + beta * t[inside] + max(3.0 * sigma, 0.05 * r)
    if beyond.mean() > BORDER_OUTSIDE:
        return None
    p0 = a - side * alpha * u
    dn = d - side * beta * u
    return p0, dn / np.linalg.norm(dn)


def _hull_border(t: np.ndarray, w: np.ndarray, wall: np.ndarray, min_chord: float):
    """Direction ``(dt, dw)`` of the longest run of convex-hull edges of the points
    ``(t, w)`` whose vertices are not ``wall`` points, when its chord is at least
    ``min_chord`` long (else ``None``), and the side of the points in the frame turned to
    that direction (always +1: the hull is walked counter-clockwise)."""
    from scipy.spatial import ConvexHull, QhullError

    if len(t) < 4:
        return None
    try:
        hv = ConvexHull(np.c_[t, w]).vertices  # counter-clockwise
    except (QhullError, ValueError):
        return None
    free = ~wall[hv]
    k = len(hv)
    if free.all() or not free.any():
        return None
    start = int(np.flatnonzero(~free)[0])  # walk the ring from a wall vertex
    best, run = None, []
    for i in range(1, k + 1):
        j = (start + i) % k
        if free[j]:
            run.append(hv[j])
        else:
            if len(run) >= 2 and (best is None or _chord(t, w, run) > _chord(t, w, best)):
                best = run
            run = []
    if best is None or _chord(t, w, best) < min_chord:
        return None
    p0, p1 = best[0], best[-1]
    v = np.array([t[p1] - t[p0], w[p1] - w[p0]])
    v /= np.linalg.norm(v)
    # counter-clockwise hull: the interior lies to the left of the walk direction v, which is
    # +w in the frame turned to v (w' = (n × d')·q): the plane side is +1 there
    return (float(v[0]), float(v[1])), 1.0


def _chord(t: np.ndarray, w: np.ndarray, run: list) -> float:
    return float(math.hypot(t[run[-1]] - t[run[0]], w[run[-1]] - w[run[0]]))


def _border_mle(t: np.ndarray, w: np.ndarray, alpha: float, beta: float, b: float, sigma: float, L: float, *,
                fit_direction: bool = True) -> tuple[float, float]:
    """Maximum-likelihood border ``w = α + β t`` of an even point spread on ``w <= α + β t``
    (0 <= t <= L) blurred by Gaussian noise ``sigma`` across it, from the points in the fixed
    window ``w >= α₀ + β₀ t − b`` (the start values).  The intensity there is
    ρ Φ((α + β t − w)/σ); with ρ profiled out the log-likelihood is
    Σ log Φ((α + β tᵢ − wᵢ)/σ) − N log ∫₀ᴸ G(α + β t − lo(t)) dt, where
    G(s) = sΦ(s/σ) + σφ(s/σ) is the integral of Φ over the window at one t."""
    from scipy.optimize import minimize
    from scipy.special import log_ndtr, ndtr

    a0, b0 = float(alpha), float(beta)
    sel = w >= a0 + b0 * t - b
    t, w = t[sel], w[sel]
    if len(t) < 4:
        return a0, b0
    gx, gw = np.polynomial.legendre.leggauss(8)
    tq = 0.5 * L * (gx + 1.0)
    wq = 0.5 * L * gw
    c = 1.0 / math.sqrt(2.0 * math.pi)

    def nll(x: np.ndarray) -> float:
        al, be = x[0], (x[1] if fit_direction else b0)
        s = (al - a0) + (be - b0) * tq + b  # border minus the window's edge at the nodes
        g = s * ndtr(s / sigma) + sigma * c * np.exp(-0.5 * (s / sigma) ** 2)
        integral = float((wq * g).sum())
        if not integral > 0:
            return 1e300
        return -(float(log_ndtr((al + be * t - w) / sigma).sum()) - len(t) * math.log(integral))

    x0 = np.array([a0, b0]) if fit_direction else np.array([a0])
    step = np.array([0.25 * b, 0.25 * b / max(L, 1e-9)]) if fit_direction else np.array([0.25 * b])
    simplex = np.vstack([x0] + [x0 + np.diag(step)[k] for k in range(len(x0))])
    res = minimize(nll, x0, method="Nelder-Mead",
                   options={"initial_simplex": simplex, "xatol": 1e-5 * b, "fatol": 1e-9, "maxiter": 400})
    x = res.x
    al, be = float(x[0]), float(x[1]) if fit_direction else b0
    if not (abs(al - a0) <= b and abs(be - b0) * L <= b):  # wandered off: keep the band's line
        return a0, b0
    return al, be
