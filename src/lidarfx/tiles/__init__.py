"""Chunked runs of the per-point commands: inputs of any size (one big file, several files, a
folder of tiles) cut into square chunks with a buffer, computed on Dask (embedded or a
``dask.distributed`` cluster), merged into one file or one file per input tile; a killed run
resumes.  docs/scaling.md.

>>> from lidarfx.tiles import run_tiled
>>> run_tiled("tiles/", "features/", "features", {"features": "eigen", "radii": [0.5]})  # doctest: +SKIP
"""
from .catalog import Catalog, open_catalog
from .engine import TileRun, run_tiled
from .plan import Grid
from .processors import PROCESSORS

__all__ = ["Catalog", "Grid", "PROCESSORS", "TileRun", "open_catalog", "run_tiled"]
