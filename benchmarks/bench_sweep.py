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
numba cache), the truth tasks, scheduling and the tail. ``core`` is the CPU time
the scenarios' threads got over their run time: below 1 when a worker waited for
a core (the machine shared with other work, or Dask's own threads). The runner's
profile (``run_sweep(...)["profile"]``) splits each wall time into phases.

A shared host also changes speed from minute to minute (here the same four
scenarios took 3.2 to 4.3 s of CPU time in one process, runs a minute apart), so
runs done minutes apart differ by ±15 % whatever the backend. ``cpu/wall`` — the
scenarios' CPU time per second of wall time, i.e. cores' worth of scenario work
done per second — moves with the host's speed in both runs, and the ratio of
the N-worker run's to the one-worker run's (``drift-free``) is the speed-up
with that drift taken out. It hides what makes each scenario's CPU time longer
when N run at once (shared caches, memory bandwidth), which the raw speed-up
keeps; both are printed, with the rounds' medians (``--repeat``).

Two CPU-bound processes do not always get two cores on a shared (virtual)
machine: before each timed run, ``capacity`` measures what N processes that only
compute get together, in cores (N on a quiet machine). A speed-up is bounded by
it; both are printed, so a run on a busy host reads as such.

Usage: ``python benchmarks/bench_sweep.py [--workers N] [--replicates R] [--no-dask]
[--repeat R] [--sweep FILE]`` (``make bench`` runs it with N = the CPUs available, at least 2).
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
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


_SPIN = ("import time\nt = time.perf_counter() + {s}\nx = 0\n"
         "while time.perf_counter() < t:\n    x += 1\nprint(time.process_time())")


def capacity(n: int, seconds: float = 2.0) -> float:
    """The cores ``n`` CPU-bound processes get together on this machine now: each spins
    ``seconds``; their CPU times summed / ``seconds`` (``n`` on a quiet machine with ``n``
    cores)."""
    procs = [subprocess.Popen([sys.executable, "-c", _SPIN.format(s=seconds)],
                              stdout=subprocess.PIPE, text=True) for _ in range(n)]
    cpu = [float(p.communicate()[0].split()[-1]) for p in procs]
    return sum(cpu) / seconds


def _run(tmp: Path, sweep, tag: str, **kw) -> dict:
    out = tmp / tag
    n = kw.get("workers") or int(str(kw.get("dask", "local:1")).split(":")[1])
    cap = capacity(n)
    t0 = time.perf_counter()
    summary = run_sweep(sweep, out, progress=False, **kw)
    wall = time.perf_counter() - t0
    prof = summary["profile"]
    return {"wall_s": wall, "workers": n, "failed": len(summary["failed"]),
            "busy": summary["worker_seconds"] / (wall * n), "out": out, "capacity": cap,
            "core": prof["cpu_s"] / prof["busy_s"] if prof["busy_s"] else float("nan"),
            "cpu_per_wall": prof["cpu_s"] / wall,
            "profile": prof}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--workers", type=int, default=max(2, available_cpus()),
                    help="N: the workers of the parallel runs (default: the CPUs available, >= 2)")
    ap.add_argument("--replicates", type=int, default=None,
                    help="run every scenario R times (design_quick x 10 = 480 scenarios)")
    ap.add_argument("--sweep", type=Path, default=SWEEP, help="another sweep file")
    ap.add_argument("--no-dask", action="store_true", help="local processes only")
    ap.add_argument("--repeat", type=int, default=1,
                    help="R rounds of every run (each round in another order); medians reported")
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
        configs = [(("processes", 1), {"workers": 1}), (("processes", n), {"workers": n})]
        if not args.no_dask:
            try:
                t0 = time.perf_counter()
                with local_cluster(n):
                    started = time.perf_counter() - t0
                print(f"  a LocalCluster of {n} workers starts and closes in {started:.1f} s")
                results["dask_cluster_start_close_s"] = started
                configs += [(("dask local", 1), {"dask": "local:1"}),
                            (("dask local", n), {"dask": f"local:{n}"})]
            except Exception as err:                   # noqa: BLE001 - dask missing or no cluster
                print(f"  dask: skipped ({err})")
                results["dask_skipped"] = str(err)
        # R rounds, each in another order (a drift of the host's load spreads over all)
        runs: dict = {key: [] for key, _ in configs}
        for rnd in range(args.repeat):
            for key, kw in configs[rnd % len(configs):] + configs[:rnd % len(configs)]:
                r = _run(tmp, sweep, f"{key[0][0]}{key[1]}_{rnd}", **kw)
                r["identical"] = _same(load_results(r["out"]), ref)
                shutil.rmtree(r.pop("out"), ignore_errors=True)
                runs[key].append(r)
        med = {key: float(np.median([r["wall_s"] for r in rs])) for key, rs in runs.items()}
        rate = {key: float(np.median([r["cpu_per_wall"] for r in rs])) for key, rs in runs.items()}
        base = med[("processes", 1)]
        print(f"  {'backend':<12} {'workers':>7} {'wall [s]':>9} {'vs proc 1':>10} "
              f"{'vs own 1':>9} {'drift-free':>10} {'busy':>6} {'core':>5} {'capacity':>9}  identical"
              + (f"   (medians of {args.repeat} rounds)" if args.repeat > 1 else ""))
        table = []
        for (backend, k), rs in runs.items():
            wall = med[(backend, k)]
            own = med[(backend, 1)] / wall
            busy, core, cap = (float(np.median([r[f] for r in rs]))
                               for f in ("busy", "core", "capacity"))
            same = all(r["identical"] for r in rs)
            free = rate[(backend, k)] / rate[("processes", 1)]
            table.append({"backend": backend, "workers": k, "wall_s": round(wall, 2),
                          "walls_s": [round(r["wall_s"], 2) for r in rs],
                          "speedup_vs_processes_1": round(base / wall, 3),
                          "speedup_vs_own_1": round(own, 3),
                          "speedup_drift_free_vs_processes_1": round(free, 3),
                          "cpu_per_wall": [round(r["cpu_per_wall"], 3) for r in rs],
                          "busy": round(busy, 3),
                          "core": round(core, 3), "capacity_cores": round(cap, 2),
                          "identical": same, "failed_scenarios": rs[0]["failed"],
                          "profiles": [r["profile"] for r in rs]})
            print(f"  {backend:<12} {k:>7} {wall:>9.1f} {base / wall:>9.2f}x "
                  f"{own:>8.2f}x {free:>9.2f}x {busy:>6.2f} {core:>5.2f} {cap:>9.2f}  {same}")
        if args.repeat > 1:
            for (backend, k), rs in runs.items():
                print(f"  {backend:<12} {k:>7}  rounds' walls [s]: "
                      + ", ".join(f"{r['wall_s']:.1f}" for r in rs) + "; cpu/wall: "
                      + ", ".join(f"{r['cpu_per_wall']:.2f}" for r in rs))
        print("  where the time went [s] (phases of the runner's profile, last round; tail: a "
              "worker idle at the end)")
        for (backend, k), rs in runs.items():
            prof = rs[-1]["profile"]
            phases = ", ".join(f"{name} {v:.2f}" for name, v in prof["phases_s"].items())
            print(f"  {backend:<12} {k:>7}  {phases}; tail {prof['tail_s']:.2f}")
        results["runs"] = table
        if n == 2:
            print(f"  target at 2 workers: >= {TARGET}x for both backends")
        failed = {r["failed"] for rs in runs.values() for r in rs}
        if failed != {0}:
            print(f"  note: scenarios failed (the same in every run): {sorted(failed)}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return results


if __name__ == "__main__":
    main(sys.argv[1:])
