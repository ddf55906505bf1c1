"""Picture of vectorised lattice-tower members: the points in grey, the members coloured by label."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from . import label_axes, offset_text, save_figure

MEMBER_COLOURS = {"leg": "#d62728", "brace": "#1f77b4", "arm": "#2ca02c", "other": "#ff7f0e"}
"""Colours of the member labels (a label not listed: grey-brown)."""


def _axis(name: str, offset: float) -> str:
    """``x (East) − 512,000 [m]``: an axis label with what was subtracted (nothing when 0)."""
    return " ".join(filter(None, (name, offset_text(offset), "[m]")))


def _oblique(xyz: np.ndarray, azimuth: float, elevation: float) -> np.ndarray:
    """Screen coordinates (right, up) of an orthographic view from ``azimuth`` (degrees
    clockwise from north, where the viewer stands) and ``elevation`` (degrees above the horizon)."""
    a, e = math.radians(azimuth), math.radians(elevation)
    view = np.array([math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)])  # towards the viewer
    right = np.array([-math.cos(a), math.sin(a), 0.0])
    up = np.cross(view, right)
    return np.c_[xyz @ right, xyz @ up]


def members_view(xyz: np.ndarray, lines: Sequence, path: str | Path, *, title: str | None = None,
                 max_points: int = 150_000, azimuth: float = 210.0, elevation: float = 20.0, seed: int = 0,
                 dpi: int = 110) -> Path:
    """Three panels and a legend: front (x–z), side (y–z) and an oblique view (from ``azimuth`` /
    ``elevation``); the points (at most ``max_points``, drawn at random) in light grey and
    every member polyline in the colour of its ``attrs["label"]``, with a legend of the
    counts and lengths per label.  Axes in metres relative to the points' minimum (rounded
    to whole metres)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    xyz = np.asarray(xyz, dtype=np.float64)
    o = np.round(xyz.min(axis=0)) + 0.0 if len(xyz) else np.zeros(3)  # whole metres: short axis labels
    rng = np.random.default_rng(seed)
    pts = xyz if len(xyz) <= max_points else xyz[np.sort(rng.choice(len(xyz), max_points, replace=False))]
    pts = pts - o
    ext = np.ptp(pts, axis=0) if len(pts) else np.ones(3)
    tall = float(ext[2]) / max(float(ext[:2].max()), 1e-9)
    height = float(np.clip(3.2 * tall, 5.0, 9.0))
    fig, axes = plt.subplots(1, 4, figsize=(14.5, height), gridspec_kw={"width_ratios": [1, 1, 1.15, 0.5]})
    key, axes = axes[3], axes[:3]  # the last, narrow panel holds the legend
    views = [("front (looking north)", lambda p: p[:, [0, 2]], _axis("x (East)", o[0])),
             ("side (looking west)", lambda p: p[:, [1, 2]], _axis("y (North)", o[1])),
             (f"oblique (from azimuth {azimuth:g}°, {elevation:g}° up)",
              lambda p: _oblique(p, azimuth, elevation), "screen x [m]")]
    kinds: dict[str, list[float]] = {}
    for pl in lines:
        kinds.setdefault(str(pl.attrs.get("label", pl.kind)), []).append(pl.length)
    order = [k for k in MEMBER_COLOURS if k in kinds] + sorted(k for k in kinds if k not in MEMBER_COLOURS)
    for ax, (name, proj, xlabel) in zip(axes, views):
        if len(pts):
            uv = proj(pts)
            ax.scatter(uv[:, 0], uv[:, 1], s=0.15, c="0.72", linewidths=0, rasterized=True)
        for lab in reversed(order):  # legs drawn last, over the braces
            for pl in lines:
                if str(pl.attrs.get("label", pl.kind)) != lab:
                    continue
                uv = proj(pl.vertices - o)
                ax.plot(uv[:, 0], uv[:, 1], "-", lw=1.6 if lab == "leg" else 1.1,
                        color=MEMBER_COLOURS.get(lab, "#8c564b"), solid_capstyle="round")
        ax.set_aspect("equal", adjustable="datalim")
        label_axes(ax, xlabel, _axis("z", o[2]) if ax is not axes[2] else "screen y [m]")
        ax.set_title(name, fontsize=9)
    handles = [plt.Line2D([], [], color=MEMBER_COLOURS.get(k, "#8c564b"), lw=2.5,
                          label=f"{k}: {len(kinds[k])} members, {sum(kinds[k]):,.1f} m") for k in order]
    handles.append(plt.Line2D([], [], marker="o", ls="", color="0.72", label="points"))
    key.axis("off")
    key.legend(handles=handles, fontsize=8, loc="center left", frameon=False, title="members", title_fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, dpi)
