"""Effects declare their predictor term; the predictor, the estimators and the error budget ask them.

Outside truth, per test:

* the source itself (an AST walk): no effect-name literal in the predictor, the budget or
  the estimators;
* closed forms written here for a static GLS with fixed weights W (no filter):
  white noise, E|θ_T|² = n·dt²·tr(W R Wᵀ); the random walk from b_{−1} = 0,
  E|e_k|² = (k + 1)·tr(W Q Wᵀ), E|θ_T|² = dt²·tr(W Q Wᵀ)·n(n + 1)(2n + 1)/6; scale factor,
  misalignment, g-sensitivity and a temperature coefficient at a stated motion,
  e = W·d(t) with d the per-gyro error written out here;
* a Monte Carlo of the simulator's flicker process (``core.physics.flicker_noise``) through
  W, with a 4σ interval of the mean square;
* the predictor's own full prediction (a second code path) for the budget's total;
* the CLI as a user runs it for the example plugin ``examples/plugins/warmup_bias.py``:
  simulated, found by ``diagnose``, fitted by ``fit --add``, and its own term of the budget
  (closed form through W).
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from gyroarray.core import units
from gyroarray.core.constants import G0_M_S2
from gyroarray.core.layout import Layout
from gyroarray.core.physics import flicker_noise, tilted_axes
from gyroarray.design import predict as predict_mod
from gyroarray.design.budget import error_budget, linear_response
from gyroarray.design.predict import Swing, predict
from gyroarray.effects import REGISTRY
from gyroarray.effects import terms as T
from gyroarray.effects.model import ModelEntry as E, NoiseModel
from gyroarray.estimators import get_estimator
from gyroarray.estimators.base import LinearSystem
from gyroarray.estimators.noise import array_noise

from hostile import assert_contract, run_cli

ROOT = Path(__file__).resolve().parents[1]
PLUGIN = ROOT / "examples" / "plugins" / "warmup_bias.py"
DT = 0.01
LAYOUT = Layout.conical(1, 6, math.radians(54.7356))


def static_gls(H: np.ndarray, R: np.ndarray) -> tuple[LinearSystem, np.ndarray]:
    """ω̂_k = W z_k with W = (HᵀR⁻¹H)⁻¹HᵀR⁻¹ fixed: a memoryless linear system and W."""
    Ri = np.linalg.inv(R)
    W = np.linalg.solve(H.T @ Ri @ H, H.T @ Ri)
    eye = np.eye(3)
    return LinearSystem(A=np.zeros((3, 3)), K=W, C=eye, X0=np.zeros((3, H.shape[0])),
                        lam=np.zeros(3), S=eye, S_inv=eye), W


def rms_deg_s(ms_rad2: float) -> float:
    return float(units.rad_s_to_deg_s(math.sqrt(ms_rad2)))


def angle_deg(sum_sq_rad2: float) -> float:
    return float(units.rad_to_deg(math.sqrt(sum_sq_rad2)))


# -- no hand list ----------------------------------------------------------------------------

def _literals(path: Path) -> list[tuple[int, str]]:
    names = set(REGISTRY)
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in names:
            out.append((node.lineno, node.value))
    return out


def test_no_effect_name_literal_in_the_predictor_the_budget_or_the_estimators():
    src = ROOT / "src" / "gyroarray"
    files = [src / "design" / "predict.py", src / "design" / "budget.py",
             *sorted((src / "estimators").glob("*.py"))]
    found = {str(f.relative_to(ROOT)): lits for f in files if (lits := _literals(f))}
    assert found == {}, f"effect names spelled out (ask the effect's declaration instead): {found}"


def test_the_built_in_effects_declare_their_terms():
    declared = predict_mod.declared_terms()
    want = {"arw": T.WhiteTerm, "rrw": T.WalkTerm, "correlation": T.CorrelationTerm,
            "bias_instability": T.FlickerTerm, "gauss_markov": T.GaussMarkovTerm,
            "bandwidth": T.SensorFilter, "g_sensitivity": T.ForceTerm, "scale_factor": T.ScaleTerm,
            "misalignment": T.AxisTerm, "temperature_bias": T.TemperatureTerm, "quantization": None,
            "sinusoid": T.LineTerm, "narrowband_line": T.LineTerm}
    assert {k: declared[k] for k in want} == want
    # the former hand list, now computed from the declarations (its callers keep working)
    assert set(predict_mod.MODELLED) == {"arw", "rrw", "correlation", "bias_instability",
                                         "gauss_markov", "bandwidth", "g_sensitivity"}


def test_ignored_is_what_declares_no_term_or_lacks_its_input():
    model = NoiseModel((E("arw", None, {"n_deg_rt_h": 0.1}), E("rrw", None, {"k_deg_h_rt_h": 50.0}),
                        E("quantization", None, {"q_deg": 1e-3}),
                        E("temperature_bias", 2, {"deg_h_per_c": 20.0, "t0_c": 25.0}),
                        E("scale_factor", None, {"ppm": 300.0})))
    est = get_estimator("gls")().fit(LAYOUT, model, DT)
    p = predict(est, model, n_samples=500)
    assert p.ignored == ("quantization", "temperature_bias")
    p = predict(est, model, n_samples=500, temp_swing_k=np.linspace(0.0, 5.0, 500))
    assert p.ignored == ("quantization",)
    b = error_budget(est.linear_system(), LAYOUT.H, model, n_samples=500, dt_s=DT)
    assert b.ignored == ["quantization", "temperature_bias"] and "scale_factor" in b.terms
    assert array_noise(model, 6).ignored_effects == ("quantization", "scale_factor", "temperature_bias")


# -- the budget against closed forms ------------------------------------------------------------

def _noise_model(**kw):
    e = [E("arw", None, {"n_deg_rt_h": kw.get("arw", 0.15)}), E("arw", 2, {"n_deg_rt_h": 0.3})]
    if kw.get("rrw"):
        e.append(E("rrw", None, {"k_deg_h_rt_h": kw["rrw"]}))
    if kw.get("bi"):
        e.append(E("bias_instability", None, {"b_deg_h": kw["bi"]}))
    if kw.get("rho"):
        e.append(E("correlation", None, {"rho_arw": kw["rho"], "rho_rrw": kw["rho"]}))
    return NoiseModel(tuple(e) + tuple(kw.get("extra", ())))


def test_white_and_walk_terms_are_the_closed_forms_of_a_fixed_gls():
    n, k0 = 3000, 200
    model = _noise_model(rrw=40.0, rho=0.3)
    an = array_noise(model, 6)
    R, Q = an.R(DT), an.Qb(DT)
    sys, W = static_gls(LAYOUT.H, np.eye(6))                       # fixed weights: not R's
    b = error_budget(sys, LAYOUT.H, model, n_samples=n, dt_s=DT, settle_s=k0 * DT)
    tw, tq = np.trace(W @ R @ W.T), np.trace(W @ Q @ W.T)
    assert b.terms["arw"]["rms_deg_s"] == pytest.approx(rms_deg_s(tw), rel=1e-10)
    assert b.terms["arw"]["angle_deg"] == pytest.approx(angle_deg(n * DT ** 2 * tw), rel=1e-10)
    ks = np.arange(k0, n)
    assert b.terms["rrw"]["rms_deg_s"] == pytest.approx(rms_deg_s(np.mean(ks + 1) * tq), rel=1e-10)
    assert b.terms["rrw"]["angle_deg"] == pytest.approx(
        angle_deg(DT ** 2 * tq * n * (n + 1) * (2 * n + 1) / 6), rel=1e-10)
    assert b.modifiers == ["correlation"]
    # independent zero-mean terms: the total is their quadrature sum
    for key in ("rms_deg_s", "angle_deg"):
        assert b.total[key] == pytest.approx(math.hypot(b.terms["arw"][key], b.terms["rrw"][key]), rel=1e-10)


def test_flicker_term_inside_a_monte_carlo_of_the_simulated_process():
    n, k0, runs = 1500, 100, 400
    model = _noise_model(bi=400.0)
    sys, W = static_gls(LAYOUT.H, np.eye(6))
    b = error_budget(sys, LAYOUT.H, model, n_samples=n, dt_s=DT, settle_s=k0 * DT)
    rng = np.random.default_rng(20261128)
    bi = np.full(6, units.deg_h_to_rad_s(400.0))
    ms, ang = np.empty(runs), np.empty(runs)
    for r in range(runs):
        gens = [np.random.default_rng(rng.integers(2 ** 63)) for _ in range(6)]
        e = flicker_noise(n, DT, bi, gens) @ W.T
        ms[r] = np.mean(np.sum(e[k0:] ** 2, axis=1))
        ang[r] = np.sum((DT * e.sum(axis=0)) ** 2)
    for key, x, conv in (("rms_deg_s", ms, rms_deg_s), ("angle_deg", ang, angle_deg)):
        lo = conv(max(x.mean() - 4 * x.std(ddof=1) / math.sqrt(runs), 0.0))
        hi = conv(x.mean() + 4 * x.std(ddof=1) / math.sqrt(runs))
        assert lo <= b.terms["bias_instability"][key] <= hi, (key, lo, b.terms["bias_instability"][key], hi)


def test_deterministic_terms_are_w_times_the_declared_gyro_error():
    n, k0 = 800, 100
    H = LAYOUT.H
    ppm = np.array([500.0, -300.0, 0.0, 800.0, 100.0, -50.0])
    kg = np.zeros((6, 3))
    kg[1], kg[4] = (0.02, -0.01, 0.05), (0.0, 0.03, -0.02)        # (deg/s)/g
    extra = [E("scale_factor", g + 1, {"ppm": float(p)}) for g, p in enumerate(ppm)]
    extra += [E("misalignment", 3, {"tilt_deg": 0.4, "tilt_azimuth_deg": 30.0}),
              E("misalignment", 5, {"axis": (0.1, 0.2, 0.97467943448)}),
              E("g_sensitivity", 2, {"deg_s_per_g": tuple(kg[1])}),
              E("g_sensitivity", 5, {"deg_s_per_g": tuple(kg[4])}),
              E("temperature_bias", 6, {"deg_h_per_c": 30.0, "t0_c": 20.0}),
              E("sinusoid", 2, {"amp_deg_s": 0.04, "freq_hz": 3.3, "phase_deg": 40.0}),
              E("sinusoid", 4, {"amp_deg_s": 0.02, "freq_hz": 11.0})]
    model = _noise_model(extra=extra)
    sys, W = static_gls(H, np.eye(6))
    w0 = units.deg_s_to_rad_s(np.array([100.0, -40.0, 60.0]))        # a constant rate
    dT = np.linspace(0.0, 8.0, n)                                    # a temperature swing [K]
    motion = T.Motion(omega_rad_s=np.tile(w0, (n, 1)), temp_swing_k=dT)
    b = error_budget(sys, H, model, n_samples=n, dt_s=DT, settle_s=k0 * DT, motion=motion)

    def const(e3):                                                   # a constant 3-axis error
        return {"rms_deg_s": rms_deg_s(e3 @ e3), "angle_deg": angle_deg((n * DT) ** 2 * (e3 @ e3))}
    true = H.copy()
    true[2] = tilted_axes(H[2:3], [math.radians(0.4)], [math.radians(30.0)])[0]
    a5 = np.array([0.1, 0.2, 0.97467943448])
    true[4] = a5 / np.linalg.norm(a5)
    want = {"scale_factor": const(W @ (ppm * 1e-6 * (H @ w0))),
            "misalignment": const(W @ ((true - H) @ w0)),
            "g_sensitivity": const(W @ (units.deg_s_per_g_to_rad_s_per_m_s2(kg) @ [0.0, 0.0, G0_M_S2]))}
    c6 = np.zeros(6)
    c6[5] = units.deg_h_to_rad_s(30.0)
    wc = W @ c6
    want["temperature_bias"] = {"rms_deg_s": rms_deg_s(np.mean(dT[k0:] ** 2) * (wc @ wc)),
                                "angle_deg": angle_deg((DT * dT.sum()) ** 2 * (wc @ wc))}
    t = np.arange(n) * DT                                            # the two lines, written out
    d = np.zeros((n, 6))
    d[:, 1] = units.deg_s_to_rad_s(0.04) * np.sin(2 * np.pi * 3.3 * t + math.radians(40.0))
    d[:, 3] = units.deg_s_to_rad_s(0.02) * np.sin(2 * np.pi * 11.0 * t)
    e = d @ W.T
    want["sinusoid"] = {"rms_deg_s": rms_deg_s(np.mean(np.sum(e[k0:] ** 2, axis=1))),
                        "angle_deg": angle_deg(np.sum((DT * e.sum(axis=0)) ** 2))}
    for name, row in want.items():
        for key in row:
            assert b.terms[name][key] == pytest.approx(row[key], rel=1e-9), (name, key)
    assert b.tracking["rms_deg_s"] < 1e-12                          # W H = I: no lag
    assert b.ignored == []


def test_budget_total_equals_the_full_prediction():
    """Two code paths: the budget's total (every term at once) and predict() per axis."""
    n = 2000
    extra = (E("gauss_markov", 4, {"sigma_deg_h": 200.0, "tau_s": 0.5}),
             E("bandwidth", None, {"cutoff_hz": 15.0, "order": 2}),
             E("scale_factor", None, {"ppm": 2000.0}),
             E("g_sensitivity", 1, {"deg_s_per_g": (0.05, 0.0, -0.02)}))
    model = _noise_model(rrw=300.0, bi=30.0, rho=0.2, extra=extra)
    est = get_estimator("kf_array")(bandwidth_hz=5.0).fit(LAYOUT, model, DT)
    swing = Swing(units.deg_s_to_rad_s(30.0), 0.7)
    p = predict(est, model, n_samples=n, swing=swing)
    b = error_budget(est.linear_system(), LAYOUT.H, model, n_samples=n, dt_s=DT, motion=swing)
    for key in ("rms_deg_s", "angle_deg"):
        assert b.total[key] == pytest.approx(math.sqrt(sum(p.axes[a][key] ** 2 for a in "xyz")), rel=1e-9)
    assert set(b.terms) == {"arw", "rrw", "bias_instability", "gauss_markov", "scale_factor", "g_sensitivity"}
    assert b.modifiers == ["correlation", "bandwidth"] and b.tracking["rms_deg_s"] > 0


def test_linear_response_is_the_plain_recursion():
    model = _noise_model(rrw=300.0)
    est = get_estimator("kf_array")(bandwidth_hz=3.0).fit(LAYOUT, model, DT)
    sys = est.linear_system()
    z = np.random.default_rng(5).standard_normal((300, 6)) * 0.01
    x = sys.X0 @ z[0]
    want = np.empty((300, 3))
    for k in range(300):
        x = sys.A @ x + sys.K @ z[k]
        want[k] = sys.C @ x
    np.testing.assert_allclose(linear_response(sys, z), want, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(linear_response(sys, z), est.estimate(z), rtol=1e-9, atol=1e-12)


def test_tactical_gyro_bias_instability_is_the_largest_angle_term():
    """Issue 30: ARW 0.15 deg/√h, BI 3 deg/h, RRW 1 deg/h/√h, 1 h, a 6-gyro array."""
    dt, n = 0.1, 36000
    model = NoiseModel((E("arw", None, {"n_deg_rt_h": 0.15}), E("bias_instability", None, {"b_deg_h": 3.0}),
                        E("rrw", None, {"k_deg_h_rt_h": 1.0})))
    est = get_estimator("gls")().fit(LAYOUT, model, dt)
    b = error_budget(est.linear_system(), LAYOUT.H, model, n_samples=n, dt_s=dt)
    assert b.largest("angle_deg") == "bias_instability"
    assert b.terms["bias_instability"]["angle_deg"] > 1.5 * max(b.terms["rrw"]["angle_deg"],
                                                               b.terms["arw"]["angle_deg"])
    # the other two through the closed forms of GLS: tr((HᵀH)⁻¹) = 3/2 for this cone
    g = math.sqrt(np.trace(np.linalg.inv(LAYOUT.H.T @ LAYOUT.H)))
    assert b.terms["arw"]["angle_deg"] == pytest.approx(0.15 * g, rel=1e-6)
    assert b.terms["rrw"]["angle_deg"] == pytest.approx(1.0 * g / math.sqrt(3.0), rel=1e-3)
    d = b.to_dict()
    assert d["largest_angle_term"] == "bias_instability" and d["ignored_effects"] == []


# -- a plugin effect with a predictor term ------------------------------------------------------

SCENARIO = '''
name = "warmup_run"
description = "4-gyro array, 30 min static, gyro 2 warming up"
sample_rate_hz = 50.0
duration_s = 1800.0
seed = 11
effects = [
  { effect = "arw", n_deg_rt_h = 0.15 },
  { effect = "rrw", k_deg_h_rt_h = 5.0 },
  { effect = "warmup_bias", gyro = 2, amp_deg_h = 60.0, tau_s = 150.0 },
]

[layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356

[motion]
profile = "p003_static_1h"
'''


@pytest.fixture(scope="module", autouse=True)
def _plugin_taken_out_again():
    """The plugin is registered in this process by the calls below: out again afterwards."""
    yield
    from gyroarray.effects import unregister
    unregister("warmup_bias")


@pytest.fixture(scope="module")
def warmup_record(tmp_path_factory):
    folder = tmp_path_factory.mktemp("warmup")
    scen = folder / "warmup_run.toml"
    scen.write_text(SCENARIO)
    o = run_cli(["simulate", scen, "--out", folder / "out", "--plugin", PLUGIN, "--json"], timeout=600)
    assert_contract(o)
    assert o.code == 0, o.err
    return folder / "out" / "warmup_run.csv.gz"


@pytest.mark.slow   # simulate, diagnose and fit the plugin effect (8 s on 2 cores): make score
def test_the_plugin_is_simulated_diagnosed_and_fitted(warmup_record):
    o = run_cli(["diagnose", warmup_record, "--plugin", PLUGIN, "--runs", 20, "--json"], timeout=900)
    assert o.code == 0, o.err
    top = o.json["candidates"][0]
    assert (top["effect"], top["gyro"]) == ("warmup_bias", 2) and top["significant"], o.json["candidates"][:3]
    o = run_cli(["fit", warmup_record, "--add", "warmup_bias:2", "--plugin", PLUGIN, "--runs", 20, "--json"],
                timeout=900)
    assert o.code == 0, o.err
    f = o.json
    assert f["discrepancy_before"] > 2.0 and f["discrepancy_after"] <= 1.0
    entry = next(e for e in f["effects"] if e["effect"] == "warmup_bias")
    p, s = entry["params"], entry["sigma"]
    assert abs(p["amp_deg_h"] - 60.0) <= max(2 * s["amp_deg_h"], 6.0)
    assert abs(p["tau_s"] - 150.0) <= max(2 * s.get("tau_s", 0.0), 15.0)


def test_the_plugin_is_its_own_term_of_the_error_budget():
    from gyroarray.chain.plugins import load_plugin
    assert load_plugin(PLUGIN) == ["warmup_bias"]                 # the load-time conformance checks pass
    model = NoiseModel((E("arw", None, {"n_deg_rt_h": 0.15}), E("rrw", None, {"k_deg_h_rt_h": 5.0}),
                        E("warmup_bias", 2, {"amp_deg_h": 60.0, "tau_s": 150.0})))
    n, dt = 6000, 0.1
    sys, W = static_gls(LAYOUT.H, np.eye(6))
    b = error_budget(sys, LAYOUT.H, model, n_samples=n, dt_s=dt)
    assert list(b.terms) == ["arw", "rrw", "warmup_bias"] and b.ignored == []
    w2 = W[:, 1] * units.deg_h_to_rad_s(60.0)                      # gyro 2's column
    decay = np.exp(-np.arange(n) * dt / 150.0)
    k0 = int(round(2.0 / dt))
    assert b.terms["warmup_bias"]["rms_deg_s"] == pytest.approx(
        rms_deg_s(np.mean(decay[k0:] ** 2) * (w2 @ w2)), rel=1e-9)
    assert b.terms["warmup_bias"]["angle_deg"] == pytest.approx(
        angle_deg((dt * decay.sum()) ** 2 * (w2 @ w2)), rel=1e-9)
    # and the full predictor carries it (not ignored)
    est = get_estimator("gls")().fit(LAYOUT, model, dt)
    p = predict(est, model, n_samples=n)
    assert p.ignored == () and p.components["x"]["motion"] > 0


@pytest.mark.slow   # two 30-minute simulated sessions per statistical check: make score
def test_the_plugin_passes_the_public_conformance_check():
    from gyroarray.chain.plugins import load_plugin
    from gyroarray.chain.testing import check_effect
    load_plugin(PLUGIN)
    check_effect(type(REGISTRY["warmup_bias"]))


def test_a_wandering_line_through_the_filters_is_the_simulated_one():
    """``narrowband_line`` (random start phase, a wandering phase) on two gyros, through
    kf_array and gls: the predicted RMS and 1σ per axis lie in the interval of 60 simulated
    replicates (the simulator's own line, ``rms_ci``: family-wise 95 % by Šidák over the 12
    comparisons); without the line the prediction lies below every interval (the test can
    fail)."""
    from gyroarray.analysis.replicates import replicate_rng, rms_ci
    from gyroarray.design.predict import settle_start
    from gyroarray.sim.effects import simulate_readings
    n, reps = 2000, 60
    lines = (E("narrowband_line", 2, {"amp_deg_s": 0.06, "freq_hz": 1.7, "linewidth_hz": 0.01}),
             E("narrowband_line", 5, {"amp_deg_s": 0.09, "freq_hz": 0.6, "linewidth_hz": 0.002}))
    base = _noise_model(rrw=300.0)
    model = _noise_model(rrw=300.0, extra=lines)
    t = np.arange(n) * DT
    k0 = settle_start(n, DT, 2.0)
    level = (1 - 0.05) ** (1 / 12)
    truth = np.zeros((n, 3))
    for name in ("kf_array", "gls"):
        est = get_estimator(name)().fit(LAYOUT, base, DT)         # designed without the lines
        p = predict(est, model, n_samples=n)
        p0 = predict(est, base, n_samples=n)
        assert "narrowband_line" not in p.ignored
        vals = []
        for r in range(reps):
            z = simulate_readings(model, truth, LAYOUT, DT, replicate_rng(41, r), time_s=t)
            w = est.estimate(z)[k0:]
            vals.append(np.stack([np.sqrt(np.mean(w ** 2, 0)), np.std(w, 0, ddof=1)]))
        arr = units.rad_s_to_deg_s(np.array(vals))
        for a, ax in enumerate("xyz"):
            for m, key in enumerate(("rms_deg_s", "std_deg_s")):
                ci = rms_ci(arr[:, m, a], level)
                assert ci["ci_low"] <= p.axes[ax][key] <= ci["ci_high"], (name, ax, key, ci)
            assert p0.axes[ax]["rms_deg_s"] < rms_ci(arr[:, 0, a], level)["ci_low"], (name, ax)
