"""TLS rock face of planar facets from three known joint sets, with an overhang (after the LIS slides).

Layout (local frame, x = East, y = North, z = Up): the cliff foot runs along the
x axis, the face looks South (towards −y) at three scanners standing 25 m in
front of it at the height of the reference horizon.  The face is a grid of
columns × rows of cells; every cell carries one *main* facet of joint set 0,
the columns are set back by random amounts and the exposed sides of
protruding columns are *side* facets of joint set 1.  In the overhang zone the
lower rows are recessed and the recess is closed at the top by *roof* facets of
joint set 2, seen from below (outward normals pointing down).

Roles of the three joint sets: set 0 must face the scanners roughly (|n_y| ≥
0.2), set 1 must have |n_x| ≥ 0.2 (its sides face −x or +x by the sign of its
normal), set 2 must have |n_z| ≥ 0.2.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ._common import (
    MAX_COUNT,
    Scene,
    add_noise,
    capture_params,
    check_finite,
    check_flag,
    check_fraction,
    check_length,
    check_nonneg,
    check_origin,
    check_positive,
    dip_from_normal,
    finish,
    isolated_outliers,
    make_rng,
    no_points,
    normal_from_dip,
    plane_basis,
    sample_plane_over_rect,
)
from ..errors import LidarfxError

__all__ = ["DEFAULT_JOINT_SETS", "rockface"]

DEFAULT_JOINT_SETS = (
    {"dip": 80.0, "dip_direction": 170.0},  # main face, facing SSE
    {"dip": 65.0, "dip_direction": 245.0},  # sides of protruding columns, facing WSW
    {"dip": 30.0, "dip_direction": 20.0},   # dipping into the cliff: overhang roofs, seen from below
)

_ROLE_AXIS = {"main": 1, "side": 0, "roof": 2}


def _outward(n: np.ndarray, role: str, facing: float) -> np.ndarray:
    """Orient a facet normal outwards, i.e. out of the rock towards free space."""
    k = _ROLE_AXIS[role]
    want = {"main": -1.0, "side": facing, "roof": -1.0}[role]
    return n if n[k] * want > 0 else -n


def _scatter(rng, n: np.ndarray, sigma_deg: float) -> np.ndarray:
    """Tilt ``n`` by a Rayleigh(σ) angle in a uniform random direction (≈ Fisher, κ ≈ 1/σ²)."""
    if sigma_deg <= 0:
        return n
    theta = math.radians(sigma_deg) * math.sqrt(-2.0 * math.log(1.0 - rng.uniform()))
    phi = rng.uniform(0.0, 2 * math.pi)
    e1, e2, _ = plane_basis(n)
    return math.cos(theta) * n + math.sin(theta) * (math.cos(phi) * e1 + math.sin(phi) * e2)


def rockface(
    *,
    sets: Sequence[dict[str, float]] = DEFAULT_JOINT_SETS,
    width: float = 30.0,
    height: float = 20.0,
    cell_width: float = 5.0,
    cell_height: float = 4.0,
    density: float = 60.0,
    noise: float = 0.01,
    scatter: float = 0.0,
    overhang: bool = True,
    overhang_x: Sequence[float] = (10.0, 20.0),
    overhang_z: float = 8.0,
    overhang_depth: float = 3.0,
    scanner_distance: float = 25.0,
    scanner_height: float = 1.5,
    noise_fraction: float = 0.002,
    seed: int = 0,
    origin: Any = None,
):
    """TLS rock face: planar facets of 3 joint sets, an overhang, isolated noise.

    Parameters
    ----------
    sets:
        Three joint sets as ``{"dip": deg, "dip_direction": deg}`` (dip from
        horizontal, dip direction clockwise from North); roles see the module doc.
    width, height, cell_width, cell_height:
        Face extent along x and z (m) and the facet grid.
    density:
        Points per m² on every facet.
    noise:
        Gaussian σ (m) on every coordinate (surface roughness + ranging noise).
    scatter:
        Per-facet orientation scatter around the set's mean (degrees, Rayleigh
        σ ≈ 1/√κ of a Fisher distribution); 0 = every facet exactly on its set.
    overhang, overhang_x, overhang_z, overhang_depth:
        Columns whose centre lies in ``overhang_x`` are recessed by
        ``overhang_depth`` m below ``overhang_z``; roof facets (set 2) close the
        recess at ``overhang_z``.
    scanner_distance, scanner_height:
        Three scanners at y = −distance, x = width/6, width/2, 5·width/6 and
        z = scanner_height, which is also the reference horizon.  Facets facing
        away from every scanner are not generated (occlusion is not simulated).
    noise_fraction:
        Isolated outliers (joint_set −1) as a share of the facet points.
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).

    Returns
    -------
    PointCloud
        Attributes ``joint_set`` (0, 1, 2; −1 = none/noise), ``facet_id``
        (−1 = none) and ``overhang`` (1 on facets whose outward normal points
        down).  ``meta["truth"]``: ``sets`` (dip, dip_direction, upward
        normal, role), ``facets`` (id, joint_set, role, outward normal, dip,
        dip_direction, centroid, area, overhang), ``overhang`` (region and
        facet ids), ``reference_horizon`` and ``scanners``.
    """
    params = capture_params(locals())
    if len(sets) != 3:
        raise LidarfxError(f"rockface needs exactly 3 joint sets, got {len(sets)}")
    try:
        set_normals = [normal_from_dip(float(s["dip"]), float(s["dip_direction"])) for s in sets]
    except (KeyError, TypeError, ValueError):
        raise LidarfxError("each joint set needs numeric 'dip' and 'dip_direction'") from None
    for k, role in enumerate(("main", "side", "roof")):
        if abs(set_normals[k][_ROLE_AXIS[role]]) < 0.2:
            raise LidarfxError(f"joint set {k} is too oblique for its role ({role}); see the rockface docs")
    width, height = check_length("width", width), check_length("height", height)
    cw, ch = check_length("cell_width", cell_width), check_length("cell_height", cell_height)
    density = check_positive("density", density)
    noise = check_nonneg("noise", noise)
    scatter = check_nonneg("scatter", scatter)
    depth = check_length("overhang_depth", overhang_depth)
    overhang = check_flag("overhang", overhang)
    overhang_z = check_nonneg("overhang_z", overhang_z)
    scanner_distance = check_length("scanner_distance", scanner_distance)
    scanner_height = check_finite("scanner_height", scanner_height)
    try:
        overhang_x = tuple(check_finite("overhang_x", v) for v in overhang_x)
    except TypeError:
        raise LidarfxError(f"overhang_x must be two numbers (from, to), got {overhang_x!r}") from None
    if len(overhang_x) != 2:
        raise LidarfxError(f"overhang_x must be two numbers (from, to), got {overhang_x!r}")
    noise_fraction = check_fraction("noise_fraction", noise_fraction)
    origin = check_origin(origin)
    rng = make_rng(seed)

    nc, nr = max(1, int(round(width / cw))), max(1, int(round(height / ch)))
    if nc * nr > 100 * MAX_COUNT:
        raise LidarfxError(f"{nc} x {nr} facets are too many; use larger cell_width / cell_height")
    cw, ch = width / nc, height / nr
    gap = min(0.05, 0.05 * cw, 0.05 * ch)
    lean = 0.18  # the face steps back with height (about 80° overall)
    offsets = rng.uniform(0.0, 2.5, nc)
    x_mid = (np.arange(nc) + 0.5) * cw
    z_mid = (np.arange(nr) + 0.5) * ch
    ov_cols = [i for i in range(nc) if overhang and overhang_x[0] <= x_mid[i] <= overhang_x[1]]
    ov_row = int(round(overhang_z / ch))  # first row above the recess
    overhang_z = ov_row * ch
    if ov_cols and not 0 < ov_row < nr:
        raise LidarfxError(f"overhang_z must lie inside the face (0, {height:g}) m")
    recessed = np.zeros((nc, nr), dtype=bool)
    for i in ov_cols:
        recessed[i, :ov_row] = True
    front = offsets[:, None] + lean * z_mid[None, :] + rng.normal(0.0, 0.25, (nc, nr)) + depth * recessed

    scanners = np.array([[width * f, -float(scanner_distance), float(scanner_height)] for f in (1 / 6, 1 / 2, 5 / 6)])
    scene = Scene({"joint_set": (np.int32, -1), "facet_id": (np.int32, -1), "overhang": (np.uint8, 0)})
    facets: list[dict[str, Any]] = []

    def add_facet(set_id: int, role: str, point: np.ndarray, bounds: list[tuple[float, float]],
                  facing: float = -1.0) -> None:
        n = _scatter(rng, set_normals[set_id], scatter)
        n = _outward(n, role, facing)
        if np.max((scanners - point) @ n) <= 0:
            return  # faces away from every scanner: not scanned
        pts = sample_plane_over_rect(rng, n, point, _ROLE_AXIS[role], bounds, density)
        if len(pts) < 3:
            return
        fid = len(facets)
        is_over = bool(n[2] < 0)
        scene.add(pts, joint_set=set_id, facet_id=fid, overhang=int(is_over))
        dip, ddir = dip_from_normal(n)
        area = (bounds[0][1] - bounds[0][0]) * (bounds[1][1] - bounds[1][0]) / abs(n[_ROLE_AXIS[role]])
        facets.append({"id": fid, "joint_set": set_id, "role": role, "normal": n, "dip": dip,
                       "dip_direction": ddir, "point": point, "centroid": pts.mean(axis=0),
                       "area": area, "n_points": len(pts), "overhang": is_over})

    # main facets
    for i in range(nc):
        for j in range(nr):
            p = np.array([x_mid[i], front[i, j], z_mid[j]])
            add_facet(0, "main", p, [(i * cw + gap, (i + 1) * cw - gap), (j * ch + gap, (j + 1) * ch - gap)])
    # side facets of protruding columns: set 1 faces -x (west) or +x by the sign of its normal
    facing = -1.0 if set_normals[1][0] < 0 else 1.0
    for i in range(nc - 1):
        for j in range(nr):
            west, east = front[i, j], front[i + 1, j]
            exposed = west - east if facing < 0 else east - west  # the protruding column's side is seen
            if exposed < 1.0:
                continue
            lo_y, hi_y = min(west, east), max(west, east)
            p = np.array([(i + 1) * cw, 0.5 * (lo_y + hi_y), z_mid[j]])
            add_facet(1, "side", p, [(lo_y + gap, hi_y - gap), (j * ch + gap, (j + 1) * ch - gap)], facing)
    # roofs closing the recess (seen from below)
    roof_ids = []
    for i in ov_cols:
        y_out = offsets[i] + lean * overhang_z
        p = np.array([x_mid[i], y_out + depth / 2.0, overhang_z])
        before = len(facets)
        add_facet(2, "roof", p, [(i * cw + gap, (i + 1) * cw - gap), (y_out + gap, y_out + depth - gap)])
        roof_ids += list(range(before, len(facets)))

    if scene.n == 0:
        raise no_points("rockface", params)
    xyz, attrs = scene.arrays()
    xyz = add_noise(rng, xyz, noise)
    n_facet_points = len(xyz)
    lo = np.array([0.0, -8.0, 0.0])
    hi = np.array([width, float(xyz[:, 1].max()), height])
    out = isolated_outliers(rng, xyz, lo, hi, int(round(noise_fraction * n_facet_points)), 0.5)
    xyz = np.vstack([xyz, out])
    for name, arr in attrs.items():
        attrs[name] = np.concatenate([arr, np.full(len(out), 0 if name == "overhang" else -1, dtype=arr.dtype)])

    over_ids = [f["id"] for f in facets if f["overhang"]]
    if over_ids:
        pts = xyz[np.isin(attrs["facet_id"], over_ids)]
        region = {"x": [ov_cols[0] * cw, (ov_cols[-1] + 1) * cw] if ov_cols else None,
                  "z_roof": overhang_z, "depth": depth,
                  "bbox_min": pts.min(axis=0), "bbox_max": pts.max(axis=0), "facet_ids": over_ids,
                  "roof_facet_ids": roof_ids}
    else:
        region = None
    truth = {
        "sets": [{"id": k, "dip": float(s["dip"]), "dip_direction": float(s["dip_direction"]) % 360.0,
                  "normal": set_normals[k], "role": role}
                 for k, (s, role) in enumerate(zip(sets, ("main face", "side faces", "overhang roofs")))],
        "facets": facets,
        "overhang": region,
        "reference_horizon": {"z": float(scanner_height), "normal": [0.0, 0.0, 1.0],
                              "description": "horizontal plane at the scanner height"},
        "scanners": scanners.tolist(),
        "counts": {"facet_points": n_facet_points, "noise": len(out),
                   "per_set": [int(np.count_nonzero(attrs["joint_set"] == k)) for k in range(3)]},
    }
    return finish("rockface", xyz, attrs, truth, params, origin)
