"""PLY point clouds (ASCII and binary, either byte order) through plyfile.

Reading: the ``vertex`` element; ``x``, ``y``, ``z`` become float64 ``xyz``,
every other scalar vertex property an attribute with its own dtype (native byte
order), e.g. ``red``/``green``/``blue``, ``nx``/``ny``/``nz``, ``intensity``,
``scalar_*``.  List properties and other elements (faces) are ignored.

Writing: binary little-endian by default (``ascii=True`` for text); ``x y z``
as ``double`` (float32 would cost ~0.5 m at UTM northings), attributes with
their dtype where PLY has it: bool -> ``uchar``, 64-bit integers -> ``int`` /
``uint`` when the values fit, float16 -> ``float``.

ASCII bodies do not go through plyfile's row-by-row text code (about 100 s for half a
million points): the vertex lines are parsed by ``numpy.loadtxt`` and written by two numba
kernels in chunks.  Every number reads back as the value written (any correctly rounding
parser; tested with plyfile and this reader).  A ``double`` is written as the shortest
fixed-point decimal ``m / 10**d`` with ``m < 2**53`` that reads back as itself (``m / 10**d``
in float64 is exactly what such a parser returns), e.g. a LAS coordinate ``515396.148``;
else, from 1e-6 to 2**53, with 17 significant digits rounded in exact integer arithmetic; a
``float`` as the shortest decimal well inside its rounding interval; values beyond those
ranges as Python / NumPy print them (``1e-30``); ``nan``, ``inf``, ``-inf``, ``-0``.
Integers as integers.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from plyfile import (
    PlyData,
    PlyElement,
    PlyElementParseError,
    PlyHeaderParseError,
    PlyListProperty,
    PlyParseError,
    PlyProperty,
)

from ..cloud import PointCloud
from ..errors import LidarfxError

ACCEPTS_COLUMNS = False
READ_ERRORS = (PlyParseError, PlyHeaderParseError, PlyElementParseError, ValueError, EOFError, OSError, UnicodeDecodeError)

_PLY_KINDS = {np.dtype(t) for t in ("i1", "u1", "i2", "u2", "i4", "u4", "f4", "f8")}
MAX_HEADER_BYTES = 1 << 16
"""Longest PLY header read (real ones take a few hundred bytes; plyfile parses a header
character by character, about 10 s per megabyte)."""


def read(path: Path, *, columns: list[str] | None = None, progress: bool | None = None) -> PointCloud:
    """Read the vertices of a PLY file (see the module docstring)."""
    with open(path, "rb") as fh:
        head = fh.read(MAX_HEADER_BYTES + 1)
        if head.startswith(b"ply") and b"end_header" not in head and len(head) > MAX_HEADER_BYTES:
            raise LidarfxError(f"{path}: no end_header in the first {MAX_HEADER_BYTES} bytes "
                               f"(lidarfx reads PLY headers up to {MAX_HEADER_BYTES // 1024} KiB)")
        fh.seek(0)
        parse_header = getattr(PlyData, "_parse_header", None)  # plyfile's own (checking) header parser
        header_only = parse_header is not None
        ply = parse_header(fh) if header_only else PlyData.read(fh)
        if not any(el.name == "vertex" for el in ply.elements):
            raise LidarfxError(f"{path}: PLY file has no 'vertex' element")
        if header_only:
            _check_counts(path, ply, path.stat().st_size - fh.tell())
        if header_only and ply.text and _scalar_only(ply["vertex"]):
            vertex = _read_text_vertices(fh, ply)
        else:
            if header_only:  # binary (memory-mapped by plyfile), or list properties in the vertices
                fh.seek(0)
                ply = PlyData.read(fh)
            vertex = ply["vertex"].data
    names = vertex.dtype.names or ()
    missing = [c for c in ("x", "y", "z") if c not in names]
    if missing:
        raise LidarfxError(f"{path}: PLY vertices lack {', '.join(missing)} (properties: {', '.join(names)})")
    xyz = np.column_stack([vertex[c].astype(np.float64) for c in ("x", "y", "z")])
    attrs = {}
    for name in names:
        if name in ("x", "y", "z"):
            continue
        dt = vertex.dtype[name]
        if dt.kind == "O":  # list property
            continue
        attrs[name] = np.ascontiguousarray(vertex[name], dtype=dt.newbyteorder("="))
    return PointCloud(xyz, attrs, meta={"ply_text": bool(ply.text), "ply_comments": list(ply.comments)})


def _check_counts(path: Path, ply: PlyData, body: int) -> None:
    """The header's element counts against the ``body`` bytes after it, before anything is
    allocated by them: every element takes at least its scalar bytes and list counts (binary), or
    two characters per property (text: a digit and a separator; a line break at least)."""
    need = 0
    for el in ply.elements:
        if el.count < 0:
            raise LidarfxError(f"{path}: PLY header announces {el.count} {el.name} elements")
        if ply.text:
            least = max(1, 2 * len(el.properties))  # a line per element
        else:
            least = sum(np.dtype(p.len_dtype if isinstance(p, PlyListProperty) else p.val_dtype).itemsize
                        for p in el.properties)
        need += el.count * least
        if need > body:
            raise LidarfxError(f"{path}: PLY header announces {el.count} {el.name} elements, more than the "
                               f"{body} bytes after the header can hold (truncated or damaged file)")


def _ply_dtype(name: str, values: np.ndarray) -> np.dtype:
    dt = values.dtype
    if dt.kind == "b":
        return np.dtype("u1")
    if dt.kind == "f" and dt.itemsize < 4:
        return np.dtype("f4")
    if dt.kind in "iu" and dt.itemsize == 8:
        target = np.dtype("i4" if dt.kind == "i" else "u4")
        info = np.iinfo(target)
        if values.size == 0 or (values.min() >= info.min and values.max() <= info.max):
            return target
        raise LidarfxError(f"attribute {name!r}: values exceed PLY's 32-bit integers")
    if dt.newbyteorder("=") in _PLY_KINDS:
        return dt.newbyteorder("=")
    raise LidarfxError(f"attribute {name!r}: dtype {dt} has no PLY property type")


def write(
    cloud: PointCloud,
    path: Path,
    *,
    ext: str = ".ply",
    progress: bool | None = None,
    ascii: bool = False,
) -> None:
    """Write ``cloud`` as a PLY vertex element (binary little-endian, or text with ``ascii=True``)."""
    bad = [n for n in cloud.names if not n or any(ch.isspace() for ch in n) or n in ("x", "y", "z")]
    if bad:
        raise LidarfxError(f"attribute name(s) {bad} cannot be PLY property names")
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    fields += [(n, _ply_dtype(n, cloud[n]).newbyteorder("<")) for n in cloud.names]
    comments = ["generated by lidarfx"]
    if ascii:
        element = PlyElement("vertex", [PlyProperty(n, np.dtype(dt).str[1:]) for n, dt in fields], len(cloud))
        columns = [cloud.xyz[:, i] for i in range(3)] + [cloud[n] for n in cloud.names]
        with open(path, "wb") as fh:
            fh.write(PlyData([element], text=True, comments=comments).header.encode("ascii") + b"\n")
            _write_text_vertices(fh, columns, [np.dtype(dt) for _, dt in fields], progress, Path(path).name)
        return
    table = np.empty(len(cloud), dtype=fields)
    for i, c in enumerate(("x", "y", "z")):
        table[c] = cloud.xyz[:, i]
    for n in cloud.names:
        table[n] = cloud[n]
    element = PlyElement.describe(table, "vertex")
    PlyData([element], text=False, byte_order="<", comments=comments).write(str(path))


# ----------------------------------------------------------------------------- ASCII bodies
TEXT_CHUNK = 1 << 15
"""Vertices formatted per numba call when writing ASCII PLY."""


def _scalar_only(element) -> bool:
    return all(not isinstance(p, PlyListProperty) for p in element.properties)


def _read_text_vertices(fh, ply: PlyData) -> np.ndarray:
    """The vertex lines of an ASCII PLY whose header ``fh`` has just passed: the lines of the
    elements before it are skipped (one line per element, as plyfile reads them), the
    vertex lines parsed by ``numpy.loadtxt`` (C; the same strict integers as plyfile: ``1.0``
    or ``300`` for a ``uchar`` is a ``ValueError``)."""
    import io
    from itertools import islice

    text = io.TextIOWrapper(fh, "ascii")
    try:
        for element in ply.elements:
            if element.name == "vertex":
                break
            got = sum(1 for _ in islice(text, element.count))
            if got < element.count:
                raise PlyElementParseError("early end-of-file", element, got)
        vertex = ply["vertex"]
        dtype = np.dtype([(p.name, p.dtype("=")) for p in vertex.properties])
        if vertex.count == 0:
            return np.empty(0, dtype)
        data = np.loadtxt(islice(text, vertex.count), dtype=dtype, comments=None, ndmin=1)
        if len(data) < vertex.count:  # the file ends early, or blank lines (loadtxt skips them)
            raise PlyElementParseError("early end-of-file (or a blank line)", vertex, len(data))
    finally:
        text.detach()  # leave ``fh`` to its own ``with``
    return data


def _write_text_vertices(fh, columns: list[np.ndarray], dtypes: list[np.dtype], progress: bool | None,
                         name: str) -> None:
    """``columns`` (stored as ``dtypes``) as ASCII PLY lines (see the module docstring), in chunks."""
    from . import progress_bar

    kinds = np.array([0 if dt.kind in "iu" else (2 if dt.itemsize == 4 else 1) for dt in dtypes], dtype=np.int8)
    int_cols = [c for c, k in zip(columns, kinds) if k == 0]
    float_cols = [c for c, k in zip(columns, kinds) if k != 0]
    is32 = np.array([k == 2 for k in kinds if k != 0], dtype=np.bool_)
    where = np.empty(len(kinds), dtype=np.int64)
    where[kinds == 0] = np.arange(len(int_cols))
    where[kinds != 0] = np.arange(len(float_cols))
    float_parts, write_rows = _text_kernels()
    n = len(columns[0])
    with progress_bar(n, f"writing {name}", progress) as advance:
        for a in range(0, n, TEXT_CHUNK):
            b = min(n, a + TEXT_CHUNK)
            ints = np.empty((b - a, len(int_cols)), dtype=np.int64)
            for j, c in enumerate(int_cols):
                ints[:, j] = c[a:b]
            floats = np.empty((b - a, len(float_cols)), dtype=np.float64)
            for j, c in enumerate(float_cols):
                floats[:, j] = c[a:b].astype(np.float32) if is32[j] else c[a:b]  # float16 is written as float
            mant, dec = float_parts(floats, is32)
            rows, cols = np.nonzero(dec == _FALLBACK)
            blob, starts = _fallback_text(floats[rows, cols], is32[cols])
            out = np.empty((b - a) * (26 * len(kinds) + 1) + len(blob), dtype=np.uint8)
            used = write_rows(ints, mant, dec, kinds, where, blob, starts, out)
            fh.write(out[:used].data)
            advance(b - a)


_FALLBACK, _NAN, _POS_INF, _NEG_INF, _NEG_ZERO = -1, -2, -3, -4, -5
_MAX_DECIMALS = 22  # 10**22 is the largest power of ten a double holds exactly


def _fallback_text(values: np.ndarray, is32: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Python's (float32: NumPy's) shortest repr of the values the kernel cannot write in fixed
    point, as one byte string and the start of each (n + 1 offsets)."""
    texts = [str(np.float32(v)) if s else repr(float(v)) for v, s in zip(values.tolist(), is32.tolist())]
    starts = np.zeros(len(texts) + 1, dtype=np.int64)
    np.cumsum([len(t) for t in texts], out=starts[1:])
    return np.frombuffer("".join(texts).encode("ascii"), dtype=np.uint8), starts


def _float_parts_py(values, is32):  # pragma: no cover - compiled by numba
    """Per value the integer ``m`` and decimals ``d`` of the shortest fixed-point decimal
    ``m / 10**d`` that reads back as the value (else one of 17 significant digits), or a
    code (nan, +-inf, -0, fallback)."""
    pow10 = np.empty(_MAX_DECIMALS + 1)
    p = 1.0
    for d in range(_MAX_DECIMALS + 1):
        pow10[d] = p
        p *= 10.0
    two53 = 9007199254740992.0
    pow5 = np.empty(_MAX_DECIMALS + 1, dtype=np.uint64)
    pow5[0] = 1
    for d in range(1, _MAX_DECIMALS + 1):
        pow5[d] = pow5[d - 1] * np.uint64(5)
    mask32 = np.uint64(0xFFFFFFFF)
    e16 = np.uint64(10**16)
    e17 = np.uint64(10**17)
    n, k = values.shape
    mant = np.zeros((n, k), dtype=np.int64)
    dec = np.full((n, k), _FALLBACK, dtype=np.int8)
    for i in range(n):
        for j in range(k):
            v = values[i, j]
            if math.isnan(v):
                dec[i, j] = _NAN
                continue
            if v == np.inf:
                dec[i, j] = _POS_INF
                continue
            if v == -np.inf:
                dec[i, j] = _NEG_INF
                continue
            if v == 0.0:
                dec[i, j] = _NEG_ZERO if math.copysign(1.0, v) < 0 else 0
                continue
            a = abs(v)
            tol = 0.0
            if is32[j]:  # well inside the float32's rounding interval (a quarter ulp at a binade's foot)
                tol = 0.24 * math.ldexp(1.0, math.frexp(a)[1] - 24)
            for d in range(_MAX_DECIMALS + 1):
                s = a * pow10[d]
                if s >= two53:
                    break
                r = math.floor(s + 0.5)
                back = r / pow10[d]
                if back == a if tol == 0.0 else (abs(back - a) <= tol and r > 0.0):
                    mant[i, j] = np.int64(r) if v > 0 else -np.int64(r)
                    dec[i, j] = d
                    break
            if dec[i, j] != _FALLBACK or is32[j] or a >= two53 or a < 1e-6:
                continue
            # No short decimal (most random doubles): 17 significant digits, rounded in exact
            # integer arithmetic.  a = f * 2**(e - 53), so a * 10**d = f * 5**d * 2**(e - 53 + d),
            # f * 5**d < 2**105 as a 128-bit (high, low) pair.  |m - a * 10**d| <= 1/2 with
            # a * 10**d >= 1e16 keeps m / 10**d within 0.9 of half an ulp of a: it reads back as a.
            fr, e = math.frexp(a)
            f = np.uint64(fr * two53)
            f0 = f & mask32
            f1 = f >> np.uint64(32)
            d = 16 - math.floor(math.log10(a))
            for _ in range(3):
                sh = 53 - e - d
                if d < 0 or d > _MAX_DECIMALS or sh >= 64:
                    break
                g0 = pow5[d] & mask32
                g1 = pow5[d] >> np.uint64(32)
                lo = f0 * g0
                mid = f1 * g0 + f0 * g1
                low = lo + ((mid & mask32) << np.uint64(32))
                high = f1 * g1 + (mid >> np.uint64(32)) + (np.uint64(1) if low < lo else np.uint64(0))
                if sh <= 0:  # a * 10**d is a whole number
                    m = low << np.uint64(-sh)
                else:
                    m = (high << np.uint64(64 - sh)) | (low >> np.uint64(sh))
                    if (low & ((np.uint64(1) << np.uint64(sh)) - np.uint64(1))) >= (np.uint64(1) << np.uint64(sh - 1)):
                        m += np.uint64(1)
                if m >= e17:
                    d -= 1
                elif m < e16:
                    d += 1
                else:
                    while d > 0 and m % np.uint64(10) == np.uint64(0):
                        m //= np.uint64(10)
                        d -= 1
                    mant[i, j] = np.int64(m) if v > 0 else -np.int64(m)
                    dec[i, j] = d
                    break
    return mant, dec


def _write_rows_py(ints, mant, dec, kinds, where, blob, starts, out):  # pragma: no cover - compiled by numba
    """Rows of integers (``ints``) and floats (``mant``/``dec``, ``blob`` for the fallbacks
    in row-major order) as space-separated text lines into ``out``; returns the bytes used."""
    digits = np.empty(24, dtype=np.uint8)
    n = ints.shape[0]
    pos = 0
    fb = 0
    for i in range(n):
        for c in range(kinds.shape[0]):
            if c:
                out[pos] = 32  # space
                pos += 1
            kind = kinds[c]
            if kind == 0:
                m = ints[i, where[c]]
                d = 0
            else:
                d = dec[i, where[c]]
                m = mant[i, where[c]]
                if d < 0:
                    if d == _FALLBACK:
                        for b in range(starts[fb], starts[fb + 1]):
                            out[pos] = blob[b]
                            pos += 1
                        fb += 1
                    elif d == _NAN:
                        out[pos] = 110  # nan
                        out[pos + 1] = 97
                        out[pos + 2] = 110
                        pos += 3
                    else:
                        if d == _NEG_INF or d == _NEG_ZERO:
                            out[pos] = 45  # -
                            pos += 1
                        if d == _NEG_ZERO:
                            out[pos] = 48
                            pos += 1
                        else:
                            out[pos] = 105  # inf
                            out[pos + 1] = 110
                            out[pos + 2] = 102
                            pos += 3
                    continue
            if m < 0:  # |m| < 2**53: 32-bit integers, mantissas of doubles
                out[pos] = 45
                pos += 1
                m = -m
            nd = 0
            while m > 0 or nd <= d:  # at least d + 1 digits: 0.001
                digits[nd] = 48 + m % 10
                m //= 10
                nd += 1
            for t in range(nd - 1, -1, -1):
                out[pos] = digits[t]
                pos += 1
                if t == d and d > 0:
                    out[pos] = 46  # .
                    pos += 1
        out[pos] = 10  # newline
        pos += 1
    return pos


_KERNELS = None


def _text_kernels():
    """The two ASCII-writing kernels, compiled (or loaded from numba's cache) on first use,
    so that reading and binary writing never import numba."""
    global _KERNELS
    if _KERNELS is None:
        import numba as nb

        _KERNELS = (nb.njit(cache=True)(_float_parts_py), nb.njit(cache=True)(_write_rows_py))
    return _KERNELS
