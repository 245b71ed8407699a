"""Sweep speed-up on the cores this machine has: local processes and a Dask LocalCluster.

The 48-scenario quick design sweep (``scenarios/sweeps/design_quick.toml``: both
schemes, N = 4, 5, 6, 8 at the optimal α, ρ ∈ {−0.1, 0, 0.5}, static and swing,
90 s at 100 Hz, every estimator incl. the bound) run into a fresh folder with 1
and with N workers, for local processes (``--workers``) and for a Dask
``LocalCluster`` of the same size (``--dask local:N``: the cluster's start and
close are inside the time, as a user meets them). One warm-up run first fills
the rate-table truth cache and numba's cache. Every run's dataset must be
bit-identical to the warm-up's. Target (issue 34): ≥ 1.8× at 2 workers for both
backends on 2 quiet cores; ≥ 10× at 16 workers on a 480-scenario sweep
(``--workers 16 --replicates 10``).

``busy`` is the share of the workers' time spent in scenarios (their measured run
times summed / (wall × N)); the rest is start-up (processes or cluster, imports,
numba cache), the truth tasks, scheduling and the tail.

Usage: ``python benchmarks/bench_sweep.py [--workers N] [--replicates R] [--no-dask]
[--sweep FILE]`` (``make bench`` runs it with N = the CPUs available, at least 2).
"""

from __future__ import annotations

import argparse
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from gyroarray.core.parallel import available_cpus
from gyroarray.sweep.runner import THREAD_ENV, load_results, local_cluster, run_sweep
from gyroarray.sweep.sweep import load_sweep

SWEEP = (Path(__file__).resolve().parents[1] / "src" / "gyroarray" / "data" / "scenarios"
         / "sweeps" / "design_quick.toml")
TARGET = 1.8


def _same(a, b) -> bool:
    """Equal datasets, floats compared by their bits."""
    try:
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    except AssertionError:
        return False
    return all(np.array_equal(a[c].to_numpy().view(np.uint64), b[c].to_numpy().view(np.uint64))
               for c in a.columns if a[c].dtype == np.float64)


def _sweep_file(tmp: Path, path: Path, replicates: int | None) -> Path:
    """The sweep file, or a copy whose every scenario runs ``replicates`` times."""
    if not replicates or replicates == 1:
        return path
    text = re.sub(r"(?m)^replicates\s*=.*$", "", path.read_text())
    copy = tmp / f"{path.stem}_x{replicates}.toml"
    head, sep, rest = text.partition("\n[")          # top-level keys come before the first table
    copy.write_text(f"{head}\nreplicates = {int(replicates)}\n{sep}{rest}")
    return copy


def _run(tmp: Path, sweep, tag: str, **kw) -> dict:
    out = tmp / tag
    t0 = time.perf_counter()
    summary = run_sweep(sweep, out, progress=False, **kw)
    wall = time.perf_counter() - t0
    n = kw.get("workers") or int(str(kw.get("dask", "local:1")).split(":")[1])
    return {"wall_s": wall, "workers": n, "failed": len(summary["failed"]),
            "busy": summary["worker_seconds"] / (wall * n), "out": out}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", type=int, default=max(2, available_cpus()),
                    help="N: the workers of the parallel runs (default: the CPUs available, >= 2)")
    ap.add_argument("--replicates", type=int, default=None,
                    help="run every scenario R times (design_quick x 10 = 480 scenarios)")
    ap.add_argument("--sweep", type=Path, default=SWEEP, help="another sweep file")
    ap.add_argument("--no-dask", action="store_true", help="local processes only")
    args = ap.parse_args([] if argv is None else argv)
    n = args.workers
    tmp = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    results: dict = {"workers": n, "cpus": available_cpus(), "thread_env": THREAD_ENV}
    try:
        sweep = load_sweep(_sweep_file(tmp, args.sweep, args.replicates))
        results["scenarios"] = len(sweep)
        print(f"run_sweep: {sweep.name}, {len(sweep)} scenarios, {available_cpus()} CPUs "
              f"available, N = {n} workers")
        t0 = time.perf_counter()
        run_sweep(sweep, tmp / "warmup", workers=n, progress=False)    # truth + numba caches
        print(f"  warm-up run ({n} processes): {time.perf_counter() - t0:.1f} s")
        ref = load_results(tmp / "warmup")
        runs = {("processes", 1): _run(tmp, sweep, "p1", workers=1),
                ("processes", n): _run(tmp, sweep, f"p{n}", workers=n)}
        if not args.no_dask:
            try:
                t0 = time.perf_counter()
                with local_cluster(n):
                    started = time.perf_counter() - t0
                print(f"  a LocalCluster of {n} workers starts and closes in {started:.1f} s")
                results["dask_cluster_start_close_s"] = started
                runs[("dask local", 1)] = _run(tmp, sweep, "d1", dask="local:1")
                runs[("dask local", n)] = _run(tmp, sweep, f"d{n}", dask=f"local:{n}")
            except Exception as err:                   # noqa: BLE001 - dask missing or no cluster
                print(f"  dask: skipped ({err})")
                results["dask_skipped"] = str(err)
        base = runs[("processes", 1)]["wall_s"]
        print(f"  {'backend':<12} {'workers':>7} {'wall [s]':>9} {'vs proc 1':>10} "
              f"{'vs own 1':>9} {'busy':>6}  identical")
        table = []
        for (backend, k), r in runs.items():
            same = _same(load_results(r["out"]), ref)
            own = runs[(backend, 1)]["wall_s"] / r["wall_s"]
            row = {"backend": backend, "workers": k, "wall_s": round(r["wall_s"], 2),
                   "speedup_vs_processes_1": round(base / r["wall_s"], 3),
                   "speedup_vs_own_1": round(own, 3), "busy": round(r["busy"], 3),
                   "identical": same, "failed_scenarios": r["failed"]}
            table.append(row)
            print(f"  {backend:<12} {k:>7} {r['wall_s']:>9.1f} {base / r['wall_s']:>9.2f}x "
                  f"{own:>8.2f}x {r['busy']:>6.2f}  {same}")
        results["runs"] = table
        if n == 2:
            print(f"  target at 2 workers: >= {TARGET}x for both backends")
        failed = {r["failed"] for r in runs.values()}
        if failed != {0}:
            print(f"  note: scenarios failed (the same in every run): {sorted(failed)}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return results


if __name__ == "__main__":
    main(sys.argv[1:])
