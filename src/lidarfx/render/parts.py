"""Picture of the small parts of a tower: the cloud in grey, the parts coloured by kind, two views."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import label_axes, offset_text, save_figure

KIND_STYLE: dict[str, dict[str, Any]] = {
    "bolt": {"colour": "#d62728", "marker": "o", "size": 14, "label": "bolt / rivet"},
    "insulator": {"colour": "#1f77b4", "marker": "s", "size": 40, "label": "insulator"},
    "corona_ring": {"colour": "#2ca02c", "marker": "D", "size": 40, "label": "corona ring"},
    "other": {"colour": "#ff7f0e", "marker": "^", "size": 28, "label": "other compact part"},
}
"""Colour, marker, marker size and legend label of every part kind."""


def _detail_window(parts: Sequence[dict[str, Any]]) -> tuple[np.ndarray, float] | None:
    """Centre and half-width of a detail window: around the bolt with the most bolts nearby,
    16 median bolt sizes wide (at least 0.4 m); None without bolts."""
    bolts = [p for p in parts if p["kind"] == "bolt"]
    if not bolts:
        return None
    c = np.array([[p["centroid_x"], p["centroid_y"], p["centroid_z"]] for p in bolts])
    half = max(8.0 * float(np.median([p["size"] for p in bolts])), 0.2)
    near = (np.abs(c[:, None, :] - c[None, :, :]).max(axis=2) <= half).sum(axis=1)
    return c[int(np.argmax(near))], half


def _origin(xyz: np.ndarray) -> np.ndarray:
    """What the axes subtract: the minimum rounded down to whole metres (0 when it is below 1 m)."""
    lo = xyz.min(axis=0) if len(xyz) else np.zeros(3)
    return np.where(np.abs(lo) < 1.0, 0.0, np.floor(lo))


def parts_view(xyz: np.ndarray, part_kind: np.ndarray, parts: Sequence[dict[str, Any]], path: str | Path, *,
               kinds: Sequence[str] = tuple(KIND_STYLE), title: str | None = None, max_points: int = 300_000,
               dpi: int = 110, seed: int = 0) -> Path:
    """Save a PNG with a front (x–z) and a side (y–z) view and a detail: every point in light
    grey, the points of the parts in the colour of their kind (``part_kind`` codes are indices
    into ``kinds``, −1 = none), and a marker at every part's centroid so that parts of a few
    millimetres stay visible on a tower of tens of metres.  The detail (front view of a slab)
    shows the bolts around the bolt with the most bolts nearby.  Axes are metres relative to
    the cloud's minimum rounded down; the legend counts the parts of each kind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xyz = np.asarray(xyz, dtype=np.float64)
    kind_code = np.asarray(part_kind).astype(np.int64)
    o = _origin(xyz)
    rng = np.random.default_rng(seed)
    rest = np.flatnonzero(kind_code < 0)
    if len(rest) > max_points:
        rest = np.sort(rng.choice(rest, max_points, replace=False))
    ext = np.ptp(xyz, axis=0) if len(xyz) else np.ones(3)
    detail = _detail_window(parts)
    widths = [max(float(ext[0]), 1e-9), max(float(ext[1]), 1e-9)]
    if detail is not None:
        widths.append(0.8 * max(widths))
    fig_w = 5.0 * len(widths) - 0.5
    h = float(np.clip(0.85 * fig_w * ext[2] / sum(widths), 3.0, 11.0))  # panels of equal scale fill the width
    fig, axes = plt.subplots(1, len(widths), figsize=(fig_w, h + 1.0),
                             gridspec_kw={"width_ratios": widths}, squeeze=False)
    counts = {k: sum(1 for p in parts if p["kind"] == k) for k in kinds}
    centroids = {k: np.array([[p["centroid_x"], p["centroid_y"], p["centroid_z"]] for p in parts
                              if p["kind"] == k]).reshape(-1, 3) for k in kinds}

    def draw(ax, a: int, keep, s_grey: float, s_part: float, scale: float) -> None:
        grey = rest if keep is None else rest[keep(xyz[rest])]
        ax.scatter(xyz[grey, a] - o[a], xyz[grey, 2] - o[2], s=s_grey, c="#b4b4b4", linewidths=0, rasterized=True)
        for code, kind in enumerate(kinds):
            st = KIND_STYLE.get(kind, KIND_STYLE["other"])
            pts = np.flatnonzero(kind_code == code)
            if keep is not None and len(pts):
                pts = pts[keep(xyz[pts])]
            if len(pts):
                ax.scatter(xyz[pts, a] - o[a], xyz[pts, 2] - o[2], s=s_part, c=st["colour"], linewidths=0, rasterized=True)
            cs = centroids[kind]
            if keep is not None and len(cs):
                cs = cs[keep(cs)]
            if len(cs):
                ax.scatter(cs[:, a] - o[a], cs[:, 2] - o[2], s=st["size"] * scale, marker=st["marker"], facecolors="none",
                           edgecolors=st["colour"], linewidths=1.0)
        ax.set_aspect("equal")
        axis_name = "x (East)" if a == 0 else "y (North)"
        label_axes(ax, " ".join(filter(None, (axis_name, offset_text(o[a]), "[m]"))),
                    " ".join(filter(None, ("z", offset_text(o[2]), "[m]"))))

    for ax, (a, name) in zip(axes[0], ((0, "front (looking north)"), (1, "side (looking west)"))):
        draw(ax, a, None, 0.15, 0.6, 1.0)
        ax.set_title(name, fontsize=9)
    if detail is not None:
        centre, half = detail
        ax = axes[0, 2]

        def inside(p: np.ndarray) -> np.ndarray:
            return (np.abs(p - centre) <= half).all(axis=1)

        draw(ax, 0, inside, 4.0, 6.0, 4.0)
        ax.set_xlim(centre[0] - half - o[0], centre[0] + half - o[0])
        ax.set_ylim(centre[2] - half - o[2], centre[2] + half - o[2])
        ax.set_title(f"detail: front view of a {2 * half:.2g} m cube", fontsize=9)
        for a in axes[0, :2]:
            a.add_patch(plt.Rectangle((centre[0 if a is axes[0, 0] else 1] - half - o[0 if a is axes[0, 0] else 1],
                                       centre[2] - half - o[2]), 2 * half, 2 * half, fill=False, ec="k", lw=0.8))
    handles = [plt.Line2D([], [], marker=KIND_STYLE[k]["marker"], ls="", mfc="none", mec=KIND_STYLE[k]["colour"], ms=7,
                          label=f"{KIND_STYLE[k]['label']}: {counts[k]}") for k in kinds if k in KIND_STYLE]
    axes[0, 0].legend(handles=handles, fontsize=8, loc="upper left", framealpha=0.9)
    if title:
        fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, dpi)
