"""Independent Monte-Carlo runs on the machine's cores (threads).

Each run draws from its own ``numpy.random.Generator`` seeded by the run's
index, so the results are the same bits whatever the number of workers; the
runs come back in index order. Threads, not processes: a run's time is spent
in numpy, scipy and numba code that releases the GIL (random fills, FFTs,
array arithmetic, the Allan kernels), the run function may be a closure over
the caller's arrays, and a fork would be unsafe once numba's OpenMP
threading layer is loaded.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, TypeVar

__all__ = ["available_cpus", "map_runs"]

T = TypeVar("T")


def available_cpus() -> int:
    """CPUs this process may run on."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:                      # not Linux
        return max(os.cpu_count() or 1, 1)


def map_runs(fn: Callable[[int], T], n_runs: int, workers: int) -> list[T]:
    """``[fn(0), ..., fn(n_runs − 1)]``, on up to ``workers`` threads."""
    workers = min(int(workers), int(n_runs))
    if workers <= 1:
        return [fn(k) for k in range(n_runs)]
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="gyroarray-run") as pool:
        return list(pool.map(fn, range(n_runs)))
