"""Merging point clouds into one: headers, point formats, scales, offsets, CRS and extra bytes
reconciled, or refused with a one-line error.

Rules (:func:`plan_merge`; the same for :func:`merge_clouds` in memory and :func:`merge_files`,
which streams LAS/LAZ inputs into a LAS/LAZ output file by file, chunk by chunk)

* **CRS**: the inputs that have one must have the same (:func:`lidarfx.reproject.same_crs`: equal
  for PROJ, or one EPSG code); different CRSs are refused, naming two files and their CRSs
  (reproject one first).  An input without a CRS is taken to be in the others' CRS, with a
  warning.  The output carries the CRS records of the first input that has one, byte for byte;
  when the output's point format (6-10) needs WKT and that input has only GeoTIFF keys, a WKT
  record made by PROJ.
* **Point format**: the smallest format of the inputs' family that holds every standard field of
  every input: legacy formats (0-5) stay legacy (0 + 1 -> 1, 1 + 2 -> 3), any format 6-10 among the
  inputs makes it 6-10 (3 + 6 -> 7).  Fields an input does not have are 0 in its points.  The one
  field whose meaning changes between families: the legacy ``scan_angle_rank`` (whole degrees)
  becomes ``scan_angle`` (0.006° steps), the nearest step (within 0.003°).  The version is the
  highest of the inputs', raised to what the format needs (1.4 for 6-10).
* **Extra bytes**: the union, by name, in order of first appearance.  One name with another type,
  scale, offset or no-data value in two files is refused, naming the field and the two files; an
  extra dimension that clashes with a standard field of the output format too.  An input without
  a dimension gets its no-data value, else NaN (floating point) or 0.  The descriptors
  (description, no-data) are the first file's.
* **Scale**: the finest of the inputs, per axis.  **Offset**, per axis: among the inputs' offsets,
  the minimum rounded down to a whole unit and the middle, those holding every coordinate in
  32-bit integers at that scale, the one that keeps the most points exact (shared offsets stay);
  a one-line error when none does.  Coordinates are re-encoded exactly when an input's scale is a
  whole multiple of the output's and its offset differs by whole steps (the summary says which
  inputs), else to the nearest step, within half the output scale.
* **Header**: the first input's (system identifier, software, dates, file source id, global
  encoding, VLRs and EVLRs other than the CRS records); the GPS time type is the first input's
  with GPS time, with a warning when another input says otherwise (the times are copied as they
  are).
* Points keep the inputs' order, file after file.
"""
from __future__ import annotations

import copy
import math
import os
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .cloud import PointCloud
from .errors import LidarfxError, LidarfxWarning

__all__ = ["MergePlan", "plan_merge", "merge_clouds", "merge_files", "SCAN_ANGLE_STEP"]

SCAN_ANGLE_STEP = 0.006
"""Degrees per unit of the ``scan_angle`` field of point formats 6-10."""

_FAMILIES = ((0, 1, 2, 3, 4, 5), (6, 7, 8, 9, 10))
_MIN_VERSION = {0: (1, 1), 1: (1, 1), 2: (1, 2), 3: (1, 2), 4: (1, 3), 5: (1, 3)}
"""The oldest LAS version of each point format an output gets (laspy writes no LAS 1.0: a 1.0 input
merges into 1.1, the same records)."""
_INT32 = (-(2**31), 2**31 - 1)
CHUNK_POINTS = 1 << 20
"""Points converted at a time by the streamed merge."""


@dataclass
class MergePlan:
    """The output header and how each input's points go into it."""

    header: Any  # laspy.LasHeader of the output
    names: list[str]
    crs: Any = None  # pyproj.CRS or None
    exact: list[bool] = field(default_factory=list)  # per input: coordinates re-encoded exactly
    scan_angle: list[bool] = field(default_factory=list)  # per input: scan_angle_rank -> scan_angle
    fills: dict[str, Any] = field(default_factory=dict)  # output extra dimension -> raw fill value
    warnings: list[str] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        from .reproject import crs_label

        h = self.header
        return {"point_format": int(h.point_format.id), "version": str(h.version),
                "scales": [float(s) for s in h.scales], "offsets": [float(o) for o in h.offsets],
                "crs": None if self.crs is None else crs_label(self.crs),
                "extra_dims": [d.name for d in h.point_format.extra_dimensions],
                "coordinates_exact": dict(zip(self.names, self.exact)),
                "scan_angle_converted": [n for n, s in zip(self.names, self.scan_angle) if s]}


# --------------------------------------------------------------------------- planning
def _version(header) -> tuple[int, int]:
    return int(header.version.major), int(header.version.minor)


def _std_dims(pf) -> set[str]:
    return set(pf.standard_dimension_names) - {"X", "Y", "Z"}


def _extra_structs(header) -> dict[str, Any]:
    found = header.vlrs.get("ExtraBytesVlr")
    return {s.format_name(): s for s in found[0].extra_bytes_structs} if found else {}


def _eb_key(s) -> tuple:
    """What must agree between two files for one extra dimension: type, scale, offset, no-data."""
    o = int(s.options)
    n = max(1, int(s.num_elements())) if callable(getattr(s, "num_elements", None)) else 3

    def vals(flag, attr):
        if not o & flag:
            return None
        v = np.atleast_1d(getattr(s, attr))[:n]
        return tuple(float(x) for x in v)

    return (int(s.data_type), o if int(s.data_type) == 0 else None, vals(s.SCALE_BIT_MASK, "scale"),
            vals(s.OFFSET_BIT_MASK, "offset"), vals(s.NO_DATA_BIT_MASK, "no_data"))


def _eb_text(s, dim) -> str:
    t = str(dim.dtype) if dim is not None and dim.dtype is not None else f"data type {int(s.data_type)}"
    _, _, scale, offset, no_data = _eb_key(s)
    parts = [t] + ([f"scale {scale[0]:g}"] if scale else []) + ([f"offset {offset[0]:g}"] if offset else []) \
        + ([f"no-data {no_data[0]:g}"] if no_data else [])
    return ", ".join(parts)


def _family_format(pfs: list[int], dims: set[str]) -> int:
    fam = _FAMILIES[1] if any(p >= 6 for p in pfs) else _FAMILIES[0]
    from laspy import PointFormat

    for cand in fam:
        if dims <= _std_dims(PointFormat(cand)):
            return cand
    return fam[-1]


def _axis_exact(s_in: float, o_in: float, s_out: float, o_out: float) -> bool:
    r = s_in / s_out
    d = (o_in - o_out) / s_out
    return abs(r - round(r)) <= 1e-9 and round(r) >= 1 and abs(d - round(d)) <= 1e-6


def _choose_offsets(lo: np.ndarray, hi: np.ndarray, scales: np.ndarray, frames: list[tuple[np.ndarray, np.ndarray]],
                    weights: list[float]) -> np.ndarray:
    """Per axis, among the inputs' offsets, the minimum rounded down and the middle, those that hold
    ``lo .. hi`` in 32-bit integers at ``scales``, the one that re-encodes the most points exactly
    (``frames``: each input's scales and offsets; ``weights``: its points), the first on a tie; a
    one-line error when none fits."""
    out = np.zeros(3)
    for a, name in enumerate("xyz"):
        cands = [float(o[a]) for _, o in frames] + [math.floor(lo[a]), float(round((lo[a] + hi[a]) / 2.0))]
        best, score = None, -1.0
        for off in cands:
            if not (round((lo[a] - off) / scales[a]) >= _INT32[0] and round((hi[a] - off) / scales[a]) <= _INT32[1]):
                continue
            sc = sum(w for (s, o), w in zip(frames, weights) if _axis_exact(s[a], o[a], scales[a], off))
            if sc > score:
                best, score = off, sc
        if best is None:
            raise LidarfxError(f"cannot merge: the merged extent of {name} ({hi[a] - lo[a]:.6g}, from {lo[a]:.10g} to "
                               f"{hi[a]:.10g}) does not fit 32-bit LAS coordinates at the finest scale {scales[a]:g} "
                               f"(at most {scales[a] * 2**32:.6g}); merge fewer or closer files")
        out[a] = best
    return out


def _is_exact(s_in, o_in, s_out, o_out) -> bool:
    return all(_axis_exact(s_in[a], o_in[a], s_out[a], o_out[a]) for a in range(3))


def plan_merge(headers: Sequence[Any], names: Sequence[str], mins: Sequence, maxs: Sequence,
               counts: Sequence[int] | None = None) -> MergePlan:
    """The output header for inputs with these LAS headers (None for an input from another format),
    coordinate bounds and point counts; see the module docstring for the rules.  One-line errors for
    different CRSs, clashing extra dimensions and extents that do not fit."""
    import laspy
    from laspy import PointFormat
    from laspy.header import Version

    from .reproject import _CRS_RECORDS, crs_label, crs_of, same_crs, set_crs

    names = [str(n) for n in names]
    las = [i for i, h in enumerate(headers) if h is not None]
    plan_warnings: list[str] = []
    # CRS
    crss = [crs_of(h, n) if h is not None else None for h, n in zip(headers, names)]
    ref = next((i for i, c in enumerate(crss) if c is not None), None)
    if ref is not None:
        for i, c in enumerate(crss):
            if c is not None and not same_crs(crss[ref], c):
                raise LidarfxError(f"cannot merge: {names[ref]} is in {crs_label(crss[ref])} but {names[i]} in "
                                   f"{crs_label(c)}; reproject one first (lidarfx reproject)")
        missing = [names[i] for i, c in enumerate(crss) if c is None]
        if missing:
            plan_warnings.append(f"{', '.join(missing[:3])}{' ...' if len(missing) > 3 else ''} "
                                 f"{'has' if len(missing) == 1 else 'have'} no CRS; taken to be in "
                                 f"{crs_label(crss[ref])} like {names[ref]}")
    lo = np.min(np.asarray(mins, dtype=np.float64), axis=0)
    hi = np.max(np.asarray(maxs, dtype=np.float64), axis=0)
    if not las:
        return MergePlan(None, names, None, [False] * len(names), [False] * len(names), {}, plan_warnings)
    # point format and version
    pfs = [headers[i].point_format.id for i in las]
    new_family = any(p >= 6 for p in pfs)
    dims: set[str] = set()
    for i in las:
        d = _std_dims(headers[i].point_format)
        if new_family and "scan_angle_rank" in d:
            d = (d - {"scan_angle_rank"}) | {"scan_angle"}
        dims |= d
    pf_id = _family_format(pfs, dims)
    version = max([_version(headers[i]) for i in las] + [(1, 4) if pf_id >= 6 else _MIN_VERSION[pf_id]])
    # extra dimensions
    std_out = set(PointFormat(pf_id).dimension_names)
    extra_dims, structs, owner = [], {}, {}
    for i in las:
        h = headers[i]
        eb = _extra_structs(h)
        for dim in h.point_format.extra_dimensions:
            if dim.name in std_out:
                raise LidarfxError(f"cannot merge: the extra dimension {dim.name!r} of {names[i]} clashes with the standard "
                                   f"field of point format {pf_id}")
            s = eb.get(dim.name)
            if dim.name not in owner:
                owner[dim.name] = i
                extra_dims.append(dim)
                structs[dim.name] = s
            elif s is not None and structs[dim.name] is not None and _eb_key(s) != _eb_key(structs[dim.name]):
                j = owner[dim.name]
                raise LidarfxError(f"cannot merge: the extra dimension {dim.name!r} is "
                                   f"{_eb_text(structs[dim.name], headers[j].point_format.dimension_by_name(dim.name))} "
                                   f"in {names[j]} but {_eb_text(s, dim)} in {names[i]}")
    pf = PointFormat(pf_id)
    pf.dimensions.extend(extra_dims)
    first = headers[las[0]]
    header = first.copy()
    header.set_version_and_point_format(Version(*version), pf)
    if structs and all(s is not None for s in structs.values()):
        header.vlrs.get("ExtraBytesVlr")[0].extra_bytes_structs = [
            type(structs[d.name]).from_buffer_copy(bytes(structs[d.name])) for d in extra_dims]
    fills = {}
    for d in extra_dims:
        s = structs.get(d.name)
        if s is not None and s.options & s.NO_DATA_BIT_MASK:
            fills[d.name] = np.atleast_1d(s.no_data)[0]
        else:
            fills[d.name] = np.nan if d.dtype is not None and d.dtype.base.kind == "f" else 0
    # scales and offsets
    scales = np.min([np.asarray(headers[i].scales, dtype=np.float64) for i in las], axis=0)
    frames = [(np.asarray(headers[i].scales, dtype=np.float64), np.asarray(headers[i].offsets, dtype=np.float64))
              for i in las]
    weights = [float(counts[i]) if counts is not None else 1.0 for i in las]
    offsets = _choose_offsets(lo, hi, scales, frames, weights)
    header.scales, header.offsets = scales, offsets
    exact = [h is not None and _is_exact(np.asarray(h.scales), np.asarray(h.offsets), scales, offsets) for h in headers]
    # CRS records: the first input with a CRS, byte for byte (WKT made by PROJ where it must be WKT)
    set_crs(header, None)
    crs = crss[ref] if ref is not None else None
    if crs is not None:
        src = headers[ref]
        records = [copy.deepcopy(v) for v in list(src.vlrs) + list(src.evlrs or [])
                   if (str(v.user_id).rstrip("\x00"), int(v.record_id)) in _CRS_RECORDS]
        has_wkt = any(isinstance(v, laspy.vlrs.known.WktCoordinateSystemVlr) for v in records)
        if pf_id >= 6 and not has_wkt:
            set_crs(header, crs)
        else:
            header.vlrs.extend(records)
            header.global_encoding.wkt = bool(has_wkt and version >= (1, 4))
    # GPS time type
    timed = [i for i in las if "gps_time" in headers[i].point_format.dimension_names]
    if timed:
        kinds = {i: int(headers[i].global_encoding.gps_time_type) for i in timed}
        header.global_encoding.gps_time_type = kinds[timed[0]]
        other = [i for i in timed if kinds[i] != kinds[timed[0]]]
        if other:
            label = ("GPS week time", "adjusted standard GPS time")
            plan_warnings.append(f"{names[timed[0]]} says {label[kinds[timed[0]]]}, {names[other[0]]} "
                                 f"{label[kinds[other[0]]]}; the output says {label[kinds[timed[0]]]} and the times are "
                                 f"copied as they are")
    scan = [h is not None and new_family and "scan_angle_rank" in _std_dims(h.point_format) for h in headers]
    return MergePlan(header, names, crs, exact, scan, fills, plan_warnings)


# --------------------------------------------------------------------------- in memory
def _attr_template(header) -> PointCloud:
    """An empty cloud with the attributes (names, dtypes) a file with ``header`` reads as."""
    import laspy

    from .io.las import record_cloud

    return record_cloud(laspy.PackedPointRecord.zeros(0, header.point_format), header)


def _attr_fills(plan: MergePlan) -> dict[str, Any]:
    """Attribute name -> the value of an input without it, for the output's extra dimensions (their
    no-data value, scaled like the values, else NaN or 0); other attributes: NaN or 0."""
    out = {}
    for d in plan.header.point_format.extra_dimensions:
        raw = plan.fills.get(d.name, 0)
        v = raw
        if d.scales is not None and np.isfinite(raw):
            v = float(raw) * float(np.atleast_1d(d.scales)[0]) + float(np.atleast_1d(d.offsets)[0])
        names = [d.name] if d.num_elements == 1 else [f"{d.name}_{k}" for k in range(d.num_elements)]
        out.update({n: v for n in names})
    return out


def _cast(values: np.ndarray, dtype: np.dtype, what: str) -> np.ndarray:
    if values.dtype == dtype:
        return values
    if np.can_cast(values.dtype, dtype, "safe"):
        return values.astype(dtype)
    with np.errstate(invalid="ignore", over="ignore"):
        out = values.astype(dtype)
        back = out.astype(values.dtype)
    same = (back == values) | (np.isnan(values) & np.isnan(back) if values.dtype.kind == "f" else False)
    if not np.all(same):
        raise LidarfxError(f"cannot merge: {what} holds values that do not fit {dtype}")
    return out


def merge_clouds(clouds: Sequence[PointCloud], names: Sequence[str] | None = None) -> PointCloud:
    """One cloud of ``clouds`` (in order), reconciled by :func:`plan_merge`: the header of the
    output (point format, scales, offsets, CRS, extra dimensions) and every attribute of every
    input, filled where an input lacks it.  ``names`` name the inputs in messages (default: their
    ``meta["source"]``).  ``meta["merge"]`` holds the summary; warnings as :class:`LidarfxWarning`."""
    clouds = list(clouds)
    if not clouds:
        raise LidarfxError("nothing to merge: no input")
    names = [str(n) for n in (names or [c.meta.get("source") or c.meta.get("name") or f"input {i + 1}"
                                        for i, c in enumerate(clouds)])]
    from laspy import LasHeader

    headers = [c.header if isinstance(c.header, LasHeader) else None for c in clouds]
    full = [c for c in clouds if len(c)]
    mins = [c.xyz.min(axis=0) for c in full] or [np.zeros(3)]
    maxs = [c.xyz.max(axis=0) for c in full] or [np.zeros(3)]
    plan = plan_merge(headers, names, mins, maxs, [len(c) for c in clouds])
    for w in plan.warnings:
        warnings.warn(w, LidarfxWarning, stacklevel=2)
    template = _attr_template(plan.header) if plan.header is not None else None
    order: list[str] = list(template.names) if template is not None else []
    dtypes: dict[str, np.dtype] = {n: template[n].dtype for n in order} if template is not None else {}
    for c in clouds:
        for n in c.names:
            if n == "scan_angle_rank" and "scan_angle" in dtypes:
                continue
            if n not in dtypes:
                order.append(n)
                dtypes[n] = c[n].dtype
            elif template is None or n not in template:
                dtypes[n] = np.promote_types(dtypes[n], c[n].dtype)
    fills = _attr_fills(plan) if plan.header is not None else {}
    attrs = {}
    for n in order:
        parts = []
        for c, name, h, scan in zip(clouds, names, headers, plan.scan_angle):
            if n in c:
                parts.append(_cast(c[n], dtypes[n], f"{name}: {n}"))
            elif n == "scan_angle" and scan and "scan_angle_rank" in c:
                parts.append(np.round(c["scan_angle_rank"].astype(np.float64) / SCAN_ANGLE_STEP).astype(dtypes[n]))
            else:  # a standard field: 0, as LAS writes it; an extra dimension: its no-data, NaN or 0
                standard = template is not None and n in template and n not in fills
                v = 0 if standard else fills.get(n, np.nan if dtypes[n].kind == "f" else 0)
                parts.append(np.full(len(c), v, dtype=dtypes[n]))
        attrs[n] = np.concatenate(parts) if parts else np.zeros(0, dtypes[n])
    xyz = np.vstack([c.xyz for c in clouds])
    out = PointCloud(xyz, attrs, header=plan.header)
    out.meta["merge"] = {"inputs": names, "points": [len(c) for c in clouds], "warnings": plan.warnings,
                         **({"output": plan.summary()} if plan.header is not None else {})}
    return out


# --------------------------------------------------------------------------- streamed
def _recode(raw: np.ndarray, s_in: float, o_in: float, s_out: float, o_out: float, exact: bool) -> np.ndarray:
    """Raw integer coordinates of one axis in the output's scale and offset (int64, unchecked)."""
    if exact:
        r = int(round(s_in / s_out))
        d = int(round((o_in - o_out) / s_out))
        return raw.astype(np.int64) * r + d
    x = raw.astype(np.float64) * s_in + o_in  # as lidarfx.io reads it
    return np.rint((x - o_out) / s_out).astype(np.int64)


def convert_records(rec, header_in, plan: MergePlan, i: int, name: str):
    """An input's point record in the output's point format, scales and offsets."""
    import laspy

    h = plan.header
    out = laspy.PackedPointRecord.zeros(len(rec), h.point_format)
    for a, c in enumerate("XYZ"):
        v = _recode(rec.array[c], float(header_in.scales[a]), float(header_in.offsets[a]), float(h.scales[a]),
                    float(h.offsets[a]), plan.exact[i])
        if len(v) and (v.min() < _INT32[0] or v.max() > _INT32[1]):
            raise LidarfxError(f"{name}: points outside the bounds in its header do not fit the merged "
                               f"coordinates (scale {h.scales[a]:g}, offset {h.offsets[a]:.10g}); the header is stale")
        out.array[c] = v.astype(np.int32)
    have = set(header_in.point_format.dimension_names)
    for dim in h.point_format.dimensions:
        n = dim.name
        if n in ("X", "Y", "Z"):
            continue
        if n in have:
            if dim.is_standard:
                out[n] = rec[n]
            else:
                out.array[n] = rec.array[n]
        elif n == "scan_angle" and plan.scan_angle[i]:
            out[n] = np.round(np.asarray(rec["scan_angle_rank"], dtype=np.float64) / SCAN_ANGLE_STEP).astype(np.int16)
        elif n in plan.fills:
            out.array[n] = plan.fills[n]
    return out


def _bounds(path: Path, header) -> tuple[np.ndarray, np.ndarray]:
    """The header's coordinate bounds, or, when they are not numbers (a damaged header), the
    bounds of the file's points (a pass over them)."""
    from .io import las

    lo, hi = np.asarray(header.mins, dtype=np.float64), np.asarray(header.maxs, dtype=np.float64)
    if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi):
        return lo, hi
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for _, rec, h in las.iter_records(path, CHUNK_POINTS):
        xyz = las.record_cloud(rec, h).xyz
        xyz = xyz[np.all(np.isfinite(xyz), axis=1)]
        if len(xyz):
            lo, hi = np.minimum(lo, xyz.min(axis=0)), np.maximum(hi, xyz.max(axis=0))
    if not np.all(lo <= hi):
        raise LidarfxError(f"{path}: no point with finite coordinates to merge")
    return lo, hi


def merge_files(inputs: Sequence[str | os.PathLike] | str | os.PathLike, output: str | os.PathLike, *,
                columns: Sequence[str] | None = None, progress: bool | None = None) -> dict[str, Any]:
    """Merge point-cloud files into ``output`` (see the module docstring); returns a summary.

    ``inputs``: files, or folders standing for their ``*.las`` / ``*.laz`` files.  LAS/LAZ inputs
    into a LAS/LAZ output are streamed (headers first, then the points file by file, in chunks of
    :data:`CHUNK_POINTS`): memory does not grow with the inputs.  Other combinations read every
    input into memory (:func:`merge_clouds`).  The output is checked before any work, written to a
    temporary file and renamed at the end; it may not be one of the inputs."""
    from . import io
    from ._atomic import atomic_path, check_not_same_file
    from .io import las

    t0 = time.perf_counter()
    from .tiles.catalog import expand_inputs

    paths = expand_inputs(inputs, any_format=True, none="nothing to merge: no input")
    dst = Path(output)
    for p in paths:
        io.input_format(p)
        check_not_same_file(p, dst)
    io.check_output_path(dst)
    out_las = io.FORMATS[dst.suffix.lower()] == "las"
    all_las = all(io.input_format(p) == "las" for p in paths)
    if not (out_las and all_las):
        clouds = [io.read(p, columns=list(columns) if columns and io.accepts_columns(p) else None, progress=progress)
                  for p in paths]
        merged = merge_clouds(clouds, [str(p) for p in paths])
        io.write(merged, dst, progress=progress)
        plan_summary = merged.meta["merge"].get("output")
        return _summary(paths, dst, [len(c) for c in clouds], merged.meta["merge"]["warnings"], plan_summary,
                        "in memory", time.perf_counter() - t0)
    if columns:
        raise LidarfxError("a column spec applies only to text and .npy inputs")
    headers = []
    for p in paths:
        try:
            headers.append(las.read_header(p))
        except las.READ_ERRORS as exc:
            from .io import one_line

            raise LidarfxError(f"cannot read {p}: {one_line(exc)}") from exc
    counts = [int(h.point_count) for h in headers]
    use = [i for i, n in enumerate(counts) if n > 0] or [0]
    bounds = [_bounds(paths[i], headers[i]) for i in use]
    plan = plan_merge(headers, [str(p) for p in paths], [b[0] for b in bounds], [b[1] for b in bounds], counts)
    for w in plan.warnings:
        warnings.warn(w, LidarfxWarning, stacklevel=2)
    from .progress import bar, wanted

    def records(advance):
        for i, p in enumerate(paths):
            for _, rec, h in las.iter_records(p, CHUNK_POINTS):
                yield convert_records(rec, h, plan, i, str(p))
                advance(len(rec))

    with bar(f"merging into {dst.name}", sum(counts), wanted(progress)) as advance:
        with atomic_path(dst) as tmp:
            try:
                written = las.write_records(tmp, plan.header, records(advance), ext=dst.suffix.lower())
            except OSError as exc:
                if exc.errno is not None and exc.filename is None:
                    raise LidarfxError(f"cannot write {dst}: {exc.strerror or exc}") from exc
                raise
    if written != sum(counts):
        raise LidarfxError("an input changed while it was read")
    return _summary(paths, dst, counts, plan.warnings, plan.summary(), "streamed", time.perf_counter() - t0)


def _summary(paths, dst, counts, warns, plan_summary, mode, seconds) -> dict[str, Any]:
    return {"inputs": [{"file": str(p), "points": int(n)} for p, n in zip(paths, counts)],
            "output": str(dst), "points": int(sum(counts)), "mode": mode,
            **({"las": plan_summary} if plan_summary else {}), "warnings": list(warns),
            "seconds": round(seconds, 3)}
