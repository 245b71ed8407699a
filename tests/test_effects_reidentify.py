"""Re-identification: simulate each stochastic effect, fit it back, compare.

Allan-visible terms (ARW N, RRW K, bias instability B, quantization Q,
rate ramp R) are fitted with the IEEE Std 952 noise fit of
:mod:`gyroarray.analysis.allan` (``allan_analysis(..., terms=...)``, GLS with
the correlation between taus, 1σ uncertainties), restricted to the terms the
simulated model has: this checks the simulator (does the simulated process
have the stated coefficient?), not the fit's ability to tell terms apart.
Gauss–Markov σ and τc are fitted with the noise fit the diagnosis uses
(:func:`gyroarray.effects.stochastic.fit_gyro_noise`, the term in the
model: GLS on the Allan variance with the covariance between taus); the
correlation of the white draws with the sample correlation matrix (Fisher z,
Bonferroni).

Tolerances. A fitted coefficient must lie within K_BAND·σ_true of the value
simulated, σ_true = c·σ_fit: σ_fit is the fit's own 1σ and c the RMS of
z = (fit − true)/σ_fit measured over 300 seeds (1000–1299, disjoint from the
test seeds) with exactly the set-up of the test, rounded up to 0.05 and at
least 1 (below 1 the fit's σ is conservative and is used as it is):

    check                              RMS(z)  mean(z)  95 % of |z|   c
    ARW N (terms n)                    1.07    −0.06    2.1           1.1
    RRW K (terms n, k)                 0.93    −0.01    1.8           1
    rate ramp R (terms n, r)           0.45    −0.00    0.8           1
    bias instability B (terms n, b)    1.02    −0.04    1.9           1.05
    quantization Q (terms q, n)        0.95    +0.73    1.6           1
    Gauss–Markov σ (term in model)     0.91    +0.02    1.7           1
    Gauss–Markov τc (term in model)    0.92    −0.00    1.7           1

Both fits' σ are close to calibrated (their GLS accounts for the
correlation between octaves).

The band is the issue's 2σ (in σ_true). A 2σ band holds for one seed with
probability 95.4 %, so a single-seed 2σ assertion would encode "fails for one
seed in 22". Instead each check runs seeds 0–9 (fixed, so deterministic) and
asserts (a) at least 8 of the 10 fits inside 2σ_true — for a correct
simulator P(X >= 8 | n = 10, p = 0.954) = 0.99 — and (b) every fit inside
4σ_true (a gross-error guard, P = 6e-5 per fit). The correlation checks are
exact-level tests (Bonferroni, stated family-wise level 0.1 %).

Everything runs 2 h at 100 Hz (720 000 samples) unless stated.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal, stats

from gyroarray.analysis.allan import allan_analysis, edf, oadev
from gyroarray.core.layout import Layout
from gyroarray.core.sensor import output_lattice_step
from gyroarray.effects.stochastic import fit_gyro_noise
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.core.units import (arw_deg_rt_h_to_rad_rt_s, deg_h_to_rad_s, deg_s_to_rad_s, deg_to_rad,
                             ramp_deg_h2_to_rad_s2, rrw_deg_h_rt_h_to_rad_s_rt_s)

DT = 0.01
N_2H = 720_000
TRIAD = Layout.triad()
SEED = 0

#: c of σ_true = c·σ_fit for each check, and the band in σ_true (module docstring).
C = {"n": 1.1, "k": 1.0, "r": 1.0, "b": 1.05, "q": 1.0, "gm_sigma": 1.0, "gm_tau": 1.0}
K_BAND = 2.0
#: Seeds of the band checks, how many of them must fall inside K_BAND, and the gross-error guard.
SEEDS = range(10)
MIN_INSIDE = 8
GROSS_BAND = 4.0
#: Family-wise level of the exact-level tests: a correct simulator fails a seed with probability
#: <= 0.1 % (Bonferroni over the points or pairs of one test).
ALPHA = 0.001


def simulate(effects, seed, n=N_2H, layout=TRIAD, omega=None):
    m = NoiseModel.from_toml({"effects": effects}, n_gyros=layout.n_gyros)
    w = np.zeros((n, 3)) if omega is None else omega
    return simulate_readings(m, w, layout, DT, np.random.default_rng(seed))


def fitted(rate, term, terms):
    """(value, σ_fit) of one IEEE 952 term from the Allan fit of one gyro's rate."""
    return allan_analysis(rate, DT, terms=terms).fit.coefficient(term)


def assert_band(results, c):
    """results: (value, true, sigma) per seed; see the module docstring for the rule."""
    z = [(v - t) / (c * s) for v, t, s in results]
    assert sum(abs(x) <= K_BAND for x in z) >= MIN_INSIDE, z
    assert all(abs(x) <= GROSS_BAND for x in z), z


# -- the IEEE 952 terms ------------------------------------------------------
#
# Each check_* returns (fitted, true, sigma_fit); the test asserts, and the
# seed-robustness count in the report runs the same function over seeds 0-19.

def check_arw(seed):
    n_true = 0.1  # deg/√h
    y = simulate([{"effect": "arw", "n_deg_rt_h": n_true}], seed)
    value, sigma = fitted(y[:, 0], "n", ("n",))
    return value, arw_deg_rt_h_to_rad_rt_s(n_true), sigma


def check_rrw(seed):
    # K = 100 deg/h/√h dominates ARW 0.1 deg/√h beyond τ = 3N²/K² ≈ 39 s: 7 octaves of the record
    y = simulate([{"effect": "arw", "n_deg_rt_h": 0.1}, {"effect": "rrw", "k_deg_h_rt_h": 100.0}], seed)
    value, sigma = fitted(y[:, 0], "k", ("n", "k"))
    return value, rrw_deg_h_rt_h_to_rad_s_rt_s(100.0), sigma


def check_bias_instability(seed):
    # B = 3 deg/h: the plateau 0.664·B is above the ARW line beyond τ ≈ 9 s
    y = simulate([{"effect": "arw", "n_deg_rt_h": 0.1}, {"effect": "bias_instability", "b_deg_h": 3.0}],
                 seed)
    value, sigma = fitted(y[:, 0], "b", ("n", "b"))
    return value, deg_h_to_rad_s(3.0), sigma


def check_rate_ramp(seed):
    y = simulate([{"effect": "arw", "n_deg_rt_h": 0.1}, {"effect": "rate_ramp", "r_deg_h2": 50.0}], seed)
    value, sigma = fitted(y[:, 0], "r", ("n", "r"))
    return value, ramp_deg_h2_to_rad_s2(50.0), sigma


def table_triangle(n, amp_deg_s=10.0, period_s=100.0):
    """The table turns about x with a triangle-wave rate (uniformly distributed in ±amp)."""
    t = np.arange(n) * DT
    w = np.zeros((n, 3))
    w[:, 0] = deg_s_to_rad_s(amp_deg_s) * signal.sawtooth(2 * np.pi * t / period_s, 0.5)
    return w


QUANT = [{"effect": "arw", "n_deg_rt_h": 0.05}, {"effect": "quantization", "q_deg": 1e-3}]


def check_quantization(seed):
    # Angle quantization noise (the dithered counter's uniform angle error): its Allan variance is
    # 3Q²/τ² whatever the table does; here on the table's triangle-wave rate, the residual against
    # the table's rate being quantization + ARW.
    w = table_triangle(N_2H)
    y = simulate(QUANT, seed, omega=w)
    value, sigma = fitted(y[:, 0] - w[:, 0], "q", ("q", "n"))
    return value, deg_to_rad(1e-3), sigma


@pytest.mark.parametrize("check,c", [(check_arw, C["n"]), (check_rrw, C["k"]),
                                     (check_bias_instability, C["b"]), (check_rate_ramp, C["r"]),
                                     (check_quantization, C["q"])],
                         ids=["arw_N", "rrw_K", "bias_instability_B", "rate_ramp_R", "quantization_Q"])
def test_ieee952_term_is_reidentified(check, c):
    results = [check(seed) for seed in SEEDS]
    for value, true, sigma in results:
        assert sigma is not None and 0 < sigma < 0.2 * true    # a meaningful uncertainty
    assert_band(results, c)


def test_quantization_at_rest_is_the_correlated_regime():
    # The spec's counter (shared/spec/effects.md, "Definition of quantization"): at rest, with
    # only ARW (8e-5 deg per sample against a step of 3.5e-3 deg), the angle error follows the
    # slow angle and is not white: the 3Q²/τ² column reads about half of Q, > 4σ off (the old dithered
    # counter gave Q back here), while the output's grid gives the step exactly
    # (tests/test_spec_quantization.py fits that regime).
    step = math.sqrt(12.0) * deg_to_rad(1e-3)
    for seed in SEEDS[:4]:
        y = simulate(QUANT, seed, n=N_2H // 4)
        value, sigma = fitted(y[:, 0], "q", ("q", "n"))
        assert value < 0.7 * deg_to_rad(1e-3) and deg_to_rad(1e-3) - value > 4.0 * sigma, (value, sigma)
        assert output_lattice_step(y[:, 0]) * DT == pytest.approx(step, rel=1e-9)


def test_flicker_plateau_is_flat_at_0664_b():
    # 3 gyros x 1 h of pure flicker: the mean of their Allan variances at each octave from 0.32 s
    # to T/40 (90 s) against (2 ln 2/π)·B². One gyro's estimate is σ²·χ²_ν/ν with ν the flicker-FM
    # EDF (Greenhall) of that octave, so the mean of 3 is σ²·χ²_3ν/(3ν): each point within its
    # χ² interval, two-sided, Bonferroni over the points at family-wise ALPHA. Below 0.32 s the
    # *sampled* flicker is measurably above the continuous-time plateau (+9 % ADEV at τ = dt,
    # +0.5 % at 0.08 s, mean of 60 realisations), which this test would see; above T/40 the
    # estimates are too scattered to say anything.
    b = deg_h_to_rad_s(3.0)
    y = simulate([{"effect": "bias_instability", "b_deg_h": 3.0}], SEED, n=N_2H // 2)
    results = [oadev(y[:, k], DT) for k in range(3)]
    res = results[0]
    avar = np.mean([r.avar for r in results], axis=0)
    band = (res.taus_s >= 0.32) & (res.taus_s <= len(y) * DT / 40)
    nu3 = 3 * edf("oadev", res.n_phase, res.m[band], -1)
    a = ALPHA / band.sum()
    lo = stats.chi2.ppf(a / 2, nu3) / nu3
    hi = stats.chi2.ppf(1 - a / 2, nu3) / nu3
    ratio = avar[band] / (2 * math.log(2) / math.pi * b**2)
    assert band.sum() >= 8
    assert np.all((ratio > lo) & (ratio < hi)), (ratio, lo, hi)


# -- Gauss–Markov ------------------------------------------------------------

def check_gauss_markov(seed):
    sigma, tau_c = 20.0, 10.0   # deg/h, s: peak at 1.89 τc = 19 s, 7.5 octaves below T/2
    y = simulate([{"effect": "gauss_markov", "sigma_deg_h": sigma, "tau_s": tau_c}], seed)
    fit = {f.effect: f for f in fit_gyro_noise(y[:, 0], DT, 1, gm_tau_s=tau_c)}["gauss_markov"]
    return fit, sigma, tau_c


def test_gauss_markov_sigma_and_tau_are_reidentified():
    runs = [check_gauss_markov(seed) for seed in SEEDS]
    assert_band([(f.params["sigma_deg_h"], sigma, f.sigma["sigma_deg_h"]) for f, sigma, _ in runs],
                C["gm_sigma"])
    assert_band([(f.params["tau_s"], tau_c, f.sigma["tau_s"]) for f, _, tau_c in runs], C["gm_tau"])
    fit = runs[0][0]
    # the model has the right shape: χ²/dof over 300 seeds has mean 0.83, 99 % quantile 1.8 and
    # maximum 2.2 (the fit's generalized χ² with the covariance between taus)
    assert fit.extra["chi2"] / fit.extra["dof"] < 4.0


# -- correlation of the white draws ------------------------------------------

CONE6 = Layout.conical(1, 6, math.acos(1 / math.sqrt(3)))
RHO6 = np.array([[1.0, 0.5, 0.25, 0.0, -0.2, 0.1],
                 [0.5, 1.0, 0.5, 0.25, 0.0, -0.2],
                 [0.25, 0.5, 1.0, 0.5, 0.25, 0.0],
                 [0.0, 0.25, 0.5, 1.0, 0.5, 0.25],
                 [-0.2, 0.0, 0.25, 0.5, 1.0, 0.5],
                 [0.1, -0.2, 0.0, 0.25, 0.5, 1.0]])


def fisher_ok(x: np.ndarray, rho: np.ndarray, alpha: float = ALPHA) -> bool:
    """All pairwise sample correlations within their Fisher-z interval, Bonferroni over pairs.

    atanh(r) is ≈ normal with mean atanh(ρ) and sd 1/√(n − 3) for bivariate normal samples; with
    N(N−1)/2 pairs each gets α/(N(N−1)/2), two-sided.
    """
    n, k = x.shape
    r = np.corrcoef(x.T)
    iu = np.triu_indices(k, 1)
    z_crit = stats.norm.ppf(1 - alpha / (2 * len(iu[0])))
    dev = np.abs(np.arctanh(r[iu]) - np.arctanh(rho[iu])) * math.sqrt(n - 3)
    return bool(np.all(dev <= z_crit))


def variance_ok(x: np.ndarray, sigma: np.ndarray, alpha: float = ALPHA) -> bool:
    """Each column's sample variance within its χ²(n−1) interval, Bonferroni over columns."""
    n, k = x.shape
    lo, hi = stats.chi2.ppf([alpha / (2 * k), 1 - alpha / (2 * k)], n - 1) / (n - 1)
    ratio = x.var(axis=0, ddof=1) / sigma**2
    return bool(np.all((ratio > lo) & (ratio < hi)))


N_CORR = 100_000  # 1000 s: Fisher sd 1/√n = 0.003 in z


def check_arw_correlation_matrix(seed):
    # unequal σ: Σ_ij = ρ_ij σ_i σ_j must hold with gyro 4 three times noisier
    y = simulate([{"effect": "arw", "n_deg_rt_h": 0.1}, {"effect": "arw", "gyro": 4, "n_deg_rt_h": 0.3},
                  {"effect": "correlation", "rho_arw": RHO6.tolist()}], seed, n=N_CORR, layout=CONE6)
    sig = arw_deg_rt_h_to_rad_rt_s(np.array([0.1, 0.1, 0.1, 0.3, 0.1, 0.1])) / math.sqrt(DT)
    return fisher_ok(y, RHO6) and variance_ok(y, sig)


def check_rrw_correlation_scalar(seed):
    # the RRW increments (the differences of the readings) carry the correlation
    rho = -0.15   # inside (−1/(N−1), 1) = (−0.2, 1) for N = 6
    y = simulate([{"effect": "rrw", "k_deg_h_rt_h": 10.0}, {"effect": "correlation", "rho_rrw": rho}],
                 seed, n=N_CORR, layout=CONE6)
    inc = np.diff(y, axis=0)
    sig = np.full(6, rrw_deg_h_rt_h_to_rad_s_rt_s(10.0) * math.sqrt(DT))
    return fisher_ok(inc, (1 - rho) * np.eye(6) + rho) and variance_ok(inc, sig)


def check_common_mode(seed):
    rho = 0.4
    y = simulate([{"effect": "arw", "n_deg_rt_h": 0.2},
                  {"effect": "correlation", "rho_arw": rho, "common_mode": True}], seed, n=N_CORR,
                 layout=CONE6)
    sig = np.full(6, arw_deg_rt_h_to_rad_rt_s(0.2) / math.sqrt(DT))
    # one shared source: the mean over gyros has variance σ²(ρ + (1 − ρ)/N), χ²(n−1)
    mean_ok = variance_ok(y.mean(axis=1, keepdims=True), np.array([sig[0] * math.sqrt(rho + (1 - rho) / 6)]))
    return fisher_ok(y, (1 - rho) * np.eye(6) + rho) and variance_ok(y, sig) and mean_ok


@pytest.mark.parametrize("check", [check_arw_correlation_matrix, check_rrw_correlation_scalar,
                                   check_common_mode],
                         ids=["arw_matrix", "rrw_scalar", "common_mode"])
def test_correlation_is_reidentified(check):
    assert check(SEED)


def test_common_mode_and_cholesky_are_different_realisations_of_one_law():
    base = [{"effect": "arw", "n_deg_rt_h": 0.2}]
    a = simulate(base + [{"effect": "correlation", "rho_arw": 0.4, "common_mode": True}], 3,
                 n=N_CORR, layout=CONE6)
    b = simulate(base + [{"effect": "correlation", "rho_arw": 0.4}], 3, n=N_CORR, layout=CONE6)
    assert not np.array_equal(a, b)
    rho = 0.6 * np.eye(6) + 0.4
    assert fisher_ok(a, rho) and fisher_ok(b, rho)
