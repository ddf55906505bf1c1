"""lidarfx: per-point 3D features, segments, classes and vector products from LiDAR point clouds."""
from __future__ import annotations

__version__ = "0.1.0"

from . import _numba_cache, _prebuilt

# before any module defines a kernel: numba misses edits in other files (check), and the shipped
# kernels fix the processor numba compiles for (install)
_numba_cache.check()
_prebuilt.install()

from ._atomic import overwriting  # noqa: E402
from .cloud import PointCloud  # noqa: E402
from .errors import LidarfxError  # noqa: E402
from .io import read, write  # noqa: E402

__all__ = [
    "PointCloud",
    "LidarfxError",
    "read",
    "write",
    "compute_features",
    "segment_planes",
    "classify_ground",
    "classify_structures",
    "extract_edges",
    "extract_powerlines",
    "analyse_discontinuities",
    "colour_cloud",
    "extract_breaklines",
    "detect_small_parts",
    "vectorise_members",
    "Pipeline",
    "overwriting",
    "__version__",
]


def __getattr__(name: str):
    # Heavy modules (numba kernels) load on first use so `lidarfx --help` stays fast.
    if name == "compute_features":
        from .features import compute_features

        return compute_features
    if name == "segment_planes":
        from .segment import segment_planes

        return segment_planes
    if name == "classify_ground":
        from .ground import classify_ground

        return classify_ground
    if name == "classify_structures":
        from .structures import classify_structures

        return classify_structures
    if name == "extract_edges":
        from .edges import extract_edges

        return extract_edges
    if name == "extract_powerlines":
        from .powerlines import extract_powerlines

        return extract_powerlines
    if name == "analyse_discontinuities":
        from .discontinuities import analyse_discontinuities

        return analyse_discontinuities
    if name == "extract_breaklines":
        from .breaklines import extract_breaklines

        return extract_breaklines
    if name == "colour_cloud":
        from .colour import colour_cloud

        return colour_cloud
    if name == "Pipeline":
        from .pipeline import Pipeline

        return Pipeline
    if name in ("detect_small_parts", "vectorise_members"):
        from . import tower

        return getattr(tower, name)
    if name in ("synth", "select", "segment", "ground", "structures", "edges", "vector", "powerlines",
                "discontinuities", "colour", "breaklines", "tower", "thin", "section"):
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'lidarfx' has no attribute {name!r}")
