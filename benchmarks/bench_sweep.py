"""Parallel speed-up of the sweep runner (:func:`gyroarray.sweep.runner.run_sweep`).

The 48-scenario quick design sweep (``scenarios/sweeps/design_quick.toml``:
both schemes, N = 4, 5, 6, 8 at the optimal α, ρ ∈ {−0.1, 0, 0.5}, static and
swing, 90 s at 100 Hz, every estimator incl. the bound) run into a fresh folder with
1 and with 2 local worker processes, then (``GYROARRAY_BENCH_DASK=0`` skips
it) on a ``dask.distributed`` LocalCluster with 1 and with 2 workers. The
rate-table truth is cached before timing (one warm-up run), so the timings
are the simulation + estimators + metrics + Parquet writing. Target: a
speed-up ≥ 1.8× from 1 to 2 workers (on a machine with ≥ 2 free cores);
every run's dataset must be bit-identical to the 1-worker one.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
from _timing import best_of

from gyroarray.sweep.runner import THREAD_ENV, load_results, run_sweep
from gyroarray.sweep.sweep import load_sweep

SWEEP = Path(__file__).resolve().parents[1] / "src" / "gyroarray" / "data" / "scenarios" / "sweeps" / "design_quick.toml"
TARGET = 1.8
REPEATS = 1          # each run is ~1-2 min; one is enough for a ratio


def _timed(tmp: Path, tag: str, **kw) -> tuple[float, object]:
    counter = iter(range(10**6))

    def once():
        out = tmp / f"{tag}-{next(counter)}"
        summary = run_sweep(SWEEP_OBJ, out, progress=False, **kw)
        FAILED[tag] = len(summary["failed"])
        return out

    return best_of(once, REPEATS)


def _same(a, b) -> bool:
    try:
        import pandas as pd
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    except AssertionError:
        return False
    return all(np.array_equal(a[c].to_numpy().view(np.uint64), b[c].to_numpy().view(np.uint64))
               for c in a.columns if a[c].dtype == np.float64)


SWEEP_OBJ = None
FAILED: dict = {}


def main() -> dict:
    global SWEEP_OBJ
    SWEEP_OBJ = load_sweep(SWEEP)
    n = len(SWEEP_OBJ)
    print(f"run_sweep: {SWEEP.name}, {n} scenarios, {os.cpu_count()} CPUs, "
          f"workers with {THREAD_ENV}")
    tmp = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    results: dict = {"scenarios": n}
    try:
        run_sweep(SWEEP_OBJ, tmp / "warmup", workers=2, progress=False)   # fills the truth cache
        ref = load_results(tmp / "warmup")
        t1, out1 = _timed(tmp, "local1", workers=1)
        t2, out2 = _timed(tmp, "local2", workers=2)
        same = _same(load_results(out1), ref) and _same(load_results(out2), ref)
        results["local"] = {"1_worker_s": t1, "2_workers_s": t2, "speedup": t1 / t2,
                            "identical": same, "failed_scenarios": FAILED["local1"]}
        if FAILED["local1"]:
            print(f"  note: {FAILED['local1']} of {n} scenarios failed (the same ones in every "
                  "run; see the runner's summary['failed'])")
        print(f"  local  1 worker  {t1:7.1f} s   ({t1 / n:.2f} s/scenario)")
        print(f"  local  2 workers {t2:7.1f} s   speed-up {t1 / t2:.2f}x (target >= {TARGET}x)"
              f"   datasets identical: {same}")
        if os.environ.get("GYROARRAY_BENCH_DASK", "1") != "0":
            results["dask"] = _dask(tmp, ref, n)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return results


def _dask(tmp: Path, ref, n: int) -> dict:
    try:
        import dask
        from distributed import LocalCluster
    except ImportError as err:
        print(f"  dask: skipped ({err})")
        return {"skipped": str(err)}
    times = {}
    for k in (1, 2):
        with dask.config.set({"distributed.nanny.pre-spawn-environ": THREAD_ENV}), \
                LocalCluster(n_workers=k, threads_per_worker=1, processes=True,
                             dashboard_address=None, silence_logs=40) as cluster:
            times[k], out = _timed(tmp, f"dask{k}", scheduler=cluster.scheduler_address)
            same = _same(load_results(out), ref)
        print(f"  dask   {k} worker{'s' if k > 1 else ' '} {times[k]:7.1f} s   identical: {same}")
    print(f"  dask   speed-up {times[1] / times[2]:.2f}x")
    return {"1_worker_s": times[1], "2_workers_s": times[2], "speedup": times[1] / times[2]}


if __name__ == "__main__":
    main()
