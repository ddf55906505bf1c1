"""Reading, writing and summarising point-cloud files.

One entry point per job, dispatching on the file extension (case-insensitive):

===========================================  ==========================
extension                                    module
===========================================  ==========================
``.las`` ``.laz``                            :mod:`lidarfx.io.las`
``.ply``                                     :mod:`lidarfx.io.ply`
``.xyz`` ``.txt`` ``.csv`` ``.pts``          :mod:`lidarfx.io.ascii`
``.xyz_label_conf`` (Oakland 3-D)            :mod:`lidarfx.io.ascii`
``.npy`` ``.npz``                            :mod:`lidarfx.io.npy`
===========================================  ==========================

Every format module exposes ``read(path, *, columns, progress)``,
``write(cloud, path, *, ext, progress, **opts)``, ``READ_ERRORS`` (the library
exceptions that mean "this file is damaged") and ``ACCEPTS_COLUMNS``.
Format modules are imported on first use so ``lidarfx --help`` stays fast.
"""
from __future__ import annotations

import importlib
import inspect
import os
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .._atomic import atomic_path, check_not_same_file, check_output_folder
from ..cloud import PointCloud, measurement_flags
from ..errors import LidarfxError
from ..progress import bar as _bar
from ..progress import wanted as _wanted

__all__ = ["read", "write", "info", "accepts_columns", "input_format", "FORMATS", "ASPRS_CLASSES", "progress_bar"]

FORMATS: dict[str, str] = {
    ".las": "las",
    ".laz": "las",
    ".ply": "ply",
    ".xyz": "ascii",
    ".txt": "ascii",
    ".csv": "ascii",
    ".pts": "ascii",
    ".xyz_label_conf": "ascii",
    ".npy": "npy",
    ".npz": "npy",
}
"""Lower-case file extension -> format module name."""

DENSITY_CELL_M = 1.0
"""Edge of the grid cells (metres) used for the occupied-area density."""

ASPRS_CLASSES: dict[int, str] = {
    0: "never classified",
    1: "unclassified",
    2: "ground",
    3: "low vegetation",
    4: "medium vegetation",
    5: "high vegetation",
    6: "building",
    7: "low point (noise)",
    8: "model key-point",
    9: "water",
    10: "rail",
    11: "road surface",
    12: "overlap",
    13: "wire - guard (shield)",
    14: "wire - conductor (phase)",
    15: "transmission tower",
    16: "wire-structure connector",
    17: "bridge deck",
    18: "high noise",
    19: "overhead structure",
    20: "ignored ground",
    21: "snow",
    22: "temporal exclusion",
}
"""ASPRS LAS 1.4 (R15) class names; 8 and 12 are the LAS 1.0-1.3 meanings."""


# ----------------------------------------------------------------- helpers
def _format_module(path: Path):
    ext = path.suffix.lower()
    try:
        name = FORMATS[ext]
    except KeyError:
        known = " ".join(sorted(FORMATS))
        raise LidarfxError(
            f"{path}: unknown file extension {path.suffix or '(none)'!r}; known: {known}"
        ) from None
    return importlib.import_module(f"{__name__}.{name}")


def check_output_path(path: str | os.PathLike) -> Path:
    """Refuse an output path before any work: unknown extension or a missing folder."""
    p = Path(path)
    _format_module(p)
    check_output_folder(p)
    return p


def _input_module(path: Path):
    """The format module for an existing input file (else a one-line error)."""
    if not path.exists():
        raise LidarfxError(f"file not found: {path}")
    if path.is_dir():
        raise LidarfxError(f"{path} is a folder, not a point-cloud file")
    if not path.is_file():
        raise LidarfxError(f"not a file: {path}")
    return _format_module(path)


def input_format(path: str | os.PathLike) -> str:
    """Format module name (``"las"``, ``"ply"``, ``"ascii"``, ``"npy"``) of an existing input file;
    a one-line error for a missing file, a folder or an unknown extension."""
    return _input_module(Path(path)).__name__.rsplit(".", 1)[-1]


def accepts_columns(path: str | os.PathLike) -> bool:
    """True when ``path``'s format takes a column spec (text and plain ``.npy``); a one-line
    error for a missing file, a folder or an unknown extension."""
    p = Path(path)
    return bool(_input_module(p).ACCEPTS_COLUMNS) and p.suffix.lower() != ".npz"  # .npz arrays are named


def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or exc.__class__.__name__
    return text if len(text) <= 200 else text[:197] + "..."


def progress_bar(total: int, description: str, enabled: bool | None):
    """``lidarfx.progress.bar`` for reading/writing ``total`` points (automatic: by the expected time, on a terminal)."""
    return _bar(description, total, _wanted(enabled))


def _normalise_columns(columns: str | Sequence[str] | None) -> list[str] | None:
    if columns is None:
        return None
    if isinstance(columns, str):
        columns = columns.split(",")
    return [str(c).strip() for c in columns]


# --------------------------------------------------------------- read/write
def read(
    path: str | os.PathLike,
    *,
    columns: str | Sequence[str] | None = None,
    progress: bool | None = None,
) -> PointCloud:
    """Read a point cloud from any supported file.

    Parameters
    ----------
    path:
        File to read; the extension chooses the format (see :data:`FORMATS`).
    columns:
        Column spec for text and plain ``.npy`` files, e.g.
        ``["x", "y", "z", "intensity", "classification"]`` or ``"x,y,z,-,label"``
        (``"-"`` / ``"skip"`` drops a column).  Rejected for other formats.
    progress:
        ``True`` shows a progress bar, ``False`` never; ``None`` decides by size.

    Returns
    -------
    PointCloud
        ``meta["source"]`` holds the resolved input path, ``meta["format"]`` the
        format module name.

    Raises
    ------
    LidarfxError
        Unknown extension, missing file, bad column spec or damaged file; the
        message is one line and names the file.
    """
    p = Path(path)
    module = _input_module(p)
    cols = _normalise_columns(columns)
    if cols is not None and not module.ACCEPTS_COLUMNS:
        raise LidarfxError(f"{p}: a column spec applies only to text and .npy files")
    try:
        cloud = module.read(p, columns=cols, progress=progress)
    except LidarfxError as exc:  # name the file in the message
        if str(p) in str(exc):
            raise
        raise LidarfxError(f"{p}: {exc}") from exc
    except module.READ_ERRORS as exc:
        raise LidarfxError(f"cannot read {p}: {one_line(exc)}") from exc
    cloud = finite_points(cloud, p)
    cloud.meta["source"] = str(p.resolve())
    cloud.meta["format"] = module.__name__.rsplit(".", 1)[-1]
    return cloud


MAX_COORDINATE = 1e12
"""Largest coordinate magnitude read (a billion kilometres, or millimetres of the whole Earth):
beyond it a value is no survey coordinate, and its squares would overflow the analyses."""


def finite_points(cloud: PointCloud, path: str | os.PathLike) -> PointCloud:
    """The one rule for unusable coordinates, applied to every file read: points with a NaN or
    infinite x, y or z, or one beyond :data:`MAX_COORDINATE` (PLY, text and NumPy files can hold
    them; LAS/LAZ headers that could give them are refused, see
    :func:`lidarfx.io.las.check_header`), are left out with one warning naming how many; a file
    with points but none of them usable is an error."""
    with np.errstate(invalid="ignore"):
        ok = (np.abs(cloud.xyz) <= MAX_COORDINATE).all(axis=1)  # False for NaN too
    bad = len(ok) - int(np.count_nonzero(ok))
    if bad == 0:
        return cloud
    what = f"a NaN, infinite or out-of-range (beyond ±{MAX_COORDINATE:g}) x, y or z"
    if bad == len(ok):
        raise LidarfxError(f"{path}: no point has usable coordinates (all {bad} have {what})")
    import warnings

    from ..errors import LidarfxWarning

    warnings.warn(f"{path}: {bad} of {len(ok)} points have {what} and are left out", LidarfxWarning, stacklevel=3)
    return cloud.subset(ok)


def write(
    cloud: PointCloud,
    path: str | os.PathLike,
    *,
    progress: bool | None = None,
    fill: Callable[[int, int], dict[str, np.ndarray]] | None = None,
    **opts: Any,
) -> Path:
    """Write ``cloud`` to ``path``; the extension chooses the format.

    The file is written to a temporary name in the target folder and renamed at
    the end, so a failure never leaves a partial output.  Writing over the
    cloud's own input file (``cloud.meta["source"]``) is refused.

    Format options (``**opts``): LAS/LAZ ``point_format``, ``scale``; PLY
    ``ascii``; text ``precision``, ``delimiter``; ``.npz`` ``compressed``.
    Unknown options raise :class:`LidarfxError`.

    ``fill(start, stop)`` streams attributes: it returns the values of points
    ``start:stop`` for attributes the cloud holds only as placeholders (e.g.
    ``np.broadcast_to(np.float32(np.nan), n)``), and is called in order over
    the whole cloud.  LAS/LAZ call it once per written chunk, so those
    attributes never exist in full; other formats collect them first.

    Returns the output path.
    """
    p = Path(path)
    module = _format_module(p)
    allowed = [
        name
        for name, prm in inspect.signature(module.write).parameters.items()
        if prm.kind is inspect.Parameter.KEYWORD_ONLY and name not in ("ext", "progress", "fill")
    ]
    unknown = sorted(set(opts) - set(allowed))
    if unknown:
        raise LidarfxError(
            f"{p}: option(s) {', '.join(unknown)} not supported for {p.suffix} output"
            f" (supported: {', '.join(allowed) or 'none'})"
        )
    source = cloud.meta.get("source")
    if source:
        check_not_same_file(source, p)
    if fill is not None:
        if "fill" in inspect.signature(module.write).parameters:
            opts["fill"] = fill
        else:
            cloud = _collect_filled(cloud, fill)
    with atomic_path(p) as tmp:
        try:
            module.write(cloud, tmp, ext=p.suffix.lower(), progress=progress, **opts)
        except LidarfxError as exc:  # name the file in the message
            if str(p) in str(exc):
                raise
            raise LidarfxError(f"{p}: {exc}") from exc
        except OSError as exc:  # disk full, permissions, ...
            raise LidarfxError(f"cannot write {p}: {exc.strerror or one_line(exc)}") from exc
    return p


def _collect_filled(cloud: PointCloud, fill: Callable[[int, int], dict[str, np.ndarray]]) -> PointCloud:
    """A copy of ``cloud`` whose streamed attributes are filled in full."""
    out = PointCloud(cloud.xyz, dict(cloud.attrs), cloud.header, cloud.meta)
    n = len(cloud)
    full: dict[str, np.ndarray] = {}
    step = 1 << 16
    for a in range(0, n, step):
        b = min(n, a + step)
        for name, values in fill(a, b).items():
            if name not in full:
                full[name] = np.empty(n, dtype=np.asarray(values).dtype)
            full[name][a:b] = values
    out.update(full)
    return out


# ---------------------------------------------------------------------- info
class _Summary:
    """Streaming accumulator for :func:`info`: feed chunks, read the result once."""

    def __init__(self, unit_to_metre: float) -> None:
        self.cell = DENSITY_CELL_M / unit_to_metre  # cell edge in coordinate units
        self.unit_to_metre = unit_to_metre
        self.n = 0
        self.lo = np.full(3, np.inf)
        self.hi = np.full(3, -np.inf)
        self.cells: list[np.ndarray] = []
        # measured points (cloud.measurement_flags), split by return number > 0 / = 0 because
        # whether the zeros count is decided over the whole file
        self.measured = {True: [0, []], False: [0, []]}
        self.any_returned = False
        self.counts: dict[str, dict[int, int]] = {}
        self.dtypes: dict[str, str] = {}

    def add(self, xyz: np.ndarray, attrs: dict[str, np.ndarray]) -> None:
        for name, arr in attrs.items():
            self.dtypes.setdefault(name, str(arr.dtype))
        if len(xyz) == 0:
            return
        self.n += len(xyz)
        self.lo = np.minimum(self.lo, xyz.min(axis=0))
        self.hi = np.maximum(self.hi, xyz.max(axis=0))
        with np.errstate(invalid="ignore"):
            ix = np.floor(xyz[:, 0] / self.cell).astype(np.int64)
            iy = np.floor(xyz[:, 1] / self.cell).astype(np.int64)
        key = (ix << 32) + (iy & 0xFFFFFFFF)
        self.cells.append(np.unique(key))
        ok, returned = measurement_flags(xyz, attrs)
        self.any_returned |= returned is not None and bool(returned.any())
        parts = {True: ok} if returned is None else {True: ok & returned, False: ok & ~returned}
        for positive, m in parts.items():
            acc = self.measured[positive]
            acc[0] += int(m.sum())
            acc[1].append(np.unique(key[m]))
        for name in ("classification", "return_number", "number_of_returns"):
            if name in attrs:
                values, counts = np.unique(attrs[name], return_counts=True)
                acc = self.counts.setdefault(name, {})
                for v, c in zip(values.tolist(), counts.tolist()):
                    acc[v] = acc.get(v, 0) + c

    def result(self) -> dict[str, Any]:
        out: dict[str, Any] = {"points": int(self.n)}
        if self.n == 0:
            out.update(bounds=None, density=None)
        else:
            occupied = int(np.unique(np.concatenate(self.cells)).size)
            with np.errstate(over="ignore", invalid="ignore"):  # extents beyond float64 squares: no area
                dx, dy = (self.hi[:2] - self.lo[:2]) * self.unit_to_metre
                area = float(dx * dy)
            out["bounds"] = {"min": self.lo.tolist(), "max": self.hi.tolist()}
            out["density"] = {
                "per_m2_occupied_cells": self.n / (occupied * DENSITY_CELL_M**2),
                "per_m2_bbox": self.n / area if 0 < area < np.inf else None,
                "occupied_cells": occupied,
                "cell_size_m": DENSITY_CELL_M,
                "measured": self._measured(),
            }
        classes = self.counts.get("classification")
        out["classes"] = (
            None
            if classes is None
            else [
                {"code": int(k), "name": ASPRS_CLASSES.get(int(k)), "count": int(c)}
                for k, c in sorted(classes.items())
            ]
        )
        returns = {
            name: {str(int(k)): int(c) for k, c in sorted(self.counts[name].items())}
            for name in ("return_number", "number_of_returns")
            if name in self.counts
        }
        out["returns"] = returns or None
        out["attributes"] = dict(self.dtypes)
        return out


    def _measured(self) -> dict[str, Any] | None:
        """Density of the real measurements (no virtual / withheld / synthetic points), or None
        when that is every point."""
        pos, zero = self.measured[True], self.measured[False]
        n, parts = (pos[0], pos[1]) if self.any_returned else (pos[0] + zero[0], pos[1] + zero[1])
        if n == self.n:
            return None
        occupied = int(np.unique(np.concatenate(parts)).size) if n else 0
        return {"points": n, "occupied_cells": occupied,
                "per_m2_occupied_cells": n / (occupied * DENSITY_CELL_M**2) if occupied else 0.0}


def info(source: str | os.PathLike | PointCloud) -> dict[str, Any]:
    """Summarise a file or an in-memory cloud as a JSON-serialisable dict.

    Keys: ``file``, ``format``, ``points``, ``bounds`` (``min``/``max`` xyz),
    ``density``, ``classes`` (list of ``{code, name, count}``; names are ASPRS),
    ``returns`` (histograms of ``return_number`` / ``number_of_returns``),
    ``attributes`` (name -> dtype), ``crs`` and ``las`` (version, point format,
    scales, offsets, VLRs; ``None`` for other formats).

    Density is given two ways, both in points per square metre:
    ``per_m2_occupied_cells`` = n / (number of occupied 1 m x 1 m grid cells, in
    plan view), robust to irregular outlines and holes; ``per_m2_bbox`` =
    n / area of the xy bounding box, the figure most tools print.  When the CRS
    says the coordinates are in feet, the grid and the area are converted to
    metres; with no CRS the coordinates are taken as metres; with geographic
    (longitude/latitude) coordinates ``density`` is ``None``.

    LAS/LAZ files are streamed in chunks, so files larger than memory work.
    """
    from . import las

    if isinstance(source, PointCloud):
        header = source.header if isinstance(source.header, las.LasHeader) else None
        chunks: Any = [source]
        out: dict[str, Any] = {
            "file": source.meta.get("source"),
            "format": source.meta.get("format"),
        }
    else:
        p = Path(source)
        module = _input_module(p)
        out = {"file": str(p), "format": module.__name__.rsplit(".", 1)[-1]}
        if module is las:
            try:
                header = las.read_header(p)
                chunks = las.iter_chunks(p)
            except las.READ_ERRORS as exc:
                raise LidarfxError(f"cannot read {p}: {one_line(exc)}") from exc
        else:
            cloud = read(p)
            header, chunks = None, [cloud]
    crs = las.crs_info(header) if header is not None else None
    unit = (crs or {}).get("unit_to_metre") or 1.0
    summary = _Summary(unit)
    try:
        for chunk in chunks:
            summary.add(chunk.xyz, chunk.attrs)
    except las.READ_ERRORS as exc:
        raise LidarfxError(f"cannot read {out['file']}: {one_line(exc)}") from exc
    out.update(summary.result())
    if (crs or {}).get("geographic"):
        out["density"] = None  # degrees: no metric area without a projection
    elif out["density"] is not None:
        out["density"]["unit_to_metre"] = unit
        out["density"]["unit_assumed"] = not (crs or {}).get("unit_to_metre")
    out["crs"] = crs
    out["las"] = las.header_info(header) if header is not None else None
    return out
