"""Outlier (noise) filters: statistical and radius outliers, as PDAL ``filters.outlier`` and
CloudCompare's SOR filter define them.

Statistical (``method="statistical"``, ``k``, ``std``)
    For every point the mean 3-D distance to its ``k`` nearest *other* points, d̄ᵢ.  Over all
    points, μ = mean(d̄) and σ = their sample standard deviation (n − 1), as PDAL; a point is an
    outlier when d̄ᵢ > μ + ``std`` · σ.  Defaults ``k = 8``, ``std = 2.0`` (PDAL's ``mean_k`` and
    ``multiplier``; CloudCompare's SOR takes the same two numbers).  μ and σ are computed from
    exact sums (:func:`moments`, :func:`threshold`), so a chunked run, whose chunks each add their
    points' sums, gets the same threshold and the same outliers as one run in memory, bit for bit.

Radius (``method="radius"``, ``radius``, ``min_neighbours``)
    A point is an outlier when fewer than ``min_neighbours`` *other* points lie within ``radius``
    (3-D, metres; converted for clouds in feet).  PDAL's ``min_k`` counts the point itself:
    ``min_k = min_neighbours + 1``.

Neighbours come from the one spatial index (:class:`lidarfx.neighbors.NeighborIndex`, local
origin = the per-axis minimum); duplicates are neighbours at distance 0.  Every point takes part,
noise already classified included (as PDAL).

Actions (:func:`filter_outliers`)
    ``classify`` (default): outliers get class ``7`` (ASPRS low noise; ``cls`` chooses another,
    e.g. 18 high noise), the other points keep theirs; a cloud without classes gets 0 (never
    classified) for them.  ``drop``: outliers are left out.
"""
from __future__ import annotations

import math
from fractions import Fraction
from typing import Any

import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError, check_int, check_number

__all__ = ["METHODS", "ACTIONS", "NOISE_CLASS", "mean_knn_distance", "neighbour_counts", "moments", "threshold",
           "outlier_mask", "apply_action", "filter_outliers", "check_options", "knn_cell"]

METHODS = ("statistical", "radius")
ACTIONS = ("classify", "drop")
NOISE_CLASS = 7
"""ASPRS class 7, low point (noise)."""
MAX_K = 1000


def check_options(method: str, k=8, std=2.0, radius=None, min_neighbours=None, action: str = "classify",
                  cls: int = NOISE_CLASS) -> dict[str, Any]:
    """The options of a filter, checked (one-line errors), as a dict."""
    if method not in METHODS:
        raise LidarfxError(f"--outliers must be one of {', '.join(METHODS)}; got {method!r}")
    if action not in ACTIONS:
        raise LidarfxError(f"--action must be one of {', '.join(ACTIONS)}; got {action!r}")
    cls = check_int("--class", cls, 0, 255)
    if method == "statistical":
        if radius is not None or min_neighbours is not None:
            raise LidarfxError("--radius and --min-neighbours belong to --outliers radius; statistical takes --k and --std")
        return {"method": method, "k": check_int("--k", k, 1, MAX_K), "std": check_number("--std", std, -1e6, 1e6),
                "action": action, "class": cls}
    if radius is None or min_neighbours is None:
        raise LidarfxError("--outliers radius needs --radius R (m) and --min-neighbours N")
    return {"method": method, "radius": check_number("--radius", radius, 0.0, 1e6, open_lo=True),
            "min_neighbours": check_int("--min-neighbours", min_neighbours, 1, 1_000_000), "action": action,
            "class": cls}


# --------------------------------------------------------------------------- per point
def knn_cell(xyz: np.ndarray, k: int, sample: int = 200_000) -> float:
    """A column size holding about ``k`` points where there are points: the 2-D density over the
    *occupied* columns (two refinements from the bounding box's), so that clouds made of distant
    parts (merged sites, strips with gaps) do not get huge columns.  Only the search speed depends
    on it, never the neighbours found."""
    xy = np.asarray(xyz, dtype=np.float64)[:, :2]
    n = len(xy)
    if n < 2:
        return 1.0
    if n > sample:
        xy = xy[np.random.default_rng(0).choice(n, sample, replace=False)]
    lo = xy.min(axis=0)
    ext = np.ptp(xy, axis=0)
    cell = max(math.sqrt(max(float(ext[0]) * float(ext[1]), 1e-6) * k / len(xy)), 1e-3)
    for _ in range(3):
        ij = np.floor((xy - lo) / cell).astype(np.int64)
        occupied = len(np.unique(ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]))
        density = len(xy) / (occupied * cell * cell)
        new = max(math.sqrt(k / density), 1e-3)
        if new >= 0.7 * cell:
            return float(min(new, cell))
        cell = new
    return float(cell)


def mean_knn_distance(xyz: np.ndarray, k: int, *, query: np.ndarray | None = None, origin=None,
                      cell: float | None = None) -> np.ndarray:
    """Mean 3-D distance of each point (or of the ``query`` indices) to its ``k`` nearest other
    points; the index uses ``origin`` (default: the minimum) and ``cell`` (default:
    :func:`knn_cell`; the distances do not depend on it)."""
    from .neighbors import NeighborIndex

    xyz = np.asarray(xyz, dtype=np.float64)
    if len(xyz) <= k:
        raise LidarfxError(f"the statistical filter needs more than k = {k} points; the cloud has {len(xyz)}")
    o = xyz.min(axis=0) if origin is None else np.asarray(origin, dtype=np.float64)
    index = NeighborIndex(xyz, cell or knn_cell(xyz, k + 1), o)
    q = xyz if query is None else xyz[query]
    _, dist = index.knn(q, k + 1)  # the point itself first, at distance 0
    return dist[:, 1:].sum(axis=1) / k


def neighbour_counts(xyz: np.ndarray, radius: float, *, query: np.ndarray | None = None, origin=None) -> np.ndarray:
    """Number of other points within ``radius`` (3-D) of each point (or of the ``query`` indices)."""
    from .neighbors import NeighborIndex

    xyz = np.asarray(xyz, dtype=np.float64)
    index = NeighborIndex(xyz, radius, None if origin is None else np.asarray(origin, dtype=np.float64))
    q = xyz if query is None else xyz[query]
    return index.count(q, radius) - 1


# --------------------------------------------------------------------------- exact statistics
def _exact_int_sum(a: np.ndarray) -> int:
    """The exact sum of non-negative int64 values below 2**54 (blocks of 256 cannot overflow)."""
    pad = (-len(a)) % 256
    if pad:
        a = np.concatenate([a, np.zeros(pad, np.int64)])
    return sum(a.reshape(-1, 256).sum(axis=1).tolist())


def moments(d: np.ndarray) -> tuple[int, Fraction, Fraction]:
    """``(n, Σd, Σd²)`` of finite non-negative float64 values, the sums exact (rational): the sum of
    parts equals the sum of the whole, in any order.  Each value is its 53-bit integer mantissa m
    times a power of two; per exponent, Σm and Σm² are summed exactly in integers (m split into
    27 + 26 bits so that no int64 sum overflows)."""
    d = np.asarray(d, dtype=np.float64)
    if not len(d):
        return 0, Fraction(0), Fraction(0)
    if not (np.isfinite(d).all() and (d >= 0).all()):
        raise LidarfxError("moments need finite non-negative values")
    m, e = np.frexp(d)
    mant = np.ldexp(m, 53).astype(np.int64)  # exact: d = mant * 2**(e - 53)
    order = np.argsort(e, kind="stable")
    e, mant = e[order], mant[order]
    cuts = np.flatnonzero(np.diff(e)) + 1
    s1, s2 = Fraction(0), Fraction(0)
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(e)]):
        hi, lo = mant[a:b] >> 26, mant[a:b] & ((1 << 26) - 1)
        p = int(e[a]) - 53
        sm = (_exact_int_sum(hi) << 26) + _exact_int_sum(lo)
        sq = (_exact_int_sum(hi * hi) << 52) + (_exact_int_sum(hi * lo) << 27) + _exact_int_sum(lo * lo)
        s1 += Fraction(sm) * Fraction(2) ** p
        s2 += Fraction(sq) * Fraction(2) ** (2 * p)
    return len(d), s1, s2


def threshold(n: int, s1: Fraction, s2: Fraction, std: float) -> tuple[float, float, float]:
    """``(mean, sigma, mean + std * sigma)`` from exact sums: the mean and the sample standard
    deviation (n − 1) correctly rounded to float64."""
    if n < 2:
        raise LidarfxError(f"the statistical filter needs at least 2 points, got {n}")
    mean = s1 / n
    var = (s2 - s1 * s1 / n) / (n - 1)
    mu = float(mean)
    sigma = math.sqrt(float(var)) if var > 0 else 0.0
    return mu, sigma, mu + float(std) * sigma


# --------------------------------------------------------------------------- filters
def outlier_mask(cloud: PointCloud | np.ndarray, method: str = "statistical", *, k: int = 8, std: float = 2.0,
                 radius: float | None = None, min_neighbours: int | None = None, units: str = "auto",
                 progress: bool | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    """``(mask, facts)``: True for the outliers of ``cloud`` (see the module docstring), and what
    was measured (threshold, mean, sigma; counts).  ``radius`` is metres (``units="native"``:
    coordinate units)."""
    from .crs import length_to_units
    from .progress import stage, wanted

    o = check_options(method, k, std, radius, min_neighbours)
    xyz = cloud.xyz if isinstance(cloud, PointCloud) else np.asarray(cloud, dtype=np.float64)
    n = len(xyz)
    if method == "statistical":
        with stage(f"mean distance to {o['k']} neighbours of {n:,} points", wanted(progress)):
            d = mean_knn_distance(xyz, o["k"])
        mu, sigma, thr = threshold(*moments(d), o["std"])
        mask = d > thr
        facts = {"mean_distance": mu, "sigma": sigma, "threshold": thr, "k": o["k"], "std": o["std"]}
    else:
        r = float(length_to_units(cloud, o["radius"], units)) if isinstance(cloud, PointCloud) else o["radius"]
        with stage(f"neighbours within {o['radius']:g} m of {n:,} points", wanted(progress)):
            counts = neighbour_counts(xyz, r)
        mask = counts < o["min_neighbours"]
        facts = {"radius": o["radius"], "min_neighbours": o["min_neighbours"]}
    facts = {"method": method, **facts, "points": n, "outliers": int(mask.sum())}
    return mask, facts


def apply_action(cloud: PointCloud, mask: np.ndarray, action: str = "classify", cls: int = NOISE_CLASS) -> PointCloud:
    """``classify``: a copy with class ``cls`` on the points of ``mask`` (the classes of the others
    kept; 0 where the cloud had none); ``drop``: the points not in ``mask``."""
    if action == "drop":
        return cloud.subset(~mask)
    out = PointCloud(cloud.xyz, dict(cloud.attrs), cloud.header, cloud.meta)
    c = np.array(cloud["classification"]) if "classification" in cloud else np.zeros(len(cloud), np.uint8)
    if c.dtype.kind in "iu" and cls > np.iinfo(c.dtype).max:
        c = c.astype(np.int32)
    c[mask] = cls
    out["classification"] = c
    return out


def filter_outliers(cloud: PointCloud, method: str = "statistical", *, k: int = 8, std: float = 2.0,
                    radius: float | None = None, min_neighbours: int | None = None, action: str = "classify",
                    cls: int = NOISE_CLASS, units: str = "auto", progress: bool | None = None) -> PointCloud:
    """The cloud with its outliers classified (class ``cls``, default 7) or dropped (``action``);
    ``meta["outliers"]`` holds what was measured.  See the module docstring."""
    check_options(method, k, std, radius, min_neighbours, action, cls)
    mask, facts = outlier_mask(cloud, method, k=k, std=std, radius=radius, min_neighbours=min_neighbours,
                               units=units, progress=progress)
    out = apply_action(cloud, mask, action, cls)
    out.meta["outliers"] = {**facts, "action": action, **({"class": int(cls)} if action == "classify" else {})}
    return out
