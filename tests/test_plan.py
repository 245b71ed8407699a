"""``gyroarray plan``: how long to record for a precision on ARW, bias instability and RRW
(issue 33, item 4).

Outside check: the predicted 1σ (the Allan GLS fit's own, on the model's noise-free curve) is
compared with the spread of the same fit on records simulated with plain numpy (white noise +
a cumulative sum), not with gyroarray's simulator.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroarray.analysis.allan import allan_analysis
from gyroarray.chain.plan import plan_record, predicted_sigma
from gyroarray.cli.plan import parse_precision
from gyroarray.core import units
from hostile import assert_contract, run_cli

RATE = 10.0
N = units.arw_deg_rt_h_to_rad_rt_s(0.5)
K = units.rrw_deg_h_rt_h_to_rad_s_rt_s(50.0)


def _spread(n_records: int, duration_s: float, seed: int) -> tuple[float, float]:
    """Relative standard deviations of the fitted N and K over numpy-simulated records."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / RATE
    n = int(round(duration_s * RATE))
    ns, ks = [], []
    for _ in range(n_records):
        rate = N / math.sqrt(dt) * rng.standard_normal(n) + \
            np.cumsum(K * math.sqrt(dt) * rng.standard_normal(n))
        fit = allan_analysis(rate, dt, terms=("n", "k")).fit
        ns.append(fit.n_rad_rt_s)
        ks.append(fit.k_rad_s_rt_s)
    return float(np.std(ns, ddof=1) / N), float(np.std(ks, ddof=1) / K)


def _check_against_monte_carlo(n_records: int, bound: float) -> None:
    plan = plan_record({"n": N, "k": K}, RATE, 0.2)            # ±20 % on K: a short record
    length = plan.duration_s["k"]
    assert 1000.0 < length < 20000.0
    sig = predicted_sigma({"n": N, "k": K}, RATE, length)
    assert sig["k"] / K == pytest.approx(0.2, rel=0.05)       # the plan met its precision
    mc_n, mc_k = _spread(n_records, length, seed=11)
    assert mc_k / (sig["k"] / K) == pytest.approx(1.0, abs=bound), (mc_k, sig["k"] / K)
    assert mc_n / (sig["n"] / N) == pytest.approx(1.0, abs=bound), (mc_n, sig["n"] / N)


def test_predicted_half_width_matches_the_spread_of_fits_fast():
    """40 records: the sample standard deviation itself scatters by 1/√(2·39) = 11 %, so the
    issue's 15 % is widened by two of those, to 38 % (200 records, 15 %: the slow test)."""
    _check_against_monte_carlo(40, 0.15 + 2.0 / math.sqrt(2.0 * 39))


@pytest.mark.slow   # 200 records of 4000 s at 10 Hz (about 20 s): make score
def test_predicted_half_width_matches_the_spread_of_fits_200_records():
    _check_against_monte_carlo(200, 0.15)


def test_record_length_scales_as_the_inverse_square_of_the_precision():
    """σ ∝ 1/√T: halving the precision asks about four times the record (octave steps aside)."""
    coef = {"n": N, "b": units.deg_h_to_rad_s(2.0), "k": K}
    p10 = plan_record(coef, 100.0, 0.10)
    p05 = plan_record(coef, 100.0, 0.05)
    for t in ("b", "k"):
        assert p05.duration_s[t] / p10.duration_s[t] == pytest.approx(4.0, rel=0.35)
    # and each reaches its precision, while a record a third shorter does not
    for t in ("b", "k"):
        rel = predicted_sigma(coef, 100.0, p10.duration_s[t])[t] / coef[t]
        short = predicted_sigma(coef, 100.0, p10.duration_s[t] / 1.5)[t] / coef[t]
        assert rel <= 0.10 < short


def test_confidence_widens_the_record():
    """95 % two-sided is 1.96σ: about 1.96² ≈ 3.8 times the 1σ record."""
    one = plan_record({"n": N, "k": K}, RATE, 0.2).duration_s["k"]
    wide = plan_record({"n": N, "k": K}, RATE, 0.2, confidence=0.95).duration_s["k"]
    assert wide / one == pytest.approx(1.96 ** 2, rel=0.35)


def test_plan_cli_with_a_fitted_model_gives_its_own_sigma(tmp_path):
    """A model written by ``fit --out`` carries 1σ: plan prints it beside the prediction at
    the record's length (--at-h), per gyro."""
    model = tmp_path / "fit.toml"
    model.write_text(
        'effects = [\n'
        '  {effect = "arw", gyro = 1, n_deg_rt_h = 2.1, sigma = {n_deg_rt_h = 0.0015}},\n'
        '  {effect = "rrw", gyro = 1, k_deg_h_rt_h = 76.0, sigma = {k_deg_h_rt_h = 33.0}},\n'
        '  {effect = "arw", gyro = 2, n_deg_rt_h = 2.2},\n'
        '  {effect = "rrw", gyro = 2, k_deg_h_rt_h = 125.0},\n]\n')
    o = run_cli(["plan", "--model", model, "--rate-hz", 100, "--precision", "10%", "--at-h",
                 2.78, "--json"])
    assert_contract(o)
    assert o.code == 0
    g1, g2 = o.json["gyros"]
    k1 = g1["terms"]["rrw_deg_h_rt_h"]
    assert k1["model_sigma_rel"] == pytest.approx(33.0 / 76.0)
    assert 1.0 < k1["record_h"] < 20.0 and 0.05 < k1["precision_at_record"] < 0.5
    assert "model_sigma_rel" not in g2["terms"]["rrw_deg_h_rt_h"]
    o = run_cli(["plan", "--model", model, "--gyro", 1, "--rate-hz", 100])
    assert o.code == 0 and "rrw_deg_h_rt_h" in o.out and "gyro 2" not in o.out


@pytest.mark.parametrize("argv,fragment", [
    (["plan", "--rate-hz", "100"], "--arw"),
    (["plan", "--arw", "0.1", "--rate-hz", "100", "--precision", "150%"], "--precision"),
    (["plan", "--arw", "0.1", "--rate-hz", "100", "--precision", "ten"], "--precision"),
    (["plan", "--arw", "0", "--rate-hz", "100"], "--arw"),
    (["plan", "--arw", "-1", "--rate-hz", "100"], "--arw"),
    (["plan", "--arw", "0.1", "--rate-hz", "0"], "--rate-hz"),
    (["plan", "--arw", "0.1", "--model", "m.toml", "--rate-hz", "100"], "--model"),
])
def test_bad_plan_arguments_are_refused_in_one_line(argv, fragment):
    o = run_cli(argv)
    assert_contract(o)
    assert o.code == 2 and fragment in o.err


def test_parse_precision():
    assert parse_precision("10%") == pytest.approx(0.1)
    assert parse_precision("0.05") == pytest.approx(0.05)


# ---------------------------------------------------------------- the accelerometer (issue 42, item 2)

#: An accelerometer of the ADIS16405's class: VRW 0.25 m/s/√h, acc RW 0.02 m/s²/√h.
VRW_M_S_RT_H, ACC_RW_M_S2_RT_H = 0.25, 0.02
N_A = units.vrw_m_s_rt_h_to_si(VRW_M_S_RT_H)               # [m/s²/√Hz]
K_A = units.accel_rw_m_s2_rt_h_to_si(ACC_RW_M_S2_RT_H)     # [m/s²/√s]


def _acc_spread(n_records: int, duration_s: float, seed: int) -> tuple[float, float]:
    """Relative standard deviations of N_a and K_a fitted to numpy-simulated specific force
    [m/s²] (white + a cumulative sum), each record with gravity's 9.80665 m/s² added."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / RATE
    n = int(round(duration_s * RATE))
    ns, ks = [], []
    for _ in range(n_records):
        acc = 9.80665 + N_A / math.sqrt(dt) * rng.standard_normal(n) + \
            np.cumsum(K_A * math.sqrt(dt) * rng.standard_normal(n))
        fit = allan_analysis(acc, dt, terms=("n", "k")).fit
        ns.append(fit.n_rad_rt_s)
        ks.append(fit.k_rad_s_rt_s)
    return float(np.std(ns, ddof=1) / N_A), float(np.std(ks, ddof=1) / K_A)


def _check_acc_against_monte_carlo(n_records: int, bound: float) -> None:
    """``plan --sensor acc`` (datasheet units in, through the CLI) for ±20 % on K_a: the length
    it gives is the SI plan's, the 1σ predicted there is 20 %, and the spread of fits on numpy
    records of that length matches the predicted 1σ of both terms."""
    o = run_cli(["plan", "--sensor", "acc", "--vrw", VRW_M_S_RT_H, "--acc-rw", ACC_RW_M_S2_RT_H,
                 "--rate-hz", RATE, "--precision", "20%", "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    (d,) = o.json["axes"]
    assert o.json["sensor"] == d["sensor"] == "acc" and d["axis"] is None
    terms = d["terms"]
    assert terms["vrw_m_s_rt_h"]["value"] == pytest.approx(VRW_M_S_RT_H, rel=1e-14)
    assert terms["accel_rw_m_s2_rt_h"]["unit"] == "m/s²/√h"
    length = terms["accel_rw_m_s2_rt_h"]["record_s"]
    assert length == plan_record({"n": N_A, "k": K_A}, RATE, 0.2).duration_s["k"]
    assert 300.0 < length < 20000.0
    sig = predicted_sigma({"n": N_A, "k": K_A}, RATE, length)
    assert sig["k"] / K_A == pytest.approx(0.2, rel=0.05)
    mc_n, mc_k = _acc_spread(n_records, length, seed=23)
    assert mc_k / (sig["k"] / K_A) == pytest.approx(1.0, abs=bound), (mc_k, sig["k"] / K_A)
    assert mc_n / (sig["n"] / N_A) == pytest.approx(1.0, abs=bound), (mc_n, sig["n"] / N_A)


def test_acc_plan_matches_the_spread_of_fits_fast():
    """40 records of about 990 s: as the gyro's, 15 % widened by two of the sample standard
    deviation's own 1/√(2·39) = 11 % scatter, to 38 % (200 records, 15 %: the slow test)."""
    _check_acc_against_monte_carlo(40, 0.15 + 2.0 / math.sqrt(2.0 * 39))


@pytest.mark.slow   # 200 records of about 990 s at 10 Hz (about 7 s): make score
def test_acc_plan_matches_the_spread_of_fits_200_records():
    _check_acc_against_monte_carlo(200, 0.15)


def _acc_model(tmp_path, table: str):
    path = tmp_path / "acc.toml"
    path.write_text('description = "fitted"\neffects = [\n'
                    '  {effect = "arw", gyro = 1, n_deg_rt_h = 2.1},\n]\n\n[accelerometer]\n' + table)
    return path


def test_acc_plan_from_a_model_table_gives_each_axis_and_its_own_sigma(tmp_path):
    """``plan --sensor acc --model M.toml`` reads the ``[accelerometer]`` table ``fit --out``
    writes: one plan per axis (or ``--axis``), each term's relative 1σ from the table beside it,
    and a term the table leaves out is not planned (never planned as 0)."""
    model = _acc_model(tmp_path, 'axes = ["x", "z"]\nn_m_s_rt_h = [0.28, 0.2755]\n'
                                 'k_m_s2_rt_h = [0.0213, 0.0126]\n'
                                 'sigma = {k_m_s2_rt_h = [0.0078, 0.0039]}\n'
                                 'notes = ["b_mg not resolved"]\n')
    o = run_cli(["plan", "--sensor", "acc", "--model", model, "--rate-hz", 100, "--at-h", 2.78, "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    x, z = o.json["axes"]
    assert (x["axis"], z["axis"]) == ("x", "z")
    assert set(x["terms"]) == {"vrw_m_s_rt_h", "accel_rw_m_s2_rt_h"}             # no bi_mg
    kz = z["terms"]["accel_rw_m_s2_rt_h"]
    assert kz["value"] == pytest.approx(0.0126, rel=1e-14)
    assert kz["model_sigma_rel"] == pytest.approx(0.0039 / 0.0126)
    assert "model_sigma_rel" not in z["terms"]["vrw_m_s_rt_h"]
    # the same numbers as the plan of the SI coefficients, converted by hand (÷ 60)
    by_hand = plan_record({"n": 0.2755 / 60.0, "k": 0.0126 / 60.0}, 100.0, 0.1, at_s=2.78 * 3600.0)
    assert kz["record_s"] == pytest.approx(by_hand.duration_s["k"], rel=1e-12)
    assert kz["precision_at_record"] == pytest.approx(by_hand.at_precision["k"], rel=1e-12)
    o = run_cli(["plan", "--sensor", "acc", "--model", model, "--axis", "z", "--rate-hz", 100])
    assert o.code == 0 and "acc_z:" in o.out and "acc_x:" not in o.out and "m/s²/√h" in o.out


@pytest.mark.parametrize("argv,fragment", [
    (["plan", "--sensor", "acc", "--arw", "0.1", "--rate-hz", "100"], "--arw"),
    (["plan", "--vrw", "0.1", "--rate-hz", "100"], "--vrw"),
    (["plan", "--sensor", "acc", "--rate-hz", "100"], "--vrw"),
    (["plan", "--sensor", "acc", "--vrw", "0", "--rate-hz", "100"], "--vrw"),
    (["plan", "--sensor", "acc", "--acc-bi", "-1", "--rate-hz", "100"], "--acc-bi"),
    (["plan", "--sensor", "acc", "--vrw", "0.1", "--gyro", "1", "--rate-hz", "100"], "--gyro"),
    (["plan", "--arw", "0.1", "--axis", "x", "--rate-hz", "100"], "--axis"),
    (["plan", "--sensor", "acc", "--vrw", "0.1", "--model", "m.toml", "--rate-hz", "100"], "--model"),
])
def test_bad_acc_plan_arguments_are_refused_in_one_line(argv, fragment):
    o = run_cli(argv)
    assert_contract(o)
    assert o.code == 2 and fragment in o.err


def test_acc_plan_refuses_a_model_without_the_table_or_the_axis(tmp_path):
    bare = tmp_path / "bare.toml"
    bare.write_text('effects = [\n  {effect = "arw", n_deg_rt_h = 2.1},\n]\n')
    o = run_cli(["plan", "--sensor", "acc", "--model", bare, "--rate-hz", 100])
    assert_contract(o, str(bare))
    assert o.code == 2 and "[accelerometer]" in o.err
    model = _acc_model(tmp_path, 'axes = ["x"]\nn_m_s_rt_h = [0.28]\n')
    o = run_cli(["plan", "--sensor", "acc", "--model", model, "--axis", "y", "--rate-hz", 100])
    assert_contract(o, str(model))
    assert o.code == 2 and "--axis y" in o.err
