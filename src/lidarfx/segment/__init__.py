"""Segmentation (docs/segmentation.md): planes by surface growing against the segment plane.

>>> import lidarfx
>>> from lidarfx.segment import segment_planes, segments_table
>>> cloud = lidarfx.read("scan.laz")                       # doctest: +SKIP
>>> seg = segment_planes(cloud)                            # LIS defaults (dense TLS)  # doctest: +SKIP
>>> seg["segment_id"], segments_table(seg)[0]["dip"]       # doctest: +SKIP

The numba kernels load on first use of a function (``lidarfx --help`` stays fast).
"""
from __future__ import annotations

from typing import Any

DEFAULTS: dict[str, Any] = {
    "normal_radius": 0.10,  # Suchradius (local plane: normal, plane_std)
    "max_distance": 0.10,  # maximaler Abstand zum Flächensegment
    "growing_radius": 0.15,  # Suchradius zur Flächenverdichtung (region growing)
    "max_angle": 15.0,  # maximale Abweichung vom Normalvektor [deg]
    "min_size": 30,  # smaller segments are released
    "min_width": 0.0,  # narrower segments are released (0 = off)
}
"""The LIS defaults (dense TLS), the minimum segment size and width."""

TABLE_COLUMNS = [
    "id",
    "size",
    "centroid_x",
    "centroid_y",
    "centroid_z",
    "normal_x",
    "normal_y",
    "normal_z",
    "dip",
    "dip_direction",
    "rms",
    "area",
]
"""Columns of the per-segment table (CSV header, JSON keys)."""

_LAZY = ("segment_planes", "segments_table", "write_segments_csv", "write_segments_json")

__all__ = [
    "DEFAULTS",
    "TABLE_COLUMNS",
    "segment_planes",
    "segments_table",
    "write_segments_csv",
    "write_segments_json",
]


def __getattr__(name: str):
    if name in _LAZY:
        from . import planes

        return getattr(planes, name)
    raise AttributeError(f"module 'lidarfx.segment' has no attribute {name!r}")
