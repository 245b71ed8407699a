"""A fitted model tested on new data: ``compare --validate`` and ``ladder --holdout``.

Monday's model, Tuesday's run: every parameter of the model stays fixed, only
the starting biases belong to the new record. A model fitted on one record of
a sensor predicts another record of the same sensor (consistent), and not one
of a sensor whose scale factor differs (the prediction error of the scale
factor is the worst test). Outside truth: the sensors are set, so the answer
is known; the held-out record never saw the fit.
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from gyroarray.cli.main import main
from gyroarray.chain.compare import ModelComparison, split_measurement
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import write_measurement
from gyroarray.sim.lab import lab_run
from gyroarray.effects.model import ModelEntry, NoiseModel

LAYOUT = Layout.conical(1, 5, math.radians(54.7356))


def _sensor(ppm, seed):
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}),
                        ModelEntry("scale_factor", 2, {"ppm": ppm})))
    return lab_run(model, LAYOUT, np.random.default_rng(seed), static_s=300.0, motion_s=240.0, tail_s=60.0)


@pytest.fixture(scope="module")
def monday():
    """The model fitted on Monday's run (scale factor 3000 ppm on gyro 2)."""
    _, after = ModelComparison(_sensor(3000.0, 1), n_runs=10).fit([("scale_factor", 2)])
    return NoiseModel(after.model.entries, description="fitted on Monday's run")


def test_the_same_sensor_is_predicted(monday):
    a = ModelComparison(_sensor(3000.0, 2), monday, n_runs=20).validate()
    assert a.consistent, [(t.effect, t.gyro, round(t.z, 1)) for t in a.tests if a.significant(t)]
    assert a.notes[0].startswith("validation: every parameter")
    assert a.model.entries == monday.entries                 # nothing refitted


def test_another_scale_factor_is_not_and_says_where(monday):
    a = ModelComparison(_sensor(4500.0, 3), monday, n_runs=20).validate()
    assert not a.consistent
    top = a.candidates[0]
    assert (top.effect, top.gyro) == ("scale_factor", 2)
    assert top.evidence.startswith("prediction error of the model's")
    # the error is the difference: 1500 ppm, within its 2σ or 10 %
    got, s = top.fit.params["ppm"], top.fit.sigma["ppm"]
    assert abs(got - 1500.0) <= max(2 * s, 150.0)


def test_validate_refuses_a_model_without_its_baseline():
    m = _sensor(3000.0, 2)
    with pytest.raises(InputError, match="needs a fitted model"):
        ModelComparison(m, NoiseModel((ModelEntry("scale_factor", 2, {"ppm": 3000.0}),)), n_runs=5).validate()


def test_cli_validate_and_holdout(monday, tmp_path, capsys):
    csv, _ = write_measurement(_sensor(3000.0, 4), tmp_path / "tuesday.csv")
    model = tmp_path / "monday.toml"
    model.write_text(monday.to_toml())
    code = main(["diagnose", str(csv), "--model", str(model), "--validate", "--runs", "10", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["validated"] and out["consistent"]
    assert "predicts" in out["verdict"] and "consistent" in out["verdict"]
    code = main(["diagnose", str(csv), "--validate"])
    assert code == 2 and "needs --model" in capsys.readouterr().err


def test_split_measurement_refuses_a_too_short_part():
    m = _sensor(3000.0, 5)
    first, rest = split_measurement(m, 0.4)
    assert first.time_s.size + rest.time_s.size == m.time_s.size and rest.time_s[0] > first.time_s[-1]
    with pytest.raises(InputError, match="--holdout"):
        split_measurement(m, 0.999)


def _filtered(cutoff_hz, seed):
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}),
                        ModelEntry("bandwidth", 3, {"cutoff_hz": cutoff_hz, "order": 2})))
    return lab_run(model, LAYOUT, np.random.default_rng(seed), static_s=300.0, motion_s=0.0, tail_s=0.0)


@pytest.mark.slow   # 5 s: make score
def test_a_filter_read_from_the_spectrum_is_compared_with_the_model_not_taken_as_an_error():
    """The spectrum gives a filter's cut-off itself, whatever the model holds: validation compares
    it with the model's (same sensor: no prediction error; another cut-off: the worst test)."""
    _, after = ModelComparison(_filtered(10.0, 1), n_runs=10).fit([("bandwidth", 3)])
    fitted = after.model
    same = ModelComparison(_filtered(10.0, 2), fitted, n_runs=10).validate()
    t = next(t for t in same.tests if t.effect == "bandwidth" and t.gyro == 3)
    assert t.extra.get("prediction_error") and not same.significant(t), t.evidence
    other = ModelComparison(_filtered(5.0, 2), fitted, n_runs=10).validate()
    worst = other.candidates[0]
    assert (worst.effect, worst.gyro) == ("bandwidth", 3) and other.significant(worst), worst.evidence


def test_a_model_whose_white_noise_is_in_another_term_is_not_read_against_zero():
    """A fitted model may carry its white noise in a short Gauss–Markov term and have N = 0 (the
    ADIS16405's gyro 3 did). Its own record, validated, is predicted: the tests whiten with the
    record's white level (its Allan fit), not with r = N²/dt = 0, which made a 3.7σ line a false
    alarm of probability 1e-4278. Closed forms that bracket that white level: sample to sample a
    Gauss–Markov of σ and τc has first differences of variance 2σ²(1 − e^(−dt/τc)) (r = σ²(1 − φ)),
    and far beyond τc it reads as white noise of N² = 2σ²τc (r = 2σ²τc/dt); the Allan fit over
    the octaves between lies between the two."""
    sigma_deg_h, tau_s = 600.0, 0.04
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.0}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}),
                        ModelEntry("gauss_markov", None, {"sigma_deg_h": sigma_deg_h, "tau_s": tau_s})))
    m = lab_run(model, LAYOUT, np.random.default_rng(4), static_s=300.0, motion_s=240.0, tail_s=60.0)
    a = ModelComparison(m, model, n_runs=20).validate()
    s2 = math.radians(sigma_deg_h / 3600.0) ** 2                                        # [rad²/s²]
    lo, hi = s2 * (1.0 - math.exp(-m.dt_s / tau_s)), 2.0 * s2 * tau_s / m.dt_s
    assert np.all((lo <= a.r) & (a.r <= hi)), (a.r, lo, hi)
    # a noise that is all Gauss–Markov at τc = 2 samples is not white at the sample level, so the
    # regressions' tests are not N(0, 1) here (up to z ≈ 17 on the spectral one); whitened with
    # r = 0 they were beyond 1e5
    worst = max(t.z for t in a.tests if t.kind == "effect" and np.isfinite(t.z))
    assert worst < 50.0, worst


def test_an_all_gyros_baseline_entry_reaches_every_gyro_and_a_gyros_own_entry_wins():
    """A model file may give ARW and RRW once for all gyros (no gyro). They used to be dropped
    when the model was spread per gyro, so validation simulated a band with no noise at all (an
    ADEV of exactly 0, log 0 in the band test). Each gyro now gets the all-gyros value, except a
    gyro the model names itself."""
    base = (ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}),
            ModelEntry("arw", 2, {"n_deg_rt_h": 0.4}))
    rec = lab_run(NoiseModel(base), LAYOUT, np.random.default_rng(3), static_s=300.0, motion_s=60.0,
                  tail_s=60.0)
    comp = ModelComparison(rec, NoiseModel(base), n_runs=5)
    n = {e.gyro: e.params["n_deg_rt_h"] for e in comp.model if e.effect == "arw"}
    k = {e.gyro: e.params["k_deg_h_rt_h"] for e in comp.model if e.effect == "rrw"}
    gyros = list(range(1, LAYOUT.n_gyros + 1))
    assert n == {g: (0.4 if g == 2 else 0.15) for g in gyros} and k == {g: 5.0 for g in gyros}
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        a = comp.validate()
    assert a.consistent and np.isfinite(a.discrepancy), a.discrepancy


def test_a_line_found_again_elsewhere_is_as_evident_as_the_line():
    """A model's line (sinusoid, 2.0 Hz) that the new record has at 2.3 Hz: the refit on the residual
    finds the 2.3 Hz line; its 'error' against the model's frequency is thousands of its σ, but the
    prediction error is no more evident than the line left in the residual (the refit's own z)."""
    base = (ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}))
    line = {"amp_deg_s": 0.01, "phase_deg": 0.0}
    monday_model = NoiseModel(base + (ModelEntry("sinusoid", 1, {**line, "freq_hz": 2.0}),))
    tuesday = lab_run(NoiseModel(base + (ModelEntry("sinusoid", 1, {**line, "freq_hz": 2.3}),)), LAYOUT,
                      np.random.default_rng(5), static_s=300.0, motion_s=240.0, tail_s=60.0)
    a = ModelComparison(tuesday, monday_model, n_runs=10).validate()
    t = next(t for t in a.tests if t.effect == "sinusoid" and t.gyro == 1)
    assert t.fit.params["freq_hz"] == pytest.approx(2.0, abs=0.35)        # one of the two lines
    assert t.z <= t.extra["z_without_model_sigma"] and not a.consistent
    assert t.z < 1e3


@pytest.mark.slow   # a ladder step and a held-out validation of a 600 s five-gyro run (25-60 s): make score
def test_ladder_holdout_says_whether_structure_or_transfer_fails(tmp_path, capsys):
    """A run with a 3000 ppm scale factor on gyros 2 and 4 and a ladder allowed one step: the
    model lacks one of them on the part it was fitted on as well, so the held-out verdict blames
    its structure and names the term the fitted part's candidates ask for (the set answer: the
    other gyro's scale factor)."""
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}),
                        ModelEntry("scale_factor", 2, {"ppm": 3000.0}), ModelEntry("scale_factor", 4, {"ppm": 3000.0})))
    run = lab_run(model, LAYOUT, np.random.default_rng(6), static_s=300.0, motion_s=240.0, tail_s=60.0)
    csv, _ = write_measurement(run, tmp_path / "run.csv")
    code = main(["ladder", str(csv), "--max-steps", "1", "--holdout", "0.4", "--runs", "5",
                 "--out", str(tmp_path / "r.html"), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and not out["consistent"] and not out["holdout"]["consistent"]
    added = out["steps"][1]["added"]
    assert added["effect"] == "scale_factor" and added["gyro"] in (2, 4)
    assert "its structure lacks a term" in out["holdout"]["structure"]
    assert out["holdout"]["missing_terms"][0] == f"scale_factor:{6 - added['gyro']}"
