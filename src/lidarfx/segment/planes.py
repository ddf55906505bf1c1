"""Plane segmentation by surface growing against the segment plane (LIS slides; docs/segmentation.md).

Algorithm
---------
1. Normals and ``plane_std`` per point from the feature engine at the normal
   radius (LIS "Suchradius" 0.10 m).  Points whose normal is not computable
   (fewer than 3 neighbours, NaN) never seed and never join a segment.
2. Seeds are visited in order of increasing ``plane_std`` (ties: original
   point index), skipping points already in a segment.
3. A segment grows breadth-first: every member's neighbours within the growing
   radius ("Suchradius zur Flächenverdichtung", 0.15 m) are candidates; a
   candidate joins when its distance to the CURRENT segment plane is at most
   ``max_distance`` ("maximaler Abstand zum Flächensegment", 0.10 m) and its
   normal deviates by at most ``max_angle`` from the segment normal
   ("maximale Abweichung vom Normalvektor", 15°; axial, n and −n are equal).
4. The segment plane starts as the seed's own local plane (its normal at the
   normal radius, through the seed point) and is refitted from the members'
   running mean and covariance (Welford update, O(1) per point, closed-form
   3×3 eigen solve) once the segment has ``first_refit`` members and then
   every time it grew by ``refit_fraction`` (at most every ``refit_max``
   points).  A refit whose in-plane spread is not clearly larger than the
   out-of-plane spread (λ2 < 4 λ3: collinear members) keeps the previous plane.
5. A finished segment smaller than ``min_size`` (or, optionally, narrower
   than ``min_width``) is released: its points go back to −1, may be absorbed
   by a later segment growing into them, but are never used as seeds again
   (this keeps the run O(n) and deterministic).
6. Segment ids are renumbered by decreasing size (0 = largest; equal sizes
   keep their creation order).

Everything runs on local coordinates (the cloud minimum as origin) in one
sorted column grid (:class:`lidarfx.neighbors.NeighborIndex`) shared by the
normal computation and the growing.
"""
from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numba as nb
import numpy as np

from .. import _json
from .._atomic import atomic_path
from ..cloud import PointCloud
from ..errors import LidarfxError, check_int
from ..features.eigen import eigh3
from ..neighbors import NeighborIndex, column_ranges, ring_buffer_size
from ..progress import stage, wanted
from . import DEFAULTS, TABLE_COLUMNS

__all__ = [
    "DEFAULTS",
    "TABLE_COLUMNS",
    "segment_planes",
    "segments_table",
    "write_segments_csv",
    "write_segments_json",
]

_FREE = -1  # not in a segment, may seed
_RELEASED = -2  # was in a too-small segment: may join later segments, never seeds
_NO_NORMAL = -3  # normal not computable: never seeds, never joins


# ----------------------------------------------------------------------------
# numba kernel
# ----------------------------------------------------------------------------
@nb.njit(cache=True)
def _grow(
    pts, cstart, cend, ckey, table, nx, ny, cell,  # the grid (lidarfx.neighbors.Grid)
    nrm,  # (n, 3) unit normals in sorted order
    seeds,  # sorted positions, in seed order
    r_grow, dmax, cos_max,
    min_size, min_width, first_refit, refit_fraction, refit_max,
    nbuf,
    label,  # (n,) int64 in sorted order: _FREE / _NO_NORMAL on entry; segment (creation order) on exit
    sizes,  # (n,) int64 out: size per created segment
):
    """Region growing; returns the number of segments (ids in creation order)."""
    n = pts.shape[0]
    queue = np.empty(n, np.int64)
    lo = np.empty(nbuf, np.int64)
    hi = np.empty(nbuf, np.int64)
    lam = np.empty(3)
    v1 = np.empty(3)
    v3 = np.empty(3)
    r2 = r_grow * r_grow
    nseg = 0
    for t0 in range(seeds.shape[0]):
        s = seeds[t0]
        if label[s] != -1:
            continue
        seg = nseg
        label[s] = seg
        queue[0] = s
        head = 0
        tail = 1
        # running mean / co-moments relative to the seed point (Welford)
        ox, oy, oz = pts[s, 0], pts[s, 1], pts[s, 2]
        mx = my = mz = 0.0
        sxx = sxy = sxz = syy = syz = szz = 0.0
        # segment plane: the seed's local plane
        cx, cy, cz = ox, oy, oz
        ux, uy, uz = nrm[s, 0], nrm[s, 1], nrm[s, 2]
        next_refit = first_refit
        while head < tail:
            i = queue[head]
            head += 1
            qx, qy, qz = pts[i, 0], pts[i, 1], pts[i, 2]
            nr = column_ranges(pts, cstart, cend, ckey, table, nx, ny, cell, qx, qy, qz, r_grow, r_grow, lo, hi)
            for k in range(nr):
                for j in range(lo[k], hi[k]):
                    lj = label[j]
                    if lj >= 0 or lj == -3:
                        continue
                    px, py, pz = pts[j, 0], pts[j, 1], pts[j, 2]
                    dx = px - qx
                    dy = py - qy
                    dz = pz - qz
                    if dx * dx + dy * dy + dz * dz > r2:
                        continue
                    d = (px - cx) * ux + (py - cy) * uy + (pz - cz) * uz
                    if abs(d) > dmax:
                        continue
                    c = nrm[j, 0] * ux + nrm[j, 1] * uy + nrm[j, 2] * uz
                    if abs(c) < cos_max:
                        continue
                    label[j] = seg
                    queue[tail] = j
                    tail += 1
                    # Welford update of mean and co-moments (coordinates relative to the seed)
                    ax = px - ox - mx
                    ay = py - oy - my
                    az = pz - oz - mz
                    inv = 1.0 / tail
                    mx += ax * inv
                    my += ay * inv
                    mz += az * inv
                    bx = px - ox - mx
                    by = py - oy - my
                    bz = pz - oz - mz
                    sxx += ax * bx
                    sxy += ax * by
                    sxz += ax * bz
                    syy += ay * by
                    syz += ay * bz
                    szz += az * bz
                    if tail >= next_refit:
                        step = int(tail * refit_fraction)
                        step = min(step, refit_max)
                        step = max(step, 1)
                        next_refit = tail + step
                        inv = 1.0 / tail
                        eigh3(sxx * inv, sxy * inv, sxz * inv, syy * inv, syz * inv, szz * inv, lam, v1, v3, False)
                        if lam[1] > 4.0 * lam[2] and np.isfinite(lam[2]):
                            ux, uy, uz = v3[0], v3[1], v3[2]
                            cx, cy, cz = ox + mx, oy + my, oz + mz
        release = tail < min_size
        if not release and min_width > 0.0:
            # equivalent width of the segment: sqrt(12 λ2) (a w-wide strip has λ2 = w²/12)
            inv = 1.0 / tail
            eigh3(sxx * inv, sxy * inv, sxz * inv, syy * inv, syz * inv, szz * inv, lam, v1, v3, False)
            release = 12.0 * lam[1] < min_width * min_width
        if release:
            for t in range(tail):
                label[queue[t]] = -2
        else:
            sizes[nseg] = tail
            nseg += 1
    return nseg


# ----------------------------------------------------------------------------
# Python side
# ----------------------------------------------------------------------------
MAX_COUNT = 10**12
"""Largest value of the integer options (``min_size``, ``first_refit``, ``refit_max``): more
points than any cloud holds, and far inside the int64 of the numba kernel."""


def _check_int(name: str, value: Any, lo: int) -> int:
    """An integer in ``lo ..`` :data:`MAX_COUNT` (the numba kernel takes int64: a 23-digit value was a
    TypingError traceback)."""
    return check_int(name, value, lo, MAX_COUNT, hi_text="10^12")


def check_params(normal_radius, max_distance, growing_radius, max_angle, min_size, min_width=0.0, *,
                  first_refit=10, refit_fraction=0.10, refit_max=1000):
    """Every option of :func:`segment_planes` (the CLI runs this before it reads the cloud)."""
    for name, v in (("normal_radius", normal_radius), ("max_distance", max_distance), ("growing_radius", growing_radius)):
        if not (isinstance(v, (int, float, np.floating, np.integer)) and math.isfinite(v) and v > 0):
            raise LidarfxError(f"{name} must be a positive number (m), got {v!r}")
    if not (0 < max_angle < 90):
        raise LidarfxError(f"max_angle must be between 0 and 90 degrees, got {max_angle!r}")
    _check_int("min_size", min_size, 1)
    if not (0 < refit_fraction <= 10):
        raise LidarfxError(f"refit_fraction must be in (0, 10], got {refit_fraction!r}")
    _check_int("first_refit", first_refit, 3)
    if not (isinstance(min_width, (int, float, np.floating, np.integer)) and math.isfinite(min_width) and min_width >= 0):
        raise LidarfxError(f"min_width must be a number >= 0 (m), got {min_width!r}")
    _check_int("refit_max", refit_max, 1)


def segment_planes(
    cloud: PointCloud,
    *,
    normal_radius: float = DEFAULTS["normal_radius"],
    max_distance: float = DEFAULTS["max_distance"],
    growing_radius: float = DEFAULTS["growing_radius"],
    max_angle: float = DEFAULTS["max_angle"],
    min_size: int = DEFAULTS["min_size"],
    min_width: float = DEFAULTS["min_width"],
    scanner: Sequence[float] | None = None,
    first_refit: int = 10,
    refit_fraction: float = 0.10,
    refit_max: int = 1000,
    keep_features: bool = False,
    features: dict[str, np.ndarray] | None = None,
    inplace: bool = False,
    progress: bool | None = None,
    units: str = "auto",
) -> PointCloud:
    """Segment a cloud into planes by surface growing (LIS defaults for dense TLS).

    Parameters
    ----------
    cloud:
        The point cloud.
    normal_radius:
        Sphere radius of the local plane fit giving each point's normal and
        ``plane_std`` (LIS "Suchradius", 0.10 m).
    max_distance:
        Largest distance of a joining point to the current segment plane
        (LIS "maximaler Abstand zum Flächensegment", 0.10 m).
    growing_radius:
        Neighbours of a segment point within this radius are candidates
        (LIS "Suchradius zur Flächenverdichtung (region growing)", 0.15 m).
    max_angle:
        Largest angle (degrees, axial) between a joining point's normal and
        the segment normal (LIS "maximale Abweichung vom Normalvektor", 15°).
    min_size:
        Segments with fewer points are released (their points get −1).
    min_width:
        Segments whose equivalent width √(12·λ2) (λ2 = the smaller in-plane
        variance of the segment) is below this (m) are released too.  This
        removes the thin strips of intermediate normals that grow along
        edges; 0 (default) switches the test off.  A good value is about the
        growing radius.
    scanner:
        Scanner position (x, y, z) passed to the normal computation (TLS);
        the growing itself compares normals axially, so it only matters for
        the optional ``keep_features`` output.
    first_refit, refit_fraction, refit_max:
        The segment plane is refitted when the segment reaches
        ``first_refit`` points and then after every growth by
        ``refit_fraction`` (at most ``refit_max`` points apart).
    keep_features:
        Also store ``normal_x/y/z`` and ``plane_std`` (float32) of the normal
        radius on the result.
    features:
        Precomputed ``normal_x/y/z`` and ``plane_std`` of every point at
        ``normal_radius`` (from :func:`lidarfx.features.feature_arrays`), so
        that a caller needing them anyway computes them once.
    inplace:
        Add the attributes to ``cloud`` itself instead of a new cloud.
    progress:
        Progress bar of the normal computation (default: on a terminal for
        large clouds).
    units:
        ``"auto"`` (default): ``normal_radius``, ``max_distance``, ``growing_radius`` and
        ``min_width`` are metres, converted when the LAS header's CRS names another linear
        unit (US survey feet, feet); ``"native"``: coordinate units as given.

    Returns
    -------
    PointCloud
        With ``segment_id`` (int32, −1 = no segment, 0 = largest segment) and
        ``segment_size`` (int32, points in the point's segment, 0 for −1).
        ``result.meta["segmentation"]`` holds the parameters and counts.
    """
    from ..features import feature_arrays

    if not isinstance(cloud, PointCloud):
        raise LidarfxError("segment_planes expects a PointCloud (see lidarfx.read)")
    check_params(normal_radius, max_distance, growing_radius, max_angle, min_size, min_width,
                  first_refit=first_refit, refit_fraction=refit_fraction, refit_max=refit_max)
    n = len(cloud)
    if n == 0:
        raise LidarfxError("the point cloud is empty")
    from ..crs import metres_per_unit

    given = {"normal_radius": float(normal_radius), "max_distance": float(max_distance),
             "growing_radius": float(growing_radius), "min_width": float(min_width)}
    u = metres_per_unit(cloud, units)  # the lengths in coordinate units from here on
    normal_radius = float(normal_radius) / u
    growing_radius = float(growing_radius) / u
    max_distance = float(max_distance) / u
    min_width = float(min_width) / u

    # one index for the normals and the growing (cell = the larger radius)
    index = NeighborIndex(cloud.xyz, max(normal_radius, growing_radius))
    need = ["normal_x", "normal_y", "normal_z", "plane_std"]
    if features is not None:
        if any(k not in features or np.shape(features[k]) != (n,) for k in need):
            raise LidarfxError("precomputed features need normal_x, normal_y, normal_z and plane_std, one value per point")
        feats = {k: features[k] for k in need}
    else:
        feats = feature_arrays(cloud.xyz, need, radius=normal_radius, scanner=scanner, progress=progress, index=index)
    order = index.order
    nrm_orig = np.column_stack([feats["normal_x"], feats["normal_y"], feats["normal_z"]]).astype(np.float64)
    std = feats["plane_std"]
    nrm = np.ascontiguousarray(nrm_orig[order])
    ok = np.isfinite(nrm).all(axis=1)
    label = np.where(ok, _FREE, _NO_NORMAL).astype(np.int64)
    # seeds: increasing plane_std, ties by original index; NaN excluded
    inv = np.empty(n, np.int64)
    inv[order] = np.arange(n, dtype=np.int64)
    cand = np.flatnonzero(np.isfinite(std) & np.isfinite(nrm_orig).all(axis=1))
    seeds_orig = cand[np.lexsort((cand, std[cand]))]
    seeds = np.ascontiguousarray(inv[seeds_orig])

    g = index.grid
    sizes = np.zeros(n, np.int64)
    with stage("segment: growing planes", wanted(progress)):
        nseg = _grow(
            *g, nrm, seeds, growing_radius, float(max_distance), math.cos(math.radians(float(max_angle))),
            int(min_size), float(min_width), int(first_refit), float(refit_fraction), int(refit_max),
            ring_buffer_size(growing_radius, g.cell), label, sizes,
        )
    sizes = sizes[:nseg]
    # renumber: decreasing size, ties by creation order
    rank = np.argsort(-sizes, kind="stable")
    new_id = np.empty(nseg, np.int64)
    new_id[rank] = np.arange(nseg)
    lab_sorted = np.where(label >= 0, new_id[np.maximum(label, 0)] if nseg else -1, -1)
    seg_id = np.empty(n, np.int32)
    seg_id[order] = lab_sorted
    size_by_id = sizes[rank]
    seg_size = np.where(seg_id >= 0, size_by_id[np.maximum(seg_id, 0)] if nseg else 0, 0).astype(np.int32)

    result = cloud if inplace else PointCloud(cloud.xyz, dict(cloud.attrs), cloud.header, cloud.meta)
    result["segment_id"] = seg_id
    result["segment_size"] = seg_size
    if keep_features:
        for k in ("normal_x", "normal_y", "normal_z", "plane_std"):
            result[k] = feats[k]
    result.meta = dict(result.meta)
    result.meta["segmentation"] = {
        "method": "surface growing against the segment plane",
        "parameters": {
            "normal_radius": given["normal_radius"],
            "max_distance": given["max_distance"],
            "growing_radius": given["growing_radius"],
            "max_angle": float(max_angle),
            "min_size": int(min_size),
            "min_width": given["min_width"],
            "scanner": None if scanner is None else [float(v) for v in scanner],
            "first_refit": int(first_refit),
            "refit_fraction": float(refit_fraction),
            "refit_max": int(refit_max),
        },
        "lengths": "m" if units == "auto" else "coordinate units",
        "unit_to_metre": u if units == "auto" else None,
        "segments": int(nseg),
        "points": n,
        "segmented_points": int((seg_id >= 0).sum()),
        "no_normal_points": int((~ok).sum()),
    }
    return result


def suggested_parameters(cloud: PointCloud, units: str = "auto") -> dict[str, float]:
    """Lengths of :func:`segment_planes` that fit the cloud's point density (metres, or coordinate
    units with ``units="native"``), and the point spacing they come from: a normal radius holding
    about 20 points of a plane, a growing radius (and minimum width) holding about 12 — the LIS
    defaults hold about that many on dense TLS; on an ALS roof at 3.4 pts/m² they give 1.4 m and
    1.1 m — and a maximum distance of 0.10 m or a tenth of the normal radius, whichever is larger.
    ``spacing`` is 1/√(points per unit area of a plane)."""
    from ..crs import metres_per_unit
    from ..neighbors import default_radius

    r20 = default_radius(cloud, neighbours=20) * metres_per_unit(cloud, units)  # π r² ρ = 20

    def nice(v: float) -> float:
        return float(f"{v:.2g}")

    growing = nice(r20 * math.sqrt(12 / 20))
    return {"normal_radius": max(nice(r20), DEFAULTS["normal_radius"]),
            "growing_radius": max(growing, DEFAULTS["growing_radius"]),
            "max_distance": max(nice(r20 / 10), DEFAULTS["max_distance"]),
            "min_width": growing,
            "spacing": nice(r20 * math.sqrt(math.pi / 20))}


def no_segments_hint(cloud: PointCloud, units: str = "auto") -> str:
    """One line: no segment was found, the point spacing, and parameters that fit it."""
    try:
        p = suggested_parameters(cloud, units)
    except LidarfxError:  # coincident points: nothing to suggest
        return "no plane segment found"
    unit = "m" if units == "auto" else "units"
    return (f"no plane segment found: the points are about {p['spacing']:g} {unit} apart and the defaults are "
            f"for dense TLS (about 1 cm); try --normal-radius {p['normal_radius']:g} --growing-radius "
            f"{p['growing_radius']:g} --max-distance {p['max_distance']:g} --min-width {p['min_width']:g}")


def segments_table(cloud: PointCloud, attribute: str = "segment_id") -> list[dict[str, Any]]:
    """One row per segment (ids ≥ 0, ascending): the plane refitted to all its points.

    Keys (see :data:`TABLE_COLUMNS`): ``id``, ``size``, ``centroid_x/y/z``
    (world coordinates), ``normal_x/y/z`` (unit, flipped up), ``dip`` and
    ``dip_direction`` (degrees, docs/conventions.md), ``rms`` (RMS distance of the points
    to the plane, m) and ``area`` (m², convex hull of the points projected
    into the plane): metres also for a cloud whose LAS CRS is in feet.
    """
    from ..crs import unit_to_metre

    from ..geometry import dip_from_normal, fit_plane, hull_area_in_plane

    ids = np.asarray(cloud[attribute]).astype(np.int64)
    sel = np.flatnonzero(ids >= 0)
    if sel.size == 0:
        return []
    origin = cloud.origin
    local = cloud.xyz - origin
    order = sel[np.argsort(ids[sel], kind="stable")]
    sid = ids[order]
    uniq, start, counts = np.unique(sid, return_index=True, return_counts=True)
    rows: list[dict[str, Any]] = []
    normals = np.zeros((len(uniq), 3))
    cents = np.zeros((len(uniq), 3))
    rms = np.zeros(len(uniq))
    areas = np.zeros(len(uniq))
    for k, (a, m) in enumerate(zip(start, counts)):
        p = local[order[a : a + m]]
        if m >= 3:
            c, nv, lam = fit_plane(p)
            rms[k] = math.sqrt(lam[2])
            areas[k] = hull_area_in_plane(p, nv)
        else:
            c, nv = p.mean(axis=0), np.array([np.nan, np.nan, np.nan])
            rms[k] = np.nan
        normals[k] = nv
        cents[k] = c + origin
    u = unit_to_metre(cloud)
    rms, areas = rms * u, areas * (u * u)
    okn = np.isfinite(normals).all(axis=1)
    dip = np.full(len(uniq), np.nan)
    ddir = np.full(len(uniq), np.nan)
    if okn.any():
        dip[okn], ddir[okn] = dip_from_normal(normals[okn])
    for k, sidk in enumerate(uniq):
        rows.append(
            {
                "id": int(sidk),
                "size": int(counts[k]),
                "centroid_x": float(cents[k, 0]),
                "centroid_y": float(cents[k, 1]),
                "centroid_z": float(cents[k, 2]),
                "normal_x": float(normals[k, 0]),
                "normal_y": float(normals[k, 1]),
                "normal_z": float(normals[k, 2]),
                "dip": float(dip[k]),
                "dip_direction": float(ddir[k]),
                "rms": float(rms[k]),
                "area": float(areas[k]),
            }
        )
    return rows


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(round(v, 6))
    return str(v)


def write_segments_csv(rows: Sequence[dict[str, Any]], path: str | Path) -> Path:
    """Write the table as CSV (header = :data:`TABLE_COLUMNS`; NaN as empty field), atomically."""
    with atomic_path(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(TABLE_COLUMNS)
        for r in rows:
            w.writerow([_fmt(r[c]) for c in TABLE_COLUMNS])
    return Path(path)


def write_segments_json(rows: Sequence[dict[str, Any]], path: str | Path, meta: dict[str, Any] | None = None) -> Path:
    """Write ``{"columns": ..., "segmentation": meta, "segments": [rows]}`` as JSON (NaN as null), atomically."""
    doc = {
        "columns": TABLE_COLUMNS,
        "segmentation": meta or {},
        "segments": [{c: r[c] for c in TABLE_COLUMNS} for r in rows],
    }
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        _json.dump(doc, fh, indent=1)
        fh.write("\n")
    return Path(path)
