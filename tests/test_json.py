"""The one JSON helper behind every --json output, report, truth file and model metadata."""
from __future__ import annotations

import io
import json
import math

import numpy as np

from lidarfx import _json


def test_jsonable_plain_types_and_nan_as_null():
    obj = {1: np.float32(0.5), "a": (np.int64(3), np.bool_(True), np.array([1.0, np.nan])),
           "b": [math.inf, -math.inf, None, "x"], "c": {"d": np.uint8(7)}, "e": object}
    out = _json.jsonable(obj)
    assert out == {"1": 0.5, "a": [3, True, [1.0, None]], "b": [None, None, None, "x"], "c": {"d": 7},
                   "e": str(object)}
    assert type(out["a"][0]) is int and type(out["a"][1]) is bool and type(out["c"]["d"]) is int


def test_dump_is_strict_json():
    fh = io.StringIO()
    _json.dump({"x": float("nan"), "y": np.float64(2.0)}, fh, indent=1)
    text = fh.getvalue()
    assert "NaN" not in text
    assert json.loads(text, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c))) == {"x": None, "y": 2.0}
    assert _json.dumps([np.int32(1)]) == "[1]"
