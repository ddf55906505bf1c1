"""numba kernel behind :func:`lidarfx.geometry.group_hull_areas` (loaded on first use)."""
from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _cross(ox, oy, ax, ay, bx, by):
    return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox)


@nb.njit(cache=True)
def hull_areas(x, y, starts, ends):
    """Convex-hull area of each run ``[starts[g], ends[g])`` of points sorted by (x, y)
    inside the run (Andrew's monotone chain, then the shoelace formula)."""
    out = np.zeros(starts.shape[0])
    hx = np.empty(0)
    hy = np.empty(0)
    for g in range(starts.shape[0]):
        s, e = starts[g], ends[g]
        m = e - s
        if m < 3:
            continue
        if hx.shape[0] < 2 * m + 1:
            hx = np.empty(2 * m + 1)
            hy = np.empty(2 * m + 1)
        h = 0
        for i in range(s, e):  # lower hull
            while h >= 2 and _cross(hx[h - 2], hy[h - 2], hx[h - 1], hy[h - 1], x[i], y[i]) <= 0.0:
                h -= 1
            hx[h] = x[i]
            hy[h] = y[i]
            h += 1
        lower = h + 1
        for i in range(e - 2, s - 1, -1):  # upper hull
            while h >= lower and _cross(hx[h - 2], hy[h - 2], hx[h - 1], hy[h - 1], x[i], y[i]) <= 0.0:
                h -= 1
            hx[h] = x[i]
            hy[h] = y[i]
            h += 1
        a = 0.0  # the last vertex repeats the first
        for i in range(h - 1):
            a += hx[i] * hy[i + 1] - hx[i + 1] * hy[i]
        out[g] = 0.5 * abs(a)
    return out
