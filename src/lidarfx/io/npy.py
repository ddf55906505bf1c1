"""NumPy files.

``.npy``
    Read: a plain ``(n, k >= 3)`` numeric array (columns ``x, y, z, col3, ...``
    or named by the ``columns`` spec, ``"-"`` skipping one) or a structured
    array with fields ``x``, ``y``, ``z`` (other fields become attributes).
    Write: a plain float64 ``(n, 3 + attributes)`` array in attribute order;
    the names are not stored (use ``.npz`` to keep them).
``.npz``
    Arrays ``xyz`` (n x 3) plus one array per attribute, dtype kept: an exact
    round trip.  ``compressed=True`` deflates the archive.

Pickled (object) arrays are never loaded.
"""
from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from ..cloud import PointCloud
from ..errors import LidarfxError

ACCEPTS_COLUMNS = True
READ_ERRORS = (ValueError, EOFError, OSError, zipfile.BadZipFile, KeyError)

SKIP_NAMES = frozenset({"-", "skip"})
XYZ_KEY = "xyz"


def _plain_columns(arr: np.ndarray, columns: list[str] | None) -> dict[str, np.ndarray]:
    if arr.ndim != 2 or arr.shape[1] < 3 or arr.dtype.kind not in "biuf":
        raise LidarfxError(f"expected a numeric (n, >=3) array, got shape {arr.shape} and dtype {arr.dtype}")
    k = arr.shape[1]
    if columns is None:
        names = ["x", "y", "z"] + [f"col{i}" for i in range(3, k)]
    elif len(columns) > k:
        raise LidarfxError(f"column spec has {len(columns)} names but the array has {k} columns")
    else:
        names = columns
    kept = [n for n in names if n not in SKIP_NAMES]
    if len(set(kept)) != len(kept) or not {"x", "y", "z"} <= set(kept):
        raise LidarfxError(f"column spec must name x, y, z once each (got {', '.join(names)})")
    return {n: np.ascontiguousarray(arr[:, i]) for i, n in enumerate(names) if n not in SKIP_NAMES}


def _to_cloud(columns: dict[str, np.ndarray]) -> PointCloud:
    xyz = np.column_stack([columns.pop(c) for c in ("x", "y", "z")])
    return PointCloud(xyz, columns)


_DEFLATE_MAX_RATIO = 1032
"""Most a deflated stream expands (zlib's own bound, about 1032:1)."""


def _check_header(fh, what: str, available: int) -> None:
    """The array header at ``fh`` against the ``available`` bytes: an array announced larger than
    its data is refused before numpy allocates it."""
    import math

    version = np.lib.format.read_magic(fh)
    start = fh.tell()
    read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
    shape, _fortran, dtype = read_header(fh, max_header_size=10_000)
    if dtype.hasobject:
        raise LidarfxError(f"{what} holds Python objects; not loaded")
    need = math.prod(shape) * dtype.itemsize
    have = available - (fh.tell() - start) - 8  # the magic and version bytes
    if need > have:
        raise LidarfxError(f"{what}: the array header announces shape {shape} ({need} bytes) but {max(0, have)} "
                           f"bytes of data follow (truncated or damaged file)")


def check_sizes(path: Path) -> None:
    """The ``.npy`` array or every ``.npz`` member against the bytes really there (for ``.npz`` the
    member's size, itself checked against its compressed size), before anything is allocated."""
    size = path.stat().st_size
    if path.suffix.lower() != ".npz":
        with open(path, "rb") as fh:
            _check_header(fh, str(path), size)
        return
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            if not info.filename.endswith(".npy"):
                continue
            stored = info.compress_type == zipfile.ZIP_STORED
            if info.file_size > (info.compress_size if stored else info.compress_size * _DEFLATE_MAX_RATIO + 1024):
                raise LidarfxError(f"{path}: member {info.filename} announces {info.file_size} bytes from "
                                   f"{info.compress_size} stored (damaged archive)")
            with zf.open(info) as fh:
                _check_header(fh, f"{path}: member {info.filename}", info.file_size)


def read(path: Path, *, columns: list[str] | None = None, progress: bool | None = None) -> PointCloud:
    """Read a ``.npy`` or ``.npz`` file (see the module docstring)."""
    check_sizes(path)
    if path.suffix.lower() == ".npz":
        if columns is not None:
            raise LidarfxError("a column spec applies to .npy, not .npz (its arrays are named)")
        with np.load(path, allow_pickle=False) as z:
            if XYZ_KEY not in z.files:
                raise LidarfxError(f"no {XYZ_KEY!r} array in the archive (arrays: {', '.join(z.files)})")
            xyz = z[XYZ_KEY]
            attrs = {k: z[k] for k in z.files if k != XYZ_KEY}
        return PointCloud(xyz, attrs)
    arr = np.load(path, allow_pickle=False)
    if arr.dtype.names:
        if columns is not None:
            raise LidarfxError("a column spec applies to plain arrays, not to structured ones")
        missing = [c for c in ("x", "y", "z") if c not in arr.dtype.names]
        if missing:
            raise LidarfxError(f"structured array lacks field(s) {', '.join(missing)}")
        return _to_cloud({n: np.ascontiguousarray(arr[n]) for n in arr.dtype.names})
    return _to_cloud(_plain_columns(arr, columns))


def write(
    cloud: PointCloud,
    path: Path,
    *,
    ext: str = ".npz",
    progress: bool | None = None,
    compressed: bool = False,
) -> None:
    """Write ``.npy`` (plain float64 table) or ``.npz`` (named arrays, exact)."""
    if ext == ".npy":
        if compressed:
            raise LidarfxError("compressed=True applies to .npz only")
        table = np.empty((len(cloud), 3 + len(cloud.names)), dtype=np.float64)
        table[:, :3] = cloud.xyz
        for j, name in enumerate(cloud.names, start=3):
            table[:, j] = cloud[name]
        with open(path, "wb") as fh:
            np.save(fh, table, allow_pickle=False)
        return
    bad = [n for n in cloud.names if n == XYZ_KEY or "/" in n or "\\" in n]
    if bad:
        raise LidarfxError(f"attribute name(s) {bad} cannot be stored in .npz")
    arrays = {XYZ_KEY: cloud.xyz, **cloud.attrs}
    mode = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    # Written member by member (like numpy.savez) so no name can clash with savez's own arguments.
    with zipfile.ZipFile(path, "w", compression=mode, allowZip64=True) as zf:
        for name, arr in arrays.items():
            if arr.dtype.kind == "O":
                raise LidarfxError(f"attribute {name!r} holds Python objects; not stored")
            with zf.open(f"{name}.npy", "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(arr), allow_pickle=False)
