"""Feature importance (impurity, permutation) and Chehata-style backward elimination.

* **Impurity importance** (mean decrease in impurity, Breiman 2001): what a
  random forest's splits gained per feature, on the training data.  Cheap, but
  biased towards features with many distinct values and shared arbitrarily
  between correlated features (the same feature at two radii).
* **Permutation importance**: the drop of a score on *held-out* points when one
  feature's column is shuffled (scikit-learn's ``permutation_importance``).
* **Backward elimination** (Chehata, Guo & Mallet 2009): train a random forest,
  drop the least important feature(s), repeat; track the cross-validated score
  of every subset and keep the smallest subset whose score is within a
  tolerance of the best.
"""
from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np

from ..errors import LidarfxError
from .fastpredict import fast_estimator
from .folds import fold_parts
from .metrics import confusion_matrix, metrics
from .pipeline import balanced_sample

__all__ = ["impurity_importance", "permutation_importance", "backward_elimination"]


def _final(estimator: Any) -> Any:
    """The classifier at the end of a pipeline / model."""
    est = getattr(estimator, "pipeline", estimator)
    if hasattr(est, "steps"):
        est = est.steps[-1][1]
    return est


def impurity_importance(estimator: Any, names: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Mean decrease in impurity per feature, largest first (needs a random forest)."""
    clf = _final(estimator)
    imp = getattr(clf, "feature_importances_", None)
    if imp is None:
        raise LidarfxError(f"impurity importance needs a tree ensemble with feature_importances_ "
                           f"(random forest, classifier 'rf'); got {type(clf).__name__}")
    names = list(names) if names is not None else list(getattr(estimator, "feature_names", range(len(imp))))
    if len(names) != len(imp):
        raise LidarfxError(f"{len(names)} names for {len(imp)} features")
    order = np.argsort(-imp, kind="stable")
    return [{"name": str(names[i]), "importance": float(imp[i])} for i in order]


def _fast_scorer(estimator: Any, scoring: Any) -> Any:
    """``scoring`` as a callable predicting through :mod:`.fastpredict` (same predictions,
    4x faster for boosting); unchanged for other estimators and scorers."""
    if scoring not in ("f1_macro", "accuracy"):
        return scoring
    fast = fast_estimator(estimator)
    if fast is None:
        return scoring
    from sklearn.metrics import accuracy_score, f1_score

    def score(_est: Any, X: np.ndarray, y: np.ndarray) -> float:
        pred = fast.predict(X)
        return float(f1_score(y, pred, average="macro") if scoring == "f1_macro" else accuracy_score(y, pred))

    return score


def permutation_importance(estimator: Any, X: np.ndarray, y: np.ndarray, names: Sequence[str] | None = None, *,
                           n_repeats: int = 3, scoring: str = "f1_macro", max_points: int | None = 20_000,
                           seed: int = 0, n_jobs: int | None = None) -> list[dict[str, Any]]:
    """Score drop when a feature is shuffled, on held-out ``X, y``; largest first.

    ``estimator`` is anything with ``predict`` on feature matrices (e.g.
    ``model.estimator`` or a fold's fitted estimator).  At most ``max_points``
    random rows are used.
    """
    from sklearn.inspection import permutation_importance as _pi

    est = getattr(estimator, "estimator", estimator) if hasattr(estimator, "pipeline") else estimator
    X = np.asarray(X)
    y = np.asarray(y)
    if max_points and len(y) > max_points:
        pick = np.sort(np.random.default_rng(seed).choice(len(y), max_points, replace=False))
        X, y = X[pick], y[pick]
    res = _pi(est, X, y, n_repeats=n_repeats, scoring=_fast_scorer(est, scoring), random_state=seed, n_jobs=n_jobs)
    names = list(names) if names is not None else [str(i) for i in range(X.shape[1])]
    order = np.argsort(-res.importances_mean, kind="stable")
    return [{"name": str(names[i]), "mean": float(res.importances_mean[i]), "std": float(res.importances_std[i])}
            for i in order]


def backward_elimination(
    X: np.ndarray,
    y: np.ndarray,
    names: Sequence[str],
    folds: np.ndarray,
    *,
    step: float = 0.1,
    min_features: int = 1,
    tolerance: float = 0.005,
    n_estimators: int = 50,
    max_per_class: int | None = 10_000,
    seed: int = 0,
    log: Callable[[str], None] | None = None,
    exclude: np.ndarray | None = None,
) -> dict[str, Any]:
    """Backward feature elimination with a random forest (Chehata et al. 2009).

    Each round: cross-validate a random forest on the current features over
    ``folds`` (e.g. spatial-block folds from
    :func:`lidarfx.classify.block_folds`), record OA and mean F1, then drop the
    ``max(1, step · n)`` features with the lowest impurity importance (forest
    trained on all folds).  Stops at ``min_features``.  ``exclude``: points left
    out of each fold's training part (a buffered block CV,
    :func:`lidarfx.classify.folds.block_buffer_mask`).

    Returns ``{"steps": [{"n_features", "oa", "mean_f1", "features", "removed"}...],
    "best": <the smallest step whose mean F1 is within tolerance of the best>}``.
    """
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.utils.class_weight import compute_sample_weight

    X = np.asarray(X, dtype=np.float32)
    y = np.asarray(y)
    names = list(names)
    if X.shape[1] != len(names):
        raise LidarfxError(f"{len(names)} names for {X.shape[1]} columns")
    if not 0 < step < 1 and step != 1:
        raise LidarfxError("step must be a fraction in (0, 1)")
    k = int(y.max()) + 1
    current = list(range(len(names)))
    steps = []

    def forest():
        return RandomForestClassifier(n_estimators=n_estimators, n_jobs=-1, random_state=seed)

    while True:
        cm = np.zeros((k, k), np.int64)
        for f in np.unique(folds):
            tr, te = fold_parts(folds, y, int(f), exclude)
            s = tr[balanced_sample(y[tr], max_per_class, seed)]
            clf = forest().fit(X[np.ix_(s, current)], y[s], sample_weight=compute_sample_weight("balanced", y[s]))
            cm += confusion_matrix(y[te], clf.predict(X[np.ix_(te, current)]), k)
        m = metrics(cm)
        s = balanced_sample(y, max_per_class, seed)
        clf = forest().fit(X[np.ix_(s, current)], y[s], sample_weight=compute_sample_weight("balanced", y[s]))
        order = np.argsort(clf.feature_importances_, kind="stable")
        n_drop = max(1, int(step * len(current))) if len(current) > min_features else 0
        n_drop = min(n_drop, len(current) - min_features)
        removed = [names[current[i]] for i in order[:n_drop]]
        steps.append({"n_features": len(current), "oa": m["oa"], "mean_f1": m["mean_f1"],
                      "features": [names[i] for i in current], "removed": removed})
        if log:
            log(f"  {len(current):3d} features: OA {m['oa']:.4f}, mean F1 {m['mean_f1']:.4f}"
                + (f"; dropping {', '.join(removed)}" if removed else ""))
        if n_drop == 0:
            break
        drop = set(current[i] for i in order[:n_drop])
        current = [c for c in current if c not in drop]
    best_f1 = max(s["mean_f1"] for s in steps)
    ok = [s for s in steps if s["mean_f1"] >= best_f1 - tolerance]
    best = min(ok, key=lambda s: s["n_features"])
    return {"steps": steps, "best": best, "tolerance": tolerance}
