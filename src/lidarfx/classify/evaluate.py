"""Honest evaluation: metrics, random and spatial-block folds, transfer, reports.

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

import datetime as _dt
import math
import os
import time
import warnings
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .. import __version__
from ..cloud import PointCloud
from ..errors import LidarfxError, LidarfxWarning, check_seed
from .classes import ClassMap
from .model import (
    ClassifierModel,
    Source,
    TrainConfig,
    _labels,
    read_sources,
    resolve_classes,
    sheared_sources,
    thinned_sources,
    train,
)
from .fastpredict import predict as fast_predict
from .objects import building_class
from .pipeline import CloudSample, balanced_sample, unit_to_metre

__all__ = ["LAYOUT", "confusion_matrix", "metrics", "random_folds", "block_folds", "block_ids", "block_bootstrap",
           "block_buffer_mask",
           "file_buffer_mask", "cross_validate", "evaluate", "evaluate_model", "format_metrics", "format_report", "write_report", "plot_confusion",
           "plot_importance", "plot_elimination", "terrain_slope", "SLOPE_BINS"]

LAYOUT = "rows = reference, columns = predicted"


# --------------------------------------------------------------------------- metrics
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


def _metrics_for(cm: np.ndarray, cmap: ClassMap) -> dict[str, Any]:
    return metrics(cm, list(cmap.names), ["+".join(str(c) for c in g) for g in cmap.groups])


# --------------------------------------------------------------------------- folds
def random_folds(n: int, n_folds: int, seed: int = 0, y: np.ndarray | None = None) -> np.ndarray:
    """Fold id (0..n_folds−1) of every point: random, stratified by ``y`` when given."""
    from sklearn.model_selection import KFold, StratifiedKFold

    if n_folds < 2:
        raise LidarfxError("cross-validation needs at least 2 folds")
    if n < n_folds:
        raise LidarfxError(f"{n} points cannot make {n_folds} folds")
    folds = np.empty(n, dtype=np.int64)
    if y is not None:
        y = np.asarray(y)
        _, counts = np.unique(y, return_counts=True)
        if counts.min() >= n_folds:
            split = StratifiedKFold(n_folds, shuffle=True, random_state=seed).split(np.zeros(n), y)
        else:
            split = KFold(n_folds, shuffle=True, random_state=seed).split(np.zeros(n))
    else:
        split = KFold(n_folds, shuffle=True, random_state=seed).split(np.zeros(n))
    for f, (_, te) in enumerate(split):
        folds[te] = f
    return folds


def block_folds(xy: np.ndarray, n_folds: int, block_size: float, seed: int = 0,
                groups: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Spatial-block folds: ``(fold, block)`` ids per point.

    The plane is cut into square blocks of ``block_size`` (aligned to multiples
    of it, so neighbouring tiles share the grid; ``groups`` — e.g. a file id —
    keeps blocks of different files apart).  Whole blocks go to folds: shuffled
    with ``seed``, each block joins the fold holding the fewest points so far.
    No block is ever split between folds.
    """
    if n_folds < 2:
        raise LidarfxError("cross-validation needs at least 2 folds")
    block = block_ids(xy, block_size, groups)
    counts = np.bincount(block)
    nb = len(counts)
    if nb < n_folds:
        raise LidarfxError(f"only {nb} spatial block(s) of {block_size:g} m for {n_folds} folds; "
                           "use smaller blocks or fewer folds")
    order = np.random.default_rng(seed).permutation(nb)
    load = np.zeros(n_folds, np.int64)
    fold_of_block = np.empty(nb, np.int64)
    for b in order:
        f = int(np.argmin(load))
        fold_of_block[b] = f
        load[f] += counts[b]
    return fold_of_block[block], block


def block_ids(xy: np.ndarray, block_size: float, groups: np.ndarray | None = None) -> np.ndarray:
    """Id (0..B−1) of the square block of ``block_size`` m each point lies in; the grid is
    aligned to multiples of the size, and ``groups`` (e.g. a file id) keeps blocks apart."""
    xy = np.asarray(xy, dtype=np.float64)
    _check_block_size(block_size)
    bx = np.floor(xy[:, 0] / block_size).astype(np.int64)
    by = np.floor(xy[:, 1] / block_size).astype(np.int64)
    g = np.zeros(len(xy), np.int64) if groups is None else np.asarray(groups, dtype=np.int64)
    _, block = np.unique(np.stack([g, bx, by], axis=1), axis=0, return_inverse=True)
    return block.ravel()


def block_bootstrap(ref: np.ndarray, pred: np.ndarray, blocks: np.ndarray, n_classes: int, *,
                    n_boot: int = 1000, level: float = 0.95, seed: int = 0,
                    block_size: float | None = None) -> dict[str, Any] | None:
    """Confidence intervals of OA, kappa and mean F1 by a spatial block bootstrap.

    The labelled points (``ref`` ≥ 0, ``pred`` ≥ 0) are grouped by ``blocks``
    (:func:`block_ids`); ``n_boot`` times, as many blocks as there are are drawn with
    replacement and their confusion matrices summed.  The interval holds the central
    ``level`` of the resampled values (percentiles).  Neighbouring points are correlated,
    so whole blocks, not points, are resampled; the interval says how much the figure
    depends on which parts of *these* files were tested, not how it would move on
    another survey.  None when fewer than 2 blocks hold labelled points.
    """
    ref, pred, blocks = np.asarray(ref), np.asarray(pred), np.asarray(blocks)
    ok = (ref >= 0) & (pred >= 0)
    if not ok.any():
        return None
    _, b = np.unique(blocks[ok], return_inverse=True)
    nb = int(b.max()) + 1
    if nb < 2:
        return None
    k = n_classes
    cms = np.bincount((b * k + ref[ok]) * k + pred[ok], minlength=nb * k * k).reshape(nb, k * k)
    rng = np.random.default_rng(seed)
    draws = rng.multinomial(nb, np.full(nb, 1.0 / nb), size=int(n_boot))  # (n_boot, nb) block counts
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

    out = {"level": level, "method": "spatial block bootstrap (percentile)", "blocks": nb, "resamples": int(n_boot),
           "oa": ci(oa), "kappa": ci(kappa), "mean_f1": ci(mean_f1)}
    if block_size:
        out["block_size"] = float(block_size)
    return out


MIN_BLOCK_SIZE = 0.01
"""Smallest spatial block (m): smaller ones hold a point each, and their ids overflow on large extents."""
MAX_BOOTSTRAP = 100_000
"""Most bootstrap resamples (each holds one block id per block)."""


def _check_block_size(block_size: Any) -> None:
    ok = isinstance(block_size, (int, float, np.integer, np.floating)) and not isinstance(block_size, bool)
    if not (ok and MIN_BLOCK_SIZE <= block_size < math.inf):
        raise LidarfxError(f"block size must be a number of metres from {MIN_BLOCK_SIZE:g} on, got {block_size!r}")


def _check_bootstrap(bootstrap: Any, block_size: float) -> None:
    if isinstance(bootstrap, bool) or not (isinstance(bootstrap, (int, np.integer)) and 0 <= bootstrap <= MAX_BOOTSTRAP):
        raise LidarfxError(f"bootstrap must be a whole number of resamples from 0 (no intervals) to {MAX_BOOTSTRAP}, "
                           f"got {bootstrap!r}")
    if bootstrap:
        _check_block_size(block_size)


def block_buffer_mask(xy: np.ndarray, folds: np.ndarray, block_size: float, buffer: float,
                      groups: np.ndarray | None = None) -> np.ndarray:
    """Points near another fold's blocks: ``near[f, i]`` is True when point ``i`` lies within
    ``buffer`` m (plan distance) of a block of :func:`block_folds` that belongs to fold ``f``
    and not to the point's own fold.  Cross-validation leaves such points out of fold ``f``'s
    training part (a buffered spatial-block CV), so that no training point lies within
    ``buffer`` of the held-out area.  The distance is to the block's square, not to its
    points; ``groups`` (file ids) as in :func:`block_folds`."""
    xy = np.asarray(xy, dtype=np.float64)
    folds = np.asarray(folds, dtype=np.int64)
    n_folds = int(folds.max()) + 1 if len(folds) else 0
    near = np.zeros((n_folds, len(xy)), dtype=bool)
    if not (buffer > 0) or not len(xy):
        return near
    if not math.isfinite(buffer):
        raise LidarfxError(f"buffer must be a finite number of metres, got {buffer!r}")
    s = float(block_size)
    bx = np.floor(xy[:, 0] / s).astype(np.int64)
    by = np.floor(xy[:, 1] / s).astype(np.int64)
    ox, oy = xy[:, 0] - bx * s, xy[:, 1] - by * s  # offsets inside the own block, 0..s
    g = np.zeros(len(xy), np.int64) if groups is None else np.asarray(groups, dtype=np.int64)
    # blocks further away than the data's span in blocks do not exist (a huge buffer: no huge loop)
    reach = min(math.ceil(buffer / s), int(max(np.ptp(bx), np.ptp(by))) + 1)
    bx, by = bx - bx.min() + reach, by - by.min() + reach
    w, h = int(bx.max()) + reach + 1, int(by.max()) + reach + 1
    key = (g * w + bx) * h + by
    ukey, first = np.unique(key, return_index=True)
    ufold = folds[first]  # a block lies in one fold (block_folds never splits one)
    for dx in range(-reach, reach + 1):
        gx = 0.0 if dx == 0 else ((dx - 1) * s + (s - ox) if dx > 0 else (-dx - 1) * s + ox)
        for dy in range(-reach, reach + 1):
            if dx == 0 and dy == 0:
                continue
            gy = 0.0 if dy == 0 else ((dy - 1) * s + (s - oy) if dy > 0 else (-dy - 1) * s + oy)
            idx = np.flatnonzero(np.hypot(gx, gy) < buffer)
            if not len(idx):
                continue
            k2 = (g[idx] * w + bx[idx] + dx) * h + by[idx] + dy
            pos = np.minimum(np.searchsorted(ukey, k2), len(ukey) - 1)
            hit = ukey[pos] == k2
            f2, i2 = ufold[pos[hit]], idx[hit]
            other = f2 != folds[i2]
            near[f2[other], i2[other]] = True
    return near


def file_buffer_mask(xy: np.ndarray, files: np.ndarray, buffer: float) -> np.ndarray:
    """Points near another file: ``near[f, i]`` is True when point ``i`` of another file lies
    within ``buffer`` m (plan distance) of a point of file ``f``.  Leave-one-file-out leaves
    them out of the training when file ``f`` is held out: tiles of one survey are usually
    contiguous, and the points along a shared edge are neighbours."""
    from scipy.spatial import cKDTree

    xy = np.asarray(xy, dtype=np.float64)
    files = np.asarray(files, dtype=np.int64)
    n_files = int(files.max()) + 1 if len(files) else 0
    near = np.zeros((n_files, len(xy)), dtype=bool)
    if not (buffer > 0) or n_files < 2:
        return near
    if not math.isfinite(buffer):
        raise LidarfxError(f"buffer must be a finite number of metres, got {buffer!r}")
    for f in range(n_files):
        mine = files == f
        if not mine.any():
            continue
        others = np.flatnonzero(~mine)
        d, _ = cKDTree(xy[mine]).query(xy[others], distance_upper_bound=buffer)
        near[f, others[d < buffer]] = True
    return near


def default_buffer(config: TrainConfig) -> float:
    """The default buffer of the spatial-block CV and leave-one-file-out: twice the largest
    radius (no training point's neighbourhood then holds a point of a held-out point's),
    0 for k-NN."""
    if config.neighbourhood == "knn" or not config.radii:
        return 0.0
    return 2.0 * max(config.radii)


def fold_parts(folds: np.ndarray, y: np.ndarray, f: int, exclude: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Training and held-out indices of fold ``f`` (labelled points only); ``exclude``
    (:func:`block_buffer_mask`, :func:`file_buffer_mask`) removes the points near the held-out
    part from the training part."""
    train = (folds != f) & (y >= 0)
    if exclude is not None:
        train &= ~exclude[f]
    return np.flatnonzero(train), np.flatnonzero((folds == f) & (y >= 0))


def cross_validate(X: np.ndarray, y: np.ndarray, folds: np.ndarray, config: TrainConfig, n_classes: int,
                   log: Callable[[str], None] | None = None, X_aug: Sequence[np.ndarray] = (),
                   exclude: np.ndarray | None = None,
                   post: Callable[[int, Any, np.ndarray], np.ndarray] | None = None,
                   out_pred: np.ndarray | None = None, class_names: Sequence[str] | None = None,
                   ) -> tuple[np.ndarray, list[dict[str, Any]], list]:
    """Train on all folds but one (balanced sample, as :func:`train` does), predict the
    held-out fold, for every fold.  ``X_aug``: features of the same points in
    terrain-sheared copies, or ``(Xa, rows)`` pairs for copies holding only some of
    the points (thinned copies: row ``j`` of ``Xa`` is point ``rows[j]``); the
    training part of each fold adds a balanced sample of them like :func:`train`.
    ``exclude``: ``(n_folds, n)`` bool, points left out of fold ``f``'s training part
    (:func:`block_buffer_mask`, :func:`file_buffer_mask`).  ``post(f, estimator, held_out)``,
    when given, replaces the plain prediction of the held-out points (class indices;
    e.g. the object-size rule, :class:`HeldOutRule`).  ``out_pred`` (length n), when given,
    receives every held-out point's predicted class index.  A fold whose training part lacks a
    class lists it (``class_names``, else indices) in ``not_trained``: that fold cannot predict it.
    Returns the summed confusion matrix,
    per-fold results and
    the fitted estimators with their held-out indices."""
    from .model import _aug_cap

    cm = np.zeros((n_classes, n_classes), np.int64)
    per_fold, fitted = [], []
    for f in np.unique(folds):
        tr, te = fold_parts(folds, y, int(f), exclude)
        if not len(te):
            continue
        s = tr[balanced_sample(y[tr], config.max_per_class, config.seed)]
        t0 = time.perf_counter()
        Xf, yf = X[s], y[s]
        for a, Xa in enumerate(X_aug):
            if isinstance(Xa, tuple):  # a copy with a subset of the points
                Xa, rows = Xa
                ok = (folds[rows] != f) & (y[rows] >= 0)
                if exclude is not None:
                    ok &= ~exclude[f][rows]
                ok = np.flatnonzero(ok)
                pick = ok[balanced_sample(y[rows[ok]], _aug_cap(config), config.seed + 1 + a)]
                Xf, yf = np.vstack([Xf, Xa[pick]]), np.concatenate([yf, y[rows[pick]]])
                continue
            sa = tr[balanced_sample(y[tr], _aug_cap(config), config.seed + 1 + a)]
            Xf, yf = np.vstack([Xf, Xa[sa]]), np.concatenate([yf, y[sa]])
        if len(np.unique(yf)) < 2:
            near = "" if exclude is None else (
                f" ({int((exclude[f] & (folds != f) & (y >= 0)).sum()):,} of its labelled points lie within the "
                "buffer of the held-out part; use a smaller --buffer)")
            raise LidarfxError(f"fold {int(f)}: its training part holds fewer than two classes{near}")
        est = config.fit_matrix(Xf, yf)
        pred = fast_predict(est, X[te]) if post is None else post(int(f), est, te)
        if out_pred is not None:
            out_pred[te] = pred
        c = confusion_matrix(y[te], pred, n_classes)
        cm += c
        m = metrics(c)
        per_fold.append({"fold": int(f), "train_points": int(len(yf)), "test_points": int(len(te)),
                         "oa": m["oa"], "kappa": m["kappa"], "mean_f1": m["mean_f1"],
                         "seconds": round(time.perf_counter() - t0, 3)})
        if exclude is not None:
            per_fold[-1]["buffer_excluded"] = int((exclude[f] & (folds != f) & (y >= 0)).sum())
        absent = [c for c in range(n_classes) if not (yf == c).any()]
        if absent:
            per_fold[-1]["not_trained"] = [class_names[c] if class_names else c for c in absent]
        fitted.append((est, te))
        if log:
            copies = f" ({len(s):,} + {len(yf) - len(s):,} from augmented copies)" if len(yf) > len(s) else ""
            log(f"  fold {int(f)}: train {len(yf):,}{copies} / test {len(te):,} points, OA {m['oa']:.4f}, "
                f"mean F1 {m['mean_f1']:.4f}{_not_trained(per_fold[-1])}")
    return cm, per_fold, fitted


def _not_trained(fold: dict[str, Any]) -> str:
    """The note on a fold whose training part lacks classes (empty if none)."""
    absent = fold.get("not_trained")
    if not absent:
        return ""
    return (f"; its training part has no {', '.join(repr(str(a)) for a in absent)} points, so none of its "
            f"held-out points can be called {'that' if len(absent) == 1 else 'those'}")


class HeldOutRule:
    """The object-size rule of prediction (:mod:`.objects`) inside cross-validation.

    A model applies the rule to every usable point of a cloud, so a held-out part
    is predicted the same way: its labelled points together with the *context*
    points of the same part (usable points outside the class map, e.g. IGN 1 and
    64), one file at a time, with the link of the file's density.  The held-out
    part's edge is then the edge of its blocks (of its file): a building cut by a
    block edge is kept, as one cut by a tile edge is.  Only the labelled points are
    counted.  ``stats`` sums the rule's counts per section."""

    def __init__(self, sources: list[Source], cmap: ClassMap, config: TrainConfig, labelled: tuple,
                 X: np.ndarray, target: int, progress: bool | None = False) -> None:
        from .model import cloud_density
        from .objects import link_for

        idxs, y, _, g = labelled
        self.target, self.area, self.k = target, float(config.min_building_area), len(cmap)
        self.share = float(config.max_multi_return_share)
        tr = config.transformer(progress=progress)
        xyz_l, xyz_c, Xc, g_c, nr_l, nr_c = [], [], [], [], [], []
        self.link = []
        for i, (s, idx) in enumerate(zip(sources, idxs)):
            u = unit_to_metre(s.cloud)
            ctx = np.flatnonzero(_labels(s, cmap) < 0)
            xyz_l.append(s.cloud.xyz[idx] * u)
            xyz_c.append(s.cloud.xyz[ctx] * u)
            nr = np.asarray(s.cloud["number_of_returns"]) if "number_of_returns" in s.cloud else np.zeros(len(s.cloud))
            nr_l.append(nr[idx])
            nr_c.append(nr[ctx])
            Xc.append(tr.transform(CloudSample(s.cloud, ctx)) if len(ctx) else
                      np.empty((0, len(config.feature_names())), np.float32))
            g_c.append(np.full(len(ctx), i, np.int64))
            self.link.append(link_for(cloud_density(s.cloud)))
        self.X, self.xyz, self.g, self.nr = X, np.vstack(xyz_l), g, np.concatenate(nr_l)
        self.xyz_c, self.X_c, self.g_c = np.vstack(xyz_c), np.vstack(Xc), np.concatenate(g_c)
        self.nr_c = np.concatenate(nr_c)
        self.folds_c = np.full(len(self.g_c), -1, np.int64)
        self.stats: dict[str, int] = {}

    def set_folds(self, kind: str, folds: np.ndarray, cv: int = 3, seed: int = 0, block_size: float = 0.0) -> None:
        """Assign the context points to the folds of one CV run: ``random`` (at random),
        ``blocks`` (the fold of their block; −1 in a block without labelled points),
        ``files`` (their file)."""
        n = len(self.g_c)
        self.stats = {}
        if kind == "files":
            self.folds_c = self.g_c.copy()
        elif kind == "random":
            self.folds_c = np.random.default_rng(seed).integers(0, cv, n) if n else np.zeros(0, np.int64)
        else:
            def keys(xy, g):  # block_folds' blocks, as integers
                return np.stack([g, np.floor(xy[:, 0] / block_size).astype(np.int64),
                                 np.floor(xy[:, 1] / block_size).astype(np.int64)], 1)
            nl = len(self.g)
            _, inv = np.unique(np.vstack([keys(self.xyz, self.g), keys(self.xyz_c, self.g_c)]), axis=0,
                               return_inverse=True)
            inv = inv.ravel()
            fold_of_block = np.full(int(inv.max()) + 1, -1, np.int64)
            fold_of_block[inv[:nl]] = folds  # a block lies in one fold
            self.folds_c = fold_of_block[inv[nl:]]

    def __call__(self, f: int, est: Any, te: np.ndarray) -> np.ndarray:
        from .fastpredict import predict_proba
        from .objects import drop_small_objects

        def proba(X: np.ndarray) -> np.ndarray:
            # columns = class indices of the map: a fold's training part may lack a class
            # (small files, fine blocks, buffers), and then the estimator knows fewer columns
            P = np.zeros((len(X), self.k))
            if len(X):
                P[:, np.asarray(est.classes_, np.int64)] = predict_proba(est, X)
            return P

        ctx = np.flatnonzero(self.folds_c == f)
        P = proba(self.X_c[ctx])
        P_te = proba(self.X[te])
        out = P_te.argmax(axis=1)
        for i in np.unique(self.g[te]):
            a = np.flatnonzero(self.g[te] == i)
            c = ctx[self.g_c[ctx] == i]
            Q = np.vstack([P_te[a], P[self.g_c[ctx] == i]]) if len(c) else P_te[a]
            k = Q.argmax(axis=1)
            R = Q.copy()
            R[:, self.target] = -1.0
            st: dict[str, int] = {}
            new = drop_small_objects(k, R.argmax(axis=1), np.vstack([self.xyz[te[a]], self.xyz_c[c]]),
                                     self.target, self.area, link=self.link[i],
                                     returns=np.concatenate([self.nr[te[a]], self.nr_c[c]]),
                                     max_multi_return_share=self.share, stats=st)
            out[a] = new[: len(a)]
            for key, v in st.items():
                self.stats[key] = self.stats.get(key, 0) + v
        return out


# --------------------------------------------------------------------------- evaluation
def _labelled(sources: list[Source], cmap: ClassMap
              ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """Indices (per source), labels, xy (metres) and file id of every labelled point of every source."""
    idxs, ys, xys, gs = [], [], [], []
    for i, s in enumerate(sources):
        y = _labels(s, cmap)
        idx = np.flatnonzero(y >= 0)
        idxs.append(idx)
        ys.append(y[idx])
        xys.append(s.cloud.xyz[idx, :2] * unit_to_metre(s.cloud))  # blocks in metres
        gs.append(np.full(len(idx), i, np.int64))
    return idxs, np.concatenate(ys).astype(np.int64), np.vstack(xys), np.concatenate(gs)


def _file_features(sources: list[Source], cmap: ClassMap, config: TrainConfig, progress: bool | None,
                   labelled: tuple | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Features, labels, xy and file id of every labelled point of every source
    (``labelled``: :func:`_labelled` of ``sources``, when already known)."""
    tr = config.transformer(progress=progress)
    idxs, y, xy, g = labelled or _labelled(sources, cmap)
    X = np.vstack([tr.transform(CloudSample(s.cloud, idx)) for s, idx in zip(sources, idxs)])
    return X, y, xy, g


def _thinned_features(sources: list[Source], copies: list[tuple[Source, np.ndarray]], cmap: ClassMap,
                      config: TrainConfig, progress: bool | None) -> tuple[np.ndarray, np.ndarray]:
    """Features of the labelled points of thinned copies and their rows in :func:`_file_features`."""
    tr = config.transformer(progress=progress)
    Xs, rows, offset = [], [], 0
    for s, (c, keep) in zip(sources, copies):
        idx = np.flatnonzero(_labels(s, cmap) >= 0)
        idx_c = np.flatnonzero(_labels(c, cmap) >= 0)
        Xs.append(tr.transform(CloudSample(c.cloud, idx_c)))
        rows.append(offset + np.searchsorted(idx, np.flatnonzero(keep)[idx_c]))
        offset += len(idx)
    return np.vstack(Xs), np.concatenate(rows)


def _out_dir(out_dir: str | os.PathLike, create: bool = True) -> Path:
    """The report folder (an error if it is a file), created if missing and ``create``."""
    d = Path(out_dir)
    if d.exists() and not d.is_dir():
        raise LidarfxError(f"{d} exists and is not a folder")
    if create:
        d.mkdir(parents=True, exist_ok=True)
    return d


#: terrain-slope classes (degrees) of the accuracy breakdown of :func:`evaluate_model` (``by_slope``)
SLOPE_BINS = (0.0, 10.0, 20.0, 30.0, 45.0, 90.0)


def terrain_slope(cloud: PointCloud) -> np.ndarray:
    """Slope of the terrain under every point (degrees, float32): the gradient of a 1 m DTM
    (TIN of the SMRF ground points, :func:`lidarfx.ground.dtm`) in the point's cell.  The
    filter never looks at the classification; NaN for every point when it finds no ground."""
    from ..ground import classify_ground, dtm
    from ..ground.grid import gradient_slope

    n = len(cloud)
    mask = classify_ground(cloud, ignore_classes=None, progress=False) if n else np.zeros(0, bool)
    if not mask.any():
        return np.full(n, np.nan, dtype=np.float32)
    r = dtm(cloud, resolution=1.0 / unit_to_metre(cloud), ground=mask)  # 1 m cells whatever the unit
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


def _slope_table(cms: np.ndarray, cmap: ClassMap) -> list[dict[str, Any]]:
    rows = []
    for i, cm in enumerate(cms):
        m = metrics(cm)
        rows.append({"slope_deg": [SLOPE_BINS[i], SLOPE_BINS[i + 1]], "points": int(cm.sum()), "oa": m["oa"],
                     "pa": {cmap.names[c]: m["classes"][c]["pa"] for c in range(len(cmap))},
                     "confusion": cm.tolist()})
    return rows


def evaluate_model(model: ClassifierModel, sources: Any, *, progress: bool | None = False,
                   log: Callable[[str], None] | None = None,
                   maps_dir: str | os.PathLike | None = None,
                   min_building_area: float | None = None,
                   max_multi_return_share: float | None = None, by_slope: bool = False,
                   bootstrap: int = 1000, ci_block_size: float = 20.0) -> dict[str, Any]:
    """Metrics of a trained model on labelled clouds: per file and pooled.

    Every usable point is classified (features use all of them as neighbours);
    only points whose reference class is in the model's class map count.
    With ``maps_dir``, a plan-view error map ``errors_<file>.png`` of every file
    is written there (:func:`lidarfx.render.error_map`; its path in the file's
    ``error_map``, the points of its error pairs in ``error_pairs``).
    ``min_building_area``, ``max_multi_return_share``: override the model's building-cluster
    rule (:meth:`ClassifierModel.predict`).  ``by_slope``: also OA and PA per class of
    terrain slope (:data:`SLOPE_BINS`, slope from :func:`terrain_slope`), per file and pooled,
    in ``by_slope``.  ``bootstrap``: resamples of the 95 % confidence intervals of OA, kappa
    and mean F1 in ``ci`` (:func:`block_bootstrap` over blocks of ``ci_block_size`` m; 0 = none).
    """
    _check_bootstrap(bootstrap, ci_block_size)
    maps = _out_dir(maps_dir, create=False) if maps_dir is not None else None  # refused before any work
    srcs = read_sources(sources, progress=progress)
    cmap = model.classes
    k = len(cmap)
    total = np.zeros((k, k), np.int64)
    total_slope = np.zeros((len(SLOPE_BINS) - 1, k, k), np.int64)
    files = {}
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # per file: ref, pred, block ids (bootstrap)
    t0 = time.perf_counter()
    for s in srcs:
        t = time.perf_counter()
        y = _labels(s, cmap)
        if not (y >= 0).any():
            found = sorted(int(c) for c in np.unique(np.asarray(s.cloud["classification"])))
            msg = (f"{s.name} has no points of the model's classes ({cmap.spec()}); its classes: "
                   f"{found[:20]}{' …' if len(found) > 20 else ''}")
            if len(srcs) == 1:
                raise LidarfxError(msg)
            warnings.warn(msg + "; not counted", LidarfxWarning, stacklevel=2)
            continue
        dens = model.density_check(s.cloud, s.name)
        rule: dict[str, Any] = {}
        codes = model.predict(s.cloud, progress=progress, check_density=False,
                              min_building_area=min_building_area, max_multi_return_share=max_multi_return_share,
                              stats=rule)
        pred = cmap.index_of(np.clip(codes, 0, 255))
        cm = confusion_matrix(y, np.where(y >= 0, pred, 0), k)
        total += cm
        m = _metrics_for(cm, cmap)
        m["seconds"] = round(time.perf_counter() - t, 3)
        m["ignored_points"] = int((y < 0).sum())
        m["unusable_points"] = int(s.n_total - len(s.cloud))
        m["density"] = dens
        if bootstrap:
            blocks = block_ids(s.cloud.xyz[:, :2] * unit_to_metre(s.cloud), ci_block_size)
            m["ci"] = block_bootstrap(y, pred, blocks, k, n_boot=bootstrap, block_size=ci_block_size)
            parts.append((y, pred, blocks))
        if by_slope:
            cms = slope_confusions(y, pred, terrain_slope(s.cloud), k)
            total_slope += cms
            m["by_slope"] = _slope_table(cms, cmap)
        if rule:
            m["small_buildings"] = {
                "min_building_area": model.min_building_area if min_building_area is None else float(min_building_area),
                "max_multi_return_share": (model.max_multi_return_share if max_multi_return_share is None
                                           else float(max_multi_return_share)),
                **rule}
        if maps is not None:
            from ..render import error_map

            u = unit_to_metre(s.cloud)
            _out_dir(maps)
            png, pairs = error_map(s.cloud.xyz[:, :2] * u, s.cloud.xyz[:, 2] * u, y, pred,
                                   [c["name"] for c in m["classes"]], maps / f"errors_{_stem(s.name)}.png",
                                   title=f"{Path(s.name).name}: OA {m['oa']:.4f}, mean F1 {m['mean_f1']:.4f}")
            m["error_map"], m["error_pairs"] = str(png), pairs
        files[s.name] = m
        if log:
            log(f"  {Path(s.name).name}: {m['points']:,} points, OA {m['oa']:.4f}, mean F1 {m['mean_f1']:.4f} "
                f"({m['seconds']:.1f} s)")
    if not files:
        raise LidarfxError(f"none of the files has points of the model's classes ({cmap.spec()})")
    pooled = _metrics_for(total, cmap)
    if bootstrap and parts:
        off = np.cumsum([0] + [int(b.max()) + 1 for _, _, b in parts[:-1]])  # block ids unique across files
        pooled["ci"] = block_bootstrap(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
                                       np.concatenate([p[2] + o for p, o in zip(parts, off)]), k,
                                       n_boot=bootstrap, block_size=ci_block_size)
    if by_slope:
        pooled["by_slope"] = _slope_table(total_slope, cmap)
    return {"title": "trained model on test files", "files": files, "metrics": pooled,
            "seconds": round(time.perf_counter() - t0, 3)}


def evaluate(
    sources: Any,
    *,
    test: Any = None,
    cv: int | None = 3,
    block_size: float | None = 20.0,
    buffer: float | None = None,
    random_cv: bool = True,
    leave_one_out: bool = False,
    classes: Any = None,
    ignore: Iterable[int] | None = None,
    config: TrainConfig | None = None,
    importance: bool = False,
    eliminate: bool = False,
    cv_seed: int = 0,
    progress: bool | None = False,
    log: Callable[[str], None] | None = None,
    maps_dir: str | os.PathLike | None = None,
    by_slope: bool = False,
    bootstrap: int = 1000,
    **params: Any,
) -> dict[str, Any]:
    """Evaluate a classifier configuration on labelled clouds; returns a report dict.

    Sections (each with the pooled confusion matrix and all metrics):

    * ``cv_random`` — ``cv``-fold cross-validation with random (stratified) folds
      (when ``random_cv``); neighbouring points fall into different folds, so it
      is optimistic.
    * ``cv_blocks`` — ``cv``-fold cross-validation with spatial blocks of
      ``block_size`` m (when ``block_size``).
    * ``leave_one_file_out`` — train on all files but one, test on it (when
      ``leave_one_out`` and ≥ 2 files).

    Both are buffered: training points within ``buffer`` m of the held-out blocks
    (of the held-out file's points) are left out of that fold's training (default
    ``None``: twice the largest radius, so that no training point's neighbourhood
    shares a point with a held-out point's; 0 for k-NN neighbourhoods, which have
    no fixed size; ``0`` = no buffer).
    * ``test`` — train on all ``sources``, test on the ``test`` files (per file
      and pooled; with ``maps_dir`` an error map per test file, with ``by_slope``
      the accuracy per terrain-slope class, see :func:`evaluate_model`).

    ``importance`` adds impurity importance (a random forest on the training
    sample) and permutation importance (held-out block fold 0); ``eliminate``
    runs :func:`~lidarfx.classify.backward_elimination` over the spatial-block
    folds (random folds when blocks are off).

    Every section's metrics carry ``ci``: 95 % confidence intervals of OA, kappa and
    mean F1 from ``bootstrap`` resamples of spatial blocks of ``block_size`` m (20 m
    when block folds are off; :func:`block_bootstrap`; 0 = none).

    Features of every labelled point are computed once; each fold then trains
    on a class-balanced sample of its training part (``max_per_class``) exactly
    like :func:`train`, and predicts every labelled point of the held-out part.
    """
    say = log or (lambda msg: None)
    cfg = config or TrainConfig(**params)
    if config is not None and params:
        raise LidarfxError("give either config= or keyword parameters, not both")
    cv_seed = check_seed(cv_seed)
    buf = default_buffer(cfg) if buffer is None else float(buffer)
    if not (buf >= 0 and math.isfinite(buf)):
        if buffer is None:
            raise LidarfxError(f"the default buffer (twice the largest radius) is {buf:g} m, not a finite number; "
                               "give --buffer")
        raise LidarfxError(f"buffer must be a number of metres >= 0, got {buffer!r}")
    if block_size:
        _check_block_size(block_size)
    ci_size = float(block_size) if block_size else 20.0
    _check_bootstrap(bootstrap, ci_size)
    if by_slope and test is None:
        raise LidarfxError("by_slope breaks down the results on test files: give test files (or use evaluate_model)")
    t_all = time.perf_counter()
    srcs = read_sources(sources, progress=progress)
    cmap = resolve_classes(srcs, classes, ignore)
    k = len(cmap)
    report: dict[str, Any] = {
        "lidarfx_version": __version__,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "layout": LAYOUT,
        "config": cfg.to_dict(),
        "features": cfg.feature_names(),
        "classes": cmap.to_dict(),
        "class_spec": cmap.spec(),
        "train_files": [{"name": s.name, "points": s.n_total, "usable": len(s.cloud)} for s in srcs],
        "sections": {},
        "seconds": {},
    }
    need_cv = bool(cv) and (random_cv or block_size) or (leave_one_out and len(srcs) > 1)
    if (importance or eliminate) and not need_cv:
        raise LidarfxError("feature importance and backward elimination need cross-validation (cv >= 2)")
    if need_cv:
        labelled = _labelled(srcs, cmap)  # the folds first: a bad fold setting fails before the features
        _, y, xy, g = labelled
        runs = []
        if cv and random_cv:
            runs.append(("cv_random", f"{cv}-fold CV, random folds (stratified by class)",
                         random_folds(len(y), int(cv), cv_seed, y), {}))
        near: dict[str, np.ndarray] = {}  # per section: points left out of each fold's training
        tail = f", buffer {buf:g} m" if buf > 0 else ""
        if cv and block_size:
            fb, blocks = block_folds(xy, int(cv), float(block_size), cv_seed, g)
            if buf > 0:
                near["cv_blocks"] = block_buffer_mask(xy, fb, float(block_size), buf, g)
            runs.append(("cv_blocks", f"{cv}-fold CV, spatial blocks of {float(block_size):g} m" + tail,
                         fb, {"block_size": float(block_size), "blocks": int(blocks.max() + 1), "buffer": buf}))
        if leave_one_out and len(srcs) > 1:
            if buf > 0:
                near["leave_one_file_out"] = nf = file_buffer_mask(xy, g, buf)
                for f, src in enumerate(srcs):
                    left = np.unique(y[(g != f) & ~nf[f]])
                    if len(left) < min(2, len(np.unique(y[g != f]))):
                        raise LidarfxError(
                            f"leave one file out: a buffer of {buf:g} m around {src.name} leaves "
                            f"{'no training point' if not len(left) else 'only one class'} in the other files "
                            "(the files overlap); give --buffer 0 to test on overlapping scans")
            runs.append(("leave_one_file_out", "leave one file out (train on the others)" + tail, g,
                         {"files": [s.name for s in srcs], "buffer": buf}))
        t0 = time.perf_counter()
        X = _file_features(srcs, cmap, cfg, progress, labelled)[0]
        rule = None
        target = building_class(cmap) if cfg.min_building_area > 0 else None
        if target is not None:  # the held-out parts are classified as a model classifies a cloud
            rule = HeldOutRule(srcs, cmap, cfg, labelled, X, target, progress)
        X_aug = [_file_features(copies, cmap, cfg, progress)[0] for copies in sheared_sources(srcs, cfg)]
        X_aug += [_thinned_features(srcs, copies, cmap, cfg, progress) for copies in thinned_sources(srcs, cfg)]
        report["seconds"]["cv_features"] = round(time.perf_counter() - t0, 3)
        say(f"features of {len(y):,} labelled points: {X.shape[1]} columns, {time.perf_counter() - t0:.1f} s")
        fitted_blocks = None
        for key, title, folds, extra in runs:
            t0 = time.perf_counter()
            say(f"{title}:")
            if rule is not None:
                rule.set_folds({"cv_random": "random", "cv_blocks": "blocks"}.get(key, "files"), folds,
                               int(cv or 0), cv_seed, float(block_size or 0))
            held = np.full(len(y), -1, np.int64)
            cm, per_fold, fitted = cross_validate(X, y, folds, cfg, k, log=say, X_aug=X_aug,
                                                  exclude=near.get(key), post=rule, out_pred=held,
                                                  class_names=cmap.names)
            if key == "leave_one_file_out":
                for pf in per_fold:
                    pf["file"] = srcs[pf["fold"]].name
            report["sections"][key] = {"title": title, **extra, "folds": per_fold,
                                       "metrics": _metrics_for(cm, cmap),
                                       "seconds": round(time.perf_counter() - t0, 3)}
            if bootstrap:
                report["sections"][key]["metrics"]["ci"] = block_bootstrap(
                    y, held, block_ids(xy, ci_size, g), k, n_boot=bootstrap, block_size=ci_size)
            if rule is not None:
                report["sections"][key]["small_buildings"] = {"min_building_area": cfg.min_building_area,
                                                              "max_multi_return_share": cfg.max_multi_return_share,
                                                              **rule.stats}
            if key == "cv_blocks":
                fitted_blocks = fitted
        if importance:
            from .importance import impurity_importance, permutation_importance

            names = cfg.feature_names()
            t0 = time.perf_counter()
            imp: dict[str, Any] = {}
            s = balanced_sample(y, cfg.max_per_class, cfg.seed)
            rf_cfg = TrainConfig(**{**cfg.to_dict(), "classifier": "rf", "n_estimators": None})  # 100 trees
            imp["impurity"] = impurity_importance(rf_cfg.fit_matrix(X[s], y[s]), names)
            imp["impurity_model"] = "random forest (100 trees) on the training sample"
            if fitted_blocks:
                est, te = fitted_blocks[0]
                imp["permutation"] = permutation_importance(est, X[te], y[te], names, seed=cfg.seed)
                imp["permutation_data"] = "held-out points of spatial-block fold 0 (at most 20 000)"
            report["importance"] = imp
            report["seconds"]["importance"] = round(time.perf_counter() - t0, 3)
        if eliminate:
            from .importance import backward_elimination

            t0 = time.perf_counter()
            blocks_run = next((r for r in runs if r[0] == "cv_blocks"), None)
            folds = blocks_run[2] if blocks_run else runs[0][2]
            say("backward elimination (random forest, 50 trees):")
            report["backward_elimination"] = backward_elimination(
                X, y, cfg.feature_names(), folds, max_per_class=cfg.max_per_class, seed=cfg.seed, log=say,
                exclude=near.get("cv_blocks") if blocks_run else None)
            report["seconds"]["backward_elimination"] = round(time.perf_counter() - t0, 3)
    if test is not None:
        t0 = time.perf_counter()
        say("train on all training files:")
        model = train(srcs, classes=cmap, config=cfg, progress=progress, log=lambda m: say("  " + m))
        say("test:")
        sec = evaluate_model(model, test, progress=progress, log=say, maps_dir=maps_dir, by_slope=by_slope,
                             bootstrap=bootstrap, ci_block_size=ci_size)
        sec["title"] = "train on the training files, test on the test files"
        sec["train_seconds"] = model.meta["training"]["seconds"]
        sec["seconds"] = round(time.perf_counter() - t0, 3)
        report["sections"]["test"] = sec
    report["seconds"]["total"] = round(time.perf_counter() - t_all, 3)
    return report


# --------------------------------------------------------------------------- text
def _f(v: float, nd: int = 4) -> str:
    return "   nan" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{nd}f}"


def format_metrics(m: dict[str, Any], title: str | None = None) -> str:
    """Text table of one metrics dict (per-class rows, then the confusion matrix)."""
    lines = []
    if title:
        lines.append(title)
    lines.append(f"points {m['points']:,}   OA {_f(m['oa'])}   kappa {_f(m['kappa'])}   "
                 f"mean F1 {_f(m['mean_f1'])}   mean IoU {_f(m['mean_iou'])}")
    ci = m.get("ci")
    if ci:
        size = f" of {ci['block_size']:g} m" if ci.get("block_size") else ""
        lines.append(f"{ci['level']:.0%} interval (bootstrap of {ci['blocks']} blocks{size}): "
                     f"OA {_f(ci['oa'][0])}–{_f(ci['oa'][1])}   kappa {_f(ci['kappa'][0])}–{_f(ci['kappa'][1])}   "
                     f"mean F1 {_f(ci['mean_f1'][0])}–{_f(ci['mean_f1'][1])}")
    w = max([len(c["name"]) for c in m["classes"]] + [5])
    lines.append(f"  {'class':<{w}} {'codes':>8} {'support':>9} {'PA':>7} {'UA':>7} {'F1':>7} {'IoU':>7}")
    for c in m["classes"]:
        lines.append(f"  {c['name']:<{w}} {str(c['code']):>8} {c['support']:>9,} {_f(c['pa']):>7} "
                     f"{_f(c['ua']):>7} {_f(c['f1']):>7} {_f(c['iou']):>7}"
                     + ("  (no reference points: not in the means)" if c["support"] == 0 else ""))
    lines.append(f"  confusion matrix ({LAYOUT}):")
    cw = max(9, max(len(f"{v:,}") for row in m["confusion"] for v in row) + 1)
    lines.append("  " + " " * w + "".join(f"{c['name'][:cw - 1]:>{cw}}" for c in m["classes"]))
    for c, row in zip(m["classes"], m["confusion"]):
        lines.append(f"  {c['name']:<{w}}" + "".join(f"{v:>{cw},}" for v in row))
    return "\n".join(lines)


def format_slope_table(rows: list[dict[str, Any]]) -> str:
    """Text table of a ``by_slope`` breakdown: points, OA and PA per class per slope class."""
    names = list(rows[0]["pa"]) if rows else []
    w = max([len(n) for n in names] + [7])
    out = ["  by terrain slope (1 m DTM of the SMRF ground):",
           f"  {'slope':>9} {'points':>9} {'OA':>7}" + "".join(f" {'PA ' + n:>{w + 3}}" for n in names)]
    for r in rows:
        lo, hi = r["slope_deg"]
        out.append(f"  {f'{lo:g}–{hi:g}°':>9} {r['points']:>9,} {_f(r['oa']):>7}"
                   + "".join(f" {_f(r['pa'][n]):>{w + 3}}" for n in names))
    return "\n".join(out)


def _small_buildings_line(sb: dict[str, Any]) -> str:
    text = (f"small-building rule ({sb['min_building_area']:g} m², docs/classification.md §2): "
            f"{sb.get('relabelled_components', 0):,} of {sb.get('components', 0):,} predicted-building clusters "
            f"relabelled ({sb.get('relabelled_points', 0):,} points), {sb.get('kept_at_edge', 0):,} small ones "
            "kept at the data's edge")
    share = sb.get("max_multi_return_share", 1.0)
    if share < 1:
        text += (f"; see-through test (> {share:g} of the points from multi-return pulses): "
                 f"{sb.get('see_through_components', 0):,} clusters relabelled "
                 f"({sb.get('see_through_points', 0):,} points)")
        if sb.get("see_through_untested"):
            text += ", not run where the data record no return numbers"
    return text


def format_report(report: dict[str, Any]) -> str:
    """The whole report as text: one block per section, then importances."""
    out = [f"lidarfx {report.get('lidarfx_version', '')} classification report",
           f"classes: {report.get('class_spec', '')}",
           f"classifier: {report['config']['classifier']}, {len(report['features'])} features, "
           f"radii {', '.join(f'{r:g}' for r in report['config']['radii'])} m, "
           f"max {report['config']['max_per_class']} training points per class",
           f"training files: {', '.join(Path(f['name']).name for f in report['train_files'])}", ""]
    for key, sec in report["sections"].items():
        out.append(f"== {sec['title']} [{key}] ==")
        if "block_size" in sec:
            out.append(f"{sec['blocks']} blocks of {sec['block_size']:g} m")
        if sec.get("buffer"):
            out.append(f"training points within {sec['buffer']:g} m of the held-out "
                       f"{'blocks' if 'block_size' in sec else 'file'} are left out of that fold's training")
        for pf in sec.get("folds", []):
            label = Path(pf["file"]).name if "file" in pf else f"fold {pf['fold']}"
            left = f", {pf['buffer_excluded']:,} training points in the buffer" if pf.get("buffer_excluded") else ""
            out.append(f"  {label}: test {pf['test_points']:,} points, OA {_f(pf['oa'])}, "
                       f"mean F1 {_f(pf['mean_f1'])}{left}{_not_trained(pf)}")
        if sec.get("small_buildings"):
            out.append(_small_buildings_line(sec["small_buildings"]))
        if key == "test":
            for name, m in sec["files"].items():
                d = m.get("density")
                dens = (f" ({d['density']:.1f} pts/m², {d['ratio']:.2f} × the training density)" if d else "")
                out.append(format_metrics(m, f"-- {Path(name).name}{dens}"))
                if m.get("small_buildings"):
                    out.append(_small_buildings_line(m["small_buildings"]))
                if m.get("by_slope"):
                    out.append(format_slope_table(m["by_slope"]))
            out.append(format_metrics(sec["metrics"], "-- all test files pooled"))
            if sec["metrics"].get("by_slope") and len(sec["files"]) > 1:
                out.append(format_slope_table(sec["metrics"]["by_slope"]))
        else:
            out.append(format_metrics(sec["metrics"]))
        out.append("")
    imp = report.get("importance")
    if imp:
        out.append("== feature importance (top 15) ==")
        out.append(f"impurity ({imp.get('impurity_model')}):")
        for r in imp["impurity"][:15]:
            out.append(f"  {r['name']:<32} {r['importance']:.4f}")
        if "permutation" in imp:
            out.append(f"permutation, drop of mean F1 ({imp.get('permutation_data')}):")
            for r in imp["permutation"][:15]:
                out.append(f"  {r['name']:<32} {r['mean']:.4f} ± {r['std']:.4f}")
        out.append("")
    be = report.get("backward_elimination")
    if be:
        out.append("== backward elimination (Chehata 2009; random forest) ==")
        for st in be["steps"]:
            out.append(f"  {st['n_features']:3d} features: OA {_f(st['oa'])}, mean F1 {_f(st['mean_f1'])}")
        b = be["best"]
        out.append(f"smallest set within {be['tolerance']} of the best mean F1: {b['n_features']} features: "
                   + ", ".join(b["features"]))
        out.append("")
    if report.get("seconds"):
        out.append("seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in report["seconds"].items()))
    return "\n".join(out)


def report_json(report: dict[str, Any]) -> str:
    """The report as strict JSON (NaN → null)."""
    from .._json import dumps

    return dumps(report, indent=2)


def write_report(report: dict[str, Any], out_dir: str | os.PathLike) -> list[Path]:
    """``report.txt``, ``report.json`` and ``confusion_<section>.png`` (pooled, and one
    per test file) in ``out_dir`` (created if missing; each file written atomically)."""
    from .._atomic import atomic_path

    d = _out_dir(out_dir)
    written = []
    with atomic_path(d / "report.txt") as tmp:
        tmp.write_text(format_report(report) + "\n")
    written.append(d / "report.txt")
    with atomic_path(d / "report.json") as tmp:
        tmp.write_text(report_json(report) + "\n")
    written.append(d / "report.json")
    for key, sec in report["sections"].items():
        written.append(plot_confusion(sec["metrics"], d / f"confusion_{key}.png", title=sec["title"]))
        if key == "test" and len(sec["files"]) > 1:
            for name, m in sec["files"].items():
                written.append(plot_confusion(m, d / f"confusion_test_{_stem(name)}.png",
                                              title=f"test: {Path(name).name}"))
        if key == "test":
            written += [Path(m["error_map"]) for m in sec["files"].values() if m.get("error_map")]
    if report.get("importance"):
        written.append(plot_importance(report["importance"], d / "importance.png"))
    if report.get("backward_elimination"):
        written.append(plot_elimination(report["backward_elimination"], d / "backward_elimination.png"))
    return written


def _stem(name: str) -> str:
    return Path(name).stem.replace(" ", "_")


def plot_confusion(m: dict[str, Any], path: str | os.PathLike, title: str | None = None) -> Path:
    """Confusion-matrix PNG: cells coloured by row share (= PA on the diagonal), with counts;
    the layout (rows = reference, columns = predicted) is written on the figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .._atomic import atomic_path

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
    ax.set_xticks(range(k), [f"{n}\nUA {_f(c['ua'], 3)}" for n, c in zip(names, m["classes"])], fontsize=8)
    ax.set_yticks(range(k), [f"{n}\nPA {_f(c['pa'], 3)}" for n, c in zip(names, m["classes"])], fontsize=8)
    ax.set_xlabel("predicted (columns)")
    ax.set_ylabel("reference (rows)")
    head = (title + "\n") if title else ""
    ci = m.get("ci")
    tail = (f"\n{ci['level']:.0%} interval, {ci['blocks']} blocks: OA {_f(ci['oa'][0], 3)}–{_f(ci['oa'][1], 3)}  "
            f"mean F1 {_f(ci['mean_f1'][0], 3)}–{_f(ci['mean_f1'][1], 3)}") if ci else ""
    ax.set_title(f"{head}OA {_f(m['oa'])}  kappa {_f(m['kappa'])}  mean F1 {_f(m['mean_f1'])}{tail}", fontsize=9)
    fig.text(0.5, 0.01, f"layout: {LAYOUT}; cell = points and share of the reference row",
             ha="center", fontsize=7)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    p = Path(path)
    with atomic_path(p) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return p


def plot_importance(imp: dict[str, Any], path: str | os.PathLike, top: int = 20) -> Path:
    """Feature-importance PNG: the ``top`` features by impurity importance and, when the
    report has it, by permutation importance (drop of mean F1, bars ± one standard
    deviation over the repeats), largest at the top; ``imp`` as in ``report["importance"]``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..render import _save

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
    return _save(fig, path, dpi=110)


def plot_elimination(be: dict[str, Any], path: str | os.PathLike) -> Path:
    """Backward-elimination PNG (Chehata et al. 2009): cross-validated OA and mean F1 against
    the number of features kept, from all features down to one, with the smallest set within
    the tolerance of the best mean F1 marked; ``be`` as in ``report["backward_elimination"]``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..render import _save

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
    return _save(fig, path, dpi=110)
