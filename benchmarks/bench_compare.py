"""Speed of the model-vs-measurement loop (:mod:`gyroarray.chain.compare`).

Targets (issue 6): ``diagnose`` of a 46-min, 8-gyro, 100 Hz measurement
with reference and temperature <= 20 s; ``ladder`` to consistency on one
hidden effect <= 60 s. The measurement is :func:`gyroarray.sim.lab.lab_run`
(1200 s static, 900 s of steps and swings, 660 s static, S2 N = 8 at
60.79°, ARW 0.15 deg/√h, RRW 10 deg/h/√h; the ladder's hides a 3000 ppm
scale factor on gyro 5). The reference in the same run: allantools'
overlapping ADEV of the 8 gyros at octave τ, the one step a user would
otherwise script by hand (the ratio says how many such passes a diagnosis
costs).
"""

from __future__ import annotations

import math

import numpy as np
from _timing import best_of

from gyroarray.chain.compare import ModelComparison
from gyroarray.core.layout import Layout
from gyroarray.sim.lab import lab_run
from gyroarray.effects.model import ModelEntry, NoiseModel

BASE = (ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 10.0}))
LAYOUT = Layout.conical(2, 8, math.radians(60.7941))
KW = dict(rate_hz=100.0, static_s=1200.0, motion_s=900.0, tail_s=660.0)


def main() -> dict:
    import allantools

    base = lab_run(NoiseModel(BASE), LAYOUT, np.random.default_rng(1), **KW)
    hidden = lab_run(NoiseModel(BASE + (ModelEntry("scale_factor", 5, {"ppm": 3000.0}),)), LAYOUT,
                     np.random.default_rng(2), **KW)
    ModelComparison(base, n_runs=2).analyse()          # warm the numba caches
    y = base.gyro_deg_s
    t_ref, _ = best_of(lambda: [allantools.oadev(y[:, g], rate=100.0, data_type="freq", taus="octave")
                                for g in range(y.shape[1])], 3)
    t_diag, a = best_of(lambda: ModelComparison(base).analyse(), 1)
    t_lad, steps = best_of(lambda: ModelComparison(hidden).ladder(), 1)
    added = [s[0] for s in steps[1:]]
    rows = [("diagnose 46 min x 8 gyros x 100 Hz", t_diag, 20.0),
            ("ladder, one hidden effect", t_lad, 60.0)]
    print(f"{'job':<40} {'time s':>8} {'target s':>9} {'x allantools ADEV':>18}")
    for name, t, target in rows:
        print(f"{name:<40} {t:8.2f} {target:9.0f} {t / t_ref:18.1f}  {'ok' if t <= target else 'SLOW'}")
    print(f"allantools oadev, 8 gyros: {t_ref:.2f} s; diagnose D = {a.discrepancy:.2f} "
          f"(consistent {a.consistent}); ladder added {added}, final D = {steps[-1][1].discrepancy:.2f}")
    return {"diagnose_s": t_diag, "ladder_s": t_lad, "allantools_oadev_s": t_ref,
            "diagnose_ok": t_diag <= 20.0, "ladder_ok": t_lad <= 60.0,
            "ladder_added": [list(x) for x in added], "ladder_consistent": steps[-1][1].consistent}
