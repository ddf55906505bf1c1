"""Point colours: morphology in HSV (aspect, slope, sun shading), or by attribute, joint set or class.

The colours go to the LAS RGB fields (``red``, ``green``, ``blue``: uint16, 0–65535) and to a
picture (:func:`colour_picture`).  The library knows nothing of the command line; ``lidarfx
colour`` (:mod:`lidarfx.cli.colour`) is a thin layer over :func:`colour_cloud`.

Morphology colours (:func:`morphology_hsv`), per point with unit normal n:

* the normal is flipped up first: n → −n when n_z < 0 (so n and −n give the same colour; a
  horizontal normal, |n_z| < 1e-6, is flipped to n_x > 0, or along y to n_y > 0, as in
  :mod:`lidarfx.features`);
* slope s = arccos(n_z) in degrees (0 = horizontal, 90 = vertical);
* aspect a = atan2(n_x, n_y) mod 360 in degrees, clockwise from North (x = East, y = North):
  the direction the up-facing normal leans to, i.e. the dip direction of the surface;
* hue H = a / 360, saturation S = s / 90, value V = max(0, n·L) (Lambert shading) with the
  sun vector L = (cos h · sin z, cos h · cos z, sin h) for sun azimuth z (clockwise from North)
  and altitude h.

A point without a normal (NaN, zero length: fewer than 3 neighbours) gets HSV (0, 0, 0), i.e.
black.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError

__all__ = [
    "morphology_hsv",
    "morphology_rgb",
    "colour_cloud",
    "colour_picture",
    "class_colour",
    "check_sun",
    "check_cmap",
    "check_value_range",
    "check_radius",
    "to_uint16",
    "NO_VALUE",
    "NORMAL_NAMES",
    "KEYWORDS",
]

NO_VALUE = (0.62, 0.62, 0.62)
"""Colour of points whose attribute is NaN (``by`` = an attribute)."""

NORMAL_NAMES = ("normal_x", "normal_y", "normal_z")
"""Attributes read as normals by ``by="morphology"`` when all three are present."""

KEYWORDS = ("morphology", "set", "class")
"""Values of ``by`` that are not attribute names (they win over attributes of the same name)."""

VIEWS = ("auto", "top", "front", "side")


# ASPRS code -> key of lidarfx.render.CLASS_COLOURS
_CLASS_KEYS = {2: "ground", 3: "vegetation", 4: "vegetation", 5: "vegetation", 6: "building", 9: "water",
               13: "wire", 14: "wire", 16: "wire", 15: "pole"}


# --------------------------------------------------------------------------- checks
def check_sun(azimuth: float, altitude: float) -> tuple[float, float]:
    """``(azimuth mod 360, altitude)`` of the sun; a one-line error unless the azimuth is finite
    and the altitude is in 0–90 degrees."""
    try:
        az, alt = float(azimuth), float(altitude)
    except (TypeError, ValueError):
        raise LidarfxError(f"sun azimuth and altitude must be numbers, got {azimuth!r}, {altitude!r}") from None
    if not math.isfinite(az):
        raise LidarfxError(f"sun azimuth must be a finite angle in degrees, got {azimuth!r}")
    if not (math.isfinite(alt) and 0.0 <= alt <= 90.0):
        raise LidarfxError(f"sun altitude must be 0 to 90 degrees, got {altitude!r}")
    return az % 360.0, alt


def check_cmap(name: str):
    """The matplotlib colormap called ``name``; a one-line error naming a few that exist otherwise."""
    import matplotlib

    try:
        return matplotlib.colormaps[str(name)]
    except KeyError:
        raise LidarfxError(f"unknown colour map {name!r}; e.g. viridis, plasma, cividis, turbo, terrain, "
                           f"gray, coolwarm, RdBu (any matplotlib colormap)") from None


def check_value_range(value_range) -> tuple[float, float] | None:
    """``(lo, hi)`` as floats with lo < hi, both finite (None passes)."""
    if value_range is None:
        return None
    try:
        lo, hi = (float(v) for v in value_range)
    except (TypeError, ValueError):
        raise LidarfxError(f"value range must be two numbers lo, hi, got {value_range!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise LidarfxError(f"value range must be two finite numbers with lo < hi, got {lo:g}, {hi:g}")
    return lo, hi


def check_radius(radius) -> float | None:
    if radius is None:
        return None
    try:
        r = float(radius)
    except (TypeError, ValueError):
        raise LidarfxError(f"radius must be a positive length in metres, got {radius!r}") from None
    if not (math.isfinite(r) and r > 0):
        raise LidarfxError(f"radius must be a positive length in metres, got {radius!r}")
    return r


def _check_view(view: str) -> str:
    if view not in VIEWS:
        raise LidarfxError(f"view must be one of {', '.join(VIEWS)}; got {view!r}")
    return view


# --------------------------------------------------------------------------- morphology
def _points_down(u: np.ndarray) -> np.ndarray:
    """Rows of unit vectors ``u`` that the up orientation flips (:func:`lidarfx.features.plane.points_down`:
    z < 0, or, horizontal, x < 0, or, along y, y < 0); rounding alone does not decide a wall's side."""
    from .features.plane import HORIZONTAL

    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    return np.where(np.abs(z) >= HORIZONTAL, z < 0, np.where(np.abs(x) >= HORIZONTAL, x < 0, y < 0))


def _sun_vector(azimuth: float, altitude: float) -> np.ndarray:
    az, alt = math.radians(azimuth), math.radians(altitude)
    return np.array([math.cos(alt) * math.sin(az), math.cos(alt) * math.cos(az), math.sin(alt)])


def morphology_hsv(normals, *, sun_azimuth: float = 315.0, sun_altitude: float = 45.0) -> np.ndarray:
    """HSV (0–1, ``(n, 3)`` float64) of surfaces with normals ``normals`` (``(n, 3)``).

    With the normal flipped up (n → −n when n_z < 0) and scaled to unit length:

    * H = (atan2(n_x, n_y) mod 360°) / 360 — aspect, clockwise from North (x = East, y = North);
    * S = arccos(n_z) / 90° — slope;
    * V = max(0, n·L), L = (cos h sin z, cos h cos z, sin h) — Lambert shading by a sun at
      azimuth z (clockwise from North, default 315° = NW) and altitude h (default 45°).

    A horizontal surface has S = 0 and V = sin h; a surface facing the sun has V = 1.
    Rows with a NaN or zero-length normal get (0, 0, 0) (black).
    """
    az, alt = check_sun(sun_azimuth, sun_altitude)
    n = np.asarray(normals, dtype=np.float64)
    if n.ndim != 2 or n.shape[1] != 3:
        raise LidarfxError(f"normals must have shape (n, 3), got {n.shape}")
    length = np.sqrt(np.einsum("ij,ij->i", n, n))
    ok = np.isfinite(length) & (length > 0)
    u = np.zeros_like(n)
    u[ok] = n[ok] / length[ok, None]
    u[_points_down(u)] *= -1.0
    hsv = np.zeros_like(n)
    aspect = np.degrees(np.arctan2(u[ok, 0], u[ok, 1])) % 360.0
    hue = aspect / 360.0
    hsv[ok, 0] = np.where(hue >= 1.0, 0.0, hue)  # a float that rounds to 360 is 0
    hsv[ok, 1] = np.degrees(np.arccos(np.clip(u[ok, 2], 0.0, 1.0))) / 90.0
    hsv[ok, 2] = np.clip(u[ok] @ _sun_vector(az, alt), 0.0, 1.0)
    return hsv


def morphology_rgb(normals, *, sun_azimuth: float = 315.0, sun_altitude: float = 45.0) -> np.ndarray:
    """RGB (0–1, ``(n, 3)`` float64) of :func:`morphology_hsv` (``matplotlib.colors.hsv_to_rgb``);
    points without a normal are black (0, 0, 0)."""
    from matplotlib.colors import hsv_to_rgb

    hsv = morphology_hsv(normals, sun_azimuth=sun_azimuth, sun_altitude=sun_altitude)
    if not len(hsv):
        return np.zeros((0, 3))
    return np.clip(hsv_to_rgb(hsv), 0.0, 1.0)


def to_uint16(rgb) -> np.ndarray:
    """RGB 0–1 floats as LAS colours: round(c × 65535) as uint16 (clipped to 0–65535)."""
    c = np.asarray(rgb, dtype=np.float64)
    return np.round(np.clip(np.nan_to_num(c, nan=0.0), 0.0, 1.0) * 65535.0).astype(np.uint16)


# --------------------------------------------------------------------------- categorical colours
def class_colour(code: int) -> tuple[float, float, float]:
    """RGB (0–1) of ASPRS class ``code``: :data:`lidarfx.render.CLASS_COLOURS` by name (2 ground,
    3/4/5 vegetation, 6 building, 9 water, 13/14/16 wire, 15 transmission tower = pole), 0 and 1
    (never classified, unclassified) :data:`lidarfx.render.NOT_CLASSIFIED`, any other code the
    tab10 colour number ``code mod 10``."""
    import matplotlib
    from matplotlib.colors import to_rgb

    from .render import CLASS_COLOURS, NOT_CLASSIFIED

    code = int(code)
    if code in (0, 1):
        return tuple(float(v) for v in NOT_CLASSIFIED)
    key = _CLASS_KEYS.get(code)
    if key is not None:
        return to_rgb(CLASS_COLOURS[key])
    return to_rgb(matplotlib.colormaps["tab10"](code % 10))


def _hex(rgb) -> str:
    from matplotlib.colors import to_hex

    return to_hex(tuple(float(v) for v in rgb))


def attribute_array(cloud: PointCloud, name: str) -> np.ndarray:
    if name in ("x", "y", "z") and name not in cloud:
        return getattr(cloud, name)
    if name not in cloud:
        have = ", ".join(["x", "y", "z", *cloud.names])
        raise LidarfxError(f"no attribute {name!r} to colour by; colour by morphology, set, class or one of: {have}")
    return np.asarray(cloud[name])


def by_attribute(cloud, name, cmap, value_range) -> tuple[np.ndarray, dict]:
    v = attribute_array(cloud, name)
    if v.dtype.kind not in "biuf":
        raise LidarfxError(f"attribute {name!r} is not numeric ({v.dtype}); it cannot be colour-mapped")
    cm = check_cmap(cmap)
    v = v.astype(np.float64)
    ok = np.isfinite(v)
    if value_range is not None:
        lo, hi = value_range
        source = "given"
    elif ok.any():
        lo, hi = (float(t) for t in np.percentile(v[ok], [2, 98]))
        source = "percentiles 2-98"
    else:
        lo, hi = 0.0, 1.0
        source = "no finite values"
    t = np.full(len(v), 0.5)
    if hi > lo:
        t[ok] = np.clip((v[ok] - lo) / (hi - lo), 0.0, 1.0)
    rgb = np.empty((len(v), 3))
    rgb[ok] = np.asarray(cm(t[ok]))[:, :3] if ok.any() else np.zeros((0, 3))
    rgb[~ok] = NO_VALUE
    meta = {"attribute": name, "cmap": cm.name, "range": [lo, hi], "range_source": source,
            "no_value": int((~ok).sum())}
    return rgb, meta


def by_set(cloud) -> tuple[np.ndarray, dict]:
    from .render.palette import set_colour, set_colours

    if "set_id" not in cloud:
        have = ", ".join(cloud.names) or "none"
        raise LidarfxError(f"colour by set needs the set_id attribute (written by the discontinuities command); "
                           f"this cloud has: {have}")
    raw = np.asarray(cloud["set_id"])
    if raw.dtype.kind == "f":
        ids = np.where(np.isfinite(raw), np.round(np.nan_to_num(raw, nan=-1.0)), -1).astype(np.int64)
    elif raw.dtype.kind in "biu":
        ids = raw.astype(np.int64)
    else:
        raise LidarfxError(f"set_id is not numeric ({raw.dtype})")
    ids = np.where(ids < 0, -1, ids)
    rgb = set_colours(ids)
    vals, counts = np.unique(ids, return_counts=True)
    sets = [{"id": int(i), "points": int(c), "colour": _hex(set_colour(int(i)))} for i, c in zip(vals, counts)]
    return rgb, {"sets": sets}


def by_class(cloud) -> tuple[np.ndarray, dict]:
    from .classify.classes import ASPRS_NAMES

    if "classification" not in cloud:
        have = ", ".join(cloud.names) or "none"
        raise LidarfxError(f"colour by class needs the classification attribute; this cloud has: {have}")
    raw = np.asarray(cloud["classification"])
    if raw.dtype.kind not in "biuf":
        raise LidarfxError(f"classification is not numeric ({raw.dtype})")
    codes = np.nan_to_num(raw.astype(np.float64), nan=0.0).round().astype(np.int64)
    vals, inverse, counts = np.unique(codes, return_inverse=True, return_counts=True)
    table = np.array([class_colour(c) for c in vals]).reshape(len(vals), 3)
    rgb = table[inverse.ravel()]
    classes = [{"code": int(c), "name": ASPRS_NAMES.get(int(c), f"class {int(c)}"), "points": int(m),
                "colour": _hex(table[i])} for i, (c, m) in enumerate(zip(vals, counts))]
    return rgb, {"classes": classes}


# --------------------------------------------------------------------------- the cloud
def colour_cloud(
    cloud: PointCloud,
    by: str = "morphology",
    *,
    radius: float | None = None,
    scanner: Sequence[float] | None = None,
    sun_azimuth: float = 315.0,
    sun_altitude: float = 45.0,
    cmap: str = "viridis",
    value_range: tuple[float, float] | None = None,
    progress: bool | None = None,
    units: str = "auto",
) -> PointCloud:
    """A copy of ``cloud`` with ``red``, ``green``, ``blue`` (uint16, round(c × 65535)) set from ``by``.

    ``by``:

    * ``"morphology"`` — :func:`morphology_rgb` of the point normals: the cloud's
      ``normal_x/normal_y/normal_z`` when all three are present, else computed by the feature
      engine in a sphere of ``radius`` (default :func:`lidarfx.neighbors.default_radius`, about 40 points on a plane; ``scanner`` orients them,
      which only matters for exactly vertical faces, since the normals are flipped up);
    * an attribute name (``x``, ``y``, ``z`` included) — the matplotlib colormap ``cmap`` over
      ``value_range`` (default: 2nd–98th percentile of the finite values; values outside are
      clipped to the ends), NaN in :data:`NO_VALUE` grey;
    * ``"set"`` — the ``set_id`` attribute in :func:`lidarfx.render.palette.set_colours`
      (−1 = no set, grey);
    * ``"class"`` — the ``classification`` attribute in :func:`class_colour`.

    Existing colours are replaced.  ``meta["colour"]`` of the result records ``by`` and what was
    used (normal source and radius, sun, colormap and range, sets or classes with their points
    and colours).  ``radius`` is metres, converted when the LAS header's CRS names another linear
    unit (US survey feet, feet; ``units="native"``: coordinate units); ``scanner`` is a position
    in the cloud's coordinates.
    """
    if not isinstance(by, str) or not by:
        raise LidarfxError(f"'by' must be morphology, set, class or an attribute name, got {by!r}")
    if len(cloud) == 0:
        raise LidarfxError("the cloud has no points; nothing to colour")
    az, alt = check_sun(sun_azimuth, sun_altitude)
    radius = check_radius(radius)
    value_range = check_value_range(value_range)
    meta: dict[str, Any] = {"by": by}
    if by == "morphology":
        if all(k in cloud for k in NORMAL_NAMES):
            normals = np.column_stack([np.asarray(cloud[k], dtype=np.float64) for k in NORMAL_NAMES])
            meta.update(normals="attributes", radius=None)
        else:
            from .features import feature_arrays
            from .neighbors import default_radius

            from .crs import metres_per_unit

            u = metres_per_unit(cloud, units)
            r = default_radius(cloud) if radius is None else radius / u  # coordinate units
            f = feature_arrays(cloud.xyz, list(NORMAL_NAMES), radius=r, scanner=scanner, progress=progress)
            normals = np.column_stack([np.asarray(f[k], dtype=np.float64) for k in NORMAL_NAMES])
            meta.update(normals="computed", radius=r * u, radius_source="auto" if radius is None else "given",
                        scanner=None if scanner is None else [float(v) for v in scanner])
        rgb = morphology_rgb(normals, sun_azimuth=az, sun_altitude=alt)
        no_normal = ~np.all(np.isfinite(normals), axis=1) | ~np.any(normals != 0, axis=1)
        meta.update(sun_azimuth=az, sun_altitude=alt, no_normal=int(no_normal.sum()))
    elif by == "set":
        rgb, m = by_set(cloud)
        meta.update(m)
    elif by == "class":
        rgb, m = by_class(cloud)
        meta.update(m)
    else:
        rgb, m = by_attribute(cloud, by, cmap, value_range)
        meta.update(m)
    out = cloud.copy()
    meta["replaced_colours"] = any(k in cloud for k in ("red", "green", "blue"))
    c16 = to_uint16(rgb)
    out["red"], out["green"], out["blue"] = c16[:, 0], c16[:, 1], c16[:, 2]
    out.meta["colour"] = meta
    return out


# --------------------------------------------------------------------------- the picture
def _projection(xyz: np.ndarray, view: str) -> dict:
    """Image axes u (right), v (up) and nearness (larger = nearer the viewer) of a view.

    top: x right, y up, nearest = highest; front: seen from the South (x right, z up, nearest =
    smallest y); side: seen from the East (y right, z up, nearest = largest x); auto: the
    smallest-variance axis d of the points (PCA), oriented up: within 45° of vertical → top,
    else an elevation seen from the side d points to, looking horizontally along −d."""
    if view == "auto":
        sample = xyz
        if len(xyz) > 200_000:
            sample = xyz[np.random.default_rng(0).choice(len(xyz), 200_000, replace=False)]
        d = np.array([0.0, 0.0, 1.0])
        if len(sample) >= 3:
            _, vec = np.linalg.eigh(np.cov(sample.T))
            d = vec[:, 0] * (1.0 if vec[2, 0] >= 0 else -1.0)
        if d[2] >= math.cos(math.radians(45.0)):
            view = "top"
        else:
            h = np.array([d[0], d[1], 0.0])
            h /= np.linalg.norm(h)
            u = np.array([-h[1], h[0], 0.0])  # z × h: to the right of a viewer looking along −h
            az_u = math.degrees(math.atan2(u[0], u[1])) % 360.0
            az_look = math.degrees(math.atan2(-h[0], -h[1])) % 360.0
            return {"u": xyz @ u, "v": xyz[:, 2], "near": xyz @ h, "view": "elevation",
                    "look_azimuth": az_look, "xlabel": f"horizontal distance, towards {az_u:.0f}°", "ylabel": "z"}
    if view == "top":
        return {"u": xyz[:, 0], "v": xyz[:, 1], "near": xyz[:, 2], "view": "top", "xlabel": "x (East)",
                "ylabel": "y (North)"}
    if view == "front":
        return {"u": xyz[:, 0], "v": xyz[:, 2], "near": -xyz[:, 1], "view": "front", "look_azimuth": 0.0,
                "xlabel": "x (East)", "ylabel": "z"}
    return {"u": xyz[:, 1], "v": xyz[:, 2], "near": xyz[:, 0], "view": "side", "look_azimuth": 270.0,
            "xlabel": "y (North)", "ylabel": "z"}


def _morphology_key(ax, sun_azimuth: float, sun_altitude: float) -> None:
    """The colour of every (aspect, slope) as a disc: aspect around (North up), slope outwards."""
    m = 201
    g = np.linspace(-1.0, 1.0, m)
    gx, gy = np.meshgrid(g, g)
    r = np.hypot(gx, gy)
    slope = np.radians(np.clip(r, 0, 1) * 90.0)
    aspect = np.arctan2(gx, gy)
    normals = np.column_stack([(np.sin(slope) * np.sin(aspect)).ravel(), (np.sin(slope) * np.cos(aspect)).ravel(),
                               np.cos(slope).ravel()])
    img = morphology_rgb(normals, sun_azimuth=sun_azimuth, sun_altitude=sun_altitude).reshape(m, m, 3)
    img[r > 1] = 1.0
    ax.imshow(img, origin="lower", extent=(-1, 1, -1, 1), interpolation="bilinear")
    for text, x, y in (("N", 0, 1.13), ("E", 1.15, 0), ("S", 0, -1.15), ("W", -1.15, 0)):
        ax.text(x, y, text, ha="center", va="center", fontsize=7)
    ax.set_xlim(-1.3, 1.3)
    ax.set_ylim(-1.3, 1.3)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(f"aspect around, slope 0° (centre)\nto 90° (rim); sun {sun_azimuth:.0f}° / {sun_altitude:.0f}°",
                 fontsize=7)


def zbuffer(u, v, near, colours, pixels: int):
    """Raster of about ``pixels`` cells along the longer side, drawn by the splat kernel
    (:func:`lidarfx.render.splat.splat`): every point covers a disc of
    :func:`~lidarfx.render.splat.auto_point_size` (1.5 × the median distance to its 4th nearest
    neighbour in the picture plane, 1 to 12 cells, so random sampling leaves no holes) and
    every cell shows the nearest point covering it (largest ``near``).  Returns the image
    ``(rows, cols, 3)`` (row 0 = bottom, empty cells white), the cell size, the columns and
    rows, and the minimum u and v."""
    from .render.splat import Frame, auto_point_size, splat

    u0, v0 = float(u.min()), float(v.min())
    span_u, span_v = float(u.max()) - u0, float(v.max()) - v0
    cell = max(span_u, span_v, 1e-9) / max(int(pixels), 10)
    nu, nv = int(span_u / cell) + 1, int(span_v / cell) + 1
    winner, _ = splat(u, v, near, Frame(nu, nv, u0, v0, cell), auto_point_size(u, v, cell))
    img = np.ones((nv, nu, 3))
    shown = winner >= 0
    img[shown] = colours[winner[shown]]
    return np.ascontiguousarray(img[::-1]), cell, nu, nv, u0, v0


def colour_picture(
    cloud: PointCloud,
    rgb,
    path: str | Path,
    *,
    view: str = "auto",
    title: str | None = None,
    key: bool = True,
    pixels: int = 1200,
    dpi: int = 130,
) -> Path:
    """Save a PNG of the points drawn in their colours ``rgb`` (``(n, 3)``, floats 0–1 or uint16
    0–65535), the point nearest the viewer per pixel.

    ``view``: ``"top"`` (x right, y up, highest point wins), ``"front"`` (seen from the South:
    x right, z up, smallest y wins), ``"side"`` (seen from the East: y right, z up, largest x
    wins), or ``"auto"``: looking along the smallest-variance axis of the points (PCA), taken
    upward — within 45° of vertical a top view (ALS terrain), else a horizontal elevation facing
    the surface (a steep rock face).  No view is mirrored.  The picture is a raster of about
    ``pixels`` cells along the longer side; every point covers a disc of 1.5 × the median
    distance to its 4th nearest neighbour in the picture plane (1 to 12 cells, so random
    sampling leaves no holes) and each cell shows the nearest point covering it (the z-buffer
    kernel of :mod:`lidarfx.render.splat`);
    empty cells are white.  Axes are world coordinates in metres, less a round offset (as the
    label says) beyond 10 km; the horizontal axis of a rotated elevation is the distance from
    its leftmost point.  With ``key`` and
    ``cloud.meta["colour"]`` (from :func:`colour_cloud`) the picture gets a key: the
    aspect/slope disc, a colour bar, or the sets / classes with their points.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .render import offset_text, save_figure

    _check_view(view)
    if len(cloud) == 0:
        raise LidarfxError("the cloud has no points; nothing to draw")
    c = np.asarray(rgb)
    if c.shape != (len(cloud), 3):
        raise LidarfxError(f"colours must have shape ({len(cloud)}, 3), got {c.shape}")
    c = c.astype(np.float64) / 65535.0 if c.dtype.kind in "iu" else np.clip(np.nan_to_num(c.astype(np.float64)), 0, 1)
    ok = np.all(np.isfinite(cloud.xyz), axis=1)
    if not ok.any():
        raise LidarfxError("no point has finite coordinates; nothing to draw")
    origin = cloud.xyz[ok].min(axis=0)
    xyz = cloud.xyz[ok] - origin
    c = c[ok]
    pr = _projection(xyz, view)
    img, cell, nu, nv, u0, v0 = zbuffer(pr["u"], pr["v"], pr["near"], c, pixels)

    meta = cloud.meta.get("colour") if key else None
    by = meta.get("by") if isinstance(meta, dict) else None
    side = key_panel(meta)
    w = 8.0
    h = max(2.5, min(w * nv / nu, 1.3 * w)) + 0.6
    if side:
        fig, (ax, kx) = plt.subplots(1, 2, figsize=(w + 1.8, h), gridspec_kw={"width_ratios": [w, 1.8]})
    else:
        fig, ax = plt.subplots(figsize=(w + (1.8 if by else 0.0), h))
        kx = None
    # plotted coordinates: world coordinates, less a round offset when they are large
    axes_of = {"top": (0, 1), "front": (0, 2), "side": (1, 2), "elevation": (None, 2)}[pr["view"]]
    lo, texts = [], []
    for axis, m in zip(axes_of, (u0, v0)):
        if axis is None:  # distance along a rotated horizontal axis, from the leftmost point
            lo.append(0.0)
            texts.append("")
            continue
        world = float(origin[axis]) + m
        off = 0.0 if abs(world) < 1e4 else math.floor(world / 1000.0) * 1000.0
        lo.append(world - off)
        texts.append(offset_text(off))
    ax.imshow(img, origin="lower", interpolation="nearest",
              extent=(lo[0], lo[0] + nu * cell, lo[1], lo[1] + nv * cell))
    ax.set_aspect("equal")
    ax.set_xlabel(" ".join(t for t in (pr["xlabel"], texts[0], "[m]") if t), fontsize=8)
    ax.set_ylabel(" ".join(t for t in (pr["ylabel"], texts[1], "[m]") if t), fontsize=8)
    ax.tick_params(labelsize=7)
    look = pr.get("look_azimuth")
    seen = "seen from above" if look is None else f"looking towards {look:.0f}°"
    ax.set_title(f"{title}\n{seen}" if title else seen, fontsize=9)
    picture_key(fig, ax, kx, meta)
    return save_figure(fig, path, dpi)


def key_panel(meta) -> bool:
    """True when the key of colours made with ``meta`` (``cloud.meta["colour"]``) needs a panel of
    its own beside the picture (the morphology disc, a colour bar); sets and classes get a legend."""
    by = meta.get("by") if isinstance(meta, dict) else None
    return by == "morphology" or by not in (None, "set", "class")


def picture_key(fig, ax, kx, meta, label: str | None = None) -> None:
    """The key of a picture ``ax`` of points coloured by :func:`colour_cloud` (its
    ``meta["colour"]``): the aspect/slope disc or a colour bar in the panel ``kx`` (see
    :func:`key_panel`; a colour bar goes beside ``ax`` when ``kx`` is None), or the sets /
    classes with their points as a legend beside ``ax``.
    ``label``: the colour bar's label (default: the attribute name)."""
    import matplotlib.pyplot as plt

    by = meta.get("by") if isinstance(meta, dict) else None
    if by == "morphology":
        _morphology_key(kx, float(meta.get("sun_azimuth", 315.0)), float(meta.get("sun_altitude", 45.0)))
    elif by in ("set", "class"):
        rows = meta.get("sets" if by == "set" else "classes", [])
        if by == "set":
            labels = [(r["colour"], f"set {r['id']}: {r['points']:,}" if r["id"] >= 0 else f"no set: {r['points']:,}")
                      for r in rows]
        else:
            labels = [(r["colour"], f"{r['code']} {r['name']}: {r['points']:,}") for r in rows]
        handles = [plt.Line2D([], [], marker="s", ls="", color=col, label=lab) for col, lab in labels[:30]]
        if handles:
            ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0,
                      title="points", title_fontsize=7)
    elif by is not None:
        from matplotlib.cm import ScalarMappable
        from matplotlib.colors import Normalize

        lo, hi = meta.get("range", [0.0, 1.0])
        sm = ScalarMappable(norm=Normalize(lo, hi), cmap=meta.get("cmap", "viridis"))
        if kx is None:  # beside the picture, as high as it
            from mpl_toolkits.axes_grid1 import make_axes_locatable

            bar = fig.colorbar(sm, cax=make_axes_locatable(ax).append_axes("right", size=0.15, pad=0.12))
        else:
            kx.set_axis_off()
            bar = fig.colorbar(sm, ax=kx, fraction=0.6, aspect=18)
        bar.set_label(label or str(meta.get("attribute", by)), fontsize=8)
        bar.ax.tick_params(labelsize=7)
