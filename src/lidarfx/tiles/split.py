"""The split pass of a tiled run: every input is read once, in chunks of records, and each
point's raw record is appended to the piece of every chunk whose buffered square holds it.

Work files (private to a run, in ``WORK/split``): per source file ``k`` a header file
``h<k>.las`` (the source's header, no points) and per chunk ``<chunk>/<k>.rec`` (raw point
records, the source's point format) and ``<chunk>/<k>.ids`` (int64 global indices, ascending).
Pieces are uncompressed: a chunk task reads only its own, at disk speed.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

import laspy
import numpy as np

from ..cloud import PointCloud
from ..errors import LidarfxError
from .catalog import Catalog
from .plan import Grid, chunk_name

SPLIT_RECORDS = 2_000_000
"""Records read at a time from an input."""


def header_path(work: Path, k: int) -> Path:
    return work / "split" / f"h{k}.las"


def split_inputs(cat: Catalog, grid: Grid, work: Path, advance: Callable[[int], None] = lambda k: None) -> dict:
    """Write the pieces of every chunk; returns the split summary (also saved as
    ``WORK/split/split.json``): chunks with their own and buffered point counts, and the exact
    per-axis minimum and maximum of all points."""
    from ..io.las import iter_records, record_xyz, write_records

    out = work / "split"
    out.mkdir(parents=True, exist_ok=True)
    own: dict[str, list] = {}
    buffered: dict[str, int] = {}
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    fmt = None
    for k, src in enumerate(cat.sources):
        header = None
        for start, rec, header in iter_records(Path(src.path), SPLIT_RECORDS):
            if fmt is None:
                fmt = header.point_format
            xyz = record_xyz(rec, header)
            if not np.isfinite(xyz).all():
                raise LidarfxError(f"{src.path}: coordinates that are not finite numbers")
            lo = np.minimum(lo, xyz.min(axis=0))
            hi = np.maximum(hi, xyz.max(axis=0))
            ids = np.arange(src.first + start, src.first + start + len(rec), dtype=np.int64)
            ci, cj = grid.cells(xyz[:, 0], xyz[:, 1])
            x0, x1 = grid.reach(xyz[:, 0])
            y0, y1 = grid.reach(xyz[:, 1])
            spread_x = int((x1 - x0).max(initial=0)) + 1
            spread_y = int((y1 - y0).max(initial=0)) + 1
            sels, keys = [], []
            for dx in range(spread_x):
                for dy in range(spread_y):
                    gi, gj = x0 + dx, y0 + dy
                    sel = np.flatnonzero((gi <= x1) & (gj <= y1))
                    sels.append(sel)
                    keys.append(np.stack([gi[sel], gj[sel]], axis=1))
            sel = np.concatenate(sels)
            key = np.concatenate(keys)
            order = np.lexsort((sel, key[:, 1], key[:, 0]))  # by chunk, then in file order
            sel, key = sel[order], key[order]
            cut = np.flatnonzero(np.any(np.diff(key, axis=0) != 0, axis=1)) + 1
            for part, first in zip(np.split(sel, cut), np.r_[0, cut]):
                i, j = int(key[first, 0]), int(key[first, 1])
                name = chunk_name(i, j)
                folder = out / name
                if name not in buffered:
                    folder.mkdir(exist_ok=True)
                    buffered[name] = 0
                    own[name] = [i, j, 0]
                with open(folder / f"{k}.rec", "ab") as fh:
                    rec.array[part].tofile(fh)
                with open(folder / f"{k}.ids", "ab") as fh:
                    ids[part].tofile(fh)
                buffered[name] += len(part)
                own[name][2] += int(np.count_nonzero((ci[part] == i) & (cj[part] == j)))
            advance(len(rec))
        if header is None:
            continue
        write_records(header_path(work, k), header, [])
    chunks = [{"name": n, "i": v[0], "j": v[1], "points": v[2], "buffered": buffered[n]}
              for n, v in sorted(own.items(), key=lambda kv: (kv[1][1], kv[1][0])) if v[2] > 0]
    summary = {"chunks": chunks, "mins": lo.tolist(), "maxs": hi.tolist(), "points": cat.points}
    (out / "split.json").write_text(json.dumps(summary))
    return summary


def read_chunk(work: Path, name: str, n_sources: int) -> tuple[PointCloud, np.ndarray, np.ndarray]:
    """A chunk's buffered cloud (pieces in source order, so in global order), the global index
    of each point and the source of each point."""
    from ..io.las import read_header, record_cloud

    folder = work / "split" / name
    clouds, ids, src = [], [], []
    for k in range(n_sources):
        rec_path = folder / f"{k}.rec"
        if not rec_path.exists():
            continue
        header = read_header(header_path(work, k))
        raw = np.fromfile(rec_path, dtype=header.point_format.dtype())
        idk = np.fromfile(folder / f"{k}.ids", dtype=np.int64)
        if len(raw) != len(idk):
            raise LidarfxError(f"chunk {name}: its work files are damaged (start again without --resume)")
        clouds.append(record_cloud(laspy.PackedPointRecord(raw, header.point_format), header))
        ids.append(idk)
        src.append(np.full(len(idk), k, dtype=np.int32))
    if not clouds:
        raise LidarfxError(f"chunk {name}: no work files (start again without --resume)")
    cloud = clouds[0] if len(clouds) == 1 else PointCloud.concatenate(clouds)
    return cloud, np.concatenate(ids), np.concatenate(src)
