"""Model vs measurement (gyroarray.chain.compare): no false alarms, one test per effect, bad input.

Measurements come from the project's own simulator (:func:`gyroarray.sim.lab.lab_run`:
600 s static, 300 s of rate steps and swings, 300 s static, 50 Hz, warming
temperature). Tolerances:

* "consistent" means D <= 1, i.e. no test beyond the 1 % family-wise
  critical value: under the baseline each run has <= 1 % chance of a false
  alarm by construction (the z's are null-calibrated, see
  gyroarray.effects.stochastic and .regress); the seeds are fixed, so
  the tests are deterministic and were checked once.
* a fitted parameter is within 10 % of the value set or within 2σ of its
  own uncertainty (the issue's rule); 2σ is a 95 % interval.
"""

from __future__ import annotations

import json
from dataclasses import replace
import math
from pathlib import Path

import numpy as np
import pytest

from gyroarray.chain.compare import ModelComparison, critical_z, parse_add
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import write_measurement
from gyroarray.sim.cases import EFFECTS, single_effect_case
from gyroarray.sim.lab import lab_run
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.sim.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
BASE = (ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 10.0}))
S1N6 = Layout.conical(1, 6, math.radians(54.7356))


def test_critical_z_is_sidak():
    # one test at 1 %: the one-sided normal quantile 2.326; 100 tests: 1 - 0.99^(1/100) = 1.005e-4 -> 3.7178
    assert critical_z(1) == pytest.approx(2.3263, abs=1e-4)
    assert critical_z(100) == pytest.approx(3.7178, abs=1e-3)


# -- no false alarms: every layout of the paper scenarios, several seeds ----------

def _paper_layouts():
    seen = {}
    for f in sorted((ROOT / "src" / "gyroarray" / "data" / "scenarios").glob("paper00[23]/*.toml")):
        sc = load_scenario(f)
        key = tuple(np.round(np.asarray(sc.layout.axes), 6).ravel())
        if key not in seen:
            seen[key] = (f.stem, sc.layout, NoiseModel(tuple(e for e in sc.model if e.effect in ("arw", "rrw"))))
    return list(seen.values())


PAPER_LAYOUTS = _paper_layouts()


def test_paper_layouts_are_all_there():
    # triad (paper 002), tetrahedron, S1/S2 with N = 6 and N = 8
    assert sorted(lay.n_gyros for _, lay, _ in PAPER_LAYOUTS) == [3, 4, 6, 6, 8, 8]


#: the eight-gyro layouts (7-10 s each on 2 cores) run in make score: make test at 6 min
_FALSE_ALARM_SLOW = {"swing_s1_n8", "swing_s2_n8"}


@pytest.mark.parametrize("seed", [pytest.param(11, marks=pytest.mark.slow), 12])
@pytest.mark.parametrize("case", [pytest.param(c, marks=[pytest.mark.slow] if c[0] in _FALSE_ALARM_SLOW else [])
                                  for c in PAPER_LAYOUTS], ids=[c[0] for c in PAPER_LAYOUTS])
def test_no_false_alarm_on_baseline(case, seed):
    name, layout, model = case
    m = lab_run(model, layout, np.random.default_rng(seed))
    a = ModelComparison(m, n_runs=20).analyse()
    assert a.consistent, [(t.effect, t.gyro, t.z) for t in a.tests if a.significant(t)]
    assert not any(a.significant(t) for t in a.candidates)
    # the baseline itself is calibrated: ARW within 10 % of the scenario's
    for g in range(1, layout.n_gyros + 1):
        n_set = next(e for e in model if e.effect == "arw" and e.gyro in (None, g)).params["n_deg_rt_h"]
        n_fit = a.fits[("arw", g)].params["n_deg_rt_h"]
        assert n_fit == pytest.approx(n_set, rel=0.10)


# -- one test per effect ----------------------------------------------------------

CASES = {
    "bias_instability": (2, {"b_deg_h": 8.0}),
    "quantization": (3, {"q_deg": 5e-4}),
    "rate_ramp": (1, {"r_deg_h2": 300.0}),
    "gauss_markov": (4, {"sigma_deg_h": 100.0, "tau_s": 0.5}),
    "sinusoid": (5, {"amp_deg_s": 0.01, "freq_hz": 3.7, "phase_deg": 30.0}),
    "scale_factor": (2, {"ppm": 2000.0}),
    "scale_nonlinearity": (3, {"k2_per_deg_s": 2e-5}),
    "misalignment": (4, {"tilt_deg": 0.3, "tilt_azimuth_deg": 40.0}),
    "temperature_bias": (1, {"deg_h_per_c": 20.0, "t0_c": 25.0}),
    "latency": (6, {"delay_s": 0.002}),
    "saturation": (2, {"range_deg_s": 30.0}),
    "correlation": (None, {"rho_arw": 0.3, "rho_rrw": 0.0}),
    "earth_rate": (None, {"latitude_deg": 34.25}),
    "burst": (None, {"start_s": 300.0, "end_s": 420.0, "variance_ratio": 4.0}),
}
# parameters the fit does not estimate (t0 is not identifiable from k·(T − t0) + bias)
NOT_FITTED = {("temperature_bias", "t0_c"), ("correlation", "rho_rrw")}


def _with(effect, gyro, params, extra=()):
    return NoiseModel(BASE + tuple(extra) + (ModelEntry(effect, gyro, params),))


# Known failures at this seed (issue 6 closing note), kept strict so a fix shows up:
XFAIL = {"sinusoid": "fitted phase 26.8 ± 1.2° against 30° set (2.7σ, outside 10 %) at this seed, a "
                     "1-in-150 draw: over seeds 20–31 the phase pulls have mean 0.33 and sd 1.1 "
                     "(unbiased, σ right); amplitude and frequency within 1σ"}


#: The cases make test runs (one per kind of fit: Allan term, regression on the rate, on the
#: temperature, clipping, array-wide); the others run in make score (`pytest -m slow`)
# saturation and burst (5-6 s each on 2 cores) moved to make score this stop: make test at 6 min
# temperature_bias and quantization (10 s and 7 s) to make score: the temperature regression is
# held by test_temperature_gls and test_real_cats, the quantizer by test_filter_quantization
CASES_FAST = {"bias_instability", "scale_factor"}


def _case_marks(e):
    return ([pytest.mark.xfail(reason=XFAIL[e], strict=True)] if e in XFAIL else []) + \
        ([] if e in CASES_FAST else [pytest.mark.slow])


@pytest.mark.parametrize("effect", [pytest.param(e, marks=_case_marks(e)) for e in sorted(CASES)])
def test_effect_is_found_fitted_and_explained(effect):
    gyro, params = CASES[effect]
    extra = ()
    if effect == "quantization":
        # a turn-on bias of 1 deg/s, as a real gyro has (the quantization noise does not care)
        extra = (ModelEntry("constant_bias", gyro, {"bias_deg_h": 3600.0}),)
    m = lab_run(_with(effect, gyro, params, extra), S1N6, np.random.default_rng(7))
    comp = ModelComparison(m, n_runs=20)
    before, after = comp.fit([(effect, gyro)])
    top = before.candidates[0]
    assert (top.effect, top.gyro) == (effect, gyro), [(t.effect, t.gyro, t.z) for t in before.candidates[:3]]
    assert before.significant(top) and not before.consistent
    # D falls to consistent (D ≤ 1). A consistent model's D is the largest of its tests' z over the
    # critical z, typically 0.6–0.9, so a fixed fall (say by half) cannot be asked of an effect
    # whose D before is 1.4 (the ramp and the temperature cases): the fall itself is asserted
    assert after.discrepancy < before.discrepancy
    assert after.consistent, [(t.effect, t.gyro, t.z) for t in after.tests if after.significant(t)]
    fit = after.fits[(effect, gyro)]
    for key, want in params.items():
        if (effect, key) in NOT_FITTED:
            continue
        got, sig = fit.params[key], fit.sigma.get(key, 0.0)
        assert abs(got - want) <= max(0.10 * abs(want), 2.0 * sig), (key, got, sig, want)


@pytest.mark.slow
def test_sinusoid_phase_is_unbiased_with_an_honest_sigma():
    """The phase that misses the 2σ rule at seed 7 (xfail above) is a chance draw.

    Over 12 seeds the pulls (fit − set)/σ of a 0.01 deg/s, 3.7 Hz line must
    look like N(0, 1): their mean within 3/√12 of 0, their sd inside the
    99.9 % χ²(11) interval [0.38, 1.74] (measured: mean 0.33, sd 1.1)."""
    pulls = []
    for seed in range(20, 32):
        m = lab_run(_with("sinusoid", 5, {"amp_deg_s": 0.01, "freq_hz": 3.7, "phase_deg": 30.0}), S1N6,
                    np.random.default_rng(seed))
        f = next(t for t in ModelComparison(m, n_runs=4).analyse().candidates
                 if (t.effect, t.gyro) == ("sinusoid", 5)).fit
        pulls.append(((f.params["phase_deg"] - 30.0 + 180.0) % 360.0 - 180.0) / f.sigma["phase_deg"])
    assert abs(np.mean(pulls)) < 3.0 / math.sqrt(len(pulls))
    assert 0.38 < np.std(pulls, ddof=1) < 1.74


def test_constant_bias_is_part_of_the_baseline():
    # never a candidate (the baseline's starting bias is unknown), but --add fits it
    m = lab_run(_with("constant_bias", 3, {"bias_deg_h": 200.0}), S1N6, np.random.default_rng(3))
    comp = ModelComparison(m, n_runs=10)
    before, after = comp.fit([("constant_bias", 3)])
    assert before.consistent
    assert all(t.effect != "constant_bias" for t in before.candidates)
    f = after.fits[("constant_bias", 3)]
    assert abs(f.params["bias_deg_h"] - 200.0) <= 2.0 * f.sigma["bias_deg_h"]


@pytest.mark.slow   # two ladder steps on a lab run (9 s on 2 cores; test_ladder_keeps runs fast twins): make score
def test_ladder_on_two_hidden_effects_finds_both():
    model = NoiseModel(BASE + (ModelEntry("scale_factor", 2, {"ppm": 3000.0}),
                               ModelEntry("sinusoid", 4, {"amp_deg_s": 0.02, "freq_hz": 5.1, "phase_deg": 0.0})))
    m = lab_run(model, S1N6, np.random.default_rng(5))
    steps = ModelComparison(m, n_runs=20).ladder()
    added = [s[0] for s in steps[1:]]
    assert set(added) == {("scale_factor", 2), ("sinusoid", 4)}
    d = [a.discrepancy for _, a in steps]
    assert d[-1] <= 1.0 < d[0] and all(x > y for x, y in zip(d, d[1:]))


# -- records shaped like the practice set (gyroarray.sim.cases) -----------------------

# Cases of benchmarks/diagnosis_score.py that went wrong before the ranking
# and model fixes they guard (numbers from the score run of this session):
RIVALS = {
    # a bias instability scored below the Gauss–Markov hump fitted to the same
    # floor (z 11.97 vs 11.72); the AIC of the two Allan fits (9 vs 26 on 11 dof) decides
    ("bias_instability", 100): "gauss_markov",
    # rates mostly of one sign: k2·u² has a large linear part, the scale factor
    # scored z 323 against the curvature's 159 (tested given a scale factor)
    ("scale_nonlinearity", 200): "scale_factor",
    # clipping of input + turn-on bias: with the bias left out of the
    # prediction, D stayed at 4.6 after the fit
    ("saturation", 100): None,
    # a 0.92° tilt: its (1 − cos θ)·u term (−129 ppm) was left as a scale
    # factor and curvature, D 1.72 after the fit
    ("misalignment", 202): None,
}


def test_case_noise_seed_redraws_the_noise_only():
    # seed 103's gauss_markov case (S2 N6, gyro 1, σ 52.04 deg/h, τc 1.301 s): another noise
    # seed keeps the layout and the hidden parameters and changes every output sample; None is
    # the case as scored (bit for bit)
    c = single_effect_case("gauss_markov", 103)
    same = single_effect_case("gauss_markov", 103, noise_seed=None)
    other = single_effect_case("gauss_markov", 103, noise_seed=1)
    assert (c.layout_name, c.gyro) == (other.layout_name, other.gyro) == ("S2 N6", 1)
    assert c.params == other.params and c.params["tau_s"] == pytest.approx(1.3012, abs=1e-4)
    assert np.array_equal(c.measurement.gyro_deg_s, same.measurement.gyro_deg_s)
    assert np.array_equal(c.measurement.ref_deg_s, other.measurement.ref_deg_s)
    assert np.all(c.measurement.gyro_deg_s != other.measurement.gyro_deg_s)


@pytest.mark.slow   # a study of 20-45 s: make score
def test_a_scale_factor_after_a_curvature_is_tested_jointly():
    """Seed 109's curvature (gyro 1, k2 = −2.6e-5 per deg/s, no scale factor): after the fit its
    gyro's scale-factor test is the joint fit's (the slope the curvature's fit left behind, over
    its own σ; :func:`test_a_slope_after_a_curvature_is_tested_with_the_joint_sigma` has the
    statistics). Tested alone it read z = 4.17 and the right model was 'not consistent'."""
    c = single_effect_case("scale_nonlinearity", 109)
    _, after = ModelComparison(c.measurement, n_runs=20).fit([("scale_nonlinearity", c.gyro)])
    sf = next(t for t in after.tests if (t.effect, t.gyro) == ("scale_factor", c.gyro))
    assert sf.fit.extra["joint_with_nonlinearity"] and abs(sf.z) < 3.0
    others = [t for t in after.tests if t.effect == "scale_factor" and t.gyro != c.gyro]
    assert others and not any(t.fit.extra.get("joint_with_nonlinearity") for t in others)
    assert after.consistent


@pytest.mark.slow   # a study of 20-45 s: make score
def test_spikes_are_counted_at_the_noise_level_of_a_burst_in_the_model():
    """Seed 111's burst (180.65–439.29 s, variance × 5.70, every gyro). With the burst fitted,
    no gyro shows spikes: the count reads the record at the model's level. Read as it is, the
    running median at the burst's edges mixed the two levels and gyro 3 showed 6 clusters
    against 0.82 expected (z 3.69: the right model 'not consistent'). Outside check, plain
    numpy: the first differences of gyro 3's residual have an excess kurtosis of about 3 (a
    two-level mixture: 3·(p·r² + 1 − p)/(p·r + 1 − p)² − 3 = 2.8 at p = 0.108, r = 5.7), and
    with the window's samples divided by √5.70 it is within 0.1 of 0 (its sd is √(24/n) =
    0.014)."""
    from scipy import stats
    c = single_effect_case("burst", 111)
    _, after = ModelComparison(c.measurement, n_runs=20).fit([("burst", None)])
    outl = [t for t in after.tests if t.effect == "outliers"]
    assert len(outl) == 6 and max(t.z for t in outl) < 3.0
    e = after.residual_rad_s[:, 2]
    t = c.measurement.time_s - c.measurement.time_s[0]
    inside = (t >= c.params["start_s"]) & (t < c.params["end_s"])
    assert stats.kurtosis(np.diff(e)) > 2.0
    w = np.where(inside, e / math.sqrt(c.params["variance_ratio"]), e)
    assert abs(stats.kurtosis(np.diff(w))) < 0.1
    assert after.consistent


# every effect once (seed 100) and the rival cases; the parameters are checked
# by `make score` (benchmarks/diagnosis_score.py), which reports them per case
SHAPED = sorted({(e, 100) for e in EFFECTS} | set(RIVALS))
SHAPED_XFAIL: dict = {}
#: The cases make test runs (this round's new effects and the clipped record); the others are
#: in make score (`pytest -m slow`), with benchmarks/diagnosis_score.py.
# g_sensitivity (11 s) to make score too: make test at 6 min; the diagnose path is held fast by
# test_effect_is_found_fitted_and_explained's bias_instability and scale_factor cases
SHAPED_FAST: set = set()   # outliers, saturation, bandwidth (12 s): make score


def _shaped_marks(e, s):
    marks = [pytest.mark.xfail(reason=SHAPED_XFAIL[e], strict=True)] if e in SHAPED_XFAIL else []
    return marks + ([] if (e, s) in SHAPED_FAST else [pytest.mark.slow])


@pytest.mark.parametrize("effect,seed", [pytest.param(e, s, marks=_shaped_marks(e, s)) for e, s in SHAPED],
                         ids=[f"{e}-{s}" for e, s in SHAPED])
def test_practice_shaped_case_is_found_and_explained(effect, seed):
    c = single_effect_case(effect, seed)
    before, after = ModelComparison(c.measurement, n_runs=20).fit([(effect, c.gyro)])
    top = before.candidates[0]
    assert (top.effect, top.gyro) == (effect, c.gyro), [(t.effect, t.gyro, t.z) for t in before.candidates[:3]]
    assert before.significant(top)
    rival = RIVALS.get((effect, seed))
    if rival is not None:     # the rival is significant too, and says why it ranks lower
        r = next(t for t in before.candidates if (t.effect, t.gyro) == (rival, c.gyro))
        assert before.significant(r)
        assert "fits this ADEV better" in r.evidence or "the nonlinearity explains it" in r.evidence
    assert after.consistent, [(t.effect, t.gyro, t.z) for t in after.tests if after.significant(t)]
    assert after.discrepancy < before.discrepancy


@pytest.mark.parametrize("seed", [pytest.param(100, marks=pytest.mark.slow),
                                  pytest.param(102, marks=pytest.mark.slow)])
def test_quantization_as_the_spec_defines_it_is_found_fitted_and_explained(seed):
    """The spec's counter (shared/spec/effects.md, "Definition of quantization": the increments
    of the rounded integrated angle, step √12·Q), written here in numpy outside the simulator, as
    an independent generator may, on gyro 2's whole output of a table run (Q = 7e-4 deg). At rest
    the gyro is quiet (0.1 step per sample): the correlated regime, Δ read from the output's grid.
    (This test used to add white Gaussian angle noise, the old dithered model: the spec's
    counter at rest is not that process.)"""
    layout = Layout.conical(1, 5, math.radians(54.7356))
    rng = np.random.default_rng(seed)
    m = lab_run(NoiseModel(BASE[:1] + (ModelEntry("rrw", None, {"k_deg_h_rt_h": 3.0}),)), layout, rng,
                static_s=1200.0, motion_s=900.0, tail_s=300.0, protocol="table")
    q = 7e-4
    y = np.array(m.gyro_deg_s, copy=True)
    step = math.sqrt(12.0) * q                                          # deg
    y[:, 1] = np.diff(np.round(np.cumsum(y[:, 1] * m.dt_s) / step), prepend=0.0) * (step / m.dt_s)
    m = replace(m, gyro_deg_s=y)
    before, after = ModelComparison(m, n_runs=20).fit([("quantization", 2)])
    assert (before.candidates[0].effect, before.candidates[0].gyro) == ("quantization", 2)
    assert after.consistent, [(t.effect, t.gyro, t.z) for t in after.tests if after.significant(t)]
    f = after.fits[("quantization", 2)]
    assert abs(f.params["q_deg"] - q) <= max(0.10 * q, 2.0 * f.sigma["q_deg"])


@pytest.mark.parametrize("seed", [0, 1])
def test_the_spec_counters_repeats_are_not_holds_and_held_samples_still_are(seed):
    """The repeats of the spec's counter (the increments of the rounded integrated angle, numpy
    here: white rate at 0.2 and 0.4 step per sample, at rest) are the quantizer's, not a
    pipeline's: it repeats as often two samples apart as one apart (the practice-shaped
    quantization case, seed 100, was read as holds at z 15 and its quantization explained away;
    at these two rates the density's null alone calls holds in every seed). A pipeline that
    holds 2 % of the samples (each one repeats the sample before it; numpy) is still found on a
    finer grid (3 steps per sample: 1.2 % repeats by chance, 2 % more held)."""
    from gyroarray.analysis.pipeline import gyro_holds
    rng = np.random.default_rng(seed)
    n = 60000

    def counter(sd_steps):
        return np.diff(np.round(np.cumsum(rng.normal(0.0, sd_steps, n))), prepend=0.0)

    for sd in (0.2, 0.4):
        h = gyro_holds(counter(sd))
        assert h.fraction > 0.15 and not h.significant, (sd, h)
    y = counter(3.0)
    held = rng.random(n) < 0.02
    held[0] = False
    h = gyro_holds(y[np.maximum.accumulate(np.where(held, 0, np.arange(n)))])
    assert h.significant and h.n_held - h.chance > 0.5 * held.sum(), h


@pytest.mark.slow
def test_ladder_keeps_only_steps_that_help(monkeypatch):
    """A step that makes D worse is refused, the next candidate tried, the refusal noted."""
    m = lab_run(_with("scale_factor", 2, {"ppm": 3000.0}), S1N6, np.random.default_rng(5))
    comp = ModelComparison(m, n_runs=10)
    real = comp.analyse
    first = real()
    # a wrong candidate made significant and put first; its step doubles D
    wrong = replace(next(t for t in first.candidates if t.effect == "rate_ramp"), z=first.z_crit + 1.0)

    def analyse(model=None):
        if model is None:
            return replace(first, candidates=[wrong] + list(first.candidates))
        a = real(model)
        if any(e.effect == "rate_ramp" for e in model):
            return replace(a, discrepancy=2.0 * first.discrepancy)
        return a
    monkeypatch.setattr(comp, "analyse", analyse)
    steps = comp.ladder()
    assert [s[0] for s in steps[1:]] == [("scale_factor", 2)]
    assert steps[-1][1].consistent
    assert any(n.startswith(f"the ladder did not add rate_ramp on gyro {wrong.gyro}")
               for n in steps[-1][1].notes)


def test_same_seed_same_bits():
    # a short record (the same code path: static parts, motion, tail) keeps it quick
    m = lab_run(NoiseModel(BASE), S1N6, np.random.default_rng(1), static_s=120, motion_s=60, tail_s=30)
    a = ModelComparison(m, n_runs=5, seed=3).analyse()
    b = ModelComparison(m, n_runs=5, seed=3).analyse()
    assert a.discrepancy == b.discrepancy
    assert np.array_equal(a.adev["mc"], b.adev["mc"])


# -- without a reference ---------------------------------------------------------

def test_no_reference_gives_static_diagnoses_and_says_what_needs_one():
    m = lab_run(_with("bias_instability", 2, {"b_deg_h": 8.0}), S1N6, np.random.default_rng(7),
                motion_s=0.0, tail_s=0.0, static_s=1200.0, reference=False)
    a = ModelComparison(m, n_runs=20).analyse()
    assert (a.candidates[0].effect, a.candidates[0].gyro) == ("bias_instability", 2)
    assert not any(t.effect in ("scale_factor", "misalignment", "latency") for t in a.candidates)
    assert any("need ref_x, ref_y, ref_z" in n for n in a.notes)


def _biased(extra=()):
    """BASE with a different turn-on bias on every gyro (300·g deg/h) and ``extra`` entries."""
    return NoiseModel(BASE + tuple(ModelEntry("constant_bias", g, {"bias_deg_h": 300.0 * g})
                                   for g in range(1, 7)) + tuple(extra))


@pytest.mark.parametrize("seed", [pytest.param(11, marks=pytest.mark.slow), 12])
def test_no_reference_motion_is_cut_out_not_read_as_noise(seed):
    """Without ref_*, the turns of the lab run are found in the outputs and left out.

    The steps-and-swings part (600–~888 s) would otherwise read as a huge
    bias instability / random walk; the still parts are stitched and the
    baseline is consistent again (seed 11: D 0.82, seed 12: D 0.50)."""
    m = lab_run(_biased(), S1N6, np.random.default_rng(seed), reference=False)
    comp = ModelComparison(m, n_runs=20)
    (a0, b0), (a1, b1) = comp.parts_s           # two still parts: the static head and tail
    assert a0 == 0.0 and 597.0 < b0 <= 600.0 and 880.0 < a1 < 892.0 and b1 == pytest.approx(1200.0)
    a = comp.analyse()
    assert a.consistent, [(t.effect, t.gyro, t.z) for t in a.tests if a.significant(t)]
    assert any("2 still parts" in n for n in a.notes)


def test_no_reference_motion_still_finds_a_noise_effect():
    m = lab_run(_biased([ModelEntry("bias_instability", 2, {"b_deg_h": 8.0})]), S1N6,
                np.random.default_rng(11), reference=False)
    a = ModelComparison(m, n_runs=20).analyse()
    assert (a.candidates[0].effect, a.candidates[0].gyro) == ("bias_instability", 2)
    assert a.significant(a.candidates[0])


def test_no_reference_and_too_little_still_is_refused(tmp_path, cli):
    # still: 15 s head + ~10 s after the last block (the blocks stop short of 300 s): < 2048 samples
    m = lab_run(NoiseModel(BASE), S1N6, np.random.default_rng(2), static_s=15.0, motion_s=300.0,
                tail_s=2.0, reference=False)
    csv, _ = write_measurement(m, tmp_path / "moving.csv.gz")
    p = cli("diagnose", csv, check=False)
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert "no reference rate" in p.stderr and "the outputs show motion" in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


# -- CLI: the loop a user runs, and bad input ---------------------------------------

@pytest.fixture(scope="module")
def sf_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("sf")
    m = lab_run(_with("scale_factor", 2, {"ppm": 2500.0}), S1N6, np.random.default_rng(22))
    csv, _ = write_measurement(m, d / "run.csv.gz")
    return csv


@pytest.mark.slow   # a study of 20-45 s: make score
def test_cli_diagnose_fit_and_model_round_trip(sf_files, tmp_path, cli):
    d = json.loads(cli("diagnose", sf_files, "--runs", 10, "--json").stdout)
    assert set(d) >= {"discrepancy", "consistent", "candidates"}
    c0 = d["candidates"][0]
    assert (c0["effect"], c0["gyro"], c0["significant"]) == ("scale_factor", 2, True)
    assert d["consistent"] is False and d["discrepancy"] > 1
    assert "gyro 2" in c0["evidence"] and "%" in c0["evidence"]
    out = tmp_path / "fitted.toml"
    f = json.loads(cli("fit", sf_files, "--runs", 10, "--add", "scale_factor:2", "--out", out, "--json").stdout)
    assert f["discrepancy_after"] <= 0.5 * f["discrepancy_before"] and f["consistent"] is True
    sf = next(e for e in f["effects"] if e["effect"] == "scale_factor")
    assert sf["gyro"] == 2 and abs(sf["params"]["ppm"] - 2500) <= max(250, 2 * sf["sigma"]["ppm"])
    assert set(sf["params"]) == {"ppm"} and set(sf["sigma"]) == {"ppm"}      # the 1σ beside, not inside
    again = json.loads(cli("diagnose", sf_files, "--runs", 10, "--model", out, "--json").stdout)
    assert again["consistent"] is True
    assert again["discrepancy"] == pytest.approx(f["discrepancy_after"], rel=1e-6)
    # compare --model: the report of the error falling, baseline first, then the model's effect
    c = json.loads(cli("compare", sf_files, "--runs", 10, "--model", out, "--out", tmp_path / "after.html",
                       "--json").stdout)
    assert [s["added"] for s in c["steps"]] == [None, {"effect": "scale_factor", "gyro": 2}]
    assert c["steps"][0]["discrepancy"] == pytest.approx(d["discrepancy"], rel=1e-6)
    assert c["discrepancy"] == pytest.approx(f["discrepancy_after"], rel=1e-6) and c["consistent"]
    assert "Started at D = " in (tmp_path / "after.html").read_text()


@pytest.mark.parametrize("args, message", [
    (["--add", "scale_factr:2"], "did you mean"),
    (["--add", "scale_factor:x"], "gyro must be a number"),   # scale_factor alone: every gyro (issue 32)
    (["--add", "scale_factor:9"], "not in 1..6"),
    (["--add", "burst:2"], "whole array"),
])
def test_cli_bad_add(sf_files, args, message, cli):
    p = cli("fit", sf_files, "--runs", 5, *args, check=False)
    assert p.returncode == 2 and message in p.stderr and "Traceback" not in p.stderr
    assert len(p.stderr.strip().splitlines()) == 1


def test_cli_refuses_to_write_over_its_inputs(sf_files, tmp_path, cli):
    model = tmp_path / "m.toml"
    model.write_text('effects = [{effect = "arw", n_deg_rt_h = 0.1}]\n')
    before = model.read_bytes()
    p = cli("fit", sf_files, "--runs", 5, "--model", model, "--out", model, check=False)
    assert p.returncode == 2 and "input of this command" in p.stderr
    assert model.read_bytes() == before


def _short(tmp_path, seconds, static=True):
    m = lab_run(NoiseModel(BASE), S1N6, np.random.default_rng(2), static_s=seconds if static else 0.0,
                motion_s=0.0 if static else seconds, tail_s=0.0)
    csv, _ = write_measurement(m, tmp_path / "m.csv")
    return csv


def test_too_short_is_refused_clearly(tmp_path, cli):
    p = cli("diagnose", _short(tmp_path, 20.0), check=False)
    assert p.returncode == 2 and "too short for a diagnosis" in p.stderr and "m.csv" in p.stderr


@pytest.mark.slow   # a record diagnosed with and without its reference, the temperature test calibrated on its nulls (40 s): make score
def test_no_static_part_is_calibrated_on_what_the_reference_leaves(tmp_path, cli):
    """A table that never stands still: the noise from the residual's high-pass, said in the notes."""
    p = cli("diagnose", _short(tmp_path, 200.0, static=False), "--runs", "10", "--json")
    d = json.loads(p.stdout)
    assert any("no static part" in n and "whole record" in n for n in d["notes"])
    assert d["consistent"], d["candidates"][:3]


def test_parse_add():
    assert parse_add("misalignment:3", 4) == ("misalignment", 3)
    assert parse_add("earth_rate", 4) == ("earth_rate", None)
    with pytest.raises(InputError):
        parse_add("arw:0", 4)


def test_a_ramp_in_the_model_tells_the_noise_fit_it_was_taken_out(monkeypatch):
    """With ``rate_ramp`` in the model, its regression takes part of the random walk out with the
    ramp, and the gyro's Allan fit reads K with the walk's column for that (``ramp_taken_out``);
    the other gyros' fits do not. Paired plain-numpy records (20 min, ARW 0.5 deg/√h, K 30
    deg/h/√h, 30 records with and without a 2000 deg/h² ramp on gyro 1) read K 6.1 ± 2.0 % low
    with the ramp in the model before, −0.2 ± 1.9 % after (closing note of this change)."""
    import gyroarray.chain.compare as compare_mod
    from gyroarray.core.measurement import Measurement

    seen = {}
    real = compare_mod.fit_gyro_noise

    def spy(e, dt_s, gyro, **kw):
        if e.size == n:                                    # the stochastic record's fits
            seen[gyro] = kw.get("ramp_taken_out", False)
        return real(e, dt_s, gyro, **kw)

    monkeypatch.setattr(compare_mod, "fit_gyro_noise", spy)
    n, dt = 12000, 0.01                                    # 2 min: the spy needs no more
    rng = np.random.default_rng(5)
    y = 1e-3 * rng.standard_normal((n, 3)) + np.cumsum(1e-6 * rng.standard_normal((n, 3)), axis=0)
    y[:, 0] += 1e-6 * np.arange(n)
    m = Measurement(time_s=dt * np.arange(n), gyro_deg_s=np.degrees(y), layout=Layout.triad(),
                    sample_rate_hz=1 / dt)
    _, after = ModelComparison(m, n_runs=3).fit([("rate_ramp", 1)])
    assert ("rate_ramp", 1) in after.fits
    assert seen == {1: True, 2: False, 3: False}, seen
