"""Eigen features of the local covariance (structure tensor).

Closed-form symmetric 3×3 eigen solve (trigonometric eigenvalues; robust
eigenvectors after D. Eberly, "A Robust Eigensolver for 3×3 Symmetric
Matrices", 2014) and the per-point eigen / Westin feature formulas of
SPEC §3.  Everything here is a numba function on scalars: the fused scan
kernel in :mod:`lidarfx.features.engine` calls it once per point and scale.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from . import slots as S

# conventions (see docs/features.md)
CONV_DEFAULT = 0  # SPEC table: normalised eigenvalues for omnivariance / eigenentropy
CONV_CLOUDCOMPARE = 1  # CloudCompare / jakteristics: raw eigenvalues for omnivariance / eigenentropy
CONV_PDAL = 2  # PDAL (SQRT mode) / pgeof: square roots of the eigenvalues in the ratio features
CONVENTIONS = {"default": CONV_DEFAULT, "cloudcompare": CONV_CLOUDCOMPARE, "pdal": CONV_PDAL}


@nb.njit(cache=True, inline="always")
def _unit_cross_best(r0x, r0y, r0z, r1x, r1y, r1z, r2x, r2y, r2z, out):
    """Unit vector along the largest of the three cross products of the rows; False if all vanish."""
    ax = r0y * r1z - r0z * r1y
    ay = r0z * r1x - r0x * r1z
    az = r0x * r1y - r0y * r1x
    bx = r0y * r2z - r0z * r2y
    by = r0z * r2x - r0x * r2z
    bz = r0x * r2y - r0y * r2x
    cx = r1y * r2z - r1z * r2y
    cy = r1z * r2x - r1x * r2z
    cz = r1x * r2y - r1y * r2x
    da = ax * ax + ay * ay + az * az
    db = bx * bx + by * by + bz * bz
    dc = cx * cx + cy * cy + cz * cz
    if da >= db and da >= dc:
        d, x, y, z = da, ax, ay, az
    elif db >= dc:
        d, x, y, z = db, bx, by, bz
    else:
        d, x, y, z = dc, cx, cy, cz
    if d <= 0.0:
        return False
    s = 1.0 / math.sqrt(d)
    out[0] = x * s
    out[1] = y * s
    out[2] = z * s
    return True


@nb.njit(cache=True, inline="always")
def _orthogonal_pair(wx, wy, wz, u, v):
    """Unit u, v with (u, v, w) orthonormal."""
    if abs(wx) > abs(wy):
        inv = 1.0 / math.sqrt(wx * wx + wz * wz)
        u[0] = -wz * inv
        u[1] = 0.0
        u[2] = wx * inv
    else:
        inv = 1.0 / math.sqrt(wy * wy + wz * wz)
        u[0] = 0.0
        u[1] = wz * inv
        u[2] = -wy * inv
    v[0] = wy * u[2] - wz * u[1]
    v[1] = wz * u[0] - wx * u[2]
    v[2] = wx * u[1] - wy * u[0]


@nb.njit(cache=True)
def eigh3(a00, a01, a02, a11, a12, a22, lam, v1, v3, work):
    """Eigen-decomposition of a symmetric 3×3 matrix.

    Writes eigenvalues λ1 ≥ λ2 ≥ λ3 into ``lam`` (tiny negatives clipped to 0),
    the unit eigenvector of λ1 into ``v1`` and of λ3 into ``v3`` (v2 = v3 × v1).
    ``work`` is scratch space of at least 12 float64 (no allocation per call).
    """
    mx = max(abs(a00), abs(a01), abs(a02), abs(a11), abs(a12), abs(a22))
    if mx == 0.0 or not np.isfinite(mx):
        lam[0] = lam[1] = lam[2] = 0.0 if mx == 0.0 else np.nan
        v1[0], v1[1], v1[2] = 1.0, 0.0, 0.0
        v3[0], v3[1], v3[2] = 0.0, 0.0, 1.0
        return
    inv = 1.0 / mx
    a00 *= inv
    a01 *= inv
    a02 *= inv
    a11 *= inv
    a12 *= inv
    a22 *= inv
    q = (a00 + a11 + a22) / 3.0
    b00 = a00 - q
    b11 = a11 - q
    b22 = a22 - q
    off = a01 * a01 + a02 * a02 + a12 * a12
    p = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * off) / 6.0)
    if p < 1e-15:
        # a multiple of the identity
        lam[0] = lam[1] = lam[2] = max(q * mx, 0.0)
        v1[0], v1[1], v1[2] = 1.0, 0.0, 0.0
        v3[0], v3[1], v3[2] = 0.0, 0.0, 1.0
        return
    ip = 1.0 / p
    c00 = b00 * ip
    c11 = b11 * ip
    c22 = b22 * ip
    c01 = a01 * ip
    c02 = a02 * ip
    c12 = a12 * ip
    half_det = 0.5 * (c00 * (c11 * c22 - c12 * c12) - c01 * (c01 * c22 - c12 * c02) + c02 * (c01 * c12 - c11 * c02))
    if half_det > 1.0:
        half_det = 1.0
    elif half_det < -1.0:
        half_det = -1.0
    phi = math.acos(half_det) / 3.0
    beta2 = 2.0 * math.cos(phi)
    beta0 = 2.0 * math.cos(phi + 2.0943951023931957)
    beta1 = -(beta0 + beta2)
    e_hi = q + p * beta2
    e_mid = q + p * beta1
    e_lo = q + p * beta0

    w = work[0:3]
    u = work[3:6]
    v = work[6:9]
    # first the eigenvector of the best separated eigenvalue
    first_is_hi = half_det >= 0.0
    e0 = e_hi if first_is_hi else e_lo
    ok = _unit_cross_best(a00 - e0, a01, a02, a01, a11 - e0, a12, a02, a12, a22 - e0, w)
    if not ok:
        w[0], w[1], w[2] = (1.0, 0.0, 0.0) if first_is_hi else (0.0, 0.0, 1.0)
    # then the middle eigenvector inside the plane orthogonal to w
    _orthogonal_pair(w[0], w[1], w[2], u, v)
    # A u, A v
    aux = a00 * u[0] + a01 * u[1] + a02 * u[2]
    auy = a01 * u[0] + a11 * u[1] + a12 * u[2]
    auz = a02 * u[0] + a12 * u[1] + a22 * u[2]
    avx = a00 * v[0] + a01 * v[1] + a02 * v[2]
    avy = a01 * v[0] + a11 * v[1] + a12 * v[2]
    avz = a02 * v[0] + a12 * v[1] + a22 * v[2]
    m00 = u[0] * aux + u[1] * auy + u[2] * auz - e_mid
    m01 = u[0] * avx + u[1] * avy + u[2] * avz
    m11 = v[0] * avx + v[1] * avy + v[2] * avz - e_mid
    # (m00 m01; m01 m11) is singular: the middle eigenvector is the null vector
    # (q, −p) of its larger row (p, q), expressed in the (u, v) basis
    if abs(m00) >= abs(m11):
        p, qq = m00, m01
    else:
        p, qq = m01, m11
    mid = work[9:12]
    mm = max(abs(p), abs(qq))
    if mm > 0.0:
        p /= mm
        qq /= mm
        inv = 1.0 / math.sqrt(p * p + qq * qq)
        for t in range(3):
            mid[t] = (qq * u[t] - p * v[t]) * inv
    else:
        for t in range(3):
            mid[t] = u[t]
    # third = first × mid
    tx = w[1] * mid[2] - w[2] * mid[1]
    ty = w[2] * mid[0] - w[0] * mid[2]
    tz = w[0] * mid[1] - w[1] * mid[0]
    if first_is_hi:
        v1[0], v1[1], v1[2] = w[0], w[1], w[2]
        v3[0], v3[1], v3[2] = tx, ty, tz
    else:
        v3[0], v3[1], v3[2] = w[0], w[1], w[2]
        v1[0], v1[1], v1[2] = -tx, -ty, -tz
    # Rayleigh quotients of the eigenvectors: error O(eps²) instead of the
    # O(eps·λ1) of the trigonometric formula, which matters for λ3 ≈ 0 (planes)
    r1 = _rayleigh(a00, a01, a02, a11, a12, a22, v1[0], v1[1], v1[2])
    r3 = _rayleigh(a00, a01, a02, a11, a12, a22, v3[0], v3[1], v3[2])
    r2 = _rayleigh(a00, a01, a02, a11, a12, a22, mid[0], mid[1], mid[2])
    lam[0] = max(r1 * mx, 0.0)
    lam[1] = max(r2 * mx, 0.0)
    lam[2] = max(r3 * mx, 0.0)


@nb.njit(cache=True, inline="always")
def _rayleigh(a00, a01, a02, a11, a12, a22, x, y, z):
    """xᵀ A x for a unit vector x."""
    return a00 * x * x + a11 * y * y + a22 * z * z + 2.0 * (a01 * x * y + a02 * x * z + a12 * y * z)


@nb.njit(cache=True)
def eigen_features(lam, v3z, convention, col, out):
    """Write the eigen and Westin features (SPEC §3) for eigenvalues ``lam``.

    ``v3z`` is the z component of the normal (for verticality); ``col`` maps
    feature slots to output columns (-1 = not requested).
    """
    l1, l2, l3 = lam[0], lam[1], lam[2]
    S.put(out, col, S.EIGENVALUE1, l1)
    S.put(out, col, S.EIGENVALUE2, l2)
    S.put(out, col, S.EIGENVALUE3, l3)
    S.put(out, col, S.EIGENVALUE_SUM, l1 + l2 + l3)
    S.put(out, col, S.VERTICALITY, 1.0 - abs(v3z))
    if convention == CONV_PDAL:
        l1, l2, l3 = math.sqrt(l1), math.sqrt(l2), math.sqrt(l3)
    tot = l1 + l2 + l3
    if l1 <= 0.0 or tot <= 0.0:
        return  # everything below divides by λ1: leave NaN
    e1, e2, e3 = l1 / tot, l2 / tot, l3 / tot
    S.put(out, col, S.LINEARITY, (l1 - l2) / l1)
    S.put(out, col, S.PLANARITY, (l2 - l3) / l1)
    S.put(out, col, S.SPHERICITY, l3 / l1)
    S.put(out, col, S.ANISOTROPY, (l1 - l3) / l1)
    S.put(out, col, S.SURFACE_VARIATION, e3)
    if convention == CONV_CLOUDCOMPARE:
        a1, a2, a3 = l1, l2, l3
    else:
        a1, a2, a3 = e1, e2, e3
    S.put(out, col, S.OMNIVARIANCE, (a1 * a2 * a3) ** (1.0 / 3.0))
    ent = 0.0
    if a1 > 0.0:
        ent -= a1 * math.log(a1)
    if a2 > 0.0:
        ent -= a2 * math.log(a2)
    if a3 > 0.0:
        ent -= a3 * math.log(a3)
    S.put(out, col, S.EIGENENTROPY, ent)
    if l1 > l3:
        S.put(out, col, S.SFFI_X, (l1 - l2) / (l1 - l3))
    S.put(out, col, S.SFFI_Y, l3 / l1)
    S.put(out, col, S.WESTIN_LINEAR, e1 - e2)
    S.put(out, col, S.WESTIN_PLANAR, 2.0 * (e2 - e3))
    S.put(out, col, S.WESTIN_SPHERICAL, 3.0 * e3)
