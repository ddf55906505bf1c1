"""``crop``, ``filter`` and ``reproject`` in chunks (docs/scaling.md, docs/everyday.md).

- ``crop``: per point, no buffer; every chunk keeps its own points inside the box or area (the
  area travels as WKB).  The same points as one run in memory.
- ``filter``: the outlier filters of :mod:`lidarfx.outliers` with the whole cloud's index origin.
  Radius outliers: buffer = the radius, the same counts as in memory.  Statistical outliers: the
  threshold μ + std·σ belongs to the whole cloud, so a first pass (command ``outliers-stats``)
  adds up every chunk's exact sums (:func:`lidarfx.outliers.moments`) and the second pass
  classifies or drops with that threshold: the same outliers as in memory, bit for bit.  Every
  chunk checks that its points' k-th neighbours lie inside its buffer.  The default buffer is five
  times the radius holding k + 1 points at the mean density; when some neighbours reach farther
  (gaps, isolated points) the statistics pass says how far, and runs again once with that buffer
  (the reach found is an upper bound, so once is enough).  A buffer given by the user is kept: a
  one-line error names the buffer needed.
- ``reproject``: per point, no buffer.  The output scales and offsets are settled before the
  chunks from the inputs' header bounds (:func:`reproject_options`), so every chunk and every
  output tile shares them; coordinates equal the in-memory run's within the output scale (the
  in-memory run takes its offsets from the points themselves).

A chunk of ``crop`` or ``filter --action drop`` returns ``(points kept, mask over its own
points)``; the engine writes those only.  When no point is left, :func:`run_ops` reports it:
``crop`` refuses (unless ``allow_empty``), the others write an empty file.
"""
from __future__ import annotations

import functools
import json
import math
import shutil
import time
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import LidarfxError
from .processors import Processor, unit_of


# --------------------------------------------------------------------------- crop
def crop_buffer(o: dict, density: float) -> tuple[float, bool]:
    return 0.0, True


def check_crop_options(o: dict) -> None:
    if (o.get("bounds") is None) == (o.get("polygon") is None):
        raise LidarfxError("give exactly one of --bounds and --polygon")


@functools.lru_cache(maxsize=4)
def _geometry(wkb_hex: str):
    import shapely

    return shapely.from_wkb(bytes.fromhex(wkb_hex))


def crop_process(chunk, ctx, o: dict):
    from ..crop import area_mask

    cloud, own = chunk.cloud, chunk.own
    sub = cloud.subset(own)
    sub.meta.pop("source", None)
    d = float(o.get("buffer") or 0.0) / unit_of(o)
    if o.get("bounds") is not None:
        b = o["bounds"]
        x, y = sub.x, sub.y
        keep = (x >= b[0] - d) & (x <= b[2] + d) & (y >= b[1] - d) & (y <= b[3] + d)
        if len(b) == 6:
            keep &= (sub.z >= b[4]) & (sub.z <= b[5])
    else:
        keep = area_mask(_geometry(o["polygon"]), sub.x, sub.y, d)
    if o.get("invert"):
        keep = ~keep
    return sub.subset(keep), keep


# --------------------------------------------------------------------------- filter
def filter_buffer(o: dict, density: float) -> tuple[float, bool]:
    if o["method"] == "radius":
        return float(o["radius"]) / unit_of(o), True
    rk = math.sqrt((int(o["k"]) + 1) / (math.pi * max(density, 1e-12)))
    return float(f"{5.0 * rk:.2g}"), False


def check_filter_options(o: dict) -> None:
    from ..outliers import check_options

    check_options(o["method"], o.get("k", 8), o.get("std", 2.0), o.get("radius"), o.get("min_neighbours"),
                  o.get("action", "classify"), o.get("class", 7))


def _mean_distances(chunk, ctx, o: dict, with_reach: bool = False):
    """The mean distance of every owned point to its k nearest other points (the whole cloud's
    index origin), and None when the buffer holds every k-th neighbour, else the buffer (m) that
    does (an upper bound: a neighbour missing beyond the buffer is nearer than the one found).
    ``with_reach``: also every owned point's distance to its k-th neighbour (coordinate units)."""
    from ..neighbors import NeighborIndex
    from ..outliers import knn_cell

    k = int(o["k"])
    cloud, own = chunk.cloud, chunk.own
    b = ctx.grid.buffer
    q = cloud.xyz[own]
    if len(cloud) <= k:  # fewer points than a neighbourhood, buffer included
        far = np.full(len(q), np.inf)
        return (far, max(2.0 * b, b + 1.0) * unit_of(o)) + ((far,) if with_reach else ())
    index = NeighborIndex(cloud.xyz, knn_cell(cloud.xyz, k + 1), np.asarray(ctx.mins, dtype=np.float64))
    _, dist = index.knn(q, k + 1)
    bx0, by0, bx1, by1 = chunk.square(ctx)
    lo, hi = np.asarray(ctx.mins, dtype=np.float64), np.asarray(ctx.maxs, dtype=np.float64)
    # a side whose buffered edge lies beyond the data misses no neighbour
    sides = [(q[:, 0] - (bx0 - b), bx0 - b < lo[0]), ((bx1 + b) - q[:, 0], bx1 + b > hi[0]),
             (q[:, 1] - (by0 - b), by0 - b < lo[1]), ((by1 + b) - q[:, 1], by1 + b > hi[1])]
    room = np.minimum.reduce([np.full(len(q), np.inf) if open_ else r for r, open_ in sides])
    reach = dist[:, -1]
    bad = reach > room
    need = float((reach[bad] - room[bad]).max() + b) * unit_of(o) if bad.any() else None
    return (dist[:, 1:].sum(axis=1) / k, need) + ((reach,) if with_reach else ())


def _reach_error(k: int, need: float) -> LidarfxError:
    return LidarfxError(f"the {k} nearest neighbours reach {need:.2f} m beyond the chunk; give --buffer {math.ceil(need)}")


def stats_process(chunk, ctx, o: dict):
    """First pass of the statistical filter: the exact sums of the owned points' mean distances, or
    the buffer the chunk needs, written to ``stats_dir/<chunk>.json``; no point is written."""
    from ..outliers import moments

    d, need, reach = _mean_distances(chunk, ctx, o, with_reach=True)
    n, s1, s2 = moments(d) if need is None else (len(d), 0, 0)
    folder = Path(o["stats_dir"])
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / f".{chunk.name}.tmp"
    tmp.write_text(json.dumps({"n": n, "s1": str(s1), "s2": str(s2), "need": need,
                               "reach": None if need is not None else float(reach.max(initial=0.0)) * unit_of(o)}))
    tmp.replace(folder / f"{chunk.name}.json")
    none = np.zeros(int(chunk.own.sum()), dtype=bool)
    sub = chunk.cloud.subset(chunk.own)
    return sub.subset(none), none


def filter_process(chunk, ctx, o: dict):
    from ..outliers import apply_action
    from ..neighbors import NeighborIndex

    cloud, own = chunk.cloud, chunk.own
    if o["method"] == "statistical":
        d, need = _mean_distances(chunk, ctx, o)
        if need is not None:
            raise _reach_error(int(o["k"]), need)
        mask = d > float(o["threshold"])
    else:
        r = float(o["radius"]) / unit_of(o)
        index = NeighborIndex(cloud.xyz, r, np.asarray(ctx.mins, dtype=np.float64))
        mask = (index.count(cloud.xyz[own], r) - 1) < int(o["min_neighbours"])
    sub = cloud.subset(own)
    sub.meta.pop("source", None)
    out = apply_action(sub, mask, o.get("action", "classify"), int(o.get("class", 7)))
    return (out, ~mask) if o.get("action") == "drop" else out


# --------------------------------------------------------------------------- reproject
@functools.lru_cache(maxsize=4)
def _operation(src: str, dst: str, ballpark: bool):
    from ..reproject import parse_crs, transformer

    s, d = parse_crs(src, "--from"), parse_crs(dst, "--to")
    return s, d, transformer(s, d, ballpark=ballpark)[0]


def reproject_process(chunk, ctx, o: dict):
    from ..cloud import PointCloud
    from ..reproject import _transform, set_crs

    _, dst, t = _operation(o["from"], o["to"], bool(o.get("ballpark")))
    sub = chunk.cloud.subset(chunk.own)
    xyz = _transform(t, sub.xyz, progress=False)
    header = sub.header.copy()
    header.scales = np.asarray(o["scales"], dtype=np.float64)
    header.offsets = np.asarray(o["offsets"], dtype=np.float64)
    set_crs(header, dst)
    return PointCloud(xyz, sub.attrs, header=header)


# --------------------------------------------------------------------------- select
def check_select_options(o: dict) -> None:
    from ..select import parse

    if not isinstance(o.get("where"), str):
        raise LidarfxError("select options need 'where', an expression")
    parse(o["where"])


def select_process(chunk, ctx, o: dict):
    """The owned points where the expression holds (not, with ``invert``): per point, no buffer."""
    from ..select import evaluate, parse

    sub = chunk.cloud.subset(chunk.own)
    sub.meta.pop("source", None)
    mask = np.asarray(evaluate(sub, parse(o["where"])), dtype=bool)
    if o.get("invert"):
        mask = ~mask
    return sub.subset(mask), mask


PROCESSORS = {
    "crop": Processor(crop_buffer, crop_process, check_crop_options, metres=True),
    "select": Processor(crop_buffer, select_process, check_select_options),
    "filter": Processor(filter_buffer, filter_process, check_filter_options, metres=True),
    "outliers-stats": Processor(filter_buffer, stats_process, check_filter_options, metres=True),
    "reproject": Processor(crop_buffer, reproject_process),
}


# --------------------------------------------------------------------------- drivers
def _headers(inputs) -> list:
    from ..io.las import read_header
    from .catalog import expand_inputs

    return [(p, read_header(p)) for p in expand_inputs(inputs)]


def crop_options(inputs, *, bounds=None, polygon=None, buffer: float = 0.0, invert: bool = False) -> dict:
    """The options of a chunked crop: the box, or the area as WKB after its CRS was checked against
    every input's."""
    import shapely

    from ..crop import Area, _check_polygonal, parse_bounds, read_area
    from ..reproject import crs_label, crs_of, same_horizontal

    if (bounds is None) == (polygon is None):
        raise LidarfxError("give exactly one of --bounds and --polygon")
    b = float(buffer or 0.0)
    if not math.isfinite(b):
        raise LidarfxError(f"--buffer must be a finite number of metres, got {buffer!r}")
    o: dict[str, Any] = {"bounds": None, "polygon": None, "buffer": b, "invert": bool(invert)}
    heads = _headers(inputs)
    if b:
        from ..crs import crs_info

        for p, h in heads:
            if (crs_info(h) or {}).get("geographic"):
                raise LidarfxError(f"{p}: a buffer in metres needs projected coordinates; this file is in degrees")
    if bounds is not None:
        o["bounds"] = list(parse_bounds(bounds))
        return o
    area = polygon if isinstance(polygon, Area) else (read_area(polygon) if isinstance(polygon, (str, Path)) else
                                                      Area(_check_polygonal(polygon, "polygon"), None, "polygon", 1))
    if area.crs is not None:
        for p, h in heads:
            c = crs_of(h, str(p))
            if c is not None and not same_horizontal(c, area.crs):
                raise LidarfxError(f"{area.source} is in {crs_label(area.crs)} but {p} in {crs_label(c)}; give the area "
                                   "in the cloud's CRS (e.g. ogr2ogr -t_srs) or reproject the cloud")
    o["polygon"] = shapely.to_wkb(area.geometry, hex=True)
    return o


def filter_options(method: str, *, k=8, std=2.0, radius=None, min_neighbours=None, action="classify",
                   cls: int = 7) -> dict:
    from ..outliers import check_options

    return check_options(method, k, std, radius, min_neighbours, action, cls)


def reproject_options(inputs, to, *, source=None, scale=None, ballpark: bool = False) -> dict:
    """The options of a chunked reprojection: the source CRS (``source``, else the inputs', which
    must agree), the target, and the scales and offsets of every output, from the inputs' header
    bounds transformed (densified edges, a margin of 1 % of the extent)."""
    import warnings

    from ..errors import LidarfxWarning
    from ..reproject import (_horizontal, crs_label, crs_of, heights_note, output_frame, parse_crs, same_crs,
                             same_horizontal, transformer)

    dst = parse_crs(to, "--to")
    heads = _headers(inputs)
    found = [(p, crs_of(h, str(p))) for p, h in heads]
    if source is not None:
        src = parse_crs(source, "--from")
        other = next(((p, c) for p, c in found if c is not None and not same_horizontal(c, src)), None)
        if other:
            warnings.warn(f"{other[0]} says {crs_label(other[1])}; --from {crs_label(src)} is used instead",
                          LidarfxWarning, stacklevel=2)
    else:
        missing = [p for p, c in found if c is None]
        if missing:
            raise LidarfxError(f"{missing[0]} has no CRS; give the one its coordinates are in with --from")
        src = found[0][1]
        for p, c in found[1:]:
            if not same_crs(src, c):
                raise LidarfxError(f"{found[0][0]} is in {crs_label(src)} but {p} in {crs_label(c)}; reproject them "
                                   "separately, or give --from")
    t, _ = transformer(src, dst, ballpark=ballpark)
    note = heights_note(src, dst)
    if note:
        warnings.warn(note, LidarfxWarning, stacklevel=2)
    lo = np.min([np.asarray(h.mins, dtype=np.float64) for _, h in heads], axis=0)
    hi = np.max([np.asarray(h.maxs, dtype=np.float64) for _, h in heads], axis=0)
    g = np.stack(np.meshgrid(*[np.linspace(lo[a], hi[a], 11) for a in range(3)], indexing="ij"), -1).reshape(-1, 3)
    from ..reproject import _transform

    tg = _transform(t, g, progress=False)
    unchanged = [bool(np.array_equal(tg[:, a], g[:, a])) for a in range(3)]
    tlo, thi = tg.min(axis=0), tg.max(axis=0)
    margin = 0.01 * (thi - tlo) + 1e-9
    if not _horizontal(dst).is_geographic:
        margin[:2] += 1.0
    scales = np.min([np.asarray(h.scales, dtype=np.float64) for _, h in heads], axis=0)
    offsets0 = np.asarray(heads[0][1].offsets, dtype=np.float64)
    sc, off = output_frame(scales, src, dst, tlo - margin, thi + margin, unchanged, offsets0, scale)
    return {"from": src.to_wkt(), "to": dst.to_wkt(), "ballpark": bool(ballpark),
            "scales": [float(v) for v in sc], "offsets": [float(v) for v in off],
            "source_label": crs_label(src), "target_label": crs_label(dst)}


def write_empty(path: Path, header) -> None:
    from .._atomic import atomic_path
    from ..io.las import write_records

    with atomic_path(path) as tmp:
        write_records(tmp, header, [], ext=path.suffix.lower())


def statistical_threshold(inputs, output, options: dict, *, work_dir=None, kw: dict) -> tuple[dict, dict]:
    """The first pass of the statistical filter in chunks (command ``outliers-stats``): ``options``
    with the whole cloud's ``threshold``, and the facts (mean distance, sigma, threshold, a widened
    buffer).  ``kw``: run_tiled's chunk keywords; its ``buffer`` is widened (in place) when the
    default buffer does not hold every k-th neighbour."""
    from ..outliers import threshold
    from . import run_tiled

    t0 = time.perf_counter()
    out = Path(output)
    extra: dict[str, Any] = {}
    buffer = kw.get("buffer")
    base = Path(work_dir) if work_dir is not None else out.with_name(out.name + ".lidarfx-work")
    stats_dir = base.with_name(base.name + "-stats.d")
    for attempt in range(3):  # the default buffer grows to what the k-th neighbours reach
        shutil.rmtree(stats_dir, ignore_errors=True)
        try:
            first = run_tiled(inputs, output, "outliers-stats", {**options, "stats_dir": str(stats_dir)},
                              work_dir=base.with_name(base.name + "-stats"), **kw)
            n, s1, s2, need, far = 0, Fraction(0), Fraction(0), None, 0.0
            for f in sorted(stats_dir.glob("*.json")):
                d = json.loads(f.read_text())
                n, s1, s2 = n + d["n"], s1 + Fraction(d["s1"]), s2 + Fraction(d["s2"])
                if d.get("need") is not None:
                    need = max(need or 0.0, float(d["need"]))
                elif d.get("reach") is not None:
                    far = max(far, float(d["reach"]))
        finally:
            shutil.rmtree(stats_dir, ignore_errors=True)
        if need is None:
            break
        if buffer is not None or attempt == 2:  # the user's buffer is kept: say what it takes
            raise _reach_error(int(options["k"]), need)
        kw["buffer"] = float(f"{math.ceil(need * 1.05 * 100) / 100:.6g}")
        extra["buffer_widened_m"] = kw["buffer"]
    if n != first.points:
        raise LidarfxError(f"the statistics pass saw {n} of {first.points} points; start again")
    mu, sigma, thr = threshold(n, s1, s2, options["std"])
    extra.update({"mean_distance": mu, "sigma": sigma, "threshold": thr, "neighbour_reach_m": far,
                  "seconds_statistics": round(time.perf_counter() - t0, 3)})
    return {**options, "threshold": thr}, extra


def run_ops(inputs, output, command: str, options: dict, *, allow_empty: bool = True, empty_message: str = "",
            chunk_size=None, buffer=None, workers=None, scheduler=None, resume=False, work_dir=None,
            progress=None) -> dict[str, Any]:
    """Run ``command`` (crop, filter, reproject) in chunks, with the statistics pass of the
    statistical filter first; returns the summary (points in and out, outputs, chunks, seconds).
    When no point is left: with ``allow_empty`` an empty output (the first input's header), else a
    one-line error (``empty_message``)."""
    from ..io.las import read_header
    from . import run_tiled
    from .catalog import expand_inputs

    t0 = time.perf_counter()
    out = Path(output)
    existed = out.exists()
    kw = dict(chunk_size=chunk_size, buffer=buffer, workers=workers, scheduler=scheduler, progress=progress)
    extra: dict[str, Any] = {}
    if command == "filter" and options["method"] == "statistical":
        options, facts = statistical_threshold(inputs, output, options, work_dir=work_dir, kw=kw)
        extra.update(facts)
    res = run_tiled(inputs, output, command, options, resume=resume, work_dir=work_dir, **kw)
    outputs = [Path(p) for p in res.outputs]
    sources = expand_inputs(inputs)
    per_tile = out.suffix.lower() not in (".las", ".laz")
    empty = []
    if per_tile:
        done = {p.name for p in outputs}
        empty = [s for s in sources if s.name not in done]
        if empty and allow_empty:
            for s in empty:
                write_empty(out / s.name, read_header(s))
                outputs.append(out / s.name)
    elif not outputs and allow_empty:
        write_empty(out, read_header(sources[0]))
        outputs = [out]
    if not outputs:
        if per_tile and not existed and out.is_dir() and not any(out.iterdir()):
            out.rmdir()  # the folder the run made for its tiles
        raise LidarfxError(empty_message or "no point is left; nothing written")
    kept = sum(int(read_header(p).point_count) for p in outputs)
    return {"input": [str(s) for s in sources] if len(sources) > 1 else str(sources[0]), "output": str(output),
            "command": command, "points": res.points, "kept": kept, **extra,
            "empty_tiles": [s.name for s in empty] if per_tile else [], **res.as_dict(),
            "seconds_total": round(time.perf_counter() - t0, 3)}


__all__ = ["PROCESSORS", "crop_options", "filter_options", "reproject_options", "run_ops"]
