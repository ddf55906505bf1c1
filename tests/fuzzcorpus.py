"""Hostile input files made from the real data, and the worker that runs lidarfx on them.

Used by ``tests/test_reliability_fuzz.py`` (bounded, in CI) and ``tools/fuzz_cli.py mutants``
(by hand, at any budget).  Three steps:

1. :func:`cut_sources` cuts every LAS/LAZ file of the real data to its first
   :data:`CUT_POINTS` points (same version, point format, VLRs and extra bytes), adds an
   uncompressed copy of some LAZ cuts, two extra-bytes variants and a LAS 1.4 file with an
   EVLR, and writes PLY (binary both byte orders, ASCII) and text (``.xyz`` ``.txt`` ``.csv``
   ``.pts``) copies of a few cuts.
2. :func:`build_corpus` mutates them deterministically (``seed``): :data:`KINDS` lists the
   six kinds of mutant (truncated files, lying header fields, broken VLRs / extra bytes /
   EVLRs / LAZ tables, wrong names / empty / garbage / huge declared counts, bad PLY, bad text).
3. :func:`plan` turns mutants into command lines: every mutant through the readers (``info``,
   ``convert``), and through a rotating subset of the other commands so that every command
   sees :data:`PER_COMMAND` mutants of every kind; :func:`run_cases` runs them in long-lived
   worker processes (``python tests/fuzzcorpus.py worker ...``) that call
   ``lidarfx.cli.main`` in-process under a memory limit and a time limit per case.

The contract checked per run (:func:`check_run`): exit code 0 or 2; on exit 2 exactly one
stderr line ``lidarfx: error: ...``; no other stderr line than ``lidarfx: warning: ...``
(so never a traceback); no file left in the output folder after an error; the input file
unchanged and nothing added next to it; an answer within the time limit; no worker death
(a ``MemoryError`` under the address-space limit shows as a traceback).
"""
from __future__ import annotations

import hashlib
import json
import os
import random
import shutil
import struct
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

REAL = Path(__file__).resolve().parents[2] / "shared/data/real"
"""The real data (``shared/data/real`` beside the repository, see its SOURCES.md)."""

CUT_POINTS = 2000
"""Points kept of every real file: runs that survive reading stay fast."""
PER_COMMAND = 30
"""Mutants of every kind each non-reader command sees per round."""
MUTANTS_PER_KIND = 50
"""Mutants of every kind per round (every one goes through ``info`` and ``convert``); at least the
number of operators of any kind, so that one round applies every operator."""
CASE_SECONDS = 30.0
"""Time limit of one run (an alarm in the worker; the parent kills a worker silent 30 s longer)."""
MEMORY_BYTES = 3 << 30
"""Address-space limit of a worker (RLIMIT_AS)."""

KINDS = ("truncated", "header", "vlr", "misnamed", "ply", "text")
READERS = ("info", "convert")

# --------------------------------------------------------------------------- the sources


@dataclass
class Source:
    """A small valid file cut from the real data (``family``: las, ply or text)."""

    name: str
    path: str
    family: str
    origin: str
    bounds: tuple = ()  # (xmin, ymin, zmin, xmax, ymax, zmax) of the cut's points


def _cut(src: Path, dest: Path, n: int, *, evlr: bool = False, extra: bool = False) -> tuple:
    import laspy
    import numpy as np
    from laspy.vlrs.vlrlist import VLRList

    with laspy.open(src) as reader:
        header = reader.header
        rec = reader.read_points(n)
    las = laspy.LasData(header, rec)
    if extra:
        las.add_extra_dims([
            laspy.ExtraBytesParams("height", "int32", description="fuzz extra"),
            laspy.ExtraBytesParams("vec", "3i2", scales=[0.01] * 3, offsets=[0.0] * 3),
        ])
        las["height"] = np.arange(len(las), dtype=np.int32)
        las["vec"] = np.zeros((len(las), 3), dtype=np.int16) + np.arange(3, dtype=np.int16)
    if evlr:
        las.evlrs = VLRList([laspy.VLR("lidarfx", 7, "fuzz evlr", b"lidarfx" * 20)])
    v10 = str(header.version) == "1.0"
    if v10:  # laspy writes 1.1 (the same header layout); the version byte is set back to 1.0 below
        las.header.version = laspy.header.Version(1, 1)
    las.write(dest)
    if v10:
        dest.write_bytes(_put(dest.read_bytes(), 25, "<B", 0))
    xyz = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    return tuple(float(v) for v in (*xyz.min(axis=0), *xyz.max(axis=0)))


def _table(las_path: Path):
    """(xyz, intensity, classification, rgb or None) of a cut, read with laspy."""
    import laspy
    import numpy as np

    las = laspy.read(las_path)
    xyz = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    rgb = None
    if "red" in las.point_format.dimension_names:
        rgb = np.column_stack([np.asarray(las.red), np.asarray(las.green), np.asarray(las.blue)]) >> 8
    return xyz, np.asarray(las.intensity), np.asarray(las.classification), rgb


def _write_ply(path: Path, xyz, intensity, cls, rgb, fmt: str) -> None:
    import numpy as np

    props = [("x", "double", "f8"), ("y", "double", "f8"), ("z", "double", "f8"),
             ("intensity", "ushort", "u2"), ("classification", "uchar", "u1")]
    if rgb is not None:
        props += [("red", "uchar", "u1"), ("green", "uchar", "u1"), ("blue", "uchar", "u1")]
    head = [b"ply", f"format {fmt} 1.0".encode(), b"comment cut from real data",
            f"element vertex {len(xyz)}".encode()]
    head += [f"property {t} {n}".encode() for n, t, _ in props]
    head += [b"end_header"]
    cols = [xyz[:, 0], xyz[:, 1], xyz[:, 2], intensity, cls] + ([rgb[:, 0], rgb[:, 1], rgb[:, 2]] if rgb is not None else [])
    if fmt == "ascii":
        lines = [" ".join(f"{v:.3f}" if j < 3 else str(int(v)) for j, v in enumerate(row)) for row in zip(*(c.tolist() for c in cols))]
        body = ("\n".join(lines) + "\n").encode()
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        table = np.empty(len(xyz), dtype=[(n, order + d) for n, _, d in props])
        for (n, _, _), c in zip(props, cols):
            table[n] = c
        body = table.tobytes()
    path.write_bytes(b"\n".join(head) + b"\n" + body)


def _write_text(path: Path, xyz, intensity, cls, *, delimiter: str, header: str | None, count: bool) -> None:
    rows = [delimiter.join([f"{a:.3f}", f"{b:.3f}", f"{c:.3f}", str(int(i)), str(int(k))])
            for (a, b, c), i, k in zip(xyz.tolist(), intensity.tolist(), cls.tolist())]
    if header:
        rows.insert(0, header)
    if count:
        rows.insert(0, str(len(xyz)))
    path.write_text("\n".join(rows) + "\n")


def cut_sources(dest: Path, n: int = CUT_POINTS) -> list[Source]:
    """Cut the real files into ``dest`` (see the module docstring); ``[]`` without the real data."""
    dest = dest.resolve()
    dest.mkdir(parents=True, exist_ok=True)
    found = sorted(p for p in REAL.glob("*") if p.suffix.lower() in (".las", ".laz")) if REAL.is_dir() else []
    out: list[Source] = []
    for i, p in enumerate(found):
        cut = dest / f"cut_{p.stem}{p.suffix.lower()}"
        out.append(Source(cut.name, str(cut), "las", p.name, _cut(p, cut, n)))
        if p.suffix.lower() == ".laz" and i % 3 == 0:  # an uncompressed copy: header mutations reach LAS point data
            plain = dest / f"cut_{p.stem}_plain.las"
            out.append(Source(plain.name, str(plain), "las", p.name, _cut(p, plain, n)))
    by_name = {p.name: p for p in found}
    extras = [("warsaw_small.las", "eb", ".las", {"extra": True}), ("samp11-utm.laz", "eb", ".laz", {"extra": True}),
              ("crop_1.laz", "evlr", ".las", {"evlr": True}), ("test_data_77050_627755_LA93_IGN69.laz", "evlr", ".las",
                                                              {"evlr": True})]
    for name, tag, ext, kw in extras:
        if name in by_name:
            p = by_name[name]
            cut = dest / f"cut_{p.stem}_{tag}{ext}"
            out.append(Source(cut.name, str(cut), "las", name, _cut(p, cut, n, **kw)))
    las_cuts = [s for s in out if s.name.endswith(".las")]
    for j, s in enumerate(las_cuts[:4]):
        xyz, inten, cls, rgb = _table(Path(s.path))
        stem = Path(s.name).stem
        for fmt in ("binary_little_endian", "ascii", "binary_big_endian"):
            ply = dest / f"{stem}_{fmt.split('_')[-1] if fmt != 'ascii' else 'ascii'}.ply"
            _write_ply(ply, xyz, inten, cls, rgb, fmt)
            out.append(Source(ply.name, str(ply), "ply", s.origin, s.bounds))
        for ext, delim, head, count in ((".xyz", " ", "x y z intensity classification", False),
                                        (".txt", " ", None, False),
                                        (".csv", ",", "//X,Y,Z,Intensity,Class", False),
                                        (".pts", " ", None, True)):
            txt = dest / f"{stem}{ext}"
            _write_text(txt, xyz, inten, cls, delimiter=delim, header=head, count=count)
            out.append(Source(txt.name, str(txt), "text", s.origin, s.bounds))
    return out


# --------------------------------------------------------------------------- LAS layout


@dataclass
class Layout:
    """Where the fields of a LAS/LAZ file are (read from its bytes, not through laspy)."""

    size: int
    minor: int
    header_size: int
    point_offset: int
    n_vlrs: int
    pf_byte: int
    rec_len: int
    count: int
    vlrs: list = field(default_factory=list)  # (position, user_id, record_id, length)
    evlr_start: int = 0
    n_evlrs: int = 0

    @property
    def compressed(self) -> bool:
        return bool(self.pf_byte & 0xC0)

    @property
    def v14(self) -> bool:
        return self.minor >= 4

    def vlr(self, user: str, record: int | None = None):
        for v in self.vlrs:
            if v[1] == user and (record is None or v[2] == record):
                return v
        return None


def layout(data: bytes) -> Layout:
    u = struct.unpack_from
    minor = data[25]
    lay = Layout(size=len(data), minor=minor, header_size=u("<H", data, 94)[0], point_offset=u("<I", data, 96)[0],
                 n_vlrs=u("<I", data, 100)[0], pf_byte=data[104], rec_len=u("<H", data, 105)[0],
                 count=u("<I", data, 107)[0])
    if minor >= 4:
        lay.evlr_start, lay.n_evlrs = u("<QI", data, 235)
        lay.count = u("<Q", data, 247)[0]
    pos = lay.header_size
    for _ in range(lay.n_vlrs):
        user = data[pos + 2: pos + 18].split(b"\0")[0].decode("ascii", "replace")
        record, length = u("<HH", data, pos + 18)
        lay.vlrs.append((pos, user, record, length))
        pos += 54 + length
    return lay


def _put(data: bytes, offset: int, fmt: str, *values) -> bytes:
    out = bytearray(data)
    struct.pack_into(fmt, out, offset, *values)
    return bytes(out)


# --------------------------------------------------------------------------- mutation operators
# Each operator: (label, applies(layout or source) -> bool, mutate(data, layout, rng) -> (bytes, ext or None)).
# ``ext`` None keeps the source's extension.

Op = tuple[str, Callable, Callable]


def _ANY(lay) -> bool:
    return True


def _V14(lay) -> bool:
    return lay.v14


def _LAZ(lay) -> bool:
    return lay.compressed


def _PLAIN(lay) -> bool:
    return not lay.compressed


_NAN = float("nan")
_INF = float("inf")


def _scale(axis: int, value: float) -> Callable:
    return lambda d, lay, rng: (_put(d, 131 + 8 * axis, "<d", value), None)


def _offset(axis: int, value: float) -> Callable:
    return lambda d, lay, rng: (_put(d, 155 + 8 * axis, "<d", value), None)


def _legacy_count(f: Callable) -> Callable:
    return lambda d, lay, rng: (_put(d, 107, "<I", f(lay) & 0xFFFFFFFF), None)


def _count14(f: Callable) -> Callable:
    return lambda d, lay, rng: (_put(d, 247, "<Q", f(lay) & 0xFFFFFFFFFFFFFFFF), None)


def _u32(offset: int, f: Callable) -> Callable:
    return lambda d, lay, rng: (_put(d, offset, "<I", f(lay) & 0xFFFFFFFF), None)


def _u16(offset: int, f: Callable) -> Callable:
    return lambda d, lay, rng: (_put(d, offset, "<H", f(lay) & 0xFFFF), None)


def _pf(f: Callable) -> Callable:
    return lambda d, lay, rng: (_put(d, 104, "<B", f(lay, rng) & 0xFF), None)


def _other_format(lay, rng) -> int:
    base = lay.pf_byte & 0x3F
    return (lay.pf_byte & 0xC0) | rng.choice([i for i in range(11) if i != base])


HEADER_OPS: list[Op] = [
    ("legacy count 0", _ANY, _legacy_count(lambda lay: 0)),
    ("legacy count n+1", _ANY, _legacy_count(lambda lay: lay.count + 1)),
    ("legacy count n-1", _ANY, _legacy_count(lambda lay: lay.count - 1)),
    ("legacy count 2n", _ANY, _legacy_count(lambda lay: 2 * lay.count)),
    ("legacy count 2^32-1", _ANY, _legacy_count(lambda lay: 2**32 - 1)),
    ("1.4 count 0", _V14, _count14(lambda lay: 0)),
    ("1.4 count n+1", _V14, _count14(lambda lay: lay.count + 1)),
    ("1.4 count 2^63-1", _V14, _count14(lambda lay: 2**63 - 1)),
    ("1.4 count 2^40", _V14, _count14(lambda lay: 2**40)),
    ("1.4 count 2^64-1", _V14, _count14(lambda lay: 2**64 - 1)),
    ("offset to points 0", _ANY, _u32(96, lambda lay: 0)),
    ("offset to points header-1", _ANY, _u32(96, lambda lay: lay.header_size - 1)),
    ("offset to points +1", _ANY, _u32(96, lambda lay: lay.point_offset + 1)),
    ("offset to points -1", _ANY, _u32(96, lambda lay: lay.point_offset - 1)),
    ("offset to points = size", _ANY, _u32(96, lambda lay: lay.size)),
    ("offset to points 2^32-1", _ANY, _u32(96, lambda lay: 2**32 - 1)),
    ("header size 0", _ANY, _u16(94, lambda lay: 0)),
    ("header size 65535", _ANY, _u16(94, lambda lay: 65535)),
    ("header size 226", _ANY, _u16(94, lambda lay: 226)),
    ("scale x 0", _ANY, _scale(0, 0.0)),
    ("scale z negative", _ANY, _scale(2, -0.01)),
    ("scale y NaN", _ANY, _scale(1, _NAN)),
    ("scale x inf", _ANY, _scale(0, _INF)),
    ("scale z 1e308", _ANY, _scale(2, 1e308)),
    ("scale y 1e-320", _ANY, _scale(1, 1e-320)),
    ("scale x 1e6", _ANY, _scale(0, 1e6)),
    ("offset x NaN", _ANY, _offset(0, _NAN)),
    ("offset y 1e308", _ANY, _offset(1, 1e308)),
    ("offset z -inf", _ANY, _offset(2, -_INF)),
    ("offset x 1e17", _ANY, _offset(0, 1e17)),
    ("record length 0", _ANY, _u16(105, lambda lay: 0)),
    ("record length -1", _ANY, _u16(105, lambda lay: lay.rec_len - 1)),
    ("record length +1", _ANY, _u16(105, lambda lay: lay.rec_len + 1)),
    ("record length 65535", _ANY, _u16(105, lambda lay: 65535)),
    ("point format other", _ANY, _pf(_other_format)),
    ("point format 11..63", _ANY, _pf(lambda lay, rng: (lay.pf_byte & 0xC0) | rng.randrange(11, 64))),
    ("point format compression bit toggled", _ANY, _pf(lambda lay, rng: lay.pf_byte ^ 0x80)),
    ("point format 255", _ANY, _pf(lambda lay, rng: 255)),
    ("version 1.9", _ANY, lambda d, lay, rng: (_put(d, 24, "<BB", 1, 9), None)),
    ("version 2.0", _ANY, lambda d, lay, rng: (_put(d, 24, "<BB", 2, 0), None)),
    ("version 1.4 on an older header", (lambda lay: not lay.v14), lambda d, lay, rng: (_put(d, 24, "<BB", 1, 4), None)),
    ("signature LASG", _ANY, lambda d, lay, rng: (b"LASG" + d[4:], None)),
    ("bounds NaN, min > max", _ANY, lambda d, lay, rng: (_put(d, 179, "<6d", -1.0, 1.0, _NAN, _NAN, -_INF, _INF), None)),
    ("global encoding 0xFFFF", _ANY, _u16(6, lambda lay: 0xFFFF)),
    ("points by return > total", _ANY, lambda d, lay, rng: (_put(d, 111, "<5I", *([2**32 - 1] * 5)), None)),
    ("legacy 0, 1.4 count n", _V14, _legacy_count(lambda lay: 0)),
    ("random header bytes", _ANY, lambda d, lay, rng: (_scramble(d, rng, 94, lay.header_size, 6), None)),
]


def _scramble(data: bytes, rng: random.Random, lo: int, hi: int, k: int) -> bytes:
    out = bytearray(data)
    for _ in range(k):
        if hi > lo:
            out[rng.randrange(lo, min(hi, len(out)))] = rng.randrange(256)
    return bytes(out)


def _truncate(f: Callable) -> Callable:
    return lambda d, lay, rng: (d[: max(0, min(len(d) - 1, f(lay, rng)))], None)


TRUNCATED_OPS: list[Op] = [
    ("1 byte", _ANY, _truncate(lambda lay, rng: 1)),
    ("4 bytes (signature only)", _ANY, _truncate(lambda lay, rng: 4)),
    ("100 bytes (mid header)", _ANY, _truncate(lambda lay, rng: 100)),
    ("226 bytes", _ANY, _truncate(lambda lay, rng: 226)),
    ("header only", _ANY, _truncate(lambda lay, rng: lay.header_size)),
    ("inside the first VLR header", (lambda lay: lay.vlrs), _truncate(lambda lay, rng: lay.vlrs[0][0] + 20)),
    ("inside the last VLR", (lambda lay: lay.vlrs), _truncate(lambda lay, rng: lay.vlrs[-1][0] + 54 + lay.vlrs[-1][3] // 2)),
    ("at the point data", _ANY, _truncate(lambda lay, rng: lay.point_offset)),
    ("one byte into the points", _ANY, _truncate(lambda lay, rng: lay.point_offset + 1)),
    ("one and a half records", _ANY, _truncate(lambda lay, rng: lay.point_offset + lay.rec_len * 3 // 2)),
    ("half the file", _ANY, _truncate(lambda lay, rng: lay.size // 2)),
    ("last byte missing", _ANY, _truncate(lambda lay, rng: lay.size - 1)),
    ("last record missing", _PLAIN, _truncate(lambda lay, rng: lay.size - lay.rec_len - (lay.size - lay.evlr_start if lay.evlr_start else 0))),
    ("at a random offset", _ANY, _truncate(lambda lay, rng: rng.randrange(1, lay.size))),
    ("inside the EVLR", (lambda lay: lay.n_evlrs), _truncate(lambda lay, rng: lay.evlr_start + 30)),
    ("LAZ chunk table cut", _LAZ, _truncate(lambda lay, rng: lay.size - 6)),
]


def _vlr_field(user: str, record: int | None, rel: int, fmt: str, value) -> Callable:
    def f(d, lay, rng):
        v = lay.vlr(user, record)
        got = value(v, lay) if callable(value) else value
        return _put(d, v[0] + rel, fmt, *(got if isinstance(got, tuple) else (got,))), None
    return f


def _has(user: str, record: int | None = None) -> Callable:
    return lambda lay: lay.vlr(user, record) is not None


def _eb(rel: int, fmt: str, value) -> Callable:
    """Set a field of the first extra-bytes descriptor (VLR data starts 54 bytes after its header)."""
    return _vlr_field("LASF_Spec", 4, 54 + rel, fmt, value)


_EB = _has("LASF_Spec", 4)
_LAZVLR = _has("laszip encoded", 22204)


def _laz_vlr(rel: int, fmt: str, value) -> Callable:
    # laszip VLR data: compressor u16, coder u16, version 3 x u8 + u16, options u32, chunk size u32,
    # num points i64, num bytes i64, num items u16, then items (type, size, version: 3 x u16)
    return _vlr_field("laszip encoded", 22204, 54 + rel, fmt, value)


def _chunk_table(value) -> Callable:
    return lambda d, lay, rng: (_put(d, lay.point_offset, "<q", value(lay) if callable(value) else value), None)


def _evlr(rel: int, fmt: str, value) -> Callable:
    return lambda d, lay, rng: (_put(d, rel, fmt, value(lay) if callable(value) else value), None)


def _evlr_len(value) -> Callable:
    return lambda d, lay, rng: (_put(d, lay.evlr_start + 20, "<Q", value), None)


_GEOKEYS = _has("LASF_Projection", 34735)
_WKT = _has("LASF_Projection", 2112)


def _EVLR(lay) -> bool:
    return lay.n_evlrs > 0


VLR_OPS: list[Op] = [
    ("VLR count +1", _ANY, _u32(100, lambda lay: lay.n_vlrs + 1)),
    ("VLR count 2^32-1", _ANY, _u32(100, lambda lay: 2**32 - 1)),
    ("VLR count 0", (lambda lay: lay.n_vlrs), _u32(100, lambda lay: 0)),
    ("VLR count 1000", _ANY, _u32(100, lambda lay: 1000)),
    ("first VLR length 65535", (lambda lay: lay.vlrs), lambda d, lay, rng: (_put(d, lay.vlrs[0][0] + 20, "<H", 65535), None)),
    ("first VLR length 0", (lambda lay: lay.vlrs), lambda d, lay, rng: (_put(d, lay.vlrs[0][0] + 20, "<H", 0), None)),
    ("last VLR length +1", (lambda lay: lay.vlrs), lambda d, lay, rng: (_put(d, lay.vlrs[-1][0] + 20, "<H", lay.vlrs[-1][3] + 1), None)),
    ("last VLR length -1", (lambda lay: lay.vlrs and lay.vlrs[-1][3]), lambda d, lay, rng: (_put(d, lay.vlrs[-1][0] + 20, "<H", lay.vlrs[-1][3] - 1), None)),
    ("VLR user id bytes 0xFF", (lambda lay: lay.vlrs), lambda d, lay, rng: (_put(d, lay.vlrs[0][0] + 2, "16s", b"\xff" * 16), None)),
    ("extra bytes type 0, options 0", _EB, _eb(2, "<BB", (0, 0))),
    ("extra bytes type 0, options 255", _EB, _eb(2, "<BB", (0, 255))),
    ("extra bytes type 31", _EB, _eb(2, "<B", 31)),
    ("extra bytes type 255", _EB, _eb(2, "<B", 255)),
    ("extra bytes type 30 (3 doubles)", _EB, _eb(2, "<B", 30)),
    ("extra bytes type 10 (double)", _EB, _eb(2, "<B", 10)),
    ("extra bytes scale NaN", _EB, lambda d, lay, rng: (_put(_put(d, lay.vlr("LASF_Spec", 4)[0] + 54 + 3, "<B", 0x1F),
                                                            lay.vlr("LASF_Spec", 4)[0] + 54 + 112, "<3d", _NAN, _NAN, _NAN), None)),
    ("extra bytes scale 0", _EB, lambda d, lay, rng: (_put(_put(d, lay.vlr("LASF_Spec", 4)[0] + 54 + 3, "<B", 0x08),
                                                          lay.vlr("LASF_Spec", 4)[0] + 54 + 112, "<3d", 0.0, 0.0, 0.0), None)),
    ("extra bytes options 0xFF", _EB, _eb(3, "<B", 0xFF)),
    ("extra bytes empty name", _EB, _eb(4, "32s", b"")),
    ("extra bytes name 0xFF", _EB, _eb(4, "32s", b"\xff" * 32)),
    ("extra bytes name 'X'", _EB, _eb(4, "32s", b"X")),
    ("extra bytes name 'classification'", _EB, _eb(4, "32s", b"classification")),
    ("extra bytes VLR length 191", _EB, _vlr_field("LASF_Spec", 4, 20, "<H", 191)),
    ("extra bytes VLR length 0", _EB, _vlr_field("LASF_Spec", 4, 20, "<H", 0)),
    ("GeoTIFF key count 65535", _GEOKEYS, _vlr_field("LASF_Projection", 34735, 54 + 6, "<H", 65535)),
    ("GeoTIFF keys garbage", _GEOKEYS, lambda d, lay, rng: (_scramble(d, rng, lay.vlr("LASF_Projection", 34735)[0] + 54,
                                                                     lay.vlr("LASF_Projection", 34735)[0] + 54 + lay.vlr("LASF_Projection", 34735)[3], 40), None)),
    ("WKT not UTF-8", _WKT, lambda d, lay, rng: (_scramble(d, rng, lay.vlr("LASF_Projection", 2112)[0] + 54,
                                                          lay.vlr("LASF_Projection", 2112)[0] + 54 + lay.vlr("LASF_Projection", 2112)[3], 60), None)),
    ("WKT cut short", _WKT, lambda d, lay, rng: (_put(d, lay.vlr("LASF_Projection", 2112)[0] + 54, "12s", b'PROJCS["x",'), None)),
    ("laszip chunk size 0", _LAZVLR, _laz_vlr(12, "<I", 0)),
    ("laszip chunk size 1", _LAZVLR, _laz_vlr(12, "<I", 1)),
    ("laszip chunk size 2^32-1", _LAZVLR, _laz_vlr(12, "<I", 2**32 - 1)),
    ("laszip item count 0", _LAZVLR, _laz_vlr(32, "<H", 0)),
    ("laszip item count 65535", _LAZVLR, _laz_vlr(32, "<H", 65535)),
    ("laszip item type 99", _LAZVLR, _laz_vlr(34, "<H", 99)),
    ("laszip item size 65535", _LAZVLR, _laz_vlr(36, "<H", 65535)),
    ("laszip compressor 99", _LAZVLR, _laz_vlr(0, "<H", 99)),
    ("laszip special EVLR count 2^40", _LAZVLR, _laz_vlr(16, "<q", 2**40)),
    ("LAZ chunk table offset 0", _LAZ, _chunk_table(0)),
    ("LAZ chunk table offset -1", _LAZ, _chunk_table(-1)),
    ("LAZ chunk table past the end", _LAZ, _chunk_table(lambda lay: lay.size + 1000)),
    ("LAZ chunk table in the header", _LAZ, _chunk_table(50)),
    ("LAZ chunk count 2^32-1", _LAZ, lambda d, lay, rng: (_chunk_count(d, lay, 2**32 - 1), None)),
    ("EVLR start 0", _EVLR, _evlr(235, "<Q", 0)),
    ("EVLR start past the end", _EVLR, _evlr(235, "<Q", lambda lay: lay.size + 100)),
    ("EVLR start 2^63", _EVLR, _evlr(235, "<Q", 2**63)),
    ("EVLR start inside the points", _EVLR, _evlr(235, "<Q", lambda lay: lay.point_offset + 7)),
    ("EVLR count 2^32-1", _EVLR, _evlr(243, "<I", 2**32 - 1)),
    ("EVLR count 5", _EVLR, _evlr(243, "<I", 5)),
    ("EVLR length 2^63", _EVLR, _evlr_len(2**63)),
    ("EVLR count 3 on a file without", (lambda lay: lay.v14 and not lay.n_evlrs), lambda d, lay, rng: (_put(d, 235, "<QI", lay.size - 10, 3), None)),
]


def _chunk_count(data: bytes, lay: Layout, value: int) -> bytes:
    (table,) = struct.unpack_from("<q", data, lay.point_offset)
    if 0 < table <= len(data) - 8:
        return _put(data, table + 4, "<I", value)
    return data


def _ext_swap(new_ext: str) -> Callable:
    return lambda d, lay, rng: (d, new_ext)


MISNAMED_LAS_OPS: list[Op] = [
    ("LAZ named .las", _LAZ, _ext_swap(".las")),
    ("LAS named .laz", _PLAIN, _ext_swap(".laz")),
    ("LAS/LAZ named .ply", _ANY, _ext_swap(".ply")),
    ("LAS/LAZ named .xyz", _ANY, _ext_swap(".xyz")),
    ("LAS/LAZ named .txt", _ANY, _ext_swap(".txt")),
    ("LAS/LAZ named .csv", _ANY, _ext_swap(".csv")),
    ("LAS/LAZ named .npz", _ANY, _ext_swap(".npz")),
    ("LAS/LAZ named .npy", _ANY, _ext_swap(".npy")),
    ("empty .las", _ANY, lambda d, lay, rng: (b"", ".las")),
    ("empty .laz", _ANY, lambda d, lay, rng: (b"", ".laz")),
    ("garbage .las", _ANY, lambda d, lay, rng: (rng.randbytes(rng.randrange(10, 6000)), ".las")),
    ("garbage .laz", _ANY, lambda d, lay, rng: (rng.randbytes(rng.randrange(10, 6000)), ".laz")),
    ("LASF and garbage", _ANY, lambda d, lay, rng: (b"LASF" + rng.randbytes(rng.randrange(200, 4000)), None)),
    ("header of LASF, random body", _ANY, lambda d, lay, rng: (d[: lay.point_offset] + rng.randbytes(lay.size - lay.point_offset), None)),
    ("NUL bytes", _ANY, lambda d, lay, rng: (bytes(lay.size), None)),
    ("huge legacy count, header only", _ANY, lambda d, lay, rng: (_put(d[: lay.point_offset], 107, "<I", 2**32 - 1), None)),
    ("huge 1.4 count, header only", _V14, lambda d, lay, rng: (_put(_put(d[: lay.point_offset], 247, "<Q", 2**62), 107, "<I", 0), None)),
    ("huge count, a few points", _PLAIN, lambda d, lay, rng: (_put(d[: lay.point_offset + 5 * lay.rec_len], 107, "<I", 4_000_000_000), None)),
    ("huge 1.4 count, a few points", (lambda lay: lay.v14 and not lay.compressed), lambda d, lay, rng: (
        _put(_put(d[: lay.point_offset + 5 * lay.rec_len], 247, "<Q", 10**15), 107, "<I", 0), None)),
]

MISNAMED_OTHER_OPS: list[Op] = [  # on PLY / text sources
    ("PLY/text named .las", _ANY, _ext_swap(".las")),
    ("PLY/text named .laz", _ANY, _ext_swap(".laz")),
    ("empty .ply", _ANY, lambda d, lay, rng: (b"", ".ply")),
    ("empty .xyz", _ANY, lambda d, lay, rng: (b"", ".xyz")),
    ("empty .txt", _ANY, lambda d, lay, rng: (b"", ".txt")),
    ("empty .npz", _ANY, lambda d, lay, rng: (b"", ".npz")),
    ("garbage .ply", _ANY, lambda d, lay, rng: (rng.randbytes(rng.randrange(10, 6000)), ".ply")),
    ("garbage .xyz", _ANY, lambda d, lay, rng: (rng.randbytes(rng.randrange(10, 6000)), ".xyz")),
    ("garbage .npz", _ANY, lambda d, lay, rng: (b"PK\x03\x04" + rng.randbytes(rng.randrange(10, 3000)), ".npz")),
    ("garbage .npy", _ANY, lambda d, lay, rng: (b"\x93NUMPY\x01\x00" + rng.randbytes(rng.randrange(10, 3000)), ".npy")),
    ("npy with a huge shape", _ANY, lambda d, lay, rng: (_npy_header("<f8", (10**12, 3)) + bytes(48), ".npy")),
    ("npy of objects", _ANY, lambda d, lay, rng: (_npy_header("|O", (2, 3)) + bytes(48), ".npy")),
    ("npz with a huge member", _ANY, lambda d, lay, rng: (_npz({"xyz.npy": _npy_header("<f8", (10**12, 3)) + bytes(48)}), ".npz")),
    ("npz xyz of the wrong shape", _ANY, lambda d, lay, rng: (_npz({"xyz.npy": _npy_header("<f8", (4, 2)) + bytes(64)}), ".npz")),
    ("npz attribute of the wrong length", _ANY, lambda d, lay, rng: (_npz({"xyz.npy": _npy_header("<f8", (2, 3)) + bytes(48),
                                                                              "intensity.npy": _npy_header("<u2", (5,)) + bytes(10)}), ".npz")),
    ("npz with NaN coordinates", _ANY, lambda d, lay, rng: (_npz({"xyz.npy": _npy_header("<f8", (3, 3)) + struct.pack(
        "<9d", 1, 2, 3, _NAN, 2, 3, 4, _INF, 6)}), ".npz")),
    ("PLY header with a huge count, tiny body", _ANY, lambda d, lay, rng: (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 3000000000\nproperty double x\nproperty double y\n"
        b"property double z\nend_header\n" + bytes(72), ".ply")),
    ("ASCII PLY with a huge count", _ANY, lambda d, lay, rng: (
        b"ply\nformat ascii 1.0\nelement vertex 9000000000000000000\nproperty float x\nproperty float y\nproperty float z\n"
        b"end_header\n1 2 3\n4 5 6\n", ".ply")),
    (".pts count 10^15, three rows", _ANY, lambda d, lay, rng: (b"1000000000000000\n1 2 3 4\n5 6 7 8\n9 10 11 12\n", ".pts")),
]


def _npy_header(descr: str, shape: tuple) -> bytes:
    head = repr({"descr": descr, "fortran_order": False, "shape": shape}).encode()
    pad = 64 - (10 + len(head) + 1) % 64
    head = head + b" " * pad + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(head)) + head


def _npz(members: dict[str, bytes]) -> bytes:
    import io
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for name, blob in members.items():
            zf.writestr(zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0)), blob)  # reproducible bytes
    return buf.getvalue()


# PLY and text operators work on the file's text / bytes (``lay`` is the Source).

def _ply_split(d: bytes) -> tuple[list[bytes], bytes]:
    end = d.index(b"end_header\n") + len(b"end_header\n")
    return d[:end].split(b"\n")[:-1], d[end:]


def _ply_join(head: list[bytes], body: bytes) -> bytes:
    return b"\n".join(head) + b"\n" + body


def _ply_head(f: Callable) -> Callable:
    def op(d, src, rng):
        head, body = _ply_split(d)
        return _ply_join(f(head, rng), body), None
    return op


def _ply_count(value) -> Callable:
    def f(head, rng):
        return [(b"element vertex " + str(value(int(h.split()[2])) if callable(value) else value).encode())
                if h.startswith(b"element vertex") else h for h in head]
    return _ply_head(f)


def _is_ascii_ply(src) -> bool:
    return src.name.endswith("_ascii.ply")


def _is_binary_ply(src) -> bool:
    return src.name.endswith(".ply") and not src.name.endswith("_ascii.ply")


def _ply_body(f: Callable) -> Callable:
    def op(d, src, rng):
        head, body = _ply_split(d)
        return _ply_join(head, f(body, rng)), None
    return op


def _ascii_values(token: str) -> Callable:
    def f(body, rng):
        lines = body.split(b"\n")
        for _ in range(5):
            i = rng.randrange(max(1, len(lines) - 1))
            parts = lines[i].split(b" ")
            parts[rng.randrange(3)] = token.encode()
            lines[i] = b" ".join(parts)
        return b"\n".join(lines)
    return f


def _binary_nonfinite(every: bool) -> Callable:
    """Little-endian NaN / inf written over the first record's x, y, z (or over every 8 bytes):
    in a big-endian file the same bytes read as tiny numbers, a point near 0 far from the rest."""
    def f(body, rng):
        out = bytearray(body)
        if every:
            for k in range(0, len(out) - 8, 8):
                struct.pack_into("<d", out, k, _NAN)
        elif len(out) >= 24:
            for k in (0, 8, 16):
                struct.pack_into("<d", out, k, rng.choice([_NAN, _INF, -_INF]))
        return bytes(out)
    return f


PLY_OPS: list[Op] = [
    ("no end_header", _ANY, lambda d, src, rng: (d.replace(b"end_header\n", b"", 1), None)),
    ("no vertex element", _ANY, _ply_head(lambda h, rng: [x.replace(b"element vertex", b"element point") for x in h])),
    ("vertex count +10", _ANY, _ply_count(lambda n: n + 10)),
    ("vertex count x2", _ANY, _ply_count(lambda n: 2 * n)),
    ("vertex count 2^31-1", _ANY, _ply_count(2**31 - 1)),
    ("vertex count 2^63", _ANY, _ply_count(2**63)),
    ("vertex count -5", _ANY, _ply_count(-5)),
    ("vertex count 'many'", _ANY, _ply_count("many")),
    ("vertex count 0, data follow", _ANY, _ply_count(0)),
    ("unknown property type", _ANY, _ply_head(lambda h, rng: [x.replace(b"property double x", b"property float128 x") for x in h])),
    ("format binary_middle_endian", _ANY, _ply_head(lambda h, rng: [b"format binary_middle_endian 1.0" if x.startswith(b"format") else x for x in h])),
    ("format 2.0", _ANY, _ply_head(lambda h, rng: [x.replace(b" 1.0", b" 2.0") if x.startswith(b"format") else x for x in h])),
    ("ascii body declared binary", _is_ascii_ply, _ply_head(lambda h, rng: [b"format binary_little_endian 1.0" if x.startswith(b"format") else x for x in h])),
    ("binary body declared ascii", _is_binary_ply, _ply_head(lambda h, rng: [b"format ascii 1.0" if x.startswith(b"format") else x for x in h])),
    ("byte order swapped", _is_binary_ply, _ply_head(lambda h, rng: [
        x.replace(b"little", b"TMP").replace(b"big", b"little").replace(b"TMP", b"big") for x in h])),
    ("list property in the vertices", _ANY, _ply_head(lambda h, rng: [x.replace(b"property double x", b"property list uchar int x") for x in h])),
    ("x missing", _ANY, _ply_head(lambda h, rng: [x.replace(b"property double x", b"property double q") for x in h])),
    ("duplicate property", _ANY, _ply_head(lambda h, rng: [x.replace(b"property double y", b"property double x") for x in h])),
    ("x declared as uchar", _ANY, _ply_head(lambda h, rng: [x.replace(b"property double x", b"property uchar x") for x in h])),
    ("extra property declared", _ANY, _ply_head(lambda h, rng: h[:-1] + [b"property float extra", h[-1]])),
    ("face element before vertex, huge", _ANY, _ply_head(lambda h, rng: h[:2] + [b"element face 4000000000", b"property list uchar int vertex_indices"] + h[2:])),
    ("no magic", _ANY, lambda d, src, rng: (d[4:], None)),
    ("magic PLY", _ANY, lambda d, src, rng: (b"PLY" + d[3:], None)),
    ("NUL in the header", _ANY, lambda d, src, rng: (d.replace(b"comment", b"comm\0nt", 1), None)),
    ("non-ASCII header", _ANY, lambda d, src, rng: (d.replace(b"comment cut", b"comment \xff\xfe cut", 1), None)),
    ("header line of 1 MB", _ANY, lambda d, src, rng: (d.replace(b"comment cut", b"comment " + b"a" * (1 << 20), 1), None)),
    ("CRLF line ends", _is_ascii_ply, lambda d, src, rng: (d.replace(b"\n", b"\r\n"), None)),
    ("binary garbage body", _ANY, _ply_body(lambda b, rng: rng.randbytes(len(b)))),
    ("body cut in half", _ANY, _ply_body(lambda b, rng: b[: len(b) // 2])),
    ("body cut by one byte", _ANY, _ply_body(lambda b, rng: b[:-1])),
    ("NaN/inf in x, y, z", _is_binary_ply, _ply_body(_binary_nonfinite(False))),
    ("every double NaN", _is_binary_ply, _ply_body(_binary_nonfinite(True))),
    ("nan in the text", _is_ascii_ply, _ply_body(_ascii_values("nan"))),
    ("inf in the text", _is_ascii_ply, _ply_body(_ascii_values("-inf"))),
    ("1e400 in the text", _is_ascii_ply, _ply_body(_ascii_values("1e400"))),
    ("word in the text", _is_ascii_ply, _ply_body(_ascii_values("abc"))),
    ("fraction for an integer", _is_ascii_ply, _ply_body(lambda b, rng: b.replace(b"\n", b" 1.5\n", 3))),
    ("a short line", _is_ascii_ply, _ply_body(lambda b, rng: b.replace(b" ", b"\n", 1))),
    ("a long line", _is_ascii_ply, _ply_body(lambda b, rng: b.replace(b"\n", b" 7 7 7\n", 1))),
    ("blank lines", _is_ascii_ply, _ply_body(lambda b, rng: b.replace(b"\n", b"\n\n", 5))),
    ("all points NaN (text)", _is_ascii_ply, _ply_body(lambda b, rng: b"\n".join(
        b" ".join([b"nan", b"nan", b"nan", *ln.split(b" ")[3:]]) if ln else ln for ln in b.split(b"\n")))),
]


def _text_lines(f: Callable) -> Callable:
    def op(d, src, rng):
        lines = d.split(b"\n")
        return b"\n".join(f(lines, rng)), None
    return op


def _data_start(lines: list[bytes]) -> int:
    for i, ln in enumerate(lines):
        t = ln.strip()
        if t and t[:1] in b"0123456789-." and len(t.split()) > 1 or (b"," in t and t[:1].isdigit()):
            return i
    return 0


def _text_token(token: bytes, k: int = 5) -> Callable:
    def f(lines, rng):
        s = _data_start(lines)
        for _ in range(k):
            i = rng.randrange(s, max(s + 1, len(lines) - 1))
            sep = b"," if b"," in lines[i] else b" "
            parts = lines[i].split(sep)
            if parts and parts[0]:
                parts[rng.randrange(min(3, len(parts)))] = token
                lines[i] = sep.join(parts)
        return lines
    return f


def _every_coordinate(token: bytes) -> Callable:
    def f(lines, rng):
        s = _data_start(lines)
        out = lines[:s]
        for ln in lines[s:]:
            sep = b"," if b"," in ln else b" "
            parts = ln.split(sep)
            out.append(sep.join([token] * 3 + parts[3:]) if len(parts) >= 3 else ln)
        return out
    return f


TEXT_OPS: list[Op] = [
    ("header only", _ANY, _text_lines(lambda ls, rng: ls[: _data_start(ls)] or [b"x y z"])),
    ("point count larger than the data", (lambda s: s.name.endswith(".pts")), _text_lines(lambda ls, rng: [b"99999999"] + ls[1:])),
    ("point count 10^18", (lambda s: s.name.endswith(".pts")), _text_lines(lambda ls, rng: [b"1000000000000000000"] + ls[1:])),
    ("point count line added", (lambda s: not s.name.endswith(".pts")), _text_lines(lambda ls, rng: [b"123456789"] + ls)),
    ("a row with fewer columns", _ANY, _text_lines(lambda ls, rng: ls[:50] + [ls[50].rsplit(b" " if b" " in ls[50] else b",", 2)[0]] + ls[51:])),
    ("a row with more columns", _ANY, _text_lines(lambda ls, rng: ls[:60] + [ls[60] + (b",9,9" if b"," in ls[60] else b" 9 9")] + ls[61:])),
    ("nan values", _ANY, _text_lines(_text_token(b"nan"))),
    ("inf values", _ANY, _text_lines(_text_token(b"-inf"))),
    ("NaN spelt NaN", _ANY, _text_lines(_text_token(b"NaN", 40))),
    ("every coordinate nan", _ANY, _text_lines(_every_coordinate(b"nan"))),
    ("every coordinate inf", _ANY, _text_lines(_every_coordinate(b"inf"))),
    ("1e400", _ANY, _text_lines(_text_token(b"1e400"))),
    ("1e308 everywhere", _ANY, _text_lines(_every_coordinate(b"1e308"))),
    ("a word in the data", _ANY, _text_lines(_text_token(b"abc", 1))),
    ("binary garbage lines", _ANY, lambda d, src, rng: (d[: len(d) // 2] + rng.randbytes(2000) + d[len(d) // 2:], None)),
    ("binary garbage file", _ANY, lambda d, src, rng: (rng.randbytes(len(d) // 4), None)),
    ("latin-1 bytes", _ANY, lambda d, src, rng: (b"# caf\xe9\n" + d.replace(b"\n", b" \xe9\n", 2), None)),
    ("NUL bytes", _ANY, lambda d, src, rng: (d.replace(b"\n", b"\0\n", 3), None)),
    ("UTF-8 BOM", _ANY, lambda d, src, rng: (b"\xef\xbb\xbf" + d, None)),
    ("UTF-16", _ANY, lambda d, src, rng: (d[:3000].decode("ascii", "replace").encode("utf-16"), None)),
    ("a line of 2 MB", _ANY, _text_lines(lambda ls, rng: ls[:10] + [b"1" * (2 << 20)] + ls[10:])),
    ("mixed delimiters", _ANY, _text_lines(lambda ls, rng: [ln.replace(b" ", b";", 1).replace(b",", b";", 1) if i % 7 == 3 else ln for i, ln in enumerate(ls)])),
    ("decimal commas with ;", _ANY, _text_lines(lambda ls, rng: [ln.replace(b".", b",").replace(b" ", b";") for ln in ls])),
    ("only comments", _ANY, _text_lines(lambda ls, rng: [b"# " + ln for ln in ls])),
    ("one column", _ANY, _text_lines(lambda ls, rng: [ln.split(b" ")[0].split(b",")[0] for ln in ls])),
    ("two columns", _ANY, _text_lines(lambda ls, rng: [b" ".join(ln.replace(b",", b" ").split()[:2]) for ln in ls])),
    ("blank lines", _ANY, _text_lines(lambda ls, rng: [ln + (b"\n\n   " if i % 9 == 0 else b"") for i, ln in enumerate(ls)])),
    ("trailing delimiter", _ANY, _text_lines(lambda ls, rng: [ln + (b"," if b"," in ln else b" ,") if ln else ln for ln in ls])),
    ("header with duplicate names", _ANY, _text_lines(lambda ls, rng: [b"x y z x x"] + ls[_data_start(ls):])),
    ("header with more names", _ANY, _text_lines(lambda ls, rng: [b"x y z intensity classification extra more"] + ls[_data_start(ls):])),
    ("header with empty names", _ANY, _text_lines(lambda ls, rng: [b"x,y,z,,"] + ls[_data_start(ls):])),
    ("classification 1e20", _ANY, _text_lines(lambda ls, rng: [b"x y z intensity classification"] + [
        b" ".join(ln.replace(b",", b" ").split()[:4] + [b"1e20"]) for ln in ls[_data_start(ls):] if ln])),
    ("negative intensity", _ANY, _text_lines(lambda ls, rng: [b"x y z intensity classification"] + [
        b" ".join(ln.replace(b",", b" ").split()[:3] + [b"-5", b"2"]) for ln in ls[_data_start(ls):] if ln])),
    ("quoted fields", _ANY, _text_lines(lambda ls, rng: [b",".join(b'"' + t + b'"' for t in ln.replace(b",", b" ").split()) for ln in ls])),
    ("lone signs", _ANY, _text_lines(_text_token(b"-", 3))),
    ("hex floats", _ANY, _text_lines(_text_token(b"0x1p3", 3))),
    ("truncated mid-number", _ANY, lambda d, src, rng: (d[: len(d) // 2 + 3], None)),
    ("CR line ends", _ANY, lambda d, src, rng: (d.replace(b"\n", b"\r"), None)),
]

# --------------------------------------------------------------------------- the corpus


@dataclass
class Mutant:
    name: str
    path: str
    kind: str
    what: str
    source: str
    bounds: tuple = ()
    seed: int = 0


def _ops_for(kind: str) -> list[tuple[Op, str]]:
    """(operator, family of the sources it applies to) of one kind."""
    table = {
        "truncated": [(op, "las") for op in TRUNCATED_OPS],
        "header": [(op, "las") for op in HEADER_OPS],
        "vlr": [(op, "las") for op in VLR_OPS],
        "misnamed": [(op, "las") for op in MISNAMED_LAS_OPS] + [(op, "other") for op in MISNAMED_OTHER_OPS],
        "ply": [(op, "ply") for op in PLY_OPS],
        "text": [(op, "text") for op in TEXT_OPS],
    }
    return table[kind]


def build_corpus(sources: list[Source], dest: Path, seed: int = 0, per_kind: int = MUTANTS_PER_KIND) -> list[Mutant]:
    """``per_kind`` mutants of every kind in :data:`KINDS` written into ``dest`` (deterministic in ``seed``):
    operator ``j mod len(ops)`` of the kind on a source chosen by ``j`` and ``seed``."""
    dest = dest.resolve()
    dest.mkdir(parents=True, exist_ok=True)
    blobs = {s.name: Path(s.path).read_bytes() for s in sources}
    layouts = {s.name: layout(blobs[s.name]) for s in sources if s.family == "las"}
    out: list[Mutant] = []
    for k, kind in enumerate(KINDS):
        ops = _ops_for(kind)
        j = made = 0
        tries = 0
        while made < per_kind and tries < per_kind * 20:
            tries += 1
            (label, applies, mutate), family = ops[(j + seed * 5) % len(ops)]
            j += 1
            pool = [s for s in sources if (s.family == "las") == (family == "las") and
                    (family in ("las", "other") or s.family == family)]
            rng = random.Random(f"{seed}:{kind}:{j}")
            cands = [s for s in pool if applies(layouts[s.name] if s.family == "las" else s)]
            if not cands:
                continue
            src = cands[(j * 7 + seed * 13) % len(cands)]
            data, ext = mutate(blobs[src.name], layouts.get(src.name), rng)
            ext = ext or Path(src.name).suffix
            name = f"{kind}_{made:03d}_s{seed}{ext}"
            path = dest / name
            path.write_bytes(data)
            out.append(Mutant(name, str(path), kind, label, src.name, tuple(src.bounds), seed))
            made += 1
    return out


# --------------------------------------------------------------------------- command lines


def _section(m: Mutant) -> list[str]:
    if m.bounds:
        x0, y0, _, x1, y1, _ = m.bounds
        ym = (y0 + y1) / 2
        return ["--from", f"{x0:.3f},{ym:.3f}", "--to", f"{x1:.3f},{ym:.3f}", "--width", "2"]
    return ["--from", "0,5", "--to", "10,5", "--width", "1"]


PIPELINE = Path(__file__).with_name("fuzz_pipeline.json")
"""The pipeline ``lidarfx run`` gets (its read and write paths replaced by --input / --output)."""


def _middle(m: Mutant) -> str:
    """--bounds of the middle of the source's extent."""
    if m.bounds:
        x0, y0, _, x1, y1, _ = m.bounds
        return f"{x0 + (x1 - x0) / 4:.3f},{y0 + (y1 - y0) / 4:.3f},{x1 - (x1 - x0) / 4:.3f},{y1 - (y1 - y0) / 4:.3f}"
    return "0,0,10,10"


_CONVERT_OUT = ("o.laz", "o.ply", "o.xyz", "o.las", "o.npz")
_WHERE = ("z > 0", "classification in [2, 6] or z > 10", "intensity >= 0 and not (z < -1e6)")

COMMANDS: dict[str, Callable[[Mutant, int], list[str]]] = {
    "info": lambda m, i: ["info", m.path] + (["--json"] if i % 2 else []),
    "convert": lambda m, i: ["convert", m.path, "{OUT}/" + _CONVERT_OUT[i % len(_CONVERT_OUT)]],
    "features": lambda m, i: ["features", m.path, "{OUT}/o.laz", "-r", "1", "-q"],
    "segment": lambda m, i: ["segment", m.path, "{OUT}/o.laz", "--normal-radius", "1.5", "--growing-radius", "1.2",
                             "--max-distance", "0.15", "-q"],
    "select": lambda m, i: ["select", m.path, "{OUT}/o.laz", "-w", _WHERE[i % len(_WHERE)], "-q"],
    "ground": lambda m, i: ["ground", m.path, "{OUT}/o.laz", "--hag", "-q"],
    "dtm": lambda m, i: ["dtm", m.path, "{OUT}/o.asc", "-q"],
    "thin": lambda m, i: ["thin", m.path, "{OUT}/o" + Path(m.path).suffix if Path(m.path).suffix in (".las", ".laz") else "{OUT}/o.laz",
                          "--cell", "0.5", "-q"],
    "eigenclass": lambda m, i: ["eigenclass", m.path, "{OUT}/o.laz", "-r", "1", "-q"],
    "colour": lambda m, i: ["colour", m.path, "{OUT}/o.laz", "-q"],
    "render": lambda m, i: ["render", m.path, "{OUT}/o.png", "--size", "160x160", "-q"],
    "section": lambda m, i: ["section", m.path, "{OUT}/o.laz", *_section(m), "-q"],
    "classify predict": lambda m, i: ["classify", "predict", m.path, "{OUT}/o.laz", "--model", "default", "-q"],
    "edges": lambda m, i: ["edges", m.path, "{OUT}/o.geojson", "-r", "1", "-q"],
    "breaklines": lambda m, i: ["breaklines", m.path, "{OUT}/o.geojson", "-q"],
    "powerlines": lambda m, i: ["powerlines", m.path, "{OUT}/pl", "--no-picture", "-q"],
    "discontinuities": lambda m, i: ["discontinuities", m.path, "{OUT}/dc", "--no-picture", "-q"],
    "parts": lambda m, i: ["parts", m.path, "{OUT}/pa", "-r", "1", "--no-picture", "-q"],
    "members": lambda m, i: ["members", m.path, "{OUT}/o.geojson", "-q"],
    "report": lambda m, i: ["report", m.path, "{OUT}/rep", "--no-picture", "-q"],
    "crop": lambda m, i: ["crop", m.path, "{OUT}/o.laz", "--bounds", _middle(m), "--allow-empty", "-q"],
    "merge": lambda m, i: ["merge", m.path, "{OUT}/o.laz", "-q"],
    "filter": lambda m, i: ["filter", m.path, "{OUT}/o.laz", "--outliers", "statistical", "-q"] if i % 2 else
    ["filter", m.path, "{OUT}/o.laz", "--outliers", "radius", "--radius", "1", "--min-neighbours", "2", "-q"],
    "reproject": lambda m, i: ["reproject", m.path, "{OUT}/o.laz", "--to", "EPSG:4326", "-q"],
    "dsm": lambda m, i: ["dsm", m.path, "{OUT}/o.asc", "-r", "1", "-q"],
    "chm": lambda m, i: ["chm", m.path, "{OUT}/o.asc", "-r", "1", "-q"],
    "run": lambda m, i: ["run", str(PIPELINE), "--input", m.path, "--output", "{OUT}/o.laz", "-q"]
    + (["--chunk-size", "20", "--workers", "1"] if i % 2 else []),
}
"""Every command that reads a cloud, with small parameters (``{OUT}``: the run's output folder)."""


@dataclass
class Case:
    i: int
    command: str
    kind: str
    mutant: str
    what: str
    argv: list
    input: str


def plan(mutants: list[Mutant], per_command: int = PER_COMMAND) -> list[Case]:
    """Every mutant through the readers; each other command through ``per_command`` mutants of
    every kind, chosen by rotation so that the commands see different mutants."""
    cases: list[Case] = []
    by_kind: dict[str, list[Mutant]] = {}
    for m in mutants:
        by_kind.setdefault(m.kind, []).append(m)
    others = [c for c in COMMANDS if c not in READERS]
    for kind, ms in by_kind.items():
        for m_i, m in enumerate(ms):
            for c in READERS:
                cases.append(Case(0, c, kind, m.name, m.what, COMMANDS[c](m, m_i), m.path))
        step = max(1, len(ms) // len(others))
        for c_i, c in enumerate(others):
            for t in range(min(per_command, len(ms))):
                m = ms[(c_i * step + t) % len(ms)]
                cases.append(Case(0, c, kind, m.name, m.what, COMMANDS[c](m, t), m.path))
    # interleave the kinds and commands so that both workers get a similar mix
    rng = random.Random(0)
    rng.shuffle(cases)
    for i, c in enumerate(cases):
        c.i = i
    return cases


# --------------------------------------------------------------------------- the contract


def check_run(rc, stderr: str, left: list[str], changed: bool) -> list[str]:
    """The problems of one run (empty when it keeps the contract; see the module docstring)."""
    problems = []
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("lidarfx: error:")]
    stray = [ln for ln in lines if not ln.startswith(("lidarfx: error:", "lidarfx: warning:"))]
    if "Traceback" in stderr:
        problems.append("traceback: " + (lines[-1] if lines else "")[:300])
    elif stray:
        problems.append("stray stderr: " + stray[0][:300])
    if rc not in (0, 2):
        problems.append(f"exit code {rc!r}")
    if rc == 2 and len(errors) != 1:
        problems.append(f"{len(errors)} error lines")
    if rc == 0 and errors:
        problems.append("an error line with exit code 0")
    if rc != 0 and left:
        problems.append(f"left behind after an error: {left[:5]}")
    if changed:
        problems.append("the input or its folder changed")
    return problems


def _digest(path: str) -> str:
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError as exc:
        return f"unreadable: {exc}"


# --------------------------------------------------------------------------- the worker


class _Timeout(BaseException):
    """Raised by the alarm: a BaseException so that no ``except Exception`` of the product eats it."""


def _hang() -> int:
    import signal

    signal.pthread_sigmask(signal.SIG_BLOCK, [signal.SIGALRM])  # deaf to its own alarm: the parent must kill it
    time.sleep(3600)
    return 0


def _raise() -> int:
    raise RuntimeError("a bug")


_SELF_TEST = {"__crash__": lambda: os._exit(3), "__hang__": _hang, "__raise__": _raise}
"""Commands that only the harness's own test uses: a worker that dies, hangs or meets a bug."""


def _reuse_slow_setup(cli) -> None:
    """Two costs paid once per worker instead of once per run, neither of them under test: the
    argument parser (0.1 s to build, reused as a fresh process would rebuild the same one) and the
    shipped classifier (about 5 s to load with skops; each run gets its own unpickled copy)."""
    import functools
    import pickle

    import lidarfx.classify as classify

    cli.build_parser = functools.lru_cache(maxsize=1)(cli.build_parser)
    load = classify.load_model
    cache: dict = {}

    def load_model(path, *args, **kwargs):
        if path != "default" or args or kwargs:
            return load(path, *args, **kwargs)
        if "default" not in cache:
            cache["default"] = pickle.dumps(load(path))
        return pickle.loads(cache["default"])

    classify.load_model = load_model


def worker(cases_file: str, results_file: str, start: int, out_dir: str, case_seconds: float) -> None:
    """Run the cases from index ``start`` in this process; one JSON line per case to ``results_file``
    (a ``{"begin": i}`` line before each, so that the parent knows which case killed a worker)."""
    import contextlib
    import io
    import resource
    import signal
    import traceback
    import warnings

    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_BYTES, MEMORY_BYTES))
    os.environ.setdefault("LIDARFX_COMPILE_NOTICE", "0")
    cases = json.loads(Path(cases_file).read_text())
    out = Path(out_dir)
    import lidarfx.cli
    from lidarfx.cli import main
    from lidarfx.errors import LidarfxWarning

    _reuse_slow_setup(lidarfx.cli)

    def on_alarm(signum, frame):
        raise _Timeout()

    signal.signal(signal.SIGALRM, on_alarm)
    with open(results_file, "a", buffering=1) as res:
        for case in cases[start:]:
            res.write(json.dumps({"begin": case["i"]}) + "\n")
            shutil.rmtree(out, ignore_errors=True)
            out.mkdir(parents=True)
            folder = Path(case["input"]).parent
            before = (_digest(case["input"]), sorted(os.listdir(folder)))
            argv = [a.replace("{OUT}", str(out)) for a in case["argv"]]
            err, std = io.StringIO(), io.StringIO()
            warnings.filterwarnings("default", category=LidarfxWarning)  # resets "shown once" as a fresh process
            t0 = time.perf_counter()
            rc: object = None
            limit = case.get("seconds", case_seconds)
            try:
                with contextlib.redirect_stderr(err), contextlib.redirect_stdout(std):
                    if limit:
                        signal.setitimer(signal.ITIMER_REAL, limit)
                    try:
                        rc = _SELF_TEST[argv[0]]() if argv and argv[0] in _SELF_TEST else main(argv)
                    finally:
                        signal.setitimer(signal.ITIMER_REAL, 0)
            except SystemExit as exc:
                rc = exc.code
            except _Timeout:
                rc = "timeout"
            except BaseException:  # noqa: BLE001 - what the CLI would print as a traceback
                err.write(traceback.format_exc())
                rc = 1
            seconds = time.perf_counter() - t0
            left = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
            changed = (_digest(case["input"]), sorted(os.listdir(folder))) != before
            problems = check_run(rc, err.getvalue(), left, changed)
            if rc == "timeout":
                problems = [f"no answer in {limit:g} s"]
            res.write(json.dumps({"i": case["i"], "rc": rc if isinstance(rc, (int, str)) or rc is None else str(rc),
                                  "seconds": round(seconds, 3), "problems": problems,
                                  "stderr": err.getvalue()[-3000:]}) + "\n")


# --------------------------------------------------------------------------- the parent


@dataclass
class Outcome:
    cases: int = 0
    results: dict = field(default_factory=dict)  # case index -> result dict
    restarts: int = 0
    seconds: float = 0.0
    warmup: dict = field(default_factory=dict)

    def bad(self) -> list[dict]:
        return [r for r in self.results.values() if r["problems"]]


def _worker_env() -> dict:
    src = Path(__file__).resolve().parents[1] / "src"
    env = dict(os.environ)
    env["PYTHONPATH"] = str(src) + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("LIDARFX_COMPILE_NOTICE", "0")
    env["PYTHONFAULTHANDLER"] = "1"
    return env


def _run_share(cases: list[dict], work: Path, tag: str, case_seconds: float, outcome: Outcome, log,
               grace: float) -> None:
    """Run ``cases`` in one worker process at a time, restarting it after a death or a hang."""
    cases_file = work / f"cases_{tag}.json"
    cases_file.write_text(json.dumps(cases))
    results_file = work / f"results_{tag}.jsonl"
    results_file.write_text("")
    limits = {c["i"]: c.get("seconds", case_seconds) for c in cases}
    start = 0
    pos = 0
    while start < len(cases):
        stderr_path = work / f"worker_{tag}.stderr"
        with open(stderr_path, "w") as errlog:
            proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "worker", str(cases_file),
                                     str(results_file), str(start), str(work / f"out_{tag}"), str(case_seconds)],
                                    stdout=subprocess.DEVNULL, stderr=errlog, env=_worker_env(), cwd=str(work))
        began: tuple[int, float] | None = None
        hung = False
        while True:
            finished = proc.poll() is not None
            with open(results_file, "rb") as fh:
                fh.seek(pos)
                chunk = fh.read()
            complete = chunk[: chunk.rfind(b"\n") + 1]
            pos += len(complete)
            for line in complete.decode().splitlines():
                rec = json.loads(line)
                if "begin" in rec:
                    began = (rec["begin"], time.monotonic())
                else:
                    outcome.results[rec["i"]] = rec
                    began = None
                    log(rec)
            if finished:
                break
            limit = limits.get(began[0], case_seconds) if began else 0
            if began and limit and time.monotonic() - began[1] > limit + grace:
                proc.kill()  # the worker this function started: no answer to its own alarm
                proc.wait()
                hung = True
                break
            time.sleep(0.05)
        if began is not None and began[0] not in outcome.results:
            rc = proc.returncode
            if hung:
                why = f"no answer in {limits[began[0]] + grace:g} s (worker killed)"
            elif rc is not None and rc < 0:
                why = f"worker killed by signal {-rc}"
            else:
                why = f"worker died (exit {rc})"
            tail = stderr_path.read_text(errors="replace")[-2000:]
            rec = {"i": began[0], "rc": rc, "seconds": None, "problems": [why], "stderr": tail}
            outcome.results[began[0]] = rec
            log(rec)
            outcome.restarts += 1
        elif proc.returncode and not any(c["i"] in outcome.results for c in cases[start:]):
            tail = stderr_path.read_text(errors="replace")[-2000:]
            raise RuntimeError(f"the fuzz worker failed before its first case (exit {proc.returncode}): {tail}")
        remaining = [k for k, c in enumerate(cases) if c["i"] not in outcome.results]
        if not remaining:
            break
        start = remaining[0]


def run_cases(cases: list[Case], work: Path, *, workers: int = 2, case_seconds: float = CASE_SECONDS,
              warmup: list[list[str]] = (), log=None, grace: float = 30.0) -> Outcome:
    """Run ``cases`` in ``workers`` long-lived worker processes (in threads of this process).
    ``warmup`` argvs run first in every worker without a time limit (compiling or loading kernels)
    and are not counted.  A worker silent ``grace`` seconds past a case's limit is killed."""
    import threading

    work = work.resolve()
    work.mkdir(parents=True, exist_ok=True)
    outcome = Outcome(cases=len(cases))
    lock = threading.Lock()
    failures: list[BaseException] = []

    def share_thread(*args):
        try:
            _run_share(*args)
        except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread
            failures.append(exc)

    def note(rec):
        if log is not None:
            with lock:
                log(rec)

    t0 = time.perf_counter()
    shares = [[asdict(c) for c in cases[w::workers]] for w in range(workers)]
    threads = []
    for w, share in enumerate(shares):
        warm = [{"i": -1 - k, "command": "warm-up", "kind": "", "mutant": "", "what": "", "argv": argv,
                 "input": argv[1] if argv[0] != "classify" else argv[2], "seconds": 0} for k, argv in enumerate(warmup)]
        t = threading.Thread(target=share_thread, args=(warm + share, work, str(w), case_seconds, outcome, note, grace))
        t.start()
        threads.append(t)
    for t in threads:
        t.join()
    if failures:
        raise failures[0]
    outcome.warmup = {i: r for i, r in outcome.results.items() if i < 0}
    outcome.results = {i: r for i, r in outcome.results.items() if i >= 0}
    outcome.seconds = time.perf_counter() - t0
    return outcome


def warmup_argvs(sources: list[Source]) -> list[list[str]]:
    """Every command once on a valid cut (kernels compiled or loaded before the timed cases)."""
    good = next((s for s in sources if s.name.startswith("cut_warsaw_small")), None) or next(
        (s for s in sources if s.family == "las"), None)
    if good is None:
        return []
    m = Mutant(good.name, good.path, "warm-up", "", good.name, tuple(good.bounds))
    return [COMMANDS[c](m, 0) for c in COMMANDS]


def summary(outcome: Outcome, cases: list[Case]) -> str:
    by_i = {c.i: c for c in cases}
    lines = [f"{outcome.cases} runs, {len(outcome.bad())} bad, {outcome.restarts} worker restarts, "
             f"{outcome.seconds:.0f} s"]
    for r in sorted(outcome.bad(), key=lambda r: r["i"]):
        c = by_i[r["i"]]
        lines.append(f"  BAD {c.command} on {c.mutant} ({c.kind}: {c.what}): {'; '.join(r['problems'])}")
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) == 7 and sys.argv[1] == "worker":
        worker(sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5], float(sys.argv[6]))
    else:
        sys.exit("usage: python tests/fuzzcorpus.py worker CASES RESULTS START OUTDIR SECONDS")
