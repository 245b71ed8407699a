"""Where it fails: the localisation of what a model leaves unexplained.

Records: a 4-gyro cone with ARW + RRW swung about two axes (smooth
envelopes), given the model's own ADEV band (closed form N²/τ + K²τ/3 with
χ² intervals from the Greenhall EDF) and PSD (2N² + 2(K/2π)²/f²). The
residual is the output minus H·ω. Filters that are *not* in the library are
applied outside gyroarray with scipy: a zero-phase filter with bandwidth's
magnitude (the "Samsung" case), ``filtfilt`` of a Butterworth (zero-phase,
steeper), a causal 4th-order Butterworth; the expected numbers (−3 dB
point, group delay 1/(ωc sin(π/2p))) are written here.

False alarms: on 30 clean records (seeds 2-31) no finding at all
(measured; the family-wise rate is set to 1 %).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import signal, stats

from gyroarray.analysis.allan import averaging_factors, confidence_interval, edf
from gyroarray.chain.localise import (baseline_psd, chi2_z, critical_z, localise,
                                         residual_psd)
from gyroarray.core.layout import Layout
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.core.sensor import bandwidth_sos
from gyroarray.core.units import arw_deg_rt_h_to_rad_rt_s, deg_s_to_rad_s, rrw_deg_h_rt_h_to_rad_s_rt_s
from swings import two_swings

FS = 100.0
DT = 1.0 / FS
N_SAMPLES = 40_000
LAYOUT = Layout.conical(1, 4, math.acos(1 / math.sqrt(3)))
ARW, RRW = 0.3, 5.0                                   # deg/√h, deg/h/√h
N_SI, K_SI = arw_deg_rt_h_to_rad_rt_s(ARW), rrw_deg_h_rt_h_to_rad_s_rt_s(RRW)


def _motion():
    """Still 100 s; 30 deg/s at 0.5 Hz about (1,1,1)/√3; 20 deg/s at 1.3 Hz about (1,−1,0)/√2."""
    t = np.arange(N_SAMPLES) * DT
    return t, two_swings(t)


T, W = _motion()
U = W @ LAYOUT.H.T


def _record(seed=1, extra=()):
    m = NoiseModel.from_toml({"effects": [{"effect": "arw", "n_deg_rt_h": ARW},
                                          {"effect": "rrw", "k_deg_h_rt_h": RRW}, *extra]}, n_gyros=4)
    return simulate_readings(m, W, LAYOUT, DT, np.random.default_rng(seed), time_s=T)


def _band():
    taus = averaging_factors(N_SAMPLES + 1, DT, "octave") * DT
    sigma = np.sqrt(N_SI**2 / taus + K_SI**2 * taus / 3)
    alpha = np.where(N_SI**2 / taus > K_SI**2 * taus / 3, 0, -2)
    lo, hi = confidence_interval(sigma, edf("oadev", N_SAMPLES + 1, np.rint(taus / DT), alpha), 0.95)
    return taus, np.tile(lo, (4, 1)), np.tile(hi, (4, 1))


def _localise(y, **kw):
    taus, lo, hi = _band()
    return localise(y - U, DT, time_s=T, taus_s=taus, band_lo=lo, band_hi=hi,
                    model_psd=lambda f: baseline_psd(f, np.full(4, N_SI), np.full(4, K_SI)),
                    rate=U, **kw)


def _zero_phase_bandwidth(x, fc, order):
    """|H| of the library's filter applied with no phase (FFT of the mirrored record)."""
    n = x.shape[0]
    f = np.fft.rfftfreq(2 * n, DT)
    _, h = signal.sosfreqz(bandwidth_sos(fc, order, DT), worN=f, fs=FS)
    X = np.fft.rfft(np.concatenate([x, x[::-1]]), axis=0)
    return np.fft.irfft(X * np.abs(h)[:, None], n=2 * n, axis=0)[:n]


def _no_false_labels(loc):
    for f in loc.findings:
        assert "Gauss" not in f.summary and "burst" not in f.summary
        assert f.kind not in ("band_excess", "low_frequency")
        if f.kind == "time_window":
            assert f.details["moving_fraction"] > 0      # never a noise-level change at rest


def test_zero_phase_filter_with_bandwidths_magnitude_is_a_lowpass_without_lag():
    y = _record()
    y[:, 1:3] = _zero_phase_bandwidth(y[:, 1:3], 8.0, 2)
    loc = _localise(y)
    top = loc.findings[0]
    assert top.kind == "lowpass" and top.gyros == (2, 3)
    assert "low-pass at ≈ 8" in top.summary and "not causal: no lag on motion" in top.summary
    d = top.details
    assert d["library_fits"] and d["bandwidth_order"] == 2
    assert d["bandwidth_cutoff_hz"] == pytest.approx(8.0, rel=0.03)     # measured 8.00
    # a causal filter of that magnitude lags √2/ωc = 28 ms; measured 0.008 ± 0.008 ms
    assert d["expected_lag_s"] == pytest.approx(math.sqrt(2) / (2 * math.pi * 8.0), rel=0.03)
    assert abs(d["lag_s"]) < 1e-3 and d["causal"] is False
    assert loc.gyro_scores[[0, 3]].max() < loc.z_crit < loc.gyro_scores[1:3].min()
    _no_false_labels(loc)
    out = json.loads(json.dumps(loc.to_dict()))
    assert out["findings"][0]["details"]["per_gyro"]["2"]["causal"] is False


def test_filtfilt_butterworth_is_a_steeper_lowpass_not_in_the_library_and_not_causal():
    y = _record()
    b, a = signal.butter(2, 8.0, fs=FS)
    y[:, 1:3] = signal.filtfilt(b, a, y[:, 1:3], axis=0)
    loc = _localise(y)
    top = loc.findings[0]
    assert top.kind == "lowpass" and top.gyros == (2, 3) and top.details["causal"] is False
    # |H|² of filtfilt = |H_butter|⁴: −3 dB where (1 + x⁴)² = 2, x = 0.80 (6.4 Hz), and
    # −80 dB/decade far above; the fit sees 6.7 Hz and about −60 dB/decade below Nyquist
    assert top.details["cutoff_hz"] == pytest.approx(8.0 * (math.sqrt(2) - 1) ** 0.25, rel=0.1)
    assert not top.details["library_fits"] and top.details["slope_db_decade"] < -50
    assert "steeper than bandwidth's" in top.summary and "not causal" in top.summary
    _no_false_labels(loc)


def test_causal_4th_order_butterworth_lags_as_its_magnitude_says():
    y = _record()
    sos = signal.butter(4, 10.0, fs=FS, output="sos")
    y[:, :1] = signal.sosfilt(sos, y[:, :1], axis=0, zi=signal.sosfilt_zi(sos)[:, :, None] * y[0, 0])[0]
    loc = _localise(y)
    low = loc.of_kind("lowpass")
    assert len(low) == 1 and low[0].gyros == (1,) and low[0].details["causal"] is True
    assert low[0].details["cutoff_hz"] == pytest.approx(10.0, rel=0.05)           # 9.89
    assert low[0].details["slope_db_decade"] == pytest.approx(-80, abs=10)         # -84
    tau_g = 1 / (2 * math.pi * 10.0 * math.sin(math.pi / 8))                       # 41.6 ms
    assert low[0].details["lag_s"] == pytest.approx(tau_g, rel=0.1)                # 39.9 ms
    # the lag also shows as a residual that follows the angular acceleration
    acc = [f for f in loc.of_kind("channel") if f.details["channel"] == "angular acceleration"]
    assert acc and acc[0].gyros == (1,) and acc[0].details["slope"] == pytest.approx(-tau_g, rel=0.1)


def test_the_librarys_own_bandwidth_is_found_causal_at_its_cutoff():
    y = _record(extra=[{"effect": "bandwidth", "cutoff_hz": 15.0, "order": 2}])
    loc = _localise(y)
    low = loc.of_kind("lowpass")
    assert len(low) == 1 and low[0].gyros == (1, 2, 3, 4)
    d = low[0].details
    assert d["library_fits"] and d["bandwidth_order"] == 2 and d["causal"] is True
    for g in range(1, 5):
        assert d["per_gyro"][g]["bandwidth_cutoff_hz"] == pytest.approx(15.0, rel=0.03)


def test_clean_record_raises_no_alarm():
    loc = _localise(_record(seed=1))
    assert loc.findings == () and loc.z_crit == pytest.approx(4.33, abs=0.01)
    assert {c.channel for c in loc.correlations} == {"time", "rate", "rate²", "angular acceleration"}


def test_a_line_a_noise_burst_and_a_temperature_slope_are_placed():
    temp = 25.0 + 10.0 * T / T[-1]
    m = NoiseModel.from_toml({"effects": [
        {"effect": "arw", "n_deg_rt_h": ARW}, {"effect": "rrw", "k_deg_h_rt_h": RRW},
        {"effect": "sinusoid", "gyro": 4, "amp_deg_s": 0.02, "freq_hz": 7.0},
        {"effect": "burst", "start_s": 40.0, "end_s": 70.0, "variance_ratio": 4.0},
        {"effect": "temperature_bias", "gyro": 3, "deg_h_per_c": 30.0, "t0_c": 25.0}]}, n_gyros=4)
    y = simulate_readings(m, W, LAYOUT, DT, np.random.default_rng(5), time_s=T, temp_c=temp)
    loc = _localise(y, temp_c=temp)
    (line,) = [f for f in loc.of_kind("line") if f.gyros == (4,)]
    assert line.details["freq_hz"] == pytest.approx(7.0, abs=FS / 2048)            # one Welch bin
    assert math.degrees(line.details["amp_rad_s"]) == pytest.approx(0.02, rel=0.15)
    burst = [f for f in loc.of_kind("time_window") if f.details["moving_fraction"] == 0]
    assert burst and burst[0].gyros == (1, 2, 3, 4)
    assert 35 <= burst[0].details["t0_s"] <= 45 and 65 <= burst[0].details["t1_s"] <= 75
    assert burst[0].details["variance_ratio"] == pytest.approx(4.0, rel=0.25)
    temp_found = [f for f in loc.of_kind("channel") if f.details["channel"] == "temperature"]
    assert temp_found and temp_found[0].gyros == (3,)
    # 30 deg/h per °C = 1.45e-4 rad/s per °C
    assert temp_found[0].details["slope"] == pytest.approx(deg_s_to_rad_s(30 / 3600), rel=0.2)


# -- the statistics ------------------------------------------------------------

def test_chi2_scores_and_critical_values():
    r = np.array([0.5, 0.9, 1.0, 1.3, 2.0])
    nu = 40.0
    expect = stats.norm.ppf(stats.chi2.cdf(nu * r, nu))
    np.testing.assert_allclose(chi2_z(r, nu), expect, rtol=1e-9, atol=1e-9)
    assert critical_z(1, 0.01) == pytest.approx(stats.norm.ppf(0.995), rel=1e-12)
    # Šidák: 1 − (1 − α)^(1/K) per test
    assert critical_z(100, 0.01) == pytest.approx(stats.norm.isf((1 - 0.99 ** 0.01) / 2), rel=1e-10)


def test_baseline_psd_is_what_welch_sees_of_arw_and_rrw():
    y = _record(seed=9)
    f, P, nu = residual_psd(y - U, DT)
    S = baseline_psd(f, N_SI, K_SI)
    ratio = P[:, 1:] / S[1:]
    # mean over 4 gyros × 2048 frequencies of a χ²_ν/ν ratio: 1 within a few 1/√(ν·m)
    assert ratio.mean() == pytest.approx(1.0, abs=4 * math.sqrt(2 / (nu * ratio.size)) * 3)


def test_bad_inputs_are_refused():
    from gyroarray.core.errors import InputError
    e = np.zeros((1000, 4))
    with pytest.raises(InputError, match="n >= 512"):
        localise(np.zeros((100, 4)), DT)
    with pytest.raises(InputError, match=r"channel 'rate' must be 1000 finite samples.*\(4\)"):
        localise(e, DT, rate=np.zeros((1000, 3)))
    with pytest.raises(InputError, match=r"acc must be \(1000, 3\)"):
        localise(e, DT, acc=np.zeros((1000, 4)))


def test_bandwidth_gain2_is_sosfreqz_of_the_library_filter():
    from gyroarray.chain.localise import bandwidth_gain2
    f = np.linspace(0.01, 49.9, 997)
    for fc, order in ((0.5, 1), (8.0, 2), (30.0, 1), (45.0, 2)):
        _, h = signal.sosfreqz(bandwidth_sos(fc, order, DT), worN=f, fs=FS)
        np.testing.assert_allclose(bandwidth_gain2(f, fc, order, DT), np.abs(h) ** 2, rtol=1e-9, atol=1e-15)


def test_a_flat_deficit_is_the_models_level_not_a_lowpass():
    # a model 1.6x too high everywhere (its white level inflated by what it misses): the residual
    # sits at 1/1.6 of it up to Nyquist, a level, not a roll-off (it was read as a low-pass once)
    loc = localise(_record(seed=3) - U, DT, rate=U,
                   model_psd=lambda f: 1.6 * baseline_psd(f, np.full(4, N_SI), np.full(4, K_SI)))
    assert not loc.of_kind("lowpass")
    (deficit,) = loc.of_kind("band_deficit")
    assert deficit.gyros == (1, 2, 3, 4) and 0.5 < deficit.details["ratio"] < 1 / 1.6


def test_a_stuck_output_is_a_finite_finding_named_stuck():
    """A gyro that stops changing (a stuck output: every window after the onset has an Allan
    variance of exactly 0) is one finding named so, with a finite score, not log 0 (which made
    the score infinite and the JSON invalid)."""
    import json
    import warnings

    from gyroarray.chain.localise import time_windows

    rng = np.random.default_rng(4)
    dt, n = 0.02, 60_000
    e = 1e-3 * rng.standard_normal((n, 2))
    e[40_000:, 1] = e[40_000, 1]                                   # gyro 2 stuck from 800 s
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        found = time_windows(e, dt, np.arange(n) * dt, z_crit=4.0)
    stuck = [f for f in found if f.gyros == (2,)]
    assert stuck and all("stuck" in f.summary and math.isfinite(f.score) for f in stuck)
    assert min(f.details["t0_s"] for f in stuck) == pytest.approx(800.0, abs=30.0)
    assert not [f for f in found if f.gyros == (1,)]
    json.dumps([f.score for f in found], allow_nan=False)
