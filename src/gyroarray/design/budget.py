"""The error budget of a design: each declared term's own share of the rate and angle error.

For a linear estimator (:class:`~gyroarray.estimators.base.LinearSystem`, as
:func:`gyroarray.design.predict.predict_system` takes it), the mounted axes H
and a noise model, :func:`error_budget` gives, per effect of the model that
declares a predictor term (:meth:`~gyroarray.effects.protocol.Effect.predictor_term`),
the error that effect alone causes in the fused rate:

* a stochastic term (white, random walk, flicker, Gauss–Markov noise): the
  exact moments of :mod:`gyroarray.design.predict` with only that source on
  (the correlation modifier and the sensor filter applied as for the total);
* a deterministic term (scale factor, misalignment, g-sensitivity, a
  temperature coefficient, a plugin's): the per-gyro rate error it declares
  for the stated :class:`~gyroarray.effects.terms.Motion`, propagated through
  the (linear) estimator, started as the estimator starts.

Each row holds the 3-axis RMS of the rate error about the truth over the
scored window, √E[(1/n_W) Σ_W |e_k|²] [deg/s], and the 3-axis RMS angle
error at the end of the run (the horizon), √E[|dt Σ_{k<n} e_k|²] [deg]. The
total has every source on at once: the squares of the rows add up to it when
the terms are independent of each other (every stochastic term is zero-mean
and independent of the others; deterministic terms add as signals, so their
cross products belong to the total only).

Effects that declare no term, or whose term the motion cannot evaluate (a
temperature coefficient without a temperature swing), are listed in
``ignored``; the modifiers (correlation, the gyros' own filter) in
``modifiers``. Nothing here names an effect.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import signal

from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.design.predict import (Moments, NoiseSources, Swing, cascade, deterministic_error, error_moments,
                                      flicker_moments, noise_sources, settle_start, swing_truth)
from gyroarray.effects.terms import (CorrelationTerm, DeterministicTerm, FlickerTerm, GaussMarkovTerm, Motion,
                                     SensorFilter, WalkTerm, WhiteTerm)

__all__ = ["ErrorBudget", "error_budget", "linear_response", "undetected_fault"]


@dataclass(frozen=True)
class ErrorBudget:
    """The error budget of one design (module docstring).

    Attributes
    ----------
    terms : dict
        Effect name -> {``rms_deg_s``: 3-axis RMS rate error about the truth over the scored
        window [deg/s], ``angle_deg``: 3-axis RMS angle error at the horizon [deg]}, in the
        model's order.
    total : dict
        The same with every term on (and the estimator's own tracking error).
    ignored : list of str
        Effects of the model the budget leaves out (no declared term, or the motion lacks
        what their term needs).
    modifiers : list of str
        Effects whose terms shape the others (a correlation, the gyros' own filter).
    tracking : dict or None
        The estimator's own error on the stated body rate (its lag), when the body moves.
    horizon_s : float
        Run length n·dt [s].
    settle_s : float
        Start-up left out of the RMS window [s].
    """

    terms: dict
    total: dict
    ignored: list = field(default_factory=list)
    modifiers: list = field(default_factory=list)
    tracking: dict | None = None
    horizon_s: float = 0.0
    settle_s: float = 0.0

    def largest(self, key: str = "angle_deg") -> str | None:
        """The term with the largest ``key`` (``angle_deg`` or ``rms_deg_s``); None without terms."""
        return max(self.terms, key=lambda k: self.terms[k][key]) if self.terms else None

    def to_dict(self) -> dict:
        """Plain dict for JSON (units in the keys)."""
        return {"terms": {k: dict(v) for k, v in self.terms.items()}, "total": dict(self.total),
                "tracking": None if self.tracking is None else dict(self.tracking),
                "ignored_effects": list(self.ignored), "modifiers": list(self.modifiers),
                "horizon_s": self.horizon_s, "settle_s": self.settle_s,
                "largest_angle_term": self.largest("angle_deg"),
                "largest_rms_term": self.largest("rms_deg_s")}


def linear_response(sys, z: np.ndarray) -> np.ndarray:
    """The estimate (n, 3) of a :class:`~gyroarray.estimators.base.LinearSystem` on readings z.

    x̂_k = A x̂_{k−1} + K z_k from x̂_{−1} = X0 z_0, ω̂_k = C x̂_k, run in its modal
    coordinates (m_k = λ m_{k−1} + S⁻¹K z_k, one first-order recursion per mode).

    Parameters
    ----------
    sys : LinearSystem
    z : ndarray (n, N)
        Readings [rad/s].

    Returns
    -------
    ndarray (n, 3)
        [rad/s].
    """
    z = np.asarray(z, dtype=float)
    bk = sys.S_inv @ sys.K                                           # (D, N)
    m0 = sys.S_inv @ (sys.X0 @ z[0])                                 # m_{-1}
    cs = sys.C @ sys.S                                               # (3, D)
    out = np.zeros((z.shape[0], cs.shape[0]), dtype=complex if np.iscomplexobj(sys.lam) else float)
    for i, lam in enumerate(np.asarray(sys.lam)):
        u = z @ bk[i]
        y, _ = signal.lfilter([1.0], [1.0, -lam], u, zi=[lam * m0[i]])
        out += np.outer(y, cs[:, i])
    return np.real(out)


def _row(ms_window: float, sum_full: float, dt: float) -> dict:
    """{rms_deg_s, angle_deg} of a mean square over the window [rad²/s²] and the angle's
    mean-square sum [rad²/s²·samples²]."""
    return {"rms_deg_s": float(units.rad_s_to_deg_s(math.sqrt(max(ms_window, 0.0)))),
            "angle_deg": float(units.rad_to_deg(dt * math.sqrt(max(sum_full, 0.0))))}


def _moment_row(m: Moments, dt: float) -> dict:
    return _row(float(np.trace(m.ms_window)), float(np.trace(m.sum_full)), dt)


def _signal_row(e: np.ndarray, k0: int, dt: float) -> dict:
    return _row(float(np.mean(np.sum(e[k0:] ** 2, axis=1))), float(np.sum(np.sum(e, axis=0) ** 2)), dt)


def _only(noise: NoiseSources, **kw) -> NoiseSources:
    """``noise`` with every stochastic source off but those in ``kw``."""
    N = noise.n_gyros
    off = NoiseSources(R=np.zeros((N, N)), Qb=np.zeros((N, N)), gm_sigma_rad_s=np.zeros(N),
                       gm_tau_s=np.ones(N), bi_rad_s=np.zeros(N), dt_s=noise.dt_s)
    return replace(off, **kw)


def error_budget(sys, H, noise_model, *, n_samples: int, dt_s: float, settle_s: float = 2.0,
                 motion: Motion | Swing | np.ndarray | None = None,
                 bi_correlation: np.ndarray | None = None, flicker_model: str = "circular") -> ErrorBudget:
    """The error budget of a linear estimator on an array: each declared term's share.

    Parameters
    ----------
    sys : LinearSystem
        The estimator alone (:meth:`~gyroarray.estimators.Estimator.linear_system`, or
        :func:`gyroarray.design.predict.channel_filter` per axis); the model's sensor filter
        is cascaded before it here.
    H : ndarray (N, 3)
        The mounted unit axes (signs included) [-].
    noise_model : NoiseModel
        The effects of the array (per-gyro parameters kept per gyro).
    n_samples : int
        Samples in the run; the horizon is n_samples·dt_s.
    dt_s : float
        Sample period [s].
    settle_s : float
        Start-up left out of the RMS window [s] (as the chain scores).
    motion : Motion, Swing or ndarray (n, 3), optional
        The stated motion the deterministic terms are evaluated on
        (:class:`~gyroarray.effects.terms.Motion`): the true body rate ω(t) (n, 3) [rad/s]
        (an array: that rate alone; a :class:`~gyroarray.design.predict.Swing`: a swing about
        every axis), the specific force at each gyro [m/s²] (default: level at rest, [0, 0, g0]),
        the temperature swing ΔT(t) [K] (default: not stated; a temperature term is then
        ignored). None: at rest, level, no temperature swing.
    bi_correlation : ndarray (N, N), optional
        Correlation of the gyros' flicker (bias instability) [-] (``design --rho-bi``); the
        flicker covariance is B Bᵀ ∘ bi_correlation. None: independent (as simulated).
    flicker_model : {"circular", "kasdin"}
        The flicker model (:func:`gyroarray.design.moments.flicker_moments`): the simulator's
        circular stationary 1/f (default), or Kasdin's 1/f from switch-on.

    Returns
    -------
    ErrorBudget
        Per term: 3-axis RMS rate error [deg/s] over the scored window and 3-axis RMS angle
        error at the horizon [deg]; the total, the ignored effects, the modifiers.

    Raises
    ------
    InputError
        A run too short for the start-up, a motion of the wrong shape, a model the
        estimators refuse (no white noise on a gyro).
    """
    H = np.asarray(H, dtype=float)
    N = H.shape[0]
    n = int(n_samples)
    dt = float(dt_s)
    if isinstance(motion, Swing):
        motion = Motion(omega_rad_s=swing_truth(motion, n, dt))
    elif motion is not None and not isinstance(motion, Motion):
        motion = Motion(omega_rad_s=np.asarray(motion, dtype=float))
    motion = Motion() if motion is None else motion
    from gyroarray.estimators.noise import model_terms  # lazy: the estimators load pandas (core.measurement)
    noise = noise_sources(noise_model, N, dt)
    declared = model_terms(noise_model, N)
    csys = cascade(sys, noise.sensor)
    k0 = settle_start(n, dt, settle_s)
    if n - k0 < 2:
        raise InputError(f"the run is too short: {n - k0} samples after the {settle_s:g} s start-up")
    corr = next((t for _, t in declared if isinstance(t, CorrelationTerm)), None)
    c_white = np.eye(N) if corr is None or corr.white is None else corr.white
    c_walk = np.eye(N) if corr is None or corr.walk is None else corr.walk
    errors, left_out = deterministic_error(noise, motion, n, H)
    ignored = set(noise.ignored) | set(left_out)
    modifiers = []
    rows: dict = {}
    flicker_total = None                               # linear in B²: the terms' moments add up
    for eff, t in declared:
        if t is None or eff.name in ignored:
            continue
        if isinstance(t, (CorrelationTerm, SensorFilter)):
            modifiers.append(eff.name)
            continue
        m = None
        if isinstance(t, WhiteTerm):
            s = np.nan_to_num(t.n_rad_rt_s) / np.sqrt(dt)
            m = error_moments(csys, _only(noise, R=c_white * np.outer(s, s)), n, k0,
                              white=True, walk=False, gm=False)
        elif isinstance(t, WalkTerm):
            s = np.nan_to_num(t.k_rad_s_rt_s) * np.sqrt(dt)
            m = error_moments(csys, _only(noise, Qb=c_walk * np.outer(s, s)), n, k0,
                              white=False, walk=True, gm=False)
        elif isinstance(t, FlickerTerm):
            m = flicker_moments(csys, np.nan_to_num(t.b_rad_s), n, k0, dt, model=flicker_model,
                                corr=bi_correlation)
            flicker_total = m if flicker_total is None else flicker_total + m
        elif isinstance(t, GaussMarkovTerm):
            sig = np.nan_to_num(t.sigma_rad_s)
            if np.any(sig > 0):
                m = error_moments(csys, _only(noise, gm_sigma_rad_s=sig,
                                              gm_tau_s=np.nan_to_num(t.tau_s, nan=1.0)),
                                  n, k0, white=False, walk=False, gm=True)
            else:
                rows[eff.name] = _row(0.0, 0.0, dt)
        elif isinstance(t, DeterministicTerm) and eff.name in errors:
            rows[eff.name] = _signal_row(linear_response(csys, errors[eff.name]), k0, dt)
        else:                                          # a term of a kind this budget does not know
            ignored.add(eff.name)
        if m is not None:
            rows[eff.name] = _moment_row(m, dt)
    # the total: every noise source on at once, the deterministic errors and the motion as one signal
    tot = error_moments(csys, noise, n, k0, white=True, walk=True, gm=True)
    if flicker_total is not None:
        tot = tot + flicker_total
    m_all = motion.resolved(n, dt, H)
    omega = m_all.omega_rad_s
    tracking = None
    z = omega @ H.T
    if np.any(omega):
        tracking = _signal_row(linear_response(csys, z) - omega, k0, dt)
    for e in errors.values():
        z = z + e
    det = linear_response(csys, z) - omega
    det_ms = float(np.mean(np.sum(det[k0:] ** 2, axis=1)))
    det_sf = float(np.sum(np.sum(det, axis=0) ** 2))
    total = _row(float(np.trace(tot.ms_window)) + det_ms, float(np.trace(tot.sum_full)) + det_sf, dt)
    order = [eff.name for eff, _ in declared if eff.name in rows]
    return ErrorBudget(terms={k: rows[k] for k in order}, total=total, ignored=sorted(ignored),
                       modifiers=modifiers, tracking=tracking, horizon_s=n * dt, settle_s=float(settle_s))


def undetected_fault(sys, n_gyros: int, gyro: int, step_rad_s: float, *, n_samples: int, dt_s: float,
                     settle_s: float = 2.0, sensor=None) -> dict:
    """The error of an undetected fault: a bias step on one gyro, present from t = 0 and never
    isolated, through the (intact) estimator to the rate and the angle at the horizon.

    Parameters
    ----------
    sys : LinearSystem
        The estimator on every gyro (the fault is not detected, so no gyro is removed).
    n_gyros : int
        Gyros of the array (the estimator's inputs).
    gyro : int
        The faulty gyro, 1-based in the estimator's input order.
    step_rad_s : float
        The step's size [rad/s].
    n_samples : int
        Samples in the run; the horizon is n_samples·dt_s.
    dt_s : float
        Sample period [s].
    settle_s : float
        Start-up left out of the RMS window [s].
    sensor : SensorBandwidth, optional
        The gyros' own filter, cascaded before the estimator (a step passes it).

    Returns
    -------
    dict
        ``rms_deg_s`` (3-axis RMS of the rate error over the scored window [deg/s]),
        ``angle_deg`` (3-axis angle error at the horizon [deg]), ``step_deg_s`` [deg/s], ``gyro``.
    """
    n = int(n_samples)
    dt = float(dt_s)
    k0 = settle_start(n, dt, settle_s)
    if not 1 <= int(gyro) <= int(n_gyros):
        raise ValueError(f"gyro {gyro} is not one of the {n_gyros} gyros")
    z = np.zeros((n, int(n_gyros)))
    z[:, int(gyro) - 1] = float(step_rad_s)
    e = linear_response(cascade(sys, sensor), z)
    return {**_signal_row(e, k0, dt), "step_deg_s": float(units.rad_s_to_deg_s(step_rad_s)),
            "gyro": int(gyro)}
