"""The thermal-lag column of the temperature fit (src/gyroarray/effects/temperature_bias.py: fit_temperature_bias).

Outside truth: the simulated coefficient, and the binomial law of the 1σ coverage. Records
like the CATS tag's: 1 Hz, 25 h, ARW 6 deg/√h, RRW 25 deg/h/√h, a fast 11 °C drop (300 s)
then a slow 11 °C rise, a thermometer that lags the gyro by 240 s (first order) and reads
with 0.028 °C white noise.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from gyroarray.analysis.gls import gls_rw
from gyroarray.effects.temperature_bias import fit_temperature_bias
from gyroarray.core.units import arw_deg_rt_h_to_rad_rt_s, deg_h_to_rad_s, rad_s_to_deg_h, rrw_deg_h_rt_h_to_rad_s_rt_s

DT, N_SAMPLES, K_TRUE = 1.0, 90_000, 90.0                  # s, -, deg/h/°C
R = arw_deg_rt_h_to_rad_rt_s(6.0) ** 2 / DT                 # white variance per sample [rad²/s²]
Q = rrw_deg_h_rt_h_to_rad_s_rt_s(25.0) ** 2 * DT            # random-walk increment variance [rad²/s²]
T_S = np.arange(N_SAMPLES) * DT


def _record(seed: int, lag_s: float):
    rng = np.random.default_rng(seed)
    true = 5.0 + 11.3 * np.exp(-T_S / 300.0) + 5.6 * (1.0 + np.tanh((T_S - 60_000.0) / 6_000.0))
    if lag_s > 0:                                           # the reading: a first-order lag of it
        a = DT / (lag_s + DT)
        read = signal.lfilter([a], [1.0, a - 1.0], true, zi=[true[0] * (1.0 - a)])[0]
    else:
        read = true.copy()
    read = read + 0.028 * rng.standard_normal(N_SAMPLES)
    e = (deg_h_to_rad_s(K_TRUE) * (true - true[0]) + np.cumsum(math.sqrt(Q) * rng.standard_normal(N_SAMPLES))
         + math.sqrt(R) * rng.standard_normal(N_SAMPLES))
    return e, read


@pytest.mark.slow
def test_lagged_thermometer_coefficient_is_unbiased_and_its_1_sigma_covers_68_percent():
    seeds = range(200)
    k, s, k1 = [], [], []
    for seed in seeds:
        e, read = _record(seed, 240.0)
        f = fit_temperature_bias(e, read, T_S, DT, R, Q, 2)
        k.append(f.params["deg_h_per_c"])
        s.append(f.sigma["deg_h_per_c"])
        k1.append(rad_s_to_deg_h(float(gls_rw(e, read - read[0], R, Q).beta[0])))
    k, s, k1 = map(np.asarray, (k, s, k1))
    cover = float(np.mean(np.abs(k - K_TRUE) < s))
    # binomial: 200 draws at p = 0.683 have σ = 0.033; 99.9 % two-sided band ±3.29σ
    assert 0.683 - 0.108 <= cover <= 0.683 + 0.108, cover
    # unbiased: the mean within 3.3 standard errors (measured: 89.9, sd 3.3 over 400 seeds)
    assert abs(k.mean() - K_TRUE) < 3.3 * k.std() / math.sqrt(k.size)
    # without the lag column the same records read low (the fast drop answers less): the
    # column is what removes that bias
    assert k1.mean() < K_TRUE - 5.0 * k1.std() / math.sqrt(k1.size)


def test_no_lag_column_without_a_lag_or_when_dt_is_proportional_to_temperature():
    e, read = _record(7, 0.0)
    f = fit_temperature_bias(e, read, T_S, DT, R, Q, 2)
    assert f.extra["lag_smoothing_s"] is None
    plain = rad_s_to_deg_h(float(gls_rw(e, read - read[0], R, Q).beta[0]))
    assert f.params["deg_h_per_c"] == pytest.approx(plain, rel=1e-12)
    # a first-order approach to a final temperature: dT/dt ∝ T − const, the lag is not identifiable
    rng = np.random.default_rng(3)
    t = np.arange(20_000) * DT
    temp = 30.0 - 10.0 * np.exp(-t / 3000.0)
    e2 = deg_h_to_rad_s(50.0) * (temp - temp[0]) + math.sqrt(R) * rng.standard_normal(t.size)
    f2 = fit_temperature_bias(e2, temp, t, DT, R, Q, 1)
    assert f2.extra["lag_smoothing_s"] is None
    assert f2.params["deg_h_per_c"] == pytest.approx(50.0, abs=4 * f2.sigma["deg_h_per_c"])


def test_lag_column_enters_and_recovers_the_coefficient_on_one_lagged_record():
    e, read = _record(11, 240.0)
    f = fit_temperature_bias(e, read, T_S, DT, R, Q, 2)
    assert f.extra["lag_smoothing_s"] is not None
    k, s = f.params["deg_h_per_c"], f.sigma["deg_h_per_c"]
    assert abs(k - K_TRUE) < 3.0 * s                        # 3σ: fails with probability 0.3 %
    assert f.extra["thermal_lag_s"] == pytest.approx(240.0, abs=3.0 * f.extra["thermal_lag_sigma_s"])
