"""Shared helpers of the synthetic-scene generators: sampling, orientation, assembly.

Every generator samples its primitives with the functions below, so "a plane
patch", "a rotation from dip / dip direction" or "points along a segment" is
written exactly once.  All randomness comes from the ``numpy.random.Generator``
passed in; nothing here touches global random state.

Sampling modes (``sampling``):

``"random"``
    uniform random positions; the count is ``round(measure * density)``.
``"grid"``
    a regular lattice at cell centres, spacing ``density ** (-1/dim)`` adjusted
    so that a whole number of cells fits the interval exactly (midpoint rule:
    moments of the lattice equal the continuous moments up to O(h²)).
"""
from __future__ import annotations

import math
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .._json import jsonable
from ..cloud import PointCloud
from ..errors import LidarfxError
from ..geometry import EX, EY, EZ, dip_from_normal, normal_from_dip, perpendicular_frame, plane_basis, unit  # noqa: F401

SAMPLINGS = ("random", "grid")
MAX_POINTS = 50_000_000
"""Refuse to sample more points than this in one primitive (a typo in ``density``)."""



# ------------------------------------------------------------------ checks
def make_rng(seed: Any) -> np.random.Generator:
    """``np.random.default_rng(seed)``; ``seed`` must be an int (or None)."""
    if seed is not None and not isinstance(seed, (int, np.integer)):
        raise LidarfxError(f"seed must be an integer, got {seed!r}")
    if seed is not None and seed < 0:
        raise LidarfxError(f"seed must be >= 0, got {seed}")
    return np.random.default_rng(seed)


MAX_LENGTH = 10_000.0
"""Largest length (m) of a synthetic scene's parts: widths, heights, spans, radii."""

MAX_COUNT = 10_000
"""Largest count of a synthetic scene's parts: floors, spans, trees, panels, bolts."""


def check_finite(name: str, value: Any) -> float:
    """Any finite number."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise LidarfxError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise LidarfxError(f"{name} must be a finite number, got {value!r}")
    return v


def check_positive(name: str, value: Any, hi: float = math.inf) -> float:
    """A finite number > 0 (and <= ``hi``)."""
    v = check_finite(name, value)
    if v <= 0:
        raise LidarfxError(f"{name} must be > 0, got {value!r}")
    if v > hi:
        raise LidarfxError(f"{name} must be at most {hi:g}, got {value!r}")
    return v


def check_length(name: str, value: Any) -> float:
    """A length in metres: > 0 and at most :data:`MAX_LENGTH`."""
    return check_positive(name, value, MAX_LENGTH)


def check_count(name: str, value: Any, lo: int = 0, hi: int = MAX_COUNT) -> int:
    """A whole number in ``lo .. hi``."""
    try:
        v = int(value)
        ok = v == float(value)
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise LidarfxError(f"{name} must be a whole number, got {value!r}")
    if not lo <= v <= hi:
        raise LidarfxError(f"{name} must be in {lo} .. {hi}, got {value!r}")
    return v


def check_flag(name: str, value: Any) -> bool:
    """True / False (or 1 / 0)."""
    if isinstance(value, (bool, np.bool_)) or (isinstance(value, (int, float)) and value in (0, 1)):
        return bool(value)
    raise LidarfxError(f"{name} must be true or false, got {value!r}")


def check_fraction(name: str, value: Any) -> float:
    """A share in [0, 1]."""
    v = check_nonneg(name, value)
    if v > 1:
        raise LidarfxError(f"{name} is a share in [0, 1], got {value!r}")
    return v


def check_nonneg(name: str, value: Any) -> float:
    """A finite number >= 0."""
    v = check_finite(name, value)
    if v < 0:
        raise LidarfxError(f"{name} must be >= 0, got {value!r}")
    return v


def check_sampling(sampling: str) -> str:
    if sampling not in SAMPLINGS:
        raise LidarfxError(f"sampling must be one of {', '.join(SAMPLINGS)}; got {sampling!r}")
    return sampling


MAX_COORDINATE = 1e9
"""Largest absolute coordinate of an ``origin`` or a scanner position (m): float64 steps
are 1.2e-7 m up to 1e9, so the points keep sub-mm resolution (at 1e23 every point of a
scene had the same x)."""


def check_point(name: str, value: Any) -> np.ndarray:
    """Three finite numbers of at most :data:`MAX_COORDINATE` as a float64 array (an
    ``origin``, a scanner position, ...)."""
    try:
        o = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise LidarfxError(f"{name} must be three numbers, got {value!r}") from None
    if o.shape != (3,) or not np.all(np.isfinite(o)):
        raise LidarfxError(f"{name} must be three finite numbers, got {value!r}")
    if np.any(np.abs(o) > MAX_COORDINATE):
        raise LidarfxError(
            f"{name} coordinates must be at most {MAX_COORDINATE:g} in absolute value (float64 would lose "
            f"the mm resolution), got {', '.join(f'{v:g}' for v in o)}"
        )
    return o


def check_origin(origin: Any) -> np.ndarray:
    """``None`` -> zeros; otherwise three finite numbers."""
    return np.zeros(3) if origin is None else check_point("origin", origin)


def _count(measure: float, density: float) -> int:
    m = measure * density
    if not m <= MAX_POINTS:  # also inf (a density or radius of 1e308) and NaN
        raise LidarfxError(
            f"density {density:g} on a primitive of size {measure:g} would give {m:.3g} points (at most "
            f"{MAX_POINTS:,}); lower the density or the size"
        )
    return int(round(m))


# -------------------------------------------------------------- orientation
def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly distributed (Haar) rotation matrix in SO(3)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def resolve_rotation(rotation: Any, rng: np.random.Generator) -> np.ndarray | None:
    """``None``/``False`` -> no rotation; ``"random"``/``True`` -> seeded Haar; else a 3×3 rotation."""
    if rotation is None or rotation is False:
        return None
    if rotation is True or (isinstance(rotation, str) and rotation == "random"):
        return random_rotation(rng)
    try:
        m = np.asarray(rotation, dtype=np.float64)
    except (TypeError, ValueError):
        raise LidarfxError(f"rotation must be None, 'random' or a 3x3 matrix, got {rotation!r}") from None
    if m.size == 9:
        m = m.reshape(3, 3)
    # entries of a rotation are in [-1, 1]: checked first, so NaN / inf / 1e308 never reach the product
    if m.shape != (3, 3) or not np.all(np.abs(m) <= 1.0 + 1e-6) \
            or not np.allclose(m @ m.T, np.eye(3), atol=1e-6) or np.linalg.det(m) < 0:
        raise LidarfxError("rotation must be a proper 3x3 rotation matrix (orthonormal, det +1)")
    return m


def rotate_z(xyz: np.ndarray, angle_deg: float) -> np.ndarray:
    """Rotate points counter-clockwise (seen from above) about the z axis."""
    a = math.radians(angle_deg)
    c, s = math.cos(a), math.sin(a)
    m = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.asarray(xyz, dtype=np.float64) @ m.T


# ----------------------------------------------------------------- sampling
def grid_1d(lo: float, hi: float, step: float) -> np.ndarray:
    """Cell centres of ``round((hi-lo)/step)`` equal cells covering [lo, hi]."""
    f = (hi - lo) / step
    if not f <= MAX_POINTS:  # also inf and NaN
        raise LidarfxError(f"grid of {f:.3g} cells per axis (at most {MAX_POINTS:,}); lower the density or the size")
    m = max(1, int(round(f)))
    return lo + (np.arange(m) + 0.5) * ((hi - lo) / m)


def sample_interval(rng, lo: float, hi: float, density: float, sampling: str = "random") -> np.ndarray:
    """Positions on [lo, hi] with ``density`` per unit length."""
    if hi <= lo:
        return np.empty(0)
    if sampling == "grid":
        return grid_1d(lo, hi, 1.0 / density)
    return rng.uniform(lo, hi, _count(hi - lo, density))


def sample_rect(rng, u_range: Sequence[float], v_range: Sequence[float], density: float,
                sampling: str = "random") -> np.ndarray:
    """``(m, 2)`` positions in the rectangle ``u_range × v_range`` with ``density`` per unit area."""
    (u0, u1), (v0, v1) = u_range, v_range
    if u1 <= u0 or v1 <= v0:
        return np.empty((0, 2))
    if sampling == "grid":
        h = density ** -0.5
        u, v = np.meshgrid(grid_1d(u0, u1, h), grid_1d(v0, v1, h), indexing="ij")
        return np.column_stack([u.ravel(), v.ravel()])
    n = _count((u1 - u0) * (v1 - v0), density)
    return np.column_stack([rng.uniform(u0, u1, n), rng.uniform(v0, v1, n)])


def sample_box(rng, lo: Sequence[float], hi: Sequence[float], density: float,
               sampling: str = "random") -> np.ndarray:
    """``(m, 3)`` positions filling the axis-aligned box [lo, hi] with ``density`` per unit volume."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if np.any(hi <= lo):
        return np.empty((0, 3))
    if sampling == "grid":
        h = density ** (-1.0 / 3.0)
        axes = [grid_1d(lo[k], hi[k], h) for k in range(3)]
        g = np.meshgrid(*axes, indexing="ij")
        return np.column_stack([a.ravel() for a in g])
    n = _count(float(np.prod(hi - lo)), density)
    return lo + rng.uniform(size=(n, 3)) * (hi - lo)


def sample_patch(rng, origin: Any, e1: Any, e2: Any, u_range: Sequence[float],
                 v_range: Sequence[float], density: float, sampling: str = "random") -> np.ndarray:
    """Points ``origin + u·e1 + v·e2`` of a planar rectangle (``e1``, ``e2`` orthonormal)."""
    uv = sample_rect(rng, u_range, v_range, density, sampling)
    return np.asarray(origin, float) + uv[:, :1] * np.asarray(e1, float) + uv[:, 1:] * np.asarray(e2, float)


def sample_plane_over_rect(rng, normal: Any, point: Any, axis: int, bounds: Sequence[Sequence[float]],
                           density: float, sampling: str = "random") -> np.ndarray:
    """Points of the plane (``normal``, through ``point``) above an axis-aligned rectangle.

    The rectangle ``bounds = [(lo, hi), (lo, hi)]`` lies in the two coordinates
    other than ``axis`` (in increasing order); the ``axis`` coordinate is solved
    from the plane equation.  ``density`` is per unit area *of the plane*
    (the projected density is scaled by ``|n[axis]|``).
    """
    n = unit(normal)
    if abs(n[axis]) < 0.2:
        raise LidarfxError("plane too oblique to its projection axis (|n| component < 0.2)")
    others = [k for k in range(3) if k != axis]
    uv = sample_rect(rng, bounds[0], bounds[1], density / abs(n[axis]), sampling)
    p = np.asarray(point, float)
    out = np.empty((len(uv), 3))
    out[:, others[0]] = uv[:, 0]
    out[:, others[1]] = uv[:, 1]
    out[:, axis] = p[axis] - (n[others[0]] * (uv[:, 0] - p[others[0]]) + n[others[1]] * (uv[:, 1] - p[others[1]])) / n[axis]
    return out


def sample_segment(rng, a: Any, b: Any, density: float, sampling: str = "random") -> np.ndarray:
    """Points on the segment a→b with ``density`` per metre."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    t = sample_interval(rng, 0.0, float(np.linalg.norm(b - a)), density, sampling)
    if len(t) == 0:
        return np.empty((0, 3))
    return a + (t / np.linalg.norm(b - a))[:, None] * (b - a)


def sample_box_surface(rng, lo: Any, hi: Any, density: float, bottom: bool = False) -> np.ndarray:
    """Points on the faces of an axis-aligned box (the bottom face only if ``bottom``)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    parts = []
    for axis in range(3):
        others = [k for k in range(3) if k != axis]
        for side, level in ((0, lo[axis]), (1, hi[axis])):
            if axis == 2 and side == 0 and not bottom:
                continue
            uv = sample_rect(rng, (lo[others[0]], hi[others[0]]), (lo[others[1]], hi[others[1]]), density)
            p = np.empty((len(uv), 3))
            p[:, others[0]], p[:, others[1]], p[:, axis] = uv[:, 0], uv[:, 1], level
            parts.append(p)
    return np.vstack(parts)


def sample_cylinder_surface(rng, base: Any, axis: Any, radius: float, length: float,
                            density: float, caps: bool = False) -> np.ndarray:
    """Points on the lateral surface (and optionally the top cap) of a cylinder."""
    base, d = np.asarray(base, float), unit(axis)
    e1, e2 = perpendicular_frame(d)
    n = _count(2 * math.pi * radius * length, density)
    phi, t = rng.uniform(0, 2 * math.pi, n), rng.uniform(0, length, n)
    pts = base + t[:, None] * d + radius * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
    if caps:
        m = _count(math.pi * radius**2, density)
        r, phi = radius * np.sqrt(rng.uniform(size=m)), rng.uniform(0, 2 * math.pi, m)
        cap = base + length * d + r[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)
        pts = np.vstack([pts, cap])
    return pts


def sample_ellipsoid(rng, centre: Any, radii: Any, density: float, shell: float = 0.0,
                     upper_only: bool = False) -> np.ndarray:
    """Points filling an axis-aligned ellipsoid (``density`` per m³).

    ``shell`` in [0, 1): only the outer part with normalised radius > shell is
    filled (TLS/ALS see the outer foliage); ``upper_only`` keeps z ≥ centre.
    """
    c, r = np.asarray(centre, float), np.asarray(radii, float)
    vol = 4.0 / 3.0 * math.pi * float(np.prod(r)) * (1.0 - shell**3)
    if upper_only:
        vol /= 2
    n = _count(vol, density)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if upper_only:
        d[:, 2] = np.abs(d[:, 2])
    rho = np.cbrt(rng.uniform(shell**3, 1.0, n))
    return c + d * rho[:, None] * r


def add_noise(rng, xyz: np.ndarray, sigma: float, axes: str = "xyz") -> np.ndarray:
    """``xyz`` plus Gaussian noise of std ``sigma`` on the given axes (a new array)."""
    out = np.array(xyz, dtype=np.float64, copy=True)
    if sigma > 0 and len(out):
        for k, name in enumerate("xyz"):
            if name in axes:
                out[:, k] += rng.normal(0.0, sigma, len(out))
    return out


def range_keep(rng, xyz: np.ndarray, scanners: Any, ref_range: float, normal: Any = None) -> np.ndarray:
    """TLS-like thinning mask: keep with probability ``min(1, (ref_range / r)² · |cos θ|)``.

    ``r`` is the distance to the nearest scanner and θ the incidence angle
    between the beam and the surface ``normal`` (when given), so a surface
    sampled at the reference density keeps it up to ``ref_range`` at normal
    incidence and thins with 1/r² beyond and at grazing angles.
    """
    s = np.atleast_2d(np.asarray(scanners, float))
    diff = xyz[:, None, :] - s[None, :, :]
    dist = np.linalg.norm(diff, axis=2)
    near = np.argmin(dist, axis=1)
    r = np.maximum(dist[np.arange(len(xyz)), near], 1e-9)
    p = np.minimum(1.0, (ref_range / r) ** 2)
    if normal is not None:
        beam = diff[np.arange(len(xyz)), near] / r[:, None]
        p = p * np.abs(beam @ unit(normal))
    return rng.uniform(size=len(xyz)) < p


def isolated_outliers(rng, xyz: np.ndarray, lo: Any, hi: Any, n: int, min_dist: float) -> np.ndarray:
    """``n`` uniform random points in the box [lo, hi], each farther than ``min_dist`` from ``xyz``."""
    from scipy.spatial import cKDTree

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    if n <= 0:
        return np.empty((0, 3))
    tree = cKDTree(xyz) if len(xyz) else None
    out: list[np.ndarray] = []
    have = 0
    for _ in range(50):
        cand = lo + rng.uniform(size=(2 * (n - have) + 8, 3)) * (hi - lo)
        if tree is not None:
            d, _ = tree.query(cand, k=1, distance_upper_bound=min_dist)
            cand = cand[~np.isfinite(d)]
        # also keep the outliers apart from each other
        if len(cand) > 1:
            d2, _ = cKDTree(cand).query(cand, k=2)
            cand = cand[d2[:, 1] > min_dist]
        out.append(cand[: n - have])
        have += len(out[-1])
        if have >= n:
            break
    return np.vstack(out)[:n]


def smooth_field(rng, amplitude: float, wavelength: float, n_waves: int = 4) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """A smooth random height field ``f(x, y)``: a sum of plane cosine waves.

    Wave directions and phases are drawn from ``rng``; wavelengths vary around
    ``wavelength`` (× 0.7 … 1.6) and the amplitudes sum to ``amplitude``.
    """
    dirs = rng.uniform(0, 2 * math.pi, n_waves)
    lens = wavelength * rng.uniform(0.7, 1.6, n_waves)
    phases = rng.uniform(0, 2 * math.pi, n_waves)
    amps = rng.uniform(0.5, 1.0, n_waves)
    amps *= amplitude / amps.sum()
    kx, ky = np.cos(dirs) * 2 * math.pi / lens, np.sin(dirs) * 2 * math.pi / lens

    def f(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        x, y = np.asarray(x, float), np.asarray(y, float)
        out = np.zeros(np.broadcast(x, y).shape)
        for k in range(n_waves):
            out = out + amps[k] * np.cos(kx[k] * x + ky[k] * y + phases[k])
        return out

    return f


# ----------------------------------------------------------------- assembly
class Scene:
    """Accumulates point parts with their per-part attribute values.

    ``add(xyz, classification=2, object_id=ids)`` — each value is a scalar
    (broadcast) or an array of the part's length; :meth:`arrays` fills
    attributes a part did not set with the declared default.
    """

    def __init__(self, attributes: Mapping[str, tuple[Any, Any]]):
        # name -> (dtype, default)
        self.attributes = dict(attributes)
        self.parts: list[tuple[np.ndarray, dict[str, Any]]] = []

    def add(self, xyz: np.ndarray, **attrs: Any) -> int:
        unknown = set(attrs) - set(self.attributes)
        if unknown:
            raise ValueError(f"undeclared attributes {sorted(unknown)}")
        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        self.parts.append((xyz, attrs))
        return len(xyz)

    @property
    def n(self) -> int:
        return sum(len(p) for p, _ in self.parts)

    def xyz(self) -> np.ndarray:
        return np.vstack([p for p, _ in self.parts]) if self.parts else np.empty((0, 3))

    def arrays(self) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        xyz = self.xyz()
        attrs: dict[str, np.ndarray] = {}
        for name, (dtype, default) in self.attributes.items():
            cols = []
            for p, a in self.parts:
                v = a.get(name, default)
                cols.append(np.broadcast_to(np.asarray(v, dtype=dtype), (len(p),)))
            attrs[name] = np.concatenate(cols).astype(dtype) if cols else np.empty(0, dtype)
        return xyz, attrs


def no_points(name: str, params: Mapping[str, Any]) -> LidarfxError:
    """The refusal of a scene without points (a density so low that every part rounds to 0 points)."""
    density = params.get("density")
    at = f" at density {float(density):g}" if isinstance(density, (int, float, np.number)) else ""
    return LidarfxError(f"{name}: the scene has no points{at}; raise the density")


def finish(name: str, xyz: np.ndarray, attrs: Mapping[str, np.ndarray], truth: Mapping[str, Any],
           params: Mapping[str, Any], origin: np.ndarray) -> PointCloud:
    """Shift by ``origin`` and wrap as a :class:`PointCloud` with ``meta["truth"]``.

    ``truth`` coordinates stay *local* (relative to ``truth["origin"]``), like
    LAS offsets: world = local + origin.
    """
    if len(xyz) == 0:
        raise no_points(name, params)
    full = {"generator": name, "params": dict(params), "origin": origin, **truth}
    return PointCloud(
        np.asarray(xyz, dtype=np.float64) + origin,
        dict(attrs),
        meta={"generator": name, "truth": jsonable(full)},
    )


def class_counts(classification: np.ndarray, classes: Mapping[str, int]) -> dict[str, int]:
    return {name: int(np.count_nonzero(classification == code)) for name, code in classes.items()}


def merge_classes(default: Mapping[str, int], override: Mapping[str, int] | None) -> dict[str, int]:
    """Default class codes with user overrides; codes must be distinct ints 0..255."""
    out = dict(default)
    for k, v in (override or {}).items():
        if k not in out:
            raise LidarfxError(f"unknown class name {k!r}; known: {', '.join(out)}")
        out[k] = v
    codes = list(out.values())
    if any(not isinstance(c, (int, np.integer)) or not 0 <= c <= 255 for c in codes):
        raise LidarfxError("class codes must be integers in 0..255")
    if len(set(codes)) != len(codes):
        raise LidarfxError(f"class codes must be distinct, got {out}")
    return out


def capture_params(values: Mapping[str, Any]) -> dict[str, Any]:
    """The generator's call parameters (``locals()`` at its first line), JSON-ready."""
    return {k: jsonable(v) for k, v in values.items()}
