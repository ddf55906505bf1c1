"""The warning when most of a computed feature is NaN, with its likely cause and a radius that works.

A feature is NaN where it is not computable (docs/features.md §3, "NaN when"); the usual reason
for a mostly-NaN run is a radius below the point spacing, so that most neighbourhoods hold fewer
points than the feature needs (3 for the covariance features, 6 for the quadric curvature).
:func:`nan_warnings` measures that on a sample of the points: the share of them with too few
points within the radius, the point spacing (median distance to the nearest other point) and the
radius that gives enough points to 90 % of them.  Radii in the messages are metres.
"""
from __future__ import annotations

import math
import warnings
from typing import Mapping, Sequence

import numpy as np

from ..errors import LidarfxWarning
from . import slots as S

NAN_SHARE = 0.5
"""A feature is reported when more than this share of the points is NaN."""
COVERED = 0.9
"""The proposed radius gives enough points to this share of the points."""
SAMPLE = 10_000
"""Points (seeded sample) the diagnosis measures at most."""

MIN_POINTS: dict[str, int] = {S.NAMES[s]: 6 for s in S.GROUPS["curvature"] + S.GROUPS["quadric"]}
MIN_POINTS.update({S.NAMES[s]: 1 for s in S.CYLINDER_SLOTS | set(S.GROUPS["distribution"] + S.GROUPS["count"])})
MIN_POINTS["echo_ratio_slope"] = 3  # needs the slope of the local plane
"""Points (the query point included) a feature needs in its neighbourhood; 3 for the others."""


FLAT_NAN = frozenset({"aspect", "msac_aspect"})
"""Features NaN by design on level ground (slope below 0.1°): reported only when the radius is the cause."""


def min_points(name: str) -> int:
    """Points a feature (name without scale suffix) needs in its neighbourhood."""
    return MIN_POINTS.get(name, 3)


def _round_up(x: float) -> float:
    """``x`` rounded up to two significant digits."""
    if not (x > 0 and math.isfinite(x)):
        return x
    e = 10.0 ** (math.floor(math.log10(x)) - 1)
    v = float(f"{math.ceil(x / e - 1e-9) * e:.3g}")
    return v if v >= x else float(f"{(math.ceil(x / e) + 1) * e:.3g}")


def _split(name: str, suffixes: Sequence[str]) -> tuple[str, int]:
    """(feature name, scale index) of an attribute name."""
    for i, sfx in enumerate(suffixes):
        if sfx and name.endswith(sfx):
            return name[: -len(sfx)], i
    return name, 0


def nan_warnings(nan_share: Mapping[str, float], xyz: np.ndarray, *, radii: Sequence[float],
                 suffixes: Sequence[str], neighbourhood: str = "sphere", unit: float = 1.0,
                 query_xyz: np.ndarray | None = None, seed: int = 0) -> list[str]:
    """The warning (a list of at most one line) when a neighbourhood feature is NaN for more than
    :data:`NAN_SHARE` of the points.

    ``nan_share``: feature attribute name -> share of NaN; ``xyz``: the neighbour cloud
    (coordinate units); ``radii``: the run's radii in metres and ``suffixes`` their attribute-name
    suffixes (``""`` for a single scale); ``unit``: metres per coordinate unit; ``query_xyz``:
    the points the features were computed at (default ``xyz``).  The line names the feature with
    the largest share, the share, and either the cause — the radius holds fewer points than the
    feature needs around most points: the measured point spacing and a radius that gives
    enough points to :data:`COVERED` of them — or that the radius is not the cause.  A mostly
    NaN ``aspect`` (:data:`FLAT_NAN`: level ground) is reported only when the radius is the
    cause."""
    over = [(n, float(v)) for n, v in nan_share.items() if v > NAN_SHARE]
    if not over:
        return []
    # the worst feature, one NaN by design on level ground (aspect) only when nothing else is
    main = [t for t in over if _split(t[0], suffixes)[0] not in FLAT_NAN] or over
    name, share = max(main, key=lambda t: t[1])
    feature, s = _split(name, suffixes)
    flat = feature in FLAT_NAN
    text = f"{name} is NaN for {100 * share:.1f} % of the points"
    if len(over) > 1:
        text += f" ({len(over) - 1} more feature{'s' if len(over) > 2 else ''} over half NaN)"
    m = min_points(feature)
    xyz = np.asarray(xyz, dtype=np.float64)
    if not radii or m < 2 or len(xyz) < 2:
        return [] if flat else [text + "; see 'NaN when' in docs/features.md §3"]
    r_m = float(radii[min(s, len(radii) - 1)])
    r_u = r_m / unit
    from ..neighbors import NeighborIndex, default_cell_for_knn

    q = xyz if query_xyz is None else np.asarray(query_xyz, dtype=np.float64)
    q = q[np.isfinite(q).all(axis=1)]
    pts = xyz[np.isfinite(xyz).all(axis=1)]
    if len(q) == 0 or len(pts) < 2:
        return [] if flat else [text + "; see 'NaN when' in docs/features.md §3"]
    rng = np.random.default_rng(seed)
    pick = q[rng.choice(len(q), size=min(SAMPLE, len(q)), replace=False)]
    if neighbourhood == "cylinder":  # plan distances (unbounded height)
        pts, pick = pts.copy(), pick.copy()
        pts[:, 2] = 0.0
        pick[:, 2] = 0.0
    kk = min(max(m, 2), len(pts))
    index = NeighborIndex(pts, default_cell_for_knn(pts - pts.min(axis=0), kk))
    _, d = index.knn(pick, kk)  # the query point itself first (distance 0)
    nearest = d[:, 1][np.isfinite(d[:, 1])]
    spacing = float(np.median(nearest)) * unit if len(nearest) else math.nan
    dm = d[:, m - 1] if m <= kk else np.full(len(pick), np.inf)
    short = float(np.mean(~(dm <= r_u)))  # fewer than m points within the radius
    where = f"{r_m:g} m" + (f" ({r_u:.4g} {_unit_label(unit)})" if unit != 1.0 else "")
    if short > NAN_SHARE:
        fin = dm[np.isfinite(dm)]
        advice = ""
        if len(fin):
            ok = _round_up(float(np.quantile(fin, COVERED)) * unit * 1.01)
            advice = f"; a radius of {ok:g} m (-r {ok:g}) gives {m} or more to {100 * COVERED:.0f} % of the points"
        below = "below" if r_m < spacing else "too small for"
        return [text + f": the radius {where} holds fewer than {m} points (the point itself included) around "
                f"{100 * short:.0f} % of the points — it is {below} the point spacing "
                f"({spacing:.3g} m, the median distance to the nearest point){advice}"]
    if flat:  # level ground: aspect is undefined there, as documented
        return []
    return [text + f"; not for want of neighbours ({100 * (1 - short):.0f} % of the points have {m} or more "
            f"within {where}): see 'NaN when' in docs/features.md §3"]


def _unit_label(unit: float) -> str:
    from ..crs import unit_name

    return unit_name(unit)


def warn(messages: Sequence[str], stacklevel: int = 3) -> None:
    """Issue each message as a :class:`~lidarfx.errors.LidarfxWarning` (the CLI prints one line)."""
    for msg in messages:
        warnings.warn(msg, LidarfxWarning, stacklevel=stacklevel)
