"""Pictures of rock-face discontinuities: stereonet of poles, rose of strikes, cloud coloured by joint set.

Conventions (as :mod:`lidarfx.geometry`): x = East, y = North, z = Up, angles in
degrees.  A plane is ``dip`` (0–90°) and ``dip_direction`` (azimuth of the
down-dip direction); strike = dip direction − 90° (right-hand rule, what
mplstereonet takes); its pole plunges 90° − dip towards dip direction + 180°.

* :func:`stereonet_view` — lower-hemisphere equal-area (Schmidt) net of the
  poles with Kamb density contours, the poles coloured by joint set and each
  set's mean plane (great circle), mean pole and α95 cone.
* :func:`rose_view` — axial rose diagram of strikes, stacked by joint set.
* :func:`set_view` — the cloud coloured by joint set, seen along a view normal
  (z-buffered raster: the point nearest to the viewer per pixel).
* :func:`orientation_summary_view` — stereonet and rose side by side.

The drawing lives in private helpers that take an ``ax`` and return what they
drew (positions, bin heights, the raster), so the pictures can be checked.
matplotlib and mplstereonet are imported inside the functions.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import LidarfxError, check_int
from . import save_figure
from .palette import set_colour, set_colours

__all__ = ["stereonet_view", "rose_view", "set_view", "orientation_summary_view"]

DENSITY_METHODS = ("exponential_kamb", "linear_kamb", "square_kamb", "kamb", "schmidt")
"""Density estimators of mplstereonet (``density_contourf(method=...)``)."""

_SEED = 0  # fixed seed of every subsample (poles, points): the same input gives the same picture
_DENSITY_CMAP_RANGE = (0.0, 0.75)  # a light part of "Greys": the coloured poles stay visible on top
_MIN_DENSITY_POLES = 3


# ----------------------------------------------------------------------------- input checks


def _vector(name: str, values: Any) -> np.ndarray:
    """``values`` as a 1-D float array (one-line error if it is not numeric)."""
    try:
        a = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise LidarfxError(f"{name} must be numbers") from None
    if a.ndim == 0:
        a = a.reshape(1)
    if a.ndim != 1:
        raise LidarfxError(f"{name} must be one-dimensional, got shape {a.shape}")
    return a


def _same_length(name: str, a: np.ndarray, ref_name: str, n: int) -> None:
    if len(a) != n:
        raise LidarfxError(f"{name} must have one value per {ref_name}: got {len(a):,} for {n:,}")


def _weights(weights: Any, n: int, what: str) -> np.ndarray | None:
    """Finite, non-negative weights of length ``n`` (``None`` stays ``None``)."""
    if weights is None:
        return None
    w = _vector("weights", weights)
    _same_length("weights", w, what, n)
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise LidarfxError("weights must be finite and non-negative")
    if len(w) and not w.sum() > 0:
        raise LidarfxError("weights must not all be zero")
    return w


def _ids(set_ids: Any, n: int, what: str) -> np.ndarray | None:
    """Integer joint-set ids of length ``n`` (< 0 = no set; ``None`` stays ``None``)."""
    if set_ids is None:
        return None
    raw = np.asarray(set_ids)
    if raw.ndim == 0:
        raw = raw.reshape(1)
    if raw.ndim != 1 or (raw.size and raw.dtype.kind not in "iu" and not (
            raw.dtype.kind == "f" and np.all(np.isfinite(raw)) and np.all(raw == np.round(raw)))):
        raise LidarfxError("set_ids must be a one-dimensional array of integers (< 0 = no set)")
    ids = raw.astype(np.int64)
    _same_length("set_ids", ids, what, n)
    return ids


def _orientations(dip: Any, dip_direction: Any, weights: Any, set_ids: Any) -> dict:
    """Checked planes: rows with a NaN / infinite dip or dip direction are dropped.

    Returns ``dip``, ``dip_direction`` (0 ≤ · < 360), ``strike`` (right-hand rule),
    ``weights`` and ``set_ids`` (or ``None``) of the kept rows and ``dropped``.
    """
    d = _vector("dip", dip)
    a = _vector("dip_direction", dip_direction)
    _same_length("dip_direction", a, "dip", len(d))
    w = _weights(weights, len(d), "plane")
    ids = _ids(set_ids, len(d), "plane")
    ok = np.isfinite(d) & np.isfinite(a)
    if np.any((d[ok] < -1e-6) | (d[ok] > 90 + 1e-6)):
        raise LidarfxError("dip must be from 0 to 90 degrees (flip normals up before converting)")
    d = np.clip(d[ok], 0.0, 90.0)
    a = np.mod(a[ok], 360.0)
    return {"dip": d, "dip_direction": a, "strike": np.mod(a - 90.0, 360.0),
            "weights": None if w is None else w[ok], "set_ids": None if ids is None else ids[ok],
            "dropped": int(np.count_nonzero(~ok))}


def _set_records(sets: Sequence[Mapping[str, Any]]) -> list[dict]:
    """Checked set summaries: ``id``, ``dip``, ``dip_direction`` and optional ``kappa``,
    ``alpha95`` (degrees), ``share`` (a fraction 0–1)."""
    out = []
    for i, rec in enumerate(sets or ()):
        if not isinstance(rec, Mapping):
            raise LidarfxError(f"sets[{i}] must be a dict with id, dip and dip_direction")
        try:
            r = {"id": int(rec["id"]), "dip": float(rec["dip"]), "dip_direction": float(rec["dip_direction"]) % 360.0}
        except KeyError as e:
            raise LidarfxError(f"sets[{i}] has no {e.args[0]!r}") from None
        except (TypeError, ValueError):
            raise LidarfxError(f"sets[{i}]: id, dip and dip_direction must be numbers") from None
        if not (0.0 <= r["dip"] <= 90.0) or not math.isfinite(r["dip_direction"]):
            raise LidarfxError(f"sets[{i}]: dip must be from 0 to 90 degrees and dip_direction finite")
        for key in ("kappa", "alpha95", "share"):
            v = rec.get(key)
            if v is not None:
                try:
                    v = float(v)
                except (TypeError, ValueError):
                    raise LidarfxError(f"sets[{i}]: {key} must be a number") from None
                r[key] = v if math.isfinite(v) else None
            else:
                r[key] = None
        out.append(r)
    return out


def _subsample(n: int, limit: int) -> np.ndarray:
    """Sorted indices of at most ``limit`` of ``n`` items (seeded, without replacement)."""
    if n <= limit:
        return np.arange(n)
    return np.sort(np.random.default_rng(_SEED).choice(n, limit, replace=False))


def _set_label(r: dict) -> str:
    """``set 0: 80/170, κ 120, α95 1.2°, 45 %`` (dip/dip direction; the parts that are known)."""
    parts = [f"set {r['id']}: {r['dip']:02.0f}/{r['dip_direction']:03.0f}"]
    if r.get("kappa") is not None:
        k = r["kappa"]
        parts.append(f"κ {k:.0f}" if k >= 10 else f"κ {k:.1f}")
    if r.get("alpha95") is not None:
        parts.append(f"α95 {r['alpha95']:.1f}°")
    if r.get("share") is not None:
        parts.append(f"{100 * r['share']:.0f} %")
    return ", ".join(parts)


def _density_label(method: str, sigma: float) -> str:
    """Colour-bar label in mplstereonet's units of ``method``."""
    if method == "schmidt":
        return "density (% of poles per 1 % area; uniform = 1)"
    name = {"exponential_kamb": "exponential Kamb", "linear_kamb": "linear Kamb",
            "square_kamb": "inverse-square Kamb", "kamb": "Kamb"}[method]
    return f"{name} density (standard deviations, σ = {sigma:g})"


def _save_quiet(fig, path: str | Path, dpi: int) -> Path:
    """:func:`lidarfx.render.save_figure` without tight_layout's warning about mplstereonet's hidden
    azimuth axes (:func:`_primitive_labels` leaves it empty)."""
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="This figure includes Axes that are not compatible with tight_layout")
        return save_figure(fig, path, dpi)


# ----------------------------------------------------------------------------- stereonet


def _primitive_labels(ax) -> None:
    """N, E, S, W and 10° ticks around the primitive circle, in axes coordinates (the
    stereonet is the circle inscribed in its axes), so they follow the axes in any layout
    (mplstereonet's azimuth labels live on a hidden axes that a colour bar leaves behind)."""
    ax.set_azimuth_ticks([])
    for az in range(0, 360, 10):
        t = math.radians(az)
        r0, r1 = 0.5, 0.5 + (0.022 if az % 90 == 0 else 0.012)
        ax.plot([0.5 + r0 * math.sin(t), 0.5 + r1 * math.sin(t)], [0.5 + r0 * math.cos(t), 0.5 + r1 * math.cos(t)],
                color="k", lw=0.8, transform=ax.transAxes, clip_on=False, zorder=7)
    for az, lab in ((0, "N"), (90, "E"), (180, "S"), (270, "W")):
        t = math.radians(az)
        ax.text(0.5 + 0.555 * math.sin(t), 0.5 + 0.555 * math.cos(t), lab, transform=ax.transAxes, ha="center",
                va="center", fontsize=9 if az else 11, fontweight="bold", clip_on=False)


def _draw_stereonet(ax, o: dict, sets: list[dict], *, method: str, sigma: float, max_poles: int,
                    colorbar: bool = True, legend: bool = True) -> dict:
    """Draw the poles of the checked planes ``o`` (see :func:`_orientations`) and the set
    records onto an ``equal_area_stereonet`` axes.

    The density is mplstereonet's ``density_grid`` drawn with ``contourf`` and thin
    ``contour`` lines — what ``ax.density_contourf`` does, with the grid computed once.
    Returns ``lon``/``lat`` (radians, the axes' data coordinates) of the poles drawn,
    ``index`` (their rows in ``o``), ``poles`` (the scatter or ``None``), ``density``
    (the filled contour set or ``None``), ``grid`` (``(lon, lat, density)`` or ``None``),
    ``colorbar``, and per set record ``mean_poles`` (``(lon, lat)``), ``great_circles``
    and ``cones`` (artists or ``None``).
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import LinearSegmentedColormap
    from matplotlib.ticker import MaxNLocator
    from mplstereonet import density_grid
    from mplstereonet import pole as pole_lonlat

    n = len(o["dip"])
    idx = _subsample(n, max_poles)
    strike, dip = o["strike"][idx], o["dip"][idx]
    lon, lat = pole_lonlat(strike, dip)
    lon, lat = np.atleast_1d(lon), np.atleast_1d(lat)
    out: dict[str, Any] = {"lon": lon, "lat": lat, "index": idx, "poles": None, "density": None, "grid": None,
                           "colorbar": None, "mean_poles": [], "great_circles": [], "cones": []}
    w = None if o["weights"] is None else o["weights"][idx].copy()  # mplstereonet normalises in place
    if len(idx) >= _MIN_DENSITY_POLES and (w is None or w.sum() > 0):
        glon, glat, z = density_grid(strike, dip, measurement="poles", method=method, sigma=sigma, weights=w)
        out["grid"] = (glon, glat, z)
        top = float(np.nanmax(z))
        if top > 0:
            levels = MaxNLocator(nbins=8).tick_values(0.0, top)
            if levels[-1] < top:
                levels = np.r_[levels, top]
            lo, hi = _DENSITY_CMAP_RANGE
            cmap = LinearSegmentedColormap.from_list("light_greys", plt.get_cmap("Greys")(np.linspace(lo, hi, 256)))
            cf = ax.contourf(glon, glat, z, levels=levels, cmap=cmap, zorder=1)
            # thin lines above the dots, so the density stays readable under thousands of poles
            ax.contour(glon, glat, z, levels=levels[1:], colors="0.2", linewidths=0.45, alpha=0.8, zorder=3.5)
            out["density"] = cf
            if colorbar:
                cb = ax.figure.colorbar(cf, ax=ax, shrink=0.6, pad=0.1, aspect=25)
                cb.set_label(_density_label(method, sigma), fontsize=7)
                cb.ax.tick_params(labelsize=6)
                out["colorbar"] = cb
    if len(idx):
        size = 5.0 if len(idx) <= 2000 else 1.0
        alpha = 0.85 if len(idx) <= 2000 else 0.3
        colours = "k" if o["set_ids"] is None else set_colours(o["set_ids"][idx])
        out["poles"] = ax.scatter(lon, lat, s=size, c=colours, linewidths=0, alpha=alpha, zorder=3, rasterized=True)
    handles = []
    for r in sets:
        c = set_colour(r["id"])
        s = r["dip_direction"] - 90.0
        (gc,) = ax.plane(s, r["dip"], color=c, lw=1.6, zorder=4)
        mlon, mlat = pole_lonlat(s, r["dip"])
        ax.plot(mlon, mlat, ls="none", marker="o", ms=7, mfc=c, mec="k", mew=0.9, zorder=6)
        out["great_circles"].append(gc)
        out["mean_poles"].append((float(np.ravel(mlon)[0]), float(np.ravel(mlat)[0])))
        cone = None
        if r.get("alpha95") is not None and r["alpha95"] > 0:
            cone = ax.cone(90.0 - r["dip"], r["dip_direction"] + 180.0, r["alpha95"], facecolor="none",
                           edgecolor=c, linewidth=1.2, zorder=5)
        out["cones"].append(cone)
        handles.append(plt.Line2D([], [], color=c, lw=1.6, marker="o", ms=6, mfc=c, mec="k", mew=0.9,
                                  label=_set_label(r)))
    ax.grid(True, color="0.6", linewidth=0.3, alpha=0.7)
    _primitive_labels(ax)
    if legend and handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.06), fontsize=7.5, frameon=False,
                  title="mean plane (dip/dip direction) and mean pole", title_fontsize=7.5,
                  ncol=1 if len(handles) <= 4 else 2)
    return out


def _pole_note(o: dict, shown: int) -> str:
    """``1,234 poles`` (+ ``, 20,000 drawn`` / ``, 3 without orientation dropped``)."""
    n = len(o["dip"])
    note = (f"{n:,} poles" if n else "no poles, sets only") + (f", {shown:,} drawn" if shown < n else "")
    if o["dropped"]:
        note += f", {o['dropped']:,} without orientation dropped"
    if o["weights"] is not None:
        note += ", weighted"
    return note


def _check_stereonet_options(method: str, sigma: float, max_poles: int) -> int:
    if method not in DENSITY_METHODS:
        raise LidarfxError(f"unknown density method {method!r}: use one of {', '.join(DENSITY_METHODS)}")
    if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma > 0):
        raise LidarfxError(f"sigma must be a positive number, got {sigma!r}")
    return check_int("max_poles", max_poles, 1, 10**9)


def stereonet_view(
    dip: Any,
    dip_direction: Any,
    path: str | Path,
    *,
    weights: Any = None,
    set_ids: Any = None,
    sets: Sequence[Mapping[str, Any]] = (),
    title: str | None = None,
    method: str = "exponential_kamb",
    sigma: float = 3,
    max_poles: int = 20000,
    dpi: int = 150,
) -> Path:
    """Save a lower-hemisphere equal-area (Schmidt) stereonet of the poles of planes.

    ``dip`` / ``dip_direction`` hold one plane per segment or per point.  Drawn:
    filled density contours of the poles (mplstereonet's ``density_grid``, what
    ``ax.density_contourf`` contours, ``method`` and ``sigma`` as there, with thin
    contour lines over the dots; light greys, with a colour bar in
    mplstereonet's units: for the Kamb methods the count in standard deviations
    expected from a uniform sample, so a uniform distribution sits near σ; for
    ``"schmidt"`` % of the poles per 1 % of the area), the poles as small dots
    (coloured by ``set_ids`` via :func:`~lidarfx.render.palette.set_colours`,
    grey for < 0; black without ``set_ids``), and for each record of ``sets``
    (dicts with ``id``, ``dip``, ``dip_direction`` and optionally ``kappa``,
    ``alpha95`` in degrees and ``share`` as a fraction 0–1) its mean plane as
    a great circle, its mean pole as a larger marker and, if ``alpha95`` is
    given, the α95 cone around the mean pole, in the set's colour, with a legend
    line ``set 0: 80/170, κ 120, α95 1.2°, 45 %``.

    ``weights`` (e.g. segment areas; finite, ≥ 0) weight the density (mplstereonet
    normalises them to mean 1, so only their ratios count); they do not change the
    dots.  At most ``max_poles`` poles (a seeded random subsample, keeping their
    weights) are drawn and contoured, so a million points stay fast; note that the
    Kamb smoothing radius depends on the number of poles contoured.  Rows with a
    NaN dip or dip direction are dropped; with no pole left the sets alone are
    drawn, with no sets either it is an error.
    """
    import matplotlib

    dpi = check_int("dpi", dpi, 10, 2400)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mplstereonet  # noqa: F401  (registers the stereonet projections)

    max_poles = _check_stereonet_options(method, sigma, max_poles)
    o = _orientations(dip, dip_direction, weights, set_ids)
    recs = _set_records(sets)
    if not len(o["dip"]) and not recs:
        raise LidarfxError("nothing to draw: no plane with a finite dip and dip direction and no sets")
    fig = plt.figure(figsize=(6.6, 6.4 + 0.17 * len(recs)))
    ax = fig.add_subplot(111, projection="equal_area_stereonet")
    drawn = _draw_stereonet(ax, o, recs, method=method, sigma=sigma, max_poles=max_poles)
    ax.set_title((title or "poles (lower hemisphere, equal area)") + f"\n{_pole_note(o, len(drawn['index']))}",
                 fontsize=9, pad=26)
    return _save_quiet(fig, path, dpi)


# ----------------------------------------------------------------------------- rose


def _rose_heights(strike: np.ndarray, weights: np.ndarray | None, set_ids: np.ndarray | None,
                  bin_width: float) -> dict:
    """Axial bin sums of strikes: each strike ``s`` counts (with its full weight) in the bins
    of ``s`` and ``s + 180``.  Returns ``edges`` (degrees, 0 … 360), ``groups`` (set ids,
    ascending with −1 last; ``[None]`` without ``set_ids``) and ``heights`` (one row per group)."""
    nb = int(round(360.0 / bin_width))
    edges = np.arange(nb + 1) * bin_width
    a = np.mod(strike, 360.0)
    b = np.mod(a + 180.0, 360.0)
    ia = np.minimum((a / bin_width).astype(np.int64), nb - 1)
    ib = np.minimum((b / bin_width).astype(np.int64), nb - 1)
    w = np.ones(len(a)) if weights is None else weights
    if set_ids is None:
        groups: list[int | None] = [None]
        rows = [np.zeros(len(a), bool) | True]
    else:
        ids = np.where(set_ids < 0, -1, set_ids)
        u = np.unique(ids)
        groups = [int(g) for g in u if g >= 0] + ([-1] if np.any(u < 0) else [])
        rows = [ids == g for g in groups]
    heights = np.array([np.bincount(ia[m], w[m], nb) + np.bincount(ib[m], w[m], nb) for m in rows]).reshape(
        len(groups), nb)
    return {"edges": edges, "groups": groups, "heights": heights}


def _check_bin_width(bin_width: Any) -> float:
    try:
        bw = float(bin_width)
    except (TypeError, ValueError):
        bw = float("nan")
    k = 360.0 / bw if math.isfinite(bw) and bw > 0 else 0.0
    if not (0 < bw <= 90 and abs(k - round(k)) < 1e-9):
        raise LidarfxError(f"bin_width must divide 360 and be at most 90 degrees (e.g. 5, 10, 15), got {bin_width!r}")
    return bw


def _draw_rose(ax, strike: np.ndarray, weights: np.ndarray | None, set_ids: np.ndarray | None,
               bin_width: float, *, legend: bool = True) -> dict:
    """Stacked axial rose of ``strike`` on a polar axes (0 = North, clockwise); returns
    :func:`_rose_heights` plus ``bars`` (one bar container per group)."""
    from matplotlib.ticker import MaxNLocator

    r = _rose_heights(strike, weights, set_ids, bin_width)
    edges, heights = r["edges"], r["heights"]
    theta = np.radians(edges[:-1])
    width = np.radians(bin_width)
    bottom = np.zeros(len(theta))
    bars = []
    for g, h in zip(r["groups"], heights):
        colour = "#5b7fa6" if g is None else set_colour(g)
        label = None if g is None else ("no set" if g < 0 else f"set {g}")
        bars.append(ax.bar(theta, h, width=width, bottom=bottom, align="edge", color=colour, edgecolor="white",
                           linewidth=0.5, label=label, zorder=3))
        bottom = bottom + h
    ax.set_theta_zero_location("N")
    ax.set_theta_direction(-1)
    ax.set_thetagrids(np.arange(0, 360, 30), labels=[("N" if t == 0 else "E" if t == 90 else "S" if t == 180 else
                                                     "W" if t == 270 else f"{t}°") for t in range(0, 360, 30)],
                      fontsize=7)
    top = float(bottom.max()) if len(bottom) else 0.0
    rmax = top * 1.05 if top > 0 else 1.0
    ax.set_ylim(0, rmax)
    unit = "count" if weights is None else "weight"
    ticks = [t for t in MaxNLocator(nbins=4).tick_values(0.0, rmax) if 0 < t <= rmax]
    text = [f"{t:,.0f}" if rmax >= 20 else f"{t:g}" for t in ticks]
    ax.set_yticks(ticks, labels=[t + (f" {unit}" if i == len(ticks) - 1 else "") for i, t in enumerate(text)])
    # radial labels along the emptiest half-bin direction away from N/E/S/W, so they sit on no bar
    centres = edges[:-1] + bin_width / 2
    off_axis = np.abs((centres + 45.0) % 90.0 - 45.0) >= min(10.0, bin_width)
    load = np.where(off_axis, bottom, np.inf)
    quiet = float(centres[int(np.argmin(load))]) if len(bottom) and np.isfinite(load).any() else 45.0
    ax.set_rlabel_position(quiet)
    ax.tick_params(axis="y", labelsize=6, labelcolor="0.3")
    ax.grid(True, color="0.75", linewidth=0.4)
    if legend and set_ids is not None:
        ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.05), fontsize=7, frameon=False)
    r["bars"] = bars
    r["unit"] = unit
    return r


def rose_view(
    strike: Any,
    path: str | Path,
    *,
    weights: Any = None,
    set_ids: Any = None,
    bin_width: float = 10,
    title: str | None = None,
    dpi: int = 150,
) -> Path:
    """Save a rose diagram of strikes (degrees, azimuth of the strike direction).

    Polar axes with North up and azimuths clockwise, bins of ``bin_width``
    degrees (a divisor of 360, at most 90) over 0–360°.  Strikes are axial, so
    each strike ``s`` also counts at ``s + 180`` (the usual symmetric rose).
    Bar length is the count of strikes per bin or, with ``weights`` (e.g.
    segment areas; finite, ≥ 0), their weight sum (the radial axis says which);
    with ``set_ids`` the bars are stacked by joint set in the set colours (no set
    in grey, outermost).  NaN strikes are dropped; none left is an error.
    """
    import matplotlib

    dpi = check_int("dpi", dpi, 10, 2400)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = _vector("strike", strike)
    w = _weights(weights, len(s), "strike")
    ids = _ids(set_ids, len(s), "strike")
    bw = _check_bin_width(bin_width)
    ok = np.isfinite(s)
    if not ok.any():
        raise LidarfxError("nothing to draw: no finite strike")
    s, w, ids = s[ok], None if w is None else w[ok], None if ids is None else ids[ok]
    fig = plt.figure(figsize=(6.4, 5.6))
    ax = fig.add_subplot(111, projection="polar")
    _draw_rose(ax, s, w, ids, bw)
    ax.set_title((title or "strikes (axial rose)") + f"\n{len(s):,} strikes, {bw:g}° bins", fontsize=9, pad=16)
    return _save_quiet(fig, path, dpi)


# ----------------------------------------------------------------------------- set view


def _default_view_normal(xyz: np.ndarray) -> np.ndarray:
    """Smallest-variance PCA axis of the points, turned up (z > 0); an exactly vertical
    one (|z| < 1e-3) is turned to look from the South (y < 0), then from the East (x > 0)."""
    c = xyz - xyz.mean(axis=0)
    _, vec = np.linalg.eigh(c.T @ c)
    n = vec[:, 0]
    if abs(n[2]) >= 1e-3:
        return n if n[2] > 0 else -n
    if abs(n[1]) >= 1e-3:
        return n if n[1] < 0 else -n
    return n if n[0] >= 0 else -n


def _image_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(right, up, n)``: the viewer at ``+n`` looking along ``−n`` sees ``right`` to the right
    (horizontal, ``z × n``) and ``up`` upwards (as far up as possible); ``right × up = n``.
    Looking straight down or up, ``right`` is East."""
    n = normal / np.linalg.norm(normal)
    h = np.cross([0.0, 0.0, 1.0], n)
    right = np.array([1.0, 0.0, 0.0]) if np.linalg.norm(h) < 1e-9 else h / np.linalg.norm(h)
    right = right - (right @ n) * n
    right /= np.linalg.norm(right)
    return right, np.cross(n, right), n


def _fill_holes(win: np.ndarray, depth: np.ndarray, min_neighbours: int = 5) -> tuple[np.ndarray, int]:
    """Fill empty cells (``win < 0``) that have at least ``min_neighbours`` of their 8
    neighbours occupied with the neighbour nearest to the viewer (largest ``depth``):
    closes the pin holes a random sampling leaves, not the outline (a straight edge cell
    has 3 occupied neighbours, a convex corner 2).  Returns the new winners and the count filled."""
    nv, nu = win.shape
    pad = np.pad(win, 1, constant_values=-1)
    best = np.full((nv, nu), -1, np.int64)
    best_d = np.full((nv, nu), -np.inf)
    occupied = np.zeros((nv, nu), np.int64)
    for dv in (-1, 0, 1):
        for du in (-1, 0, 1):
            if dv == du == 0:
                continue
            nb = pad[1 + dv: 1 + dv + nv, 1 + du: 1 + du + nu]
            has = nb >= 0
            occupied += has
            d = np.where(has, depth[np.maximum(nb, 0)], -np.inf)
            better = d > best_d
            best = np.where(better, nb, best)
            best_d = np.where(better, d, best_d)
    hole = (win < 0) & (occupied >= min_neighbours)
    out = win.copy()
    out[hole] = best[hole]
    return out, int(np.count_nonzero(hole))


def _set_raster(xyz: Any, set_ids: Any, *, view_normal: Any = None, pixels: int = 1200,
                max_points: int = 2_000_000) -> dict:
    """The cloud seen along ``view_normal`` as an RGB raster of joint-set colours.

    Points are projected on the image frame of :func:`_image_frame`; the raster is
    ``pixels`` cells wide (cells never finer than 1.5 × the mean point spacing, so
    there are few holes, and at most 4 × ``pixels`` rows); each cell shows the point
    nearest to the viewer (largest ``p · n``; the z-buffer kernel
    :func:`lidarfx.render.splat.splat`, one cell per point), and the remaining pin holes
    are filled from their neighbours (:func:`_fill_holes`).  Returns
    ``image`` (``(rows, cols, 3)``, row 0 at the bottom, white = empty), ``extent``
    (metres, for ``imshow``), ``cell``, ``normal``, ``right``, ``up``, ``index`` (the
    points used), ``winner`` (``(rows, cols)``: the shown point as an index into
    ``index``, −1 = empty), ``filled`` (cells filled from neighbours) and ``counts``
    (``{set id: points}`` of all finite input points).
    """
    from .splat import Frame, splat

    p = np.asarray(xyz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise LidarfxError(f"xyz must be an (n, 3) array, got shape {p.shape}")
    ids = _ids(set_ids, len(p), "point")
    pixels = check_int("pixels", pixels, 10, 20000)
    max_points = check_int("max_points", max_points, 1, 10**10)
    finite = np.all(np.isfinite(p), axis=1)
    p, ids = p[finite], ids[finite]
    if not len(p):
        raise LidarfxError("nothing to draw: no point with finite coordinates")
    u_ids, cnt = np.unique(np.where(ids < 0, -1, ids), return_counts=True)
    counts = {int(g): int(c) for g, c in zip(u_ids, cnt)}
    idx = _subsample(len(p), max_points)
    p, ids = p[idx], ids[idx]
    p = p - p.mean(axis=0)
    if view_normal is None:
        if len(p) < 3:
            raise LidarfxError("set_view needs at least 3 points to choose a view_normal; give one")
        n = _default_view_normal(p)
    else:
        n = np.asarray(view_normal, dtype=np.float64).ravel()
        if n.shape != (3,) or not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
            raise LidarfxError(f"view_normal must be a non-zero 3-vector, got {view_normal!r}")
    right, up, n = _image_frame(n)
    u, v, depth = p @ right, p @ up, p @ n
    u0, v0 = float(u.min()), float(v.min())
    ext_u, ext_v = float(u.max()) - u0, float(v.max()) - v0
    spacing = math.sqrt(max(ext_u * ext_v, 1e-12) / len(p))
    cell = max(ext_u / pixels, ext_v / (4 * pixels), 1.5 * spacing, 1e-9)
    nu = max(int(math.ceil(ext_u / cell - 1e-9)), 1)  # exactly ``pixels`` wide when the width sets the cell
    nv = max(int(math.ceil(ext_v / cell - 1e-9)), 1)
    win, _ = splat(u, v, depth, Frame(nu, nv, u0, v0, cell), 0.0)
    win, filled = _fill_holes(np.ascontiguousarray(win[::-1]), depth)  # row 0 at the bottom
    img = np.ones((nv, nu, 3))
    shown = win >= 0
    img[shown] = set_colours(ids[win[shown]])
    return {"image": img, "extent": (0.0, nu * cell, 0.0, nv * cell), "cell": cell, "normal": n, "right": right,
            "up": up, "index": idx, "winner": win, "filled": filled, "counts": counts}


def _azimuth(v: np.ndarray) -> float:
    return float(np.degrees(np.arctan2(v[0], v[1])) % 360.0)


def set_view(
    xyz: Any,
    set_ids: Any,
    path: str | Path,
    *,
    view_normal: Any = None,
    title: str | None = None,
    pixels: int = 1200,
    dpi: int = 150,
    max_points: int = 2_000_000,
) -> Path:
    """Save a picture of the cloud coloured by joint set, seen along ``view_normal``.

    ``view_normal`` points from the rock towards the viewer.  Default: the
    smallest-variance PCA axis of the points turned up (z > 0) — for a face that
    does not overhang that is out of the rock, so a steep face is seen from the
    front; an exactly vertical axis is turned towards the South (−y), then East.
    Give it for an overhanging face or when the scanner stood behind the
    default (e.g. the direction to the scanner).  Image axes: horizontal =
    horizontal direction perpendicular to the view (East when looking straight
    down), vertical = as far up as possible; metres from the lower-left corner.
    A z-buffered raster about ``pixels`` cells wide (see :func:`_set_raster`)
    shows the point nearest to the viewer per cell; colours from
    :func:`~lidarfx.render.palette.set_colours` (set id < 0 grey), empty cells
    white.  At most ``max_points`` points (seeded subsample) are rasterised;
    points with non-finite coordinates are dropped.
    """
    import matplotlib

    dpi = check_int("dpi", dpi, 10, 2400)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = _set_raster(xyz, set_ids, view_normal=view_normal, pixels=pixels, max_points=max_points)
    nv, nu = r["image"].shape[:2]
    w = 8.0
    fig, ax = plt.subplots(figsize=(w, min(max(2.5, w * nv / nu * 0.92 + 0.9), 1.4 * w)))
    ax.imshow(r["image"], origin="lower", interpolation="nearest", extent=r["extent"])
    handles = [plt.Line2D([], [], marker="s", ls="", ms=7, color=set_colour(g),
                          label=("no set" if g < 0 else f"set {g}") + f": {c:,}")
               for g, c in sorted(r["counts"].items(), key=lambda t: (t[0] < 0, t[0]))]
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False,
              title="joint set: points", title_fontsize=7)
    n, right, up = r["normal"], r["right"], r["up"]
    look = -n
    plunge = math.degrees(math.asin(max(-1.0, min(1.0, -look[2]))))
    ax.set_xlabel(f"horizontal, towards azimuth {_azimuth(right):03.0f}° [m]", fontsize=8)
    ax.set_ylabel("up the face [m]" if abs(up[2]) > 1e-6 else f"towards azimuth {_azimuth(up):03.0f}° [m]",
                  fontsize=8)
    ax.tick_params(labelsize=7)
    head = title or "joint sets"
    ax.set_title(f"{head}\nlooking towards azimuth {_azimuth(look):03.0f}°, plunge {plunge:.0f}° "
                 f"(nearest point per {r['cell'] * 100:.0f} cm cell)", fontsize=9)
    return _save_quiet(fig, path, dpi)


# ----------------------------------------------------------------------------- summary


def orientation_summary_view(
    dip: Any,
    dip_direction: Any,
    set_ids: Any,
    sets: Sequence[Mapping[str, Any]],
    path: str | Path,
    *,
    weights: Any = None,
    strike_weights: Any = None,
    title: str | None = None,
    dpi: int = 150,
) -> Path:
    """Save one figure with the stereonet of :func:`stereonet_view` (left) and the rose of
    :func:`rose_view` (right) of the same planes.

    The rose shows the strikes (dip direction − 90°) of the planes with a finite
    orientation, stacked by ``set_ids`` (``None`` = no sets), weighted by
    ``strike_weights`` or, if not given, by ``weights`` (the stereonet's density
    weights).  Subhorizontal planes, whose strike is ill-defined, are counted
    too.  Density: exponential Kamb, σ = 3, at most 20,000 poles.
    """
    import matplotlib

    dpi = check_int("dpi", dpi, 10, 2400)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mplstereonet  # noqa: F401  (registers the stereonet projections)

    d = _vector("dip", dip)
    sw = _weights(strike_weights, len(d), "plane")
    o = _orientations(d, dip_direction, weights, set_ids)
    recs = _set_records(sets)
    if not len(o["dip"]):
        raise LidarfxError("nothing to draw: no plane with a finite dip and dip direction")
    keep = np.isfinite(d) & np.isfinite(_vector("dip_direction", dip_direction))
    rose_w = sw[keep] if sw is not None else o["weights"]
    fig = plt.figure(figsize=(12.0, 6.6 + 0.17 * len(recs)))
    grid = fig.add_gridspec(1, 2, width_ratios=(1.25, 1.0))
    ax1 = fig.add_subplot(grid[0, 0], projection="equal_area_stereonet")
    drawn = _draw_stereonet(ax1, o, recs, method="exponential_kamb", sigma=3, max_poles=20000)
    ax1.set_title(f"poles (lower hemisphere, equal area)\n{_pole_note(o, len(drawn['index']))}", fontsize=9, pad=26)
    ax2 = fig.add_subplot(grid[0, 1], projection="polar")
    _draw_rose(ax2, o["strike"], rose_w, o["set_ids"], 10.0)
    ax2.set_title(f"strikes (axial rose, 10° bins)\n{len(o['strike']):,} planes"
                  + (", weighted" if rose_w is not None else ""), fontsize=9, pad=16)
    if title:
        fig.suptitle(title, fontsize=11)
    return _save_quiet(fig, path, dpi)
