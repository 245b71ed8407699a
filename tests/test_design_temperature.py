"""Issue 43 item 2: ``design --temperature-swing C [--temperature-period S]``, so that a model's
temperature terms are evaluated (before: no input for a temperature swing, and an alike model's
deterministic effects never reached the error budget).

The outside check: for fixed-weight GLS the fused rate error of a bias c·ΔT(t) common to every
gyro is M·1·c·ΔT(t), M = (HᵀH)⁻¹Hᵀ of the recommended axes, so its 3-axis RMS over the scored
window [settle, T] is ‖M·1‖·|c|·rms(ΔT) there, computed here in numpy from the JSON's axes.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from hostile import assert_contract, run_cli

C_DEG_H_PER_C = 20.0
SWING_K, PERIOD_S, HORIZON_S, RATE_HZ, SETTLE_S = 5.0, 45.0, 60.0, 100.0, 2.0

MODEL = f"""description = "alike gyros with a temperature coefficient"
effects = [
    {{effect = "arw", n_deg_rt_h = 0.1}},
    {{effect = "rrw", k_deg_h_rt_h = 600.0}},
    {{effect = "temperature_bias", deg_h_per_c = {C_DEG_H_PER_C}, t0_c = 25.0}},
]
"""


def _design(tmp_path, *extra, names_model: bool = True):
    path = tmp_path / "m.toml"
    path.write_text(MODEL)
    o = run_cli(["design", "--recommend", "--model", path, "--alike", "--n", "6", "--horizon-s", HORIZON_S,
                 "--rate-hz", RATE_HZ, "--estimators", "gls", "--json", *extra], timeout=300)
    assert_contract(o, str(path) if names_model else None)
    return o


def test_the_temperature_row_is_the_gls_weights_on_the_swing(tmp_path):
    o = _design(tmp_path, "--temperature-swing", SWING_K, "--temperature-period", PERIOD_S)
    assert o.code == 0, o.err
    res = json.loads(o.out)
    rec = res["recommended"]
    row = rec["error_budget"]["terms"]["temperature_bias"]
    H = np.array(rec["axes"], dtype=float)
    m1 = np.linalg.solve(H.T @ H, H.T @ np.ones(H.shape[0]))          # M·1, the common bias's gain
    dt = 1.0 / RATE_HZ
    t = np.arange(int(round(HORIZON_S * RATE_HZ))) * dt
    dT = SWING_K * np.sin(2 * np.pi * t / PERIOD_S)
    win = t >= SETTLE_S
    c_deg_s = C_DEG_H_PER_C / 3600.0
    want_rms = float(np.linalg.norm(m1)) * c_deg_s * float(np.sqrt(np.mean(dT[win] ** 2)))
    assert row["rms_deg_s"] == pytest.approx(want_rms, rel=2e-3), (row, want_rms)
    # the angle at the horizon: the integral of the error over the run (the held-sample sum)
    want_angle = float(np.linalg.norm(m1)) * c_deg_s * abs(float(np.sum(dT) * dt))
    assert row["angle_deg"] == pytest.approx(want_angle, rel=2e-3, abs=1e-9)
    a = res["assumptions"]["temperature"]
    assert a["source"] == "user" and f"{SWING_K:g} K · sin(2π t / {PERIOD_S:g} s)" in a["value"]


def test_without_a_swing_the_term_is_left_out_and_said(tmp_path):
    res = json.loads(_design(tmp_path).out)
    assert "temperature_bias" not in res["recommended"]["error_budget"]["terms"]
    assert res["assumptions"]["temperature"]["value"].startswith("not stated")
    text = _design(tmp_path, "--temperature-swing", 3).out
    res = json.loads(text)
    row = res["recommended"]["error_budget"]["terms"]["temperature_bias"]
    H = np.array(res["recommended"]["axes"], dtype=float)
    m1 = np.linalg.solve(H.T @ H, H.T @ np.ones(H.shape[0]))
    # a constant 3 K departure: a constant rate error, its angle growing with the horizon
    assert row["rms_deg_s"] == pytest.approx(float(np.linalg.norm(m1)) * C_DEG_H_PER_C / 3600.0 * 3.0, rel=2e-3)
    assert row["angle_deg"] == pytest.approx(row["rms_deg_s"] * HORIZON_S, rel=2e-3)


def test_a_period_without_a_swing_is_refused(tmp_path):
    o = _design(tmp_path, "--temperature-period", 60, names_model=False)   # an option's refusal
    assert o.code == 2 and "--temperature-period S needs --temperature-swing C" in o.err
    assert len(o.err.strip().splitlines()) == 1
