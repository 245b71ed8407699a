"""``bound``: the best offline estimate for the full model, and the CRB.

The time-varying KF and the Rauch–Tung–Striebel smoother on the state of
``kf_array`` (x = [ω_b; b], random walks) use every sample, before and
after, with the exact start (biases at 0, a diffuse rate prior). Beside it,
``crb_covariance_`` = (HᵀR⁻¹H)⁻¹: the Cramér–Rao bound of one sample under
white Gaussian noise, the floor of any unbiased per-sample estimator.

Cost: two numba passes (:mod:`._bound_kernels`), O(D²N) flops per sample
(D = N + 3), one compiled kernel for every N. Measured on the project
machine (2 shared cores, OPENBLAS_NUM_THREADS=1, best of 5 on 60 000
samples, CPU time, over several runs): ≈ 1.4–1.8 µs per sample for N = 6
and ≈ 2.2–3.1 µs for N = 8 (~1 s for a 1-hour, 360 000-sample run at
100 Hz), against 55–66 and 63–78 µs per sample for the former numpy loop
(:func:`smooth_reference`): 20–40× faster. Wall time is up to ~2× the
CPU time while other jobs hold the cores (3.9 µs for N = 8 in one such
benchmark run). ``benchmarks/bench_estimators.py`` measures the ratio in
one run.

Memory: the forward pass keeps, per sample, the filtered state (D doubles)
and the packed Cholesky factor of the one-step prediction P_{k+1|k}
(D(D+1)/2 doubles, for the smoother gain); the gain C_k itself (D² doubles,
what the numpy loop stored) is never formed. For 360 000 samples and D = 11
(N = 8): factors 190 MB + states 32 MB; peak (tracemalloc) 222 MB in
``estimate`` (smoothed in place) and 253 MB in :meth:`OfflineBound.smooth`
(filtered and smoothed kept apart), against ≈ 412 MB of gains and states in
the numpy loop. D = 9 (N = 6): 156 MB and 181 MB.

The loop over samples is needed: along the unobservable directions the
covariance grows without bound and the smoother gain tends to I only like
1/k, so no constant-gain (lfilter) form exists.

Numerics: the same recursion as the numpy loop, rounding aside. Forwards,
the Joseph update (expanded: P − K U' − (U − K S) K', an identity for any
gain, so its first-order insensitivity to the rounding of K is kept);
S⁻¹ through a Cholesky factor. Backwards, the RTS gain is applied as
C_k = P_k P_{k+1|k}⁻¹ = I − Q P_{k+1|k}⁻¹ (F = I) through the Cholesky
factor of P_{k+1|k} (backward stable for a symmetric positive definite
matrix, where the numpy loop used an LU solve): along the unobservable
directions P_{k+1|k} grows, Q P_{k+1|k}⁻¹ → 0 and C_k → I without forming
the ratio of two growing matrices. The tests hold the kernels to the numpy
loop within 1e-9 of the rate scale (observed ≤ 6e-11).
"""

from __future__ import annotations

import numpy as np

from gyroarray.core.errors import InputError

from gyroarray.estimators import _bound_kernels
from gyroarray.estimators.kalman import kf_step, state_model
from gyroarray.estimators.base import Estimator, readonly, register
from gyroarray.estimators.kf_array import gls_weights, rate_psd
from gyroarray.estimators.noise import baseline_effect

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
    unknown. Forwards, as ``kf_step`` (x = F x, P = F P F' + Q,
    K = P H' S⁻¹, x = x + K(z − H x), Joseph update), keeping the Cholesky
    factor of F P_k F' + Q. Backwards: x_s,k = x_k + C_k (x_s,k+1 − F x_k)
    with the smoother gain C_k = P_k F' (F P_k F' + Q)⁻¹ = I − Q (P_k + Q)⁻¹
    (F = I), applied through that factor. Both passes are numba kernels
    (:mod:`gyroarray.estimators._bound_kernels`); a predicted covariance
    that is not positive definite (no RRW on some gyro: Q_b singular) is
    an InputError.

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
        self.q_omega_ = readonly(q)
        self.gls_weights_ = readonly(g)
        self.crb_covariance_ = readonly(cov)
        self.covariance_ = None

    def _prior(self, z0):
        D = self._model.dim
        x0 = np.zeros(D)
        x0[:3] = self.gls_weights_ @ z0
        P0 = np.zeros((D, D))
        P0[:3, :3] = PRIOR_RATE_VARIANCE_FACTOR * np.max(np.diag(self._model.R)) * np.eye(3)
        return x0, P0

    def smooth(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Filtered and smoothed states (n, D) [rad/s] of checked readings z (n, N).

        Raises
        ------
        InputError
            A one-step prediction P_{k|k-1} that is not positive definite:
            a gyro without rate random walk (Q_b singular), where the RTS
            gain P_k (P_k + Q)⁻¹ does not exist.
        """
        z = np.ascontiguousarray(z, dtype=float)
        xs = np.empty((z.shape[0], self._model.dim))
        xsm = np.empty_like(xs)
        self._run(z, xs, xsm)
        return xs, xsm

    def _run(self, z: np.ndarray, xs: np.ndarray, xsm: np.ndarray) -> None:
        """Forward and backward kernels; ``xsm`` may be ``xs`` (smoothed in place)."""
        mdl = self._model
        n, D, p = z.shape[0], mdl.dim, mdl.p
        if not (mdl.bias and np.array_equal(mdl.F, np.eye(D))
                and np.array_equal(mdl.H1[:, p:], np.eye(D - p))):  # pragma: no cover - invariant
            raise RuntimeError("bound: the kernels need F = I and H1 = [H I]")
        x0, P0 = self._prior(z[0])
        hr = np.ascontiguousarray(mdl.H1[:, :p])
        lfac = np.empty((max(n - 1, 0), D * (D + 1) // 2))       # packed factor of P_{k+1|k}
        k = _bound_kernels.forward(z, x0, P0, hr, mdl.R, mdl.Q, xs, lfac)
        if k >= 0:
            raise InputError(f"bound: the predicted covariance is not positive definite at sample "
                             f"{k}: the RTS smoother gain P (P + Q)⁻¹ needs a rate random walk "
                             f"({baseline_effect('walk').name!r} > 0) on every gyro, with a positive "
                             "definite RRW correlation")
        _bound_kernels.backward(xs, lfac, mdl.Q, xsm)

    def _estimate(self, z):
        xs = np.empty((z.shape[0], self._model.dim))
        self._run(z, xs, xs)                                         # smoothed in place
        return np.ascontiguousarray(xs[:, :self._model.p])


def smooth_reference(model, x0: np.ndarray, P0: np.ndarray, z: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The former numpy loop (one ``kf_step`` and one D×D solve per sample,
    n·D² doubles of stored gains), kept only as the reference of the kernels
    in tests/test_bound_kernels.py and benchmarks/bench_estimators.py.
    Filtered and smoothed states (n, D) [rad/s]."""
    F, H, Q, R = model.F, model.H1, model.Q, model.R
    n, D = z.shape[0], model.dim
    x, P = x0, P0
    xs = np.empty((n, D))
    cs = np.empty((n, D, D))
    for k in range(n):
        x, P, _, _ = kf_step(x, P, z[k], F, H, Q, R)
        xs[k] = x
        cs[k] = np.linalg.solve(F @ P @ F.T + Q, F @ P).T              # C = P F' (F P F' + Q)⁻¹
    xsm = xs.copy()
    for k in range(n - 2, -1, -1):
        xsm[k] = xs[k] + cs[k] @ (xsm[k + 1] - F @ xs[k])             # x_s = x + C (x_s⁺ − F x)
    return xs, xsm


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
