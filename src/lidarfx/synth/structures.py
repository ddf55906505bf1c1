"""Ideal local structures around a query point at the origin (the reference shapes of ISPRS 2016).

Each generator samples one structure — plane, plane border, edge, corner, line,
line end, volume — over the cube ``[-extent, extent]³`` (default
``extent = 2 × radius``), so that a sphere of ``radius`` around the origin is
completely covered.  The query point itself is point 0, exactly at the origin
(noise-free) unless ``query_point=False``.

``meta["truth"]["analytic_eigenvalues"]`` holds the closed-form eigenvalues
λ1 ≥ λ2 ≥ λ3 of the covariance ``C = (1/n) Σ (p − c)(p − c)ᵀ`` of a uniform,
noise-free sample inside the sphere of radius R around the origin, divided by
R² (e.g. line (1/3, 0, 0), plane (1/4, 1/4, 0), volume (1/5, 1/5, 1/5)).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._common import (
    EX,
    EY,
    EZ,
    add_noise,
    capture_params,
    check_nonneg,
    check_origin,
    check_positive,
    check_sampling,
    finish,
    make_rng,
    resolve_rotation,
    sample_box,
    sample_patch,
    sample_segment,
)
from ..errors import LidarfxError

__all__ = [
    "STRUCTURE_IDS",
    "plane",
    "plane_border",
    "edge",
    "corner",
    "line",
    "line_end",
    "volume",
    "analytic_eigenvalues",
    "analytic_centroid_offset",
    "density_for_count",
    "STRUCTURE_MEASURE",
]

STRUCTURE_IDS: dict[str, int] = {
    "isolated": 0,
    "plane": 1,
    "plane_border": 2,
    "edge": 3,
    "corner": 4,
    "line": 5,
    "line_end": 6,
    "volume": 7,
}
"""Values of the ``structure`` attribute (0 = isolated / none, never generated here)."""

DEFAULT_DENSITY = {"surface": 1000.0, "line": 500.0, "volume": 2000.0}
"""Default ``density``: points per m² (surfaces), per m (lines), per m³ (volumes)."""

_KIND_DIM = {
    "plane": "surface",
    "plane_border": "surface",
    "edge": "surface",
    "corner": "surface",
    "line": "line",
    "line_end": "line",
    "volume": "volume",
}


def _edge_faces(angle: float) -> tuple[np.ndarray, np.ndarray]:
    """In-face directions (perpendicular to the edge line = x axis) of a dihedral ``angle``.

    The two half-planes leave the edge symmetric about −z (a roof ridge for
    angles < 180°): ``d = (0, ±sin(angle/2), −cos(angle/2))``.
    """
    h = math.radians(angle) / 2.0
    return np.array([0.0, math.sin(h), -math.cos(h)]), np.array([0.0, -math.sin(h), -math.cos(h)])


def _pieces(kind: str, extent: float, angle: float) -> list[tuple[str, tuple]]:
    """The primitives of a structure in its canonical frame (before rotation)."""
    e = extent
    if kind == "plane":
        return [("patch", (EX, EY, (-e, e), (-e, e)))]
    if kind == "plane_border":
        return [("patch", (EX, EY, (-e, e), (0.0, e)))]
    if kind == "edge":
        d0, d1 = _edge_faces(angle)
        return [("patch", (EX, d0, (-e, e), (0.0, e))), ("patch", (EX, d1, (-e, e), (0.0, e)))]
    if kind == "corner":
        return [
            ("patch", (EX, EY, (0.0, e), (0.0, e))),
            ("patch", (EY, EZ, (0.0, e), (0.0, e))),
            ("patch", (EZ, EX, (0.0, e), (0.0, e))),
        ]
    if kind == "line":
        return [("segment", (-e * EX, e * EX))]
    if kind == "line_end":
        return [("segment", (np.zeros(3), e * EX))]
    if kind == "volume":
        return [("box", (-e * np.ones(3), e * np.ones(3)))]
    raise LidarfxError(f"unknown structure {kind!r}")


def _moments(kind: str, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form mean and second moment (R = 1) of a uniform sample in the unit sphere."""
    sector_mean = 4.0 / (3.0 * math.pi)  # E[v] on a half disk v >= 0, also E[u] on a quarter disk
    if kind == "plane":
        return np.zeros(3), 0.25 * (np.outer(EX, EX) + np.outer(EY, EY))
    if kind == "plane_border":
        return sector_mean * EY, 0.25 * (np.outer(EX, EX) + np.outer(EY, EY))
    if kind == "edge":
        d0, d1 = _edge_faces(angle)
        m2 = 0.5 * sum(0.25 * (np.outer(EX, EX) + np.outer(d, d)) for d in (d0, d1))
        return 0.5 * sector_mean * (d0 + d1), m2
    if kind == "corner":
        m2 = np.zeros((3, 3))
        mean = np.zeros(3)
        for a, b in ((EX, EY), (EY, EZ), (EZ, EX)):
            # quarter disk: E[u²] = 1/4, E[uv] = 1/(2π), E[u] = 4/(3π)
            m2 += (0.25 * (np.outer(a, a) + np.outer(b, b)) + (np.outer(a, b) + np.outer(b, a)) / (2 * math.pi)) / 3
            mean += sector_mean * (a + b) / 3
        return mean, m2
    if kind == "line":
        return np.zeros(3), np.outer(EX, EX) / 3.0
    if kind == "line_end":
        return 0.5 * EX, np.outer(EX, EX) / 3.0
    if kind == "volume":
        return np.zeros(3), np.eye(3) / 5.0
    raise LidarfxError(f"unknown structure {kind!r}")


def analytic_eigenvalues(kind: str, angle: float = 90.0) -> list[float]:
    """λ1 ≥ λ2 ≥ λ3 / R² of a uniform noise-free sample of ``kind`` inside a sphere of radius R.

    E.g. ``plane_border`` → (1/4, 1/4 − 16/(9π²), 0); ``edge`` at 90° →
    (1/4, 1/8, 1/8 − 8/(9π²)); ``corner`` → ((π−1)/(6π), (π−1)/(6π),
    1/6 + 1/(3π) − 64/(27π²)); ``line_end`` → (1/12, 0, 0).
    """
    mean, m2 = _moments(kind, angle)
    ev = np.linalg.eigvalsh(m2 - np.outer(mean, mean))[::-1]
    return [float(max(v, 0.0)) if abs(v) > 1e-15 else 0.0 for v in ev]


def analytic_centroid_offset(kind: str, angle: float = 90.0) -> float:
    """|c − p| / R: distance of the centroid of a uniform noise-free sample of ``kind`` inside
    the sphere of radius R from the query point, divided by R (e.g. ``plane_border`` →
    4/(3π), ``line_end`` → 1/2, ``plane`` → 0)."""
    mean, _ = _moments(kind, angle)
    return float(np.linalg.norm(mean))


STRUCTURE_MEASURE = {
    "plane": math.pi,
    "plane_border": math.pi / 2,
    "edge": math.pi,
    "corner": 3 * math.pi / 4,
    "line": 2.0,
    "line_end": 1.0,
    "volume": 4 * math.pi / 3,
}
"""Measure of each structure inside the unit sphere (area in R², length in R, volume in R³):
``density × measure × R^dim`` is the expected number of points in the sphere of radius R."""


def density_for_count(kind: str, count: float, radius: float = 1.0) -> float:
    """The ``density`` that puts ``count`` points (expected) into the sphere of ``radius``
    around the query point of the structure ``kind``."""
    dim = {"surface": 2, "line": 1, "volume": 3}[_KIND_DIM[kind]]
    return float(count) / (STRUCTURE_MEASURE[kind] * radius**dim)


def _structure(kind: str, params: dict[str, Any], *, radius: float, density: float | None,
               noise: float, sampling: str, rotation: Any, extent: float | None, angle: float,
               query_point: bool, seed: Any, origin: Any):
    radius = check_positive("radius", radius)
    dim = _KIND_DIM[kind]
    density = check_positive("density", DEFAULT_DENSITY[dim] if density is None else density)
    noise = check_nonneg("noise", noise)
    sampling = check_sampling(sampling)
    extent = 2.0 * radius if extent is None else check_positive("extent", extent)
    if kind == "edge" and not 0.0 < float(angle) <= 180.0:
        raise LidarfxError(f"edge angle must be in (0, 180] degrees, got {angle!r}")
    origin = check_origin(origin)
    rng = make_rng(seed)
    rot = resolve_rotation(rotation, rng)

    parts, faces = [], []
    for face, (what, args) in enumerate(_pieces(kind, extent, angle)):
        if what == "patch":
            e1, e2, ur, vr = args
            p = sample_patch(rng, np.zeros(3), e1, e2, ur, vr, density, sampling)
        elif what == "segment":
            p = sample_segment(rng, args[0], args[1], density, sampling)
        else:
            p = sample_box(rng, args[0], args[1], density, sampling)
        parts.append(p)
        faces.append(np.full(len(p), face, dtype=np.int32))
    xyz = np.vstack(parts)
    face = np.concatenate(faces)
    # the query point is added explicitly; drop a lattice point sitting on it
    if query_point:
        keep = np.linalg.norm(xyz, axis=1) > 1e-9
        xyz, face = xyz[keep], face[keep]
    xyz = add_noise(rng, xyz, noise)
    if query_point:
        xyz = np.vstack([np.zeros((1, 3)), xyz])
        face = np.concatenate([[-1], face]).astype(np.int32)
    if rot is not None:
        xyz = xyz @ rot.T

    mean, m2 = _moments(kind, angle)
    truth = {
        "structure": kind,
        "structure_ids": STRUCTURE_IDS,
        "radius": radius,
        "extent": extent,
        "density": density,
        "density_unit": {"surface": "points/m2", "line": "points/m", "volume": "points/m3"}[dim],
        "noise": noise,
        "sampling": sampling,
        "angle": float(angle) if kind == "edge" else None,
        "rotation": rot if rot is not None else np.eye(3),
        "query_index": 0 if query_point else None,
        "query_point": [0.0, 0.0, 0.0],
        "analytic_eigenvalues": analytic_eigenvalues(kind, angle),
        "analytic_centroid": (rot @ mean if rot is not None else mean),
        "faces": _face_truth(kind, extent, angle, rot),
    }
    attrs = {
        "structure": np.full(len(xyz), STRUCTURE_IDS[kind], dtype=np.int32),
        "face": face,
    }
    return finish(kind, xyz, attrs, truth, params, origin)


def _face_truth(kind: str, extent: float, angle: float, rot: np.ndarray | None) -> list[dict[str, Any]]:
    """Per face: normal (surfaces) or direction (lines), rotated like the points."""
    r = np.eye(3) if rot is None else rot
    out = []
    for face, (what, args) in enumerate(_pieces(kind, extent, angle)):
        if what == "patch":
            e1, e2 = args[0], args[1]
            out.append({"face": face, "normal": r @ np.cross(e1, e2), "in_plane": [r @ e1, r @ e2],
                        "u_range": args[2], "v_range": args[3]})
        elif what == "segment":
            out.append({"face": face, "start": r @ args[0], "end": r @ args[1]})
        else:
            out.append({"face": face, "box_min": args[0], "box_max": args[1], "axes": r})
    return out


_COMMON_DOC = """
    Parameters
    ----------
    radius:
        Neighbourhood radius R the structure is made for (m); the sampled region
        is ``[-extent, extent]`` per axis with ``extent = 2 R`` by default.
    density:
        Points per m² (surfaces), per m (lines) or per m³ (volumes).
    noise:
        Gaussian σ (m) added to every coordinate (not to the query point).
    sampling:
        ``"random"`` (uniform) or ``"grid"`` (cell-centred lattice; moments are
        near-exact).
    rotation:
        ``None`` (canonical frame), ``"random"`` (seeded uniform rotation) or a
        3×3 rotation matrix, applied about the origin.
    query_point:
        Put a noise-free point 0 exactly at the origin (default True).
    seed, origin:
        Random seed; shift added to all coordinates (truth stays local).

    Returns
    -------
    PointCloud
        Attributes ``structure`` (see :data:`STRUCTURE_IDS`) and ``face``
        (index of the face / piece, −1 for the query point).
"""


def plane(radius: float = 1.0, *, density: float | None = None, noise: float = 0.0,
          sampling: str = "random", rotation: Any = None, extent: float | None = None,
          query_point: bool = True, seed: int = 0, origin: Any = None):
    """Plane z = 0 through the query point."""
    params = capture_params(locals())
    return _structure("plane", params, radius=radius, density=density, noise=noise, sampling=sampling,
                      rotation=rotation, extent=extent, angle=180.0, query_point=query_point,
                      seed=seed, origin=origin)


def plane_border(radius: float = 1.0, *, density: float | None = None, noise: float = 0.0,
                 sampling: str = "random", rotation: Any = None, extent: float | None = None,
                 query_point: bool = True, seed: int = 0, origin: Any = None):
    """Half plane z = 0, y ≥ 0: the query point on its straight border (the x axis)."""
    params = capture_params(locals())
    return _structure("plane_border", params, radius=radius, density=density, noise=noise,
                      sampling=sampling, rotation=rotation, extent=extent, angle=180.0,
                      query_point=query_point, seed=seed, origin=origin)


def edge(radius: float = 1.0, *, angle: float = 90.0, density: float | None = None, noise: float = 0.0,
         sampling: str = "random", rotation: Any = None, extent: float | None = None,
         query_point: bool = True, seed: int = 0, origin: Any = None):
    """Two half planes meeting at the x axis with dihedral ``angle`` (degrees, default 90).

    Face 0 leaves the edge along ``(0, sin(angle/2), −cos(angle/2))``, face 1
    along ``(0, −sin(angle/2), −cos(angle/2))`` (a roof ridge for angle < 180;
    180 is a plane).
    """
    params = capture_params(locals())
    return _structure("edge", params, radius=radius, density=density, noise=noise, sampling=sampling,
                      rotation=rotation, extent=extent, angle=angle, query_point=query_point,
                      seed=seed, origin=origin)


def corner(radius: float = 1.0, *, density: float | None = None, noise: float = 0.0,
           sampling: str = "random", rotation: Any = None, extent: float | None = None,
           query_point: bool = True, seed: int = 0, origin: Any = None):
    """Three mutually perpendicular quarter planes (faces xy, yz, zx of the positive octant)."""
    params = capture_params(locals())
    return _structure("corner", params, radius=radius, density=density, noise=noise, sampling=sampling,
                      rotation=rotation, extent=extent, angle=90.0, query_point=query_point,
                      seed=seed, origin=origin)


def line(radius: float = 1.0, *, density: float | None = None, noise: float = 0.0,
         sampling: str = "random", rotation: Any = None, extent: float | None = None,
         query_point: bool = True, seed: int = 0, origin: Any = None):
    """Straight line along the x axis through the query point."""
    params = capture_params(locals())
    return _structure("line", params, radius=radius, density=density, noise=noise, sampling=sampling,
                      rotation=rotation, extent=extent, angle=180.0, query_point=query_point,
                      seed=seed, origin=origin)


def line_end(radius: float = 1.0, *, density: float | None = None, noise: float = 0.0,
             sampling: str = "random", rotation: Any = None, extent: float | None = None,
             query_point: bool = True, seed: int = 0, origin: Any = None):
    """Half line x ≥ 0 ending at the query point."""
    params = capture_params(locals())
    return _structure("line_end", params, radius=radius, density=density, noise=noise,
                      sampling=sampling, rotation=rotation, extent=extent, angle=180.0,
                      query_point=query_point, seed=seed, origin=origin)


def volume(radius: float = 1.0, *, density: float | None = None, noise: float = 0.0,
           sampling: str = "random", rotation: Any = None, extent: float | None = None,
           query_point: bool = True, seed: int = 0, origin: Any = None):
    """Points filling the cube around the query point (a volumetric scatter)."""
    params = capture_params(locals())
    return _structure("volume", params, radius=radius, density=density, noise=noise, sampling=sampling,
                      rotation=rotation, extent=extent, angle=180.0, query_point=query_point,
                      seed=seed, origin=origin)


for _f in (plane, plane_border, edge, corner, line, line_end, volume):
    _f.__doc__ = (_f.__doc__ or "") + "\n" + _COMMON_DOC
del _f
