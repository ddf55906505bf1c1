"""Structure lines (breaklines) of ALS terrain (Mandlburger & Briese 2009; docs/breaklines.md).

Steps of :func:`extract_breaklines`:

1. **Ground points**: the classes given (default 2), else the ground filter.
2. **Curvature**: a quadric per point in a sphere of radius r (the feature
   engine's curvature group) gives the principal curvatures; k_max is the one
   of larger magnitude, k_min the other.
3. **Start points**: |k_max| above the threshold (default: 6 standard deviations
   of k_max — the smaller of its robust spread over the tile and the spread the
   ground noise alone gives, 8σ/(r²√60)) and |k_min| ≤ ``curvature_ratio`` · |k_max|
   — a linear break in slope, not a bump.  Convex breaks (crests, edges:
   k_max < 0) and concave ones (toes, bottoms: k_max > 0) are kept apart.  Each
   start point gets the 2-D direction of the start points of its kind around
   it (principal axis); the strongest come first.
4. **Patch pairs**: around a point p on the line and its direction u, the
   ground points left and right of the line (a gap g either side, patches of
   ``patch_width`` × ``patch_length``) are fitted by planes z = a + b·s + c·t
   (s across, t along the line) by least squares with robust weights:
   Kraus–Pfeifer-style, points far above the plane (vegetation left in the
   ground class) lose their weight fast, points far below slowly.  The two
   planes intersect in the 3-D structure line; its position across the line
   and its height carry σ from the adjustment (the planes' covariances
   propagated), the angle between the planes is the intersection angle.  A pair
   whose points along the line lie off the two planes' ridge (or trough) is
   refused: a third, narrow face lies between them (a ditch bottom).
5. **Growing**: from a start point the patch pair is moved onto the line
   (iterated), then stepped forward and backward by ``step`` along the current
   direction while the intersection angle (≥ ``min_angle``), the point support
   (≥ ``min_points`` per patch), the fit (RMS ≤ ``max_rms``) and a smooth course
   (turn ≤ 30° per step) hold.  Start points within 1.5 point spacings of a line
   of their kind are used up; a start point that fails is retried one spacing to
   either side (it may lie between two close lines).
6. **Narrow faces**: every vertex is tested for a third face between the two planes
   (a ditch bottom or narrow crest a patch pair straddles): the profile across the
   line is fitted as a continuous hinge and a continuous trapezoid (two knots) in a
   window that shrinks until no fourth break lies in it; where the trapezoid wins by
   BIC, with a wide enough middle face meeting both sides at ``min_angle``, runs of
   such vertices are replaced by the face's two edges (:meth:`_Model.narrow_face`).
7. **Post-processing**: parts whose ends meet (within ``join``, directions
   agreeing) are connected, a part running mostly within 1.5 point spacings of a
   longer one of its form is dropped, lines shorter than ``min_length`` dropped, the rest
   thinned by 3-D Douglas–Peucker (``simplify``), keeping each kept vertex's σ and angle.

Optional 2-D approximations (``approximations``: polylines in x, y) replace
step 3: start points are taken along them, every ``step``, with their direction.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numba as nb
import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError, check_int, check_number
from .features.eigen import eigh3
from .vector.polyline import Polyline

__all__ = ["DEFAULTS", "Breaklines", "extract_breaklines", "line_distances"]

DEFAULTS: dict[str, Any] = {
    "radius": None,  # curvature radius; None = about 60 ground points in the circle
    "min_curvature": None,  # 1/m; None = 6 standard deviations of k_max (robust spread, or the noise's)
    "curvature_ratio": 0.5,  # |k_min| <= ratio * |k_max|: a line, not a bump
    # lengths: None = a multiple of the mean point spacing a = 1/sqrt(density) (the value at 4 pts/m², a = 0.5 m)
    "patch_length": None,  # 12 a (6 m) along the line
    "patch_width": None,  # 5 a (2.5 m) across, each side
    "gap": None,  # 0.6 a (0.3 m) either side of the line left out of the patches
    "step": None,  # 4 a (2 m) between vertices
    "min_angle": 8.0,  # degrees between the two planes
    "min_points": 8,  # per patch
    "max_rms": None,  # m; None = 1.3 x the noise of the ground (median plane_std): a patch is one plane
    "min_length": 10.0,  # m (2-D)
    "join": None,  # 8 a (4 m) between ends of parts that are connected
    "simplify": 0.05,  # m, 3-D Douglas-Peucker tolerance
    "classes": (2,),
}
"""Parameters of :func:`extract_breaklines`."""

_MAX_TURN = math.radians(30.0)


@dataclass
class Breaklines:
    """Result of :func:`extract_breaklines`: ``lines`` (:class:`~lidarfx.vector.Polyline`, kind
    ``"breakline"``, world coordinates; attrs ``form`` convex / concave, ``mean_angle``,
    ``mean_sigma_xy``, ``mean_sigma_z`` and per vertex ``sigma_xy``, ``sigma_z``, ``angle``),
    ``ground`` (the ground mask used) and ``meta`` (parameters, counts, timings)."""

    lines: list[Polyline]
    ground: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------- robust patch planes
@nb.njit(cache=True)
def _kp_weights(r: np.ndarray, sig: float) -> np.ndarray:
    """Kraus–Pfeifer-style weights of residuals ``r`` (z − surface): 1 within ±2σ; above
    1/(1 + ((r − 2σ)/σ)⁴), 0 beyond 6σ (off-terrain points); below
    1/(1 + ((|r| − 3σ)/(2σ))²) (the other side of a nearby break)."""
    w = np.ones(len(r))
    for i in range(len(r)):
        ri = r[i]
        if ri > 6.0 * sig:
            w[i] = 0.0
        elif ri > 2.0 * sig:
            x = (ri - 2.0 * sig) / sig
            w[i] = 1.0 / (1.0 + x ** 4)
        elif ri < -3.0 * sig:
            x = (-ri - 3.0 * sig) / (2.0 * sig)
            w[i] = 1.0 / (1.0 + x * x)
    return w


@nb.njit(cache=True)
def _normal3(s, t, z, w):
    """Weighted normal equations of z = a + b·s + c·t."""
    n = np.zeros((3, 3))
    b = np.zeros(3)
    for i in range(len(z)):
        wi, si, ti = w[i], s[i], t[i]
        n[0, 0] += wi
        n[0, 1] += wi * si
        n[0, 2] += wi * ti
        n[1, 1] += wi * si * si
        n[1, 2] += wi * si * ti
        n[2, 2] += wi * ti * ti
        b[0] += wi * z[i]
        b[1] += wi * si * z[i]
        b[2] += wi * ti * z[i]
    n[1, 0], n[2, 0], n[2, 1] = n[0, 1], n[0, 2], n[1, 2]
    return n, b


@nb.njit(cache=True)
def _median(x):
    """The median of a 1-D float array (NaN for none); numba's own np.median costs seconds to compile."""
    n = len(x)
    if n == 0:
        return np.nan
    v = np.sort(x)
    return v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2])


@nb.njit(cache=True)
def _cond3(n):
    """Condition number λmax / λmin of a symmetric positive semi-definite 3×3 matrix (inf when singular)."""
    lam = np.empty(3)
    v = np.empty(3)
    eigh3(n[0, 0], n[0, 1], n[0, 2], n[1, 1], n[1, 2], n[2, 2], lam, v, v, False)
    if not lam[2] > 0.0:
        return np.inf
    return lam[0] / lam[2]


@nb.njit(cache=True)
def _robust_plane_kernel(s, t, z, sigma0, iterations):
    """The adjustment of :func:`_robust_plane`; ``ok`` False where it has no answer."""
    nz = len(z)
    w = np.ones(nz)
    r = np.empty(nz)
    p = np.zeros(3)
    cov = np.zeros((3, 3))
    sig = sigma0
    if iterations < 1 or nz < 3:
        return False, p, cov, np.inf, 0.0, 0.0
    for _ in range(iterations):
        n, b = _normal3(s, t, z, w)
        if _cond3(n) > 1e10:
            return False, p, cov, np.inf, 0.0, 0.0
        _, p = _solve_small(n.copy(), b)
        for i in range(nz):
            r[i] = z[i] - (p[0] + p[1] * s[i] + p[2] * t[i])
        med = _median(r)
        sig = max(sigma0, 1.4826 * _median(np.abs(r - med)))
        w = _kp_weights(r, sig)
    n, b = _normal3(s, t, z, w)
    ne = w.sum()
    if ne < 3 or _cond3(n) > 1e10:
        return False, p, cov, np.inf, ne, 0.0
    wrr = 0.0
    kept_ss = 0.0
    kept = 0
    for i in range(nz):
        wrr += w[i] * r[i] * r[i]
        if r[i] <= 3.0 * sig:  # all but the points above the plane (vegetation): a bent patch shows here
            kept_ss += r[i] * r[i]
            kept += 1
    s0 = max(np.sqrt(wrr / max(ne - 3.0, 1.0)), 1e-6)
    for c in range(3):  # the inverse of n, a column at a time
        e = np.zeros(3)
        e[c] = 1.0
        _, col = _solve_small(n.copy(), e)
        cov[:, c] = col * (s0 * s0)
    rms = np.sqrt(kept_ss / kept) if kept else np.inf
    return True, p, cov, rms, ne, 1.0 - kept / nz


def _robust_plane(s: np.ndarray, t: np.ndarray, z: np.ndarray, sigma0: float, iterations: int = 6):
    """z = a + b·s + c·t by iteratively reweighted least squares.  Weights: 1 within
    ±2σ; above the plane 1/(1 + ((r − 2σ)/σ)⁴), 0 beyond 6σ (off-terrain points);
    below 1/(1 + ((|r| − 3σ)/(2σ))²) (the other side of a nearby break).  σ is
    1.4826 × the median absolute deviation of the residuals, at least ``sigma0``.  Returns ``(params, cov, rms,
    n_effective, share_above)`` or ``None``: ``rms`` over the points not more than 3σ
    above the plane, ``share_above`` the share of those left out."""
    f64 = np.float64
    ok, p, cov, rms, ne, above = _robust_plane_kernel(np.ascontiguousarray(s, f64), np.ascontiguousarray(t, f64),
                                                      np.ascontiguousarray(z, f64), float(sigma0), int(iterations))
    return (p, cov, float(rms), float(ne), float(above)) if ok else None


@nb.njit(cache=True)
def _solve_small(a, b):
    """Solve a·x = b (a small, symmetric positive definite) by Gaussian elimination with
    partial pivoting, in place; ``ok`` False on a vanishing pivot."""
    m = len(b)
    for c in range(m):
        piv = c
        for r_ in range(c + 1, m):
            if abs(a[r_, c]) > abs(a[piv, c]):
                piv = r_
        if abs(a[piv, c]) < 1e-300:
            return False, b
        if piv != c:
            for k in range(m):
                a[c, k], a[piv, k] = a[piv, k], a[c, k]
            b[c], b[piv] = b[piv], b[c]
        for r_ in range(c + 1, m):
            f = a[r_, c] / a[c, c]
            for k in range(c, m):
                a[r_, k] -= f * a[c, k]
            b[r_] -= f * b[c]
    x = np.zeros(m)
    for c in range(m - 1, -1, -1):
        acc = b[c]
        for k in range(c + 1, m):
            acc -= a[c, k] * x[k]
        x[c] = acc / a[c, c]
    return True, x


@nb.njit(cache=True)
def _bisect(a, x, right):
    """np.searchsorted(a, x, "right" if right else "left") for a sorted 1-D ``a``."""
    lo, hi = 0, len(a)
    while lo < hi:
        mid = (lo + hi) // 2
        if a[mid] < x or (right and a[mid] == x):
            lo = mid + 1
        else:
            hi = mid
    return lo


@nb.njit(cache=True)
def _profile_kernel(s, t, z, w, k1, k2, middle):
    """Best knot pair of :func:`_profile_fits`: index (−1: none), parameters, residuals.

    The normal equations of every knot pair come from prefix sums over the points sorted by
    s (left of k1, between, right of k2 are runs of the sorted order): O(1) per pair."""
    n = len(s)
    order = np.argsort(s)
    ss = s[order]
    pre = np.zeros((n + 1, 9))  # w, ws, wt, wss, wst, wtt, wz, wsz, wtz
    for i in range(n):
        j = order[i]
        wi, si, ti, zi = w[j], s[j], t[j], z[j]
        v = (wi, wi * si, wi * ti, wi * si * si, wi * si * ti, wi * ti * ti, wi * zi, wi * si * zi, wi * ti * zi)
        for c in range(9):
            pre[i + 1, c] = pre[i, c] + v[c]
    wzz = 0.0
    for i in range(n):
        wzz += w[i] * z[i] * z[i]
    m = 5 if middle else 4
    tot = pre[n]
    best, best_rss = -1, np.inf
    best_x = np.zeros(m)
    a = np.zeros((m, m))
    b = np.zeros(m)
    for j in range(len(k1)):
        ka, kc = k1[j], k2[j]
        il = _bisect(ss, ka, False)  # s < k1: [0, il)
        ir = _bisect(ss, kc, True)  # s > k2: [ir, n)
        left = pre[il]
        mid = pre[ir] - pre[il]
        right = tot - pre[ir]
        a[:] = 0.0
        a[0, 0], a[0, 1], a[1, 1] = tot[0], tot[2], tot[5]
        a[0, 2] = left[1] - ka * left[0]
        a[1, 2] = left[4] - ka * left[2]
        a[2, 2] = left[3] - 2.0 * ka * left[1] + ka * ka * left[0]
        a[0, 3] = right[1] - kc * right[0]
        a[1, 3] = right[4] - kc * right[2]
        a[3, 3] = right[3] - 2.0 * kc * right[1] + kc * kc * right[0]
        b[0], b[1] = tot[6], tot[8]
        b[2] = left[7] - ka * left[6]
        b[3] = right[7] - kc * right[6]
        if middle:
            d = kc - ka
            a[0, 4] = mid[1] - ka * mid[0] + d * right[0]
            a[1, 4] = mid[4] - ka * mid[2] + d * right[2]
            a[3, 4] = d * (right[1] - kc * right[0])
            a[4, 4] = mid[3] - 2.0 * ka * mid[1] + ka * ka * mid[0] + d * d * right[0]
            b[4] = mid[7] - ka * mid[6] + d * right[6]
        for r_ in range(m):
            a[r_, r_] += 1e-9
            for c in range(r_):
                a[r_, c] = a[c, r_]
        rhs = b.copy()
        ok, x = _solve_small(a, rhs)
        if not ok:
            continue
        rss = wzz
        for c in range(m):
            rss -= x[c] * b[c]
        if rss < best_rss:
            best, best_rss = j, rss
            best_x[:] = x
    res = np.empty(n)
    if best >= 0:
        ka, kc = k1[best], k2[best]
        for i in range(n):
            si = s[i]
            f = best_x[0] + best_x[1] * t[i] + best_x[2] * min(si - ka, 0.0) + best_x[3] * max(si - kc, 0.0)
            if middle:
                f += best_x[4] * (min(max(si, ka), kc) - ka)
            res[i] = z[i] - f
    return best, best_x, res


def _profile_fits(s: np.ndarray, t: np.ndarray, z: np.ndarray, w: np.ndarray, k1: np.ndarray, k2: np.ndarray,
                  middle: bool):
    """Weighted least-squares fits of continuous piecewise-planar profiles across a line,
    z = a + c·t + b₁·min(s − k1, 0) + b₂·max(s − k2, 0) [+ b₃·(clip(s, k1, k2) − k1)], one per knot
    pair (``middle``: the trapezoid, else the hinge with k1 = k2).  Returns the best as
    ``(wrss, k1, k2, params, residuals)`` or ``None``."""
    f64 = np.float64
    k1 = np.ascontiguousarray(k1, f64)
    k2 = np.ascontiguousarray(k2, f64)
    if len(k1) == 0:
        return None
    j, x, r = _profile_kernel(np.ascontiguousarray(s, f64), np.ascontiguousarray(t, f64),
                              np.ascontiguousarray(z, f64), np.ascontiguousarray(w, f64), k1, k2, bool(middle))
    if j < 0:
        return None
    return float(w @ (r * r)), float(k1[j]), float(k2[j]), x, r


def _trapezoid(s, t, z, lim, coarse, fine, wmin, sigma0, max_rms):
    """The narrow-face test of :meth:`_Model.narrow_face` in one window: ``False`` when the hinge
    fits within ``max_rms`` (one break), ``None`` when the trapezoid does not fit within it either
    (another break in the window) or loses by BIC, else ``(k1, k2, (left, middle, right slope))``."""
    kv = np.arange(-lim, lim + 1e-9, coarse)
    if len(kv) < 2:
        return None

    def weights(r):
        return _kp_weights(r, max(sigma0, 1.4826 * float(np.median(np.abs(r)))))

    def rms(fit):
        """RMS over all points but those far above (vegetation): a bend the fit misses shows here."""
        r = fit[4]
        kept = r <= 3.0 * max(sigma0, 1.4826 * float(np.median(np.abs(r))))
        return math.sqrt(float((r[kept] ** 2).mean())) if kept.any() else math.inf

    w = np.ones(len(z))
    for _ in range(2):
        v = _profile_fits(s, t, z, w, kv, kv, False)
        if v is None:
            return None
        w = weights(v[4])
    v = _profile_fits(s, t, z, w, kv, kv, False)
    if v is None:
        return None
    if rms(v) <= max_rms:
        return False
    g1, g2 = np.meshgrid(kv, kv, indexing="ij")
    ok = (g2 - g1) >= wmin
    tr = _profile_fits(s, t, z, w, g1[ok], g2[ok], True) if ok.any() else None
    if tr is None:
        return None
    for it in range(2):  # fine grid, then again with weights from the better model's residuals
        if it:
            w = weights(tr[4] if tr[0] < v[0] else v[4])
        v = _profile_fits(s, t, z, w, v[1] + fine, v[1] + fine, False) or v
        g1, g2 = np.meshgrid(tr[1] + fine, tr[2] + fine, indexing="ij")
        ok = (g2 - g1) >= wmin
        tr = (_profile_fits(s, t, z, w, g1[ok], g2[ok], True) or tr) if ok.any() else tr
    ne = float(w.sum())
    if rms(tr) > max_rms or ne < 10:
        return None
    sig = max(sigma0, rms(tr))
    for outer in (s <= -0.75 * lim, s >= 0.75 * lim):  # the outer quarters must not bend away (a fourth break)
        if outer.sum() >= 3:
            mo = float(np.median(tr[4][outer]))
            if abs(mo) > max(0.5 * sig, 2.5 * sig / math.sqrt(outer.sum())):
                return None
    bic_v = ne * math.log(max(v[0], 1e-12) / ne) + 5.0 * math.log(ne)
    bic_t = ne * math.log(max(tr[0], 1e-12) / ne) + 7.0 * math.log(ne)
    if bic_t >= bic_v:
        return None
    x, k1 = tr[3], tr[1]
    return (k1, tr[2], (float(x[2]), float(x[4]), float(x[3])), float(x[1]),
            lambda k: x[0] + x[4] * (min(max(k, k1), tr[2]) - k1))  # the profile's height at t = 0


def _intersect(pa, ca, pb, cb):
    """Line of the planes z = a + b·s + c·t (parameters ``pa``, ``pb``, covariances ``ca``, ``cb``):
    ``(s0, ds/dt, z0, var_s0, var_z0, angle°)`` at t = 0, or ``None`` for (nearly) parallel planes."""
    db = pa[1] - pb[1]
    if abs(db) < 1e-6:
        return None
    da = pa[0] - pb[0]
    s0 = -da / db
    dsdt = -(pa[2] - pb[2]) / db
    z0 = pa[0] + pa[1] * s0
    # error propagation of (s0, z0) from the six plane parameters
    j_s = np.array([-1.0 / db, da / db ** 2, 0.0, 1.0 / db, -da / db ** 2, 0.0])
    j_z = np.array([1.0, s0, 0.0, 0.0, 0.0, 0.0]) + pa[1] * j_s
    cov = np.zeros((6, 6))
    cov[:3, :3], cov[3:, 3:] = ca, cb
    n1 = np.array([-pa[1], -pa[2], 1.0])
    n2 = np.array([-pb[1], -pb[2], 1.0])
    ang = math.degrees(math.acos(min(1.0, abs(n1 @ n2) / (np.linalg.norm(n1) * np.linalg.norm(n2)))))
    return s0, dsdt, z0, float(j_s @ cov @ j_s), float(j_z @ cov @ j_z), ang


@dataclass
class _Vertex:
    xy: np.ndarray
    z: float
    u: np.ndarray
    sigma_xy: float
    sigma_z: float
    angle: float
    support: int
    offset: float


class _Model:
    """Patch pairs on the ground points (local coordinates)."""

    def __init__(self, xyz: np.ndarray, prm: dict[str, Any], sigma0: float, max_rms: float, spacing: float):
        from scipy.spatial import cKDTree

        self.xyz = xyz
        self.spacing = spacing
        self.tree = cKDTree(xyz[:, :2])
        self.prm = prm
        self.sigma0 = sigma0
        self.max_rms = max_rms
        self.reach = math.hypot(prm["patch_length"] / 2.0, prm["gap"] + prm["patch_width"])
        self.widths = [prm["patch_width"] * 0.8 ** k for k in range(7)]  # down to a quarter

    def pair(self, p: np.ndarray, u: np.ndarray) -> _Vertex | None:
        """The structure line near ``p`` along ``u`` from a patch pair, or ``None``."""
        prm = self.prm
        idx = self.tree.query_ball_point(p, self.reach)
        if len(idx) < 2 * prm["min_points"]:
            return None
        q = self.xyz[idx]
        nl = np.array([-u[1], u[0]])
        d = q[:, :2] - p
        t = d @ u
        s = d @ nl
        half = prm["patch_length"] / 2.0
        g = prm["gap"]
        inside = np.abs(t) <= half
        fits = []
        for side in (1.0, -1.0):
            ss = s * side
            fit = None
            for w in self.widths:  # the widest patch that is one plane (narrow ditch bottoms, crests)
                m = inside & (ss >= g) & (ss <= g + w)
                if m.sum() < prm["min_points"]:
                    break
                f = _robust_plane(s[m], t[m], q[m, 2], self.sigma0)
                if f is None or f[3] < prm["min_points"] or f[2] > self.max_rms or f[4] > 0.3:
                    continue
                # one plane: the outer quarter of the patch must not bend away (a second break)
                res = q[m, 2] - (f[0][0] + f[0][1] * s[m] + f[0][2] * t[m])
                outer = ss[m] >= g + 0.75 * w
                sig = max(self.sigma0, f[2])
                if outer.sum() >= 3:
                    mo = float(np.median(res[outer]))
                    if abs(mo) > max(0.5 * sig, 2.5 * sig / math.sqrt(outer.sum())):
                        continue
                fit = (*f, int(m.sum()), w)
                break
            if fit is None:
                return None
            fits.append(fit)
        (pl, cl, _, _, _, nl_pts, wl), (pr, cr, _, _, _, nr_pts, wr) = fits
        x = _intersect(pl, cl, pr, cr)
        if x is None:
            return None
        s0, dsdt, z0, var_s, var_z, ang = x
        if (s0 > 0 and s0 > g + wl / 2.0) or (s0 < 0 and -s0 > g + wr / 2.0):
            return None  # the planes meet outside the gap: the patches straddle another break
        near = inside & (np.abs(s - s0 - dsdt * t) <= max(g, 0.5))
        if near.sum() >= 3:  # the points around the line must lie on the two planes' roof (or trough)
            za = pl[0] + pl[1] * s[near] + pl[2] * t[near]
            zb = pr[0] + pr[1] * s[near] + pr[2] * t[near]
            convex = (pl[0] + pl[1] * (s0 - 1.0)) > (pr[0] + pr[1] * (s0 - 1.0))
            res = q[near, 2] - (np.minimum(za, zb) if convex else np.maximum(za, zb))
            if abs(float(np.median(res))) > 2.0 * max(self.sigma0, 0.02):
                return None  # a third face between the planes (a narrow bottom or crest): not one line
        if ang < prm["min_angle"]:
            return None
        un = u + dsdt * nl
        un = un / np.linalg.norm(un)
        return _Vertex(p + s0 * nl, float(z0), un, math.sqrt(max(var_s, 0.0)), math.sqrt(max(var_z, 0.0)), ang,
                       nl_pts + nr_pts, float(s0))

    def narrow_face(self, p: np.ndarray, u: np.ndarray) -> tuple[_Vertex, _Vertex] | None:
        """A narrow face across the line at ``p`` (direction ``u``): the two edges of a ditch
        bottom or a narrow crest that one patch pair models as a single V, or ``None``.

        The profile across the line, in a window of half-width W, is fitted with robust weights
        as a hinge (one break at knot k) and as a trapezoid (breaks at k1 < k2, a third face
        between), both continuous and piecewise planar, z = a + c·t + piecewise-linear(s), the
        knots on a coarse then a fine grid.  Like the patches, the window shrinks (from
        gap + patch_width, by 0.8, to a quarter) until the trapezoid fits within ``max_rms``,
        so that no fourth break lies in it; nothing is split where the hinge already fits
        within ``max_rms``.  The trapezoid is taken when its BIC is lower, its middle face is
        at least half a point spacing wide and every face holds ``min_points``, and it meets
        both outer faces at ``min_angle`` or more.  Each edge is then the intersection of its
        two faces fitted as planes (σ and angle as for any pair)."""
        prm = self.prm
        big = prm["gap"] + prm["patch_width"]
        idx = self.tree.query_ball_point(p, math.hypot(prm["patch_length"] / 2.0, big))
        if len(idx) < 3 * prm["min_points"]:
            return None
        q = self.xyz[idx]
        nl = np.array([-u[1], u[0]])
        d = q[:, :2] - p
        t0, s0_all = d @ u, d @ nl
        along = np.abs(t0) <= prm["patch_length"] / 2.0
        wmin = max(0.5 * self.spacing, 2.0 * prm["gap"])
        coarse = 0.4 * self.spacing
        f = np.linspace(-coarse, coarse, 11)
        for wk in range(7):
            half_w = prm["gap"] + prm["patch_width"] * 0.8 ** wk
            m = along & (np.abs(s0_all) <= half_w)
            if m.sum() < 3 * prm["min_points"]:
                return None
            fit = _trapezoid(s0_all[m], t0[m], q[m, 2], half_w - 0.5 * self.spacing, coarse, f, wmin,
                             self.sigma0, self.max_rms)
            if fit is None:
                continue  # a fourth break in the window: narrower
            if fit is False:
                return None  # the hinge fits: one break, no third face
            s, t, z = s0_all[m], t0[m], q[m, 2]
            break
        else:
            return None
        k1, k2, slopes, c, z_at = fit
        if any(math.degrees(abs(math.atan(slopes[i]) - math.atan(slopes[i + 1]))) < prm["min_angle"] for i in (0, 1)):
            return None
        band = min(prm["gap"], 0.25 * (k2 - k1))  # the points at a knot belong to either face: left out
        faces = (s < k1 - band, (s > k1 + band) & (s < k2 - band), s > k2 + band)
        planes = []
        for face in faces:
            if face.sum() < prm["min_points"]:
                return None
            pf = _robust_plane(s[face], t[face], z[face], self.sigma0)
            if pf is None:
                return None
            planes.append(pf)
        out = []
        for a, b, k, (b1, b2) in ((planes[0], planes[1], k1, slopes[:2]), (planes[1], planes[2], k2, slopes[1:])):
            x = _intersect(a[0], a[1], b[0], b[1])
            if x is None:
                return None
            _, _, _, var_s, var_z, _ = x  # σ from the two faces fitted apart (each face's own points)
            n1, n2 = np.array([-b1, -c, 1.0]), np.array([-b2, -c, 1.0])
            ang = math.degrees(math.acos(min(1.0, float(n1 @ n2) / float(np.linalg.norm(n1) * np.linalg.norm(n2)))))
            if ang < prm["min_angle"]:
                return None
            out.append(_Vertex(p + k * nl, float(z_at(k)), u.copy(), math.sqrt(max(var_s, 0.0)),
                               math.sqrt(max(var_z, 0.0)), ang, int(len(z)), float(k)))
        return out[0], out[1]

    def settle(self, p: np.ndarray, u: np.ndarray, rounds: int = 4) -> _Vertex | None:
        """Move the patch pair onto the line: intersect, recentre, repeat."""
        v = None
        for _ in range(rounds):
            v = self.pair(p, u)
            if v is None:
                return None
            if abs(v.offset) < 0.02 and abs(float(v.u @ u)) > math.cos(math.radians(1.0)):
                return v
            p, u = v.xy, v.u
        return v

    def grow(self, v0: _Vertex, direction: float, stop) -> list[_Vertex]:
        out: list[_Vertex] = []
        cur = v0
        step = self.prm["step"]
        for _ in range(100_000):
            u = cur.u * direction
            p = cur.xy + step * u
            if stop(p):
                break
            v = self.settle(p, u, rounds=2)
            if v is None:
                break
            if float(v.u @ u) < 0:
                v.u = -v.u
            if math.acos(min(1.0, float(v.u @ u))) > _MAX_TURN:
                break
            lat = float((v.xy - p) @ np.array([-u[1], u[0]]))
            if abs(lat) > step * math.tan(_MAX_TURN):
                break
            if np.linalg.norm(v.xy - cur.xy) < 0.25 * step:
                break  # not advancing
            v.u = v.u * direction
            out.append(v)
            cur = v
        return out


# --------------------------------------------------------------------------- helpers
def _directions(xy: np.ndarray, tree, idx: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """2-D principal direction and elongation λ2/λ1 of the start points within ``radius`` of each."""
    dirs = np.full((len(idx), 2), np.nan)
    ratio = np.full(len(idx), np.inf)
    nb = tree.query_ball_point(xy[idx], radius)
    for k, lst in enumerate(nb):
        if len(lst) < 5:
            continue
        q = xy[lst] - xy[lst].mean(axis=0)
        w, v = np.linalg.eigh(q.T @ q)
        dirs[k] = v[:, 1]
        ratio[k] = w[0] / max(w[1], 1e-12)
    return dirs, ratio


def _near_lines(lines: list[np.ndarray], pts: np.ndarray, dist: float) -> np.ndarray:
    """Points within ``dist`` (2-D) of any of the polylines."""
    from .vector.lines import point_polyline_distance

    near = np.zeros(len(pts), bool)
    if not len(pts):
        return near
    p3 = np.column_stack([pts, np.zeros(len(pts))])
    for ln in lines:
        v = np.column_stack([ln[:, :2], np.zeros(len(ln))]) if len(ln) >= 2 else None
        if v is None:
            continue
        lo, hi = ln[:, :2].min(axis=0) - dist, ln[:, :2].max(axis=0) + dist
        box = np.flatnonzero(np.all((pts >= lo) & (pts <= hi), axis=1) & ~near)
        if len(box):
            near[box[point_polyline_distance(p3[box], v) <= dist]] = True
    return near


def _split_narrow(parts: list[dict], model: _Model) -> tuple[list[dict], int]:
    """Replace the runs of vertices where a part is a V over a narrow face (a ditch bottom, a
    narrow crest: :meth:`_Model.narrow_face`) by that face's two edges.  A vertex's decision
    follows the majority of it and its two neighbours; runs of at least two split vertices
    become two parts of the same form, the rest stays.  Returns the parts and the number of
    vertices split."""
    out: list[dict] = []
    n_split = 0
    for pt in parts:
        v = pt["v"]
        if len(v) < 2:
            out.append(pt)
            continue
        xy = v[:, :2]
        fwd = np.diff(xy, axis=0)
        dirs = np.vstack([fwd[:1], fwd[:-1] + fwd[1:], fwd[-1:]]) if len(v) > 2 else np.vstack([fwd, fwd])
        dirs /= np.maximum(np.linalg.norm(dirs, axis=1, keepdims=True), 1e-12)
        edges = [model.narrow_face(xy[i], dirs[i]) for i in range(len(v))]
        flag = np.array([e is not None for e in edges])
        if not flag.any():
            out.append(pt)
            continue
        vote = flag.astype(int) + np.r_[flag[1:], flag[-1]] + np.r_[flag[0], flag[:-1]]
        flag = (vote >= 2) & np.array([e is not None for e in edges])
        per = pt["support"] / len(v)
        k = 0
        while k < len(v):
            j = k
            while j + 1 < len(v) and flag[j + 1] == flag[k]:
                j += 1
            run = np.arange(k, j + 1)
            if flag[k] and len(run) >= 2:
                n_split += len(run)
                for side in (0, 1):
                    vs = [edges[i][side] for i in run]
                    out.append({"form": pt["form"], "v": np.array([[*e.xy, e.z] for e in vs]),
                                "sxy": np.array([e.sigma_xy for e in vs]), "sz": np.array([e.sigma_z for e in vs]),
                                "ang": np.array([e.angle for e in vs]), "support": int(sum(e.support for e in vs))})
            elif not flag[k]:
                out.append({"form": pt["form"], **{key: pt[key][run] for key in ("v", "sxy", "sz", "ang")},
                            "support": int(per * len(run))})
            k = j + 1
    return out, n_split


def _join(parts: list[dict], join: float) -> list[dict]:
    """Connect parts of one form whose ends are within ``join`` and whose directions agree."""
    parts = list(parts)
    merged = True
    while merged:
        merged = False
        for i in range(len(parts)):
            for j in range(i + 1, len(parts)):
                a, b = parts[i], parts[j]
                if a["form"] != b["form"]:
                    continue
                best = None
                for ra in (False, True):
                    va = a["v"][::-1] if ra else a["v"]
                    for rb in (False, True):
                        vb = b["v"][::-1] if rb else b["v"]
                        gap = float(np.linalg.norm(va[-1, :2] - vb[0, :2]))
                        if gap > join:
                            continue
                        da = va[-1, :2] - va[max(len(va) - 3, 0), :2]
                        db = vb[min(2, len(vb) - 1), :2] - vb[0, :2]
                        if np.linalg.norm(da) == 0 or np.linalg.norm(db) == 0:
                            continue
                        c = float(da @ db) / (np.linalg.norm(da) * np.linalg.norm(db))
                        if c < math.cos(math.radians(30.0)) or (best is not None and gap >= best[0]):
                            continue
                        best = (gap, ra, rb)
                if best is None:
                    continue
                _, ra, rb = best
                sa = slice(None, None, -1) if ra else slice(None)
                sb = slice(None, None, -1) if rb else slice(None)
                parts[i] = {"form": a["form"], **{k: np.concatenate([a[k][sa], b[k][sb]]) for k in ("v", "sxy", "sz", "ang")},
                            "support": a["support"] + b["support"]}
                del parts[j]
                merged = True
                break
            if merged:
                break
    return parts


def _drop_shadowed(parts: list[dict], dist: float) -> list[dict]:
    """Drop a part that runs for more than half its length within ``dist`` (2-D) of a longer part
    of the same form: two lines that close are one line modelled twice (e.g. a V through a
    narrow ditch bottom beside the bottom's own edges)."""
    order = sorted(range(len(parts)), key=lambda i: -_length_2d(parts[i]["v"]))
    kept: list[int] = []
    for i in order:
        v = parts[i]["v"]
        others = [parts[j]["v"] for j in kept if parts[j]["form"] == parts[i]["form"]]
        if others and len(v) >= 2 and _near_lines(others, v[:, :2], dist).mean() > 0.5:
            continue
        kept.append(i)
    return [parts[i] for i in sorted(kept)]


def _length_2d(v: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(v[:, :2], axis=0), axis=1).sum()) if len(v) > 1 else 0.0


# --------------------------------------------------------------------------- main
def check_breakline_options(*, radius: Any = DEFAULTS["radius"], min_curvature: Any = DEFAULTS["min_curvature"],
                            curvature_ratio: Any = DEFAULTS["curvature_ratio"],
                            patch_length: Any = DEFAULTS["patch_length"], patch_width: Any = DEFAULTS["patch_width"],
                            gap: Any = DEFAULTS["gap"], step: Any = DEFAULTS["step"],
                            min_angle: Any = DEFAULTS["min_angle"], min_points: Any = DEFAULTS["min_points"],
                            max_rms: Any = DEFAULTS["max_rms"], min_length: Any = DEFAULTS["min_length"],
                            join: Any = DEFAULTS["join"], simplify: Any = DEFAULTS["simplify"]) -> dict[str, Any]:
    """Every parameter check of :func:`extract_breaklines`, before any work (metres, as given);
    returns the parameters as numbers (None stays None: the data's default)."""
    for name, val, open_lo in (("patch_length", patch_length, True), ("patch_width", patch_width, True),
                               ("gap", gap, False), ("step", step, True), ("join", join, False)):
        if val is not None:
            check_number(name, val, 0.0, 1e4, open_lo=open_lo)
    out = {
        "min_angle": check_number("min_angle", min_angle, 0.0, 90.0, open_lo=False),
        "min_points": check_int("min_points", min_points, 3, 10**6),
        "curvature_ratio": check_number("curvature_ratio", curvature_ratio, 0.0, 1.0, open_lo=True),
        "min_length": check_number("min_length", min_length, 0.0, 1e6, open_lo=False),
        "simplify": check_number("simplify", simplify, 0.0, 1e4, open_lo=False),
        "radius": None if radius is None else check_number("radius", radius, 0.0, 1e4, open_lo=True),
        "min_curvature": None if min_curvature is None else check_number("min_curvature", min_curvature, 0.0, 1e6,
                                                                         open_lo=True),
        "max_rms": None if max_rms is None else check_number("max_rms", max_rms, 0.0, 1e4, open_lo=True),
    }
    return out


def extract_breaklines(
    cloud: PointCloud,
    *,
    radius: float | None = DEFAULTS["radius"],
    min_curvature: float | None = DEFAULTS["min_curvature"],
    curvature_ratio: float = DEFAULTS["curvature_ratio"],
    patch_length: float | None = DEFAULTS["patch_length"],
    patch_width: float | None = DEFAULTS["patch_width"],
    gap: float | None = DEFAULTS["gap"],
    step: float | None = DEFAULTS["step"],
    min_angle: float = DEFAULTS["min_angle"],
    min_points: int = DEFAULTS["min_points"],
    max_rms: float | None = DEFAULTS["max_rms"],
    min_length: float = DEFAULTS["min_length"],
    join: float | None = DEFAULTS["join"],
    simplify: float = DEFAULTS["simplify"],
    classes: Sequence[int] | None = DEFAULTS["classes"],
    approximations: Sequence[Any] | None = None,
    progress: bool | None = None,
    units: str = "auto",
) -> Breaklines:
    """Structure lines of the terrain: 3-D lines where the slope breaks (module docstring).

    ``classes``: ground classes (default 2; the ground filter runs when the cloud has
    none of them; ``None`` = every point is ground).  ``approximations``: optional 2-D
    (or 3-D) polylines near the lines, used instead of the curvature start points.
    The other parameters: :data:`DEFAULTS` and the docs.  ``units="auto"`` (default): the
    lengths are metres (``min_curvature`` 1/m), converted when the LAS header's CRS names another
    linear unit (US survey feet, feet); ``"native"``: coordinate units as given.  ``meta`` and
    the lines' σ are in metres, the vertices in the cloud's coordinates.
    """
    from .crs import metres_per_unit
    from .features import feature_arrays
    from .vector.lines import douglas_peucker

    if not isinstance(cloud, PointCloud):
        raise LidarfxError("extract_breaklines expects a PointCloud (see lidarfx.read)")
    lengths = {"patch_length": (patch_length, 12.0, True), "patch_width": (patch_width, 5.0, True),
               "gap": (gap, 0.6, False), "step": (step, 4.0, True), "join": (join, 8.0, False)}
    c = check_breakline_options(radius=radius, min_curvature=min_curvature, curvature_ratio=curvature_ratio,
                                patch_length=patch_length, patch_width=patch_width, gap=gap, step=step,
                                min_angle=min_angle, min_points=min_points, max_rms=max_rms, min_length=min_length,
                                join=join, simplify=simplify)
    prm = {"min_angle": c["min_angle"], "min_points": c["min_points"]}
    curvature_ratio, min_length, simplify = c["curvature_ratio"], c["min_length"], c["simplify"]
    radius, min_curvature, max_rms = c["radius"], c["min_curvature"], c["max_rms"]
    unit = metres_per_unit(cloud, units)
    if unit != 1.0:  # metres -> coordinate units (curvatures 1/m -> 1/unit)
        lengths = {k: (None if v is None else float(v) / unit, f, o) for k, (v, f, o) in lengths.items()}
        min_length, simplify = min_length / unit, simplify / unit
        radius = None if radius is None else radius / unit
        max_rms = None if max_rms is None else max_rms / unit
        min_curvature = None if min_curvature is None else min_curvature * unit
    approx = None
    if approximations is not None:
        approx = []
        for a in approximations:
            v = np.asarray(getattr(a, "vertices", a), dtype=np.float64)
            if v.ndim != 2 or v.shape[1] < 2 or len(v) < 2 or not np.isfinite(v[:, :2]).all():
                raise LidarfxError("each approximation must be a polyline of at least 2 points (x, y[, z])")
            approx.append(v[:, :2])
    t0 = time.perf_counter()

    # 1. ground
    n = len(cloud)
    if classes is None:
        ground = np.ones(n, bool)
    else:
        cls_codes = [int(c) for c in classes]
        ground = np.isin(np.asarray(cloud["classification"]), cls_codes) if "classification" in cloud else np.zeros(n, bool)
        if not ground.any():
            from .ground import classify_ground

            ground = np.asarray(classify_ground(cloud), bool)
    gi = np.flatnonzero(ground & np.isfinite(cloud.xyz).all(axis=1))
    if len(gi) < 30:
        raise LidarfxError(f"only {len(gi)} ground points; breaklines need a terrain of at least 30 points")
    origin = cloud.xyz[gi].min(axis=0)
    g = cloud.xyz[gi] - origin
    ext = g.max(axis=0) - g.min(axis=0)
    area = max(float(ext[0] * ext[1]), 1e-9)
    rho = len(g) / area
    r = radius if radius is not None else float(f"{math.sqrt(60.0 / (math.pi * rho)):.2g}")
    spacing = 1.0 / math.sqrt(rho)
    for name, (val, factor, _) in lengths.items():
        prm[name] = float(val) if val is not None else float(f"{factor * spacing:.2g}")
    join = prm.pop("join")
    t1 = time.perf_counter()

    # 2. curvature (quadric per point)
    f = feature_arrays(g, ["k1", "k2", "plane_std"], radius=r, progress=progress)
    k1, k2 = np.asarray(f["k1"], np.float64), np.asarray(f["k2"], np.float64)
    big = np.abs(k1) >= np.abs(k2)
    kmax = np.where(big, k1, k2)
    kmin = np.where(big, k2, k1)
    ok = np.isfinite(kmax) & np.isfinite(kmin)
    ps = np.asarray(f["plane_std"], np.float64)
    sigma0 = float(np.nanmedian(ps)) if np.isfinite(ps).any() else 0.05 / unit
    sigma0 = max(sigma0, 0.005 / unit)
    if max_rms is None:  # a patch is one plane when it fits about as well as the ground's noise
        max_rms = 1.3 * sigma0
    if min_curvature is None:
        # 6 standard deviations of k_max, the smaller of: its robust spread over the tile, and the spread
        # the ground noise alone gives a quadric of ~60 points in the radius (8 σ / (r² √n); rough terrain
        # widens the first, a mostly flat tile the second)
        med = float(np.median(kmax[ok])) if ok.any() else 0.0
        mad = float(np.median(np.abs(kmax[ok] - med))) * 1.4826 if ok.any() else 0.0
        min_curvature = 6.0 * min(mad, 8.0 * sigma0 / (r * r * math.sqrt(60.0)))
    t2 = time.perf_counter()

    # 3. start points
    model = _Model(g, prm, 0.5 * sigma0 if sigma0 > 0 else 0.01 / unit, max_rms, spacing)
    from scipy.spatial import cKDTree

    seeds: list[tuple[int, np.ndarray, np.ndarray]] = []  # (form, xy, u)
    start_mask = ok & (np.abs(kmax) >= min_curvature) & (np.abs(kmin) <= curvature_ratio * np.abs(kmax))
    forms = np.where(kmax < 0, 0, 1)  # 0 convex (crest, edge), 1 concave (toe, bottom)
    pools: dict[int, dict[str, Any]] = {}
    if approx is None:
        for form in (0, 1):
            idx = np.flatnonzero(start_mask & (forms == form))
            if not len(idx):
                continue
            xy = g[idx, :2]
            tree = cKDTree(xy)
            order = np.argsort(-np.abs(kmax[idx]), kind="stable")
            dirs, ratio = _directions(xy, tree, np.arange(len(idx)), r)
            good = order[ratio[order] < 0.25]
            pools[form] = {"xy": xy, "used": np.zeros(len(idx), bool), "tree": tree}
            seeds += [(form, k, dirs[k]) for k in good]
    else:
        for a in approx:
            seg = np.diff(a, axis=0)
            for p0, d in zip(a[:-1], seg):
                ln = float(np.linalg.norm(d))
                if ln == 0:
                    continue
                u = d / ln
                for s in np.arange(0.0, ln, prm["step"]):
                    seeds.append((-1, p0 + s * u - origin[:2], u))
    t3 = time.perf_counter()

    # 4. + 5. model and grow
    parts: list[dict] = []
    done: dict[int, list[np.ndarray]] = {0: [], 1: [], -1: []}
    consume = 1.5 * spacing  # start points this close to a line of their kind are used up
    tried = 0
    for form, key, u in seeds:
        if form >= 0:
            pool = pools[form]
            if pool["used"][key]:
                continue
            p = pool["xy"][key]
        else:
            p = key
            if done[-1] and _near_lines(done[-1], p[None, :], consume)[0]:
                continue
        tried += 1
        u = np.asarray(u, dtype=np.float64)
        v0 = None
        for off in (0.0, spacing, -spacing):  # a start point between two close lines: try beside it
            v0 = model.settle(p + off * np.array([-u[1], u[0]]), u)
            if v0 is not None:
                break
        if form >= 0:  # a failed start uses up only its close neighbours: a narrow bottom's lines lie near
            near = pool["tree"].query_ball_point(p, 0.25 * r if v0 is None else 0.5 * r)
            pool["used"][near] = True
        if v0 is None:
            continue
        fwd = model.grow(v0, 1.0, lambda q, f=form: bool(done[f]) and _near_lines(done[f], q[None, :], 0.5 * consume)[0])
        bwd = model.grow(v0, -1.0, lambda q, f=form: bool(done[f]) and _near_lines(done[f], q[None, :], 0.5 * consume)[0])
        verts = bwd[::-1] + [v0] + fwd
        if len(verts) < 2:
            continue
        vx = np.array([[*v.xy, v.z] for v in verts])
        lf = form
        if form < 0:  # approximations: the form from the sign of k_max at the ground points nearest the vertices
            _, near_idx = model.tree.query(vx[:, :2])
            kn = kmax[near_idx]
            lf = 0 if np.nanmedian(kn) < 0 else 1
        part = {"form": lf, "v": vx, "sxy": np.array([v.sigma_xy for v in verts]),
                "sz": np.array([v.sigma_z for v in verts]), "ang": np.array([v.angle for v in verts]),
                "support": int(sum(v.support for v in verts))}
        parts.append(part)
        done[form].append(vx)
        if form >= 0:
            pool["used"] |= _near_lines([vx], pool["xy"], consume)
    t4 = time.perf_counter()

    # 6. post-processing
    parts, n_split = _split_narrow(parts, model)
    parts = _join(parts, join)
    parts = _drop_shadowed(parts, consume)
    lines: list[Polyline] = []
    for pt in parts:
        if _length_2d(pt["v"]) < min_length:
            continue
        keep = douglas_peucker(pt["v"], simplify, return_index=True) if simplify > 0 else np.arange(len(pt["v"]))
        v = pt["v"][keep] + origin
        lines.append(Polyline(
            v, support=pt["support"], rms=math.nan, kind="breakline",
            attrs={"form": "convex" if pt["form"] == 0 else "concave",
                   "mean_angle": round(float(pt["ang"].mean()), 3),
                   "mean_sigma_xy": round(float(pt["sxy"].mean()) * unit, 4),
                   "mean_sigma_z": round(float(pt["sz"].mean()) * unit, 4),
                   "sigma_xy": [round(float(x) * unit, 4) for x in pt["sxy"][keep]],
                   "sigma_z": [round(float(x) * unit, 4) for x in pt["sz"][keep]],
                   "angle": [round(float(x), 3) for x in pt["ang"][keep]]}))
    lines.sort(key=lambda ln: -ln.length_2d)
    t5 = time.perf_counter()
    meta = {
        "points": n, "ground_points": int(len(gi)), "density": rho / (unit * unit),
        "lengths": "m" if units == "auto" else "coordinate units",
        "unit_to_metre": unit if units == "auto" else None,
        "parameters": {**{k: (v * unit if k in lengths else v) for k, v in prm.items()}, "radius": r * unit,
                       "min_curvature": float(min_curvature) / unit, "curvature_ratio": curvature_ratio,
                       "max_rms": float(max_rms) * unit, "min_length": min_length * unit, "join": join * unit,
                       "simplify": simplify * unit,
                       "classes": None if classes is None else [int(c) for c in classes],
                       "approximations": None if approx is None else len(approx)},
        "noise": sigma0 * unit,
        "start_points": int(start_mask.sum()) if approx is None else 0,
        "seeds_tried": tried,
        "parts": len(parts),
        "narrow_face_vertices": n_split,
        "lines": len(lines),
        "total_length": float(sum(ln.length_2d for ln in lines)) * unit,
        "seconds": {"ground": round(t1 - t0, 3), "curvature": round(t2 - t1, 3), "start": round(t3 - t2, 3),
                    "grow": round(t4 - t3, 3), "post": round(t5 - t4, 3)},
    }
    return Breaklines(lines, ground, meta)


def line_distances(lines: Sequence[Any], reference: Sequence[Any], *, step: float = 0.5, within: float = 1.0) -> dict:
    """Compare lines with reference lines (both polylines in x, y, z).

    The reference is densified every ``step``; for each of its points the 3-D and 2-D
    distance to the nearest line and the height difference there are measured, and
    likewise for the lines against the reference.  Returns ``completeness`` (share of the
    reference length within ``within`` (2-D) of a line), ``correctness`` (share of the
    line length within ``within`` of the reference), and over the matched reference
    points: ``rms_xy``, ``rms_z``, ``mean_3d``, ``rms_3d``; ``reference_length``, ``length``.
    """
    from .vector.lines import point_polyline_distance

    def dense(ls):
        out = []
        for ln in ls:
            v = np.asarray(getattr(ln, "vertices", ln), dtype=np.float64)
            for a, b in zip(v[:-1], v[1:]):
                k = max(int(math.ceil(np.linalg.norm(b[:2] - a[:2]) / step)), 1)
                out.append(a + (b - a) * (np.arange(k)[:, None] / k))
            out.append(v[-1:])
        return np.vstack(out) if out else np.zeros((0, 3))

    def nearest(p: np.ndarray, ls) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """2-D distance to the nearest line, the 3-D distance to it, and the height
        difference to the line at the plan-view foot point."""
        d2 = np.full(len(p), np.inf)
        d3 = np.full(len(p), np.inf)
        dz = np.full(len(p), np.nan)
        for ln in ls:
            v = np.asarray(getattr(ln, "vertices", ln), dtype=np.float64)
            a, b = v[:-1], v[1:]
            ab = b[:, :2] - a[:, :2]
            ll = np.maximum((ab * ab).sum(axis=1), 1e-12)
            for lo in range(0, len(p), 4096):
                q = p[lo:lo + 4096]
                t = np.clip(((q[:, None, :2] - a[None, :, :2]) * ab[None]).sum(axis=2) / ll[None], 0.0, 1.0)
                foot = a[None, :, :] + t[:, :, None] * (b - a)[None, :, :]
                dd = np.linalg.norm(q[:, None, :2] - foot[:, :, :2], axis=2)
                k = np.argmin(dd, axis=1)
                best = dd[np.arange(len(q)), k]
                sel = best < d2[lo:lo + 4096]
                rows = np.flatnonzero(sel) + lo
                d2[rows] = best[sel]
                dz[rows] = q[sel, 2] - foot[np.flatnonzero(sel), k[sel], 2]
            d3 = np.minimum(d3, point_polyline_distance(p, v))
        return d2, d3, dz

    ref = dense(reference)
    got = dense(lines)
    out: dict[str, Any] = {"reference_length": float(sum(_length_2d(np.asarray(getattr(r, "vertices", r))) for r in reference)),
                           "length": float(sum(_length_2d(np.asarray(getattr(r, "vertices", r))) for r in lines))}
    if not len(ref) or not len(got):
        return {**out, "completeness": 0.0, "correctness": 0.0, "rms_xy": math.nan, "rms_z": math.nan,
                "mean_3d": math.nan, "rms_3d": math.nan}
    d2, d3, dz = nearest(ref, lines)
    m = d2 <= within
    g2, _, _ = nearest(got, reference)
    out.update(completeness=float(m.mean()), correctness=float((g2 <= within).mean()),
               rms_xy=float(np.sqrt((d2[m] ** 2).mean())) if m.any() else math.nan,
               rms_z=float(np.sqrt((dz[m] ** 2).mean())) if m.any() else math.nan,
               mean_3d=float(d3.mean()), rms_3d=float(np.sqrt((d3 ** 2).mean())),
               mean_3d_matched=float(d3[m].mean()) if m.any() else math.nan)
    return out
