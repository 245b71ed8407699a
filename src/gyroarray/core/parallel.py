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

__all__ = ["available_cpus", "map_runs", "MAX_WORKERS_PER_CPU", "WORKER_BASELINE_BYTES",
           "DASK_WORKER_EXTRA_BYTES", "max_workers", "check_worker_count", "check_workers_memory"]

#: Most worker processes per CPU this process may run on [-]. A scenario runs on one core (one
#: BLAS/numba thread per worker), so workers past the cores only wait for one while each holds
#: its memory (:data:`WORKER_BASELINE_BYTES`); up to 4 per CPU still lets a sweep overlap its
#: workers' start-up and file writing with the others' computing on a machine whose cores are
#: shared or hyper-threaded (2 cores: 8 workers), and anything beyond is only memory and start-up.
MAX_WORKERS_PER_CPU = 4
#: What one sweep worker process holds before its scenario's own arrays [bytes]: measured here
#: (Linux, CPython 3, numba and mujoco) as the peak RSS of a spawned worker after its imports and
#: its first scenario's JIT compilation: 259 MiB warm, 325-330 MiB after a first 90 s x 4-gyro
#: scenario (whose arrays are 10 MiB); a 600 s x 8-gyro scenario then peaks at 401 MiB (its
#: arrays: 78 MiB, :func:`gyroarray.sim.scenario.memory_needed`).
WORKER_BASELINE_BYTES = 320 * 2**20
#: What a Dask worker holds beyond that (dask.distributed's own modules and threads) [bytes]:
#: measured 19 MiB more than a process-pool worker.
DASK_WORKER_EXTRA_BYTES = 24 * 2**20

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


def max_workers() -> int:
    """Most worker processes a command starts on this machine: :data:`MAX_WORKERS_PER_CPU` x
    :func:`available_cpus`."""
    return MAX_WORKERS_PER_CPU * available_cpus()


def check_worker_count(n: int, option: str, form: str = "{n}") -> None:
    """Refuse ``n`` worker processes beyond :func:`max_workers`, before any work.

    ``option`` names the option (``--workers``, ``--dask``) and ``form`` how its value is written
    (``local:{n}``), for the message.

    Raises
    ------
    InputError
        ``--dask local:1024: 1024 worker processes on 2 CPUs ...: give 1 to 8``.
    """
    from gyroarray.core.errors import InputError  # deferred: a light module for compare's threads
    cap, cpus = max_workers(), available_cpus()
    if int(n) > cap:
        raise InputError(f"{option} {form.format(n=n)}: {n} worker processes on {cpus} CPU(s) are more "
                         f"than {MAX_WORKERS_PER_CPU} per CPU (each scenario runs on one core, so the "
                         f"others only wait for one, each holding about "
                         f"{WORKER_BASELINE_BYTES // 2**20} MiB): give {option} "
                         f"{form.format(n=1)} to {form.format(n=cap)}")


def check_workers_memory(n: int, work_bytes: float, option: str, form: str = "{n}", *,
                         baseline_bytes: float = WORKER_BASELINE_BYTES,
                         asked: int | None = None) -> int:
    """Refuse ``n`` worker processes whose memory passes the budget
    (:func:`gyroarray.core.limits.max_memory`), before any work; returns the budget's share of
    one worker [bytes] (the budget / ``n``: a Dask worker's ``memory_limit``).

    Each worker is estimated at ``baseline_bytes`` (an idle worker with its imports,
    :data:`WORKER_BASELINE_BYTES`) plus ``work_bytes`` (the working memory of the largest
    scenario it may run). ``asked``: the count the user gave, when fewer start (one per
    scenario left to run).

    Raises
    ------
    InputError
        ``--dask local:12 needs about 4.22 GiB for 12 workers (360 MiB each ...); the memory
        budget is 1 GiB: use at most 2 workers (--dask local:2), or raise --max-memory``.
    """
    from gyroarray.core.errors import InputError  # deferred: as in check_worker_count
    from gyroarray.core.limits import format_size, max_memory  # deferred: as above
    budget = max_memory()
    each = float(baseline_bytes) + max(float(work_bytes), 0.0)
    n = int(n)
    if n * each <= budget:
        return int(budget // n)
    fit = int(budget // each)
    given = n if asked is None else int(asked)
    head = (f"{option} {form.format(n=given)} needs about {format_size(n * each)} for {n} worker(s)"
            + ("" if given == n else " (one per scenario to run)")
            + f" ({format_size(each)} each: {format_size(baseline_bytes)} a worker process with its "
            f"imports, {format_size(work_bytes)} its largest scenario); the memory budget is "
            f"{format_size(budget)} (--max-memory)")
    if fit >= 1:
        raise InputError(f"{head}: use at most {fit} worker(s) ({option} {form.format(n=fit)}), or "
                         f"raise --max-memory to at least {format_size(n * each)}")
    raise InputError(f"{head}: not even one worker fits; raise --max-memory to at least "
                     f"{format_size(each)}, or shorten the largest scenarios")
