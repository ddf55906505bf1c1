"""Compact encodings of points, attributes and lines for the report page.

Positions are float32 offsets from a rounded centre (float64 coordinates of a
national grid do not fit float32; the offsets do, to well below a millimetre
over a few kilometres).  Each attribute becomes one unsigned-integer code per
point plus ``min`` and ``scale`` (value = min + code × scale):

* integer values (integer, boolean, or integral floats) whose range fits are
  stored exactly: uint8 up to 255 steps, uint16 up to 65 535, uint32 beyond;
* other floats become uint16 over their finite range (step = range / 65 534,
  so a value is within half a step, about 5 significant digits of the range);
* a float attribute's missing values (NaN, ±inf) take the reserved code
  ``nan_code``, the largest of the type.

Everything is little-endian and base64 in the page.
"""
from __future__ import annotations

import base64
from typing import Any, Mapping, Sequence

import numpy as np

U16_STEPS = 65534
"""Steps of a quantised float (code 65535 is the missing value)."""

CATEGORICAL_MAX = 32
"""Integer attributes with at most this many distinct values are shown as categories."""

CATEGORY_LIST_MAX = 256
"""Distinct values listed in the legend at most (more: colours repeat, no list)."""

_INT_TYPES = (("u8", np.uint8, 255), ("u16", np.uint16, 65535), ("u32", np.uint32, 2**32 - 1))

ID_NAMES = ("classification", "class", "label", "labels", "cluster", "segment", "set", "id", "part", "kind")
"""Names (or ``*_id`` / ``*_class`` suffixes) of integer attributes that are categories whatever their count."""


def b64(arr: np.ndarray) -> str:
    """Base64 of the little-endian bytes of ``arr``."""
    a = np.ascontiguousarray(arr)
    if a.dtype.byteorder == ">":
        a = a.astype(a.dtype.newbyteorder("<"))
    return base64.b64encode(a.tobytes()).decode("ascii")


def is_scalar_attribute(values: Any) -> bool:
    """A 1-D numeric (or boolean) per-point array: what the viewer can show."""
    a = np.asarray(values)
    return a.ndim == 1 and a.dtype.kind in "biuf"


def _looks_categorical(name: str) -> bool:
    low = name.lower()
    return low in ID_NAMES or low.endswith(("_id", "_class", "_label", "_kind"))


def encode_attribute(name: str, values: np.ndarray, labels: Mapping[int, str] | None = None) -> tuple[dict, np.ndarray]:
    """The page's description of one attribute and its codes (see the module docstring).

    The description holds ``name``, ``type`` (u8/u16/u32), ``min``, ``scale``,
    ``nan_code`` (None when no code is reserved), ``kind`` (categorical or
    continuous), ``vmin``/``vmax`` (finite range), ``lo``/``hi`` (2–98 %
    percentiles: the colour range), ``nan_count``, ``n_distinct``,
    ``categories`` (``[value, count]`` pairs, categorical with at most
    :data:`CATEGORY_LIST_MAX` values) and ``labels`` (value -> name).
    """
    v = np.asarray(values)
    if v.dtype.kind == "b":
        v = v.astype(np.uint8)
    n = len(v)
    if v.dtype.kind == "f":
        finite = np.isfinite(v)
        fv = v[finite].astype(np.float64)
        integral = bool(fv.size == 0 or (np.all(fv == np.rint(fv)) and np.all(np.abs(fv) < 2**53)))
        has_nan = fv.size < n
    else:
        finite = None
        fv = v
        integral, has_nan = True, False
    vmin = float(fv.min()) if fv.size else 0.0
    vmax = float(fv.max()) if fv.size else 0.0
    span = vmax - vmin
    spec: dict[str, Any] = {"name": name, "vmin": vmin if fv.size else None, "vmax": vmax if fv.size else None,
                            "nan_count": int(n - fv.size)}
    if integral and span <= 2**32 - 2:
        type_, dtype, top = next(t for t in _INT_TYPES if span <= t[2] - has_nan)
        if finite is None:
            imin = v.min() if n else 0
            wide = v.astype(np.int64) - int(imin) if v.dtype.kind == "i" else v - imin  # no int8 wrap-around
            codes = wide.astype(dtype)
            vmin = int(imin)
        else:
            codes = np.full(n, top, dtype=dtype)
            codes[finite] = (fv - vmin).astype(dtype)
        nan_code = top if has_nan else None
        spec.update(type=type_, min=_num(vmin), scale=1, nan_code=nan_code,
                    max_code=top if has_nan else int(span))
        categorical = labels is not None or _looks_categorical(name) or _distinct_at_most(codes, nan_code,
                                                                                         CATEGORICAL_MAX)
    else:
        scale = span / U16_STEPS if span > 0 else (abs(vmin) or 1.0) / U16_STEPS
        if not np.isfinite(scale):  # values from -1e308 to 1e308: the span overflows, its steps do not
            scale = vmax / U16_STEPS - vmin / U16_STEPS
        codes = np.full(n, 65535, dtype=np.uint16)
        if fv.size:
            with np.errstate(over="ignore"):
                steps = (fv - vmin) / scale if np.isfinite(span) else fv / scale - vmin / scale
            q = np.clip(np.rint(steps), 0, U16_STEPS).astype(np.uint16)
            if finite is None:
                codes[:] = q
            else:
                codes[finite] = q
        spec.update(type="u16", min=vmin, scale=scale, nan_code=65535, max_code=65535)
        categorical = False
    spec["kind"] = "categorical" if categorical else "continuous"
    if fv.size:
        lo, hi = np.percentile(fv, [2, 98])
        spec["lo"], spec["hi"] = float(lo), float(hi)
    else:
        spec["lo"], spec["hi"] = 0.0, 1.0
    if categorical:
        if codes.dtype.itemsize <= 2:
            counts = np.bincount(codes)
            if has_nan:
                counts[spec["nan_code"]] = 0
            uniq = np.flatnonzero(counts)
            counts = counts[uniq]
        else:
            uniq, counts = np.unique(codes[codes != spec["nan_code"]] if has_nan else codes, return_counts=True)
        spec["n_distinct"] = int(len(uniq))
        vals = uniq.astype(np.float64) + vmin
        spec["categories"] = ([[_num(x), int(c)] for x, c in zip(vals, counts)]
                              if len(uniq) <= CATEGORY_LIST_MAX else None)
        spec["labels"] = {str(int(k)): str(t) for k, t in (labels or {}).items()}
    else:
        spec["categories"] = None
        spec["labels"] = {}
    return spec, codes


def _distinct_at_most(codes: np.ndarray, skip: int | None, limit: int) -> bool:
    """At most ``limit`` distinct codes, not counting ``skip``."""
    if codes.dtype.itemsize <= 2:
        counts = np.bincount(codes, minlength=1)
        if skip is not None and skip < len(counts):
            counts[skip] = 0
        return int(np.count_nonzero(counts)) <= limit
    uniq = np.unique(codes)
    return int(np.count_nonzero(uniq != skip)) <= limit


def _num(x: float) -> int | float:
    """An integral float as an int (for JSON and labels)."""
    return int(x) if float(x).is_integer() and abs(x) < 2**53 else float(x)


def decode_attribute(spec: Mapping[str, Any], codes: np.ndarray) -> np.ndarray:
    """The values of :func:`encode_attribute` (float64, NaN for the missing-value code)."""
    out = spec["min"] + codes.astype(np.float64) * spec["scale"]
    if spec.get("nan_code") is not None:
        out[codes == spec["nan_code"]] = np.nan
    return out


def rounded_centre(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The middle of a box rounded to whole units (a readable origin; float32 offsets keep
    0.5 mm at 4 km from it)."""
    mid = (np.asarray(lo, dtype=np.float64) + np.asarray(hi, dtype=np.float64)) / 2
    return np.round(mid) + 0.0  # no -0.0


def encode_lines(lines: Sequence[np.ndarray], centre: np.ndarray) -> tuple[list[list[int]], np.ndarray]:
    """``[start, count]`` per line and all vertices as float32 offsets from ``centre`` (n×3)."""
    spans, start = [], 0
    for ln in lines:
        spans.append([start, len(ln)])
        start += len(ln)
    xyz = np.concatenate(lines) if lines else np.empty((0, 3))
    return spans, (xyz - centre).astype(np.float32)
