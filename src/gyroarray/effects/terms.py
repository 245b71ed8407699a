"""What an effect contributes to the design predictor: its declared term.

An effect declares its part of the analytic predictor
(:mod:`gyroarray.design.predict`, :mod:`gyroarray.design.budget`) and of the
estimators' noise (:func:`gyroarray.estimators.noise.array_noise`) with
:meth:`Effect.predictor_term(act, n_gyros) <gyroarray.effects.protocol.Effect.predictor_term>`,
which returns one of the terms below (or None: the predictor leaves the
effect out and lists it in ``ignored``). Nothing outside the effect names it:
the predictor and the estimators ask each entry of a model for its term.

Every per-gyro array has one row per gyro of the array (length N); a gyro
the effect's entries do not cover is NaN there (it contributes nothing).
Units are SI.

Stochastic terms (the exact moments of :func:`gyroarray.design.predict.error_moments`
and :func:`~gyroarray.design.predict.flicker_moments`):

* :class:`WhiteTerm`: white rate noise of density N_i [rad/√s]; one sample
  has variance N_i²/dt [rad²/s²] (the angle random walk convention:
  R = C ∘ (σ σᵀ), σ = N/√dt, C the white correlation of
  :class:`CorrelationTerm`, the identity without one);
* :class:`WalkTerm`: a rate random walk of coefficient K_i [rad/s/√s]; one
  increment over dt has variance K_i²·dt (Q_b = C ∘ (s sᵀ), s = K√dt);
* :class:`FlickerTerm`: flicker (1/f) rate noise of coefficient B_i [rad/s]
  (the simulator's circular process, ADEV floor 0.664·B), independent
  between gyros;
* :class:`GaussMarkovTerm`: first-order Gauss–Markov rate noise, stationary
  σ_i [rad/s] and correlation time τ_i [s], independent between gyros.

Modifiers (no error of their own):

* :class:`CorrelationTerm`: the N×N correlation matrices of the white and
  of the random-walk terms (every :class:`WhiteTerm`/:class:`WalkTerm` is
  correlated by it);
* :class:`SensorFilter`: the gyros' own low-pass (cut-off [Hz], order 1 or
  2), which every reading passes before the estimator.

Deterministic terms: :class:`DeterministicTerm` gives, for a stated motion
(:class:`Motion`: the true body rate ω(t), the specific force f(t) at each
gyro, a temperature swing ΔT(t)), the rate error [rad/s] (n × N) the effect
adds to each gyro's reading; the predictor propagates it through the
(linear) estimator. Built-in forms: :class:`ScaleTerm` (s_i·h_i·ω),
:class:`AxisTerm` ((a_i − h_i)·ω, a_i the true axis), :class:`ForceTerm`
(k_i·f_i), :class:`TemperatureTerm` (c_i·ΔT); a plugin returns a
:class:`FunctionTerm` or its own subclass.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

import numpy as np

from gyroarray.core.constants import G0_M_S2
from gyroarray.core.errors import InputError
from gyroarray.core.physics import tilted_axes

__all__ = ["PredictorTerm", "WhiteTerm", "WalkTerm", "FlickerTerm", "GaussMarkovTerm", "CorrelationTerm",
           "SensorFilter", "Motion", "DeterministicTerm", "ScaleTerm", "AxisTerm", "ForceTerm",
           "TemperatureTerm", "LineTerm", "FunctionTerm", "spread"]


def spread(act, key: str, n_gyros: int, shape: tuple[int, ...] = ()) -> np.ndarray:
    """One SI parameter of a resolved entry (:class:`~gyroarray.effects.protocol.Active`) on every
    gyro of the array: shape (N,) + ``shape``, NaN on the gyros its entries do not cover.

    Parameters
    ----------
    act : Active
        ``act.p[key]`` holds one value per gyro of ``act.cols`` (a per-gyro effect) or one
        value for all (an array-wide effect).
    key : str
        The parameter's ``Param.si_name``.
    n_gyros : int
    shape : tuple of int
        Shape of one gyro's value (``(3,)`` for a vector).
    """
    out = np.full((int(n_gyros),) + tuple(shape), np.nan)
    v = np.asarray(act.p[key], dtype=float)
    cols = np.asarray(act.cols, dtype=int)
    out[cols] = v if v.ndim > len(shape) else np.broadcast_to(v, (cols.size,) + tuple(shape))
    return out


class PredictorTerm:
    """Base of every declared term. ``source``: the predictor's name of the noise source
    (the key of ``mean_square_by_source``), or the role of a modifier."""

    source: ClassVar[str] = ""


@dataclass(frozen=True, eq=False)
class WhiteTerm(PredictorTerm):
    """White rate noise: density N_i [rad/√s] per gyro (NaN: none); per sample N_i²/dt [rad²/s²]."""

    n_rad_rt_s: np.ndarray
    source: ClassVar[str] = "white"


@dataclass(frozen=True, eq=False)
class WalkTerm(PredictorTerm):
    """Rate random walk: K_i [rad/s/√s] per gyro (NaN: none); increments K_i²·dt [rad²/s²]."""

    k_rad_s_rt_s: np.ndarray
    source: ClassVar[str] = "walk"


@dataclass(frozen=True, eq=False)
class FlickerTerm(PredictorTerm):
    """Flicker (bias instability) noise: B_i [rad/s] per gyro (NaN: none)."""

    b_rad_s: np.ndarray
    source: ClassVar[str] = "flicker"


@dataclass(frozen=True, eq=False)
class GaussMarkovTerm(PredictorTerm):
    """First-order Gauss–Markov noise: stationary σ_i [rad/s] and τ_i [s] per gyro (NaN: none)."""

    sigma_rad_s: np.ndarray
    tau_s: np.ndarray
    source: ClassVar[str] = "gauss_markov"


@dataclass(frozen=True, eq=False)
class CorrelationTerm(PredictorTerm):
    """Correlation between gyros of the white and random-walk terms: N×N matrices [-]
    (None: independent)."""

    white: np.ndarray | None = None
    walk: np.ndarray | None = None
    source: ClassVar[str] = "correlation"


@dataclass(frozen=True, eq=False)
class SensorFilter(PredictorTerm):
    """The gyros' own low-pass: −3 dB frequency [Hz] (NaN: no filter) and order (1, 2; NaN: none)."""

    cutoff_hz: np.ndarray
    order: np.ndarray
    source: ClassVar[str] = "sensor"


@dataclass(frozen=True, eq=False)
class Motion:
    """The motion a deterministic term is evaluated on (SI).

    Attributes
    ----------
    omega_rad_s : ndarray (n, 3) or None
        True body rate, platform frame [rad/s]; None: at rest.
    specific_force_m_s2 : ndarray (n, N, 3), (3,), or None
        Specific force at each gyro, platform frame [m/s²]; (3,): the same at
        every gyro and sample; None: level at rest, [0, 0, g0].
    temp_swing_k : ndarray (n,), float, or None
        Departure of the temperature from the one the biases were calibrated
        at [K] (a temperature coefficient's error is c·ΔT); None: not stated
        (a temperature term is then left out and listed as ignored).
    axes : ndarray (N, 3) or None
        Nominal unit sensitive axes (set by :meth:`resolved`).
    time_s : ndarray (n,) or None
        Sample times from 0 [s] (set by :meth:`resolved`).
    """

    omega_rad_s: np.ndarray | None = None
    specific_force_m_s2: np.ndarray | None = None
    temp_swing_k: Any = None
    axes: np.ndarray | None = None
    time_s: np.ndarray | None = None

    def resolved(self, n: int, dt_s: float, axes: np.ndarray) -> "Motion":
        """Every field at full shape for a run of ``n`` samples of step ``dt_s`` [s] on ``axes``.

        Raises
        ------
        InputError
            A field of the wrong shape.
        """
        H = np.asarray(axes, dtype=float)
        N = H.shape[0]
        w = np.zeros((n, 3)) if self.omega_rad_s is None else np.asarray(self.omega_rad_s, dtype=float)
        if w.shape != (n, 3):
            raise InputError(f"the motion's rate must have shape ({n}, 3), got {w.shape}")
        f = np.array([0.0, 0.0, G0_M_S2]) if self.specific_force_m_s2 is None else \
            np.asarray(self.specific_force_m_s2, dtype=float)
        if f.shape == (3,):
            f = np.broadcast_to(f, (n, N, 3))
        if f.shape != (n, N, 3):
            raise InputError(f"the motion's specific force must have shape ({n}, {N}, 3) or (3,), got {f.shape}")
        temp = None
        if self.temp_swing_k is not None:
            temp = np.broadcast_to(np.asarray(self.temp_swing_k, dtype=float), (n,))
        return Motion(omega_rad_s=w, specific_force_m_s2=f, temp_swing_k=temp, axes=H,
                      time_s=np.arange(n) * float(dt_s))


class DeterministicTerm(PredictorTerm):
    """A deterministic rate error of each gyro for a stated motion.

    Subclasses write :meth:`rate_error`; ``needs`` names what of the motion it
    reads (for the message when it is left out).
    """

    source: ClassVar[str] = "motion"
    needs: ClassVar[str] = "the motion"

    def rate_error(self, motion: Motion) -> np.ndarray | None:
        """The error (n, N) [rad/s] added to each gyro's reading on a :meth:`Motion.resolved`
        motion; None: the motion does not state what it needs."""
        raise NotImplementedError


@dataclass(frozen=True, eq=False)
class ScaleTerm(DeterministicTerm):
    """Scale-factor error: e_i = s_i·(h_i·ω), s_i [-] per gyro (NaN: none)."""

    ratio: np.ndarray
    needs: ClassVar[str] = "the body rate"

    def rate_error(self, motion):
        return motion.omega_rad_s @ motion.axes.T * np.nan_to_num(self.ratio)


@dataclass(frozen=True, eq=False)
class AxisTerm(DeterministicTerm):
    """Misaligned sensitive axes: e_i = (a_i − h_i)·ω, a_i the true unit axis.

    Per gyro either ``axis`` (the true unit axis, (N, 3)) or ``tilt_rad`` θ and
    ``azimuth_rad`` ψ (:func:`gyroarray.core.physics.tilted_axes` of the nominal
    axis); NaN everywhere: the nominal axis.
    """

    axis: np.ndarray
    tilt_rad: np.ndarray
    azimuth_rad: np.ndarray
    needs: ClassVar[str] = "the body rate"

    def true_axes(self, nominal: np.ndarray) -> np.ndarray:
        """The true unit axes (N, 3) of gyros whose nominal axes are ``nominal``."""
        h = np.asarray(nominal, dtype=float)
        tilted = tilted_axes(h, np.nan_to_num(self.tilt_rad), np.nan_to_num(self.azimuth_rad))
        a = np.asarray(self.axis, dtype=float)
        return np.where(np.isnan(a).any(axis=1, keepdims=True), tilted, a)

    def rate_error(self, motion):
        return motion.omega_rad_s @ (self.true_axes(motion.axes) - motion.axes).T


@dataclass(frozen=True, eq=False)
class ForceTerm(DeterministicTerm):
    """g-sensitivity: e_i = k_i·f_i, k_i (N, 3) [(rad/s)/(m/s²)] (NaN rows: none).

    ``key``: the name the predictor reports its per-gyro share under."""

    coeff_rad_s_per_m_s2: np.ndarray
    needs: ClassVar[str] = "the specific force"
    key: ClassVar[str] = "g_sensitivity"

    def rate_error(self, motion):
        k = np.nan_to_num(np.asarray(self.coeff_rad_s_per_m_s2, dtype=float))
        return np.einsum("nkj,kj->nk", motion.specific_force_m_s2, k)


@dataclass(frozen=True, eq=False)
class TemperatureTerm(DeterministicTerm):
    """Temperature coefficient: e_i = c_i·ΔT(t), c_i [rad/s/K] per gyro (NaN: none)."""

    coeff_rad_s_per_k: np.ndarray
    needs: ClassVar[str] = "a temperature swing"

    def rate_error(self, motion):
        if motion.temp_swing_k is None:
            return None
        return np.asarray(motion.temp_swing_k, dtype=float)[:, None] * np.nan_to_num(self.coeff_rad_s_per_k)


@dataclass(frozen=True, eq=False)
class LineTerm(DeterministicTerm):
    """A spectral line on each gyro: e_i = A_i·sin(2π f_i t + φ_i), A_i [rad/s], f_i [Hz],
    φ_i [rad] per gyro (NaN: none), on the motion's sample times.

    Exact for a fixed line (its stated phase). A line whose phase wanders (a narrowband
    process) is given its centre frequency and phase 0: over a window of many periods the
    mean square of a sinusoid through a linear filter, A²·|T(f)|²/2, does not depend on its
    phase, and the line's width is taken as narrow beside the filter's features (|T| flat
    over it); its cross terms with the other deterministic errors are then those of one
    phase, not their average (zero) — small unless another error has the line's frequency —
    and its angle error (the integral, bounded by A·|T(f)|/(π f)) is that of phase 0, not
    the average over phases.
    """

    amp_rad_s: np.ndarray
    freq_hz: np.ndarray
    phase_rad: np.ndarray
    needs: ClassVar[str] = "the sample times"

    def rate_error(self, motion):
        t = np.asarray(motion.time_s, dtype=float)[:, None]
        amp = np.nan_to_num(self.amp_rad_s)
        return amp * np.sin(2.0 * np.pi * np.nan_to_num(self.freq_hz) * t
                            + np.nan_to_num(self.phase_rad))


@dataclass(frozen=True, eq=False)
class FunctionTerm(DeterministicTerm):
    """A deterministic error given as a function ``fn(motion) -> (n, N) [rad/s] or None``
    (for a plugin's own effect)."""

    fn: Callable[[Motion], np.ndarray | None]

    def rate_error(self, motion):
        return self.fn(motion)


def root_sum_square(values: list[np.ndarray]) -> np.ndarray:
    """Per-gyro levels of independent terms combined: √Σ v² (NaN where none has one); one term
    as is (bit for bit)."""
    if len(values) == 1:
        return np.asarray(values[0], dtype=float)
    a = np.stack([np.asarray(v, dtype=float) for v in values])
    out = np.sqrt(np.nansum(a ** 2, axis=0))
    out[np.all(np.isnan(a), axis=0)] = math.nan
    return out
