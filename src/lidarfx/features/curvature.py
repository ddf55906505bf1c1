"""Quadric curvature (Mandlburger & Briese 2009; docs/features.md §3.9).

In the frame of the local PCA plane (axes v1, v2, normal n; origin at the
query point; coordinates divided by the radius for conditioning) the
neighbours are fitted by least squares with

    h = a + b·u + c·w + d·u² + e·u·w + f·w²

and the principal curvatures k1 ≥ k2 of that graph surface are evaluated at
the query point's footprint (u = w = 0):

    H = ((1+c²)·2d − 2bc·e + (1+b²)·2f) / (2 (1+b²+c²)^{3/2}),
    K = (4df − e²) / (1+b²+c²)²,   k1,2 = H ± √(H² − K)        [1/m]

Signs follow the oriented normal (up, or towards the scanner): a bowl opening
towards the normal (ditch, valley) has positive curvature, a ridge negative.
Fewer than 6 neighbours or a singular fit (points on a line) give NaN.

The same fit gives ``quadric_inlier_ratio``: the share of the neighbours whose
distance from the quadric along the normal is at most ``d_max`` — the
counterpart of ``plane_inlier_ratio`` for a curved or bumpy surface.
"""
from __future__ import annotations

import math

import numba as nb

from . import slots as S


@nb.njit(cache=True)
def solve_sym6(qa, work):
    """Solve the 6×6 normal equations packed in ``qa`` (see ``engine._sum_quadric``).

    Cholesky on the packed upper triangle; the solution goes to work[36:42].
    Returns False when the system is (numerically) singular.
    """
    # unpack into a full matrix in work[0:36]
    t = 0
    for r in range(6):
        for c in range(r, 6):
            work[r * 6 + c] = qa[t]
            work[c * 6 + r] = qa[t]
            t += 1
    tol = 1e-12 * max(work[0], 1e-300)
    for j in range(6):
        d = work[j * 6 + j]
        for k in range(j):
            d -= work[j * 6 + k] * work[j * 6 + k]
        if d <= tol:
            return False
        d = math.sqrt(d)
        work[j * 6 + j] = d
        for i in range(j + 1, 6):
            s = work[i * 6 + j]
            for k in range(j):
                s -= work[i * 6 + k] * work[j * 6 + k]
            work[i * 6 + j] = s / d
    # forward: L y = b ; backward: Lᵀ x = y
    for i in range(6):
        s = qa[21 + i]
        for k in range(i):
            s -= work[i * 6 + k] * work[36 + k]
        work[36 + i] = s / work[i * 6 + i]
    for i in range(5, -1, -1):
        s = work[36 + i]
        for k in range(i + 1, 6):
            s -= work[k * 6 + i] * work[36 + k]
        work[36 + i] = s / work[i * 6 + i]
    return True


@nb.njit(cache=True)
def quadric_curvatures(work, radius, col, out):
    """k1, k2, mean and Gaussian curvature from the solved quadric in ``work[36:42]``
    (:func:`solve_sym6` of the normal equations in coordinates divided by ``radius``)."""
    b = work[37]
    c = work[38]
    # undo the 1/r scaling of coordinates: second-order terms scale by 1/r
    d = work[39] / radius
    e = work[40] / radius
    f = work[41] / radius
    g2 = 1.0 + b * b + c * c
    hm = ((1.0 + c * c) * 2.0 * d - 2.0 * b * c * e + (1.0 + b * b) * 2.0 * f) / (2.0 * g2 ** 1.5)
    kg = (4.0 * d * f - e * e) / (g2 * g2)
    disc = math.sqrt(max(hm * hm - kg, 0.0))
    S.put(out, col, S.K1, hm + disc)
    S.put(out, col, S.K2, hm - disc)
    S.put(out, col, S.MEAN_CURVATURE, hm)
    S.put(out, col, S.GAUSS_CURVATURE, kg)
