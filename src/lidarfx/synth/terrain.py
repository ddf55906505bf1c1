"""ALS terrain with known structure lines (Mandlburger & Briese 2009): a dike and a ditch.

The surface is ``z = base(x, y) + dike(d₁) − ditch(d₂)``: a gently tilted,
gently undulating base, a straight trapezoidal dike (flat crest, planar
slopes) and a curved trapezoidal ditch (circular-arc centreline).  ``d₁`` /
``d₂`` are signed distances to the centrelines, so every breakline is an exact
offset curve of a centreline and its height is the surface height there.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._common import (
    capture_params,
    check_finite,
    check_fraction,
    check_length,
    check_nonneg,
    check_origin,
    check_positive,
    check_sampling,
    finish,
    make_rng,
    sample_rect,
    smooth_field,
)
from ..errors import LidarfxError

__all__ = ["LANDFORMS", "terrain"]

LANDFORMS: dict[str, int] = {"base": 0, "dike_crest": 1, "dike_slope": 2, "ditch_slope": 3, "ditch_bottom": 4}
"""Values of the ``landform`` attribute."""


def _trapezoid(d: np.ndarray, height: float, top_half: float, slope_width: float) -> np.ndarray:
    """Height of a symmetric trapezoid profile at signed distance ``d``."""
    a = np.abs(d)
    return height * np.clip((top_half + slope_width - a) / slope_width, 0.0, 1.0)


def terrain(
    *,
    size: float = 150.0,
    density: float = 5.0,
    noise: float = 0.03,
    sampling: str = "random",
    dike_height: float = 3.0,
    dike_crest_width: float = 3.0,
    dike_slope: float = 2.0,
    dike_azimuth: float = 75.0,
    dike_offset: float = 25.0,
    ditch_depth: float = 1.2,
    ditch_top_width: float = 4.0,
    ditch_bottom_width: float = 1.0,
    ditch_radius: float = 150.0,
    ditch_offset: float = -10.0,
    relief: float = 0.3,
    breakline_step: float = 2.0,
    vegetation: float = 0.0,
    vegetation_density: float | None = None,
    off_terrain: float = 0.0,
    seed: int = 0,
    origin: Any = None,
):
    """Square ALS ground tile with a dike and a ditch and their breaklines.

    Parameters
    ----------
    size:
        Tile edge (m); the tile is ``[-size/2, size/2]²`` in local x, y.
    density:
        Ground points per m² (ALS-like, default 5).
    noise:
        Gaussian σ (m) of the heights (ALS ranging noise; x, y are exact).
    sampling:
        ``"random"`` (uniform) or ``"grid"``.
    dike_height, dike_crest_width, dike_slope:
        Dike above the base surface (m), flat crest width (m) and slope ratio
        (horizontal : vertical, default 1 : 2 → slope width = 2 × height).
    dike_azimuth, dike_offset:
        Direction of the straight dike (degrees clockwise from North) and the
        signed distance of its centreline from the tile centre (m, to the left
        of the direction).
    ditch_depth, ditch_top_width, ditch_bottom_width:
        Trapezoidal ditch below the base surface.
    ditch_radius, ditch_offset:
        The ditch centreline is a circle of this radius with its top at
        (0, ditch_offset) and its centre straight below, so inside the tile it
        is an arc bending away from the dike (they must not overlap).
    relief:
        Amplitude (m) of the smooth undulation of the base surface (on top of a
        random tilt of at most 1 %).
    breakline_step:
        Vertex spacing (m) of the truth polylines.
    vegetation, vegetation_density, off_terrain:
        Share of the tile covered by shrub and tree patches (discs of 2–6 m
        radius), their points per m² (default: the ground density) at 0.2–8 m
        above the ground (class 3 below 0.5 m, 4 below 2 m, else 5), and the
        share of them wrongly left in the ground class 2 (off-terrain points a
        breakline or DTM method must resist).  0 = bare ground (the default:
        the scene is then the same as without these parameters).
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).

    Returns
    -------
    PointCloud
        Attributes ``classification`` (2 = ground everywhere, vegetation 3 / 4 / 5
        or wrongly 2) and ``landform`` (:data:`LANDFORMS`, −1 = vegetation).  ``meta["truth"]["breaklines"]``: list of
        ``{"kind", "side", "points"}`` with ``points`` a polyline
        ``[[x, y, z], ...]`` and ``kind`` one of ``dike_crest``, ``dike_toe``,
        ``ditch_edge``, ``ditch_bottom``; ``side`` is ``left`` / ``right`` of
        the dike direction, ``inner`` / ``outer`` of the ditch arc.
    """
    params = capture_params(locals())
    size = check_length("size", size)
    density = check_positive("density", density)
    noise = check_nonneg("noise", noise)
    sampling = check_sampling(sampling)
    dike_height = check_positive("dike_height", dike_height)
    dike_crest_width = check_positive("dike_crest_width", dike_crest_width)
    dike_slope = check_positive("dike_slope", dike_slope)
    ditch_depth = check_positive("ditch_depth", ditch_depth)
    check_positive("ditch_bottom_width", ditch_bottom_width)
    if not ditch_top_width > ditch_bottom_width:
        raise LidarfxError("ditch_top_width must be larger than ditch_bottom_width")
    ditch_radius = check_length("ditch_radius", ditch_radius)
    for name, v in (("dike_azimuth", dike_azimuth), ("dike_offset", dike_offset), ("ditch_offset", ditch_offset)):
        check_finite(name, v)
    relief = check_nonneg("relief", relief)
    step = check_positive("breakline_step", breakline_step)
    vegetation = check_fraction("vegetation", vegetation)
    off_terrain = check_fraction("off_terrain", off_terrain)
    if vegetation_density is not None:
        vegetation_density = check_positive("vegetation_density", vegetation_density)
    origin = check_origin(origin)
    rng = make_rng(seed)

    half = size / 2.0
    field = smooth_field(rng, relief, 60.0)
    tilt = rng.uniform(-0.01, 0.01, 2)

    def base(x: Any, y: Any) -> np.ndarray:
        return 2.0 + field(x, y) + tilt[0] * np.asarray(x) + tilt[1] * np.asarray(y)

    # dike: straight line through p0 with direction u; left normal nl
    az = math.radians(dike_azimuth)
    u = np.array([math.sin(az), math.cos(az)])
    nl = np.array([-u[1], u[0]])
    p0 = dike_offset * nl
    crest_half = dike_crest_width / 2.0
    slope_w = dike_slope * dike_height
    # ditch: circle with its top (vertex) at (0, ditch_offset), centre straight below
    centre = np.array([0.0, ditch_offset - ditch_radius])
    bottom_half = ditch_bottom_width / 2.0
    ditch_slope_w = (ditch_top_width - ditch_bottom_width) / 2.0

    def dike_d(xy: np.ndarray) -> np.ndarray:
        return (xy - p0) @ nl

    def ditch_d(xy: np.ndarray) -> np.ndarray:
        return ditch_radius - np.linalg.norm(xy - centre, axis=-1)

    def surface(xy: np.ndarray) -> np.ndarray:
        return (base(xy[..., 0], xy[..., 1])
                + _trapezoid(dike_d(xy), dike_height, crest_half, slope_w)
                - _trapezoid(ditch_d(xy), ditch_depth, bottom_half, ditch_slope_w))

    arc = centre + ditch_radius * np.column_stack([np.cos(np.linspace(0, 2 * math.pi, 3600)),
                                                   np.sin(np.linspace(0, 2 * math.pi, 3600))])
    arc = arc[np.all(np.abs(arc) <= half + ditch_top_width, axis=1)]
    if len(arc) and np.min(np.abs(dike_d(arc))) < crest_half + slope_w + ditch_top_width / 2.0:
        raise LidarfxError("the dike and the ditch overlap inside the tile; move them apart "
                           "(dike_offset, dike_azimuth, ditch_offset, ditch_radius)")

    # ---- points
    xy = sample_rect(rng, (-half, half), (-half, half), density, sampling)
    z = surface(xy) + (rng.normal(0.0, noise, len(xy)) if noise > 0 else 0.0)
    d1, d2 = np.abs(dike_d(xy)), np.abs(ditch_d(xy))
    landform = np.zeros(len(xy), dtype=np.int32)
    landform[d1 < crest_half + slope_w] = LANDFORMS["dike_slope"]
    landform[d1 <= crest_half] = LANDFORMS["dike_crest"]
    landform[d2 < bottom_half + ditch_slope_w] = LANDFORMS["ditch_slope"]
    landform[d2 <= bottom_half] = LANDFORMS["ditch_bottom"]
    xyz = np.column_stack([xy, z])
    classification = np.full(len(xyz), 2, dtype=np.uint8)
    n_veg = n_off = 0
    if vegetation > 0:
        # patches: discs of 2-6 m radius at random centres until the covered share is reached
        area, centres, radii = size * size, [], []
        while sum(math.pi * r * r for r in radii) < vegetation * area:
            centres.append(rng.uniform(-half, half, 2))
            radii.append(float(rng.uniform(2.0, 6.0)))
        c, r = np.array(centres), np.array(radii)
        dens = density if vegetation_density is None else vegetation_density
        cand = sample_rect(rng, (-half, half), (-half, half), dens, "random")
        dist = np.linalg.norm(cand[:, None, :] - c[None, :, :], axis=2) / r[None, :]
        vxy = cand[(dist <= 1.0).any(axis=1)]
        h = 0.2 + 7.8 * rng.uniform(0.0, 1.0, len(vxy)) ** 2  # more low than high returns
        vz = surface(vxy) + h
        vcls = np.where(h < 0.5, 3, np.where(h < 2.0, 4, 5)).astype(np.uint8)
        wrong = rng.uniform(0.0, 1.0, len(vxy)) < off_terrain
        vcls[wrong] = 2
        n_veg, n_off = len(vxy), int(wrong.sum())
        xyz = np.vstack([xyz, np.column_stack([vxy, vz])])
        classification = np.concatenate([classification, vcls])
        landform = np.concatenate([landform, np.full(len(vxy), -1, np.int32)])

    # ---- breaklines
    def inside(p: np.ndarray) -> np.ndarray:
        return np.all(np.abs(p) <= half, axis=1)

    def polyline(p2: np.ndarray) -> np.ndarray:
        p2 = p2[inside(p2)]
        return np.column_stack([p2, surface(p2)])

    breaklines = []
    t = np.arange(-size, size + step / 2, step)  # long enough to cross the tile
    for kind, off in (("dike_crest", crest_half), ("dike_toe", crest_half + slope_w)):
        for side, sgn in (("left", 1.0), ("right", -1.0)):
            line = p0 + sgn * off * nl + t[:, None] * u
            breaklines.append({"kind": kind, "side": side, "points": polyline(line)})
    for kind, off in (("ditch_edge", bottom_half + ditch_slope_w), ("ditch_bottom", bottom_half)):
        for side, sgn in (("inner", 1.0), ("outer", -1.0)):
            r = ditch_radius - sgn * off  # inner = towards the circle centre (d > 0)
            ang = np.arange(0.0, 2 * math.pi, step / r)
            ring = centre + r * np.column_stack([np.cos(ang), np.sin(ang)])
            # keep the arc inside the tile, ordered along the arc from left (−x) to right
            ring = ring[inside(ring)]
            ring = ring[np.argsort(ring[:, 0])]
            breaklines.append({"kind": kind, "side": side, "points": np.column_stack([ring, surface(ring)])})
    breaklines = [b for b in breaklines if len(b["points"]) >= 2]

    truth = {
        "classes": {"ground": 2},
        "landforms": LANDFORMS,
        "breaklines": breaklines,
        "dike": {"point": p0, "direction": u, "azimuth": dike_azimuth % 360.0, "height": dike_height,
                 "crest_width": dike_crest_width, "slope_width": slope_w,
                 "crest_offsets": [crest_half, -crest_half], "toe_offsets": [crest_half + slope_w, -crest_half - slope_w]},
        "ditch": {"centre": centre, "radius": ditch_radius, "depth": ditch_depth, "top_width": ditch_top_width,
                  "bottom_width": ditch_bottom_width},
        "tile": {"min": [-half, -half], "max": [half, half]},
    }
    truth["vegetation"] = {"points": n_veg, "off_terrain": n_off}
    attrs = {"classification": classification, "landform": landform}
    return finish("terrain", xyz, attrs, truth, params, origin)
