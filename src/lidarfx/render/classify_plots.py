"""Pictures of classification reports: confusion matrix, feature importance, backward elimination.

Each takes the plain dicts of a report (:func:`lidarfx.classify.evaluate`): a metrics dict
(``report["sections"][key]["metrics"]``, one file of a test section), ``report["importance"]``,
``report["backward_elimination"]``; nothing here imports :mod:`lidarfx.classify`.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._atomic import atomic_path
from . import save_figure

__all__ = ["plot_confusion", "plot_importance", "plot_elimination"]

#: the confusion-matrix layout of lidarfx (``lidarfx.classify.metrics.LAYOUT``), for metrics dicts without "layout"
_LAYOUT = "rows = reference, columns = predicted"


def _num(v: Any, nd: int = 4) -> str:
    return "   nan" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{nd}f}"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_confusion(m: dict[str, Any], path: str | os.PathLike, title: str | None = None) -> Path:
    """Confusion-matrix PNG: cells coloured by row share (= PA on the diagonal), with counts;
    the layout (rows = reference, columns = predicted) is written on the figure."""
    plt = _pyplot()
    layout = m.get("layout", _LAYOUT)
    cm = np.asarray(m["confusion"], dtype=np.int64)
    names = [c["name"] for c in m["classes"]]
    k = len(names)
    rows = cm.sum(axis=1, keepdims=True)
    share = np.divide(cm, rows, out=np.zeros_like(cm, dtype=float), where=rows > 0)
    size = 2.2 + 1.1 * k
    fig, ax = plt.subplots(figsize=(size + 1.2, size + 0.6))
    ax.imshow(share, cmap="Blues", vmin=0, vmax=1)
    for i in range(k):
        for j in range(k):
            ax.text(j, i, f"{cm[i, j]:,}\n{100 * share[i, j]:.1f}%", ha="center", va="center", fontsize=8,
                    color="white" if share[i, j] > 0.55 else "black")
    ax.set_xticks(range(k), [f"{n}\nUA {_num(c['ua'], 3)}" for n, c in zip(names, m["classes"])], fontsize=8)
    ax.set_yticks(range(k), [f"{n}\nPA {_num(c['pa'], 3)}" for n, c in zip(names, m["classes"])], fontsize=8)
    ax.set_xlabel("predicted (columns)")
    ax.set_ylabel("reference (rows)")
    head = (title + "\n") if title else ""
    ci = m.get("ci")
    tail = (f"\n{ci['level']:.0%} interval, {ci['blocks']} blocks: OA {_num(ci['oa'][0], 3)}–{_num(ci['oa'][1], 3)}  "
            f"mean F1 {_num(ci['mean_f1'][0], 3)}–{_num(ci['mean_f1'][1], 3)}") if ci else ""
    ax.set_title(f"{head}OA {_num(m['oa'])}  kappa {_num(m['kappa'])}  mean F1 {_num(m['mean_f1'])}{tail}", fontsize=9)
    fig.text(0.5, 0.01, f"layout: {layout}; cell = points and share of the reference row",
             ha="center", fontsize=7)
    fig.tight_layout(rect=(0, 0.03, 1, 1))  # room for the layout line (not save_figure: its layout drops the rect)
    p = Path(path)
    try:
        with atomic_path(p) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
    finally:
        plt.close(fig)
    return p


def plot_importance(imp: dict[str, Any], path: str | os.PathLike, top: int = 20) -> Path:
    """Feature-importance PNG: the ``top`` features by impurity importance and, when the
    report has it, by permutation importance (drop of mean F1, bars ± one standard
    deviation over the repeats), largest at the top; ``imp`` as in ``report["importance"]``."""
    plt = _pyplot()
    panels = [("impurity", "importance", None, f"impurity: {imp.get('impurity_model', '')}")]
    if imp.get("permutation"):
        panels.append(("permutation", "mean", "std", f"permutation, drop of mean F1: {imp.get('permutation_data', '')}"))
    n = max(min(top, len(imp[key])) for key, *_ in panels)
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels), 1.2 + 0.26 * n), squeeze=False)
    for ax, (key, val, err, title) in zip(axes[0], panels):
        rows = imp[key][:top][::-1]  # largest at the top
        pos = np.arange(len(rows))
        ax.barh(pos, [r[val] for r in rows], xerr=[r[err] for r in rows] if err else None,
                color="#4c72b0", ecolor="0.3", capsize=2)
        ax.set_yticks(pos, [r["name"] for r in rows], fontsize=7)
        ax.axvline(0.0, color="0.5", lw=0.6)
        ax.set_title(title, fontsize=8, wrap=True)
        ax.tick_params(axis="x", labelsize=7)
    fig.suptitle(f"feature importance (top {n})", fontsize=9)
    return save_figure(fig, path, dpi=110)


def plot_elimination(be: dict[str, Any], path: str | os.PathLike) -> Path:
    """Backward-elimination PNG (Chehata et al. 2009): cross-validated OA and mean F1 against
    the number of features kept, from all features down to one, with the smallest set within
    the tolerance of the best mean F1 marked; ``be`` as in ``report["backward_elimination"]``."""
    plt = _pyplot()
    steps = be["steps"]
    n = [s["n_features"] for s in steps]
    f1 = np.array([np.nan if s["mean_f1"] is None else s["mean_f1"] for s in steps], dtype=float)
    oa = np.array([np.nan if s["oa"] is None else s["oa"] for s in steps], dtype=float)
    best = be["best"]
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    ax.plot(n, oa, "o-", ms=3, label="OA")
    ax.plot(n, f1, "s-", ms=3, label="mean F1")
    top = np.nanmax(f1)
    ax.axhspan(top - be["tolerance"], top, color="0.85", label=f"within {be['tolerance']:g} of the best mean F1")
    ax.axvline(best["n_features"], color="C3", lw=1, ls="--",
               label=f"smallest such set: {best['n_features']} features")
    ax.set_xlim(max(n) + 0.5, 0.5)  # as the elimination runs: all features on the left
    ax.set_xlabel("features kept")
    ax.set_ylabel("cross-validated score")
    ax.set_title("backward elimination (random forest, impurity importance)", fontsize=9)
    ax.legend(fontsize=7, loc="lower left")
    ax.grid(alpha=0.3)
    return save_figure(fig, path, dpi=110)
