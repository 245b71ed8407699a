"""The fault detector ``fdi``: parity, false alarms, delays, minimum detectable steps, isolation.

Outside truth: the parity identities (V W H = 0, V Vᵀ = I, P R Pᵀ = I), Sturza's
parity gain √(1 − hⱼᵀ(HᵀH)⁻¹hⱼ)/σ, scipy's discrete Riccati solver for the bias
tracker, the Gaussian power function of a matched window (non-centrality from
P_FA and P_MD, Baarda/Sturza's minimum detectable bias), binomial/Poisson
confidence intervals on simulated clean hours, and the simulator's own fault
effects (right gyro, kind and onset).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import linalg, special, stats

from gyroarray.core.gdop import optimal_alpha
from gyroarray.core.errors import InputError
from gyroarray.estimators import get_estimator
from gyroarray.estimators.fdi import (FaultDetector, estimate_noise, fuse, isolability,
                                      minimum_detectable, parity_matrix)
from gyroarray.estimators.noise import ArrayNoise
from gyroarray.core.layout import Layout
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel

DT = 0.01
PAPER = [{"effect": "arw", "n_deg_rt_h": 0.1}, {"effect": "rrw", "k_deg_h_rt_h": 600.0}]


def cone(scheme, n):
    return Layout.conical(scheme, n, optimal_alpha(scheme, n).alpha_rad)


def model(*entries) -> NoiseModel:
    return NoiseModel.from_toml({"effects": list(entries)})


def run(m, layout, n, seed=0, dt=DT):
    return simulate_readings(m, np.zeros((n, 3)), layout, dt, np.random.default_rng(seed))


# -- parity space ---------------------------------------------------------------------

def test_parity_identities_with_correlated_noise():
    rng = np.random.default_rng(3)
    axes = rng.standard_normal((7, 3))
    H = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    A = rng.standard_normal((7, 7))
    R = A @ A.T + 7 * np.eye(7)                                # correlated, unequal gyros
    V, P = parity_matrix(H, R)
    W = np.linalg.inv(np.linalg.cholesky(R))
    assert V.shape == (4, 7)
    np.testing.assert_allclose(V @ (W @ H), 0, atol=1e-12)     # V W H = 0
    np.testing.assert_allclose(V @ V.T, np.eye(4), atol=1e-12)  # V Vᵀ = I
    np.testing.assert_allclose(P @ H, 0, atol=1e-12)           # P H = 0
    np.testing.assert_allclose(P @ R @ P.T, np.eye(4), atol=1e-10)   # white parity


def test_detector_parity_is_whitened_and_rotated_to_a_diagonal_walk():
    m = model(*PAPER, {"effect": "correlation", "rho_arw": 0.3, "rho_rrw": -0.1})
    det = FaultDetector().fit(cone(1, 6), m, DT)
    P, H = det.parity_, cone(1, 6).H
    R, Qb = det.noise_.R(DT), det.noise_.Qb(DT)
    np.testing.assert_allclose(P @ H, 0, atol=1e-9 * np.abs(P).max())
    np.testing.assert_allclose(P @ R @ P.T, np.eye(3), atol=1e-10)
    np.testing.assert_allclose(det.V_ @ det.V_.T, np.eye(3), atol=1e-12)
    qp = P @ Qb @ P.T
    np.testing.assert_allclose(qp - np.diag(np.diag(qp)), 0, atol=1e-12)


@pytest.mark.parametrize("scheme,n", [(1, 4), (1, 6), (2, 5), (2, 8)])
def test_parity_gain_is_sturzas(scheme, n):
    """Identical uncorrelated gyros: |P[:, j]|·σ = √(1 − hⱼᵀ(HᵀH)⁻¹hⱼ) (the leverage form)."""
    H = cone(scheme, n).H
    sigma = 0.3
    _, P = parity_matrix(H, sigma**2 * np.eye(n))
    lev = np.einsum("ij,jk,ik->i", H, np.linalg.inv(H.T @ H), H)
    np.testing.assert_allclose(np.linalg.norm(P, axis=0) * sigma, np.sqrt(1 - lev), rtol=1e-12)


def test_isolability_of_the_designs():
    assert isolability(cone(1, 4)) == {"parity_dim": 1, "isolable": False,
                                       "groups": [[1, 2, 3, 4]], "max_cos": 1.0}
    # Scheme 2, N = 5: z2 + z4 = 2 cos α z1 = z3 + z5, so gyros 2, 4 (and 3, 5) enter
    # one parity check each, with equal weight: a fault on 2 looks like one on 4
    s25 = isolability(cone(2, 5))
    assert not s25["isolable"] and s25["groups"] == [[1], [2, 4], [3, 5]]
    assert isolability(cone(1, 5))["isolable"] and isolability(cone(2, 6))["isolable"]
    # S1 N = 6: |cos| between parity directions of neighbours is 2/3 (3 of 6 gyros span z)
    assert isolability(cone(1, 6))["max_cos"] == pytest.approx(2 / 3, rel=1e-12)


# -- minimum detectable step: closed form --------------------------------------------------

def test_minimum_detectable_step_is_the_noncentrality_over_the_parity_gain():
    """(u + Φ⁻¹(1 − P_MD)) / (parity gain · √(Σ_{n<L} a²ⁿ/S)), K and S from scipy's DARE."""
    lay, n = cone(1, 6), 6
    N_arw, K_rrw = math.radians(0.1 / 60), math.radians(600 / 3600 / 60)
    noise = ArrayNoise.identical(n, N_arw, K_rrw)
    p_md = 0.001
    md = minimum_detectable(lay, noise, 0.01, p_md, dt_s=DT)
    sigma = N_arw / math.sqrt(DT)
    q = (K_rrw * math.sqrt(DT) / sigma) ** 2                   # walk / white, per sample
    P_pred = linalg.solve_discrete_are(np.eye(1), np.eye(1), np.array([[q]]), np.eye(1))[0, 0]
    S, K = P_pred + 1.0, P_pred / (P_pred + 1.0)
    a = 1.0 - K
    det = FaultDetector().fit(lay, noise, DT)
    L = det.design_.scales["step"][-1]
    energy = (1 - a ** (2 * L)) / (1 - a * a) / S
    gain = math.sqrt(1 - 3 / n) / sigma                        # Sturza, leverage 3/N on the cone
    want = (md["u_step"] + special.ndtri(1 - p_md)) / (gain * math.sqrt(energy))
    np.testing.assert_allclose(md["step_rad_s"], want, rtol=1e-9)


def test_white_noise_limit_is_baardas_minimum_detectable_bias():
    """No RRW, a one-sample window at the per-sample false-alarm probability α:
    MDB = (Φ⁻¹(1 − α/2) + Φ⁻¹(1 − β))·σ/√(1 − h'(H'H)⁻¹h)."""
    lay = cone(2, 6)
    noise = ArrayNoise.identical(6, math.radians(0.2 / 60))
    det = FaultDetector(bias_memory_s=1e9, drift_window_s=DT).fit(lay, noise, DT)
    d = det.design_
    assert d.scales["step"] == (1,)                            # one sample: a snapshot test
    u = d.thresholds["step"]
    alpha = 2 * stats.norm.sf(u)                               # two-sided, per sample
    # the threshold sets alpha × (distinct directions) = the family's share, per sample
    assert alpha * len(d.groups) == pytest.approx(0.01 / 3 * DT / 3600, rel=1e-3)
    beta = 0.05
    sigma = math.radians(0.2 / 60) / math.sqrt(DT)
    H = lay.H
    lev = np.einsum("ij,jk,ik->i", H, np.linalg.inv(H.T @ H), H)
    baarda = (stats.norm.isf(alpha / 2) + stats.norm.isf(beta)) * sigma / np.sqrt(1 - lev)
    md = minimum_detectable(lay, noise, 0.01, beta, dt_s=DT, bias_memory_s=1e9, drift_window_s=DT)
    np.testing.assert_allclose(md["step_rad_s"], baarda, rtol=1e-6)


# -- false alarms over simulated clean hours -------------------------------------------

@pytest.fixture(scope="module")
def clean_200h():
    """200 h of a clean N = 6 array at 1 Hz, tracker time constant 60 samples (as paper 003's
    gyros at 100 Hz: the detector works per sample, so the windows are scaled by 100)."""
    lay = cone(1, 6)
    m = model({"effect": "arw", "n_deg_rt_h": 6.0}, {"effect": "rrw", "k_deg_h_rt_h": 360.0})
    z = run(m, lay, 200 * 3600, seed=16, dt=1.0)
    return lay, m, z


def _detector(lay, m, far):
    return FaultDetector(far_per_h=far, drift_window_s=60000.0, variance_window_s=4000.0).fit(lay, m, 1.0)


def test_false_alarms_over_200_clean_hours_match_the_set_rate(clean_200h):
    lay, m, z = clean_200h
    det = _detector(lay, m, 3.0)
    fa = det.false_alarms(z)
    assert fa["hours"] == pytest.approx(200.0)
    expected = 3.0 / 3 * fa["hours"]                           # each family: a third
    for fam, count in fa["per_family"].items():
        # the analytic rate is a union bound over directions and windows (measured
        # 0.8–1.0 of it): [0.75 E − 3√E, E + 3√E], 3σ of a Poisson count
        lo, hi = 0.75 * expected - 3 * math.sqrt(expected), expected + 3 * math.sqrt(expected)
        assert lo <= count <= hi, (fam, count, expected)
    total = fa["samples"].size
    assert total <= 3.0 * 200 + 3 * math.sqrt(600)             # never above the set rate (3σ)
    assert total >= 0.6 * 600 - 3 * math.sqrt(600)             # and not uselessly below it


def test_default_rate_over_200_clean_hours(clean_200h):
    lay, m, z = clean_200h
    fa = _detector(lay, m, 0.01).false_alarms(z)
    # 0.01/h × 200 h = 2 expected: Poisson(2) gives >= 8 with probability 0.0011
    assert fa["samples"].size <= 7


# -- detection delay of a k·σ step against the matched-window theory ------------------

def test_step_detection_delay_within_the_matched_window_bounds():
    """White noise (no RRW): at the window of L samples that starts at the onset the step
    statistic is N(δ√L, 1) (δ the per-sample non-centrality), so
    P(alarm by onset + L − 1) >= Φ(δ√L − u); and at most the sum over every step window
    evaluated by then of its exceedance probability (means δ·m/√L, m samples after the
    onset, projected on each parity direction)."""
    lay, n = cone(1, 6), 6
    noise = ArrayNoise.identical(n, math.radians(0.1 / 60))
    det = FaultDetector(bias_memory_s=1e9).fit(lay, noise, DT)
    d = det.design_
    u = d.thresholds["step"]
    sigma = math.radians(0.1 / 60) / math.sqrt(DT)
    gain = math.sqrt(1 - 3 / n) / sigma
    delta = (u + 1.0) / math.sqrt(16)                          # P >= 0.84 by the 16-sample window
    size = delta / gain
    theta = 32 * 30 + 10                                       # no variance block ends near it
    dirs = d.coef / np.linalg.norm(d.coef, axis=0)
    cosj = np.abs(dirs.T @ dirs[:, 2])                         # fault on gyro 3
    trials, hits = 300, {dd: 0 for dd in (0, 3, 7, 15)}
    rng = np.random.default_rng(5)
    for i in range(trials):
        z = rng.standard_normal((theta + 40, n)) * sigma
        z[theta:, 2] += size
        res = det.detect(z)
        k = round(res.alarms[0].detected_s / DT) if res.alarms else 10**9
        for dd in hits:
            hits[dd] += k <= theta + dd
    for dd, h in hits.items():
        p = h / trials
        se = math.sqrt(0.25 / trials)
        lower = max(stats.norm.cdf(delta * math.sqrt(L) - u) for L in d.scales["step"] if L <= dd + 1)
        upper = 0.0
        for L in d.scales["step"]:
            for k in range(theta, theta + dd + 1):
                mean = delta * min(k - theta + 1, L) / math.sqrt(L)
                upper += sum(stats.norm.sf(u - c * mean) + stats.norm.cdf(-u - c * mean) for c in cosj)
        assert lower - 3 * se <= p <= min(upper, 1.0) + 3 * se, (dd, p, lower, upper)


# -- the done-when, in miniature ----------------------------------------------------

FAULTS = {
    "step": {"effect": "fault_step", "start_s": 60.0, "size_deg_s": 0.1},
    "drift": {"effect": "fault_drift", "start_s": 60.0, "rate_deg_s2": 0.01},
    "stuck": {"effect": "fault_stuck", "start_s": 60.0},
    "noise": {"effect": "fault_noise", "start_s": 60.0, "ratio": 2.5},
}
TOL = {"step": 2.0, "stuck": 2.0, "noise": 10.0, "drift": 150.0}


@pytest.mark.parametrize("kind", list(FAULTS))
def test_finds_the_right_gyro_kind_and_onset(kind):
    lay = cone(1, 6)
    m = model(*PAPER, {**FAULTS[kind], "gyro": 4})
    det = FaultDetector().fit(lay, model(*PAPER), DT)
    res = det.detect(run(m, lay, 16000, seed=11))
    assert len(res.alarms) == 1
    a = res.alarms[0]
    assert (a.gyro, a.kind, a.isolated) == (4, kind, True), a.evidence
    assert abs(a.onset_s - 60.0) <= TOL[kind] and a.detected_s >= 60.0
    assert res.exclusions[0][1] == 3                           # gyro 4 excluded (0-based)


def test_four_gyros_detect_but_do_not_isolate():
    lay = cone(1, 4)
    m = model(*PAPER, {**FAULTS["step"], "gyro": 2})
    res = FaultDetector().fit(lay, model(*PAPER), DT).detect(run(m, lay, 9000, seed=2))
    a, = res.alarms
    assert a.gyro is None and not a.isolated and a.candidates == (1, 2, 3, 4)
    assert "detected, not isolable" in a.evidence and a.kind == "step"
    assert not res.exclusions                                  # nothing excluded on a guess


def test_shared_parity_direction_is_not_isolated():
    lay = cone(2, 5)                                           # gyros 2 and 4 share a direction
    m = model(*PAPER, {**FAULTS["step"], "gyro": 4})
    a, = FaultDetector().fit(lay, model(*PAPER), DT).detect(run(m, lay, 9000, seed=3)).alarms
    assert a.gyro is None and a.candidates == (2, 4)


def test_no_alarm_on_clean_records():
    for scheme, n in ((1, 4), (2, 5), (1, 8)):
        lay = cone(scheme, n)
        res = FaultDetector().fit(lay, model(*PAPER), DT).detect(run(model(*PAPER), lay, 60000, seed=n))
        assert not res.alarms


# -- recovery -------------------------------------------------------------------------------

def test_recovery_is_gls_without_the_excluded_gyro():
    lay = cone(1, 6)
    noise = ArrayNoise.identical(6, 1e-3, 0.0, rho_arw=0.2)
    z = np.random.default_rng(0).standard_normal((100, 6))
    out = fuse(z, lay.H, noise, DT, [(40, 2)])
    R = noise.R(DT)
    keep = [0, 1, 3, 4, 5]
    Rk, Hk = R[np.ix_(keep, keep)], lay.H[keep]
    # GLS by whitening and lstsq (numpy), independent of gls_weights
    Wk = np.linalg.inv(np.linalg.cholesky(Rk))
    want = np.linalg.lstsq(Wk @ Hk, Wk @ z[40:, keep].T, rcond=None)[0].T
    np.testing.assert_allclose(out[40:], want, rtol=1e-10, atol=1e-14)
    W = np.linalg.inv(np.linalg.cholesky(R))
    want0 = np.linalg.lstsq(W @ lay.H, W @ z[:40].T, rcond=None)[0].T
    np.testing.assert_allclose(out[:40], want0, rtol=1e-10, atol=1e-14)


def test_estimate_is_the_recovered_rate():
    lay = cone(1, 6)
    m = model(*PAPER, {**FAULTS["step"], "gyro": 4})
    z = run(m, lay, 12000, seed=11)
    det = get_estimator("fdi")().fit(lay, model(*PAPER), DT)
    res = det.detect(z)
    np.testing.assert_array_equal(det.estimate(z), fuse(z, lay.H, det.noise_, DT, res.exclusions))


# -- noise from the record ---------------------------------------------------------------------

def test_noise_estimate_without_a_model():
    lay = cone(1, 6)
    z = run(model(*PAPER), lay, 60000, seed=4)
    noise, notes = estimate_noise(z, lay, DT, np.zeros((60000, 3)))
    N = math.radians(0.1 / 60)
    K = math.radians(600 / 3600 / 60)
    # robust MAD fits + 2σ: within [0.95, 1.35] of the truth (measured 1.00–1.15)
    assert np.all((noise.arw_rad_rt_s > 0.95 * N) & (noise.arw_rad_rt_s < 1.35 * N)), noise.arw_rad_rt_s / N
    assert np.all((noise.rrw_rad_s_rt_s > 0.8 * K) & (noise.rrw_rad_s_rt_s < 1.6 * K)), noise.rrw_rad_s_rt_s / K
    assert any("first" in n for n in notes)


def test_too_few_gyros_are_refused():
    with pytest.raises(InputError, match="at least 4"):
        FaultDetector().fit(Layout.triad(), model(*PAPER), DT)
    with pytest.raises(InputError, match="far_per_h"):
        FaultDetector(far_per_h=-1).fit(cone(1, 5), model(*PAPER), DT)


# -- a noise fault is an increase (issue 41, item 4) -------------------------------------------

def test_variance_threshold_is_set_on_the_upper_tail_only():
    """n_dir · Σ_L P(χ²_L/L > λ_hi(g))/L = the family's share per sample, λ_hi > 1 the root of
    L/2·(λ − 1 − ln λ) = g (scipy's brentq and χ² here, not the detector's helpers)."""
    from scipy import optimize
    det = FaultDetector().fit(cone(1, 6), model(*PAPER), DT)
    d = det.design_
    g = d.thresholds["variance"]
    n_dir = len(d.groups)

    def upper(L):
        hi = optimize.brentq(lambda x: 0.5 * L * (x - 1.0 - math.log(x)) - g, 1.0 + 1e-12, 1e3)
        return stats.chi2.sf(L * hi, L)
    rate = n_dir * sum(upper(L) / L for L in d.scales["variance"])
    assert rate == pytest.approx(0.01 / 3 * DT / 3600, rel=1e-6)
    # the two-sided level for the same rate would be higher: the lower tail is no longer spent
    two = n_dir * sum((upper(L) + stats.chi2.cdf(L * optimize.brentq(
        lambda x: 0.5 * L * (x - 1.0 - math.log(x)) - g, 1e-9, 1.0 - 1e-12), L)) / L
        for L in d.scales["variance"])
    assert two > rate


def test_a_gyro_that_gets_quieter_is_no_fault():
    """A real gyro's level drops between orientations (MIMU4444: x0.4 in variance): no alarm,
    while the same record with the gyro x2.5 noisier is found."""
    lay = cone(1, 6)
    N_arw = math.radians(0.1 / 60)
    det = FaultDetector().fit(lay, ArrayNoise.identical(6, N_arw), DT)
    sigma = N_arw / math.sqrt(DT)
    white = np.random.default_rng(12).standard_normal((16000, 6)) * sigma
    quiet, loud = white.copy(), white.copy()
    quiet[6000:, 3] *= 0.4                                     # gyro 4: amplitude x0.4 from 60 s
    loud[6000:, 3] *= 2.5
    assert not det.detect(quiet).alarms
    a = det.detect(loud).alarms[0]
    assert (a.gyro, a.kind) == (4, "noise") and a.detected_s >= 60.0
