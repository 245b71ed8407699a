"""The part of a noise model the estimators design with: ARW, RRW, correlation.

A :class:`~gyroarray.effects.model.NoiseModel` lists effect entries in the
spec's units; :func:`array_noise` reduces it to per-gyro white-noise and
random-walk levels in SI and the two N×N correlation matrices, exactly as
the simulator draws them (``src/gyroarray/sim/effects.py``): ARW is white with
σ = N/√dt per sample, RRW increments have σ = K√dt, and the ``correlation``
entry gives Σ_ij = C_ij σ_i σ_j for both.

Only ``arw``, ``rrw`` and ``correlation`` are used; the names of the other
effects of the model are kept in :attr:`ArrayNoise.ignored_effects` so a
report can say what the estimators did not model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gyroarray.core.gdop import correlation_matrix
from gyroarray.core.errors import InputError

__all__ = ["ArrayNoise", "array_noise"]

_USED = ("arw", "rrw", "correlation")


def _frozen(a, shape) -> np.ndarray:
    out = np.array(a, dtype=float, copy=True)
    if out.shape != shape:
        raise InputError(f"expected shape {shape}, got {out.shape}")
    if not np.all(np.isfinite(out)):
        raise InputError("noise parameters must be finite")
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class ArrayNoise:
    """White and random-walk noise of an N-gyro array, in SI.

    Parameters
    ----------
    arw_rad_rt_s : ndarray, shape (N,)
        Angle random walk N_i of each gyro [rad/√s] (> 0).
    rrw_rad_s_rt_s : ndarray, shape (N,)
        Rate random walk K_i of each gyro [rad/s/√s] (>= 0).
    corr_arw : ndarray, shape (N, N)
        Correlation matrix of the ARW noise [-] (positive definite).
    corr_rrw : ndarray, shape (N, N)
        Correlation matrix of the RRW increments [-] (positive semi-definite).
    ignored_effects : tuple of str
        Effects of the source model that the estimators do not model.
    zero_arw_ok : bool, default False
        True: an ARW of 0 is accepted (R is then singular): only for the
        estimators that use the layout alone (``ols``, ``naive``).
    """

    arw_rad_rt_s: np.ndarray
    rrw_rad_s_rt_s: np.ndarray
    corr_arw: np.ndarray
    corr_rrw: np.ndarray
    ignored_effects: tuple[str, ...] = ()
    zero_arw_ok: bool = False

    def __post_init__(self):
        n = np.size(self.arw_rad_rt_s)
        object.__setattr__(self, "arw_rad_rt_s", _frozen(self.arw_rad_rt_s, (n,)))
        object.__setattr__(self, "rrw_rad_s_rt_s", _frozen(self.rrw_rad_s_rt_s, (n,)))
        object.__setattr__(self, "corr_arw", _frozen(self.corr_arw, (n, n)))
        object.__setattr__(self, "corr_rrw", _frozen(self.corr_rrw, (n, n)))
        object.__setattr__(self, "ignored_effects", tuple(self.ignored_effects))
        if np.any(self.arw_rad_rt_s < 0) or (np.any(self.arw_rad_rt_s == 0) and not self.zero_arw_ok):
            raise InputError("every gyro needs a positive angle random walk: the estimators "
                             "weight the gyros by their white noise")
        if np.any(self.rrw_rad_s_rt_s < 0):
            raise InputError("rate random walk must be >= 0")
        try:
            np.linalg.cholesky(self.corr_arw)
        except np.linalg.LinAlgError:
            raise InputError("the ARW correlation matrix is not positive definite: the "
                             "measurement noise covariance R would be singular") from None

    def __eq__(self, other) -> bool:
        if not isinstance(other, ArrayNoise):
            return NotImplemented
        return (self.ignored_effects == other.ignored_effects
                and all(np.array_equal(getattr(self, k), getattr(other, k))
                        for k in ("arw_rad_rt_s", "rrw_rad_s_rt_s", "corr_arw", "corr_rrw")))

    __hash__ = None  # type: ignore[assignment]

    @property
    def n_gyros(self) -> int:
        """Number of gyros N."""
        return int(self.arw_rad_rt_s.size)

    @classmethod
    def identical(cls, n_gyros: int, arw_rad_rt_s: float, rrw_rad_s_rt_s: float = 0.0,
                  rho_arw: float = 0.0, rho_rrw: float = 0.0) -> "ArrayNoise":
        """N gyros with equal noise and equicorrelation ρ (SI units)."""
        eye, one = np.eye(n_gyros), np.ones((n_gyros, n_gyros))
        return cls(np.full(n_gyros, float(arw_rad_rt_s)), np.full(n_gyros, float(rrw_rad_s_rt_s)),
                   (1 - rho_arw) * eye + rho_arw * one, (1 - rho_rrw) * eye + rho_rrw * one)

    def R(self, dt_s: float) -> np.ndarray:
        """Covariance of one sample of the white measurement noise [rad²/s²].

        Σ_ij = C_ij σ_i σ_j with σ_i = N_i/√dt.
        """
        s = self.arw_rad_rt_s / np.sqrt(dt_s)
        return self.corr_arw * np.outer(s, s)

    def Qb(self, dt_s: float) -> np.ndarray:
        """Covariance of one bias increment (RRW over one sample) [rad²/s²].

        Σ_ij = C_ij s_i s_j with s_i = K_i √dt.
        """
        s = self.rrw_rad_s_rt_s * np.sqrt(dt_s)
        return self.corr_rrw * np.outer(s, s)


def per_gyro(model, effect: str, key: str, n_gyros: int) -> np.ndarray:
    """Per-gyro SI value of a per-gyro effect (NaN where absent); gyro=k overrides all."""
    out = np.full(n_gyros, np.nan)
    for e in model.entries:
        if e.effect == effect and e.gyro is None:
            out[:] = e.si_params[key]
    for e in model.entries:
        if e.effect == effect and e.gyro is not None:
            out[e.gyro - 1] = e.si_params[key]
    return out


def _corr(rho, n: int, common_mode: bool, what: str) -> np.ndarray:
    if np.ndim(rho) == 0 and common_mode:
        r = float(rho)                       # e_k = √ρ c + √(1−ρ) z_k: same law, ρ = 1 allowed
        return (1.0 - r) * np.eye(n) + r * np.ones((n, n))
    try:
        return correlation_matrix(n, rho)
    except InputError as err:
        raise InputError(f"correlation {what}: {err.message}") from None


def array_noise(noise_model, n_gyros: int, require_arw: bool = True) -> ArrayNoise:
    """The ARW/RRW/correlation part of a noise model for an N-gyro array.

    Parameters
    ----------
    noise_model : NoiseModel
        Entries in the spec's units; an entry with ``gyro = k`` overrides the
        all-gyros entry of the same effect for gyro k.
    n_gyros : int
        Number of gyros N.
    require_arw : bool, default True
        False: a gyro without ``arw`` (or with ``arw = 0``) gets a white-noise
        level of 0 [rad/√s] instead of a refusal (estimators that only use the
        layout, :attr:`~gyroarray.estimators.base.Estimator.needs_arw`).

    Returns
    -------
    ArrayNoise

    Raises
    ------
    InputError
        The model fails :meth:`NoiseModel.check`, a gyro has no ``arw`` (the
        estimators weight the gyros by their white noise), an ``arw`` of zero,
        or an ARW correlation whose covariance is singular (``common_mode``
        with ρ = 1: every gyro sees the same white noise).
    """
    from gyroarray.effects.model import NoiseModel  # lazy: loads gyroarray.effects and its plugins
    if not isinstance(noise_model, NoiseModel):
        raise InputError(f"noise_model must be a NoiseModel, got {type(noise_model).__name__}")
    noise_model.check(n_gyros)
    arw = per_gyro(noise_model, "arw", "n_rad_rt_s", n_gyros)
    missing = np.flatnonzero(np.isnan(arw)) + 1
    if not require_arw:
        arw = np.nan_to_num(arw, nan=0.0)
    elif missing.size:
        raise InputError(
            f"the noise model has no angle random walk ('arw') for gyro(s) "
            f"{', '.join(map(str, missing))}: the estimators need the white-noise level of every "
            "gyro; add e.g. {effect = \"arw\", n_deg_rt_h = 0.1}")
    zero = np.flatnonzero(arw <= 0) + 1
    if zero.size and require_arw:
        raise InputError(f"arw is 0 on gyro(s) {', '.join(map(str, zero))}: the estimators need a "
                         "positive white-noise level on every gyro (R must be positive definite)")
    rrw = np.nan_to_num(per_gyro(noise_model, "rrw", "k_rad_s_rt_s", n_gyros), nan=0.0)
    corr = [e for e in noise_model.entries if e.effect == "correlation"]
    c_arw = c_rrw = np.eye(n_gyros)
    if corr:
        p = corr[0].si_params
        cm = bool(p["common_mode"])
        if cm and np.ndim(p["rho_arw"]) == 0 and float(p["rho_arw"]) == 1.0:
            raise InputError("correlation: rho_arw = 1 with common_mode makes every gyro see the "
                             "same white noise: the measurement covariance R is singular and no "
                             "estimator here is defined; use rho_arw < 1")
        c_arw = _corr(p["rho_arw"], n_gyros, cm, "rho_arw")
        c_rrw = _corr(p["rho_rrw"], n_gyros, cm, "rho_rrw")
    ignored = tuple(sorted({e.effect for e in noise_model.entries} - set(_USED)))
    return ArrayNoise(arw, rrw, c_arw, c_rrw, ignored, zero_arw_ok=not require_arw)
