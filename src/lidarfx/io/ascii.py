"""Text point clouds: ``.xyz`` ``.txt`` ``.csv`` ``.pts`` and Oakland ``.xyz_label_conf``.

Reading
    * Lines starting with ``#`` and blank lines are skipped.
    * The delimiter is detected on the first data line: ``;`` if present, else
      ``,``, else whitespace (spaces / tabs).
    * Column names come from, in order: the ``columns`` spec (``"-"`` or
      ``"skip"`` drops a column; columns beyond the spec are ignored), a header
      line (the first non-comment line when one of its fields is not a number,
      e.g. CloudCompare's ``//X,Y,Z,R,G,B`` or ``x y z intensity``; names are
      lower-cased, quotes and a leading ``//`` removed, ``r/g/b`` read as
      ``red/green/blue`` and ``class`` as ``classification``, in a spec too),
      the format default (Oakland: ``x y z label confidence``; Leica ``.pts``
      with 4 or 7 columns: ``x y z intensity [red green blue]``), else
      ``x, y, z, col3, col4, ...``.
    * A first data line holding one whole number followed by lines of three or
      more columns is a point count (Leica ``.pts``) and is skipped.
    * Values are parsed as float64 (``numpy.loadtxt``); columns named like an
      integer LAS dimension (``classification``, ``return_number``,
      ``intensity``, ``red`` ...) or ``label`` / ``segment_id`` become that
      integer dtype when every value is a whole number in range.

Writing
    A header line of names, then ``x y z`` with ``precision`` decimals
    (0 .. 17, default 3 = millimetres) and the attributes: integers as integers,
    float32 with 7 and float64 with 15 significant digits.  Space-separated,
    comma-separated for ``.csv``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterator

import numpy as np

from ..cloud import PointCloud
from ..errors import LidarfxError, check_int

ACCEPTS_COLUMNS = True
MAX_PRECISION = 17
"""Most decimals of x, y, z in text output: float64 holds 17 significant digits, so more
decimals only print rounding noise (and 10^9 decimals tried a 4 GB line)."""
READ_ERRORS = (ValueError, UnicodeDecodeError, OSError)

SKIP_NAMES = frozenset({"-", "skip"})
DEFAULT_COLUMNS = {".xyz_label_conf": ["x", "y", "z", "label", "confidence"]}
_PTS_COLUMNS = {4: ["x", "y", "z", "intensity"], 7: ["x", "y", "z", "intensity", "red", "green", "blue"]}
_ALIASES = {"r": "red", "g": "green", "b": "blue", "class": "classification"}
_EXTRA_INTEGER_COLUMNS = {"label": np.dtype(np.int32), "segment_id": np.dtype(np.int32)}
_WRITE_BLOCK = 100_000


def _integer_columns() -> dict[str, np.dtype]:
    from .las import standard_dtypes

    ints = {k: v for k, v in standard_dtypes().items() if v.kind in "iu"}
    return {**ints, **_EXTRA_INTEGER_COLUMNS}


def _data_lines(path: Path) -> Iterator[tuple[int, str]]:
    """(line index, stripped text) of the lines that are not blank and not ``#`` comments."""
    with open(path, encoding="utf-8", errors="replace") as fh:
        for i, line in enumerate(fh):
            text = line.strip()
            if text and not text.startswith("#"):
                yield i, text


def _delimiter(line: str) -> str | None:
    for d in (";", ","):
        if d in line:
            return d
    return None  # whitespace


def _split(line: str, delimiter: str | None) -> list[str]:
    return [t.strip() for t in line.split(delimiter)] if delimiter else line.split()


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _header_name(token: str) -> str:
    """A header field as a column name, before the aliases (``r`` stays ``r``)."""
    name = token.strip().strip("\"'")
    if name.startswith("//"):
        name = name[2:]
    return "_".join(name.strip().lower().split())


def _resolve_names(spec: list[str] | None, header: list[str] | None, ncols: int, ext: str) -> list[str]:
    """The column names (aliases applied); messages quote the names as the spec or header gave them."""
    if spec is not None:
        if len(spec) > ncols:
            raise LidarfxError(f"column spec has {len(spec)} names but the file has {ncols} columns")
        given = [s.strip() for s in spec]
    elif header is not None:
        if len(header) != ncols:
            raise LidarfxError(f"header line has {len(header)} names but the data has {ncols} columns")
        given = header
    elif ext in DEFAULT_COLUMNS and len(DEFAULT_COLUMNS[ext]) <= ncols:
        names = DEFAULT_COLUMNS[ext]
    elif ext == ".pts" and ncols in _PTS_COLUMNS:
        names = _PTS_COLUMNS[ncols]
    else:
        names = ["x", "y", "z"][:ncols] + [f"col{i}" for i in range(3, ncols)]
    if spec is not None or header is not None:
        names = [_ALIASES.get(n, n) for n in given]
    else:
        given = names
    kept = [n for n in names if n not in SKIP_NAMES]
    if any(not n for n in kept):
        raise LidarfxError("empty column name in the column spec")
    dup = sorted({n for n in kept if kept.count(n) > 1})
    if dup:
        also = sorted({f"{g} means {n}" for g, n in zip(given, names) if n in dup and g != n})
        raise LidarfxError(f"duplicate column name(s): {', '.join(dup)}" + (f" ({', '.join(also)})" if also else ""))
    missing = [c for c in ("x", "y", "z") if c not in kept]
    if missing:
        raise LidarfxError(f"no column named {', '.join(missing)} (columns: {', '.join(given)})")
    return names


def _narrow(name: str, values: np.ndarray, ints: dict[str, np.dtype]) -> np.ndarray:
    """Integer dtype for integer-valued columns with an integer meaning, else unchanged."""
    dtype = ints.get(name)
    if dtype is None:
        return values
    info = np.iinfo(dtype)
    if values.size == 0 or (
        np.isfinite(values).all()
        and (values == np.trunc(values)).all()
        and values.min() >= info.min
        and values.max() <= info.max
    ):
        return values.astype(dtype)
    return values


def _blank_whitespace(path: Path) -> Iterator[str]:
    """The lines of ``path`` with whitespace-only lines made empty: ``numpy.loadtxt`` skips empty
    lines, but with a ``,`` or ``;`` delimiter a line of spaces would be one empty field."""
    with open(path, encoding="utf-8") as fh:
        for line in fh:
            yield line if line.strip() else "\n"


def read(path: Path, *, columns: list[str] | None = None, progress: bool | None = None) -> PointCloud:
    """Read a text point cloud (see the module docstring for the rules)."""
    lines = _data_lines(path)
    first = next(lines, None)
    header: list[str] | None = None
    skiprows = 0
    if first is not None:
        delimiter = _delimiter(first[1])
        tokens = _split(first[1], delimiter)
        if len(tokens) == 1 and tokens[0].isdigit():  # a point count (Leica .pts), if data follow
            following = next(lines, None)  # (else a one-column file: it fails on the missing y, z)
            if following is not None and len(_split(following[1], _delimiter(following[1]))) >= 3:
                skiprows = first[0] + 1
                first = following
                delimiter = _delimiter(first[1])
                tokens = _split(first[1], delimiter)
        if not all(_is_number(t) for t in tokens):
            header = [_header_name(t) for t in tokens]
            skiprows = first[0] + 1
            first = next(lines, None)
            if first is not None:
                delimiter = _delimiter(first[1])
    lines.close()
    ncols = len(_split(first[1], delimiter)) if first is not None else len(header or [])
    ext = path.suffix.lower()
    if first is None and header is None and columns is None:
        names = ["x", "y", "z"]
    else:
        names = _resolve_names(columns, header, ncols, ext)
    use = [i for i, n in enumerate(names) if n not in SKIP_NAMES]
    kept = [names[i] for i in use]
    if first is None:
        table = np.empty((0, len(use)))
    else:
        table = np.loadtxt(
            _blank_whitespace(path),
            delimiter=delimiter,
            comments="#",
            skiprows=skiprows,
            usecols=use,
            ndmin=2,
            dtype=np.float64,
            encoding="utf-8",
        )
    col = {n: table[:, j] for j, n in enumerate(kept)}
    xyz = np.column_stack([col.pop("x"), col.pop("y"), col.pop("z")])
    ints = _integer_columns()
    attrs = {n: _narrow(n, np.ascontiguousarray(v), ints) for n, v in col.items()}
    return PointCloud(xyz, attrs, meta={"columns": kept})


def _format(arr: np.ndarray) -> str:
    if arr.dtype.kind in "biu":
        return "%d"
    if arr.dtype.kind == "f":
        return "%.7g" if arr.dtype.itemsize <= 4 else "%.15g"
    raise LidarfxError(f"cannot write attribute values of dtype {arr.dtype} as text")


def check_precision(precision) -> int:
    """The ``precision`` of :func:`write`: an integer number of decimals 0 .. :data:`MAX_PRECISION`."""
    return check_int("precision", precision, 0, MAX_PRECISION, note=" (decimals of x, y, z)")


def write(
    cloud: PointCloud,
    path: Path,
    *,
    ext: str = ".xyz",
    progress: bool | None = None,
    precision: int = 3,
    delimiter: str | None = None,
    header: bool = True,
) -> None:
    """Write a text point cloud: header line, ``x y z`` with ``precision`` decimals, attributes.

    ``delimiter`` defaults to ``","`` for ``.csv`` and ``" "`` otherwise;
    ``header=False`` omits the line of names (e.g. for tools expecting raw Oakland files).
    """
    check_precision(precision)
    delim = delimiter if delimiter is not None else ("," if ext == ".csv" else " ")
    names = cloud.names
    bad = [n for n in names if (delim.strip() or " ") in n or not n.strip() or n != n.strip() or " " in n]
    if bad:
        raise LidarfxError(f"attribute name(s) {bad} cannot be written to a text header")
    fmt = [f"%.{precision}f"] * 3 + [_format(cloud[n]) for n in names]
    line_fmt = delim.join(fmt) + "\n"
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        if header:
            fh.write(delim.join(["x", "y", "z", *names]) + "\n")
        for start in range(0, len(cloud), _WRITE_BLOCK):
            sl = slice(start, start + _WRITE_BLOCK)
            cols = [cloud.xyz[sl, 0], cloud.xyz[sl, 1], cloud.xyz[sl, 2]] + [cloud[n][sl] for n in names]
            fh.writelines(line_fmt % row for row in zip(*(c.tolist() for c in cols)))
