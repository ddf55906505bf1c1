"""Lattice steel tower (LIS slides, seed 000): legs, bracings, cross arms and bolts.

:func:`lattice_members` builds the member skeleton (3-D segments) and is also
used for the pylons of :func:`lidarfx.synth.powerline`; :func:`tower` samples
TLS-like points on the members' angle profiles and adds bolt heads as small
dense clusters.

Frame: tower axis = z, base centre at the local origin, cross arms along ±x.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ._common import (
    Scene,
    add_noise,
    capture_params,
    check_count,
    check_length,
    check_nonneg,
    check_origin,
    check_positive,
    finish,
    make_rng,
    perpendicular_frame,
    sample_rect,
    unit,
)
from ..errors import LidarfxError

__all__ = ["PARTS", "lattice_members", "tower"]

PARTS: dict[str, int] = {"leg": 0, "brace": 1, "arm": 2, "bolt": 3}
"""Values of the ``part`` attribute."""

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
    seed: int = 0,
    origin: Any = None,
):
    """TLS-like lattice steel tower: angle-profile members plus bolt heads.

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
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).

    Returns
    -------
    PointCloud
        Attributes ``member_id`` (−1 for bolts), ``part`` (:data:`PARTS`),
        ``bolt_id`` (−1 for members).  ``meta["truth"]``: ``members`` (id,
        part, start, end, width), ``bolts`` (id, centre, axis, member),
        ``arm_tips``, ``scanners``.
    """
    params = capture_params(locals())
    density = check_positive("density", density)
    noise = check_nonneg("noise", noise)
    bolts_per_joint = check_count("bolts_per_joint", bolts_per_joint, 0, 100)
    bolt_points = check_count("bolt_points", bolt_points, 1)
    bolt_radius = check_length("bolt_radius", bolt_radius)
    bolt_height = check_length("bolt_height", bolt_height)
    origin = check_origin(origin)
    rng = make_rng(seed)
    members, tips = lattice_members(height, base_width, top_width, n_panels, arms)

    scene = Scene({"member_id": (np.int32, -1), "part": (np.int32, -1), "bolt_id": (np.int32, -1)})
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

    xyz, attrs = scene.arrays()
    xyz = add_noise(rng, xyz, noise)
    top = max(max(m["start"][2], m["end"][2]) for m in members)
    truth = {
        "parts": PARTS,
        "members": members,
        "arm_tips": tips,
        "bolts": bolts,
        "height": height,
        "top": top,
        "scanners": [[-15.0, -15.0, 1.6], [15.0, -12.0, 1.6]],
        "counts": {name: int(np.count_nonzero(attrs["part"] == code)) for name, code in PARTS.items()},
    }
    return finish("tower", xyz, attrs, truth, params, origin)


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
