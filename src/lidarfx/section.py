"""Section projection: the points of a thin slab around a cut plane, in profile coordinates.

The frame (:func:`section_frame`), from the two ends ``a`` (from) and ``b`` (to):

* default, a vertical cut: the vertical plane through the line a→b in plan view.
  ``e_s`` = the horizontal direction a→b, ``e_h`` = up (0, 0, 1), ``e_n = e_s × e_h`` (the
  right-hand side, looking from a to b).  The z of a and b may be left out; given, z of a is
  the zero of h (else h = z).  The length is the horizontal distance from a to b.
* with ``normal``: the plane through a (x, y, z needed) with that normal ``n`` (made unit),
  ``e_n = n``; ``e_s`` = the direction a→b projected into the plane (b's z defaults to a's);
  ``e_h = n × e_s``, turned to point up (``e_h`` · z ≥ 0), so up is up in the picture.  The
  length is that of a→b projected into the plane.  A normal parallel to a→b is refused.

Every point ``p`` gets ``section_s = (p − a)·e_s`` (along the section, 0 at a),
``section_h = (p − a)·e_h`` (height in the plane) and ``section_d = (p − a)·e_n`` (signed
offset from the plane).  The section keeps the points with ``|d| ≤ width / 2`` and
``0 ≤ s ≤ length``: a closed slab, so points exactly on its faces or end planes (in float64
arithmetic) are kept; there is no limit on h.  Coordinates are differenced from a before
any product, so UTM-sized coordinates lose nothing.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError, check_number

__all__ = ["SectionFrame", "section_frame", "section_coordinates", "section_indices", "section", "cut_section",
           "slab_indices", "read_near_section", "ATTRIBUTES", "MAX_WIDTH"]

ATTRIBUTES = ("section_s", "section_h", "section_d")
"""The attributes a section adds: along, height, offset (m)."""

MAX_WIDTH = 1e6
"""Largest slab width (m)."""

_BLOCK = 1 << 20
"""Points per block of the slab test (bounds the temporaries)."""


@dataclass(frozen=True)
class SectionFrame:
    """A cut: origin ``a``, unit axes ``along`` (s), ``up`` (h), ``normal`` (d), ``length`` and ``width``
    (coordinate units, as the origin), ``unit`` (metres per coordinate unit)."""

    origin: np.ndarray
    along: np.ndarray
    up: np.ndarray
    normal: np.ndarray
    length: float
    width: float
    vertical: bool
    unit: float = 1.0

    def describe(self) -> dict[str, Any]:
        """JSON-ready facts of the frame: the origin in coordinates, length and width in metres."""
        def r(v):
            return [round(float(t), 9) for t in v]

        return {"origin": [float(t) for t in self.origin], "along": r(self.along), "up": r(self.up),
                "normal": r(self.normal), "length": float(self.length) * self.unit,
                "width": float(self.width) * self.unit, "vertical": self.vertical, "unit_to_metre": self.unit}


def _point(name: str, value) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        v = np.zeros(0)
    if v.size not in (2, 3) or not np.isfinite(v).all():
        raise LidarfxError(f"{name} must be 2 or 3 finite numbers x,y[,z], got {value!r}")
    return v


def section_frame(start, end, width: float, normal=None, *, unit: float = 1.0) -> SectionFrame:
    """The frame of a section from ``start`` to ``end`` (x, y[, z], coordinates) of slab ``width``
    (m), vertical or with the cut plane's ``normal`` (see the module docstring); one-line errors
    for a zero width, equal ends, a zero normal or one parallel to the line.  ``unit``: metres per
    coordinate unit of the cloud (:func:`lidarfx.crs.unit_to_metre`), which converts the width."""
    width = check_number("width", width, 0.0, MAX_WIDTH, open_lo=True) / unit
    a, b = _point("from", start), _point("to", end)
    if normal is None:
        t = b[:2] - a[:2]
        length = math.hypot(float(t[0]), float(t[1]))
        if not length > 0:
            raise LidarfxError("from and to are the same point in plan view; a section needs a line")
        along = np.array([t[0] / length, t[1] / length, 0.0])
        up = np.array([0.0, 0.0, 1.0])
        origin = np.array([a[0], a[1], a[2] if a.size == 3 else 0.0])
        return SectionFrame(origin, along, up, np.cross(along, up), length, width, True, unit)
    n = _point("normal", normal)
    if n.size != 3:
        raise LidarfxError(f"normal must be 3 finite numbers nx,ny,nz, got {normal!r}")
    norm = float(np.linalg.norm(n))
    if not norm > 0 or not math.isfinite(norm):
        raise LidarfxError(f"normal must not be zero, got {normal!r}")
    n = n / norm
    if a.size != 3:
        raise LidarfxError("with a normal, from needs x,y,z: the cut plane goes through it")
    b = np.array([b[0], b[1], b[2] if b.size == 3 else a[2]])
    v = b - a
    vlen = float(np.linalg.norm(v))
    if not vlen > 0:
        raise LidarfxError("from and to are the same point; a section needs a line")
    v_in = v - float(v @ n) * n
    length = float(np.linalg.norm(v_in))
    if not length > 1e-9 * vlen:
        raise LidarfxError("the normal is parallel to the line from -> to; the line must run along the cut plane")
    along = v_in / length
    up = np.cross(n, along)
    if up[2] < 0:
        up = -up
    return SectionFrame(a, along, up, n, length, width, False, unit)


def section_coordinates(xyz: np.ndarray, frame: SectionFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(s, h, d)`` of every point (float64)."""
    p = np.asarray(xyz, dtype=np.float64) - frame.origin
    return p @ frame.along, p @ frame.up, p @ frame.normal


def slab_indices(xyz: np.ndarray, frame: SectionFrame, margin: float = 0.0) -> np.ndarray:
    """Indices (ascending) of the points in the slab of ``frame``, widened by ``margin`` across
    the plane and beyond both ends (in blocks of points, so temporaries stay small)."""
    half = 0.5 * frame.width + margin
    out = []
    for a in range(0, len(xyz), _BLOCK):
        p = xyz[a:a + _BLOCK] - frame.origin
        d = p @ frame.normal
        s = p @ frame.along
        out.append(a + np.flatnonzero((np.abs(d) <= half) & (s >= -margin) & (s <= frame.length + margin)))
    return np.concatenate(out) if out else np.zeros(0, np.int64)


def section_indices(xyz: np.ndarray, start, end, width: float, normal=None):
    """``(idx, s, h, d)``: indices (ascending) of the points in the slab and their section
    coordinates (see the module docstring)."""
    frame = section_frame(start, end, width, normal)
    xyz = np.asarray(xyz, dtype=np.float64)
    idx = slab_indices(xyz, frame)
    return (idx, *section_coordinates(xyz[idx], frame))


def section(cloud: PointCloud, start, end, width: float, normal=None, *, units: str = "auto") -> PointCloud:
    """The points of ``cloud`` in the slab, with their attributes and ``section_s``,
    ``section_h``, ``section_d`` (float64, coordinate units); ``meta["section"]`` describes the
    frame.  ``width`` is metres, converted when the LAS header's CRS names another linear unit
    (US survey feet, feet; ``units="native"``: coordinate units); ``start``, ``end`` are
    coordinates."""
    from .crs import metres_per_unit

    frame = section_frame(start, end, width, normal, unit=metres_per_unit(cloud, units))
    return cut_section(cloud, frame)


def cut_section(cloud: PointCloud, frame: SectionFrame) -> PointCloud:
    """:func:`section` for a frame made already."""
    idx = slab_indices(cloud.xyz, frame)
    out = cloud.subset(idx)
    s, h, d = section_coordinates(out.xyz, frame)
    out.update(dict(zip(ATTRIBUTES, (s, h, d))))
    out.meta = {**cloud.meta, "section": frame.describe()}
    return out


def read_near_section(path: str | os.PathLike, frame: SectionFrame, margin: float = 0.0, *,
                      columns: Sequence[str] | None = None, progress: bool | None = None) -> PointCloud:
    """The points of a file within the slab widened by ``margin`` (e.g. a feature radius, so
    the slab points have all their neighbours; m, converted by ``frame.unit`` as the width).
    LAS/LAZ files are read in chunks and only these points are kept; other formats are read
    whole."""
    margin = float(margin) / frame.unit
    from . import io
    from .io import las

    p = Path(path)
    if io.input_format(p) != "las":
        cloud = io.read(p, columns=columns, progress=progress)
        return cloud.subset(slab_indices(cloud.xyz, frame, margin))
    if columns is not None:
        raise LidarfxError(f"{p}: a column spec applies only to text and .npy files")
    import laspy

    from .io import one_line

    try:
        header = las.read_header(p)
    except las.READ_ERRORS as exc:
        raise LidarfxError(f"cannot read {p}: {one_line(exc)}") from exc
    parts = [las.record_cloud(laspy.PackedPointRecord.empty(header.point_format), header)]  # names, even for no points
    with io.progress_bar(int(header.point_count), f"reading {p.name}", progress) as advance:
        for _, rec, hdr in las.iter_records(p):
            parts.append(las.record_cloud(rec[slab_indices(las.record_xyz(rec, hdr), frame, margin)], hdr))
            advance(len(rec))
    out = PointCloud.concatenate(parts)
    out.meta.update({"source": str(p.resolve()), "format": "las"})
    return out
