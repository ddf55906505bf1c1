"""Supervised point classification (docs/classification.md; after Lang, docs/conventions.md#sources).

Public API
----------
:func:`train`                  fit a classifier on labelled clouds → :class:`ClassifierModel`
:func:`load_model`             load a model file (skops, trusted types only)
:class:`ClassifierModel`       ``predict`` / ``classify`` / ``save``
:class:`LidarFeatures`         scikit-learn transformer: clouds → feature matrix
:func:`make_pipeline`          ``Pipeline(LidarFeatures → impute → classifier)``
:class:`ClassMap`              class merging / ignoring (``"2,3+4+5,6"``)
:func:`evaluate`               CV (random and buffered spatial-block folds), leave-one-file-out, transfer
:func:`metrics`                OA, kappa, PA, UA, F1, IoU from a confusion matrix
:func:`drop_small_objects`     the object-size rule of prediction (small "building" clusters)

See ``docs/classification.md``.
"""
from __future__ import annotations

from .classes import ASPRS_NAMES, DEFAULT_IGNORE, ClassMap
from .evaluate import (
    block_bootstrap,
    block_buffer_mask,
    block_folds,
    block_ids,
    confusion_matrix,
    evaluate,
    evaluate_model,
    file_buffer_mask,
    format_report,
    metrics,
    plot_confusion,
    plot_elimination,
    plot_importance,
    random_folds,
    write_report,
)
from .importance import backward_elimination, impurity_importance, permutation_importance
from .objects import drop_small_objects
from .model import TRUSTED_TYPES, ClassifierModel, TrainConfig, load_model, read_sources, train
from .pipeline import (
    CLASSIFIERS,
    DEFAULT_FEATURES,
    DEFAULT_RADII,
    EXTRA_INPUTS,
    CloudSample,
    LidarFeatures,
    balanced_sample,
    make_classifier,
    make_pipeline,
    pulse_heights,
    pulse_ids,
    usable_mask,
)

__all__ = [
    "ASPRS_NAMES", "DEFAULT_IGNORE", "ClassMap",
    "block_bootstrap", "block_buffer_mask", "block_folds", "block_ids", "confusion_matrix", "evaluate", "evaluate_model", "file_buffer_mask",
    "format_report", "metrics",
    "plot_confusion", "plot_elimination", "plot_importance", "random_folds", "write_report",
    "backward_elimination", "impurity_importance", "permutation_importance",
    "drop_small_objects", "TRUSTED_TYPES", "ClassifierModel", "TrainConfig", "load_model", "read_sources", "train",
    "CLASSIFIERS", "DEFAULT_FEATURES", "DEFAULT_RADII", "EXTRA_INPUTS", "CloudSample", "LidarFeatures",
    "balanced_sample", "make_classifier", "make_pipeline", "pulse_heights", "pulse_ids", "usable_mask",
]
