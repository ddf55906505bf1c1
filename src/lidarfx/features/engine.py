"""The fused neighbourhood-feature kernel.

For every query point the kernel walks the candidate runs of the sorted grid
(:func:`lidarfx.neighbors.column_ranges`) of the *widest* neighbourhood once —
the largest radius; the whole vertical cylinder when density, height or
histogram features are requested — and compacts the points inside it into a
small per-thread buffer (structure of arrays: dx, dy, dz relative to
the query point; branch-free).  Everything else runs over that buffer, which
sits in L1 cache:

* per scale, the covariance sums of the chosen neighbourhood (sphere or
  cylinder) and the cylinder's counts and z moments, in branch-free loops the
  compiler vectorises;
* a closed-form eigen solve gives eigen, Westin, plane, density and height
  features;
* only when requested: inlier ratio and slope-adaptive echo ratio (a second
  vectorised count once the plane is known), quadric curvature, Lang's
  height-difference histogram and the octant / above-below counts.

So several radii cost one walk of the largest, plus cheap passes over the
buffer.  When the buffer holds a whole cylinder column and there are several
radii, it is first sorted (stably) into horizontal shells, so that the passes
of radius r walk only the points within r (≈ 8 % less feature time for the
classification default on `crop_1.laz`).  The caller passes the query points
in grid order (for a whole cloud: the index's own sorted points), so
consecutive queries share cached neighbours.  Results of a chunk of 256 queries are collected point-major in a
small per-thread tile and copied to the feature-major output at the end of
the chunk (no strided writes to the large output); the caller restores the
original point order afterwards, one feature at a time.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..neighbors import G_DX, G_DY, G_DZ, column_ranges, gather
from . import slots as S
from .curvature import quadric_curvatures, solve_sym6
from .eigen import eigen_features, eigh3
from .histogram import histogram_features
from .plane import orient_normal, points_down, write_plane

KIND_SPHERE = 0
KIND_CYLINDER = 1

# reassociation lets LLVM vectorise the reductions; no NaN/inf assumptions
_FAST = {"reassoc", "contract", "nsz"}

# pass-1 sums: covariance neighbourhood
_N, _SX, _SY, _SZ, _XX, _XY, _XZ, _YY, _YZ, _ZZ = range(10)
# cylinder statistics
_NSPH, _NCYL, _CZMIN, _CZMAX, _CZ, _CZZ, _CZZZ = range(10, 17)
_NACC = 17
# pass-2 counters
_INL, _ECHO, _ABV, _BLW, _CABV, _CBLW = range(6)


# rows of the gathered neighbour buffer (lidarfx.neighbors.gather)
_BX, _BY, _BZ = G_DX, G_DY, G_DZ


@nb.njit(cache=True, inline="always")
def _member(dx, dy, dz, r2, height, cylinder):
    """1.0 if the offset (dx, dy, dz) lies in the sphere of squared radius r2, or with
    ``cylinder`` in the vertical cylinder of that radius and half-height ``height``; else 0.0."""
    h2 = dx * dx + dy * dy
    if cylinder:
        return 1.0 if (h2 <= r2 and abs(dz) <= height) else 0.0
    return 1.0 if h2 + dz * dz <= r2 else 0.0


@nb.njit(cache=True, fastmath=_FAST)
def _sum_cov(buf, cnt, r2, height, cylinder, acc):
    """Covariance sums over the sphere (or cylinder) of squared radius r2."""
    n = sx = sy = sz = xx = xy = xz = yy = yz = zz = 0.0
    for j in range(cnt):
        dx = buf[_BX, j]
        dy = buf[_BY, j]
        dz = buf[_BZ, j]
        w = _member(dx, dy, dz, r2, height, cylinder)
        n += w
        sx += w * dx
        sy += w * dy
        sz += w * dz
        xx += w * dx * dx
        xy += w * dx * dy
        xz += w * dx * dz
        yy += w * dy * dy
        yz += w * dy * dz
        zz += w * dz * dz
    acc[_N] = n
    acc[_SX] = sx
    acc[_SY] = sy
    acc[_SZ] = sz
    acc[_XX] = xx
    acc[_XY] = xy
    acc[_XZ] = xz
    acc[_YY] = yy
    acc[_YZ] = yz
    acc[_ZZ] = zz


@nb.njit(cache=True, fastmath=_FAST)
def _sum_cyl(buf, cnt, r2, height, acc):
    """Sphere count, cylinder count and the cylinder's z moments (relative to the query)."""
    nsph = ncyl = cz = czz = czzz = 0.0
    zmn = 1e300
    zmx = -1e300
    for j in range(cnt):
        dx = buf[_BX, j]
        dy = buf[_BY, j]
        dz = buf[_BZ, j]
        h2 = dx * dx + dy * dy
        nsph += 1.0 if h2 + dz * dz <= r2 else 0.0
        w = 1.0 if (h2 <= r2 and abs(dz) <= height) else 0.0
        ncyl += w
        cz += w * dz
        czz += w * dz * dz
        czzz += w * dz * dz * dz
        off = (1.0 - w) * 1e30  # pushes outside points out of the min / max
        zmn = min(zmn, dz + off)
        zmx = max(zmx, dz - off)
    acc[_NSPH] = nsph
    acc[_NCYL] = ncyl
    acc[_CZMIN] = zmn
    acc[_CZMAX] = zmx
    acc[_CZ] = cz
    acc[_CZZ] = czz
    acc[_CZZZ] = czzz


@nb.njit(cache=True, fastmath=_FAST)
def _count_plane(buf, cnt, r2, height, cylinder, cx, cy, cz, nx_, ny_, nz_, dmax, rr2, acc):
    """Inliers of the local plane (within dmax) among the neighbours, and the
    slope-adaptive echo count: cylinder points within the sphere of squared radius rr2."""
    inl = echo = 0.0
    for j in range(cnt):
        dx = buf[_BX, j]
        dy = buf[_BY, j]
        dz = buf[_BZ, j]
        h2 = dx * dx + dy * dy
        d2 = h2 + dz * dz
        wc = 1.0 if (h2 <= r2 and abs(dz) <= height) else 0.0
        wm = wc if cylinder else (1.0 if d2 <= r2 else 0.0)
        dist = (dx - cx) * nx_ + (dy - cy) * ny_ + (dz - cz) * nz_
        inl += wm * (1.0 if abs(dist) <= dmax else 0.0)
        echo += wc * (1.0 if d2 <= rr2 else 0.0)
    acc[_INL] = inl
    acc[_ECHO] = echo


@nb.njit(cache=True, fastmath=_FAST)
def _sum_quadric(buf, cnt, r2, height, cylinder, v1, v2, nx_, ny_, nz_, r, qa):
    """Normal equations of the local quadric h = a + b u + c w + d u² + e u w + f w² over the
    sphere (or cylinder) of squared radius r2, in the frame v1, v2, n with coordinates divided
    by r: ``qa[0:21]`` the upper triangle of AᵀA row by row, ``qa[21:27]`` Aᵀh.

    AᵀA holds only the 15 moments of u, w up to order 4, so they are summed once each, in a
    branch-free loop that LLVM vectorises.
    """
    inv_r = 1.0 / r
    n = m_u = m_w = m_uu = m_uw = m_ww = 0.0
    m_uuu = m_uuw = m_uww = m_www = 0.0
    m_uuuu = m_uuuw = m_uuww = m_uwww = m_wwww = 0.0
    s_h = s_uh = s_wh = s_uuh = s_uwh = s_wwh = 0.0
    for j in range(cnt):
        dx = buf[_BX, j]
        dy = buf[_BY, j]
        dz = buf[_BZ, j]
        k = _member(dx, dy, dz, r2, height, cylinder)
        kr = k * inv_r  # a point outside the neighbourhood gets u = w = h = 0 and adds nothing
        u = (dx * v1[0] + dy * v1[1] + dz * v1[2]) * kr
        w = (dx * v2[0] + dy * v2[1] + dz * v2[2]) * kr
        h = (dx * nx_ + dy * ny_ + dz * nz_) * kr
        uu = u * u
        uw = u * w
        ww = w * w
        n += k
        m_u += u
        m_w += w
        m_uu += uu
        m_uw += uw
        m_ww += ww
        m_uuu += uu * u
        m_uuw += uu * w
        m_uww += u * ww
        m_www += ww * w
        m_uuuu += uu * uu
        m_uuuw += uu * uw
        m_uuww += uu * ww
        m_uwww += uw * ww
        m_wwww += ww * ww
        s_h += h
        s_uh += u * h
        s_wh += w * h
        s_uuh += uu * h
        s_uwh += uw * h
        s_wwh += ww * h
    # basis (1, u, w, u², uw, w²): entry (r, c) of AᵀA is the moment of basis_r · basis_c
    qa[0] = n
    qa[1] = m_u
    qa[2] = m_w
    qa[3] = m_uu
    qa[4] = m_uw
    qa[5] = m_ww
    qa[6] = m_uu
    qa[7] = m_uw
    qa[8] = m_uuu
    qa[9] = m_uuw
    qa[10] = m_uww
    qa[11] = m_ww
    qa[12] = m_uuw
    qa[13] = m_uww
    qa[14] = m_www
    qa[15] = m_uuuu
    qa[16] = m_uuuw
    qa[17] = m_uuww
    qa[18] = m_uuww
    qa[19] = m_uwww
    qa[20] = m_wwww
    qa[21] = s_h
    qa[22] = s_uh
    qa[23] = s_wh
    qa[24] = s_uuh
    qa[25] = s_uwh
    qa[26] = s_wwh


@nb.njit(cache=True, fastmath=_FAST)
def _count_quadric(buf, cnt, r2, height, cylinder, v1, v2, nx_, ny_, nz_, r, dmax, work):
    """Neighbours within dmax (along the normal) of the solved local quadric (work[36:42],
    coordinates in the frame v1, v2, n divided by r, as in :func:`_sum_quadric`)."""
    inv_r = 1.0 / r
    lim = dmax * inv_r
    a, b, c, d, e, f = work[36], work[37], work[38], work[39], work[40], work[41]
    inl = 0.0
    for j in range(cnt):
        dx = buf[_BX, j]
        dy = buf[_BY, j]
        dz = buf[_BZ, j]
        k = _member(dx, dy, dz, r2, height, cylinder)
        u = (dx * v1[0] + dy * v1[1] + dz * v1[2]) * inv_r
        w = (dx * v2[0] + dy * v2[1] + dz * v2[2]) * inv_r
        h = (dx * nx_ + dy * ny_ + dz * nz_) * inv_r
        res = h - (a + b * u + c * w + d * u * u + e * u * w + f * w * w)
        inl += k * (1.0 if abs(res) <= lim else 0.0)
    return inl


@nb.njit(cache=True, nogil=True)
def point_features(
    start,  # first row of q to process
    stop,  # one past the last row
    pts, cstart, cend, ckey, table, nx, ny, cell,  # the grid (lidarfx.neighbors.Grid)
    q,  # (m, 3) query points, local coordinates, in grid order
    rad,  # (1 or m, S) radii per scale, ascending (one per point for kNN)
    kind,  # KIND_SPHERE / KIND_CYLINDER: neighbourhood of the covariance features
    height,  # half-height of the cylinder (inf = unbounded)
    scanner,  # (3,) scanner position (local) for normal orientation
    has_scanner,
    col,  # (NSLOTS,) slot -> output column or -1
    convention,
    dmax,  # inlier distance for plane_inlier_ratio
    nbins,  # histogram bins
    need_cyl,
    need_pass2,
    nbuf,  # size of the column-run buffers
    out,  # (S, F, m) float32; every row of a processed query is written (NaN = not computable)
):
    m = stop - start
    nscale = rad.shape[1]
    per_point = rad.shape[0] > 1
    cyl_kind = kind == KIND_CYLINDER
    want_curv = S.any_requested(col, S.K1, S.GAUSS_CURVATURE)
    want_qinl = col[S.QUADRIC_INLIER_RATIO] >= 0
    want_quad = want_curv or want_qinl  # the quadric fit is needed
    want_hist = S.any_requested(col, S.DH_PEAKS, S.DH_MAX_BIN)
    want_dist = S.any_requested(col, S.OCTANT_OCCUPANCY, S.Z_ASYMMETRY)
    want_plane_counts = col[S.PLANE_INLIER_RATIO] >= 0 or col[S.ECHO_RATIO_SLOPE] >= 0
    # what the closed-form eigen solve is needed for (nothing else pays for it)
    want_eigen = S.any_requested(col, S.EIGENVALUE1, S.WESTIN_SPHERICAL)
    want_slope = col[S.SLOPE] >= 0 or col[S.ASPECT] >= 0 or col[S.ECHO_RATIO_SLOPE] >= 0
    need_v1 = want_quad or S.any_requested(col, S.EIGENVECTOR1_X, S.EIGENVECTOR1_Z)
    need_solve = (
        want_eigen
        or S.any_requested(col, S.NORMAL_X, S.PLANE_INLIER_RATIO)
        or want_slope
        or want_quad
        or S.any_requested(col, S.EIGENVECTOR1_X, S.EIGENVECTOR1_Z)
    )
    nfeat = out.shape[1]
    # unbounded cylinders hold whole columns (every point of a tree under the query): sort the
    # gathered neighbours into horizontal shells once, so that scale s walks only the points
    # within its radius (every criterion of every scale implies h² <= r_s²)
    shells = need_cyl and nscale > 1
    chunk = 256
    nchunk = (m + chunk - 1) // chunk
    for ch in range(nchunk):  # threads take ranges of rows (lidarfx._parallel)
        lo = np.empty(nbuf, np.int64)
        hi = np.empty(nbuf, np.int64)
        buf = np.empty((3, 1040))  # rows not 4 KiB apart (no 4K aliasing)
        buf2 = np.empty((3, 1040))
        shell = np.empty(1040, np.int64)
        ends = np.empty(nscale, np.int64)
        acc = np.empty(_NACC)
        p2 = np.empty(6)
        quad = np.empty(27)
        hist = np.empty(nbins)
        lam = np.empty(3)
        v1 = np.empty(3)
        v3 = np.empty(3)
        v2 = np.empty(3)
        work = np.empty(48)
        i0 = start + ch * chunk
        i1 = min(stop, i0 + chunk)
        # results of this chunk, point-major (one point's features are adjacent),
        # copied to the feature-major output at the end of the chunk
        tile = np.empty((i1 - i0, nscale, nfeat), np.float32)
        for i in range(i0, i1):
            row = i if per_point else 0
            qx, qy, qz = q[i, 0], q[i, 1], q[i, 2]
            # one walk of the widest neighbourhood, compacted into buf
            rmax = rad[row, nscale - 1]
            wide_cyl = need_cyl or cyl_kind
            zwin = max(height, rmax) if wide_cyl else rmax
            nr = column_ranges(pts, cstart, cend, ckey, table, nx, ny, cell, qx, qy, qz, rmax, zwin, lo, hi)
            buf, cnt = gather(pts, lo, hi, nr, qx, qy, qz, rmax * rmax, zwin, wide_cyl, buf)
            if shells:
                if buf2.shape[1] < buf.shape[1]:
                    buf2 = np.empty((3, buf.shape[1]))
                    shell = np.empty(buf.shape[1], np.int64)
                ends[:] = 0
                for j in range(cnt):
                    h2 = buf[_BX, j] * buf[_BX, j] + buf[_BY, j] * buf[_BY, j]
                    k = 0
                    while k < nscale - 1 and h2 > rad[row, k] * rad[row, k]:
                        k += 1
                    shell[j] = k
                    ends[k] += 1
                for k in range(1, nscale):
                    ends[k] += ends[k - 1]
                for j in range(cnt - 1, -1, -1):  # stable: the points keep their order in a shell
                    k = shell[j]
                    ends[k] -= 1
                    d = ends[k]
                    buf2[_BX, d] = buf[_BX, j]
                    buf2[_BY, d] = buf[_BY, j]
                    buf2[_BZ, d] = buf[_BZ, j]
                for k in range(nscale - 1):  # ends[k] now starts shell k: make it shell k's end
                    ends[k] = ends[k + 1]
                ends[nscale - 1] = cnt
                buf, buf2 = buf2, buf
            for s in range(nscale):
                r = rad[row, s]
                r2 = r * r
                if shells:
                    cnt = ends[s]
                o = tile[i - i0, s]
                o[:] = np.nan
                _sum_cov(buf, cnt, r2, height, cyl_kind, acc)
                if need_cyl:
                    _sum_cyl(buf, cnt, r2, height, acc)
                n = acc[_N]
                S.put(o, col, S.N_NEIGHBOURS, n)
                nsph = acc[_NSPH]
                ncyl = acc[_NCYL]
                if need_cyl and ncyl > 0.0:
                    d2d = ncyl / (math.pi * r2)
                    d3d = nsph / (4.0 / 3.0 * math.pi * r2 * r)
                    S.put(o, col, S.DENSITY_2D, d2d)
                    S.put(o, col, S.DENSITY_3D, d3d)
                    S.put(o, col, S.DENSITY_RATIO, d3d / d2d)
                    S.put(o, col, S.NEIGHBOUR_RATIO, nsph / ncyl)
                    S.put(o, col, S.ECHO_RATIO, 100.0 * nsph / ncyl)
                    # height features (Chehata 2009), relative to the query's z
                    S.put(o, col, S.DZ_BELOW, -acc[_CZMIN])
                    S.put(o, col, S.DZ_ABOVE, acc[_CZMAX])
                    S.put(o, col, S.Z_RANGE, acc[_CZMAX] - acc[_CZMIN])
                    mz = acc[_CZ] / ncyl
                    var = max(acc[_CZZ] / ncyl - mz * mz, 0.0)
                    S.put(o, col, S.Z_STD, math.sqrt(var))
                    # dh = z_p - z_j = -dz: same std (metres), opposite skewness
                    S.put(o, col, S.DH_STD, math.sqrt(var))
                    if var > 1e-24:
                        m3 = acc[_CZZZ] / ncyl - 3.0 * mz * acc[_CZZ] / ncyl + 2.0 * mz * mz * mz
                        S.put(o, col, S.DH_SKEWNESS, -m3 / (var * math.sqrt(var)))
                    else:
                        S.put(o, col, S.DH_SKEWNESS, 0.0)
                plane_ok = False
                cx = cy = cz = 0.0
                nxv = nyv = nzv = 0.0
                slope = 0.0
                inv_n = 1.0 / n if n > 0.0 else 0.0
                if n > 0.0:
                    cx = acc[_SX] * inv_n
                    cy = acc[_SY] * inv_n
                    cz = acc[_SZ] * inv_n
                    S.put(o, col, S.CENTROID_OFFSET, math.sqrt(cx * cx + cy * cy + cz * cz) / r)
                if n >= 3.0 and need_solve:
                    eigh3(
                        acc[_XX] * inv_n - cx * cx, acc[_XY] * inv_n - cx * cy, acc[_XZ] * inv_n - cx * cz,
                        acc[_YY] * inv_n - cy * cy, acc[_YZ] * inv_n - cy * cz, acc[_ZZ] * inv_n - cz * cz,
                        lam, v1, v3, need_v1,
                    )
                    nxv, nyv, nzv = orient_normal(v3[0], v3[1], v3[2], qx, qy, qz, scanner, has_scanner)
                    if want_eigen:
                        eigen_features(lam, nzv, convention, col, o)
                    slope = write_plane(o, col, S.NORMAL_X, nxv, nyv, nzv, cx, cy, cz, want_slope)
                    S.put(o, col, S.PLANE_STD, math.sqrt(lam[2]))
                    e1x, e1y, e1z = v1[0], v1[1], v1[2]
                    if points_down(e1x, e1y, e1z):
                        e1x, e1y, e1z = -e1x, -e1y, -e1z
                    S.put(o, col, S.EIGENVECTOR1_X, e1x)
                    S.put(o, col, S.EIGENVECTOR1_Y, e1y)
                    S.put(o, col, S.EIGENVECTOR1_Z, e1z)
                    v2[0] = nyv * v1[2] - nzv * v1[1]
                    v2[1] = nzv * v1[0] - nxv * v1[2]
                    v2[2] = nxv * v1[1] - nyv * v1[0]
                    plane_ok = True
                if not need_pass2:
                    continue
                # ------------------------------------------------------ pass 2
                if plane_ok and want_plane_counts:
                    rr = r / math.cos(math.radians(min(slope, 80.0)))
                    _count_plane(buf, cnt, r2, height, cyl_kind, cx, cy, cz, nxv, nyv, nzv, dmax, rr * rr, p2)
                    S.put(o, col, S.PLANE_INLIER_RATIO, p2[_INL] / n)
                    if need_cyl and ncyl > 0.0:
                        S.put(o, col, S.ECHO_RATIO_SLOPE, 100.0 * p2[_ECHO] / ncyl)
                want_fit = want_quad and plane_ok and n >= 6.0
                if want_fit:
                    _sum_quadric(buf, cnt, r2, height, cyl_kind, v1, v2, nxv, nyv, nzv, r, quad)
                    if solve_sym6(quad, work):
                        if want_curv:
                            quadric_curvatures(work, r, col, o)
                        if want_qinl:
                            inl = _count_quadric(buf, cnt, r2, height, cyl_kind, v1, v2, nxv, nyv, nzv, r, dmax, work)
                            S.put(o, col, S.QUADRIC_INLIER_RATIO, inl / n)
                if not (want_hist or want_dist):
                    continue
                p2[:] = 0.0
                hist[:] = 0.0
                octbits = 0
                amax = 0.0
                if need_cyl:
                    amax = max(-acc[_CZMIN], acc[_CZMAX])
                for j in range(cnt):
                    dx = buf[_BX, j]
                    dy = buf[_BY, j]
                    dz = buf[_BZ, j]
                    h2 = dx * dx + dy * dy
                    d2 = h2 + dz * dz
                    in_cyl = h2 <= r2 and abs(dz) <= height
                    if in_cyl and want_hist:
                        u = 0.0 if amax <= 0.0 else -dz / amax
                        b = int((u + 1.0) * 0.5 * nbins)
                        b = min(max(b, 0), nbins - 1)
                        hist[b] += 1.0
                        if dz > 0.0:
                            p2[_CABV] += 1.0
                        elif dz < 0.0:
                            p2[_CBLW] += 1.0
                    if not (in_cyl if cyl_kind else d2 <= r2):
                        continue
                    if want_dist:
                        if dz > 0.0:
                            p2[_ABV] += 1.0
                        elif dz < 0.0:
                            p2[_BLW] += 1.0
                        if d2 > 0.0:
                            octbits |= 1 << ((dx > 0.0) * 4 + (dy > 0.0) * 2 + (dz > 0.0))
                if want_hist and need_cyl and ncyl > 0.0:
                    histogram_features(hist, ncyl, p2[_CABV], p2[_CBLW], col, o)
                if want_dist and n > 0.0:
                    occupied = 0
                    while octbits:
                        occupied += octbits & 1
                        octbits >>= 1
                    S.put(o, col, S.OCTANT_OCCUPANCY, occupied)
                    S.put(o, col, S.Z_ASYMMETRY, (p2[_ABV] - p2[_BLW]) / n)
        for s in range(nscale):
            for c in range(nfeat):
                dst = out[s, c]
                for i in range(i0, i1):
                    dst[i] = tile[i - i0, s, c]
