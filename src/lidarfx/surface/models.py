"""Surface models of the highest returns: DSM and (pit-free) CHM rasters.

:func:`dsm` — the highest return in every cell (all returns or first returns only; noise
classes 7 and 18 left out), small empty gaps filled by the TIN of the filled cells, larger ones
left as no data.  :func:`chm` — canopy height: the same highest-return raster of the first returns'
heights above the ground (the DSM minus the DTM, subtracted point by point), pit-free by
Khosravipour et al. (2014), negative heights clipped to 0.  The method, the options and the cell
convention are in docs/surfaces.md.

Grid (:func:`lidarfx.surface.raster.grid_layout`, shared with :func:`lidarfx.ground.dtm`): the
south-west corner ``(x0, y0)`` is the extent's minimum snapped down to a multiple of the
resolution ``r``; a point is in column ``floor((x - x0) / r)`` and, counted from the south, row
``floor((y - y0) / r)`` — a point on a cell edge belongs to the cell east / north of it.  The
DSM, the CHM and the DTM of one cloud and resolution share their cells.
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np
from scipy import ndimage

from .. import progress as _progress
from ..cloud import PointCloud
from ..crs import check_units, cloud_crs, metres_per_unit
from ..errors import LidarfxError
from .grid import GridSpec, cell_index, inpaint
from .raster import Raster, grid_layout

__all__ = [
    "dsm",
    "chm",
    "check_options",
    "fill_gaps",
    "highest_surface",
    "MAX_CELLS",
    "MAX_GAP",
    "NOISE_CLASSES",
    "PIT_FREE_THRESHOLDS",
    "THRESHOLD_STEP",
    "GROUND_SOURCES",
]

MAX_CELLS = 100_000_000
"""Largest DSM / CHM (cells) :func:`dsm` and :func:`chm` make (10 km × 10 km at 1 m); a larger one
is refused before anything is allocated.  They need about 60 bytes per cell at their peak."""

MAX_GAP = 5.0
"""Default widest gap (m) that is filled; at least two cells are always filled (see :func:`fill_gaps`)."""

NOISE_CLASSES: tuple[int, ...] = (7, 18)
"""Classes left out of the surface models by default: low noise 7, high noise 18."""

PIT_FREE_THRESHOLDS: tuple[float, ...] = (0.0, 2.0, 5.0, 10.0, 15.0)
"""Height thresholds (m) of the partial CHMs (Khosravipour et al. 2014), continued every
:data:`THRESHOLD_STEP` m above the last one up to the highest return."""

THRESHOLD_STEP = 5.0

GROUND_SOURCES = ("auto", "class", "smrf")
"""``ground`` of :func:`chm` as a word: ``"class"`` (class 2), ``"smrf"`` (the ground filter),
``"auto"`` (class 2 when the cloud has any class 2 point, else the filter)."""

FREEZE_SPACINGS = 3.0
"""The default freeze distance in mean first-return spacings (and in cells, whichever is larger)."""


# --------------------------------------------------------------------------- checks
def _finite_positive(name: str, value: Any, *, zero: bool = False, inf: bool = False) -> float:
    try:
        v = float(value)
        ok = not isinstance(value, (bool, np.bool_)) and (v > 0 or (zero and v == 0)) and \
            (math.isfinite(v) or (inf and v == math.inf))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        what = "a positive number" if not zero else "a number >= 0"
        raise LidarfxError(f"{name} must be {what} (metres{'; inf = no limit' if inf else ''}), got {value!r}")
    return v


def _classes(exclude_classes: Iterable[int] | None) -> list[int]:
    from ..ground import check_ignore_classes

    try:
        return check_ignore_classes(exclude_classes)
    except LidarfxError:
        raise LidarfxError(f"exclude_classes must be class codes from 0 to 255, got {exclude_classes!r}") from None


def _thresholds(thresholds: Any) -> list[float] | None:
    if thresholds is None:
        return None
    try:
        vals = [float(t) for t in np.atleast_1d(np.asarray(thresholds, dtype=object))]
        ok = len(vals) > 0 and all(math.isfinite(v) and v >= 0 for v in vals)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise LidarfxError(f"thresholds must be heights >= 0 (metres), got {thresholds!r}")
    return sorted(set(vals) | {0.0})


def check_options(*, resolution: Any = 1.0, max_gap: Any = None, freeze_distance: Any = None,
                  thresholds: Any = None, exclude_classes: Any = NOISE_CLASSES) -> dict[str, Any]:
    """The options of :func:`dsm` and :func:`chm`, checked before any work (the command line calls
    it before reading): a one-line :class:`LidarfxError` for a bad value.  Returns them parsed:
    ``max_gap`` and ``freeze_distance`` (m, None = default), ``thresholds`` (sorted, with 0, or
    None) and ``exclude_classes`` (a list of codes)."""
    from ..ground.dtm import check_resolution

    check_resolution(resolution)
    return {
        "max_gap": None if max_gap is None else _finite_positive("max_gap", max_gap, zero=True, inf=True),
        "freeze_distance": None if freeze_distance is None else _finite_positive("freeze_distance", freeze_distance),
        "thresholds": _thresholds(thresholds),
        "exclude_classes": _classes(exclude_classes),
    }


def _source(cloud: Any) -> tuple[np.ndarray, dict[str, np.ndarray], PointCloud | None]:
    if isinstance(cloud, PointCloud):
        return cloud.xyz, cloud.attrs, cloud
    xyz = np.asarray(cloud, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise LidarfxError(f"expected a PointCloud or an (n, 3) array of points, got shape {xyz.shape}")
    return xyz, {}, None


def _used(xyz: np.ndarray, attrs: dict, first_returns: bool, exclude: list[int], what: str
          ) -> tuple[np.ndarray, np.ndarray]:
    """``(finite, used)``: points with finite coordinates, and those of them the model uses."""
    finite = np.isfinite(xyz).all(axis=1)
    if not finite.any():
        raise LidarfxError(f"no points{' with finite coordinates' if len(xyz) else ''}: no {what}")
    used = finite.copy()
    if exclude and "classification" in attrs:
        used &= ~np.isin(np.asarray(attrs["classification"]), exclude)
    if first_returns and "return_number" in attrs:
        rn = np.asarray(attrs["return_number"]).astype(np.int64)
        used &= rn <= 1  # 1 = first; 0 = return number unknown (files without return information)
    if not used.any():
        why = []
        if exclude:
            why.append(f"classes {','.join(map(str, exclude))} left out")
        if first_returns:
            why.append("first returns only")
        raise LidarfxError(f"no points left for the {what}" + (f" ({'; '.join(why)})" if why else ""))
    return finite, used


class _Grid:
    """The cells of a product: layout (:func:`grid_layout`) and the local :class:`GridSpec`."""

    def __init__(self, xyz: np.ndarray, finite: np.ndarray, r: float, bounds: Any, what: str) -> None:
        if bounds is None:
            lo = xyz[finite, :2].min(axis=0)
            hi = xyz[finite, :2].max(axis=0)
        else:
            try:
                b = np.asarray(bounds, dtype=np.float64).reshape(4)
            except (TypeError, ValueError):
                b = np.full(4, np.nan)
            if not (np.isfinite(b).all() and b[2] >= b[0] and b[3] >= b[1]):
                raise LidarfxError(f"bounds must be (xmin, ymin, xmax, ymax), got {bounds!r}")
            lo, hi = b[:2], b[2:]
        self.x0, self.y0, self.rows, self.cols = grid_layout(lo, hi, r, max_cells=MAX_CELLS, what=what)
        self.spec = GridSpec(np.zeros((0, 2)), r)
        self.spec.nx, self.spec.ny = self.cols, self.rows

    @property
    def size(self) -> int:
        return self.rows * self.cols

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat cell index (row from the south × cols + column) of the points inside the grid, and
        the mask of those points."""
        local = xy - np.array([self.x0, self.y0])
        c = self.spec.cell
        fj = np.floor(local[:, 0] / c)
        fi = np.floor(local[:, 1] / c)
        inside = (fj >= 0) & (fj < self.cols) & (fi >= 0) & (fi < self.rows)
        i, j = cell_index(local[inside], self.spec)
        return i * self.cols + j, inside

    def raster(self, grid: np.ndarray, crs: Any, meta: dict) -> Raster:
        r = self.spec.cell
        return Raster(grid[::-1].astype(np.float32), (self.x0, self.y0 + self.rows * r), r, crs, meta)


# --------------------------------------------------------------------------- raster steps
def highest_surface(flat: np.ndarray, values: np.ndarray, spec: GridSpec) -> np.ndarray:
    """The largest of ``values`` in every cell (flat index ``row * nx + col``, rows from the
    south): a ``(ny, nx)`` float64 grid, NaN where no value falls."""
    g = np.full(spec.ny * spec.nx, -np.inf)
    np.maximum.at(g, flat, np.asarray(values, dtype=np.float64))
    g[g == -np.inf] = np.nan
    return g.reshape(spec.ny, spec.nx)


def fill_gaps(grid: np.ndarray, spec: GridSpec, max_gap: float) -> np.ndarray:
    """Fill the empty (NaN) cells of ``grid`` that lie in gaps narrower than ``max_gap``.

    The filled values come from the linear TIN of the filled cells (:func:`grid.inpaint`).  An
    empty cell stays empty when it lies in an *empty disk* of diameter ``max_gap``: a disk of
    radius ``max_gap / 2`` around a cell centre that is farther than ``max_gap / 2`` from every
    filled cell centre (exact Euclidean distance transforms).  This is the raster form of
    removing the TIN triangles longer than ``max_gap``: a gap whose filled cells lie at most
    ``max_gap`` apart across it is filled, a wider one is not, and neither are the parts of it
    next to its rim (but for cells in its sharp corners, which no such disk reaches).  A single
    empty cell among filled ones is filled from ``max_gap`` = 2 cells on.  ``max_gap`` = 0:
    nothing is filled; ``inf``: every empty cell is (the nearest filled value outside their
    convex hull).  Same units as ``spec.cell``.
    """
    known = np.isfinite(grid)
    empty = ~known
    if max_gap <= 0 or not empty.any() or not known.any():
        return grid.copy()
    stay = np.zeros_like(empty)
    if math.isfinite(max_gap):
        rho = max_gap / 2.0 / spec.cell  # in cells: the distances of neighbouring centres are exact
        core = ndimage.distance_transform_edt(empty) > rho
        if core.any():
            stay = (ndimage.distance_transform_edt(~core) <= rho) & empty
    if stay[empty].all():
        return grid.copy()
    out = inpaint(grid, spec)
    out[stay] = np.nan
    return out


# --------------------------------------------------------------------------- DSM
def dsm(
    cloud: Any,
    resolution: float = 1.0,
    *,
    first_returns: bool = False,
    exclude_classes: Iterable[int] | None = NOISE_CLASSES,
    max_gap: float | None = None,
    bounds: tuple[float, float, float, float] | None = None,
    crs: dict[str, Any] | None = None,
    units: str = "auto",
    progress: bool | None = None,
) -> Raster:
    """Digital surface model: the highest return in every cell.

    Parameters
    ----------
    cloud:
        A :class:`~lidarfx.PointCloud` or an ``(n, 3)`` array of points (no CRS: metres).
    resolution:
        Cell edge in metres (default 1.0), converted when the LAS CRS names another linear unit
        (``units="native"``: coordinate units as given).  ``Raster.resolution`` is in map units.
    first_returns:
        Only first returns (``return_number`` 1; 0 = unknown counts as first).  Default: all.
    exclude_classes:
        Classes left out (default :data:`NOISE_CLASSES`: 7, 18; ``None`` or ``()``: none).
    max_gap:
        Widest gap (m) filled from the surrounding cells, :func:`fill_gaps`: default
        :data:`MAX_GAP` (5 m) or 2 cells, the larger; 0 = no filling; ``math.inf`` = fill all.
    bounds:
        ``(xmin, ymin, xmax, ymax)`` to cover (map units) instead of the cloud's extent; points
        outside are left out.
    crs:
        CRS dict for the raster; default: from the LAS header.
    progress:
        A spinner while the gaps are filled: ``True`` / ``False`` / ``None`` (a terminal, long work).

    Returns
    -------
    Raster
        float32 heights (the file's z unit), NaN = no data.  A cell holding a used point is the
        largest z among them (to float32 rounding).  Grid as :func:`lidarfx.ground.dtm`: origin
        snapped to multiples of the resolution, over the extent of every point with finite
        coordinates, so DSM, CHM and DTM of a cloud share their cells.  ``meta``: the counts of
        points and cells and the options.
    """
    opts = check_options(resolution=resolution, max_gap=max_gap, exclude_classes=exclude_classes)
    check_units(units)
    xyz, attrs, pc = _source(cloud)
    u = metres_per_unit(pc, units) if pc is not None else 1.0
    r = float(resolution) / u
    gap_m = max(MAX_GAP, 2.0 * float(resolution)) if opts["max_gap"] is None else opts["max_gap"]
    exclude = opts["exclude_classes"]
    finite, used = _used(xyz, attrs, bool(first_returns), exclude, "DSM")
    grid = _Grid(xyz, finite, r, bounds, "DSM")
    flat, inside = grid.cells(xyz[used, :2])
    z = xyz[used, 2][inside]
    if not len(z):
        raise LidarfxError(f"no points inside bounds {tuple(bounds or ())}: no DSM")
    top = highest_surface(flat, z, grid.spec)
    with _progress.stage("DSM: filling gaps", _progress.wanted(progress)):
        out = fill_gaps(top, grid.spec, gap_m / u)
    occupied = int(np.isfinite(top).sum())
    valid = int(np.isfinite(out).sum())
    meta = {
        "product": "dsm",
        "method": "highest",
        "points": int(len(z)),
        "first_returns": bool(first_returns),
        "exclude_classes": exclude,
        "max_gap_m": gap_m,
        "cells": grid.size,
        "cells_with_points": occupied,
        "filled_cells": valid - occupied,
        "nodata_cells": grid.size - valid,
        "lengths": "m",
    }
    return grid.raster(out, cloud_crs(pc) if crs is None else crs, meta)


# --------------------------------------------------------------------------- CHM
def _ground_of(pc: PointCloud | None, xyz: np.ndarray, attrs: dict, ground: Any, units: str,
               smrf: dict | None, progress: bool | None) -> tuple[Any, str]:
    """The ground of :func:`chm`: a boolean mask or a DTM :class:`Raster`, and its name."""
    if isinstance(ground, Raster):
        return ground, "raster"
    if isinstance(ground, str):
        if ground not in GROUND_SOURCES:
            raise LidarfxError(f"ground must be one of {', '.join(GROUND_SOURCES)}, a boolean mask or a DTM raster, "
                               f"got {ground!r}")
        cls2 = np.asarray(attrs["classification"]) == 2 if "classification" in attrs else np.zeros(len(xyz), bool)
        if ground == "class" or (ground == "auto" and cls2.any()):
            if not cls2.any():
                raise LidarfxError("no ground points (class 2): classify the ground first (lidarfx ground) "
                                   "or let the ground filter find them (ground smrf)")
            return cls2, "class 2"
        from ..ground import classify_ground

        try:
            mask = classify_ground(pc if pc is not None else xyz, units=units, progress=progress, **(smrf or {}))
        except TypeError as exc:
            raise LidarfxError(f"smrf: {exc}") from None
        if not mask.any():
            raise LidarfxError("the ground filter found no ground point: no CHM")
        return mask, "smrf"
    mask = np.asarray(ground)
    if mask.dtype != bool or mask.shape != (len(xyz),):
        raise LidarfxError(f"ground must be one of {', '.join(GROUND_SOURCES)}, a boolean mask of length {len(xyz)} "
                           f"or a DTM raster, got {getattr(mask, 'dtype', type(ground))} {mask.shape}")
    if not mask.any():
        raise LidarfxError("no ground points in the ground mask: no CHM")
    return mask, "mask"


def _heights(xyz: np.ndarray, finite: np.ndarray, used: np.ndarray, ground: Any) -> np.ndarray:
    """Height above the ground of the used points (float64, the file's unit): z minus the ground
    TIN under each point (:func:`lidarfx.ground.height_above_ground`), or minus a DTM raster."""
    from ..ground.dtm import height_above_ground

    if isinstance(ground, Raster):
        p = xyz[used]
        return p[:, 2] - ground.sample(p[:, 0], p[:, 1])
    sub = (used | ground) & finite
    hag = height_above_ground(xyz[sub], ground=ground[sub])
    return hag[used[sub]].astype(np.float64)


def _spacing(grid: _Grid, flat: np.ndarray, u: float) -> float:
    """Mean spacing (map units) of the points with cell indices ``flat``: sqrt(area / n) over the
    squares of 2 m (at least one cell) that hold any of them."""
    k = max(1, int(math.ceil(2.0 / u / grid.spec.cell - 1e-9)))  # cells per square
    i, j = np.divmod(flat, grid.cols)
    coarse = (i // k) * (grid.cols // k + 1) + j // k
    area = len(np.unique(coarse)) * (k * grid.spec.cell) ** 2
    return math.sqrt(area / max(len(flat), 1))


def chm(
    cloud: Any,
    resolution: float = 1.0,
    *,
    ground: Any = "auto",
    pit_free: bool = True,
    thresholds: Iterable[float] | None = None,
    freeze_distance: float | None = None,
    max_gap: float | None = None,
    first_returns: bool = True,
    exclude_classes: Iterable[int] | None = NOISE_CLASSES,
    smrf: dict[str, Any] | None = None,
    bounds: tuple[float, float, float, float] | None = None,
    crs: dict[str, Any] | None = None,
    units: str = "auto",
    progress: bool | None = None,
) -> Raster:
    """Canopy height model: the highest first return's height above the ground in every cell.

    Heights are z minus the ground TIN under each point (the surface ``lidarfx dtm`` samples;
    so the CHM is the DSM minus the DTM with the subtraction done per point, which on slopes gives
    a crown's height above the ground under it, not under the cell centre).

    Pit-free (Khosravipour et al. 2014): partial CHMs from the first returns at or above
    successive height ``thresholds`` (0, 2, 5, 10, 15 m, then every 5 m up to the highest
    return), each the highest height per cell with its gaps narrower than ``freeze_distance``
    filled from the TIN of its filled cells (:func:`fill_gaps`: the raster form of removing the
    triangles longer than the freeze distance), combined by their maximum.  A return that went
    deep into a crown is left out of the higher partial CHMs, whose TIN closes the hole it made;
    gaps between crowns wider than the freeze distance stay open.  The partial CHM of threshold 0
    takes every first return (also those a little below the ground TIN) and fills gaps up to
    ``max_gap``, as the plain CHM (``pit_free=False``) does.  Negative heights are clipped to 0.

    Parameters
    ----------
    cloud:
        A :class:`~lidarfx.PointCloud` (or an ``(n, 3)`` array with ``ground`` a mask or a raster).
    resolution:
        Cell edge in metres (default 1.0; converted for files in feet, as :func:`dsm`).
    ground:
        ``"auto"`` (default: class 2 when the cloud has any class 2 point, else the ground filter),
        ``"class"`` (class 2), ``"smrf"`` (:func:`lidarfx.ground.classify_ground` with ``smrf``
        keyword arguments), a boolean ground mask, or a DTM :class:`Raster` (sampled bilinearly).
    pit_free:
        The pit-free combination (default) or only the partial CHM of threshold 0.
    thresholds:
        Heights (m, >= 0) of the partial CHMs; 0 is always one.  Default :data:`PIT_FREE_THRESHOLDS`
        continued every :data:`THRESHOLD_STEP` m up to the highest return.
    freeze_distance:
        Widest gap (m) a partial CHM above 0 fills.  Default: 3 mean first-return spacings or
        3 cells, the larger (the spacing is sqrt(area / points) over the 2 m squares holding any).
        It should exceed the holes between the returns of one crown and stay below the gaps
        between crowns.
    max_gap, first_returns, exclude_classes, bounds, crs, units, progress:
        As :func:`dsm`; ``first_returns`` is on by default (``False``: every return).

    Returns
    -------
    Raster
        float32 heights (the file's z unit) >= 0, NaN = no data, on the grid of :func:`dsm`.
        ``meta``: the ground source and its points, thresholds, freeze distance, counts.
    """
    opts = check_options(resolution=resolution, max_gap=max_gap, freeze_distance=freeze_distance,
                         thresholds=thresholds, exclude_classes=exclude_classes)
    check_units(units)
    xyz, attrs, pc = _source(cloud)
    if pc is None and isinstance(ground, str):
        raise LidarfxError("the CHM of a bare array needs a ground mask or a DTM raster")
    u = metres_per_unit(pc, units) if pc is not None else 1.0
    r = float(resolution) / u
    gap_m = max(MAX_GAP, 2.0 * float(resolution)) if opts["max_gap"] is None else opts["max_gap"]
    freeze_m, given, exclude = opts["freeze_distance"], opts["thresholds"], opts["exclude_classes"]
    finite, used = _used(xyz, attrs, bool(first_returns), exclude, "CHM")
    grid = _Grid(xyz, finite, r, bounds, "CHM")
    flat, inside = grid.cells(xyz[used, :2])
    if not inside.any():
        raise LidarfxError(f"no points inside bounds {tuple(bounds or ())}: no CHM")
    ground_of, source = _ground_of(pc, xyz, attrs, ground, units, smrf, progress)
    wanted = _progress.wanted(progress)
    with _progress.stage("CHM: height above ground", wanted):
        h = _heights(xyz, finite, used, ground_of)[inside]
    if not np.isfinite(h).all():  # a DTM raster with no data under some points
        keep = np.isfinite(h)
        flat, h = flat[keep], h[keep]
        if not len(h):
            raise LidarfxError("the DTM raster has no data under the points: no CHM")
    hmax_m = float(h.max()) * u
    if given is None:
        levels = list(PIT_FREE_THRESHOLDS)
        while levels[-1] + THRESHOLD_STEP <= hmax_m:
            levels.append(levels[-1] + THRESHOLD_STEP)
    else:
        levels = given
    levels = [t for t in levels if t == 0.0 or t <= hmax_m] if pit_free else [0.0]
    if freeze_m is None:
        freeze = FREEZE_SPACINGS * max(grid.spec.cell, _spacing(grid, flat, u))
        freeze_m = round(freeze * u, 9)
    else:
        freeze = freeze_m / u
    with _progress.bar("CHM: partial CHMs", len(levels), wanted) as advance:
        out = fill_gaps(highest_surface(flat, h, grid.spec), grid.spec, gap_m / u)
        occupied = int(np.isfinite(out).sum())  # before the higher layers: cells with points or filled
        advance(1)
        for t in levels[1:]:
            sel = h >= t / u
            layer = fill_gaps(highest_surface(flat[sel], h[sel], grid.spec), grid.spec, freeze)
            np.fmax(out, layer, out=out)
            advance(1)
    raised = int(np.isfinite(out).sum()) - occupied
    np.maximum(out, 0.0, out=out, where=np.isfinite(out))  # negative heights -> 0, NaN stays
    valid = int(np.isfinite(out).sum())
    cells_with_points = len(np.unique(flat))
    meta = {
        "product": "chm",
        "method": "pit-free" if pit_free else "highest",
        "points": int(len(h)),
        "first_returns": bool(first_returns),
        "exclude_classes": exclude,
        "ground": source,
        "ground_points": None if source == "raster" else int(ground_of.sum()),
        "thresholds_m": levels if pit_free else None,
        "freeze_distance_m": freeze_m if pit_free else None,
        "max_gap_m": gap_m,
        "height_max_m": hmax_m,
        "cells": grid.size,
        "cells_with_points": cells_with_points,
        "filled_cells": valid - cells_with_points,
        "cells_only_in_partial_chms": raised,
        "nodata_cells": grid.size - valid,
        "lengths": "m",
    }
    return grid.raster(out, cloud_crs(pc) if crs is None else crs, meta)
