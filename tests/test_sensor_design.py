"""Design consequences of the sensor as a device: its own bandwidth and its g-sensitivity.

Outside truth:

* the spec's filter written here from its H(s) (bilinear transform pre-warped at the
  cut-off, ``scipy.signal.bilinear``) and evaluated by ``scipy.signal.freqz``: the
  sensor's share of the swing response, and total = estimator × sensor;
* a plain state-space loop written here against the simulator's filter followed by
  the estimator (the cascade the predictor uses);
* Monte-Carlo runs of a swing scenario with a ``bandwidth`` effect (``run --replicates``):
  every prediction inside the runs' interval, family-wise 95 % (Šidák);
* the g-sensitivity on a level static table: gyro i's error k_i · [0, 0, g0], the fused
  error pinv(H) e, computed here with numpy.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import signal

from gyroarray.core import units
from gyroarray.analysis.replicates import mean_ci, rms_ci
from gyroarray.chain.run import run_replicates, run_scenario
from gyroarray.cli.main import main
from gyroarray.core.constants import G0_M_S2
from gyroarray.estimators import get_estimator
from gyroarray.core.layout import Layout
from gyroarray.design.predict import (Swing, cascade, g_sensitivity_error, predict, sensor_bandwidth,
                               swing_truth)
from gyroarray.design.recommend import DesignSpace, GyroNoise, recommend
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.sim.scenario import load_scenario
from gyroarray.core.sensor import bandwidth_filter
from replicates import predictions_outside

DT = 0.01
TETRA = Layout.conical(1, 4, math.radians(54.7356))


def _model(fc=3.0, order=2, arw=0.5, rrw=30.0, extra=()):
    return NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": arw}),
                       ModelEntry("rrw", None, {"k_deg_h_rt_h": rrw}),
                       ModelEntry("bandwidth", None, {"cutoff_hz": fc, "order": order})) + tuple(extra))


def _spec_filter(fc: float, order: int, fs: float):
    """The spec's H(s) (order 1: 1/(1 + s/ωc); 2: 1/(1 + √2 s/ωc + s²/ωc²)), bilinear, pre-warped at fc."""
    wc = 2.0 * fs * math.tan(math.pi * fc / fs)
    a = [1.0 / wc, 1.0] if order == 1 else [1.0 / wc ** 2, math.sqrt(2.0) / wc, 1.0]
    return signal.bilinear([1.0], a, fs=fs)


@pytest.mark.parametrize("order", [1, 2])
def test_swing_response_is_estimator_times_the_spec_filter(order):
    fc, f = 4.0, 1.7
    model = _model(fc, order)
    b, a = _spec_filter(fc, order, 1.0 / DT)
    _, F = signal.freqz(b, a, worN=[f], fs=1.0 / DT)
    F = complex(F[0])
    for name, kw in (("kf_array", {"bandwidth_hz": 2.0}), ("gls", {"lowpass_hz": 5.0}), ("naive", {})):
        est = get_estimator(name)(**kw).fit(TETRA, model, DT)
        T = np.diagonal(est.linear_system().response(2 * np.pi * f * DT)[0] @ TETRA.H)
        p = predict(est, model, n_samples=500, swing=Swing(0.1, f))
        for i, ax in enumerate("xyz"):
            q = p.axes[ax]
            assert q["sensor_amplitude_ratio"] == pytest.approx(abs(F), rel=1e-12)
            assert q["sensor_phase_deg"] == pytest.approx(-math.degrees(np.angle(F)), abs=1e-9)
            assert q["estimator_amplitude_ratio"] == pytest.approx(abs(T[i]), rel=1e-12)
            assert q["amplitude_ratio"] == pytest.approx(abs(T[i] * F), rel=1e-12)
            assert q["phase_deg"] == pytest.approx(-math.degrees(np.angle(T[i] * F)), abs=1e-9)
        # the cascade's own frequency response is the product too
        R = cascade(est.linear_system(), sensor_bandwidth(model, 4, DT)).response(2 * np.pi * f * DT)[0]
        np.testing.assert_allclose(R, est.linear_system().response(2 * np.pi * f * DT)[0] * F,
                                   atol=1e-13)


@pytest.mark.parametrize("order", [1, 2])
def test_cascade_is_the_simulated_filter_then_the_estimator(order):
    """A plain loop x_k = A x_{k-1} + K u_k from x_{-1} = X0 u_0 equals estimate(bandwidth_filter(u))."""
    model = _model(6.0, order)
    rng = np.random.default_rng(3)
    u = rng.normal(size=(300, 4)) + 2.0                   # an offset: the start state matters
    for name, kw in (("kf_array", {"bandwidth_hz": 2.0}), ("gls", {"lowpass_hz": 5.0})):
        est = get_estimator(name)(**kw).fit(TETRA, model, DT)
        sys = cascade(est.linear_system(), sensor_bandwidth(model, 4, DT))
        x = sys.X0 @ u[0]
        out = np.empty((u.shape[0], 3))
        for k in range(u.shape[0]):
            x = sys.A @ x + sys.K @ u[k]
            out[k] = sys.C @ x
        ref = est.estimate(bandwidth_filter(u, DT, 6.0, order))
        np.testing.assert_allclose(out, ref, atol=1e-9)
        # the modal form is the same matrix
        np.testing.assert_allclose((sys.S * sys.lam) @ sys.S_inv, sys.A, atol=1e-10)


def test_predictor_inside_monte_carlo_with_a_sensor_filter():
    """40 runs of 15 s through the simulator (Butterworth 3 Hz filter on every gyro), three
    estimators, 4 metrics × 3 axes: each prediction inside the runs' interval at a family-wise
    95 % (Šidák over the 36 comparisons)."""
    model = _model(3.0, 2)
    sw = Swing(units.deg_s_to_rad_s(10.0), 0.7)
    n = 1500
    truth = swing_truth(sw, n, DT)
    ests = {nm: get_estimator(nm)(**kw).fit(TETRA, model, DT)
            for nm, kw in (("kf_array", {"bandwidth_hz": 2.0}), ("gls", {"lowpass_hz": 8.0}), ("naive", {}))}
    preds = {nm: predict(e, model, n_samples=n, swing=sw) for nm, e in ests.items()}
    level = 0.95 ** (1.0 / (len(ests) * 3 * 4))
    outside = predictions_outside(ests, preds, model, TETRA, truth, DT, reps=40, seed=11, level=level)
    assert not outside, outside[:4]
    # the filter's lag is in the error: the naive motion error is A |1 − F| (mean square A²|1 − F|²/2,
    # 9 swing periods in the window: within 3 %)
    b, a = _spec_filter(3.0, 2, 1.0 / DT)
    _, F = signal.freqz(b, a, worN=[0.7], fs=1.0 / DT)
    ms = (units.rad_s_to_deg_s(sw.amplitude_rad_s) * abs(1 - F[0])) ** 2 / 2
    assert preds["naive"].components["z"]["motion"] == pytest.approx(ms, rel=0.03)


SWING_BW = """
name = "swing_bw"
sample_rate_hz = 100.0
duration_s = 12.0
seed = 5
effects = [
  { effect = "arw", n_deg_rt_h = 0.5 },
  { effect = "rrw", k_deg_h_rt_h = 30.0 },
  { effect = "bandwidth", cutoff_hz = 1.5, order = 2 },
]
[layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356
[motion]
profile = "p002_swing_20dps_0p5hz"
"""


def test_run_replicates_split_the_swing_response(tmp_path):
    """``run --replicates`` on a swing scenario with a bandwidth effect: the measured sensor,
    estimator and total responses (and std/RMS/mean/angle) against the prediction, each inside
    the runs' interval at a family-wise 95 % (Šidák over every comparison)."""
    path = tmp_path / "swing_bw.toml"
    path.write_text(SWING_BW)
    sc = load_scenario(path)
    rep = run_replicates(sc, ["kf_array", "gls"], replicates=6, seed=1)
    comp = rep.comparison()
    cells = [(nm, ax, key, c) for nm, axes in comp.items() for ax, m in axes.items() for key, c in m.items()]
    level = 0.95 ** (1.0 / len(cells))
    outside = []
    for nm, ax, key, c in cells:
        col = {"amplitude_ratio": "attenuation", "std_deg_s": "sigma_1_deg_s",
               "mean_deg_s": "mean_error_deg_s", "angle_deg": "angle_error_deg"}.get(key, key)
        vals = [float(r.table[(r.table.estimator == nm) & (r.table.axis == ax)][col].iloc[0]) for r in rep.runs]
        if c["monte_carlo"]["pooled"] == "rms":
            ci = rms_ci(vals, level, gaussian=key in ("mean_deg_s", "angle_deg"))
        else:
            ci = mean_ci(vals, level)
        tol = 1e-9 * max(1.0, abs(c["predicted"]))          # rounding: a gls passes exactly 1
        if not ci["ci_low"] - tol <= c["predicted"] <= ci["ci_high"] + tol:
            outside.append((nm, ax, key, c["predicted"], ci))
    assert not outside, outside[:4]
    z = comp["gls"]["z"]
    # the low-passed 1.5 Hz Butterworth at 0.5 Hz: the spec's filter by freqz
    b, a = _spec_filter(1.5, 2, 100.0)
    _, F = signal.freqz(b, a, worN=[0.5], fs=100.0)
    assert z["sensor_amplitude_ratio"]["predicted"] == pytest.approx(abs(F[0]), rel=1e-12)
    assert z["sensor_phase_deg"]["monte_carlo"]["value"] == pytest.approx(-math.degrees(np.angle(F[0])),
                                                                          abs=0.05)
    k = comp["kf_array"]["z"]
    assert k["amplitude_ratio"]["predicted"] == pytest.approx(
        k["estimator_amplitude_ratio"]["predicted"] * k["sensor_amplitude_ratio"]["predicted"], rel=1e-12)
    assert k["phase_deg"]["predicted"] == pytest.approx(
        k["estimator_phase_deg"]["predicted"] + k["sensor_phase_deg"]["predicted"], abs=1e-9)


STATIC_GS = """
name = "static_gs"
sample_rate_hz = 100.0
duration_s = 6.0
seed = 2
effects = [
  { effect = "arw", n_deg_rt_h = 0.1 },
  { effect = "g_sensitivity", gyro = 1, deg_s_per_g = [0.05, -0.02, 0.1] },
  { effect = "g_sensitivity", gyro = 2, deg_s_per_g = [0.0, 0.03, -0.04] },
  { effect = "g_sensitivity", gyro = 4, deg_s_per_g = [0.2, 0.0, 0.07] },
]
[layout]
scheme = 2
n_gyros = 5
alpha_deg = 63.4349
[motion]
profile = "p003_static_1h"
"""


def test_g_sensitivity_on_a_level_static_table_is_pinv_of_k_dot_g(tmp_path):
    k = np.zeros((5, 3))
    k[0], k[1], k[3] = (0.05, -0.02, 0.1), (0.0, 0.03, -0.04), (0.2, 0.0, 0.07)      # (deg/s)/g
    e = k @ np.array([0.0, 0.0, 1.0])                         # gyro i: k_i · f / g0 [deg/s]
    path = tmp_path / "static_gs.toml"
    path.write_text(STATIC_GS)
    sc = load_scenario(path)
    H = sc.layout.H
    fused = np.linalg.pinv(H) @ e
    res = run_scenario(sc, ["gls", "ols", "naive"])
    np.testing.assert_allclose(res.single_gyro["g_sensitivity_rms_deg_s"], np.abs(e), rtol=1e-9, atol=1e-12)
    for nm in ("gls", "ols"):
        got = res.table[res.table.estimator == nm].set_index("axis")["g_sensitivity_rms_deg_s"]
        np.testing.assert_allclose([got[a] for a in "xyz"], np.abs(fused), rtol=1e-9, atol=1e-12)
    # the closed form through the predictor's own function, with the signed mean
    coeff = units.deg_s_per_g_to_rad_s_per_m_s2(k)
    est = get_estimator("gls")().fit(sc.layout, sc.model, 0.01)
    r = g_sensitivity_error(coeff, np.array([0.0, 0.0, G0_M_S2]), est.linear_system().dc_gain())
    np.testing.assert_allclose([r["fused_mean_deg_s"][a] for a in "xyz"], fused, rtol=1e-12, atol=1e-15)
    # and the predicted mean error of a noise-free run carries it: estimate(F(e)) = pinv(H) e
    p = predict(est, sc.model, n_samples=600)
    assert p.g_sensitivity["per_gyro_rms_deg_s"] == pytest.approx(list(np.abs(e)), rel=1e-12)
    for i, ax in enumerate("xyz"):
        assert p.axes[ax]["mean_deg_s"] >= abs(fused[i]) * (1 - 1e-9)


def test_recommend_says_when_the_sensor_limits_tracking():
    g = GyroNoise(arw_deg_rt_h=0.5, rrw_deg_h_rt_h=30.0)
    base = dict(rate_hz=100.0, horizon_s=20.0, ns=(4,), schemes=(1,), estimators=("kf_array", "gls"),
                swing=Swing(units.deg_s_to_rad_s(20.0), 2.0))
    res = recommend(g, DesignSpace(**base, sensor_bandwidth=(12.0, 2)))
    lim = res["tracking_limit"]
    b, a = _spec_filter(12.0, 2, 100.0)
    _, F = signal.freqz(b, a, worN=[2.0], fs=100.0)
    assert lim["limited_by"] == "sensor"
    assert "the sensor bandwidth, not the" in lim["statement"]
    assert lim["sensor_amplitude_ratio"] == pytest.approx(abs(F[0]), rel=1e-12)
    assert lim["sensor_tracking_error_share"] == pytest.approx(abs(1 - F[0]), rel=1e-9)
    assert lim["sensor_tracking_error_share"] > lim["estimator_tracking_error_share"]
    # a wide sensor and a slow estimator: the estimator limits it
    res = recommend(g, DesignSpace(**{**base, "swing": Swing(units.deg_s_to_rad_s(20.0), 0.5)},
                                   bandwidth_hz=(1.0, 1.0), sensor_bandwidth=(45.0, 1)))
    assert res["tracking_limit"]["limited_by"] == "estimator"
    # the sensor's filter costs accuracy: the same search without it predicts less error
    free = recommend(g, DesignSpace(**base))
    with_s = recommend(g, DesignSpace(**base, sensor_bandwidth=(12.0, 2)))
    assert with_s["recommended"]["rms_3axis_deg_s"] > free["recommended"]["rms_3axis_deg_s"]


def test_fast_path_with_a_sensor_equals_the_full_predictor():
    from gyroarray.design.recommend import generic_design, generic_or_fast
    g = GyroNoise(arw_deg_rt_h=0.15, rrw_deg_h_rt_h=40.0, bi_deg_h=5.0, rho_arw=0.2, rho_rrw=0.2)
    space = DesignSpace(rate_hz=100.0, horizon_s=20.0, swing=Swing(math.radians(5.0), 1.5),
                        bandwidth_hz=(0.5, 40.0), sensor_bandwidth=(8.0, 2))
    for est, bw in (("kf_array", 3.0), ("gls", 2.0), ("naive", None)):
        fast = generic_or_fast(1, 6, est, 0.9, bw, 0.2, g, space)
        full = generic_design(1, 6, est, 0.9, bw, 0.2, space, g, 0)
        for ax in "xyz":
            for key, v in full["predicted"][ax].items():
                if v is not None:
                    assert fast["predicted"][ax][key] == pytest.approx(v, rel=1e-9, abs=1e-12), (est, key)


def test_recommend_g_sensitivity_is_pinv_applied_to_the_common_error():
    """Every gyro alike: e = k·[0, 0, g0]/g0 on each; on Scheme 1 the fused error is (0, 0, k_z/cos α)."""
    g = GyroNoise(arw_deg_rt_h=0.5)
    res = recommend(g, DesignSpace(horizon_s=20.0, ns=(4,), schemes=(1,), estimators=("gls",),
                                   g_sensitivity_deg_s_per_g=(0.3, -0.1, 0.1)))
    rec = res["recommended"]
    H = Layout.conical(1, 4, math.radians(rec["alpha_deg"])).H
    fused = np.linalg.pinv(H) @ np.full(4, 0.1)
    gs = res["g_sensitivity"]
    assert gs["per_gyro_rms_deg_s"] == pytest.approx(0.1, rel=1e-12)
    assert [gs["fused_rms_deg_s"][a] for a in "xyz"] == pytest.approx(list(np.abs(fused)), rel=1e-9, abs=1e-12)
    assert gs["fused_rms_deg_s"]["z"] == pytest.approx(0.1 / math.cos(math.radians(rec["alpha_deg"])), rel=1e-9)
    assert "g-sensitivity" in gs["statement"]


@pytest.mark.parametrize("value, why", [("-5", "from 0.0001 Hz"), ("12,3", "1 or 2"), ("50", "Nyquist"),
                                        ("12,1.5", "1 or 2"), ("1,2,3", "HZ or HZ,ORDER")])
def test_bad_sensor_bandwidth_is_one_line_exit_2(capsys, value, why):
    code = main(["design", "--recommend", "--arw", "0.5", f"--sensor-bandwidth={value}", "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and why in err and "Traceback" not in err


def test_design_json_carries_the_sensor_numbers(capsys):
    code = main(["design", "--recommend", "--arw", "0.5", "--rrw", "30", "--n", "4", "--horizon-s", "20",
                 "--swing", "20,2", "--sensor-bandwidth", "12,2", "--g-sensitivity", "0.05",
                 "--estimators", "gls", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    res = json.loads(out)
    z = res["recommended"]["predicted"]["z"]
    assert {"sensor_amplitude_ratio", "sensor_phase_deg", "estimator_amplitude_ratio",
            "estimator_phase_deg", "amplitude_ratio", "phase_deg"} <= set(z)
    assert res["tracking_limit"]["limited_by"] == "sensor"
    assert res["assumptions"]["sensor_bandwidth"]["value"] == {"cutoff_hz": 12.0, "order": 2}
    assert res["g_sensitivity"]["per_gyro_rms_deg_s"] == pytest.approx(0.05)


def test_recommend_takes_the_sensor_bandwidth_from_the_model(tmp_path, capsys):
    path = tmp_path / "m.toml"
    path.write_text('effects = [ { effect = "arw", n_deg_rt_h = 0.5 },\n'
                    '  { effect = "bandwidth", gyro = 1, cutoff_hz = 20.0, order = 1 },\n'
                    '  { effect = "bandwidth", gyro = 2, cutoff_hz = 15.0, order = 2 } ]\n')
    code = main(["design", "--recommend", "--model", str(path), "--n", "4", "--horizon-s", "20",
                 "--swing", "20,2", "--estimators", "gls", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    res = json.loads(out)
    src = res["assumptions"]["sensor_bandwidth"]
    assert src["value"] == {"cutoff_hz": 15.0, "order": 2} and src["source"].startswith("model")
    b, a = _spec_filter(15.0, 2, 100.0)
    _, F = signal.freqz(b, a, worN=[2.0], fs=100.0)
    assert res["tracking_limit"]["sensor_amplitude_ratio"] == pytest.approx(abs(F[0]), rel=1e-12)
    assert "bandwidth" not in res["assumptions"]["ignored_effects"]["value"]
    # without the filter the same design tracks better
    assert res["tracking_limit"]["rms_3axis_without_sensor_filter_deg_s"] < res["recommended"]["rms_3axis_deg_s"]


def test_run_refuses_a_sensor_cutoff_above_nyquist_naming_the_file(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(SWING_BW.replace("cutoff_hz = 1.5", "cutoff_hz = 60.0"))
    code = main(["run", str(path), "--json"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "bad.toml" in err and "Nyquist" in err
