"""Lang's height-difference histogram features (docs/features.md §3.7).

dh = z_p − z_j over the vertical cylinder around p, scaled to [−1, 1] by
max |dh| and binned into ``nbins`` equal bins (the engine does the binning in
its second walk).  From the histogram:

* ``dh_peaks``: number of local maxima — a bin strictly greater than both
  neighbours; an edge bin compares with its one neighbour;
* ``dh_peak_distance``: mean distance between consecutive peak positions in
  bin units (0 with fewer than two peaks);
* ``dh_share_above`` / ``dh_share_below``: share of neighbours above / below p;
* ``dh_entropy``: −Σ p_b ln p_b of the normalised histogram;
* ``dh_max_bin``: centre of the highest bin in scaled units [−1, 1] (first on ties).

``dh_std`` (metres) and ``dh_skewness`` come from the moments of pass 1.
"""
from __future__ import annotations

import math

import numba as nb

from . import slots as S


@nb.njit(cache=True)
def histogram_features(hist, n, n_above, n_below, col, out):
    nb_ = hist.shape[0]
    peaks = 0
    first = -1
    last = -1
    best = 0
    ent = 0.0
    for b in range(nb_):
        h = hist[b]
        left_ok = b == 0 or h > hist[b - 1]
        right_ok = b == nb_ - 1 or h > hist[b + 1]
        if left_ok and right_ok and h > 0.0:
            peaks += 1
            if first < 0:
                first = b
            last = b
        if h > hist[best]:
            best = b
        if h > 0.0:
            p = h / n
            ent -= p * math.log(p)
    S.put(out, col, S.DH_PEAKS, peaks)
    # mean gap between consecutive peaks = (last - first) / (peaks - 1)
    S.put(out, col, S.DH_PEAK_DISTANCE, (last - first) / (peaks - 1) if peaks >= 2 else 0.0)
    S.put(out, col, S.DH_SHARE_ABOVE, n_above / n)
    S.put(out, col, S.DH_SHARE_BELOW, n_below / n)
    S.put(out, col, S.DH_ENTROPY, ent)
    S.put(out, col, S.DH_MAX_BIN, -1.0 + (best + 0.5) * 2.0 / nb_)
