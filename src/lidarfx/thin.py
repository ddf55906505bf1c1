"""Block (voxel) thinning: exactly one point per occupied cubic cell.

The grid
    Cells are the cubes ``[i c, (i+1) c) × [j c, (j+1) c) × [k c, (k+1) c)`` of edge ``c``
    anchored at the coordinate origin (0, 0, 0): a point's cell is
    ``(floor(x / c), floor(y / c), floor(z / c))``, computed in float64.  The grid is the same
    for every file and every chunking, so tiles thinned one by one mesh with each other (for
    tile edges on multiples of ``c``), and thinning a file in chunks gives the same points as
    thinning it in memory.  A point exactly on a cell face belongs to the upper cell (up to the
    rounding of ``x / c``).

The kept point (``keep``)
    ``centre``: nearest the cell centre ``((i + ½) c, (j + ½) c, (k + ½) c)`` (3-D distance);
    ``first``: first in file order; ``lowest`` / ``highest``: smallest / largest z; ``random``:
    smallest hash of (``seed``, point index) — a random choice that is the same whatever the
    chunking.  Ties go to the point first in file order.  The kept points stay in file order.

Streaming (:func:`thin_file`, LAS/LAZ input)
    The file is read chunk by chunk and, per occupied cell, only the current winner is kept: a
    table of (cell key, score, point index) sorted by key, into which the winners of each
    chunk are merged, together with the winners' raw point records while these take at most
    :data:`RECORD_BUDGET` bytes.  The kept records are then written bit for bit
    (:func:`lidarfx.io.las.write_records`), so every attribute, extra bytes, the point format,
    scales, offsets, CRS and VLRs pass through.  When the records outgrow the budget they are
    dropped and a second pass reads the file again for the records of the winning indices.
    Memory: 24 bytes per occupied cell plus its record (the point format's record length)
    within the budget, twice that while a chunk's new cells are inserted, plus one chunk
    (about 150 bytes per point of :data:`CHUNK_POINTS`) — it grows with the output, not with
    the input.  Nothing is allocated from the header's point count.  The cell key packs the
    three indices into one int64 over the header's bounds; when a point lies outside them (a
    stale header), the bounds are read from the points first (one more pass).
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError, check_int, check_number, check_seed

__all__ = ["KEEP", "CHUNK_POINTS", "thin_cloud", "thin_indices", "thin_file", "cell_indices", "check_cell", "check_keep"]

KEEP = ("centre", "first", "lowest", "highest", "random")
"""Which point of a cell is kept."""

CHUNK_POINTS = 1 << 20
"""Points per chunk of the streamed passes (and of the in-memory kernel's temporaries)."""

RECORD_BUDGET = 512 << 20
"""Bytes of point records of the current winners kept during the first pass of :func:`thin_file`;
beyond, they are dropped and a second pass reads the kept points again."""

MAX_CELL = 1e6
"""Largest cell edge (coordinate units)."""

_INT_LIMIT = 2.0**62
"""Cell indices (x / c) must stay below this in magnitude (int64 with room for differences)."""


def check_cell(cell) -> float:
    """The cell edge: a finite number in (0, :data:`MAX_CELL`], else a one-line error."""
    return check_number("cell", cell, 0.0, MAX_CELL, open_lo=True)


def check_keep(keep) -> str:
    """One of :data:`KEEP` (``center`` is taken for ``centre``), else a one-line error."""
    k = str(keep).strip().lower() if isinstance(keep, str) else keep
    if k == "center":
        k = "centre"
    if k not in KEEP:
        raise LidarfxError(f"keep must be one of {', '.join(KEEP)}; got {keep!r}")
    return k


def cell_indices(xyz: np.ndarray, cell: float) -> np.ndarray:
    """``floor(xyz / cell)`` as int64 (n, 3): the cell of every point (see the module docstring)."""
    q = np.floor(np.asarray(xyz, dtype=np.float64) / cell)
    return q.astype(np.int64)


def _grid(lo, hi, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """First cell index and number of cells per axis of the cells covering ``lo .. hi``;
    a one-line error when the int64 cell keys or indices would overflow."""
    from .neighbors import check_grid

    with np.errstate(over="ignore", invalid="ignore"):
        a = np.floor(np.asarray(lo, dtype=np.float64) / cell)
        b = np.floor(np.asarray(hi, dtype=np.float64) / cell)
    if not (np.isfinite(a).all() and np.isfinite(b).all()) or max(np.abs(a).max(), np.abs(b).max()) >= _INT_LIMIT:
        top = float(np.nanmax(np.abs(np.r_[a, b])))
        raise LidarfxError(f"the cell is too small for the coordinates: coordinate / cell reaches {top:.3g}, "
                           f"beyond the int64 cell indices; use a larger cell")
    shape = b - a + 1.0
    check_grid(shape, cell, option="cell", grid="the thinning grid", unit="cells")
    return a.astype(np.int64), shape.astype(np.int64)


class _OutsideGrid(Exception):
    """A point lies outside the bounds the grid was made for (a stale LAS header)."""


def _keys(ijk: np.ndarray, base: np.ndarray, shape: np.ndarray) -> np.ndarray:
    """One int64 key per cell: ``((i - i0) ny + (j - j0)) nz + (k - k0)``."""
    rel = ijk - base
    if len(rel) and ((rel < 0).any() or (rel >= shape).any()):
        raise _OutsideGrid
    return (rel[:, 0] * shape[1] + rel[:, 1]) * shape[2] + rel[:, 2]


_GOLDEN = 0x9E3779B97F4A7C15


def _random_scores(index: np.ndarray, seed: int) -> np.ndarray:
    """A uniform number in [0, 1) per point index (splitmix64 of the index, offset by the seed)."""
    m = np.uint64
    x = index.astype(np.uint64) + m((seed * _GOLDEN + _GOLDEN) % 2**64)
    x = (x ^ (x >> m(30))) * m(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> m(27))) * m(0x94D049BB133111EB)
    x ^= x >> m(31)
    return (x >> m(11)).astype(np.float64) * 2.0**-53


def _scores(xyz: np.ndarray, ijk: np.ndarray, cell: float, keep: str, index: np.ndarray, seed: int) -> np.ndarray:
    """Per point: the smaller, the better its claim to its cell."""
    if keep == "first":
        return np.zeros(len(xyz))
    if keep == "lowest":
        return xyz[:, 2].copy()
    if keep == "highest":
        return -xyz[:, 2]
    if keep == "random":
        return _random_scores(index, seed)
    d2 = np.zeros(len(xyz))
    for a in range(3):
        d2 += (xyz[:, a] - (ijk[:, a] + 0.5) * cell) ** 2
    return d2


class _Winners:
    """The running winner of every occupied cell: keys ascending, with score and point index and,
    optionally, a payload row per winner (its raw point record) while the payload stays within
    ``budget`` bytes (then it is dropped: :attr:`payload` is None, :attr:`dropped` true)."""

    def __init__(self, payload_dtype: np.dtype | None = None, budget: int = 0) -> None:
        self.key = np.zeros(0, np.int64)
        self.score = np.zeros(0, np.float64)
        self.index = np.zeros(0, np.int64)
        self.payload = None if payload_dtype is None else np.zeros(0, payload_dtype)
        self.budget = budget
        self.dropped = False

    def add(self, key: np.ndarray, score: np.ndarray, index: np.ndarray, payload: np.ndarray | None = None) -> None:
        """Merge a chunk (points in file order, ``index`` contiguous and ascending; ``payload``
        one row per point) into the table."""
        if not len(key):
            return
        # the chunk's own winners: per key the smallest score, among equal scores the smallest index
        # (an unstable sort by key, then minima per run: several times faster than a lexsort)
        order = np.argsort(key)
        k = key[order]
        starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
        ck = k[starts]
        del k
        sc = score[order]
        cs = np.minimum.reduceat(sc, starts)
        runs = np.diff(np.r_[starts, len(order)])
        cand = np.where(sc == np.repeat(cs, runs), index[order], np.iinfo(np.int64).max)
        ci = np.minimum.reduceat(cand, starts)
        del order, sc, cand, runs, starts
        keep_rows = self.payload is not None and payload is not None
        rows = payload[ci - index[0]] if keep_rows else None
        if not len(self.key):
            self.key, self.score, self.index = ck, cs, ci
            if keep_rows:
                self.payload = rows
            self._check_budget()
            return
        pos = np.searchsorted(self.key, ck)
        hit = pos < len(self.key)
        hit[hit] = self.key[pos[hit]] == ck[hit]
        p = pos[hit]
        # an earlier chunk's point wins ties (it comes first in file order)
        better = cs[hit] < self.score[p]
        self.score[p[better]] = cs[hit][better]
        self.index[p[better]] = ci[hit][better]
        if keep_rows:
            self.payload[p[better]] = rows[hit][better]
        new = ~hit
        if new.any():
            at = pos[new]
            self.key = np.insert(self.key, at, ck[new])
            self.score = np.insert(self.score, at, cs[new])
            self.index = np.insert(self.index, at, ci[new])
            if keep_rows:
                self.payload = np.insert(self.payload, at, rows[new])
        self._check_budget()

    def _check_budget(self) -> None:
        if self.payload is not None and self.payload.nbytes > self.budget:
            self.payload, self.dropped = None, True

    def indices(self) -> np.ndarray:
        """The kept point indices, ascending (the table is released)."""
        return self.result()[0]

    def result(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The kept point indices, ascending, and their payload rows in that order (None when
        there is none); the table is released."""
        order = np.argsort(self.index)
        out = self.index[order]
        rows = None if self.payload is None else self.payload[order]
        self.key = self.score = self.index = np.zeros(0, np.int64)
        self.payload = None
        return out, rows

    @property
    def nbytes(self) -> int:
        return int(self.key.nbytes + self.score.nbytes + self.index.nbytes
                   + (0 if self.payload is None else self.payload.nbytes))


def _add_chunk(w: _Winners, xyz: np.ndarray, start: int, cell: float, keep: str, seed: int,
               base: np.ndarray, shape: np.ndarray, payload: np.ndarray | None = None) -> None:
    ijk = cell_indices(xyz, cell)
    key = _keys(ijk, base, shape)
    index = np.arange(start, start + len(xyz), dtype=np.int64)
    w.add(key, _scores(xyz, ijk, cell, keep, index, seed), index, payload)


def thin_indices(xyz: np.ndarray, cell: float, keep: str = "centre", seed: int = 0,
                 chunk_points: int = CHUNK_POINTS) -> np.ndarray:
    """Indices (ascending) of the points kept by block thinning of ``xyz`` (n, 3): one per
    occupied cell of edge ``cell``, chosen by ``keep`` (:data:`KEEP`; see the module docstring).
    Temporaries are bounded by ``chunk_points``; the result is the same for any chunking."""
    cell = check_cell(cell)
    keep = check_keep(keep)
    seed = check_seed(seed)
    chunk_points = check_int("chunk_points", chunk_points, 1, 1 << 30)
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise LidarfxError(f"xyz must have shape (n, 3), got {xyz.shape}")
    if not len(xyz):
        return np.zeros(0, np.int64)
    lo, hi = xyz.min(axis=0), xyz.max(axis=0)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise LidarfxError("coordinates contain NaN or infinite values; cannot thin")
    base, shape = _grid(lo, hi, cell)
    w = _Winners()
    for a in range(0, len(xyz), chunk_points):
        _add_chunk(w, xyz[a:a + chunk_points], a, cell, keep, seed, base, shape)
    return w.indices()


def thin_cloud(cloud: PointCloud | np.ndarray, cell: float, keep: str = "centre", seed: int = 0, *,
               units: str = "auto") -> np.ndarray:
    """Indices (ascending) of the points of ``cloud`` (a :class:`PointCloud` or an (n, 3) array)
    that block thinning keeps; ``cloud.subset(idx)`` is the thinned cloud.  ``cell`` is metres,
    converted when the cloud's LAS CRS is in feet (``units="native"``: coordinate units; an
    array is in coordinate units)."""
    from .crs import length_to_units

    if isinstance(cloud, PointCloud):
        return thin_indices(cloud.xyz, length_to_units(cloud, check_cell(cell), units), keep, seed)
    return thin_indices(cloud, cell, keep, seed)


# --------------------------------------------------------------------------- files
def _pass(src: Path, chunk_points: int, advance: Callable[[int], None]):
    """``(start, record, header, xyz)`` of every chunk of a LAS/LAZ file (read errors: one line)."""
    from .io import las

    for start, rec, header in las.iter_records(src, chunk_points):
        yield start, rec, header, las.record_xyz(rec, header)
        advance(len(rec))


def _bar(description: str, total: int, progress: bool | None):
    from .progress import bar, wanted

    return bar(description, total, wanted(progress))


def _scan_bounds(src: Path, chunk_points: int, progress: bool | None, total: int) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    with _bar(f"bounds of {src.name}", total, progress) as advance:
        for _, _, _, xyz in _pass(src, chunk_points, advance):
            if len(xyz):
                lo, hi = np.minimum(lo, xyz.min(axis=0)), np.maximum(hi, xyz.max(axis=0))
    return lo, hi


def _winners_of_file(src: Path, header, cell: float, keep: str, seed: int, chunk_points: int,
                     progress: bool | None, record_budget: int = 0) -> tuple[np.ndarray, np.ndarray | None, int, dict]:
    """Pass 1: the kept point indices of a LAS/LAZ file, their raw records (None when they
    outgrew ``record_budget`` bytes: pass 2 reads them), the points read and some facts."""
    total = int(header.point_count)
    scales = np.abs(np.asarray(header.scales, dtype=np.float64))
    lo = np.asarray(header.mins, dtype=np.float64) - scales
    hi = np.asarray(header.maxs, dtype=np.float64) + scales
    facts = {"bounds": "header"}
    if not (np.isfinite(lo).all() and np.isfinite(hi).all() and (lo <= hi).all()):
        lo, hi = _scan_bounds(src, chunk_points, progress, total)
        facts["bounds"] = "scanned (the header's are not usable)"
    for attempt in range(2):
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()):  # no points at all
            return np.zeros(0, np.int64), None, 0, facts
        base, shape = _grid(lo, hi, cell)
        w, n, peak = _Winners(header.point_format.dtype(), record_budget), 0, 0
        try:
            with _bar(f"thinning {src.name}", total, progress) as advance:
                for start, rec, _, xyz in _pass(src, chunk_points, advance):
                    _add_chunk(w, xyz, start, cell, keep, seed, base, shape, rec.array)
                    n = start + len(xyz)
                    peak = max(peak, w.nbytes)
        except _OutsideGrid:
            if attempt:
                raise LidarfxError(f"{src}: a point lies outside the bounds read from the points; "
                                   "the file changed while it was read") from None
            lo, hi = _scan_bounds(src, chunk_points, progress, total)
            facts["bounds"] = "scanned (points outside the header's bounds)"
            continue
        facts["table_bytes"] = peak
        facts["passes"] = 1 if not w.dropped else 2
        idx, rows = w.result()
        return idx, rows, n, facts
    raise AssertionError("unreachable")


def _kept_records(src: Path, kept: np.ndarray, rows: np.ndarray | None, header, chunk_points: int,
                  advance) -> Iterable:
    """The records of the kept points, chunk by chunk: from ``rows`` (kept in pass 1), else from
    pass 2 over the file (``kept`` ascending)."""
    if rows is not None:
        import laspy

        for a in range(0, len(rows), chunk_points):
            yield laspy.PackedPointRecord(rows[a:a + chunk_points], header.point_format)
            advance(min(chunk_points, len(rows) - a))
        return
    for start, rec, _, _ in _pass(src, chunk_points, advance):
        a, b = np.searchsorted(kept, [start, start + len(rec)])
        if b > a:
            yield rec[kept[a:b] - start]


def thin_file(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    *,
    cell: float,
    keep: str = "centre",
    seed: int = 0,
    columns: str | list[str] | None = None,
    chunk_points: int = CHUNK_POINTS,
    record_budget: int = RECORD_BUDGET,
    progress: bool | None = None,
    units: str = "auto",
) -> dict[str, Any]:
    """Block-thin the file ``src`` into ``dst`` (see the module docstring); returns a summary.

    LAS/LAZ input is streamed in two passes of ``chunk_points`` points, so memory is bounded
    by the number of occupied cells, not by the input; LAS/LAZ output then gets the kept
    records bit for bit (same point format, scales, offsets, VLRs and CRS), other outputs the
    kept points with all their attributes.  Other inputs (``columns``: the text column spec)
    are read in memory.  ``dst`` is written to a temporary file and renamed at the end; it
    may not be ``src``.  ``cell`` is metres, converted to the file's unit when its CRS is in
    feet (``units="native"``: in coordinate units as given); the summary gives it in metres.
    """
    from . import io
    from ._atomic import atomic_path, check_not_same_file
    from .crs import check_units, length_to_units, units_summary
    from .io import las

    cell = check_cell(cell)
    check_units(units)
    keep = check_keep(keep)
    seed = check_seed(seed)
    chunk_points = check_int("chunk_points", chunk_points, 1, 1 << 30)
    src, dst = Path(src), Path(dst)
    fmt = io.input_format(src)
    check_not_same_file(src, dst)
    io.check_output_path(dst)
    t0 = time.perf_counter()
    facts: dict[str, Any] = {}
    if fmt != "las":
        cloud = io.read(src, columns=columns, progress=progress)
        n = len(cloud)
        unit = units_summary(cloud if units == "auto" else None)
        idx = thin_cloud(cloud, cell, keep, seed, units=units)
        t1 = time.perf_counter()
        io.write(cloud.subset(idx), dst, progress=progress)
        kept = len(idx)
        facts["mode"] = "in memory"
    else:
        if columns is not None:
            raise LidarfxError(f"{src}: a column spec applies only to text and .npy files")
        try:
            header = las.read_header(src)
        except las.READ_ERRORS as exc:
            from .io import one_line

            raise LidarfxError(f"cannot read {src}: {one_line(exc)}") from exc
        unit = units_summary(header if units == "auto" else None)
        idx, rows, n, facts = _winners_of_file(src, header, check_cell(length_to_units(header, cell, units)), keep,
                                               seed, chunk_points, progress,
                                               check_int("record_budget", record_budget, 0, 1 << 50))
        t1 = time.perf_counter()
        kept = len(idx)
        with _bar(f"writing {dst.name}", n if rows is None else kept, progress) as advance:
            records = _kept_records(src, idx, rows, header, chunk_points, advance)
            if io.FORMATS[dst.suffix.lower()] == "las":
                with atomic_path(dst) as tmp:
                    try:
                        written = las.write_records(tmp, header, records, ext=dst.suffix.lower())
                    except OSError as exc:
                        raise LidarfxError(f"cannot write {dst}: {exc.strerror or exc}") from exc
                if written != kept:
                    raise LidarfxError(f"{src}: the file changed while it was read")
            else:
                parts = [las.record_cloud(rec, header) for rec in records]
                if not parts:  # no points: the attribute names still go to the output
                    import laspy

                    parts = [las.record_cloud(laspy.PackedPointRecord.empty(header.point_format), header)]
                out = PointCloud.concatenate(parts)
                io.write(out, dst, progress=False)
        facts["mode"] = "streamed"
    t2 = time.perf_counter()
    return {
        "input": str(src),
        "output": str(dst),
        "points": int(n),
        "kept": int(kept),
        "share_kept": round(kept / n, 6) if n else None,
        "cell": cell,
        "units": unit,
        "keep": keep,
        **({"seed": seed} if keep == "random" else {}),
        "grid": "cells [i c, (i+1) c) per axis, anchored at (0, 0, 0)",
        **facts,
        "seconds": {"cells": round(t1 - t0, 3), "write": round(t2 - t1, 3)},
    }
