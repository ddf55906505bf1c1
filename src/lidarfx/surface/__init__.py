"""Surfaces from points, shared by the ground filter and the products.

* :mod:`lidarfx.surface.grid` — regular grids: :class:`~lidarfx.surface.grid.GridSpec`, cell
  indices, per-cell minima, morphological opening, inpainting, bilinear lookup, slope.
* :mod:`lidarfx.surface.tin` — Delaunay TIN interpolation with a tiled point-location walk.
* :mod:`lidarfx.surface.raster` — :class:`~lidarfx.surface.raster.Raster`, a georeferenced grid
  with its writers (ESRI ASCII grid with ``.prj``, GeoTIFF).

Kernels take and return numpy arrays; nothing here reads point-cloud files.
"""
from __future__ import annotations

from .raster import Raster

__all__ = ["Raster"]
