"""Member vectorisation of steel lattice towers: one straight 3-D line per member.

A lattice tower scanned by a terrestrial laser scanner is a frame of angle (L)
profiles: legs, bracings, cross arms.  Their points form thin straight bands,
and :func:`vectorise_members` turns them into 3-D line segments of the vector
layer (:mod:`lidarfx.vector`) in seven steps (docs/tower.md, "Member
vectorisation"):

1. **linear points** — the eigen features at ``radius`` (larger than the profile
   width, so that a profile looks like a line): points with linearity at least
   ``min_linearity``, each with its local direction (the first eigenvector).
   Joints, bolts and plates are not linear and drop out, which cuts the frame
   into its members;
2. **clusters** — region growing by direction: linear points within ``link`` of
   each other whose directions differ by at most ``max_angle`` are linked
   (:func:`lidarfx.segment.components.linked_components`), so crossing braces
   and the members meeting at a joint stay apart;
3. **segments** — a cluster within ``threshold`` of its least-squares line is one
   segment, others get sequential RANSAC lines
   (:func:`lidarfx.vector.lines.extract_segments`, inlier distance
   ``threshold``); collinear pieces merged across the joints
   (:func:`lidarfx.vector.lines.merge_collinear`, gap ``max_gap``);
4. **refit** — every segment takes the linear points within ``threshold`` of its
   line whose direction agrees with it (within ``max_angle``) over its length and
   up to ``join`` beyond its ends, and is fitted again by least squares
   (:func:`lidarfx.vector.lines.fit_line`), until its ends settle; a segment whose points
   are mostly taken by a better supported one is a duplicate and dropped; pieces
   that now overlap are merged;
5. **extent** — the fitted points stop short of the joints (a joint is not
   linear); each end grows along the line over *all* points within ``threshold``
   that continue it without a gap (over ``threshold`` or 8 × the spacing of its
   fitted points), up to ``join`` beyond;
6. **nodes** — an end is moved to the joint with another member when the two
   lines pass within ``threshold`` of each other between the end of the fitted
   points and the grown end (the point of the member's line closest to the other
   line);
7. **labels** — ``leg`` (steep and long, or the peak continuing a leg upwards),
   ``brace`` (inside the body spanned by the legs), ``arm`` (outside the body,
   at most 45° steep), ``other``.  Before that, a member whose points lie mostly
   within ``threshold`` of longer members is dropped (the blend of two braces
   crossing at a small angle).

**What the line is.** Each member's line is the least-squares axis of its own
points: the *centroid axis* of the scanned profile, what a user measuring the
points gets.  For an angle profile whose two flanges ``e1``, ``e2`` (width ``w``)
are evenly sampled, it lies ``(w / 4)(e1 + e2)`` from the heel of the L (the
corner line a drawing gives), about 0.35 w; :func:`centroid_axis` computes it
for a synthetic tower's truth and :func:`score_members` compares with it.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ..cloud import PointCloud
from ..errors import LidarfxError, check_int, check_number
from ..vector.lines import (
    LineSegment,
    closest_points_of_lines,
    extract_segments,
    fit_line,
    merge_collinear,
    point_line_distance,
    point_polyline_distance,
)
from ..vector.polyline import Polyline

__all__ = ["LABELS", "DEFAULTS", "TowerMembers", "vectorise_members", "check_parameters", "centroid_axis",
           "score_members"]

LABELS: dict[str, int] = {"leg": 0, "brace": 1, "arm": 2, "other": 3}
"""Member labels and their codes in the per-point ``member_label`` attribute (−1: no member)."""

DEFAULTS: dict[str, float] = {"radius": 0.4, "threshold": 0.1, "min_linearity": 0.8, "max_angle": 15.0,
                              "min_points": 15, "min_length": 0.5, "merge_angle": 2.0}
"""Defaults of :func:`vectorise_members` (lengths in metres, angles in degrees)."""

MIN_LENGTH = 1e-3
"""Smallest radius, threshold and link (m): the neighbour grid of a finer one would not fit in memory."""
LEG_INCLINATION = 60.0
"""A leg is at least this steep (degrees from horizontal) ..."""
LEG_SHARE = 0.3
"""... and at least this share of the height spanned by all members long."""
ARM_INCLINATION = 45.0
"""A member outside the body is an arm when at most this steep."""
REFIT_ROUNDS = 30
"""Most rounds of a member's refit (each may reach ``join`` further along it)."""
GROW_GAP = 8.0
"""A member's end grows over gaps of up to this many times the mean spacing of its fitted points
(or ``threshold``, whichever is larger)."""
MAX_QUERIES = 10_000
"""Most neighbour queries along one member (their spacing is ``threshold`` up to this many)."""
EXPLAINED = 0.5
"""A member is dropped when more than this share of its points lie within ``threshold`` of
longer members."""
NODE_MIN_ANGLE = 10.0
"""Two members make a joint (node) only when they meet at this angle or more."""


@dataclass
class TowerMembers:
    """Result of :func:`vectorise_members`.

    ``lines``: one 2-vertex :class:`~lidarfx.vector.polyline.Polyline` per member
    (kind ``"member"``; attrs ``label``, ``inclination`` (degrees from horizontal),
    ``azimuth`` (degrees clockwise from north, of the upward direction), ``dx``,
    ``dy``, ``dz`` (unit direction, upwards), ``start_node``, ``end_node`` (the end
    was placed at a joint with another member)); ``segments``: the same members as
    :class:`~lidarfx.vector.lines.LineSegment` (world coordinates, ``label``, ``index``
    = the cloud's points the line was fitted to); ``member_id`` (per point, the
    index into ``lines``, −1 for none) and ``member_label`` (per point, code of
    :data:`LABELS`, −1); ``meta``: parameters, counts, timings.
    """

    lines: list[Polyline]
    segments: list[LineSegment]
    member_id: np.ndarray
    member_label: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    def labels(self) -> list[str]:
        """The label of every line, in order."""
        return [str(pl.attrs["label"]) for pl in self.lines]


def _length(name: str, value: Any, default: float, lo: float = 0.0) -> float:
    if value is None:
        return float(default)
    return check_number(name, value, lo, 1e6, open_lo=lo == 0.0)


def check_parameters(*, radius: Any = DEFAULTS["radius"], threshold: Any = DEFAULTS["threshold"],
                     min_linearity: Any = DEFAULTS["min_linearity"], max_angle: Any = DEFAULTS["max_angle"],
                     link: Any = None, min_points: Any = DEFAULTS["min_points"],
                     min_length: Any = DEFAULTS["min_length"], max_gap: Any = None,
                     merge_angle: Any = DEFAULTS["merge_angle"], join: Any = None, seed: Any = 0) -> dict[str, Any]:
    """The parameters of :func:`vectorise_members` checked (one-line :class:`LidarfxError`
    otherwise) with the defaults that depend on others filled in; the command line checks
    them with this before reading its input."""
    r = check_number("radius", radius, MIN_LENGTH, 1e4)
    thr = check_number("threshold", threshold, MIN_LENGTH, 1e4)
    return {
        "radius": r,
        "threshold": thr,
        "min_linearity": check_number("min_linearity", min_linearity, 0.0, 1.0),
        "max_angle": check_number("max_angle", max_angle, 0.0, 90.0, open_lo=True),
        "link": _length("link", link, max(thr, 0.5 * r), MIN_LENGTH),
        "min_points": check_int("min_points", min_points, 2, 10**9),
        "min_length": check_number("min_length", min_length, 0.0, 1e6),
        "max_gap": _length("max_gap", max_gap, 6.0 * r),
        "merge_angle": check_number("merge_angle", merge_angle, 0.0, 45.0, open_lo=True),
        "join": _length("join", join, 4.0 * r),
        "seed": check_int("seed", seed, 0, 2**32 - 1),
    }


def vectorise_members(
    cloud: PointCloud | np.ndarray,
    radius: float = DEFAULTS["radius"],
    *,
    threshold: float = DEFAULTS["threshold"],
    min_linearity: float = DEFAULTS["min_linearity"],
    max_angle: float = DEFAULTS["max_angle"],
    link: float | None = None,
    min_points: int = int(DEFAULTS["min_points"]),
    min_length: float = DEFAULTS["min_length"],
    max_gap: float | None = None,
    merge_angle: float = DEFAULTS["merge_angle"],
    join: float | None = None,
    seed: int = 0,
    progress: bool | None = None,
    units: str = "auto",
) -> TowerMembers:
    """Straight members of a lattice structure as 3-D lines (module docstring for the steps).

    Parameters
    ----------
    cloud:
        The point cloud (a :class:`~lidarfx.cloud.PointCloud` or an (n, 3) array).
    radius:
        Radius (m) of the eigen features; larger than the profiles' width (0.3–0.5 m
        for profiles up to about 0.15 m).
    threshold:
        Largest distance (m) of a member's points from its line: about 0.8 × the
        widest profile's flange width (an angle's flange edge lies 0.79 w from its
        centroid axis).  Also the smallest gap that stops a member's end from growing,
        and how close two lines pass at a joint.
    min_linearity:
        Linearity (0–1) a point needs to be a line point.
    max_angle:
        Largest angle (degrees) between the local directions of linked line points and
        between a point's direction and its member's line.
    link:
        Link distance (m) of the clusters; default radius / 2 (or ``threshold`` when larger).
    min_points, min_length:
        Fewest line points and shortest length (m) of a member.
    max_gap:
        Largest gap (m) between collinear pieces that are merged into one member
        (the non-linear joints between them); default 6 × radius.
    merge_angle:
        Largest angle (degrees) between collinear pieces that are merged.
    join:
        How far (m) a member's line may reach beyond its fitted points to take more
        points, grow over its joint and meet another member; default 4 × radius.
    seed:
        Seed of the RANSAC draws (results are deterministic).
    units:
        ``"auto"`` (default): the lengths (m) are converted when the cloud's LAS CRS names
        another linear unit (US survey feet, feet); ``"native"``: coordinate units as given
        (an array is in coordinate units).  ``meta`` gives them in metres.
    """
    from ..crs import metres_per_unit
    from ..features import feature_arrays
    from ..neighbors import NeighborIndex
    from ..segment.components import linked_components

    t_start = time.perf_counter()
    if isinstance(cloud, PointCloud):
        xyz = cloud.xyz
    else:
        xyz = np.asarray(cloud, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise LidarfxError(f"vectorise_members expects a PointCloud or an (n, 3) array, got shape {xyz.shape}")
    if len(xyz) == 0:
        raise LidarfxError("the point cloud is empty")
    if not np.isfinite(xyz).all():
        raise LidarfxError("coordinates contain NaN or infinite values")
    prm = check_parameters(radius=radius, threshold=threshold, min_linearity=min_linearity, max_angle=max_angle,
                           link=link, min_points=min_points, min_length=min_length, max_gap=max_gap,
                           merge_angle=merge_angle, join=join, seed=seed)
    u = metres_per_unit(cloud if isinstance(cloud, PointCloud) else None, units)
    for key in ("radius", "threshold", "link", "min_length", "max_gap", "join"):  # metres -> coordinate units
        prm[key] = prm[key] / u
    r, thr, min_lin, max_angle = prm["radius"], prm["threshold"], prm["min_linearity"], prm["max_angle"]
    link, min_points, min_length, max_gap = prm["link"], prm["min_points"], prm["min_length"], prm["max_gap"]
    merge_angle, join, seed = prm["merge_angle"], prm["join"], prm["seed"]
    cos_dir = math.cos(math.radians(max_angle))

    origin = xyz.min(axis=0)
    local = xyz - origin
    n = len(local)
    # 1. line points and their directions
    f = feature_arrays(local, ["linearity", "eigenvector1_x", "eigenvector1_y", "eigenvector1_z"], radius=r,
                       progress=progress)
    lin = np.nan_to_num(np.asarray(f["linearity"], dtype=np.float64), nan=0.0) >= min_lin
    dirs = np.stack([f[f"eigenvector1_{a}"] for a in "xyz"], axis=1).astype(np.float64)
    lin &= np.isfinite(dirs).all(axis=1) & (np.linalg.norm(dirs, axis=1) > 0.5)
    del f
    line_ids = np.flatnonzero(lin)
    t_feat = time.perf_counter()

    # 2. clusters by direction, 3. RANSAC segments, collinear pieces merged
    segments: list[LineSegment] = []
    n_clusters = 0
    if len(line_ids) >= min_points:
        comp = linked_components(local[line_ids], link, dirs[line_ids], max_angle)
        order = np.argsort(comp, kind="stable")
        bounds = np.flatnonzero(np.diff(comp[order])) + 1
        rng = np.random.default_rng(seed)
        for ids in np.split(order, bounds):
            if len(ids) < min_points:
                continue
            n_clusters += 1
            gids = line_ids[ids]
            one = _straight_cluster(local[gids], thr)  # most clusters are one straight piece: no RANSAC
            found = [one] if one is not None else extract_segments(
                local[gids], threshold=thr, min_points=min_points, min_length=min(min_length, 2.0 * thr),
                seed=int(rng.integers(2**31)))
            for s in found:
                s.index = gids[s.index]  # indices into the cloud
                segments.append(s)
    n_raw = len(segments)
    segments = merge_collinear(segments, local, angle=merge_angle, offset=0.5 * thr, gap=max_gap)
    t_seg = time.perf_counter()

    # 4. refit on the agreeing line points along the whole member; duplicates dropped
    index = NeighborIndex(local, cell=max(thr, 1e-6), origin=np.zeros(3))
    refined = [s for s in _refit_all(segments, local, lin, dirs, index, thr, join, cos_dir, min_points) if s is not None]
    claimed = np.zeros(n, bool)
    kept: list[LineSegment] = []
    for s in sorted(refined, key=lambda sg: -sg.support):
        if claimed[s.index].mean() > 0.5:
            continue
        claimed[s.index] = True
        kept.append(s)
    kept = merge_collinear(kept, local, angle=merge_angle, offset=0.5 * thr, gap=max_gap)

    # 5. extent over all points, 6. ends at the joints
    fit_ext = _grow_all(kept, local, index, thr, join)
    nodes = _place_nodes(kept, fit_ext, thr, join)
    members = [(s, nd) for s, nd in zip(kept, nodes) if s.length >= max(min_length, 1e-9)]
    members.sort(key=lambda m: -m[0].length)
    members = [members[k] for k in _not_explained([m[0] for m in members], local, thr)]
    t_fit = time.perf_counter()

    # 7. labels, per-point ids, polylines
    segs = [m[0] for m in members]
    labels = _labels(segs, thr)
    member_id = np.full(n, -1, np.int32)
    best = np.full(n, np.inf)
    for k, (s, ids) in enumerate(zip(segs, _bands(index, [(s.start, s.end) for s in segs], thr))):
        s.label = labels[k]
        if not len(ids):
            continue
        d = point_polyline_distance(local[ids], np.array([s.start, s.end]))
        ok = (d <= thr) & (d < best[ids])
        member_id[ids[ok]] = k
        best[ids[ok]] = d[ok]
    codes = np.array([LABELS[lab] for lab in labels] + [-1], np.int8)
    member_label = codes[member_id]  # member_id −1 takes the last code, −1
    lines: list[Polyline] = []
    for k, (s, (n0, n1)) in enumerate(members):
        a, b = s.start + origin, s.end + origin
        if b[2] < a[2] or (b[2] == a[2] and tuple(b[:2]) < tuple(a[:2])):  # upwards (then east / north)
            a, b, n0, n1 = b, a, n1, n0
        s.start, s.end = a, b
        d = s.direction
        incl = math.degrees(math.asin(min(1.0, abs(float(d[2])))))
        az = math.degrees(math.atan2(float(d[0]), float(d[1]))) % 360.0 if math.hypot(d[0], d[1]) > 1e-9 else 0.0
        lines.append(Polyline(np.array([a, b]), support=s.support, rms=s.rms, kind="member",
                              attrs={"label": s.label, "inclination": round(incl, 3), "azimuth": round(az, 3),
                                     "dx": round(float(d[0]), 6), "dy": round(float(d[1]), 6),
                                     "dz": round(float(d[2]), 6), "start_node": bool(n0), "end_node": bool(n1)}))
    t_end = time.perf_counter()
    counts = {lab: sum(1 for x in labels if x == lab) for lab in LABELS}
    meta = {
        "radius": r * u,
        "lengths": "m" if units == "auto" else "coordinate units",
        "unit_to_metre": u if units == "auto" else None,
        "parameters": {"threshold": thr * u, "min_linearity": min_lin, "max_angle": max_angle, "link": link * u,
                       "min_points": min_points, "min_length": min_length * u, "max_gap": max_gap * u,
                       "merge_angle": merge_angle, "join": join * u, "seed": seed},
        "points": int(n),
        "line_points": int(len(line_ids)),
        "clusters": n_clusters,
        "segments": n_raw,
        "members": len(lines),
        "labels": counts,
        "member_points": int((member_id >= 0).sum()),
        "nodes": int(sum(n0 + n1 for _, (n0, n1) in members)),
        "total_length": round(float(sum(pl.length for pl in lines)) * u, 3),
        "seconds": {"features": round(t_feat - t_start, 3), "segments": round(t_seg - t_feat, 3),
                    "refit": round(t_fit - t_seg, 3), "labels": round(t_end - t_fit, 3)},
    }
    return TowerMembers(lines, segs, member_id, member_label, meta)


# ------------------------------------------------------------------ steps
def _bands(index, ends: list[tuple[np.ndarray, np.ndarray]], thr: float) -> list[np.ndarray]:
    """For every segment ``(a, b)``: indices of the indexed points near it, a superset of those
    within ``thr`` (the caller filters): spheres every ``thr`` or less along each segment,
    all queried at once."""
    if not ends:
        return []
    qs, rad, counts = [], [], []
    for a, b in ends:
        length = float(np.linalg.norm(b - a))
        k = max(min(math.ceil(length / thr), MAX_QUERIES), 1)  # spacing thr (wider for a tiny thr)
        qs.append(a + np.linspace(0.0, 1.0, k + 1)[:, None] * (b - a))
        rad.append(np.full(k + 1, math.hypot(thr, 0.5 * length / k)))
        counts.append(k + 1)
    off, nbr, _ = index.query_radius(np.vstack(qs), np.concatenate(rad))
    qb = np.r_[0, np.cumsum(counts)]
    return [np.unique(nbr[off[qb[i]]:off[qb[i + 1]]]) for i in range(len(ends))]


def _straight_cluster(pts: np.ndarray, thr: float) -> LineSegment | None:
    """The cluster as one segment when all its points lie within ``thr`` of their least-squares
    line without a gap over 3 × ``thr`` along it (what :func:`extract_segments` would find
    there, without its RANSAC draws); else ``None``."""
    o = pts[0]
    c, d, rms, _ = fit_line(pts - o)
    t, dist = _line_coords(pts - o, c, d)
    ts = np.sort(t)
    if dist.max() > thr or (len(ts) > 1 and np.diff(ts).max() > 3.0 * thr):
        return None
    return LineSegment(c + ts[0] * d + o, c + ts[-1] * d + o, np.arange(len(pts), dtype=np.int64), rms)


def _line_coords(pts: np.ndarray, c: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions along the line (c, d) and distances from it."""
    q = pts - c
    t = q @ d
    return t, np.sqrt(np.maximum((q * q).sum(axis=1) - t * t, 0.0))


def _refit_all(segs: list[LineSegment], local: np.ndarray, lin: np.ndarray, dirs: np.ndarray, index, thr: float,
               reach: float, cos_dir: float, min_points: int) -> list[LineSegment | None]:
    """Every segment fitted again to the line points within ``thr`` of its line, from ``reach``
    before its start to ``reach`` beyond its end, whose directions agree with it (the runs of
    those points with gaps up to ``reach`` that overlap the segment); repeated until its ends
    move less than ``thr`` (at most :data:`REFIT_ROUNDS` times), so a member grows over the
    joints along its whole length.  ``None`` where too few points remain."""
    state = [(s.start.copy(), s.direction.copy(), 0.0, s.length) for s in segs]
    out: list[LineSegment | None] = [None] * len(segs)
    active = list(range(len(segs)))
    for _ in range(REFIT_ROUNDS):
        if not active:
            break
        bands = _bands(index, [(c + (t0 - reach) * d, c + (t1 + reach) * d)
                               for c, d, t0, t1 in (state[k] for k in active)], thr)
        still = []
        for k, ids in zip(active, bands):
            c, d, t0, t1 = state[k]
            t, dist = _line_coords(local[ids], c, d)
            ok = (dist <= thr) & (t >= t0 - reach) & (t <= t1 + reach) & lin[ids] & (np.abs(dirs[ids] @ d) >= cos_dir)
            ids, t = ids[ok], t[ok]
            if len(ids) < min_points:
                continue
            o = np.argsort(t, kind="stable")
            ts = t[o]
            cut = np.flatnonzero(np.diff(ts) > reach) + 1
            keep = np.zeros(len(ts), bool)
            for a_, b_ in zip(np.r_[0, cut], np.r_[cut, len(ts)]):
                if ts[b_ - 1] >= t0 and ts[a_] <= t1:
                    keep[a_:b_] = True
            ids = ids[o[keep]]
            if len(ids) < min_points:
                continue
            c_new, d_new, rms, (u0, u1) = fit_line(local[ids] - local[ids[0]])
            c_new = c_new + local[ids[0]]
            if d_new @ d < 0:
                d_new, u0, u1 = -d_new, -u1, -u0
            a_new, b_new = c_new + u0 * d_new, c_new + u1 * d_new
            moved = max(float(np.linalg.norm(a_new - (c + t0 * d))), float(np.linalg.norm(b_new - (c + t1 * d))))
            state[k] = (a_new, d_new, 0.0, u1 - u0)
            out[k] = LineSegment(a_new.copy(), b_new, ids, rms, segs[k].label)
            if moved >= thr:
                still.append(k)
        active = still
    return out


def _grow_all(segs: list[LineSegment], local: np.ndarray, index, thr: float, reach: float) -> list[tuple[float, float]]:
    """Extend every segment (in place) over all points within ``thr`` of its line that continue
    its fitted points (``index``) without a gap over ``thr`` or :data:`GROW_GAP` times their
    mean spacing along it (sparse scans), up to ``reach`` beyond them.  Returns the extent of
    the fitted points along each grown segment (from its start)."""
    fits = []
    for s in segs:
        t = (local[s.index] - s.start) @ s.direction
        fits.append((float(t.min()), float(t.max())))
    bands = _bands(index, [(s.start + (f0 - reach) * s.direction, s.start + (f1 + reach) * s.direction)
                           for s, (f0, f1) in zip(segs, fits)], thr)
    out = []
    for s, (f0, f1), ids in zip(segs, fits, bands):
        c, d = s.start, s.direction
        t, dist = _line_coords(local[ids], c, d)
        t = t[(dist <= thr) & (t >= f0 - reach) & (t <= f1 + reach)]
        gap = max(thr, GROW_GAP * (f1 - f0) / max(len(s.index) - 1, 1))
        hi = _reach_run(np.sort(t[t > f1]) - f1, gap) + f1
        lo = f0 - _reach_run(np.sort(f0 - t[t < f0]), gap)
        s.start, s.end = c + lo * d, c + hi * d
        out.append((f0 - lo, f1 - lo))
    return out


def _reach_run(steps_from_end: np.ndarray, gap: float) -> float:
    """How far the sorted distances beyond an end continue without a gap over ``gap`` (0 if
    the first one is already farther)."""
    if not len(steps_from_end):
        return 0.0
    jumps = np.flatnonzero(np.diff(np.r_[0.0, steps_from_end]) > gap)
    if not len(jumps):
        return float(steps_from_end[-1])
    return float(steps_from_end[jumps[0] - 1]) if jumps[0] > 0 else 0.0


def _place_nodes(segs: list[LineSegment], fit_ext: list[tuple[float, float]], thr: float,
                 reach: float) -> list[tuple[bool, bool]]:
    """Move each end (in place) to its joint with another member: the point of its line
    closest to another member's line that passes within ``thr``, between the end of its
    fitted points (less ``thr``) and its grown end (plus ``thr``), the other line's point
    within that member (± ``reach``).  Of several joints the one nearest the grown end."""
    cos_min = math.cos(math.radians(NODE_MIN_ANGLE))
    lines = [(s.start.copy(), s.direction.copy(), s.length) for s in segs]
    out = []
    if not segs:
        return out
    ends = np.array([[s.start, s.end] for s in segs])
    box_lo = ends.min(axis=1) - reach - thr  # each member extended by reach: where a joint may lie
    box_hi = ends.max(axis=1) + reach + thr
    for k, s in enumerate(segs):
        c, d, L = lines[k]
        f0, f1 = fit_ext[k]  # positions along the (unchanged) line from its start
        new = [0.0, L]
        flags = [False, False]
        for side in (0, 1):
            lo, hi = (-thr, f0 + thr) if side == 0 else (f1 - thr, L + thr)
            grown = 0.0 if side == 0 else L
            w = np.array([c + lo * d, c + hi * d])  # the window of this end
            near = np.flatnonzero(((w.min(axis=0) - thr <= box_hi) & (w.max(axis=0) + thr >= box_lo)).all(axis=1))
            best = None
            for j in near:
                c2, d2, L2 = lines[j]
                if j == k or abs(float(d @ d2)) > cos_min:
                    continue
                q1, q2, dl = closest_points_of_lines(c, d, c2, d2)
                if dl > thr:
                    continue
                t2 = float((q2 - c2) @ d2)
                if t2 < -reach or t2 > L2 + reach:
                    continue
                t = float((q1 - c) @ d)
                if not lo <= t <= hi:
                    continue
                if best is None or abs(t - grown) < abs(best - grown):
                    best = t
            if best is not None:
                new[side] = best
                flags[side] = True
        if new[1] > new[0]:
            s.start, s.end = c + new[0] * d, c + new[1] * d
        out.append((flags[0], flags[1]))
    return out


def _not_explained(segs: list[LineSegment], local: np.ndarray, thr: float) -> list[int]:
    """Indices of the segments (longest first) to keep: a segment most of whose fitted points lie
    within ``thr`` of longer kept members is dropped — the blend of two members crossing at a
    small angle (the bisector of an X bracing, where both braces share a neighbourhood)."""
    keep: list[int] = []
    for k, s in enumerate(segs):
        pts = local[s.index]
        lo, hi = pts.min(axis=0) - thr, pts.max(axis=0) + thr
        near = np.zeros(len(pts), bool)
        for j in keep:
            o = segs[j]
            if (np.minimum(o.start, o.end) > hi).any() or (np.maximum(o.start, o.end) < lo).any():
                continue
            near |= point_polyline_distance(pts, np.array([o.start, o.end])) <= thr
        if near.mean() <= EXPLAINED:
            keep.append(k)
    return keep


def _labels(segs: list[LineSegment], thr: float) -> list[str]:
    """leg / brace / arm / other by inclination and position (module docstring, step 7)."""
    if not segs:
        return []
    ends = np.array([[s.start, s.end] for s in segs])
    lo_end = np.where((ends[:, 0, 2] <= ends[:, 1, 2])[:, None], ends[:, 0], ends[:, 1])
    hi_end = np.where((ends[:, 0, 2] <= ends[:, 1, 2])[:, None], ends[:, 1], ends[:, 0])
    incl = np.degrees(np.arcsin(np.clip(np.abs(hi_end[:, 2] - lo_end[:, 2])
                                        / np.maximum(np.linalg.norm(hi_end - lo_end, axis=1), 1e-12), 0, 1)))
    length = np.linalg.norm(hi_end - lo_end, axis=1)
    height = float(ends[:, :, 2].max() - ends[:, :, 2].min())
    legs = (incl >= LEG_INCLINATION) & (length >= LEG_SHARE * height)
    labels = ["leg" if g else "" for g in legs]
    leg_ids = np.flatnonzero(legs)
    # the peak: a steep member rising from a leg's top end
    for k in range(len(segs)):
        if labels[k] or incl[k] < ARM_INCLINATION or not len(leg_ids):
            continue
        if np.linalg.norm(hi_end[leg_ids] - lo_end[k], axis=1).min() <= 2.0 * thr:
            labels[k] = "leg"
    body = _body(lo_end[leg_ids], hi_end[leg_ids]) if len(leg_ids) >= 3 else None
    for k in range(len(segs)):
        if labels[k]:
            continue
        if body is None:
            labels[k] = "other"
            continue
        mid = 0.5 * (lo_end[k] + hi_end[k])
        inside = body(mid) <= thr
        labels[k] = "brace" if inside else ("arm" if incl[k] <= ARM_INCLINATION else "other")
    return labels


def _body(lo: np.ndarray, hi: np.ndarray):
    """A function giving how far (m) a point lies outside the plan convex hull of the legs at
    its height (negative inside); heights beyond the legs use their end positions."""
    from scipy.spatial import ConvexHull, QhullError

    def outside(p: np.ndarray) -> float:
        dz = hi[:, 2] - lo[:, 2]
        u = np.clip((p[2] - lo[:, 2]) / np.where(dz > 0, dz, 1.0), 0.0, 1.0)
        xy = lo[:, :2] + u[:, None] * (hi[:, :2] - lo[:, :2])
        try:
            hull = ConvexHull(xy)
        except (QhullError, ValueError):
            return math.inf
        eq = hull.equations  # a·x + b·y + c <= 0 inside, (a, b) unit
        return float((eq[:, :2] @ p[:2] + eq[:, 2]).max())

    return outside


# ------------------------------------------------------------------ truth and scores
def centroid_axis(member: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """The centroid axis ``(start, end)`` of a synthetic tower's truth member (local
    coordinates): its heel line shifted by ``(w / 4)(e1 + e2)``, the flange frame of
    :func:`lidarfx.geometry.perpendicular_frame` as :func:`lidarfx.synth.tower` builds
    the profile (both flanges equally sampled)."""
    from ..geometry import perpendicular_frame

    a = np.asarray(member["start"], dtype=np.float64)
    b = np.asarray(member["end"], dtype=np.float64)
    e1, e2 = perpendicular_frame(b - a)
    off = 0.25 * float(member["width"]) * (e1 + e2)
    return a + off, b + off


def score_members(result: TowerMembers | Sequence[Polyline], truth: Mapping[str, Any], *, max_angle: float = 2.0,
                  max_distance: float = 0.05, min_cover: float = 0.8) -> dict[str, Any]:
    """Found members of a synthetic tower (``cloud.meta["truth"]``).

    A truth member is *found* when one vectorised line lies within ``max_angle``
    degrees of its centroid axis (:func:`centroid_axis`), covers at least
    ``min_cover`` of its length (the overlap of the line's end projections with the
    axis) and the covered part of the axis lies on average within ``max_distance``
    (m) of the line.  Legs are the body legs (truth part ``leg`` longer than half the
    height), ``peak`` the legs of the peak.  Returns per group ``found``, ``total``,
    ``share``, the angle and distance errors of the found ones (median, max) and the
    label agreement; ``members``: one record per truth member.
    """
    lines = result.lines if isinstance(result, TowerMembers) else list(result)
    origin = np.asarray(truth.get("origin") if truth.get("origin") is not None else np.zeros(3), dtype=np.float64)
    height = float(truth.get("height", 0.0))
    v = np.array([pl.vertices[[0, -1]] - origin for pl in lines]).reshape(-1, 2, 3)
    recs = []
    for m in truth["members"]:
        a, b = centroid_axis(m)
        L = float(np.linalg.norm(b - a))
        u = (b - a) / L
        best = None
        for k in range(len(v)):
            p0, p1 = v[k]
            ds = p1 - p0
            ls = float(np.linalg.norm(ds))
            if ls == 0:
                continue
            ang = math.degrees(math.acos(min(1.0, abs(float(ds @ u)) / ls)))
            if ang > max_angle:
                continue
            ta, tb = sorted((float((p0 - a) @ u), float((p1 - a) @ u)))
            lo, hi = max(ta, 0.0), min(tb, L)
            cover = max(hi - lo, 0.0) / L
            if cover <= 0:
                continue
            q = a + np.linspace(lo, hi, 11)[:, None] * u
            dist = float(point_line_distance(q, p0, ds).mean())
            if dist > max_distance:
                continue
            if best is None or cover > best[1]:
                best = (k, cover, ang, dist)
        part = m["part"]
        group = "peak" if part == "leg" and L < 0.5 * height else part
        found = best is not None and best[1] >= min_cover
        recs.append({"id": int(m["id"]), "part": part, "group": group, "length": round(L, 3), "found": bool(found),
                     "line": None if best is None else best[0],
                     "cover": None if best is None else round(best[1], 4),
                     "angle": None if best is None else round(best[2], 4),
                     "distance": None if best is None else round(best[3], 4),
                     "label": None if best is None else str(lines[best[0]].attrs.get("label"))})
    groups: dict[str, Any] = {}
    for g in ("leg", "peak", "brace", "arm"):
        rs = [r for r in recs if r["group"] == g]
        if not rs:
            continue
        ok = [r for r in rs if r["found"]]
        want = "leg" if g == "peak" else g
        groups[g] = {"found": len(ok), "total": len(rs), "share": round(len(ok) / len(rs), 4),
                     "angle_median": round(float(np.median([r["angle"] for r in ok])), 4) if ok else None,
                     "angle_max": round(float(max(r["angle"] for r in ok)), 4) if ok else None,
                     "distance_median": round(float(np.median([r["distance"] for r in ok])), 4) if ok else None,
                     "distance_max": round(float(max(r["distance"] for r in ok)), 4) if ok else None,
                     "label_agreement": round(sum(r["label"] == want for r in ok) / len(ok), 4) if ok else None}
    return {"groups": groups, "members": recs, "lines": len(lines),
            "criteria": {"max_angle": max_angle, "max_distance": max_distance, "min_cover": min_cover}}
