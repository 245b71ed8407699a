"""CPU and memory of ``gyroarray diagnose`` on a long record with a hidden filter on every gyro.

Target: <= 30 s of CPU and <= 1 GB peak RSS for ``gyroarray diagnose REC --json``, a fresh
process (imports, reading, calibration, every candidate's test, the ranking of rivals, the
Monte-Carlo band, the localisation), on a 46-min, 5-gyro, 100 Hz record
(:func:`gyroarray.sim.lab.lab_run`, ``protocol="table"``: 1200 s static, 900 s of steps and
swings, 660 s static; S1 N = 5, ARW 0.15 deg/√h, RRW 3 deg/h/√h, Earth rate at 34.25°, a
warming room) with ``bandwidth`` (8 Hz, order 2) on every gyro: the record whose rivals
(latency, the faults, g-sensitivity) were each tested again on every other fit's cut record,
288 s of CPU and 2.6 GB before.

CPU is the child's user + system time and the peak its ``ru_maxrss`` (``os.wait4``), not the
wall clock: the benchmark machine is shared. The reference in the same run, a fresh process
too: what a user would script by hand for a first look, pandas.read_csv of the same file and
allantools' overlapping ADEV of each gyro at octave τ; the ratio says how many such first looks
a diagnosis costs.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from gyroarray.core.layout import Layout
from gyroarray.core.measurement import write_measurement
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.sim.lab import lab_run

CPU_TARGET_S = 30.0
RSS_TARGET_MB = 1024.0

MODEL = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 3.0}),
                    ModelEntry("earth_rate", None, {"latitude_deg": 34.25}),
                    ModelEntry("bandwidth", None, {"cutoff_hz": 8.0, "order": 2})))
LAYOUT = Layout.conical(1, 5, math.radians(54.7356))
KW = dict(rate_hz=100.0, static_s=1200.0, motion_s=900.0, tail_s=660.0, protocol="table")
WARM_KW = dict(KW, static_s=300.0, motion_s=300.0, tail_s=60.0)

_BY_HAND = """
import sys, pandas as pd, allantools
df = pd.read_csv(sys.argv[1], comment="#")
for c in [c for c in df.columns if c.startswith("gyro")]:
    allantools.oadev(df[c].to_numpy(), rate=100.0, data_type="freq", taus="octave")
"""


def child_usage(argv: list[str]) -> tuple[float, float]:
    """(CPU seconds, peak RSS MB) of one child process run to its end (its own rusage)."""
    p = subprocess.Popen(argv, stdout=subprocess.DEVNULL)
    _, status, ru = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise RuntimeError(f"{argv} exited with {p.returncode}")
    return ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0          # Linux: ru_maxrss in KiB


def main() -> dict:
    m = lab_run(MODEL, LAYOUT, np.random.default_rng(5), **KW)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "diag5_bandwidth.csv.gz"
        write_measurement(m, path)
        warm = Path(tmp) / "warm.csv.gz"            # a short record: the numba caches on disk, warm
        write_measurement(lab_run(MODEL, LAYOUT, np.random.default_rng(6), **WARM_KW), warm)
        diagnose = [sys.executable, "-m", "gyroarray.cli.main", "diagnose"]
        child_usage(diagnose + [str(warm), "--json"])
        env_cmd = diagnose + [str(path), "--json"]
        cpu_ref, rss_ref = child_usage([sys.executable, "-c", _BY_HAND, str(path)])
        cpu, rss = child_usage(env_cmd)
    ok_cpu, ok_rss = cpu <= CPU_TARGET_S, rss <= RSS_TARGET_MB
    print(f"{'job':<44} {'CPU s':>7} {'target':>7} {'peak MB':>8} {'target':>7} {'x by hand':>10}")
    print(f"{'diagnose 46 min x 5 gyros x 100 Hz, bandwidth':<44} {cpu:7.1f} {CPU_TARGET_S:7.0f} "
          f"{rss:8.0f} {RSS_TARGET_MB:7.0f} {cpu / cpu_ref:10.1f}  "
          f"{'ok' if ok_cpu and ok_rss else 'SLOW' if not ok_cpu else 'BIG'}")
    print(f"by hand (pandas.read_csv + allantools oadev, 5 gyros): {cpu_ref:.1f} s CPU, {rss_ref:.0f} MB")
    return {"diagnose_cpu_s": cpu, "diagnose_peak_mb": rss, "by_hand_cpu_s": cpu_ref,
            "by_hand_peak_mb": rss_ref, "ratio_cpu": cpu / cpu_ref, "cpu_ok": ok_cpu, "rss_ok": ok_rss}


if __name__ == "__main__":
    main()
