"""Deterministic synthetic point clouds with ground truth (docs/synth.md).

Every generator takes keyword arguments only (the ideal structures also accept
``radius`` positionally), is deterministic for a given ``seed``
(``numpy.random.default_rng(seed)``), returns a :class:`~lidarfx.PointCloud`
with ground-truth attributes and stores the exact parameters and the truth in
``cloud.meta["truth"]`` (plain JSON types).  Truth coordinates are local: the
points are ``local + origin`` and ``truth["origin"]`` holds that shift.

==============  =============================================================
name            scene
==============  =============================================================
plane           ideal plane through the query point (origin)
plane_border    half plane, query point on its border
edge            two half planes meeting at a dihedral angle
corner          three mutually perpendicular quarter planes
line            straight line
line_end        half line ending at the query point
volume          volumetric scatter
facade          TLS house facade: ground, wall, roof, window, vegetation, clutter, noise
rockface        TLS rock face: facets of 3 joint sets, overhang, noise
powerline       ALS corridor: terrain, pylons, 3 spans × 3 catenary wires (bundles, earth wire, cranes optional), trees
tower           TLS lattice steel tower: legs, braces, arms, bolts
terrain         ALS ground with a dike and a ditch and their breaklines
house           ALS gable-roof house on ground with its ridge, eave and verge lines
street          MLS street: road, facades both sides, poles, overhead wires, trees, cars
==============  =============================================================
"""
from __future__ import annotations

from typing import Callable

from ..cloud import PointCloud
from .facade import FACADE_CLASSES, facade
from .house import HOUSE_CLASSES, house
from .powerline import POWERLINE_CLASSES, catenary_through, catenary_z, powerline
from .rockface import DEFAULT_JOINT_SETS, rockface
from .street import STREET_CLASSES, street
from .structures import (
    STRUCTURE_IDS,
    analytic_centroid_offset,
    analytic_eigenvalues,
    corner,
    density_for_count,
    edge,
    line,
    line_end,
    plane,
    plane_border,
    volume,
)
from .terrain import LANDFORMS, terrain
from .tower import PARTS, lattice_members, tower

GENERATORS: dict[str, Callable[..., PointCloud]] = {
    "plane": plane,
    "plane_border": plane_border,
    "edge": edge,
    "corner": corner,
    "line": line,
    "line_end": line_end,
    "volume": volume,
    "facade": facade,
    "rockface": rockface,
    "powerline": powerline,
    "tower": tower,
    "terrain": terrain,
    "house": house,
    "street": street,
}
"""Generator name -> function (used by ``lidarfx synth``)."""

STRUCTURES = ("plane", "plane_border", "edge", "corner", "line", "line_end", "volume")
"""The ideal structures (reference shapes of the unsupervised classification)."""


def generate(kind: str, **params) -> PointCloud:
    """Run the generator ``kind`` with ``params``; unknown kinds or parameters raise LidarfxError."""
    import inspect

    from ..errors import LidarfxError

    try:
        func = GENERATORS[kind]
    except KeyError:
        raise LidarfxError(f"unknown synthetic scene {kind!r}; known: {', '.join(GENERATORS)}") from None
    accepted = inspect.signature(func).parameters
    unknown = sorted(set(params) - set(accepted))
    if unknown:
        raise LidarfxError(
            f"{kind} does not take {', '.join(unknown)}; parameters: {', '.join(accepted)}"
        )
    try:
        return func(**params)
    except (TypeError, ValueError) as exc:  # e.g. a string where a number belongs
        raise LidarfxError(f"{kind}: bad parameter value: {' '.join(str(exc).split())}") from None


__all__ = [
    "GENERATORS",
    "STRUCTURES",
    "generate",
    "plane",
    "plane_border",
    "edge",
    "corner",
    "line",
    "line_end",
    "volume",
    "facade",
    "rockface",
    "powerline",
    "tower",
    "terrain",
    "house",
    "street",
    "analytic_eigenvalues",
    "analytic_centroid_offset",
    "density_for_count",
    "catenary_z",
    "catenary_through",
    "lattice_members",
    "STRUCTURE_IDS",
    "FACADE_CLASSES",
    "HOUSE_CLASSES",
    "POWERLINE_CLASSES",
    "STREET_CLASSES",
    "DEFAULT_JOINT_SETS",
    "PARTS",
    "LANDFORMS",
]
