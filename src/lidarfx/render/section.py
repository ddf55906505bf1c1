"""Picture of a section (:func:`lidarfx.section.section`): the profile, coloured by an attribute."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..cloud import PointCloud
from ..errors import LidarfxError

__all__ = ["section_view", "CLASS_NAMES"]

CLASS_NAMES = ("class", "classification")
"""Values of ``by`` that colour the points by their ASPRS class (a legend instead of a colour bar)."""

_LABELS = {"section_d": "offset from the cut plane, d [m]", "section_s": "along the section, s [m]",
           "section_h": "height in the cut plane, h [m]", "z": "z [m]", "x": "x [m]", "y": "y [m]"}


def _azimuth(v: np.ndarray) -> float:
    return math.degrees(math.atan2(float(v[0]), float(v[1]))) % 360.0


def section_view(
    cloud: PointCloud,
    path: str | Path,
    *,
    by: str = "section_d",
    cmap: str = "viridis",
    value_range: tuple[float, float] | None = None,
    title: str | None = None,
    pixels: int = 1400,
    dpi: int = 130,
) -> Path:
    """Save a PNG of a section: ``section_s`` to the right, ``section_h`` up, equal scales.

    The points are coloured by ``by``: any numeric attribute (``x``, ``y``, ``z`` included)
    through the colour map ``cmap`` over ``value_range`` (default: the 2nd–98th percentile of its
    finite values; NaN grey) with a colour bar, or ``class`` / ``classification`` (ASPRS
    colours, a legend with the points per class).  The picture is a raster of about ``pixels``
    cells along the longer side; each point covers a small disc (from the point spacing) and
    each cell shows the point nearest the viewer, who looks at the cut plane from its
    ``section_d > 0`` side (so ``s`` runs to the right).  Axes in metres.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..colour import zbuffer, colour_cloud, key_panel, picture_key
    from . import save_figure

    missing = [a for a in ("section_s", "section_h", "section_d") if a not in cloud]
    if missing:
        raise LidarfxError(f"a section picture needs {', '.join(missing)} (from lidarfx.section.section)")
    if len(cloud) == 0:
        raise LidarfxError("the section holds no points; nothing to draw")
    mode = "class" if by in CLASS_NAMES else by
    coloured = colour_cloud(cloud, mode, cmap=cmap, value_range=value_range)
    rgb = np.column_stack([coloured["red"], coloured["green"], coloured["blue"]]).astype(np.float64) / 65535.0
    meta = coloured.meta["colour"]
    s = np.asarray(cloud["section_s"], dtype=np.float64)
    h = np.asarray(cloud["section_h"], dtype=np.float64)
    d = np.asarray(cloud["section_d"], dtype=np.float64)
    img, cell, nu, nv, u0, v0 = zbuffer(s, h, d, rgb, pixels)

    frame = cloud.meta.get("section") or {}
    span_s = max(nu * cell, float(frame.get("length") or 0.0))
    aspect = nv * cell / max(span_s, 1e-9)
    w, ht = (8.0, max(2.0, 8.0 * aspect)) if aspect * 8.0 <= 9.0 else (max(3.0, 9.0 / aspect), 9.0)
    if meta.get("by") == "morphology":  # the aspect/slope disc needs a panel; a colour bar goes beside
        fig, (ax, kx) = plt.subplots(1, 2, figsize=(w + 2.6, ht + 1.1), gridspec_kw={"width_ratios": [w, 1.6]})
    else:
        fig, ax = plt.subplots(figsize=(w + (1.7 if key_panel(meta) else 2.8), ht + 1.1))
        kx = None
    ax.imshow(img, origin="lower", interpolation="nearest", extent=(u0, u0 + nu * cell, v0, v0 + nv * cell))
    ax.set_aspect("equal")
    if frame.get("length") is not None:  # the whole section, 0 .. length, even where it is empty
        pad = 0.01 * float(frame["length"])
        ax.set_xlim(min(u0, 0.0) - pad, max(u0 + nu * cell, float(frame["length"])) + pad)
    origin = frame.get("origin")
    if frame.get("vertical", True):
        up = "z [m]" if origin is None or origin[2] == 0 else f"h = z − {origin[2]:g} [m]"
    else:
        up = "h, up in the cut plane [m]"
    start = f" from ({origin[0]:,.2f}, {origin[1]:,.2f})" if origin is not None else ""
    ax.set_xlabel(f"s, along the section{start} [m]", fontsize=8)
    ax.set_ylabel(up, fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, color="0.85", lw=0.4)
    ax.set_axisbelow(True)
    facts = []
    if frame.get("width") is not None:
        facts.append(f"slab {frame['width']:g} m wide")
    if frame.get("along") is not None:
        if frame.get("vertical", True):
            facts.append(f"s towards {_azimuth(np.asarray(frame['along'])):.0f}°, "
                         f"looking towards {_azimuth(-np.asarray(frame['normal'])):.0f}°")
        else:
            facts.append("normal (" + ", ".join(f"{v:.2f}" for v in frame["normal"]) + ")")
    facts.append(f"{len(cloud):,} points")
    head = "; ".join(facts)
    ax.set_title(f"{title}\n{head}" if title else head, fontsize=9)
    label = None
    if meta.get("attribute") is not None:
        name = str(meta["attribute"])
        label = _LABELS.get(name, name)
        if meta.get("range_source", "").startswith("percentiles"):
            label += "  (2–98 % range)"
    picture_key(fig, ax, kx, meta, label=label)
    return save_figure(fig, path, dpi)
