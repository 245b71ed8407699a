"""``svo``: variance-optimal static weights for one averaging time (issue 31, item 3a).

A static estimator ω̂_k = M z_k (3×N, M H = I: unity gain on the body rate) gives axis a
the Allan variance σ²_a(τ) = m_aᵀ A(τ) m_a, where A(τ) is the gyros' *Allan covariance* at
τ: A_ij(τ) = ½ E[(ȳ_i,k+1 − ȳ_i,k)(ȳ_j,k+1 − ȳ_j,k)], ȳ the τ-averages (its diagonal is
each gyro's Allan variance). The weights that minimise every axis's Allan variance at τ
under M H = I are the generalised least squares with A(τ) as the weight:

    M(τ) = (Hᵀ A(τ)⁻¹ H)⁻¹ Hᵀ A(τ)⁻¹,   σ²(τ) = diag((Hᵀ A(τ)⁻¹ H)⁻¹)

(a "virtual gyro" for a chosen τ: Vaccaro & Zaki; synimu's SVO). From the noise model,
A(τ) = D_N C_arw D_N / τ + D_K C_rrw D_K τ / 3, D_N = diag(N_i), D_K = diag(K_i), the white
and walk correlations C (:class:`~gyroarray.estimators.noise.ArrayNoise`). With white noise
alone A(τ) ∝ R and ``svo`` is ``gls``. With gyros whose slow noise ranks them differently
from their white noise (MIMU4444), the weights differ and ``svo`` wins at τ where the
slow noise matters. It gives up some of the white-noise level at short τ in return.

``allan_covariance`` (N×N [rad²/s²] at ``tau_s``) replaces the model's A(τ). Use it for an
Allan covariance measured on the record (:func:`allan_covariance`).
"""

from __future__ import annotations

import math

import numpy as np

from gyroarray.core.errors import InputError
from gyroarray.estimators.base import register
from gyroarray.estimators.kf_array import gls_weights
from gyroarray.estimators.simple import GLS

__all__ = ["SVO", "model_allan_covariance", "allan_covariance"]


def model_allan_covariance(noise, tau_s: float) -> np.ndarray:
    """A(τ) = D_N C_arw D_N / τ + D_K C_rrw D_K τ / 3 [rad²/s²] of an ArrayNoise."""
    n, k = noise.arw_rad_rt_s, noise.rrw_rad_s_rt_s
    return noise.corr_arw * np.outer(n, n) / tau_s + noise.corr_rrw * np.outer(k, k) * tau_s / 3.0


def allan_covariance(x, m: int) -> np.ndarray:
    """Overlapping Allan covariance of the columns of x (n, N) at averaging factor m.

    A_ij = Σ_t d_i(t) d_j(t) / (2 m² (n + 1 − 2m)), d the second difference of the
    cumulative sums at lag m (its diagonal is :func:`gyroarray.analysis.allan.oadev`²) [unit
    of x squared].
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[0]
    if not 1 <= m <= n // 2:
        raise InputError(f"averaging factor {m} needs at least {2 * m} samples, got {n}")
    phase = np.zeros((n + 1, x.shape[1]))
    np.cumsum(x - x.mean(axis=0), axis=0, out=phase[1:])
    d = phase[2 * m:] - 2.0 * phase[m:n + 1 - m] + phase[:n + 1 - 2 * m]
    return d.T @ d / (2.0 * m * m * (n + 1 - 2 * m))


@register("svo")
class SVO(GLS):
    """Variance-optimal static weights for averaging time ``tau_s`` (module docstring).

    Parameters
    ----------
    tau_s : float
        Averaging time [s] whose Allan variance the weights minimise (default 1 s).
    allan_covariance : array_like (N, N), optional
        Allan covariance of the gyros at ``tau_s`` [rad²/s²] (e.g. measured); default: from
        the noise model's ARW, RRW and correlations.
    lowpass_hz : float or None
        The comparison low-pass of ``gls`` [Hz].

    Attributes
    ----------
    weights_ : ndarray, shape (3, N)
        M(τ) [-].
    covariance_ : ndarray, shape (3, 3)
        M R Mᵀ [rad²/s²]: the per-sample white-noise covariance with these weights.
    allan_variance_ : ndarray, shape (3,)
        Predicted Allan variance of each fused axis at ``tau_s`` [rad²/s²].
    """

    description = "variance-optimal static weights for one averaging time tau_s (GLS on the Allan covariance)"
    _design_tags = {"weights": None}            # its own weights: read from the fitted filter

    def __init__(self, *, tau_s=1.0, allan_covariance=None, lowpass_hz=None):
        self.tau_s = tau_s
        self.allan_covariance = allan_covariance
        self.lowpass_hz = lowpass_hz

    def _fit(self, H, noise, dt_s):
        try:
            tau = float(self.tau_s)
        except (TypeError, ValueError):
            raise InputError(f"tau_s must be a number [s], got {self.tau_s!r}") from None
        if not (math.isfinite(tau) and tau >= dt_s):
            raise InputError(f"tau_s must be finite and at least the sample period {dt_s:g} s, got {self.tau_s!r}")
        n = H.shape[0]
        if self.allan_covariance is None:
            a = model_allan_covariance(noise, tau)
        else:
            a = np.array(self.allan_covariance, dtype=float)
            if a.shape != (n, n) or not np.all(np.isfinite(a)):
                raise InputError(f"allan_covariance must be a finite {n}x{n} matrix [rad²/s²]")
            a = 0.5 * (a + a.T)
        try:
            np.linalg.cholesky(a)
        except np.linalg.LinAlgError:
            raise InputError(f"the Allan covariance at tau = {tau:g} s is not positive definite: "
                             "no variance-optimal weights; use gls or leave the gyros that repeat "
                             "another's noise out") from None
        self._a = a
        super()._fit(H, noise, dt_s)
        m = np.array(self.weights_)
        self.allan_variance_ = np.einsum("ai,ij,aj->a", m, a, m)

    def _weights(self, H, R):
        return gls_weights(H, self._a)[0]
