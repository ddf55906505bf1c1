"""Accuracy figures: confusion matrices, metrics, block-bootstrap intervals, slope breakdown.

Confusion matrix layout (everywhere in lidarfx): **rows = reference, columns =
predicted**; ``cm[i, j]`` = points of reference class i predicted as class j.

* overall accuracy OA = Σ cm_ii / N
* Cohen's kappa κ = (OA − p_e) / (1 − p_e), p_e = Σ_i (row_i · col_i) / N²
* producer's accuracy PA_i = cm_ii / row_i (recall), user's accuracy UA_i = cm_ii / col_i
  (precision), F1_i = 2 cm_ii / (row_i + col_i) (= 2·PA·UA / (PA + UA)),
  IoU_i = cm_ii / (row_i + col_i − cm_ii), support_i = row_i
* mean F1 / mean IoU: over the classes present in the reference (support > 0)

Undefined ratios (0 / 0) are NaN (``null`` in JSON).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from ..errors import LidarfxError
from .folds import check_block_size

if TYPE_CHECKING:  # annotations only
    from ..cloud import PointCloud
    from .classes import ClassMap

__all__ = ["LAYOUT", "confusion_matrix", "metrics", "metrics_for", "block_bootstrap", "check_bootstrap",
           "MAX_BOOTSTRAP", "SLOPE_BINS", "terrain_slope", "slope_confusions", "slope_table"]

LAYOUT = "rows = reference, columns = predicted"

MAX_BOOTSTRAP = 100_000
"""Most bootstrap resamples (each holds one block id per block)."""

#: terrain-slope classes (degrees) of the accuracy breakdown of :func:`~lidarfx.classify.evaluate_model`
#: (``by_slope``)
SLOPE_BINS = (0.0, 10.0, 20.0, 30.0, 45.0, 90.0)


def confusion_matrix(reference: np.ndarray, predicted: np.ndarray, n_classes: int) -> np.ndarray:
    """k × k counts, rows = reference, columns = predicted; points with reference < 0 are ignored."""
    ref = np.asarray(reference, dtype=np.int64).ravel()
    pred = np.asarray(predicted, dtype=np.int64).ravel()
    if ref.shape != pred.shape:
        raise LidarfxError(f"reference and prediction differ in length ({len(ref)} vs {len(pred)})")
    keep = ref >= 0
    ref, pred = ref[keep], pred[keep]
    if ref.size and (ref.max() >= n_classes or pred.min() < 0 or pred.max() >= n_classes):
        raise LidarfxError("class index out of range in the confusion matrix")
    return np.bincount(ref * n_classes + pred, minlength=n_classes * n_classes).reshape(n_classes, n_classes)


def _div(a: float, b: float) -> float:
    return float(a) / float(b) if b else float("nan")


def metrics(cm: Any, names: Sequence[str] | None = None, codes: Sequence[Any] | None = None) -> dict[str, Any]:
    """OA, kappa, mean F1 / IoU and per-class PA, UA, F1, IoU, support from a confusion matrix."""
    cm = np.asarray(cm, dtype=np.int64)
    if cm.ndim != 2 or cm.shape[0] != cm.shape[1]:
        raise LidarfxError(f"confusion matrix must be square, got shape {cm.shape}")
    k = cm.shape[0]
    names = list(names) if names is not None else [str(i) for i in range(k)]
    codes = list(codes) if codes is not None else list(range(k))
    n = int(cm.sum())
    diag = np.diag(cm).astype(float)
    rows = cm.sum(axis=1).astype(float)
    cols = cm.sum(axis=0).astype(float)
    oa = _div(diag.sum(), n)
    pe = float((rows * cols).sum()) / float(n) ** 2 if n else float("nan")
    if n and 1.0 - pe > 1e-15:
        kappa = (oa - pe) / (1.0 - pe)
    else:
        kappa = 1.0 if n and oa == 1.0 else float("nan")
    per = []
    for i in range(k):
        per.append({
            "index": i, "name": names[i], "code": codes[i],
            "support": int(rows[i]), "predicted": int(cols[i]),
            "pa": _div(diag[i], rows[i]), "ua": _div(diag[i], cols[i]),
            "f1": _div(2 * diag[i], rows[i] + cols[i]),
            "iou": _div(diag[i], rows[i] + cols[i] - diag[i]),
        })
    present = [p for p in per if p["support"] > 0]
    mean = lambda key: float(np.mean([p[key] for p in present])) if present else float("nan")  # noqa: E731
    return {"points": n, "oa": oa, "kappa": kappa, "mean_f1": mean("f1"), "mean_iou": mean("iou"),
            "classes": per, "confusion": cm.tolist(), "layout": LAYOUT}


def metrics_for(cm: np.ndarray, cmap: "ClassMap") -> dict[str, Any]:
    """:func:`metrics` with the class names and codes of a class map."""
    return metrics(cm, list(cmap.names), ["+".join(str(c) for c in g) for g in cmap.groups])


# --------------------------------------------------------------------------- intervals
def block_bootstrap(ref: np.ndarray, pred: np.ndarray, blocks: np.ndarray, n_classes: int, *,
                    n_boot: int = 1000, level: float = 0.95, seed: int = 0,
                    block_size: float | None = None, strata: np.ndarray | None = None) -> dict[str, Any] | None:
    """Confidence intervals of OA, kappa and mean F1 by a spatial block bootstrap.

    The labelled points (``ref`` ≥ 0, ``pred`` ≥ 0) are grouped by ``blocks``
    (:func:`~lidarfx.classify.folds.block_ids`); ``n_boot`` times, as many blocks as there
    are are drawn with replacement and their confusion matrices summed.  With ``strata``
    (one value per point, e.g. the file id) the draw is stratified: each stratum's blocks
    are drawn from that stratum only, as many as it has, so every resample holds every
    file in its own share, as the evaluated data do (a pooled figure of two files
    resampled as one pool would also vary with how many blocks of each file a resample
    happens to hold, which is not a property of the test).  A block lying in several
    strata counts as one block per stratum.  The interval holds the central ``level`` of
    the resampled values (percentiles).  Neighbouring points are correlated, so whole
    blocks, not points, are resampled; the interval says how much the figure depends on
    which parts of *these* files were tested, not how it would move on another survey.
    None when no stratum has 2 blocks holding labelled points.
    """
    ref, pred, blocks = np.asarray(ref), np.asarray(pred), np.asarray(blocks)
    ok = (ref >= 0) & (pred >= 0)
    if not ok.any():
        return None
    st = np.zeros(int(ok.sum()), np.int64) if strata is None else np.asarray(strata, dtype=np.int64)[ok]
    keys, b = np.unique(np.stack([st, np.asarray(blocks[ok], dtype=np.int64)], axis=1), axis=0,
                        return_inverse=True)
    b = b.ravel()
    nb = len(keys)
    block_stratum = keys[:, 0]
    groups = [np.flatnonzero(block_stratum == s) for s in np.unique(block_stratum)]
    if max(len(g) for g in groups) < 2:
        return None
    k = n_classes
    cms = np.bincount((b * k + ref[ok]) * k + pred[ok], minlength=nb * k * k).reshape(nb, k * k)
    rng = np.random.default_rng(seed)
    draws = np.zeros((int(n_boot), nb), np.int64)  # (n_boot, nb) block counts
    for g in groups:  # one stratum: the same draws as an unstratified bootstrap
        draws[:, g] = rng.multinomial(len(g), np.full(len(g), 1.0 / len(g)), size=int(n_boot))
    tot = (draws @ cms).reshape(-1, k, k).astype(np.float64)
    n = tot.sum(axis=(1, 2))
    diag = np.einsum("bii->bi", tot)
    rows, cols = tot.sum(axis=2), tot.sum(axis=1)
    oa = diag.sum(axis=1) / n
    pe = (rows * cols).sum(axis=1) / n**2
    with np.errstate(invalid="ignore", divide="ignore"):
        kappa = np.where(1 - pe > 1e-15, (oa - pe) / (1 - pe), np.nan)
        f1 = np.where(rows > 0, 2 * diag / (rows + cols), np.nan)  # classes absent from a resample: not counted
    mean_f1 = np.nanmean(f1, axis=1)
    q = [(1 - level) / 2 * 100, (1 + level) / 2 * 100]

    def ci(v: np.ndarray) -> list[float]:
        v = v[np.isfinite(v)]
        return [float(x) for x in np.percentile(v, q)] if len(v) else [float("nan")] * 2

    method = "spatial block bootstrap (percentile)"
    if len(groups) > 1:
        method = "spatial block bootstrap, stratified by file (percentile)"
    out = {"level": level, "method": method, "blocks": nb, "resamples": int(n_boot),
           "oa": ci(oa), "kappa": ci(kappa), "mean_f1": ci(mean_f1)}
    if len(groups) > 1:
        out["strata"] = len(groups)
    if block_size:
        out["block_size"] = float(block_size)
    return out


def check_bootstrap(bootstrap: Any, block_size: float) -> None:
    """Refuse a resample count outside 0..:data:`MAX_BOOTSTRAP` (and, when resampling, a bad block size)."""
    if isinstance(bootstrap, bool) or not (isinstance(bootstrap, (int, np.integer)) and 0 <= bootstrap <= MAX_BOOTSTRAP):
        raise LidarfxError(f"bootstrap must be a whole number of resamples from 0 (no intervals) to {MAX_BOOTSTRAP}, "
                           f"got {bootstrap!r}")
    if bootstrap:
        check_block_size(block_size)


# --------------------------------------------------------------------------- by terrain slope
def terrain_slope(cloud: "PointCloud") -> np.ndarray:
    """Slope of the terrain under every point (degrees, float32): the gradient of a 1 m DTM
    (TIN of the SMRF ground points, :func:`lidarfx.ground.dtm`) in the point's cell.  The
    filter never looks at the classification; NaN for every point when it finds no ground."""
    from ..ground import classify_ground, dtm
    from ..surface.grid import gradient_slope

    n = len(cloud)
    mask = classify_ground(cloud, ignore_classes=None, progress=False) if n else np.zeros(0, bool)
    if not mask.any():
        return np.full(n, np.nan, dtype=np.float32)
    r = dtm(cloud, resolution=1.0, ground=mask)  # 1 m cells whatever the unit (dtm takes metres)
    g = gradient_slope(np.asarray(r.array, dtype=np.float64), r.resolution)
    row, col = r.cell_of(cloud.x, cloud.y)
    return np.degrees(np.arctan(g[row, col])).astype(np.float32)


def slope_confusions(y: np.ndarray, pred: np.ndarray, slope: np.ndarray, k: int) -> np.ndarray:
    """Confusion matrices of the labelled points (``y >= 0``) per class of :data:`SLOPE_BINS`
    (``len(SLOPE_BINS) - 1`` × k × k; the last class includes 90°)."""
    out = np.zeros((len(SLOPE_BINS) - 1, k, k), np.int64)
    b = np.clip(np.searchsorted(SLOPE_BINS, slope, side="right") - 1, 0, len(SLOPE_BINS) - 2)
    for i in range(len(SLOPE_BINS) - 1):
        sel = (y >= 0) & (b == i) & np.isfinite(slope)
        out[i] = confusion_matrix(y[sel], pred[sel], k)
    return out


def slope_table(cms: np.ndarray, cmap: "ClassMap") -> list[dict[str, Any]]:
    """Rows of the ``by_slope`` breakdown (points, OA, PA per class, confusion) from :func:`slope_confusions`."""
    rows = []
    for i, cm in enumerate(cms):
        m = metrics(cm)
        rows.append({"slope_deg": [SLOPE_BINS[i], SLOPE_BINS[i + 1]], "points": int(cm.sum()), "oa": m["oa"],
                     "pa": {cmap.names[c]: m["classes"][c]["pa"] for c in range(len(cmap))},
                     "confusion": cm.tolist()})
    return rows
