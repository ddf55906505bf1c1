"""Rock-face discontinuities (LIS slides; docs/discontinuities.md): orientations, joint sets, spacing, overhangs.

>>> import lidarfx
>>> cloud = lidarfx.read("face.laz")                                   # doctest: +SKIP
>>> res = lidarfx.analyse_discontinuities(cloud, scanner=(10, -25, 1.5))  # doctest: +SKIP
>>> [(s["dip"], s["dip_direction"], s["kappa"]) for s in res.sets]     # doctest: +SKIP

``lidarfx.discontinuities.stats`` holds the statistics of axial orientations
(Fisher mean, κ, α95, joint-set search); ``lidarfx.discontinuities.output`` the
tables and pictures.
"""
from __future__ import annotations

from .analyse import DEFAULTS, Discontinuities, analyse_discontinuities, parse_reference_plane

__all__ = ["DEFAULTS", "Discontinuities", "analyse_discontinuities", "parse_reference_plane"]
