"""``diagnose`` names a fault like any other missing effect, and ``fit --add`` explains it.

Each case is a practice-shaped record (:func:`gyroarray.sim.cases.single_effect_case`:
20 min static, steps and swings, 5 min static, 50 Hz) with one fault on one
gyro. The fitted numbers are checked against a plain numpy reading of the
record written here, not against gyroarray's own fit of it:

* step: the mean of the gyro's residual (output − nominal axis · reference)
  over the 60 s after the onset minus the 60 s before;
* drift: the least-squares slope of that residual after the onset minus the
  slope before (the random walk's slope over the same spans is its noise);
* stuck: the first sample from which the raw output column never changes;
* noise: the ratio of the standard deviations of the residual's first
  differences after and before the onset.

Tolerances are the sampling spread of these plain estimates (stated per test).
"""

from __future__ import annotations

import numpy as np
import pytest

from gyroarray.chain.compare import ModelComparison
from gyroarray.sim.cases import single_effect_case

SEED = 100


def _residual_deg_s(c):
    m = c.measurement
    H = np.asarray(m.layout.axes, float)
    return m.gyro_deg_s - m.ref_deg_s @ H.T, m.time_s


#: every fault case runs in make score (`pytest -m slow`; also benchmarks/diagnosis_score.py):
#: stuck, the last in make test, moved this stop (15 s on 2 cores; test_faults.py tests each
#: fault's scan fast)
FAULTS = [pytest.param("fault_step", marks=pytest.mark.slow), pytest.param("fault_drift", marks=pytest.mark.slow),
          pytest.param("fault_stuck", marks=pytest.mark.slow), pytest.param("fault_noise", marks=pytest.mark.slow)]


@pytest.fixture(scope="module", params=FAULTS)
def fitted(request):
    c = single_effect_case(request.param, SEED)
    before, after = ModelComparison(c.measurement, n_runs=20).fit([(request.param, c.gyro)])
    return request.param, c, before, after


def test_the_fault_is_named_first_and_explains_the_record(fitted):
    effect, c, before, after = fitted
    top = before.candidates[0]
    assert (top.effect, top.gyro) == (effect, c.gyro), [(t.effect, t.gyro, t.z) for t in before.candidates[:4]]
    assert before.significant(top) and not before.consistent
    assert after.discrepancy < 0.5 * before.discrepancy
    assert after.consistent, [(t.effect, t.gyro, t.z) for t in after.tests if after.significant(t)]
    # every rival it beat on its gyro says why
    for t in before.candidates[1:]:
        if t.gyro == c.gyro and before.significant(t) and t.effect != effect and t.explained_by is None:
            assert "; but" in t.evidence, t.evidence


def test_the_fitted_fault_agrees_with_a_plain_reading_of_the_record(fitted):
    effect, c, _, after = fitted
    f = after.fits[(effect, c.gyro)]
    e, t = _residual_deg_s(c)
    g = c.gyro - 1
    on = float(c.params["start_s"])
    k = int(np.searchsorted(t, on))
    if effect == "fault_stuck":
        y = c.measurement.gyro_deg_s[:, g]
        changes = np.flatnonzero(np.diff(y) != 0.0)
        # the endless run starts with the last sample the gyro gave; the fault with the next one,
        # the first that repeats it (spec: "the last value it gave before start_s, forever")
        frozen_from = float(t[changes[-1] + 2])
        assert f.params["start_s"] == pytest.approx(frozen_from, abs=1e-9)
        assert frozen_from == pytest.approx(t[np.searchsorted(t, on)], abs=1e-9)
        return
    # the onset: within 3σ of the fit, or 1 s (a step or a noise change is sharp at 50 Hz)
    assert abs(f.params["start_s"] - on) <= max(3.0 * f.sigma["start_s"], 1.0 if effect != "fault_drift" else 150.0)
    if effect == "fault_step":
        w = int(60.0 / (t[1] - t[0]))
        plain = e[k:k + w, g].mean() - e[k - w:k, g].mean()
        # 60 s of white noise at ARW ≤ 0.25 deg/√h: σ(mean) ≤ 0.25/60/√60 ≈ 5e-4 deg/s; the two
        # means and the random walk over 60 s (K ≤ 8 deg/h/√h: ≤ 3e-4 deg/s) add in quadrature
        assert f.params["size_deg_s"] == pytest.approx(plain, abs=2.5e-3)
        assert f.params["size_deg_s"] == pytest.approx(c.params["size_deg_s"], abs=3.0 * f.sigma["size_deg_s"] + 1e-3)
    elif effect == "fault_drift":
        after_slope = np.polyfit(t[k:], e[k:, g], 1)[0]
        before_slope = np.polyfit(t[:k], e[:k, g], 1)[0]
        plain = after_slope - before_slope
        # the random walk's slope over a span T has σ ≈ K·√(6/(5T)) … at K = 8 deg/h/√h and T ≥ 300 s
        # that is ≤ 1e-5 deg/s²; the fit and the plain slopes agree within that and the fit's 3σ
        assert f.params["rate_deg_s2"] == pytest.approx(plain, abs=3.0 * f.sigma["rate_deg_s2"] + 1e-5)
        assert f.params["rate_deg_s2"] == pytest.approx(c.params["rate_deg_s2"], rel=0.10, abs=2.0 * f.sigma["rate_deg_s2"])
    else:                                                   # fault_noise
        d = np.diff(e[:, g])
        plain = d[k:].std() / d[:k - 1].std()
        # n ≥ 1e4 differences each side: σ(ratio)/ratio = ½√(3/n_a + 3/n_b) ≤ 1.3 %
        assert f.params["ratio"] == pytest.approx(plain, rel=0.02)
        assert f.params["ratio"] == pytest.approx(c.params["ratio"], rel=0.05)
