"""The tapered Whittle fit (gyroarray.analysis.whittle, issue 45) against the Cramér–Rao bound."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroarray.analysis import crb, whittle
from gyroarray.core.errors import InputError

N_, K_, DT = 1e-3, 1e-3, 0.01            # τ_K = N/K = 1 s, 100 Hz
T_S = 100.0                              # T/τ_K = 100
N_SAMPLES = int(round(T_S / DT))


def _records(r: int, seed: int):
    rng = np.random.default_rng(seed)
    for _ in range(r):
        yield (N_ / math.sqrt(DT) * rng.standard_normal(N_SAMPLES)
               + np.cumsum(K_ * math.sqrt(DT) * rng.standard_normal(N_SAMPLES)))


def _k_stats(r: int, seed: int):
    k = np.array([whittle.fit_whittle(x, DT, ("n", "k")).values["k"] for x in _records(r, seed)]) / K_
    bound = crb.crb({"n": N_, "k": K_}, DT, n_samples=N_SAMPLES).rel["k"]   # 14.45 %
    rmse = math.sqrt(float(np.mean((k - 1.0) ** 2)))
    return k, bound, (bound / rmse) ** 2


def test_efficiency_30_records():
    # seeds 101, 102, 103, 145 read efficiency 1.09, 0.93, 0.90, 1.03 (seed 20261203: bias -5.3 %,
    # 2.2 MC σ, which a 2σ check refuses on 5 % of seeds: hence 3σ below)
    k, bound, eff = _k_stats(30, 101)
    # the estimator's true efficiency is 0.92 (1000 records, two seeds: 0.918, 0.928). Over 30
    # records the mean square error has a relative sd √(2/30) = 0.26 (normal errors), so a true
    # efficiency of 0.9 reads above 0.9/(1 + 2·0.26) = 0.59 with 2σ (97.7 %) confidence
    assert eff >= 0.59
    # no bias beyond 3 Monte Carlo σ of the mean (an unbiased estimator fails this on 0.3 % of seeds)
    assert abs(k.mean() - 1.0) <= 3.0 * k.std(ddof=1) / math.sqrt(len(k))


@pytest.mark.slow
def test_efficiency_200_records():
    k, bound, eff = _k_stats(200, 1)
    # the issue asks for efficiency (CRB variance over the MSE) >= 0.9 on 200 records. An
    # efficiency from 200 records has a Monte Carlo sd of √(2/200)·eff ≈ 0.09 (the MSE of 200
    # near-normal errors is a χ²₂₀₀/200), so a single 200-record reading cannot show >= 0.9: seeds
    # 1-5 and 45 read 0.906, 0.966, 0.884, 0.909, 0.873, 0.805 around the true 0.92 (1000 records,
    # two seeds: 0.918, 0.928). The test asserts what 200 records can: the reading is consistent
    # with an efficiency of at least 0.9 (within 2 MC sd below it: eff >= 0.9 - 2·0.09 = 0.72),
    # which an estimator at the Allan fit's 0.72-0.82 would fail about half of the time and one at
    # the slope reading's 0.27 always.
    sd_mc = math.sqrt(2.0 / len(k)) * 0.9
    assert eff >= 0.9 - 2.0 * sd_mc
    assert abs(k.mean() - 1.0) <= 3.0 * k.std(ddof=1) / math.sqrt(len(k))


def test_taper_is_needed():
    # the gyro: N = 0.3 deg/√h, K = 41 deg/h/√h at 100 Hz (τ_K = 26.3 s), T/τ_K = 100
    n_, k_, dt = 8.7266e-5, 3.3135e-6, 0.01
    n = int(round(100 * (n_ / k_) / dt))
    rng = np.random.default_rng(5)
    x = n_ / math.sqrt(dt) * rng.standard_normal(n) + np.cumsum(k_ * math.sqrt(dt) * rng.standard_normal(n))
    plain = whittle.fit_whittle(x, dt, ("n", "k"), taper=0.0).values["k"] / k_
    tapered = whittle.fit_whittle(x, dt, ("n", "k")).values["k"] / k_
    # untapered, the white noise's differenced end samples put 2N²/(m dt) = 2τ_K²/(T dt) = 53 × the
    # walk's K²dt at every frequency: K read about √53 ≈ 7 times too high
    assert plain > 3.0
    assert abs(tapered - 1.0) < 4 * 0.1445            # within 4 CRB σ


def test_fields_and_parts():
    x = next(_records(1, 11))
    fit = whittle.fit_whittle(x, DT, ("n", "k"), parts=[(0, 4000), (4500, 10000)])
    assert fit.converged
    kappa = whittle.taper_inflation(whittle.tukey(5499, whittle.TAPER))
    # the efficiency is 1/κ at the fitted values (the whole band): κ = 1.026 for a 5 % Tukey taper
    assert fit.efficiency["k"] == pytest.approx(1.0 / fit.inflation, rel=1e-6)
    assert fit.inflation == pytest.approx(kappa, rel=0.01)
    assert 1.02 < kappa < 1.03
    bound = crb.crb(fit.values, DT, parts=[(0, 4000), (4500, 10000)])
    assert fit.crb["k"] == pytest.approx(bound.sd["k"], rel=1e-12)
    assert fit.to_json_dict()["taper"] == "Tukey"
    # N from ~5000 ordinates: relative CRB 1/√(2·10⁴) = 0.7 %; within 5σ
    assert fit.values["n"] / N_ == pytest.approx(1.0, abs=5 * 0.0071)


def test_more_terms_recovered():
    rng = np.random.default_rng(3)
    n, dt, q, tau, sig = 200_000, 0.01, 1e-5, 2.0, 3e-3
    phi = math.exp(-dt / tau)
    z = rng.standard_normal(n) * sig * math.sqrt(1 - phi * phi)
    gm = np.empty(n)
    gm[0] = sig * rng.standard_normal()
    for i in range(1, n):
        gm[i] = phi * gm[i - 1] + z[i]
    ang = q * rng.standard_normal(n + 1)
    x = N_ / math.sqrt(dt) * rng.standard_normal(n) + gm + np.diff(ang) / dt
    fit = whittle.fit_whittle(x, dt, ("n", "q", "gm"))
    truth = {"n": N_, "q": q, "gm_sigma": sig, "gm_tau": tau}
    for p, v in truth.items():
        # each within 4 of its own CRB σ (at the truth)
        assert abs(fit.values[p] - v) <= 4.0 * crb.crb(truth, dt, n_samples=n).sd[p], p


def test_bad_input():
    with pytest.raises(InputError):
        whittle.fit_whittle(np.zeros(1000), DT)
    with pytest.raises(InputError):
        whittle.fit_whittle(np.ones(10), DT, ("n", "k", "q"))


def test_bias_instability_from_the_project_flicker_simulator():
    """The ``b`` spectrum is the one :func:`gyroarray.core.physics.flicker_noise` makes."""
    from gyroarray.core.physics import flicker_noise
    n, dt, n_, b_ = 1 << 17, 0.01, 1e-3, 2e-4
    rel = crb.crb({"n": n_, "b": b_}, dt, n_samples=n).rel["b"]          # 17.9 %
    got = []
    for seed in range(8):
        rng = np.random.default_rng(seed)
        x = flicker_noise(n, dt, [b_], [rng])[:, 0] + n_ / math.sqrt(dt) * rng.standard_normal(n)
        got.append(whittle.fit_whittle(x, dt, ("n", "b")).values["b"] / b_)
    got = np.array(got)
    # the mean of 8 within 3 CRB σ/√8 (a B² convention off by 2 would read 0.71 or 1.41)
    assert abs(got.mean() - 1.0) <= 3.0 * rel / math.sqrt(len(got))
    assert np.all(np.abs(got - 1.0) <= 4.0 * rel)
