"""Plain JSON for summaries, reports and metadata.

numpy scalars and arrays become Python numbers and lists, tuples become lists, mapping
keys strings, NaN and ±inf ``null`` (strict JSON: ``json.loads`` in other languages
refuses ``NaN``), anything else its ``str``.  One place for every ``--json`` output,
evaluation report, synthetic-scene truth and model-file metadata.
"""
from __future__ import annotations

import json
import math
from typing import IO, Any, Mapping

import numpy as np

__all__ = ["jsonable", "dumps", "dump"]


def jsonable(obj: Any) -> Any:
    """A copy of ``obj`` made of dict / list / str / int / float / bool / None only."""
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if obj is None or isinstance(obj, (int, str)):
        return obj
    return str(obj)


def dumps(obj: Any, **kwargs: Any) -> str:
    """``json.dumps`` of :func:`jsonable` (``obj``), strict (no NaN)."""
    return json.dumps(jsonable(obj), allow_nan=False, **kwargs)


def dump(obj: Any, fh: IO[str], **kwargs: Any) -> None:
    """``json.dump`` of :func:`jsonable` (``obj``), strict (no NaN)."""
    fh.write(dumps(obj, **kwargs))
