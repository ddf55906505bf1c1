"""Pictures of point clouds and features (matplotlib, headless)."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .._atomic import atomic_path
from ..cloud import PointCloud


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
    seed: int = 0,
) -> Path:
    """Save a PNG with one panel per attribute, points coloured by value, seen from ``view``.

    Float attributes use a continuous colour map clipped to their 2–98 %
    range (NaN in grey); integer attributes (classes, ids) a categorical one.
    Points are drawn far to near so the nearest lie on top.
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
            cats, codes = np.unique(v, return_inverse=True)
            sc = ax.scatter(xyz[:, a], xyz[:, b], c=codes, s=0.3, cmap="tab10", vmin=0, vmax=9, linewidths=0)
            handles = [
                plt.Line2D([], [], marker="o", ls="", color=plt.cm.tab10(i % 10), label=str(c)) for i, c in enumerate(cats)
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
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130, format="png")
    plt.close(fig)
    return Path(path)
