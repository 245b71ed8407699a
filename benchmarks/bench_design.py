"""Speed of the design search and of ``make demo``.

* The predictor's full grid (``gyroarray.design.recommend.recommend``): 2 schemes ×
  N = 4, 5, 6, 8 × 100 cone angles (refined continuously) × 5 estimators with
  their bandwidth optimised against a 5 deg/s, 0.03 Hz swing (paper 003
  noise, 600 s horizon, one failure to survive). CPU time of one process on
  one core (``OPENBLAS_NUM_THREADS=1``), after a warm-up call that imports
  and compiles. Target ≤ 2 s. The same grid at rest (bandwidth held at
  10 Hz) is shown too.
* The demo's compute: the commands of ``make demo`` after the install, run as
  the user runs them (fresh processes), wall time on this machine against
  the 90 s target (2 cores), and their CPU time.
"""

from __future__ import annotations

import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GRID_TARGET_S = 2.0
DEMO_TARGET_S = 90.0
ROOT = Path(__file__).resolve().parents[1]
GYRO = str(Path(sys.executable).with_name("gyroarray"))
#: The demo's design question (Makefile DEMO_ARGS).
DEMO_ARGS = ["--arw", "0.1", "--rrw", "600", "--rate-hz", "100", "--horizon-s", "600",
             "--swing", "5,0.03", "--n", "4,5,6,8", "--failures", "1", "--rho-range=-0.1,0.5"]


def _grid_cpu(space_kw: dict) -> tuple[float, dict]:
    from gyroarray.design.predict import Swing
    from gyroarray.design.recommend import DesignSpace, GyroNoise, recommend
    g = GyroNoise(arw_deg_rt_h=0.1, rrw_deg_h_rt_h=600.0)
    kw = dict(space_kw)
    if kw.pop("swing", False):
        kw["swing"] = Swing(math.radians(5.0), 0.03)
    recommend(g, DesignSpace(rate_hz=100.0, horizon_s=60.0))      # warm-up: imports, caches
    best, res = math.inf, None
    for _ in range(3):
        t0 = time.process_time()
        res = recommend(g, DesignSpace(**kw))
        best = min(best, time.process_time() - t0)
    return best, res


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def main() -> dict:
    out = {}
    swing_s, res = _grid_cpu({"rate_hz": 100.0, "horizon_s": 600.0, "failures": 1, "swing": True,
                              "bandwidth_hz": (0.1, 45.0)})
    rest_s, _ = _grid_cpu({"rate_hz": 100.0, "horizon_s": 600.0, "failures": 1})
    designs = len(res["designs"])
    print(f"{'grid':<44} {'CPU [s]':>8} {'target':>7}")
    print(f"{'swing: bandwidth optimised, ' + str(designs) + ' designs':<44} {swing_s:>8.3f} {GRID_TARGET_S:>7.1f}")
    print(f"{'at rest: bandwidth held at 10 Hz':<44} {rest_s:>8.3f} {GRID_TARGET_S:>7.1f}")
    out["grid_cpu_s"] = {"swing_bandwidth_optimised": swing_s, "at_rest": rest_s,
                         "target_s": GRID_TARGET_S, "designs": designs}
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
        steps = [[GYRO, "design", "--paper-tables"],
                 [GYRO, "design", "--recommend", *DEMO_ARGS, "--check", "20",
                  "--out", f"{tmp}/design.json"],
                 [GYRO, "report", "--design", f"{tmp}/design.json", "--out", f"{tmp}/report.html",
                  "--md", f"{tmp}/report.md"]]
        cpu0, t0 = _children_cpu(), time.perf_counter()
        for cmd in steps:
            subprocess.run(cmd, check=True, cwd=ROOT, env=env, stdout=subprocess.DEVNULL)
        wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    print(f"{'make demo compute (3 commands)':<44} {'wall':>8} {'CPU':>7} {'target':>7}")
    print(f"{'':<44} {wall:>8.1f} {cpu:>7.1f} {DEMO_TARGET_S:>7.0f}")
    out["demo_s"] = {"wall": wall, "cpu": cpu, "target_s": DEMO_TARGET_S}
    return out


if __name__ == "__main__":
    main()
