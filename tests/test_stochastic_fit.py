"""Fit side of the stochastic, array and time effects (src/gyroarray/effects/stochastic.py, correlation.py, burst.py, gauss_markov.py).

Data come from the project's simulator (``simulate_readings`` with a zero
truth: a static record, so the output is the residual). Seeds are explicit
``numpy.random.default_rng`` seeds, so every check is deterministic.

Two kinds of checks:

* present: baseline (ARW 0.1–0.5 deg/√h, RRW 10–600 deg/h/√h) plus one
  effect at a clearly visible level; the fitted parameter must be within
  10 % or 2σ of the value simulated and z > 5;
* null: the baseline alone for 20 seeds (ARW and RRW drawn in those ranges);
  for every term at most 2 of the 20 |z| may exceed 3. If z is standard
  normal, P(|z| > 3) = 0.0027 and P(at least 3 of 20) = 2e-5; even a tail
  five times too heavy (P = 0.0135) fails only with probability 0.002. So a
  failure means a miscalibrated z, not bad luck. (The calibration itself was
  measured on hundreds of seeds; see the module docstring.)
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import stats

from gyroarray.analysis import allan_gls
from gyroarray.effects import burst as burst_fit, correlation as correlation_fit, gauss_markov as gm_fit
from gyroarray.effects import stochastic as sf
from gyroarray.analysis.avar_covariance import AvarCovariance
from gyroarray.analysis.allan import edf
from gyroarray.effects.fitting import EffectFit, z_from_log_p
from gyroarray.analysis.noise_fit import term_basis
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.sim.effects import REGISTRY, simulate_readings
from gyroarray.effects.model import NoiseModel

DT = 0.01
N_46MIN = 276_000            # 46 min at 100 Hz
N_20MIN = 120_000
TRIAD = Layout.triad()
CONE4 = Layout.conical(1, 4, math.radians(54.7356))


def simulate(effects, seed, layout=TRIAD, n=N_46MIN):
    m = NoiseModel.from_toml({"effects": effects}, n_gyros=layout.n_gyros)
    return simulate_readings(m, np.zeros((n, 3)), layout, DT, np.random.default_rng(seed))


def baseline(arw=0.2, rrw=30.0):
    return [{"effect": "arw", "n_deg_rt_h": arw}, {"effect": "rrw", "k_deg_h_rt_h": rrw}]


def by_effect(fits):
    return {f.effect: f for f in fits}


def close(value, truth, sigma):
    """Within 10 % or 2σ of the value simulated."""
    return abs(value - truth) <= max(0.1 * abs(truth), 2.0 * sigma)


def check_valid_entry(fit: EffectFit):
    """The parameters are the spec's names, and the entry makes a valid model."""
    names = set(REGISTRY[fit.effect].param_names)
    assert set(fit.params) <= names and set(fit.sigma) <= set(fit.params)
    assert all(math.isfinite(v) and v >= 0 for v in fit.sigma.values())
    NoiseModel.from_toml({"effects": [fit.entry()]}, n_gyros=4)


# -- the covariance of the Allan variance estimates ---------------------------

def test_estimate_covariance_agrees_with_greenhall_edf():
    """Diagonal of the exact covariance = 2 σ⁴/ν with Greenhall's EDF of one noise
    type (white FM, flicker FM, white PM at every τ; RW FM from m = 8: at m = 1, 2
    the sampled random walk's Allan variance exceeds the continuous K²τ/3)."""
    n = N_20MIN
    m = allan_gls.factors(n)
    cov = AvarCovariance(m, n + 1 - 2 * m, 2, DT)
    taus = m * DT
    for key, alpha in (("n", 0), ("b", -1), ("q", 2), ("k", -2)):
        var = np.diag(cov.covariance({key: 1.0}))
        expect = 2.0 * term_basis("oadev", key, taus) ** 2 / edf("oadev", n + 1, m, np.full(m.size, alpha))
        use = m >= 8 if key == "k" else np.ones(m.size, bool)
        np.testing.assert_allclose(var[use], expect[use], rtol=0.015)


# -- present: one effect at a clearly visible level ----------------------------

def test_baseline_terms_are_recovered():
    fits = by_effect(sf.fit_gyro_noise(simulate(baseline(0.2, 100.0), 1)[:, 0], DT, 1))
    arw, rrw = fits["arw"], fits["rrw"]
    assert close(arw.params["n_deg_rt_h"], 0.2, arw.sigma["n_deg_rt_h"]) and arw.z > 5
    assert close(rrw.params["k_deg_h_rt_h"], 100.0, rrw.sigma["k_deg_h_rt_h"]) and rrw.z > 5
    assert "gyro 1" in arw.evidence and "deg/√h" in arw.evidence


def test_bias_instability_is_found_on_every_gyro():
    y = simulate(baseline(0.2, 30.0) + [{"effect": "bias_instability", "b_deg_h": 6.0}], 2)
    for g in range(3):
        f = by_effect(sf.fit_gyro_noise(y[:, g], DT, g + 1))["bias_instability"]
        assert f.z > 5, f.evidence
        assert close(f.params["b_deg_h"], 6.0, f.sigma["b_deg_h"]), (f.params, f.sigma)
        assert f"gyro {g + 1} ADEV flattens" in f.evidence and "ARW + RRW alone predicts" in f.evidence
        check_valid_entry(f)


def test_quantization_is_found():
    y = simulate(baseline(0.2, 30.0) + [{"effect": "quantization", "q_deg": 5e-5}], 3)
    f = by_effect(sf.fit_gyro_noise(y[:, 0], DT, 1))["quantization"]
    assert f.z > 5 and close(f.params["q_deg"], 5e-5, f.sigma["q_deg"]), (f.params, f.sigma, f.z)
    check_valid_entry(f)


@pytest.mark.parametrize("r_deg_h2", [200.0, -200.0])
def test_rate_ramp_is_found_with_its_sign(r_deg_h2):
    y = simulate(baseline(0.2, 10.0) + [{"effect": "rate_ramp", "r_deg_h2": r_deg_h2}], 4)
    fits = by_effect(sf.fit_gyro_noise(y[:, 0], DT, 1))
    f = fits["rate_ramp"]
    assert f.z > 5 and close(f.params["r_deg_h2"], r_deg_h2, f.sigma["r_deg_h2"]), (f.params, f.sigma)
    check_valid_entry(f)
    # the ramp is taken out before the Allan fits: no bias instability or RRW inflation
    assert fits["bias_instability"].extra["ramp_removed"]
    assert fits["bias_instability"].z < 3


def test_gauss_markov_is_found():
    y = simulate(baseline(0.2, 30.0) + [{"effect": "gauss_markov", "sigma_deg_h": 20.0, "tau_s": 10.0}], 5)
    f = by_effect(sf.fit_gyro_noise(y[:, 0], DT, 1))["gauss_markov"]
    assert f.z > 5, f.evidence
    assert close(f.params["sigma_deg_h"], 20.0, f.sigma["sigma_deg_h"]), (f.params, f.sigma)
    assert close(f.params["tau_s"], 10.0, f.sigma["tau_s"]), (f.params, f.sigma)
    assert "hump" in f.evidence
    check_valid_entry(f)
    # the sentence's numbers at the hump's peak: the measured ADEV is allantools' there, and the
    # fitted model with the hump is within 10 % of it (the ADEV's own 1σ there is ~1 %)
    import allantools
    x = np.degrees(y[:, 0]) * 3600.0
    _, ad, _, _ = allantools.oadev(x, rate=1.0 / DT, data_type="freq", taus=[f.extra["peak_tau_s"]])
    assert abs(f.extra["peak_tau_s"] / (1.89 * f.params["tau_s"]) - 1.0) < 0.5           # the nearest octave
    assert f.extra["peak_adev_deg_h"] == pytest.approx(float(ad[0]), rel=1e-9)
    assert f.extra["peak_model_adev_deg_h"] == pytest.approx(float(ad[0]), rel=0.1)
    assert f.extra["peak_rest_adev_deg_h"] < 0.9 * f.extra["peak_adev_deg_h"]
    assert f"{f.extra['peak_adev_deg_h']:.3g} deg/h at τ = {f.extra['peak_tau_s']:.3g} s" in f.evidence


def test_correlation_of_arw_and_rrw_is_found():
    y = simulate(baseline(0.2, 300.0) + [{"effect": "correlation", "rho_arw": 0.3, "rho_rrw": 0.5}], 6,
                 layout=CONE4)
    fa, fr = correlation_fit.fit_correlation(y, DT)
    assert (fa.extra["family"], fr.extra["family"]) == ("rho_arw", "rho_rrw")
    assert fa.z > 5 and close(fa.params["rho_arw"], 0.3, fa.sigma["rho_arw"]), (fa.params, fa.sigma)
    assert fr.z > 5 and close(fr.params["rho_rrw"], 0.5, fr.sigma["rho_rrw"]), (fr.params, fr.sigma)
    mat = np.array(fa.extra["matrix"])
    assert mat.shape == (4, 4) and np.allclose(mat, mat.T) and np.allclose(np.diag(mat), 1.0)
    assert np.all(np.array(fa.extra["z_matrix"])[np.triu_indices(4, 1)] > 5)
    for f in (fa, fr):
        assert f.gyro is None and f.effect == "correlation"
        check_valid_entry(f)


def test_burst_is_found_with_its_window_and_ratio():
    y = simulate(baseline(0.2, 30.0) + [{"effect": "burst", "start_s": 600.0, "end_s": 900.0,
                                         "variance_ratio": 3.0}], 7, layout=CONE4)
    t = np.arange(y.shape[0]) * DT
    f = burst_fit.fit_burst(y, t, DT)
    assert f.z > 5 and f.gyro is None
    for key, truth in (("start_s", 600.0), ("end_s", 900.0), ("variance_ratio", 3.0)):
        assert close(f.params[key], truth, f.sigma[key]), (key, f.params, f.sigma)
    # sharper than 10 %: the boundaries to a few samples, the ratio to 3σ
    assert abs(f.params["start_s"] - 600.0) < 0.1 and abs(f.params["end_s"] - 900.0) < 0.1
    assert abs(f.params["variance_ratio"] - 3.0) < 3.0 * f.sigma["variance_ratio"]
    assert "between 600" in f.evidence and "on all gyros" in f.evidence
    # the dynamic Allan variance agrees on the ratio (a window-averaged estimate: 15 %)
    assert abs(f.extra["davar"]["variance_ratio"] / 3.0 - 1.0) < 0.15
    check_valid_entry(f)


def test_burst_clock_is_the_records_clock():
    """A record whose clock starts at 1000 s reports the window on that clock."""
    m = NoiseModel.from_toml({"effects": baseline(0.3, 30.0) + [
        {"effect": "burst", "start_s": 1300.0, "end_s": 1400.0, "variance_ratio": 4.0}]}, n_gyros=4)
    t = 1000.0 + np.arange(N_20MIN) * DT
    y = simulate_readings(m, np.zeros((N_20MIN, 3)), CONE4, DT, np.random.default_rng(8), time_s=t)
    f = burst_fit.fit_burst(y, t, DT)
    assert f.z > 5
    assert abs(f.params["start_s"] - 1300.0) < 0.2 and abs(f.params["end_s"] - 1400.0) < 0.2


# -- null: the baseline alone, 20 seeds ---------------------------------------

NULL_SEEDS = range(100, 120)


@pytest.fixture(scope="module")
def null_runs():
    """20 static 4-gyro records of 20 min, ARW and RRW drawn log-uniformly in
    [0.1, 0.5] deg/√h and [10, 600] deg/h/√h (the drawing uses its own
    Generator, seeded like the record)."""
    runs = []
    for seed in NULL_SEEDS:
        pick = np.random.default_rng(seed + 10_000)
        arw = float(np.exp(pick.uniform(np.log(0.1), np.log(0.5))))
        rrw = float(np.exp(pick.uniform(np.log(10.0), np.log(600.0))))
        runs.append((seed, arw, rrw, simulate(baseline(arw, rrw), seed, layout=CONE4, n=N_20MIN)))
    return runs


def assert_calibrated(z, what):
    z = np.asarray(z, dtype=float)
    assert np.all(np.isfinite(z)), what
    assert np.count_nonzero(np.abs(z) > 3.0) <= 2, f"{what}: {np.round(z, 2)}"


def test_gyro_terms_are_calibrated_without_them(null_runs):
    z: dict = {}
    for seed, arw, rrw, y in null_runs:
        g = seed % 4                                   # a different gyro each seed
        for f in sf.fit_gyro_noise(y[:, g], DT, g + 1):
            z.setdefault(f.effect, []).append(f.z)
            if f.effect in ("arw", "rrw"):
                continue
            check_valid_entry(f)
    for effect in ("bias_instability", "quantization", "rate_ramp", "gauss_markov"):
        assert_calibrated(z[effect], effect)
    assert min(z["arw"]) > 5                           # the baseline itself is always there


def test_correlation_is_calibrated_without_it(null_runs):
    za, zr = [], []
    for seed, arw, rrw, y in null_runs:
        fa, fr = correlation_fit.fit_correlation(y, DT)
        za.append(fa.z)
        zr.append(fr.z)
        assert abs(fa.params["rho_arw"]) < 0.02
    assert_calibrated(za, "rho_arw")
    assert_calibrated(zr, "rho_rrw")


def test_burst_is_calibrated_without_it(null_runs):
    t = np.arange(N_20MIN) * DT
    z = [burst_fit.fit_burst(y, t, DT).z for seed, arw, rrw, y in null_runs]
    assert_calibrated(z, "burst")
    assert "no burst" in burst_fit.fit_burst(null_runs[0][3], t, DT).evidence


# -- scan calibration helpers -----------------------------------------------------

def test_scan_maximum_of_one_statistic_is_its_normal_tail():
    """With one correlation time the scan is a single N(0, 1): z = w."""
    maxima = gm_fit._max_calibration(np.eye(3)[:, :1])
    for w in (-1.0, 0.0, 1.5, 2.5, 6.0, 40.0):
        log_p, m_eff = gm_fit._scan_log_p(w, maxima)
        assert abs(m_eff - 1.0) < 0.15
        assert abs(z_from_log_p(log_p) - w) < (0.05 if w < 2.8 else 0.15)


def test_burst_null_tail_formula_is_monotone_and_finite():
    for blocks in burst_fit._BURST_NULL:
        lp = [burst_fit._burst_log_p(x, blocks) for x in (1.0, 5.0, 10.0, 20.0, 100.0, 5000.0)]
        assert all(a > b for a, b in itertools.pairwise(lp)) and lp[0] <= 0.0
        assert math.isfinite(z_from_log_p(lp[-1]))


# -- input checks ------------------------------------------------------------------

def test_bad_inputs_are_refused():
    y = np.zeros((1000, 3))
    with pytest.raises(InputError, match="shape"):
        sf.fit_gyro_noise(y, DT, 1)
    with pytest.raises(InputError, match="dt_s"):
        sf.fit_gyro_noise(y[:, 0], 0.0, 1)
    with pytest.raises(InputError, match="gyro"):
        sf.fit_gyro_noise(y[:, 0], DT, 0)
    with pytest.raises(InputError, match="too few"):
        sf.fit_gyro_noise(np.ones(100), DT, 1)
    bad = np.ones(1000)
    bad[5] = np.nan
    with pytest.raises(InputError, match="non-finite"):
        sf.fit_gyro_noise(bad, DT, 1)
    with pytest.raises(InputError, match="at least 2 gyros"):
        correlation_fit.fit_correlation(y[:, :1], DT)
    with pytest.raises(InputError, match="time_s"):
        burst_fit.fit_burst(y, np.arange(999) * DT, DT)
    with pytest.raises(InputError, match="uniformly"):
        burst_fit.fit_burst(y, np.arange(1000) * DT * 1.5, DT)


def test_a_late_start_is_moved_back_to_leave_six_octaves():
    # 10016 samples: octaves m = 1 ... 1024; a start at 5 s (m = 512) would leave 2, the fit
    # needs 6, so it starts at m = 32 (the 6th-longest), exactly as asked with 0.32 s
    x = np.random.default_rng(3).normal(0.0, 1e-3, 10016)
    late = sf.fit_gyro_noise(x, 0.01, 1, min_tau_s=5.0)
    at_cap = sf.fit_gyro_noise(x, 0.01, 1, min_tau_s=0.32)
    assert late[0].params == at_cap[0].params and late[1].params == at_cap[1].params
    assert late[0].params != sf.fit_gyro_noise(x, 0.01, 1)[0].params


@pytest.mark.slow   # 6 s: make score
def test_white_column_through_the_sensors_filter():
    """White noise (N = 0.25 deg/√h) through a first-order 3 Hz low-pass at 50 Hz, 40 records
    of 60 000 samples. With the filter's exact Allan-variance shape in the white column
    (:func:`~gyroarray.analysis.psd_fit.filtered_white_avar_ratio`) N is unbiased whether the
    fit reads every τ (what the chain does) or starts at the 5 %-clean τ; starting there
    without the shape it read 0.2469, 3.6 standard errors low. Reading every τ, N's spread is
    less than 0.6 of the late start's (measured 0.37): for two samples of 40 with equal
    variances the sd ratio falls below 0.6 with probability 0.1 % (F with 39, 39 dof)."""
    from functools import partial

    from gyroarray.analysis.psd_fit import filtered_white_avar_ratio, shortest_clean_tau
    from gyroarray.core.sensor import bandwidth_filter
    dt, n, n_true = 0.02, 60_000, 0.25
    min_tau = shortest_clean_tau(3.0, 1, dt)
    shape = partial(filtered_white_avar_ratio, 3.0, 1, dt)
    every, late, without = [], [], []
    for s in range(40):
        x = math.radians(n_true / 60.0) / math.sqrt(dt) * np.random.default_rng([23, s]).standard_normal(n)
        x = bandwidth_filter(x, dt, 3.0, 1)
        every.append(sf.fit_gyro_noise(x, dt, 1, white_shape=shape)[0].params["n_deg_rt_h"])
        late.append(sf.fit_gyro_noise(x, dt, 1, min_tau_s=min_tau, white_shape=shape)[0].params["n_deg_rt_h"])
        without.append(sf.fit_gyro_noise(x, dt, 1, min_tau_s=min_tau)[0].params["n_deg_rt_h"])
    for got in (every, late):
        assert abs(np.mean(got) - n_true) < 3.3 * np.std(got) / math.sqrt(40)
    assert np.mean(without) < n_true - 2.0 * np.std(late) / math.sqrt(40)
    assert np.std(every) < 0.6 * np.std(late)


def test_filtered_white_ratio_closed_form():
    """The ratio against the overlapping Allan variance of a 2e6-sample filtered record computed
    directly in numpy (σ² of unit white noise is 1/m; the estimate's relative sd √(4m/(3n)),
    4 of them allowed), and → 1 at long τ (the filter passes DC: Σh = 1)."""
    from gyroarray.analysis.psd_fit import filtered_white_avar_ratio
    from gyroarray.core.sensor import bandwidth_filter
    dt = 0.02
    m = np.array([1, 4, 16, 64, 256])
    ratio = filtered_white_avar_ratio(3.0, 1, dt, m)
    x = bandwidth_filter(np.random.default_rng(5).standard_normal(2_000_000), dt, 3.0, 1)
    phase = np.concatenate([[0.0], np.cumsum(x)])
    for mi, r in zip(m, ratio):
        d = phase[2 * mi:] - 2 * phase[mi:-mi] + phase[:-2 * mi]
        avar = np.mean(d * d) / (2.0 * mi * mi)
        # white of unit variance per sample: σ²(m) = 1/m; the estimate's sd ≈ √(4m/(3n)) relative
        assert abs(avar * mi / r - 1.0) < 4.0 * math.sqrt(4.0 * mi / (3.0 * 2_000_000))
    assert 0.999 < filtered_white_avar_ratio(3.0, 1, dt, np.array([4096]))[0] <= 1.0


def test_avar_normal_score_takes_the_chi2_skew_out():
    """Allan variances μ·χ²_ν/ν at ν = 3 (a long octave), 1e6 draws (scipy): mapped, the mean
    stays μ (within 1 %) and the sd √(2/ν)·μ within 2 % (Wilson–Hilferty's own error at ν = 3 is
    1.2 %; the sampling error 0.07 %), and the fraction beyond the normal 3σ point is near the
    normal tail of 0.135 %: 0.118 % measured (Wilson–Hilferty's tail at ν = 3; the binomial
    sd is 0.004 %), allowed 0.7–1.3× the normal's, where the raw estimates put 1.58 % there."""
    mu, nu = 2.5, 3.0
    y = mu * stats.chi2.rvs(nu, size=1_000_000, random_state=np.random.default_rng(9)) / nu
    g = allan_gls.avar_normal_score(y, mu, nu)
    sd = mu * math.sqrt(2.0 / nu)
    assert abs(g.mean() - mu) < 0.01 * mu and abs(g.std() - sd) < 0.02 * sd
    assert 945 <= np.count_nonzero(g > mu + 3 * sd) <= 1755
    assert np.count_nonzero(y > mu + 3 * sd) > 15_000


def test_walk_after_a_ramp_equals_the_explicit_covariance():
    """The random walk's expected Allan variance with the GLS ramp taken out, against the plain
    n × n computation written here: tr(Zᵀ Z · P C Pᵀ) with C_ij = min(i, j) + 1 the unit walk's
    covariance, P = I − i gᵀ the ramp's removal and Z the second differences of the cumulative
    sum at lag m (the overlapping estimator), over the walk's own (P = I)."""
    n = 512
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.standard_normal(n)) + 0.5 * rng.standard_normal(n)
    g = sf._ramp_fit(x, DT, 0.25 * DT, 1.0 / DT, 0.0)[3]
    i = np.arange(n)
    C = np.minimum.outer(i, i) + 1.0
    P = np.eye(n) - np.outer(i, g)
    S = P @ C @ P.T
    X = np.zeros((n + 1, n))
    X[1:] = np.tril(np.ones((n, n)))
    m = np.array([4, 32, 128, 170])
    got = sf._walk_after_ramp(g, m)
    for mm, r in zip(m, got):
        Z = X[2 * mm:] - 2 * X[mm:n + 1 - mm] + X[:n + 1 - 2 * mm]
        want = float(np.sum((Z @ S) * Z) / np.sum((Z @ C) * Z))
        assert r == pytest.approx(want, rel=1e-9), mm
    assert got[-1] < 0.6                      # a third of the record: the ramp took about half


@pytest.mark.slow   # a study of 200 paired records (19 s): make score
def test_k_is_not_lowered_by_the_ramp_taken_out():
    """Plain-numpy records (20 min at 100 Hz, ARW 0.2 deg/√h, RRW K = 30 deg/h/√h), each read
    with and without a 2000 deg/h² ramp added: the ramp is found (z > 3) and taken out, and K of
    the two readings agrees, paired, within 3 standard errors of the mean difference (+0.06 ±
    0.14 deg/h/√h on these 200). Before the random walk's column knew of the ramp taken out, K
    read 4.4 % low on them (−1.32 ± 0.13: 10 standard errors). 200 records, not fewer: the
    differences are skewed (quartiles −0.7 / +1.2), and the first 40 alone read +0.93 ± 0.22."""
    n, k, nw = 120_000, 30.0, 0.2
    k_rad = k / 3600.0 / 60.0 * math.pi / 180.0
    n_rad = nw / 60.0 * math.pi / 180.0
    ramp = 2000.0 * math.pi / 180.0 / 3600.0 ** 2 * DT * np.arange(n)
    d = []
    for s in range(200):
        rng = np.random.default_rng(4000 + s)
        x = n_rad / math.sqrt(DT) * rng.standard_normal(n) + np.cumsum(k_rad * math.sqrt(DT) * rng.standard_normal(n))
        without, with_ramp = (sf.fit_gyro_noise(y, DT, 1) for y in (x, x + ramp))
        assert with_ramp[4].extra["ramp_removed"] and not without[4].extra["ramp_removed"]
        d.append(with_ramp[1].params["k_deg_h_rt_h"] - without[1].params["k_deg_h_rt_h"])
    d = np.asarray(d)
    assert abs(d.mean()) <= 3.0 * d.std(ddof=1) / math.sqrt(d.size), (d.mean(), d.std(ddof=1))
