"""Filter accuracy as in the ISPRS filter test (Sithole & Vosselman 2004)."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import LidarfxError

__all__ = ["ground_errors"]


def ground_errors(pred_mask: Any, ref_mask: Any) -> dict[str, Any]:
    """Type I, type II and total error of a ground classification.

    Parameters
    ----------
    pred_mask, ref_mask:
        Boolean arrays of equal length: predicted ground and reference ground.

    Returns
    -------
    dict
        ``type_i`` = ground points rejected as object / all reference ground;
        ``type_ii`` = object points accepted as ground / all reference object;
        ``total`` = all misclassified / all points (fractions, NaN when the
        denominator is 0), plus the counts ``n_points``, ``n_ground``,
        ``n_object``, ``n_type_i``, ``n_type_ii`` and the 2×2 cross table
        ``table`` = [[ground→ground, ground→object], [object→ground,
        object→object]] (rows = reference, columns = predicted), as in
        Sithole & Vosselman (2004), Table 3.
    """
    pred = np.asarray(pred_mask)
    ref = np.asarray(ref_mask)
    if pred.shape != ref.shape or pred.ndim != 1:
        raise LidarfxError(f"pred and ref masks must be 1-D of equal length, got {pred.shape} and {ref.shape}")
    pred = pred.astype(bool)
    ref = ref.astype(bool)
    n = int(ref.size)
    n_ground = int(ref.sum())
    n_object = n - n_ground
    a = int(np.count_nonzero(ref & pred))
    b = int(np.count_nonzero(ref & ~pred))  # type I
    c = int(np.count_nonzero(~ref & pred))  # type II
    d = n_object - c

    def frac(num: int, den: int) -> float:
        return num / den if den else float("nan")

    return {
        "type_i": frac(b, n_ground),
        "type_ii": frac(c, n_object),
        "total": frac(b + c, n),
        "n_points": n,
        "n_ground": n_ground,
        "n_object": n_object,
        "n_type_i": b,
        "n_type_ii": c,
        "table": [[a, b], [c, d]],
    }
