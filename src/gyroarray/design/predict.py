"""Analytic accuracy of a fused gyro array: what a run of length T will show, without running it.

For a fitted linear estimator (:meth:`gyroarray.estimators.Estimator.linear_system`:
x̂_k = A x̂_{k-1} + K z_k, ω̂_k = C x̂_k, x̂_{-1} = X0 z_0) and the noise the
simulator draws (``src/gyroarray/sim/effects.py``: white ARW of covariance R per sample,
rate random walk b_k = b_{k-1} + w_k from b_{-1} = 0 with increments of
covariance Q_b, first-order Gauss–Markov noise from a stationary start,
flicker bias instability), :func:`predict` gives per body axis the
expectations of the metrics :func:`gyroarray.chain.run.score` measures on one
run of n samples, after the same start-up ``settle_s``:

``rms_deg_s``
    √E[(1/n_W) Σ e_k²], the RMS of the rate error about the truth over the
    scored window W (paper 002 Eq. 19), random-walk drift included.
``std_deg_s``
    √E[s²], s² the sample variance of e over W (what ``sigma_1_deg_s`` is:
    the run's own mean removed).
``mean_deg_s``
    √E[ē²], the RMS of the run's mean error.
``angle_deg``
    √E[θ_T²], θ_T = dt Σ_{k<n} e_k the integrated rate error at the end of the
    run (what an attitude system feels).
``amplitude_ratio``, ``phase_deg``
    |T_aa| and −arg T_aa of the rate response at the swing frequency (phase
    positive when the estimate lags): the total, the product of
    ``estimator_amplitude_ratio``/``estimator_phase_deg`` (the array
    estimator's [T H]_aa) and ``sensor_amplitude_ratio``/``sensor_phase_deg``
    (the gyros' own ``bandwidth`` filter F at that frequency; 1 and 0 without one).
``arw_long_deg_rt_h``, ``rrw_long_deg_h_rt_h``, ``bi_long_deg_h``
    The noise terms of the fused rate at averaging times long against the
    filter's time constants: the readings' terms through the low-frequency
    gain T₀ (:meth:`LinearSystem.dc_gain`). A unity-DC-gain filter cannot
    lower them below GLS: ARW_fused = N·√[(HᵀC⁻¹H)⁻¹]_aa.
``dc_gain``
    [T₀ H]_aa: how much of a slow rate the estimate follows (a Kalman filter
    with bias states gives q_ω/(q_ω + q_b) < 1).

Notes
-----
The noise part is exact for white, random-walk and Gauss–Markov noise. With
A = S Λ S⁻¹ and the noise states g_k = Φ g_{k-1} + ε_k (Φ = 1 for the random
walks, e^{-dt/τ} for Gauss–Markov), the filter's modal state m = S⁻¹x̂ minus
X g, with X solving the diagonal Sylvester equation Λ X − X Φ = −S⁻¹K G Φ
elementwise, and g itself form a state ξ_k = diag(ν) ξ_{k-1} + B u_k with
white input u = [ε; v]. So Cov ξ_k = ν^k ∘ P₀ + S_k(ν νᵀ) ∘ B U Bᵀ with
S_k(a) = Σ_{j<k} a^j, Cov(ξ_j, ξ_k) = diag(ν^{j−k}) Cov ξ_k for j ≥ k, and
every window sum is a sum of such terms. They are accumulated by a
six-state affine recursion per element (p_k, the two one-sided sums
q_k = ν_i q_{k-1} + p_k, r_k, and the two totals) raised to the window
length by repeated squaring: O(d² log n) work, no loop over samples, and
no cancellation (every entry is a sum of non-negative powers). The
Kalman filters' unit modes (the unobservable split of rate and bias) are
not driven by K, so they never resonate with the random walks.

The flicker (bias instability) is the simulator's circular process: a sum
of independent sinusoids at the FFT frequencies j/(M dt) of variance
B²/(π j) (j <= M/2, M = next_fast_len(2n); the Nyquist line half that); each passes the steady-state
response T(θ_j) (the filter's start-up transient is left out, a fraction
≈ 1/(n·BW·dt) of the window), and its window sum follows the Fejér kernel.

A deterministic motion adds its own error e_det = estimate(F(H ω + b)) − ω
exactly (the filter is linear; cross terms with the zero-mean noise vanish),
with b the sum of the deterministic rate errors the model's effects declare
for that motion (a scale factor s_i h_i·ω, a tilted axis (a_i − h_i)·ω, a
g-sensitivity k_i · f_i, a temperature coefficient c_i ΔT, a plugin's own)
and F the gyros' own filters (a declared sensor filter), which the noise
passes too: the estimator is cascaded after them (:func:`cascade`), so the
moments above stay exact. The g-sensitivity's own share is reported per
gyro and through the estimator's DC gain (:func:`g_sensitivity_error`).

Which effect contributes what is the effect's own declaration
(:meth:`~gyroarray.effects.protocol.Effect.predictor_term`, the terms of
:mod:`gyroarray.effects.terms`): this module names no effect. The effects
of a model that declare no term, or whose term the stated motion cannot
evaluate (a temperature coefficient without a temperature swing), are
listed in ``ignored``; :mod:`gyroarray.design.budget` gives each term's
own share.

The predictor by its jobs (every name stays importable from here):
:mod:`~gyroarray.design.noise_sources` (the noise and sensor read from a model),
:mod:`~gyroarray.design.sensor_response` (the sensor filter cascaded, the swing response,
the deterministic errors), :mod:`~gyroarray.design.moments` (the exact error moments),
:mod:`~gyroarray.design.channel_response` (the scalar channels of the design search's fast
path); this module: the motion and :func:`predict` / :func:`predict_system`.

References
----------
Paper 002 (``shared/papers/002_*.txt``) Eq. 19 (RMS about the truth);
paper 003 Eq. 4–12 (the array model and GDOP).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.effects.terms import (DeterministicTerm, FlickerTerm, ForceTerm, GaussMarkovTerm,
                                     Motion, WalkTerm, WhiteTerm)
from gyroarray.design.noise_sources import (AXES, NOISE_TERMS, declared_terms, NoiseSources,  # noqa: F401 (re-exported)
                                            noise_sources, SensorBandwidth, sensor_bandwidth,
                                            force_coeffs, replace_noise)
from gyroarray.design.sensor_response import (cascade, swing_response, g_sensitivity_coeffs,  # noqa: F401 (re-exported)
                                              deterministic_error, g_sensitivity_error)
from gyroarray.design.moments import (window_sums, Moments, error_moments, flicker_moments)  # noqa: F401 (re-exported)
from gyroarray.design.channel_response import (channel_filter, ChannelResponse, channel_response)  # noqa: F401 (re-exported)

__all__ = ["NoiseSources", "noise_sources", "Prediction", "predict", "predict_system",
           "window_sums", "error_moments", "Swing", "swing_truth", "settle_start", "deterministic_error",
           "declared_terms"]


def __getattr__(name: str):
    # MODELLED (kept for callers of the former hand list): the effects whose declared term is a
    # noise term, a sensor filter or a g-sensitivity, computed from the declarations
    if name == "MODELLED":
        kinds = NOISE_TERMS + (ForceTerm,)
        return tuple(n for n, t in declared_terms().items() if t is not None and issubclass(t, kinds))
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class Swing:
    """A sinusoidal body rate A·sin(2π f t) on every body axis at once (about x, y and z together).

    Attributes
    ----------
    amplitude_rad_s : float
    frequency_hz : float
    """

    amplitude_rad_s: float
    frequency_hz: float


def swing_truth(swing: Swing, n: int, dt_s: float) -> np.ndarray:
    """The body rate (n, 3) of a swing on every axis at once [rad/s]; per axis it is the
    swing about that axis (the filters act per axis on a decoupled layout)."""
    t = np.arange(n) * dt_s
    w = swing.amplitude_rad_s * np.sin(2.0 * np.pi * swing.frequency_hz * t)
    return np.repeat(w[:, None], 3, axis=1)


def settle_start(n: int, dt_s: float, settle_s: float) -> int:
    """First scored sample, as :func:`gyroarray.chain.run.score` selects it (t >= t0 + settle)."""
    t = np.arange(n) / (1.0 / dt_s)
    return int(np.argmax(t >= t[0] + settle_s)) if np.any(t >= t[0] + settle_s) else n


@dataclass(frozen=True)
class Prediction:
    """Predicted metrics of one estimator on one layout, per body axis (module docstring).

    Attributes
    ----------
    estimator : str
    n_samples : int
    dt_s : float
    settle_s : float
    axes : dict
        axis -> {metric: value} in datasheet units (deg/s, deg, deg/√h, ...).
    components : dict
        axis -> mean-square of the rate error over the window by source
        ("white", "walk", "gauss_markov", "flicker", "motion") [(deg/s)²].
    swing_hz : float or None
    ignored : tuple of str
    sensor : dict or None
        The gyros' own filters the prediction cascades (``cutoff_hz``, ``order`` per gyro).
    g_sensitivity : dict or None
        The rate error the g-sensitivity causes (:func:`g_sensitivity_error`).
    """

    estimator: str
    n_samples: int
    dt_s: float
    settle_s: float
    axes: dict
    components: dict
    swing_hz: float | None = None
    ignored: tuple[str, ...] = field(default=())
    sensor: dict | None = None
    g_sensitivity: dict | None = None

    def to_json_dict(self) -> dict:
        return {"estimator": self.estimator, "n_samples": self.n_samples,
                "horizon_s": self.n_samples * self.dt_s, "settle_s": self.settle_s,
                "swing_hz": self.swing_hz, "axes": self.axes, "mean_square_by_source": self.components,
                "sensor_bandwidth": self.sensor, ForceTerm.key: self.g_sensitivity,
                "ignored_effects": list(self.ignored)}


def predict(estimator, noise_model, *, n_samples: int, settle_s: float = 2.0,
            truth_rad_s: np.ndarray | None = None, swing: Swing | None = None,
            specific_force_m_s2: np.ndarray | None = None,
            temp_swing_k: np.ndarray | float | None = None) -> Prediction:
    """Predict the metrics of a fitted estimator on a run (module docstring).

    Parameters
    ----------
    estimator : Estimator
        Fitted (``fit(layout, model, dt_s)``); must have a :meth:`linear_system`.
    noise_model : NoiseModel or NoiseSources
        The noise the run will have (usually the one the estimator was fitted with).
        Its declared sensor filters are cascaded before the estimator
        (:func:`cascade`: noise and motion pass them, as simulated); its
        deterministic terms add their rate errors for the motion to the
        readings (:func:`deterministic_error`).
    n_samples : int
        Samples in the run (T / dt).
    settle_s : float
        Start-up excluded from the window metrics [s] (as the chain).
    truth_rad_s : ndarray (n, 3), optional
        The body rate of the run [rad/s] (a scenario's truth); None: at rest.
    swing : Swing, optional
        Instead of ``truth_rad_s``: a swing about each axis (amplitude ratio and
        phase are reported at its frequency: the estimator's, the sensors' and
        their product, :func:`swing_response`).
    specific_force_m_s2 : ndarray (n, N, 3), optional
        The specific force at each gyro, platform frame [m/s²]
        (:func:`gyroarray.sim.truth.specific_force`); default: the level table at
        rest, [0, 0, g0] at every gyro. Read by the force terms (g-sensitivity).
    temp_swing_k : ndarray (n,) or float, optional
        The temperature's departure from the calibration temperature [K], read by
        the temperature terms; None: not stated (those effects are listed in
        ``ignored``).
    """
    sys = estimator.linear_system()
    dt = float(estimator.dt_s_)
    noise = (noise_model if isinstance(noise_model, NoiseSources)
             else noise_sources(noise_model, estimator.n_gyros_, dt))
    H = np.array(estimator.H_)
    n = int(n_samples)
    if n < 2:
        raise InputError(f"the run needs at least 2 samples, got {n_samples!r}")
    if swing is not None and truth_rad_s is not None:
        raise InputError("give truth_rad_s or swing, not both")
    omega = swing_truth(swing, n, dt) if swing is not None else truth_rad_s
    if omega is not None:
        omega = np.asarray(omega, dtype=float)
        if omega.shape != (n, 3):
            raise InputError(f"truth_rad_s must have shape ({n}, 3), got {omega.shape}")
    if specific_force_m_s2 is not None and np.shape(specific_force_m_s2) != (n, H.shape[0], 3):
        raise InputError(f"specific_force_m_s2 must have shape ({n}, {H.shape[0]}, 3), "
                         f"got {np.shape(specific_force_m_s2)}")
    motion = Motion(omega_rad_s=omega, specific_force_m_s2=specific_force_m_s2, temp_swing_k=temp_swing_k)
    errors, left_out = deterministic_error(noise, motion, n, H)
    bias = gsens = None
    if errors:
        parts = list(errors.values())
        bias = parts[0] if len(parts) == 1 else np.sum(parts, axis=0)
        if omega is None and not np.any(bias) and noise.g_sensitivity_rad_s_per_m_s2 is None:
            bias = None                                # at rest nothing moves (gravity always acts)
    if noise.g_sensitivity_rad_s_per_m_s2 is not None:
        f = motion.resolved(n, dt, H).specific_force_m_s2
        assert f is not None                                         # resolved: always set
        gsens = g_sensitivity_error(noise.g_sensitivity_rad_s_per_m_s2, f, sys.dc_gain(),
                                    settle_start(n, dt, settle_s))
    if left_out:
        noise = replace(noise, ignored=tuple(sorted(set(noise.ignored) | set(left_out))))
    det = None
    if omega is not None or bias is not None:
        w = np.zeros((n, 3)) if omega is None else omega
        z = w @ H.T + (0.0 if bias is None else bias)
        if noise.sensor is not None:
            z = noise.sensor.apply(z)
        det = estimator.estimate(z) - w
    pred = predict_system(sys, noise, H, n=n, settle_s=settle_s, det_error=det,
                          swing_hz=None if swing is None else swing.frequency_hz,
                          name=getattr(estimator, "name", ""))
    return pred if gsens is None else replace(pred, g_sensitivity=gsens)


def predict_system(sys, noise: NoiseSources, H: np.ndarray, *, n: int, settle_s: float = 2.0,
                   det_error: np.ndarray | None = None, swing_hz: float | None = None,
                   name: str = "") -> Prediction:
    """:func:`predict` for a :class:`~gyroarray.estimators.base.LinearSystem` and its noise.

    ``sys`` is the estimator alone: the noise's sensor filters are cascaded here
    (``det_error``, the deterministic error, must already include them).
    """
    dt = noise.dt_s
    est_sys = sys
    sys = cascade(sys, noise.sensor)
    k0 = settle_start(n, dt, settle_s)
    if n - k0 < 2:
        raise InputError(f"the run is too short: {n - k0} samples after the {settle_s:g} s start-up")
    nw = n - k0
    raw = {WhiteTerm.source: error_moments(sys, noise, n, k0, white=True, walk=False, gm=False),
           WalkTerm.source: error_moments(sys, noise, n, k0, white=False, walk=True, gm=False),
           GaussMarkovTerm.source: error_moments(sys, noise, n, k0, white=False, walk=False, gm=True)
           if np.any(noise.gm_sigma_rad_s > 0) else None,
           FlickerTerm.source: flicker_moments(sys, noise.bi_rad_s, n, k0, dt, model=noise.flicker_model,
                                               corr=noise.bi_corr)}
    parts: dict[str, Moments] = {k: v for k, v in raw.items() if v is not None}
    total = parts[WhiteTerm.source]
    for key, m in parts.items():
        if key != WhiteTerm.source:
            total = total + m
    ms = np.diag(total.ms_window).copy()
    mean_sq = np.diag(total.sum_window) / nw ** 2
    angle_sq = np.diag(total.sum_full) * dt ** 2
    comps = {k: np.diag(v.ms_window) for k, v in parts.items()}
    if det_error is not None:
        e = np.asarray(det_error, dtype=float)
        w = e[k0:]
        comps[DeterministicTerm.source] = np.mean(w ** 2, axis=0)
        ms = ms + comps[DeterministicTerm.source]
        mean_sq = mean_sq + np.mean(w, axis=0) ** 2
        angle_sq = angle_sq + (dt * e.sum(axis=0)) ** 2
    var = nw / (nw - 1.0) * (ms - mean_sq)
    t0 = sys.dc_gain()                                               # (3, N)
    arw2 = np.einsum("ai,ij,aj->a", t0, noise.R, t0) * dt           # N² = dt·σ²
    rrw2 = np.einsum("ai,ij,aj->a", t0, noise.Qb, t0) / dt          # K² = q/dt
    bi2 = (t0 ** 2) @ (noise.bi_rad_s ** 2)
    dcg = np.diag(t0 @ H)
    resp = None if swing_hz is None else swing_response(est_sys, H, noise.sensor, swing_hz, dt)
    to = units.rad_s_to_deg_s
    axes = {}
    for a, ax in enumerate(AXES):
        axes[ax] = {
            "rms_deg_s": float(to(math.sqrt(max(ms[a], 0.0)))),
            "std_deg_s": float(to(math.sqrt(max(var[a], 0.0)))),
            "mean_deg_s": float(to(math.sqrt(max(mean_sq[a], 0.0)))),
            "angle_deg": float(units.rad_to_deg(math.sqrt(max(angle_sq[a], 0.0)))),
            "amplitude_ratio": None, "phase_deg": None,
            "arw_long_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(math.sqrt(max(arw2[a], 0.0)))),
            "rrw_long_deg_h_rt_h": float(units.rrw_rad_s_rt_s_to_deg_h_rt_h(math.sqrt(max(rrw2[a], 0.0)))),
            "bi_long_deg_h": float(units.rad_s_to_deg_h(math.sqrt(max(bi2[a], 0.0)))),
            "dc_gain": float(dcg[a]),
        }
        if resp is not None:
            axes[ax].update(resp[ax])
    comps_deg = {ax: {k: float(to(1.0) ** 2 * v[a]) for k, v in comps.items()}
                 for a, ax in enumerate(AXES)}
    return Prediction(estimator=name, n_samples=n, dt_s=dt, settle_s=settle_s, axes=axes,
                      components=comps_deg, swing_hz=swing_hz, ignored=noise.ignored,
                      sensor=_sensor_dict(noise.sensor))


def _sensor_dict(sensor: SensorBandwidth | None) -> dict | None:
    if sensor is None:
        return None
    return {"cutoff_hz": [None if not f else float(c) for c, f in zip(sensor.cutoff_hz, sensor.filtered)],
            "order": [int(o) if o else None for o in sensor.order]}
