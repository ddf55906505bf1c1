"""ALS power-line corridor (LIS slides, seed 000): terrain, pylons, catenary wires, trees.

Span-local frame of a wire (the convention of every catenary in lidarfx):
``s`` = horizontal distance from the wire's start attachment point towards its
end attachment point (along the straight plan-view chord), ``z(s) = c + a ·
cosh((s − s0) / a)``.  ``a`` (m) is the catenary parameter (horizontal
tension / weight per metre), ``s0`` the position of the vertex (lowest point of
the full curve; may lie outside the span), ``c`` the height offset, so the
vertex height is ``c + a``.  ``c`` and all coordinates in the truth are local:
add ``truth["origin"]`` for world coordinates.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ._common import (
    Scene,
    add_noise,
    capture_params,
    check_count,
    check_fraction,
    check_length,
    check_nonneg,
    check_origin,
    check_positive,
    class_counts,
    finish,
    isolated_outliers,
    make_rng,
    merge_classes,
    rotate_z,
    sample_ellipsoid,
    sample_interval,
    sample_segment,
    smooth_field,
)
from .tower import lattice_members
from ..errors import LidarfxError

__all__ = ["POWERLINE_CLASSES", "powerline", "catenary_z", "catenary_through"]

POWERLINE_CLASSES: dict[str, int] = {
    "ground": 2,
    "vegetation": 5,
    "noise": 7,
    "wire": 14,
    "pylon": 15,
    "insulator": 16,
}
"""ASPRS LAS 1.4 codes: 14 wire – conductor, 15 transmission tower, 16 wire–structure connector."""

PYLON_ARMS = (
    {"z_frac": 0.72, "left": 6.5, "right": 6.5, "depth": 1.8},
    {"z_frac": 0.90, "left": 0.0, "right": 4.5, "depth": 1.2},
)
"""Pylon cross arms: a lower arm with two phases (±x) and an upper arm with one (+x)."""


def catenary_z(s: Any, a: float, s0: float, c: float) -> np.ndarray:
    """``z(s) = c + a · cosh((s − s0) / a)``."""
    return c + a * np.cosh((np.asarray(s, float) - s0) / a)


def catenary_through(z_start: float, z_end: float, length: float, a: float) -> tuple[float, float]:
    """``(s0, c)`` of the catenary with parameter ``a`` through (0, z_start) and (length, z_end).

    Closed form: ``z_end − z_start = 2a sinh((L − 2 s0)/(2a)) sinh(L/(2a))``.
    """
    if length <= 0 or a <= 0:
        raise LidarfxError("catenary needs length > 0 and a > 0")
    s0 = length / 2.0 - a * math.asinh((z_end - z_start) / (2.0 * a * math.sinh(length / (2.0 * a))))
    c = z_start - a * math.cosh(s0 / a)
    return s0, c


def _wire_truth(wid: int, span: int, phase: int, A: np.ndarray, B: np.ndarray, a: float,
                ground) -> dict[str, Any]:
    """Parameters and derived quantities of one wire from A to B."""
    d = B[:2] - A[:2]
    L = float(np.linalg.norm(d))
    s0, c = catenary_through(A[2], B[2], L, a)
    m = (B[2] - A[2]) / L
    s_sag = s0 + a * math.asinh(m)  # curve slope = chord slope
    sag = A[2] + m * s_sag - float(catenary_z(s_sag, a, s0, c))
    s_low = min(max(s0, 0.0), L)
    u = d / L
    low = np.array([*(A[:2] + s_low * u), float(catenary_z(s_low, a, s0, c))])
    ss = np.linspace(0.0, L, max(50, int(L)))
    xy = A[:2] + ss[:, None] * u
    clearance = float(np.min(catenary_z(ss, a, s0, c) - ground(xy[:, 0], xy[:, 1])))
    length = a * (math.sinh((L - s0) / a) - math.sinh(-s0 / a))
    return {
        "id": wid, "span_id": span, "phase": phase,
        "a": a, "s0": s0, "c": c,
        "start_xy": A[:2], "end_xy": B[:2],
        "attachment_start": A, "attachment_end": B,
        "horizontal_length": L, "direction": u,
        "sag": sag, "sag_s": s_sag, "lowest_point": low, "conductor_length": length,
        "ground_clearance": clearance,
    }


def powerline(
    *,
    n_spans: int = 3,
    span_length: float = 200.0,
    density: float = 4.0,
    wire_density: float = 3.0,
    pylon_density: float = 6.0,
    noise: float = 0.05,
    corridor_width: float = 60.0,
    pylon_height: float = 34.0,
    catenary_a: Sequence[float] = (1000.0, 1600.0),
    n_trees: int = 14,
    n_near_trees: int = 3,
    noise_fraction: float = 0.001,
    classes: dict[str, int] | None = None,
    seed: int = 0,
    origin: Any = None,
):
    """ALS corridor: undulating terrain, lattice pylons, 3 wires per span on catenaries, trees.

    Parameters
    ----------
    n_spans:
        Number of spans (pylons = n_spans + 1); 3 wires (phases) per span.
    span_length:
        Mean horizontal pylon distance (m); each span varies by ±15 % and the
        line turns by up to ±12° at each inner pylon.
    density:
        Ground points per m² (ALS); trees get 1.5 × this per m² of crown.
    wire_density, pylon_density:
        Points per metre along each wire / each pylon member.
    noise:
        Gaussian σ (m) on every coordinate.
    corridor_width:
        Width of the sampled strip centred on the line (m).
    pylon_height:
        Body height of the pylons (m); arms see :data:`PYLON_ARMS`; insulators
        hang 2.5 m below the arm tips, the wires attach at their lower ends.
    catenary_a:
        Range (min, max) of the per-wire catenary parameter a (m).
    n_trees, n_near_trees:
        Trees in the corridor; the first ``n_near_trees`` stand under a wire at
        mid-span with a 2–4 m clearance, the others keep ≥ 4 m from every wire.
    noise_fraction:
        Isolated outliers (class noise) as a share of the points: half below
        ground, half high above the wires.
    classes:
        Override class codes (name -> code) of :data:`POWERLINE_CLASSES`.
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).

    Returns
    -------
    PointCloud
        Attributes ``classification``, ``wire_id`` (−1 = not a wire),
        ``span_id`` (wires, −1 otherwise), ``pylon_id`` (pylon and insulator
        points, −1 otherwise).  ``meta["truth"]``: ``classes``, ``pylons``,
        ``spans``, ``wires`` (a, s0, c, start/end xy, attachment points, sag,
        lowest point, conductor length, ground clearance), ``trees``
        (with ``clearance`` to the nearest wire), ``catenary`` (the frame).
    """
    params = capture_params(locals())
    if not isinstance(n_spans, (int, np.integer)) or n_spans < 1:
        raise LidarfxError(f"n_spans must be a positive integer, got {n_spans!r}")
    n_spans = check_count("n_spans", n_spans, 1, 100)
    span_length = check_length("span_length", span_length)
    density = check_positive("density", density)
    wire_density = check_positive("wire_density", wire_density)
    pylon_density = check_positive("pylon_density", pylon_density)
    noise = check_nonneg("noise", noise)
    half_w = check_length("corridor_width", corridor_width) / 2.0
    pylon_height = check_length("pylon_height", pylon_height)
    n_trees = check_count("n_trees", n_trees)
    n_near_trees = check_count("n_near_trees", n_near_trees)
    noise_fraction = check_fraction("noise_fraction", noise_fraction)
    a_lo, a_hi = (float(v) for v in catenary_a)
    if not (0 < a_lo <= a_hi and math.isfinite(a_hi)):
        raise LidarfxError(f"catenary_a must be (min, max) with 0 < min <= max, got {catenary_a!r}")
    cls = merge_classes(POWERLINE_CLASSES, classes)
    origin = check_origin(origin)
    rng = make_rng(seed)

    # ---- line geometry: pylon positions and azimuths (clockwise from North)
    azimuth = [rng.uniform(60.0, 120.0)]
    for _ in range(1, n_spans):
        azimuth.append(azimuth[-1] + rng.uniform(-12.0, 12.0))
    pos = [np.zeros(2)]
    for k in range(n_spans):
        L = span_length * rng.uniform(0.85, 1.15)
        a = math.radians(azimuth[k])
        pos.append(pos[-1] + L * np.array([math.sin(a), math.cos(a)]))
    pos = np.array(pos)
    field = smooth_field(rng, 4.0, 250.0)
    tilt = rng.uniform(-0.01, 0.01, 2)

    def ground(x: Any, y: Any) -> np.ndarray:
        return 20.0 + field(x, y) + tilt[0] * np.asarray(x) + tilt[1] * np.asarray(y)

    scene = Scene({
        "classification": (np.uint8, cls["ground"]),
        "wire_id": (np.int32, -1),
        "span_id": (np.int32, -1),
        "pylon_id": (np.int32, -1),
    })

    # ---- ground: the corridor strip around the polyline
    lo, hi = pos.min(axis=0) - half_w, pos.max(axis=0) + half_w
    n = int(round(float(np.prod(hi - lo)) * density))
    xy = lo + rng.uniform(size=(n, 2)) * (hi - lo)
    dist, _, _ = _polyline_distance(xy, pos)
    xy = xy[dist <= half_w]
    scene.add(np.column_stack([xy, ground(xy[:, 0], xy[:, 1])]), classification=cls["ground"])

    # ---- pylons: arms perpendicular to the bisector of the adjacent spans
    members, tips = lattice_members(pylon_height, 5.0, 1.4, 5, PYLON_ARMS, peak=2.0)
    tips = sorted(tips, key=lambda t: (t["arm"], t["side"]))  # phases 0, 1: lower −x, +x; 2: upper +x
    insulator = 2.5
    pylons = []
    for k, p in enumerate(pos):
        az = azimuth[min(k, n_spans - 1)] if k in (0, n_spans) else 0.5 * (azimuth[k - 1] + azimuth[k])
        # local x (arms) must point to the right of the line direction: azimuth + 90
        rot = 90.0 - (az + 90.0)  # counter-clockwise angle from +x to the arm direction
        base = np.array([p[0], p[1], float(ground(p[0], p[1]))])
        for m in members:
            a_, b_ = rotate_z(m["start"][None], rot)[0] + base, rotate_z(m["end"][None], rot)[0] + base
            scene.add(sample_segment(rng, a_, b_, pylon_density), classification=cls["pylon"], pylon_id=k)
        attach = []
        for t in tips:
            top = rotate_z(t["xyz"][None], rot)[0] + base
            bottom = top - np.array([0.0, 0.0, insulator])
            scene.add(sample_segment(rng, top, bottom, 4 * pylon_density), classification=cls["insulator"], pylon_id=k)
            attach.append(bottom)
        pylons.append({"id": k, "base": base, "height": pylon_height, "azimuth": az % 360.0,
                       "attachments": attach, "insulator_length": insulator})

    # ---- wires
    wires, spans = [], []
    for k in range(n_spans):
        spans.append({"id": k, "start_pylon": k, "end_pylon": k + 1, "wire_ids": []})
        a_span = rng.uniform(a_lo, a_hi)
        for ph in range(len(tips)):
            wid = len(wires)
            A, B = pylons[k]["attachments"][ph], pylons[k + 1]["attachments"][ph]
            a = float(np.clip(a_span * rng.uniform(0.97, 1.03), a_lo, a_hi))
            w = _wire_truth(wid, k, ph, A, B, a, ground)
            s = sample_interval(rng, 0.0, w["horizontal_length"], wire_density)
            pts = np.column_stack([A[:2] + s[:, None] * w["direction"], catenary_z(s, a, w["s0"], w["c"])])
            scene.add(pts, classification=cls["wire"], wire_id=wid, span_id=k)
            wires.append(w)
            spans[-1]["wire_ids"].append(wid)

    # dense wire curves for clearances
    curves = []
    for w in wires:
        ss = np.linspace(0.0, w["horizontal_length"], int(w["horizontal_length"] * 2) + 2)
        curves.append(np.column_stack([w["start_xy"] + ss[:, None] * w["direction"],
                                       catenary_z(ss, w["a"], w["s0"], w["c"])]))
    curve = np.vstack(curves)
    from scipy.spatial import cKDTree

    curve_tree = cKDTree(curve)
    curve_xy_tree = cKDTree(curve[:, :2])

    # ---- trees
    trees = []
    total_len = [float(np.linalg.norm(pos[k + 1] - pos[k])) for k in range(n_spans)]
    for i in range(int(n_trees)):
        near = i < n_near_trees
        if near:
            w = wires[(i * 4 + 1) % len(wires)]  # different spans and phases
            s = w["horizontal_length"] * rng.uniform(0.4, 0.6)
            xy0 = w["start_xy"] + s * w["direction"]
        else:
            k = int(rng.integers(n_spans))
            t = rng.uniform(0.1, 0.9) * total_len[k]
            u = (pos[k + 1] - pos[k]) / total_len[k]
            xy0 = pos[k] + t * u + rng.uniform(-half_w + 4, half_w - 4) * np.array([u[1], -u[0]])
        g = float(ground(*xy0))
        r = rng.uniform(2.0, 3.5)
        # lowest wire height over the crown footprint (near trees) or within 6 m of it (others:
        # every crown point then stays >= 4 m below, or > 6 m beside, any wire)
        idx = curve_xy_tree.query_ball_point(xy0, r + (2.0 if near else 6.0))
        wire_z = float(np.min(curve[idx, 2])) if idx else np.inf
        if near:
            h = wire_z - g - rng.uniform(2.0, 4.0)
        else:
            h = min(rng.uniform(8.0, 20.0), wire_z - g - 4.0)
        h = max(h, 3.0)
        crown_c = np.array([xy0[0], xy0[1], g + h - r * 0.9])
        # about 1.5 x density points per m² of crown footprint, in the outer half of the crown
        shell_volume = 4.0 / 3.0 * math.pi * r * r * (0.9 * r) * (1 - 0.5**3)
        crown = sample_ellipsoid(rng, crown_c, (r, r, r * 0.9), 1.5 * density * math.pi * r * r / shell_volume,
                                 shell=0.5)
        stem = sample_segment(rng, [xy0[0], xy0[1], g], [xy0[0], xy0[1], crown_c[2]], 2.0)
        pts = np.vstack([crown, stem])
        scene.add(pts, classification=cls["vegetation"])
        d, _ = curve_tree.query(pts, k=1)
        trees.append({"id": i, "position": [xy0[0], xy0[1], g], "height": h, "crown_radius": r,
                      "near_wire": near, "clearance": float(d.min()) if len(d) else None})

    xyz, attrs = scene.arrays()
    xyz = add_noise(rng, xyz, noise)
    # ---- isolated noise: below ground and high above the wires
    n_noise = int(round(noise_fraction * len(xyz)))
    top = float(xyz[:, 2].max())
    low_lo = np.array([lo[0], lo[1], float(xyz[:, 2].min()) - 15.0])
    pts_low = isolated_outliers(rng, xyz, low_lo, [hi[0], hi[1], low_lo[2] + 10.0], n_noise // 2, 5.0)
    pts_high = isolated_outliers(rng, xyz, [lo[0], lo[1], top + 10.0], [hi[0], hi[1], top + 60.0],
                                 n_noise - n_noise // 2, 5.0)
    noise_pts = np.vstack([pts_low, pts_high])
    xyz = np.vstack([xyz, noise_pts])
    for name, arr in attrs.items():
        fill = cls["noise"] if name == "classification" else -1
        attrs[name] = np.concatenate([arr, np.full(len(noise_pts), fill, dtype=arr.dtype)])

    truth = {
        "classes": cls,
        "catenary": "z(s) = c + a*cosh((s - s0)/a); s = horizontal distance from attachment_start "
                    "towards end_xy; local coordinates (add origin)",
        "pylons": pylons,
        "spans": spans,
        "wires": wires,
        "trees": trees,
        "corridor_width": 2 * half_w,
        "counts": class_counts(attrs["classification"], cls),
    }
    return finish("powerline", xyz, attrs, truth, params, origin)


def _polyline_distance(xy: np.ndarray, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plan distance of points to a polyline: ``(distance, segment index, parameter t in [0, 1])``."""
    best = np.full(len(xy), np.inf)
    seg = np.zeros(len(xy), dtype=np.int64)
    tt = np.zeros(len(xy))
    for k in range(len(vertices) - 1):
        a, b = vertices[k], vertices[k + 1]
        d = b - a
        t = np.clip(((xy - a) @ d) / float(d @ d), 0.0, 1.0)
        dist = np.linalg.norm(xy - (a + t[:, None] * d), axis=1)
        better = dist < best
        best[better], seg[better], tt[better] = dist[better], k, t[better]
    return best, seg, tt
