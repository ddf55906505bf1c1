"""Small parts of steel lattice towers: bolts and rivets, insulators, corona rings.

Bolt heads and rivets stand a few millimetres off the flange they hold: they are
found as compact groups of points far from their local plane (LIS slides: the
standard deviation to the local plane).  Insulator strings and corona rings
hang free of the lattice: they are compact groups of points of their own, told
apart by the eigenvalues of their covariance (an insulator is long and round,
λ1 dominant; a corona ring is a flat hollow circle, λ1 ≈ λ2 ≫ λ3).  Steps
(:func:`detect_small_parts`, docs/tower.md "Small parts"):

1. **spacing** — the typical point spacing ``h``: the median distance to the
   nearest neighbour (over a seeded sample), and the coordinates' resolution
   (:func:`coordinate_resolution`);
2. **compact parts** — connected components of the whole cloud under a link of
   ``compact_link`` (default 6 h: angle profiles a few spacings wide, sampled
   at random, hold together from about 5.5 h); the largest component and those
   more than ``max_compact_size`` across are the structure (the tower), the
   others with at least ``min_points`` points are compact parts;
3. **local planes** — for every point of the structure, the robust (MSAC)
   plane of its neighbours within ``radius`` in the cloud thinned to one point
   per cube of ``h`` (:mod:`lidarfx.thin`; a densely sampled bolt then weighs no more than its area,
   so the flange dominates the neighbourhood); the score of a point is its
   distance to that plane in units of the noise ``σ`` (the median RMS of the
   inliers of the planes fitted to 6 or more points, or ``noise``);
4. **clusters** — the off-plane points (score above ``threshold`` and farther
   than 2 coordinate steps) with at
   least 5 off-plane points within 3 h (dense groups, not the scattered points
   at flange edges and joints) are linked within ``link`` (default 2.5 × their
   own median spacing); a cluster more than 1.6 × the median cluster size is
   cut in two by two-means (two bolts side by side) when both halves keep
   ``min_points``; a cluster keeps its points on the side of their planes that
   most of it stands on (a bolt stands on one side of its flange, noise on both);
5. **bolts** — clusters of at least ``min_points`` points whose largest
   principal extent lies in [``min_size``, ``max_size``];
6. **kinds** — compact parts by their eigenvalues (:data:`KIND_RULES`).
"""
from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ..cloud import PointCloud
from ..errors import LidarfxError, LidarfxWarning, check_int, check_number

__all__ = ["DEFAULTS", "KINDS", "KIND_RULES", "PART_COLUMNS", "SmallParts", "check_options", "coordinate_resolution",
           "point_spacing", "detect_small_parts",
           "match_centres", "evaluate_parts", "write_tables", "draw_picture", "summary_line"]

KINDS: dict[str, int] = {"bolt": 0, "insulator": 1, "corona_ring": 2, "other": 3}
"""Values of the ``part_kind`` attribute (−1: no part)."""

DEFAULTS: dict[str, Any] = {
    "radius": 0.05,  # local-plane radius (m): about twice a bolt head, below a flange's width
    "threshold": 1.75,  # a point stands off its plane beyond threshold x noise
    "noise": None,  # sigma of the surfaces (m); None = the median inlier RMS of the local planes
    "min_points": 10,  # smallest part (points)
    "min_size": 0.005,  # smallest bolt (largest principal extent, m)
    "max_size": 0.06,  # largest bolt (m)
    "link": None,  # link of the off-plane points (m); None = 2.5 x their median spacing
    "compact": True,  # look for compact parts (insulators, corona rings) too
    "compact_link": None,  # link of the compact parts (m); None = 6 x the point spacing
    "max_compact_size": 3.0,  # largest compact part (m)
}
"""Parameters of :func:`detect_small_parts` (tuned on ``lidarfx.synth.tower`` seeds 100–104)."""

KIND_RULES: dict[str, str] = {
    "insulator": "elongated (λ2/λ1 ≤ 0.1) with a round cross-section (λ3/λ2 ≥ 0.5; an angle profile has 0.25) "
                 "at least 0.05 m across (4√λ2)",
    "corona_ring": "round and flat (λ2/λ1 ≥ 0.5, λ3/λ2 ≤ 0.1) and hollow (in-plane distance to the centroid "
                   "varies by at most 25 % of its mean)",
    "other": "any other compact part",
}
"""How a compact part gets its kind from the eigenvalues λ1 ≥ λ2 ≥ λ3 of its points' covariance."""

_CORE_COUNT = 5  # an off-plane point with this many off-plane points within 3 h (itself included) is in a dense group
_CORE_SPACINGS = 3.0  # ... within this many point spacings
_LINK_SPACINGS = 2.5  # default link: this many median spacings of the dense off-plane points
_COMPACT_SPACINGS = 6.0  # default compact link: this many point spacings (thin profiles hold together)
_SPLIT_SIZE = 1.6  # a cluster this many times the median cluster size is cut in two (two touching bolts)
_NOISE_NEIGHBOURS = 6  # planes with this many points of the thinned cloud give the noise
_RESOLUTION_STEPS = 2.0  # a point stands off by more than this many coordinate steps, whatever the noise
_MIN_NOISE = 1e-4  # the noise found is at least this share of the radius (noise-free data)
_MSAC_SHARE = 0.2  # MSAC inlier distance = this share of the radius
_SAMPLE = 20_000  # points of the spacing estimate

PART_COLUMNS = ["id", "kind", "centroid_x", "centroid_y", "centroid_z", "size", "extent1", "extent2", "extent3",
                "eigenvalue1", "eigenvalue2", "eigenvalue3", "points", "mean_score", "standoff",
                "axis_x", "axis_y", "axis_z"]
"""Columns of ``parts.csv``: centroid in cloud coordinates; ``size`` = ``extent1``, the largest of the
extents along the principal axes (m); eigenvalues of the covariance (m²); ``mean_score`` = mean distance
to the local plane in units of the noise; ``standoff`` = 95th percentile of that distance (m); ``axis`` =
the first principal axis (z ≥ 0)."""


@dataclass
class SmallParts:
    """Result of :func:`detect_small_parts`.

    ``cloud`` is a copy of the input with ``part_id`` (int32, −1 = none),
    ``part_kind`` (int8, :data:`KINDS`, −1 = none) and ``part_score`` (float32,
    distance to the local plane in units of the noise; NaN without a plane).
    ``parts`` holds one record per part (keys :data:`PART_COLUMNS`), ``meta``
    the parameters, the spacing and noise found, counts and timings.
    """

    cloud: PointCloud
    parts: list[dict[str, Any]]
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def part_id(self) -> np.ndarray:
        return np.asarray(self.cloud["part_id"])

    @property
    def part_kind(self) -> np.ndarray:
        return np.asarray(self.cloud["part_kind"])

    def of_kind(self, kind: str) -> list[dict[str, Any]]:
        """The parts of one kind (``bolt``, ``insulator``, ``corona_ring``, ``other``)."""
        if kind not in KINDS:
            raise LidarfxError(f"unknown part kind {kind!r}; kinds: {', '.join(KINDS)}")
        return [p for p in self.parts if p["kind"] == kind]


# --------------------------------------------------------------------------- helpers
def point_spacing(local: np.ndarray, *, sample: int = _SAMPLE, seed: int = 0) -> float:
    """Median distance to the nearest other point over a seeded sample (coinciding points skipped)."""
    from ..neighbors import NeighborIndex, default_cell_for_knn

    rng = np.random.default_rng(seed)
    pick = rng.choice(len(local), size=min(sample, len(local)), replace=False) if len(local) > sample else np.arange(len(local))
    index = NeighborIndex(local, default_cell_for_knn(local - local.min(axis=0), 2))
    _, d = index.knn(local[pick], 2)
    d = d[:, 1]
    d = d[np.isfinite(d) & (d > 0)]
    if not len(d):
        raise LidarfxError("cannot find the point spacing: the points coincide")
    return float(np.median(d))


def coordinate_resolution(local: np.ndarray, *, sample: int = _SAMPLE, seed: int = 0) -> float:
    """The step of quantised coordinates (a LAS scale of 0.001 gives 0.001): the smallest positive
    difference between the distinct values of each coordinate over a seeded sample, the
    largest of the three; about 0 for coordinates that are not quantised."""
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(local), size=min(sample, len(local)), replace=False) if len(local) > sample else np.arange(len(local))
    steps = []
    for k in range(3):
        d = np.diff(np.unique(local[pick, k]))
        d = d[d > 0]
        steps.append(float(d.min()) if len(d) else 0.0)
    return max(steps)


def _principal(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Centroid, eigenvalues (descending, ≥ 0), eigenvectors (columns) and extents along them."""
    c = p.mean(axis=0)
    q = p - c
    w, v = np.linalg.eigh(q.T @ q / len(p))
    w, v = np.clip(w[::-1], 0.0, None), v[:, ::-1]
    proj = q @ v
    return c, w, v, proj.max(axis=0) - proj.min(axis=0)


def _kind(p: np.ndarray, w: np.ndarray, v: np.ndarray) -> str:
    """The kind of a compact part from its eigenvalues (:data:`KIND_RULES`)."""
    l1, l2, l3 = (float(x) for x in w)
    if l1 <= 0:
        return "other"
    if l2 <= 0.1 * l1 and l3 >= 0.5 * l2 and 4.0 * math.sqrt(l2) >= 0.05:
        return "insulator"
    if l2 >= 0.5 * l1 and l3 <= 0.1 * l2:
        q = p - p.mean(axis=0)
        rho = np.hypot(q @ v[:, 0], q @ v[:, 1])
        if rho.mean() > 0 and rho.std() <= 0.25 * rho.mean():
            return "corona_ring"
    return "other"


def _record(pid: int, kind: str, p: np.ndarray, origin: np.ndarray, score: np.ndarray, dist: np.ndarray) -> dict[str, Any]:
    c, w, v, ext = _principal(p)
    axis = v[:, 0] if v[2, 0] >= 0 else -v[:, 0]
    fin = np.isfinite(score)
    return {
        "id": pid, "kind": kind,
        "centroid_x": float(c[0] + origin[0]), "centroid_y": float(c[1] + origin[1]), "centroid_z": float(c[2] + origin[2]),
        "size": float(ext[0]), "extent1": float(ext[0]), "extent2": float(ext[1]), "extent3": float(ext[2]),
        "eigenvalue1": float(w[0]), "eigenvalue2": float(w[1]), "eigenvalue3": float(w[2]),
        "points": int(len(p)),
        "mean_score": float(score[fin].mean()) if fin.any() else math.nan,
        "standoff": float(np.percentile(dist[fin], 95)) if fin.any() else math.nan,
        "axis_x": float(axis[0]), "axis_y": float(axis[1]), "axis_z": float(axis[2]),
    }


def _groups(labels: np.ndarray) -> list[np.ndarray]:
    """Indices of every label ≥ 0, one array per label in ascending label order."""
    ok = np.flatnonzero(labels >= 0)
    if not len(ok):
        return []
    order = ok[np.argsort(labels[ok], kind="stable")]
    cuts = np.flatnonzero(np.diff(labels[order])) + 1
    return np.split(order, cuts)


def _halves(p: np.ndarray, iterations: int = 10) -> np.ndarray:
    """Two-means of the points ``p`` started from the two ends of the principal axis: a bool
    mask of the second half."""
    c, _, v, _ = _principal(p)
    t = (p - c) @ v[:, 0]
    centres = np.stack([p[np.argmin(t)], p[np.argmax(t)]])
    second = t > 0
    for _ in range(iterations):
        d = np.linalg.norm(p[:, None, :] - centres[None, :, :], axis=2)
        new = d[:, 1] < d[:, 0]
        if new.all() or not new.any():
            break
        centres = np.stack([p[~new].mean(axis=0), p[new].mean(axis=0)])
        if (new == second).all():
            break
        second = new
    return second


def _split_merged(pc: np.ndarray, clusters: list[np.ndarray], min_points: int, min_size: float,
                  max_size: float) -> list[np.ndarray]:
    """Clusters of two touching parts cut in two: a cluster larger than :data:`_SPLIT_SIZE` × the
    median size of the clusters in the size range is split by two-means when both halves keep
    ``min_points`` points (repeatedly, at most three times per cluster)."""
    sizes = np.array([_principal(pc[g])[3][0] for g in clusters])
    ok = (sizes >= min_size) & (sizes <= max_size)
    if not ok.any():
        return clusters
    limit = _SPLIT_SIZE * float(np.median(sizes[ok]))
    out: list[np.ndarray] = []
    todo = [(g, s, 0) for g, s in zip(clusters, sizes)]
    while todo:
        g, size, depth = todo.pop()
        if size <= limit or depth >= 3 or len(g) < 2 * min_points:
            out.append(g)
            continue
        second = _halves(pc[g])
        a, b = g[~second], g[second]
        if min(len(a), len(b)) < min_points:
            out.append(g)
            continue
        todo += [(a, _principal(pc[a])[3][0], depth + 1), (b, _principal(pc[b])[3][0], depth + 1)]
    out.sort(key=lambda g: int(g.min()))
    return out


def _one_side(g: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """The points of cluster ``g`` on the side of their planes that most of its offset lies on
    (a bolt stands on one side of its flange; noise lies on both)."""
    u = offset[g].sum(axis=0)
    if not np.linalg.norm(u) > 0:
        return g
    return g[offset[g] @ u > 0]


def check_options(**params: Any) -> None:
    """Refuse bad parameters of :func:`detect_small_parts` (the names of :data:`DEFAULTS`) before any work."""
    unknown = set(params) - set(DEFAULTS)
    if unknown:
        raise LidarfxError(f"unknown parameters {sorted(unknown)}; known: {', '.join(DEFAULTS)}")
    p = {**DEFAULTS, **params}
    check_params(p["radius"], p["threshold"], p["noise"], p["min_points"], p["min_size"], p["max_size"], p["link"],
                  p["compact_link"], p["max_compact_size"])


def check_params(radius, threshold, noise, min_points, min_size, max_size, link, compact_link, max_compact_size):
    from ..features.api import MIN_RADIUS

    radius = check_number("radius", radius, MIN_RADIUS, 1e6)
    threshold = check_number("threshold", threshold, 0.0, 1e6, open_lo=True)
    noise = None if noise is None else check_number("noise", noise, 1e-9, 1e6)
    min_points = check_int("min_points", min_points, 3, 10**9)
    min_size = check_number("min_size", min_size, 0.0, 1e6)
    max_size = check_number("max_size", max_size, 0.0, 1e6, open_lo=True)
    if min_size > max_size:
        raise LidarfxError(f"min_size ({min_size:g}) must not exceed max_size ({max_size:g})")
    link = None if link is None else check_number("link", link, 0.0, 1e6, open_lo=True)
    compact_link = None if compact_link is None else check_number("compact_link", compact_link, 0.0, 1e6, open_lo=True)
    max_compact_size = check_number("max_compact_size", max_compact_size, 0.0, 1e6, open_lo=True)
    return radius, threshold, noise, min_points, min_size, max_size, link, compact_link, max_compact_size


# --------------------------------------------------------------------------- main
def detect_small_parts(
    cloud: PointCloud,
    *,
    radius: float = DEFAULTS["radius"],
    threshold: float = DEFAULTS["threshold"],
    noise: float | None = DEFAULTS["noise"],
    min_points: int = DEFAULTS["min_points"],
    min_size: float = DEFAULTS["min_size"],
    max_size: float = DEFAULTS["max_size"],
    link: float | None = DEFAULTS["link"],
    compact: bool = DEFAULTS["compact"],
    compact_link: float | None = DEFAULTS["compact_link"],
    max_compact_size: float = DEFAULTS["max_compact_size"],
    progress: bool | None = None,
    units: str = "auto",
) -> SmallParts:
    """Bolts and rivets (points standing off their local plane) and compact parts
    (insulators, corona rings, other free-standing groups) of a lattice tower.

    Parameters
    ----------
    cloud:
        The point cloud (dense TLS; lengths in metres).
    radius:
        Radius (m) of the local planes: a few times a bolt head, so that the
        flange dominates the neighbourhood, and below the flange width (0.05).
    threshold:
        A point stands off its plane when its distance exceeds ``threshold`` ×
        the noise (3).
    noise:
        σ of the surfaces (m); default: the median RMS of the local planes' inliers.
    min_points:
        Smallest part, points (10).
    min_size, max_size:
        Range of a bolt's largest principal extent (m; 0.005 … 0.06).
    link:
        Link distance of the off-plane points (m); default 2.5 × their median
        spacing in dense groups.
    compact, compact_link, max_compact_size:
        Look for compact parts: connected components under ``compact_link``
        (default 6 × the point spacing) at most ``max_compact_size`` (3 m) across.
    progress:
        Progress bars of the feature computation.
    units:
        ``"auto"`` (default): the lengths are metres, converted when the LAS header's CRS
        names another linear unit (US survey feet, feet); ``"native"``: coordinate units as
        given.  The parts table and ``meta`` give lengths in metres, centroids in the cloud's
        coordinates.

    Returns
    -------
    SmallParts
        ``cloud`` with ``part_id``, ``part_kind``, ``part_score``; ``parts``
        (records with the keys of :data:`PART_COLUMNS`); ``meta``.
    """
    from ..crs import metres_per_unit
    from ..features import feature_arrays
    from ..neighbors import NeighborIndex
    from ..segment.components import linked_components
    from ..thin import thin_indices

    if not isinstance(cloud, PointCloud):
        raise LidarfxError("detect_small_parts expects a PointCloud (see lidarfx.read)")
    (radius, threshold, noise, min_points, min_size, max_size, link, compact_link,
     max_compact_size) = check_params(radius, threshold, noise, min_points, min_size, max_size, link, compact_link,
                                       max_compact_size)
    given = {"radius": radius, "noise": noise, "min_size": min_size, "max_size": max_size, "link": link,
             "compact_link": compact_link, "max_compact_size": max_compact_size}
    u = metres_per_unit(cloud, units)  # metres -> coordinate units from here on

    def units_of(v):
        return None if v is None else v / u

    radius, noise, min_size, max_size = units_of(radius), units_of(noise), units_of(min_size), units_of(max_size)
    link, compact_link, max_compact_size = units_of(link), units_of(compact_link), units_of(max_compact_size)
    if not isinstance(compact, (bool, np.bool_)):
        raise LidarfxError(f"compact must be true or false, got {compact!r}")
    n = len(cloud)
    if n < 3:
        raise LidarfxError(f"the point cloud has {n} points; small parts need at least 3")
    t0 = time.perf_counter()
    origin = cloud.origin
    local = cloud.local_xyz()
    h = point_spacing(local)
    part_id = np.full(n, -1, np.int32)
    part_kind = np.full(n, -1, np.int8)
    groups: list[tuple[str, np.ndarray]] = []

    # compact parts: small connected components
    structure = np.ones(n, bool)
    lc = _COMPACT_SPACINGS * h if compact_link is None else compact_link
    if compact:
        comp = linked_components(local, lc)
        size = np.bincount(comp)
        order = np.argsort(comp, kind="stable")
        starts = np.concatenate([[0], np.cumsum(size)[:-1]])
        span = np.maximum.reduceat(local[order], starts) - np.minimum.reduceat(local[order], starts)
        small = (size >= min_points) & (span.max(axis=1) <= max_compact_size)
        small[np.argmax(size)] = False  # the largest component is the structure, however small
        lab = np.where(small[comp], comp, -1)
        for idx in _groups(lab):
            _, w, v, ext = _principal(local[idx])
            if ext[0] <= max_compact_size:
                groups.append((_kind(local[idx], w, v), idx))
                structure[idx] = False
    t1 = time.perf_counter()

    # local planes: MSAC on the cloud thinned to one point per cube of the spacing
    ref = local[thin_indices(local, h, "first")]
    feats = feature_arrays(ref, ["msac_plane_distance", "msac_plane_std", "msac_normal_x", "msac_normal_y",
                                 "msac_normal_z", "n_neighbours"], radius=radius, query_xyz=local,
                           msac_threshold=_MSAC_SHARE * radius, progress=progress)
    signed = feats["msac_plane_distance"].astype(np.float64)
    dist = np.abs(signed)
    # offset of every point from its plane as a vector (independent of the normal's orientation)
    offset = signed[:, None] * np.column_stack([feats[f"msac_normal_{a}"] for a in "xyz"]).astype(np.float64)
    planes = feats["n_neighbours"] >= _NOISE_NEIGHBOURS
    if not planes.any():
        raise LidarfxError(f"no local plane at radius {radius * u:g} m: every sphere holds fewer than "
                           f"{_NOISE_NEIGHBOURS} points of the cloud thinned to its spacing ({h * u:.3g} m); "
                           f"raise the radius (-r) to at least {2.5 * h * u:.2g} m")
    if planes.mean() < 0.5:
        warnings.warn(f"most spheres of radius {radius * u:g} m hold fewer than {_NOISE_NEIGHBOURS} points of the "
                      f"cloud thinned to its spacing ({h * u:.3g} m): the cloud is too sparse for parts of this size; "
                      f"a larger radius (-r) finds larger parts", LidarfxWarning, stacklevel=2)
    if noise is None:
        std = feats["msac_plane_std"][planes]
        std = std[np.isfinite(std)]
        sigma = max(float(np.median(std)) if len(std) else 0.0, _MIN_NOISE * radius)
    else:
        sigma = noise
    score = dist / sigma
    resolution = coordinate_resolution(local)
    cut = max(threshold, _RESOLUTION_STEPS * resolution / sigma)  # in units of the noise
    t2 = time.perf_counter()

    # off-plane points -> dense groups -> clusters
    with np.errstate(invalid="ignore"):
        cand = np.flatnonzero(structure & (score > cut))
    link_used = link
    n_bolt_clusters = 0
    if len(cand) >= min_points:
        pc = local[cand]
        off_c = offset[cand]
        r_core = _CORE_SPACINGS * h
        core = NeighborIndex(pc, r_core).count(pc, r_core) >= _CORE_COUNT
        if core.sum() >= 2:
            qc = pc[core]
            if link_used is None:
                from ..neighbors import default_cell_for_knn

                _, dn = NeighborIndex(qc, default_cell_for_knn(qc - qc.min(axis=0), 2)).knn(qc, 2)
                dn = dn[:, 1][np.isfinite(dn[:, 1]) & (dn[:, 1] > 0)]
                link_used = _LINK_SPACINGS * float(np.median(dn)) if len(dn) else h
            lab = np.full(len(pc), -1, np.int64)
            lab[core] = linked_components(qc, link_used)
            clusters = [g for g in _groups(lab) if len(g) >= min_points]
            n_bolt_clusters = len(clusters)
            for g in _split_merged(pc, clusters, min_points, min_size, max_size):
                g = _one_side(g, off_c)
                if len(g) < min_points:
                    continue
                _, _, _, ext = _principal(pc[g])
                if min_size <= ext[0] <= max_size:
                    groups.append(("bolt", cand[g]))
    if link_used is None:
        link_used = math.nan  # no dense group of off-plane points: no link was needed
    t3 = time.perf_counter()

    # ids: bolts first, then compact parts, each in the order found
    groups.sort(key=lambda kg: kg[0] != "bolt")
    parts = []
    for pid, (kind, idx) in enumerate(groups):
        part_id[idx] = pid
        part_kind[idx] = KINDS[kind]
        rec = _record(pid, kind, local[idx], origin, score[idx], dist[idx])
        for key in ("size", "extent1", "extent2", "extent3", "standoff"):  # metres
            rec[key] *= u
        for key in ("eigenvalue1", "eigenvalue2", "eigenvalue3"):
            rec[key] *= u * u
        parts.append(rec)
    out = cloud.copy()
    out["part_id"] = part_id
    out["part_kind"] = part_kind
    out["part_score"] = score.astype(np.float32)
    counts = {k: sum(1 for p in parts if p["kind"] == k) for k in KINDS}
    meta = {
        "points": n,
        "lengths": "m" if units == "auto" else "coordinate units",
        "unit_to_metre": u if units == "auto" else None,
        "spacing": h * u,
        "noise": sigma * u,
        "noise_from": "data" if noise is None else "given",
        "resolution": resolution * u,
        "cut": cut * sigma * u,
        "link": link_used * u,
        "compact_link": lc * u if compact else None,
        "off_plane_points": int(len(cand)),
        "clusters": n_bolt_clusters,
        "counts": counts,
        "part_points": int(np.count_nonzero(part_id >= 0)),
        "parameters": {"radius": given["radius"], "threshold": threshold, "noise": given["noise"],
                       "min_points": min_points, "min_size": given["min_size"], "max_size": given["max_size"],
                       "link": given["link"], "compact": bool(compact), "compact_link": given["compact_link"],
                       "max_compact_size": given["max_compact_size"]},
        "kind_rules": KIND_RULES,
        "seconds": {"compact": round(t1 - t0, 3), "planes": round(t2 - t1, 3), "bolts": round(t3 - t2, 3)},
    }
    return SmallParts(out, parts, meta)


# --------------------------------------------------------------------------- evaluation
def match_centres(found: np.ndarray, true: np.ndarray, tolerance: float) -> list[tuple[int, int, float]]:
    """One-to-one matches ``(found index, true index, distance)`` of two point sets: the
    assignment of least total distance among the pairs closer than ``tolerance`` (Hungarian
    method), so one detection never counts for two true parts."""
    from scipy.optimize import linear_sum_assignment

    found = np.asarray(found, dtype=np.float64).reshape(-1, 3)
    true = np.asarray(true, dtype=np.float64).reshape(-1, 3)
    if not len(found) or not len(true):
        return []
    d = np.linalg.norm(found[:, None, :] - true[None, :, :], axis=2)
    big = 1e6 + d.max()
    rows, cols = linear_sum_assignment(np.where(d <= tolerance, d, big))
    return [(int(r), int(c), float(d[r, c])) for r, c in zip(rows, cols) if d[r, c] <= tolerance]


def _scores(found: np.ndarray, true: np.ndarray, tolerance: float) -> dict[str, Any]:
    m = match_centres(found, true, tolerance)
    k = len(m)
    return {"true": int(len(true)), "found": int(len(found)), "matched": k,
            "recall": k / len(true) if len(true) else math.nan,
            "precision": k / len(found) if len(found) else math.nan,
            "mean_offset": float(np.mean([d for _, _, d in m])) if m else math.nan,
            "tolerance": float(tolerance)}


def evaluate_parts(result: SmallParts, truth: Mapping[str, Any], *, origin: Sequence[float] | None = None) -> dict[str, Any]:
    """Recall and precision of the parts against the truth of ``lidarfx.synth.tower``.

    A bolt is found when a detected bolt's centroid lies within two bolt radii of the
    middle of the true head (its centre on the flange plus half its height along its
    axis); an insulator when a detected insulator's centroid lies within one disc
    radius of the string's middle; a corona ring within one tube radius of its
    centre.  Matches are one-to-one (:func:`match_centres`).  Truth coordinates are
    local: ``origin`` (default ``truth["origin"]``) is added.
    """
    o = np.asarray(truth.get("origin", (0.0, 0.0, 0.0)) if origin is None else origin, dtype=np.float64)

    def centres(kind: str) -> np.ndarray:
        ps = result.of_kind(kind)
        return np.array([[p["centroid_x"], p["centroid_y"], p["centroid_z"]] for p in ps]).reshape(-1, 3)

    out: dict[str, Any] = {}
    bolts = truth.get("bolts", [])
    tb = np.array([np.asarray(b["centre"]) + 0.5 * b["height"] * np.asarray(b["axis"]) for b in bolts]).reshape(-1, 3) + o
    tol = 2.0 * float(bolts[0]["radius"]) if bolts else 0.024
    out["bolt"] = _scores(centres("bolt"), tb, tol)
    if "insulators" in truth:
        ti = np.array([s["centre"] for s in truth["insulators"]]).reshape(-1, 3) + o
        tol = float(truth["insulators"][0]["radius"]) if truth["insulators"] else 0.1
        out["insulator"] = _scores(centres("insulator"), ti, tol)
    if "corona_rings" in truth:
        tr = np.array([r["centre"] for r in truth["corona_rings"]]).reshape(-1, 3) + o
        tol = float(truth["corona_rings"][0]["tube"]) if truth["corona_rings"] else 0.025
        out["corona_ring"] = _scores(centres("corona_ring"), tr, tol)
    return out


# --------------------------------------------------------------------------- outputs
def _rounded(rec: Mapping[str, Any], nd: int = 6) -> dict[str, Any]:
    out = {}
    for k, v in rec.items():
        if isinstance(v, float):
            out[k] = round(v, nd) if math.isfinite(v) else None
        elif isinstance(v, dict):
            out[k] = _rounded(v, nd)
        else:
            out[k] = v
    return out


def write_tables(result: SmallParts, folder: Any, *, meta: Mapping[str, Any] | None = None,
                 evaluation: Mapping[str, Any] | None = None) -> dict[str, str]:
    """``parts.csv`` (one row per part, :data:`PART_COLUMNS`) and ``parts.json`` (the parts, the kind
    codes and rules, the run's meta and, when given, the evaluation against a truth) in ``folder``."""
    from pathlib import Path

    from .._tables import write_csv_rows, write_json_doc

    folder = Path(folder)
    rows = [_rounded(p) for p in result.parts]
    write_csv_rows(folder / "parts.csv", rows, PART_COLUMNS)
    info = {k: v for k, v in result.meta.items() if k != "seconds"}
    doc: dict[str, Any] = {"columns": PART_COLUMNS, "kinds": KINDS, "parts": rows, "meta": {**info, **(meta or {})}}
    if evaluation is not None:
        doc["evaluation"] = {k: _rounded(v) for k, v in evaluation.items()}
    write_json_doc(folder / "parts.json", doc)
    return {"parts_csv": str(folder / "parts.csv"), "parts_json": str(folder / "parts.json")}


def summary_line(counts: Mapping[str, int]) -> str:
    """``"281 bolts, 4 insulators, 4 corona rings, 0 other parts"``."""
    names = {"bolt": ("bolt", "bolts"), "insulator": ("insulator", "insulators"),
             "corona_ring": ("corona ring", "corona rings"), "other": ("other part", "other parts")}
    return ", ".join(f"{counts.get(k, 0)} {names[k][counts.get(k, 0) != 1]}" for k in KINDS)


def draw_picture(result: SmallParts, path: Any, *, title: str | None = None) -> str:
    """``parts.png``: front and side views and a detail, the parts coloured by kind
    (:func:`lidarfx.render.parts.parts_view`); the title says what was found."""
    from ..render.parts import parts_view

    head = summary_line(result.meta["counts"])
    parts_view(result.cloud.xyz, result.part_kind, result.parts, path, kinds=tuple(KINDS),
               title=f"{title}: {head}" if title else head)
    return str(path)
