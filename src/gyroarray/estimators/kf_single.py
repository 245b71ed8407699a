"""``kf_single``: paper 002's single-gyro KF on each gyro, then OLS.

Each gyro i has its own KF on x = [ω_i, b_i] (paper 002 §3, Eq. 4–17):
ω_i and b_i random walks, z_i = ω_i + b_i + v_i. The filtered gyro rates are
then combined by ordinary least squares, ω̂ = (HᵀH)⁻¹Hᵀ ω̂_gyros, so the
method runs on an array. The module also has the single-gyro design
functions and the reproduction of paper 002's bandwidth relation (Eq. 18).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyroarray.core import units
from gyroarray.core.errors import InputError

from gyroarray.estimators.kalman import NoSteadyState, SteadyStateFilter, state_model, steady_state
from gyroarray.estimators.base import Estimator, LinearSystem, readonly, register
from gyroarray.estimators.kf_array import filter_system, rate_psd

__all__ = ["SingleGyroKF", "single_gyro_filter", "single_gyro_gain", "bandwidth_hz",
           "q_omega_for_bandwidth", "Paper002Relation", "paper002_relation"]

_ONE = np.ones((1, 1))


def _single_covs(arw, rrw, dt):
    R = np.array([[arw * arw / dt]])                                 # σ = N/√dt
    Qb = np.array([[rrw * rrw * dt]])                                # σ = K√dt
    return R, Qb


def single_gyro_filter(arw: float, rrw: float, q_omega: float, dt: float) -> SteadyStateFilter:
    """Steady-state KF of one gyro on x = [ω, b].

    Parameters
    ----------
    arw : float
        Angle random walk N [rad/√s].
    rrw : float
        Rate random walk K [rad/s/√s] (> 0: the bias needs process noise).
    q_omega : float
        PSD of the white noise driving ω [rad²/s³].
    dt : float
        Sample period [s].
    """
    R, Qb = _single_covs(arw, rrw, dt)
    return steady_state(state_model(_ONE, R, np.array([q_omega * dt]), Qb))


def single_gyro_gain(arw: float, rrw: float, q_omega: float, dt: float) -> np.ndarray:
    """Steady-state gain K_s = [k1, k2] of paper 002's single-gyro KF [-].

    Parameters as :func:`single_gyro_filter`. The gain is that of the
    discrete KF (Eq. 9–11 iterated to convergence), from the Riccati
    equation on the observable state ω + b.
    """
    return single_gyro_filter(arw, rrw, q_omega, dt).K[:, 0].copy()


def bandwidth_hz(q_omega: float, arw: float, rrw: float, dt: float) -> float:
    """−3 dB bandwidth [Hz] of the rate estimate ω̂/z of one gyro's KF.

    The response of the discrete filter, ω̂/z = c·b/(1 − λ z⁻¹) (one stable
    mode), is evaluated on the unit circle; its −3 dB point relative to the
    DC gain q_ω/(q_ω + q_b) is found by Brent's method. Parameters as
    :func:`single_gyro_filter`.
    """
    return float(single_gyro_filter(arw, rrw, q_omega, dt).bandwidth_hz(_ONE, dt)[0])


def q_omega_for_bandwidth(f_hz: float, arw: float, rrw: float, dt: float) -> float:
    """q_ω [rad²/s³] whose single-gyro KF has the −3 dB bandwidth f [Hz]."""
    R, Qb = _single_covs(arw, rrw, dt)
    return float(rate_psd(_ONE, R, Qb, dt, f_hz, None)[0])


@register("kf_single")
class SingleGyroKF(Estimator):
    """Paper 002's single-gyro KF on each gyro, then OLS of the filtered gyros.

    Parameters
    ----------
    bandwidth_hz : float or None
        −3 dB bandwidth of each gyro's rate estimate [Hz]; None with q_omega
        None: :data:`gyroarray.estimators.kf_array.DEFAULT_BANDWIDTH_HZ`.
    q_omega : float or None
        PSD of the white noise driving each gyro's rate [rad²/s³].

    Attributes
    ----------
    q_omega_ : ndarray, shape (N,)
        PSD per gyro [rad²/s³].
    gain_ : ndarray, shape (N, 2)
        Steady-state gain [k1, k2] per gyro [-].
    bandwidth_hz_ : ndarray, shape (N,)
        −3 dB bandwidth per gyro [Hz].
    weights_ : ndarray, shape (3, N)
        OLS weights (HᵀH)⁻¹Hᵀ [-].
    covariance_ : ndarray, shape (3, 3)
        Steady covariance of the body-rate error driven by the ARW [rad²/s²].

    Notes
    -----
    Gyro i runs x̂_k = x̂_{k-1} + K_i (z_k − [1 1] x̂_{k-1}) from
    x̂_{-1} = [z_0, 0]. Paper 002 runs a continuous-time rewrite of the
    filter (its Eq. 12–17, the discrete gain inside a continuous model);
    here the discrete KF itself is run. Gyros with equal noise share one
    design. The correlation between gyros is ignored (each filter sees one
    gyro), but enters ``covariance_``.

    References
    ----------
    Paper 002 (``shared/papers/002_*.txt``), Micromachines 6(2), 266, 2015,
    §3, Eq. 4–18.
    """

    description = "paper 002 single-gyro KF [rate, bias] on each gyro, then OLS"
    _design_tags = {"weights": "ols", "rho_weighted": False, "bandwidth_param": "bandwidth_hz",
                    "channel_filter": "kf", "bias_states": "per_gyro"}

    def __init__(self, *, bandwidth_hz=None, q_omega=None):
        self.bandwidth_hz = bandwidth_hz
        self.q_omega = q_omega

    def _fit(self, H, noise, dt_s):
        designs: dict[tuple[float, float], tuple[float, SteadyStateFilter]] = {}
        filters = []
        for arw, rrw in zip(noise.arw_rad_rt_s, noise.rrw_rad_s_rt_s, strict=True):
            key = (float(arw), float(rrw))
            if key not in designs:
                R, Qb = _single_covs(arw, rrw, dt_s)
                try:
                    q = float(rate_psd(_ONE, R, Qb, dt_s, self.bandwidth_hz, self.q_omega)[0])
                    designs[key] = (q, steady_state(state_model(_ONE, R, np.array([q * dt_s]), Qb)))
                except NoSteadyState:
                    raise InputError("kf_single: the bias state needs rate random walk (rrw > 0) "
                                     "on every gyro") from None
            filters.append(designs[key])
        self._filters = [f for _, f in filters]
        self.q_omega_ = readonly([q for q, _ in filters])
        self.gain_ = readonly([f.K[:, 0] for f in self._filters])
        self.bandwidth_hz_ = readonly([f.bandwidth_hz(_ONE, dt_s)[0] for f in self._filters])
        m = np.linalg.pinv(H)
        self.weights_ = readonly(m)
        # filtered ARW of gyro i: Σ_k c_i b_i λ_i^k v_i,k-j; cov_ij = R_ij c_i b_i c_j b_j / (1 − λ_i λ_j)
        g = np.array([f.modes[0, 0] * f.B[0, 0] for f in self._filters])
        lam = np.array([f.lam[0] for f in self._filters])
        s = noise.R(dt_s) * np.outer(g, g) / (1.0 - np.outer(lam, lam))
        cov = m @ s @ m.T
        self.covariance_ = readonly(0.5 * (cov + cov.T))

    def linear_system(self) -> LinearSystem:
        """The N gyro filters (state [ω_i, b_i] each, from [z_0i, 0]) side by side, then OLS."""
        self._check_fitted()
        n = self.n_gyros_
        D = 2 * n
        out = {k: np.zeros((D, D)) for k in ("A", "S", "S_inv")}
        K, X0, lam = np.zeros((D, n)), np.zeros((D, n)), np.zeros(D)
        pick = np.zeros((n, D))
        for i, f in enumerate(self._filters):
            s = filter_system(f, np.array([[1.0], [0.0]]))
            blk = slice(2 * i, 2 * i + 2)
            for k in out:
                out[k][blk, blk] = getattr(s, k)
            K[blk, i], X0[blk, i], lam[blk] = s.K[:, 0], s.X0[:, 0], s.lam
            pick[i, 2 * i] = 1.0
        return LinearSystem(A=out["A"], K=K, C=np.array(self.weights_) @ pick, X0=X0, lam=lam,
                            S=out["S"], S_inv=out["S_inv"])

    def _estimate(self, z):
        w = np.empty_like(z)
        for i, f in enumerate(self._filters):
            w[:, i] = f.apply(z[:, i:i + 1], np.array([z[0, i], 0.0]))[:, 0]
        return np.ascontiguousarray(w @ self.weights_.T)


# -- paper 002 Eq. 18 -------------------------------------------------------------

#: Paper 002 §3.2: ARW 0.1667 deg/√h, RRW 1200 deg/h/√h, filter period 0.005 s.
P002_ARW_DEG_RT_H = 0.1667
P002_RRW_DEG_H_RT_H = 1200.0
P002_DT_S = 0.005
#: Paper 002 Eq. 18: BW [Hz] = 0.0004177·q_ω + 0.03213.
P002_SLOPE = 0.0004177
P002_INTERCEPT = 0.03213


@dataclass(frozen=True)
class Paper002Relation:
    """Bandwidth of paper 002's single-gyro KF against its rate noise, and a line.

    Attributes
    ----------
    sigma_omega : ndarray
        σ_ω = √q_ω, the rate's driving noise in RRW units [deg/h/√h]: the
        coordinate in which the paper's Eq. 18 is (nearly) linear.
    q_omega_rad2_s3 : ndarray
        The same as PSD q_ω [rad²/s³].
    bandwidth_hz : ndarray
        −3 dB bandwidth of ω̂/z from the discrete frequency response [Hz].
    fit_range : tuple of float
        σ_ω range of the lin-lin fit [deg/h/√h].
    slope, intercept : float
        Least-squares line BW = slope·σ_ω + intercept [Hz per deg/h/√h, Hz].
    asymptotic_slope : float
        1/(2π N) in the same units: BW → σ_ω/(2π N) for σ_ω ≫ K.
    floor_hz : float
        Bandwidth as q_ω → 0: K/(2π N) [Hz] (the RRW alone).
    linear_within_5pct : tuple of float
        σ_ω range [deg/h/√h] where the line is within 5 % of the bandwidth.
    paper_slope, paper_intercept : float
        Eq. 18 as printed.
    """

    sigma_omega: np.ndarray
    q_omega_rad2_s3: np.ndarray
    bandwidth_hz: np.ndarray
    fit_range: tuple[float, float]
    slope: float
    intercept: float
    asymptotic_slope: float
    floor_hz: float
    linear_within_5pct: tuple[float, float]
    paper_slope: float = P002_SLOPE
    paper_intercept: float = P002_INTERCEPT


def paper002_relation(sigma_omega=None, fit_range=(1000.0, 72000.0)) -> Paper002Relation:
    """Reproduce paper 002's linear relation between bandwidth and q_ω (Eq. 18).

    Parameters
    ----------
    sigma_omega : array_like, optional
        σ_ω grid [deg/h/√h] (default: 0 and 1..1e5, 300 log-spaced points).
    fit_range : (float, float)
        σ_ω range of the straight-line fit [deg/h/√h]; the default spans the
        paper's uses, from its example q_ω = 1000 to its 30 Hz design.

    Notes
    -----
    With the paper's ARW N = 0.1667 deg/√h, RRW K = 1200 deg/h/√h and
    T = 0.005 s, the steady-state single-gyro KF has (continuous limit)
    ω̂/z = k1/(s + k), k = √(q_ω + K²)/N, so BW_−3dB = √(q_ω + K²)/(2π N):
    a straight line in log-log against q_ω only for q_ω ≫ K² (slope 1/2),
    and never a straight line in q_ω itself. Against σ_ω = √q_ω it is
    linear for σ_ω ≫ K, with slope 1/(2πN) = 2.652e-4 Hz per deg/h/√h and
    a fitted intercept near zero; the paper's Eq. 18 (lin-lin, slope
    4.177e-4, intercept 0.032 Hz) has this shape, so its "q_ω [(deg/h)²]"
    behaves as a standard deviation (the paper calls its σ's "variances"
    elsewhere too). Its slope is π/2 (to 0.3 %) times the −3 dB one — the
    noise-equivalent bandwidth of a first-order low-pass is (π/2)·f_−3dB —
    which this function reports but does not assume.
    """
    arw = units.arw_deg_rt_h_to_rad_rt_s(P002_ARW_DEG_RT_H)
    rrw = units.rrw_deg_h_rt_h_to_rad_s_rt_s(P002_RRW_DEG_H_RT_H)
    if sigma_omega is None:
        sigma_omega = np.concatenate([[0.0], np.logspace(0, 5, 300)])
    s = np.asarray(sigma_omega, dtype=float)
    q = units.rrw_deg_h_rt_h_to_rad_s_rt_s(s) ** 2                   # σ_ω in RRW units -> PSD
    bw = np.array([bandwidth_hz(qi, arw, rrw, P002_DT_S) for qi in q])
    lo, hi = fit_range
    sel = (s >= lo) & (s <= hi)
    slope, intercept = np.polyfit(s[sel], bw[sel], 1)
    line = slope * s + intercept
    ok = np.abs(line - bw) <= 0.05 * bw
    # the longest run of grid points where the line holds
    best, run_start, span = (0, 0), None, (float("nan"), float("nan"))
    for i, flag in enumerate(np.append(ok, False)):
        if flag and run_start is None:
            run_start = i
        elif not flag and run_start is not None:
            if i - run_start > best[1] - best[0]:
                best = (run_start, i)
            run_start = None
    if best[1] > best[0]:
        span = (float(s[best[0]]), float(s[best[1] - 1]))
    n_rad = arw
    return Paper002Relation(
        sigma_omega=s, q_omega_rad2_s3=q, bandwidth_hz=bw, fit_range=(float(lo), float(hi)),
        slope=float(slope), intercept=float(intercept),
        asymptotic_slope=float(units.rrw_deg_h_rt_h_to_rad_s_rt_s(1.0) / (2 * np.pi * n_rad)),
        floor_hz=float(rrw / (2 * np.pi * n_rad)), linear_within_5pct=span)
