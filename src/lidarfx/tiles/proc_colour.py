"""``colour`` in chunks: every point's RGB equals the in-memory run's (bit for bit).

What the in-memory run takes from the whole cloud is settled once, before the chunks, by
:func:`colour_options` (the CLI calls it; so may a caller of :func:`lidarfx.tiles.run_tiled`):

- ``by`` an attribute without ``range``: the 2nd-98th percentile of its finite values over all
  inputs, exact (:func:`exact_percentiles`: all values when they fit in memory, else a radix
  selection over a few streaming passes, interpolated as :func:`numpy.percentile` does);
- ``by="morphology"`` with normals to compute: the radius must be given (the in-memory default
  comes from the whole cloud's point spacing); the normals of a chunk's points are computed with
  the whole cloud's index layout (origin = the global minimum), buffer = the radius;
- normals in the inputs (``normal_x/y/z``), ``by="set"`` and ``by="class"`` are per point
  (buffer 0).

Options (JSON): ``by``, ``cmap``, ``range`` ([lo, hi]), ``range_source``, ``normals``
("attributes" / "computed"), ``radius``, ``scanner``, ``sun_azimuth``, ``sun_altitude``.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable, Iterable, Iterator

import numpy as np

from ..errors import LidarfxError
from .processors import Processor

PERCENTILES = (2.0, 98.0)
"""The default value range of ``colour --by ATTRIBUTE`` (as :func:`lidarfx.colour.colour_cloud`)."""

IN_MEMORY_VALUES = 20_000_000
"""Finite values an exact percentile gathers in memory at most; beyond, radix selection."""


# --------------------------------------------------------------------------- exact percentiles
def _keys(v: np.ndarray) -> np.ndarray:
    """Order-preserving uint64 keys of finite float64 values."""
    b = np.ascontiguousarray(v, dtype=np.float64).view(np.uint64)
    top = np.uint64(1 << 63)
    return np.where(b & top, ~b, b | top)


def _value_of_key(k: int) -> float:
    k = np.uint64(k)
    top = np.uint64(1 << 63)
    b = (k ^ top) if (k & top) else ~k
    return float(np.array([b], dtype=np.uint64).view(np.float64)[0])


def _lerp_like_numpy(n: int, q: np.ndarray, below: np.ndarray, above: np.ndarray) -> np.ndarray:
    """``numpy.percentile(values, q * 100)`` (method "linear") from the order statistics ``below``
    (at floor((n - 1) q)) and ``above`` (the next one) of ``n`` values: numpy's own arithmetic."""
    virtual = (n - 1) * q
    prev = np.floor(virtual)
    gamma = virtual - prev
    diff = above - below
    out = below + diff * gamma
    hi = gamma >= 0.5
    out[hi] = (above - diff * (1 - gamma))[hi]
    return out


def _ranks(n: int, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The indices (in sorted order) numpy's "linear" percentile reads: below and above."""
    virtual = (n - 1) * q
    prev = np.floor(virtual)
    nxt = prev + 1
    top = virtual >= n - 1
    prev[top], nxt[top] = n - 1, n - 1
    low = virtual < 0
    prev[low], nxt[low] = 0, 0
    return prev.astype(np.int64), nxt.astype(np.int64)


def exact_percentiles(values: Callable[[], Iterable[np.ndarray]], percentiles=PERCENTILES, *,
                      in_memory: int | None = None) -> tuple[int, list[float]]:
    """``(n, [p, ...])``: the number of finite values and their percentiles, equal to
    ``numpy.percentile`` of all of them, over data larger than memory.

    ``values()`` yields the values (float64 arrays, NaN / inf skipped) and may be called again:
    the first pass counts and keeps the values while at most ``in_memory`` (default
    :data:`IN_MEMORY_VALUES`); beyond, each further
    pass fixes 16 more bits of the order-preserving keys of the values sought (radix selection)
    until the values left fit in memory.  ``n == 0``: no percentiles (empty list)."""
    in_memory = IN_MEMORY_VALUES if in_memory is None else int(in_memory)
    q = np.true_divide(np.asarray(percentiles, dtype=np.float64), 100)
    n = 0
    kept: list[np.ndarray] | None = []
    hist = np.zeros(1 << 16, dtype=np.int64)
    for v in values():
        v = np.asarray(v, dtype=np.float64)
        v = v[np.isfinite(v)]
        n += len(v)
        if kept is not None:
            kept.append(v)
            if n > in_memory:
                kept = None
        hist += np.bincount((_keys(v) >> np.uint64(48)).astype(np.int64), minlength=1 << 16)
    if n == 0:
        return 0, []
    if kept is not None:
        return n, [float(t) for t in np.percentile(np.concatenate(kept), np.asarray(percentiles))]
    below, above = _ranks(n, q)
    wanted = sorted(set(below.tolist()) | set(above.tolist()))
    found: dict[int, float] = {}
    # groups: (key prefix, free low bits) -> [(rank within the group, global rank)]
    groups: dict[tuple[int, int], list[tuple[int, int]]] = {}
    counts: dict[tuple[int, int], int] = {}
    cum = np.cumsum(hist)
    for r in wanted:
        d = int(np.searchsorted(cum, r, side="right"))
        g = (d, 48)
        groups.setdefault(g, []).append((r - (int(cum[d - 1]) if d else 0), r))
        counts[g] = int(hist[d])
    while groups:
        for g in [g for g in groups if g[1] == 0]:  # every key fixed: one value
            for _, r in groups.pop(g):
                found[r] = _value_of_key(g[0])
        if not groups:
            break
        collect = {g for g in groups if counts[g] <= in_memory}
        refine = [g for g in groups if g not in collect]
        got: dict = {g: [] for g in collect}
        hists = {g: np.zeros(1 << 16, dtype=np.int64) for g in refine}
        for v in values():
            v = np.asarray(v, dtype=np.float64)
            v = v[np.isfinite(v)]
            k = _keys(v)
            for g in groups:
                m = (k >> np.uint64(g[1])) == np.uint64(g[0])
                if g in collect:
                    got[g].append(v[m])
                else:
                    digit = ((k[m] >> np.uint64(g[1] - 16)) & np.uint64(0xFFFF)).astype(np.int64)
                    hists[g] += np.bincount(digit, minlength=1 << 16)
        new: dict[tuple[int, int], list[tuple[int, int]]] = {}
        for g in collect:
            vals = np.sort(np.concatenate(got[g]))
            for rr, r in groups[g]:
                found[r] = float(vals[rr])
        for g in refine:
            cum = np.cumsum(hists[g])
            for rr, r in groups[g]:
                d = int(np.searchsorted(cum, rr, side="right"))
                ng = ((g[0] << 16) | d, g[1] - 16)
                new.setdefault(ng, []).append((rr - (int(cum[d - 1]) if d else 0), r))
                counts[ng] = int(hists[g][d])
        groups = new
    out = _lerp_like_numpy(n, q, np.array([found[int(r)] for r in below]), np.array([found[int(r)] for r in above]))
    return n, [float(t) for t in out]


# --------------------------------------------------------------------------- the whole input, once
def _first_clouds(cat) -> list:
    """One point of every input (its attribute names and types)."""
    from ..io.las import iter_chunks

    return [next(iter(iter_chunks(Path(s.path), 1))) for s in cat.sources]


def _attribute_values(cat, name: str) -> Callable[[], Iterator[np.ndarray]]:
    from ..colour import attribute_array
    from ..io.las import iter_chunks

    def values():
        for s in cat.sources:
            for c in iter_chunks(Path(s.path)):
                yield attribute_array(c, name).astype(np.float64)

    return values


def colour_options(inputs, by: str = "morphology", *, radius: float | None = None, scanner=None,
                   sun_azimuth: float = 315.0, sun_altitude: float = 45.0, cmap: str = "viridis",
                   value_range=None, progress: bool | None = None) -> dict:
    """The options of a chunked ``colour`` run over ``inputs`` (as :func:`lidarfx.tiles.run_tiled`
    takes them), with what the in-memory run takes from the whole cloud settled once: the value
    range of an attribute (exact 2nd-98th percentile, a pass over the inputs), whether the
    inputs carry normals.  One-line errors as the in-memory run's, and for morphology without
    normals and without ``radius``."""
    from ..colour import KEYWORDS, NORMAL_NAMES, attribute_array, check_cmap, check_radius, check_sun, check_value_range
    from .catalog import open_catalog

    if not isinstance(by, str) or not by.strip():
        raise LidarfxError(f"'by' must be morphology, set, class or an attribute name, got {by!r}")
    by = by.strip()
    az, alt = check_sun(sun_azimuth, sun_altitude)
    radius = check_radius(radius)
    value_range = check_value_range(value_range)
    cat = open_catalog(inputs)
    firsts = _first_clouds(cat)
    o: dict = {"by": by}
    if by == "morphology":
        has = [all(k in c for k in NORMAL_NAMES) for c in firsts]
        if all(has):
            o.update(normals="attributes")
        elif any(has):
            raise LidarfxError("some inputs carry normal_x/y/z and some do not; colour them apart "
                               "(the normals would come from different sources)")
        else:
            if radius is None:
                raise LidarfxError("colour by morphology in chunks needs --radius (the default comes from the "
                                   "whole cloud's point spacing), or run in memory with --chunk-size 0")
            if scanner is not None:
                from ..features.api import check_options
                from ..features.registry import resolve

                check_options(resolve(list(NORMAL_NAMES)), [radius], scanner=scanner)
            o.update(normals="computed", radius=radius,
                     scanner=None if scanner is None else [float(v) for v in scanner])
        o.update(sun_azimuth=az, sun_altitude=alt)
    elif by in KEYWORDS:  # set, class
        need = "set_id" if by == "set" else "classification"
        for s, c in zip(cat.sources, firsts):
            if need not in c:
                raise LidarfxError(f"{Path(s.path).name}: colour by {by} needs the {need} attribute; "
                                   f"it has: {', '.join(c.names) or 'none'}")
    else:
        cm = check_cmap(cmap)
        for c in firsts:
            v = attribute_array(c, by)
            if v.dtype.kind not in "biuf":
                raise LidarfxError(f"attribute {by!r} is not numeric ({v.dtype}); it cannot be colour-mapped")
        o.update(cmap=cm.name)
        if value_range is not None:
            o.update(range=[float(value_range[0]), float(value_range[1])], range_source="given")
        else:
            n, p = exact_percentiles(_attribute_values(cat, by))
            if n:
                o.update(range=p, range_source="percentiles 2-98")
            else:
                o.update(range=[0.0, 1.0], range_source="no finite values")
    return o


# --------------------------------------------------------------------------- the processor
def colour_buffer(o: dict, density: float) -> tuple[float, bool]:
    """The normals' radius when they are computed (metres in the options, coordinate units
    here), else 0 (per point)."""
    from .processors import unit_of

    if o.get("by") == "morphology" and o.get("normals") == "computed":
        return float(o["radius"]) / unit_of(o), True
    return 0.0, True


def check_colour_options(o: dict) -> None:
    """Options from :func:`colour_options` (a one-line error otherwise)."""
    from ..colour import KEYWORDS, check_cmap, check_radius, check_sun, check_value_range

    by = o.get("by")
    if not isinstance(by, str) or not by:
        raise LidarfxError("colour options need 'by' (use lidarfx.tiles.proc_colour.colour_options)")
    if by == "morphology":
        check_sun(o.get("sun_azimuth", 315.0), o.get("sun_altitude", 45.0))
        if o.get("normals") not in ("attributes", "computed"):
            raise LidarfxError("colour by morphology in chunks needs options from colour_options (normals)")
        if o["normals"] == "computed" and check_radius(o.get("radius")) is None:
            raise LidarfxError("colour by morphology in chunks needs --radius (the default comes from the "
                               "whole cloud's point spacing), or run in memory with --chunk-size 0")
    elif by not in KEYWORDS:
        check_cmap(o.get("cmap", "viridis"))
        vr = o.get("range")
        if vr is None:
            raise LidarfxError(f"colour by {by} in chunks needs the value range of the whole input "
                               f"(--range, or the options of colour_options)")
        if o.get("range_source", "given") == "given":
            check_value_range(vr)
        elif not (len(vr) == 2 and all(math.isfinite(float(v)) for v in vr) and float(vr[0]) <= float(vr[1])):
            raise LidarfxError(f"colour range must be two finite numbers lo <= hi, got {vr!r}")


def colour_process(chunk, ctx, o: dict):
    """RGB of the owned points: :func:`lidarfx.colour.colour_cloud` on them, the normals (when
    computed) in the whole cloud's index layout over the buffered cloud."""
    from ..colour import KEYWORDS, NORMAL_NAMES, by_attribute, colour_cloud, morphology_rgb, to_uint16

    cloud, own = chunk.cloud, chunk.own
    result = cloud.subset(own)
    result.meta.pop("source", None)
    by = o["by"]
    if by == "morphology" and o.get("normals") == "computed":
        from ..features.registry import resolve
        from .processors import chunk_feature_arrays, unit_of

        f = chunk_feature_arrays(chunk, ctx, resolve(list(NORMAL_NAMES)), [float(o["radius"]) / unit_of(o)],
                                 scanner=o.get("scanner"))
        normals = np.column_stack([np.asarray(f[k], dtype=np.float64) for k in NORMAL_NAMES])
        c16 = to_uint16(morphology_rgb(normals, sun_azimuth=o.get("sun_azimuth", 315.0),
                                       sun_altitude=o.get("sun_altitude", 45.0)))
        result["red"], result["green"], result["blue"] = c16[:, 0], c16[:, 1], c16[:, 2]
        return result
    if by == "morphology" and not all(k in result for k in NORMAL_NAMES):
        raise LidarfxError("these points carry no normal_x/y/z; give --radius to compute them")
    if by in KEYWORDS:
        out = colour_cloud(result, by, sun_azimuth=o.get("sun_azimuth", 315.0),
                           sun_altitude=o.get("sun_altitude", 45.0), progress=False)
        out.meta.pop("colour", None)
        return out
    # the whole input's range as the in-memory run has it (lo == hi included: mid colour)
    rgb, _ = by_attribute(result, by, o.get("cmap", "viridis"), tuple(float(v) for v in o["range"]))
    c16 = to_uint16(rgb)
    result["red"], result["green"], result["blue"] = c16[:, 0], c16[:, 1], c16[:, 2]
    return result


PROCESSORS = {"colour": Processor(colour_buffer, colour_process, check_colour_options, metres=True)}

__all__ = ["PROCESSORS", "colour_options", "exact_percentiles"]
