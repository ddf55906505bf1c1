"""Colours shared by every picture and by ``lidarfx colour``: one palette per concept."""
from __future__ import annotations

import numpy as np

NO_SET = (0.62, 0.62, 0.62)
"""Colour of points / poles / segments without a joint set (set id < 0)."""

_SETS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f")


def set_colour(set_id: int) -> tuple[float, float, float]:
    """RGB (0–1) of joint set ``set_id`` (0 = the largest set); ids < 0 get :data:`NO_SET`.

    Ten distinct colours (the tab10 order without its grey first), cycled beyond ten sets.
    """
    from matplotlib.colors import to_rgb

    if set_id < 0:
        return NO_SET
    return to_rgb(_SETS[set_id % len(_SETS)])


def set_colours(set_ids) -> np.ndarray:
    """``(n, 3)`` RGB (0–1) for an array of set ids (< 0 → :data:`NO_SET`)."""
    ids = np.asarray(set_ids, dtype=np.int64).ravel()
    if ids.size == 0:
        return np.zeros((0, 3))
    k = int(max(ids.max(), 0)) + 1
    table = np.array([set_colour(i) for i in range(k)] + [NO_SET])
    return table[np.where(ids < 0, k, ids)]
