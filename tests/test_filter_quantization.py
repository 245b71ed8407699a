"""Quantization behind a sensor's filter: the calibration reads Q where it lives.

The spec puts quantization after the bandwidth filter, so its Allan variance
3Q²/τ² is largest at τ = dt, where the filter also lowers the white noise.
A calibration that starts its Allan fit above the filter's short τ does not
see Q there (the ADIS16405's gyro 3: Q = 0.0046° fitted, a band at τ = dt
twice the record's ADEV; 0.0011° read at every τ). Outside truth: the Q set,
and allantools' ADEV at τ = dt against the model's band.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroarray.chain.compare import ModelComparison
from gyroarray.core.layout import Layout
from gyroarray.sim.lab import lab_run
from gyroarray.effects.model import ModelEntry, NoiseModel

Q_DEG = 0.002


@pytest.mark.slow   # a filtered, quantized lab run diagnosed (6 s on 2 cores): make score
def test_quantization_behind_a_filter_is_read_at_the_shortest_tau():
    import allantools

    layout = Layout.triad()
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 1.0}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 20.0}),
                        ModelEntry("bandwidth", 1, {"cutoff_hz": 10.0, "order": 2}),
                        ModelEntry("quantization", 1, {"q_deg": Q_DEG})))
    m = lab_run(model, layout, np.random.default_rng(8), static_s=600.0, motion_s=120.0, tail_s=60.0)
    _, after = ModelComparison(m, n_runs=20).fit([("bandwidth", 1), ("quantization", 1)])
    f = after.fits[("quantization", 1)]
    assert abs(f.params["q_deg"] - Q_DEG) <= max(0.1 * Q_DEG, 2.0 * f.sigma["q_deg"]), (f.params, f.sigma)
    # the model's band at τ = dt holds the record's ADEV there (allantools, static part)
    band = next(t for t in after.tests if t.kind == "adev_band" and t.gyro == 1)
    assert not after.significant(band), band.evidence
    a, b = after.context.longest
    x = np.degrees(m.gyro_rad_s[a:b, 0]) * 3600.0
    _, ad, _, _ = allantools.oadev(x, rate=1.0 / m.dt_s, data_type="freq", taus=[m.dt_s])
    q_only = math.sqrt(3.0) * Q_DEG / m.dt_s * 3600.0                  # √3·Q/τ [deg/h] at τ = dt
    assert ad[0] == pytest.approx(q_only, rel=0.25)                     # Q dominates there
