"""Unsupervised structure classification by eigenvalue signatures (ISPRS 2016; docs/structures.md).

Every point gets the label of the ideal structure whose reference signature is
nearest to its own: plane, plane border, edge, corner, line, line end or volume;
*isolated* when its sphere holds fewer than ``min_neighbours`` points, and
*unclassified* when even the nearest reference is farther than ``reject``.

>>> import lidarfx
>>> cloud = lidarfx.read("roofs.laz")                               # doctest: +SKIP
>>> out = lidarfx.classify_structures(cloud, radius=1.5)            # doctest: +SKIP
>>> out["structure"], out["structure_confidence"], out["structure_distance"]  # doctest: +SKIP

The signature of a point at radius r is ``(e1, e2, e3, centroid_offset)``: the
eigenvalues of the covariance of its sphere neighbourhood divided by their sum
and ``|c − p| / r`` (docs/features.md §3).  The distance to a reference is a weighted
(diagonal Mahalanobis) distance: per component, the difference divided by the
reference's spread, taken as the root mean square over the components (and
over the radii of a multi-scale run), so ``distance = 1`` is one standard
deviation on average whatever the number of radii.  The spread depends on the
number of points in the neighbourhood, so the references are tabulated by
count level and interpolated at each point's own count (see
:mod:`lidarfx.structures.references`).
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numba as nb
import numpy as np

from .. import _parallel as parallel
from ..cloud import PointCloud
from ..errors import LidarfxError, check_int
from ..neighbors import default_radius
from ..synth.structures import STRUCTURE_IDS
from .references import (
    SIGNATURE,
    References,
    default_references,
    generate_references,
    resolve_references,
)

UNCLASSIFIED = -1
"""Label of points whose nearest reference is farther than the reject threshold."""

LABELS: dict[int, str] = {UNCLASSIFIED: "unclassified", **{v: k for k, v in STRUCTURE_IDS.items()}}
"""Value of the ``structure`` attribute → name."""

DESCRIPTIONS: dict[str, str] = {
    "unclassified": "nearest reference farther than the reject threshold",
    "isolated": "fewer than min_neighbours points in the sphere",
    "plane": "inside a planar surface",
    "plane_border": "on the free border of a planar surface (roof eave, wall top, hole)",
    "edge": "on the intersection line of two planes (ridge, wall-roof edge, step)",
    "corner": "where three planes meet",
    "line": "on a thin linear object (wire, rail, thin pole)",
    "line_end": "at the end of a linear object",
    "volume": "in a volumetric scatter (vegetation, noise clusters)",
}

DEFAULT_REJECT = 3.0
"""Default reject threshold: RMS distance in reference standard deviations."""
DEFAULT_MIN_NEIGHBOURS = 5
"""Fewer points than this in the sphere (the point included) make a point isolated."""
MAX_REJECT = 1e6

OUTPUTS = ("structure", "structure_confidence", "structure_distance")
"""Attributes written by :func:`classify_structures`."""

__all__ = [
    "LABELS",
    "DESCRIPTIONS",
    "UNCLASSIFIED",
    "DEFAULT_REJECT",
    "DEFAULT_MIN_NEIGHBOURS",
    "OUTPUTS",
    "SIGNATURE",
    "References",
    "classify_structures",
    "classify_signatures",
    "structure_signatures",
    "structure_counts",
    "default_radius",
    "default_references",
    "generate_references",
]


# ------------------------------------------------------------------ signatures
def structure_signatures(xyz: np.ndarray, radii: Sequence[float], *, query_xyz: np.ndarray | None = None,
                         progress: bool | None = None, origin: np.ndarray | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Signatures ``(m, len(radii), 4)`` (float64, NaN where fewer than 3 neighbours or
    all neighbours coincide) and neighbour counts ``(m, len(radii))`` of the query points
    (default: every point of ``xyz``).  ``origin`` (default: the per-axis minimum of ``xyz``)
    is the neighbour index's local origin: a chunk of a larger cloud given the whole cloud's
    minimum gets the whole cloud's signatures bit for bit (:mod:`lidarfx.tiles`)."""
    from ..features.api import feature_arrays, feature_index, radii_list, scale_suffix
    from ..features.registry import resolve

    rs = radii_list(None, radii)
    if not rs:
        raise LidarfxError("give a radius (e.g. radius=1.5) or several radii")
    names = ["eigenvalue1", "eigenvalue2", "eigenvalue3", "centroid_offset", "n_neighbours"]
    index = None
    if origin is not None:
        xyz = np.asarray(xyz, dtype=np.float64)
        if len(xyz):
            index = feature_index(xyz, "sphere", None, rs, resolve(names), origin=np.asarray(origin, dtype=np.float64))
    f = feature_arrays(xyz, names, radii=rs, query_xyz=query_xyz, progress=progress, index=index)
    m = len(f["n_neighbours" if len(rs) == 1 else "n_neighbours" + scale_suffix(rs[0])])
    sig = np.empty((m, len(rs), len(SIGNATURE)))
    cnt = np.empty((m, len(rs)))
    for s, r in enumerate(rs):
        sfx = "" if len(rs) == 1 else scale_suffix(r)
        parallel.run(_signature_columns, len(sig), f["eigenvalue1" + sfx], f["eigenvalue2" + sfx],
                     f["eigenvalue3" + sfx], f["centroid_offset" + sfx], f["n_neighbours" + sfx], sig[:, s], cnt[:, s],
                     grain=65536)
        for name in ("eigenvalue1", "eigenvalue2", "eigenvalue3", "centroid_offset", "n_neighbours"):
            del f[name + sfx]  # free as we go (1 M points × 5 float32 per radius)
    return sig, cnt


@nb.njit(cache=True, nogil=True)
def _signature_columns(lo, hi, l1, l2, l3, co, nn, sig, cnt):
    for i in range(lo, hi):
        a, b, c = float(l1[i]), float(l2[i]), float(l3[i])
        t = a + b + c
        if t > 0.0:
            sig[i, 0] = a / t
            sig[i, 1] = b / t
            sig[i, 2] = c / t
        else:  # NaN eigenvalues, or every neighbour at the same place
            sig[i, 0] = np.nan
            sig[i, 1] = np.nan
            sig[i, 2] = np.nan
        sig[i, 3] = co[i]
        cnt[i] = nn[i]


# ------------------------------------------------------------------ classification kernel
@nb.njit(cache=True, inline="always")
def _lerp_level(log_n, x):
    """Level index l and weight t so that x sits at (1 − t)·level l + t·level l+1 (clamped)."""
    L = log_n.shape[0]
    if L == 1 or x <= log_n[0]:
        return 0, 0.0
    if x >= log_n[L - 1]:
        return L - 2, 1.0
    lo = 0
    while log_n[lo + 1] < x:
        lo += 1
    return lo, (x - log_n[lo]) / (log_n[lo + 1] - log_n[lo])


@nb.njit(cache=True, nogil=True)
def _classify_kernel(lo, hi, sig, cnt, cid, log_n, mean, std, n_classes, reject, min_n, label, conf, dist):
    nr, nd = sig.shape[1], sig.shape[2]
    P = cid.shape[0]
    valid = np.zeros(nr, np.bool_)
    score = np.empty(n_classes)
    for i in range(lo, hi):
        if cnt[i, nr - 1] < min_n:  # the widest sphere: too few points for any shape
            label[i] = 0
            conf[i] = np.nan
            dist[i] = np.nan
            continue
        # the radii that take part: enough points and a finite signature
        used = 0
        for s in range(nr):
            ok = cnt[i, s] >= min_n
            for j in range(nd):
                ok = ok and np.isfinite(sig[i, s, j])
            valid[s] = ok
            used += 1 if ok else 0
        if used == 0:
            label[i] = -1
            conf[i] = np.nan
            dist[i] = np.nan
            continue
        score[:] = np.inf
        for p in range(P):
            tot = 0.0
            for s in range(nr):
                if not valid[s]:
                    continue
                l, t = _lerp_level(log_n[p], math.log(cnt[i, s]))
                l1 = l + 1 if t > 0.0 else l
                for j in range(nd):
                    mu = (1.0 - t) * mean[p, l, j] + t * mean[p, l1, j]
                    sd = (1.0 - t) * std[p, l, j] + t * std[p, l1, j]
                    z = (sig[i, s, j] - mu) / sd
                    tot += z * z
            k = cid[p]
            if tot < score[k]:
                score[k] = tot
        best = 0
        for k in range(n_classes):
            if score[k] < score[best]:
                best = k
        den = 0.0
        for k in range(n_classes):
            if np.isfinite(score[k]):
                den += math.exp(-0.5 * (score[k] - score[best]))
        d = math.sqrt(score[best] / (used * nd))
        dist[i] = d
        conf[i] = 1.0 / den
        label[i] = best if d <= reject else -1


def check_reject(reject) -> float:
    try:
        v = math.nan if isinstance(reject, (bool, str)) else float(reject)
    except (TypeError, ValueError):
        v = math.nan
    if not (0 < v <= MAX_REJECT):
        raise LidarfxError(f"reject threshold must be a distance in reference standard deviations, > 0 and at most "
                           f"{MAX_REJECT:g} (default {DEFAULT_REJECT:g}), got {reject!r}")
    return v


def check_min_neighbours(min_neighbours) -> int:
    return check_int("min_neighbours", min_neighbours, 3, 1_000_000)


def classify_signatures(sig: np.ndarray, cnt: np.ndarray, *, references: Any = "trained",
                        weighting: str = "structure", reject: float = DEFAULT_REJECT,
                        min_neighbours: int = DEFAULT_MIN_NEIGHBOURS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Labels (int32), confidences and distances (float32) of signatures from
    :func:`structure_signatures` (see :func:`classify_structures` for the parameters)."""
    reject = check_reject(reject)
    min_n = check_min_neighbours(min_neighbours)
    refs, kind = resolve_references(references)
    cid, log_n, mean, std = refs.tables(kind, weighting)
    sig = np.ascontiguousarray(sig, dtype=np.float64)
    cnt = np.ascontiguousarray(cnt, dtype=np.float64)
    if sig.ndim == 2:
        sig, cnt = sig[:, None, :], cnt.reshape(-1, 1)
    if sig.ndim != 3 or sig.shape[2] != len(SIGNATURE) or cnt.shape != sig.shape[:2]:
        raise LidarfxError("signatures must have shape (m, radii, 4) and counts (m, radii)")
    m = sig.shape[0]
    label = np.empty(m, np.int32)
    conf = np.empty(m, np.float32)
    dist = np.empty(m, np.float32)
    n_classes = int(max(STRUCTURE_IDS.values())) + 1
    parallel.run(_classify_kernel, m, sig, cnt, cid, log_n, mean, std, n_classes, reject, float(min_n),
                 label, conf, dist, grain=4096)
    return label, conf, dist


# ------------------------------------------------------------------ public API
def classify_structures(
    cloud: PointCloud,
    radius: float | None = None,
    *,
    radii: Sequence[float] | None = None,
    references: Any = "trained",
    weighting: str = "structure",
    reject: float = DEFAULT_REJECT,
    min_neighbours: int = DEFAULT_MIN_NEIGHBOURS,
    keep_signature: bool = False,
    progress: bool | None = None,
    inplace: bool = False,
    units: str = "auto",
) -> PointCloud:
    """Label every point with the ideal structure its neighbourhood resembles most.

    Parameters
    ----------
    cloud:
        The point cloud.
    radius, radii:
        Sphere radius, or several (multi-scale: the distances of all radii are
        combined), in metres: converted when the LAS header's CRS names another
        linear unit (US survey feet, feet); ``units="native"``: coordinate units.
        Default: :func:`default_radius` (about 40 points on a plane).
    references:
        ``"trained"`` (the shipped references generated on synthetic ideal
        structures), ``"analytic"`` (closed-form signatures of the ideal
        structures with the trained spreads), a references file written by
        ``lidarfx eigenclass-references``, or a :class:`References`.
    weighting:
        ``"structure"``: each reference's own spread per component (ISPRS 2016's
        structure-dependent weighting); ``"uniform"``: one spread for every
        reference and component (a plain Euclidean distance).
    reject:
        Points whose nearest reference is farther than this (RMS over the
        components, in reference standard deviations) are ``unclassified`` (−1).
    min_neighbours:
        Points with fewer points in their (largest) sphere, themselves included,
        are ``isolated`` (0).
    keep_signature:
        Also write the signature (``e1``, ``e2``, ``e3``, ``centroid_offset``, with
        the ``_r0.50`` suffix per radius in a multi-scale run) and ``n_neighbours``.

    Returns
    -------
    PointCloud
        With ``structure`` (int32, see :data:`LABELS`), ``structure_confidence``
        (float32: the share of the nearest class in exp(−χ²/2) over all classes)
        and ``structure_distance`` (float32: the RMS distance to the nearest
        reference; NaN for isolated points).  ``meta["structures"]`` holds the
        radii (m), parameters and the count per label.
    """
    from ..crs import metres_per_unit
    from ..features.api import radii_list, scale_suffix

    if not isinstance(cloud, PointCloud):
        raise LidarfxError("classify_structures expects a PointCloud (see lidarfx.read)")
    reject = check_reject(reject)
    min_n = check_min_neighbours(min_neighbours)
    refs, kind = resolve_references(references)
    refs.tables(kind, weighting)  # checks weighting before any work
    if len(cloud) == 0:
        raise LidarfxError("the point cloud is empty")
    u = metres_per_unit(cloud, units)
    rs_m = radii_list(radius, radii)  # metres (units="auto")
    rs = [r / u for r in rs_m]  # coordinate units
    if not rs:
        rs = [default_radius(cloud)]
        rs_m = [float(f"{rs[0] * u:.4g}")]
    sig, cnt = structure_signatures(cloud.xyz, rs, progress=progress)
    label, conf, dist = classify_signatures(sig, cnt, references=refs if kind == "trained" else kind,
                                            weighting=weighting, reject=reject, min_neighbours=min_n)
    out = cloud if inplace else PointCloud(cloud.xyz, dict(cloud.attrs), cloud.header, cloud.meta)
    out.update({"structure": label, "structure_confidence": conf, "structure_distance": dist})
    if keep_signature:
        for s, r in enumerate(rs_m):
            sfx = "" if len(rs) == 1 else scale_suffix(r)
            for j, name in enumerate(SIGNATURE):
                out[name + sfx] = sig[:, s, j].astype(np.float32)
            out["n_neighbours" + sfx] = cnt[:, s].astype(np.float32)
    out.meta["structures"] = {
        "radii": rs_m,
        "radii_units": "m" if units == "auto" else "coordinate units",
        "references": _reference_name(references),
        "weighting": weighting,
        "reject": reject,
        "min_neighbours": min_n,
        "counts": structure_counts(label),
    }
    return out


def _reference_name(references: Any) -> str:
    """What ``meta["structures"]["references"]`` records: the name, the file path, or "custom"."""
    import os

    if isinstance(references, (str, os.PathLike)):
        return os.fspath(references)
    return "custom"


def structure_counts(label: np.ndarray) -> dict[str, int]:
    """Number of points per label name, in the order of :data:`LABELS`."""
    lab = np.asarray(label).astype(np.int64)
    counts = np.bincount(lab + 1, minlength=len(LABELS))
    return {LABELS[v]: int(counts[v + 1]) for v in sorted(LABELS)}
