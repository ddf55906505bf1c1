"""The in-memory point cloud: float64 xyz, named per-point attributes, LAS pass-through.

Kernels never see this class; they take numpy arrays.  ``PointCloud`` is the
container that travels between readers, feature computation and writers.
"""
from __future__ import annotations

from typing import Any, Iterable, Iterator, Mapping

import numpy as np

from .errors import LidarfxError

__all__ = ["PointCloud", "measurement_flags"]


def measurement_flags(xyz: np.ndarray, attrs: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray | None]:
    """``(ok, returned)`` per point: ``ok`` = finite coordinates, not withheld, not synthetic;
    ``returned`` = ``return_number > 0`` (None without return numbers).

    A point is a real measurement when it is ``ok`` and, if any point of the cloud has a
    return number above 0, ``returned``: IGN LiDAR HD *virtual* points (class 66) have
    return number 0.  One definition for the classifier's usable points and ``info``'s
    measured density; a caller that sees a cloud in chunks applies the "any point" part
    over the whole cloud.
    """
    ok = np.all(np.isfinite(xyz), axis=1)
    for flag in ("withheld", "synthetic"):
        if flag in attrs:
            ok &= np.asarray(attrs[flag]) == 0
    returned = np.asarray(attrs["return_number"]) > 0 if "return_number" in attrs else None
    return ok, returned


class PointCloud:
    """A point cloud: ``xyz`` (n×3 float64) plus named 1-D attribute arrays.

    Parameters
    ----------
    xyz:
        Coordinates, anything convertible to an ``(n, 3)`` float64 array.
    attrs:
        Per-point attributes, each a 1-D array of length n (``intensity``,
        ``classification``, ``red``, every computed feature, ...).
    header:
        Opaque format header carried through unchanged (for LAS/LAZ a
        ``laspy.LasHeader`` holding version, point format, scales, offsets,
        CRS, VLRs and EVLRs).  Only :mod:`lidarfx.io` looks inside it.
    meta:
        Free-form metadata (source path, format name, ...).

    Attribute access: ``cloud["planarity"]``, ``cloud["planarity"] = arr``,
    ``"planarity" in cloud``, ``cloud.names``.
    """

    __slots__ = ("xyz", "_attrs", "header", "meta")

    def __init__(
        self,
        xyz: Any,
        attrs: Mapping[str, Any] | None = None,
        header: Any = None,
        meta: Mapping[str, Any] | None = None,
    ) -> None:
        arr = np.ascontiguousarray(np.asarray(xyz, dtype=np.float64))
        if arr.ndim != 2 or arr.shape[1] != 3:
            if arr.size == 0:
                arr = arr.reshape(0, 3)
            else:
                raise LidarfxError(f"xyz must have shape (n, 3), got {arr.shape}")
        self.xyz = arr
        self._attrs: dict[str, np.ndarray] = {}
        self.header = header
        self.meta: dict[str, Any] = dict(meta or {})
        for name, values in (attrs or {}).items():
            self[name] = values

    # ------------------------------------------------------------------ basics
    def __len__(self) -> int:
        return int(self.xyz.shape[0])

    @property
    def n(self) -> int:
        """Number of points."""
        return len(self)

    @property
    def x(self) -> np.ndarray:
        return self.xyz[:, 0]

    @property
    def y(self) -> np.ndarray:
        return self.xyz[:, 1]

    @property
    def z(self) -> np.ndarray:
        return self.xyz[:, 2]

    @property
    def names(self) -> list[str]:
        """Attribute names in insertion order."""
        return list(self._attrs)

    @property
    def attrs(self) -> dict[str, np.ndarray]:
        """The attribute dictionary (a live view: assign through ``cloud[name] = ...``)."""
        return self._attrs

    def __contains__(self, name: object) -> bool:
        return name in self._attrs

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self._attrs[name]
        except KeyError:
            avail = ", ".join(self._attrs) or "none"
            raise LidarfxError(f"unknown attribute {name!r}; available: {avail}") from None

    def __setitem__(self, name: str, values: Any) -> None:
        if not isinstance(name, str) or not name:
            raise LidarfxError("attribute names must be non-empty strings")
        arr = np.asarray(values)
        if arr.ndim == 0:
            arr = np.full(len(self), arr)
        if arr.ndim != 1 or arr.shape[0] != len(self):
            raise LidarfxError(
                f"attribute {name!r} must be a 1-D array of length {len(self)}, got shape {arr.shape}"
            )
        self._attrs[name] = arr

    def __delitem__(self, name: str) -> None:
        del self._attrs[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._attrs)

    def get(self, name: str, default: Any = None) -> Any:
        return self._attrs.get(name, default)

    def update(self, attrs: Mapping[str, Any]) -> "PointCloud":
        """Set several attributes; returns ``self`` for chaining."""
        for k, v in attrs.items():
            self[k] = v
        return self

    # ------------------------------------------------------------- derivation
    @property
    def origin(self) -> np.ndarray:
        """Local origin used by every kernel: the per-axis minimum (zeros when empty)."""
        if len(self) == 0:
            return np.zeros(3)
        return self.xyz.min(axis=0)

    def local_xyz(self, origin: Iterable[float] | None = None) -> np.ndarray:
        """Coordinates relative to ``origin`` (default: :attr:`origin`), float64, C-contiguous."""
        o = self.origin if origin is None else np.asarray(origin, dtype=np.float64)
        return np.ascontiguousarray(self.xyz - o)

    def subset(self, index: Any) -> "PointCloud":
        """A new cloud holding the points selected by a boolean mask or an index array."""
        idx = np.asarray(index)
        if idx.dtype == bool and idx.shape != (len(self),):
            raise LidarfxError(f"mask must have length {len(self)}, got {idx.shape}")
        return PointCloud(
            self.xyz[idx],
            {k: v[idx] for k, v in self._attrs.items()},
            header=self.header,
            meta=self.meta,
        )

    def copy(self) -> "PointCloud":
        """A deep copy of coordinates and attributes (the header object is shared)."""
        return PointCloud(
            self.xyz.copy(), {k: v.copy() for k, v in self._attrs.items()}, self.header, self.meta
        )

    @classmethod
    def concatenate(cls, clouds: "list[PointCloud]") -> "PointCloud":
        """Stack clouds; attributes missing in some clouds are filled with NaN / 0."""
        if not clouds:
            return cls(np.empty((0, 3)))
        names: list[str] = []
        for c in clouds:
            names += [k for k in c.names if k not in names]
        attrs = {}
        for k in names:
            ref = next(c[k] for c in clouds if k in c)
            fill = np.nan if ref.dtype.kind == "f" else 0
            attrs[k] = np.concatenate(
                [c[k] if k in c else np.full(len(c), fill, dtype=ref.dtype) for c in clouds]
            )
        return cls(np.vstack([c.xyz for c in clouds]), attrs, clouds[0].header, clouds[0].meta)

    def __repr__(self) -> str:
        names = ", ".join(self._attrs)
        return f"PointCloud(n={len(self)}, attrs=[{names}])"
