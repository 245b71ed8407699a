"""Per-sample linear estimators: ``ols``, ``gls`` and ``naive``.

Each maps one sample of readings to a body rate with a fixed 3×N matrix M,
ω̂_k = M z_k (one matrix product for the whole record). ``ols`` and ``gls``
can follow it with the comparison low-pass (``lowpass_hz``).

The comparison low-pass is the first-order IIR y_k = a y_{k-1} + (1 − a) x_k
per axis, with a set so its −3 dB point is at ``lowpass_hz`` (exactly, in
discrete time: :func:`gyroarray.estimators.kalman.lowpass_pole`). It is the
KF's own rate channel: the KF without bias states is exactly GLS followed by
x̂_k = A x̂_{k-1} + (I − A) ω̂_GLS,k (K = (I − A)·G), which is this filter per
axis when HᵀR⁻¹H is isotropic. So ``gls`` at ``lowpass_hz = f`` and a KF
at ``bandwidth_hz = f`` differ only by the KF's model, not by the filter
shape. It starts in steady state on the first estimate.
"""

from __future__ import annotations

import math

import numpy as np

from gyroarray.core.errors import InputError

from gyroarray.estimators.kalman import first_order_lowpass, lowpass_pole
from gyroarray.estimators.base import Estimator, LinearSystem, readonly, register
from gyroarray.estimators.kf_array import gls_weights

__all__ = ["OLS", "GLS", "Naive"]


class _PerSample(Estimator):
    """ω̂_k = M z_k, optionally low-passed; subclasses give M and its covariance."""

    def _weights(self, H, R) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _fit(self, H, noise, dt_s):
        R = noise.R(dt_s)
        m = self._weights(H, R)
        cov = m @ R @ m.T                                            # cov(M v) = M R Mᵀ
        f = getattr(self, "lowpass_hz", None)
        if f is not None:
            try:
                f = float(f)
            except (TypeError, ValueError):
                raise InputError(f"lowpass_hz must be a number [Hz] or None, got {f!r}") from None
            if not (math.isfinite(f) and 0 < f < 0.5 / dt_s):
                raise InputError(f"lowpass_hz must be in (0, Nyquist = {0.5 / dt_s:g}) Hz, "
                                 f"got {self.lowpass_hz!r}")
            a = lowpass_pole(f, dt_s)
            cov = cov * (1.0 - a) / (1.0 + a)                        # Σ h_k² of (1−a) a^k
        self._lowpass = f
        self.weights_ = readonly(m)
        self.covariance_ = readonly(0.5 * (cov + cov.T))

    def linear_system(self) -> LinearSystem:
        """ω̂_k = M z_k (A = 0), or with the low-pass y_k = a y_{k-1} + (1 − a) M z_k, y_{-1} = M z_0."""
        self._check_fitted()
        m, eye = np.array(self.weights_), np.eye(3)
        if self._lowpass is None:
            return LinearSystem(A=np.zeros((3, 3)), K=m, C=eye, X0=np.zeros_like(m),
                                lam=np.zeros(3), S=eye, S_inv=eye)
        a = lowpass_pole(self._lowpass, self.dt_s_)
        return LinearSystem(A=a * eye, K=(1.0 - a) * m, C=eye, X0=m, lam=np.full(3, a),
                            S=eye, S_inv=eye)

    def _estimate(self, z):
        w = z @ self.weights_.T                                      # ω̂_k = M z_k
        if self._lowpass is not None:
            w = first_order_lowpass(w, self._lowpass, self.dt_s_)
        return np.ascontiguousarray(w)


@register("ols")
class OLS(_PerSample):
    """Ordinary least squares per sample, ω̂ = (HᵀH)⁻¹Hᵀ z.

    Parameters
    ----------
    lowpass_hz : float or None
        −3 dB frequency of the comparison low-pass [Hz] (module docstring);
        None: none.

    Attributes
    ----------
    weights_ : ndarray, shape (3, N)
        M = (HᵀH)⁻¹Hᵀ [-].
    covariance_ : ndarray, shape (3, 3)
        M R Mᵀ [rad²/s²] (times the low-pass noise gain (1 − a)/(1 + a)).
    """

    description = "ordinary least squares per sample (pseudo-inverse of H)"
    needs_arw = False                    # M = pinv(H): no noise model needed
    _design_tags = {"weights": "ols", "bandwidth_param": "lowpass_hz", "bandwidth_optional": True,
                    "channel_filter": "lowpass"}

    def __init__(self, *, lowpass_hz=None):
        self.lowpass_hz = lowpass_hz

    def _weights(self, H, R):
        return np.linalg.pinv(H)


@register("gls")
class GLS(_PerSample):
    """Generalized least squares per sample, weighted by the ARW covariance.

    ω̂ = (HᵀR⁻¹H)⁻¹HᵀR⁻¹ z, covariance (HᵀR⁻¹H)⁻¹: the Cramér–Rao bound of
    one sample under white Gaussian noise.

    Parameters
    ----------
    lowpass_hz : float or None
        −3 dB frequency of the comparison low-pass [Hz] (module docstring).

    Attributes
    ----------
    weights_ : ndarray, shape (3, N)
    covariance_ : ndarray, shape (3, 3)
        (HᵀR⁻¹H)⁻¹ [rad²/s²] (times the low-pass noise gain).

    References
    ----------
    Paper 003 Eq. 12 (GDOP = sqrt(trace((HᵀC⁻¹H)⁻¹))).
    """

    description = "generalized least squares per sample, weighted by the ARW covariance"
    _design_tags = {"weights": "gls", "bandwidth_param": "lowpass_hz", "bandwidth_optional": True,
                    "channel_filter": "lowpass"}

    def __init__(self, *, lowpass_hz=None):
        self.lowpass_hz = lowpass_hz

    def _weights(self, H, R):
        return gls_weights(H, R)[0]


@register("naive")
class Naive(_PerSample):
    """Mean of the back-projected readings, no noise model.

    Each axis a is the projection-weighted mean over the gyros,
    ω̂_a = Σ_k h_ka z_k / Σ_k h_ka²: every gyro's reading is pushed back
    along its axis, z_k h_k, and each axis is rescaled by how much of it the
    gyros see. It ignores the cross terms of HᵀH and the noise; it equals
    OLS when HᵀH is diagonal (every conical layout of gyroarray), and is
    biased otherwise.

    Attributes
    ----------
    weights_ : ndarray, shape (3, N)
        diag(Σ_k h_ka²)⁻¹ Hᵀ [-].
    covariance_ : ndarray, shape (3, 3)
        M R Mᵀ [rad²/s²].
    """

    description = "mean of the back-projected readings per axis (no model)"
    needs_arw = False
    _design_tags = {"weights": "naive"}

    def __init__(self):
        pass

    def _weights(self, H, R):
        return H.T / np.sum(H * H, axis=0)[:, None]
