"""``compute_features``: the public entry point of the feature engine."""
from __future__ import annotations

import math
from typing import Callable, Iterable, Sequence

import numba as nb
import numpy as np

from .. import _parallel as parallel
from ..cloud import PointCloud
from ..errors import LidarfxError, check_int, check_seed
from ..neighbors import NeighborIndex, default_cell_for_knn, ring_buffer_size
from ..progress import bar, wanted
from . import slots as S
from .eigen import CONVENTIONS
from .engine import KIND_CYLINDER, KIND_SPHERE, point_features
from .msac import msac_features
from .registry import Request, resolve

NEIGHBOURHOODS = ("sphere", "cylinder", "knn")
_BLOCK = 262_144  # queries per kernel call (progress granularity)


def scale_suffix(radius: float) -> str:
    """Attribute-name suffix of one scale in a multi-scale run: ``_r0.50``."""
    return f"_r{radius:.2f}"


MIN_RADIUS = 1e-9
"""Smallest radius (coordinate units)."""


def radii_list(radius, radii) -> list[float]:
    """``radius`` and/or ``radii`` as one sorted list of distinct positive radii."""
    if radii is None and radius is None:
        return []
    vals: list[float] = []
    for r in ([radius] if radius is not None else []) + list(radii or []):
        vals += list(np.atleast_1d(np.asarray(r, dtype=float)))
    out = sorted(set(float(r) for r in vals))
    if any(not (r > 0 and math.isfinite(r)) for r in out):
        raise LidarfxError(f"radii must be positive numbers, got {out}")
    if out and out[0] < MIN_RADIUS:  # its square underflows towards 0 (densities, thinning divide by it)
        raise LidarfxError(f"radii must be at least {MIN_RADIUS:g}, got {out[0]:g}")
    return out


def _query_index(query, n: int) -> np.ndarray | None:
    if query is None:
        return None
    q = np.asarray(query)
    if q.dtype == bool:
        if q.shape != (n,):
            raise LidarfxError(f"query mask must have length {n}, got {q.shape}")
        return np.flatnonzero(q)
    q = q.astype(np.int64, copy=False).ravel()
    if q.size and (q.min() < 0 or q.max() >= n):
        raise LidarfxError("query indices out of range")
    return q


@nb.njit(cache=True, nogil=True)
def _unpermute_rows(lo, hi, a, inv):
    """In place, for rows ``lo:hi``: a[r, perm[i]] = old a[r, i] — as a gather through the
    inverse permutation ``inv`` (sequential writes), one row at a time (it stays in cache)."""
    for r in range(lo, hi):
        tmp = a[r].copy()
        row = a[r]
        for j in range(tmp.shape[0]):
            row[j] = tmp[inv[j]]


def unpermute_rows(a: np.ndarray, perm: np.ndarray) -> None:
    """In place, for every row of the 2-D ``a``: a[r, perm[i]] = old a[r, i]."""
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.shape[0], dtype=perm.dtype)
    parallel.run(_unpermute_rows, a.shape[0], a, inv, grain=1)


def _grid_order(q: np.ndarray, cell: float) -> np.ndarray:
    """Processing order of query points: by grid column, so neighbours stay in cache."""
    ix = np.floor(q[:, 0] / cell).astype(np.int64)
    iy = np.floor(q[:, 1] / cell).astype(np.int64)
    key = (ix - ix.min(initial=0)) * (int(iy.max(initial=0) - iy.min(initial=0)) + 1) + (iy - iy.min(initial=0))
    return np.argsort(key, kind="stable")


def _suffixes(rs: list[float]) -> list[str]:
    """Attribute-name suffix of every scale ("" for a single one)."""
    return [scale_suffix(r) for r in rs] if len(rs) > 1 else [""]


def _lengths(cloud: PointCloud, units: str, rs: list[float], height, d_max, msac_threshold):
    """The run's lengths in the cloud's coordinate unit (docs/conventions.md: given in metres and
    converted when the LAS CRS is in feet; ``units="native"``: as given): ``(metres per unit,
    radii, height, d_max, msac_threshold)``."""
    from ..crs import length_to_units, metres_per_unit

    u = metres_per_unit(cloud, units)
    if u == 1.0:
        return u, list(rs), height, d_max, msac_threshold
    return (u, [r / u for r in rs], length_to_units(u, height), length_to_units(u, d_max),
            length_to_units(u, msac_threshold))


def scale_names(names: list[str], rs_units: list[float], rs: list[float], neighbourhood: str) -> dict[str, str]:
    """Attribute names of the radii in coordinate units -> names of the same radii in metres
    (the multi-scale suffix names the radius as the user gave it)."""
    if neighbourhood == "knn" or len(rs) < 2 or rs_units == rs:
        return {}
    out = {}
    for su, sm in zip(_suffixes(rs_units), _suffixes(rs)):
        out.update({n: n[: -len(su)] + sm for n in names if n.endswith(su)})
    return out


def _nan_check(arrays: dict, xyz: np.ndarray, rs: list[float], neighbourhood: str, unit: float,
               query_xyz=None, counts: dict | None = None, points: int | None = None) -> list[str]:
    """The warning when most of a computed feature is NaN (:mod:`lidarfx.features.nan`), issued
    and returned.  ``counts`` / ``points``: NaN counts gathered over the pieces of a stream."""
    from .nan import nan_warnings, warn

    if counts is None:
        m = max(len(next(iter(arrays.values()))), 1) if arrays else 1
        shares = {n: np.count_nonzero(np.isnan(v)) / m for n, v in arrays.items()}
    else:
        shares = {n: c / max(points or 1, 1) for n, c in counts.items()}
    msgs = nan_warnings(shares, xyz, radii=rs, suffixes=[""] if neighbourhood == "knn" else _suffixes(rs),
                        neighbourhood=neighbourhood, unit=unit, query_xyz=query_xyz)
    warn(msgs, stacklevel=4)
    return msgs


MAX_HIST_BINS = 1000
"""Most bins of the height-difference histogram (a neighbourhood holds far fewer points)."""
MAX_K = 10_000
"""Most neighbours of a kNN neighbourhood (every query walks at least k points)."""
_KNN_ENTRIES = 4_000_000
"""kNN distances are found for blocks of queries of at most this many (query, neighbour) pairs."""


def check_hist_bins(hist_bins) -> int:
    """The bins of the height-difference histogram: 2 .. :data:`MAX_HIST_BINS`."""
    return check_int("hist_bins", hist_bins, 2, MAX_HIST_BINS)


def check_options(req, rs, neighbourhood="sphere", k=None, convention="default", hist_bins=10, height=None, *,
                  d_max=0.10, msac_threshold=None, msac_iterations=100, seed=0, scanner=None) -> None:
    """Every parameter check of :func:`feature_arrays` (request ``req``, radii
    ``rs`` from :func:`radii_list`), before any work."""
    check_seed(seed)
    if scanner is not None:
        try:
            sc = np.asarray(scanner, dtype=np.float64)
        except (TypeError, ValueError):
            sc = np.zeros(0)
        if sc.shape != (3,) or not np.isfinite(sc).all():
            raise LidarfxError(f"scanner position must be three finite numbers x,y,z, got {scanner!r}")
    for name, v in (("d_max (the plane inlier distance)", d_max), ("msac_threshold", msac_threshold)):
        if v is not None and not (isinstance(v, (int, float, np.integer, np.floating)) and 0 < v < math.inf):
            raise LidarfxError(f"{name} must be a positive finite distance, got {v!r}")
    check_int("msac_iterations", msac_iterations, 1, 1_000_000)
    if neighbourhood not in NEIGHBOURHOODS:
        raise LidarfxError(f"neighbourhood must be one of {', '.join(NEIGHBOURHOODS)}, got {neighbourhood!r}")
    if convention not in CONVENTIONS:
        raise LidarfxError(f"convention must be one of {', '.join(CONVENTIONS)}, got {convention!r}")
    if k is not None and neighbourhood != "knn":
        raise LidarfxError(f"k (the number of neighbours) is for the 'knn' neighbourhood, not {neighbourhood!r}")
    if not req.slots:
        return
    if neighbourhood == "knn":
        if not k or k < 1:
            raise LidarfxError("neighbourhood 'knn' needs k >= 1 (e.g. k=20)")
        if k > MAX_K:
            raise LidarfxError(f"k must be at most {MAX_K} neighbours, got {k}")
        if len(rs) > 1:
            raise LidarfxError("kNN takes at most one radius (the cap)")
    elif not rs:
        raise LidarfxError("give a radius (e.g. radius=0.5) or several radii")
    elif len(set(_suffixes(rs))) < len(rs):
        raise LidarfxError(f"radii {rs} give the same attribute suffix (2 decimals); use radii that differ when rounded to 2 decimals")
    check_hist_bins(hist_bins)
    if height is not None and not height > 0:
        raise LidarfxError("cylinder height limit must be > 0")


def _check_not_empty(xyz: np.ndarray) -> None:
    if len(xyz) == 0:
        raise LidarfxError("the point cloud is empty")


def feature_index(xyz: np.ndarray, neighbourhood: str, k: int | None, rs: list[float], req: Request, *,
                  origin: np.ndarray | None = None, knn_cell: float | None = None) -> NeighborIndex:
    """The index a feature run needs: cells of the largest radius (kNN: sized for k).

    Vertical cylinders (density, height, histogram features; the cylinder
    neighbourhood) take half that cell: a cylinder walks whole columns, and a
    finer ring of columns holds fewer points outside the circle (10 % less
    feature time on the classification default over dense trees; spheres are
    faster with the larger cell).  ``origin`` (default: the per-axis minimum of
    ``xyz``) and ``knn_cell`` (default: from ``xyz``'s extent) let a chunk of a
    larger cloud build the index the whole cloud would have: its features then
    equal the whole cloud's bit for bit (:mod:`lidarfx.tiles`)."""
    if neighbourhood == "knn":
        return NeighborIndex(xyz, knn_cell or default_cell_for_knn(xyz - xyz.min(0), k), origin)
    cylinder = req.need_cylinder or neighbourhood == "cylinder"
    return NeighborIndex(xyz, rs[-1] / 2 if cylinder else rs[-1], origin)


def feature_arrays(
    xyz: np.ndarray,
    features: str | Iterable[str] | None = None,
    *,
    radius: float | None = None,
    radii: Sequence[float] | None = None,
    neighbourhood: str = "sphere",
    k: int | None = None,
    query_xyz: np.ndarray | None = None,
    query_ids: np.ndarray | None = None,
    scanner: Sequence[float] | None = None,
    height: float | None = None,
    convention: str = "default",
    d_max: float = 0.10,
    hist_bins: int = 10,
    msac_threshold: float | None = None,
    msac_iterations: int = 100,
    seed: int = 0,
    progress: bool | None = None,
    index: NeighborIndex | None = None,
) -> dict[str, np.ndarray]:
    """Neighbourhood features as a dict ``name -> float32 array`` (the array-level API).

    ``xyz`` is the neighbour cloud; features are computed at ``query_xyz``
    (default: every point of ``xyz``).  See :func:`compute_features` for the
    parameters.  Per-point features (``return_ratio``) are not handled here.
    """
    req = features if isinstance(features, Request) else resolve(features)
    xyz = np.asarray(xyz, dtype=np.float64)
    if not req.slots:
        check_options(req, [], neighbourhood, k, convention, hist_bins, height, d_max=d_max,
                      msac_threshold=msac_threshold, msac_iterations=msac_iterations, seed=seed, scanner=scanner)
        return {}
    rs = radii_list(radius, radii)
    check_options(req, rs, neighbourhood, k, convention, hist_bins, height, d_max=d_max,
                  msac_threshold=msac_threshold, msac_iterations=msac_iterations, seed=seed, scanner=scanner)
    _check_not_empty(xyz)
    if index is None:
        index = feature_index(xyz, neighbourhood, k, rs, req)
    g = index.grid
    # queries in grid order: consecutive queries share cached neighbours and
    # results are written sequentially; ``perm[i]`` is the output row of query i
    if query_xyz is None:
        q = g.pts  # the cloud itself: the index's sorted points
        perm = index.order
        qid = index.order
    else:
        ql = index.to_local(query_xyz)
        perm = _grid_order(ql, g.cell)
        q = np.ascontiguousarray(ql[perm])
        qid = perm if query_ids is None else np.asarray(query_ids, dtype=np.int64)[perm]
    m = len(q)
    if neighbourhood == "knn":
        # more neighbours than points cannot exist: the search asks for at most n (same answer);
        # only each query's k-th distance is kept, so blocks of queries bound the memory
        kk = min(int(k), len(xyz))
        rk = np.empty(m)
        step = max(1, _KNN_ENTRIES // kk)
        for a in range(0, m, step):
            _, kd = index.knn(q[a:a + step] + index.origin, kk, max_radius=rs[0] if rs else None)
            r_a = np.where(np.isfinite(kd), kd, -np.inf).max(axis=1)
            if rs:
                r_a = np.where(np.isfinite(kd[:, -1]), r_a, rs[0])
            rk[a:a + step] = r_a
        rk = np.maximum(rk, 0.0)
        rad = (rk * (1.0 + 1e-9) + 1e-12).reshape(-1, 1)
        names_for_scale = [""]
    else:
        rad = np.asarray(rs, dtype=np.float64).reshape(1, -1)
        names_for_scale = _suffixes(rs)
    nscale = rad.shape[1]
    kind = KIND_CYLINDER if neighbourhood == "cylinder" else KIND_SPHERE

    col = np.full(S.NSLOTS, -1, np.int64)
    for c, s in enumerate(req.slots):
        col[s] = c
    out = np.empty((nscale, len(req.slots), m), dtype=np.float32)
    if not req.need_engine:
        out.fill(np.nan)  # otherwise the engine initialises every row it writes
    sc = np.zeros(3) if scanner is None else np.asarray(scanner, dtype=np.float64) - index.origin
    hz = np.inf if height is None else float(height)
    nbuf = ring_buffer_size(float(rad.max()), g.cell)
    conv = CONVENTIONS[convention]
    show = wanted(progress)
    with bar("features", m, show) as advance:
        for a in range(0, m, _BLOCK):
            b = min(m, a + _BLOCK)
            if req.need_engine:
                parallel.run(
                    point_features, b - a, *g, q, rad, kind, hz, sc, scanner is not None, col, conv, float(d_max),
                    int(hist_bins), req.need_cylinder, req.need_pass2, nbuf, out, start=a,
                )
            if req.need_msac:
                thr = float(d_max if msac_threshold is None else msac_threshold)
                for s in range(nscale):
                    parallel.run(
                        msac_features, b - a, *g, q, qid, rad, s, kind, hz, sc, scanner is not None, col, thr,
                        10, int(msac_iterations), int(seed), nbuf, out, start=a,
                    )
            advance(b - a)
    unpermute_rows(out.reshape(-1, m), perm)
    result: dict[str, np.ndarray] = {}
    for s, suffix in enumerate(names_for_scale):
        for c, slot in enumerate(req.slots):
            result[S.NAMES[slot] + suffix] = out[s, c]
    return result


def compute_features(
    cloud: PointCloud,
    features: str | Iterable[str] | None = None,
    *,
    radius: float | None = None,
    radii: Sequence[float] | None = None,
    neighbourhood: str = "sphere",
    k: int | None = None,
    query=None,
    scanner: Sequence[float] | None = None,
    height: float | None = None,
    convention: str = "default",
    d_max: float = 0.10,
    hist_bins: int = 10,
    msac_threshold: float | None = None,
    msac_iterations: int = 100,
    seed: int = 0,
    progress: bool | None = None,
    inplace: bool = False,
    units: str = "auto",
) -> PointCloud:
    """Compute per-point features and return a cloud carrying them as attributes.

    Parameters
    ----------
    cloud:
        The neighbour cloud.
    features:
        Group names (``eigen, westin, plane, msac, density, height, histogram,
        distribution, curvature, eigenvectors, count, echo, ground``), single
        feature names (``slope``), ``all`` (every group but ``ground``), or a
        comma-separated string of them.  Default: ``eigen, plane, density``.
        ``height_above_ground`` (group ``ground``) uses the cloud's class 2
        points, or runs :func:`lidarfx.ground.classify_ground` when there are none.
    radius, radii:
        One radius, or several (multi-scale: names get the suffix ``_r0.50``), in metres
        (converted when the LAS CRS is in feet; see ``units``).
        With ``neighbourhood="knn"`` an optional radius caps the kNN search.
    neighbourhood:
        ``sphere`` (3-D), ``cylinder`` (vertical, 2-D distance) or ``knn``.
        It decides the neighbours of the covariance features (eigen, westin,
        plane, msac, distribution, curvature); density always compares the
        sphere with the cylinder, height and histogram features always use the
        cylinder.
    k:
        Number of neighbours for ``knn`` (the query point counts as one).
    query:
        Boolean mask or indices of the points to compute features for; all
        points of ``cloud`` still serve as neighbours.  The result then holds
        only the query points.
    scanner:
        Scanner position (x, y, z) for TLS: normals are oriented towards it
        instead of up.
    height:
        Half-height limit of the vertical cylinder (m; default: unbounded).
    convention:
        ``default`` (docs/features.md §3), ``cloudcompare`` (raw eigenvalues in
        omnivariance / eigenentropy, as CloudCompare and jakteristics) or
        ``pdal`` (square roots of the eigenvalues in the ratio features, as
        PDAL's SQRT mode and pgeof; pgeof also adds 1e-3 to its denominators).
        docs/features.md lists exactly what each convention reproduces.
    d_max:
        Distance to the local plane that counts as inlier (m), also the MSAC
        threshold unless ``msac_threshold`` is given.
    hist_bins:
        Bins of Lang's height-difference histogram.
    msac_iterations, seed:
        Upper bound of MSAC trials and the seed of its generator.
    progress:
        Show a progress bar (default: on a terminal for large clouds).
    inplace:
        Add the features to ``cloud`` itself instead of a new cloud (ignored
        with ``query``).
    units:
        ``"auto"`` (default): the lengths ``radius``, ``radii``, ``height``, ``d_max`` and
        ``msac_threshold`` are metres, converted to the coordinate unit when the LAS header's
        CRS names another linear unit (US survey feet, feet); ``"native"``: they are in
        coordinate units as given.  Positions (``scanner``) are coordinates, and the features
        themselves are in the coordinate unit (plane_std, z_range, densities ...), like the
        coordinates (docs/conventions.md).

    Returns
    -------
    PointCloud
        Features as float32 attributes; NaN where not computable (fewer than 3
        neighbours for covariance features, 6 for curvature, flat ground for
        aspect, ...).  ``result.meta["features"]`` lists the names written.
        When more than half of the points are NaN for a feature, a
        :class:`~lidarfx.errors.LidarfxWarning` names it with the likely cause (a radius
        below the point spacing) and a radius that works (:mod:`lidarfx.features.nan`);
        ``result.meta["feature_warnings"]`` holds it too.
    """
    if not isinstance(cloud, PointCloud):
        raise LidarfxError("compute_features expects a PointCloud (see lidarfx.read)")
    req = resolve(features)
    qi = _query_index(query, len(cloud))
    rs = radii_list(radius, radii) if req.slots else []
    check_options(req, rs, neighbourhood, k, convention, hist_bins, height, d_max=d_max,  # metres, as given
                  msac_threshold=msac_threshold, msac_iterations=msac_iterations, seed=seed, scanner=scanner)
    unit, rs_units, height, d_max, msac_threshold = _lengths(cloud, units, rs, height, d_max, msac_threshold)
    arrays = feature_arrays(
        cloud.xyz,
        req,
        radii=rs_units,
        neighbourhood=neighbourhood,
        k=k,
        query_xyz=None if qi is None else cloud.xyz[qi],
        query_ids=qi,
        scanner=scanner,
        height=height,
        convention=convention,
        d_max=d_max,
        hist_bins=hist_bins,
        msac_threshold=msac_threshold,
        msac_iterations=msac_iterations,
        seed=seed,
        progress=progress,
    )
    rename = scale_names(list(arrays), rs_units, rs, neighbourhood)
    if rename:
        arrays = {rename.get(n, n): v for n, v in arrays.items()}
    msgs = _nan_check(arrays, cloud.xyz, rs, neighbourhood, unit, None if qi is None else cloud.xyz[qi])
    point = {name: point_feature(name, cloud) for name in req.point}
    if qi is not None:
        result = cloud.subset(qi)
        point = {k: v[qi] for k, v in point.items()}
    elif inplace:
        result = cloud
    else:
        result = PointCloud(cloud.xyz, dict(cloud.attrs), cloud.header, cloud.meta)
    result.update(point)
    result.update(arrays)
    result.meta["features"] = list(req.point) + list(arrays)
    if msgs:
        result.meta["feature_warnings"] = msgs
    return result


def stream_features(
    cloud: PointCloud,
    features: str | Iterable[str] | None = None,
    *,
    radius: float | None = None,
    radii: Sequence[float] | None = None,
    neighbourhood: str = "sphere",
    k: int | None = None,
    scanner: Sequence[float] | None = None,
    height: float | None = None,
    convention: str = "default",
    d_max: float = 0.10,
    hist_bins: int = 10,
    msac_threshold: float | None = None,
    msac_iterations: int = 100,
    seed: int = 0,
    units: str = "auto",
) -> tuple[list[str], Callable[[int, int], dict[str, np.ndarray]]]:
    """The features of :func:`compute_features`, computed piece by piece.

    Returns ``(names, fill)``: the attribute names in the order
    :func:`compute_features` writes them, and ``fill(start, stop)``, which
    computes the features of points ``start:stop`` of ``cloud`` (every point
    stays a neighbour; one index is built here and shared) as a dict of
    float32 arrays.  Values equal :func:`compute_features`' exactly.  Meant for
    writers that stream (``lidarfx.write(cloud, path, fill=fill)``): a file's
    features then never exist in memory all at once.  Parameters as in
    :func:`compute_features` (lengths in metres, ``units``); every check runs here, before
    any work.  Once every point has been filled, the NaN warning of
    :func:`compute_features` is issued; ``fill.warnings`` holds it.
    """
    if not isinstance(cloud, PointCloud):
        raise LidarfxError("stream_features expects a PointCloud (see lidarfx.read)")
    req = resolve(features)
    rs = radii_list(radius, radii) if req.slots else []
    check_options(req, rs, neighbourhood, k, convention, hist_bins, height, d_max=d_max,
                  msac_threshold=msac_threshold, msac_iterations=msac_iterations, seed=seed, scanner=scanner)
    unit, rs_units, height, d_max, msac_threshold = _lengths(cloud, units, rs, height, d_max, msac_threshold)
    if req.slots:
        _check_not_empty(cloud.xyz)
    index = feature_index(cloud.xyz, neighbourhood, k, rs_units, req) if req.slots else None
    point = {name: point_feature(name, cloud) for name in req.point}
    names = list(req.point)
    if req.slots:
        suffixes = [""] if neighbourhood == "knn" else _suffixes(rs)
        names += [S.NAMES[slot] + sfx for sfx in suffixes for slot in req.slots]
    opts = dict(
        radii=rs_units, neighbourhood=neighbourhood, k=k, scanner=scanner, height=height,
        convention=convention, d_max=d_max, hist_bins=hist_bins, msac_threshold=msac_threshold,
        msac_iterations=msac_iterations, seed=seed, progress=False,
    )
    rename: dict[str, str] | None = None
    n = len(cloud)
    seen = {"points": 0, "nan": {}}

    def fill(start: int, stop: int) -> dict[str, np.ndarray]:
        nonlocal rename
        out = {name: values[start:stop] for name, values in point.items()}
        if req.slots:
            ids = np.arange(start, stop, dtype=np.int64)
            arrays = feature_arrays(cloud.xyz, req, query_xyz=cloud.xyz[start:stop], query_ids=ids,
                                    index=index, **opts)
            if rename is None:
                rename = scale_names(list(arrays), rs_units, rs, neighbourhood)
            if rename:
                arrays = {rename.get(k_, k_): v for k_, v in arrays.items()}
            out.update(arrays)
            if seen["points"] < n:  # the NaN warning once every point is done
                seen["points"] += stop - start
                for name, v in arrays.items():
                    seen["nan"][name] = seen["nan"].get(name, 0) + int(np.count_nonzero(np.isnan(v)))
                if seen["points"] >= n:
                    fill.warnings[:] = _nan_check({}, cloud.xyz, rs, neighbourhood, unit, counts=seen["nan"],
                                                  points=seen["points"])
        return out

    fill.warnings = []  # type: ignore[attr-defined]
    return names, fill


def point_feature(name: str, cloud: PointCloud) -> np.ndarray:
    """A per-point feature of every point of ``cloud``."""
    if name == "return_ratio":
        if "return_number" not in cloud or "number_of_returns" not in cloud:
            return np.full(len(cloud), np.nan, np.float32)
        rn = cloud["return_number"].astype(np.float32)
        nr = cloud["number_of_returns"].astype(np.float32)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(nr > 0, rn / nr, np.nan).astype(np.float32)
    if name == "height_above_ground":
        from ..ground import classify_ground, height_above_ground

        cls = cloud.get("classification")
        has_ground = cls is not None and bool(np.any(cls == 2))
        # the cloud's ground class when it has one, else the ground filter's ground
        return height_above_ground(cloud, ground=None if has_ground else classify_ground(cloud))
    raise LidarfxError(f"unknown per-point feature {name!r}")  # pragma: no cover
