"""Scoring metrics (src/gyroarray/analysis/metrics.py) and the model chain's `gyroarray run`."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from gyroarray.analysis.metrics import attenuation_and_lag, noise_density, sine_fit
from gyroarray.cli.main import main
from gyroarray.core.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


def test_sine_fit_is_exact_on_a_noise_free_sinusoid():
    t = np.arange(0, 100, 0.01)
    y = 5.0 * np.sin(2 * np.pi * 0.05 * t + 0.3) + 0.2
    fit = sine_fit(t, y, 0.05)
    # linear least squares on an exact model: rounding only
    assert fit.amplitude == pytest.approx(5.0, rel=1e-12)
    assert fit.phase_rad == pytest.approx(0.3, abs=1e-12)
    assert fit.offset == pytest.approx(0.2, abs=1e-12)


def test_attenuation_and_lag_of_a_first_order_lowpass():
    # y = H(jw) x for a first-order low-pass with corner fc: |H| = 1/sqrt(1+(f/fc)^2), lag = atan(f/fc)
    f, fc = 0.5, 2.0
    t = np.arange(0, 200, 0.01)
    gain, lag = 1 / math.sqrt(1 + (f / fc) ** 2), math.atan(f / fc)
    truth = np.sin(2 * np.pi * f * t)
    est = gain * np.sin(2 * np.pi * f * t - lag)
    att, got_lag = attenuation_and_lag(t, est, truth, f)
    assert att == pytest.approx(gain, rel=1e-12)
    assert got_lag == pytest.approx(lag, abs=1e-12)
    with pytest.raises(InputError, match="no component"):
        attenuation_and_lag(t, est, np.zeros_like(t), f)


def test_noise_density_of_white_noise():
    # white noise of variance s^2 at fs has one-sided PSD 2 s^2 / fs: density s*sqrt(2 dt).
    # Welch with 2^14-sample Hann segments, 50 % overlap over 2^20 samples: ~127 segments, each
    # PSD bin ~ chi2 with ~2*127*0.95 dof; the median over ~4000 bins of the band is then
    # within ~0.3 % (sd of one bin ~9 %, median of 4000 -> ~0.2 %) -- allow 2 %.
    rng = np.random.default_rng(5)
    s, dt = 0.3, 0.01
    x = s * rng.standard_normal(2**20)
    d = noise_density(x, dt)
    # the median of a chi2_nu/nu variable is ~(1 - 2/(9 nu))^3 < 1: ~0.3 % low for nu ~ 240
    assert d == pytest.approx(s * math.sqrt(2 * dt), rel=0.02)


@pytest.mark.slow
def test_run_cli_on_the_paper003_swing(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("GYROARRAY_CACHE", str(tmp_path))
    code = main(["run", str(ROOT / "src" / "gyroarray" / "data" / "scenarios" / "paper003" / "swing_s1_n6.toml"), "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    res = json.loads(out)
    assert res["scenario"] == "paper003_swing_s1_n6" and res["swing_hz"] == pytest.approx(0.03)
    keys = {"sigma_1_deg_s", "attenuation", "phase_deg", "arw_deg_rt_h", "bi_deg_h", "rrw_deg_h_rt_h",
            "efficiency"}
    for name in ("kf_array", "gls", "ols", "naive", "bound"):
        for axis in "xyz":
            assert keys <= set(res["estimators"][name][axis]), (name, axis)
    # only z swings: attenuation reported on z, not on x, y
    kf = res["estimators"]["kf_array"]
    assert kf["x"]["attenuation"] is None and kf["z"]["attenuation"] is not None
    # a 0.03 Hz swing is far below the KF bandwidth: amplitude within 1 % and lag below 1 deg
    assert kf["z"]["attenuation"] == pytest.approx(1.0, abs=0.01)
    assert abs(kf["z"]["phase_deg"]) < 1.0
    # the smoother is the bound: no causal estimator beats it by more than estimation noise
    # (1 sigma of a 1sigma estimate from ~6e4 correlated samples is well under 5 %)
    for name in ("kf_array", "gls", "ols", "naive"):
        for axis in "xyz":
            assert res["estimators"][name][axis]["efficiency"] <= 1.05
    # the fused ARW is well below the single gyros' (GLS on 6 gyros: sqrt(3/6) = 0.71 of one gyro);
    # tolerance 3 sigma of the fused fit (its own *_sigma, ~1 %) plus the single-gyro mean's
    single = res["single_gyro"]["arw_deg_rt_h"]
    for axis in "xyz":
        g = res["estimators"]["gls"][axis]
        tol = 3 * math.hypot(g["arw_deg_rt_h_sigma"], res["single_gyro"]["arw_deg_rt_h_sigma"] / math.sqrt(6))
        assert abs(g["arw_deg_rt_h"] - single * math.sqrt(0.5)) <= tol, (g, single)


def test_score_ignores_a_swing_the_run_was_cut_before():
    # the swing segment starts at 500 s but the run ends at 60 s: no attenuation, no crash
    from gyroarray.chain.run import score
    from gyroarray.core.layout import Layout
    rng = np.random.default_rng(2)
    n, dt = 6000, 0.01
    t = np.arange(n) * dt
    lay = Layout.conical(1, 4, math.acos(1 / math.sqrt(3)))
    truth = np.zeros((n, 3))
    readings = 1e-3 * rng.standard_normal((n, 4))
    est = {"ols": readings @ np.linalg.pinv(lay.H).T}
    res = score(est, truth, readings, lay, t, dt, swing=(0.05, (500.0, 700.0)))
    assert res.swing_hz is None
    assert res.table["attenuation"].isna().all()
    # ... and a swing that is there is scored: 0.5 Hz, 1 deg/s about z, estimate = truth + noise
    truth[:, 2] = math.radians(1.0) * np.sin(2 * np.pi * 0.5 * t)
    readings = truth @ lay.H.T + 1e-3 * rng.standard_normal((n, 4))
    est = {"ols": readings @ np.linalg.pinv(lay.H).T}
    res = score(est, truth, readings, lay, t, dt, swing=(0.5, (0.0, 60.0)))
    z = res.table.set_index("axis").loc["z"]
    # noise 1e-3 rad/s per gyro over ~5800 samples vs a 0.0175 rad/s amplitude: amplitude error ~1e-3
    assert z["attenuation"] == pytest.approx(1.0, abs=5e-3)
    assert res.table.set_index("axis").loc["x", "attenuation"] is None or \
        np.isnan(res.table.set_index("axis").loc["x", "attenuation"])
