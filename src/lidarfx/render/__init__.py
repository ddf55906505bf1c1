"""Pictures of point clouds and features (matplotlib, headless)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from .._atomic import atomic_path
from ..cloud import PointCloud


def save_figure(fig, path: str | Path, dpi: int) -> Path:
    """Lay out, write the PNG atomically (temporary file, then rename) and close the figure."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        plt.close(fig)
    return Path(path)


def label_axes(ax, xlabel: str = "x (East) [m]", ylabel: str = "y (North) [m]") -> None:
    """Axis labels and tick size of a map panel (plan view by default)."""
    ax.set_xlabel(xlabel, fontsize=8)
    ax.set_ylabel(ylabel, fontsize=8)
    ax.tick_params(labelsize=7)


def _view_axes(view: str) -> tuple[int, int, str, str]:
    views = {"top": (0, 1, "x (East) [m]", "y (North) [m]"), "front": (0, 2, "x [m]", "z [m]"), "side": (1, 2, "y [m]", "z [m]")}
    return views[view]


def feature_views(
    cloud: PointCloud,
    names: Sequence[str],
    path: str | Path,
    *,
    view: str = "front",
    max_points: int = 200_000,
    title: str | None = None,
    labels: dict[str, dict[int, str]] | None = None,
    seed: int = 0,
) -> Path:
    """Save a PNG with one panel per attribute, points coloured by value, seen from ``view``.

    Float attributes use a continuous colour map clipped to their 2–98 %
    range (NaN in grey); integer attributes (classes, ids) a categorical one.
    Points are drawn far to near so the nearest lie on top.  ``labels`` names
    the values of categorical attributes, e.g. ``{"classification": {2: "ground"}}``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rng = np.random.default_rng(seed)
    idx = np.arange(len(cloud))
    if len(idx) > max_points:
        idx = np.sort(rng.choice(len(idx), max_points, replace=False))
    a, b, xl, yl = _view_axes(view)
    depth_axis = ({0, 1, 2} - {a, b}).pop()
    xyz = cloud.xyz[idx] - cloud.origin
    far_first = np.argsort(-xyz[:, depth_axis] if view != "top" else xyz[:, 2])
    xyz = xyz[far_first]
    idx = idx[far_first]
    n = len(names)
    ext = np.ptp(xyz[:, [a, b]], axis=0) + 1e-9
    aspect = float(ext[1] / ext[0])
    w = 6.0
    fig, axes = plt.subplots(n, 1, figsize=(w, max(1.5, min(w * aspect, 6.0)) * n + 0.6), squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        v = np.asarray(cloud[name])[idx]
        if v.dtype.kind in "iub":
            names = (labels or {}).get(name, {})
            cats, codes = np.unique(v, return_inverse=True)
            sc = ax.scatter(xyz[:, a], xyz[:, b], c=codes, s=0.3, cmap="tab10", vmin=0, vmax=9, linewidths=0)
            handles = [
                plt.Line2D([], [], marker="o", ls="", color=plt.cm.tab10(i % 10), label=names.get(int(c), str(c)))
                for i, c in enumerate(cats)
            ]
            ax.legend(handles=handles, title=name, fontsize=6, title_fontsize=7, loc="upper right", markerscale=0.8)
        else:
            v = v.astype(float)
            ok = np.isfinite(v)
            lo, hi = (np.percentile(v[ok], [2, 98]) if ok.any() else (0.0, 1.0))
            ax.scatter(xyz[~ok, a], xyz[~ok, b], c="0.8", s=0.3, linewidths=0)
            sc = ax.scatter(xyz[ok, a], xyz[ok, b], c=v[ok], s=0.3, cmap="viridis", vmin=lo, vmax=hi, linewidths=0)
            fig.colorbar(sc, ax=ax, fraction=0.03, pad=0.01).set_label(name, fontsize=8)
        ax.set_aspect("equal")
        ax.set_xlabel(xl, fontsize=7)
        ax.set_ylabel(yl, fontsize=7)
        ax.tick_params(labelsize=6)
    if title:
        fig.suptitle(title, fontsize=9)
    return save_figure(fig, path, 130)


def _raster_cells(u: np.ndarray, v: np.ndarray, pixels: int, cell: float | None) -> tuple[float, int, int, np.ndarray]:
    """Cell size, raster width and height and the cell index of every point for a picture of about
    ``pixels`` cells along the longer side (never finer than 1.5 × the mean point spacing)."""
    ext_u, ext_v = float(np.ptp(u)) if len(u) else 1.0, float(np.ptp(v)) if len(v) else 1.0
    if cell is None:
        spacing = math.sqrt(max(ext_u * ext_v, 1e-12) / max(len(u), 1))
        cell = max(max(ext_u, ext_v, 1e-9) / max(int(pixels), 10), 1.5 * spacing)
    cell = float(cell)
    nu = int(ext_u / cell) + 1
    nv = int(ext_v / cell) + 1
    iu = np.minimum(((u - u.min()) / cell).astype(np.int64), nu - 1) if len(u) else u.astype(np.int64)
    iv = np.minimum(((v - v.min()) / cell).astype(np.int64), nv - 1) if len(v) else v.astype(np.int64)
    return cell, nu, nv, iv * nu + iu


def _top_of_cells(pix: np.ndarray, key: np.ndarray) -> np.ndarray:
    """Index of the point with the largest ``key`` in every occupied raster cell ``pix``."""
    order = np.lexsort((key, pix))
    if not len(order):
        return order
    return order[np.r_[np.flatnonzero(np.diff(pix[order])), len(order) - 1]]


CLASS_COLOURS = {"ground": "#b08040", "vegetation": "#2e9e3e", "building": "#d6453d", "water": "#3b7dd8",
                 "wire": "#9b4fc4", "pole": "#555555", "roof": "#e07b39", "wall": "#d6453d",
                 # structure classes (lidarfx eigenclass)
                 "isolated": "#000000", "plane": "#e6dfc8", "plane_border": "#1f77b4", "edge": "#d62728",
                 "corner": "#9467bd", "line": "#2ca02c", "line_end": "#17becf", "volume": "#556b2f"}
"""Colours of common class names in :func:`class_raster` and :func:`error_map` (others: the tab10 cycle)."""

NOT_CLASSIFIED = (0.78, 0.78, 0.78)
"""Colour of points without a class index (< 0) in :func:`class_raster`."""


def class_raster(
    xy: np.ndarray, z: np.ndarray, classes: np.ndarray, class_names: Sequence[str], *,
    pixels: int = 600, cell: float | None = None,
) -> dict:
    """Plan-view raster of class indices: each cell shows the class of its highest point.

    ``classes`` are indices into ``class_names`` (< 0 = not classified, drawn in
    :data:`NOT_CLASSIFIED`); empty cells are white.  Returns ``image``
    (``(rows, cols, 3)``, row 0 = south), ``colours`` (``(k, 3)``: :data:`CLASS_COLOURS`
    by name, else the tab10 cycle), ``cell``, ``rows``, ``cols`` and, per point,
    ``pix`` (its cell), plus ``top`` (the highest point of each occupied cell) and ``z``.
    """
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_rgb

    xy = np.asarray(xy, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    cls = np.asarray(classes, dtype=np.int64)
    k = len(class_names)
    cell, nu, nv, pix = _raster_cells(xy[:, 0], xy[:, 1], pixels, cell)
    tab = plt.get_cmap("tab10")
    ccol = np.array([to_rgb(CLASS_COLOURS.get(str(n).lower(), tab(i % 10))) for i, n in enumerate(class_names)])
    top = _top_of_cells(pix, z)
    img = np.ones((nu * nv, 3))
    ok = (cls[top] >= 0) & (cls[top] < k)
    img[pix[top[ok]]] = ccol[cls[top[ok]]]
    img[pix[top[~ok]]] = NOT_CLASSIFIED
    return {"image": img.reshape(nv, nu, 3), "colours": ccol.reshape(k, 3), "cell": cell, "rows": nv, "cols": nu,
            "pix": pix, "top": top, "z": z}


def class_map(
    xy: np.ndarray, z: np.ndarray, classes: np.ndarray, class_names: Sequence[str], path: str | Path, *,
    pixels: int = 700, cell: float | None = None, title: str | None = None, dpi: int = 100,
) -> Path:
    """Plan-view PNG of a classification (class of the highest point per cell; see
    :func:`class_raster`), with the number of points per class in the legend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cr = class_raster(xy, z, classes, class_names, pixels=pixels, cell=cell)
    cls = np.asarray(classes, dtype=np.int64)
    k = len(class_names)
    counts = np.bincount(cls[(cls >= 0) & (cls < k)], minlength=k)
    nv, nu = cr["rows"], cr["cols"]
    w = 7.0
    fig, ax = plt.subplots(figsize=(w + 1.0, max(2.5, min(w * nv / nu, 1.4 * w)) + 0.5))
    ax.imshow(cr["image"], origin="lower", interpolation="nearest", extent=(0, nu * cr["cell"], 0, nv * cr["cell"]))
    handles = [plt.Line2D([], [], marker="s", ls="", color=c, label=f"{n}: {int(m):,}")
               for c, n, m in zip(cr["colours"], class_names, counts)]
    rest = int(len(cls) - counts.sum())
    if rest:
        handles.append(plt.Line2D([], [], marker="s", ls="", color=NOT_CLASSIFIED, label=f"not classified: {rest:,}"))
    ax.legend(handles=handles, fontsize=7, loc="upper right", title="class of the highest point (points)",
              title_fontsize=7)
    label_axes(ax)
    if title:
        ax.set_title(title, fontsize=9)
    return save_figure(fig, path, dpi)


def error_images(
    xy: np.ndarray,
    z: np.ndarray,
    reference: np.ndarray,
    predicted: np.ndarray,
    class_names: Sequence[str],
    *,
    pixels: int = 600,
    cell: float | None = None,
    max_pairs: int = 8,
) -> dict:
    """The two rasters of :func:`error_map` as RGB arrays (row 0 = south) and their legends.

    Returns ``left`` and ``right`` (``(rows, cols, 3)`` floats in 0..1), ``cell`` (m),
    ``class_colours`` (``(k, 3)``), ``pairs`` (``{"ref → pred": points}``, most frequent
    first, at most ``max_pairs``), ``pair_colours`` (same order), ``other`` (points of
    the pairs not shown), ``wrong`` and ``scored`` (point counts).
    """
    import matplotlib.pyplot as plt

    ref = np.asarray(reference, dtype=np.int64)
    pred = np.asarray(predicted, dtype=np.int64)
    k = len(class_names)
    cr = class_raster(xy, z, pred, class_names, pixels=pixels, cell=cell)
    cell, nu, nv, pix, top, z, ccol = cr["cell"], cr["cols"], cr["rows"], cr["pix"], cr["top"], cr["z"], cr["colours"]
    npix = nu * nv
    left = cr["image"].reshape(npix, 3)
    # right: grey by height, then the dominant error pair per cell
    right = np.ones((npix, 3))
    if len(top):
        lo, hi = np.percentile(z, [2, 98])
        g = 0.62 + 0.3 * np.clip((z[top] - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
        right[pix[top]] = np.c_[g, g, g]
    scored = ref >= 0
    wrong = scored & (pred != ref)
    pair = ref * k + pred
    counts = np.bincount(pair[wrong], minlength=k * k)
    ranked = [int(q) for q in np.argsort(-counts, kind="stable") if counts[q] > 0]
    shown = ranked[:max_pairs]
    pmap = plt.get_cmap("tab10" if len(shown) <= 10 else "tab20")
    pcol = {q: np.array(pmap(i % pmap.N)[:3]) for i, q in enumerate(shown)}
    other = np.array([0.2, 0.2, 0.2])
    if wrong.any():
        n_scored = np.bincount(pix[scored], minlength=npix)
        n_wrong = np.bincount(pix[wrong], minlength=npix)
        keys, cnt = np.unique(pix[wrong] * (k * k) + pair[wrong], return_counts=True)
        cells, pairs = keys // (k * k), keys % (k * k)
        best = np.lexsort((-cnt, cells))
        first = best[np.r_[0, np.flatnonzero(np.diff(cells[best])) + 1]]
        c = cells[first]
        col = np.array([pcol.get(int(q), other) for q in pairs[first]])
        a = 0.35 + 0.65 * np.minimum(1.0, n_wrong[c] / np.maximum(n_scored[c], 1) / 0.5)
        right[c] = (1 - a)[:, None] + a[:, None] * col
    return {
        "left": left.reshape(nv, nu, 3), "right": right.reshape(nv, nu, 3), "cell": cell, "class_colours": ccol,
        "pairs": {f"{class_names[q // k]} → {class_names[q % k]}": int(counts[q]) for q in shown},
        "pair_colours": [pcol[q] for q in shown], "other": int(counts[ranked[len(shown):]].sum()),
        "wrong": int(wrong.sum()), "scored": int(scored.sum()),
    }


def error_map(
    xy: np.ndarray,
    z: np.ndarray,
    reference: np.ndarray,
    predicted: np.ndarray,
    class_names: Sequence[str],
    path: str | Path,
    *,
    pixels: int = 600,
    cell: float | None = None,
    title: str | None = None,
    max_pairs: int = 8,
    dpi: int = 100,
) -> tuple[Path, dict[str, int]]:
    """Plan-view PNG of a classification against its reference: where the errors are.

    ``reference`` and ``predicted`` are class indices into ``class_names``
    (reference < 0 = not scored); ``xy`` and ``z`` in metres.  Left panel: the
    predicted class of the highest point of each raster cell.  Right panel: each
    cell holding a misclassified point takes the colour of its most frequent
    error (reference → predicted), paler where errors are a small share of the
    cell's scored points; cells without errors are grey by height.  The legend
    counts points per error pair.  Returns the path and ``{"ref → pred": points}``
    for the pairs drawn (see :func:`error_images`).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    im = error_images(xy, z, reference, predicted, class_names, pixels=pixels, cell=cell, max_pairs=max_pairs)
    nv, nu = im["left"].shape[:2]
    w = 6.0
    fig, axes = plt.subplots(1, 2, figsize=(2 * w + 1.5, max(2.5, min(w * nv / nu, 1.4 * w)) + 0.6), squeeze=False)
    extent = (0, nu * im["cell"], 0, nv * im["cell"])
    for ax, img, head in ((axes[0, 0], im["left"], "predicted class (highest point)"),
                          (axes[0, 1], im["right"], "errors: reference → predicted (dominant per cell)")):
        ax.imshow(img, origin="lower", interpolation="nearest", extent=extent)
        ax.set_title(head, fontsize=9)
        label_axes(ax)
    axes[0, 0].legend(handles=[plt.Line2D([], [], marker="s", ls="", color=c, label=str(n))
                               for c, n in zip(im["class_colours"], class_names)], fontsize=7, loc="upper right")
    handles = [plt.Line2D([], [], marker="s", ls="", color=c, label=f"{lab}: {n:,}")
               for c, (lab, n) in zip(im["pair_colours"], im["pairs"].items())]
    if im["other"]:
        handles.append(plt.Line2D([], [], marker="s", ls="", color=(0.2, 0.2, 0.2), label=f"other: {im['other']:,}"))
    axes[0, 1].legend(handles=handles or [plt.Line2D([], [], ls="", label="no errors")], fontsize=7,
                      loc="upper right", title=f"{im['wrong']:,} of {im['scored']:,} points wrong", title_fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, dpi), im["pairs"]


def segment_view(
    cloud: PointCloud,
    path: str | Path,
    *,
    attribute: str = "segment_id",
    view: str = "top",
    pixels: int = 700,
    cell: float | None = None,
    height_panel: bool = False,
    title: str | None = None,
    dpi: int = 100,
    seed: int = 0,
) -> Path:
    """Save a PNG of the cloud seen from ``view``, one random colour per segment.

    Made for many segments (hundreds or thousands), where a categorical map
    with a legend does not work: each id ≥ 0 gets a random, seeded, saturated
    colour.  The picture is a raster of about ``pixels`` cells along the
    longer side (or of ``cell`` metres; by default never finer than 1.5 × the
    mean point spacing, so sparse ALS has no holes); each cell shows the point
    nearest to the viewer (the highest one seen from the top).  Points without
    a segment (id < 0) are drawn in a grey ramp by height so the context stays
    readable; empty cells are white.  A raster keeps the PNG small whatever
    the number of points.  ``height_panel`` adds a first panel with the same
    raster coloured by z.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a, b, xl, yl = _view_axes(view)
    depth_axis = ({0, 1, 2} - {a, b}).pop()
    xyz = cloud.xyz - cloud.origin
    ids = np.asarray(cloud[attribute]).astype(np.int64)
    cell, nu, nv, pix = _raster_cells(xyz[:, a], xyz[:, b], pixels, cell)
    # nearest to the viewer: highest z from the top, smallest depth from front/side
    near = xyz[:, 2] if view == "top" else -xyz[:, depth_axis]
    win = _top_of_cells(pix, near)
    img = np.ones((nv * nu, 3))
    nid = int(ids.max(initial=-1)) + 1
    # saturated random colours (never grey: grey is for unsegmented points)
    prng = np.random.default_rng(seed)
    k = max(nid, 1)
    hsv = np.c_[prng.uniform(0, 1, k), prng.uniform(0.45, 1.0, k), prng.uniform(0.55, 1.0, k)]
    from matplotlib.colors import hsv_to_rgb

    palette = hsv_to_rgb(hsv)
    seg = ids[win] >= 0
    img[pix[win[seg]]] = palette[ids[win[seg]]]
    rest = win[~seg]
    if len(rest):
        zz = xyz[rest, 2]
        lo, hi = np.percentile(xyz[:, 2], [2, 98])
        g = 0.55 + 0.35 * np.clip((zz - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
        img[pix[rest]] = np.c_[g, g, g]
    img = img.reshape(nv, nu, 3)
    w = 7.0
    npan = 2 if height_panel else 1
    fig, axes = plt.subplots(1, npan, figsize=(w * npan, max(2.0, min(w * nv / nu, 1.4 * w))), squeeze=False)
    extent = (0, nu * cell, 0, nv * cell)
    if height_panel:
        zimg = np.full(nv * nu, np.nan)
        zimg[pix[win]] = cloud.xyz[win, 2] if view == "top" else cloud.xyz[win, depth_axis]
        ax = axes[0, 0]
        im = ax.imshow(zimg.reshape(nv, nu), origin="lower", interpolation="nearest", extent=extent, cmap="viridis")
        fig.colorbar(im, ax=ax, fraction=0.04, pad=0.01).set_label("z [m]" if view == "top" else "depth [m]", fontsize=8)
        ax.set_title("height", fontsize=9)
    ax = axes[0, npan - 1]
    ax.imshow(img, origin="lower", interpolation="nearest", extent=extent)
    for ax in axes[0]:
        label_axes(ax, xl, yl)
    if title:
        axes[0, npan - 1].set_title(title, fontsize=9)
    return save_figure(fig, path, dpi)


def offset_text(v: float) -> str:
    """``− 630,240`` / ``+ 21`` / empty: what was subtracted from a plotted coordinate."""
    if v == 0:
        return ""
    return f"− {v:,.0f}" if v > 0 else f"+ {-v:,.0f}"


LINE_COLOURS = {"edge": "#d62728", "border": "#1f77b4", "reference": "#2ca02c"}
"""Colours of polyline kinds in :func:`lines_view` (other kinds: the tab10 cycle)."""


def _finish_line_map(fig, ax, handles, reference: bool, reference_label: str, span_x: float, span_y: float,
                     x0: float, y0: float, title: str | None, path, dpi: int) -> Path:
    """Legend (with the reference entry), extent, labels and title of a plan view of lines; saves it."""
    import matplotlib.pyplot as plt

    if reference:
        handles = [*handles, plt.Line2D([], [], color=LINE_COLOURS["reference"], lw=5, alpha=0.45, label=reference_label)]
    if handles:
        ax.legend(handles=handles, fontsize=7, loc="upper right", framealpha=0.85)
    ax.set_xlim(0, span_x)
    ax.set_ylim(0, span_y)
    ax.set_aspect("equal")
    label_axes(ax, f"x (East) {offset_text(x0)} [m]", f"y (North) {offset_text(y0)} [m]")
    if title:
        ax.set_title(title, fontsize=9)
    return save_figure(fig, path, dpi)


def lines_view(
    cloud: PointCloud,
    lines: Sequence,
    path: str | Path,
    *,
    reference: Sequence[np.ndarray] | None = None,
    reference_label: str = "reference",
    window: tuple[float, float, float, float] | None = None,
    pixels: int = 900,
    title: str | None = None,
    dpi: int = 110,
) -> Path:
    """Plan view of 3-D polylines over the points: a grey raster of the highest point per
    cell (darker = higher), every polyline in the colour of its ``kind`` (edge red, border
    blue) and, when given, ``reference`` polylines ((k, 2 or 3) arrays, world x/y) as wide
    translucent green lines under them.  ``window`` = (x_min, y_min, x_max, y_max) in world
    coordinates zooms in.  Axes are metres relative to the window's (or cloud's) minimum."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xyz = cloud.xyz
    if window is not None:
        x0, y0, x1, y1 = (float(v) for v in window)
        keep = (xyz[:, 0] >= x0) & (xyz[:, 0] <= x1) & (xyz[:, 1] >= y0) & (xyz[:, 1] <= y1)
        xyz = xyz[keep]
    else:
        x0, y0 = (float(v) for v in xyz[:, :2].min(axis=0)) if len(xyz) else (0.0, 0.0)
        x1, y1 = (float(v) for v in xyz[:, :2].max(axis=0)) if len(xyz) else (1.0, 1.0)
    fig_w = 8.0
    span_x, span_y = max(x1 - x0, 1e-9), max(y1 - y0, 1e-9)
    fig, ax = plt.subplots(figsize=(fig_w, max(3.0, min(fig_w * span_y / span_x, 1.4 * fig_w)) + 0.4))
    if len(xyz):
        u, v = xyz[:, 0] - x0, xyz[:, 1] - y0
        cell, nu, nv, pix = _raster_cells(np.r_[u, 0.0, span_x], np.r_[v, 0.0, span_y], pixels, None)
        pix = pix[:-2]
        top = _top_of_cells(pix, xyz[:, 2])
        img = np.full(nu * nv, np.nan)
        img[pix[top]] = xyz[top, 2]
        lo, hi = np.nanpercentile(img, [2, 98]) if np.isfinite(img).any() else (0.0, 1.0)
        ax.imshow(img.reshape(nv, nu), origin="lower", interpolation="nearest", cmap="Greys", vmin=lo - 0.5 * (hi - lo),
                  vmax=hi, extent=(0, nu * cell, 0, nv * cell))
    for ref in reference or []:
        r = np.asarray(ref, dtype=np.float64)
        ax.plot(r[:, 0] - x0, r[:, 1] - y0, "-", lw=5, alpha=0.45, color=LINE_COLOURS["reference"], solid_capstyle="round")
    tab = plt.get_cmap("tab10")
    kinds: dict[str, list[float]] = {}
    for pl in lines:
        ring = pl.ring
        if window is not None and not ((ring[:, 0] >= x0) & (ring[:, 0] <= x1) & (ring[:, 1] >= y0) & (ring[:, 1] <= y1)).any():
            continue
        colour = LINE_COLOURS.get(pl.kind, tab(len(kinds) % 10))
        ax.plot(ring[:, 0] - x0, ring[:, 1] - y0, "-", lw=1.3, color=colour)
        kinds.setdefault(pl.kind, []).append(pl.length)
    handles = [plt.Line2D([], [], color=LINE_COLOURS.get(k, tab(i % 10)), lw=2, label=f"{k}: {len(v)} lines, {sum(v):,.0f} m")
               for i, (k, v) in enumerate(sorted(kinds.items()))]
    return _finish_line_map(fig, ax, handles, bool(reference), reference_label, span_x, span_y, x0, y0, title, path, dpi)


def powerline_view(result, path: str | Path, *, title: str | None = None, max_profiles: int = 12,
                   dpi: int = 110) -> Path:
    """Plan view of a power-line result (points grey by height, pylons red, each
    conductor's catenary in its own colour) above one profile per span (horizontal
    distance along the span against height: the conductors' points and curves and the
    ground under them).  ``result`` is a :class:`lidarfx.powerlines.PowerLines`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cloud = result.cloud
    xyz = cloud.xyz
    spans = result.spans[:max_profiles]
    ncol = 2 if len(spans) > 1 else 1
    nrow = int(math.ceil(len(spans) / ncol))
    ext = np.ptp(xyz[:, :2], axis=0) if len(xyz) else np.ones(2)
    plan_h = float(np.clip(10.0 * ext[1] / max(ext[0], 1e-9), 2.5, 9.0))
    fig = plt.figure(figsize=(11, plan_h + 0.8 + 2.6 * nrow))
    gs = fig.add_gridspec(1 + nrow, ncol, height_ratios=[plan_h + 0.8] + [2.6] * nrow)
    ax = fig.add_subplot(gs[0, :])
    x0, y0 = (float(v) for v in xyz[:, :2].min(axis=0)) if len(xyz) else (0.0, 0.0)
    if len(xyz):
        step = max(1, len(xyz) // 200_000)
        q = xyz[::step]
        ax.scatter(q[:, 0] - x0, q[:, 1] - y0, s=0.2, c=q[:, 2], cmap="Greys", alpha=0.5, linewidths=0, rasterized=True)
    cls = np.asarray(cloud["classification"]) if "classification" in cloud else None
    if cls is not None and (cls == 15).any():
        p = xyz[cls == 15]
        ax.scatter(p[:, 0] - x0, p[:, 1] - y0, s=1.5, c="#d62728", linewidths=0, label="pylon points")
    tab = plt.get_cmap("tab20")
    for cd in result.conductors:
        cv = cd.curve(1.0)
        ax.plot(cv[:, 0] - x0, cv[:, 1] - y0, "-", lw=0.9, color=tab(cd.bundle_id % 20))
    for p in result.pylons:
        ax.plot(p["position"][0] - x0, p["position"][1] - y0, "^", color="#d62728", ms=7, mec="k")
        ax.annotate(f"P{p['id']}", (p["position"][0] - x0, p["position"][1] - y0), fontsize=7, xytext=(4, 4),
                    textcoords="offset points")
    ax.set_aspect("equal")
    label_axes(ax, f"x (East) {offset_text(x0)} [m]", f"y (North) {offset_text(y0)} [m]")
    ax.set_title(title or f"{len(result.conductors)} conductors, {len(result.spans)} spans, {len(result.pylons)} pylons",
                 fontsize=9)
    for k, sp in enumerate(spans):
        a2 = fig.add_subplot(gs[1 + k // ncol, k % ncol])
        cds = [cd for cd in result.conductors if cd.span_id == sp["id"]]
        if not cds:
            continue
        ref = cds[0]
        for cd in cds:
            pts = xyz[cd.index]
            s = (pts[:, :2] - ref.start[:2]) @ ref.direction
            a2.plot(s, pts[:, 2], ".", ms=1.2, color=tab(cd.bundle_id % 20), alpha=0.5)
            cv = cd.curve(1.0)
            a2.plot((cv[:, :2] - ref.start[:2]) @ ref.direction, cv[:, 2], "-", lw=0.8, color="k")
        if result.objects is not None and len(result.objects):
            ob = result.objects
            so = (ob[:, :2] - ref.start[:2]) @ ref.direction
            do = np.abs((ob[:, :2] - ref.start[:2]) @ np.array([-ref.direction[1], ref.direction[0]]))
            near = (so >= 0) & (so <= ref.length) & (do <= 15.0)
            a2.plot(so[near], ob[near, 2], ".", ms=0.8, color="#2ca02c", alpha=0.4)
        if result.ground_z is not None:
            ss = np.linspace(0.0, ref.length, 200)
            g = result.ground_z(ref.start[:2] + ss[:, None] * ref.direction)
            a2.fill_between(ss, g, g.min() - 1.0, color="#c8b68e", lw=0)
        a2.set_title(f"span {sp['id']}: {len(cds)} conductors, {sp['length']:.0f} m", fontsize=8)
        a2.set_xlabel("along the span [m]", fontsize=7)
        a2.set_ylabel("z [m]", fontsize=7)
        a2.tick_params(labelsize=6)
    fig.tight_layout()
    return save_figure(fig, path, dpi)


def hillshade(z: np.ndarray, cell: float, *, azimuth: float = 315.0, altitude: float = 45.0) -> np.ndarray:
    """Lambert shading (0–1) of a north-up height grid (row 0 = north) under a sun at
    ``azimuth`` (clockwise from North) and ``altitude`` degrees; NaN cells stay NaN."""
    z = np.asarray(z, dtype=np.float64)
    rows, cols = z.shape
    if min(rows, cols) < 2:  # one row or column: repeat it, so that it shades as flat across
        z = np.pad(z, [(0, max(0, 2 - rows)), (0, max(0, 2 - cols))], mode="edge")
    gy, gx = np.gradient(z, cell)
    gy = -gy  # rows run south
    n = np.dstack([-gx, -gy, np.ones_like(gx)])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    az, alt = math.radians(azimuth), math.radians(altitude)
    sun = np.array([math.cos(alt) * math.sin(az), math.cos(alt) * math.cos(az), math.sin(alt)])
    return np.clip(n @ sun, 0.0, 1.0)[:rows, :cols]


def breakline_view(dtm, lines: Sequence, path: str | Path, *, reference: Sequence[np.ndarray] | None = None,
                   title: str | None = None, dpi: int = 110) -> Path:
    """Hillshade of a DTM (:class:`lidarfx.surface.raster.Raster`) with 3-D polylines drawn in plan
    view (convex breaks red, concave blue; ``attrs["form"]``) and optional reference lines
    (wide translucent green).  Axes in metres from the raster's south-west corner."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    z = np.asarray(dtm.array, dtype=np.float64)
    rows, cols = z.shape
    cell = float(dtm.resolution)
    x0, ytop = (float(v) for v in dtm.origin)
    y0 = ytop - rows * cell
    span_x, span_y = cols * cell, rows * cell
    fig_w = 8.0
    fig, ax = plt.subplots(figsize=(fig_w, max(3.0, min(fig_w * span_y / span_x, 1.4 * fig_w)) + 0.4))
    ax.imshow(hillshade(z, cell), cmap="Greys_r", vmin=0, vmax=1, extent=(0, span_x, 0, span_y), interpolation="bilinear")
    for ref in reference or []:
        r = np.asarray(ref, dtype=np.float64)
        ax.plot(r[:, 0] - x0, r[:, 1] - y0, "-", lw=5, alpha=0.45, color=LINE_COLOURS["reference"], solid_capstyle="round")
    colours = {"convex": "#d62728", "concave": "#1f77b4"}
    seen: dict[str, list[float]] = {}
    for pl in lines:
        form = str(pl.attrs.get("form", "line"))
        v = pl.vertices
        ax.plot(v[:, 0] - x0, v[:, 1] - y0, "-", lw=1.4, color=colours.get(form, "#ff7f0e"))
        seen.setdefault(form, []).append(pl.length_2d)
    handles = [plt.Line2D([], [], color=colours.get(k, "#ff7f0e"), lw=2, label=f"{k}: {len(v)} lines, {sum(v):,.0f} m")
               for k, v in sorted(seen.items())]
    return _finish_line_map(fig, ax, handles, bool(reference), "reference", span_x, span_y, x0, y0, title, path, dpi)


def __getattr__(name: str):
    # the splat renderer's numba kernels load on first use (lidarfx.render.splat)
    if name in ("render_points", "render_picture"):
        from . import splat

        return getattr(splat, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
