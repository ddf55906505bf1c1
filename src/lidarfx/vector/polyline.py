"""The one record type of every vector product: a 3-D polyline with its support."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import LidarfxError


@dataclass
class Polyline:
    """A 3-D polyline in the cloud's coordinates (world coordinates, like ``cloud.xyz``).

    ``vertices`` (k, 3) float64, k ≥ 2; ``closed`` repeats no vertex (writers close
    the ring themselves); ``support`` the number of points the line was fitted
    to; ``rms`` the RMS distance of those points to the line (m, NaN if unknown);
    ``kind`` a short class name (``"edge"``, ``"border"``, ``"wire"`` …) that
    writers use as layer name; ``attrs`` further properties (JSON scalars)
    written to GeoJSON properties and CSV columns.
    """

    vertices: np.ndarray
    support: int = 0
    rms: float = math.nan
    kind: str = "line"
    closed: bool = False
    attrs: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(np.asarray(self.vertices, dtype=np.float64))
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 2:
            raise LidarfxError(f"a polyline needs at least 2 vertices of 3 coordinates, got shape {v.shape}")
        if not np.isfinite(v).all():
            raise LidarfxError("polyline vertices must be finite")
        self.vertices = v

    @property
    def n_vertices(self) -> int:
        return int(len(self.vertices))

    @property
    def ring(self) -> np.ndarray:
        """The vertices, with the first repeated at the end when ``closed``."""
        return np.vstack([self.vertices, self.vertices[:1]]) if self.closed else self.vertices

    @property
    def length(self) -> float:
        """3-D length (m), the closing segment included."""
        return float(np.linalg.norm(np.diff(self.ring, axis=0), axis=1).sum())

    @property
    def length_2d(self) -> float:
        """Plan-view length (m)."""
        return float(np.linalg.norm(np.diff(self.ring[:, :2], axis=0), axis=1).sum())

    def properties(self) -> dict[str, Any]:
        """The flat property record writers use (id excluded): kind, n_vertices, length,
        length_2d, support, rms, z_min, z_max, closed, then ``attrs``."""
        z = self.vertices[:, 2]
        out: dict[str, Any] = {
            "kind": self.kind,
            "n_vertices": self.n_vertices,
            "length": round(self.length, 4),
            "length_2d": round(self.length_2d, 4),
            "support": int(self.support),
            "rms": None if not math.isfinite(self.rms) else round(float(self.rms), 4),
            "z_min": round(float(z.min()), 4),
            "z_max": round(float(z.max()), 4),
            "closed": bool(self.closed),
        }
        for k, v in self.attrs.items():
            if k in out:
                raise LidarfxError(f"polyline attribute {k!r} clashes with a built-in property")
            out[k] = v
        return out
