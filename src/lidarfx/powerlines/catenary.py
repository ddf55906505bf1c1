"""One catenary per conductor and span, fitted robustly (docs/powerlines.md).

Frame (the convention of every catenary in lidarfx, also :mod:`lidarfx.synth.powerline`):
``s`` is the horizontal distance from the conductor's start attachment point
along its straight plan-view chord, and ``z(s) = c + a · cosh((s − s0) / a)``;
``a`` (m) = horizontal tension / weight per metre, ``s0`` the vertex position,
``c + a`` the vertex height.

The fit works in a tangent parametrisation around a reference position
``s_r`` (the median ``s``): height ``h``, slope ``m`` and curvature ``u = 1/a``
there,

    z(s) = h + 2 · sinh(t + x·u/2) · sinh(x·u/2) / u,   t = asinh(m),  x = s − s_r,

which is exactly the catenary for ``u > 0`` and tends to the straight line
``h + m·x`` as ``u → 0``: all three parameters are well scaled even for the
nearly straight curve of a short or tight span, where ``a``, ``s0`` and ``c``
run off to infinity.  Start: a least-squares parabola (``u = 2·p2``) with a
3-σ (MAD) trim; then Levenberg–Marquardt (``scipy.optimize.least_squares``,
``method="lm"``) on residuals weighted by Tukey's biweight (c = 4.685 σ, σ from
the MAD, floored at ``sigma_floor``), iterated until the weights settle
(iteratively reweighted LM: MINPACK's LM itself has no robust loss).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import LidarfxError

__all__ = ["CatenaryFit", "catenary_through", "catenary_z", "fit_catenary", "tangent_z"]

TUKEY_C = 4.685
MAD_TO_SIGMA = 1.4826


def tangent_z(s: np.ndarray, h: float, m: float, u: float, s_ref: float) -> np.ndarray:
    """Heights of the catenary in tangent form (module docstring) at ``s``."""
    x = np.asarray(s, dtype=np.float64) - s_ref
    t = math.asinh(m)
    half = 0.5 * x * u
    if abs(u) < 1e-12:
        return h + 2.0 * np.sinh(t + half) * (0.5 * x)
    return h + 2.0 * np.sinh(t + half) * np.sinh(half) / u


def catenary_z(s: np.ndarray, a: float, s0: float, c: float) -> np.ndarray:
    """``z(s) = c + a · cosh((s − s0) / a)``."""
    return c + a * np.cosh((np.asarray(s, dtype=np.float64) - s0) / a)


def catenary_through(z_start: float, z_end: float, length: float, a: float) -> tuple[float, float]:
    """``(s0, c)`` of the catenary with parameter ``a`` through (0, z_start) and (length, z_end).

    Closed form: ``z_end − z_start = 2a sinh((L − 2 s0)/(2a)) sinh(L/(2a))``.
    """
    if length <= 0 or a <= 0:
        raise LidarfxError("catenary needs length > 0 and a > 0")
    s0 = length / 2.0 - a * math.asinh((z_end - z_start) / (2.0 * a * math.sinh(length / (2.0 * a))))
    c = z_start - a * math.cosh(s0 / a)
    return s0, c


@dataclass
class CatenaryFit:
    """A fitted catenary ``z(s)`` over ``s_min … s_max`` (tangent parameters and derived ones).

    ``a``, ``s0``, ``c`` are in the frame of the caller's ``s`` (infinite ``a`` and NaN
    ``s0``, ``c`` when the curve is not convex: ``u ≤ 0``).  ``rmse`` is the RMS of the
    vertical residuals of the inliers (Tukey weight > 0), ``rmse_all`` of all points,
    ``sigma`` the robust (MAD) scale, ``inliers`` a boolean mask of the points.
    """

    h: float
    m: float
    u: float
    s_ref: float
    s_min: float
    s_max: float
    rmse: float
    rmse_all: float
    sigma: float
    n: int
    inliers: np.ndarray

    @property
    def convex(self) -> bool:
        return self.u > 0

    @property
    def a(self) -> float:
        return 1.0 / self.u if self.u > 0 else math.inf

    @property
    def s0(self) -> float:
        return self.s_ref - self.a * math.asinh(self.m) if self.u > 0 else math.nan

    @property
    def c(self) -> float:
        return self.h - self.a * math.sqrt(1.0 + self.m * self.m) if self.u > 0 else math.nan

    def z(self, s: np.ndarray) -> np.ndarray:
        return tangent_z(s, self.h, self.m, self.u, self.s_ref)

    def slope(self, s: np.ndarray) -> np.ndarray:
        """dz/ds = sinh(t + x·u)."""
        x = np.asarray(s, dtype=np.float64) - self.s_ref
        return np.sinh(math.asinh(self.m) + x * self.u)

    def shifted(self, ds: float) -> "CatenaryFit":
        """The same curve in the frame ``s' = s − ds``."""
        return CatenaryFit(self.h, self.m, self.u, self.s_ref - ds, self.s_min - ds, self.s_max - ds, self.rmse,
                           self.rmse_all, self.sigma, self.n, self.inliers)


def _parabola(s: np.ndarray, z: np.ndarray, s_ref: float, scale: float) -> np.ndarray:
    x = (s - s_ref) / scale
    keep = np.ones(len(s), bool)
    coef = np.zeros(3)
    for _ in range(3):
        if keep.sum() < 3:
            break
        coef = np.polyfit(x[keep], z[keep], 2)
        r = z - np.polyval(coef, x)
        sig = max(MAD_TO_SIGMA * float(np.median(np.abs(r[keep] - np.median(r[keep])))), 1e-6)
        keep = np.abs(r) <= 3.0 * sig
    p2, p1, p0 = coef
    return np.array([p0, p1 / scale, 2.0 * p2 / scale**2])  # h, m, u at s_ref (parabola: z'' = u)


def fit_catenary(s: np.ndarray, z: np.ndarray, *, sigma_floor: float = 0.01, iterations: int = 8) -> CatenaryFit:
    """Robust catenary ``z(s)`` of the points ``(s, z)`` (module docstring).

    Needs at least 5 points spread over more than zero length.  Raises
    :class:`LidarfxError` otherwise.
    """
    from scipy.optimize import least_squares

    s = np.asarray(s, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    if s.shape != z.shape or s.ndim != 1:
        raise LidarfxError("a catenary needs s and z of the same length")
    ok = np.isfinite(s) & np.isfinite(z)
    if ok.sum() < 5:
        raise LidarfxError(f"a catenary needs at least 5 points, got {int(ok.sum())}")
    ss, zz = s[ok], z[ok]
    span = float(ss.max() - ss.min())
    if not span > 0:
        raise LidarfxError("a catenary needs points spread along s")
    s_ref = float(np.median(ss))
    scale = 0.5 * span
    p = _parabola(ss, zz, s_ref, scale)
    # LM in scaled parameters: h, m, u·scale²
    pscale = np.array([1.0, 1.0 / scale, 1.0 / scale**2])

    def resid(q, w):
        h, m, u = q * pscale
        return w * (tangent_z(ss, h, m, u, s_ref) - zz)

    q = p / pscale
    w = np.ones(len(ss))
    sigma = sigma_floor
    for _ in range(int(iterations)):
        sol = least_squares(resid, q, args=(np.sqrt(w),), method="lm", x_scale=1.0)
        q = sol.x
        r = resid(q, np.ones(len(ss)))
        sigma = max(MAD_TO_SIGMA * float(np.median(np.abs(r - np.median(r)))), sigma_floor)
        t = r / (TUKEY_C * sigma)
        w_new = np.where(np.abs(t) < 1.0, (1.0 - t * t) ** 2, 0.0)
        if (w_new > 0).sum() < 5:
            break
        done = np.max(np.abs(w_new - w)) < 1e-3
        w = w_new
        if done:
            break
    h, m, u = (q * pscale).tolist()
    r = tangent_z(ss, h, m, u, s_ref) - zz
    inl_ok = w > 0
    inliers = np.zeros(len(s), bool)
    inliers[np.flatnonzero(ok)[inl_ok]] = True
    rmse = float(np.sqrt(np.mean(r[inl_ok] ** 2))) if inl_ok.any() else math.nan
    return CatenaryFit(h, m, u, s_ref, float(ss.min()), float(ss.max()), rmse, float(np.sqrt(np.mean(r * r))),
                       sigma, int(len(ss)), inliers)
