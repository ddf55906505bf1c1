"""Brute-force numpy reference of the formulas of docs/features.md §3, for one query point at a time.

Deliberately written from those formulas, independently of the numba kernels:
scipy's KD-tree finds neighbours, numpy's eigh does the eigen solve.
"""
from __future__ import annotations

import math

import numpy as np


def neighbours(xyz, p, r, kind="sphere", height=np.inf):
    d = xyz - p
    h2 = d[:, 0] ** 2 + d[:, 1] ** 2
    if kind == "sphere":
        return xyz[h2 + d[:, 2] ** 2 <= r * r]
    return xyz[(h2 <= r * r) & (np.abs(d[:, 2]) <= height)]


def eigen(nb):
    c = nb.mean(axis=0)
    cov = (nb - c).T @ (nb - c) / len(nb)
    w, v = np.linalg.eigh(cov)
    w = np.clip(w[::-1], 0, None)
    v = v[:, ::-1]
    return w, v, c


def features(xyz, p, r, kind="sphere", dmax=0.10, bins=10, height=np.inf):
    """Dict of every neighbourhood feature at query p (NaN where not computable)."""
    nb = neighbours(xyz, p, r, kind, height)
    sph = neighbours(xyz, p, r, "sphere")
    cyl = neighbours(xyz, p, r, "cylinder", height)
    f: dict[str, float] = {}
    n = len(nb)
    f["n_neighbours"] = n
    # density
    f["density_2d"] = len(cyl) / (math.pi * r * r)
    f["density_3d"] = len(sph) / (4 / 3 * math.pi * r**3)
    f["density_ratio"] = f["density_3d"] / f["density_2d"]
    f["neighbour_ratio"] = len(sph) / len(cyl)
    f["echo_ratio"] = 100 * len(sph) / len(cyl)
    # height (cylinder)
    z = cyl[:, 2]
    f["dz_below"] = p[2] - z.min()
    f["dz_above"] = z.max() - p[2]
    f["z_range"] = z.max() - z.min()
    f["z_std"] = z.std()
    # histogram (Lang)
    dh = p[2] - z
    amax = np.abs(dh).max()
    u = dh / amax if amax > 0 else np.zeros_like(dh)
    hist = np.histogram(u, bins=bins, range=(-1, 1))[0].astype(float)
    peaks = []
    for b in range(bins):
        left = b == 0 or hist[b] > hist[b - 1]
        right = b == bins - 1 or hist[b] > hist[b + 1]
        if left and right and hist[b] > 0:
            peaks.append(b)
    f["dh_peaks"] = len(peaks)
    f["dh_peak_distance"] = float(np.mean(np.diff(peaks))) if len(peaks) >= 2 else 0.0
    f["dh_share_above"] = float((dh < 0).mean())
    f["dh_share_below"] = float((dh > 0).mean())
    pr = hist[hist > 0] / len(dh)
    f["dh_entropy"] = float(-(pr * np.log(pr)).sum())
    f["dh_std"] = float(dh.std())
    f["dh_skewness"] = float(((dh - dh.mean()) ** 3).mean() / dh.std() ** 3) if dh.std() > 0 else 0.0
    f["dh_max_bin"] = -1 + (int(np.argmax(hist)) + 0.5) * 2 / bins
    if n == 0:
        return f
    c = nb.mean(axis=0)
    f["centroid_offset"] = float(np.linalg.norm(c - p) / r)
    d = nb - p
    nz = np.any(d != 0, axis=1)
    octs = {(a > 0, b > 0, cc > 0) for a, b, cc in d[nz]}
    f["octant_occupancy"] = len(octs)
    f["z_asymmetry"] = float(((d[:, 2] > 0).sum() - (d[:, 2] < 0).sum()) / n)
    if n < 3:
        return f
    w, v, c = eigen(nb)
    l1, l2, l3 = w
    e = w / w.sum()
    f.update(
        eigenvalue1=l1, eigenvalue2=l2, eigenvalue3=l3, eigenvalue_sum=w.sum(),
        linearity=(l1 - l2) / l1, planarity=(l2 - l3) / l1, sphericity=l3 / l1,
        anisotropy=(l1 - l3) / l1, omnivariance=float(np.prod(e) ** (1 / 3)),
        eigenentropy=float(-sum(x * math.log(x) for x in e if x > 0)),
        surface_variation=e[2], verticality=1 - abs(v[2, 2]),
        sffi_x=(l1 - l2) / (l1 - l3), sffi_y=l3 / l1,
        westin_linear=e[0] - e[1], westin_planar=2 * (e[1] - e[2]), westin_spherical=3 * e[2],
    )
    nrm = v[:, 2] * (1 if v[2, 2] >= 0 else -1)
    f.update(normal_x=nrm[0], normal_y=nrm[1], normal_z=nrm[2])
    f["slope"] = math.degrees(math.acos(min(abs(nrm[2]), 1)))
    f["aspect"] = math.degrees(math.atan2(nrm[0], nrm[1])) % 360 if f["slope"] >= 0.1 else np.nan
    f["plane_distance"] = float((p - c) @ nrm)
    f["plane_std"] = math.sqrt(l3)
    f["plane_inlier_ratio"] = float((np.abs((nb - c) @ nrm) <= dmax).mean())
    s = math.radians(min(f["slope"], 80))
    rr = r / math.cos(s)
    dc = cyl - p
    f["echo_ratio_slope"] = 100 * float((np.einsum("ij,ij->i", dc, dc) <= rr * rr).sum()) / len(cyl)
    if n >= 6:
        v1 = v[:, 0]
        v2 = np.cross(nrm, v1)
        uu, ww, hh = d @ v1, d @ v2, d @ nrm
        A = np.c_[np.ones(n), uu, ww, uu**2, uu * ww, ww**2]
        coef = np.linalg.lstsq(A, hh, rcond=None)[0]
        a, b, cc, dd, ee, ff = coef
        f["quadric_inlier_ratio"] = float((np.abs(hh - A @ coef) <= dmax).mean())
        g2 = 1 + b * b + cc * cc
        H = ((1 + cc * cc) * 2 * dd - 2 * b * cc * ee + (1 + b * b) * 2 * ff) / (2 * g2**1.5)
        K = (4 * dd * ff - ee * ee) / g2**2
        disc = math.sqrt(max(H * H - K, 0))
        f.update(k1=H + disc, k2=H - disc, mean_curvature=H, gauss_curvature=K)
    return f
