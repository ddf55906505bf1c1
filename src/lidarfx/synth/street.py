"""Mobile-mapping (MLS) street: road and sidewalks, facades on both sides, poles, overhead
wires, street trees and parked cars, as a vehicle-borne laser scanner sees them.

Local frame: the street runs along x (0 ≤ x ≤ ``length``), the vehicle drives along the
line y = 0 (the street's centre) with its scanners ``scanner_height`` m above the road,
y points to the left of the driving direction, z up.  The road rises by ``grade`` per
metre along x; its cross-section has a crown (``camber``), a curb of ``curb_height`` at
|y| = ``road_width`` / 2 and sidewalks that rise gently to the facades.

MLS-like sampling: every surface is sampled at ``density`` points per m² and kept with
probability ``min(1, ref_range / r) · min(1, max(0, cos θ) / cos(tilt))``, where r is the
range from the driving line (the scanner passes every x, so the range is measured in the
cross-section) and θ the incidence angle of the better of two profile scanners tilted
±``tilt`` degrees from the cross-section plane (common MLS set-ups; surfaces facing along
the street, such as the side walls of an alley, are seen at all); a surface facing the
driving line squarely keeps the full density within ``ref_range``.  Only surface sides facing a scanner are
kept (the back of a pole is not seen).  Density therefore falls like 1/r away from the
driving line, as for a profile scanner (the spacing along the track is fixed by the
vehicle speed, the spacing across grows with the range).  Wires (points per metre,
``wire_density``) and crowns (volumetric) are thinned by range only.  Occlusion of one
object by another is not simulated.  The cloud has no return numbers (a profile scanner's
single returns), no intensity and no GPS time.

Wire frame: each wire is a catenary in the convention of :mod:`lidarfx.synth.powerline`,
``z(s) = c + a · cosh((s − s0) / a)``, s the horizontal distance from ``attachment_start``
towards ``attachment_end``; its points lie on the surface of the wire (radius
``wire_radius``) around that curve, before the noise.
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
    no_points,
    sample_ellipsoid,
    sample_rect,
)

__all__ = ["STREET_CLASSES", "street"]

STREET_CLASSES: dict[str, int] = {
    "ground": 2,
    "vegetation": 5,
    "building": 6,
    "noise": 7,
    "wire": 14,
    "pole": 64,
    "car": 65,
}
"""ASPRS codes where one exists (2 ground, 5 high vegetation, 6 building, 7 noise, 14 wire –
conductor); poles (lamp posts, utility poles, sign posts with their arms, lamps, cross arms and
plates) and cars use the LAS 1.4 user-definable range 64+.  ``car`` exists only with cars."""

LAMP_ARM = 1.5
"""Length (m) of a lamp post's arm, over the road."""
UTILITY_ARM = 1.8
"""Length (m) of a utility pole's cross arm (across the street, centred on the pole)."""


def _cyl_dirs(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to ``axis`` and to each other (the first horizontal when possible)."""
    a = axis / np.linalg.norm(axis)
    e1 = np.cross(a, [0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-9:
        e1 = np.array([1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(a, e1)


def street(
    *,
    length: float = 60.0,
    density: float = 100.0,
    ref_range: float = 5.0,
    scanner_height: float = 2.3,
    tilt: float = 30.0,
    grade: float = 0.02,
    road_width: float = 8.0,
    camber: float = 0.02,
    curb_height: float = 0.12,
    facade_offset: Sequence[float] = (9.0, 11.0),
    building_width: Sequence[float] = (8.0, 20.0),
    building_height: Sequence[float] = (8.0, 16.0),
    gap_probability: float = 0.25,
    lamp_spacing: float = 20.0,
    span_length: float = 30.0,
    n_wires: int = 3,
    cross_wires: int = 1,
    wire_radius: float = 0.01,
    wire_density: float = 40.0,
    catenary_a: Sequence[float] = (150.0, 400.0),
    n_trees: int = 6,
    n_signs: int = 2,
    n_cars: int = 4,
    noise: float = 0.01,
    noise_fraction: float = 0.001,
    classes: dict[str, int] | None = None,
    seed: int = 0,
    origin: Any = None,
):
    """A street as a mobile-mapping system sees it, with ground-truth classes.

    Parameters
    ----------
    length:
        Street length (m) along x.
    density, ref_range, scanner_height, tilt:
        Points per m² on a surface at range ``ref_range`` (m) or closer, facing the driving
        line; beyond, the density falls like ``ref_range / r`` (times the cosine of the incidence
        angle, relative to that of the tilted scanners).  Scanners ``scanner_height`` m above the road on the line y = 0, two profile
        scanners tilted ±``tilt`` degrees from the cross-section plane.
    grade, road_width, camber, curb_height:
        Rise of the street per metre along x; carriageway width (m), its crown (fall per metre
        to either side), the curb (m) at its edges.  Sidewalks rise 1.5 % towards the facades.
    facade_offset:
        Range (min, max) of the distance (m) of each side's facade line from the driving line,
        drawn per side; each building stands back from it by up to 0.5 m more.
    building_width, building_height:
        Ranges (m) of the buildings' widths along the street and of their heights.
    gap_probability:
        Chance of an alley (3–5 m, ground continues, the side walls are seen) after a building.
    lamp_spacing:
        Lamp posts (7–9 m, an arm over the road with a lamp) on the left sidewalk every that
        many metres (±10 %).
    span_length, n_wires, catenary_a, wire_radius, wire_density:
        Utility poles (9.5–10.5 m, a cross arm) on the right sidewalk every ``span_length`` m
        (±15 %), ``n_wires`` (0 .. 3) overhead wires along the street between consecutive poles
        (the cross arm's two ends and the pole top), each a catenary with ``a`` drawn from
        ``catenary_a`` (m), a conductor of radius ``wire_radius`` (m) sampled at
        ``wire_density`` points per metre at ``ref_range`` (fewer farther away).
    cross_wires:
        Span wires (0 .. 20) across the street, from facade to facade 7–8 m above the road.
    n_trees, n_signs, n_cars:
        Street trees on the sidewalks (kept 1 m from every wire and 2.5 m from every pole),
        sign posts (2.6–3.2 m, a 0.6 m plate) on the right sidewalk and cars parked along
        the curbs.
    noise:
        Gaussian σ (m) on every coordinate.
    noise_fraction:
        Isolated outliers (class noise, ≥ 0.3 m from any point) as a share of the points.
    classes:
        Override class codes (name -> code) of :data:`STREET_CLASSES`.
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).

    Returns
    -------
    PointCloud
        Attributes ``classification`` and ``object_id`` (0 ground, then one id per building,
        pole, wire, tree and car; −1 noise).  ``meta["truth"]``: ``classes``, ``trajectory``,
        ``ground`` (the road profile), ``buildings``, ``poles`` (kind, base, radius, height,
        arm), ``wires`` (catenary ``a``, ``s0``, ``c``, ``start_xy``, ``direction``,
        ``horizontal_length``, attachment points, ``radius``, ``kind`` along / across),
        ``trees``, ``cars``, ``counts``.
    """
    params = capture_params(locals())
    origin = check_origin(origin)
    length = check_length("length", length)
    density = check_positive("density", density)
    ref_range = check_length("ref_range", ref_range)
    scanner_height = check_length("scanner_height", scanner_height)
    tilt = check_nonneg("tilt", tilt)
    if tilt >= 80.0:
        raise LidarfxError(f"tilt must be below 80 degrees, got {tilt!r}")
    grade = check_nonneg("grade", grade)
    if grade > 0.3:
        raise LidarfxError(f"grade is a rise per metre of at most 0.3, got {grade!r}")
    road_half = check_length("road_width", road_width) / 2.0
    camber = check_nonneg("camber", camber)
    curb_height = check_nonneg("curb_height", curb_height)
    f_lo, f_hi = _range("facade_offset", facade_offset)
    if f_lo < road_half + 2.0:
        raise LidarfxError(f"facade_offset must leave a sidewalk of at least 2 m beside the road "
                           f"(>= {road_half + 2.0:g} m), got {f_lo:g}")
    w_lo, w_hi = _range("building_width", building_width)
    h_lo, h_hi = _range("building_height", building_height)
    if h_lo < 4.0:
        raise LidarfxError(f"building_height must be at least 4 m, got {h_lo:g}")
    gap_probability = check_fraction("gap_probability", gap_probability)
    lamp_spacing = check_length("lamp_spacing", lamp_spacing)
    span_length = check_length("span_length", span_length)
    n_wires = check_count("n_wires", n_wires, 0, 3)
    cross_wires = check_count("cross_wires", cross_wires, 0, 20)
    wire_radius = check_positive("wire_radius", wire_radius, 0.2)
    wire_density = check_positive("wire_density", wire_density)
    a_lo, a_hi = _range("catenary_a", catenary_a)
    n_trees = check_count("n_trees", n_trees, 0, 1000)
    n_signs = check_count("n_signs", n_signs, 0, 1000)
    n_cars = check_count("n_cars", n_cars, 0, 1000)
    noise = check_nonneg("noise", noise)
    noise_fraction = check_fraction("noise_fraction", noise_fraction)
    cls = merge_classes(STREET_CLASSES, classes)
    rng = make_rng(seed)
    t = math.radians(tilt)
    beams_x = (math.tan(t), -math.tan(t)) if tilt > 0 else (0.0,)

    def ground_z(x: Any, y: Any) -> np.ndarray:
        x, ay = np.asarray(x, float), np.abs(np.asarray(y, float))
        road = -camber * np.minimum(ay, road_half)
        walk = np.where(ay >= road_half, curb_height + 0.015 * (ay - road_half), 0.0)
        return grade * x + road + walk

    def keep(xyz: np.ndarray, normals: np.ndarray | None) -> np.ndarray:
        """MLS thinning mask: range from the driving line, incidence of the better tilted scanner."""
        if not len(xyz):
            return np.zeros(0, dtype=bool)
        dy = xyz[:, 1]
        dz = xyz[:, 2] - (grade * xyz[:, 0] + scanner_height)
        rho = np.maximum(np.hypot(dy, dz), 1e-6)  # range in the cross-section
        p = np.minimum(1.0, ref_range / rho)
        if normals is not None:
            best = np.zeros(len(xyz))
            for bx in beams_x:  # beam from the scanner to the point, unit
                b = np.column_stack([np.full(len(xyz), bx) * rho, dy, dz])
                b /= np.linalg.norm(b, axis=1, keepdims=True)
                best = np.maximum(best, -np.einsum("ij,ij->i", b, normals))
            p = p * np.minimum(1.0, best / math.cos(t))  # relative to a surface facing the driving line
        return rng.uniform(size=len(xyz)) < p

    scene = Scene({"classification": (np.uint8, cls["noise"]), "object_id": (np.int32, -1)})
    n_objects = [0]

    def new_id() -> int:
        n_objects[0] += 1
        return n_objects[0] - 1

    def add(xyz: np.ndarray, normals: np.ndarray | None, name: str, oid: int) -> int:
        m = keep(xyz, normals)
        return scene.add(xyz[m], classification=cls[name], object_id=oid)

    # ---- buildings along both sides (side +1 = left, y > 0; −1 = right)
    ground_id = new_id()
    buildings: list[dict[str, Any]] = []
    facade_line = {+1: rng.uniform(f_lo, f_hi), -1: rng.uniform(f_lo, f_hi)}
    for side in (+1, -1):
        x = rng.uniform(-6.0, 0.0)  # the first building starts before the street's start
        while x < length:
            w = rng.uniform(w_lo, w_hi)
            h = rng.uniform(h_lo, h_hi)
            setback = rng.uniform(0.0, 0.5)
            x0, x1 = x, x + w
            buildings.append({"object_id": new_id(), "side": side, "x_range": [x0, x1],
                              "facade_y": side * (facade_line[side] + setback), "height": h})
            x = x1
            if rng.uniform() < gap_probability:
                x += rng.uniform(3.0, 5.0)
    for b in buildings:  # clip to the street
        b["x_range"] = [max(b["x_range"][0], 0.0), min(b["x_range"][1], length)]
    buildings = [b for b in buildings if b["x_range"][1] - b["x_range"][0] > 0.5]

    def facade_at(side: int, x: np.ndarray) -> np.ndarray:
        """|y| of the facade of ``side`` at each x (inf in a gap: the ground goes on)."""
        out = np.full(len(x), np.inf)
        for b in buildings:
            if b["side"] == side:
                inside = (x >= b["x_range"][0]) & (x < b["x_range"][1])
                out[inside] = abs(b["facade_y"])
        return out

    # ---- ground: road, curbs, sidewalks (and the alleys 5 m deep)
    y_max = f_hi + 0.5 + 5.0
    uv = sample_rect(rng, (0.0, length), (-y_max, y_max), density)
    left, right = uv[:, 1] > 0, uv[:, 1] < 0
    behind = (left & (uv[:, 1] > facade_at(+1, uv[:, 0]))) | (right & (-uv[:, 1] > facade_at(-1, uv[:, 0])))
    uv = uv[~behind]
    g = np.column_stack([uv, ground_z(uv[:, 0], uv[:, 1])])
    add(g, np.tile([-grade, 0.0, 1.0], (len(g), 1)) / math.hypot(grade, 1.0), "ground", ground_id)
    if curb_height > 0:
        for side in (+1, -1):
            cz = sample_rect(rng, (0.0, length), (0.0, curb_height), density)
            y = side * road_half
            base = ground_z(cz[:, 0], y - side * 1e-9)
            pts = np.column_stack([cz[:, 0], np.full(len(cz), y), base + cz[:, 1]])
            add(pts, np.tile([0.0, -side, 0.0], (len(pts), 1)), "ground", ground_id)

    # ---- facades with recessed windows, and the side walls seen from an alley
    windows_total = 0
    for b in buildings:
        side, (x0, x1), fy, h = b["side"], b["x_range"], b["facade_y"], b["height"]
        uz = sample_rect(rng, (x0, x1), (0.0, h), density)  # (along x, height above the sidewalk)
        wins = []
        n_floors = max(1, int(h // 3.0))
        n_win = int((x1 - x0) // 3.0)
        for f in range(1 if n_floors > 1 else 0, n_floors):  # no windows on the ground floor of a tall block
            for k in range(n_win):
                xc = x0 + (x1 - x0) * (k + 0.5) / n_win
                wins.append((xc - 0.6, xc + 0.6, f * 3.0 + 0.8, f * 3.0 + 2.3))
        zz = uz[:, 1]
        hole = np.zeros(len(uz), dtype=bool)
        for wx0, wx1, wz0, wz1 in wins:
            hole |= (uz[:, 0] > wx0) & (uz[:, 0] < wx1) & (zz > wz0) & (zz < wz1)
        wall = np.column_stack([uz[:, 0], np.full(len(uz), fy), ground_z(uz[:, 0], fy) + zz])
        n_wall = np.tile([0.0, -side, 0.0], (len(wall), 1))
        parts, normals = [wall[~hole]], [n_wall[~hole]]
        # windows: the pane 0.15 m behind the wall (glass returns a fifth), reveals at the sides
        for wx0, wx1, wz0, wz1 in wins:
            pane = sample_rect(rng, (wx0, wx1), (wz0, wz1), 0.2 * density)
            py = fy + side * 0.15
            parts.append(np.column_stack([pane[:, 0], np.full(len(pane), py), ground_z(pane[:, 0], fy) + pane[:, 1]]))
            normals.append(np.tile([0.0, -side, 0.0], (len(pane), 1)))
            for xr, nx in ((wx0, 1.0), (wx1, -1.0)):
                rv = sample_rect(rng, (0.0, 0.15), (wz0, wz1), density)
                parts.append(np.column_stack([np.full(len(rv), xr), fy + side * rv[:, 0],
                                              ground_z(xr, fy) + rv[:, 1]]))
                normals.append(np.tile([nx, 0.0, 0.0], (len(rv), 1)))
            for zr, nz in ((wz0, 1.0), (wz1, -1.0)):
                rv = sample_rect(rng, (wx0, wx1), (0.0, 0.15), density)
                parts.append(np.column_stack([rv[:, 0], fy + side * rv[:, 1], ground_z(rv[:, 0], fy) + zr]))
                normals.append(np.tile([0.0, 0.0, nz], (len(rv), 1)))
        windows_total += len(wins)
        # side walls: the whole side at an alley (not at the street's ends), and where a neighbour
        # stands back or is lower, the part of the side that shows: from this facade back to the
        # neighbour's, and above the neighbour's height
        for xe, nx in ((x0, -1.0), (x1, 1.0)):
            if not 0.0 < xe < length:
                continue
            o = _neighbour(buildings, b, xe)
            strips = []  # (depth from this facade: from, to; height: from, to)
            if o is None:
                strips.append((0.0, 5.0, 0.0, h))
            else:
                back = max(abs(o["facade_y"]) - abs(fy), 0.0)
                if back > 0:
                    strips.append((0.0, back, 0.0, h))
                if h > o["height"]:
                    strips.append((back, back + 5.0, o["height"], h))
            for t0, t1, z0, z1 in strips:
                sw = sample_rect(rng, (t0, t1), (z0, z1), density)
                y = fy + side * sw[:, 0]
                parts.append(np.column_stack([np.full(len(sw), xe), y, ground_z(xe, fy) + sw[:, 1]]))
                normals.append(np.tile([nx, 0.0, 0.0], (len(sw), 1)))
        add(np.vstack(parts), np.vstack(normals), "building", b["object_id"])
        b["windows"] = len(wins)
        b["normal"] = [0.0, -float(side), 0.0]

    # ---- poles: lamp posts (left), utility poles carrying the wires and sign posts (right)
    poles: list[dict[str, Any]] = []
    y_lamp = road_half + 0.5
    x = rng.uniform(0.2, 0.8) * lamp_spacing
    while x < length - 1.0:
        poles.append({"kind": "lamp", "side": 1, "base_xy": [x, y_lamp], "radius": 0.07,
                      "height": rng.uniform(7.0, 9.0)})
        x += lamp_spacing * rng.uniform(0.9, 1.1)
    y_util = -(road_half + 0.7)
    x = rng.uniform(1.0, 4.0)
    util_x = []
    while x < length - 1.0:
        util_x.append(x)
        x += span_length * rng.uniform(0.85, 1.15)
    for x in util_x:
        poles.append({"kind": "utility", "side": -1, "base_xy": [x, y_util], "radius": 0.12,
                      "height": rng.uniform(9.5, 10.5)})
    for _ in range(n_signs):
        for _try in range(50):
            x = rng.uniform(2.0, length - 2.0)
            if all(abs(x - p["base_xy"][0]) > 3.0 for p in poles if p["side"] == -1):
                break
        poles.append({"kind": "sign", "side": -1, "base_xy": [x, -(road_half + 0.4)], "radius": 0.04,
                      "height": rng.uniform(2.6, 3.2)})
    for p in poles:
        p["object_id"] = new_id()
        bx, by = p["base_xy"]
        base = np.array([bx, by, float(ground_z(bx, by))])
        p["base"] = base
        r, h = p["radius"], p["height"]
        pts, nrm = _cylinder(rng, base, np.array([0.0, 0.0, 1.0]), r, h, density)
        parts, normals = [pts], [nrm]
        top = base + [0.0, 0.0, h]
        if p["kind"] == "lamp":  # an arm over the road and the lamp at its end
            arm_start = top - [0.0, 0.0, 0.2]
            arm_end = arm_start + [0.0, -LAMP_ARM, 0.0]
            a_pts, a_n = _cylinder(rng, arm_start, arm_end - arm_start, 0.04, LAMP_ARM, density)
            lo = arm_end + [-0.3, -0.15, -0.2]
            l_pts, l_n = _box(rng, lo, lo + [0.6, 0.3, 0.15], density)
            parts += [a_pts, l_pts]
            normals += [a_n, l_n]
            p["arm"] = {"start": arm_start, "end": arm_end, "radius": 0.04}
        elif p["kind"] == "utility":  # a cross arm across the street, 0.6 m below the top
            zc = h - 0.6
            lo = base + [-0.05, -UTILITY_ARM / 2, zc - 0.1]
            c_pts, c_n = _box(rng, lo, lo + [0.1, UTILITY_ARM, 0.1], density)
            parts.append(c_pts)
            normals.append(c_n)
            p["arm"] = {"z": float(base[2] + zc), "half_length": UTILITY_ARM / 2}
            p["attachments"] = [base + [0.0, -UTILITY_ARM / 2 + 0.05, zc], base + [0.0, UTILITY_ARM / 2 - 0.05, zc],
                                top]
        else:  # a sign plate facing the traffic (−x), on top
            s_pts = sample_rect(rng, (-0.3, 0.3), (-0.6, 0.0), density)
            plate = np.column_stack([np.full(len(s_pts), top[0] - r - 0.01), top[1] + s_pts[:, 0],
                                     top[2] + s_pts[:, 1]])
            parts.append(plate)
            normals.append(np.tile([-1.0, 0.0, 0.0], (len(plate), 1)))
            p["plate"] = {"centre": top + [-r - 0.01, 0.0, -0.3], "size": [0.6, 0.6]}
        add(np.vstack(parts), np.vstack(normals), "pole", p["object_id"])

    # ---- wires: along the street between consecutive utility poles, and across it
    wires: list[dict[str, Any]] = []
    util = [p for p in poles if p["kind"] == "utility"]
    for k in range(len(util) - 1):
        a_span = rng.uniform(a_lo, a_hi)
        for j in range(n_wires):
            A, B = util[k]["attachments"][j], util[k + 1]["attachments"][j]
            a = float(np.clip(a_span * rng.uniform(0.95, 1.05), a_lo, a_hi))
            wires.append(_wire(len(wires), "along", A, B, a, wire_radius, span=k, phase=j))
    fronts = [(b["x_range"], b) for b in buildings]
    for i in range(cross_wires):
        for _try in range(100):
            x = rng.uniform(2.0, length - 2.0)
            lb = [b for (x0, x1), b in fronts if b["side"] == 1 and x0 + 0.5 < x < x1 - 0.5]
            rb = [b for (x0, x1), b in fronts if b["side"] == -1 and x0 + 0.5 < x < x1 - 0.5]
            if lb and rb and all(abs(x - w["attachment_start"][0]) > 2.0 for w in wires if w["kind"] == "across"):
                break
        else:
            raise LidarfxError("no place for a cross wire: too few buildings facing each other")
        zl = rng.uniform(7.0, 8.0)
        hb = min(lb[0]["height"], rb[0]["height"])
        zl = min(zl, hb - 0.5)
        A = np.array([x, lb[0]["facade_y"], float(ground_z(x, lb[0]["facade_y"])) + zl])
        B = np.array([x, rb[0]["facade_y"], float(ground_z(x, rb[0]["facade_y"])) + zl + rng.uniform(-0.2, 0.2)])
        wires.append(_wire(len(wires), "across", A, B, float(rng.uniform(a_lo, a_hi)), wire_radius))
    for w in wires:
        w["object_id"] = new_id()
        s = rng.uniform(0.0, w["horizontal_length"], int(round(w["horizontal_length"] * wire_density)))
        pts = _wire_points(rng, w, s)
        m = keep(pts, None)
        scene.add(pts[m], classification=cls["wire"], object_id=w["object_id"])

    # dense wire curves for the trees' clearance
    from scipy.spatial import cKDTree

    curve = [_wire_points(None, w, np.linspace(0.0, w["horizontal_length"], int(w["horizontal_length"] * 4) + 2))
             for w in wires]
    curve_tree = cKDTree(np.vstack(curve)) if curve else None

    # ---- street trees on the sidewalks, clear of the poles and the wires
    trees: list[dict[str, Any]] = []
    for i in range(n_trees):
        side = 1 if i % 2 == 0 else -1
        placed = False
        for _try in range(100):
            x = rng.uniform(1.5, length - 1.5)
            y = side * (road_half + rng.uniform(1.8, 2.6))
            if any(abs(x - p["base_xy"][0]) < 2.5 for p in poles if p["side"] == side):
                continue
            if any(abs(x - tr["position"][0]) < 6.0 and tr["side"] == side for tr in trees):
                continue
            crown_r = rng.uniform(1.8, 3.0)
            trunk_h = rng.uniform(2.0, 3.0)
            g = float(ground_z(x, y))
            centre = np.array([x, y, g + trunk_h + crown_r * 0.9])
            radii = np.array([crown_r, crown_r, crown_r * 1.1])
            if curve_tree is not None:  # lower the crown until it keeps 1 m from every wire
                d = _ellipsoid_clearance(curve_tree, centre, radii)
                if d < 1.0:
                    centre[2] -= (1.0 - d) + 0.05
                    trunk_h = centre[2] - g - crown_r * 0.9
                    if trunk_h < 1.2 or _ellipsoid_clearance(curve_tree, centre, radii) < 1.0:
                        continue
            placed = True
            break
        if not placed:
            continue
        oid = new_id()
        trunk_r = rng.uniform(0.12, 0.2)
        base = np.array([x, y, g])
        t_pts, t_n = _cylinder(rng, base, np.array([0.0, 0.0, 1.0]), trunk_r, trunk_h + crown_r * 0.5, density)
        add(t_pts, t_n, "vegetation", oid)
        crown = sample_ellipsoid(rng, centre, radii, 0.5 * density, shell=0.6)
        add(crown, None, "vegetation", oid)
        trees.append({"object_id": oid, "side": side, "position": base, "trunk_radius": trunk_r,
                      "trunk_height": trunk_h, "crown_centre": centre, "crown_radii": radii})

    # ---- cars parked along the curbs
    cars: list[dict[str, Any]] = []
    for i in range(n_cars):
        side = 1 if i % 2 else -1
        for _try in range(100):
            x = rng.uniform(2.5, length - 2.5)
            if all(abs(x - c["centre"][0]) > 5.5 for c in cars if c["side"] == side):
                break
        else:
            continue
        y = side * (road_half - 1.1)
        g = float(ground_z(x, y))
        body = (np.array([x - 2.15, y - 0.9, g + 0.25]), np.array([x + 2.15, y + 0.9, g + 1.05]))
        cab = (np.array([x - 1.1, y - 0.75, g + 1.05]), np.array([x + 1.0, y + 0.75, g + 1.5]))
        oid = new_id()
        b_pts, b_n = _box(rng, *body, density)
        c_pts, c_n = _box(rng, *cab, density)
        add(np.vstack([b_pts, c_pts]), np.vstack([b_n, c_n]), "car", oid)
        cars.append({"object_id": oid, "side": side, "centre": [x, y, g], "boxes": [list(body), list(cab)]})

    if scene.n == 0:
        raise no_points("street", params)
    xyz, attrs = scene.arrays()
    xyz = add_noise(rng, xyz, noise)
    lo = np.array([0.0, -y_max, float(xyz[:, 2].min()) + 0.3])
    hi = np.array([length, y_max, float(xyz[:, 2].max()) + 3.0])
    out = isolated_outliers(rng, xyz, lo, hi, int(round(noise_fraction * len(xyz))), 0.3)
    xyz = np.vstack([xyz, out])
    attrs["classification"] = np.concatenate([attrs["classification"], np.full(len(out), cls["noise"], np.uint8)])
    attrs["object_id"] = np.concatenate([attrs["object_id"], np.full(len(out), -1, np.int32)])

    counts = class_counts(attrs["classification"], cls)
    if not n_cars:
        counts.pop("car")  # the class exists only with cars
    truth = {
        "classes": cls,
        "trajectory": {"y": 0.0, "scanner_height": scanner_height, "grade": grade, "tilt": tilt,
                       "ref_range": ref_range,
                       "z": "grade * x + scanner_height (the road's crown is at z = grade * x)"},
        "ground": {"road_half_width": road_half, "camber": camber, "curb_height": curb_height,
                   "sidewalk_slope": 0.015, "object_id": ground_id,
                   "z": "grade*x - camber*min(|y|, road_half_width) + (|y| >= road_half_width) * "
                        "(curb_height + sidewalk_slope*(|y| - road_half_width))"},
        "buildings": buildings,
        "poles": poles,
        "wires": wires,
        "catenary": "z(s) = c + a*cosh((s - s0)/a); s = horizontal distance from attachment_start "
                    "towards end_xy; local coordinates (add origin); points on the wire surface (radius)",
        "trees": trees,
        "cars": cars,
        "counts": counts,
    }
    return finish("street", xyz, attrs, truth, params, origin)


# --------------------------------------------------------------------------- helpers
def _range(name: str, value: Any) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise LidarfxError(f"{name} must be (min, max), got {value!r}") from None
    if not (0 < lo <= hi and math.isfinite(hi) and hi <= 10_000.0):
        raise LidarfxError(f"{name} must be (min, max) with 0 < min <= max <= 10000, got {value!r}")
    return lo, hi


def _neighbour(buildings: list[dict[str, Any]], b: dict[str, Any], xe: float) -> dict[str, Any] | None:
    """The building of the same side that touches ``b`` at its end ``xe`` (None: an alley)."""
    for o in buildings:
        if o is not b and o["side"] == b["side"] and (abs(o["x_range"][0] - xe) < 1e-9
                                                      or abs(o["x_range"][1] - xe) < 1e-9):
            return o
    return None


def _cylinder(rng, base: np.ndarray, axis: np.ndarray, radius: float, length: float, density: float
              ) -> tuple[np.ndarray, np.ndarray]:
    """Points on a cylinder's lateral surface and their outward normals."""
    d = np.asarray(axis, float) / np.linalg.norm(axis)
    e1, e2 = _cyl_dirs(d)
    n = max(0, int(round(2 * math.pi * radius * length * density)))
    phi, t = rng.uniform(0, 2 * math.pi, n), rng.uniform(0, length, n)
    nrm = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    return np.asarray(base, float) + t[:, None] * d + radius * nrm, nrm


def _box(rng, lo: np.ndarray, hi: np.ndarray, density: float) -> tuple[np.ndarray, np.ndarray]:
    """Points on the six faces of an axis-aligned box and their outward normals (the bottom too)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    parts, normals = [], []
    for axis in range(3):
        others = [k for k in range(3) if k != axis]
        for sign, level in ((-1.0, lo[axis]), (1.0, hi[axis])):
            uv = sample_rect(rng, (lo[others[0]], hi[others[0]]), (lo[others[1]], hi[others[1]]), density)
            p = np.empty((len(uv), 3))
            p[:, others[0]], p[:, others[1]], p[:, axis] = uv[:, 0], uv[:, 1], level
            nrm = np.zeros((len(uv), 3))
            nrm[:, axis] = sign
            parts.append(p)
            normals.append(nrm)
    return np.vstack(parts), np.vstack(normals)


def _wire(wid: int, kind: str, A: np.ndarray, B: np.ndarray, a: float, radius: float, **extra: Any
          ) -> dict[str, Any]:
    d = B[:2] - A[:2]
    L = float(np.linalg.norm(d))
    s0, c = catenary_through(float(A[2]), float(B[2]), L, a)
    ss = np.linspace(0.0, L, 200)
    zz = catenary_z(ss, a, s0, c)
    low = int(np.argmin(zz))
    return {"id": wid, "kind": kind, "a": a, "s0": s0, "c": c, "start_xy": A[:2], "end_xy": B[:2],
            "direction": d / L, "horizontal_length": L, "attachment_start": A, "attachment_end": B,
            "radius": radius, "lowest_point": [*(A[:2] + ss[low] * d / L), float(zz[low])],
            "sag": float(0.5 * (A[2] + B[2]) - catenary_z(L / 2.0, a, s0, c)), **extra}


def _wire_points(rng, w: dict[str, Any], s: np.ndarray) -> np.ndarray:
    """Points at horizontal distances ``s`` along wire ``w``: on its surface (radius) around the
    catenary with ``rng``, on the curve itself without."""
    u = np.asarray(w["direction"], float)
    a, s0, c = w["a"], w["s0"], w["c"]
    xy = np.asarray(w["start_xy"], float) + s[:, None] * u
    curve = np.column_stack([xy, catenary_z(s, a, s0, c)])
    if rng is None:
        return curve
    slope = np.sinh((s - s0) / a)  # dz/ds
    tang = np.column_stack([np.tile(u, (len(s), 1)), slope])
    tang /= np.linalg.norm(tang, axis=1, keepdims=True)
    e1 = np.array([u[1], -u[0], 0.0])  # horizontal, across the wire
    e2 = np.cross(tang, e1)
    e2 /= np.linalg.norm(e2, axis=1, keepdims=True)
    phi = rng.uniform(0.0, 2 * math.pi, len(s))
    return curve + w["radius"] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)


def _ellipsoid_clearance(tree, centre: np.ndarray, radii: np.ndarray) -> float:
    """Smallest distance from the surface of an axis-aligned ellipsoid to the points of ``tree``
    (approximate: a dense sample of the surface)."""
    g = np.random.default_rng(0).normal(size=(2000, 3))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    d, _ = tree.query(centre + g * radii, k=1)
    return float(d.min())
