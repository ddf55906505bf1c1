"""TLS house facade with the classes of Lang (docs/synth.md §2): ground, wall, roof, window,
vegetation, clutter, noise.

Local frame: the facade wall is the plane y = 0 for 0 ≤ x ≤ width, the street
(ground, z = 0) lies in front of it (y < 0) and the scanner stands in the
street.  The roof's front slope rises from the eave (with an overhang) to the
ridge behind the wall.  Windows are openings in the wall with reveals, a frame
with a mullion and sparse glass points, recessed by ``window_depth``.  Point
density falls off with the squared range beyond ``ref_range`` like a TLS scan;
occlusion is not simulated.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._common import (
    EX,
    EY,
    EZ,
    Scene,
    add_noise,
    capture_params,
    check_count,
    check_flag,
    check_fraction,
    check_length,
    check_nonneg,
    check_origin,
    check_point,
    check_positive,
    class_counts,
    finish,
    isolated_outliers,
    make_rng,
    merge_classes,
    range_keep,
    sample_box_surface,
    sample_cylinder_surface,
    sample_ellipsoid,
    sample_patch,
)
from ..errors import LidarfxError

__all__ = ["FACADE_CLASSES", "facade"]

FACADE_CLASSES: dict[str, int] = {
    "ground": 2,
    "vegetation": 5,
    "wall": 6,
    "noise": 7,
    "roof": 64,
    "window": 65,
    "clutter": 66,
}
"""ASPRS codes where one exists (2 ground, 5 high vegetation, 6 building, 7 low
point/noise); roof, window and clutter use the LAS 1.4 user-definable range 64+."""


def facade(
    *,
    width: float = 12.0,
    wall_height: float = 7.0,
    roof_pitch: float = 45.0,
    depth: float = 8.0,
    n_floors: int = 2,
    windows_per_floor: int = 4,
    window_size: tuple[float, float] = (1.2, 1.4),
    window_depth: float = 0.15,
    glass_fraction: float = 0.1,
    density: float = 400.0,
    noise: float = 0.005,
    ref_range: float = 10.0,
    range_falloff: bool = True,
    scanner: Any = None,
    noise_fraction: float = 0.005,
    classes: dict[str, int] | None = None,
    seed: int = 0,
    origin: Any = None,
):
    """TLS-like street view of a house facade with ground-truth classes.

    Parameters
    ----------
    width, wall_height, roof_pitch, depth:
        Facade width and eave height (m), roof pitch (degrees) and house depth
        (m; the ridge is at depth / 2 behind the wall).
    n_floors, windows_per_floor, window_size, window_depth:
        Window grid, (width, height) of each window (m) and how far the frame
        and glass sit behind the wall plane (m).
    glass_fraction:
        Share of the surface density returned by the glass (glass is a poor
        reflector); 0 leaves the panes empty.
    density:
        Points per m² on surfaces at the reference range and normal incidence; vegetation gets
        ``density`` points per m³ in the outer part of bushes and crowns.
    noise:
        Gaussian σ (m) on every coordinate.
    ref_range, range_falloff:
        With ``range_falloff`` a point at range r from the scanner is kept with
        probability ``min(1, (ref_range / r)² · |cos θ|)``, θ = incidence angle
        on ground, wall, roof and windows (vegetation and clutter: range only).
    scanner:
        Scanner position (default ``(width/2, −12, 1.6)``).
    noise_fraction:
        Isolated outliers (class noise, ≥ 0.3 m from any surface) as a share of
        the scene points.
    classes:
        Override class codes (name -> code) of :data:`FACADE_CLASSES`.
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).

    Returns
    -------
    PointCloud
        Attributes ``classification`` and ``object_id`` (0 ground, 1 wall,
        2 roof, then one id per window, bush, tree and clutter object; −1
        noise).  ``meta["truth"]``: ``classes`` (name -> code),
        ``scanner``, ``objects`` (id, class, kind, geometry), ``counts``.
    """
    params = capture_params(locals())
    width = check_length("width", width)
    wall_height = check_length("wall_height", wall_height)
    depth = check_length("depth", depth)
    density = check_positive("density", density)
    noise = check_nonneg("noise", noise)
    ref_range = check_length("ref_range", ref_range)
    n_floors = check_count("n_floors", n_floors, 1, 100)
    windows_per_floor = check_count("windows_per_floor", windows_per_floor, 0, 1000)
    window_depth = check_nonneg("window_depth", window_depth)
    glass_fraction = check_fraction("glass_fraction", glass_fraction)
    noise_fraction = check_fraction("noise_fraction", noise_fraction)
    range_falloff = check_flag("range_falloff", range_falloff)
    if not 0.0 < roof_pitch < 80.0:
        raise LidarfxError(f"roof_pitch must be in (0, 80) degrees, got {roof_pitch!r}")
    ww, wh = (float(v) for v in window_size)
    floor_h = wall_height / max(1, int(n_floors))
    if ww <= 0 or wh <= 0 or windows_per_floor * (ww + 0.4) > width or wh + 1.2 > floor_h:
        raise LidarfxError("windows do not fit the facade; reduce window_size or the window counts")
    cls = merge_classes(FACADE_CLASSES, classes)
    origin = check_origin(origin)
    scanner = np.array([width / 2.0, -12.0, 1.6]) if scanner is None else check_point("scanner", scanner)
    rng = make_rng(seed)

    scene = Scene({"classification": (np.uint8, cls["noise"]), "object_id": (np.int32, -1)})
    objects: list[dict[str, Any]] = []

    def add(xyz: np.ndarray, name: str, kind: str, normal: Any = None, **geometry: Any) -> None:
        oid = len(objects)
        if range_falloff and len(xyz):
            xyz = xyz[range_keep(rng, xyz, scanner, ref_range, normal)]
        scene.add(xyz, classification=cls[name], object_id=oid)
        if normal is not None:
            geometry["normal"] = normal
        objects.append({"id": oid, "class": name, "kind": kind, "n_points": len(xyz), **geometry})

    # ---- ground: the street in front, a strip beside and behind the house
    g_lo, g_hi = np.array([-6.0, -16.0]), np.array([width + 6.0, depth + 2.0])
    ground = sample_patch(rng, [0, 0, 0], EX, EY, (g_lo[0], g_hi[0]), (g_lo[1], g_hi[1]), density)
    inside = (ground[:, 0] > 0) & (ground[:, 0] < width) & (ground[:, 1] > 0) & (ground[:, 1] < depth)
    add(ground[~inside], "ground", "plane", normal=EZ, z=0.0, xy_min=g_lo, xy_max=g_hi)

    # ---- windows (rectangles in the wall plane: x0, x1, z0, z1)
    windows = []
    for f in range(int(n_floors)):
        sill = f * floor_h + 0.5 * (floor_h - wh) + 0.2
        for k in range(int(windows_per_floor)):
            xc = width * (k + 0.5) / windows_per_floor
            windows.append((xc - ww / 2, xc + ww / 2, sill, sill + wh))

    # ---- wall with openings
    wall = sample_patch(rng, [0, 0, 0], EX, EZ, (0.0, width), (0.0, wall_height), density)
    hole = np.zeros(len(wall), dtype=bool)
    for x0, x1, z0, z1 in windows:
        hole |= (wall[:, 0] > x0) & (wall[:, 0] < x1) & (wall[:, 2] > z0) & (wall[:, 2] < z1)
    add(wall[~hole], "wall", "plane", normal=-EY, plane_point=[0, 0, 0],
        x_range=[0.0, width], z_range=[0.0, wall_height])

    # ---- roof: front slope from the eave overhang to the ridge
    pitch = math.radians(roof_pitch)
    overhang = 0.5
    up_slope = np.array([0.0, math.cos(pitch), math.sin(pitch)])
    eave = np.array([-0.4, -overhang, wall_height - overhang * math.tan(pitch)])
    slope_len = (depth / 2.0 + overhang) / math.cos(pitch)
    roof = sample_patch(rng, eave, EX, up_slope, (0.0, width + 0.8), (0.0, slope_len), density)
    ridge_z = wall_height + depth / 2.0 * math.tan(pitch)
    add(roof, "roof", "plane", normal=np.cross(EX, up_slope), eave_point=eave, ridge_z=ridge_z,
        pitch=roof_pitch, x_range=[-0.4, width + 0.4])

    # ---- window details: reveals, frame + mullion, glass
    fw, d = 0.07, float(window_depth)
    for x0, x1, z0, z1 in windows:
        parts = [
            sample_patch(rng, [x0, 0, z0], EY, EZ, (0, d), (0, z1 - z0), density),  # left reveal
            sample_patch(rng, [x1, 0, z0], EY, EZ, (0, d), (0, z1 - z0), density),  # right reveal
            sample_patch(rng, [x0, 0, z0], EX, EY, (0, x1 - x0), (0, d), density),  # sill
            sample_patch(rng, [x0, 0, z1], EX, EY, (0, x1 - x0), (0, d), density),  # lintel
            sample_patch(rng, [x0, d, z0], EX, EZ, (0, x1 - x0), (0, fw), density),  # frame bottom
            sample_patch(rng, [x0, d, z1 - fw], EX, EZ, (0, x1 - x0), (0, fw), density),  # frame top
            sample_patch(rng, [x0, d, z0 + fw], EX, EZ, (0, fw), (0, z1 - z0 - 2 * fw), density),
            sample_patch(rng, [x1 - fw, d, z0 + fw], EX, EZ, (0, fw), (0, z1 - z0 - 2 * fw), density),
            sample_patch(rng, [(x0 + x1 - fw) / 2, d, z0 + fw], EX, EZ, (0, fw), (0, z1 - z0 - 2 * fw), density),
        ]
        if glass_fraction > 0:
            parts.append(sample_patch(rng, [x0 + fw, d + 0.03, z0 + fw], EX, EZ, (0, x1 - x0 - 2 * fw),
                                      (0, z1 - z0 - 2 * fw), density * glass_fraction))
        add(np.vstack(parts), "window", "window", normal=-EY, x_range=[x0, x1], z_range=[z0, z1], depth=d)

    # ---- vegetation: bushes along the wall, two trees in the street
    for k in range(3):
        c = np.array([width * (0.15 + 0.35 * k) + rng.uniform(-0.5, 0.5), -1.0, 0.55])
        radii = np.array([0.8, 0.55, 0.6]) * rng.uniform(0.8, 1.2)
        pts = sample_ellipsoid(rng, c, radii, density, shell=0.6)
        add(pts[pts[:, 2] > 0.02], "vegetation", "bush", centre=c, radii=radii)
    for x in (-3.5, width + 3.5):
        base = np.array([x, -7.0 + rng.uniform(-1, 1), 0.0])
        trunk_h, crown_r = 2.6, rng.uniform(1.8, 2.3)
        trunk = sample_cylinder_surface(rng, base, EZ, 0.15, trunk_h, density)
        crown_c = base + np.array([0.0, 0.0, trunk_h + crown_r * 0.9])
        crown = sample_ellipsoid(rng, crown_c, (crown_r, crown_r, crown_r * 1.1), density, shell=0.7)
        add(np.vstack([trunk, crown]), "vegetation", "tree", base=base, trunk_height=trunk_h,
            crown_centre=crown_c, crown_radius=crown_r)

    # ---- clutter: a car, a lamp pole, a bench, a bin
    car_lo, car_hi = np.array([1.0, -5.0, 0.25]), np.array([5.3, -3.2, 1.1])
    cab_lo, cab_hi = np.array([2.0, -4.85, 1.1]), np.array([4.3, -3.35, 1.55])
    car = np.vstack([sample_box_surface(rng, car_lo, car_hi, density),
                     sample_box_surface(rng, cab_lo, cab_hi, density)])
    add(car, "clutter", "car", boxes=[[car_lo, car_hi], [cab_lo, cab_hi]])
    pole_base = np.array([width + 1.5, -2.5, 0.0])
    add(sample_cylinder_surface(rng, pole_base, EZ, 0.06, 4.5, density, caps=True), "clutter", "pole",
        base=pole_base, radius=0.06, height=4.5)
    b_x = width * 0.55
    bench = [
        ([b_x, -2.0, 0.42], [b_x + 1.8, -1.6, 0.47]),  # seat
        ([b_x, -1.62, 0.47], [b_x + 1.8, -1.57, 0.85]),  # backrest
        ([b_x + 0.1, -1.95, 0.0], [b_x + 0.16, -1.65, 0.42]),  # legs
        ([b_x + 1.64, -1.95, 0.0], [b_x + 1.7, -1.65, 0.42]),
    ]
    add(np.vstack([sample_box_surface(rng, lo, hi, density, bottom=True) for lo, hi in bench]),
        "clutter", "bench", boxes=bench)
    bin_base = np.array([width * 0.3, -1.8, 0.0])
    add(sample_cylinder_surface(rng, bin_base, EZ, 0.3, 0.9, density, caps=True), "clutter", "bin",
        base=bin_base, radius=0.3, height=0.9)

    xyz, attrs = scene.arrays()
    xyz = add_noise(rng, xyz, noise)
    # ---- isolated noise in the scene volume
    lo = np.array([-6.0, -16.0, 0.3])
    hi = np.array([width + 6.0, depth + 2.0, ridge_z + 3.0])
    out = isolated_outliers(rng, xyz, lo, hi, int(round(noise_fraction * len(xyz))), 0.3)
    xyz = np.vstack([xyz, out])
    attrs["classification"] = np.concatenate([attrs["classification"], np.full(len(out), cls["noise"], np.uint8)])
    attrs["object_id"] = np.concatenate([attrs["object_id"], np.full(len(out), -1, np.int32)])

    truth = {
        "classes": cls,
        "scanner": scanner,
        "ref_range": ref_range,
        "range_falloff": bool(range_falloff),
        "objects": objects,
        "building": {"width": width, "wall_height": wall_height, "depth": depth, "ridge_z": ridge_z,
                     "roof_pitch": roof_pitch, "wall_plane": {"point": [0, 0, 0], "normal": [0, -1, 0]}},
        "counts": class_counts(attrs["classification"], cls),
    }
    return finish("facade", xyz, attrs, truth, params, origin)
