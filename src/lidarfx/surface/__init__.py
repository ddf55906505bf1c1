"""Surfaces from points, shared by the ground filter and the products.

* :mod:`lidarfx.surface.grid` — regular grids: :class:`~lidarfx.surface.grid.GridSpec`, cell
  indices, per-cell minima, morphological opening, inpainting, bilinear lookup, slope.
* :mod:`lidarfx.surface.tin` — Delaunay TIN interpolation with a tiled point-location walk.
* :mod:`lidarfx.surface.raster` — :class:`~lidarfx.surface.raster.Raster`, a georeferenced grid
  with its writers (ESRI ASCII grid with ``.prj``, GeoTIFF).
* :mod:`lidarfx.surface.models` — :func:`dsm` (highest return per cell) and :func:`chm` (canopy
  height, pit-free), docs/surfaces.md.

Kernels take and return numpy arrays; nothing here reads point-cloud files.
"""
from __future__ import annotations

from typing import Any

from .raster import Raster

__all__ = ["Raster", "dsm", "chm"]


def __getattr__(name: str) -> Any:  # dsm, chm on first use: importing the raster writers stays light
    if name in ("dsm", "chm"):
        from . import models

        return getattr(models, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
