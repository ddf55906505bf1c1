"""Z-buffered point splatting: millions of points to a shaded picture in seconds.

:func:`render_points` projects the points on a picture plane (a top, front or side view),
draws every point as a disc of a few pixels with a depth test — one pass over the points in a
numba kernel, each pixel keeping the point nearest to the viewer — and shades the result from
its depth buffer: eye-dome lighting (EDL, the screen-space shading of CloudCompare and Potree)
outlines depth steps; a hillshade of the depth buffer shows the relief.  The :class:`Image`
it returns holds the RGB pixels, the depth buffer, the shown point of every pixel and the
world-to-pixel mapping (:class:`Frame`).

:func:`render_picture` colours a cloud (an attribute through a colour map, the ASPRS classes,
its RGB fields or the morphology colours of :mod:`lidarfx.colour`), renders it and composes a
PNG of exactly the requested size: the picture at one image pixel per screen pixel, a title,
a colour bar or class legend, a scale bar and, in the top view, a north arrow.
``lidarfx render`` (:mod:`lidarfx.cli.render`) is a thin layer over it.

The same kernel (:func:`splat`) draws the rasters of :func:`lidarfx.colour.colour_picture`
and :func:`lidarfx.render.stereonet.set_view`.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numba as nb
import numpy as np

from ..cloud import PointCloud
from ..errors import LidarfxError

__all__ = ["Frame", "Image", "render_points", "render_picture", "splat", "fit_frame", "auto_point_size", "eye_dome",
           "parse_size", "scale_bar_length", "VIEWS", "SHADINGS", "MAX_POINT_SIZE"]

VIEWS = {"top": (0, 1, 2, 1.0), "front": (0, 2, 1, -1.0), "side": (1, 2, 0, 1.0)}
"""View -> (world axis to the right, world axis up, viewing axis, sign): a point's nearness to the
viewer is sign × its coordinate on the viewing axis.  top: x right (East), y up (North), the
highest point wins; front, seen from the South: x right, z up, the smallest y wins; side, seen
from the East: y right, z up, the largest x wins.  No view is mirrored."""

SHADINGS = ("edl", "hillshade", "none")

MAX_POINT_SIZE = 12.0
"""Largest automatic disc radius, pixels (a sparse cloud in a large picture stays points, not blobs)."""

_AXIS_NAMES = "xyz"
_SIZE_LIMITS = (1, 20_000)
_PICTURE_LIMITS = (160, 16_000)


# --------------------------------------------------------------------------- checks
def parse_size(size, limits: tuple[int, int] = _SIZE_LIMITS) -> tuple[int, int]:
    """``(width, height)`` in pixels from ``(w, h)`` or ``"WxH"``; a one-line error unless both are
    whole numbers within ``limits``."""
    lo, hi = limits
    text = size if isinstance(size, str) else None
    try:
        if text is not None:
            parts = text.lower().replace(" ", "").split("x")
            if len(parts) != 2 or not all(p.isdigit() for p in parts):
                raise ValueError
            w, h = int(parts[0]), int(parts[1])
        else:
            w, h = size
            if any(isinstance(v, bool) or float(v) != int(v) for v in (w, h)):
                raise ValueError
            w, h = int(w), int(h)
    except (TypeError, ValueError, OverflowError):
        raise LidarfxError(f"size must be WIDTHxHEIGHT in pixels, e.g. 1600x1200; got {size!r}") from None
    if not (lo <= w <= hi and lo <= h <= hi):
        raise LidarfxError(f"size must be {lo} to {hi} pixels each way, got {w}x{h}")
    return w, h


def _check_choice(what: str, value, choices) -> str:
    if value not in choices:
        raise LidarfxError(f"{what} must be one of {', '.join(choices)}; got {value!r}")
    return value


def _check_point_size(point_size) -> float | None:
    if point_size is None:
        return None
    try:
        r = float(point_size)
    except (TypeError, ValueError):
        raise LidarfxError(f"point size must be a disc radius in pixels (0 to 50), got {point_size!r}") from None
    if not (math.isfinite(r) and 0.0 <= r <= 50.0):
        raise LidarfxError(f"point size must be a disc radius in pixels (0 to 50), got {point_size!r}")
    return r


# --------------------------------------------------------------------------- the frame
@dataclass(frozen=True)
class Frame:
    """World-to-pixel mapping of a picture plane.

    Pixel ``(row, col)`` (row 0 at the top) covers world ``u`` in ``left + [col, col + 1) × cell``
    and ``v`` in ``bottom + [height − 1 − row, height − row) × cell``, where ``u`` and ``v`` are the
    world coordinates on ``axes`` (``(0, 1)`` = x, y for the top view; ``(0, 2)`` front;
    ``(1, 2)`` side)."""

    width: int
    height: int
    left: float
    bottom: float
    cell: float
    axes: tuple[int, int] = (0, 1)

    @property
    def top(self) -> float:
        return self.bottom + self.height * self.cell

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(left, right, bottom, top)`` in world units, for ``imshow(..., extent=...)``."""
        return self.left, self.left + self.width * self.cell, self.bottom, self.top

    def pixel(self, xyz) -> tuple[np.ndarray, np.ndarray]:
        """``(row, col)`` (int64) of the pixel holding the centre of each point of ``xyz`` ((n, 3)),
        as the kernel computes it (points on the far edges stay in the last pixel)."""
        p = np.atleast_2d(np.asarray(xyz, dtype=np.float64))
        col = np.floor((p[:, self.axes[0]] - self.left) / self.cell).astype(np.int64)
        rb = np.floor((p[:, self.axes[1]] - self.bottom) / self.cell).astype(np.int64)
        col = np.where(col == self.width, self.width - 1, col)
        rb = np.where(rb == self.height, self.height - 1, rb)
        return self.height - 1 - rb, col

    def describe(self) -> dict:
        return {"width": self.width, "height": self.height, "metres_per_pixel": self.cell,
                "left": self.left, "top": self.top, "right": _AXIS_NAMES[self.axes[0]],
                "up": _AXIS_NAMES[self.axes[1]]}


def fit_frame(lo_u: float, hi_u: float, lo_v: float, hi_v: float, width: int, height: int,
              axes: tuple[int, int] = (0, 1)) -> Frame:
    """The frame that fits ``[lo_u, hi_u] × [lo_v, hi_v]`` into ``width × height`` pixels with equal
    scales, centred (the spare pixels on both sides).  Degenerate extents (one point, a line
    seen end-on) get a 1 m wide picture."""
    ext_u, ext_v = max(hi_u - lo_u, 0.0), max(hi_v - lo_v, 0.0)
    cell = max(ext_u / width, ext_v / height)
    if not cell > 0:
        cell = 1.0 / max(width, height)
    cell *= 1.0 + 1e-9  # the far edges fall inside the last pixel
    left = lo_u - (width * cell - ext_u) / 2.0
    bottom = lo_v - (height * cell - ext_v) / 2.0
    return Frame(int(width), int(height), float(left), float(bottom), float(cell), tuple(axes))


# --------------------------------------------------------------------------- the kernel
@nb.njit(cache=True, nogil=True)
def _splat_kernel(u, v, near, left, bottom, inv_cell, width, height, dcol, drow, best, winner):
    """Draw point i as the pixels (centre + (dcol, drow)) and keep, per pixel, the largest
    ``near`` (ties: the later point).  ``best`` / ``winner`` are flat, row 0 at the top;
    rows count up from the bottom in ``drow``.  Non-finite points are skipped; a centre one pixel
    beyond the frame's edge is drawn on the edge (rounding), further out it is skipped."""
    k = dcol.shape[0]
    for i in range(u.shape[0]):
        a = u[i]
        b = v[i]
        d = near[i]
        if not (np.isfinite(a) and np.isfinite(b) and np.isfinite(d)):
            continue
        fc = (a - left) * inv_cell
        fr = (b - bottom) * inv_cell
        if fc < -1.0 or fr < -1.0 or fc >= width + 1.0 or fr >= height + 1.0:
            continue
        c0 = min(max(math.floor(fc), 0), width - 1)
        r0 = min(max(math.floor(fr), 0), height - 1)
        for j in range(k):
            c = c0 + dcol[j]
            r = r0 + drow[j]
            if c < 0 or c >= width or r < 0 or r >= height:
                continue
            p = (height - 1 - r) * width + c
            if d >= best[p]:
                best[p] = d
                winner[p] = i


def _disc(radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixel offsets (column, row) within ``radius`` pixels of a centre pixel (0: the pixel itself)."""
    k = math.floor(max(radius, 0.0))
    dc, dr = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1))
    inside = dc ** 2 + dr ** 2 <= max(radius, 0.0) ** 2
    return dc[inside].astype(np.int64), dr[inside].astype(np.int64)


def splat(u, v, near, frame: Frame, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Z-buffer of points at picture-plane coordinates ``u``, ``v`` (world units, 1-D) with
    nearness ``near`` (larger = nearer the viewer): every point covers the pixels within
    ``radius`` pixels of its centre pixel and each pixel keeps the nearest point covering it
    (ties: the later point, so the answer does not depend on the thread or block order).
    Returns ``winner`` ((height, width) int64, the shown point's index, −1 = empty) and ``best``
    (its ``near``, −inf where empty), row 0 at the top."""
    u = np.ascontiguousarray(u, dtype=np.float64)
    v = np.ascontiguousarray(v, dtype=np.float64)
    near = np.ascontiguousarray(near, dtype=np.float64)
    if not (u.shape == v.shape == near.shape and u.ndim == 1):
        raise LidarfxError(f"u, v and near must be 1-D arrays of one length, got {u.shape}, {v.shape}, {near.shape}")
    w, h = frame.width, frame.height
    best = np.full(w * h, -np.inf)
    winner = np.full(w * h, -1, np.int64)
    dc, dr = _disc(radius)
    _splat_kernel(u, v, near, frame.left, frame.bottom, 1.0 / frame.cell, w, h, dc, dr, best, winner)
    return winner.reshape(h, w), best.reshape(h, w)


def auto_point_size(u, v, cell: float, *, cap: float = MAX_POINT_SIZE) -> float:
    """Disc radius in pixels that closes the gaps of a random sampling: 1.5 × the median
    distance to the 4th nearest neighbour in the picture plane (10 000 points' neighbours in a
    seeded subsample of about 200 000, scaled back to the whole), in pixels of ``cell``; at
    least 1 (a pixel and its four side neighbours: a cloud of several points per pixel has no pin
    holes either), at most ``cap``.  Fewer than 5 points: 2 pixels."""
    from scipy.spatial import cKDTree

    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    n = len(u)
    if n > 200_000:  # a seeded sample (repeats dropped) rather than a permutation of millions
        idx = np.sort(np.random.default_rng(0).integers(0, n, 200_000))
        idx = idx[np.r_[True, idx[1:] != idx[:-1]]]
        u, v = u[idx], v[idx]
    ok = np.isfinite(u) & np.isfinite(v)
    m = int(ok.sum())
    if m < 5:
        return min(2.0, cap)
    total = m if n <= 200_000 else m * n / len(u)  # finite points of the whole
    uv = np.column_stack([u[ok], v[ok]])
    q = uv[np.random.default_rng(1).choice(m, 10_000, replace=False)] if m > 10_000 else uv
    d, _ = cKDTree(uv, balanced_tree=False, compact_nodes=False).query(q, k=5)
    d4 = float(np.median(d[:, 4])) * math.sqrt(m / total)  # a subsample of m of N points spaces out by sqrt(N/m)
    return float(min(max(1.5 * d4 / cell, 1.0), cap))


# --------------------------------------------------------------------------- shading
@nb.njit(cache=True, nogil=True)
def _edl_kernel(logd, drow, dcol, scale):
    """exp(−scale × Σ max(0, logd − logd_neighbour)) per pixel over the given neighbours
    (empty pixels, NaN, are left out: an outline is drawn only where something nearer is)."""
    h, w = logd.shape
    out = np.ones((h, w))
    k = drow.shape[0]
    for r in range(h):
        for c in range(w):
            d = logd[r, c]
            if not np.isfinite(d):
                continue
            s = 0.0
            for j in range(k):
                rr = r + drow[j]
                cc = c + dcol[j]
                if rr < 0 or rr >= h or cc < 0 or cc >= w:
                    continue
                dn = logd[rr, cc]
                if np.isfinite(dn) and d > dn:
                    s += d - dn
            out[r, c] = math.exp(-scale * s)
    return out


def eye_dome(near: np.ndarray, cell: float, *, strength: float = 1.0, radius: float = 1.5) -> np.ndarray:
    """Eye-dome lighting of a depth buffer: shade (0–1, (h, w)) from ``near`` ((h, w), larger =
    nearer the viewer, NaN or −inf = empty; world units, pixels of ``cell``).

    The viewer stands one picture side (max(h, w) × cell) before the nearest point, so the
    distance of a pixel is D = that + (max near − near).  With ℓ = ln D, each pixel compares
    itself with its 8 neighbours at ``radius`` pixels (N, NE, E, …):
    shade = exp(−300 × strength / 8 × Σ max(0, ℓ − ℓ_neighbour)) (Potree's constants).  A pixel
    behind a nearer neighbour darkens — the far side of every depth step, and more the deeper
    the step relative to the picture; a flat surface facing the viewer keeps 1.  The same scene
    at any picture size looks the same (depth steps count in pixels of the picture)."""
    nr = np.asarray(near, dtype=np.float64)
    ok = np.isfinite(nr)
    if not ok.any():
        return np.ones(nr.shape)
    span = float(max(nr.shape)) * float(cell)
    logd = np.full(nr.shape, np.nan)
    logd[ok] = np.log(span + (float(nr[ok].max()) - nr[ok]))
    ang = np.radians(np.arange(8) * 45.0)
    drow = np.round(-radius * np.cos(ang)).astype(np.int64)
    dcol = np.round(radius * np.sin(ang)).astype(np.int64)
    return _edl_kernel(logd, drow, dcol, 300.0 * float(strength) / 8.0)


def _hill_shade(near: np.ndarray, cell: float, azimuth: float, altitude: float, smooth: float = 0.0) -> np.ndarray:
    """Shade (flat = 1) of the depth buffer seen as a height raster (nearness = height, picture
    up = North): :func:`lidarfx.render.hillshade` over the buffer with its empty pixels filled
    from the nearest drawn pixel (no cliffs at the outline) and averaged over a square of
    2 ⌈``smooth``⌉ + 1 pixels (the disc diameter: the relief of the surface, not the steps between
    flat discs), scaled by the flat value sin(altitude) and mixed 0.25 + 0.75 × that, so
    shadowed slopes stay readable."""
    from scipy import ndimage

    from . import hillshade

    nr = np.asarray(near, dtype=np.float64)
    empty = ~np.isfinite(nr)
    if empty.all():
        return np.ones(nr.shape)
    if empty.any():
        idx = ndimage.distance_transform_edt(empty, return_distances=False, return_indices=True)
        nr = nr[tuple(idx)]
    if smooth >= 1.0:
        nr = ndimage.uniform_filter(nr, size=2 * math.ceil(smooth) + 1, mode="nearest")
    hs = hillshade(nr, cell, azimuth=azimuth, altitude=altitude)
    flat = max(math.sin(math.radians(altitude)), 1e-3)
    return np.clip(0.25 + 0.75 * hs / flat, 0.0, 1.25)


# --------------------------------------------------------------------------- the picture raster
@dataclass
class Image:
    """A rendered view (see :func:`render_points`).

    ``rgb``: (h, w, 3) uint8, row 0 at the top, shaded, the background where no point is;
    ``depth``: (h, w) float64, the world coordinate on the viewing axis of the point shown
    (z in the top view, y front, x side), NaN where empty; ``index``: (h, w) int64, the index of
    that point in the input (−1 = empty); ``shade``: (h, w), the shading factor applied;
    ``frame``: the world-to-pixel mapping (``frame.left``, ``frame.top``, ``frame.cell`` =
    metres per pixel, ``frame.axes``); ``point_size``: the disc radius used, pixels."""

    rgb: np.ndarray
    depth: np.ndarray
    index: np.ndarray
    shade: np.ndarray
    frame: Frame
    view: str
    point_size: float
    shading: str

    @property
    def metres_per_pixel(self) -> float:
        return self.frame.cell

    @property
    def rgb_float(self) -> np.ndarray:
        """The pixels as floats 0–1."""
        return self.rgb.astype(np.float64) / 255.0

    @property
    def covered(self) -> float:
        """Share of the pixels that show a point."""
        return float(np.mean(self.index >= 0))


def _colour_scale(c: np.ndarray) -> float:
    """What a colour value of dtype ``c.dtype`` is divided by to give 0–1: floats 1, uint8 255,
    other integers 65535 (the LAS range)."""
    if c.dtype.kind == "f":
        return 1.0
    if c.dtype == np.uint8:
        return 255.0
    if c.dtype.kind in "iub":
        return 65535.0
    raise LidarfxError(f"colours must be numeric, got {c.dtype}")


@nb.njit(cache=True, nogil=True)
def _compose_kernel(winner, colours, inv_scale, shade, bg, out):
    """out[r, c] = colours[winner] / scale × shade (NaN 0, clipped to 0–1) as 0–255, or ``bg``
    (0–255) where the pixel is empty; a colour array with no rows draws light grey."""
    h, w = winner.shape
    grey = colours.shape[0] == 0
    for r in range(h):
        for c in range(w):
            i = winner[r, c]
            if i < 0:
                for k in range(3):
                    out[r, c, k] = bg[k]
                continue
            for k in range(3):
                x = 0.82 if grey else colours[i, k] * inv_scale
                if not np.isfinite(x):
                    x = 0.0
                x = min(max(x * shade[r, c], 0.0), 1.0)
                out[r, c, k] = np.uint8(x * 255.0 + 0.5)


def render_points(
    xyz,
    colours=None,
    *,
    view: str = "top",
    size=(1600, 1200),
    point_size: float | None = None,
    shading: str = "edl",
    background: Any = "white",
    edl_strength: float = 1.0,
    edl_radius: float = 1.5,
    sun_azimuth: float = 315.0,
    sun_altitude: float = 45.0,
) -> Image:
    """Render points ``xyz`` ((n, 3)) in ``colours`` as a z-buffered picture of ``size`` pixels.

    ``colours``: (n, 3) floats 0–1, uint8 0–255 or uint16 0–65535 (LAS), or None (light grey,
    the shape from the shading alone).  ``view``: ``"top"`` (x right, y up, the highest point
    wins), ``"front"`` (seen from the South: x right, z up, the smallest y wins) or ``"side"``
    (seen from the East: y right, z up, the largest x wins).  The points fill ``size`` =
    (width, height) at equal scales, centred, the rest ``background`` (any matplotlib colour).

    Every point is a disc of ``point_size`` pixels radius (0 = one pixel; default
    :func:`auto_point_size`: 1.5 × the median distance to the 4th neighbour in the picture plane,
    1 to 12 pixels) and each pixel shows the nearest point covering it (:func:`splat`).
    ``shading``: ``"edl"`` (:func:`eye_dome`, ``edl_strength``, ``edl_radius`` pixels),
    ``"hillshade"`` (the depth buffer, smoothed over a disc diameter, as a height raster under a
    sun at ``sun_azimuth`` / ``sun_altitude``, picture up as North; see :func:`_hill_shade`) or
    ``"none"``.
    Non-finite points are left out.
    """
    from matplotlib.colors import to_rgb

    _check_choice("view", view, tuple(VIEWS))
    _check_choice("shading", shading, SHADINGS)
    w, h = parse_size(size)
    point_size = _check_point_size(point_size)
    try:
        bg = np.asarray(to_rgb(background))
    except ValueError:
        raise LidarfxError(f"background must be a matplotlib colour, got {background!r}") from None
    p = np.asarray(xyz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise LidarfxError(f"xyz must have shape (n, 3), got {p.shape}")
    if colours is not None:
        colours = np.asarray(colours)
        if colours.shape != (len(p), 3):
            raise LidarfxError(f"colours must have shape ({len(p)}, 3), got {colours.shape}")
    au, av, ad, sign = VIEWS[view]
    lo, hi, count = _bounds(p)
    if count == 0:
        raise LidarfxError("no point has finite coordinates; nothing to draw")
    frame = fit_frame(lo[au], hi[au], lo[av], hi[av], w, h, (au, av))
    u, v = p[:, au], p[:, av]
    near = sign * (p[:, ad] - lo[ad])  # from the lowest coordinate: full precision far from the origin
    radius = auto_point_size(u, v, frame.cell) if point_size is None else point_size
    winner, best = splat(u, v, near, frame, radius)
    shown = winner >= 0
    near_img = np.where(shown, best, np.nan)
    if shading == "edl":
        shade = eye_dome(near_img, frame.cell, strength=edl_strength, radius=edl_radius)
    elif shading == "hillshade":
        shade = _hill_shade(near_img, frame.cell, sun_azimuth, sun_altitude, smooth=radius)
    else:
        shade = np.ones((h, w))
    shade = np.where(shown, shade, 1.0)
    rgb = np.empty((h, w, 3), np.uint8)
    if colours is None:
        colours = np.zeros((0, 3))
    elif colours.dtype.kind == "b" or colours.dtype.itemsize > 8:
        colours = colours.astype(np.float64)
    _compose_kernel(winner, np.ascontiguousarray(colours), 1.0 / _colour_scale(colours), shade,
                    np.round(bg * 255.0).astype(np.uint8), rgb)
    depth = sign * near_img + lo[ad]
    return Image(rgb=rgb, depth=depth, index=winner, shade=shade, frame=frame, view=view,
                 point_size=float(radius), shading=shading)


@nb.njit(cache=True, nogil=True)
def _bounds_kernel(p):
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    count = 0
    for i in range(p.shape[0]):
        if np.isfinite(p[i, 0]) and np.isfinite(p[i, 1]) and np.isfinite(p[i, 2]):
            count += 1
            for a in range(3):
                lo[a] = min(lo[a], p[i, a])
                hi[a] = max(hi[a], p[i, a])
    return lo, hi, count


def _bounds(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Lower and upper corner of the points with three finite coordinates, and their count (one pass)."""
    return _bounds_kernel(np.ascontiguousarray(p, dtype=np.float64))


# --------------------------------------------------------------------------- colours of a cloud
CLASS_NAMES = ("class", "classification")
"""Values of ``by`` that colour the points by their ASPRS class (a legend)."""


def _rgb_attributes(cloud: PointCloud) -> tuple[np.ndarray, dict]:
    """The cloud's ``red``/``green``/``blue`` as (n, 3), and the range they were read in: 0–65535
    (LAS) unless no value exceeds 255 (8-bit colours stored in 16-bit fields), floats 0–1 unless
    one exceeds 1."""
    missing = [k for k in ("red", "green", "blue") if k not in cloud]
    if missing:
        have = ", ".join(cloud.names) or "none"
        raise LidarfxError(f"render by rgb needs the red, green and blue attributes; this cloud has: {have}")
    c = np.column_stack([np.asarray(cloud[k]) for k in ("red", "green", "blue")])
    if c.dtype.kind not in "biuf":
        raise LidarfxError(f"red/green/blue are not numeric ({c.dtype})")
    top = float(np.nanmax(c)) if c.size and np.isfinite(c).any() else 0.0
    full = 65535.0 if top > 255 else 255.0 if (top > 1 or c.dtype.kind != "f") else 1.0
    return c.astype(np.float32) / np.float32(full), {"by": "rgb", "scale": full}


def _colour_points(cloud: PointCloud, by: str, cmap: str, value_range, progress) -> tuple[np.ndarray, dict]:
    """Per-point colours of ``by`` and the key's description (``meta`` as in
    ``cloud.meta["colour"]`` of :func:`lidarfx.colour.colour_cloud`): :func:`lidarfx.colour.colour_cloud`
    for morphology, its attribute / class / set colourings otherwise, the RGB fields for ``rgb``."""
    from .. import colour as col

    if by == "rgb":
        return _rgb_attributes(cloud)
    if by == "morphology":
        out = col.colour_cloud(cloud, "morphology", progress=progress)
        rgb = np.column_stack([out["red"], out["green"], out["blue"]])
        return rgb, out.meta["colour"]
    if by in CLASS_NAMES:
        rgb, meta = col.by_class(cloud)
        return rgb, {"by": "class", **meta}
    if by == "set":
        rgb, meta = col.by_set(cloud)
        return rgb, {"by": "set", **meta}
    if by not in cloud and by not in ("x", "y", "z"):
        have = ", ".join(["x", "y", "z", *cloud.names])
        raise LidarfxError(f"no attribute {by!r} to render by; use rgb, class, morphology or one of: {have}")
    rgb, meta = col.by_attribute(cloud, by, cmap, value_range)
    return rgb, {"by": by, **meta}


# --------------------------------------------------------------------------- the composed picture
def scale_bar_length(span: float) -> float:
    """A round length (1, 2 or 5 × 10^k) of at most ``span`` / 5, the largest such."""
    target = float(span) / 5.0
    if not (math.isfinite(target) and target > 0):
        return 1.0
    k = math.floor(math.log10(target))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0 ** k <= target * (1 + 1e-9):
            return m * 10.0 ** k
    return 10.0 ** k


def _length_text(metres: float) -> str:
    """A length with its unit, three significant digits: 1.5 km, 20 m, 3.98 cm, 5 mm."""
    if metres >= 1000:
        return f"{metres / 1000:.3g} km"
    if metres >= 1:
        return f"{metres:.3g} m"
    if metres >= 0.01:
        return f"{metres * 100:.3g} cm"
    return f"{metres * 1000:.3g} mm"


_VIEW_TEXT = {"top": "top view: x East, y North", "front": "front view from the South: x East, z up",
              "side": "side view from the East: y North, z up"}
_SHADING_TEXT = {"edl": "eye-dome lighting", "hillshade": "hillshade", "none": "no shading"}


def _key_width(meta: dict | None) -> float:
    """Width in inches of the panel right of the picture that the key needs."""
    by = meta.get("by") if isinstance(meta, dict) else None
    if by in (None, "rgb"):
        return 0.0
    if by == "morphology":
        return 1.9
    if by in ("class", "set"):
        rows = meta.get("classes" if by == "class" else "sets", [])[:30]
        longest = max((len(f"{r.get('code', r.get('id'))} {r.get('name', 'no set')}: {r['points']:,}") for r in rows),
                      default=10)
        return 0.45 + 0.062 * longest
    return 1.25


def _draw_scale_and_north(ax, frame: Frame, w: int, h: int, north: bool, unit: float = 1.0) -> float:
    """A scale bar (a round length about 1/5 of the width) at the bottom left and, with ``north``,
    a north arrow at the top right of the picture axes ``ax`` (pixel coordinates, y down);
    returns the bar's length in metres (``unit``: metres per coordinate unit, for files in feet)."""
    from matplotlib import patheffects
    from matplotlib.patches import Rectangle

    halo = [patheffects.withStroke(linewidth=3, foreground="white")]
    length = scale_bar_length(w * frame.cell * unit)
    px = length / (frame.cell * unit)
    pad = 0.03 * min(w, h)
    x0, y0 = pad, h - pad
    thick = max(3.0, 0.012 * min(w, h))
    for k in range(2):  # two halves, black and white, in a black frame
        ax.add_patch(Rectangle((x0 + k * px / 2, y0 - thick), px / 2, thick, facecolor="k" if k == 0 else "w",
                               edgecolor="k", lw=0.8, zorder=5))
    ax.text(x0 + px / 2, y0 - thick - 0.4 * pad, _length_text(length), ha="center", va="bottom", fontsize=8,
            zorder=6, path_effects=halo)
    if north:
        xa, ya = w - 1.3 * pad, 1.6 * pad
        ax.annotate("", xy=(xa, ya), xytext=(xa, ya + 0.09 * min(w, h)), zorder=6,
                    arrowprops={"arrowstyle": "-|>,head_width=0.35,head_length=0.7", "lw": 1.8, "color": "k",
                                "path_effects": halo})
        ax.text(xa, ya - 0.2 * pad, "N", ha="center", va="bottom", fontsize=10, fontweight="bold", zorder=6,
                path_effects=halo)
    return length


def render_picture(
    cloud: PointCloud,
    path: str | Path,
    *,
    by: str = "z",
    view: str = "top",
    size=(1600, 1200),
    shading: str = "edl",
    point_size: float | None = None,
    cmap: str = "viridis",
    value_range: tuple[float, float] | None = None,
    title: str | None = None,
    background: Any = "white",
    progress: bool | None = None,
) -> tuple[Path, dict]:
    """Save a PNG of exactly ``size`` = (width, height) pixels of the cloud rendered by
    :func:`render_points`, and return its path and a summary.

    ``by``: a numeric attribute (``x``, ``y``, ``z`` included) through the colour map ``cmap`` over
    ``value_range`` (default the 2–98 % range of its finite values; NaN grey) with a colour bar;
    ``class`` (or ``classification``: ASPRS colours of :func:`lidarfx.colour.class_colour`, a
    legend of the classes present with their points); ``set`` (joint sets, ``set_id``); ``rgb``
    (the cloud's red/green/blue: 0–65535, or 0–255 when no value exceeds 255); ``morphology``
    (:func:`lidarfx.colour.colour_cloud`: the cloud's normal_x/y/z or normals computed at an
    automatic radius; the aspect/slope disc as key).

    Layout: a title band on top (``title``, default the source file and ``by``; below it the
    view, points, metres per pixel and shading), the key on the right, and the rendered picture
    filling the rest at one image pixel per PNG pixel (``figimage``: no resampling), with a
    scale bar and, in the top view, a north arrow.  The PNG is written atomically; on any error
    nothing is written.

    Summary: ``points``, ``drawn`` (finite), ``by``, ``view``, ``size``, ``frame`` (the picture's
    pixels and world mapping: ``left``/``top`` world coordinates of its top-left corner,
    ``metres_per_pixel``, the world axes ``right`` and ``up``), ``picture_offset`` (column and row
    of the picture's top-left pixel in the PNG), ``point_size`` (pixels) and its
    source, ``shading``, ``covered`` (share of the picture's pixels showing a point),
    ``scale_bar_m``, ``colour`` (range and colour map, classes, …) and ``seconds``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import warnings

    import matplotlib.pyplot as plt
    from matplotlib.colors import to_rgb

    from .._atomic import check_output_folder
    from ..colour import check_cmap, check_value_range, key_panel, picture_key
    from . import save_figure

    t0 = time.perf_counter()
    if not isinstance(by, str) or not by.strip():
        raise LidarfxError(f"'by' must be an attribute name, class, rgb or morphology; got {by!r}")
    by = by.strip()
    _check_choice("view", view, tuple(VIEWS))
    _check_choice("shading", shading, SHADINGS)
    width, height = parse_size(size, _PICTURE_LIMITS)
    point_size = _check_point_size(point_size)
    value_range = check_value_range(value_range)
    if by not in ("rgb", "morphology", "set", *CLASS_NAMES):
        check_cmap(cmap)
    try:
        to_rgb(background)
    except ValueError:
        raise LidarfxError(f"background must be a matplotlib colour, got {background!r}") from None
    if Path(path).suffix.lower() != ".png":
        raise LidarfxError(f"picture {path}: pictures are PNG files; give a path ending in .png")
    check_output_folder(path)
    if len(cloud) == 0:
        raise LidarfxError("the cloud has no points; nothing to draw")

    rgb, meta = _colour_points(cloud, by, cmap, value_range, progress)
    t1 = time.perf_counter()

    # layout in inches at a resolution that scales with the picture: the same composition at any size
    dpi = float(np.clip(min(width, height) / 8.0, 60.0, 200.0))
    key_meta = None if meta.get("by") == "rgb" else meta
    margin = round(0.08 * dpi)
    band = round(0.62 * dpi)
    key_w = min(round(_key_width(key_meta) * dpi), int(0.45 * width))
    w, h = width - key_w - 2 * margin, height - band - 2 * margin
    if w < 40 or h < 40:
        raise LidarfxError(f"size {width}x{height} leaves no room for the picture beside its key; give a larger size")
    img = render_points(cloud.xyz, rgb, view=view, size=(w, h), point_size=point_size, shading=shading,
                        background=background)
    t2 = time.perf_counter()

    fig = plt.figure(figsize=((width + 1e-3) / dpi, (height + 1e-3) / dpi), dpi=dpi, facecolor=background)
    try:
        fig.figimage(img.rgb, xo=margin, yo=margin, origin="upper", zorder=0)
        ax = fig.add_axes((margin / width, margin / height, w / width, h / height))
        ax.set_zorder(1)
        ax.set_xlim(0, w)
        ax.set_ylim(h, 0)
        ax.set_axis_off()
        from ..crs import unit_to_metre

        bar = _draw_scale_and_north(ax, img.frame, w, h, north=view == "top", unit=unit_to_metre(cloud))
        kx = None
        if key_meta is not None and key_panel(key_meta):
            part = 0.5 if key_meta.get("by") != "morphology" else 1.0  # a colour bar leaves room for its ticks and label
            kx = fig.add_axes(((width - key_w) / width, margin / height, part * (key_w - margin) / width, h / height))
        label = None
        if meta.get("attribute") is not None:
            label = str(meta["attribute"])
            if str(meta.get("range_source", "")).startswith("percentiles"):
                label += "  (2–98 % range)"
            if meta.get("no_value"):
                label += "\nNaN grey"
        if key_meta is not None:
            picture_key(fig, ax, kx, key_meta, label=label)
        source = cloud.meta.get("source")
        head = title or f"{Path(source).name if source else 'points'}: {by}"
        drawn = int(_bounds(cloud.xyz)[2])
        sub = (f"{_VIEW_TEXT[view]}  ·  {drawn:,} points  ·  {_length_text(img.frame.cell * unit_to_metre(cloud))} per pixel  ·  "
               f"{_SHADING_TEXT[shading]}")
        top = 1.0 - band / height
        fig.text(0.5, top + 0.62 * band / height, head, ha="center", va="center", fontsize=11)
        fig.text(0.5, top + 0.22 * band / height, sub, ha="center", va="center", fontsize=7.5, color="0.3")
    except BaseException:  # no figure is left open after an error
        plt.close(fig)
        raise
    with warnings.catch_warnings():  # save_figure lays out subplots; these axes are placed by hand
        warnings.simplefilter("ignore", UserWarning)
        out = save_figure(fig, path, dpi)
    t3 = time.perf_counter()
    summary = {
        "output": str(out),
        "points": len(cloud),
        "drawn": drawn,
        "by": by,
        "view": view,
        "size": [width, height],
        "frame": img.frame.describe(),
        "picture_offset": [margin, band + margin],
        "point_size": round(img.point_size, 3),
        "point_size_source": "auto" if point_size is None else "given",
        "shading": shading,
        "covered": round(img.covered, 4),
        "scale_bar_m": bar,
        "colour": meta,
        "seconds": {"colour": round(t1 - t0, 3), "render": round(t2 - t1, 3), "picture": round(t3 - t2, 3)},
    }
    return out, summary
