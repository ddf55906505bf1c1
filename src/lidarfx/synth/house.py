"""ALS gable-roof house on flat ground with exact 3-D roof lines (docs/synth.md §7).

House frame (local metres, x = East, y = North, z = Up): ``u = (sin az, cos az, 0)``
is the ridge direction (``azimuth`` clockwise from North) and ``v = (−cos az, sin az, 0)``
the horizontal direction 90° to its left, so (u, v, z) is right-handed.  The house
is centred at the origin on the ground z = 0; its footprint is ``|u| ≤ length/2``,
``|v| ≤ width/2``.  The roof is a zero-thickness surface
``z(v) = wall_height + (width/2 − |v|) · tan(pitch)`` over
``|u| ≤ length/2 + overhang``, ``|v| ≤ width/2 + overhang``: the eaves run along
``v = ±(width/2 + overhang)``, the ridge along ``v = 0`` and the verges (gable
edges) along ``u = ±(length/2 + overhang)``.

ALS-like sampling: uniform positions in plan over the tile take the roof height
inside the roof's plan extent and the ground height (0) elsewhere; sparser ground
returns reach under the overhang (never inside the footprint); the four walls are
sampled from the ground up to the roof.  Every coordinate gets Gaussian noise.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._common import (
    MAX_LENGTH,
    MAX_POINTS,
    EZ,
    Scene,
    add_noise,
    capture_params,
    check_finite,
    check_fraction,
    check_length,
    check_nonneg,
    check_origin,
    check_positive,
    check_sampling,
    class_counts,
    dip_from_normal,
    finish,
    make_rng,
    merge_classes,
    sample_rect,
)
from ..errors import LidarfxError

__all__ = ["HOUSE_CLASSES", "HOUSE_PARTS", "house"]

HOUSE_CLASSES: dict[str, int] = {"ground": 2, "building": 6}
"""ASPRS codes: 2 ground, 6 building (roof and walls)."""

HOUSE_PARTS: dict[str, int] = {"ground": 0, "roof": 1, "wall": 2}
"""Values of the ``part`` attribute."""


def _check_extent(name: str, value: Any) -> float:
    """A length that may be 0: >= 0 and at most :data:`MAX_LENGTH`."""
    v = check_nonneg(name, value)
    if v > MAX_LENGTH:
        raise LidarfxError(f"{name} must be at most {MAX_LENGTH:g}, got {value!r}")
    return v


def house(
    *,
    length: float = 12.0,
    width: float = 9.0,
    wall_height: float = 6.0,
    roof_pitch: float = 35.0,
    overhang: float = 0.5,
    azimuth: float = 30.0,
    density: float = 20.0,
    wall_density: float = 2.0,
    noise: float = 0.02,
    margin: float = 10.0,
    ground_under_roof: float = 0.5,
    sampling: str = "random",
    seed: int = 0,
    origin: Any = None,
    classes: dict[str, int] | None = None,
):
    """ALS gable-roof house on flat ground with its exact ridge, eave and verge lines.

    Parameters
    ----------
    length, width, wall_height:
        Footprint along the ridge (u) and across it (v), and the height of the
        long walls where the roof planes meet them (m).
    roof_pitch:
        Roof slope in degrees, (0, 75].
    overhang:
        Horizontal roof overhang beyond the walls on all four sides (m, >= 0);
        the eaves sit at ``wall_height − overhang · tan(pitch)``, which must be
        above the ground.
    azimuth:
        Ridge direction in degrees clockwise from North.
    density:
        ALS points per m² of plan area over the tile (roof or ground).
    wall_density:
        Points per m² on each of the four walls (0: no wall points).
    noise:
        Gaussian σ (m) on x, y and z of every point.
    margin:
        Ground around the roof (m): the tile is ``|u| ≤ length/2 + overhang + margin``,
        ``|v| ≤ width/2 + overhang + margin``.
    ground_under_roof:
        Extra ground returns under the overhang (inside the roof's plan extent,
        outside the footprint) as a share of ``density``.
    sampling:
        ``"random"`` (uniform) or ``"grid"`` (lattice per part).
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).
    classes:
        Override class codes (name -> code) of :data:`HOUSE_CLASSES`.

    Returns
    -------
    PointCloud
        Attributes ``classification`` (:data:`HOUSE_CLASSES`), ``part``
        (:data:`HOUSE_PARTS`: 0 ground, 1 roof, 2 wall) and ``roof_face``
        (0 for the roof side with v ≥ 0, 1 for v < 0, −1 for other points).
        ``meta["truth"]``: ``classes``, ``parts``, ``frame`` (u, v), ``building``,
        ``lines`` (list of ``{"kind", "side", "faces", "start", "end"}``, kinds
        ``ridge``, ``eave``, ``verge``), ``roof_planes``, ``tile``, ``counts``.
    """
    params = capture_params(locals())
    length = check_length("length", length)
    width = check_length("width", width)
    wall_height = check_length("wall_height", wall_height)
    pitch_deg = check_finite("roof_pitch", roof_pitch)
    if not 0.0 < pitch_deg <= 75.0:
        raise LidarfxError(f"roof_pitch must be in (0, 75] degrees, got {roof_pitch!r}")
    overhang = _check_extent("overhang", overhang)
    margin = _check_extent("margin", margin)
    azimuth = check_finite("azimuth", azimuth)
    density = check_positive("density", density)
    wall_density = check_nonneg("wall_density", wall_density)
    noise = check_nonneg("noise", noise)
    ground_under_roof = check_fraction("ground_under_roof", ground_under_roof)
    sampling = check_sampling(sampling)
    cls = merge_classes(HOUSE_CLASSES, classes)
    origin = check_origin(origin)
    rng = make_rng(seed)

    tan_p = math.tan(math.radians(pitch_deg))
    drop = overhang * tan_p
    if not drop < wall_height:
        raise LidarfxError(
            f"eaves below ground: overhang × tan(roof_pitch) = {drop:g} m must be less than "
            f"wall_height = {wall_height:g} m; shorten the overhang or lower the pitch"
        )
    hl, hw = length / 2.0, width / 2.0  # footprint half extents (u, v)
    ru, rv = hl + overhang, hw + overhang  # roof plan half extents
    tu, tv = ru + margin, rv + margin  # tile half extents
    eave_z = wall_height - drop
    ridge_z = wall_height + hw * tan_p

    # refuse before sampling: the grid helpers check each axis, not the product
    wall_area = 2 * length * wall_height + 2 * width * (wall_height + ridge_z) / 2.0
    total = 4 * tu * tv * density + (4 * ru * rv - 4 * hl * hw) * density * ground_under_roof \
        + wall_area * wall_density
    if not total <= MAX_POINTS:  # also inf and NaN
        raise LidarfxError(
            f"house: density {density:g} / wall_density {wall_density:g} would give {total:.3g} points "
            f"(at most {MAX_POINTS:,}); lower the density or the size"
        )

    az = math.radians(azimuth)
    u_dir = np.array([math.sin(az), math.cos(az), 0.0])
    v_dir = np.array([-math.cos(az), math.sin(az), 0.0])  # = z × u: left of the ridge direction

    def to_xyz(uc: Any, vc: Any, z: Any) -> np.ndarray:
        uc, vc, z = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (uc, vc, z)))
        return uc[..., None] * u_dir + vc[..., None] * v_dir + z[..., None] * EZ

    def roof_z(vc: Any) -> np.ndarray:
        return wall_height + (hw - np.abs(vc)) * tan_p

    def xy(uc: float, vc: float) -> list[float]:
        return to_xyz(uc, vc, 0.0)[:2].tolist()

    def rect(a: float, b: float) -> list[list[float]]:
        # counter-clockwise seen from above ((u, v) is right-handed)
        return [xy(-a, -b), xy(a, -b), xy(a, b), xy(-a, b)]

    scene = Scene({"classification": (np.uint8, cls["ground"]), "part": (np.int32, HOUSE_PARTS["ground"]),
                   "roof_face": (np.int32, -1)})

    # ---- first returns over the tile: roof inside its plan extent, ground elsewhere
    uv = sample_rect(rng, (-tu, tu), (-tv, tv), density, sampling)
    on_roof = (np.abs(uv[:, 0]) <= ru) & (np.abs(uv[:, 1]) <= rv)
    g = uv[~on_roof]
    scene.add(to_xyz(g[:, 0], g[:, 1], 0.0), classification=cls["ground"], part=HOUSE_PARTS["ground"])
    r = uv[on_roof]
    scene.add(to_xyz(r[:, 0], r[:, 1], roof_z(r[:, 1])), classification=cls["building"],
              part=HOUSE_PARTS["roof"], roof_face=np.where(r[:, 1] >= 0, 0, 1).astype(np.int32))

    # ---- off-nadir ground returns under the overhang (four strips, never inside the footprint)
    if ground_under_roof > 0 and overhang > 0:
        d = density * ground_under_roof
        strips = [((-ru, ru), (hw, rv)), ((-ru, ru), (-rv, -hw)),  # along the eaves
                  ((hl, ru), (-hw, hw)), ((-ru, -hl), (-hw, hw))]  # under the verges
        for us, vs in strips:
            p = sample_rect(rng, us, vs, d, sampling)
            scene.add(to_xyz(p[:, 0], p[:, 1], 0.0), classification=cls["ground"], part=HOUSE_PARTS["ground"])

    # ---- walls from the ground to the roof underside
    if wall_density > 0:
        for side in (1.0, -1.0):  # long walls v = ±width/2, up to wall_height
            p = sample_rect(rng, (-hl, hl), (0.0, wall_height), wall_density, sampling)
            scene.add(to_xyz(p[:, 0], side * hw, p[:, 1]), classification=cls["building"], part=HOUSE_PARTS["wall"])
        for side in (1.0, -1.0):  # gable walls u = ±length/2, up to the roof line z(v)
            p = sample_rect(rng, (-hw, hw), (0.0, ridge_z), wall_density, sampling)
            p = p[p[:, 1] <= roof_z(p[:, 0])]
            scene.add(to_xyz(side * hl, p[:, 0], p[:, 1]), classification=cls["building"], part=HOUSE_PARTS["wall"])

    xyz, attrs = scene.arrays()
    xyz = add_noise(rng, xyz, noise)

    # ---- truth: lines, planes
    def pt(uc: float, vc: float, z: float) -> list[float]:
        return to_xyz(uc, vc, z).tolist()

    lines = [{"kind": "ridge", "side": "centre", "faces": [0, 1],
              "start": pt(-ru, 0.0, ridge_z), "end": pt(ru, 0.0, ridge_z)}]
    for name, face, s in (("left", 0, 1.0), ("right", 1, -1.0)):
        lines.append({"kind": "eave", "side": name, "faces": [face],
                      "start": pt(-ru, s * rv, eave_z), "end": pt(ru, s * rv, eave_z)})
    for end, e in (("start", -1.0), ("end", 1.0)):
        for name, face, s in (("left", 0, 1.0), ("right", 1, -1.0)):
            lines.append({"kind": "verge", "side": f"{end}_{name}", "faces": [face],
                          "start": pt(e * ru, s * rv, eave_z), "end": pt(e * ru, 0.0, ridge_z)})
    pitch = math.radians(pitch_deg)
    roof_planes = []
    for face, s in ((0, 1.0), (1, -1.0)):
        normal = s * math.sin(pitch) * v_dir + math.cos(pitch) * EZ
        dip, ddir = dip_from_normal(normal)
        roof_planes.append({
            "face": face, "side": "left" if s > 0 else "right", "normal": normal.tolist(),
            "point": pt(0.0, s * rv / 2.0, float(roof_z(rv / 2.0))), "dip": float(dip), "dip_direction": float(ddir),
            "corners": [pt(-ru, s * rv, eave_z), pt(ru, s * rv, eave_z), pt(ru, 0.0, ridge_z), pt(-ru, 0.0, ridge_z)],
        })

    truth = {
        "classes": cls,
        "parts": HOUSE_PARTS,
        "frame": {"u": u_dir.tolist(), "v": v_dir.tolist(),
                  "note": "u = ridge direction (azimuth clockwise from North), v = z × u (left of u); "
                          "roof_face 0: v >= 0, 1: v < 0"},
        "building": {
            "length": length, "width": width, "wall_height": wall_height, "roof_pitch": pitch_deg,
            "overhang": overhang, "azimuth": azimuth % 360.0, "eave_height": eave_z, "ridge_height": ridge_z,
            "centre": [0.0, 0.0], "footprint": rect(hl, hw), "roof_extent": rect(ru, rv),
        },
        "lines": lines,
        "roof_planes": roof_planes,
        "tile": {"u_half": tu, "v_half": tv, "corners": rect(tu, tv)},
        "counts": class_counts(attrs["classification"], cls),
    }
    return finish("house", xyz, attrs, truth, params, origin)
