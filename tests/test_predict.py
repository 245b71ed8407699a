"""The analytic accuracy predictor against closed forms, plain recursions and the simulator.

Outside truth, in order of strength:

* closed forms: GLS on white noise, σ·√diag((HᵀC⁻¹H)⁻¹) (paper 003 Eq. 12);
  the single-input Kalman filter's gain against the Riccati solution;
* a plain covariance recursion written here (the augmented state
  [x̂; b; Σ e] stepped sample by sample), to 1e-9;
* the simulator's own noise (``sim.effects.simulate_readings``) through the
  real estimators: 30 replicates per design, every prediction inside the
  replicates' confidence interval (family-wise over the comparisons).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from gyroarray.core import units
from gyroarray.analysis.replicates import rms_ci
from gyroarray.core.errors import InputError
from gyroarray.estimators import get_estimator
from gyroarray.estimators.kalman import state_model, steady_state
from gyroarray.estimators.kf_array import rate_psd
from gyroarray.core.layout import Layout
from gyroarray.design.predict import (Swing, channel_filter, noise_sources, predict,
                               swing_truth, window_sums)
from gyroarray.effects.model import ModelEntry, NoiseModel
from replicates import predictions_outside

DT = 0.01
ESTIMATORS = ("kf_array", "kf_single", "gls", "ols", "naive")


def _model(arw=0.1, rrw=600.0, rho_arw=0.0, rho_rrw=0.0, extra=()):
    e = [ModelEntry("arw", None, {"n_deg_rt_h": arw})]
    if rrw:
        e.append(ModelEntry("rrw", None, {"k_deg_h_rt_h": rrw}))
    if rho_arw or rho_rrw:
        e.append(ModelEntry("correlation", None, {"rho_arw": rho_arw, "rho_rrw": rho_rrw}))
    return NoiseModel(tuple(e) + tuple(extra))


def test_window_sums_equal_the_plain_double_sums():
    nu = np.array([0.0, 0.37, 0.9995, 1.0])
    k0, k1 = 5, 61
    x1, y1, x2, y2 = window_sums(nu, k0, k1)
    for i, l in np.ndindex(4, 4):
        a = nu[i] * nu[l]
        ks = np.arange(k0, k1 + 1)
        ak = a ** ks
        sk = np.array([sum(a ** j for j in range(k)) for k in ks])
        g = lambda v: np.array([sum(v ** j for j in range(k1 - k + 1)) for k in ks])  # noqa: E731
        w = g(nu[i]) + g(nu[l]) - 1
        np.testing.assert_allclose([x1[i, l], y1[i, l], x2[i, l], y2[i, l]],
                                   [ak.sum(), sk.sum(), (w * ak).sum(), (w * sk).sum()], rtol=1e-13)


@pytest.mark.parametrize("layout", [Layout.conical(1, 6, math.radians(54.7356)),
                                    Layout.conical(2, 5, math.radians(40.0)),
                                    Layout.from_axes([[1, 0, 0], [0, 1, 0], [0, 0, 1],
                                                      [0.6, 0.8, 0], [0, 0.6, 0.8]])])
def test_gls_white_noise_is_the_closed_form(layout):
    # GLS on white noise: every sample's error has covariance σ²(HᵀC⁻¹H)⁻¹, so the expected
    # sample variance over the window is exactly its diagonal (no filter, no drift).
    n = layout.n_gyros
    rho = 0.2
    model = _model(arw=0.1, rrw=0.0, rho_arw=rho)
    est = get_estimator("gls")().fit(layout, model, DT)
    p = predict(est, model, n_samples=3000)
    sigma = units.arw_deg_rt_h_to_rad_rt_s(0.1) / math.sqrt(DT)
    c = (1 - rho) * np.eye(n) + rho * np.ones((n, n))
    h = layout.H
    closed = units.rad_s_to_deg_s(sigma * np.sqrt(np.diag(np.linalg.inv(h.T @ np.linalg.solve(c, h)))))
    got = np.array([p.axes[a]["std_deg_s"] for a in "xyz"])
    np.testing.assert_allclose(got, closed, rtol=1e-12)
    # the same level, as the long-τ ARW of a unity-DC-gain estimator: N·√diag((HᵀC⁻¹H)⁻¹)
    arw = np.array([p.axes[a]["arw_long_deg_rt_h"] for a in "xyz"])
    np.testing.assert_allclose(arw, 0.1 * closed / units.rad_s_to_deg_s(sigma), rtol=1e-12)


def test_moments_equal_a_plain_recursion():
    # The window sums need the cross-covariances of e across time; a plain augmented recursion
    # with the running sums as states gives them exactly.
    layout = Layout.conical(2, 5, math.radians(65.0))
    model = _model(arw=0.2, rrw=900.0, rho_arw=0.1, rho_rrw=0.05)
    n, k0 = 300, 40
    for name in ESTIMATORS:
        kw = {"bandwidth_hz": 4.0} if name.startswith("kf") else {}
        est = get_estimator(name)(**kw).fit(layout, model, DT)
        sys = est.linear_system()
        ns = noise_sources(model, layout.n_gyros, DT)
        D, N = sys.A.shape[0], layout.n_gyros
        d = D + N + 6
        F = np.eye(d)
        F[:D, :D] = sys.A
        F[:D, D:D + N] = sys.K
        G = np.zeros((d, 2 * N))
        G[:D, :N] = G[:D, N:] = sys.K
        G[D:D + N, :N] = np.eye(N)
        C = sys.C
        Q = np.zeros((2 * N, 2 * N))
        Q[:N, :N], Q[N:, N:] = ns.Qb, ns.R
        m0 = sys.A @ sys.X0 + sys.K
        P = np.zeros((d, d))
        T0 = np.zeros((d, 2 * N))
        T0[:D, :N] = T0[:D, N:] = m0
        T0[D:D + N, :N] = np.eye(N)
        P = T0 @ Q @ T0.T
        ms = np.zeros(3)
        for k in range(n):
            if k > 0:
                # s_k = F s_{k-1} + G u_k, the sums copied unchanged
                P = F @ P @ F.T + G @ Q @ G.T
            # add e_k = C x̂_k to sf (always) and sw (in the window): s ← E s
            E = np.eye(d)
            E[D + N + 3:, :D] += C
            if k >= k0:
                E[D + N:D + N + 3, :D] += C
                ms += np.diag(C @ P[:D, :D] @ C.T)
            P = E @ P @ E.T
        p = predict(est, model, n_samples=n, settle_s=k0 * DT)
        to = units.rad_s_to_deg_s
        got_ms = np.array([p.axes[a]["rms_deg_s"] for a in "xyz"]) ** 2
        np.testing.assert_allclose(got_ms, to(1.0) ** 2 * ms / (n - k0), rtol=1e-9, err_msg=name)
        mean2 = np.diag(P[D + N:D + N + 3, D + N:D + N + 3]) / (n - k0) ** 2
        np.testing.assert_allclose(np.array([p.axes[a]["mean_deg_s"] for a in "xyz"]) ** 2,
                                   to(1.0) ** 2 * mean2, rtol=1e-9, err_msg=name)
        ang2 = np.diag(P[D + N + 3:, D + N + 3:]) * DT ** 2
        np.testing.assert_allclose(np.array([p.axes[a]["angle_deg"] for a in "xyz"]) ** 2,
                                   units.rad_to_deg(1.0) ** 2 * ang2, rtol=1e-9, err_msg=name)


def test_single_input_kf_closed_form_matches_the_riccati_solution():
    r, qb = 2.5e-4, 3e-9
    for f in (0.5, 3.0, 20.0):
        q = rate_psd(np.ones((1, 1)), np.array([[r]]), np.array([[qb]]), DT, f, None)[0]
        filt = steady_state(state_model(np.ones((1, 1)), np.array([[r]]), np.array([q * DT]),
                                        np.array([[qb]])))
        sys = channel_filter("kf", DT, f, qb / r)
        np.testing.assert_allclose(sys.K[:, 0], filt.K[:, 0], rtol=1e-9)
        assert sys.lam[0] == pytest.approx(filt.lam[0], rel=1e-12)
        # its DC gain is q_ω / (q_ω + q_b)
        assert sys.dc_gain()[0, 0] == pytest.approx(q * DT / (q * DT + qb), rel=1e-9)


def test_amplitude_and_phase_equal_the_noiseless_response():
    from gyroarray.analysis.metrics import attenuation_and_lag
    layout = Layout.conical(1, 4, math.radians(54.7356))
    model = _model()
    sw = Swing(units.deg_s_to_rad_s(5.0), 0.4)
    n = 6000
    t = np.arange(n) * DT
    truth = swing_truth(sw, n, DT)
    for name in ("kf_array", "gls"):
        kw = {"bandwidth_hz": 2.0} if name == "kf_array" else {"lowpass_hz": 2.0}
        est = get_estimator(name)(**kw).fit(layout, model, DT)
        p = predict(est, model, n_samples=n, swing=sw)
        y = est.estimate(truth @ layout.H.T)
        keep = t > 5.0
        att, lag = attenuation_and_lag(t[keep], y[keep, 2], truth[keep, 2], sw.frequency_hz)
        assert p.axes["z"]["amplitude_ratio"] == pytest.approx(att, rel=2e-4)
        assert p.axes["z"]["phase_deg"] == pytest.approx(math.degrees(lag), abs=2e-3)


#: Designs of scenarios/sweeps/design_quick.toml (scheme, N, α at the optimum for ρ_arw, ρ_arw,
#: motion) and the paper 003 §5 tetrahedral array with its Table 8 noise (bias instability).
_QUICK = [(1, 4, None, -0.1, None), (2, 5, None, 0.5, "swing"), (2, 8, None, 0.0, "swing")]


def _tetra_model():
    rows = [(0.1476, 4.979, 1.0285), (0.1849, 2.8545, 0.9711), (0.1618, 2.8764, 0.9399),
            (0.1519, 2.6229, 0.9461)]
    e = []
    for k, (a, r, b) in enumerate(rows, start=1):
        e += [ModelEntry("arw", k, {"n_deg_rt_h": a}), ModelEntry("rrw", k, {"k_deg_h_rt_h": r}),
              ModelEntry("bias_instability", k, {"b_deg_h": b})]
    return NoiseModel(tuple(e))


def test_prediction_inside_the_simulated_replicates():
    """100 paired replicates of 20 s per design, through the simulator and the real estimators.

    Each prediction must lie in the replicates' interval for √E[x²] (rms_ci: χ² with the
    Satterthwaite ν, exact ν = n for the Gaussian mean and angle errors). The intervals are
    family-wise at 95 % over all the comparisons of the test (Šidák), so the test is a 95 %
    test of "the predictor is right", not 240 separate ones. 100 runs rather than 30: the
    Satterthwaite ν of the RMS and 1σ rests on the runs' own variance of x², which 30 skewed
    values (skewness ≈ 2 when random-walk drift dominates) underestimate too often.
    """
    from gyroarray.core.gdop import optimal_alpha
    reps, n = 100, 2000
    cases = []
    for scheme, nn, _, rho, motion in _QUICK:
        alpha = optimal_alpha(scheme, nn, rho).alpha_rad
        cases.append((Layout.conical(scheme, nn, alpha), _model(rho_arw=rho), motion))
    cases.append((Layout.conical(1, 4, math.radians(54.7356)), _tetra_model(), "swing"))
    comparisons = len(cases) * len(ESTIMATORS) * 3 * 4
    level = (1 - 0.05) ** (1 / comparisons)                      # Šidák
    outside = []
    for layout, model, motion in cases:
        sw = Swing(units.deg_s_to_rad_s(5.0), 0.03) if motion else None
        truth = swing_truth(sw, n, DT) if sw else np.zeros((n, 3))
        ests = {nm: get_estimator(nm)().fit(layout, model, DT) for nm in ESTIMATORS}
        preds = {nm: predict(e, model, n_samples=n, swing=sw) for nm, e in ests.items()}
        outside += [(layout.name, *o) for o in predictions_outside(
            ests, preds, model, layout, truth, DT, reps=reps, seed=99, level=level)]
    assert not outside, outside[:5]


def test_unobservable_layout_is_refused_with_the_reason():
    model = _model()
    flat = Layout.conical(1, 6, math.pi / 2)
    for name in ESTIMATORS:
        with pytest.raises(InputError, match="z is unobservable: all axes lie in the x-y plane"):
            get_estimator(name)().fit(flat, model, DT)
    r2 = 1 / math.sqrt(2)
    tilted = Layout.from_axes([[1, 0, 0], [0, 0.8, -0.6], [r2, 0.8 * r2, -0.6 * r2]])
    with pytest.raises(InputError, match="unobservable: all axes lie in the plane normal"):
        get_estimator("gls")().fit(tilted, model, DT)
    with pytest.raises(InputError, match="all axes are parallel"):
        get_estimator("ols")().fit(Layout.from_axes([[0, 0, 1]] * 4), model, DT)


def test_bound_has_no_linear_form():
    layout = Layout.conical(1, 4, math.radians(54.7356))
    est = get_estimator("bound")().fit(layout, _model(), DT)
    with pytest.raises(InputError, match="not a fixed linear filter"):
        predict(est, _model(), n_samples=500)


def test_chi2_interval_is_exact_for_gaussian_runs():
    # ν = n: the interval of √E[x²] for 30 N(0, 1) draws is [√(S/χ²₃₀(0.975)), √(S/χ²₃₀(0.025))]
    x = np.random.default_rng(5).standard_normal(30)
    ci = rms_ci(x, gaussian=True)
    s = np.sum(x ** 2)
    assert ci["ci_low"] == pytest.approx(math.sqrt(s / stats.chi2.ppf(0.975, 30)), rel=1e-12)
    assert ci["ci_high"] == pytest.approx(math.sqrt(s / stats.chi2.ppf(0.025, 30)), rel=1e-12)
