"""Quantization and the filter as ``shared/spec/effects.md`` now defines them (issue 32).

* ``quantization``: y_k = (round(θ_k/Δ) − round(θ_{k−1}/Δ))·Δ/dt, Δ = √12·Q, θ_k the
  integrated angle of everything the gyro outputs before the counter. White angle error
  (ADEV √3·Q/τ) only when the angle moves by many steps per sample; a quiet gyro with a
  coarse step has a correlated error, which the fit reads from the output's grid and the
  model band simulates.
* ``bandwidth``: ``scipy.signal.butter(order, cutoff_hz, fs)`` run causally with ``lfilter``
  from the steady state of the first sample.

Outside truth: the spec's formulas written here in numpy, scipy's filter, the χ² interval of
the Allan variance with Greenhall's equivalent degrees of freedom.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal, stats

from gyroarray.analysis.allan import edf_greenhall, oadev
from gyroarray.chain.compare import ModelComparison
from gyroarray.core.layout import Layout
from gyroarray.core.sensor import output_lattice_step, quantize_rate
from gyroarray.core.units import deg_to_rad
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.quantization import Quantization, quant_avar_shape
from gyroarray.sim.effects import simulate_readings
from gyroarray.sim.lab import lab_run

DEG = math.pi / 180.0


def _spec_counter(x: np.ndarray, dt: float, step: float) -> np.ndarray:
    """The spec's definition, column by column, written here (θ_{−1} = 0)."""
    counts = np.round(np.cumsum(x * dt, axis=0) / step)
    return np.diff(counts, axis=0, prepend=0.0) * (step / dt)


def _run(model_entries, truth, dt, seed):
    return simulate_readings(NoiseModel(tuple(model_entries)), truth, Layout.triad(), dt,
                             np.random.default_rng(seed))


def test_a_fast_moving_counter_is_the_spec_s_and_its_error_is_white():
    """300 deg/s about z plus a white noise that moves the angle by 2.4 steps per sample: the
    output is the spec's counter of the unquantized output bit for bit, every value a multiple
    of Δ/dt, and the ADEV of the counter's error within its 99 % χ² interval of √3·Q/τ."""
    dt, n, q_deg = 0.02, 60_000, 2.9e-4
    step = math.sqrt(12.0) * float(deg_to_rad(q_deg))              # Δ as the model converts it
    truth = np.zeros((n, 3))
    truth[:, 2] = 300.0 * DEG
    arw = ModelEntry("arw", None, {"n_deg_rt_h": 1.0})
    x = _run([arw], truth, dt, 5)                                   # the same arw draws (keyed streams)
    y = _run([arw, ModelEntry("quantization", None, {"q_deg": q_deg})], truth, dt, 5)
    c = step / dt
    spec = _spec_counter(x, dt, step)
    np.testing.assert_array_equal(np.round(y / c), np.round(spec / c))     # the same counts
    np.testing.assert_array_equal(y, spec)
    np.testing.assert_array_equal(y, np.round(y / c) * c)                  # on the grid, exactly
    assert np.all(np.abs(y / c - np.round(y / c)) < 1e-9)
    assert output_lattice_step(y[:, 0]) == pytest.approx(c, rel=1e-9)
    err = y - x                                                     # (e_k − e_{k−1})/dt
    m = np.array([1, 10, 100])
    taus = m * dt
    avar = oadev(err[:, 0], dt, taus=taus).dev ** 2
    edf = edf_greenhall(n + 1, m, 2, 2)                             # white PM, overlapping Allan
    want = 3.0 * (step / math.sqrt(12.0)) ** 2 / taus ** 2
    lo = edf * avar / stats.chi2.ppf(0.995, edf)
    hi = edf * avar / stats.chi2.ppf(0.005, edf)
    assert np.all((lo <= want) & (want <= hi)), (avar / want, lo / want, hi / want)


def test_float64_angle_keeps_its_precision_over_a_long_fast_record():
    """1e6 samples at 300 deg/s and 100 Hz (θ up to 5.2e4 rad): the float64 cumulative sum of
    the counter stays within 1e-8 rad of the 80-bit one, 1e-4 of a 0.0035 deg step; the two
    counters differ at most at a handful of samples (a boundary crossed one sample early or
    late, as an input change of 1e-8 rad would do), and by one step there."""
    n, dt, step = 1_000_000, 0.01, math.sqrt(12.0) * 1e-3 * DEG
    rng = np.random.default_rng(3)
    x = 300.0 * DEG + 0.05 * DEG * rng.standard_normal(n)
    th64 = np.cumsum(x * dt)
    thld = np.cumsum((x * dt).astype(np.longdouble))
    assert float(np.max(np.abs(th64 - thld))) < 1e-8
    k64 = np.round(th64 / step)
    kld = np.round(thld / np.longdouble(step)).astype(float)
    diff = k64 - kld
    assert np.max(np.abs(diff)) <= 1 and np.count_nonzero(diff) <= 20
    y = quantize_rate(x, dt, step)
    assert np.sum(y) * dt == pytest.approx(k64[-1] * step, abs=1e-6 * step * n)


def test_the_output_grid_gives_the_step():
    """A quiet counter (increments mostly 0, ±Δ/dt now and then) and a grid seen only at 2c and
    3c: the step is read exactly; a continuous output has no grid."""
    dt, step = 0.02, 0.004 * DEG
    rng = np.random.default_rng(1)
    x = 0.05 * DEG + 0.02 * DEG * rng.standard_normal(20_000)
    y = quantize_rate(x, dt, step)
    assert np.unique(y).size <= 5
    assert output_lattice_step(y) == pytest.approx(step / dt, rel=1e-9)
    assert output_lattice_step(np.array([2.0, 5.0, -4.0, 2.0]) * 0.37) == pytest.approx(0.37, rel=1e-12)
    assert math.isnan(output_lattice_step(x))


def test_a_quiet_counter_departs_from_three_q_squared():
    """The correlated regime: the simulated ADEV shape at short τ is far from 1 (the white
    angle error's 3Q²/τ²), and comes back to 1 where the angle noise has moved by many steps."""
    dt, step = 0.02, math.sqrt(12.0) * 0.002 * DEG
    n_rad = 0.15 * DEG / 60.0                                     # 0.15 deg/√h
    s = quant_avar_shape(n_rad, 5.0 * DEG / 3600.0, step, dt, np.array([1, 4, 16, 2 ** 20]))
    assert s[0] < 0.5 and s[-1] == 1.0


@pytest.mark.parametrize("order", [1, 2])
def test_bandwidth_is_scipy_butter_run_by_lfilter_from_the_first_sample(order):
    """The simulated effect equals lfilter(b, a, x, zi=lfilter_zi(b, a)·x[0]) of its input, with
    (b, a) = butter(order, cutoff_hz, fs), to 1e-12 of the signal's scale."""
    dt, n, fc = 0.01, 5000, 7.0
    rng = np.random.default_rng(order)
    t = np.arange(n) * dt
    truth = np.column_stack([0.3 + 0.5 * np.sin(2 * np.pi * 1.3 * t), 0.1 * rng.standard_normal(n),
                             -0.2 + 0.0 * t])
    layout = Layout.triad()
    x = truth @ np.asarray(layout.axes, dtype=float).T
    y = simulate_readings(NoiseModel((ModelEntry("bandwidth", None, {"cutoff_hz": fc, "order": order}),)),
                          truth, layout, dt, np.random.default_rng(0))
    b, a = signal.butter(order, fc, fs=1.0 / dt)
    want = np.column_stack([signal.lfilter(b, a, x[:, j], zi=signal.lfilter_zi(b, a) * x[0, j])[0]
                            for j in range(3)])
    assert float(np.max(np.abs(y - want))) <= 1e-12 * float(np.max(np.abs(x)))
    _, h = signal.freqz(b, a, worN=[fc], fs=1.0 / dt)
    assert 20 * math.log10(abs(h[0])) == pytest.approx(-3.0103, abs=1e-3)    # digital −3 dB at fc


def _quiet_record(seed: int):
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 2.0}),
                        ModelEntry("quantization", 1, {"q_deg": 0.002})))
    return lab_run(model, Layout.triad(), np.random.default_rng(seed), static_s=900.0, motion_s=0.0, tail_s=60.0)


@pytest.mark.slow   # a quiet counter fitted with and without its correlated regime (35 s): make score
def test_a_quiet_gyro_with_a_coarse_step_is_fitted_consistently(monkeypatch):
    """A quiet gyro (0.15 deg/√h, 2.4e-4 deg per sample) behind a counter of step 0.0069 deg:
    its output takes 3 values. ``fit --add quantization:1`` recovers Δ within 1 % from the
    grid and the model is consistent (D <= 2: 23.5 -> 1.15); read as the white angle error
    (3Q²/τ², the Allan column alone) Q reads 0.00085 and the ADEV at τ = dt leaves the band."""
    m = _quiet_record(4)
    assert np.unique(m.gyro_rad_s[:, 0]).size <= 5
    before, after = ModelComparison(m, n_runs=20).fit([("quantization", 1)])
    f = after.fits[("quantization", 1)]
    assert f.params["q_deg"] == pytest.approx(0.002, rel=0.01), f.params
    assert after.discrepancy <= 2.0, [t.evidence for t in after.tests if after.significant(t)]
    assert before.discrepancy > 10.0

    def white_only(self, ctx, gyro):          # the white regime's reading: no grid, no shape
        return {"step_rad": math.nan, "counts_sd": math.nan, "correlated": False, "bias_rad_s": 0.0}

    def band_1(a):
        return next(t for t in a.tests if t.kind == "adev_band" and t.gyro == 1)

    assert not after.significant(band_1(after)), band_1(after).evidence
    monkeypatch.setattr(Quantization, "lattice", white_only)
    _, white = ModelComparison(m, n_runs=20).fit([("quantization", 1)])
    # D 23.5 -> 2.54 (the band at τ = dt: 289 deg/h against 196, Q read 0.00085), against 1.15
    assert white.discrepancy > 2.0 and white.significant(band_1(white)), band_1(white).evidence
    assert white.fits[("quantization", 1)].params["q_deg"] < 0.6 * 0.002
