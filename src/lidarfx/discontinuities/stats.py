"""Statistics of axial orientations (poles of planes): Fisher means, κ, α95, joint sets.

Poles of planes are *axial*: ``n`` and ``−n`` are the same plane.  Every function
here takes unit (or not yet unit) normals as an ``(n, 3)`` array and treats them
axially.  Angles are degrees.

* :func:`fisher_stats` — Fisher (1953) statistics of one set: the mean pole,
  the resultant length R, the precision κ = (N − 1) / (N − R) and the 95 %
  confidence cone α95 = arccos(1 − (N − R)/R · (20^{1/(N−1)} − 1)).
* :func:`find_sets` — joint sets found from the data: density peaks of the
  (weighted) poles on the sphere, refined by seeded spherical k-means on axial
  data; the number of sets is the number of peaks that carry at least
  ``min_share`` of the weight (Riquelme et al. 2014 use the same peak-and-cone
  scheme in their Discontinuity Set Extractor).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import LidarfxError, check_int, check_number

__all__ = ["axial_angle", "axial_mean", "check_search_options", "fisher_stats", "find_sets", "SetSearch"]


def _units(normals) -> np.ndarray:
    v = np.asarray(normals, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise LidarfxError("normals must be an (n, 3) array")
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    if np.any(~np.isfinite(norm)) or np.any(norm == 0):
        raise LidarfxError("normals must be finite and non-zero")
    return v / norm


def axial_angle(a, b) -> np.ndarray:
    """Angle (degrees, 0–90) between axes ``a`` and ``b`` (broadcast over rows)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c = np.abs((a * b).sum(axis=-1)) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(c, 0.0, 1.0)))


def axial_mean(normals, weights=None) -> np.ndarray:
    """Principal axis of the orientation tensor Σ w·n·nᵀ, flipped up (n_z ≥ 0)."""
    v = _units(normals)
    w = np.ones(len(v)) if weights is None else np.asarray(weights, dtype=np.float64)
    if len(v) == 0:
        raise LidarfxError("no normals to average")
    t = (v * w[:, None]).T @ v
    _, vec = np.linalg.eigh(t)
    m = vec[:, -1]
    return -m if m[2] < 0 else m


def fisher_stats(normals, weights=None, *, confidence: float = 0.95) -> dict:
    """Fisher statistics of one set of poles, treated axially.

    Each pole is flipped into the hemisphere of the set's axial mean, then
    ``R = |Σ w·n|``, the mean is ``Σ w·n / R`` (flipped up), ``kappa = (N − 1)/(N − R)``
    (∞ when all poles coincide) and ``alpha95`` the semi-angle of the cone of
    confidence (degrees; NaN for N < 2).  ``weights`` (e.g. the areas of the planes)
    are scaled to a mean of 1, so N stays the number of poles; without weights every
    pole counts 1 (Fisher 1953).  Returns ``mean``, ``n``, ``R``, ``kappa``,
    ``alpha95`` and ``spread`` (the angle 63 % of the poles fall within, 81/√κ
    degrees, Fisher's angular standard deviation).
    """
    v = _units(normals)
    n = len(v)
    if n == 0:
        raise LidarfxError("no poles")
    if weights is None:
        w = np.ones(n)
    else:
        w = np.asarray(weights, dtype=np.float64).ravel()
        if len(w) != n or not np.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
            raise LidarfxError("weights need one finite value >= 0 per pole, not all 0")
        w = w * (n / w.sum())
    ref = axial_mean(v, w)
    v = np.where((v @ ref)[:, None] < 0, -v, v)
    s = (v * w[:, None]).sum(axis=0)
    r = float(np.linalg.norm(s))
    mean = s / r
    if mean[2] < 0:
        mean = -mean
    if n < 2:
        return {"mean": mean, "n": n, "R": r, "kappa": math.nan, "alpha95": math.nan, "spread": math.nan}
    gap = max(n - r, 0.0)
    kappa = math.inf if gap <= 1e-12 * n else (n - 1) / gap
    p = 1.0 - confidence
    cos_a = 1.0 - gap / r * ((1.0 / p) ** (1.0 / (n - 1)) - 1.0)
    alpha = math.degrees(math.acos(min(1.0, max(-1.0, cos_a))))
    spread = 0.0 if math.isinf(kappa) else 81.0 / math.sqrt(kappa)
    return {"mean": mean, "n": n, "R": r, "kappa": kappa, "alpha95": alpha, "spread": spread}


@dataclass
class SetSearch:
    """Result of :func:`find_sets`: ``means`` (k, 3) upward unit poles ordered by decreasing
    weight, ``labels`` (n,) set per pole (−1 = outside every cone), ``shares`` (k,) the
    weight share of each set and ``peaks`` the density peaks found before the share test
    (pole, density in multiples of a uniform distribution, share of the weight)."""

    means: np.ndarray
    labels: np.ndarray
    shares: np.ndarray
    peaks: list[dict]


def _density(v: np.ndarray, w: np.ndarray, kappa: float, at: np.ndarray, block: int = 2048) -> np.ndarray:
    """Axial Fisher-kernel density of weighted poles ``v`` at ``at``, in multiples of uniform."""
    out = np.empty(len(at))
    # the axial kernel exp(κ(|c| − 1)) integrates over the sphere to 4π·(1 − e^{−κ})/κ
    norm = w.sum() * (1.0 - math.exp(-kappa)) / kappa
    for a in range(0, len(at), block):
        c = np.abs(at[a:a + block] @ v.T)
        out[a:a + block] = np.exp(kappa * (c - 1.0)) @ w
    return out / norm


def _assign(v: np.ndarray, means: np.ndarray, cone: float) -> np.ndarray:
    if not len(means):
        return np.full(len(v), -1, np.int64)
    c = np.abs(v @ means.T)
    lab = np.argmax(c, axis=1)
    ok = c[np.arange(len(v)), lab] >= math.cos(math.radians(cone))
    return np.where(ok, lab, -1).astype(np.int64)


def check_search_options(*, n_sets=None, bandwidth=8.0, separation=20.0, cone=30.0, min_share=0.02) -> None:
    """The options of :func:`find_sets`, checked (one-line :class:`LidarfxError`)."""
    for name, val, lo, hi in (("bandwidth", bandwidth, 0.1, 45), ("separation", separation, 0.1, 90),
                              ("cone", cone, 0.1, 90), ("min_share", min_share, 0.0, 1.0)):
        check_number(name, val, lo, hi)
    if n_sets is not None:
        check_int("the number of sets", n_sets, 1, 50)


def find_sets(
    normals,
    weights=None,
    *,
    n_sets: int | None = None,
    bandwidth: float = 8.0,
    separation: float = 20.0,
    cone: float = 30.0,
    min_share: float = 0.02,
    max_sets: int = 10,
    max_poles: int = 20000,
    iterations: int = 50,
    seed: int = 0,
) -> SetSearch:
    """Joint sets of weighted poles: density peaks, then seeded spherical k-means (axial).

    1. The density of the poles on the sphere is estimated with an axial Fisher
       kernel of angular width ``bandwidth`` (κ = 1/bandwidth², in radians) at every
       pole (at most ``max_poles`` poles, a seeded weighted sample beyond that).
    2. Peaks: in order of decreasing density, a pole is a peak when no denser
       peak lies within ``separation`` degrees.
    3. Each peak gathers the weight of the poles within ``cone`` degrees that are
       nearer to it than to any other peak; peaks with at least ``min_share`` of the
       total weight seed the sets (at most ``max_sets``; ``n_sets`` forces the
       number: the ``n_sets`` heaviest peaks).
    4. Spherical k-means on axial data: every pole joins the nearest mean within
       ``cone`` (else −1), each mean becomes the weighted principal axis of its
       members; repeated until the labels are stable.  Means that come closer
       than ``separation`` are merged, sets whose share falls below
       ``min_share`` are dropped (not when ``n_sets`` is given), and the
       k-means is run again.
    """
    v = _units(normals)
    w = np.ones(len(v)) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
    if len(w) != len(v):
        raise LidarfxError("weights need one value per normal")
    if np.any(~np.isfinite(w)) or np.any(w < 0):
        raise LidarfxError("weights must be finite and >= 0")
    check_search_options(n_sets=n_sets, bandwidth=bandwidth, separation=separation, cone=cone, min_share=min_share)
    v = np.where(v[:, 2:3] < 0, -v, v)
    if len(v) == 0 or w.sum() <= 0:
        return SetSearch(np.zeros((0, 3)), np.full(len(v), -1, np.int64), np.zeros(0), [])
    kappa = 1.0 / math.radians(bandwidth) ** 2
    if len(v) > max_poles:
        rng = np.random.default_rng(seed)
        pick = rng.choice(len(v), size=max_poles, replace=True, p=w / w.sum())
        sv, sw = v[pick], np.ones(max_poles) * (w.sum() / max_poles)
    else:
        sv, sw = v, w
    dens = _density(sv, sw, kappa, sv)
    # peaks by non-maximum suppression (ties broken by index: deterministic)
    order = np.lexsort((np.arange(len(sv)), -dens))
    cos_sep = math.cos(math.radians(separation))
    peaks: list[int] = []
    for i in order:
        if peaks and np.max(np.abs(sv[peaks] @ sv[i])) >= cos_sep:
            continue
        peaks.append(int(i))
        if len(peaks) >= 200:
            break
    pk = sv[peaks]
    lab = _assign(sv, pk, cone)
    mass = np.bincount(lab[lab >= 0], weights=sw[lab >= 0], minlength=len(peaks)) / sw.sum()
    peak_records = [{"pole": sv[p].copy(), "density": float(dens[p]), "share": float(mass[k])}
                    for k, p in enumerate(peaks)]
    rank = np.argsort(-mass, kind="stable")
    if n_sets is not None:
        keep = rank[:n_sets]
    else:
        keep = [k for k in rank if mass[k] >= min_share][:max_sets]
    means = pk[np.asarray(keep, dtype=np.int64)] if len(keep) else np.zeros((0, 3))

    total = w.sum()
    labels = _assign(v, means, cone)
    for _ in range(max(1, int(iterations))):
        new_means = []
        for k in range(len(means)):
            m = labels == k
            if m.any() and w[m].sum() > 0:
                new_means.append(axial_mean(v[m], w[m]))
        means = np.array(new_means).reshape(-1, 3)
        # merge means closer than the separation (keep the heavier)
        shares = np.array([w[_assign(v, means, cone) == k].sum() / total for k in range(len(means))])
        order_m = np.argsort(-shares, kind="stable")
        kept: list[int] = []
        for k in order_m:
            if any(axial_angle(means[k], means[j]) < separation for j in kept):
                continue
            if n_sets is None and shares[k] < min_share:
                continue
            kept.append(int(k))
        means = means[kept] if kept else np.zeros((0, 3))
        new_labels = _assign(v, means, cone)
        if np.array_equal(new_labels, labels) and len(kept) == len(order_m):
            break
        labels = new_labels
    shares = np.array([w[labels == k].sum() / total for k in range(len(means))])
    order_m = np.argsort(-shares, kind="stable")
    means = means[order_m] if len(means) else means
    labels = _assign(v, means, cone)
    shares = np.array([w[labels == k].sum() / total for k in range(len(means))])
    means = np.where(means[:, 2:3] < 0, -means, means) if len(means) else means
    return SetSearch(means, labels, shares, peak_records)
