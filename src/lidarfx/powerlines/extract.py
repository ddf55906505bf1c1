"""Power-line wires from ALS: candidates, conductors, spans, pylons, catenaries, clearances.

Steps (docs/powerlines.md §1 in full):

1. **ground and height** — ground points from class 2 (or the ground filter when
   the cloud has none), height above a 1 m grid of their mean heights;
2. **candidates** — points at least ``min_height`` above ground whose
   neighbourhood within ``radius`` or twice it (sparse wires) is linear
   (``linearity ≥ linearity``) along a near-horizontal first eigenvector
   (``|v1_z| ≤ sin(max_slope)``); vertical linear points (insulator strings) are
   kept apart; the features are computed on the above-ground points only;
3. **pieces** — single-linkage clusters of the candidates (``link``), split into
   straight lines in plan view when they stray from one (``plan_tolerance``); each is
   cut where the slope of its profile drops by more than ``kink`` (a catenary is
   convex, its slope only grows: a drop is a support, i.e. a pylon) and gets a
   robust catenary in its own plan frame;
4. **joins** — pieces that continue each other (facing, at most ``max_gap`` apart,
   their points fit one catenary, no support between them) are joined and refitted,
   then cut again at the kinks they now show: gaps in the returns do not cut a wire;
5. **held and free** — every end must be held: by a support of step 3, the edge of
   the data, or a structure of above-ground points reaching up to the wire within
   ``pylon_radius``; a wire hangs free (:func:`_clutter`); runs (pieces joined at
   pylons) shorter than ``min_length``, and runs with an unheld end shorter than
   ``long_length``, are not wires (crane jibs, roof ridges, fences);
6. **attachments and growth** — an end's attachment point is the lower end of an
   insulator string, else where two spans' curves meet, else the first structure on
   the extended curve; every above-ground point within the wire's tube (``tube``)
   joins it, beyond the piece only as long as the points follow on; the residuals
   across and along the vertical tell bundled sub-conductors apart (a Gaussian
   mixture of 1 to 4 components chosen by BIC, accepted only when the components are
   separated by more than ``bundle_separation`` and four of their spreads); each
   sub-conductor gets its own catenary;
7. **pylons and spans** — held ends that share a structure are one pylon, its points
   the above-ground clusters reaching up to them; conductors between the same two
   supports form a span;
8. **measures** — per conductor: attachment points, ``a``, ``s0``, ``c``, RMSE,
   sag, conductor length, lowest point, clearance to ground and to objects (the
   remaining above-ground points, or classes 3–5 when the cloud has them).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..cloud import PointCloud
from ..errors import LidarfxError
from .catenary import CatenaryFit, fit_catenary

__all__ = ["DEFAULTS", "Conductor", "PowerLines", "extract_powerlines", "WIRE_CLASS", "PYLON_CLASS"]

WIRE_CLASS = 14
PYLON_CLASS = 15
GROUND_CLASS = 2
MAX_CURVATURE = 0.02
"""Largest curvature 1/a (1/m) of a wire piece: a = 50 m is a sag of 1/8 of a 100 m span."""
VEGETATION_CLASSES = (3, 4, 5)
NOISE_CLASSES = (7, 18)

DEFAULTS: dict[str, float] = {
    "radius": 1.5,
    "min_height": 4.0,
    "linearity": 0.7,
    "max_slope": 35.0,
    "link": 2.0,
    "plan_tolerance": 1.0,
    "min_points": 10,
    "min_length": 30.0,
    "long_length": 150.0,
    "max_gap": 40.0,
    "join_tolerance": 1.0,
    "pylon_radius": 10.0,
    "tube": 0.5,
    "bundle_separation": 0.15,
    "step": 0.5,
    "kink": 0.03,
    "max_clutter": 0.5,
}
"""Defaults of :func:`extract_powerlines` (lengths in metres)."""

LENGTHS = ("radius", "min_height", "link", "plan_tolerance", "min_length", "long_length", "max_gap", "join_tolerance", "pylon_radius",
           "tube", "bundle_separation", "step")


# ------------------------------------------------------------------ records
@dataclass
class Conductor:
    """One conductor of one span: its catenary, points and measures (world coordinates).

    The catenary frame: ``s`` from ``start`` (the start attachment point, 3-D)
    along ``direction`` (unit plan vector towards ``end``), ``z(s) = c + a cosh((s − s0)/a)``.
    """

    id: int
    span_id: int
    bundle_id: int
    bundle_index: int
    bundle_size: int
    start: np.ndarray
    end: np.ndarray
    direction: np.ndarray
    length: float
    fit: CatenaryFit
    index: np.ndarray
    z_offset: float = 0.0  # world height of the fit's z = 0
    offset: tuple[float, float] = (0.0, 0.0)  # lateral offset d = d0 + d1·s of the points from the chord (m)
    measures: dict[str, Any] = field(default_factory=dict)
    end_kinds: tuple[str, str] = ("open", "open")  # what holds the start / end: pylon, edge

    def xy(self, s: np.ndarray) -> np.ndarray:
        return self.start[:2] + np.asarray(s, float)[:, None] * self.direction

    def z(self, s: np.ndarray) -> np.ndarray:
        """World heights of the catenary at ``s``."""
        return self.fit.z(s) + self.z_offset

    def curve(self, step: float = 0.5) -> np.ndarray:
        """Vertices of the catenary every ``step`` metres of horizontal distance, both ends included."""
        n = max(2, int(math.ceil(self.length / step)) + 1)
        s = np.linspace(0.0, self.length, n)
        return np.column_stack([self.xy(s), self.z(s)])

    @property
    def a(self) -> float:
        return self.fit.a

    @property
    def s0(self) -> float:
        return self.fit.s0

    @property
    def c(self) -> float:
        return self.fit.c


@dataclass
class PowerLines:
    """Result of :func:`extract_powerlines`: conductors, pylons, spans, the classified cloud."""

    conductors: list[Conductor]
    pylons: list[dict[str, Any]]
    spans: list[dict[str, Any]]
    cloud: PointCloud
    meta: dict[str, Any]
    ground_z: Any = None  # world xy (k, 2) -> ground height (k,)
    objects: np.ndarray | None = None  # world xyz of the objects clearances are measured to


# ------------------------------------------------------------------ helpers
def _plan_frame(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid and principal plan direction (pointing towards +x, then +y)."""
    c = xy.mean(axis=0)
    q = xy - c
    if len(q) < 2:
        return c, np.array([1.0, 0.0])
    w, v = np.linalg.eigh(q.T @ q)
    d = v[:, 1]
    if d[0] < -1e-12 or (abs(d[0]) <= 1e-12 and d[1] < 0):
        d = -d
    return c, d


def _slope(s: np.ndarray, z: np.ndarray) -> tuple[float, float]:
    """Slope of a straight line through ``(s, z)`` and its variance, refitted once
    without the points more than 3 σ (MAD) off the first fit."""
    keep = np.ones(len(s), bool)
    g = var = math.nan
    for _ in range(2):
        ss, zz = s[keep], z[keep]
        sm = ss - ss.mean()
        sxx = float(sm @ sm)
        if len(ss) < 4 or sxx <= 0:
            return math.nan, math.inf
        g = float(sm @ (zz - zz.mean())) / sxx
        r = z - zz.mean() - g * (s - ss.mean())
        rk = r[keep]
        var = float(rk @ rk) / max(len(rk) - 2, 1) / sxx
        mad = 1.4826 * float(np.median(np.abs(rk - np.median(rk))))
        new = np.abs(r) <= max(3.0 * mad, 1e-6)
        if new.sum() < 4 or (new == keep).all():
            break
        keep = new
    return g, var


def _kinks(s: np.ndarray, z: np.ndarray, *, bin_size: float, window: float, kink: float) -> list[float]:
    """Positions along a profile where the slope drops abruptly: supports.

    A hanging wire is convex, its slope grows with ``s`` by ``1/a`` per metre.  At a
    support the slope falls: the straight line fitted to the points within ``window``
    before a position (tested every ``bin_size``) rises more steeply than the one after
    it, by more than ``kink`` (e.g. 0.03 = 1.7°) and by more than four standard errors of
    that difference (bundles and noise must not make kinks).  The strongest position of
    each stretch is kept."""
    if len(s) < 10:
        return []
    order = np.argsort(s)
    s, z = s[order], z[order]
    lo, hi = float(s[0]), float(s[-1])
    xs = np.arange(lo + 0.3 * window, hi - 0.3 * window + 1e-9, bin_size)
    strength = np.full(len(xs), -np.inf)
    for k, x in enumerate(xs):
        a0, a1, b1 = np.searchsorted(s, [x - window, x, x + window])
        fits = []
        for seg in (slice(a0, a1), slice(a1, b1)):
            ss, zz = s[seg], z[seg]
            if len(ss) < 6 or np.ptp(ss) < 0.3 * window:
                break
            fits.append(_slope(ss, zz))
        if len(fits) < 2:
            continue
        d = fits[0][0] - fits[1][0]
        if d > kink and d > 4.0 * math.sqrt(fits[0][1] + fits[1][1]):
            strength[k] = d
    out: list[float] = []
    for k in np.argsort(-strength):
        if not np.isfinite(strength[k]):
            break
        if all(abs(xs[k] - q) > window for q in out):
            out.append(float(xs[k]))
    return sorted(out)


@dataclass
class _Piece:
    index: np.ndarray  # into the candidate arrays
    centre: np.ndarray
    direction: np.ndarray
    fit: CatenaryFit
    peak_ends: tuple[bool, bool]  # the piece was cut at a support at its low / high s end


def _robust_plan_frame(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plan line of a wire: principal axis refitted twice without the points more than
    3 σ (MAD, at least 0.1 m) off it (a few points of an insulator or a crossing wire
    must not tilt it)."""
    c, d = _plan_frame(xy)
    for _ in range(2):
        lat = (xy - c) @ np.array([-d[1], d[0]])
        dev = np.abs(lat - np.median(lat))
        keep = dev <= max(3.0 * 1.4826 * float(np.median(dev)), 0.1)
        if keep.sum() < 5 or keep.all():
            break
        c, d = _plan_frame(xy[keep])
    return c, d


def _piece(xyz: np.ndarray, idx: np.ndarray, peak_ends=(False, False)) -> _Piece | None:
    if len(idx) < 5:
        return None
    c, d = _robust_plan_frame(xyz[idx, :2])
    s = (xyz[idx, :2] - c) @ d
    if s.max() - s.min() <= 1e-6:
        return None
    try:
        fit = fit_catenary(s, xyz[idx, 2])
    except LidarfxError:
        return None
    return _Piece(idx, c, d, fit, peak_ends)


def _plan_lines(cxyz: np.ndarray, grp: np.ndarray, L: dict[str, float]) -> list[np.ndarray]:
    """A cluster as straight lines in plan view: a cluster whose points stray more than
    ``plan_tolerance`` from its plan axis (wires linked by a cross arm, two circuits at a
    pylon) is split by sequential RANSAC lines in plan (:func:`lidarfx.vector.lines.extract_segments`);
    points on no line, and lines shorter than ``radius``, are dropped."""
    from ..vector.lines import extract_segments

    if len(grp) < 5:
        return []
    c, d = _plan_frame(cxyz[grp, :2])
    q = cxyz[grp, :2] - c
    s, off = q @ d, q @ np.array([-d[1], d[0]])
    if s.max() - s.min() < L["radius"]:
        return []
    if np.abs(off).max() <= L["plan_tolerance"]:
        return [grp]
    flat = np.column_stack([cxyz[grp, :2] - c, np.zeros(len(grp))])
    segs = extract_segments(flat, threshold=L["plan_tolerance"], min_points=5, min_length=L["radius"],
                            max_gap=L["max_gap"], split_tolerance=10.0 * L["plan_tolerance"], seed=0)
    return [grp[sg.index] for sg in segs]


def _cut(cxyz: np.ndarray, idx: np.ndarray, peak_ends: tuple[bool, bool], kink_args: dict[str, float],
         min_points: int, peaks: list[np.ndarray]) -> list[_Piece]:
    """The points ``idx`` as pieces cut at the kinks of their profile (:func:`_kinks`);
    the cut positions are appended to ``peaks``; the outer ends keep ``peak_ends``."""
    c, d = _robust_plan_frame(cxyz[idx, :2])
    s = (cxyz[idx, :2] - c) @ d
    lat = (cxyz[idx, :2] - c) @ np.array([-d[1], d[0]])
    dev = np.abs(lat - np.median(lat))
    on_line = dev <= max(3.0 * 1.4826 * float(np.median(dev)), kink_args["plan_tolerance"])  # strays make no kinks
    cuts = _kinks(s[on_line], cxyz[idx[on_line], 2],
                  **{k: v for k, v in kink_args.items() if k != "plan_tolerance"})
    if not cuts:
        pc = _piece(cxyz, idx, peak_ends)
        return [pc] if pc is not None else []
    probe = _piece(cxyz, idx)  # orientation of the flags: the piece frame of idx
    if probe is not None and float(probe.direction @ d) < 0:
        peak_ends = (peak_ends[1], peak_ends[0])
    edges = [-math.inf, *cuts, math.inf]
    out = []
    for k in range(len(edges) - 1):
        sel = idx[(s >= edges[k]) & (s < edges[k + 1])]
        if len(sel) < min_points:
            continue
        flags = (peak_ends[0] if k == 0 else True, peak_ends[1] if k == len(edges) - 2 else True)
        pc = _piece(cxyz, sel, flags)
        if pc is not None:
            if float(pc.direction @ d) < 0:
                pc.peak_ends = (pc.peak_ends[1], pc.peak_ends[0])
            out.append(pc)
    for cut in cuts:
        near = np.abs(s - cut) < 2.0 * kink_args["bin_size"]
        zc = float(np.max(cxyz[idx[near], 2])) if near.any() else float(np.max(cxyz[idx, 2]))
        peaks.append(np.array([*(c + cut * d), zc]))
    return out


def _end_point(p: _Piece, high: bool) -> np.ndarray:
    s = p.fit.s_max if high else p.fit.s_min
    return np.array([*(p.centre + s * p.direction), float(p.fit.z(np.array([s]))[0])])


# ------------------------------------------------------------------ main
def check_powerline_params(params: dict[str, Any]) -> dict[str, Any]:
    """Every parameter check of :func:`extract_powerlines`, before any work: known names (of
    :data:`DEFAULTS`), positive numbers, ``linearity`` in (0, 1), ``max_slope`` in (0, 90).
    Returns :data:`DEFAULTS` updated with ``params``."""
    unknown = sorted(set(params) - set(DEFAULTS))
    if unknown:
        raise LidarfxError(f"unknown power-line parameter(s): {', '.join(unknown)}; known: {', '.join(DEFAULTS)}")
    p = {**DEFAULTS, **params}
    for k, v in p.items():
        try:
            ok = math.isfinite(float(v)) and float(v) > 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise LidarfxError(f"{k} must be a positive number, got {v!r}")
    if not 0 < p["linearity"] < 1:
        raise LidarfxError(f"linearity must be between 0 and 1, got {p['linearity']!r}")
    if not 0 < p["max_slope"] < 90:
        raise LidarfxError(f"max_slope must be between 0 and 90 degrees, got {p['max_slope']!r}")
    return p


def extract_powerlines(
    cloud: PointCloud,
    *,
    ground: np.ndarray | None = None,
    progress: bool | None = None,
    **params: Any,
) -> PowerLines:
    """Wire conductors, pylons and spans of an ALS power-line corridor (module docstring).

    Parameters
    ----------
    cloud:
        The point cloud (metres, or the unit of its CRS: lengths are converted).
    ground:
        Boolean ground mask; default class 2 of the cloud, or the ground filter
        (:func:`lidarfx.ground.classify_ground`) when the cloud has no class 2.
    params:
        Any of :data:`DEFAULTS` (``radius``, ``min_height``, ``linearity`` …).

    Returns
    -------
    PowerLines
        ``conductors`` (one per conductor and span, with ``measures``), ``pylons``,
        ``spans``, ``cloud`` (a copy: wire points class 14, pylons 15 — points the
        input had as 14 or 15 and that are not found again become 1 — and the int32
        attributes ``conductor_id``, ``span_id``, ``pylon_id``, −1 elsewhere) and ``meta``.
    """
    from ..features.api import feature_arrays, scale_suffix
    from ..ground import classify_ground
    from ..crs import unit_to_metre
    from ..segment.components import linked_components

    if not isinstance(cloud, PointCloud):
        raise LidarfxError("extract_powerlines needs a PointCloud")
    p = check_powerline_params(params)
    if "classification" in cloud:
        _check_class_codes(cloud["classification"])
    unit = unit_to_metre(cloud)
    L = {k: float(p[k]) / unit for k in LENGTHS}
    min_points = max(5, int(p["min_points"]))
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()

    n = len(cloud)
    xyz_w = cloud.xyz
    finite = np.isfinite(xyz_w).all(axis=1)
    if n == 0 or not finite.any():
        raise LidarfxError("the cloud has no points with finite coordinates")
    origin = xyz_w[finite].min(axis=0)
    xyz = xyz_w - origin
    cls_in = np.asarray(cloud["classification"]) if "classification" in cloud else None

    # 1. ground and height above ground
    if ground is None:
        if cls_in is not None and int((cls_in == GROUND_CLASS).sum()) >= 3:
            gmask = cls_in == GROUND_CLASS
            ground_source = "class 2"
        else:
            gmask = classify_ground(cloud, progress=progress)
            ground_source = "ground filter"
    else:
        gmask = np.asarray(ground)
        if gmask.dtype != bool or gmask.shape != (n,):
            raise LidarfxError(f"ground must be a boolean mask of length {n}")
        ground_source = "mask"
    gmask = gmask & finite
    if gmask.sum() < 3:
        raise LidarfxError("fewer than 3 ground points: classify the ground first (lidarfx ground)")
    ground_z = _ground_surface(xyz, gmask, 1.0 / unit)
    hag = np.full(n, np.nan)
    hag[finite] = xyz[finite, 2] - ground_z(xyz[finite, :2])
    noise = np.isin(cls_in, NOISE_CLASSES) if cls_in is not None else np.zeros(n, bool)
    above = finite & ~gmask & ~noise & (hag >= 0.5 / unit)
    seconds["ground"] = time.perf_counter() - t0

    # 2. candidates
    t1 = time.perf_counter()
    high = np.flatnonzero(above & (hag >= L["min_height"]))
    vertical = np.zeros(n, bool)  # vertical linear points: insulator strings, poles, never wire
    cand = np.zeros(0, np.int64)
    if len(high) >= min_points:
        # two scales: the radius, and twice it for sparse wires (earth wires, thin ALS)
        f = feature_arrays(xyz[high], ["linearity", "eigenvector1_z", "n_neighbours"],
                           radii=[L["radius"], 2.0 * L["radius"]], progress=progress)
        keep = np.zeros(len(high), bool)
        for k, r in enumerate((L["radius"], 2.0 * L["radius"])):
            sfx = scale_suffix(r)
            lin = np.nan_to_num(f[f"linearity{sfx}"], nan=0.0)
            vz = np.nan_to_num(np.abs(f[f"eigenvector1_z{sfx}"]), nan=1.0)
            keep |= (lin >= p["linearity"]) & (vz <= math.sin(math.radians(p["max_slope"]))) & (f[f"n_neighbours{sfx}"] >= 4)
            if k == 0:
                vertical[high[(lin >= p["linearity"]) & (vz > math.cos(math.radians(p["max_slope"])))]] = True
        cand = high[keep]
    seconds["candidates"] = time.perf_counter() - t1

    # 3. pieces: clusters as plan lines, cut at supports
    t2 = time.perf_counter()
    pieces: list[_Piece] = []
    peak_xyz: list[np.ndarray] = []
    cxyz = xyz[cand] if len(cand) else np.zeros((0, 3))
    kink_args = {"bin_size": 2.0 / unit, "window": 15.0 / unit, "kink": float(p["kink"]),
                 "plan_tolerance": L["plan_tolerance"]}
    if len(cand) >= min_points:
        comp = linked_components(cxyz, L["link"])
        order = np.argsort(comp, kind="stable")
        bounds = np.flatnonzero(np.diff(comp[order])) + 1
        for grp in np.split(order, bounds):
            for line in _plan_lines(cxyz, grp, L):
                pieces += _cut(cxyz, line, (False, False), kink_args, min_points, peak_xyz)
    seconds["pieces"] = time.perf_counter() - t2

    # 4. join pieces that continue each other
    t3 = time.perf_counter()
    for _ in range(3):  # join, cut the joined pieces at the kinks they now show, join again
        pieces = _join_pieces(pieces, cxyz, np.array(peak_xyz).reshape(-1, 3), L)
        n_before = len(pieces)
        pieces = [q for pc in pieces for q in _cut(cxyz, pc.index, pc.peak_ends, kink_args, min_points, peak_xyz)]
        if len(pieces) == n_before:
            break
    seconds["join"] = time.perf_counter() - t3

    # 5. supports
    t4 = time.perf_counter()
    others = np.flatnonzero(above)
    is_cand = np.zeros(n, bool)
    is_cand[cand] = True
    struct_idx = others[~is_cand[others]]
    from scipy.spatial import cKDTree

    struct_tree = cKDTree(xyz[struct_idx, :2]) if len(struct_idx) else None
    occupied = _occupancy(xyz[finite, :2], 2.0 / unit)
    peaks_arr = np.array(peak_xyz).reshape(-1, 3)
    ends = []
    for pc in pieces:
        e = []
        for high_end in (False, True):
            q = _end_point(pc, high_end)
            out = pc.direction if high_end else -pc.direction
            # held by: a support cut, the edge of the data, a support near by, a structure
            kind = "open"
            if pc.peak_ends[int(high_end)]:
                kind = "pylon"
            elif _at_edge(q[:2], out, occupied, 2.0 / unit, 12.0 / unit):
                kind = "edge"
            elif len(peaks_arr) and np.min(np.linalg.norm(peaks_arr[:, :2] - q[:2], axis=1)) <= L["pylon_radius"]:
                kind = "pylon"
            elif struct_tree is not None and _structure_at(q, xyz, struct_idx, struct_tree, hag, L):
                kind = "pylon"
            e.append((kind, q))
        ends.append(e)
    all_above = np.flatnonzero(above)
    all_tree = cKDTree(xyz[all_above]) if len(all_above) else None
    clutter = np.array([_clutter(pc, xyz, all_tree, L) for pc in pieces])
    keep_piece = _runs_kept(pieces, ends, L, clutter <= p["max_clutter"])
    seconds["supports"] = time.perf_counter() - t4

    # 6. growth (tube) and bundles
    t5 = time.perf_counter()
    above_idx = np.flatnonzero(above & ~vertical)
    above_tree = cKDTree(xyz[above_idx]) if len(above_idx) else None
    owner = np.full(n, -1, np.int64)
    owner_d = np.full(n, np.inf)
    kept = [pc for k, pc in enumerate(pieces) if keep_piece[k]]
    kept_ends = [e for k, e in enumerate(ends) if keep_piece[k]]
    held = [[kind == "pylon" for kind, _ in e] for k, e in enumerate(ends) if keep_piece[k]]
    # attachment points: an insulator string at the end first, else where the curves of two
    # spans held by one pylon meet, else the first structure beyond the end (below)
    vert_idx = np.flatnonzero(vertical)
    vert_tree = cKDTree(xyz[vert_idx]) if len(vert_idx) else None
    snaps = [[_insulator_at(pc, xyz, vert_idx, vert_tree, L, hi) if held[k][hi] else None for hi in (0, 1)]
             for k, pc in enumerate(kept)]
    snaps = _attachments(kept, held, L, snaps)
    grown: list[tuple[_Piece, np.ndarray]] = []
    all_idx = np.flatnonzero(above)
    piece_of = np.full(n, -1, np.int64)  # the kept piece whose candidate a point is
    for k, pc in enumerate(kept):
        piece_of[cand[pc.index]] = k
    for k, pc in enumerate(kept):
        ids = _tube_points(pc, xyz, above_idx, above_tree, L, snaps[k], piece_of, k)
        if all_tree is not None and len(ids):
            _structure_snaps(pc, xyz, ids, all_idx, all_tree, L, snaps[k], held[k])
        grown.append((pc, ids))
    # a short piece whose points lie mostly in the tube of a longer one duplicates it (a
    # stub at a pylon); then a point in two tubes belongs to the nearer curve
    by_length = sorted(range(len(grown)), key=lambda g: grown[g][0].fit.s_max - grown[g][0].fit.s_min, reverse=True)
    claimed = np.zeros(n, bool)
    dup = set()
    for g in by_length:
        ids = grown[g][1]
        if len(ids) and claimed[ids].mean() > 0.5:
            dup.add(g)
            continue
        claimed[ids] = True
    grown = [gi for g, gi in enumerate(grown) if g not in dup]
    snaps = [sn for g, sn in enumerate(snaps) if g not in dup]
    kept_ends = [e for g, e in enumerate(kept_ends) if g not in dup]
    for g, (pc, ids) in enumerate(grown):
        dz = _curve_distance(pc, xyz[ids])
        better = dz < owner_d[ids]
        owner[ids[better]] = g
        owner_d[ids[better]] = dz[better]
    conductors: list[Conductor] = []
    for g, (pc, _) in enumerate(grown):
        ids = np.flatnonzero(owner == g)
        if len(ids) < min_points:
            continue
        for b_index, (sub, size) in enumerate(_split_bundle(pc, xyz, ids, L)):
            cd = _conductor(len(conductors), g, b_index, size, xyz, sub, origin, snaps[g],
                            L["pylon_radius"] + L["tube"])
            if cd is not None:
                local_ends = [q for _, q in kept_ends[g]]
                cd.end_kinds = tuple(kept_ends[g][int(np.argmin([np.linalg.norm(q[:2] + origin[:2] - e[:2]) for q in local_ends]))][0]
                                     for e in (cd.start, cd.end))
                conductors.append(cd)
    seconds["conductors"] = time.perf_counter() - t5

    # 7. pylons and spans
    t6 = time.perf_counter()
    wire_mask = np.zeros(n, bool)
    for cd in conductors:
        wire_mask[cd.index] = True
    pylon_pos = [q for k, pc in enumerate(pieces) if keep_piece[k] for kind, q in ends[k] if kind == "pylon"]
    pylons, pylon_id = _pylons(pylon_pos, xyz, above & ~wire_mask, L, origin)
    spans = _spans(conductors, pylons, origin, L)
    if any(cd.span_id == -2 for cd in conductors):
        conductors = [cd for cd in conductors if cd.span_id != -2]
        for k, cd in enumerate(conductors):
            cd.id = k
        for sp in spans:
            sp["conductors"] = [cd.id for cd in conductors if cd.span_id == sp["id"]]
        wire_mask[:] = False
        for cd in conductors:
            wire_mask[cd.index] = True
    seconds["pylons"] = time.perf_counter() - t6

    # 8. measures
    t7 = time.perf_counter()
    if cls_in is not None and np.isin(cls_in, VEGETATION_CLASSES).any():
        obj = np.isin(cls_in, VEGETATION_CLASSES) & finite & ~wire_mask
        object_source = "classes 3-5"
    else:
        obj = above & ~wire_mask & (pylon_id < 0)
        object_source = "above-ground points that are not wire or pylon"
    _measure(conductors, xyz, ground_z, obj, origin, L)
    seconds["measures"] = time.perf_counter() - t7

    out = cloud.copy()
    cls = np.asarray(out["classification"]).copy() if "classification" in out else np.ones(n, np.uint8)
    cls[np.isin(cls, (WIRE_CLASS, PYLON_CLASS))] = 1
    cls[pylon_id >= 0] = PYLON_CLASS
    cls[wire_mask] = WIRE_CLASS
    cid = np.full(n, -1, np.int32)
    sid = np.full(n, -1, np.int32)
    for cd in conductors:
        cid[cd.index] = cd.id
        sid[cd.index] = cd.span_id
    out["classification"] = cls.astype(np.uint8)
    out["conductor_id"] = cid
    out["span_id"] = sid
    out["pylon_id"] = pylon_id.astype(np.int32)
    seconds["total"] = time.perf_counter() - t0
    meta = {
        "parameters": {k: (float(v) if k in LENGTHS or isinstance(v, float) else v) for k, v in p.items()},
        "unit_to_metre": unit,
        "ground_source": ground_source,
        "object_source": object_source,
        "points": n,
        "candidates": int(len(cand)),
        "pieces": len(pieces),
        "wire_points": int(wire_mask.sum()),
        "pylon_points": int((pylon_id >= 0).sum()),
        "conductors": len(conductors),
        "bundles": len({cd.bundle_id for cd in conductors}),
        "spans": len(spans),
        "pylons": len(pylons),
        "seconds": {k: round(v, 3) for k, v in seconds.items()},
    }

    def ground_world(q: np.ndarray) -> np.ndarray:
        return ground_z(np.asarray(q, np.float64)[:, :2] - origin[:2]) + origin[2]

    return PowerLines(conductors, pylons, spans, out, meta, ground_world, xyz_w[obj])


def _check_class_codes(values) -> None:
    """The input's classification must be class codes (the output's classes are written into it):
    a float column of a text file may hold anything."""
    c = np.asarray(values)
    if c.dtype.kind != "f":
        return
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(c) & (c == np.round(c)) & (c >= 0) & (c <= 255)
    if not ok.all():
        raise LidarfxError(f"the classification attribute holds {int((~ok).sum())} values that are no class code "
                           f"(a whole number 0 to 255), e.g. {c[~ok][0]:g}")


MAX_GROUND_CELLS = 100_000_000
"""Largest ground grid (cells, 10 km x 10 km at 1 m), and at most 1,000 cells per ground point
beyond a million: a stray point far from the rest would otherwise ask for a grid of gigabytes."""


# ------------------------------------------------------------------ step 1
def _ground_surface(xyz: np.ndarray, gmask: np.ndarray, cell: float):
    """The ground height at any plan position: the mean height of the ground points per
    ``cell`` (1 m), empty cells filled by linear interpolation, sampled bilinearly (a DTM
    in milliseconds; wires hang metres above it)."""
    from ..surface.grid import GridSpec, bilinear, cell_index, inpaint

    lo = xyz[gmask, :2].min(axis=0)
    g = xyz[gmask]
    spec = GridSpec(g[:, :2] - lo, cell)
    if spec.nx * spec.ny > min(MAX_GROUND_CELLS, 1000 * len(g) + 1_000_000):  # cf. ground.MAX_CELLS_PER_POINT
        span = " x ".join(f"{v:,.0f}" for v in g[:, :2].max(axis=0) - lo)
        raise LidarfxError(f"the ground points span {span} (file units): a ground grid of {spec.nx * spec.ny:,} cells "
                           f"(at most {MAX_GROUND_CELLS:,}); crop the cloud or remove stray points far from the rest")
    i, j = cell_index(g[:, :2] - lo, spec)
    key = i * spec.nx + j
    cnt = np.bincount(key, minlength=spec.nx * spec.ny)
    tot = np.bincount(key, weights=g[:, 2], minlength=spec.nx * spec.ny)
    grid = np.full(spec.nx * spec.ny, np.nan)
    grid[cnt > 0] = tot[cnt > 0] / cnt[cnt > 0]
    grid = inpaint(grid.reshape(spec.ny, spec.nx), spec)

    def sample(xy: np.ndarray) -> np.ndarray:
        return bilinear(grid, spec, np.asarray(xy, np.float64) - lo)

    return sample


# ------------------------------------------------------------------ step 4
def _join_pieces(pieces: list[_Piece], cxyz: np.ndarray, peaks: np.ndarray, L: dict[str, float]) -> list[_Piece]:
    """Join pieces whose facing ends continue each other: rounds of the closest
    compatible pairs (each end joined to its nearest compatible partner, each piece at
    most once per round), refitted each time.  Compatible: nearly parallel, facing, the
    gap at most ``max_gap``, the points fit one catenary (:func:`_fit_as_one`), no
    support between them, neither end cut at a support."""
    from scipy.spatial import cKDTree

    cos10 = math.cos(math.radians(10.0))
    while len(pieces) > 1:
        ends = np.array([_end_point(pc, hi) for pc in pieces for hi in (False, True)])
        pairs = cKDTree(ends[:, :2]).query_pairs(L["max_gap"] + 2.0 * L["radius"], output_type="ndarray")
        cands = []
        for e1, e2 in pairs:
            i, j = int(e1) // 2, int(e2) // 2
            if i == j:
                continue
            hi_i, hi_j = bool(e1 % 2), bool(e2 % 2)
            a, b = pieces[i], pieces[j]
            if abs(float(a.direction @ b.direction)) < cos10:
                continue
            if a.peak_ends[int(hi_i)] or b.peak_ends[int(hi_j)]:
                continue  # cut at a support: the next span
            ea, eb = ends[e1], ends[e2]
            out_a = a.direction if hi_i else -a.direction
            out_b = b.direction if hi_j else -b.direction
            gap = float((eb[:2] - ea[:2]) @ out_a)
            overlap = max(2.0 * L["radius"], 0.5 * min(a.fit.s_max - a.fit.s_min, b.fit.s_max - b.fit.s_min))
            if not (-overlap < gap <= L["max_gap"]) or float(out_a @ out_b) > -cos10:
                continue
            tol = L["join_tolerance"] + 0.02 * max(gap, 0.0)
            # the longer piece's curve, extrapolated, passes the shorter one's points
            lng, sht = (a, b) if a.fit.s_max - a.fit.s_min >= b.fit.s_max - b.fit.s_min else (b, a)
            q = cxyz[sht.index]
            s_q, lat = _frame(lng, q)
            ok = bool(np.median(np.abs(lat)) <= tol and np.median(np.abs(lng.fit.z(s_q) - q[:, 2])) <= tol)
            if ok or gap <= 0.5 * L["max_gap"]:  # short pieces: curvature too uncertain to extrapolate
                ok = _fit_as_one(a, b, cxyz, L)
            if not ok or (len(peaks) and _peak_between(ea, eb, peaks, L)):
                continue
            cands.append((gap, i, j, hi_i, hi_j))
        # each end meets its nearest compatible partner only
        taken_end: set[tuple[int, bool]] = set()
        joins = []
        for c in sorted(cands, key=lambda c: c[0]):
            gap, i, j, hi_i, hi_j = c
            if (i, hi_i) in taken_end or (j, hi_j) in taken_end:
                continue
            taken_end.update(((i, hi_i), (j, hi_j)))
            joins.append(c)
        cands = joins
        used: set[int] = set()
        new: list[_Piece] = []
        for _, i, j, hi_i, hi_j in sorted(cands):
            if i in used or j in used:
                continue
            a, b = pieces[i], pieces[j]
            merged = _piece(cxyz, np.concatenate([a.index, b.index]))
            if merged is None:
                continue
            far_a = _end_point(a, not hi_i)  # the outer ends keep their support flags
            flags = {}
            for pc, hi, far in ((a, not hi_i, far_a), (b, not hi_j, _end_point(b, not hi_j))):
                s_far = float((far[:2] - merged.centre) @ merged.direction)
                flags[s_far > 0.5 * (merged.fit.s_min + merged.fit.s_max)] = pc.peak_ends[int(hi)]
            merged.peak_ends = (flags.get(False, False), flags.get(True, False))
            used.update((i, j))
            new.append(merged)
        if not new:
            break
        pieces = [pc for k, pc in enumerate(pieces) if k not in used] + new
    return pieces


def _fit_as_one(a: _Piece, b: _Piece, cxyz: np.ndarray, L: dict[str, float]) -> bool:
    """The points of two pieces fit one convex catenary (and one plan line) about as well
    as each piece its own: RMSE at most 1.5 × the larger one + 1 cm, lateral spread within
    ``plan_tolerance``."""
    m = _piece(cxyz, np.concatenate([a.index, b.index]))
    if m is None or m.fit.u < -1e-5 or m.fit.u > MAX_CURVATURE:
        return False
    _, lat = _frame(m, cxyz[m.index])
    return bool(m.fit.rmse <= 1.5 * max(a.fit.rmse, b.fit.rmse) + 0.01
                and np.percentile(np.abs(lat), 90) <= L["plan_tolerance"])


def _peak_between(ea: np.ndarray, eb: np.ndarray, peaks: np.ndarray, L: dict[str, float]) -> bool:
    d = eb[:2] - ea[:2]
    ln = float(np.linalg.norm(d))
    if ln <= 0:
        return False
    u = d / ln
    t = (peaks[:, :2] - ea[:2]) @ u
    off = np.abs((peaks[:, :2] - ea[:2]) @ np.array([-u[1], u[0]]))
    return bool(((t > 0) & (t < ln) & (off < L["pylon_radius"])).any())


# ------------------------------------------------------------------ step 5
def _occupancy(xy: np.ndarray, cell: float) -> tuple[set, np.ndarray, float]:
    lo = xy.min(axis=0)
    ij = np.floor((xy - lo) / cell).astype(np.int64)
    return set(map(tuple, np.unique(ij, axis=0).tolist())), lo, cell


def _at_edge(q: np.ndarray, out: np.ndarray, occupied, step: float, reach: float) -> bool:
    """An end is at the edge of the data when the plan cells ahead of it (within
    ``reach``) hold no point at all."""
    cells, lo, cell = occupied
    for t in np.arange(step, reach + 1e-9, step):
        x = q + t * out
        ij = tuple(np.floor((x - lo) / cell).astype(np.int64).tolist())
        if ij not in cells:
            return True
    return False


def _structure_at(q: np.ndarray, xyz: np.ndarray, idx: np.ndarray, tree, hag: np.ndarray, L: dict[str, float]) -> bool:
    """A structure holds the wire end ``q``: above-ground non-wire points within
    ``pylon_radius`` reach up to the wire height (within ``tube``) and down to half of it."""
    near = idx[tree.query_ball_point(q[:2], L["pylon_radius"])]
    if len(near) < 5:
        return False
    z = xyz[near, 2]
    q_hag = float(q[2] - (xyz[near, 2] - hag[near]).mean())
    return bool(z.max() >= q[2] - L["tube"] and hag[near].min() <= 0.5 * q_hag)


def _clutter(pc: _Piece, xyz: np.ndarray, tree, L: dict[str, float]) -> float:
    """Share of the piece's length (5 m bins, away from its ends by ``pylon_radius``) where
    more points lie 1–4 tubes away from its curve than within one tube of it.  A wire hangs
    in free space (≈ 0, more where trees reach it); a crane jib, a lattice boom or a roof
    ridge has its own structure around the line it shows all along (≈ 1)."""
    if tree is None:
        return 0.0
    lo, hi = pc.fit.s_min + L["pylon_radius"], pc.fit.s_max - L["pylon_radius"]
    if hi - lo < 4.0 * L["tube"]:
        lo, hi = pc.fit.s_min, pc.fit.s_max
    step = L["tube"]
    s = np.arange(lo, hi + 1e-9, step)
    pts = np.column_stack([pc.centre + s[:, None] * pc.direction, pc.fit.z(s)])
    hits = tree.query_ball_point(pts, 4.0 * L["tube"] + step)
    ids = np.unique(np.concatenate([np.asarray(h, np.int64) for h in hits])) if len(hits) else np.zeros(0, np.int64)
    if not len(ids):
        return 0.0
    q = tree.data[ids]
    ss, _ = _frame(pc, q)
    keep = (ss >= lo) & (ss <= hi)
    q, ss = q[keep], ss[keep]
    dist = _curve_distance(pc, q)
    b = np.floor((ss - lo) / 5.0).astype(np.int64)
    nb = int(b.max()) + 1 if len(b) else 0
    inner = np.bincount(b[dist <= L["tube"]], minlength=nb)
    ring = np.bincount(b[(dist > L["tube"]) & (dist <= 4.0 * L["tube"])], minlength=nb)
    used = (inner + ring) > 0
    if not used.any():
        return 0.0
    return float(np.mean(ring[used] > inner[used]))


def _groups(n: int, links: list[tuple[int, int]]) -> np.ndarray:
    """Connected-component label of each of ``n`` items linked by ``links`` (pairs)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    ij = np.array(links, dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(ij)), (ij[:, 0], ij[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _runs_kept(pieces: list[_Piece], ends: list, L: dict[str, float], free: np.ndarray) -> np.ndarray:
    """Keep the pieces of runs (pieces joined at shared pylons) that are long enough, held at
    both ends and hang free (:func:`_clutter`)."""
    k = len(pieces)
    cos45 = math.cos(math.radians(45.0))
    links = [(i, j) for i in range(k) for j in range(i + 1, k)
             if abs(float(pieces[i].direction @ pieces[j].direction)) > cos45
             and any(ki == "pylon" and kj == "pylon" and np.linalg.norm(qi - qj) <= L["pylon_radius"]
                     for ki, qi in ends[i] for kj, qj in ends[j])]
    roots = _groups(k, links)
    keep = np.zeros(k, bool)
    for r in set(roots):
        members = [i for i in range(k) if roots[i] == r]
        # a hanging wire is convex and hangs free; a short piece may straddle a support (its
        # points then go to the neighbouring pieces' tubes); a short piece with an open end is
        # a stub (a branch, a bit of a roof), not part of the run
        length_of = {i: pieces[i].fit.s_max - pieces[i].fit.s_min for i in members}
        wire_like = [i for i in members if free[i] and -1e-5 <= pieces[i].fit.u <= MAX_CURVATURE
                     and length_of[i] >= 2.0 * L["radius"]]
        run = [i for i in wire_like
               if not (length_of[i] < 0.5 * L["min_length"] and any(kind == "open" for kind, _ in ends[i]))]
        length = sum(length_of[i] for i in run)
        held = all(kind != "open" for i in run for kind, _ in ends[i])
        if run and length >= L["min_length"] and (held or length >= L["long_length"]):
            keep[run] = True
    return keep


# ------------------------------------------------------------------ step 6
def _frame(pc: _Piece, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    q = pts[:, :2] - pc.centre
    return q @ pc.direction, q @ np.array([-pc.direction[1], pc.direction[0]])


def _curve_distance(pc: _Piece, pts: np.ndarray) -> np.ndarray:
    s, d = _frame(pc, pts)
    return np.hypot(d, pts[:, 2] - pc.fit.z(s))


def _insulator_at(pc: _Piece, xyz: np.ndarray, vert_idx: np.ndarray, tree, L: dict[str, float],
                  hi: int) -> np.ndarray | None:
    """The lower end of an insulator string at one end of a piece: at least 3 vertical
    linear points within ``tube`` of the curve extrapolated up to ``pylon_radius`` beyond
    the end (a suspension string stands at one position along the wire: their median)."""
    if tree is None:
        return None
    s_end = pc.fit.s_max if hi else pc.fit.s_min
    sign = 1.0 if hi else -1.0
    probe = s_end + sign * np.arange(-2.0 * L["radius"], L["pylon_radius"] + 1e-9, 0.25)
    pts = np.column_stack([pc.centre + probe[:, None] * pc.direction, pc.fit.z(probe)])
    hits = tree.query_ball_point(pts, L["tube"])
    near = np.unique(np.concatenate([np.asarray(h, np.int64) for h in hits])) if len(hits) else []
    if len(near) < 3:
        return None
    q = xyz[vert_idx[near]]
    sv, _ = _frame(pc, q)
    keep = _curve_distance(pc, q) <= L["tube"]
    if keep.sum() < 3:
        return None
    sx = float(np.median(sv[keep]))
    return np.array([*(pc.centre + sx * pc.direction), float(pc.fit.z(np.array([sx]))[0])])


def _attachments(pieces: list[_Piece], held: list[list[bool]], L: dict[str, float],
                 out: list[list[np.ndarray | None]] | None = None) -> list[list[np.ndarray | None]]:
    """Shared attachment points at suspension pylons: where the curves of two pieces held
    by the same pylon meet (closest approach within two ``tube``).  Per piece, the 3-D point
    at its low-s and high-s end, or ``None``."""
    out = [[None, None] for _ in pieces] if out is None else [list(o) for o in out]
    ends = [(_end_point(pc, False), _end_point(pc, True)) for pc in pieces]
    cos45 = math.cos(math.radians(45.0))
    for i, a in enumerate(pieces):
        for hi_a in (0, 1):
            if not held[i][hi_a] or out[i][hi_a] is not None:
                continue
            best = None
            for j, b in enumerate(pieces):
                if j == i or abs(float(a.direction @ b.direction)) < cos45:
                    continue
                for hi_b in (0, 1):
                    if not held[j][hi_b] or out[j][hi_b] is not None:
                        continue
                    if np.linalg.norm(ends[i][hi_a] - ends[j][hi_b]) > 2.0 * L["pylon_radius"]:
                        continue
                    reach = np.arange(-2.0, L["pylon_radius"] + 1e-9, 0.05)
                    sa = (a.fit.s_max if hi_a else a.fit.s_min) + reach * (1 if hi_a else -1)
                    sb = (b.fit.s_max if hi_b else b.fit.s_min) + reach * (1 if hi_b else -1)
                    pa = np.column_stack([a.centre + sa[:, None] * a.direction, a.fit.z(sa)])
                    pb = np.column_stack([b.centre + sb[:, None] * b.direction, b.fit.z(sb)])
                    dist = np.linalg.norm(pa[:, None] - pb[None], axis=2)
                    k = np.unravel_index(int(np.argmin(dist)), dist.shape)
                    if dist[k] <= 2.0 * L["tube"] and (best is None or dist[k] < best[0]):
                        best = (float(dist[k]), j, hi_b, 0.5 * (pa[k[0]] + pb[k[1]]))
            if best is not None:
                _, j, hi_b, x = best
                out[i][hi_a] = x
                out[j][hi_b] = x
    return out


def _tube_points(pc: _Piece, xyz: np.ndarray, above_idx: np.ndarray, tree, L: dict[str, float],
                 snap: list[np.ndarray | None], piece_of: np.ndarray, me: int) -> np.ndarray:
    """Above-ground points within ``tube`` of the piece's curve: over its own range and
    beyond it as long as they follow on without a gap (up to two ``pylon_radius``; never
    past an attachment point, nor into another piece's points)."""
    if tree is None:
        return np.zeros(0, np.int64)
    ext = 2.0 * L["pylon_radius"]
    lo, hi = pc.fit.s_min - ext, pc.fit.s_max + ext
    for k, x in enumerate(snap):
        if x is not None:
            sx = float((x[:2] - pc.centre) @ pc.direction)
            lo, hi = (sx, hi) if k == 0 else (lo, sx)
    step = max(L["tube"], 0.25)
    s = np.arange(lo, hi + 1e-9, step)
    pts = np.column_stack([pc.centre + s[:, None] * pc.direction, pc.fit.z(s)])
    hits = tree.query_ball_point(pts, L["tube"] + 0.5 * step)
    ids = np.unique(np.concatenate([np.asarray(h, np.int64) for h in hits])) if len(hits) else np.zeros(0, np.int64)
    ids = above_idx[ids]
    if not len(ids):
        return ids
    ss, _ = _frame(pc, xyz[ids])
    ok = (ss >= lo) & (ss <= hi) & (_curve_distance(pc, xyz[ids]) <= L["tube"])
    ids, ss = ids[ok], ss[ok]
    core = (ss >= pc.fit.s_min) & (ss <= pc.fit.s_max)
    order = np.argsort(ss)
    ids, ss, core = ids[order], ss[order], core[order]
    if not core.any():
        return ids[:0]
    first, last = np.flatnonzero(core)[[0, -1]]
    density = len(pc.index) / max(pc.fit.s_max - pc.fit.s_min, 1e-9)  # candidate points per metre
    gaps = np.diff(ss) > max(2.0 * L["radius"], 4.0 / density)
    foreign = (piece_of[ids] >= 0) & (piece_of[ids] != me)
    a = first
    while a > 0 and not gaps[a - 1] and not foreign[a - 1]:
        a -= 1
    b = last
    while b < len(ss) - 1 and not gaps[b] and not foreign[b + 1]:
        b += 1
    return ids[a:b + 1]


def _structure_snaps(pc: _Piece, xyz: np.ndarray, ids: np.ndarray, all_idx: np.ndarray, tree, L: dict[str, float],
                     snap: list[np.ndarray | None], held: list[bool]) -> None:
    """Ends held by a pylon: the first cluster of structure points (insulator string, pylon
    peak) within ``tube`` of the extrapolated curve, at most ``pylon_radius`` beyond the
    wire's last point, marks the attachment point (its far side: a suspension string
    stands at one position); ``snap`` is completed in place."""
    ss, _ = _frame(pc, xyz[ids])
    mine = np.zeros(len(xyz), bool)
    mine[ids] = True
    for k, s_end in ((0, float(ss.min())), (1, float(ss.max()))):
        if snap[k] is not None or not held[k]:
            continue
        sign = 1.0 if k else -1.0
        probe = s_end + sign * np.arange(0.0, L["pylon_radius"] + 1e-9, 0.25)
        pts = np.column_stack([pc.centre + probe[:, None] * pc.direction, pc.fit.z(probe)])
        hits = tree.query_ball_point(pts, L["tube"])
        near = np.unique(np.concatenate([np.asarray(h, np.int64) for h in hits])) if len(hits) else []
        if len(near) < 3:
            continue
        near = all_idx[near]
        near = near[~mine[near]]
        sv, _ = _frame(pc, xyz[near])
        beyond = np.sort((sv - s_end) * sign)
        beyond = beyond[beyond > 0]
        if len(beyond) >= 3:
            # the first cluster of structure points: an insulator string stands at one s
            cut = np.flatnonzero(np.diff(beyond) > L["tube"])
            first = beyond[: cut[0] + 1] if len(cut) else beyond
            if len(first) < 3:
                continue
            sx = s_end + sign * float(first[-1])
            snap[k] = np.array([*(pc.centre + sx * pc.direction), float(pc.fit.z(np.array([sx]))[0])])


def _split_bundle(pc: _Piece, xyz: np.ndarray, ids: np.ndarray, L: dict[str, float]) -> list[tuple[np.ndarray, int]]:
    """Sub-conductors of a bundle: Gaussian mixtures of the residuals (across, vertical)."""
    from sklearn.mixture import GaussianMixture

    s, d = _frame(pc, xyz[ids])
    if len(ids) < 40:
        return [(ids, 1)]
    # detrend across-track offset linearly in s (the conductor's chord need not be the piece's axis)
    A = np.column_stack([np.ones_like(s), s])
    coef, *_ = np.linalg.lstsq(A, d, rcond=None)
    r = np.column_stack([d - A @ coef, xyz[ids, 2] - pc.fit.z(s)])
    best_k, best_bic, best_labels = 1, math.inf, np.zeros(len(ids), np.int64)
    for k in range(1, 5):
        if len(ids) < 20 * k:
            break
        gm = GaussianMixture(k, covariance_type="spherical", random_state=0, n_init=2).fit(r)
        bic = gm.bic(r)
        if k > 1:
            means = gm.means_
            spread = np.sqrt(gm.covariances_)
            sep = min(float(np.linalg.norm(means[i] - means[j])) / (spread[i] + spread[j]) * 2.0
                      for i in range(k) for j in range(i + 1, k))
            dist = min(float(np.linalg.norm(means[i] - means[j])) for i in range(k) for j in range(i + 1, k))
            labels = gm.predict(r)
            share = np.bincount(labels, minlength=k).min() / len(ids)
            if dist < L["bundle_separation"] or sep < 4.0 or share < 0.5 / k:
                continue
        else:
            labels = np.zeros(len(ids), np.int64)
        if bic < best_bic:
            best_k, best_bic, best_labels = k, bic, labels
    if best_k == 1:
        return [(ids, 1)]
    gm_means = np.array([r[best_labels == k].mean(axis=0) for k in range(best_k)])
    order = np.lexsort((gm_means[:, 0], gm_means[:, 1]))  # by height, then across
    return [(ids[best_labels == k], best_k) for k in order]


def _conductor(cid: int, bundle: int, b_index: int, size: int, xyz: np.ndarray, ids: np.ndarray,
               origin: np.ndarray, snap: list[np.ndarray | None], reach: float) -> Conductor | None:
    if len(ids) < 5:
        return None
    c, d = _robust_plan_frame(xyz[ids, :2])
    s = (xyz[ids, :2] - c) @ d
    try:
        fit = fit_catenary(s, xyz[ids, 2])
    except LidarfxError:
        return None
    # orient start -> end: from lower s to higher s; frame origin at the first point, or at the
    # attachment point found for that end when the points reach within ``reach`` of it
    s_min, s_max = fit.s_min, fit.s_max
    for x in snap:
        if x is not None:
            sx = float((x[:2] - c) @ d)
            if abs(sx - s_min) <= reach:
                s_min = sx
            elif abs(sx - s_max) <= reach:
                s_max = sx
    fit = fit.shifted(s_min)
    start_xy = c + s_min * d
    length = s_max - s_min
    perp = np.array([-d[1], d[0]])
    lat = (xyz[ids, :2] - c) @ perp
    A = np.column_stack([np.ones_like(s), s - s_min])
    coef, *_ = np.linalg.lstsq(A, lat, rcond=None)
    z0, z1 = fit.z(np.array([0.0, length]))
    start = np.array([*(start_xy + origin[:2]), z0 + origin[2]])
    end = np.array([*(start_xy + length * d + origin[:2]), z1 + origin[2]])
    return Conductor(cid, -1, bundle, b_index, size, start, end, d, float(length), fit,
                     np.sort(ids), float(origin[2]), (float(coef[0]), float(coef[1])))


# ------------------------------------------------------------------ step 7
def _pylons(pos: list[np.ndarray], xyz: np.ndarray, pool: np.ndarray, L: dict[str, float],
            origin: np.ndarray) -> tuple[list[dict[str, Any]], np.ndarray]:
    """Pylons from the held wire ends: the clusters of above-ground points (``pool``)
    within ``pylon_radius`` of an end that reach up to it (within ``tube``); ends that
    share such a cluster, or lie within ``pylon_radius`` of each other without one,
    are one pylon."""
    from scipy.spatial import cKDTree

    from ..segment.components import linked_components

    n = len(xyz)
    pid = np.full(n, -1, np.int64)
    if not pos:
        return [], pid
    P = np.array(pos)
    pool_idx = np.flatnonzero(pool)
    comp = linked_components(xyz[pool_idx], 1.5 * L["radius"]) if len(pool_idx) else np.zeros(0, np.int64)
    tree = cKDTree(xyz[pool_idx, :2]) if len(pool_idx) else None
    held: list[set] = []
    for q in P:
        near = np.asarray(tree.query_ball_point(q[:2], L["pylon_radius"]), np.int64) if tree is not None else []
        ks = set()
        if len(near):
            for k in np.unique(comp[near]):
                m = near[comp[near] == k]
                if len(m) >= 5 and xyz[pool_idx[m], 2].max() >= q[2] - L["tube"]:
                    ks.add(int(k))
        held.append(ks)
    links = [(i, j) for i in range(len(P)) for j in range(i + 1, len(P))
             if held[i] & held[j] or (np.linalg.norm(P[i, :2] - P[j, :2]) <= L["pylon_radius"]
                                      and not (held[i] or held[j]))]
    groups: dict[int, list[int]] = {}
    for i, r in enumerate(_groups(len(P), links)):
        groups.setdefault(int(r), []).append(i)
    # an end with no structure of its own, alone, belongs to the nearest pylon (an earth
    # wire whose last metres at the peak were not seen)
    alone = [r for r, g in groups.items() if len(g) == 1 and not held[g[0]]]
    for r in alone:
        others = [q for q in groups if q != r and q not in alone]
        if others:
            i = groups[r][0]
            dist = [min(np.linalg.norm(P[j, :2] - P[i, :2]) for j in groups[q]) for q in others]
            k = int(np.argmin(dist))
            if dist[k] <= 2.0 * L["pylon_radius"]:
                groups[others[k]].append(i)
                del groups[r]
    pylons = []
    for g in sorted(groups.values(), key=lambda g: tuple(P[g].mean(axis=0)[:2])):
        centre = P[g].mean(axis=0)
        ks = set().union(*(held[i] for i in g))
        sel = np.zeros(0, np.int64)
        if ks:
            members = pool_idx[np.isin(comp, list(ks))]
            reach = np.min(np.linalg.norm(xyz[members, None, :2] - P[None, g, :2], axis=2), axis=1) \
                if len(members) * len(g) < 5e7 else np.zeros(len(members))
            sel = members[(reach <= L["pylon_radius"]) & (pid[members] < 0)]
        rec = {"id": len(pylons), "position": (centre + origin).tolist(), "points": int(len(sel)), "top": None,
               "wire_ends": len(g)}
        if len(sel):
            pid[sel] = rec["id"]
            rec["top"] = float(xyz[sel, 2].max() + origin[2])
            rec["position"] = [*(xyz[sel, :2].mean(axis=0) + origin[:2]).tolist(), float(xyz[sel, 2].min() + origin[2])]
        rec["ends"] = [(P[i] + origin).tolist() for i in g]
        pylons.append(rec)
    return pylons, pid


def _spans(conductors: list[Conductor], pylons: list[dict[str, Any]], origin: np.ndarray,
           L: dict[str, float]) -> list[dict[str, Any]]:
    """Conductors between the same two supports (pylon ids, or the data edge) form a span."""
    P = np.array([p["position"] for p in pylons]).reshape(-1, 3)

    def support(q: np.ndarray, kind: str) -> int:
        """The pylon holding an end: none at the data edge, else the nearest within two
        pylon radii (an end open before the growth may have grown up to its pylon)."""
        if not len(P) or kind == "edge":
            return -1
        dist = np.linalg.norm(P[:, :2] - q[:2], axis=1)
        k = int(np.argmin(dist))
        return int(pylons[k]["id"]) if dist[k] <= 2.0 * L["pylon_radius"] else -1

    keys: dict[tuple, list[Conductor]] = {}
    for cd in conductors:
        a, b = support(cd.start, cd.end_kinds[0]), support(cd.end, cd.end_kinds[1])
        if a == b and a >= 0:
            cd.span_id = -2  # both ends at one pylon: a stub, not a span
            continue
        key = tuple(sorted((a, b)))
        if -1 in key:  # open at the data edge: group by plan direction and the side of the pylon
            held = [k for k in key if k >= 0]
            side = 0
            if held:
                mid = 0.5 * (cd.start[:2] + cd.end[:2])
                side = int(np.sign(float((mid - P[held[0], :2]) @ cd.direction)))
            key = key + (round(math.degrees(math.atan2(cd.direction[1], cd.direction[0])) % 180.0 / 15.0), side)
        keys.setdefault(key, []).append(cd)
    spans = []
    for key, cds in sorted(keys.items(), key=lambda kv: min(c.id for c in kv[1])):
        sid = len(spans)
        for cd in cds:
            cd.span_id = sid
        spans.append({"id": sid, "pylons": [k for k in key[:2] if k >= 0], "conductors": [c.id for c in cds],
                      "bundles": len({c.bundle_id for c in cds}),
                      "length": round(float(np.median([c.length for c in cds])), 3)})
    return spans


# ------------------------------------------------------------------ step 8
def _measure(conductors: list[Conductor], xyz: np.ndarray, ground_z, obj: np.ndarray, origin: np.ndarray,
             L: dict[str, float]) -> None:
    from scipy.spatial import cKDTree

    obj_xyz = xyz[obj]
    obj_tree = cKDTree(obj_xyz) if len(obj_xyz) else None
    curves = [cd.curve(L["step"]) - origin for cd in conductors]
    allq = np.vstack([c[:, :2] for c in curves]) if curves else np.zeros((0, 2))
    gz = ground_z(allq) if len(allq) else np.zeros(0)
    pos = 0
    for cd, cv in zip(conductors, curves):
        gzz = gz[pos:pos + len(cv)]
        pos += len(cv)
        cd.measures.update(conductor_measures(cd))
        clear = cv[:, 2] - gzz
        k = int(np.argmin(clear))
        cd.measures["ground_clearance"] = float(clear[k])
        cd.measures["ground_clearance_at"] = (cv[k] + origin).tolist()
        if obj_tree is not None:
            dist, j = obj_tree.query(cv, k=1)
            k = int(np.argmin(dist))
            cd.measures["object_clearance"] = float(dist[k])
            cd.measures["object_clearance_at"] = (cv[k] + origin).tolist()
            cd.measures["object_point"] = (obj_xyz[j[k]] + origin).tolist()
        else:
            cd.measures["object_clearance"] = None
            cd.measures["object_clearance_at"] = None
            cd.measures["object_point"] = None


def conductor_measures(cd: Conductor) -> dict[str, Any]:
    """Sag, conductor length and lowest point of a conductor's catenary (world coordinates)."""
    f, Lh = cd.fit, cd.length
    z0 = cd.z_offset
    z = f.z(np.array([0.0, Lh]))
    m = float((z[1] - z[0]) / Lh) if Lh > 0 else 0.0
    # sag: where the curve's slope equals the chord's: sinh(t + (s - s_ref) u) = m
    if f.u > 0:
        s_sag = f.s_ref + (math.asinh(m) - math.asinh(f.m)) / f.u
    else:
        s_sag = 0.5 * Lh
    s_sag = min(max(s_sag, 0.0), Lh)
    sag = float(z[0] + m * s_sag - f.z(np.array([s_sag]))[0])
    ss = np.linspace(0.0, Lh, max(2, int(math.ceil(Lh / 0.05)) + 1))
    zz = f.z(ss)
    length = float(np.sum(np.hypot(np.diff(ss), np.diff(zz))))
    k = int(np.argmin(zz))
    if f.u > 0 and 0.0 <= f.s0 <= Lh:
        s_low = f.s0
    else:
        s_low = float(ss[k])
    low = np.array([*cd.xy(np.array([s_low]))[0], float(f.z(np.array([s_low]))[0])])
    sag_pt = np.array([*cd.xy(np.array([s_sag]))[0], float(f.z(np.array([s_sag]))[0]) + z0])
    return {
        "a": f.a if math.isfinite(f.a) else None,
        "s0": f.s0 if math.isfinite(f.s0) else None,
        "c": (f.c + z0) if math.isfinite(f.c) else None,
        "rmse": f.rmse,
        "points": int(len(cd.index)),
        "sag": sag,
        "sag_s": s_sag,
        "sag_point": sag_pt.tolist(),
        "conductor_length": length,
        "lowest_point": [float(low[0]), float(low[1]), float(low[2] + z0)],
    }
