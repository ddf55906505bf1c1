"""Eigen features of the local covariance (structure tensor).

Closed-form symmetric 3×3 eigen solve (trigonometric eigenvalues; robust
eigenvectors after D. Eberly, "A Robust Eigensolver for 3×3 Symmetric
Matrices", 2014) and the per-point eigen / Westin feature formulas of
docs/features.md §3.  Everything here is a numba function on scalars: the fused scan
kernel in :mod:`lidarfx.features.engine` calls it once per point and scale.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from . import slots as S

# conventions (see docs/features.md)
CONV_DEFAULT = 0  # docs/features.md §3: normalised eigenvalues for omnivariance / eigenentropy
CONV_CLOUDCOMPARE = 1  # CloudCompare / jakteristics: raw eigenvalues for omnivariance / eigenentropy
CONV_PDAL = 2  # PDAL (SQRT mode) / pgeof: square roots of the eigenvalues in the ratio features
CONVENTIONS = {"default": CONV_DEFAULT, "cloudcompare": CONV_CLOUDCOMPARE, "pdal": CONV_PDAL}


@nb.njit(cache=True, inline="always")
def _unit_cross_best(r0x, r0y, r0z, r1x, r1y, r1z, r2x, r2y, r2z):
    """Unit vector along the largest of the three cross products of the rows, and
    whether one exists (False when all vanish)."""
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
        return 0.0, 0.0, 0.0, False
    s = 1.0 / math.sqrt(d)
    return x * s, y * s, z * s, True


@nb.njit(cache=True, inline="always")
def _orthogonal_pair(wx, wy, wz):
    """Unit u, v with (u, v, w) orthonormal, as two 3-tuples."""
    if abs(wx) > abs(wy):
        inv = 1.0 / math.sqrt(wx * wx + wz * wz)
        ux, uy, uz = -wz * inv, 0.0, wx * inv
    else:
        inv = 1.0 / math.sqrt(wy * wy + wz * wz)
        ux, uy, uz = 0.0, wz * inv, -wy * inv
    return (ux, uy, uz), (wy * uz - wz * uy, wz * ux - wx * uz, wx * uy - wy * ux)


@nb.njit(cache=True, inline="always")
def _rayleigh(a00, a01, a02, a11, a12, a22, x, y, z):
    """xᵀ A x for a unit vector x."""
    return a00 * x * x + a11 * y * y + a22 * z * z + 2.0 * (a01 * x * y + a02 * x * z + a12 * y * z)


@nb.njit(cache=True, inline="always", error_model="numpy")
def eigh3_normal(a00, a01, a02, a11, a12, a22):
    """Eigenvalues λ1 ≥ λ2 ≥ λ3 and the unit eigenvector of λ3 of a symmetric
    (positive semi-definite) 3×3 matrix: ``(l1, l2, l3, nx, ny, nz, ok)``.

    The normal-only path of :func:`eigh3`, written for a short dependency chain:
    no rescaling, det(A − qI) computed alongside the square root, no
    divisions by constants.  λ3 is the Rayleigh quotient of the eigenvector.
    ``ok`` is False when λ3 is not the best separated eigenvalue (line-like
    matrices, λ2 ≈ λ3): the eigenvector of λ3 is then ill-conditioned from the
    rows of A − λ3 I and :func:`eigh3` takes Eberly's path (λ1's vector first).
    """
    q = (a00 + a11 + a22) * (1.0 / 3.0)
    b00 = a00 - q
    b11 = a11 - q
    b22 = a22 - q
    p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) * (1.0 / 6.0)
    detb = b00 * (b11 * b22 - a12 * a12) - a01 * (a01 * b22 - a12 * a02) + a02 * (a01 * a12 - b11 * a02)
    if not (p2 > 1e-30 * (q * q) and p2 > 0.0):
        # a multiple of the identity (or NaN input: q is NaN then)
        lq = max(q, 0.0) if q == q else q
        return lq, lq, lq, 0.0, 0.0, 1.0, True
    p = math.sqrt(p2)
    half_det = min(max(0.5 * detb / (p2 * p), -1.0), 1.0)
    if half_det >= 0.0:
        return q, q, q, 0.0, 0.0, 1.0, False
    cphi = math.cos(math.acos(half_det) * (1.0 / 3.0))
    sphi = math.sqrt(max(1.0 - cphi * cphi, 0.0))  # phi in [0, pi/3]
    # roots 2cos(phi + 2πk/3): the largest, the smallest (k = 1) and the middle one
    beta2 = 2.0 * cphi
    beta0 = -cphi - 1.7320508075688772 * sphi
    beta1 = -(beta0 + beta2)
    e_lo = q + p * beta0
    wx, wy, wz, ok = _unit_cross_best(a00 - e_lo, a01, a02, a01, a11 - e_lo, a12, a02, a12, a22 - e_lo)
    if not ok:
        wx, wy, wz = 0.0, 0.0, 1.0
    l3 = min(_rayleigh(a00, a01, a02, a11, a12, a22, wx, wy, wz), q + p * beta1)
    l1 = q + p * beta2
    return max(l1, 0.0), max(3.0 * q - l1 - l3, 0.0), max(l3, 0.0), wx, wy, wz, True


@nb.njit(cache=True, error_model="numpy")
def eigh3(a00, a01, a02, a11, a12, a22, lam, v1, v3, want_v1=True):
    """Eigen-decomposition of a symmetric 3×3 matrix.

    Writes eigenvalues λ1 ≥ λ2 ≥ λ3 into ``lam`` (tiny negatives clipped to 0),
    the unit eigenvector of λ3 into ``v3`` and, with ``want_v1``, the one of λ1
    into ``v1`` (v2 = v3 × v1).  Without ``want_v1`` the solve is
    :func:`eigh3_normal` (about 40 % cheaper) wherever that is well conditioned,
    and ``v1`` is then left untouched.  Eigenvalues come from the trigonometric
    solution of the characteristic cubic, eigenvectors from Eberly's robust
    construction, and the final eigenvalues are the Rayleigh quotients of the
    eigenvectors (error O(eps²) instead of the O(eps·λ1) of the cubic, which
    matters for λ3 ≈ 0 on planes).
    """
    if not want_v1:
        l1, l2, l3, nx, ny, nz, ok = eigh3_normal(a00, a01, a02, a11, a12, a22)
        if ok:
            lam[0], lam[1], lam[2], v3[0], v3[1], v3[2] = l1, l2, l3, nx, ny, nz
            return
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
    p = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0)
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
    half_det = min(max(half_det, -1.0), 1.0)
    phi = math.acos(half_det) / 3.0
    cphi = math.cos(phi)
    sphi = math.sqrt(max(1.0 - cphi * cphi, 0.0))  # phi in [0, pi/3]
    # roots 2cos(phi + 2πk/3): the largest, the smallest (k = 1) and the middle one
    beta2 = 2.0 * cphi
    beta0 = -cphi - 1.7320508075688772 * sphi
    beta1 = -(beta0 + beta2)
    e_mid = q + p * beta1
    # first the eigenvector of the best separated eigenvalue
    first_is_hi = half_det >= 0.0
    e0 = q + p * (beta2 if first_is_hi else beta0)
    wx, wy, wz, ok = _unit_cross_best(a00 - e0, a01, a02, a01, a11 - e0, a12, a02, a12, a22 - e0)
    if not ok:
        wx, wy, wz = (1.0, 0.0, 0.0) if first_is_hi else (0.0, 0.0, 1.0)
    # then the middle eigenvector inside the plane orthogonal to w: the null vector
    # (q, −p) of the larger row (p, q) of the singular 2×2 matrix (A − e_mid I) on (u, v)
    (ux, uy, uz), (vx, vy, vz) = _orthogonal_pair(wx, wy, wz)
    aux = a00 * ux + a01 * uy + a02 * uz
    auy = a01 * ux + a11 * uy + a12 * uz
    auz = a02 * ux + a12 * uy + a22 * uz
    avx = a00 * vx + a01 * vy + a02 * vz
    avy = a01 * vx + a11 * vy + a12 * vz
    avz = a02 * vx + a12 * vy + a22 * vz
    m00 = ux * aux + uy * auy + uz * auz - e_mid
    m01 = ux * avx + uy * avy + uz * avz
    m11 = vx * avx + vy * avy + vz * avz - e_mid
    if abs(m00) >= abs(m11):
        rp, rq = m00, m01
    else:
        rp, rq = m01, m11
    mm = max(abs(rp), abs(rq))
    if mm > 0.0:
        rp /= mm
        rq /= mm
        s = 1.0 / math.sqrt(rp * rp + rq * rq)
        mx_, my_, mz_ = (rq * ux - rp * vx) * s, (rq * uy - rp * vy) * s, (rq * uz - rp * vz) * s
    else:
        mx_, my_, mz_ = ux, uy, uz
    # third = first × mid
    tx = wy * mz_ - wz * my_
    ty = wz * mx_ - wx * mz_
    tz = wx * my_ - wy * mx_
    if first_is_hi:
        v1[0], v1[1], v1[2] = wx, wy, wz
        v3[0], v3[1], v3[2] = tx, ty, tz
    else:
        v3[0], v3[1], v3[2] = wx, wy, wz
        v1[0], v1[1], v1[2] = -tx, -ty, -tz
    lam[0] = max(_rayleigh(a00, a01, a02, a11, a12, a22, v1[0], v1[1], v1[2]) * mx, 0.0)
    lam[1] = max(_rayleigh(a00, a01, a02, a11, a12, a22, mx_, my_, mz_) * mx, 0.0)
    lam[2] = max(_rayleigh(a00, a01, a02, a11, a12, a22, v3[0], v3[1], v3[2]) * mx, 0.0)


@nb.njit(cache=True, error_model="numpy", inline="always")
def eigen_features(lam, v3z, convention, col, out):
    """Write the eigen and Westin features (docs/features.md §3) for eigenvalues ``lam``.

    ``v3z`` is the z component of the normal (for verticality); ``col`` maps
    feature slots to output columns (-1 = not requested).  Inlined into the
    kernels; divisions by λ1 and Σλ are one reciprocal each.
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
    il1 = 1.0 / l1
    itot = 1.0 / tot
    e1, e2, e3 = l1 * itot, l2 * itot, l3 * itot
    S.put(out, col, S.LINEARITY, (l1 - l2) * il1)
    S.put(out, col, S.PLANARITY, (l2 - l3) * il1)
    S.put(out, col, S.SPHERICITY, l3 * il1)
    S.put(out, col, S.ANISOTROPY, (l1 - l3) * il1)
    S.put(out, col, S.SURFACE_VARIATION, e3)
    want_omni = col[S.OMNIVARIANCE] >= 0
    want_ent = col[S.EIGENENTROPY] >= 0
    if want_omni or want_ent:
        if convention == CONV_CLOUDCOMPARE:
            a1, a2, a3 = l1, l2, l3
        else:
            a1, a2, a3 = e1, e2, e3
        # one logarithm per eigenvalue serves both (0·ln 0 = 0; a zero makes omnivariance 0)
        g1 = math.log(a1) if a1 > 0.0 else 0.0
        g2 = math.log(a2) if a2 > 0.0 else 0.0
        g3 = math.log(a3) if a3 > 0.0 else 0.0
        if want_omni:
            omni = math.exp((g1 + g2 + g3) * (1.0 / 3.0)) if (a1 > 0.0 and a2 > 0.0 and a3 > 0.0) else 0.0
            S.put(out, col, S.OMNIVARIANCE, omni)
        if want_ent:
            S.put(out, col, S.EIGENENTROPY, -(a1 * g1 + a2 * g2 + a3 * g3))
    if l1 > l3:
        S.put(out, col, S.SFFI_X, (l1 - l2) / (l1 - l3))
    S.put(out, col, S.SFFI_Y, l3 * il1)
    S.put(out, col, S.WESTIN_LINEAR, e1 - e2)
    S.put(out, col, S.WESTIN_PLANAR, 2.0 * (e2 - e3))
    S.put(out, col, S.WESTIN_SPHERICAL, 3.0 * e3)
