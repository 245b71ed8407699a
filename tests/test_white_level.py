"""A model's white level is the one that reproduces the ADEV where the model describes it (issue 32).

The per-sample level of a record whose short τ carry a filter or a line is a different figure:
a first-order low-pass takes variance away at short τ but leaves the white level at τ >> its time
constant unchanged (the PSD at low frequency is the white noise's own); a line near Nyquist adds
per-sample variance that averages out by τ = 1 s. The truth here is the generator's N, drawn with
numpy and filtered with scipy.signal, not gyroarray.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from gyroarray.effects.stochastic import fit_gyro_noise

DT = 0.01                                        # 100 Hz
N_DEG_RT_H = 2.0                                 # the white level [deg/√h]
N_RAD = math.radians(N_DEG_RT_H / 60.0)          # [rad/√s]
SAMPLES = 400_000                                # 4000 s


def _white(rng: np.random.Generator) -> np.ndarray:
    return rng.standard_normal(SAMPLES) * N_RAD / math.sqrt(DT)     # rad/s, PSD N² (one-sided·½)


def _arw(x: np.ndarray) -> tuple[float, float, dict]:
    f = fit_gyro_noise(x, DT, 1)[0]
    assert f.effect == "arw"
    return f.params["n_deg_rt_h"], f.sigma["n_deg_rt_h"], f.extra


def test_white_level_behind_a_low_pass_is_the_noise_before_it():
    """A 1st-order low-pass at 2 Hz (unity DC gain): per-sample std falls to ~0.25 of the white
    noise's, the ADEV at τ >= 1 s is N/√τ within 1 %. N must be read there."""
    rng = np.random.default_rng(32)
    b, a = signal.butter(1, 2.0, fs=1.0 / DT)
    x = signal.lfilter(b, a, _white(rng))
    n, s, extra = _arw(x)
    # 3σ of the fit plus the filter's own 1 % at the first octave it reads
    assert abs(n - N_DEG_RT_H) < 3.0 * s + 0.01 * N_DEG_RT_H, (n, s, extra)
    assert extra["per_sample_n_deg_rt_h"] < 0.8 * N_DEG_RT_H        # the per-sample level is lower
    assert extra["n_from_tau_s"] >= 0.04


def test_white_level_under_a_line_near_nyquist_is_not_inflated():
    """A 40 Hz line with the white noise's per-sample variance: the per-sample level is ~√2 too
    high, the white level at τ >= 1 s is N."""
    rng = np.random.default_rng(33)
    w = _white(rng)
    t = np.arange(SAMPLES) * DT
    x = w + math.sqrt(2.0) * float(np.std(w)) * np.sin(2 * math.pi * 40.0 * t + 0.3)
    n, s, extra = _arw(x)
    assert abs(n - N_DEG_RT_H) < 3.0 * s + 0.01 * N_DEG_RT_H, (n, s, extra)
    assert extra["per_sample_n_deg_rt_h"] > 1.2 * N_DEG_RT_H


def test_plain_white_noise_keeps_the_per_sample_fit():
    """Pure white noise: the baseline describes every τ, N is read from the first octave (no
    per-sample figure beside it) and agrees with the generator within 3σ."""
    n, s, extra = _arw(_white(np.random.default_rng(34)))
    assert "per_sample_n_deg_rt_h" not in extra
    assert abs(n - N_DEG_RT_H) < 3.0 * s, (n, s)
