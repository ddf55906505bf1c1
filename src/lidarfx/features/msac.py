"""Robust local planes by MSAC (Torr & Zisserman 2000).

For every query point the neighbours of the chosen neighbourhood are
gathered into a per-thread buffer; random triples (seeded per point, so the
result does not depend on threads or chunking) propose planes scored by the
MSAC cost Σ min(e², t²); the number of trials adapts to the inlier share
(99 % confidence, at least ``min_iter``, at most ``max_iter``).  The best
hypothesis' inliers are refitted by PCA and give the ``msac_*`` features:
normal (oriented like the ordinary normal), slope, aspect, plane distance of
the query point, RMS of the inlier distances and the inlier share.
"""
from __future__ import annotations

import math

import numba as nb
import numpy as np

from ..neighbors import G_DX, G_DY, G_DZ, column_ranges, gather
from . import slots as S
from .eigen import eigh3
from .plane import orient_normal, write_plane


@nb.njit(cache=True, inline="always")
def _splitmix(state):
    state = (state + np.uint64(0x9E3779B97F4A7C15)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    z = state
    z = ((z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    z = ((z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    return state, z ^ (z >> np.uint64(31))


@nb.njit(cache=True, nogil=True)
def msac_features(
    start, stop, pts, cstart, cend, ckey, table, nx, ny, cell,
    q, qid, rad, scale, kind, height, scanner, has_scanner,
    col, thr, min_iter, max_iter, seed, nbuf, out,
):
    """MSAC plane features for scale ``scale`` of ``rad`` for rows start..stop of ``q``
    (grid order); writes ``out[scale, :, i]``.

    ``qid[i]`` is the global id of query row i, used to seed its generator.
    """
    m = stop - start
    per_point = rad.shape[0] > 1
    chunk = 256
    nchunk = (m + chunk - 1) // chunk
    thr2 = thr * thr
    for ch in range(nchunk):  # threads take ranges of rows (lidarfx._parallel)
        lo = np.empty(nbuf, np.int64)
        hi = np.empty(nbuf, np.int64)
        buf = np.empty((3, 256))
        lam = np.empty(3)
        v1 = np.empty(3)
        v3 = np.empty(3)
        for i in range(start + ch * chunk, min(stop, start + ch * chunk + chunk)):
            r = rad[i if per_point else 0, scale]
            r2 = r * r
            qx, qy, qz = q[i, 0], q[i, 1], q[i, 2]
            zh = r if kind == 0 else max(height, r)
            nr = column_ranges(pts, cstart, cend, ckey, table, nx, ny, cell, qx, qy, qz, r, zh, lo, hi)
            buf, cnt = gather(pts, lo, hi, nr, qx, qy, qz, r2, height, kind == 1, buf)
            if cnt < 3:
                continue
            state = np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(qid[i])
            best = np.inf
            bnx = bny = bnz = bd = 0.0
            t = 0
            need = max_iter
            while t < need and t < max_iter:
                t += 1
                state, a = _splitmix(state)
                state, b = _splitmix(state)
                state, c = _splitmix(state)
                ia = int(a % np.uint64(cnt))
                ib = int(b % np.uint64(cnt))
                ic = int(c % np.uint64(cnt))
                if ia == ib or ia == ic or ib == ic:
                    continue
                ux = buf[G_DX, ib] - buf[G_DX, ia]
                uy = buf[G_DY, ib] - buf[G_DY, ia]
                uz = buf[G_DZ, ib] - buf[G_DZ, ia]
                wx = buf[G_DX, ic] - buf[G_DX, ia]
                wy = buf[G_DY, ic] - buf[G_DY, ia]
                wz = buf[G_DZ, ic] - buf[G_DZ, ia]
                nxv = uy * wz - uz * wy
                nyv = uz * wx - ux * wz
                nzv = ux * wy - uy * wx
                nn = math.sqrt(nxv * nxv + nyv * nyv + nzv * nzv)
                if nn <= 1e-12 * (ux * ux + uy * uy + uz * uz + wx * wx + wy * wy + wz * wz):
                    continue
                nxv /= nn
                nyv /= nn
                nzv /= nn
                d0 = nxv * buf[G_DX, ia] + nyv * buf[G_DY, ia] + nzv * buf[G_DZ, ia]
                cost = 0.0
                ninl = 0
                for j in range(cnt):
                    e = nxv * buf[G_DX, j] + nyv * buf[G_DY, j] + nzv * buf[G_DZ, j] - d0
                    e2 = e * e
                    if e2 < thr2:
                        cost += e2
                        ninl += 1
                    else:
                        cost += thr2
                    if cost >= best:
                        break
                if cost < best:
                    best = cost
                    bnx, bny, bnz, bd = nxv, nyv, nzv, d0
                    w = ninl / cnt
                    w3 = w * w * w
                    if w3 >= 1.0 - 1e-12:
                        need = min_iter
                    elif w3 > 0.0:
                        need = max(min_iter, int(math.ceil(math.log(0.01) / math.log(1.0 - w3))))
            if best == np.inf:
                continue
            # refit the inliers by PCA
            sx = sy = sz = 0.0
            ninl = 0
            for j in range(cnt):
                e = bnx * buf[G_DX, j] + bny * buf[G_DY, j] + bnz * buf[G_DZ, j] - bd
                if e * e <= thr2:
                    sx += buf[G_DX, j]
                    sy += buf[G_DY, j]
                    sz += buf[G_DZ, j]
                    ninl += 1
            if ninl < 3:
                continue
            cx, cy, cz = sx / ninl, sy / ninl, sz / ninl
            cxx = cxy = cxz = cyy = cyz = czz = 0.0
            for j in range(cnt):
                e = bnx * buf[G_DX, j] + bny * buf[G_DY, j] + bnz * buf[G_DZ, j] - bd
                if e * e <= thr2:
                    ex = buf[G_DX, j] - cx
                    ey = buf[G_DY, j] - cy
                    ez = buf[G_DZ, j] - cz
                    cxx += ex * ex
                    cxy += ex * ey
                    cxz += ex * ez
                    cyy += ey * ey
                    cyz += ey * ez
                    czz += ez * ez
            eigh3(cxx / ninl, cxy / ninl, cxz / ninl, cyy / ninl, cyz / ninl, czz / ninl, lam, v1, v3, False)
            nxv, nyv, nzv = orient_normal(v3[0], v3[1], v3[2], qx, qy, qz, scanner, has_scanner)
            # inliers of the refined plane
            ss = 0.0
            nin2 = 0
            for j in range(cnt):
                e = (buf[G_DX, j] - cx) * nxv + (buf[G_DY, j] - cy) * nyv + (buf[G_DZ, j] - cz) * nzv
                if e * e <= thr2:
                    ss += e * e
                    nin2 += 1
            o = out[scale, :, i]
            write_plane(o, col, S.MSAC_NORMAL_X, nxv, nyv, nzv, cx, cy, cz, False)
            if nin2 > 0:
                S.put(o, col, S.MSAC_PLANE_STD, math.sqrt(ss / nin2))
            S.put(o, col, S.MSAC_INLIER_RATIO, nin2 / cnt)
