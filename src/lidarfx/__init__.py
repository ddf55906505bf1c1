"""lidarfx: per-point 3D features, segments, classes and vector products from LiDAR point clouds."""
from __future__ import annotations

__version__ = "0.1.0"

from .cloud import PointCloud
from .errors import LidarfxError
from .io import read, write

__all__ = ["PointCloud", "LidarfxError", "read", "write", "compute_features", "__version__"]


def __getattr__(name: str):
    # Heavy modules (numba kernels) load on first use so `lidarfx --help` stays fast.
    if name == "compute_features":
        from .features import compute_features

        return compute_features
    if name == "synth":
        import importlib

        return importlib.import_module(".synth", __name__)
    raise AttributeError(f"module 'lidarfx' has no attribute {name!r}")
