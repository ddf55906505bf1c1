"""LAS / LAZ files (LAS 1.0-1.4, every point format) through laspy + lazrs.

Reading
    ``xyz`` = scaled coordinates (``X * scale + offset``, float64).  Every
    standard dimension becomes an attribute under laspy's name and native dtype
    (bit fields such as ``return_number`` or ``synthetic`` as ``uint8``), every
    extra-bytes dimension too (scaled extra dimensions as float64, multi-element
    ones split into ``name_0``, ``name_1``, ...).  ``cloud.header`` is the
    ``laspy.LasHeader``: version, point format, scales, offsets, VLRs and EVLRs.
    The raw integer X/Y/Z are *not* kept: ``round((x - offset) / scale)``
    restores them exactly, and a single source of truth (``xyz``) cannot go
    stale when a kernel moves points.

Writing (rules in full in ``docs/io.md``)
    With a source header: same version, point format, scales, offsets, VLRs and
    EVLRs.  The point format is only widened inside its family when the cloud
    gained ``gps_time`` / RGB / NIR (e.g. 1 -> 3 when colours were added); LAS
    1.0 is written as 1.1 (same header layout; laspy cannot write 1.0).
    Without one: LAS 1.4, point format 6 (7 with RGB, 8 with RGB + NIR), scale
    0.001, offsets = per-axis minimum rounded down.
    Attributes named like a standard dimension of the point format go there
    (checked: out-of-range or fractional values raise); source extra dimensions
    keep their type; any other attribute becomes a new extra-bytes dimension:
    float -> float32, integer / bool -> int32 (int64 when the values need it).
"""
from __future__ import annotations

import ctypes
import struct
from pathlib import Path
from typing import Any, Callable, Iterator, NamedTuple

import laspy
import lazrs
import numpy as np
from laspy import ExtraBytesParams, LasHeader, PointFormat
from laspy.point import dims as _dims

from ..cloud import PointCloud
from ..crs import crs_info  # noqa: F401 - the CRS reading lives in lidarfx.crs
from ..errors import LidarfxError
from . import progress_bar

__all__ = [
    "read",
    "write",
    "read_header",
    "iter_chunks",
    "iter_records",
    "record_xyz",
    "record_cloud",
    "write_records",
    "crs_info",
    "header_info",
    "standard_dtypes",
    "format_for_classes",
    "LasHeader",
    "READ_ERRORS",
]

ACCEPTS_COLUMNS = False
READ_ERRORS = (
    laspy.errors.LaspyException,
    lazrs.LazrsError,
    ValueError,
    EOFError,
    struct.error,
    OSError,
)

CHUNK_POINTS = 1 << 17
"""Points per read chunk (about 4-20 MB of point records)."""
WRITE_CHUNK_POINTS = 1 << 16
"""Points per written chunk: a streamed write (``fill``) holds one chunk of records and features."""
_BLOCK_POINTS = 1 << 15
"""Points (un)packed at a time inside a chunk: field-by-field strided access stays in the CPU cache."""

DEFAULT_VERSION = "1.4"
DEFAULT_SCALE = 0.001
MAX_EXTRA_NAME_BYTES = 32
_COORDS = ("X", "Y", "Z")
_FAMILIES = ((0, 1, 2, 3, 4, 5), (6, 7, 8, 9, 10))
_WIDENING_DIMS = ("gps_time", "red", "green", "blue", "nir")
_DROPPED_VLR_USER_IDS = {"copc"}  # a COPC index would describe the wrong point order
_INT32 = np.iinfo(np.int32)


# ------------------------------------------------------------------ layout
class _Field(NamedTuple):
    """One cloud attribute <-> one (element of a) LAS dimension."""

    attr: str
    dim: _dims.DimensionInfo
    element: int | None  # index into a multi-element extra dimension

    @property
    def scaled(self) -> bool:
        return not self.dim.is_standard and self.dim.is_scaled

    def scale_offset(self) -> tuple[float, float]:
        i = self.element or 0
        scales = np.atleast_1d(self.dim.scales if self.dim.scales is not None else 1.0)
        offsets = np.atleast_1d(self.dim.offsets if self.dim.offsets is not None else 0.0)
        return float(scales[min(i, scales.size - 1)]), float(offsets[min(i, offsets.size - 1)])

    @property
    def attr_dtype(self) -> np.dtype:
        """dtype of the attribute array in the cloud."""
        if self.scaled:
            return np.dtype(np.float64)
        if self.dim.kind == _dims.DimensionKind.BitField:
            return np.dtype(np.uint8)
        return self.dim.dtype.base


def _fields_of_dim(dim: _dims.DimensionInfo) -> list[_Field]:
    if dim.num_elements == 1:
        return [_Field(dim.name, dim, None)]
    return [_Field(f"{dim.name}_{i}", dim, i) for i in range(dim.num_elements)]


def _fields(pf: PointFormat) -> list[_Field]:
    """Every attribute of a point format, in record order (X, Y, Z excluded)."""
    return [f for dim in pf.dimensions if dim.name not in _COORDS for f in _fields_of_dim(dim)]


def standard_dtypes() -> dict[str, np.dtype]:
    """Attribute dtype of every standard LAS dimension (all point formats; X/Y/Z excluded)."""
    out: dict[str, np.dtype] = {}
    for pf_id in (5, 10):  # together they hold every standard dimension
        for f in _fields(PointFormat(pf_id)):
            out.setdefault(f.attr, f.attr_dtype)
    return out


# ------------------------------------------------------------------ reading
def _decode_xyz(raw: np.ndarray, header: LasHeader, out: np.ndarray) -> None:
    """Scaled coordinates of raw point records into ``out`` (n, 3)."""
    for i, c in enumerate(_COORDS):
        # Same float operations as laspy's ScaledArrayView: X * scale + offset.
        np.multiply(raw[c], header.scales[i], out=out[:, i])
        out[:, i] += header.offsets[i]


def record_xyz(rec: laspy.PackedPointRecord, header: LasHeader) -> np.ndarray:
    """The (n, 3) float64 coordinates of a point record, exactly as :func:`read` gives them."""
    xyz = np.empty((len(rec), 3), dtype=np.float64)
    for b0 in range(0, len(rec), _BLOCK_POINTS):
        sl = slice(b0, min(b0 + _BLOCK_POINTS, len(rec)))
        _decode_xyz(rec.array[sl], header, xyz[sl])
    return xyz


def _decode(
    rec: laspy.PackedPointRecord,
    header: LasHeader,
    fields: list[_Field],
    xyz: np.ndarray,
    attrs: dict[str, np.ndarray],
) -> None:
    """Unpack a point record into preallocated ``xyz`` and attribute arrays."""
    for b0 in range(0, len(rec), _BLOCK_POINTS):  # block-wise: strided reads stay in cache
        sl = slice(b0, min(b0 + _BLOCK_POINTS, len(rec)))
        block, raw = rec[sl], rec.array[sl]
        _decode_xyz(raw, header, xyz[sl])
        for f in fields:
            out = attrs[f.attr][sl]
            if f.dim.kind == _dims.DimensionKind.BitField:
                out[:] = np.asarray(block[f.dim.name])
                continue
            src = raw[f.dim.name] if f.element is None else raw[f.dim.name][:, f.element]
            if f.scaled:
                scale, offset = f.scale_offset()
                np.multiply(src, scale, out=out)
                out += offset
            else:
                out[:] = src


def _empty(n: int, fields: list[_Field]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    return np.empty((n, 3), dtype=np.float64), {f.attr: np.empty(n, dtype=f.attr_dtype) for f in fields}


# ------------------------------------------------------------ damaged files
_VLR_HEADER = 54
_EVLR_HEADER = 60
_LAZ_VLR_FIXED = 34  # bytes of the laszip VLR before its item list (6 bytes per item)


def _damaged(path: Path, what: str) -> LidarfxError:
    return LidarfxError(f"{path}: damaged LAS/LAZ file: {what}")


def check_structure(path: Path) -> None:
    """The layout checks laspy does not make, from the file's own bytes and real size, before
    laspy reads anything: where the point data start, how many VLRs and EVLRs fit, the laszip
    VLR and the LAZ chunk table.  Every count read from the file is checked against the file's
    size before anything is allocated or looped over by it; a one-line :class:`LidarfxError`."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(375)
        if len(head) < 227 or head[:4] != b"LASF":
            return  # laspy's own message names it (not a LAS file / too short)
        minor = head[25]
        header_size, offset, n_vlrs = struct.unpack_from("<HII", head, 94)
        pf_byte, rec_len = struct.unpack_from("<BH", head, 104)
        if offset > size:
            raise _damaged(path, f"the point data start at byte {offset}, past the end of the file ({size} bytes)")
        if header_size > offset:
            raise _damaged(path, f"the header ({header_size} bytes) runs past the start of the point data ({offset})")
        if minor >= 4 and header_size < 375:
            raise _damaged(path, f"a LAS 1.{minor} header of {header_size} bytes (LAS 1.4 headers have 375)")
        if n_vlrs * _VLR_HEADER > offset - header_size:
            raise _damaged(path, f"{n_vlrs} VLRs cannot fit in the {offset - header_size} bytes before the point data")
        vlrs, pos = [], header_size
        for _ in range(n_vlrs):
            fh.seek(pos)
            raw = fh.read(_VLR_HEADER)
            if len(raw) < _VLR_HEADER:
                break
            user, record, length = raw[2:18].split(b"\0")[0], *struct.unpack_from("<HH", raw, 18)
            vlrs.append((user, record, pos + _VLR_HEADER, length))
            pos += _VLR_HEADER + length
        if minor >= 4 and len(head) >= 247:
            start, count = struct.unpack_from("<QI", head, 235)
            if count:
                if start < offset or start + count * _EVLR_HEADER > size:
                    raise _damaged(path, f"{count} EVLRs from byte {start} do not fit in the file ({size} bytes)")
                pos = start
                for _ in range(count):
                    fh.seek(pos + 20)
                    raw = fh.read(8)
                    length = struct.unpack("<Q", raw)[0] if len(raw) == 8 else size
                    pos += _EVLR_HEADER + length
                    if pos > size:
                        raise _damaged(path, f"an EVLR of {length} bytes runs past the end of the file")
        if pf_byte & 0x80:
            laz = next((v for v in vlrs if v[0] == b"laszip encoded" and v[1] == 22204), None)
            if laz is not None:
                count = struct.unpack_from("<I", head, 107)[0]
                if minor >= 4 and len(head) >= 255:
                    count = struct.unpack_from("<Q", head, 247)[0] or count
                _check_laz(path, fh, laz, rec_len, offset, size, count)


_VARIABLE_CHUNKS = 0xFFFFFFFF


def _check_laz(path: Path, fh, vlr, rec_len: int, offset: int, size: int, count: int) -> None:
    """The laszip VLR (chunk size, items) and the chunk table of a LAZ file: lazrs panics, or aborts
    the process allocating the announced number of chunks, on broken ones."""
    _, _, data_pos, length = vlr
    fh.seek(data_pos)
    data = fh.read(length)
    if len(data) < _LAZ_VLR_FIXED:
        raise _damaged(path, f"laszip VLR of {len(data)} bytes (at least {_LAZ_VLR_FIXED})")
    chunk_size, = struct.unpack_from("<I", data, 12)
    n_items, = struct.unpack_from("<H", data, 32)
    if n_items == 0 or _LAZ_VLR_FIXED + 6 * n_items > len(data):
        raise _damaged(path, f"laszip VLR lists {n_items} items in {len(data)} bytes")
    item_bytes = sum(struct.unpack_from("<H", data, _LAZ_VLR_FIXED + 6 * i + 2)[0] for i in range(n_items))
    if item_bytes != rec_len:
        raise _damaged(path, f"laszip items of {item_bytes} bytes for point records of {rec_len} bytes")
    compressor, = struct.unpack_from("<H", data, 0)
    if compressor not in (2, 3):  # pointwise (1): no chunks, no chunk table
        return
    if chunk_size == 0:
        raise _damaged(path, "laszip chunk size 0")
    fh.seek(offset)
    raw = fh.read(8)
    if len(raw) < 8:
        raise _damaged(path, "no LAZ chunk table offset")
    (table,) = struct.unpack("<q", raw)
    if table == -1:  # written by a writer that could not seek back: the offset is at the end
        fh.seek(max(0, size - 8))
        (table,) = struct.unpack("<q", fh.read(8).rjust(8, b"\0"))
    if not offset + 8 <= table <= size - 8:
        raise _damaged(path, f"LAZ chunk table at byte {table}, outside the point data (bytes {offset + 8} to {size})")
    fh.seek(table)
    _version, n_chunks = struct.unpack("<II", fh.read(8))
    most = (table - offset - 8) // max(1, rec_len)  # every chunk starts with one raw point record
    if n_chunks > most:
        raise _damaged(path, f"the LAZ chunk table announces {n_chunks} chunks; at most {most} fit in the file")
    if chunk_size != _VARIABLE_CHUNKS and count > n_chunks * chunk_size:
        raise _damaged(path, f"the header announces {count} points; {n_chunks} LAZ chunks of {chunk_size} hold at "
                             f"most {n_chunks * chunk_size}")


def check_header(path: Path, header: LasHeader) -> None:
    """The header facts every reader needs sound: a version 1.0 to 1.4; finite non-zero scales and
    finite offsets that cannot give a coordinate beyond :data:`lidarfx.io.MAX_COORDINATE` (a LAS
    file therefore never gives NaN, infinite or out-of-range coordinates); extra-bytes fields
    with a name of their own and finite non-zero scales; a point format laspy can lay out; and,
    uncompressed, a file long enough for the announced points (:func:`check_size`)."""
    version = header.version
    if version.major != 1 or version.minor > 4:
        raise _damaged(path, f"LAS version {version.major}.{version.minor} (lidarfx reads 1.0 to 1.4)")
    scales = np.asarray(header.scales, dtype=np.float64)
    offsets = np.asarray(header.offsets, dtype=np.float64)
    if not (np.isfinite(scales).all() and (scales != 0).all()):
        raise _damaged(path, f"coordinate scales {scales.tolist()} (each must be a finite number other than 0)")
    if not np.isfinite(offsets).all():
        raise _damaged(path, f"coordinate offsets {offsets.tolist()} (each must be a finite number)")
    from . import MAX_COORDINATE

    with np.errstate(over="ignore"):
        reach = np.abs(offsets) + np.abs(scales) * 2.0**31  # the farthest an int32 coordinate can go
    if not (reach <= MAX_COORDINATE).all():
        raise _damaged(path, f"scales {scales.tolist()} and offsets {offsets.tolist()} can give coordinates beyond "
                             f"±{MAX_COORDINATE:g}")
    names = [d.name for d in header.point_format.dimensions]
    for dim in header.point_format.extra_dimensions:
        if not dim.name.strip() or names.count(dim.name) > 1:
            raise _damaged(path, f"extra-bytes field named {dim.name!r} (empty, or the name of another field)")
        for what, values in (("scale", dim.scales), ("offset", dim.offsets)):
            v = np.atleast_1d(np.asarray(values if values is not None else 1.0, dtype=np.float64))
            if not np.isfinite(v).all() or (what == "scale" and (v == 0).any()):
                raise _damaged(path, f"extra-bytes field {dim.name!r} has {what} {v.tolist()}")
    try:
        itemsize = header.point_format.dtype().itemsize
    except Exception as exc:  # noqa: BLE001 - laspy's layout of hostile extra-bytes descriptors
        raise _damaged(path, f"its extra-bytes descriptors describe no readable point record ({exc!r})") from None
    if itemsize != header.point_format.size:
        raise _damaged(path, f"point records of {header.point_format.size} bytes laid out in {itemsize}")
    check_size(path, header)


def _is_panic(exc: BaseException) -> bool:
    """A Rust panic of lazrs (``pyo3_runtime.PanicException``, a BaseException)."""
    return type(exc).__name__ == "PanicException"


class _open:
    """``laspy.open(path)`` after :func:`check_structure`, with :func:`check_header` passed; a
    damaged file (laspy / lazrs errors, lazrs panics) as a one-line :class:`LidarfxError`."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __enter__(self):
        try:
            check_structure(self.path)
            self.reader = laspy.open(self.path)
        except BaseException as exc:  # noqa: BLE001 - converted or re-raised by _convert
            _convert(self.path, exc)
            raise
        try:
            check_header(self.path, self.reader.header)
        except BaseException:
            self.reader.close()
            raise
        return self.reader

    def __exit__(self, kind, exc, tb) -> None:
        self.reader.close()
        if exc is not None:
            _convert(self.path, exc)


def _convert(path: Path, exc: BaseException) -> None:
    """Raise the one-line LidarfxError of a reading exception (returns for any other)."""
    from . import one_line

    if isinstance(exc, READ_ERRORS) or _is_panic(exc):
        raise LidarfxError(f"cannot read {path}: {one_line(exc)}") from exc


def read_header(path: Path) -> LasHeader:
    """The header (with VLRs and EVLRs) of a LAS/LAZ file, without its points."""
    with _open(path) as reader:
        return reader.header


def iter_chunks(path: Path, chunk_points: int = CHUNK_POINTS) -> Iterator[PointCloud]:
    """Yield the file as consecutive clouds of at most ``chunk_points`` points.

    Every chunk carries the file's header; a file without points yields one
    empty chunk (so the attribute names are still known).
    """
    with _open(path) as reader:
        header = reader.header
        yielded = False
        for rec in reader.chunk_iterator(chunk_points):
            yielded = True
            yield record_cloud(rec, header)
        if not yielded:
            yield PointCloud(*_empty(0, _fields(header.point_format)), header=header)


def record_cloud(rec: laspy.PackedPointRecord, header: LasHeader) -> PointCloud:
    """A point record decoded into a :class:`PointCloud` (as :func:`read` decodes a file)."""
    fields = _fields(header.point_format)
    xyz, attrs = _empty(len(rec), fields)
    _decode(rec, header, fields, xyz, attrs)
    return PointCloud(xyz, attrs, header=header)


def check_size(path: Path, header: LasHeader) -> None:
    """An uncompressed file shorter than its header's point count says: a one-line error."""
    n = int(header.point_count)
    if not header.are_points_compressed:
        expected = header.offset_to_point_data + n * header.point_format.size
        if path.stat().st_size < expected:
            raise LidarfxError(
                f"{path}: truncated: the header announces {n} points ({expected} bytes), "
                f"the file has {path.stat().st_size} bytes"
            )


def iter_records(path: Path, chunk_points: int = CHUNK_POINTS) -> Iterator[tuple[int, laspy.PackedPointRecord, LasHeader]]:
    """Yield ``(start, record, header)``: the raw point records of a LAS/LAZ file in file order,
    at most ``chunk_points`` at a time, ``start`` being the index of the chunk's first point.

    Nothing is allocated from the header's point count; a file holding more or fewer points than
    its header announces, or a damaged one, is a one-line :class:`LidarfxError` (after the last
    chunk, for fewer points)."""
    with _open(path) as reader:
        header = reader.header
        n = int(header.point_count)
        done = 0
        for rec in reader.chunk_iterator(chunk_points):
            m = len(rec)
            if done + m > n:
                raise LidarfxError(f"{path}: more points than the header's {n}")
            yield done, rec, header
            done += m
    if done != n:
        raise LidarfxError(f"{path}: header announces {n} points but the file holds {done} (truncated?)")


def _capacity(path: Path, header: LasHeader) -> int:
    """Points to allocate before reading: the header's count, checked against the file's size.
    Uncompressed, :func:`check_size` has checked it; compressed, at most one point per
    :data:`LAZ_MIN_POINT_BYTES` bytes of the file (more points are read into grown arrays)."""
    n = int(header.point_count)
    if not header.are_points_compressed:
        return n
    return min(n, max(CHUNK_POINTS, path.stat().st_size // LAZ_MIN_POINT_BYTES))


LAZ_MIN_POINT_BYTES = 1
"""Bytes of a LAZ file per point allocated ahead of reading (real LAZ files take 2 to 10)."""


def _grow(xyz: np.ndarray, attrs: dict[str, np.ndarray], n: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """``xyz`` and ``attrs`` resized to ``n`` points (in place where the allocator can)."""
    xyz.resize((n, 3), refcheck=False)
    for a in attrs.values():
        a.resize(n, refcheck=False)
    return xyz, attrs


def read(path: Path, *, columns: list[str] | None = None, progress: bool | None = None) -> PointCloud:
    """Read a LAS/LAZ file into a :class:`PointCloud` (see the module docstring)."""
    with _open(path) as reader:
        header = reader.header
        n = int(header.point_count)
        fields = _fields(header.point_format)
        xyz, attrs = _empty(_capacity(path, header), fields)
        done = 0
        with progress_bar(n, f"reading {path.name}", progress) as advance:
            for rec in reader.chunk_iterator(CHUNK_POINTS):
                m = len(rec)
                if done + m > n:
                    raise LidarfxError(f"{path}: more points than the header's {n}")
                if done + m > len(xyz):
                    xyz, attrs = _grow(xyz, attrs, min(n, max(done + m, 2 * len(xyz))))
                sl = slice(done, done + m)
                _decode(rec, header, fields, xyz[sl], {k: v[sl] for k, v in attrs.items()})
                done += m
                advance(m)
    if done != n:
        raise LidarfxError(f"{path}: header announces {n} points but the file holds {done} (truncated?)")
    meta = {"compressed": bool(header.are_points_compressed)}
    return PointCloud(xyz, attrs, header=header, meta=meta)


# ------------------------------------------------------------------ writing
def _check_fits(values: np.ndarray, dtype: np.dtype, lo: float, hi: float, what: str) -> None:
    """Raise unless every value of ``values`` is representable in ``dtype`` within [lo, hi]."""
    kind = values.dtype.kind
    if kind not in "biuf":
        raise LidarfxError(f"{what}: cannot store values of dtype {values.dtype}")
    if dtype.kind == "f" or values.size == 0:
        return
    if kind == "f":
        if not np.isfinite(values).all():
            raise LidarfxError(f"{what}: NaN or infinite values cannot be stored as {dtype}")
        if not (values == np.trunc(values)).all():
            raise LidarfxError(f"{what}: fractional values cannot be stored as {dtype}")
    elif kind == "b":
        return
    elif np.can_cast(values.dtype, dtype) and (lo, hi) == (np.iinfo(dtype).min, np.iinfo(dtype).max):
        return
    vmin, vmax = values.min(), values.max()
    if vmin < lo or vmax > hi:
        raise LidarfxError(f"{what}: values {vmin}..{vmax} outside the storable range {lo}..{hi}")


def _new_extra_dim(name: str, values: np.ndarray) -> ExtraBytesParams:
    """Extra-bytes dimension for a new attribute: float -> float32, int/bool -> int32 (int64 if needed)."""
    if not name.isascii() or not name.isprintable():
        raise LidarfxError(f"attribute {name!r}: LAS extra-bytes names must be printable ASCII")
    if len(name) > MAX_EXTRA_NAME_BYTES:
        raise LidarfxError(
            f"attribute {name!r} has {len(name)} characters;"
            f" LAS extra-bytes names allow at most {MAX_EXTRA_NAME_BYTES}"
        )
    kind = values.dtype.kind
    if kind == "f":
        dtype = np.dtype(np.float32)
    elif kind in "biu":
        fits32 = kind == "b" or values.size == 0 or (_INT32.min <= values.min() and values.max() <= _INT32.max)
        dtype = np.dtype(np.int32 if fits32 else np.int64)
    else:
        raise LidarfxError(f"attribute {name!r}: cannot store values of dtype {values.dtype} in LAS")
    return ExtraBytesParams(name=name, type=dtype)


def _choose_point_format(source: LasHeader | None, names: set[str], requested: int | None) -> int:
    if requested is not None:
        if requested not in _dims.supported_point_formats():
            raise LidarfxError(f"unsupported LAS point format {requested}")
        return int(requested)
    if source is None:
        if {"red", "green", "blue"} & names:
            return 8 if "nir" in names else 7
        return 6
    pf_id = source.point_format.id
    have = set(source.point_format.standard_dimension_names)
    want = have | {d for d in _WIDENING_DIMS if d in names}
    if want == have:
        return pf_id
    family = next(f for f in _FAMILIES if pf_id in f)
    for cand in family:
        if want <= set(PointFormat(cand).standard_dimension_names):
            return cand
    return pf_id  # e.g. NIR on a legacy format: becomes an extra dimension


#: the LAS 1.4 point format that holds everything a legacy format (0-5) holds, and a full classification byte
_LEGACY_TO_14 = {0: 6, 1: 6, 2: 7, 3: 7, 4: 9, 5: 10}
#: the largest class code the 5-bit classification of point formats 0-5 stores
LEGACY_MAX_CLASS = 31


def format_for_classes(header: LasHeader | None, max_code: int) -> int | None:
    """The point format to write class codes up to ``max_code`` over a cloud read with
    ``header``: ``None`` when its own format stores them (or there is no LAS header),
    else the LAS 1.4 format with the same fields (0, 1 → 6; 2, 3 → 7; 4 → 9; 5 → 10),
    whose classification is a whole byte instead of the legacy formats' 5 bits (0-31)."""
    if not isinstance(header, LasHeader) or max_code <= LEGACY_MAX_CLASS:
        return None
    return _LEGACY_TO_14.get(header.point_format.id)


def _compatible_version(version: str, pf_id: int) -> str:
    versions = sorted(v for v in _dims.supported_versions() if v >= version)
    for v in versions:
        if _dims.is_point_fmt_compatible_with_version(pf_id, v):
            return v
    raise LidarfxError(f"no LAS version >= {version} supports point format {pf_id}")


def _writable_version(header: LasHeader, pf_id: int) -> str:
    """The version to write a source header's points with: its own (1.0 as 1.1, which laspy
    can write), raised when point format ``pf_id`` needs it."""
    version = str(header.version)
    if version == "1.0":
        version = "1.1"
    return _compatible_version(version, pf_id)


def _drop_stale_vlrs(header: LasHeader) -> None:
    """Remove (E)VLRs that would describe the wrong points after a rewrite (a COPC index)."""
    for vlrs in (header.vlrs, header.evlrs or []):
        # in place: assigning header.vlrs would rebuild the extra-bytes VLR
        vlrs[:] = [v for v in vlrs if getattr(v, "user_id", "") not in _DROPPED_VLR_USER_IDS]


def _fit_offsets(header: LasHeader, xyz: np.ndarray, keep: bool) -> None:
    """Keep the header's offsets when the coordinates fit int32 with them, else floor(min)."""
    if len(xyz) == 0:
        return
    if not np.isfinite(xyz).all():
        raise LidarfxError("coordinates contain NaN or infinite values")
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    scales = np.asarray(header.scales, dtype=np.float64)

    def fits(offsets: np.ndarray) -> bool:
        return bool(
            (np.rint((lo - offsets) / scales) >= _INT32.min).all()
            and (np.rint((hi - offsets) / scales) <= _INT32.max).all()
        )

    if keep and fits(np.asarray(header.offsets, dtype=np.float64)):
        return
    offsets = np.floor(lo)
    if not fits(offsets):
        raise LidarfxError(
            f"the extent {(hi - lo).tolist()} is too large for the LAS scale {scales.tolist()}"
        )
    header.offsets = offsets


def _target_header(cloud: PointCloud, point_format: int | None, scale: Any) -> LasHeader:
    """The header to write ``cloud`` with (a modified copy of its source header, or a new one)."""
    source = cloud.header if isinstance(cloud.header, LasHeader) else None
    names = set(cloud.names)
    clash = names & {"X", "Y", "Z"}
    if clash:
        raise LidarfxError(f"attribute name(s) {sorted(clash)} are reserved for LAS raw coordinates")
    pf_id = _choose_point_format(source, names, point_format)
    standard = set(PointFormat(pf_id).standard_dimension_names) - set(_COORDS)

    kept: list[_dims.DimensionInfo] = []
    covered: set[str] = set()
    if source is not None:
        for dim in source.point_format.extra_dimensions:
            attrs = [f.attr for f in _fields_of_dim(dim)]
            if dim.name not in standard and all(a in names for a in attrs):
                kept.append(dim)
                covered.update(attrs)

    reserved = set(PointFormat(pf_id).dtype().names) | {d.name for d in kept}
    new_dims = []
    for name in cloud.names:
        if name in standard or name in covered:
            continue
        if name in reserved:
            raise LidarfxError(f"attribute {name!r} clashes with a field of LAS point format {pf_id}")
        new_dims.append(_new_extra_dim(name, cloud[name]))

    if source is not None:
        header = source.copy()
        unchanged = pf_id == source.point_format.id and not new_dims and len(kept) == len(
            list(source.point_format.extra_dimensions)
        )
        wide = [d for d in kept if d.num_elements > 3] if not unchanged else []
        if wide:  # e.g. unregistered extra bytes: an extra-bytes descriptor holds 1 to 3 elements
            kept = [d for d in kept if d.num_elements <= 3]
            new_dims += [_new_extra_dim(f.attr, cloud[f.attr]) for d in wide for f in _fields_of_dim(d)]
        version = _writable_version(header, pf_id)
        if unchanged:
            if version != str(header.version):
                header.version = laspy.header.Version.from_str(version)
        else:
            header.set_version_and_point_format(
                laspy.header.Version.from_str(version), _build_pf(pf_id, kept, new_dims)
            )
        _drop_stale_vlrs(header)
    else:
        header = LasHeader(version=DEFAULT_VERSION, point_format=_build_pf(pf_id, kept, new_dims))
        header.scales = np.full(3, DEFAULT_SCALE)
        from .. import __version__

        header.generating_software = f"lidarfx {__version__}"

    if scale is not None:
        header.scales = np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)).copy()
    _fit_offsets(header, cloud.xyz, keep=source is not None)
    return header


def _build_pf(pf_id: int, kept: list[_dims.DimensionInfo], new_dims: list[ExtraBytesParams]) -> PointFormat:
    pf = PointFormat(pf_id)
    pf.dimensions.extend(kept)  # original DimensionInfo: type, description, scale, no_data
    for params in new_dims:
        pf.add_extra_dimension(params)
    return pf


class _Encoder(NamedTuple):
    field: _Field
    values: np.ndarray  # the validated source attribute

    def stored(self, sl: slice, values: np.ndarray | None = None) -> np.ndarray:
        """Contiguous values of ``sl`` in the dtype they are stored with (``values``:
        the values of exactly these points, when they come from a ``fill`` callback)."""
        f = self.field
        values = self.values[sl] if values is None else values
        if f.dim.kind == _dims.DimensionKind.BitField:
            return values.astype(np.uint8, copy=False)
        if f.scaled:
            scale, offset = f.scale_offset()
            values = np.rint((values - offset) / scale)
        return values.astype(f.dim.dtype.base, copy=False)


def _encoders(cloud: PointCloud, pf: PointFormat) -> list[_Encoder]:
    """Validate every attribute against its target LAS field (one pass, before writing)."""
    out = []
    for f in _fields(pf):
        if f.attr not in cloud:
            continue  # standard dimension the cloud does not have: stays 0
        values = cloud[f.attr]
        what = f"attribute {f.attr!r} -> LAS {f.dim.name}"
        if f.scaled:  # check the quantised extremes (NaN included) against the stored type
            scale, offset = f.scale_offset()
            stored = f.dim.dtype.base
            if values.size and stored.kind in "iu":
                ends = np.rint((np.array([values.min(), values.max()], dtype=np.float64) - offset) / scale)
                info = np.iinfo(stored)
                _check_fits(ends, stored, info.min, info.max, f"{what} (scaled)")
        else:
            bits = f.dim.kind == _dims.DimensionKind.BitField
            target = np.dtype(np.uint8) if bits else f.dim.dtype.base
            if target.kind not in "iu":
                lo, hi = 0, 0
            elif bits:
                lo, hi = f.dim.min, f.dim.max
            else:  # one element's range (laspy's own min / max fail on arrays such as unregistered extra bytes)
                lo, hi = np.iinfo(target).min, np.iinfo(target).max
            _check_fits(values, target, lo, hi, what)
        out.append(_Encoder(f, values))
    return out


def _encode(
    rec: laspy.PackedPointRecord,
    header: LasHeader,
    xyz: np.ndarray,
    encoders: list[_Encoder],
    start: int,
    stats: "_ExtraBytesStats",
    filled: dict[str, np.ndarray] | None = None,
) -> None:
    """Pack cloud points ``start : start + len(rec)`` into ``rec``; ``filled`` holds
    the values of these points for attributes produced chunk by chunk."""
    raw = rec.array
    for b0 in range(0, len(rec), _BLOCK_POINTS):
        b1 = min(b0 + _BLOCK_POINTS, len(rec))
        out, sl = raw[b0:b1], slice(start + b0, start + b1)
        for i, c in enumerate(_COORDS):
            out[c] = np.rint((xyz[sl, i] - header.offsets[i]) / header.scales[i])
        for enc in encoders:
            chunk = filled.get(enc.field.attr) if filled else None
            f = enc.field
            stored = enc.stored(sl, None if chunk is None else chunk[b0:b1])
            if f.dim.kind == _dims.DimensionKind.BitField:
                rec[b0:b1][f.dim.name] = stored
            elif f.element is None:
                out[f.dim.name] = stored
            else:
                out[f.dim.name][:, f.element] = stored
            if not f.dim.is_standard:
                stats.update(f, stored)


def _descriptor_kind(desc) -> type:
    """numpy type of the min/max/no_data slots of an extra-bytes descriptor (LAS data types 1-10, 11-30)."""
    base = (desc.data_type - 1) % 10  # 0 uchar, 1 char, ... 7 int64, 8 float, 9 double
    return np.float64 if base >= 8 else (np.uint64, np.int64)[base % 2]


class _ExtraBytesStats:
    """Min / max of the stored extra-bytes values, for the extra-bytes VLR.

    ``laspy.LasWriter`` resets the min/max bytes of every descriptor and regrows
    them from the packed records: slowly (strided), wrongly for single-element
    fields with a ``no_data`` value, and even in descriptors whose options do
    not flag min/max.  We switch that off (:meth:`detach`), track min/max from
    the contiguous values being packed, and patch the writer's header before it
    is written (:meth:`apply`), so an unchanged cloud gives a bit-identical
    extra-bytes VLR.
    """

    _MINMAX = 0b110  # ExtraBytesStruct MIN_BIT_MASK | MAX_BIT_MASK

    def __init__(self, header: LasHeader) -> None:
        found = header.vlrs.get("ExtraBytesVlr")
        self.template = found[0] if found else None
        descs = self.template.extra_bytes_structs if self.template else []
        self.by_name = {d.format_name(): d for d in descs}
        self.lo: dict[str, list] = {}
        self.hi: dict[str, list] = {}

    def detach(self, written: LasHeader) -> None:
        """Stop laspy from tracking min/max itself in the writer's header."""
        for out in self._written(written):
            out.options &= ~self._MINMAX

    def update(self, field: _Field, stored: np.ndarray) -> None:
        desc = self.by_name.get(field.dim.name)
        if desc is None or desc.data_type == 0 or not desc.options & self._MINMAX or stored.size == 0:
            return
        i = field.element or 0
        no_data = desc.no_data
        if no_data is not None:
            stored = stored[stored != no_data[i]]
            if stored.size == 0:
                return
        k = field.dim.num_elements
        lo = self.lo.setdefault(field.dim.name, [None] * k)
        hi = self.hi.setdefault(field.dim.name, [None] * k)
        vmin, vmax = stored.min().item(), stored.max().item()
        lo[i] = vmin if lo[i] is None else min(lo[i], vmin)
        hi[i] = vmax if hi[i] is None else max(hi[i], vmax)

    def _written(self, written: LasHeader) -> list:
        found = written.vlrs.get("ExtraBytesVlr")
        return list(found[0].extra_bytes_structs) if found and self.template else []

    def apply(self, written: LasHeader) -> None:
        """Restore the template's descriptors, with min/max of the data written."""
        descs = self.template.extra_bytes_structs if self.template else []
        for out, desc in zip(self._written(written), descs):
            out.options = desc.options
            ctypes.memmove(out._min, desc._min, ctypes.sizeof(out._min))
            ctypes.memmove(out._max, desc._max, ctypes.sizeof(out._max))
            name = desc.format_name()
            for slot, values, relevant in (
                (out._min, self.lo.get(name, ()), desc.min_is_relevant()),
                (out._max, self.hi.get(name, ()), desc.max_is_relevant()),
            ):
                view = np.frombuffer(slot, dtype=_descriptor_kind(desc))
                for i, v in enumerate(values):
                    if relevant and v is not None:
                        view[i] = v


class _Recorded:
    """A binary file that keeps the OSError of a failed write: the LAZ compressor (lazrs) reports
    a full disk as "IoError: Failed to call write" without it."""

    def __init__(self, fh) -> None:
        self._fh = fh
        self.error: OSError | None = None

    def write(self, data) -> int:
        try:
            return self._fh.write(data)
        except OSError as exc:
            self.error = exc
            raise

    def __getattr__(self, name: str):
        return getattr(self._fh, name)


class _output_file:
    """``open(path, "wb")`` for a LasWriter: a failed write (disk full, file too large) leaves as
    its OSError, whatever the writer made of it."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __enter__(self) -> _Recorded:
        self.fh = _Recorded(open(self.path, "wb"))
        return self.fh

    def __exit__(self, kind, exc, tb) -> None:
        try:
            self.fh.close()
        except OSError:
            if exc is None:
                raise
        if exc is not None and self.fh.error is not None and self.fh.error is not exc:
            raise self.fh.error from exc


def write(
    cloud: PointCloud,
    path: Path,
    *,
    ext: str = ".las",
    progress: bool | None = None,
    point_format: int | None = None,
    scale: float | tuple[float, float, float] | None = None,
    fill: Callable[[int, int], dict[str, np.ndarray]] | None = None,
) -> None:
    """Write ``cloud`` as LAS (``ext == ".las"``) or LAZ (``".laz"``, lazrs).

    ``point_format`` forces a point format (extra dimensions carried over);
    ``scale`` sets the coordinate scale(s) (offsets are kept when the
    coordinates still fit, else recomputed).  ``fill(start, stop)``, when
    given, returns the values of points ``start:stop`` for some float
    attributes that the cloud only holds as placeholders; it is called once per
    written chunk, in order, so those attributes never exist in full.  See the
    module docstring.
    """
    header = _target_header(cloud, point_format, scale)
    pf = header.point_format
    encoders = _encoders(cloud, pf)
    n = len(cloud)
    stats = _ExtraBytesStats(header)
    buf = np.zeros(min(n, WRITE_CHUNK_POINTS), dtype=pf.dtype())
    compress = ext == ".laz"
    with _output_file(path) as fh, laspy.LasWriter(fh, header, do_compress=compress, closefd=False) as writer:
        stats.detach(writer.header)
        with progress_bar(n, f"writing {Path(path).name}", progress) as advance:
            for start in range(0, n, WRITE_CHUNK_POINTS):
                sl = slice(start, min(start + WRITE_CHUNK_POINTS, n))
                rec = laspy.PackedPointRecord(buf[: sl.stop - sl.start], pf)
                filled = fill(sl.start, sl.stop) if fill is not None else None
                _encode(rec, header, cloud.xyz, encoders, start, stats, filled)
                writer.write_points(rec)
                advance(sl.stop - sl.start)
        stats.apply(writer.header)
        if header.version.minor >= 4 and header.evlrs:
            writer.write_evlrs(header.evlrs)


def write_records(path: Path, header: LasHeader, chunks, *, ext: str = ".las") -> int:
    """Write raw point records (in ``header``'s point format, scales and offsets, e.g. chunks of
    :func:`iter_records`) as LAS (``ext == ".las"``) or LAZ (``".laz"``); returns the points written.

    The records are copied bit for bit.  The header keeps its version (1.0 is written as 1.1),
    point format, scales, offsets, VLRs and EVLRs (a COPC index is dropped); point counts, bounds
    and the extra-bytes min/max describe the points written.  ``chunks`` is consumed once, so the
    points never exist in full."""
    out = header.copy()
    pf = out.point_format
    version = _writable_version(out, pf.id)
    if version != str(out.version):
        out.version = laspy.header.Version.from_str(version)
    _drop_stale_vlrs(out)
    stats = _ExtraBytesStats(out)
    extra = [f for f in _fields(pf) if not f.dim.is_standard]
    n = 0
    with _output_file(path) as fh, laspy.LasWriter(fh, out, do_compress=ext == ".laz", closefd=False) as writer:
        stats.detach(writer.header)
        for rec in chunks:
            if not len(rec):
                continue
            raw = rec.array
            for f in extra:
                stats.update(f, raw[f.dim.name] if f.element is None else raw[f.dim.name][:, f.element])
            writer.write_points(rec)
            n += len(rec)
        stats.apply(writer.header)
        if out.version.minor >= 4 and out.evlrs:
            writer.write_evlrs(out.evlrs)
    return n


# ---------------------------------------------------------------- summaries
def header_info(header: LasHeader) -> dict[str, Any]:
    """LAS header facts for :func:`lidarfx.io.info` (JSON-serialisable)."""
    pf = header.point_format
    return {
        "version": str(header.version),
        "point_format": int(pf.id),
        "compressed": bool(header.are_points_compressed),
        "scales": [float(s) for s in header.scales],
        "offsets": [float(o) for o in header.offsets],
        "header_point_count": int(header.point_count),
        "extra_dims": [
            {"name": d.name, "type": d.type_str() or "bits", "description": d.description}
            for d in pf.extra_dimensions
        ],
        "vlrs": [
            {"user_id": v.user_id, "record_id": int(v.record_id), "description": v.description}
            for v in header.vlrs
        ],
        "evlrs": [
            {"user_id": v.user_id, "record_id": int(v.record_id), "description": v.description}
            for v in (header.evlrs or [])
        ],
        "generating_software": str(header.generating_software).strip("\x00 "),
        "system_identifier": str(header.system_identifier).strip("\x00 "),
        "creation_date": header.creation_date.isoformat() if header.creation_date else None,
    }
