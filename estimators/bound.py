"""``bound``: the best offline estimate for the full model, and the CRB.

The time-varying KF and the Rauch–Tung–Striebel smoother on the state of
``kf_array`` (x = [ω_b; b], random walks) use every sample, before and
after, with the exact start (biases at 0, a diffuse rate prior). Beside it,
``crb_covariance_`` = (HᵀR⁻¹H)⁻¹: the Cramér–Rao bound of one sample under
white Gaussian noise, the floor of any unbiased per-sample estimator.

Cost: one numpy step per sample forwards and one backwards, about
``D³`` flops each (D = N + 3) but dominated by numpy's per-call overhead
(≈ 60–80 µs per sample for N = 6 on the project machine: ~5 s for the
60 000 samples of a 10-minute run at 100 Hz), and n·D² doubles of smoother
gains (≈ 39 MB for that run). The loop is needed: along the unobservable
directions the covariance grows without bound and the smoother gain tends to
I only like 1/k, so no constant-gain (lfilter) form exists.
"""

from __future__ import annotations

import numpy as np

from gyroarray.errors import InputError

from ._kalman import kf_step, state_model
from .base import Estimator, _readonly, register
from .kf_array import gls_weights, rate_psd

__all__ = ["OfflineBound", "efficiency"]

#: Prior variance of the rate at the start, in units of the largest one-sample
#: measurement variance: diffuse (the prior weighs 1e-6 of one sample).
PRIOR_RATE_VARIANCE_FACTOR = 1e6


@register("bound")
class OfflineBound(Estimator):
    """Time-varying KF + RTS smoother on [ω_b; b]; the CRB covariance.

    Parameters
    ----------
    bandwidth_hz : float or None
        Sets q_ω as ``kf_array`` does (the steady-state filter's −3 dB
        bandwidth) [Hz]; None with q_omega None: 10 Hz.
    q_omega : float, array_like of 3, or None
        PSD of the rate's driving noise [rad²/s³].

    Attributes
    ----------
    q_omega_ : ndarray, shape (3,)
        [rad²/s³].
    crb_covariance_ : ndarray, shape (3, 3)
        (HᵀR⁻¹H)⁻¹ [rad²/s²].
    covariance_ : None
        The smoother's error has no steady state (unobservable random walk).

    Notes
    -----
    Prior x̂_{-1} = [G z_0; 0] (G the GLS weights), P_{-1} = blkdiag(p I, 0)
    with p = 1e6·max R_ii: the biases start at 0 as simulated, the rate is
    unknown. Forwards: ``kf_step`` (x = F x, P = F P F' + Q, K = P H' S⁻¹,
    x = x + K(z − H x), Joseph update); the smoother gain
    C_k = P_k F' (F P_k F' + Q)⁻¹ is kept. Backwards:
    x_s,k = x_k + C_k (x_s,k+1 − F x_k).

    References
    ----------
    Rauch, Tung, Striebel, AIAA J. 3(8), 1965. Paper 003 §2.1 (the model).
    """

    description = "offline bound: time-varying KF + RTS smoother on [rate; biases], and the CRB"

    def __init__(self, *, bandwidth_hz=None, q_omega=None):
        self.bandwidth_hz = bandwidth_hz
        self.q_omega = q_omega

    def _fit(self, H, noise, dt_s):
        R, Qb = noise.R(dt_s), noise.Qb(dt_s)
        try:
            q = rate_psd(H, R, Qb, dt_s, self.bandwidth_hz, self.q_omega)
        except InputError as err:
            raise InputError(f"bound: {err.message}") from None
        self._model = state_model(H, R, q * dt_s, Qb)
        g, cov = gls_weights(H, R)
        self.q_omega_ = _readonly(q)
        self.gls_weights_ = _readonly(g)
        self.crb_covariance_ = _readonly(cov)
        self.covariance_ = None

    def _prior(self, z0):
        D = self._model.dim
        x0 = np.zeros(D)
        x0[:3] = self.gls_weights_ @ z0
        P0 = np.zeros((D, D))
        P0[:3, :3] = PRIOR_RATE_VARIANCE_FACTOR * np.max(np.diag(self._model.R)) * np.eye(3)
        return x0, P0

    def smooth(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Filtered and smoothed states (n, D) of checked readings z (n, N)."""
        mdl = self._model
        F, H, Q, R = mdl.F, mdl.H1, mdl.Q, mdl.R
        n, D = z.shape[0], mdl.dim
        x, P = self._prior(z[0])
        xs = np.empty((n, D))
        cs = np.empty((n, D, D))
        for k in range(n):
            x, P, _, _ = kf_step(x, P, z[k], F, H, Q, R)
            xs[k] = x
            cs[k] = np.linalg.solve(F @ P @ F.T + Q, F @ P).T          # C = P F' (F P F' + Q)⁻¹
        xsm = xs.copy()
        for k in range(n - 2, -1, -1):
            xsm[k] = xs[k] + cs[k] @ (xsm[k + 1] - F @ xs[k])         # x_s = x + C (x_s⁺ − F x)
        return xs, xsm

    def _estimate(self, z):
        return np.ascontiguousarray(self.smooth(z)[1][:, :3])


def efficiency(achieved_sigma_axis, bound_sigma_axis) -> np.ndarray:
    """Statistical efficiency per axis: bound σ / achieved σ [-] (1 = on the bound).

    Parameters
    ----------
    achieved_sigma_axis, bound_sigma_axis : array_like
        1σ errors per axis of an estimator and of the bound [rad/s], > 0.

    Returns
    -------
    ndarray
        bound/achieved, broadcast over the inputs.
    """
    a = np.asarray(achieved_sigma_axis, dtype=float)
    b = np.asarray(bound_sigma_axis, dtype=float)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.all(a > 0) and np.all(b > 0)):
        raise InputError("efficiency needs finite 1σ errors > 0")
    return b / a
