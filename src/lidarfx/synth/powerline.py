"""ALS power-line corridor (after the LIS slides): terrain, pylons, catenary wires, trees.

Optional parts for testing a wire extractor: bundled conductors (``bundle`` sub-conductors per
phase), an earth (shield) wire on the pylon peaks and tower cranes beside the line whose long
horizontal jibs run roughly parallel to it.

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
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..errors import LidarfxError
from ..powerlines.catenary import catenary_through, catenary_z
from ._common import (
    Scene,
    add_noise,
    capture_params,
    check_count,
    check_flag,
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
    sample_box_surface,
    sample_ellipsoid,
    sample_interval,
    sample_segment,
    smooth_field,
)
from .tower import lattice_members

__all__ = ["POWERLINE_CLASSES", "bundle_offsets", "catenary_through", "catenary_z", "powerline"]

POWERLINE_CLASSES: dict[str, int] = {
    "ground": 2,
    "vegetation": 5,
    "noise": 7,
    "wire": 14,
    "pylon": 15,
    "insulator": 16,
    "crane": 26,
}
"""ASPRS LAS 1.4 codes: 14 wire – conductor, 15 transmission tower, 16 wire–structure connector;
26 crane (AHN's user-defined code; only used with ``n_cranes > 0``)."""

PYLON_ARMS = (
    {"z_frac": 0.72, "left": 6.5, "right": 6.5, "depth": 1.8},
    {"z_frac": 0.90, "left": 0.0, "right": 4.5, "depth": 1.2},
)
"""Pylon cross arms: a lower arm with two phases (±x) and an upper arm with one (+x)."""

PYLON_PEAK = 2.0
"""Height (m) of the pylon's pyramid peak above the body; the earth wire attaches at its apex."""

CRANE_MAST_WIDTH = 1.6
"""Side (m) of the square cross-section of a crane mast."""
CRANE_JIB_WIDTH = 1.2
"""Side (m) of the equilateral triangular cross-section of a crane jib and counter-jib."""
CRANE_COUNTER_JIB = 10.0
"""Length (m) of a crane's counter-jib (from the mast axis)."""
CRANE_CLEARANCE = 8.5
"""Smallest plan distance (m) of every crane member from every wire and pylon member (a margin of
0.5 m over the 8 m promised in the docs, for the noise)."""


def bundle_offsets(bundle: int, spacing: float) -> np.ndarray:
    """``(bundle, 2)`` offsets ``(across, up)`` (m) of the sub-conductors from the phase point.

    ``across`` is horizontal, perpendicular to the span (positive to the right of the span
    direction), ``up`` vertical; the offsets are centred on the phase point.  1: the phase point;
    2: horizontal twin (left, right); 3: equilateral triangle of side ``spacing``, two below
    (left, right) and one above; 4: square of side ``spacing`` (lower left, lower right, upper
    right, upper left).
    """
    h = spacing / 2.0
    if bundle == 1:
        return np.zeros((1, 2))
    if bundle == 2:
        return np.array([[-h, 0.0], [h, 0.0]])
    if bundle == 3:
        t = spacing * math.sqrt(3.0) / 2.0  # triangle height; centroid at 1/3 of it
        return np.array([[-h, -t / 3.0], [h, -t / 3.0], [0.0, 2.0 * t / 3.0]])
    if bundle == 4:
        return np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    raise LidarfxError(f"bundle must be 1, 2, 3 or 4, got {bundle!r}")


def _wire_truth(wid: int, span: int, phase: int, A: np.ndarray, B: np.ndarray, a: float,
                ground, **extra: Any) -> dict[str, Any]:
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
        **extra,
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
    bundle: int = 1,
    bundle_spacing: float = 0.4,
    earth_wire: bool = False,
    n_cranes: int = 0,
    classes: dict[str, int] | None = None,
    seed: int = 0,
    origin: Any = None,
):
    """ALS corridor: undulating terrain, lattice pylons, 3 phases per span on catenaries, trees.

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
    bundle, bundle_spacing:
        Sub-conductors per phase (1 .. 4) and their spacing (m, at most 2):
        see :func:`bundle_offsets`.  Each sub-conductor is its own catenary
        (the phase's ``a``, attachment points offset from the phase's by the
        bundle offset, perpendicular to the span) with its own ``wire_id``.
    earth_wire:
        One earth (shield) wire per span between the pylon peaks (apex of the
        pyramid, ``PYLON_PEAK`` m above the body), no insulator, sampled at
        ``wire_density / 2``; its ``a`` is the span's 1.0–1.15 ×, so it stays
        above the phases.  ``phase`` = 3, ``kind`` = ``"earth"``.
    n_cranes:
        Tower cranes (0 .. 10) beside the line: a square lattice mast
        (1.6 m, 20–30 m high) standing 12–20 m to the side of the outermost
        wire, a horizontal triangular lattice jib (1.2 m, 35–50 m) at the
        mast top within ±20° of the span direction, a 10 m counter-jib with a
        counterweight box; every crane member keeps ≥ 8 m in plan from every
        wire and pylon member.  Class ``crane``.
    classes:
        Override class codes (name -> code) of :data:`POWERLINE_CLASSES`.
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).

    Returns
    -------
    PointCloud
        Attributes ``classification``, ``wire_id`` (one per sub-conductor,
        −1 = not a wire), ``span_id`` (wires, −1 otherwise), ``pylon_id``
        (pylon and insulator points, −1 otherwise), ``phase_id`` (the bundle:
        ``span_id * n_phases + phase``, −1 = not a wire), ``crane_id`` (crane
        points, −1 otherwise).  ``meta["truth"]``: ``classes``, ``pylons``,
        ``spans`` (with ``phases``), ``wires`` (a, s0, c, start/end xy,
        attachment points, sag, lowest point, conductor length, ground
        clearance, kind, phase_id, bundle_index, bundle_offset), ``trees``
        (with ``clearance`` to the nearest wire), ``cranes``, ``bundle``,
        ``n_phases``, ``catenary`` (the frame).

    Random numbers: the parts of the plain corridor draw from
    ``default_rng(seed)`` in the same order whatever the new options;
    sub-conductors after the first, the earth wire and the cranes draw from a
    second generator ``default_rng([seed, 1])``, so the defaults give exactly
    the points of the generator before these options existed, and ground,
    pylons and the phases' ``a`` never change with the options.  Tree heights
    keep their clearance to the actual (sub-)conductors, so a triangle or
    square bundle may change the trees (a tree's stem count follows its
    height); the earth wire and the cranes leave them alone.
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
    bundle = check_count("bundle", bundle, 1, 4)
    bundle_spacing = check_positive("bundle_spacing", bundle_spacing, 2.0)
    earth_wire = check_flag("earth_wire", earth_wire)
    n_cranes = check_count("n_cranes", n_cranes, 0, 10)
    a_lo, a_hi = (float(v) for v in catenary_a)
    if not (0 < a_lo <= a_hi and math.isfinite(a_hi)):
        raise LidarfxError(f"catenary_a must be (min, max) with 0 < min <= max, got {catenary_a!r}")
    cls = merge_classes(POWERLINE_CLASSES, classes)
    origin = check_origin(origin)
    rng = make_rng(seed)
    # the optional parts (sub-conductors 1.., earth wire, cranes) draw from their own generator, so
    # the main stream -- and with the defaults every point -- is the one of the plain corridor
    rng_extra = np.random.default_rng([int(seed), 1]) if seed is not None else np.random.default_rng()

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
        "phase_id": (np.int32, -1),
        "crane_id": (np.int32, -1),
    })

    # ---- ground: the corridor strip around the polyline
    lo, hi = pos.min(axis=0) - half_w, pos.max(axis=0) + half_w
    n = round(float(np.prod(hi - lo)) * density)
    xy = lo + rng.uniform(size=(n, 2)) * (hi - lo)
    dist, _, _ = _polyline_distance(xy, pos)
    xy = xy[dist <= half_w]
    scene.add(np.column_stack([xy, ground(xy[:, 0], xy[:, 1])]), classification=cls["ground"])

    # ---- pylons: arms perpendicular to the bisector of the adjacent spans
    members, tips = lattice_members(pylon_height, 5.0, 1.4, 5, PYLON_ARMS, peak=PYLON_PEAK)
    tips = sorted(tips, key=lambda t: (t["arm"], t["side"]))  # phases 0, 1: lower −x, +x; 2: upper +x
    insulator = 2.5
    pylons = []
    keep_out = []  # dense pylon member points: the cranes keep their distance in plan
    for k, p in enumerate(pos):
        az = azimuth[min(k, n_spans - 1)] if k in (0, n_spans) else 0.5 * (azimuth[k - 1] + azimuth[k])
        # local x (arms) must point to the right of the line direction: azimuth + 90
        rot = 90.0 - (az + 90.0)  # counter-clockwise angle from +x to the arm direction
        base = np.array([p[0], p[1], float(ground(p[0], p[1]))])
        for m in members:
            a_, b_ = rotate_z(m["start"][None], rot)[0] + base, rotate_z(m["end"][None], rot)[0] + base
            scene.add(sample_segment(rng, a_, b_, pylon_density), classification=cls["pylon"], pylon_id=k)
            keep_out.append(_dense_segment(a_, b_))
        attach = []
        for t in tips:
            top = rotate_z(t["xyz"][None], rot)[0] + base
            bottom = top - np.array([0.0, 0.0, insulator])
            scene.add(sample_segment(rng, top, bottom, 4 * pylon_density), classification=cls["insulator"], pylon_id=k)
            attach.append(bottom)
        peak_xyz = base + np.array([0.0, 0.0, pylon_height + PYLON_PEAK])  # apex on the pylon axis
        pylons.append({"id": k, "base": base, "height": pylon_height, "azimuth": az % 360.0,
                       "attachments": attach, "insulator_length": insulator, "peak": peak_xyz})

    # ---- wires: per span the phases (each a bundle of sub-conductors), then the earth wire
    n_phases = len(tips) + int(earth_wire)
    offsets = bundle_offsets(bundle, bundle_spacing)
    wires, spans, phase_axes = [], [], []
    for k in range(n_spans):
        spans.append({"id": k, "start_pylon": k, "end_pylon": k + 1, "wire_ids": [], "phases": []})
        a_span = rng.uniform(a_lo, a_hi)
        for ph in range(len(tips)):
            A, B = pylons[k]["attachments"][ph], pylons[k + 1]["attachments"][ph]
            a = float(np.clip(a_span * rng.uniform(0.97, 1.03), a_lo, a_hi))
            d = B[:2] - A[:2]
            L = float(np.linalg.norm(d))
            u = d / L
            phase_axes.append({"start_xy": A[:2], "direction": u, "horizontal_length": L})
            across = np.array([u[1], -u[0], 0.0])  # horizontal, to the right of the span
            pid = k * n_phases + ph
            s = sample_interval(rng, 0.0, L, wire_density)  # sub-conductor 0: the main stream
            ids = []
            for j, (o_across, o_up) in enumerate(offsets):
                off = o_across * across + np.array([0.0, 0.0, o_up])
                w = _wire_truth(len(wires), k, ph, A + off, B + off, a, ground, kind="phase", phase_id=pid,
                                bundle_index=j, bundle_offset=[float(o_across), float(o_up)])
                if j:  # parallel chords: the same horizontal length
                    s = sample_interval(rng_extra, 0.0, w["horizontal_length"], wire_density)
                pts = np.column_stack([w["start_xy"] + s[:, None] * w["direction"],
                                       catenary_z(s, a, w["s0"], w["c"])])
                scene.add(pts, classification=cls["wire"], wire_id=w["id"], span_id=k, phase_id=pid)
                wires.append(w)
                ids.append(w["id"])
            spans[-1]["wire_ids"].extend(ids)
            spans[-1]["phases"].append({"phase_id": pid, "phase": ph, "kind": "phase", "wire_ids": ids,
                                        "attachment_start": A, "attachment_end": B, "a": a})
        if earth_wire:
            ph, pid = len(tips), k * n_phases + len(tips)
            A, B = pylons[k]["peak"], pylons[k + 1]["peak"]
            a = float(a_span * rng_extra.uniform(1.0, 1.15))  # flatter than the phases: stays above
            w = _wire_truth(len(wires), k, ph, A, B, a, ground, kind="earth", phase_id=pid,
                            bundle_index=0, bundle_offset=[0.0, 0.0])
            s = sample_interval(rng_extra, 0.0, w["horizontal_length"], wire_density / 2.0)
            pts = np.column_stack([w["start_xy"] + s[:, None] * w["direction"], catenary_z(s, a, w["s0"], w["c"])])
            scene.add(pts, classification=cls["wire"], wire_id=w["id"], span_id=k, phase_id=pid)
            wires.append(w)
            spans[-1]["wire_ids"].append(w["id"])
            spans[-1]["phases"].append({"phase_id": pid, "phase": ph, "kind": "earth", "wire_ids": [w["id"]],
                                        "attachment_start": A, "attachment_end": B, "a": a})

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
            w = phase_axes[(i * 4 + 1) % len(phase_axes)]  # different spans and phases (bundle centres)
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

    # ---- tower cranes beside the line
    cranes = []
    if n_cranes:
        keep_out_xy = cKDTree(np.vstack([curve[:, :2], *[q[:, :2] for q in keep_out]]))
        skeletons: list[np.ndarray] = []
        for i in range(n_cranes):
            crane = _place_crane(rng_extra, i, pos, azimuth, wires, ground, keep_out_xy, trees, skeletons)
            lines, box = crane.pop("_members"), crane.pop("_box")
            n_before = scene.n
            for a_, b_ in lines:
                scene.add(sample_segment(rng_extra, a_, b_, pylon_density), classification=cls["crane"], crane_id=i)
            box_pts = sample_box_surface(rng_extra, box[0], box[1], density)
            scene.add(rotate_z(box_pts, crane["_rot"]) + crane["_base"], classification=cls["crane"], crane_id=i)
            skeletons.append(crane.pop("_skeleton"))
            crane.pop("_rot"), crane.pop("_base")
            crane["n_points"] = scene.n - n_before
            cranes.append(crane)

    xyz, attrs = scene.arrays()
    xyz = add_noise(rng, xyz, noise)
    # ---- isolated noise: below ground and high above the wires
    n_noise = round(noise_fraction * len(xyz))
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

    counts = class_counts(attrs["classification"], cls)
    if not n_cranes:
        counts.pop("crane")  # the class exists only with cranes
    truth = {
        "classes": cls,
        "catenary": "z(s) = c + a*cosh((s - s0)/a); s = horizontal distance from attachment_start "
                    "towards end_xy; local coordinates (add origin)",
        "pylons": pylons,
        "spans": spans,
        "wires": wires,
        "trees": trees,
        "cranes": cranes,
        "bundle": {"size": bundle, "spacing": bundle_spacing, "offsets": offsets,
                   "offsets_frame": "(across, up) m from the phase attachment point; across horizontal, "
                                    "perpendicular to the span, positive to its right"},
        "n_phases": n_phases,
        "corridor_width": 2 * half_w,
        "counts": counts,
    }
    return finish("powerline", xyz, attrs, truth, params, origin)


def _dense_segment(a: np.ndarray, b: np.ndarray, step: float = 0.5) -> np.ndarray:
    """Points every ``step`` m (at most) along a→b, both ends included (no randomness)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    m = max(2, math.ceil(float(np.linalg.norm(b - a)) / step) + 1)
    return a + np.linspace(0.0, 1.0, m)[:, None] * (b - a)


def _truss(p0: Any, p1: Any, section: Sequence[Any], n_panels: int, first_strut: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """Members of a straight lattice truss from ``p0`` to ``p1`` as segments.

    One chord per ``section`` vertex (3-D offsets from the axis, in order round the section), a
    strut across every face at the panel points ``first_strut ..`` and one diagonal per face and
    panel, alternating in direction (a Warren zig-zag).
    """
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    sec = [np.asarray(v, float) for v in section]
    k = len(sec)
    nodes = [[p0 + t * (p1 - p0) + v for v in sec] for t in np.linspace(0.0, 1.0, n_panels + 1)]
    out = [(nodes[0][i], nodes[-1][i]) for i in range(k)]
    for m in range(first_strut, n_panels + 1):
        out += [(nodes[m][i], nodes[m][(i + 1) % k]) for i in range(k)]
    for m in range(n_panels):
        for i in range(k):
            j = (i + 1) % k
            out.append((nodes[m][i], nodes[m + 1][j]) if (m + i) % 2 == 0 else (nodes[m][j], nodes[m + 1][i]))
    return out


def _crane_members(height: float, jib: float) -> tuple[list[tuple[np.ndarray, np.ndarray]], tuple[np.ndarray, np.ndarray]]:
    """Crane-local members (mast axis = z through the origin, jib along +x) and the counterweight
    box ``(lo, hi)`` hanging under the counter-jib's end."""
    h, w = CRANE_MAST_WIDTH / 2.0, CRANE_JIB_WIDTH / 2.0
    depth = CRANE_JIB_WIDTH * math.sqrt(3.0) / 2.0
    mast = _truss([0.0, 0.0, 0.0], [0.0, 0.0, height], [[h, h, 0.0], [-h, h, 0.0], [-h, -h, 0.0], [h, -h, 0.0]],
                  max(2, round(height / 2.5)), first_strut=1)
    section = [[0.0, -w, 0.0], [0.0, w, 0.0], [0.0, 0.0, depth]]
    jib_members = _truss([0.0, 0.0, height], [jib, 0.0, height], section, max(2, round(jib / 2.0)), first_strut=1)
    counter = _truss([-CRANE_COUNTER_JIB, 0.0, height], [0.0, 0.0, height], section,
                     max(2, round(CRANE_COUNTER_JIB / 2.0)))
    box = (np.array([-CRANE_COUNTER_JIB, -1.0, height - 2.0]), np.array([-CRANE_COUNTER_JIB + 2.5, 1.0, height]))
    return mast + jib_members + counter, box


def _box_edges(lo: np.ndarray, hi: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    corners = [np.array([(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]) for i in (0, 1) for j in (0, 1) for k in (0, 1)]
    return [(corners[a], corners[b]) for a in range(8) for b in range(a + 1, 8)
            if int(np.count_nonzero(corners[a] != corners[b])) == 1]


def _crane_pose(local_skeleton: np.ndarray, foot: np.ndarray, lateral: np.ndarray, along: float, ground,
                keep_out_xy, turn: float, offset: float) -> tuple[float, float, np.ndarray, np.ndarray, float]:
    """``(jib azimuth, rotation, base, world skeleton, plan clearance)`` of a crane whose mast stands
    ``offset`` m from ``foot`` along the unit vector ``lateral``, the jib at azimuth ``along + turn``."""
    az = (along + turn) % 360.0
    rot = 90.0 - az  # counter-clockwise angle from +x (the local jib) to the jib direction
    xy = foot + offset * lateral
    base = np.array([xy[0], xy[1], float(ground(xy[0], xy[1]))])
    skel = rotate_z(local_skeleton, rot) + base
    dmin, _ = keep_out_xy.query(skel[:, :2], k=1)
    return az, rot, base, skel, float(dmin.min())


def _place_crane(rng, cid: int, pos: np.ndarray, azimuth: Sequence[float], wires: list[dict[str, Any]], ground,
                 keep_out_xy, trees: list[dict[str, Any]], skeletons: list[np.ndarray]) -> dict[str, Any]:
    """Draw one tower crane beside the line that keeps clear of wires, pylons, trees and cranes.

    The mast stands beside a random span at 30–70 % of its length, 12–20 m to the side of the
    span's outermost wire; the jib points along or against the span, turned by up to ±20°.  If
    the jib (or counter-jib) comes within :data:`CRANE_CLEARANCE` m in plan of a wire or pylon
    member, the turn is mirrored, then the mast is moved outwards; a crane that then still hits a
    tree crown or another crane is drawn anew.
    """
    from scipy.spatial import cKDTree

    n_spans = len(pos) - 1
    for _attempt in range(200):
        k = int(rng.integers(n_spans))
        t = rng.uniform(0.3, 0.7)
        side = 1.0 if rng.uniform() < 0.5 else -1.0
        gap = rng.uniform(12.0, 20.0)
        height = rng.uniform(20.0, 30.0)
        jib = rng.uniform(35.0, 50.0)
        turn = rng.uniform(-20.0, 20.0)
        backwards = rng.uniform() < 0.5
        p0, p1 = pos[k], pos[k + 1]
        span_len = float(np.linalg.norm(p1 - p0))
        u = (p1 - p0) / span_len
        right = np.array([u[1], -u[0]])
        # outermost wire of this span on this side: lateral offsets of the attachment points
        outer = max(0.0, max(side * float((np.asarray(w[key])[:2] - q) @ right)
                             for w in wires if w["span_id"] == k
                             for key, q in (("attachment_start", p0), ("attachment_end", p1))))
        members, box = _crane_members(height, jib)
        local_skeleton = np.vstack([_dense_segment(a, b) for a, b in members + _box_edges(*box)])
        offset = outer + gap
        foot, lateral = p0 + t * span_len * u, side * right
        along = azimuth[k] + (180.0 if backwards else 0.0)
        pose = (local_skeleton, foot, lateral, along, ground, keep_out_xy)
        az, rot, base, skel, dmin = _crane_pose(*pose, turn, offset)
        if dmin < CRANE_CLEARANCE:
            alt = _crane_pose(*pose, -turn, offset)
            if alt[4] > dmin:
                turn = -turn
                az, rot, base, skel, dmin = alt
        for _ in range(6):
            if dmin >= CRANE_CLEARANCE:
                break
            offset += CRANE_CLEARANCE - dmin + 0.5
            az, rot, base, skel, dmin = _crane_pose(*pose, turn, offset)
        if dmin < CRANE_CLEARANCE:
            continue
        # tree crowns: no crane member over or through a crown (1.5 m margin)
        hit = False
        for tr in trees:
            txy, top = np.asarray(tr["position"][:2]), tr["position"][2] + tr["height"]
            near = np.linalg.norm(skel[:, :2] - txy, axis=1) < tr["crown_radius"] + 1.5
            if np.any(skel[near, 2] < top + 2.0):
                hit = True
                break
        if hit or any(float(cKDTree(o).query(skel, k=1)[0].min()) < 4.0 for o in skeletons):
            continue
        lines = [(rotate_z(a[None], rot)[0] + base, rotate_z(b[None], rot)[0] + base) for a, b in members]
        depth = CRANE_JIB_WIDTH * math.sqrt(3.0) / 2.0
        d3 = np.array([math.sin(math.radians(az)), math.cos(math.radians(az)), 0.0])
        axis_z = base[2] + height + depth / 3.0  # centroid of the jib's triangular section
        angle = (az - azimuth[k] + 90.0) % 180.0 - 90.0  # jib axis vs span direction, as lines
        cw_lo, cw_hi = box
        return {
            "id": cid, "span_id": k, "side": "right" if side > 0 else "left",
            "base": base, "mast_height": height, "mast_width": CRANE_MAST_WIDTH,
            "mast_offset": offset, "outer_wire_gap": offset - outer,
            "jib_azimuth": az, "jib_angle_to_line": angle, "jib_length": jib,
            "jib_width": CRANE_JIB_WIDTH, "jib_depth": depth,
            "jib_start": np.array([base[0], base[1], axis_z]),
            "jib_end": np.array([base[0], base[1], axis_z]) + jib * d3,
            "counter_jib_length": CRANE_COUNTER_JIB,
            "counterweight": {"centre": rotate_z(((cw_lo + cw_hi) / 2.0)[None], rot)[0] + base,
                              "size": cw_hi - cw_lo},
            "top": base[2] + height + depth,
            "wire_clearance": dmin,
            "_members": lines, "_box": box, "_rot": rot, "_base": base, "_skeleton": skel,
        }
    raise LidarfxError(f"could not place crane {cid} beside the line clear of the wires, pylons, trees and the "
                       f"other cranes; lower n_cranes or add spans")


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
