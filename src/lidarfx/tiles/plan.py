"""The chunk grid of a tiled run: square chunks of ``size`` metres on a grid anchored at 0, each
with a buffer; how the size and the number of workers are chosen."""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import LidarfxError

BYTES_PER_POINT = 600
"""Memory a chunk needs per point (buffer included) for the heaviest per-point command: the
cloud (xyz, attributes), the neighbour index, the features and the write buffers; measured
with ``benchmarks/bench_scale.py`` (peak resident memory / points of the largest chunk),
rounded up."""
MIN_CHUNK_POINTS = 250_000
MAX_CHUNK_POINTS = 12_000_000
MAX_CHUNKS = 1_000_000


@dataclass(frozen=True)
class Grid:
    """Chunk (i, j) owns the points with floor(x / size) == i and floor(y / size) == j
    (half-open squares: every point is owned by exactly one chunk) and reads the points within
    ``buffer`` of its square."""

    size: float
    buffer: float

    def cells(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The owning chunk of every point."""
        return np.floor(x / self.size).astype(np.int64), np.floor(y / self.size).astype(np.int64)

    def reach(self, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The first and last chunk index (along one axis) whose buffered square holds ``v``; the
        buffer is widened by a relative 1e-9 so that rounding never drops a point at its edge."""
        b = self.buffer * (1.0 + 1e-9) + 1e-9 * max(1.0, self.size)
        return np.floor((v - b) / self.size).astype(np.int64), np.floor((v + b) / self.size).astype(np.int64)

    def bounds(self, i: int, j: int) -> tuple[float, float, float, float]:
        s = self.size
        return i * s, j * s, (i + 1) * s, (j + 1) * s


def chunk_name(i: int, j: int) -> str:
    """A chunk's name in messages and file names: ``c<i>_<j>`` (indices of the grid, m for minus)."""
    return f"c{i}_{j}".replace("-", "m")


def available_memory() -> int:
    """Bytes of memory available to new work (MemAvailable; psutil elsewhere)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except Exception:  # pragma: no cover - no psutil and no /proc
        return 4 << 30


def default_workers() -> int:
    """One worker per core (each runs its chunk's kernels on cores / workers threads)."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def chunk_points_budget(workers: int, memory: int | None = None) -> int:
    """Points (buffer included) one chunk may hold: half the available memory shared by the
    workers, at :data:`BYTES_PER_POINT` each, within [MIN_CHUNK_POINTS, MAX_CHUNK_POINTS]."""
    memory = available_memory() if memory is None else memory
    n = int(0.5 * memory / max(1, workers) / BYTES_PER_POINT)
    return int(min(MAX_CHUNK_POINTS, max(MIN_CHUNK_POINTS, n)))


def default_chunk_size(points: int, mins: np.ndarray, maxs: np.ndarray, buffer: float, budget: int) -> float:
    """Chunk side (m) so that a chunk with its buffer holds about ``budget`` points at the
    inputs' mean density (points / area of their bounds), rounded down to a 1-2-5 step and at
    least 4 × the buffer (a smaller chunk reads more buffer than it owns)."""
    area = max(float((maxs[0] - mins[0]) * (maxs[1] - mins[1])), 1e-6)
    density = points / area
    side = math.sqrt(budget / max(density, 1e-12))  # buffered side
    side = max(side - 2.0 * buffer, 4.0 * buffer, 1.0)
    mag = 10.0 ** math.floor(math.log10(side))
    step = max(m * mag for m in (1.0, 2.0, 5.0) if m * mag <= side)
    return float(step)


def check_grid(size: float, buffer: float, mins: np.ndarray, maxs: np.ndarray) -> Grid:
    """A one-line error for a chunk size or buffer that is not a positive finite number, or a
    grid of more than :data:`MAX_CHUNKS` chunks over the inputs' bounds."""
    if not (math.isfinite(size) and size > 0):
        raise LidarfxError(f"--chunk-size must be a positive number of metres (0: in memory), got {size:g}")
    if not (math.isfinite(buffer) and buffer >= 0):
        raise LidarfxError(f"--buffer must be a number of metres >= 0, got {buffer:g}")
    nx = math.floor(maxs[0] / size) - math.floor(mins[0] / size) + 1
    ny = math.floor(maxs[1] / size) - math.floor(mins[1] / size) + 1
    if nx * ny > MAX_CHUNKS:
        raise LidarfxError(f"--chunk-size {size:g} makes {nx * ny:,} chunks over the inputs "
                           f"(at most {MAX_CHUNKS:,}); give a larger chunk size")
    return Grid(float(size), float(buffer))
