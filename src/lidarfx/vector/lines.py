"""Robust 3-D lines: least-squares and RANSAC fits, segments from point bands, collinear
merging, chaining into polylines and 3-D Douglas–Peucker.

Every function takes and returns numpy arrays (or :class:`LineSegment` /
:class:`~lidarfx.vector.polyline.Polyline` records) and knows nothing of files.
Coordinates may be UTM-sized: fits subtract the points' mean first.

The segment extraction (:func:`extract_segments`) is sequential RANSAC made for
*bands* of points, such as the border or edge points of a classification or the
points of a wire: a hypothesis is the principal axis of the points around a
randomly drawn seed point (more stable than a line through two points of a band
that is several spacings wide), or the line from the seed to a random point
near it, its score the number of points within
``threshold`` of it (MSAC-style: each inlier adds ``1 − d²/threshold²``); the
best hypothesis is refitted by least squares on its inliers (twice), its
inliers are split into runs where the gap along the line exceeds ``max_gap``,
and every run with at least ``min_points`` points and ``min_length`` metres
becomes a segment.  The segments' points leave the pool (all inliers, when no
run qualifies) and the search repeats until no hypothesis holds
``min_points`` points.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba as nb
import numpy as np

from ..errors import LidarfxError
from .polyline import Polyline

__all__ = [
    "LineSegment",
    "fit_line",
    "point_line_distance",
    "point_polyline_distance",
    "ransac_line",
    "extract_segments",
    "merge_collinear",
    "chain_segments",
    "douglas_peucker",
    "closest_points_of_lines",
]


@dataclass
class LineSegment:
    """A straight 3-D segment fitted to points: ``start``/``end`` (3,), the indices of its
    points in the array it was fitted to (``index``), the RMS distance of those points
    to the line (m), a free ``label`` (what the segment is, e.g. ``"edge"``) and
    ``fixed``: its line was placed precisely by other means (e.g. a plane
    intersection), so :func:`merge_collinear` extends it but does not move it (of two
    fixed segments, the longer one's line is kept)."""

    start: np.ndarray
    end: np.ndarray
    index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    rms: float = math.nan
    label: str = ""
    fixed: bool = False

    @property
    def direction(self) -> np.ndarray:
        d = self.end - self.start
        n = float(np.linalg.norm(d))
        return d / n if n > 0 else np.array([1.0, 0.0, 0.0])

    @property
    def length(self) -> float:
        return float(np.linalg.norm(self.end - self.start))

    @property
    def support(self) -> int:
        return int(len(self.index))


# ------------------------------------------------------------------ fits
def fit_line(points: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, float, tuple[float, float]]:
    """Least-squares 3-D line (principal axis): ``(centroid, unit direction, rms, (t_min, t_max))``.

    ``rms`` is the (weighted) RMS distance of the points to the line, ``t`` the
    positions of the points along it relative to the centroid.  The direction is
    made to point towards +x (then +y, +z) so that fits are reproducible.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) < 2:
        raise LidarfxError("a line needs at least 2 points of 3 coordinates")
    w = np.ones(len(p)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(p),) or not np.isfinite(w).all() or (w < 0).any():
        raise LidarfxError(f"line weights must be {len(p)} finite numbers >= 0, got shape {w.shape}")
    sw = float(w.sum())
    if not sw > 0:
        raise LidarfxError("line weights must have a positive sum")
    c = (w[:, None] * p).sum(axis=0) / sw
    q = p - c
    cov = (w[:, None, None] * (q[:, :, None] * q[:, None, :])).sum(axis=0) / sw
    val, vec = np.linalg.eigh(cov)
    d = vec[:, 2]
    d = _canonical_direction(d)
    t = q @ d
    perp2 = np.maximum((q * q).sum(axis=1) - t * t, 0.0)
    rms = math.sqrt(float((w * perp2).sum() / sw))
    return c, d, rms, (float(t.min()), float(t.max()))


def _canonical_direction(d: np.ndarray) -> np.ndarray:
    for k in range(3):
        if abs(d[k]) > 1e-12:
            return d if d[k] > 0 else -d
    return d


def point_line_distance(points: np.ndarray, point: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Distances of ``points`` (n, 3) to the infinite line through ``point`` along ``direction``."""
    q = np.asarray(points, dtype=np.float64) - np.asarray(point, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    t = q @ d
    return np.sqrt(np.maximum((q * q).sum(axis=1) - t * t, 0.0))


def point_polyline_distance(points: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """3-D distance of every point to the nearest segment of the polyline ``vertices`` (k, 3)."""
    p = np.asarray(points, dtype=np.float64)
    v = np.asarray(vertices, dtype=np.float64)
    o = v.min(axis=0)
    return _polyline_distance(np.ascontiguousarray(p - o), np.ascontiguousarray(v - o))


@nb.njit(cache=True)
def _polyline_distance(p, v):
    n = p.shape[0]
    out = np.empty(n)
    for i in range(n):
        best = np.inf
        for k in range(v.shape[0] - 1):
            ax, ay, az = v[k, 0], v[k, 1], v[k, 2]
            dx, dy, dz = v[k + 1, 0] - ax, v[k + 1, 1] - ay, v[k + 1, 2] - az
            qx, qy, qz = p[i, 0] - ax, p[i, 1] - ay, p[i, 2] - az
            ll = dx * dx + dy * dy + dz * dz
            t = 0.0 if ll == 0.0 else (qx * dx + qy * dy + qz * dz) / ll
            t = min(max(t, 0.0), 1.0)
            ex, ey, ez = qx - t * dx, qy - t * dy, qz - t * dz
            d2 = ex * ex + ey * ey + ez * ez
            if d2 < best:
                best = d2
        out[i] = math.sqrt(best)
    return out


def closest_points_of_lines(p1, d1, p2, d2) -> tuple[np.ndarray, np.ndarray, float]:
    """Closest points of two infinite 3-D lines and their distance; parallel lines give
    ``p1`` and its foot on the second line."""
    p1, d1, p2, d2 = (np.asarray(a, dtype=np.float64) for a in (p1, d1, p2, d2))
    w = p1 - p2
    a, b, c = d1 @ d1, d1 @ d2, d2 @ d2
    d, e = d1 @ w, d2 @ w
    den = a * c - b * b
    if den < 1e-12 * a * c:
        s, t = 0.0, e / c
    else:
        s, t = (b * e - c * d) / den, (a * e - b * d) / den
    q1, q2 = p1 + s * d1, p2 + t * d2
    return q1, q2, float(np.linalg.norm(q1 - q2))


# ------------------------------------------------------------------ RANSAC
@nb.njit(cache=True)
def _msac_scores(pts, alive, cs, ds, thr):
    """MSAC score (Σ 1 − d²/thr² over the inliers) of every hypothesis line (cs[h], ds[h])."""
    H = cs.shape[0]
    out = np.zeros(H)
    t2 = thr * thr
    for h in range(H):
        cx, cy, cz = cs[h, 0], cs[h, 1], cs[h, 2]
        dx, dy, dz = ds[h, 0], ds[h, 1], ds[h, 2]
        s = 0.0
        for i in range(pts.shape[0]):
            if not alive[i]:
                continue
            qx, qy, qz = pts[i, 0] - cx, pts[i, 1] - cy, pts[i, 2] - cz
            t = qx * dx + qy * dy + qz * dz
            e2 = qx * qx + qy * qy + qz * qz - t * t
            if e2 < t2:
                s += 1.0 - e2 / t2
        out[h] = s
    return out


def _local_hypotheses(pts: np.ndarray, alive_idx: np.ndarray, seeds: np.ndarray, radius: float,
                      rng: np.random.Generator, pairs: int = 4):
    """Candidate lines through each seed: the principal axis of the alive points within
    ``radius`` (when they are elongated) and the lines to ``pairs`` random partners among
    them at least radius/2 away — a band crowded by other points near one end still
    offers a line along it."""
    from ..neighbors import NeighborIndex

    sub = pts[alive_idx]
    index = NeighborIndex(sub, cell=radius, origin=sub.min(axis=0) if len(sub) else None)
    offsets, nbr, dist = index.query_radius(pts[seeds], radius)
    counts = np.diff(offsets)
    cs, ds = [], []
    has = counts >= 3
    if has.any():
        # covariance of every seed's neighbourhood at once (grouped sums)
        grp = np.repeat(np.arange(len(seeds)), counts)
        q = sub[nbr] - pts[seeds][grp]
        n = np.maximum(counts, 1).astype(float)
        m1 = np.stack([np.bincount(grp, q[:, j], minlength=len(seeds)) for j in range(3)], axis=1) / n[:, None]
        m2 = np.empty((len(seeds), 3, 3))
        for i in range(3):
            for j in range(i, 3):
                m2[:, i, j] = m2[:, j, i] = np.bincount(grp, q[:, i] * q[:, j], minlength=len(seeds)) / n
        cov = m2 - m1[:, :, None] * m1[:, None, :]
        val, vec = np.linalg.eigh(cov[has])
        ok = (val[:, 2] > 0) & (val[:, 1] <= 0.25 * val[:, 2])
        k_ok = np.flatnonzero(has)[ok]
        cs.append(pts[seeds[k_ok]])
        ds.append(vec[ok][:, :, 2])
    # partners: random neighbours, kept when at least radius/2 from the seed
    valid = counts > 0
    if valid.any() and pairs > 0:
        k = np.repeat(np.flatnonzero(valid), pairs)
        j = offsets[k] + (rng.random(len(k)) * counts[k]).astype(np.int64)
        far = dist[j] >= 0.5 * radius
        k, j = k[far], j[far]
        v = sub[nbr[j]] - pts[seeds[k]]
        cs.append(pts[seeds[k]])
        ds.append(v / np.linalg.norm(v, axis=1)[:, None])
    if not cs:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.ascontiguousarray(np.vstack(cs)), np.ascontiguousarray(np.vstack(ds))


def ransac_line(points: np.ndarray, threshold: float, *, hypotheses: int = 64, local_radius: float | None = None,
                seed: int = 0, alive: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The best line of ``points`` (n, 3): ``(inlier mask, point, unit direction)``, or ``None``.

    Hypotheses are principal axes of the points within ``local_radius`` (default
    4 × threshold) around ``hypotheses`` random seed points and lines from each seed
    to four random points there; the best by MSAC score
    is refitted by least squares on its inliers twice.  ``alive`` restricts the
    search to those points (a boolean mask).
    """
    p = np.asarray(points, dtype=np.float64)
    if not (threshold > 0 and math.isfinite(threshold)):
        raise LidarfxError(f"RANSAC threshold must be a positive distance, got {threshold!r}")
    alive = np.ones(len(p), bool) if alive is None else np.asarray(alive, bool)
    idx = np.flatnonzero(alive)
    if len(idx) < 2:
        return None
    o = p[idx].min(axis=0)
    pl = np.ascontiguousarray(p - o)
    rng = np.random.default_rng(seed)
    seeds = idx[rng.choice(len(idx), size=min(int(hypotheses), len(idx)), replace=False)]
    cs, ds = _local_hypotheses(pl, idx, seeds, float(local_radius or 4.0 * threshold), rng)
    if not len(cs):
        return None
    scores = _msac_scores(pl, alive, cs, ds, float(threshold))
    h = int(np.argmax(scores))
    c, d = cs[h], ds[h]
    inl = np.zeros(len(p), bool)
    for _ in range(2):
        dist = point_line_distance(pl[idx], c, d)
        inl[:] = False
        inl[idx[dist <= threshold]] = True
        if inl.sum() < 2:
            return None
        c, d, _, _ = fit_line(pl[inl])
    dist = point_line_distance(pl[idx], c, d)
    inl[:] = False
    inl[idx[dist <= threshold]] = True
    return inl, c + o, d


def _runs(t: np.ndarray, max_gap: float) -> list[np.ndarray]:
    """Indices (into t) of the runs of sorted positions whose steps are at most ``max_gap``."""
    order = np.argsort(t, kind="stable")
    ts = t[order]
    cut = np.flatnonzero(np.diff(ts) > max_gap) + 1
    return [order[a:b] for a, b in zip(np.r_[0, cut], np.r_[cut, len(ts)])]


def extract_segments(points: np.ndarray, *, threshold: float, min_points: int = 10, min_length: float = 1.0,
                     max_gap: float | None = None, hypotheses: int = 64, local_radius: float | None = None,
                     split_tolerance: float | None = None, max_segments: int = 10_000,
                     seed: int = 0) -> list[LineSegment]:
    """Straight segments in a band-like point set by sequential RANSAC (module docstring).

    ``threshold``: largest distance of a point to its line (m; about half the band
    width); ``max_gap``: largest gap along a segment (default 3 × threshold);
    ``split_tolerance``: a run whose band bends away from its line by more than this
    (the mean offset of the points in windows of 2 × threshold; default threshold / 2)
    is split where it bends most, so a curved band becomes a chain of segments.
    Segment ends are the extreme projections of their points; ``index`` refers to
    ``points``.  Deterministic for a given ``seed``.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise LidarfxError("points must have shape (n, 3)")
    if not (threshold > 0 and math.isfinite(threshold)):
        raise LidarfxError(f"threshold must be a positive distance, got {threshold!r}")
    gap = 3.0 * threshold if max_gap is None else float(max_gap)
    split = 0.5 * threshold if split_tolerance is None else float(split_tolerance)
    min_points = max(int(min_points), 2)
    alive = np.ones(len(p), bool)
    out: list[LineSegment] = []
    rng = np.random.default_rng(seed)
    while alive.sum() >= min_points and len(out) < max_segments:
        found = ransac_line(p, threshold, hypotheses=hypotheses, local_radius=local_radius,
                            seed=int(rng.integers(2**31)), alive=alive)
        if found is None:
            break
        inl, c, d = found
        ids = np.flatnonzero(inl)
        if len(ids) < min_points:
            break
        t = (p[ids] - c) @ d
        taken = []
        for run in _runs(t, gap):
            for piece in _straight_pieces(p, ids[run], split, 2.0 * threshold, min_points):
                seg = _segment_of(p, piece)
                if seg is not None:  # the refit may leave a few points beyond the threshold: not its own
                    dist = point_line_distance(p[piece], seg.start, seg.direction)
                    piece = piece[dist <= threshold]
                    if len(piece) < min_points:
                        continue
                    seg.index = piece
                    seg.rms = float(np.sqrt(np.mean(dist[dist <= threshold] ** 2)))
                if seg is not None and seg.length >= min_length:
                    out.append(seg)
                    taken.append(piece)
        # only the points of the segments leave the pool (a line through a sparse sheet of
        # points must not eat holes into the bands it crosses); a line that gave no
        # segment gives up all its inliers, so the search ends
        alive[np.concatenate(taken) if taken else ids] = False
    return out


def _straight_pieces(p: np.ndarray, ids: np.ndarray, tol: float, window: float, min_points: int) -> list[np.ndarray]:
    """Split the points ``p[ids]`` of one run recursively where the mean offset of the
    points from their line (in windows of ``window`` m along it) exceeds ``tol``; pieces
    with fewer than ``min_points`` points are dropped."""
    out: list[np.ndarray] = []
    stack = [np.asarray(ids, np.int64)]
    while stack:
        cur = stack.pop()
        if len(cur) < min_points:
            continue
        q = p[cur] - p[cur[0]]
        c, d, _, _ = fit_line(q)
        t = (q - c) @ d
        res = (q - c) - t[:, None] * d[None, :]
        k = np.floor((t - t.min()) / window).astype(np.int64)
        nb_ = int(k.max()) + 1
        if nb_ < 3:
            out.append(cur)
            continue
        cnt = np.bincount(k, minlength=nb_).astype(float)
        mean = np.stack([np.bincount(k, res[:, j], minlength=nb_) for j in range(3)], axis=1)
        good = cnt >= 2
        dev = np.where(good, np.linalg.norm(mean / np.maximum(cnt, 1)[:, None], axis=1), 0.0)
        worst = int(np.argmax(dev))
        if dev[worst] <= tol:
            out.append(cur)
            continue
        worst = min(max(worst, 1), nb_ - 2)  # split inside, so both pieces keep points
        cut = t.min() + (worst + 0.5) * window
        stack += [cur[t < cut], cur[t >= cut]]
    return out


def _segment_of(p: np.ndarray, ids: np.ndarray) -> LineSegment | None:
    """Least-squares segment of the points ``p[ids]``: ends at the extreme projections."""
    if len(ids) < 2:
        return None
    o = p[ids[0]]
    c, d, rms, (t0, t1) = fit_line(p[ids] - o)
    return LineSegment(c + t0 * d + o, c + t1 * d + o, np.asarray(ids, np.int64), rms)


# ------------------------------------------------------------------ merging
def merge_collinear(segments: list[LineSegment], points: np.ndarray | None = None, *, angle: float = 5.0,
                    offset: float = 0.25, gap: float = 1.0) -> list[LineSegment]:
    """Merge segments that continue each other: directions within ``angle`` degrees, the
    ends of each within ``offset`` m of the other's line, and at most ``gap`` m apart
    along it (overlapping counts).  Merged segments are refitted on the union of their
    points when ``points`` (the array their ``index`` refers to) is given, else on their
    end points weighted by support (a ``fixed`` segment keeps its line).  Every pass
    tests all pairs at once and merges disjoint pairs, longest segments first, until
    nothing merges."""
    segs = list(segments)
    cos_tol = math.cos(math.radians(angle))
    while len(segs) > 1:
        S = len(segs)
        p0 = np.array([sg.start for sg in segs])
        p1 = np.array([sg.end for sg in segs])
        o = p0.min(axis=0)
        p0, p1 = p0 - o, p1 - o
        L = np.linalg.norm(p1 - p0, axis=1)
        D = (p1 - p0) / np.maximum(L, 1e-12)[:, None]
        par = np.abs(D @ D.T) >= cos_tol
        # ends of b (columns) relative to a's line (rows)
        t0 = np.einsum("ak,abk->ab", D, p0[None, :, :] - p0[:, None, :])
        t1 = np.einsum("ak,abk->ab", D, p1[None, :, :] - p0[:, None, :])
        q0 = p0[None, :, :] - p0[:, None, :]
        q1 = p1[None, :, :] - p0[:, None, :]
        e0 = np.sqrt(np.maximum((q0 * q0).sum(axis=2) - t0 * t0, 0.0))
        e1 = np.sqrt(np.maximum((q1 * q1).sum(axis=2) - t1 * t1, 0.0))
        lat = np.maximum(e0, e1)
        sep = np.maximum(np.minimum(t0, t1) - L[:, None], -np.maximum(t0, t1))
        ok = par & (lat <= offset) & (lat.T <= offset) & (sep <= gap)
        np.fill_diagonal(ok, False)
        ok = np.triu(ok | ok.T, 1)
        ia, ib = np.nonzero(ok)
        if not len(ia):
            break
        order = np.argsort(-(L[ia] + L[ib]), kind="stable")
        used = np.zeros(S, bool)
        new_segs = []
        for k in order:
            i, j = int(ia[k]), int(ib[k])
            if used[i] or used[j]:
                continue
            used[i] = used[j] = True
            new_segs.append(_merge_two(segs[i], segs[j], points))
        segs = new_segs + [sg for k, sg in enumerate(segs) if not used[k]]
    segs.sort(key=lambda sg: -sg.length)
    return segs


def _merge_two(a: LineSegment, b: LineSegment, points: np.ndarray | None) -> LineSegment:
    ids = np.unique(np.r_[a.index, b.index]).astype(np.int64)
    ends = np.array([a.start, a.end, b.start, b.end])
    label = a.label if a.length >= b.length else b.label
    rms = math.sqrt((a.support * a.rms**2 + b.support * b.rms**2) / max(a.support + b.support, 1)) \
        if math.isfinite(a.rms) and math.isfinite(b.rms) else math.nan
    if a.fixed or b.fixed:  # keep the fixed line (the longer of two), extend it over both
        f = (a if a.length >= b.length else b) if (a.fixed and b.fixed) else (a if a.fixed else b)
        c, d = f.start, f.direction
        t = (ends - c) @ d
        return LineSegment(c + t.min() * d, c + t.max() * d, ids, rms, label, True)
    if points is not None and len(ids) >= 2 and not a.fixed:
        seg = _segment_of(np.asarray(points, dtype=np.float64), ids)
        # keep the full extent of both (points may not reach a refined end)
        c = 0.5 * (seg.start + seg.end)
        t = (ends - c) @ seg.direction
        return LineSegment(c + t.min() * seg.direction, c + t.max() * seg.direction, ids, seg.rms, label, False)
    w = np.array([a.support, a.support, b.support, b.support], float) + 1.0
    c, d, _, _ = fit_line(ends - ends[0], w)
    c = c + ends[0]
    t = (ends - c) @ d
    return LineSegment(c + t.min() * d, c + t.max() * d, ids, rms, label, a.fixed)


# ------------------------------------------------------------------ polylines
def chain_segments(segments: list[LineSegment], *, join: float, min_angle: float = 10.0,
                   offset: float | None = None) -> list[tuple[np.ndarray, list[int], bool]]:
    """Join segments whose ends lie within ``join`` m of each other into polylines.

    Each segment end links to the nearest end of another segment when they are
    each other's nearest within ``join``, and either

    * the segments meet at ``min_angle`` degrees or more and the closest point of
      their two lines lies within ``join`` of both ends: a corner, whose vertex is
      that point (on the ``fixed`` segment's line when only one is fixed); or
    * they continue each other: each end lies within ``offset`` m (default
      ``join / 2``) of the other segment's line; the vertex is the end of the
      ``fixed`` segment when only one is fixed, else the midpoint of the two ends.

    Nearly parallel segments side by side are not joined.  Returns ``(vertices
    (k, 3), segment ids in order, closed)`` per polyline.
    """
    from ..neighbors import NeighborIndex

    n = len(segments)
    if n == 0:
        return []
    off = 0.5 * join if offset is None else float(offset)
    ends = np.array([[s.start, s.end] for s in segments]).reshape(-1, 3)  # end e = 2·seg + side
    # nearest end of another segment, for every end
    k = min(4, 2 * n)
    index = NeighborIndex(ends, cell=max(join, 1e-9))
    nbr, dist = index.knn(ends, k)
    nearest = np.full(2 * n, -1, np.int64)
    ndist = np.full(2 * n, np.inf)
    for e in range(2 * n):
        for j in range(k):
            f = int(nbr[e, j])
            if f >= 0 and f // 2 != e // 2:
                nearest[e], ndist[e] = f, dist[e, j]
                break
    link = np.full(2 * n, -1, np.int64)
    vertex = {}
    cos_min = math.cos(math.radians(min_angle))
    for e in range(2 * n):
        f = int(nearest[e])
        if f < 0 or ndist[e] > join or int(nearest[f]) != e or (f, e) in vertex:
            continue
        a, b = segments[e // 2], segments[f // 2]
        if abs(float(a.direction @ b.direction)) < cos_min:
            q1, q2, _ = closest_points_of_lines(a.start, a.direction, b.start, b.direction)
            v = q1 if (a.fixed and not b.fixed) else q2 if (b.fixed and not a.fixed) else 0.5 * (q1 + q2)
            if np.linalg.norm(v - ends[e]) > join or np.linalg.norm(v - ends[f]) > join:
                continue
        else:
            if (point_line_distance(ends[f:f + 1], a.start, a.direction)[0] > off
                    or point_line_distance(ends[e:e + 1], b.start, b.direction)[0] > off):
                continue
            if a.fixed != b.fixed:
                v = ends[e] if a.fixed else ends[f]
            else:
                v = 0.5 * (ends[e] + ends[f])
        link[e], link[f] = f, e
        vertex[(e, f)] = vertex[(f, e)] = v
    used = np.zeros(n, bool)
    out: list[tuple[np.ndarray, list[int], bool]] = []
    for s0 in range(n):
        if used[s0]:
            continue
        # walk backwards out of s0's start end until a free end (a path) or s0 again (a loop)
        e, closed = 2 * s0, False
        while True:
            f = int(link[e])
            if f < 0:
                break
            if f // 2 == s0:
                closed = True
                break
            e = f ^ 1
        enter = 2 * s0 if closed else e  # the end through which the chain enters its first segment
        verts = [vertex[(enter, int(link[enter]))] if closed else ends[enter]]
        segs: list[int] = []
        s, side_in = enter // 2, enter % 2
        while True:
            used[s] = True
            segs.append(s)
            e_out = 2 * s + (1 - side_in)
            f = int(link[e_out])
            if f < 0:
                verts.append(ends[e_out])
                break
            if closed and f == enter:
                break
            verts.append(vertex[(e_out, f)])
            s, side_in = f // 2, f % 2
        out.append((np.array(verts), segs, closed))
    return out


def douglas_peucker(vertices: np.ndarray, tolerance: float, *, closed: bool = False,
                    return_index: bool = False) -> np.ndarray:
    """3-D Douglas–Peucker: the fewest vertices (kept from ``vertices``) such that no
    dropped vertex lies farther than ``tolerance`` from the simplified polyline.
    The first and last vertices stay; a closed ring keeps its first vertex and the
    vertex farthest from it.  ``return_index``: the indices of the kept vertices
    (ascending) instead, so that per-vertex values can follow them."""
    v = np.asarray(vertices, dtype=np.float64)
    if tolerance < 0 or not math.isfinite(tolerance):
        raise LidarfxError(f"simplification tolerance must be >= 0, got {tolerance!r}")
    if len(v) <= 2:
        return np.arange(len(v)) if return_index else v.copy()
    if closed:
        far = int(np.argmax(np.linalg.norm(v - v[0], axis=1)))
        ia = douglas_peucker(v[: far + 1], tolerance, return_index=True)
        ib = douglas_peucker(np.vstack([v[far:], v[:1]]), tolerance, return_index=True)
        idx = np.concatenate([ia, far + ib[1:-1]])
        return idx if return_index else v[idx]
    keep = np.zeros(len(v), bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(v) - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        seg = v[i + 1:j]
        a, b = v[i], v[j]
        d = b - a
        ll = float(d @ d)
        if ll == 0:
            dist = np.linalg.norm(seg - a, axis=1)
        else:
            t = np.clip((seg - a) @ d / ll, 0.0, 1.0)
            dist = np.linalg.norm(seg - (a + t[:, None] * d), axis=1)
        k = int(np.argmax(dist))
        if dist[k] > tolerance:
            m = i + 1 + k
            keep[m] = True
            stack += [(i, m), (m, j)]
    return np.flatnonzero(keep) if return_index else v[keep]


def polyline_of(vertices: np.ndarray, *, support: int = 0, rms: float = math.nan, kind: str = "line",
                closed: bool = False, **attrs) -> Polyline:
    """A :class:`Polyline` (shortcut)."""
    return Polyline(vertices, support=support, rms=rms, kind=kind, closed=closed, attrs=dict(attrs))
