"""Equivalent estimators agree; KF predictions match realised errors.

Tolerances are stated beside each assertion. Statistical checks use fixed
seeds and confidence intervals at a family-wise level of 1e-3 (Bonferroni
over the axes/checkpoints), so they pass for all but ~1 in 1000 seeds.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from gyroarray.core import units
from gyroarray.core.gdop import gdop, optimal_alpha
from gyroarray.core.errors import InputError
from gyroarray.estimators import (GLS, OLS, ArrayKF, ArrayNoise, Naive, OfflineBound, SingleGyroKF,
                                  array_noise, bandwidth_hz, efficiency, paper002_relation,
                                  single_gyro_gain)
from gyroarray.estimators.kalman import first_order_lowpass, kf_step, lowpass_pole
from gyroarray.estimators.kf_single import single_gyro_filter
from gyroarray.core.layout import Layout
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.sim.scenario import load_scenario, simulate

ALPHA = 1e-3                                        # family-wise false-alarm rate of a test

# paper 003 §4.2: N = 6, Scheme 1, α = 54.7356°, σn = 0.1 deg/√h, σb = 600 deg/h/√h, 100 Hz
P003_DT = 0.01
P003_LAYOUT = Layout.conical(1, 6, np.deg2rad(54.7356))
P003_ARW = units.arw_deg_rt_h_to_rad_rt_s(0.1)
P003_RRW = units.rrw_deg_h_rt_h_to_rad_s_rt_s(600.0)
P003_MODEL = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                         ModelEntry("rrw", None, {"k_deg_h_rt_h": 600.0})))
# an anisotropic, correlated case: Scheme 2, N = 5, one noisier gyro
ODD_LAYOUT = Layout.conical(2, 5, np.deg2rad(65.9))
ODD_MODEL = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                        ModelEntry("arw", 3, {"n_deg_rt_h": 0.25}),
                        ModelEntry("rrw", None, {"k_deg_h_rt_h": 300.0}),
                        ModelEntry("rrw", 1, {"k_deg_h_rt_h": 900.0}),
                        ModelEntry("correlation", None, {"rho_arw": 0.2, "rho_rrw": -0.1})))


def swing(n, dt=P003_DT, amp_deg_s=5.0, f_hz=0.03):
    """Paper 003 §4.2 input: 5 sin(2π·0.03 t) deg/s about z [rad/s]."""
    t = np.arange(n) * dt
    w = np.zeros((n, 3))
    w[:, 2] = units.deg_s_to_rad_s(amp_deg_s) * np.sin(2 * np.pi * f_hz * t)
    return w


def chi2_interval(dof, alpha):
    return stats.chi2.ppf(alpha / 2, dof), stats.chi2.ppf(1 - alpha / 2, dof)


# -- the noise reduction ---------------------------------------------------------

def test_array_noise_overrides_and_correlation():
    nz = array_noise(ODD_MODEL, 5)
    arw = units.arw_deg_rt_h_to_rad_rt_s(np.array([0.1, 0.1, 0.25, 0.1, 0.1]))
    rrw = units.rrw_deg_h_rt_h_to_rad_s_rt_s(np.array([900.0, 300, 300, 300, 300]))
    np.testing.assert_allclose(nz.arw_rad_rt_s, arw, rtol=1e-15)
    np.testing.assert_allclose(nz.rrw_rad_s_rt_s, rrw, rtol=1e-15)
    R = nz.R(0.01)
    assert R[2, 3] == pytest.approx(0.2 * arw[2] * arw[3] / 0.01, rel=1e-14)  # C_ij σ_i σ_j, σ = N/√dt
    assert nz.Qb(0.01)[0, 1] == pytest.approx(-0.1 * rrw[0] * rrw[1] * 0.01, rel=1e-14)  # σ = K√dt
    assert nz == array_noise(ODD_MODEL, 5)


def test_array_noise_refusals():
    with pytest.raises(InputError, match=r"no angle random walk \('arw'\) for gyro\(s\) 1, 2, 4"):
        array_noise(NoiseModel((ModelEntry("arw", 3, {"n_deg_rt_h": 0.1}),)), 4)
    with pytest.raises(InputError, match="arw is 0 on gyro"):
        array_noise(NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.0}),)), 4)
    common = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                         ModelEntry("correlation", None, {"rho_arw": 1.0, "common_mode": True})))
    with pytest.raises(InputError, match="singular"):
        array_noise(common, 4)
    ok = array_noise(NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                                 ModelEntry("correlation", None,
                                            {"rho_rrw": 1.0, "common_mode": True}))), 4)
    assert np.all(ok.corr_rrw == 1.0)                                  # one common RRW source
    assert array_noise(NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),
                                   ModelEntry("misalignment", 2, {"tilt_deg": 0.5}))),
                       4).ignored_effects == ("misalignment",)


# -- gains: Riccati on the observable subspace = the plain recursion ---------------

def iterated_gain(model, n_steps, p0_rate):
    """The textbook recursion from a diffuse rate and zero biases, run n_steps."""
    D = model.dim
    x, P = np.zeros(D), np.zeros((D, D))
    P[:model.p, :model.p] = p0_rate * np.eye(model.p)
    z = np.zeros(model.R.shape[0])
    for _ in range(n_steps):
        x, P, K, _ = kf_step(x, P, z, model.F, model.H1, model.Q, model.R)
    return K


@pytest.mark.parametrize("layout, model", [(P003_LAYOUT, P003_MODEL), (ODD_LAYOUT, ODD_MODEL)])
def test_steady_gain_equals_iterated_gain(layout, model):
    kf = ArrayKF().fit(layout, model, P003_DT)
    filt = kf._filter
    # The gain converges like the slowest stable mode squared; 10 000 steps
    # give λ_max^20000 < 1e-30 for both cases (λ_max ≈ 0.98 here).
    assert np.max(kf.eigenvalues_) ** 20000 < 1e-30
    K = iterated_gain(filt.model, 10000, p0_rate=1e6 * np.max(np.diag(filt.model.R)))
    np.testing.assert_allclose(K, kf.gain_, rtol=0, atol=1e-9 * np.max(np.abs(kf.gain_)))


def test_steady_start_keeps_the_steady_gain_at_every_step():
    """The fixed point of the cross covariance P_uo (the formula behind K_u)."""
    kf = ArrayKF().fit(ODD_LAYOUT, ODD_MODEL, P003_DT)
    f, mdl = kf._filter, kf._filter.model
    rng = np.random.default_rng(4)
    x, P = np.zeros(mdl.dim), f.initial_covariance()
    kmax = np.max(np.abs(kf.gain_))
    for _ in range(2000):
        x, P, K, _ = kf_step(x, P, 1e-3 * rng.standard_normal(5), mdl.F, mdl.H1, mdl.Q, mdl.R)
        # rounding only: 1e-12 of the largest gain over 2000 Joseph updates
        assert np.max(np.abs(K - kf.gain_)) <= 1e-12 * kmax


def test_gain_without_bias_states_equals_python_control_dlqe():
    import control
    kf = ArrayKF(bias_states=False).fit(ODD_LAYOUT, ODD_MODEL, P003_DT)
    mdl = kf._filter.model
    L, _, _ = control.dlqe(mdl.F, np.eye(3), mdl.H1, mdl.Q, mdl.R)  # predictor gain A P C'(CPC'+R)⁻¹, A = I
    np.testing.assert_allclose(kf.gain_, L, rtol=0, atol=1e-9 * np.max(np.abs(L)))


def test_single_gyro_gain_equals_iterated_gain():
    arw = units.arw_deg_rt_h_to_rad_rt_s(0.1667)
    rrw = units.rrw_deg_h_rt_h_to_rad_s_rt_s(1200.0)
    q = units.rrw_deg_h_rt_h_to_rad_s_rt_s(1000.0) ** 2
    filt = single_gyro_filter(arw, rrw, q, 0.005)
    K = iterated_gain(filt.model, 20000, p0_rate=1.0)
    np.testing.assert_allclose(single_gyro_gain(arw, rrw, q, 0.005), K[:, 0], rtol=1e-9)


def test_no_rrw_with_bias_states_is_refused_with_advice():
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),))
    with pytest.raises(InputError, match="bias_states=False"):
        ArrayKF().fit(P003_LAYOUT, model, P003_DT)
    assert ArrayKF(bias_states=False).fit(P003_LAYOUT, model, P003_DT).gain_.shape == (3, 6)


# -- equivalent estimators ---------------------------------------------------------

def test_kf_with_infinite_q_and_no_bias_states_is_gls():
    rng = np.random.default_rng(11)
    n = 2000
    z = swing(n) @ ODD_LAYOUT.H.T + 3e-4 * rng.standard_normal((n, 5))
    kf = ArrayKF(bias_states=False, q_omega=1e6).fit(ODD_LAYOUT, ODD_MODEL, P003_DT)
    gls = GLS().fit(ODD_LAYOUT, ODD_MODEL, P003_DT)
    a, b = kf.estimate(z), gls.estimate(z)
    # The gain differs from the GLS weights by O(R/(q_ω dt)) ≈ 1e-9/1e4 = 1e-13
    # relative (R ≈ 1e-7 rad²/s²); 1e-9 of the signal leaves room for rounding.
    assert np.max(np.abs(a - b)) <= 1e-9 * np.max(np.abs(b))
    scale = np.max(gls.covariance_)
    np.testing.assert_allclose(kf.covariance_, gls.covariance_, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(gls.covariance_, np.linalg.inv(
        ODD_LAYOUT.H.T @ np.linalg.solve(array_noise(ODD_MODEL, 5).R(P003_DT), ODD_LAYOUT.H)),
        rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("n_gyros", [4, 8])
def test_gls_on_identical_gyros_reaches_sigma_sqrt_3_over_n(n_gyros):
    opt = optimal_alpha(1, n_gyros)
    layout = Layout.conical(1, n_gyros, opt.alpha_rad)
    model = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),))
    n = 20000
    z = simulate_readings(model, np.zeros((n, 3)), layout, P003_DT, np.random.default_rng(n_gyros))
    gls = GLS().fit(layout, model, P003_DT)
    sigma = P003_ARW / np.sqrt(P003_DT)
    want = sigma * np.sqrt(3.0 / n_gyros)                  # = σ·GDOP/√3 at the optimum
    assert want == pytest.approx(sigma * gdop(layout) / np.sqrt(3), rel=1e-9)
    np.testing.assert_allclose(np.sqrt(np.diag(gls.covariance_)), want, rtol=1e-9)
    e = gls.estimate(z)
    # white, zero-mean: Σ e²/σ² ~ χ²(n) per axis; two-sided, Bonferroni over 3 axes
    lo, hi = chi2_interval(n, ALPHA / 3)
    ss = np.sum(e ** 2, axis=0) / want ** 2
    assert np.all((lo < ss) & (ss < hi)), (ss / n, lo / n, hi / n)


def test_naive_equals_ols_on_conical_layouts_and_not_on_skewed_axes():
    rng = np.random.default_rng(3)
    z = rng.standard_normal((50, 5))
    a = Naive().fit(ODD_LAYOUT, ODD_MODEL, P003_DT).estimate(z)
    b = OLS().fit(ODD_LAYOUT, ODD_MODEL, P003_DT).estimate(z)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)      # HᵀH diagonal: same weights
    skew = Layout.from_axes([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0.6, 0.8, 0], [0, 0.6, 0.8]])
    w = np.array([0.1, -0.2, 0.3])
    nv = Naive().fit(skew, ODD_MODEL, P003_DT)
    ols = OLS().fit(skew, ODD_MODEL, P003_DT)
    np.testing.assert_allclose(ols.estimate((skew.H @ w)[None]), w[None], rtol=1e-12)
    assert np.max(np.abs(nv.estimate((skew.H @ w)[None]) - w)) > 0.01      # biased here


def test_lowpass_has_its_minus_3db_point_and_noise_gain():
    dt, f = 0.01, 7.0
    t = np.arange(20000) * dt
    x = np.sin(2 * np.pi * f * t)[:, None]
    y = first_order_lowpass(x, f, dt)
    # steady-state amplitude after 100 time constants: |H(f)| = 1/√2 (to the
    # 1e-4 resolution of the peak of a sampled sinusoid, 7 Hz at 100 Hz)
    amp = 0.5 * (np.max(y[10000:]) - np.min(y[10000:]))
    assert amp == pytest.approx(2 ** -0.5, rel=2e-3)
    gls = GLS(lowpass_hz=f).fit(P003_LAYOUT, P003_MODEL, dt)
    raw = GLS().fit(P003_LAYOUT, P003_MODEL, dt)
    a = lowpass_pole(f, dt)
    np.testing.assert_allclose(gls.covariance_, raw.covariance_ * (1 - a) / (1 + a), rtol=1e-12)


# -- steady-state KF = time-varying KF after the transient ------------------------------

def test_steady_state_kf_equals_time_varying_kf_after_the_transient():
    rng = np.random.default_rng(5)
    n = 3000
    model_noise = array_noise(P003_MODEL, 6)
    z = swing(n) @ P003_LAYOUT.H.T + simulate_readings(
        P003_MODEL, np.zeros((n, 3)), P003_LAYOUT, P003_DT, rng)
    kf = ArrayKF().fit(P003_LAYOUT, model_noise, P003_DT)
    mdl = kf._filter.model
    x0 = kf._x0_map() @ z[0]
    P = np.zeros((mdl.dim, mdl.dim))
    P[:3, :3] = 1e6 * np.max(np.diag(mdl.R)) * np.eye(3)
    x = x0.copy()
    xs, gains, nus = np.empty((n, mdl.dim)), np.empty(n), np.empty(n)
    for k in range(n):
        nus[k] = np.max(np.abs(z[k] - mdl.H1 @ x))
        x, P, K, _ = kf_step(x, P, z[k], mdl.F, mdl.H1, mdl.Q, mdl.R)
        xs[k] = x
        gains[k] = np.max(np.abs(K - kf.gain_))
    ss = kf._filter.apply(z, x0, full=True)
    dx = xs - ss
    # After the gain has converged (k_c), the difference y = H1 Δx obeys
    # y_k = (I − H1 K) y_{k-1} + H1 (K_k − K) ν_k: it decays like λ_max^(k−k_c)
    # (times κ, the condition number of the modal basis) plus what the
    # remaining gain error injects, ≤ κ·|H1|·max|K_k − K|·max|ν|/(1 − λ_max).
    kmax = np.max(np.abs(kf.gain_))
    k_c = int(np.argmax(gains <= 1e-10 * kmax))
    assert 0 < k_c < n // 2
    lam = np.max(kf.eigenvalues_)
    ev = np.linalg.eig(np.eye(6) - mdl.H1 @ kf.gain_)[1]
    kappa = np.linalg.cond(ev)
    h1 = np.max(np.sum(np.abs(mdl.H1), axis=1))
    y = np.abs(dx @ mdl.H1.T).max(axis=1)
    k = np.arange(n)
    tol = (kappa * y[k_c] * lam ** (k - k_c)
           + kappa * h1 * np.max(gains[k_c:]) * np.max(nus[k_c:]) / (1 - lam) + 1e-15)
    after = k >= k_c
    assert np.all(y[after] <= tol[after])
    settle = k_c + int(np.ceil(np.log(1e-6) / np.log(lam)))
    assert np.all(y[settle:] <= 1e-6 * np.max(y[:k_c + 1]) * kappa + tol[settle:])
    # what remains lies along the unobservable directions [u; −H u]: a constant
    # offset of the rate (no measurement can resolve it) — constant to the same
    # tolerance once settled
    d = dx[:, :3]
    assert np.max(np.abs(d[settle:] - d[-1])) <= kappa * np.max(tol[settle:]) + 1e-6 * np.max(np.abs(d))


# -- single gyro (paper 002) ------------------------------------------------------------

def test_single_gyro_bandwidth_from_the_frequency_response():
    import control
    arw = units.arw_deg_rt_h_to_rad_rt_s(0.1667)
    rrw = units.rrw_deg_h_rt_h_to_rad_s_rt_s(1200.0)
    dt = 0.005
    for sigma_omega in (3000.0, 24000.0):
        q = units.rrw_deg_h_rt_h_to_rad_s_rt_s(sigma_omega) ** 2
        bw = bandwidth_hz(q, arw, rrw, dt)
        # independent route: the textbook matrices as a python-control system,
        # minimal realisation (the unit mode is not reached from z), evaluated
        filt = single_gyro_filter(arw, rrw, q, dt)
        K, H1 = filt.K, filt.model.H1
        A = np.eye(2) - K @ H1                                        # x = (I − K H) x + K z
        sys = control.minreal(control.ss2tf(control.ss(A, K, A[:1], K[:1], dt)), verbose=False)
        h = [complex(np.squeeze(sys(np.exp(2j * np.pi * f * dt)))) for f in (0.0, bw)]
        assert abs(h[1]) / abs(h[0]) == pytest.approx(2 ** -0.5, rel=1e-9)
        assert abs(h[0]) == pytest.approx(q / (q + rrw ** 2), rel=1e-9)   # DC split q_ω/(q_ω+q_b)
        # continuous limit √(q_ω + K²)/(2π N), good to O((2π BW dt)²) ≈ 1e-2 here
        assert bw == pytest.approx(np.sqrt(q + rrw ** 2) / arw / (2 * np.pi), rel=2e-2)


def test_paper002_relation_reproduced():
    rel = paper002_relation()
    # floor: BW(q_ω = 0) = K/(2π N) = 0.318 Hz (discrete: to (k dt)² ≈ 1e-4)
    assert rel.floor_hz == pytest.approx(0.31825, rel=1e-4)
    assert rel.bandwidth_hz[0] == pytest.approx(rel.floor_hz, rel=1e-4)
    # our line over the paper's range: slope within 1.5 % of the asymptote
    # 1/(2π N) (the floor and the discretisation bend it slightly), small intercept
    assert rel.asymptotic_slope == pytest.approx(2.6523e-4, rel=1e-4)
    assert rel.slope == pytest.approx(rel.asymptotic_slope, rel=1.5e-2)
    assert abs(rel.intercept) < 0.1
    lo, hi = rel.linear_within_5pct
    assert lo < 3000 and hi > 72000
    # a straight line in q_ω itself is far off: BW(4q) ≈ 2·BW(q) at the top
    top = rel.sigma_omega > 20000
    ratio = np.interp(2 * rel.sigma_omega[top][:5], rel.sigma_omega, rel.bandwidth_hz) \
        / rel.bandwidth_hz[top][:5]
    np.testing.assert_allclose(ratio, 2.0, rtol=0.03)


def test_kf_single_is_the_per_gyro_recursion_then_ols():
    rng = np.random.default_rng(2)
    n = 500
    z = swing(n) @ P003_LAYOUT.H.T + 3e-4 * rng.standard_normal((n, 6))
    est = SingleGyroKF().fit(P003_LAYOUT, P003_MODEL, P003_DT)
    ref = np.empty((n, 6))
    for i in range(6):
        Ki = est.gain_[i]
        x = np.array([z[0, i], 0.0])
        for k in range(n):
            x = x + Ki * (z[k, i] - x.sum())                          # x = x + K (z − [1 1] x)
            ref[k, i] = x[0]
    # the modal form and the recursion round differently: 1e-12 of the signal
    np.testing.assert_allclose(est.estimate(z), ref @ est.weights_.T, rtol=0,
                               atol=1e-12 * np.max(np.abs(z)))


# -- paper 003 swing: predicted vs realised error ----------------------------------------

def _stationary_terms(kf, axis):
    """Σ_τ γ(τ) and Σ_τ γ(τ)² of the ARW-driven error of one axis (τ ∈ ℤ)."""
    f = kf._filter
    R = kf.noise_.R(kf.dt_s_)
    m = f.B @ R @ f.B.T / (1 - np.outer(f.lam, f.lam))
    c = f.modes[axis]
    tau = np.arange(0, 40000)[:, None]
    g = ((c * f.lam ** tau) @ m) @ c                                   # γ(τ) = c Λ^τ M cᵀ
    return 2 * g.sum() - g[0], 2 * np.sum(g ** 2) - g[0] ** 2


def test_kf_array_swing_arw_error_matches_prediction():
    """Paper 003 §4.2 through the real chain, ARW only in the readings."""
    root = Path(__file__).resolve().parents[1]
    sc = load_scenario(root / "src" / "gyroarray" / "data" / "scenarios" / "paper003" / "swing_s1_n6.toml")
    arw_only = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.1}),))
    res = simulate(dataclasses.replace(sc, model=arw_only))
    w, z = res.truth.omega_body_rad_s, res.readings_rad_s
    n = z.shape[0]
    kf = ArrayKF().fit(sc.layout, sc.model, 1 / sc.sample_rate_hz)     # designed with RRW, as the paper
    e = kf.estimate(z) - w
    e_det = kf.estimate(w @ sc.layout.H.T) - w                         # lag of the swing (exact, linear)
    pred_cov = kf.error_covariance(n, rrw=False)
    mse = np.mean(e ** 2, axis=0)
    z_crit = stats.norm.ppf(1 - ALPHA / 6)                            # two-sided, 3 axes
    for a in range(3):
        mu2 = np.mean(e_det[:, a] ** 2)
        pred = mu2 + np.mean(pred_cov[:, a, a])
        s1, s2 = _stationary_terms(kf, a)
        sd = np.sqrt(2 * s2 / n + 4 * mu2 * s1 / n)                    # Var(mean e²), Gaussian
        assert abs(mse[a] - pred) <= z_crit * sd, (a, mse[a], pred, sd)
    assert np.allclose(np.mean(pred_cov[n // 2:], axis=0), kf.covariance_, rtol=1e-6)


def test_kf_array_error_covariance_with_rrw_matches_monte_carlo():
    m, n = 300, 3000
    kf = ArrayKF().fit(P003_LAYOUT, P003_MODEL, P003_DT)
    rng = np.random.default_rng(2023)
    b = np.cumsum(P003_RRW * np.sqrt(P003_DT) * rng.standard_normal((m, n, 6)), axis=1)
    v = (P003_ARW / np.sqrt(P003_DT)) * rng.standard_normal((m, n, 6))
    checks = np.array([0, 99, 999, n - 1])
    e = np.stack([kf.estimate(b[i] + v[i])[checks] for i in range(m)])   # (m, checks, 3)
    pred = kf.error_covariance(n)[checks][:, [0, 1, 2], [0, 1, 2]]     # (checks, 3)
    lo, hi = chi2_interval(m, ALPHA / pred.size)
    ss = np.sum(e ** 2, axis=0) / pred                                # ~ χ²(m): zero mean, Gaussian
    assert np.all((lo < ss) & (ss < hi)), ss / m
    # the RRW part grows: at the end it dominates the ARW floor by > 3x
    assert np.all(pred[-1] > 3 * np.diag(kf.covariance_))


def test_rts_smoother_beats_the_kf_on_every_axis():
    m, n = 30, 400
    rng = np.random.default_rng(99)
    w = swing(n)
    bound = OfflineBound().fit(P003_LAYOUT, P003_MODEL, P003_DT)
    kf = ArrayKF().fit(P003_LAYOUT, P003_MODEL, P003_DT)
    d_kf, d_tv = np.empty((m, 3)), np.empty((m, 3))
    for i in range(m):
        z = w @ P003_LAYOUT.H.T + simulate_readings(P003_MODEL, np.zeros((n, 3)), P003_LAYOUT,
                                                    P003_DT, rng)
        xs, xsm = bound.smooth(z)
        mse_rts = np.mean((xsm[:, :3] - w) ** 2, axis=0)
        d_tv[i] = np.mean((xs[:, :3] - w) ** 2, axis=0) - mse_rts
        d_kf[i] = np.mean((kf.estimate(z) - w) ** 2, axis=0) - mse_rts
    # paired differences over independent runs; one-sided t-test that the mean
    # gain is > 0 at 1e-3 (Bonferroni over 3 axes and 2 filters)
    t = stats.t.ppf(1 - ALPHA / 6, m - 1)
    for d in (d_kf, d_tv):
        assert np.all(d.mean(0) - t * d.std(0, ddof=1) / np.sqrt(m) > 0), d.mean(0)
    crb = GLS().fit(P003_LAYOUT, P003_MODEL, P003_DT).covariance_
    np.testing.assert_allclose(bound.crb_covariance_, crb, rtol=0, atol=1e-12 * np.max(crb))


def test_efficiency_helper():
    np.testing.assert_allclose(efficiency([2.0, 4.0, 1.0], [1.0, 1.0, 1.0]), [0.5, 0.25, 1.0])
    with pytest.raises(InputError):
        efficiency([0.0, 1, 1], [1, 1, 1])


def test_identical_noise_constructor_matches_model():
    nz = ArrayNoise.identical(6, P003_ARW, P003_RRW)
    assert nz == array_noise(P003_MODEL, 6)


# -- hyperparameters ----------------------------------------------------------------------

@pytest.mark.parametrize("est, match", [
    (ArrayKF(bandwidth_hz=5.0, q_omega=1e-6), "not both"),
    (ArrayKF(bandwidth_hz=50.0), "Nyquist"),
    (ArrayKF(bandwidth_hz=-1.0), "> 0"),
    (ArrayKF(q_omega=[1e-6, 2e-6]), "3 numbers"),
    (ArrayKF(bias_states="yes"), "True or False"),
    (ArrayKF(bandwidth_hz=0.01), "below the lowest bandwidth"),
    (SingleGyroKF(q_omega=float("nan")), "finite"),
    (GLS(lowpass_hz=0.0), "lowpass_hz"),
    (OLS(lowpass_hz="fast"), "lowpass_hz"),
    (OfflineBound(bandwidth_hz=80.0), "Nyquist"),
])
def test_bad_hyperparameters_refused_at_fit(est, match):
    with pytest.raises(InputError, match=match):
        est.fit(ODD_LAYOUT, ODD_MODEL, P003_DT)


@pytest.mark.parametrize("bias_states", [True, False])
def test_bandwidth_design_reaches_the_target_on_every_axis(bias_states):
    # anisotropic, correlated: the three axes need different q_ω
    kf = ArrayKF(bandwidth_hz=3.0, bias_states=bias_states).fit(ODD_LAYOUT, ODD_MODEL, P003_DT)
    np.testing.assert_allclose(kf.bandwidth_hz_, 3.0, rtol=1e-9)       # root find to |log| < 1e-11
    assert np.ptp(kf.q_omega_) > 0.05 * np.max(kf.q_omega_)
    again = ArrayKF(q_omega=kf.q_omega_, bias_states=bias_states).fit(ODD_LAYOUT, ODD_MODEL, P003_DT)
    np.testing.assert_array_equal(again.gain_, kf.gain_)
