"""Run a serial numba kernel over index ranges on a pool of threads.

lidarfx's kernels are compiled ``nogil=True`` without ``parallel=True`` and take the range
``[lo, hi)`` of the items they process; :func:`run` splits ``[0, n)`` into blocks and calls the
kernel for the blocks on a thread pool (dynamic scheduling: a thread takes the next block when it
is done).  Compared with numba's ``parallel=True`` this

* compiles a large kernel about three times faster (numba's parfor passes and the generated
  gufunc were most of it: the feature engine compiled in 26 s instead of 74 s on a busy 2-core
  machine), which is what a first run without the shipped kernels pays (docs/kernels.md);
* lets any kernel call any other one (a cached kernel that calls a ``parallel=True`` one
  segfaults when it is loaded from numba's disk cache, numba issue #8578);
* runs the same machine code per item, so the cached kernels are as fast as before.

The number of threads is numba's (``NUMBA_NUM_THREADS``, :func:`numba.set_num_threads` in the
calling thread), so the tiling engine's per-worker thread count applies here too.  One kernel,
the kNN search (``neighbors._knn_kernel``), keeps numba's ``parallel=True``: as a ``nogil`` kernel
its loop ran three times slower per query (measured 2026-12-03, 50 000 queries, one thread).
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable

import numba

_pools: dict[int, ThreadPoolExecutor] = {}
_lock = threading.Lock()


def threads() -> int:
    """Threads a parallel run uses: numba's setting for the calling thread."""
    return max(1, int(numba.get_num_threads()))


def _pool(n: int) -> ThreadPoolExecutor:
    with _lock:
        pool = _pools.get(n)
        if pool is None:
            pool = _pools[n] = ThreadPoolExecutor(max_workers=n, thread_name_prefix="lidarfx")
        return pool


def blocks(n: int, grain: int, nthreads: int) -> list[tuple[int, int]]:
    """``[0, n)`` cut into blocks of at least ``grain`` items, about eight per thread (so a slow
    block does not hold the others up), in order."""
    n = int(n)
    if n <= 0:
        return []
    size = max(int(grain), -(-n // (8 * nthreads)), 1)
    return [(a, min(n, a + size)) for a in range(0, n, size)]


def run(kernel: Callable[..., Any], n: int, *args: Any, grain: int = 256, start: int = 0) -> None:
    """Call ``kernel(lo, hi, *args)`` for blocks covering ``[start, start + n)``, in parallel when
    there is more than one block and more than one thread.  The kernel must release the GIL
    (``nogil=True``) and write only its own items' results; the first exception is raised."""
    nt = threads()
    parts = [(start + a, start + b) for a, b in blocks(n, grain, nt)]
    if len(parts) <= 1 or nt == 1:
        for a, b in parts:
            kernel(a, b, *args)
        return
    futures = [_pool(nt).submit(kernel, a, b, *args) for a, b in parts]
    for f in futures:
        f.result()
