"""Issue 43 item 5: a check that can resolve.

``design --recommend --check K`` says whether K paired runs can resolve the recommendation from
the runner-up on the objective metric, and how many would (K_needed), from the predicted mean
of the paired difference (the predictor, each design at its worst case) and the sd of one
paired difference (a pilot: the first min(K, 20) runs; the predictor does not hold the two
designs' cross-covariance). ``--check auto`` picks K itself, capped at 400.

* :func:`runs_needed` against the normal-theory sample size and the exact power of the
  t-interval (noncentral t), and issue 43's numbers (about 1,500 runs);
* outside check: the pilot's variance of the paired difference against the variance over
  independent runs of a small design (F interval: both are χ² estimates), and the predicted
  mean difference against the runs' mean (Student-t interval);
* ``--check auto`` on the command line: its spelling, and the JSON and text fields.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import stats

from gyroarray.core import units
from gyroarray.design.check import (AUTO_CAP, AUTO_PILOT, SIZING_POWER, check_decision, check_sizing,
                                    runs_needed)
from gyroarray.design.predict import Swing
from gyroarray.design.recommend import DesignSpace, GyroNoise, recommend


def _t_power(k: int, delta: float, sd: float) -> float:
    """Exact power of the two-sided 95 % t-interval of K paired differences excluding 0."""
    nc = delta / (sd / math.sqrt(k))
    tq = stats.t.ppf(0.975, k - 1)
    return float(stats.nct.sf(tq, k - 1, nc) + stats.nct.cdf(-tq, k - 1, nc))


def test_runs_needed_is_the_t_sample_size():
    """K_needed: at least the normal-theory ((z₀.₉₇₅ + z₀.₈)·sd/δ)², at most a few runs more (t
    quantiles at K − 1 degrees of freedom); its exact power (noncentral t) >= 80 % and that of
    K_needed − 1 below the power the t-quantile rule aims at (the rule is the usual
    approximation, so K − 1 must not already reach 80 % by more than 1 %)."""
    za, zb = stats.norm.ppf(0.975), stats.norm.ppf(SIZING_POWER)
    for delta, sd in ((0.5, 1.0), (1.0, 1.0), (0.1, 1.0), (0.000178, 0.002492)):
        k = runs_needed(delta, sd)
        kn = ((za + zb) * sd / delta) ** 2
        assert kn <= k <= kn + 3
        assert _t_power(k, delta, sd) >= SIZING_POWER - 0.005
        assert _t_power(k - 1, delta, sd) < SIZING_POWER + 0.01
    # issue 43 item 8: predicted 0.000178 (deg/s)², 400 runs gave a 95 % half-width 0.000245, so
    # sd = 0.000245·√400 / t₀.₉₇₅(399) = 0.002492: "about 1,500 runs are needed"
    sd = 0.000245 * 20.0 / stats.t.ppf(0.975, 399)
    assert 1450 <= runs_needed(0.000178, sd) <= 1600
    assert runs_needed(0.0, 1.0) is None
    assert runs_needed(1.0, 0.0) == 2


def test_power_by_simulation():
    """At K = K_needed a numpy simulation of 4000 checks of Gaussian paired differences resolves
    in the exact power's share (binomial 99.9 % interval: ± 3.29·√(p(1 − p)/4000))."""
    rng = np.random.default_rng(43)
    delta, sd = 0.5, 1.0
    k = runs_needed(delta, sd)
    x = rng.normal(delta, sd, size=(4000, k))
    half = stats.t.ppf(0.975, k - 1) * x.std(axis=1, ddof=1) / math.sqrt(k)
    share = float(np.mean(np.abs(x.mean(axis=1)) > half))
    p = _t_power(k, delta, sd)
    assert abs(share - p) <= 3.29 * math.sqrt(p * (1 - p) / 4000)


def _design(angle: float, rms: float) -> dict:
    return {"worst_case": {"angle_deg": angle, "rms_3axis_deg_s": rms}}


def test_check_sizing_fields():
    """The sizing dict: predicted mean difference from the two worst cases, the pilot's sd with its
    χ² interval, K_needed and its range, resolvable, and the cap named when even it cannot."""
    rng = np.random.default_rng(7)
    pilot = rng.normal(3.0, 10.0, size=20)
    s = check_sizing("angle", _design(2.0, 0.1), _design(3.0, 0.1), pilot, 20, cap=AUTO_CAP)
    assert s["predicted_mean_difference"] == pytest.approx(9.0 - 4.0)
    sd = float(np.std(pilot, ddof=1))
    assert s["sd_paired_difference"]["value"] == pytest.approx(sd)
    assert s["sd_paired_difference"]["ci_low"] < sd < s["sd_paired_difference"]["ci_high"]
    assert s["unit"] == "deg^2"
    assert s["k_needed"] == runs_needed(5.0, sd)
    assert s["k_needed_range"][0] <= s["k_needed"] <= s["k_needed_range"][1]
    assert s["resolvable"] is (20 >= s["k_needed"])
    big = check_sizing("rate", _design(1.0, 0.1), _design(1.0, 0.1001), pilot * 1e-3, 20, cap=AUTO_CAP)
    assert big["unit"] == "(deg/s)^2" and big["resolvable"] is False
    assert big["k_needed"] > AUTO_CAP and "even the cap" in big["statement"]


# ---------------------------------------------------------------- the small design, simulated
G = GyroNoise(arw_deg_rt_h=0.1, rrw_deg_h_rt_h=600.0)
SPACE = DesignSpace(rate_hz=50.0, horizon_s=60.0, ns=(4, 6), schemes=(1, 2), estimators=("gls",),
                    failures=1, swing=Swing(amplitude_rad_s=units.deg_s_to_rad_s(5.0), frequency_hz=0.03),
                    bandwidth_hz=(8.0, 8.0), alpha_points=12, objective="angle")


@pytest.fixture(scope="module")
def small():
    res = recommend(G, SPACE, rhos=[-0.1, 0.5], details=False)
    return res


@pytest.mark.slow
def test_pilot_variance_against_independent_runs(small):
    """Outside check. The pilot (a check of 20 runs, seed s) predicts the variance of the paired
    difference; 60 independent runs (seed s + 1) give the empirical variance. Both are χ²
    estimates of one variance, so their ratio must lie in the 95 % F(19, 59) interval. The
    predicted mean difference (predictor) must lie in the 60 runs' 95 % Student-t interval."""
    designs = small["designs"]
    pilot = check_decision(designs, G, SPACE, replicates=AUTO_PILOT, seed=20260412)
    runs = check_decision(designs, G, SPACE, replicates=60, seed=20260413)
    sd_p = pilot["sd_paired_difference"]["value"]
    po = runs["sizing"]["paired_objective_difference"]
    ratio = sd_p ** 2 / po["sd_over_runs"] ** 2
    assert stats.f.ppf(0.025, 19, 59) <= ratio <= stats.f.ppf(0.975, 19, 59), ratio
    assert po["ci_low"] <= runs["sizing"]["predicted_mean_difference"] <= po["ci_high"]
    # the sd the 60-run check sized itself with is its first 20 runs' (the pilot), not all 60
    assert runs["sizing"]["sd_paired_difference"]["source"].startswith("pilot: the first 20")


@pytest.mark.slow
def test_check_auto(small):
    """``replicates="auto"``: K = K_needed of the 20-run pilot when it is at most the cap (else
    the pilot alone, and "even the cap" said), the rule and the cap stated, K_needed and
    resolvable at the top level."""
    c = check_decision(small["designs"], G, SPACE, replicates="auto", seed=20260412)
    need = c["k_needed"]
    assert "even the cap of --check auto (400) cannot" in c["sizing"]["statement"]
    assert c["auto"] is True and "at most 400" in c["auto_rule"]
    assert c["replicates"] == AUTO_PILOT and c["resolvable"] is False
    assert c["sd_paired_difference"]["unit"] == "deg^2"
    assert c["sizing"]["k"] == c["replicates"]
    # here the two are 0.0075 deg² apart with an sd of about 1.5 deg²: past the cap
    assert need is None or need > AUTO_CAP
    # against a clearly worse runner-up (the last-ranked design of another N) K fits the cap
    rec = small["designs"][0]
    worse = [d for d in small["designs"] if d["n"] != rec["n"]][-1]
    c2 = check_decision([rec, worse], G, SPACE, replicates="auto", seed=20260412)
    assert c2["k_needed"] is not None and c2["k_needed"] <= AUTO_CAP
    assert c2["replicates"] == max(AUTO_PILOT, c2["k_needed"]) and c2["resolvable"] is True


def test_cli_check_spelling(tmp_path, capsys):
    """``--check auto`` parses (any case), ``--check 0`` and ``--check many`` are refused at parse
    time (exit 2), and --help names auto and the cap."""
    from gyroarray.cli.design import _check_runs
    assert _check_runs("auto") == "auto" and _check_runs("AUTO") == "auto" and _check_runs("7") == 7
    from gyroarray.cli.main import main
    for bad in ("0", "many"):
        assert main(["design", "--recommend", "--arw", "0.1", "--check", bad]) == 2
    assert "--check" in capsys.readouterr().err
    try:
        main(["design", "--help"])
    except SystemExit:
        pass
    out = " ".join(capsys.readouterr().out.split())
    assert "auto: K = K_needed" in out and "at most 400" in out


@pytest.mark.slow
def test_cli_check_json_and_text(tmp_path, capsys):
    """The text says whether K runs can resolve them; the JSON carries check.k_needed,
    check.resolvable and the sd of the paired difference with its unit."""
    from gyroarray.cli.main import main
    out = tmp_path / "d.json"
    rc = main(["design", "--recommend", "--arw", "0.1", "--rrw", "600", "--rate-hz", "50", "--horizon-s", "60",
               "--n", "4,6", "--failures", "1", "--rho-range=-0.1,0.5", "--estimators", "gls",
               "--check", "6", "--out", str(out), "--force"])
    assert rc in (0, None)
    text = capsys.readouterr().out
    assert "check sizing: 6 paired runs can" in text
    c = json.loads(out.read_text())["check"]
    assert c["sd_paired_difference"]["unit"] in ("deg^2", "(deg/s)^2")
    assert isinstance(c["resolvable"], bool)
    assert c["k_needed"] is None or c["k_needed"] >= 2
