"""The default parameters of the ground filter (one set for all terrain types)."""
from __future__ import annotations

DEFAULTS: dict[str, float] = {
    "cell": 1.5,
    "slope": 0.2,
    "window": 21.0,
    "threshold": 0.4,
    "scalar": 1.5,
    "edge_step": 1.0,
    "edge_share": 0.15,
}
"""The one default parameter set (tuned on the 8 ISPRS samples, see docs/ground.md).

``cell``      grid cell of the minimum surface (m)
``slope``     slope (rise/run) of the progressive opening's elevation threshold
``window``    largest opening radius (m)
``threshold`` final elevation threshold (m)
``scalar``    final threshold added per unit of DTM slope (m per rise/run)
``edge_step`` height drop (m) that counts as a step on an object region's boundary
``edge_share`` share of the boundary that must be steps for a region to stay an
              object (0 switches the step check off: plain SMRF)
"""
