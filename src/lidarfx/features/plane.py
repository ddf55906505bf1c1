"""Local-plane features shared by the ordinary (PCA) and the robust (MSAC) plane.

Normal orientation: towards the scanner when one is given (TLS), else up.
Slope = arccos |n_z| in degrees; aspect = atan2(n_x, n_y) of the up-facing
normal, clockwise from North, NaN below 0.1° of slope; plane distance =
signed distance of the query point to the plane, (p − c)·n.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from . import slots as S


HORIZONTAL = 1e-6
"""A unit vector with |z| below this is horizontal: rounding alone may give its z either sign (a
vertical wall far from the origin), so :func:`points_down` decides by x, then y."""


@nb.njit(cache=True, inline="always")
def points_down(x, y, z):
    """Whether the unit vector (x, y, z) is flipped by the up orientation: z < 0, or, horizontal
    (|z| < :data:`HORIZONTAL`), x < 0, or, along y, y < 0."""
    if abs(z) >= HORIZONTAL:
        return z < 0.0
    if abs(x) >= HORIZONTAL:
        return x < 0.0
    return y < 0.0


@nb.njit(cache=True, inline="always")
def orient_normal(nx, ny, nz, qx, qy, qz, scanner, has_scanner):
    """The normal flipped towards ``scanner`` (local coordinates) or, without one, up."""
    if has_scanner:
        if nx * (scanner[0] - qx) + ny * (scanner[1] - qy) + nz * (scanner[2] - qz) < 0.0:
            return -nx, -ny, -nz
    elif points_down(nx, ny, nz):
        return -nx, -ny, -nz
    return nx, ny, nz


@nb.njit(cache=True, inline="always")
def slope_deg(nz):
    return math.degrees(math.acos(min(abs(nz), 1.0)))


@nb.njit(cache=True)
def write_plane(o, col, first, nx, ny, nz, cx, cy, cz, need_slope):
    """Write normal x/y/z, slope, aspect and plane distance into the six consecutive
    slots starting at ``first`` (NORMAL_X or MSAC_NORMAL_X); returns the slope —
    computed only when requested (slope or aspect) or ``need_slope``, else 0.

    (cx, cy, cz) is the plane's centroid relative to the query point.
    """
    slope = 0.0
    if need_slope or col[first + 3] >= 0 or col[first + 4] >= 0:
        slope = slope_deg(nz)
    S.put(o, col, first, nx)
    S.put(o, col, first + 1, ny)
    S.put(o, col, first + 2, nz)
    S.put(o, col, first + 3, slope)
    if slope >= 0.1 and col[first + 4] >= 0:
        sg = -1.0 if points_down(nx, ny, nz) else 1.0  # aspect of the up-facing normal
        aspect = math.degrees(math.atan2(sg * nx, sg * ny)) % 360.0
        if np.float32(aspect) >= 360.0:  # just below 360 rounds up to it in float32: [0, 360) is 0 there
            aspect = 0.0
        S.put(o, col, first + 4, aspect)
    S.put(o, col, first + 5, -(cx * nx + cy * ny + cz * nz))
    return slope
