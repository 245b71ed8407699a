"""``kf_array``: the steady-state Kalman fusion of paper 003 (§2.1, Eq. 4–9).

State x = [ω_b (3); b (N)]: the body rate and the gyro biases, both random
walks; readings z = H ω_b + b + v. The gain is the steady-state one (the
covariance diverges, the gain does not); the filter runs as N first-order
IIR modes through ``scipy.signal.lfilter``.
"""

from __future__ import annotations

import numpy as np

from gyroarray.core.errors import InputError

from gyroarray.estimators.kalman import (NoSteadyState, SteadyStateFilter, solve_log, state_model,
                                          steady_state)
from gyroarray.estimators.base import Estimator, LinearSystem, readonly, register

__all__ = ["ArrayKF", "DEFAULT_BANDWIDTH_HZ", "gls_weights", "rate_psd"]

#: Bandwidth [Hz] a KF is designed for when neither bandwidth_hz nor q_omega is given.
DEFAULT_BANDWIDTH_HZ = 10.0


def gls_weights(H: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """GLS weights G = (HᵀR⁻¹H)⁻¹HᵀR⁻¹ (3×N) and covariance (HᵀR⁻¹H)⁻¹ [rad²/s²]."""
    rih = np.linalg.solve(R, H)                                      # R⁻¹ H
    cov = np.linalg.inv(H.T @ rih)
    cov = 0.5 * (cov + cov.T)
    return cov @ rih.T, cov


def _check_positive(name: str, value, shape=()) -> np.ndarray:
    try:
        v = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if v.ndim > len(shape) or (v.ndim and v.shape != shape):
        raise InputError(f"{name} must be a number" + (f" or {shape[0]} numbers" if shape else "")
                         + f", got {value!r}")
    if not (np.all(np.isfinite(v)) and np.all(v > 0)):
        raise InputError(f"{name} must be finite and > 0, got {value!r}")
    return np.broadcast_to(v, shape).copy() if shape else v


def rate_psd(H: np.ndarray, R: np.ndarray, Qb: np.ndarray | None, dt_s: float,
             bandwidth_hz, q_omega, *, per: str = "axis") -> np.ndarray:
    """q_ω per rate axis [rad²/s³]: as given, or solved for a −3 dB bandwidth.

    Parameters
    ----------
    H : ndarray, shape (N, p)
        Rate axes (p = 3 for the array, p = 1 for one gyro).
    R, Qb : ndarray
        Measurement and bias-increment covariances of one sample [rad²/s²]
        (Qb None: no bias states).
    dt_s : float
        Sample period [s].
    bandwidth_hz : float or None
        Wanted −3 dB bandwidth of every rate axis [Hz], below Nyquist.
    q_omega : float, array_like of p, or None
        Power spectral density of the rate's driving white noise [rad²/s³].

    Notes
    -----
    Each axis' q_ω is a 1-D root of log(BW_a(q_ω)/f) = 0, BW_a the −3 dB
    frequency of the filter's own frequency response. The axes are solved
    together by a secant step per axis in log q_ω (the axes couple weakly;
    BW ∝ √q_ω where the rate noise dominates, so the first slope is 1/2),
    to |log(BW/f)| < 1e-11; should that not converge in 40 steps, each axis
    is solved in turn by Brent's method (Gauss–Seidel sweeps). The start is
    the continuous first-order estimate q_ω = (2π f)²·dt·[(HᵀR⁻¹H)⁻¹]_aa.
    """
    p = H.shape[1]
    if bandwidth_hz is not None and q_omega is not None:
        raise InputError("give bandwidth_hz or q_omega, not both (set the other to None)")
    if q_omega is not None:
        return _check_positive("q_omega [rad²/s³]", q_omega, (p,))
    f = DEFAULT_BANDWIDTH_HZ if bandwidth_hz is None else float(
        _check_positive("bandwidth_hz [Hz]", bandwidth_hz))
    nyquist = 0.5 / dt_s
    if f >= nyquist:
        raise InputError(f"bandwidth_hz = {f:g} Hz is not below the Nyquist frequency "
                         f"{nyquist:g} Hz of dt = {dt_s:g} s")
    _, cov = gls_weights(H, R)
    q0 = (2 * np.pi * f) ** 2 * dt_s * np.diag(cov)

    def miss(qq):                                                    # log(BW/f) per axis
        return np.log(design(H, R, Qb, qq, dt_s).bandwidth_hz(H, dt_s) / f)

    x, y = np.log(q0), miss(q0)
    slope = np.full(p, 0.5)
    for _ in range(40):
        if np.max(np.abs(y)) < 1e-11:
            return np.exp(x)
        x_new = x - y / slope                                        # secant step per axis
        y_new = miss(np.exp(x_new))
        dx = x_new - x
        moved = np.abs(dx) > 1e-14
        slope = np.where(moved, (y_new - y) / np.where(moved, dx, 1.0), slope)
        slope = np.clip(slope, 0.02, 4.0)
        x, y = x_new, y_new
    q = q0.copy()
    try:
        for _ in range(50):
            prev = q.copy()
            for a in range(p):
                def g(v, a=a):
                    qq = q.copy()
                    qq[a] = v
                    return float(miss(qq)[a])
                q[a] = solve_log(g, q[a], what="q_omega")
            if np.max(np.abs(q - prev) / q) < 1e-9:
                return q
    except InputError:
        floor = f * np.exp(miss(q0 * 1e-12))
        if np.any(floor > f):
            raise InputError(f"bandwidth_hz = {f:g} Hz is below the lowest bandwidth this noise "
                             f"allows ({', '.join(f'{b:.3g}' for b in floor)} Hz per axis, set by the "
                             "rate random walk of the bias states)") from None
        raise
    raise InputError(f"the q_omega design for bandwidth_hz = {f:g} Hz did not converge")


def filter_system(filt: SteadyStateFilter, x0_map: np.ndarray) -> LinearSystem:
    """A steady-state filter as a :class:`LinearSystem` (its stable and unit modes)."""
    mdl = filt.model
    D, p = mdl.dim, mdl.p
    A = (np.eye(D) - filt.K @ mdl.H1) @ mdl.F                        # A = (I − K H1) F
    S = np.hstack([filt.modes, filt.Vu])
    lam = np.concatenate([filt.lam, np.ones(D - filt.lam.size)])
    C = np.zeros((p, D))
    C[:, :p] = np.eye(p)
    return LinearSystem(A=A, K=filt.K.copy(), C=C, X0=np.array(x0_map, dtype=float), lam=lam,
                        S=S, S_inv=filt.to_modes.copy())


def design(H, R, Qb, q_omega, dt_s) -> SteadyStateFilter:
    """The steady-state filter for q_ω [rad²/s³] per axis (increments q_ω·dt)."""
    return steady_state(state_model(H, R, np.asarray(q_omega, dtype=float) * dt_s, Qb))


@register("kf_array")
class ArrayKF(Estimator):
    """Steady-state Kalman fusion of a gyro array (paper 003).

    Parameters
    ----------
    bandwidth_hz : float or None
        −3 dB bandwidth of each body-rate axis [Hz]; q_ω is solved for it.
        None with q_omega None: :data:`DEFAULT_BANDWIDTH_HZ`.
    q_omega : float, array_like of 3, or None
        PSD of the white noise driving each body-rate axis [rad²/s³]
        (instead of bandwidth_hz).
    bias_states : bool
        Estimate the N gyro biases (True, paper 003); False: state ω only.

    Attributes
    ----------
    q_omega_ : ndarray, shape (3,)
        PSD used per axis [rad²/s³].
    gain_ : ndarray, shape (D, N)
        Steady-state gain K (D = 3 + N, or 3) [-].
    eigenvalues_ : ndarray
        Poles of the stable modes of A = (I − K H1) F [-].
    bandwidth_hz_ : ndarray, shape (3,)
        Achieved −3 dB bandwidth per axis [Hz].
    gls_weights_ : ndarray, shape (3, N)
        GLS weights starting the filter: x̂_{-1} = [G z_0; 0].
    covariance_ : ndarray, shape (3, 3)
        Steady covariance of the rate error driven by the ARW noise [rad²/s²]
        (the RRW part grows without bound: :meth:`error_covariance`).

    Notes
    -----
    The model is paper 003's Eq. 4–5 discretised at dt (F = I, Q =
    blkdiag(q_ω dt, Q_b), R); see :func:`gyroarray.estimators.kalman.steady_state`
    for the gain on the observable subspace. The filter is
    x̂_k = x̂_{k-1} + K (z_k − H1 x̂_{k-1}) with the prior
    x̂_{-1} = [G z_0; 0] (G the GLS weights; the simulator's biases start
    at 0). Three combinations of the state (the unobservable directions
    [u; −H u]) never change after the start: a constant rate present at the
    start is split between rate and bias in the ratio of the process noises,
    so the GLS start keeps that split at the level of one sample's noise.
    Paper 003's Eq. 8 discretises a continuous filter with the discrete gain;
    here the discrete KF itself is run (what its Eq. 9–11 iterate).

    References
    ----------
    Paper 003 (``shared/papers/003_*.txt``), Micromachines 14(4), 759, 2023,
    §2.1, Eq. 4–9.
    """

    description = "paper 003 steady-state Kalman fusion, state [body rate; gyro biases]"
    _design_tags = {"weights": "gls", "bandwidth_param": "bandwidth_hz", "channel_filter": "kf",
                    "bias_states": "array", "needs_rrw_for_bias_states": True}

    def __init__(self, *, bandwidth_hz=None, q_omega=None, bias_states=True):
        self.bandwidth_hz = bandwidth_hz
        self.q_omega = q_omega
        self.bias_states = bias_states

    def _fit(self, H, noise, dt_s):
        if not isinstance(self.bias_states, (bool, np.bool_)):
            raise InputError(f"bias_states must be True or False, got {self.bias_states!r}")
        R = noise.R(dt_s)
        Qb = noise.Qb(dt_s) if self.bias_states else None
        try:
            q = rate_psd(H, R, Qb, dt_s, self.bandwidth_hz, self.q_omega)
            filt = design(H, R, Qb, q, dt_s)
        except NoSteadyState as err:
            raise InputError(f"kf_array: {err.message}; its bias states need rate random walk "
                             "(rrw > 0) on the gyros: add an rrw entry to the model, or use an "
                             "estimator without bias states (gls, ols; in Python: "
                             "ArrayKF(bias_states=False))") from None
        self._filter = filt
        self.q_omega_ = readonly(q)
        self.gain_ = readonly(filt.K)
        self.eigenvalues_ = readonly(filt.lam)
        self.bandwidth_hz_ = readonly(filt.bandwidth_hz(H, dt_s))
        g, _ = gls_weights(H, R)
        self.gls_weights_ = readonly(g)
        self.covariance_ = readonly(filt.stationary_rate_covariance(R))

    def _x0_map(self) -> np.ndarray:
        """x̂_{-1} = X0 z_0 (D×N)."""
        D = self._filter.model.dim
        x0 = np.zeros((D, self.n_gyros_))
        x0[:3] = self.gls_weights_
        return x0

    def _estimate(self, z):
        return self._filter.apply(z, self._x0_map() @ z[0])

    def linear_system(self) -> LinearSystem:
        """x̂_k = A x̂_{k-1} + K z_k with A = (I − K H1) F, from x̂_{-1} = [G z_0; 0]."""
        self._check_fitted()
        return filter_system(self._filter, self._x0_map())

    def error_covariance(self, n_samples: int, *, arw: bool = True, rrw: bool = True) -> np.ndarray:
        """Exact covariance of the noise-driven body-rate error at each sample.

        Parameters
        ----------
        n_samples : int
            Number of samples n.
        arw, rrw : bool
            Include the ARW (white) and the RRW (bias random walk) part.

        Returns
        -------
        ndarray, shape (n, 3, 3)
            Cov(ω̂_k − ω_k) [rad²/s²] for a deterministic ω, biases starting
            at 0 (as simulated), and the fitted noise. The error of a
            deterministic rate adds to it: ``estimate(ω @ H.T) − ω``
            (the filter is linear).
        """
        self._check_fitted()
        if not self.bias_states:
            raise InputError("error_covariance needs bias_states=True")
        n = int(n_samples)
        if n < 1:
            raise InputError(f"n_samples must be >= 1, got {n_samples!r}")
        R = self.noise_.R(self.dt_s_) if arw else np.zeros((self.n_gyros_,) * 2)
        Qb = self.noise_.Qb(self.dt_s_) if rrw else np.zeros((self.n_gyros_,) * 2)
        return self._filter.error_covariance(n, R, Qb, self._x0_map())
