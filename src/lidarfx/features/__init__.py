"""Per-point neighbourhood features (docs/features.md).

>>> import lidarfx
>>> cloud = lidarfx.read("scan.laz")                                  # doctest: +SKIP
>>> out = lidarfx.compute_features(cloud, ["eigen", "slope"], radius=0.5)  # doctest: +SKIP
>>> out["planarity"]                                                  # doctest: +SKIP
"""
from __future__ import annotations

from .api import compute_features, feature_arrays, stream_features
from .registry import DEFAULT_FEATURES, available, resolve

__all__ = ["compute_features", "feature_arrays", "stream_features", "available", "resolve", "DEFAULT_FEATURES"]
