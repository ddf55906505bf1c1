"""Honest evaluation: cross-validation (random and buffered spatial-block folds), leave one
file out, transfer to test files, and a trained model on labelled files.

The parts live in their own modules and are importable from here as before:
:mod:`.metrics` (confusion matrix, OA, kappa, F1, IoU, block-bootstrap intervals, slope
breakdown), :mod:`.folds` (random / block folds and their buffers), :mod:`.report` (text,
JSON, report folder), :mod:`lidarfx.render.classify_plots` (the pictures) and
:mod:`.importance` (feature importance, backward elimination).
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
from ..errors import LidarfxError, LidarfxWarning, check_seed
from ..render.classify_plots import plot_confusion, plot_elimination, plot_importance
from .classes import ClassMap
from .fastpredict import predict as fast_predict
from .fastpredict import predict_proba
from .folds import (
    MIN_BLOCK_SIZE,
    block_buffer_mask,
    block_folds,
    block_ids,
    check_block_size,
    default_buffer,
    file_buffer_mask,
    fold_parts,
    random_folds,
)
from .importance import backward_elimination, impurity_importance, permutation_importance
from .metrics import (
    LAYOUT,
    MAX_BOOTSTRAP,
    SLOPE_BINS,
    block_bootstrap,
    check_bootstrap,
    confusion_matrix,
    metrics,
    metrics_for,
    slope_confusions,
    slope_table,
    terrain_slope,
)
from .model import (
    ClassifierModel,
    Source,
    TrainConfig,
    augment_cap,
    cloud_density,
    read_sources,
    resolve_classes,
    sheared_sources,
    source_labels,
    thinned_sources,
    train,
)
from .objects import building_class, drop_small_objects, link_for
from .pipeline import CloudSample, balanced_sample, unit_to_metre
from .report import (
    file_stem,
    format_metrics,
    format_report,
    format_slope_table,
    not_trained_note,
    report_dir,
    report_json,
    small_buildings_line,
    write_report,
)

__all__ = ["LAYOUT", "confusion_matrix", "metrics", "random_folds", "block_folds", "block_ids", "block_bootstrap",
           "block_buffer_mask",
           "file_buffer_mask", "cross_validate", "evaluate", "evaluate_model", "format_metrics", "format_report", "write_report", "plot_confusion",
           "plot_importance", "plot_elimination", "terrain_slope", "SLOPE_BINS",
           "HeldOutRule", "labelled_points", "file_features", "thinned_features", "pooled_interval_notes",
           "MIN_BLOCK_SIZE", "MAX_BOOTSTRAP", "format_slope_table", "report_json"]


def cross_validate(X: np.ndarray, y: np.ndarray, folds: np.ndarray, config: TrainConfig, n_classes: int,
                   log: Callable[[str], None] | None = None, X_aug: Sequence[np.ndarray] = (),
                   exclude: np.ndarray | None = None,
                   post: Callable[[int, Any, np.ndarray], np.ndarray] | None = None,
                   out_pred: np.ndarray | None = None, class_names: Sequence[str] | None = None,
                   progress: bool | None = False) -> tuple[np.ndarray, list[dict[str, Any]], list]:
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
    ``progress`` (:func:`lidarfx.progress.wanted`): a spinner naming the fold during each fit.
    Returns the summed confusion matrix,
    per-fold results and
    the fitted estimators with their held-out indices."""
    cm = np.zeros((n_classes, n_classes), np.int64)
    per_fold, fitted = [], []
    fold_ids = np.unique(folds)
    for i, f in enumerate(fold_ids):
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
                pick = ok[balanced_sample(y[rows[ok]], augment_cap(config), config.seed + 1 + a)]
                Xf, yf = np.vstack([Xf, Xa[pick]]), np.concatenate([yf, y[rows[pick]]])
                continue
            sa = tr[balanced_sample(y[tr], augment_cap(config), config.seed + 1 + a)]
            Xf, yf = np.vstack([Xf, Xa[sa]]), np.concatenate([yf, y[sa]])
        if len(np.unique(yf)) < 2:
            near = "" if exclude is None else (
                f" ({int((exclude[f] & (folds != f) & (y >= 0)).sum()):,} of its labelled points lie within the "
                "buffer of the held-out part; use a smaller --buffer)")
            raise LidarfxError(f"fold {int(f)}: its training part holds fewer than two classes{near}")
        est = config.fit_matrix(Xf, yf, progress, step=f"fold {i + 1} of {len(fold_ids)}: ")
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
                f"mean F1 {m['mean_f1']:.4f}{not_trained_note(per_fold[-1])}")
    return cm, per_fold, fitted



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
        idxs, y, _, g = labelled
        self.target, self.area, self.k = target, float(config.min_building_area), len(cmap)
        self.share = float(config.max_multi_return_share)
        tr = config.transformer(progress=progress)
        xyz_l, xyz_c, Xc, g_c, nr_l, nr_c = [], [], [], [], [], []
        self.link = []
        for i, (s, idx) in enumerate(zip(sources, idxs)):
            u = unit_to_metre(s.cloud)
            ctx = np.flatnonzero(source_labels(s, cmap) < 0)
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
def labelled_points(sources: list[Source], cmap: ClassMap
              ) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """Indices (per source), labels, xy (metres) and file id of every labelled point of every source."""
    idxs, ys, xys, gs = [], [], [], []
    for i, s in enumerate(sources):
        y = source_labels(s, cmap)
        idx = np.flatnonzero(y >= 0)
        idxs.append(idx)
        ys.append(y[idx])
        xys.append(s.cloud.xyz[idx, :2] * unit_to_metre(s.cloud))  # blocks in metres
        gs.append(np.full(len(idx), i, np.int64))
    return idxs, np.concatenate(ys).astype(np.int64), np.vstack(xys), np.concatenate(gs)


def file_features(sources: list[Source], cmap: ClassMap, config: TrainConfig, progress: bool | None,
                   labelled: tuple | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Features, labels, xy and file id of every labelled point of every source
    (``labelled``: :func:`labelled_points` of ``sources``, when already known)."""
    tr = config.transformer(progress=progress)
    idxs, y, xy, g = labelled or labelled_points(sources, cmap)
    X = np.vstack([tr.transform(CloudSample(s.cloud, idx)) for s, idx in zip(sources, idxs)])
    return X, y, xy, g


def thinned_features(sources: list[Source], copies: list[tuple[Source, np.ndarray]], cmap: ClassMap,
                      config: TrainConfig, progress: bool | None) -> tuple[np.ndarray, np.ndarray]:
    """Features of the labelled points of thinned copies and their rows in :func:`file_features`."""
    tr = config.transformer(progress=progress)
    Xs, rows, offset = [], [], 0
    for s, (c, keep) in zip(sources, copies):
        idx = np.flatnonzero(source_labels(s, cmap) >= 0)
        idx_c = np.flatnonzero(source_labels(c, cmap) >= 0)
        Xs.append(tr.transform(CloudSample(c.cloud, idx_c)))
        rows.append(offset + np.searchsorted(idx, np.flatnonzero(keep)[idx_c]))
        offset += len(idx)
    return np.vstack(Xs), np.concatenate(rows)



def pooled_interval_notes(parts: Sequence[tuple], cmap: ClassMap) -> list[str]:
    """Why a pooled interval of several files may reach below the files' own: one line per class
    with reference points in some of the files only while other files have points predicted as it
    (false positives that only the pooled figure counts).  ``parts``: per file ``(ref, pred,
    blocks, name)`` as :func:`evaluate_model` collects them.  The pooled F1 of such a class moves
    with how many of the blocks holding its reference points a resample draws, against a number
    of false positives that hardly moves, which a file's own F1 does not do."""
    notes = []
    counted = [(y >= 0) & (p >= 0) for y, p, _, _ in parts]
    total_blocks = sum(len(np.unique(b[ok])) for (_, _, b, _), ok in zip(parts, counted))
    for c in range(len(cmap)):
        has = [i for i, (y, _, _, _) in enumerate(parts) if (y == c).any()]
        false = [(i, int(((p == c) & ok & (y != c)).sum())) for i, ((y, p, _, _), ok) in enumerate(zip(parts, counted))
                 if i not in has]
        false = [(i, n) for i, n in false if n]
        if not has or not false:
            continue
        blocks = sum(len(np.unique(parts[i][2][parts[i][0] == c])) for i in has)
        name = cmap.names[c]
        notes.append(f"{name}: reference points in {', '.join(Path(parts[i][3]).name for i in has)} only "
                     f"({blocks} of {total_blocks} blocks), while {sum(n for _, n in false):,} points of "
                     f"{', '.join(Path(parts[i][3]).name for i, _ in false)} are predicted {name}; the pooled "
                     f"{name} F1 counts both and moves with how many of those {blocks} blocks a resample draws, "
                     "so the pooled figure and its interval can lie below the files' own")
    return notes


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
    and mean F1 in ``ci`` (:func:`block_bootstrap` over blocks of ``ci_block_size`` m; 0 = none);
    the pooled interval draws each file's blocks within that file (stratified), and the pooled
    ``interval_notes`` (:func:`pooled_interval_notes`) name the classes that can take it below the
    files' own.
    """
    check_bootstrap(bootstrap, ci_block_size)
    maps = report_dir(maps_dir, create=False) if maps_dir is not None else None  # refused before any work
    srcs = read_sources(sources, progress=progress)
    cmap = model.classes
    k = len(cmap)
    total = np.zeros((k, k), np.int64)
    total_slope = np.zeros((len(SLOPE_BINS) - 1, k, k), np.int64)
    files = {}
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray, str]] = []  # per file: ref, pred, blocks, name
    t0 = time.perf_counter()
    for s in srcs:
        t = time.perf_counter()
        y = source_labels(s, cmap)
        if not (y >= 0).any():
            found = sorted(int(c) for c in np.unique(np.asarray(s.cloud["classification"])))
            msg = (f"{s.name} has no points of the model's classes ({cmap.spec()}); its classes: "
                   f"{found[:20]}{' …' if len(found) > 20 else ''}")
            if len(srcs) == 1:
                raise LidarfxError(msg)
            warnings.warn(msg + "; not counted", LidarfxWarning, stacklevel=2)
            continue
        dens = model.density_check(s.cloud, s.name)
        if getattr(getattr(model, "features", None), "precomputed", False) and s.n_total > len(s.cloud):
            warnings.warn(  # the source holds the usable points only: LidarFeatures.check_cloud cannot see them
                f"{s.name}: {s.n_total - len(s.cloud):,} virtual, withheld or synthetic points are in no "
                "neighbourhood of a plain predict, but features written by lidarfx features have them as "
                "neighbours, so the precomputed features are not the ones a plain predict computes and some "
                "points may get another class", LidarfxWarning, stacklevel=2)
        rule: dict[str, Any] = {}
        codes = model.predict(s.cloud, progress=progress, check_density=False,
                              min_building_area=min_building_area, max_multi_return_share=max_multi_return_share,
                              stats=rule)
        pred = cmap.index_of(np.clip(codes, 0, 255))
        cm = confusion_matrix(y, np.where(y >= 0, pred, 0), k)
        total += cm
        m = metrics_for(cm, cmap)
        m["seconds"] = round(time.perf_counter() - t, 3)
        m["ignored_points"] = int((y < 0).sum())
        m["unusable_points"] = int(s.n_total - len(s.cloud))
        m["density"] = dens
        if bootstrap:
            blocks = block_ids(s.cloud.xyz[:, :2] * unit_to_metre(s.cloud), ci_block_size)
            m["ci"] = block_bootstrap(y, pred, blocks, k, n_boot=bootstrap, block_size=ci_block_size)
            parts.append((y, pred, blocks, s.name))
        if by_slope:
            cms = slope_confusions(y, pred, terrain_slope(s.cloud), k)
            total_slope += cms
            m["by_slope"] = slope_table(cms, cmap)
        if rule:
            m["small_buildings"] = {
                "min_building_area": model.min_building_area if min_building_area is None else float(min_building_area),
                "max_multi_return_share": (model.max_multi_return_share if max_multi_return_share is None
                                           else float(max_multi_return_share)),
                **rule}
        if maps is not None:
            from ..render import error_map

            u = unit_to_metre(s.cloud)
            report_dir(maps)
            png, pairs = error_map(s.cloud.xyz[:, :2] * u, s.cloud.xyz[:, 2] * u, y, pred,
                                   [c["name"] for c in m["classes"]], maps / f"errors_{file_stem(s.name)}.png",
                                   title=f"{Path(s.name).name}: OA {m['oa']:.4f}, mean F1 {m['mean_f1']:.4f}")
            m["error_map"], m["error_pairs"] = str(png), pairs
        files[s.name] = m
        if log:
            log(f"  {Path(s.name).name}: {m['points']:,} points, OA {m['oa']:.4f}, mean F1 {m['mean_f1']:.4f} "
                f"({m['seconds']:.1f} s)")
    if not files:
        raise LidarfxError(f"none of the files has points of the model's classes ({cmap.spec()})")
    pooled = metrics_for(total, cmap)
    if bootstrap and parts:
        # every resample holds every file's blocks in their own number (stratified by file): the
        # pooled figure is that of these files together, not of a pool whose mix of files varies
        pooled["ci"] = block_bootstrap(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
                                       np.concatenate([p[2] for p in parts]), k,
                                       n_boot=bootstrap, block_size=ci_block_size,
                                       strata=np.concatenate([np.full(len(p[0]), i) for i, p in enumerate(parts)]))
        notes = pooled_interval_notes(parts, cmap)
        if pooled["ci"] is not None and notes:
            pooled["interval_notes"] = notes
    if by_slope:
        pooled["by_slope"] = slope_table(total_slope, cmap)
    return {"title": "trained model on test files", "files": files, "metrics": pooled,
            "seconds": round(time.perf_counter() - t0, 3)}


def check_buffer(buffer: float | None, cfg: TrainConfig) -> float:
    """The buffer of spatial folds (metres): ``buffer``, or twice the largest radius of ``cfg``;
    a one-line error unless it is a finite number >= 0."""
    buf = default_buffer(cfg) if buffer is None else float(buffer)
    if not (buf >= 0 and math.isfinite(buf)):
        if buffer is None:
            raise LidarfxError(f"the default buffer (twice the largest radius) is {buf:g} m, not a finite number; "
                               "give --buffer")
        raise LidarfxError(f"buffer must be a number of metres >= 0, got {buffer!r}")
    return buf


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
    when block folds are off; :func:`block_bootstrap`, blocks drawn within each file; 0 = none).

    Features of every labelled point are computed once; each fold then trains
    on a class-balanced sample of its training part (``max_per_class``) exactly
    like :func:`train`, and predicts every labelled point of the held-out part.
    """
    say = log or (lambda msg: None)
    cfg = config or TrainConfig(**params)
    if config is not None and params:
        raise LidarfxError("give either config= or keyword parameters, not both")
    cv_seed = check_seed(cv_seed)
    buf = check_buffer(buffer, cfg)
    if block_size:
        check_block_size(block_size)
    ci_size = float(block_size) if block_size else 20.0
    check_bootstrap(bootstrap, ci_size)
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
        labelled = labelled_points(srcs, cmap)  # the folds first: a bad fold setting fails before the features
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
        X = file_features(srcs, cmap, cfg, progress, labelled)[0]
        rule = None
        target = building_class(cmap) if cfg.min_building_area > 0 else None
        if target is not None:  # the held-out parts are classified as a model classifies a cloud
            rule = HeldOutRule(srcs, cmap, cfg, labelled, X, target, progress)
        X_aug = [file_features(copies, cmap, cfg, progress)[0] for copies in sheared_sources(srcs, cfg)]
        X_aug += [thinned_features(srcs, copies, cmap, cfg, progress) for copies in thinned_sources(srcs, cfg)]
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
                                                  class_names=cmap.names, progress=progress)
            if key == "leave_one_file_out":
                for pf in per_fold:
                    pf["file"] = srcs[pf["fold"]].name
            report["sections"][key] = {"title": title, **extra, "folds": per_fold,
                                       "metrics": metrics_for(cm, cmap),
                                       "seconds": round(time.perf_counter() - t0, 3)}
            if bootstrap:  # blocks drawn within each file, as in evaluate_model
                report["sections"][key]["metrics"]["ci"] = block_bootstrap(
                    y, held, block_ids(xy, ci_size, g), k, n_boot=bootstrap, block_size=ci_size, strata=g)
            if rule is not None:
                report["sections"][key]["small_buildings"] = {"min_building_area": cfg.min_building_area,
                                                              "max_multi_return_share": cfg.max_multi_return_share,
                                                              **rule.stats}
            if key == "cv_blocks":
                fitted_blocks = fitted
        if importance:
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


# the names these had before the split (tests, benchmarks and scripts import them from here)
_metrics_for = metrics_for
_labelled = labelled_points
_file_features = file_features
_thinned_features = thinned_features
_out_dir = report_dir
_small_buildings_line = small_buildings_line
_not_trained = not_trained_note
_slope_table = slope_table
_stem = file_stem
_check_block_size = check_block_size
_check_bootstrap = check_bootstrap
