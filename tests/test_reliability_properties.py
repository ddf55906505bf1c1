"""Properties of the readers and of the selection parser on hostile input (hypothesis).

Readers: perturbed LAS/LAZ headers written as bytes, PLY files from a small grammar (declared
counts and types that lie), text tables (non-finite values, comments, header lines) and garbage:
``lidarfx.io.read`` either returns a cloud consistent with the bytes or raises
:class:`~lidarfx.errors.LidarfxError`, never another exception, and never allocates more than the
file can hold (``tracemalloc`` peak against the file size: no allocation sized by a number read
from a file without checking it against the file's real size).

Selection: expressions from the grammar of ``lidarfx.select`` give the mask of an independent
point-by-point evaluation; random strings and token soups either give a mask of the right length
or raise LidarfxError, and never reach ``eval`` / ``exec`` / ``compile``.

Also here: the rule for NaN / infinite coordinates (docs/io.md) and one test per damaged-file
failure the fuzz suite found (``tests/test_reliability_fuzz.py``), on synthetic files.
"""
from __future__ import annotations

import builtins
import contextlib
import io
import math
import signal
import struct
import subprocess
import sys
import time
import tracemalloc
import warnings
from pathlib import Path

import laspy
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fuzzcorpus as fc
from lidarfx.cloud import PointCloud
from lidarfx.errors import LidarfxError, LidarfxWarning
from lidarfx.io import MAX_COORDINATE, read
from lidarfx.select import evaluate

BOUNDED = settings(deadline=None, derandomize=True, database=None, print_blob=False,
                   suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                          HealthCheck.data_too_large])
SLACK_BYTES = 48 << 20
"""Allocation allowed beyond 32 x the file size: a reader's fixed chunk buffers."""
WHAT = f"a NaN, infinite or out-of-range (beyond ±{MAX_COORDINATE:g}) x, y or z"
"""How the warning and the error of the coordinate rule name the points left out."""


def _usable(xyz: np.ndarray) -> np.ndarray:
    """Rows the coordinate rule keeps: finite and within MAX_COORDINATE (docs/io.md)."""
    with np.errstate(invalid="ignore"):
        return (np.abs(xyz) <= MAX_COORDINATE).all(axis=1)


READ_SECONDS = 20
"""Longest a read of these small files may take (a reader looping on a count read from the
file fails the test instead of hanging it)."""


def _too_slow(signum, frame):
    raise TimeoutError(f"reading took more than {READ_SECONDS} s")


def _read(path: Path):
    """``read(path)`` -> (cloud or None, peak bytes allocated); any exception but LidarfxError fails."""
    previous = signal.signal(signal.SIGALRM, _too_slow)
    signal.setitimer(signal.ITIMER_REAL, READ_SECONDS)
    tracemalloc.start()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LidarfxWarning)
            try:
                cloud = read(path)
            except LidarfxError as exc:
                assert "\n" not in str(exc)
                cloud = None
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert peak <= 32 * path.stat().st_size + SLACK_BYTES, f"{peak} bytes allocated reading {path.stat().st_size}"
    return cloud, peak


# ============================================================================ LAS / LAZ headers


def _las_bytes(pf: int, n: int, *, compress: bool, extra: bool = False, evlr: bool = False) -> bytes:
    from laspy.vlrs.vlrlist import VLRList

    version = "1.4" if pf >= 6 or evlr else "1.2"
    las = laspy.LasData(laspy.LasHeader(point_format=pf, version=version))
    rng = np.random.default_rng(pf)
    las.header.scales = [0.01, 0.01, 0.001]
    las.header.offsets = [500000.0, 5200000.0, 0.0]
    las.x = 500000 + rng.uniform(0, 50, n)
    las.y = 5200000 + rng.uniform(0, 50, n)
    las.z = rng.uniform(0, 20, n)
    las.classification = rng.integers(0, 10, n).astype(np.uint8)
    if extra:
        las.add_extra_dims([laspy.ExtraBytesParams("height", "int32"),
                            laspy.ExtraBytesParams("vec", "3i2", scales=[0.01] * 3, offsets=[0.0] * 3)])
        las["height"] = np.arange(n, dtype=np.int32)
    if evlr:
        las.evlrs = VLRList([laspy.VLR("lidarfx", 7, "test", b"evlr" * 10)])
    buf = io.BytesIO()
    las.write(buf, do_compress=compress)
    return buf.getvalue()


BASES = {
    "pf0.las": _las_bytes(0, 37, compress=False),
    "pf3.las": _las_bytes(3, 23, compress=False),
    "pf6eb.las": _las_bytes(6, 41, compress=False, extra=True, evlr=True),
    "pf8.las": _las_bytes(8, 19, compress=False),
    "pf1.laz": _las_bytes(1, 300, compress=True),
    "pf7eb.laz": _las_bytes(7, 200, compress=True, extra=True),
}

_COUNT = st.one_of(st.sampled_from([0, 1, 2, 18, 19, 20, 22, 23, 24, 36, 37, 38, 40, 41, 42, 199, 200, 201, 299, 300, 301,
                                    2**31 - 1, 2**31, 2**32 - 1]), st.integers(0, 2**32 - 1))
_DOUBLE = st.one_of(st.sampled_from([0.0, -0.0, 0.01, -0.01, 1e-320, 1e300, 1e308, math.inf, -math.inf, math.nan,
                                     5e5, 1e17]), st.floats(allow_nan=True, allow_infinity=True))
FIELDS = {  # name: (offset, struct format, values) -- the LAS 1.2 / 1.4 header
    "version minor": (25, "<B", st.integers(0, 255)),
    "header size": (94, "<H", st.one_of(st.sampled_from([0, 226, 227, 235, 375, 376]), st.integers(0, 65535))),
    "offset to points": (96, "<I", st.one_of(st.integers(0, 2000), st.integers(0, 2**32 - 1))),
    "VLR count": (100, "<I", st.one_of(st.integers(0, 10), st.integers(0, 2**32 - 1))),
    "point format": (104, "<B", st.one_of(st.integers(0, 11), st.integers(128, 139), st.integers(0, 255))),
    "record length": (105, "<H", st.one_of(st.integers(0, 80), st.integers(0, 65535))),
    "legacy count": (107, "<I", _COUNT),
    "scale x": (131, "<d", _DOUBLE), "scale y": (139, "<d", _DOUBLE), "scale z": (147, "<d", _DOUBLE),
    "offset x": (155, "<d", _DOUBLE), "offset y": (163, "<d", _DOUBLE), "offset z": (171, "<d", _DOUBLE),
    "EVLR start": (235, "<Q", st.one_of(st.integers(0, 5000), st.integers(0, 2**64 - 1))),
    "EVLR count": (243, "<I", st.one_of(st.integers(0, 4), st.integers(0, 2**32 - 1))),
    "1.4 count": (247, "<Q", st.one_of(_COUNT, st.integers(0, 2**64 - 1))),
}


def _reference_las(data: bytes):
    """(point count, xyz) of an uncompressed LAS from its bytes, as the header says."""
    minor = data[25]
    offset, = struct.unpack_from("<I", data, 96)
    rec_len, = struct.unpack_from("<H", data, 105)
    count, = struct.unpack_from("<I", data, 107)
    header_size, = struct.unpack_from("<H", data, 94)
    if minor >= 4 and header_size >= 375:  # a shorter header has no 1.4 fields, whatever its version
        count, = struct.unpack_from("<Q", data, 247)
    scales = np.array(struct.unpack_from("<3d", data, 131))
    offsets = np.array(struct.unpack_from("<3d", data, 155))
    raw = np.frombuffer(data, dtype=np.uint8, count=count * rec_len, offset=offset).reshape(count, rec_len)
    ints = raw[:, :12].copy().view("<i4").astype(np.float64)
    return count, ints * scales + offsets


@settings(BOUNDED, max_examples=400)
@given(base=st.sampled_from(sorted(BASES)), field=st.sampled_from(sorted(FIELDS)), data=st.data())
def test_one_lying_las_header_field_reads_consistently_or_is_refused(tmp_path_factory, base, field, data):
    blob = bytearray(BASES[base])
    offset, fmt, values = FIELDS[field]
    struct.pack_into(fmt, blob, offset, data.draw(values, label=field))
    _check_las(tmp_path_factory.mktemp("las") / base, blob)


def _check_las(path: Path, blob: bytearray) -> None:
    path.write_bytes(bytes(blob))
    cloud, _ = _read(path)
    if cloud is None:
        return
    assert _usable(cloud.xyz).all()  # LAS/LAZ never gives NaN, infinite or out-of-range coordinates
    if path.suffix == ".las" and not blob[104] & 0x80:
        count, xyz = _reference_las(bytes(blob))
        assert len(cloud) == count
        np.testing.assert_array_equal(cloud.xyz, xyz)


@settings(BOUNDED, max_examples=300)
@given(base=st.sampled_from(sorted(BASES)), edits=st.lists(st.sampled_from(sorted(FIELDS)), max_size=4, unique=True),
       data=st.data(), cut=st.one_of(st.none(), st.floats(0, 1)), flips=st.lists(st.tuples(st.floats(0, 1),
                                                                                          st.integers(0, 255)),
                                                                                max_size=3))
def test_a_perturbed_las_header_reads_consistently_or_is_refused(tmp_path_factory, base, edits, data, cut, flips):
    blob = bytearray(BASES[base])
    for name in edits:
        offset, fmt, values = FIELDS[name]
        struct.pack_into(fmt, blob, offset, data.draw(values, label=name))
    for where, value in flips:
        blob[min(len(blob) - 1, int(where * len(blob)))] = value
    if cut is not None:
        blob = blob[: int(cut * len(blob))]
    _check_las(tmp_path_factory.mktemp("las") / base, blob)


@settings(BOUNDED, max_examples=60)
@given(base=st.sampled_from(sorted(BASES)), data=st.data())
def test_laz_and_las_bodies_of_random_bytes_are_refused_or_read(tmp_path_factory, base, data):
    blob = BASES[base]
    head = struct.unpack_from("<I", blob, 96)[0]
    body = data.draw(st.binary(min_size=0, max_size=len(blob) - head + 64), label="body")
    path = tmp_path_factory.mktemp("body") / base
    path.write_bytes(blob[:head] + body)
    cloud, _ = _read(path)
    if cloud is not None:
        assert _usable(cloud.xyz).all()


# ============================================================================ PLY


_PLY_TYPES = {"char": "i1", "uchar": "u1", "short": "i2", "ushort": "u2", "int": "i4", "uint": "u4", "float": "f4",
              "double": "f8"}


@st.composite
def ply_files(draw):
    fmt = draw(st.sampled_from(["ascii", "binary_little_endian", "binary_big_endian"]))
    names = draw(st.lists(st.sampled_from(["x", "y", "z", "intensity", "nx", "red", "q"]), min_size=1, max_size=6,
                          unique=True))
    if draw(st.booleans()):
        names = ["x", "y", "z"] + [n for n in names if n not in "xyz"]
    types = [draw(st.sampled_from(sorted(_PLY_TYPES))) for _ in names]
    rows = draw(st.integers(0, 25))
    columns = []
    for t in types:
        dt = np.dtype(_PLY_TYPES[t])
        if dt.kind == "f":
            values = st.floats(width=32 if dt.itemsize == 4 else 64, allow_nan=True, allow_infinity=True)
        else:
            info = np.iinfo(dt)
            values = st.integers(int(info.min), int(info.max))
        columns.append(np.array(draw(st.lists(values, min_size=rows, max_size=rows)), dtype=dt))
    huge = [2**31 - 1, 2**32, 2**40, 2**63 - 1, 2**63, 2**64]
    declared = draw(st.one_of(st.just(rows), st.integers(0, rows + 5), st.sampled_from(huge)))
    before = draw(st.sampled_from([None, "camera", "face"]))  # an element before the vertices
    faces = draw(st.one_of(st.integers(0, 2), st.sampled_from(huge))) if before == "face" else 0
    head = ["ply", f"format {fmt} 1.0"]
    if before == "camera":
        head += ["element camera 1", "property float k"]
    elif before == "face":
        head += [f"element face {faces}", "property list uchar int vertex_indices"]
    head += [f"element vertex {declared}"] + [f"property {t} {n}" for n, t in zip(names, types)] + ["end_header"]
    written_faces = min(faces, 2)  # a huge face count lies: two are written
    order = "<" if fmt.endswith("little_endian") else ">"
    if fmt == "ascii":
        lines = [" ".join(repr(float(c[i])) if c.dtype.kind == "f" else str(int(c[i])) for c in columns)
                 for i in range(rows)]
        first = "1.5\n" if before == "camera" else "3 0 1 2\n" * written_faces
        body = (first + "".join(line + "\n" for line in lines)).encode()
    else:
        table = np.empty(rows, dtype=[(n, order + _PLY_TYPES[t]) for n, t in zip(names, types)])
        for n, c in zip(names, columns):
            table[n] = c
        face = b"\x03" + np.array([0, 1, 2], dtype=order + "i4").tobytes()
        first = np.array([1.5], dtype=order + "f4").tobytes() if before == "camera" else face * written_faces
        body = first + table.tobytes()
    tail = draw(st.one_of(st.just(b""), st.binary(max_size=40)))
    blob = ("\n".join(head) + "\n").encode() + body + tail
    return blob, dict(zip(names, columns)), rows, declared, bool(tail) or faces > written_faces


@settings(BOUNDED, max_examples=250)
@given(ply=ply_files())
def test_a_ply_file_reads_as_its_vertices_or_is_refused(tmp_path_factory, ply):
    blob, columns, rows, declared, tail = ply  # tail: bytes beyond the data, or a face count that lies
    path = tmp_path_factory.mktemp("ply") / "v.ply"
    path.write_bytes(blob)
    cloud, _ = _read(path)
    complete = {"x", "y", "z"} <= set(columns)
    if cloud is None:  # refused: only when the file is wrong or has no usable point
        if complete and declared == rows and not tail:
            xyz = np.column_stack([columns[c].astype(np.float64) for c in "xyz"]) if rows else np.empty((0, 3))
            assert rows and not _usable(xyz).any(), "a sound PLY file was refused"
        return
    assert complete and declared <= rows or (declared > rows and tail)
    if declared > rows:
        return  # the garbage tail held the missing vertices
    xyz = np.column_stack([columns[c][:declared].astype(np.float64) for c in "xyz"]).reshape(-1, 3)
    keep = _usable(xyz)
    np.testing.assert_array_equal(cloud.xyz, xyz[keep])
    for name, values in columns.items():
        if name not in "xyz":
            np.testing.assert_array_equal(cloud[name], values[:declared][keep])


# ============================================================================ text


@st.composite
def text_tables(draw):
    k = draw(st.integers(3, 6))
    rows = draw(st.lists(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=k, max_size=k), max_size=25))
    delimiter = draw(st.sampled_from([" ", ",", ";", "\t", "  "]))
    header = draw(st.booleans())
    names = ["x", "y", "z", "intensity", "u", "w"][:k]
    lines = [delimiter.join(names)] if header else []
    for r in rows:
        if draw(st.booleans()) and draw(st.booleans()):
            lines.append(draw(st.sampled_from(["", "   ", "# a comment", "#1 2 3"])))
        lines.append(delimiter.join(repr(v) for v in r))
    return "\n".join(lines) + draw(st.sampled_from(["", "\n", "\n\n"])), rows, names, header


@settings(BOUNDED, max_examples=250)
@given(table=text_tables(), ext=st.sampled_from([".xyz", ".txt", ".csv"]))
def test_a_text_table_reads_as_its_finite_rows(tmp_path_factory, table, ext):
    text, rows, names, header = table
    path = tmp_path_factory.mktemp("txt") / f"t{ext}"
    path.write_text(text)
    cloud, _ = _read(path)
    values = np.array(rows, dtype=np.float64).reshape(-1, len(names))
    keep = _usable(values[:, :3])
    if cloud is None:
        assert len(rows) and not keep.any(), "a sound table was refused"
        return
    np.testing.assert_array_equal(cloud.xyz, values[keep, :3])
    if not rows and not header:
        return  # an empty file: no columns to know
    for j, name in enumerate(names[3:], start=3):
        key = name if header else f"col{j}"
        np.testing.assert_array_equal(np.asarray(cloud[key], dtype=np.float64), values[keep, j])


@settings(BOUNDED, max_examples=200)
@given(blob=st.one_of(st.binary(max_size=300), st.text(max_size=300).map(lambda t: t.encode("utf-8", "surrogatepass")),
                      st.lists(st.sampled_from(["1", "2.5", "nan", "-inf", "1e400", "x", "y", "z", ",", ";", " ", "\t",
                                                "\n", "#", "//", '"', "0x1p3", "-", "\0", "\xe9"]), max_size=80)
                      .map(lambda ts: "".join(ts).encode("utf-8"))),
       ext=st.sampled_from([".xyz", ".txt", ".csv", ".pts", ".ply", ".las", ".laz", ".npy", ".npz"]))
def test_garbage_is_read_or_refused_in_every_format(tmp_path_factory, blob, ext):
    path = tmp_path_factory.mktemp("junk") / f"j{ext}"
    path.write_bytes(blob)
    cloud, _ = _read(path)
    if cloud is not None:
        assert _usable(cloud.xyz).all()


# ============================================================================ selection expressions

N = 40
_RNG = np.random.default_rng(7)
_CLOUD = PointCloud(
    np.column_stack([_RNG.uniform(-5, 5, N).round(1), _RNG.uniform(0, 3, N).round(2), _RNG.normal(10, 3, N)]),
    {"intensity": _RNG.integers(0, 20, N).astype(np.uint16),
     "classification": _RNG.integers(0, 9, N).astype(np.uint8),
     "planarity": np.where(_RNG.random(N) < 0.15, np.nan, _RNG.random(N)).astype(np.float32),
     "h": np.where(_RNG.random(N) < 0.1, np.inf, _RNG.normal(0, 2, N).round(1)),
     "planarity_r0.50": _RNG.choice([0.0, 0.5, 1.0, np.nan], N),
     "edge": _RNG.random(N) < 0.3},
)
_NUMERIC = ["x", "y", "z", "intensity", "classification", "planarity", "h", "planarity_r0.50", "`h`"]
_NUMBERS = ["0", "1", "2", "3", "0.5", ".5", "2.", "1e1", "1.5E-1", "10", "0.1", "7"]


def _value(name: str, i: int):
    """Point ``i``'s value of a name, as a numpy scalar of the evaluator's dtype (integers as int64)."""
    name = name.strip("`")
    if name in ("x", "y", "z"):
        return np.float64(_CLOUD.xyz[i, "xyz".index(name)])
    v = _CLOUD[name][i]
    return np.int64(v) if _CLOUD[name].dtype.kind in "iu" else v


# An expression tree: ("num", text) ("name", text) ("neg", e) ("bin", op, a, b) ("cmp", [e...], [ops])
# ("in", negate, e, [texts]) ("and"/"or", a, b) ("not", c) ("bool", text) ("flag",)

_PREC = {"+": 1, "-": 1, "*": 2, "/": 2, "%": 2}


def numbers(depth: int):
    leaf = st.one_of(st.sampled_from(_NUMERIC).map(lambda n: ("name", n)), st.sampled_from(_NUMBERS).map(lambda t: ("num", t)))
    if depth <= 0:
        return leaf
    sub = numbers(depth - 1)
    return st.one_of(
        leaf,
        sub.map(lambda e: ("neg", e)),
        st.tuples(st.sampled_from(list(_PREC)), sub, sub).map(lambda t: ("bin", *t)),
        st.tuples(sub, st.sampled_from(["0", "1", "2"])).map(lambda t: ("bin", "**", t[0], ("num", t[1]))),
    )


def conditions(depth: int):
    cmp = st.tuples(st.lists(numbers(2), min_size=2, max_size=3),
                    st.lists(st.sampled_from(["<", "<=", ">", ">=", "==", "!="]), min_size=2, max_size=2)
                    ).map(lambda t: ("cmp", t[0], t[1][: len(t[0]) - 1]))
    member = st.tuples(st.booleans(), numbers(1), st.lists(st.sampled_from(_NUMBERS + ["-1", "-0.5"]), max_size=4)
                       ).map(lambda t: ("in", *t))
    leaf = st.one_of(cmp, member, st.sampled_from([("bool", "True"), ("bool", "False"), ("flag",)]))
    if depth <= 0:
        return leaf
    sub = conditions(depth - 1)
    return st.one_of(leaf, sub.map(lambda c: ("not", c)),
                     st.tuples(st.sampled_from(["and", "or"]), sub, sub).map(lambda t: (t[0], t[1], t[2])))


def render(e, rng) -> str:
    """The text of a tree; parentheses where the grammar needs them, and sometimes more."""
    kind = e[0]
    if kind in ("num", "name", "bool"):
        return e[1]
    if kind == "flag":
        return "edge"
    if kind == "neg":
        inner = render(e[1], rng)
        return "-" + (inner if e[1][0] in ("num", "name", "neg") or (e[1][0] == "bin" and e[1][1] == "**")
                      else f"({inner})")
    if kind == "bin":
        op, a, b = e[1], e[2], e[3]
        if op == "**":
            base = render(a, rng)
            return (base if a[0] in ("num", "name") else f"({base})") + " ** " + render(b, rng)
        p = _PREC[op]

        def side(x, right):
            text = render(x, rng)
            tight = x[0] != "bin" or (x[1] == "**" or _PREC[x[1]] > p or (_PREC[x[1]] == p and not right))
            return text if tight and not rng.random() < 0.15 else f"({text})"

        return f"{side(a, False)} {op} {side(b, True)}"
    if kind == "cmp":
        parts = [render(e[1][0], rng)]
        for op, x in zip(e[2], e[1][1:]):
            parts += [op, render(x, rng)]
        return " ".join(parts)
    if kind == "in":
        return f"{render(e[2], rng)} {'not in' if e[1] else 'in'} [{', '.join(e[3])}]"
    if kind == "not":
        inner = render(e[1], rng)
        return "not " + (inner if e[1][0] in ("cmp", "in", "bool", "flag", "not") else f"({inner})")
    a, b = render(e[1], rng), render(e[2], rng)
    if e[1][0] == "or" and kind == "and":
        a = f"({a})"
    if e[2][0] in ("or", "and") and (kind == "and" or e[2][0] == "or"):
        b = f"({b})"  # right side: keep the tree's grouping
    return f"{a} {kind} {b}"


def _has_name(e) -> bool:
    return e[0] in ("name", "flag") or any(_has_name(x) for x in e[1:] if isinstance(x, tuple)) or any(
        _has_name(y) for x in e[1:] if isinstance(x, list) for y in x if isinstance(y, tuple))


def ref_value(e, i):
    kind = e[0]
    if kind == "num":
        return np.float64(float(e[1]))
    if kind == "name":
        return _value(e[1], i)
    if kind == "neg":
        return -ref_value(e[1], i)
    op, a, b = e[1], ref_value(e[2], i), ref_value(e[3], i)
    if op in ("/", "**"):
        a = a if isinstance(a, np.floating) else np.float64(a)
        b = b if isinstance(b, np.floating) else np.float64(b)
    if op == "**":  # the ufunc on one-element arrays: the same loop as the evaluator's arrays
        return np.power(np.array([a]), np.array([b]))[0]
    return {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.true_divide, "%": np.mod}[op](a, b)


def _nan(v) -> bool:
    return isinstance(v, np.floating) and bool(np.isnan(v))


def ref_condition(e, i) -> bool:
    kind = e[0]
    if kind == "bool":
        return e[1] == "True"
    if kind == "flag":
        return bool(_CLOUD["edge"][i])
    if kind == "not":
        return not ref_condition(e[1], i)
    if kind in ("and", "or"):
        a, b = ref_condition(e[1], i), ref_condition(e[2], i)
        return (a and b) if kind == "and" else (a or b)
    if kind == "in":
        v = ref_value(e[2], i)
        if _nan(v):
            return False
        items = [np.float64(float(t)) for t in e[3]]
        if isinstance(v, np.float32):
            items = [np.float32(t) for t in items]
        hit = any(v == t for t in items)
        return (not hit) if e[1] else hit
    ok = True
    for op, left, right in zip(e[2], e[1], e[1][1:]):
        a, b = ref_value(left, i), ref_value(right, i)
        if isinstance(a, np.float32) and not _has_name(right):  # float32 attributes meet constants as float32
            b = np.float32(b)
        elif isinstance(b, np.float32) and not _has_name(left):
            a = np.float32(a)
        if _nan(a) or _nan(b):
            ok = False
            continue
        ok &= bool({"<": a < b, "<=": a <= b, ">": a > b, ">=": a >= b, "==": a == b, "!=": a != b}[op])
    return ok


@contextlib.contextmanager
def _no_code_execution():
    calls = []

    def refuse(name):
        def f(*args, **kwargs):
            calls.append(name)
            raise AssertionError(f"{name} called")
        return f

    saved = builtins.eval, builtins.exec, builtins.compile
    builtins.eval, builtins.exec, builtins.compile = refuse("eval"), refuse("exec"), refuse("compile")
    try:
        yield calls
    finally:
        builtins.eval, builtins.exec, builtins.compile = saved


@settings(BOUNDED, max_examples=400)
@given(tree=conditions(2), seed=st.integers(0, 2**16))
def test_a_grammatical_expression_gives_the_reference_mask(tree, seed):
    import random

    text = render(tree, random.Random(seed))
    with _no_code_execution() as calls, np.errstate(all="ignore"):
        mask = evaluate(_CLOUD, text)
        expected = np.array([ref_condition(tree, i) for i in range(N)])
    assert not calls
    assert mask.dtype == bool and mask.shape == (N,)
    np.testing.assert_array_equal(mask, expected, err_msg=text)


_TOKENS = ["x", "z", "h", "intensity", "planarity", "edge", "nope", "`h`", "`", "1", "2.5", ".5", "1e3", "1e", "0x10",
           "+", "-", "*", "/", "%", "**", "//", "<", "<=", "==", "!=", "=", ">", "and", "or", "not", "in", "True",
           "False", "None", "(", ")", "[", "]", ",", ".", ":", ";", "'a'", '"b"', "&", "|", "~", "^", "@", "{", "}",
           "__import__", "('os')", ".system", "lambda", "eval", "exec", "open", "__class__", "__subclasses__", "\\",
           "\n", "\t", "é", "∞", "١"]


@settings(BOUNDED, max_examples=500)
@given(text=st.one_of(st.text(max_size=60), st.lists(st.sampled_from(_TOKENS), max_size=14).map(" ".join),
                      st.lists(st.sampled_from(_TOKENS), max_size=14).map("".join)))
def test_any_string_is_a_mask_or_one_line_error_never_code(text):
    with _no_code_execution() as calls, np.errstate(all="ignore"):
        try:
            mask = evaluate(_CLOUD, text)
        except LidarfxError as exc:
            assert str(exc) and "\n" not in str(exc)
        else:
            assert mask.dtype == bool and mask.shape == (N,)
    assert not calls


def test_code_in_an_expression_is_refused_and_not_run(tmp_path):
    target = tmp_path / "ran"
    for text in (f"__import__('os').system('touch {target}')", f"open('{target}', 'w')", "x.__class__",
                 "(lambda: 1)()", "[c for c in ()]", "eval('1')", "z > 0; import os", "x if y else z", "'a' < 'b'"):
        with pytest.raises(LidarfxError):
            evaluate(_CLOUD, text)
    assert not target.exists()
    with pytest.raises(LidarfxError, match="too long"):
        evaluate(_CLOUD, "x > 0 and " * 2000 + "x > 0")


# ============================================================================ NaN / infinite coordinates


def _warned(path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cloud = read(path)
    return cloud, [str(w.message) for w in caught if issubclass(w.category, LidarfxWarning)]


def test_points_with_nan_infinite_or_absurd_coordinates_are_left_out_with_one_warning(tmp_path):
    txt = tmp_path / "t.xyz"
    txt.write_text("x y z intensity\n1 2 3 10\nnan 2 3 11\n4 5 6 12\n7 inf 9 13\n1e400 0 0 14\n8 8 8 15\n"
                   "0 -2e12 0 16\n1e12 -1e12 5 17\n")
    cloud, msgs = _warned(txt)
    assert msgs == [f"{txt}: 4 of 8 points have {WHAT} and are left out"]
    np.testing.assert_array_equal(cloud.xyz, [[1, 2, 3], [4, 5, 6], [8, 8, 8], [1e12, -1e12, 5]])
    np.testing.assert_array_equal(cloud["intensity"], [10, 12, 15, 17])

    ply = tmp_path / "v.ply"
    table = np.array([(1.0, 2.0, 3.0, 7), (np.nan, 0.0, 0.0, 8), (4.0, 5.0, -np.inf, 9)],
                     dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("intensity", "<u2")])
    ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
                    b"property double z\nproperty ushort intensity\nend_header\n" + table.tobytes())
    cloud, msgs = _warned(ply)
    assert msgs == [f"{ply}: 2 of 3 points have {WHAT} and are left out"]
    np.testing.assert_array_equal(cloud.xyz, [[1, 2, 3]])
    assert cloud["intensity"].tolist() == [7]

    npz = tmp_path / "c.npz"
    np.savez(npz, xyz=np.array([[0.0, 0, 0], [np.nan, 1, 1], [2, 2, 2]]), label=np.array([5, 6, 7]))
    cloud, msgs = _warned(npz)
    assert len(msgs) == 1 and "1 of 3 points" in msgs[0]
    assert cloud["label"].tolist() == [5, 7]

    clean = tmp_path / "ok.xyz"
    clean.write_text("1 2 3\n4 5 6\n")
    assert _warned(clean)[1] == []


def test_a_file_without_a_finite_point_is_refused(tmp_path):
    path = tmp_path / "all.xyz"
    path.write_text("nan nan nan\ninf 0 0\n")
    with pytest.raises(LidarfxError, match="no point has usable coordinates"):
        read(path)
    empty = tmp_path / "empty.xyz"
    empty.write_text("x y z\n")
    assert len(read(empty)) == 0  # no points at all is not this error


@pytest.mark.parametrize("offset, fmt, value, message", [
    (131, "<d", math.nan, "scales"), (139, "<d", 0.0, "scales"), (147, "<d", math.inf, "scales"),
    (131, "<d", 1e308, "beyond"), (131, "<d", 1000.0, "beyond"), (171, "<d", 2e12, "beyond"),
    (163, "<d", -math.inf, "offsets"), (171, "<d", math.nan, "offsets"),
])
def test_las_scales_and_offsets_that_cannot_give_finite_coordinates_are_refused(tmp_path, offset, fmt, value, message):
    blob = bytearray(BASES["pf3.las"])
    struct.pack_into(fmt, blob, offset, value)
    path = tmp_path / "s.las"
    path.write_bytes(bytes(blob))
    with pytest.raises(LidarfxError, match=f"damaged LAS/LAZ file: .*{message}"):
        read(path)


def test_the_command_line_warns_in_one_line_and_goes_on(tmp_path, run_cli):
    path = tmp_path / "n.xyz"
    path.write_text("1 2 3\nnan 2 3\n4 5 6\n")
    rc, out, err = run_cli(["convert", str(path), str(tmp_path / "o.las")])
    assert rc == 0 and err == f"lidarfx: warning: {path}: 1 of 3 points have {WHAT} and are left out\n"
    assert len(read(tmp_path / "o.las")) == 2


# ============================================================================ the failures the fuzz suite found


@pytest.fixture(scope="module")
def damaged_sources(tmp_path_factory):
    """Synthetic stand-ins for the cuts of the real data: LAS 1.4 with extra bytes, an EVLR and a
    GeoTIFF key VLR; LAZ 1.2; binary PLY; text."""
    d = tmp_path_factory.mktemp("sources")
    (d / "a.las").write_bytes(BASES["pf6eb.las"])
    (d / "b.laz").write_bytes(BASES["pf7eb.laz"])
    (d / "c.laz").write_bytes(BASES["pf1.laz"])
    las = laspy.read(d / "c.laz")
    fc._write_ply(d / "d.ply", np.column_stack([las.x, las.y, las.z]), np.asarray(las.intensity),
                  np.asarray(las.classification), None, "binary_little_endian")
    fc._write_text(d / "e.xyz", np.column_stack([las.x, las.y, las.z]), np.asarray(las.intensity),
                   np.asarray(las.classification), delimiter=" ", header="x y z intensity classification", count=False)
    return d


FOUND = [  # (operator label, source) -- each was a hang, a crash, a traceback or a MemoryError before
    ("VLR count 2^32-1", "a.las"), ("offset to points 2^32-1", "a.las"), ("EVLR start 0", "a.las"),
    ("EVLR length 2^63", "a.las"), ("extra bytes type 0, options 0", "a.las"), ("extra bytes scale NaN", "a.las"),
    ("extra bytes scale 0", "a.las"), ("extra bytes empty name", "a.las"), ("version 2.0", "a.las"),
    ("laszip chunk size 1", "c.laz"), ("laszip item count 0", "c.laz"), ("legacy count 2^32-1", "c.laz"),
    ("1.4 count 2^64-1", "b.laz"), ("vertex count 2^63", "d.ply"), ("face element before vertex, huge", "d.ply"),
    ("npy with a huge shape", "e.xyz"), ("npz with a huge member", "e.xyz"), ("scale z 1e308", "c.laz"),
    ("header line of 1 MB", "d.ply"),
]


def _mutant(sources: Path, label: str, source: str, dest: Path) -> Path:
    import random

    op = next(op for kind in fc.KINDS for op, _ in fc._ops_for(kind) if op[0] == label)
    data = (sources / source).read_bytes()
    blob, ext = op[2](data, fc.layout(data) if source.endswith((".las", ".laz")) else None, random.Random(0))
    path = dest / f"m{ext or Path(source).suffix}"
    path.write_bytes(blob)
    return path


@pytest.mark.parametrize("label, source", FOUND)
def test_a_damaged_file_the_fuzz_suite_found_is_one_line_error(damaged_sources, tmp_path, label, source):
    path = _mutant(damaged_sources, label, source, tmp_path)
    cloud, _ = _read(path)
    assert cloud is None


def test_a_laz_chunk_table_of_2_32_chunks_is_refused_not_aborted(damaged_sources, tmp_path):
    """lazrs aborted the whole process (SIGABRT) allocating the announced chunks: run in a child."""
    path = _mutant(damaged_sources, "LAZ chunk count 2^32-1", "c.laz", tmp_path)
    code = "import sys; from lidarfx.cli import main; sys.exit(main(['info', sys.argv[1]]))"
    r = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2 and r.stderr.startswith("lidarfx: error:") and "chunk" in r.stderr, r.stderr[-500:]


def test_a_comma_table_with_a_line_of_spaces_is_read(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("x,y,z\n1,2,3\n   \n4,5,6\n")
    np.testing.assert_array_equal(read(path).xyz, [[1, 2, 3], [4, 5, 6]])


def test_a_default_radius_on_a_wall_is_quick():
    """A cloud whose plan view is a line (a vertical wall) made millimetre kNN columns: 50 s for
    2,000 points in ``colour``."""
    from lidarfx.neighbors import default_radius

    rng = np.random.default_rng(0)
    default_radius(rng.random((50, 3)))  # kernels compiled or loaded
    wall = np.column_stack([rng.uniform(0, 40, 2000), np.full(2000, 7.0), rng.uniform(0, 20, 2000)])
    t0 = time.perf_counter()
    r = default_radius(wall)
    assert time.perf_counter() - t0 < 10 and 0.5 < r < 3


def _powerline_scene(extra_xyz=(), extra_cls=()):
    rng = np.random.default_rng(1)
    g = np.column_stack([rng.uniform(0, 60, 3000), rng.uniform(0, 20, 3000), rng.normal(0, 0.02, 3000)])
    wire = np.column_stack([np.linspace(0, 60, 600), np.full(600, 10.0), 12 + 0.002 * (np.linspace(0, 60, 600) - 30) ** 2])
    xyz = np.vstack([g, wire, np.reshape(extra_xyz, (-1, 3))])
    cls = np.concatenate([np.full(3000, 2.0), np.full(600, 1.0), extra_cls])
    return PointCloud(xyz, {"classification": cls})


def test_powerlines_refuses_a_ground_grid_spanning_a_stray_point():
    from lidarfx.powerlines import extract_powerlines

    with pytest.raises(LidarfxError, match="ground grid of .* cells .*stray points"):
        extract_powerlines(_powerline_scene([[3e5, 6e5, 0.0]], [2.0]))


def test_powerlines_refuses_classes_that_are_no_class_codes():
    from lidarfx.powerlines import extract_powerlines

    cloud = _powerline_scene()
    cloud["classification"] = np.where(np.arange(len(cloud)) == 5, 1e20, cloud["classification"])
    with pytest.raises(LidarfxError, match="1 values that are no class code .* 1e\\+20"):
        extract_powerlines(cloud)


@pytest.mark.parametrize("command", [["discontinuities"], ["parts", "-r", "1"], ["powerlines"]], ids=lambda c: c[0])
def test_an_unwritable_cloud_leaves_no_table_behind(tmp_path, run_cli, command):
    """A text file's negative intensity cannot be stored in LAS: the folder commands wrote their
    tables first and left them when the cloud then failed."""
    from lidarfx.synth import GENERATORS

    face = GENERATORS["rockface"](density=8.0, seed=0)
    path = tmp_path / "face.xyz"
    rows = np.column_stack([face.xyz, np.full(len(face), -5.0)])
    np.savetxt(path, rows, fmt="%.4f", header="x y z intensity", comments="")
    rc, _, err = run_cli([command[0], str(path), str(tmp_path / "out"), "--no-picture", "-q", *command[1:]])
    assert rc == 2 and err.startswith("lidarfx: error:") and err.count("\n") == 1, err
    assert "intensity" in err and "outside the storable range" in err  # the cloud, after the analysis
    left = [p for p in (tmp_path / "out").rglob("*") if p.is_file()] if (tmp_path / "out").exists() else []
    assert left == []


def test_unregistered_extra_bytes_are_written_and_read_back(damaged_sources, tmp_path):
    """Point records longer than their format with no extra-bytes description (legal LAS): laspy
    reads the bytes as one 10-element field that no extra-bytes descriptor can hold; writing the
    cloud with a new attribute raised a traceback, then wrote a file that could not be read."""
    from lidarfx.io import write

    path = _mutant(damaged_sources, "extra bytes VLR length 191", "a.las", tmp_path)
    cloud = read(path)
    extra = [n for n in cloud.names if n.startswith("ExtraBytes")]
    assert extra == [f"ExtraBytes_{i}" for i in range(10)]
    for name, added in (("same.las", False), ("more.laz", True)):
        if added:
            cloud["added"] = np.arange(len(cloud), dtype=np.float32)
        write(cloud, tmp_path / name)
        back = read(tmp_path / name)
        assert sorted(back.names) == sorted(cloud.names)
        for n in cloud.names:
            np.testing.assert_array_equal(back[n], cloud[n])


def test_the_report_encodes_an_attribute_spanning_the_doubles():
    """Random point bytes give gps_time values from -1e308 to 1e308: their span overflowed."""
    from lidarfx.report._encode import encode_attribute

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        spec, codes = encode_attribute("gps_time", np.array([-1.7e308, 0.0, 1.7e308, np.nan, 5.0]))
    assert codes.tolist() == [0, 32767, 65534, 65535, 32767] and np.isfinite(spec["scale"])


def test_the_ground_filter_refuses_a_grid_of_gigabytes_for_a_few_points():
    """LAS records read one byte off (offset to the point data - 1) scatter 2,000 points over
    7 x 30 km: SMRF's 1.5 m grid asked for 99 million cells, several gigabytes."""
    from lidarfx.ground import classify_ground

    rng = np.random.default_rng(0)
    xyz = np.column_stack([rng.uniform(0, 7400, 2000), rng.uniform(0, 30200, 2000), rng.uniform(0, 4000, 2000)])
    with pytest.raises(LidarfxError, match="more than 1,000 per point"):
        classify_ground(PointCloud(xyz))
    dense = np.column_stack([rng.uniform(0, 60, 5000), rng.uniform(0, 60, 5000), rng.normal(0, 0.05, 5000)])
    assert classify_ground(PointCloud(np.vstack([dense, [[1000.0, 1000.0, 0.0]]]))).sum() > 4000  # one stray point
