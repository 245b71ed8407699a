"""The Cramér–Rao bound and the efficiency of every fitted noise term in ``allan --json`` and
``fit --json`` (issue 45, Done-when 1).

Outside truth: :func:`gyroarray.analysis.crb.crb` called directly on the fitted values the JSON
states, and the closed form sd(K̂) ≥ √(2 τ_K / T)·K (τ_K = N/K) of a white + rate-random-walk
record with T ≫ τ_K. The records are numpy: white rate noise N/√dt plus a cumulative sum of
K√dt increments, written as CSV in deg/s.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gyroarray.analysis import crb
from gyroarray.core import units
from hostile import axes_sidecar, run_cli, write_measurement

N_DEG_RT_H = 0.3                       # ARW [deg/√h]


def _record(folder, name: str, n: int, rate_hz: float, k_deg_h_rt_h: float, seed: int):
    """A one-gyro white + walk record of ``n`` samples; its path."""
    dt = 1.0 / rate_hz
    rng = np.random.default_rng(seed)
    n_si = float(units.arw_deg_rt_h_to_rad_rt_s(N_DEG_RT_H))
    k_si = float(units.rrw_deg_h_rt_h_to_rad_s_rt_s(k_deg_h_rt_h))
    x = n_si / math.sqrt(dt) * rng.standard_normal(n) + np.cumsum(k_si * math.sqrt(dt) * rng.standard_normal(n))
    return write_measurement(folder, name, np.arange(n) * dt, np.degrees(x)[:, None],
                             sidecar=axes_sidecar(1, rate_hz))


# τ_K = 1 s (K = 0.3·3600 deg/h/√h), 50 Hz, T = 400 s: T/τ_K = 400, where the discrete bound sits
# ≈ 2τ_K/T = 0.5 % above the closed form (tests/test_crb.py). Seed 5's five-term Allan fit keeps
# ARW, RRW and a small Q (no bias instability: the closed form is the white + walk model's)
LONG = dict(n=20_000, rate_hz=50.0, k_deg_h_rt_h=N_DEG_RT_H * 3600.0, seed=5)
# τ_K = 0.3/41 h = 26 s, 100 Hz, T = 13 s < τ_K; seed 3's fit keeps an RRW (most seeds fit it 0)
SHORT = dict(n=1_300, rate_hz=100.0, k_deg_h_rt_h=41.0, seed=3)


def _json(argv):
    o = run_cli([*argv, "--json"])
    assert o.code == 0, o.err
    return json.loads(o.out)


@pytest.fixture(scope="module")
def long_record(tmp_path_factory):
    return _record(tmp_path_factory.mktemp("crb_long"), "long", **LONG)


@pytest.fixture(scope="module")
def long_allan(long_record):
    return _json(["allan", long_record, "--whittle"])


def test_allan_k_crb_is_the_bound_and_the_closed_form(long_allan):
    g = long_allan["gyros"]["1"]
    fit, block = g["fit"], g["crb"]
    assert block["model"] == ["arw_deg_rt_h", "rrw_deg_h_rt_h", "q_deg"]     # seed 5's fitted model
    assert block["parts"] == 1 and block["duration_s"] == pytest.approx(400.0, rel=1e-12)
    vals = block["values_si"]
    # the values the bound is taken at are the fit's own (JSON in deg/h/√h, 1e-12: float round trip)
    assert units.rrw_rad_s_rt_s_to_deg_h_rt_h(vals["k"]) == pytest.approx(fit["rrw_deg_h_rt_h"], rel=1e-12)
    direct = crb.crb(vals, 1.0 / LONG["rate_hz"], n_samples=LONG["n"])
    assert fit["rrw_deg_h_rt_h_crb"] == pytest.approx(
        float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(direct.sd["k"])), rel=1e-12)
    assert fit["arw_deg_rt_h_crb"] == pytest.approx(
        float(units.arw_rad_rt_s_to_deg_rt_h(direct.sd["n"])), rel=1e-12)
    # the closed form at the fitted N and K: T/τ_K ≈ 400 puts the finite-record excess at
    # ≈ 2τ_K/T = 0.5 %, the tiny Q a little more; 2 % as the issue asks
    closed = crb.closed_form_k_rel(vals["n"], vals["k"], 400.0) * fit["rrw_deg_h_rt_h"]
    assert fit["rrw_deg_h_rt_h_crb"] == pytest.approx(closed, rel=0.02)
    # the rate ramp has no bound (a drift), a term fitted to 0 none either
    assert fit["r_deg_h2_crb"] is None and fit["bi_deg_h_crb"] is None
    assert "bi_deg_h" in block["not_in_model"]


def test_allan_efficiency_is_crb_over_the_fit_sigma(long_allan):
    fit = long_allan["gyros"]["1"]["fit"]
    for key in ("arw_deg_rt_h", "rrw_deg_h_rt_h"):
        eff = fit[key + "_efficiency"]
        assert eff == pytest.approx((fit[key + "_crb"] / fit[key + "_sigma"]) ** 2, rel=1e-12)
        # no unbiased estimator beats the bound (≤ 1), but the Allan σ is itself an estimate from
        # the one record (the GLS σ at the fitted values, ~10-20 % off at this length): 1.2 allows
        # that; the Allan fit of K reads 0.65-0.78 on seeds 1-8 (issue 45: 0.72-0.82 planned)
        assert 0.0 < eff <= 1.2, (key, eff)
    assert not [n for n in long_allan["notes"] if "too short to resolve" in n and "RRW" in n]


def test_allan_whittle_second_estimate(long_allan):
    w = long_allan["gyros"]["1"]["whittle"]
    assert w["model"] == ["arw_deg_rt_h", "rrw_deg_h_rt_h", "q_deg"] and w["converged"]
    k_true = LONG["k_deg_h_rt_h"]
    # K's bound here is ≈ 7 % (√(2/400)): the ML estimate lies within 4σ of the truth (fails on
    # < 1e-4 of seeds for an efficient estimator)
    assert abs(w["values"]["rrw_deg_h_rt_h"] - k_true) <= 4.0 * w["crb"]["rrw_deg_h_rt_h"]
    # the tapered Whittle estimator's efficiency is 1/κ of the 5 % Tukey taper, κ = 1.026
    # (analysis.whittle's Notes; within 1e-3 for a 20 000-sample part)
    assert w["efficiency"]["rrw_deg_h_rt_h"] == pytest.approx(1.0 / 1.026, abs=1e-3)
    assert w["taper_fraction"] == 0.05 and "Fourier" in w["band"]


def test_allan_without_whittle_keeps_the_bounds(long_record):
    g = _json(["allan", long_record])["gyros"]["1"]          # the Whittle fit is asked for (--whittle)
    assert g["whittle"] is None and g["fit"]["rrw_deg_h_rt_h_crb"] > 0


@pytest.mark.slow
def test_fit_carries_crb_for_arw_and_rrw(long_record):
    out = _json(["fit", long_record, "--runs", "5"])
    by = {d["effect"]: d for d in out["effects"] if d["gyro"] == 1}
    arw, rrw = by["arw"], by["rrw"]
    values = {"n": float(units.arw_deg_rt_h_to_rad_rt_s(arw["params"]["n_deg_rt_h"])),
              "k": float(units.rrw_deg_h_rt_h_to_rad_s_rt_s(rrw["params"]["k_deg_h_rt_h"]))}
    # fit's baseline model is ARW + RRW: the bound of that model at its values, this record
    direct = crb.crb(values, 1.0 / LONG["rate_hz"], n_samples=LONG["n"])
    assert out["crb"]["parts"] == 1 and out["crb"]["duration_s"] == pytest.approx(400.0, rel=1e-12)
    assert rrw["crb"]["k_deg_h_rt_h"] == pytest.approx(
        float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(direct.sd["k"])), rel=1e-12)
    assert arw["crb"]["n_deg_rt_h"] == pytest.approx(
        float(units.arw_rad_rt_s_to_deg_rt_h(direct.sd["n"])), rel=1e-12)
    # T/τ_K ≈ 400: the closed form to 2 % (as for allan)
    closed = crb.closed_form_k_rel(values["n"], values["k"], 400.0) * rrw["params"]["k_deg_h_rt_h"]
    assert rrw["crb"]["k_deg_h_rt_h"] == pytest.approx(closed, rel=0.02)
    for d, p in ((arw, "n_deg_rt_h"), (rrw, "k_deg_h_rt_h")):
        assert d["efficiency"][p] == pytest.approx((d["crb"][p] / d["sigma"][p]) ** 2, rel=1e-12)
        assert 0.0 < d["efficiency"][p] <= 1.2              # as for allan: the fit's σ is an estimate


def test_allan_says_a_record_shorter_than_tau_k_cannot_resolve_k(tmp_path):
    out = _json(["allan", _record(tmp_path, "short", **SHORT)])
    fit, block = out["gyros"]["1"]["fit"], out["gyros"]["1"]["crb"]
    tau_k = N_DEG_RT_H / SHORT["k_deg_h_rt_h"] * 3600.0           # 26 s against T = 13 s
    assert SHORT["n"] / SHORT["rate_hz"] < tau_k
    assert "rrw_deg_h_rt_h" in block["model"]
    assert fit["rrw_deg_h_rt_h_crb"] >= 0.5 * fit["rrw_deg_h_rt_h"]
    assert "rrw_deg_h_rt_h" in block["unresolvable"]
    said = [n for n in out["notes"] if "too short to resolve" in n]
    assert len(said) == 1 and "RRW" in said[0] and "gyro 1" in said[0]
    # and the Allan fit's σ of K, below the bound there, is called too small
    if fit["rrw_deg_h_rt_h_efficiency"] > 1.2:
        assert any("below the Cramér–Rao bound" in n and "RRW" in n for n in out["notes"])
