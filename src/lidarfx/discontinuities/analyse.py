"""Rock-face discontinuities: orientations, joint sets, spacing, traces, reference horizon, overhangs.

Steps of :func:`analyse_discontinuities` (after the LIS slides; docs/discontinuities.md):

1. **Local planes.**  Normal, ``plane_std`` and planarity of every point at the
   normal radius (feature engine); per-point ``dip`` and ``dip_direction``.
2. **Plane segments.**  Surface growing (:func:`lidarfx.segment.segment_planes`)
   with the LIS parameters scaled to the radius, then the LIS selection: a point
   is *selected* when it is part of a segment of more than ``min_segment_size``
   points and its planarity exceeds ``min_planarity``.  Every segment's plane is
   refitted to its selected points.
3. **Joint sets.**  The segment poles, weighted by their selected points, go to
   :func:`lidarfx.discontinuities.stats.find_sets` (density peaks, then seeded
   spherical k-means on axial data; the number of sets comes from the data).
4. **Per-point set id.**  Points of a segment take its set; points outside
   every segment take the set of the nearest segment point within the growing
   radius when they lie within ``max_distance`` of that segment's plane (the
   edges of a facet, whose local normals are bent), else the set whose mean is
   within ``max_angle`` of their own normal; else −1.
5. **Statistics.**  Per set: Fisher mean of its segment poles (one pole per
   discontinuity, as a compass survey, weighted by the segment's area so that a
   sliver along an edge does not count as much as a face), κ, α95, share of the
   points, normal spacing.  Per segment: area (convex hull in the plane), trace length
   (largest extent in the plane), extents along strike and dip.
6. **Reference horizon and overhangs.**  Normals are oriented outwards (towards
   the scanners when given, else along the face's fitted normal, turned up);
   signed distance of every point to the reference plane; a point overhangs
   when its outward normal (its segment's, when it has one) points down.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..cloud import PointCloud
from ..errors import LidarfxError, check_int, check_number
from ..geometry import dip_from_normal, fit_plane, group_hull_areas, plane_bases
from .stats import axial_angle, check_search_options, find_sets, fisher_stats

__all__ = ["DEFAULTS", "Discontinuities", "analyse_discontinuities", "parse_reference_plane"]

DEFAULTS: dict[str, Any] = {
    "radius": None,  # normal radius; None = about 40 points on a plane (lidarfx.neighbors.default_radius)
    "max_distance": None,  # None = 3 x the median plane_std (surface roughness), at most the radius
    "growing_radius": None,  # None = 1.5 x the radius (LIS 0.15 m at 0.10 m)
    "max_angle": 15.0,  # LIS maximale Abweichung vom Normalvektor
    "min_segment_size": 50,  # LIS selection: Segmentgröße > 50 Punkte
    "min_planarity": 0.5,  # LIS selection: Planarität > 0.5
    "min_width": None,  # None = the growing radius: strips along edges are no discontinuities
    "n_sets": None,  # None = chosen from the data
    "bandwidth": 8.0,  # kernel width of the pole density (deg)
    "separation": 20.0,  # closest two set means (deg)
    "cone": 30.0,  # largest angle of a segment pole to its set mean (deg)
    "min_share": 0.02,  # smallest share of the selected points of a set
    "overhang_angle": 0.0,  # an outward normal this far below horizontal (deg) overhangs
}
"""Parameters of :func:`analyse_discontinuities` (LIS names where they come from the seed)."""

_TRACE_DIRECTIONS = 72  # in-plane directions of the trace (largest extent): 2.5° apart, error < 0.1 %


@dataclass
class Discontinuities:
    """Result of :func:`analyse_discontinuities`.

    ``cloud`` carries per point ``dip``, ``dip_direction`` (degrees, local
    plane), ``normal_x/y/z`` (outward), ``planarity``, ``segment_id``,
    ``segment_size``, ``selected`` (the LIS selection), ``set_id`` (−1 = none),
    ``reference_distance`` (m) and ``overhang`` (1 = overhanging).  ``sets`` and
    ``segments`` are lists of records (see the docs for the keys), ``reference``
    the reference plane, ``meta`` the parameters, counts and timings.
    """

    cloud: PointCloud
    sets: list[dict[str, Any]]
    segments: list[dict[str, Any]]
    reference: dict[str, Any]
    meta: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------- reference plane
def parse_reference_plane(spec: Any, scanners: np.ndarray | None = None) -> dict[str, Any] | None:
    """``"fit"``, ``"horizontal@Z"``, ``"horizontal"`` (at the mean scanner height),
    ``"x,y,z,nx,ny,nz"`` or six numbers → ``{"kind", "point", "normal"}``; ``None`` stays
    ``None`` (the caller's default).  The normal of an explicit plane is normalised; the
    signed distance is positive on the side it points to."""
    if spec is None:
        return None
    if isinstance(spec, str):
        s = spec.strip().lower()
        if s == "fit":
            return {"kind": "fit", "point": None, "normal": None}
        if s.startswith("horizontal"):
            rest = s[len("horizontal"):].strip()
            if not rest:
                if scanners is None:
                    raise LidarfxError("--reference-plane horizontal needs a height (horizontal@Z) or a scanner position")
                z = float(np.mean(scanners[:, 2]))
            else:
                if not rest.startswith("@"):
                    raise LidarfxError(f"reference plane {spec!r}: write horizontal@Z, e.g. horizontal@1.5")
                try:
                    z = float(rest[1:])
                except ValueError:
                    raise LidarfxError(f"reference plane {spec!r}: the height after @ must be a number") from None
            if not math.isfinite(z):
                raise LidarfxError(f"reference plane {spec!r}: the height must be finite")
            return {"kind": "horizontal", "point": np.array([0.0, 0.0, z]), "normal": np.array([0.0, 0.0, 1.0])}
        parts = s.split(",")
    else:
        parts = list(spec)
    try:
        vals = [float(p) for p in parts]
    except (TypeError, ValueError):
        raise LidarfxError(f"reference plane {spec!r}: use fit, horizontal@Z or x,y,z,nx,ny,nz") from None
    if len(vals) != 6 or not all(math.isfinite(v) for v in vals):
        raise LidarfxError(f"reference plane {spec!r}: use fit, horizontal@Z or six finite numbers x,y,z,nx,ny,nz")
    n = np.array(vals[3:])
    if np.linalg.norm(n) == 0:
        raise LidarfxError(f"reference plane {spec!r}: the normal nx,ny,nz must not be zero")
    return {"kind": "plane", "point": np.array(vals[:3]), "normal": n / np.linalg.norm(n)}


def _check_scanners(scanner: Any) -> np.ndarray | None:
    if scanner is None:
        return None
    try:
        s = np.asarray(scanner, dtype=np.float64)
    except (TypeError, ValueError):
        raise LidarfxError(f"scanner positions must be numbers x,y,z, got {scanner!r}") from None
    if s.ndim == 1:
        s = s[None, :]
    if s.ndim != 2 or s.shape[1] != 3 or len(s) == 0 or not np.isfinite(s).all():
        raise LidarfxError(f"scanner positions must be finite x,y,z triples, got {scanner!r}")
    return s


def _outward_sign(normals: np.ndarray, points: np.ndarray, scanners: np.ndarray | None, face: np.ndarray) -> np.ndarray:
    """+1 / −1 per row so that ``sign · normal`` points out of the rock: towards the scanners
    (the mean of the unit directions to them), else along the face's outward normal."""
    if scanners is not None:
        d = np.zeros_like(points)
        for s in scanners:
            v = s - points
            d += v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
        dots = (normals * d).sum(axis=1)
    else:
        dots = normals @ face
    return np.where(dots < 0, -1.0, 1.0)


# --------------------------------------------------------------------------- per-segment geometry
def _group_planes(local: np.ndarray, gid: np.ndarray, k: int):
    """Centroid, unit normal (up), eigenvalues (descending) of each group 0 … k−1 (batched PCA)."""
    cnt = np.bincount(gid, minlength=k).astype(np.float64)
    c = np.stack([np.bincount(gid, weights=local[:, i], minlength=k) for i in range(3)], axis=1) / np.maximum(cnt, 1)[:, None]
    d = local - c[gid]
    cov = np.empty((k, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[:, i, j] = cov[:, j, i] = np.bincount(gid, weights=d[:, i] * d[:, j], minlength=k) / np.maximum(cnt, 1)
    w, v = np.linalg.eigh(cov)
    n = v[:, :, 0]
    n = np.where(n[:, 2:3] < 0, -n, n)
    return c, n, np.clip(w[:, ::-1], 0.0, None), cnt


def _group_range(values: np.ndarray, gid: np.ndarray, k: int) -> np.ndarray:
    lo = np.full(k, np.inf)
    hi = np.full(k, -np.inf)
    np.minimum.at(lo, gid, values)
    np.maximum.at(hi, gid, values)
    return np.where(np.isfinite(lo), hi - lo, 0.0)


def _segment_extents(local: np.ndarray, gid: np.ndarray, k: int, normals: np.ndarray):
    """Per group: hull area in its plane, trace length (largest extent), strike and dip extents."""
    e1, e2, _ = plane_bases(normals)
    u = (local * e1[gid]).sum(axis=1)
    v = (local * e2[gid]).sum(axis=1)
    area = group_hull_areas(np.column_stack([u, v]), gid) if len(gid) else np.zeros(k)
    strike_len = _group_range(u, gid, k)
    dip_len = _group_range(v, gid, k)
    trace = np.zeros(k)
    for t in np.linspace(0.0, math.pi, _TRACE_DIRECTIONS, endpoint=False):
        trace = np.maximum(trace, _group_range(u * math.cos(t) + v * math.sin(t), gid, k))
    return area, trace, strike_len, dip_len


def _set_spacing(offsets: np.ndarray, tolerance: float) -> np.ndarray:
    """Normal spacing of a set: the segment planes' offsets along the set normal, sorted; planes
    closer than ``tolerance`` are one plane; the differences between consecutive planes."""
    if len(offsets) < 2:
        return np.zeros(0)
    d = np.sort(offsets)
    planes = [d[0]]
    for x in d[1:]:
        if x - planes[-1] > tolerance:
            planes.append(x)
    return np.diff(np.array(planes))


# --------------------------------------------------------------------------- main
def analyse_discontinuities(
    cloud: PointCloud,
    *,
    radius: float | None = DEFAULTS["radius"],
    scanner: Sequence[float] | Sequence[Sequence[float]] | None = None,
    max_distance: float | None = DEFAULTS["max_distance"],
    growing_radius: float | None = DEFAULTS["growing_radius"],
    max_angle: float = DEFAULTS["max_angle"],
    min_segment_size: int = DEFAULTS["min_segment_size"],
    min_width: float | None = DEFAULTS["min_width"],
    min_planarity: float = DEFAULTS["min_planarity"],
    n_sets: int | None = DEFAULTS["n_sets"],
    bandwidth: float = DEFAULTS["bandwidth"],
    separation: float = DEFAULTS["separation"],
    cone: float = DEFAULTS["cone"],
    min_share: float = DEFAULTS["min_share"],
    reference_plane: Any = None,
    overhang_angle: float = DEFAULTS["overhang_angle"],
    progress: bool | None = None,
    units: str = "auto",
) -> Discontinuities:
    """Discontinuity orientations, joint sets, spacing, traces, reference horizon and overhangs.

    Parameters
    ----------
    cloud:
        The point cloud (TLS of a rock face, any orientation; overhangs allowed).
    radius:
        Normal radius (m) of the local planes.  Default: about 40 points on a
        plane (:func:`lidarfx.neighbors.default_radius`).
    scanner:
        One scanner position ``(x, y, z)`` or several ``[(x, y, z), …]``.  Normals
        are oriented towards them (outwards), and the reference horizon defaults
        to a horizontal plane at their mean height (as in the LIS slides).
    max_distance, growing_radius, max_angle:
        Segmentation (LIS): largest distance to the segment plane (default 3 ×
        the median ``plane_std`` at the radius, i.e. the surface roughness, at
        most the radius; stepped facets of one set then stay apart), growing radius (default 1.5 × the radius), largest normal
        deviation (15°).
    min_segment_size, min_planarity:
        The LIS selection: segments of more than ``min_segment_size`` points,
        points with planarity above ``min_planarity``.
    min_width:
        Segments narrower than this (m, √(12 λ2) of the segment) are released:
        the strips of bent normals that grow along the edges between facets.
        Default: the growing radius; 0 keeps them.
    n_sets:
        Number of joint sets; ``None`` finds it from the data.
    bandwidth, separation, cone, min_share:
        Joint-set search (:func:`lidarfx.discontinuities.stats.find_sets`).
    reference_plane:
        ``"fit"`` (the face's least-squares plane, normal outwards), ``"horizontal@Z"``,
        ``"horizontal"`` (at the scanners' mean height), ``"x,y,z,nx,ny,nz"`` or six
        numbers.  Default: ``"horizontal"`` with scanners, else ``"fit"``.
    overhang_angle:
        A point overhangs when its outward normal points more than this many
        degrees below the horizontal (default 0).
    progress:
        Progress bars of the feature computation (default: on a terminal for large clouds).
    units:
        ``"auto"`` (default): ``radius``, ``max_distance``, ``growing_radius`` and ``min_width``
        are metres, converted when the LAS header's CRS names another linear unit (US survey
        feet, feet); ``"native"``: coordinate units as given.  The lengths of the tables
        (segments, sets) and of ``meta["parameters"]`` are metres; scanner positions, the
        reference plane and the per-point attributes are in the cloud's coordinates.
    """
    from ..crs import metres_per_unit
    from ..features import feature_arrays
    from ..neighbors import default_radius
    from ..segment import segment_planes

    if not isinstance(cloud, PointCloud):
        raise LidarfxError("analyse_discontinuities expects a PointCloud (see lidarfx.read)")
    n = len(cloud)
    if n < 3:
        raise LidarfxError(f"the point cloud has {n} points; a rock face needs at least 3")
    scanners = _check_scanners(scanner)
    ref = parse_reference_plane(reference_plane, scanners)
    if ref is None:
        ref = parse_reference_plane("horizontal" if scanners is not None else "fit", scanners)
    u = metres_per_unit(cloud, units)  # lengths in metres -> coordinate units
    r = default_radius(cloud) if radius is None else check_number("radius", radius, 0.0, 1e6, open_lo=True) / u
    dmax = None if max_distance is None else check_number("max_distance", max_distance, 0.0, 1e6, open_lo=True) / u
    rgrow = 1.5 * r if growing_radius is None else check_number("growing_radius", growing_radius, 0.0, 1e6,
                                                                open_lo=True) / u
    max_angle = check_number("max_angle", max_angle, 0.0, 90.0, open_lo=True)
    min_segment_size = check_int("min_segment_size", min_segment_size, 2, 10**9)
    min_planarity = check_number("min_planarity", min_planarity, 0.0, 1.0)
    overhang_angle = check_number("overhang_angle", overhang_angle, -90.0, 90.0)
    if min_width is not None:
        min_width = check_number("min_width", min_width, 0.0, 1e6) / u
    if n_sets is not None:
        n_sets = check_int("n_sets", n_sets, 1, 50)
    check_search_options(n_sets=n_sets, bandwidth=bandwidth, separation=separation, cone=cone, min_share=min_share)
    t0 = time.perf_counter()

    # 1. local planes
    feats = feature_arrays(cloud.xyz, ["normal_x", "normal_y", "normal_z", "plane_std", "planarity"], radius=r,
                           progress=progress)
    nrm = np.column_stack([feats["normal_x"], feats["normal_y"], feats["normal_z"]]).astype(np.float64)
    planarity = feats["planarity"]
    if dmax is None:  # 3 x the surface roughness at the radius, at most the radius
        std = feats["plane_std"][np.isfinite(feats["plane_std"])]
        dmax = float(f"{min(r, max(3.0 * float(np.median(std)), 1e-3 * r)):.2g}") if len(std) else r
    t1 = time.perf_counter()

    # 2. segments + LIS selection
    seg = segment_planes(cloud, normal_radius=r, max_distance=dmax, growing_radius=rgrow, max_angle=max_angle,
                         min_size=min_segment_size + 1, min_width=rgrow if min_width is None else min_width,
                         features=feats, progress=progress, units="native")
    sid = np.asarray(seg["segment_id"]).astype(np.int64)
    ssize = np.asarray(seg["segment_size"])
    with np.errstate(invalid="ignore"):
        selected = (sid >= 0) & (planarity > min_planarity)
    nseg = int(sid.max()) + 1 if (sid >= 0).any() else 0
    t2 = time.perf_counter()

    origin = cloud.origin
    local = cloud.xyz - origin
    sel_idx = np.flatnonzero(selected)
    sel_cnt = np.bincount(sid[sel_idx], minlength=nseg) if nseg else np.zeros(0, np.int64)
    use_sel = sel_cnt >= 3  # a segment's plane from its selected points, else from all its points
    member = sid >= 0
    gid_all = sid[member]
    pick = member & (selected | ~use_sel[np.maximum(sid, 0)]) if nseg else member
    c_seg, n_seg, lam_seg, _ = _group_planes(local[pick], sid[pick], nseg) if nseg else (
        np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    seg_total = np.bincount(gid_all, minlength=nseg) if nseg else np.zeros(0, np.int64)

    # 3. joint sets from the segment poles of segments with selected points
    valid = np.flatnonzero(sel_cnt >= 3) if nseg else np.zeros(0, np.int64)
    search = find_sets(n_seg[valid], sel_cnt[valid].astype(np.float64), n_sets=n_sets, bandwidth=bandwidth,
                       separation=separation, cone=cone, min_share=min_share)
    seg_set = np.full(nseg, -1, np.int64)
    seg_set[valid] = search.labels
    means = search.means
    k_sets = len(means)
    t3 = time.perf_counter()

    # 4. per-point set id
    set_id = np.full(n, -1, np.int64)
    set_id[member] = seg_set[gid_all]
    okn = np.isfinite(nrm).all(axis=1)
    free = np.flatnonzero(set_id < 0)
    labelled = np.flatnonzero(set_id >= 0)
    by_plane = 0
    if len(free) and len(labelled):
        from scipy.spatial import cKDTree

        tree = cKDTree(local[labelled])
        d, j = tree.query(local[free], k=1, distance_upper_bound=rgrow)
        hit = np.isfinite(d)
        if hit.any():
            near = labelled[j[hit]]
            s = sid[near]
            dist_plane = np.abs(((local[free[hit]] - c_seg[s]) * n_seg[s]).sum(axis=1))
            ok = dist_plane <= dmax
            set_id[free[hit][ok]] = seg_set[s[ok]]
            by_plane = int(ok.sum())
    by_normal = 0
    if k_sets:
        free = np.flatnonzero((set_id < 0) & okn)
        if len(free):
            c = np.abs(nrm[free] @ means.T)
            best = np.argmax(c, axis=1)
            ok = c[np.arange(len(free)), best] >= math.cos(math.radians(max_angle))
            set_id[free[ok]] = best[ok]
            by_normal = int(ok.sum())
    t4 = time.perf_counter()

    # 6. outward normals, reference plane, overhangs
    finite = np.isfinite(local).all(axis=1)
    fc, fn, _ = fit_plane(local[finite])
    if scanners is not None:
        face = fn * _outward_sign(fn[None, :], fc[None, :], scanners - origin, fn)[0]
    else:
        face = fn  # fit_plane turns it up: outwards for a face that leans back overall
    sc_local = None if scanners is None else scanners - origin
    nrm_out = nrm.copy()
    nrm_out[okn] *= _outward_sign(nrm[okn], local[okn], sc_local, face)[:, None]
    if nseg:
        n_seg = n_seg * _outward_sign(n_seg, c_seg, sc_local, face)[:, None]
    if ref["kind"] == "fit":
        ref = {"kind": "fit", "point": fc + origin, "normal": face}
    ref_d = (cloud.xyz - ref["point"]) @ ref["normal"]
    down = -math.sin(math.radians(overhang_angle))
    nz_used = np.where(member, n_seg[np.maximum(sid, 0), 2] if nseg else np.nan, nrm_out[:, 2])
    with np.errstate(invalid="ignore"):
        overhang = (nz_used < down) & np.isfinite(nz_used)
    seg_over = n_seg[:, 2] < down if nseg else np.zeros(0, bool)

    # 5. statistics
    area, trace, strike_len, dip_len = _segment_extents(local[member], gid_all, nseg, n_seg) if nseg else (
        np.zeros(0),) * 4
    seg_dip, seg_ddir = dip_from_normal(n_seg) if nseg else (np.zeros(0), np.zeros(0))
    med_plan = np.full(nseg, np.nan)
    if nseg:
        order = np.argsort(gid_all, kind="stable")
        starts = np.searchsorted(gid_all[order], np.arange(nseg))
        pl = planarity[member][order]
        ends = np.r_[starts[1:], len(order)]
        for k in range(nseg):
            if ends[k] > starts[k]:
                med_plan[k] = float(np.nanmedian(pl[starts[k]:ends[k]])) if np.isfinite(pl[starts[k]:ends[k]]).any() else math.nan
    angle_to_set = np.full(nseg, np.nan)
    for k in range(nseg):
        if seg_set[k] >= 0:
            angle_to_set[k] = float(axial_angle(n_seg[k], means[seg_set[k]]))
    seg_ref = (c_seg + origin - ref["point"]) @ ref["normal"] if nseg else np.zeros(0)
    segments = []
    for k in range(nseg):
        segments.append({
            "id": k, "set_id": int(seg_set[k]), "points": int(seg_total[k]), "selected_points": int(sel_cnt[k]),
            "centroid_x": float(c_seg[k, 0] + origin[0]), "centroid_y": float(c_seg[k, 1] + origin[1]),
            "centroid_z": float(c_seg[k, 2] + origin[2]),
            "normal_x": float(n_seg[k, 0]), "normal_y": float(n_seg[k, 1]), "normal_z": float(n_seg[k, 2]),
            "dip": float(seg_dip[k]), "dip_direction": float(seg_ddir[k]), "strike": float((seg_ddir[k] - 90.0) % 360.0),
            "angle_to_set": float(angle_to_set[k]), "rms": float(math.sqrt(lam_seg[k, 2])) * u,
            "planarity": float(med_plan[k]), "area": float(area[k]) * u * u, "trace_length": float(trace[k]) * u,
            "strike_length": float(strike_len[k]) * u, "dip_length": float(dip_len[k]) * u,
            "reference_distance": float(seg_ref[k]) * u, "overhang": int(seg_over[k]),
        })
    n_assigned = int((set_id >= 0).sum())
    sets = []
    for k in range(k_sets):
        members = np.flatnonzero(seg_set == k)
        st = fisher_stats(n_seg[members], np.maximum(area[members], 1e-12))
        mdip, mddir = dip_from_normal(st["mean"])
        offs = c_seg[members] @ means[k]
        gaps = _set_spacing(offs, 2.0 * dmax)
        npts = int((set_id == k).sum())
        sets.append({
            "id": k, "dip": mdip, "dip_direction": mddir, "strike": (mddir - 90.0) % 360.0,
            "pole_trend": (mddir + 180.0) % 360.0, "pole_plunge": 90.0 - mdip,
            "kappa": st["kappa"], "alpha95": st["alpha95"], "spread": st["spread"],
            "segments": int(len(members)), "points": npts, "share": npts / n_assigned if n_assigned else 0.0,
            "selected_share": float(search.shares[k]),
            "area": float(area[members].sum()) * u * u,
            "mean_trace_length": float(trace[members].mean()) * u if len(members) else math.nan,
            "spacing_mean": float(gaps.mean()) * u if len(gaps) else math.nan,
            "spacing_median": float(np.median(gaps)) * u if len(gaps) else math.nan,
            "spacing_count": int(len(gaps)),
            "overhang_segments": int(seg_over[members].sum()),
        })
    t5 = time.perf_counter()

    out = PointCloud(cloud.xyz, dict(cloud.attrs), cloud.header, dict(cloud.meta))
    dip, ddir = np.full(n, np.nan), np.full(n, np.nan)
    if okn.any():
        dip[okn], ddir[okn] = dip_from_normal(nrm[okn])
    out["dip"] = dip.astype(np.float32)
    out["dip_direction"] = ddir.astype(np.float32)
    for i, c in enumerate("xyz"):
        out[f"normal_{c}"] = nrm_out[:, i].astype(np.float32)
    out["planarity"] = planarity.astype(np.float32)
    out["segment_id"] = sid.astype(np.int32)
    out["segment_size"] = np.asarray(ssize, dtype=np.int32)
    out["selected"] = selected.astype(np.uint8)
    out["set_id"] = set_id.astype(np.int32)
    out["reference_distance"] = ref_d.astype(np.float32)
    out["overhang"] = overhang.astype(np.uint8)
    reference = {"kind": ref["kind"], "point": [float(v) for v in ref["point"]],
                 "normal": [float(v) for v in ref["normal"]],
                 "description": {"fit": "least-squares plane of the face, normal outwards",
                                 "horizontal": "horizontal plane (reference horizon)",
                                 "plane": "plane given by a point and a normal"}[ref["kind"]]}
    meta = {
        "points": n,
        "parameters": {"radius": r * u, "max_distance": dmax * u, "growing_radius": rgrow * u, "max_angle": max_angle,
                       "min_segment_size": min_segment_size,
                       "min_width": (rgrow if min_width is None else min_width) * u, "min_planarity": min_planarity,
                       "n_sets": n_sets,
                       "bandwidth": float(bandwidth), "separation": float(separation), "cone": float(cone),
                       "min_share": float(min_share), "overhang_angle": overhang_angle,
                       "scanners": None if scanners is None else scanners.tolist(),
                       "radius_source": "given" if radius is not None else "about 40 points on a plane"},
        "lengths": "m" if units == "auto" else "coordinate units",
        "unit_to_metre": u if units == "auto" else None,
        "segments": nseg,
        "segmented_points": int(member.sum()),
        "selected_points": int(selected.sum()),
        "sets": k_sets,
        "set_points": n_assigned,
        "set_points_by": {"segment": int((set_id[member] >= 0).sum()), "plane": by_plane, "normal": by_normal},
        "overhang_points": int(overhang.sum()),
        "face_normal": [float(v) for v in face],
        "peaks": [{"dip": dip_from_normal(p["pole"])[0], "dip_direction": dip_from_normal(p["pole"])[1],
                   "density": p["density"], "share": p["share"]} for p in search.peaks[:20]],
        "seconds": {"features": round(t1 - t0, 3), "segments": round(t2 - t1, 3), "sets": round(t3 - t2, 3),
                    "assign": round(t4 - t3, 3), "statistics": round(t5 - t4, 3)},
    }
    out.meta["discontinuities"] = {k: v for k, v in meta.items() if k != "peaks"}
    return Discontinuities(out, sets, segments, reference, meta)
