"""Cross-validation folds: random, spatial blocks, buffers around the held-out part.

Random folds put neighbouring points into different folds (optimistic); spatial-block
folds hold whole square blocks out; the buffers leave the training points near a
held-out block (or file) out of that fold's training.  See docs/classification.md §5.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import LidarfxError

if TYPE_CHECKING:  # annotations only
    from .model import TrainConfig

__all__ = ["random_folds", "block_folds", "block_ids", "block_buffer_mask", "file_buffer_mask", "default_buffer",
           "fold_parts", "check_block_size", "MIN_BLOCK_SIZE"]

MIN_BLOCK_SIZE = 0.01
"""Smallest spatial block (m): smaller ones hold a point each, and their ids overflow on large extents."""


def check_block_size(block_size: Any) -> None:
    """Refuse a block size that is not a number of metres from :data:`MIN_BLOCK_SIZE` on."""
    ok = isinstance(block_size, (int, float, np.integer, np.floating)) and not isinstance(block_size, bool)
    if not (ok and MIN_BLOCK_SIZE <= block_size < math.inf):
        raise LidarfxError(f"block size must be a number of metres from {MIN_BLOCK_SIZE:g} on, got {block_size!r}")


def random_folds(n: int, n_folds: int, seed: int = 0, y: np.ndarray | None = None) -> np.ndarray:
    """Fold id (0..n_folds−1) of every point: random, stratified by ``y`` when given."""
    from sklearn.model_selection import KFold, StratifiedKFold

    if n_folds < 2:
        raise LidarfxError("cross-validation needs at least 2 folds")
    if n < n_folds:
        raise LidarfxError(f"{n} points cannot make {n_folds} folds")
    folds = np.empty(n, dtype=np.int64)
    if y is not None:
        y = np.asarray(y)
        _, counts = np.unique(y, return_counts=True)
        if counts.min() >= n_folds:
            split = StratifiedKFold(n_folds, shuffle=True, random_state=seed).split(np.zeros(n), y)
        else:
            split = KFold(n_folds, shuffle=True, random_state=seed).split(np.zeros(n))
    else:
        split = KFold(n_folds, shuffle=True, random_state=seed).split(np.zeros(n))
    for f, (_, te) in enumerate(split):
        folds[te] = f
    return folds


def block_folds(xy: np.ndarray, n_folds: int, block_size: float, seed: int = 0,
                groups: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Spatial-block folds: ``(fold, block)`` ids per point.

    The plane is cut into square blocks of ``block_size`` (aligned to multiples
    of it, so neighbouring tiles share the grid; ``groups`` — e.g. a file id —
    keeps blocks of different files apart).  Whole blocks go to folds: shuffled
    with ``seed``, each block joins the fold holding the fewest points so far.
    No block is ever split between folds.
    """
    if n_folds < 2:
        raise LidarfxError("cross-validation needs at least 2 folds")
    block = block_ids(xy, block_size, groups)
    counts = np.bincount(block)
    nb = len(counts)
    if nb < n_folds:
        raise LidarfxError(f"only {nb} spatial block(s) of {block_size:g} m for {n_folds} folds; "
                           "use smaller blocks or fewer folds")
    order = np.random.default_rng(seed).permutation(nb)
    load = np.zeros(n_folds, np.int64)
    fold_of_block = np.empty(nb, np.int64)
    for b in order:
        f = int(np.argmin(load))
        fold_of_block[b] = f
        load[f] += counts[b]
    return fold_of_block[block], block


def block_ids(xy: np.ndarray, block_size: float, groups: np.ndarray | None = None) -> np.ndarray:
    """Id (0..B−1) of the square block of ``block_size`` m each point lies in; the grid is
    aligned to multiples of the size, and ``groups`` (e.g. a file id) keeps blocks apart."""
    xy = np.asarray(xy, dtype=np.float64)
    check_block_size(block_size)
    bx = np.floor(xy[:, 0] / block_size).astype(np.int64)
    by = np.floor(xy[:, 1] / block_size).astype(np.int64)
    g = np.zeros(len(xy), np.int64) if groups is None else np.asarray(groups, dtype=np.int64)
    _, block = np.unique(np.stack([g, bx, by], axis=1), axis=0, return_inverse=True)
    return block.ravel()


def block_buffer_mask(xy: np.ndarray, folds: np.ndarray, block_size: float, buffer: float,
                      groups: np.ndarray | None = None) -> np.ndarray:
    """Points near another fold's blocks: ``near[f, i]`` is True when point ``i`` lies within
    ``buffer`` m (plan distance) of a block of :func:`block_folds` that belongs to fold ``f``
    and not to the point's own fold.  Cross-validation leaves such points out of fold ``f``'s
    training part (a buffered spatial-block CV), so that no training point lies within
    ``buffer`` of the held-out area.  The distance is to the block's square, not to its
    points; ``groups`` (file ids) as in :func:`block_folds`."""
    xy = np.asarray(xy, dtype=np.float64)
    folds = np.asarray(folds, dtype=np.int64)
    n_folds = int(folds.max()) + 1 if len(folds) else 0
    near = np.zeros((n_folds, len(xy)), dtype=bool)
    if not (buffer > 0) or not len(xy):
        return near
    if not math.isfinite(buffer):
        raise LidarfxError(f"buffer must be a finite number of metres, got {buffer!r}")
    s = float(block_size)
    bx = np.floor(xy[:, 0] / s).astype(np.int64)
    by = np.floor(xy[:, 1] / s).astype(np.int64)
    ox, oy = xy[:, 0] - bx * s, xy[:, 1] - by * s  # offsets inside the own block, 0..s
    g = np.zeros(len(xy), np.int64) if groups is None else np.asarray(groups, dtype=np.int64)
    # blocks further away than the data's span in blocks do not exist (a huge buffer: no huge loop)
    reach = min(math.ceil(buffer / s), int(max(np.ptp(bx), np.ptp(by))) + 1)
    bx, by = bx - bx.min() + reach, by - by.min() + reach
    w, h = int(bx.max()) + reach + 1, int(by.max()) + reach + 1
    key = (g * w + bx) * h + by
    ukey, first = np.unique(key, return_index=True)
    ufold = folds[first]  # a block lies in one fold (block_folds never splits one)
    for dx in range(-reach, reach + 1):
        gx = 0.0 if dx == 0 else ((dx - 1) * s + (s - ox) if dx > 0 else (-dx - 1) * s + ox)
        for dy in range(-reach, reach + 1):
            if dx == 0 and dy == 0:
                continue
            gy = 0.0 if dy == 0 else ((dy - 1) * s + (s - oy) if dy > 0 else (-dy - 1) * s + oy)
            idx = np.flatnonzero(np.hypot(gx, gy) < buffer)
            if not len(idx):
                continue
            k2 = (g[idx] * w + bx[idx] + dx) * h + by[idx] + dy
            pos = np.minimum(np.searchsorted(ukey, k2), len(ukey) - 1)
            hit = ukey[pos] == k2
            f2, i2 = ufold[pos[hit]], idx[hit]
            other = f2 != folds[i2]
            near[f2[other], i2[other]] = True
    return near


def file_buffer_mask(xy: np.ndarray, files: np.ndarray, buffer: float) -> np.ndarray:
    """Points near another file: ``near[f, i]`` is True when point ``i`` of another file lies
    within ``buffer`` m (plan distance) of a point of file ``f``.  Leave-one-file-out leaves
    them out of the training when file ``f`` is held out: tiles of one survey are usually
    contiguous, and the points along a shared edge are neighbours."""
    from scipy.spatial import cKDTree

    xy = np.asarray(xy, dtype=np.float64)
    files = np.asarray(files, dtype=np.int64)
    n_files = int(files.max()) + 1 if len(files) else 0
    near = np.zeros((n_files, len(xy)), dtype=bool)
    if not (buffer > 0) or n_files < 2:
        return near
    if not math.isfinite(buffer):
        raise LidarfxError(f"buffer must be a finite number of metres, got {buffer!r}")
    for f in range(n_files):
        mine = files == f
        if not mine.any():
            continue
        others = np.flatnonzero(~mine)
        d, _ = cKDTree(xy[mine]).query(xy[others], distance_upper_bound=buffer)
        near[f, others[d < buffer]] = True
    return near


def default_buffer(config: "TrainConfig") -> float:
    """The default buffer of the spatial-block CV and leave-one-file-out: twice the largest
    radius (no training point's neighbourhood then holds a point of a held-out point's),
    0 for k-NN."""
    if config.neighbourhood == "knn" or not config.radii:
        return 0.0
    return 2.0 * max(config.radii)


def fold_parts(folds: np.ndarray, y: np.ndarray, f: int, exclude: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Training and held-out indices of fold ``f`` (labelled points only); ``exclude``
    (:func:`block_buffer_mask`, :func:`file_buffer_mask`) removes the points near the held-out
    part from the training part."""
    train = (folds != f) & (y >= 0)
    if exclude is not None:
        train &= ~exclude[f]
    return np.flatnonzero(train), np.flatnonzero((folds == f) & (y >= 0))
