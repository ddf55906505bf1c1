"""Lattice steel tower (after the LIS slides): legs, bracings, cross arms and bolts.

:func:`lattice_members` builds the member skeleton (3-D segments) and is also
used for the pylons of :func:`lidarfx.synth.powerline`; :func:`tower` samples
TLS-like points on the members' angle profiles and adds bolt heads as small
dense clusters.

Frame: tower axis = z, base centre at the local origin, cross arms along ±x.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ._common import (
    Scene,
    _count,
    add_noise,
    capture_params,
    check_count,
    check_flag,
    check_length,
    check_nonneg,
    check_origin,
    check_positive,
    finish,
    make_rng,
    perpendicular_frame,
    sample_cylinder_surface,
    sample_rect,
    unit,
)
from ..errors import LidarfxError

__all__ = ["PARTS", "lattice_members", "tower"]

PARTS: dict[str, int] = {"leg": 0, "brace": 1, "arm": 2, "bolt": 3, "insulator": 4, "corona_ring": 5}
"""Values of the ``part`` attribute (``insulator`` and ``corona_ring`` only with ``insulators=True``)."""

_LATTICE_PARTS = ("leg", "brace", "arm", "bolt")
"""The parts of a tower without insulators (its truth lists only these)."""

DISC_RADIUS = 0.1275
"""Radius (m) of an insulator disc (a 255 mm cap-and-pin disc)."""
DISC_PITCH = 0.146
"""Spacing (m) of the discs along an insulator string."""
CORE_RADIUS = 0.03
"""Radius (m) of the caps and pins between the discs."""
DISC_DROP = 0.03
"""Height (m) of a disc's conical top from the core to the rim."""
HANGER = 0.25
"""Gap (m) between the arm tip and the top of the string (shackle and clevis, too thin to be sampled)."""
RING_TUBE = 0.025
"""Tube radius (m) of a corona ring."""
RING_DROP = 0.12
"""Height (m) of the string's lower end above the corona ring's centre (the yoke between them is not sampled)."""
MAX_INSULATOR_LENGTH = 20.0
"""Longest insulator string (m)."""
MAX_RING_RADIUS = 2.0
"""Largest corona-ring radius (m)."""

DEFAULT_ARMS = (
    {"z_frac": 0.70, "left": 5.0, "right": 5.0, "depth": 1.6},
    {"z_frac": 0.88, "left": 3.5, "right": 3.5, "depth": 1.2},
)
"""Default cross arms: height as a fraction of the body height, length on each side (−x / +x), arm depth (m)."""


def lattice_members(
    height: float = 30.0,
    base_width: float = 6.0,
    top_width: float = 1.6,
    n_panels: int = 6,
    arms: Sequence[dict[str, float]] = DEFAULT_ARMS,
    peak: float = 2.5,
    leg_width: float = 0.12,
    brace_width: float = 0.06,
    arm_width: float = 0.08,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Members of a square lattice tower as 3-D segments.

    Returns ``(members, tips)``: ``members`` is a list of
    ``{"id", "part", "start", "end", "width"}`` (``part`` a key of
    :data:`PARTS`, ``width`` the angle-profile flange width); ``tips`` lists
    the cross-arm tips ``{"arm", "side", "xyz"}`` (side −1 = −x, +1 = +x), the
    natural attachment points for insulators.

    Body: 4 legs from the base corners (±base_width/2) to the top corners
    (±top_width/2) at ``height``, ``n_panels`` panels with a horizontal strut
    and an X bracing on each face, a pyramid peak of ``peak`` m.  Each arm: two
    lower chords from the two face corners at the arm height and two upper
    chords from the corners ``depth`` higher, all meeting at the tip.
    """
    height = check_length("height", height)
    if not isinstance(n_panels, (int, np.integer)) or n_panels < 1:
        raise LidarfxError(f"n_panels must be a positive integer, got {n_panels!r}")
    n_panels = check_count("n_panels", n_panels, 1, 1000)
    b, t = check_length("base_width", base_width) / 2.0, check_length("top_width", top_width) / 2.0

    def half(z: float) -> float:
        return b + (t - b) * min(z, height) / height

    def corner(sx: int, sy: int, z: float) -> np.ndarray:
        w = half(z)
        return np.array([sx * w, sy * w, z])

    members: list[dict[str, Any]] = []

    def add(part: str, a: np.ndarray, c: np.ndarray, width: float) -> None:
        members.append({"id": len(members), "part": part, "start": np.asarray(a, float),
                        "end": np.asarray(c, float), "width": float(width)})

    corners = [(1, 1), (-1, 1), (-1, -1), (1, -1)]  # counter-clockwise
    for sx, sy in corners:
        add("leg", corner(sx, sy, 0.0), corner(sx, sy, height), leg_width)
    levels = np.linspace(0.0, height, n_panels + 1)
    for k in range(n_panels):
        z0, z1 = levels[k], levels[k + 1]
        for i in range(4):
            (ax, ay), (bx, by) = corners[i], corners[(i + 1) % 4]
            add("brace", corner(ax, ay, z1), corner(bx, by, z1), brace_width)  # horizontal strut
            add("brace", corner(ax, ay, z0), corner(bx, by, z1), brace_width)  # X bracing
            add("brace", corner(bx, by, z0), corner(ax, ay, z1), brace_width)
    if peak > 0:
        apex = np.array([0.0, 0.0, height + peak])
        for sx, sy in corners:
            add("leg", corner(sx, sy, height), apex, leg_width)

    tips: list[dict[str, Any]] = []
    for ia, arm in enumerate(arms):
        if not isinstance(arm, dict):
            raise LidarfxError(f"arm {ia} must be a dict with z_frac or z, left, right, depth; got {arm!r}")
        z = float(arm.get("z_frac", 0.8)) * height if "z" not in arm else float(arm["z"])
        depth = float(arm.get("depth", 1.5))
        if not (0.0 < z and z + depth <= height):
            raise LidarfxError(f"arm {ia} at z={z:g} m with depth {depth:g} m is outside the body (0..{height:g} m)")
        for side, key in ((-1, "left"), (1, "right")):
            length = float(arm.get(key, 0.0))
            if length <= 0:
                continue
            tip = np.array([side * (half(z) + length), 0.0, z])
            for sy in (-1, 1):
                add("arm", corner(side, sy, z), tip, arm_width)
                add("arm", corner(side, sy, z + depth), tip, arm_width)
            tips.append({"arm": ia, "side": side, "xyz": tip})
    return members, tips


def _angle_profile(rng, start: np.ndarray, end: np.ndarray, width: float, density: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points on an L (angle) profile along start→end: two flanges of ``width``.

    Returns ``(xyz, e1, e2)``; flange 1 spans (axis, e1), flange 2 (axis, e2),
    both starting at the member axis (the heel of the L).
    """
    d = end - start
    length = float(np.linalg.norm(d))
    e1, e2 = perpendicular_frame(d)
    pts = []
    for e in (e1, e2):
        tu = sample_rect(rng, (0.0, length), (0.0, width), density)
        pts.append(start + tu[:, :1] * (d / length) + tu[:, 1:] * e)
    return np.vstack(pts), e1, e2


def tower(
    *,
    height: float = 30.0,
    base_width: float = 6.0,
    top_width: float = 1.6,
    n_panels: int = 6,
    arms: Sequence[dict[str, float]] = DEFAULT_ARMS,
    density: float = 1000.0,
    noise: float = 0.002,
    bolts_per_joint: int = 2,
    bolt_points: int = 40,
    bolt_radius: float = 0.012,
    bolt_height: float = 0.012,
    insulators: bool = False,
    insulator_length: float = 1.3,
    ring_radius: float = 0.2,
    seed: int = 0,
    origin: Any = None,
):
    """TLS-like lattice steel tower: angle-profile members plus bolt heads (and insulators).

    Parameters
    ----------
    height, base_width, top_width, n_panels, arms:
        Geometry, see :func:`lattice_members` (arms: list of dicts with
        ``z_frac`` or ``z``, ``left``, ``right``, ``depth``).
    density:
        Points per m² on the member flanges (legs 0.12 m, braces 0.06 m, arms
        0.08 m wide).
    noise:
        Gaussian σ (m) on every coordinate.
    bolts_per_joint, bolt_points, bolt_radius, bolt_height:
        At both ends of every brace, ``bolts_per_joint`` bolt heads (small
        cylinders with cap standing on the brace's flange) of ``bolt_points``
        points each: small dense clusters protruding from the local plane.
    insulators, insulator_length, ring_radius:
        With ``insulators``, a vertical string of discs hangs from every arm tip
        (top :data:`HANGER` below the tip, ``insulator_length`` long: discs of
        radius :data:`DISC_RADIUS` every :data:`DISC_PITCH` on a core of radius
        :data:`CORE_RADIUS`) with a horizontal corona ring (torus of major radius
        ``ring_radius``, tube :data:`RING_TUBE`) around its lower end, sampled
        at ``density`` per m².  Without them the scene is exactly the one of
        earlier versions (same points, attributes and truth for a seed).
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).

    Returns
    -------
    PointCloud
        Attributes ``member_id`` (−1 for bolts), ``part`` (:data:`PARTS`),
        ``bolt_id`` (−1 for members); with insulators also ``insulator_id``
        (the string of an insulator or corona-ring point, −1 elsewhere).
        ``meta["truth"]``: ``members`` (id, part, start, end, width), ``bolts``
        (id, centre, axis, member), ``arm_tips``, ``scanners``; with insulators
        ``insulators`` (id, tip, top, bottom, centre, axis, length, radius,
        discs) and ``corona_rings`` (id, insulator, centre, normal, radius, tube).
    """
    params = capture_params(locals())
    density = check_positive("density", density)
    noise = check_nonneg("noise", noise)
    bolts_per_joint = check_count("bolts_per_joint", bolts_per_joint, 0, 100)
    bolt_points = check_count("bolt_points", bolt_points, 1)
    bolt_radius = check_length("bolt_radius", bolt_radius)
    bolt_height = check_length("bolt_height", bolt_height)
    insulators = check_flag("insulators", insulators)
    insulator_length = check_positive("insulator_length", insulator_length, MAX_INSULATOR_LENGTH)
    ring_radius = check_positive("ring_radius", ring_radius, MAX_RING_RADIUS)
    if not insulators:  # the truth of a tower without insulators is the one of earlier versions
        for key in ("insulators", "insulator_length", "ring_radius"):
            params.pop(key)
    if insulators and ring_radius <= DISC_RADIUS + RING_TUBE:
        raise LidarfxError(f"ring_radius must be larger than the disc radius plus the ring tube "
                           f"({DISC_RADIUS + RING_TUBE:g} m), got {ring_radius!r}")
    origin = check_origin(origin)
    rng = make_rng(seed)
    members, tips = lattice_members(height, base_width, top_width, n_panels, arms)

    columns = {"member_id": (np.int32, -1), "part": (np.int32, -1), "bolt_id": (np.int32, -1)}
    if insulators:
        columns["insulator_id"] = (np.int32, -1)
    scene = Scene(columns)
    bolts: list[dict[str, Any]] = []
    for m in members:
        pts, e1, e2 = _angle_profile(rng, m["start"], m["end"], m["width"], density)
        scene.add(pts, member_id=m["id"], part=PARTS[m["part"]])
        if m["part"] != "brace" or bolts_per_joint <= 0:
            continue
        d = m["end"] - m["start"]
        length = float(np.linalg.norm(d))
        axis = d / length
        for end_t in (0.0, length):
            for j in range(int(bolts_per_joint)):
                # along the member, inwards from the joint, centred on flange 1
                t = 0.04 + 0.05 * j
                t = end_t + t if end_t == 0.0 else end_t - t
                centre = m["start"] + t * axis + 0.5 * m["width"] * e1
                # the bolt head stands on the flange, on the side away from flange 2
                head_axis = -unit(e2)
                p = _bolt(rng, centre, head_axis, bolt_radius, bolt_height, int(bolt_points))
                scene.add(p, part=PARTS["bolt"], bolt_id=len(bolts))
                bolts.append({"id": len(bolts), "centre": centre, "axis": head_axis, "member": m["id"],
                              "radius": bolt_radius, "height": bolt_height})

    strings: list[dict[str, Any]] = []
    rings: list[dict[str, Any]] = []
    if insulators:  # after every draw of the lattice: the scene without insulators stays the same
        for tip in tips:
            string, ring, pts_string, pts_ring = _insulator(rng, np.asarray(tip["xyz"], float), insulator_length,
                                                            ring_radius, density)
            string["id"] = ring["id"] = ring["insulator"] = len(strings)
            scene.add(pts_string, part=PARTS["insulator"], insulator_id=string["id"])
            scene.add(pts_ring, part=PARTS["corona_ring"], insulator_id=string["id"])
            strings.append(string)
            rings.append(ring)

    xyz, attrs = scene.arrays()
    xyz = add_noise(rng, xyz, noise)
    top = max(max(m["start"][2], m["end"][2]) for m in members)
    parts = PARTS if insulators else {k: PARTS[k] for k in _LATTICE_PARTS}
    truth = {
        "parts": parts,
        "members": members,
        "arm_tips": tips,
        "bolts": bolts,
        "height": height,
        "top": top,
        "scanners": [[-15.0, -15.0, 1.6], [15.0, -12.0, 1.6]],
        "counts": {name: int(np.count_nonzero(attrs["part"] == code)) for name, code in parts.items()},
    }
    if insulators:
        truth["insulators"] = strings
        truth["corona_rings"] = rings
    return finish("tower", xyz, attrs, truth, params, origin)


def _insulator(rng, tip: np.ndarray, length: float, ring_radius: float, density: float):
    """A vertical string of discs hanging from ``tip`` and its corona ring: truth records and points.

    Discs (every :data:`DISC_PITCH`, the first half a pitch below the top): a
    conical top from the core to the rim, :data:`DISC_DROP` high, and a flat
    underside at the rim's level; the core (caps and pins) is a cylinder of
    :data:`CORE_RADIUS` over the whole length.  The ring is a horizontal torus
    :data:`RING_DROP` below the string's lower end.
    """
    down = np.array([0.0, 0.0, -1.0])
    top = tip + HANGER * down
    bottom = top + length * down
    n_discs = max(1, int(math.floor(length / DISC_PITCH)))
    pts = [sample_cylinder_surface(rng, bottom, -down, CORE_RADIUS, length, density)]
    for k in range(n_discs):
        rim = top + (0.5 + k) * (length / n_discs) * down
        pts.append(_disc(rng, rim, CORE_RADIUS, DISC_RADIUS, DISC_DROP, density))  # conical top
        pts.append(_disc(rng, rim, CORE_RADIUS, DISC_RADIUS, 0.0, density))  # flat underside
    centre = bottom + RING_DROP * down
    ring_pts = _torus(rng, centre, ring_radius, RING_TUBE, density)
    string = {"tip": tip, "top": top, "bottom": bottom, "centre": 0.5 * (top + bottom), "axis": down,
              "length": length, "radius": DISC_RADIUS, "discs": n_discs}
    ring = {"centre": centre, "normal": np.array([0.0, 0.0, 1.0]), "radius": ring_radius, "tube": RING_TUBE}
    return string, ring, np.vstack(pts), ring_pts


def _disc(rng, rim_centre: np.ndarray, r_in: float, r_out: float, drop: float, density: float) -> np.ndarray:
    """A horizontal annulus ``r_in``..``r_out`` around ``rim_centre`` (area-uniform), raised
    by ``drop`` at ``r_in`` and falling linearly to the rim: a cone (``drop`` > 0) or flat."""
    slant = math.hypot(r_out - r_in, drop) / (r_out - r_in)
    n = _count(math.pi * (r_out**2 - r_in**2) * slant, density)
    r = np.sqrt(rng.uniform(r_in**2, r_out**2, n))
    phi = rng.uniform(0.0, 2 * math.pi, n)
    z = drop * (r_out - r) / (r_out - r_in)
    return rim_centre + np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def _torus(rng, centre: np.ndarray, major: float, minor: float, density: float) -> np.ndarray:
    """Area-uniform points on a horizontal torus (rejection on the tube angle)."""
    n = _count(4 * math.pi**2 * major * minor, density)
    theta = np.empty(0)
    while len(theta) < n:
        t = rng.uniform(0.0, 2 * math.pi, 2 * (n - len(theta)) + 8)
        keep = rng.uniform(size=len(t)) * (major + minor) < major + minor * np.cos(t)
        theta = np.concatenate([theta, t[keep]])
    theta = theta[:n]
    phi = rng.uniform(0.0, 2 * math.pi, n)
    rho = major + minor * np.cos(theta)
    return centre + np.column_stack([rho * np.cos(phi), rho * np.sin(phi), minor * np.sin(theta)])


def _bolt(rng, centre: np.ndarray, axis: np.ndarray, radius: float, height: float, n: int) -> np.ndarray:
    """``n`` points on a bolt head: lateral surface and top cap of a small cylinder."""
    lateral, cap = 2 * np.pi * radius * height, np.pi * radius**2
    n_lat = int(round(n * lateral / (lateral + cap)))
    e1, e2 = perpendicular_frame(axis)
    phi = rng.uniform(0, 2 * np.pi, n)
    t = np.concatenate([rng.uniform(0, height, n_lat), np.full(n - n_lat, height)])
    r = np.concatenate([np.full(n_lat, radius), radius * np.sqrt(rng.uniform(size=n - n_lat))])
    ring = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    return centre + t[:, None] * axis + r[:, None] * ring
