"""Run a per-point command chunk by chunk: split, process the chunks on Dask, merge.

:func:`run_tiled` is the one entry point.  The work folder (default ``OUTPUT.lidarfx-work``
beside the output, so that cluster workers reach it where they reach the output) holds:

- ``manifest.json``: what the run is (inputs' fingerprint, command, options, grid); a run with
  ``resume=True`` continues only a work folder with the same manifest;
- ``split/``: the pieces of each chunk (:mod:`lidarfx.tiles.split`), ``split.json`` when done;
- ``out/<chunk>/``: a finished chunk's own points with the command's results (uncompressed
  LAS, one file per source file) and ``done/<chunk>.json``, written last: a chunk with that
  marker is never computed again.

At the end the parts are merged into the output (one file, or one file per input tile) and
the work folder is removed.
"""
from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import ENVIRONMENT_ERRNOS, LidarfxError
from .catalog import Catalog, open_catalog
from .plan import (Grid, check_grid, chunk_name, chunk_points_budget, default_chunk_size, default_workers)

MANIFEST_VERSION = 1


@dataclass
class Context:
    """What every chunk of a run knows about the whole: the exact per-axis minimum (the local
    origin of every kernel, so that chunks compute exactly as one in-memory run), the maximum,
    the number of points, the grid, and the threads a chunk may use."""

    mins: np.ndarray
    maxs: np.ndarray
    points: int
    grid: Grid
    threads: int = 1


@dataclass
class Chunk:
    """One chunk's buffered cloud: ``own`` marks the points whose results the processor returns
    (the points of the chunk's square, or more in a fused pipeline), ``ids`` their global index
    (source order), ``source`` the input file of each point, ``cell`` the chunk's grid square
    ``(i, j)``."""

    name: str
    cloud: Any
    own: np.ndarray
    ids: np.ndarray
    source: np.ndarray
    cell: tuple[int, int]

    def square(self, ctx: "Context") -> tuple[float, float, float, float]:
        """The bounds of the chunk's square."""
        return ctx.grid.bounds(int(self.cell[0]), int(self.cell[1]))


@dataclass
class TileRun:
    """Summary of :func:`run_tiled`."""

    outputs: list[str]
    chunks: int
    resumed: int
    points: int
    chunk_size: float
    buffer: float
    workers: int
    scheduler: str
    seconds: dict[str, float] = field(default_factory=dict)
    largest_chunk: int = 0
    chunk_infos: list[dict] = field(default_factory=list)
    """Every chunk's ``done`` record (points, seconds, and what its processor added)."""

    def as_dict(self) -> dict:
        return {"outputs": self.outputs, "chunks": self.chunks, "chunks_resumed": self.resumed,
                "points": self.points, "chunk_size": self.chunk_size, "buffer": self.buffer,
                "workers": self.workers, "scheduler": self.scheduler,
                "largest_chunk_points": self.largest_chunk, "seconds": self.seconds}


def _write_json(path: Path, obj: Any) -> None:
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text(json.dumps(obj, indent=1))
    os.replace(tmp, path)


def process_chunk(work: str, name: str, spec: dict) -> dict:
    """One chunk, on a worker: read its pieces, run the command's processor, write its own
    points (one uncompressed LAS per source file) and then its done marker.  Returns the
    chunk's counts."""
    from .. import io
    from .processors import get
    from .split import read_chunk

    t0 = time.perf_counter()
    if spec["threads"] > 0:
        import numba

        numba.set_num_threads(max(1, min(spec["threads"], numba.config.NUMBA_NUM_THREADS)))
    w = Path(work)
    ctx = Context(np.asarray(spec["mins"]), np.asarray(spec["maxs"]), spec["points"],
                  Grid(spec["chunk_size"], spec["buffer"]), spec["threads"])
    cloud, ids, source = read_chunk(w, name, spec["sources"])
    i, j = spec["chunks"][name]
    ci, cj = ctx.grid.cells(cloud.x, cloud.y)
    own = (ci == i) & (cj == j)
    result = get(spec["command"]).process(Chunk(name, cloud, own, ids, source, (int(i), int(j))), ctx,
                                          spec["options"])
    out = w / "out" / name
    if out.exists():
        shutil.rmtree(out)
    tmp = w / "out" / f".{name}.tmp{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir(parents=True)
    src_own = source[own]
    ids_own = ids[own]
    if isinstance(result, tuple):  # a command that drops points: (the points kept, which of the owned ones)
        result, kept = result
        src_own, ids_own = src_own[kept], ids_own[kept]
    extra = result.meta.pop("chunk_info", None) or {}  # counts a processor reports (JSON data)
    for k in np.unique(src_own):
        m = src_own == k
        io.write(result.subset(m), tmp / f"{int(k)}.las", progress=False)
        ids_own[m].tofile(tmp / f"{int(k)}.ids")
    os.replace(tmp, out)
    info = {**extra, "name": name, "points": int(own.sum()), "buffered": len(cloud),
            "seconds": round(time.perf_counter() - t0, 3)}
    _write_json(w / "done" / f"{name}.json", info)
    return info


def _manifest(cat: Catalog, command: str, options: dict, grid: Grid, per_tile: bool, ext: str) -> dict:
    return {"version": MANIFEST_VERSION, "inputs": cat.key(), "command": command, "options": options,
            "chunk_size": grid.size, "buffer": grid.buffer, "per_tile": per_tile, "ext": ext}


def _read_split(work: Path, points: int) -> dict:
    """``WORK/split/split.json`` of a resumed run, checked to be what :func:`split_inputs` writes:
    data only, chunk names ``c<i>_<j>`` of their own indices (no path leaves the work folder)."""
    path = work / "split" / "split.json"
    try:
        split = json.loads(path.read_text())
        chunks = split["chunks"]
        ok = (type(split) is dict and type(chunks) is list and type(split["points"]) is int and split["points"] == points
              and all(len(split[k]) == 3 and all(type(v) in (int, float) and math.isfinite(v) for v in split[k])
                      for k in ("mins", "maxs")))
        for c in chunks:
            ok = ok and type(c) is dict and all(type(c[k]) is int for k in ("i", "j", "points", "buffered"))
            ok = ok and c["name"] == chunk_name(c["i"], c["j"]) and 0 <= c["points"] <= c["buffered"] <= points
    except (ValueError, TypeError, KeyError, OSError, RecursionError):
        ok = False
    if not ok:
        raise LidarfxError(f"{path} is damaged or was not written by lidarfx; run without --resume to start again")
    return split


def _prepare_work(work: Path, manifest: dict, resume: bool) -> bool:
    """Create (or check, with ``resume``) the work folder; True when a split can be reused."""
    mpath = work / "manifest.json"
    if resume and mpath.exists():
        try:
            old = json.loads(mpath.read_text())
        except (ValueError, RecursionError):  # not JSON, a huge integer, nested too deeply: not this run's
            old = None
        if old != json.loads(json.dumps(manifest)):
            raise LidarfxError(f"{work} holds a run with other inputs or options; run without --resume to start again")
        return (work / "split" / "split.json").exists()
    if work.exists():
        if not work.is_dir() or (any(work.iterdir()) and not mpath.exists()):
            raise LidarfxError(f"{work} exists and is not a lidarfx work folder; give another --work-dir")
        shutil.rmtree(work)
    work.mkdir(parents=True)
    (work / "done").mkdir()
    (work / "out").mkdir()
    _write_json(mpath, manifest)
    return False


@dataclass
class TaskError:
    """A task's one-line :class:`LidarfxError`, returned instead of raised: a wrong option or input
    fails the same way again, so Dask does not retry it (retries are for lost workers)."""

    message: str


def run_task(fn: Callable, *args: Any) -> Any:
    """``fn(*args)`` on a worker, its :class:`LidarfxError` as a :class:`TaskError`."""
    try:
        return fn(*args)
    except LidarfxError as exc:
        return TaskError(str(exc))


def execute(tasks: list[tuple[str, Callable, tuple]], *, workers: int, scheduler: str | None,
            progress: bool | None, retries: int = 1, what: str = "chunk") -> list[Any]:
    """Run ``tasks`` (name, function, arguments) on Dask: an embedded ``LocalCluster`` of
    ``workers`` processes (one thread each), or the ``dask.distributed`` scheduler at
    ``scheduler``; ``workers == 1`` without a scheduler runs them here, one by one.  A failed
    task is tried ``retries`` more times; then the run stops with a one-line error naming it
    (``what``: the kind of task in messages and the progress bar, "chunk" or "merge")."""
    from ..progress import bar, wanted

    show = wanted(progress)
    results: list[Any] = []
    if not tasks:
        return results
    if scheduler is None and workers <= 1:
        with bar(what + "s", len(tasks), show) as advance:
            for name, fn, args in tasks:
                for attempt in range(retries + 1):
                    try:
                        results.append(fn(*args))
                        break
                    except LidarfxError as exc:
                        raise LidarfxError(f"{what} {name}: {exc}") from exc
                    except OSError as exc:
                        if exc.errno in ENVIRONMENT_ERRNOS or attempt == retries:  # a full disk stays full
                            _raise_failure(exc, what, name, retries)
                    except Exception as exc:
                        if attempt == retries:
                            raise LidarfxError(f"{what} {name} failed {retries + 1} times: "
                                               f"{type(exc).__name__}: {exc}") from exc
                advance(1)
        return results
    import logging

    from distributed import Client, LocalCluster, as_completed

    for noisy in ("distributed", "distributed.worker", "distributed.nanny", "distributed.scheduler"):
        logging.getLogger(noisy).setLevel(logging.CRITICAL)  # a failed chunk is one lidarfx line
    cluster = None
    try:
        if scheduler is None:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, memory_limit=0,
                                   dashboard_address=":0", silence_logs=logging.CRITICAL)
            client = Client(cluster)
        else:
            try:
                client = Client(scheduler, timeout="20s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise LidarfxError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from exc
        try:
            names = {}
            futures = []
            for name, fn, args in tasks:
                f = client.submit(run_task, fn, *args, key=f"lidarfx-{name}-{os.getpid()}-{time.time_ns()}",
                                  retries=retries, pure=False)
                names[f.key] = name
                futures.append(f)
            with bar(what + "s", len(tasks), show) as advance:
                for f in as_completed(futures):
                    if f.status == "error":
                        exc = f.exception()
                        for g in futures:
                            g.cancel()
                        if isinstance(exc, LidarfxError):
                            raise LidarfxError(f"{what} {names[f.key]}: {exc}")
                        if isinstance(exc, OSError):
                            _raise_failure(exc, what, names[f.key], retries)
                        raise LidarfxError(f"{what} {names[f.key]} failed {retries + 1} times: "
                                           f"{type(exc).__name__}: {exc}") from exc
                    res = f.result()
                    if isinstance(res, TaskError):
                        for g in futures:
                            g.cancel()
                        raise LidarfxError(f"{what} {names[f.key]}: {res.message}")
                    results.append(res)
                    advance(1)
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()
    return results


@contextlib.contextmanager
def _naming(work: Path):
    """A disk-full (and alike) OSError that names no file names the work folder."""
    try:
        yield
    except OSError as exc:
        if exc.errno in ENVIRONMENT_ERRNOS and not exc.filename:
            raise OSError(exc.errno, exc.strerror or os.strerror(exc.errno), str(work)) from exc
        raise


def _raise_failure(exc: OSError, what: str, name: str, retries: int) -> None:
    """A disk-full (and alike) error as it is (lidarfx: one line naming the file, exit 1);
    other OS errors as the task's one-line failure."""
    if exc.errno in ENVIRONMENT_ERRNOS:
        raise exc
    raise LidarfxError(f"{what} {name} failed {retries + 1} times: {type(exc).__name__}: {exc}") from exc


MERGE_WINDOW = 2_000_000
"""Global indices merged at a time."""


class _Part:
    """A finished chunk's part for one source, read forward: its records (uncompressed LAS) and
    its global indices (ascending), a block of indices at a time.  Plain reads, not a memory
    map: mapped pages would count as the run's resident memory."""

    IDS_BLOCK = 262_144

    def __init__(self, path: Path):
        from ..io.las import read_header

        self.path = path
        self.header = read_header(path)
        self.n = int(self.header.point_count)
        self.dtype = self.header.point_format.dtype()
        if path.stat().st_size < self.header.offset_to_point_data + self.n * self.dtype.itemsize or \
                path.with_suffix(".ids").stat().st_size != 8 * self.n:
            raise LidarfxError(f"{path}: a damaged part (start again without --resume)")
        self.done = 0  # records taken
        self.ids = np.zeros(0, np.int64)  # the indices of records done, done + 1, ...

    def take(self, stop: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The next records whose global index is below ``stop``, with their indices."""
        got_raw, got_ids = [], []
        while self.done < self.n:
            if not len(self.ids):
                with open(self.path.with_suffix(".ids"), "rb") as fh:
                    fh.seek(8 * self.done)
                    self.ids = np.fromfile(fh, dtype=np.int64, count=min(self.IDS_BLOCK, self.n - self.done))
            k = int(np.searchsorted(self.ids, stop))
            if k == 0:
                break
            with open(self.path, "rb") as fh:
                fh.seek(self.header.offset_to_point_data + self.done * self.dtype.itemsize)
                got_raw.append(np.fromfile(fh, dtype=self.dtype, count=k))
            got_ids.append(self.ids[:k])
            self.ids = self.ids[k:]
            self.done += k
        if not got_raw:
            return None
        return np.concatenate(got_raw), np.concatenate(got_ids)


def _merge_ordered(parts: list[Path], target: Path, ext: str, first: int, stop: int) -> int:
    """The parts' points with global indices in [first, stop) into ``target`` (atomic), in
    global order, ``MERGE_WINDOW`` indices at a time: memory bounded, the output in the input's
    order.  Coordinates of a part whose scales or offsets differ from the first part's are
    re-encoded (exactly, or a one-line error); the parts must share a point format."""
    import laspy

    from .._atomic import atomic_path
    from ..io.las import write_records

    ps = [_Part(p) for p in parts]
    header = ps[0].header
    pf = header.point_format
    for p in ps:
        if p.header.point_format.id != pf.id or list(p.header.point_format.dimension_names) != list(pf.dimension_names):
            raise LidarfxError(f"the inputs have different point formats or attributes; give an output folder (one "
                               f"file per input tile) instead of {target}")

    def records():
        for a in range(first, stop, MERGE_WINDOW):
            b = min(stop, a + MERGE_WINDOW)
            blocks, ids = [], []
            for p in ps:
                got = p.take(b)
                if got is None:
                    continue
                raw, pid = got
                if not (np.array_equal(p.header.scales, header.scales) and np.array_equal(p.header.offsets, header.offsets)):
                    for axis, c in enumerate("XYZ"):
                        v = (raw[c] * p.header.scales[axis] + p.header.offsets[axis] - header.offsets[axis]) \
                            / header.scales[axis]
                        r = np.round(v)
                        if np.abs(v - r).max(initial=0) > 1e-3 or np.abs(r).max(initial=0) > 2**31 - 1:
                            raise LidarfxError(f"the inputs' coordinate scales do not match; give an output folder "
                                               f"(one file per input tile) instead of {target}")
                        raw[c] = r.astype(np.int32)
                blocks.append(raw)
                ids.append(pid)
            if blocks:
                raw = np.concatenate(blocks)
                yield laspy.PackedPointRecord(raw[np.argsort(np.concatenate(ids), kind="stable")], pf)

    with atomic_path(target) as tmp:
        return write_records(tmp, header, records(), ext=ext)


def run_tiled(
    inputs,
    output: str | os.PathLike,
    command: str,
    options: dict,
    *,
    chunk_size: float | None = None,
    buffer: float | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    resume: bool = False,
    work_dir: str | os.PathLike | None = None,
    keep_work: bool = False,
    progress: bool | None = None,
) -> TileRun:
    """Run the per-point ``command`` (a key of :data:`lidarfx.tiles.processors.PROCESSORS`) with
    ``options`` over ``inputs`` (a LAS/LAZ file, several, or a folder of tiles) chunk by chunk.

    ``output`` is one LAS/LAZ file, or a folder (created) that gets one file per input tile,
    named as the input, its points in the input's order.  ``chunk_size`` (m; None: from the inputs' density and the free
    memory), ``buffer`` (m; None: what the command needs), ``workers`` (None: one per core),
    ``scheduler`` (a ``dask.distributed`` address; None: embedded), ``resume`` (continue a
    killed run in the same work folder).  Every point's values equal those of one in-memory run
    where the command says so (:attr:`Processor.identical`).  ``chunk_size``, ``buffer`` and the
    lengths of ``options`` are metres, converted when the first input's CRS is in feet
    (docs/conventions.md); the result gives ``chunk_size`` and ``buffer`` in metres."""
    from .processors import get
    from .split import split_inputs

    from ..crs import inputs_unit_to_metre, length_to_units

    proc = get(command)
    proc.check(options)
    t0 = time.perf_counter()
    cat = open_catalog(inputs)
    unit = inputs_unit_to_metre(inputs)  # metres per coordinate unit: sizes and buffers are metres
    if proc.metres and "unit_to_metre" not in options:
        options = {**options, "unit_to_metre": unit}
    out = Path(output)
    per_tile = out.suffix.lower() not in (".las", ".laz")
    if per_tile:
        from .._atomic import check_new_folder

        if out.exists() and not out.is_dir():
            raise LidarfxError(f"{out} is not a folder; give a .las / .laz output file or a folder")
        check_new_folder(out)  # without overwriting (lidarfx without --force): new or empty
        if not out.parent.is_dir() and str(out.parent) not in ("", "."):
            raise LidarfxError(f"output folder's parent does not exist: {out.parent}")
        ext = ""
        names = [Path(s.path).name for s in cat.sources]
        if len(set(names)) < len(names):
            raise LidarfxError("two inputs have the same file name; one file per input tile needs distinct names")
        for s in cat.sources:
            if os.path.realpath(out / Path(s.path).name) == os.path.realpath(s.path):
                raise LidarfxError(f"{s.path} would be overwritten; give another output folder")
    else:
        from .._atomic import check_not_same_file, check_output_folder

        ext = out.suffix.lower()
        check_output_folder(out)
        for s in cat.sources:
            check_not_same_file(s.path, out)
    need, exact = proc.buffer(options, cat.density)  # coordinate units
    buffer, chunk_size = length_to_units(unit, buffer), length_to_units(unit, chunk_size)
    if buffer is not None and exact and buffer < need * (1 - 1e-12):
        raise LidarfxError(f"--buffer {buffer * unit:g} m is narrower than the {need * unit:g} m the neighbourhoods of "
                           f"{command} reach; results near chunk borders would differ")
    buf = float(need if buffer is None else buffer)
    n_workers = default_workers() if workers is None else int(workers)
    if n_workers < 1:
        raise LidarfxError(f"--workers must be at least 1, got {workers}")
    if chunk_size is None:
        chunk_size = default_chunk_size(cat.points, cat.mins, cat.maxs, buf, chunk_points_budget(n_workers))
    grid = check_grid(float(chunk_size), buf, cat.mins, cat.maxs)
    work = Path(work_dir) if work_dir is not None else out.with_name(out.name + ".lidarfx-work")
    manifest = _manifest(cat, command, options, grid, per_tile, ext)
    with _naming(work):  # a full disk in the work folder says so (its files are kept for --resume)
        have_split = _prepare_work(work, manifest, resume)
    try:
        with _naming(work):
            if have_split:
                split = _read_split(work, cat.points)
            else:
                from ..progress import bar, wanted

                if (work / "split").exists():
                    shutil.rmtree(work / "split")
                with bar("splitting", cat.points, wanted(progress)) as advance:
                    split = split_inputs(cat, grid, work, advance)
            t1 = time.perf_counter()
            chunks = split["chunks"]
            done = {p.stem for p in (work / "done").glob("*.json")}
            todo = [c for c in chunks if c["name"] not in done or not (work / "out" / c["name"]).is_dir()]
            threads = max(1, default_workers() // n_workers) if scheduler is None else 0
            spec = {"command": command, "options": options, "mins": split["mins"], "maxs": split["maxs"],
                    "points": split["points"], "chunk_size": grid.size, "buffer": grid.buffer, "threads": threads,
                    "sources": len(cat.sources), "chunks": {c["name"]: (c["i"], c["j"]) for c in todo}}
            n_exec = min(n_workers, max(1, len(todo)))
            execute([(c["name"], process_chunk, (str(work), c["name"], spec)) for c in todo],
                    workers=n_exec, scheduler=scheduler, progress=progress)
        t2 = time.perf_counter()
        outputs = _merge(work, chunks, cat, out, per_tile, ext, progress, n_workers, scheduler)
    except LidarfxError:
        # a damaged input or an option that does not fit: the same run would fail the same way and
        # other inputs or options cannot resume it, so nothing is kept (a full disk, a kill or Ctrl-C
        # keep the finished chunks for --resume)
        if not keep_work:
            shutil.rmtree(work, ignore_errors=True)
        raise
    t3 = time.perf_counter()
    infos = []
    for c in chunks:
        try:
            infos.append(json.loads((work / "done" / f"{c['name']}.json").read_text()))
        except (OSError, ValueError):
            pass
    if not keep_work:
        shutil.rmtree(work, ignore_errors=True)
    return TileRun(outputs=outputs, chunks=len(chunks), resumed=len(chunks) - len(todo), points=cat.points,
                   chunk_size=float(f"{grid.size * unit:.12g}"), buffer=float(f"{grid.buffer * unit:.12g}"),
                   workers=n_exec,
                   scheduler=scheduler or ("embedded LocalCluster" if n_exec > 1 else "this process"),
                   seconds={"split": round(t1 - t0, 3), "chunks": round(t2 - t1, 3), "merge": round(t3 - t2, 3)},
                   largest_chunk=max((c["buffered"] for c in chunks), default=0), chunk_infos=infos)


def _merge(work: Path, chunks: list[dict], cat: Catalog, out: Path, per_tile: bool, ext: str,
           progress: bool | None, workers: int, scheduler: str | None) -> list[str]:
    """The parts of every chunk into the output file, or into one file per input tile (those
    merged in parallel, as tasks like the chunks): in the inputs' order (global index), streamed."""

    def parts_of(ks):
        return [p for c in chunks for k in ks for p in [work / "out" / c["name"] / f"{k}.las"] if p.exists()]

    if not per_tile:
        parts = parts_of(range(len(cat.sources)))
        if not parts:  # every point was dropped (crop, filter): nothing to write, the caller decides
            return []
        execute([(out.name, _merge_ordered, (parts, out, ext, 0, cat.points))],
                workers=1, scheduler=None, progress=progress, what="merge")
        return [str(out)]
    out.mkdir(exist_ok=True)
    tasks = []
    for k, src in enumerate(cat.sources):
        parts = parts_of([k])
        target = out / Path(src.path).name
        if parts:
            tasks.append((target.name, _merge_ordered, (parts, target, target.suffix.lower(), src.first,
                                                        src.first + src.points)))
    execute(tasks, workers=min(workers, len(tasks)), scheduler=scheduler, progress=progress, what="merge")
    return [str(out / name) for name, _, _ in tasks]


__all__ = ["Context", "Chunk", "TileRun", "run_tiled", "execute", "process_chunk"]
