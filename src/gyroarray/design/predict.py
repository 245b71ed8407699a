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

References
----------
Paper 002 (``shared/papers/002_*.txt``) Eq. 19 (RMS about the truth);
paper 003 Eq. 4–12 (the array model and GDOP).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.fft as sfft
from scipy import signal
from scipy.linalg import block_diag

from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.sensor import bandwidth_filter, bandwidth_sos, g_sensitivity_bias
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.terms import (CorrelationTerm, DeterministicTerm, FlickerTerm, ForceTerm, GaussMarkovTerm,
                                     Motion, SensorFilter, WalkTerm, WhiteTerm, root_sum_square)

__all__ = ["NoiseSources", "noise_sources", "Prediction", "predict", "predict_system",
           "window_sums", "error_moments", "Swing", "swing_truth", "settle_start", "deterministic_error",
           "declared_terms"]

AXES = ("x", "y", "z")
#: The terms of the noise and sensor part of the predictor (the deterministic ones need a motion).
NOISE_TERMS = (WhiteTerm, WalkTerm, CorrelationTerm, FlickerTerm, GaussMarkovTerm, SensorFilter)


def declared_terms() -> dict:
    """Each registered effect's declared term class, probed on its placeholder parameters on
    three gyros (None: it declares none, or the probe fails)."""
    from gyroarray.effects import REGISTRY  # lazy: the registry and its plugins, at call time
    from gyroarray.estimators.noise import model_terms  # lazy: the estimators load pandas (core.measurement)
    out: dict = {}
    for name, eff in REGISTRY.items():
        try:
            (_, term), = model_terms(NoiseModel((ModelEntry(name, None, eff.placeholder()),)), 3)
        except Exception:                    # a plugin's probe that fails declares nothing usable
            term = None
        out[name] = None if term is None else type(term)
    return out


def __getattr__(name: str):
    # MODELLED (kept for callers of the former hand list): the effects whose declared term is a
    # noise term, a sensor filter or a g-sensitivity, computed from the declarations
    if name == "MODELLED":
        kinds = NOISE_TERMS + (ForceTerm,)
        return tuple(n for n, t in declared_terms().items() if t is not None and issubclass(t, kinds))
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# -- the noise ---------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class NoiseSources:
    """The noise of an N-gyro array as the predictor needs it (SI).

    Attributes
    ----------
    R : ndarray, shape (N, N)
        Covariance of one sample of the white (ARW) noise [rad²/s²].
    Qb : ndarray, shape (N, N)
        Covariance of one rate-random-walk increment [rad²/s²].
    gm_sigma_rad_s, gm_tau_s : ndarray, shape (N,)
        Gauss–Markov σ [rad/s] and τc [s] per gyro (σ = 0: none).
    bi_rad_s : ndarray, shape (N,)
        Bias instability coefficient B per gyro [rad/s].
    dt_s : float
        Sample period [s].
    ignored : tuple of str
        Effects of the model the predictor does not model.
    sensor : SensorBandwidth or None
        The gyros' own low-pass (the ``bandwidth`` effect), None: none.
    g_sensitivity_rad_s_per_m_s2 : ndarray, shape (N, 3), or None
        g-sensitivity of each gyro, platform frame [(rad/s)/(m/s²)] (the declared
        :class:`~gyroarray.effects.terms.ForceTerm` s, summed).
    deterministic : tuple of (str, DeterministicTerm)
        The declared deterministic rate errors, by effect name, that :func:`predict`
        evaluates on the stated motion.
    """

    R: np.ndarray
    Qb: np.ndarray
    gm_sigma_rad_s: np.ndarray
    gm_tau_s: np.ndarray
    bi_rad_s: np.ndarray
    dt_s: float
    ignored: tuple[str, ...] = ()
    sensor: "SensorBandwidth | None" = None
    g_sensitivity_rad_s_per_m_s2: np.ndarray | None = None
    deterministic: tuple = ()

    @property
    def n_gyros(self) -> int:
        return int(self.R.shape[0])


def noise_sources(noise_model, n_gyros: int, dt_s: float) -> NoiseSources:
    """The predictor's noise from a :class:`~gyroarray.effects.model.NoiseModel`.

    Parameters
    ----------
    noise_model : NoiseModel
        As simulated (white noise is required on every gyro, as for the estimators).
    n_gyros : int
    dt_s : float
        Sample period [s].

    Notes
    -----
    Every effect's declared term (:func:`gyroarray.estimators.noise.model_terms`):
    white and walk terms (with the correlation modifier) make R and Q_b as the
    estimators see them (:func:`~gyroarray.estimators.noise.array_noise`);
    flicker terms add their B² per gyro; a gyro has one Gauss–Markov process and
    the gyros one sensor filter (a second one on the same gyro is listed as
    ignored); the deterministic terms are kept for :func:`predict`.
    """
    from gyroarray.estimators.noise import array_noise, model_terms  # lazy: the estimators load pandas (core.measurement)
    an = array_noise(noise_model, n_gyros)
    terms = model_terms(noise_model, n_gyros)
    ignored = {eff.name for eff, t in terms if t is None}
    sig = np.zeros(n_gyros)
    tau = np.ones(n_gyros)
    for eff, t in terms:
        if isinstance(t, GaussMarkovTerm):
            has = ~np.isnan(t.sigma_rad_s)
            if np.any(has & (sig > 0)):
                ignored.add(eff.name)                # the predictor has one process per gyro
                continue
            sig = np.where(has, np.nan_to_num(t.sigma_rad_s), sig)
            tau = np.where(has, np.nan_to_num(t.tau_s, nan=1.0), tau)
    flick = [t.b_rad_s for _, t in terms if isinstance(t, FlickerTerm)]
    bi = np.nan_to_num(root_sum_square(flick)) if flick else np.zeros(n_gyros)
    sensors = [(eff, t) for eff, t in terms if isinstance(t, SensorFilter)]
    ignored.update(eff.name for eff, _ in sensors[1:])
    det = tuple((eff.name, t) for eff, t in terms if isinstance(t, DeterministicTerm))
    return NoiseSources(R=an.R(dt_s), Qb=an.Qb(dt_s), gm_sigma_rad_s=sig, gm_tau_s=tau,
                        bi_rad_s=bi, dt_s=float(dt_s), ignored=tuple(sorted(ignored)),
                        sensor=_sensor(sensors[0][1] if sensors else None, dt_s),
                        g_sensitivity_rad_s_per_m_s2=_force_coeffs(det, n_gyros), deterministic=det)


# -- the sensor's own response: bandwidth and g-sensitivity --------------------------

@dataclass(frozen=True, eq=False)
class SensorBandwidth:
    """The gyros' own low-pass filters (the spec's ``bandwidth`` effect, as simulated).

    Attributes
    ----------
    cutoff_hz : ndarray, shape (N,)
        −3 dB frequency of each gyro's filter [Hz] (NaN: no filter).
    order : ndarray of int, shape (N,)
        1, or 2 (Butterworth); 0: no filter.
    dt_s : float
        Sample period [s].
    """

    cutoff_hz: np.ndarray
    order: np.ndarray
    dt_s: float

    @property
    def filtered(self) -> np.ndarray:
        """Mask of the gyros that have a filter."""
        return np.asarray(self.order) > 0

    def sos(self, k: int) -> np.ndarray:
        """Gyro k's (0-based) digital filter as second-order sections
        (:func:`gyroarray.core.sensor.bandwidth_sos`, the simulator's own)."""
        return bandwidth_sos(float(self.cutoff_hz[k]), int(self.order[k]), self.dt_s)

    def response(self, freq_hz: float) -> np.ndarray:
        """H_d(e^{j2πf dt}) of each gyro's filter (1 where none), shape (N,) [-]."""
        out = np.ones(self.order.size, dtype=complex)
        for k in np.flatnonzero(self.filtered):
            _, h = signal.sosfreqz(self.sos(int(k)), worN=[float(freq_hz)], fs=1.0 / self.dt_s)
            out[k] = h[0]
        return out

    def apply(self, x: np.ndarray) -> np.ndarray:
        """The readings (n, N) through each gyro's filter, started at the first sample's
        steady state, as the simulator runs it (:func:`gyroarray.core.sensor.bandwidth_filter`)."""
        y = np.array(x, dtype=float)
        m = self.filtered
        if m.any():
            y[:, m] = bandwidth_filter(y[:, m], self.dt_s, self.cutoff_hz[m], self.order[m])
        return y

    def state_space(self, k: int):
        """Gyro k's filter as s_j = A s_{j-1} + B u_j, y_j = C s_{j-1} + D u_j (s_j the
        standard state of sample j + 1, :func:`scipy.signal.tf2ss`)."""
        b, a = signal.sos2tf(self.sos(k))
        while b.size > 1 and a[-1] == 0 and b[-1] == 0:             # order 1: drop the section's
            a, b = a[:-1], b[:-1]                                    # padding (a pole at 0)
        return signal.tf2ss(b, a)


def sensor_bandwidth(noise_model, n_gyros: int, dt_s: float) -> SensorBandwidth | None:
    """The sensor filter a noise model declares, per gyro (None: the model has none).

    Raises
    ------
    InputError
        An order other than 1 or 2, or a cut-off not inside (0, Nyquist).
    """
    from gyroarray.estimators.noise import model_terms  # lazy: the estimators load pandas (core.measurement)
    sensors = [t for _, t in model_terms(noise_model, n_gyros) if isinstance(t, SensorFilter)]
    return _sensor(sensors[0] if sensors else None, dt_s)


def _sensor(term: SensorFilter | None, dt_s: float) -> SensorBandwidth | None:
    """A declared :class:`~gyroarray.effects.terms.SensorFilter` as the predictor's filters."""
    if term is None:
        return None
    fc = np.asarray(term.cutoff_hz, dtype=float).copy()
    order = np.nan_to_num(np.asarray(term.order, dtype=float)).astype(int)
    sb = SensorBandwidth(cutoff_hz=fc, order=order, dt_s=float(dt_s))
    for k in np.flatnonzero(sb.filtered):
        sb.sos(int(k))                                               # checks order and cut-off
    return sb


def cascade(sys, sensor: SensorBandwidth | None):
    """The estimator ``sys`` fed through the gyros' own filters: one :class:`LinearSystem`
    from the unfiltered readings u to the rate estimate.

    With the filters' states stacked in s and the estimator's in x̂:

    # s_k = A_f s_{k-1} + B_f u_k,  y_k = C_f s_{k-1} + D_f u_k
    # x̂_k = A x̂_{k-1} + K y_k
    # [s; x̂]_k = [[A_f, 0], [K C_f, A]] [s; x̂]_{k-1} + [B_f; K D_f] u_k

    started, as the simulator starts the filters, at the steady state of the
    first reading (s_{-1} = (I − A_f)⁻¹ B_f u_0, so y_0 = u_0 and x̂_{-1} = X0 u_0).
    The modes are the estimator's, [0; v], and the filters', [w; (μ I − A)⁻¹ K C_f w]
    (complex for the Butterworth pair): block triangular, so S⁻¹ is too.
    """
    if sensor is None or not sensor.filtered.any():
        return sys
    from gyroarray.estimators.base import LinearSystem  # lazy: the estimators load pandas (core.measurement)
    N = sys.K.shape[1]
    blocks = []
    for k in range(N):
        if sensor.filtered[k]:
            blocks.append(sensor.state_space(k))
        else:                                                        # y = u: a zero-state pass
            blocks.append((np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.ones((1, 1))))
    Af = block_diag(*[b[0] for b in blocks]) if any(b[0].size for b in blocks) else np.zeros((0, 0))
    Bf = block_diag(*[b[1] for b in blocks])
    Cf = block_diag(*[b[2] for b in blocks])
    Df = np.diag([float(b[3][0, 0]) for b in blocks])
    Af, Bf, Cf = (np.asarray(m, dtype=float).reshape(sh) for m, sh in
                  ((Af, (Af.shape[0], Af.shape[0])), (Bf, (Af.shape[0], N)), (Cf, (N, Af.shape[0]))))
    F, D = Af.shape[0], sys.A.shape[0]
    A = np.block([[Af, np.zeros((F, D))], [sys.K @ Cf, sys.A]])
    K = np.vstack([Bf, sys.K @ Df])
    C = np.hstack([np.zeros((sys.C.shape[0], F)), sys.C])
    X0 = np.vstack([np.linalg.solve(np.eye(F) - Af, Bf), sys.X0])
    eigs = [np.linalg.eig(b[0]) for b in blocks if b[0].size]       # per gyro: no mixing of
    mu = np.concatenate([e[0] for e in eigs]) if eigs else np.zeros(0)   # repeated poles
    Wf = block_diag(*[e[1] for e in eigs]) if eigs else np.zeros((0, 0))
    lam_e = np.asarray(sys.lam, dtype=complex)
    ge = sys.S_inv @ sys.K @ Cf @ Wf                                 # (D, F) in the estimator's modes
    den = mu[None, :] - lam_e[:, None]
    if np.any(np.abs(den) < 1e-12):
        raise InputError("a sensor filter pole equals an estimator pole: the cascade has no "
                         "modal form")
    U = sys.S @ (ge / den)                                           # (μ I − A)⁻¹ K C_f w
    S = np.block([[Wf, np.zeros((F, D))], [U, sys.S]])
    wi = np.linalg.inv(Wf) if F else Wf
    S_inv = np.block([[wi, np.zeros((F, D))], [-sys.S_inv @ U @ wi, sys.S_inv]])
    lam = np.concatenate([mu, lam_e])
    if np.all(np.abs(lam.imag) == 0):
        lam, S, S_inv = lam.real, S.real, S_inv.real
    return LinearSystem(A=A, K=K, C=C, X0=X0, lam=lam, S=S, S_inv=S_inv)


def swing_response(sys, H: np.ndarray, sensor: SensorBandwidth | None, freq_hz: float,
                   dt_s: float) -> dict:
    """Amplitude ratio and phase lag of the fused rate at a swing frequency, per body axis:
    the array estimator's [T H]_aa, the sensors' share [T diag(F) H]_aa / [T H]_aa (their
    own filter F when the gyros are alike) and the total, their product.

    Parameters
    ----------
    sys : LinearSystem
        The estimator alone (not cascaded).
    H : ndarray (N, 3)
    sensor : SensorBandwidth or None
    freq_hz : float
        [Hz].
    dt_s : float
        [s].

    Returns
    -------
    dict
        axis -> {``amplitude_ratio``, ``phase_deg`` (total), ``estimator_amplitude_ratio``,
        ``estimator_phase_deg``, ``sensor_amplitude_ratio``, ``sensor_phase_deg``}; phases in
        degrees, positive when the output lags.
    """
    T = sys.response(2.0 * np.pi * freq_hz * dt_s)[0]               # (3, N)
    est = np.diagonal(T @ H)
    fs = np.ones(H.shape[0], complex) if sensor is None else sensor.response(freq_hz)
    tot = np.diagonal(T @ (fs[:, None] * H))
    out = {}
    for a, ax in enumerate(AXES):
        sen = tot[a] / est[a] if est[a] != 0 else complex(np.mean(fs))

        def lag(z):
            return float(-np.degrees(np.angle(z)))
        out[ax] = {"amplitude_ratio": float(abs(tot[a])), "phase_deg": lag(tot[a]),
                   "estimator_amplitude_ratio": float(abs(est[a])), "estimator_phase_deg": lag(est[a]),
                   "sensor_amplitude_ratio": float(abs(sen)), "sensor_phase_deg": lag(sen)}
    return out


def g_sensitivity_coeffs(noise_model, n_gyros: int) -> np.ndarray | None:
    """The g-sensitivity of each gyro (the declared force terms), shape (N, 3), platform frame
    [(rad/s)/(m/s²)] (None: the model has none; an entry for gyro k overrides one for all)."""
    from gyroarray.estimators.noise import model_terms  # lazy: the estimators load pandas (core.measurement)
    det = tuple((eff.name, t) for eff, t in model_terms(noise_model, n_gyros) if isinstance(t, ForceTerm))
    return _force_coeffs(det, n_gyros)


def _force_coeffs(det: tuple, n_gyros: int) -> np.ndarray | None:
    """The sum of the :class:`~gyroarray.effects.terms.ForceTerm` coefficients (N, 3), or None."""
    k = [np.nan_to_num(np.asarray(t.coeff_rad_s_per_m_s2, dtype=float)) for _, t in det
         if isinstance(t, ForceTerm)]
    if not k:
        return None
    return k[0] if len(k) == 1 else np.sum(k, axis=0)


def deterministic_error(noise: NoiseSources, motion: Motion, n: int, H: np.ndarray
                        ) -> tuple[dict, list]:
    """Each declared deterministic term's rate error on a motion.

    Parameters
    ----------
    noise : NoiseSources
    motion : Motion
        The stated motion (:class:`~gyroarray.effects.terms.Motion`; unset fields: at
        rest, level, no temperature swing).
    n : int
        Samples.
    H : ndarray (N, 3)
        Nominal axes.

    Returns
    -------
    errors : dict
        Effect name -> per-gyro rate error (n, N) [rad/s] (the errors of several terms of
        one effect added).
    left_out : list of str
        Effects whose term the motion cannot evaluate (it lacks what they need).
    """
    m = motion.resolved(n, noise.dt_s, H)
    errors: dict = {}
    left_out = []
    det = noise.deterministic
    if noise.g_sensitivity_rad_s_per_m_s2 is not None and not any(isinstance(t, ForceTerm) for _, t in det):
        det = det + ((ForceTerm.key, ForceTerm(noise.g_sensitivity_rad_s_per_m_s2)),)   # built by hand
    for name, term in det:
        e = term.rate_error(m)
        if e is None:
            left_out.append(name)
            continue
        e = np.asarray(e, dtype=float)
        if e.shape != (n, H.shape[0]):
            raise InputError(f"{name}: its predictor term gave a rate error of shape {e.shape}, not "
                             f"({n}, {H.shape[0]})")
        errors[name] = e if name not in errors else errors[name] + e
    return errors, left_out


def g_sensitivity_error(coeff_rad_s_per_m_s2: np.ndarray, specific_force_m_s2: np.ndarray,
                        dc_gain: np.ndarray | None, k0: int = 0) -> dict:
    """The rate error the g-sensitivity causes on a motion, per gyro and fused.

    Gyro i's error is e_i = k_i · f_i (the spec's bias, f_i the specific force
    at the gyro); the fused error is the estimator's DC gain applied to them,
    T₀ e (for least squares the pseudo-inverse: (HᵀC⁻¹H)⁻¹HᵀC⁻¹ e), which is
    what the filter passes of a bias that changes slowly against its bandwidth.

    Parameters
    ----------
    coeff_rad_s_per_m_s2 : ndarray, shape (N, 3)
        [(rad/s)/(m/s²)].
    specific_force_m_s2 : ndarray, shape (n, N, 3), or (3,) for a constant force at every gyro
        [m/s²].
    dc_gain : ndarray, shape (3, N), or None
        T₀ of the estimator (None: per gyro only).
    k0 : int
        First scored sample.

    Returns
    -------
    dict
        ``per_gyro_rms_deg_s`` (list of N), ``fused_rms_deg_s`` and
        ``fused_mean_deg_s`` (axis -> value; absent without a DC gain),
        RMS over the scored window.
    """
    c = np.asarray(coeff_rad_s_per_m_s2, dtype=float)
    f = np.asarray(specific_force_m_s2, dtype=float)
    if f.ndim == 1:
        f = np.broadcast_to(f, (1, c.shape[0], 3))
    e = g_sensitivity_bias(c, f)[k0:]                                # (n, N) [rad/s]
    to = units.rad_s_to_deg_s
    out: dict[str, Any] = {"per_gyro_rms_deg_s": [float(to(v))
                                                for v in np.sqrt(np.mean(e ** 2, axis=0))]}
    if dc_gain is not None:
        fe = e @ np.asarray(dc_gain, dtype=float).T                  # (n, 3)
        out["fused_rms_deg_s"] = {ax: float(to(v)) for ax, v in zip(AXES, np.sqrt(np.mean(fe ** 2, 0)))}
        out["fused_mean_deg_s"] = {ax: float(to(v)) for ax, v in zip(AXES, np.mean(fe, 0))}
    return out


# -- window sums of the modal covariance ---------------------------------------------

def _mat_power(T: np.ndarray, m: int) -> np.ndarray:
    """T^m for a stack of square matrices (E, s, s), by repeated squaring."""
    out = np.broadcast_to(np.eye(T.shape[-1]), T.shape).copy()
    base = T.copy()
    while m > 0:
        if m & 1:
            out = out @ base
        m >>= 1
        if m:
            base = base @ base
    return out


def window_sums(nu: np.ndarray, k0: int, k1: int) -> tuple[np.ndarray, ...]:
    """Sums over k = k0..k1 of the modal covariance terms, for every pair (i, l).

    With a = ν_i ν_l, S_k(a) = Σ_{j<k} a^j and g_i(k) = Σ_{j=0}^{k1−k} ν_i^j:

    X1 = Σ a^k,  Y1 = Σ S_k(a),  X2 = Σ (g_i + g_l − 1) a^k,  Y2 = Σ (g_i + g_l − 1) S_k(a).

    For complex modes (a cascaded Butterworth filter) a = ν_i conj(ν_l) and
    g_l sums conj(ν_l): the sums of E[ξ ξᴴ].

    Parameters
    ----------
    nu : ndarray, shape (d,)
        Mode factors, |ν| <= 1 [-] (real in [0, 1], or complex).
    k0, k1 : int
        First and last sample of the window (0 <= k0 <= k1).

    Returns
    -------
    X1, Y1, X2, Y2 : ndarray, shape (d, d)
    """
    nu = np.asarray(nu)
    nu = nu.astype(complex if np.iscomplexobj(nu) else float)
    d = nu.size
    a = np.outer(nu, np.conj(nu)).ravel()
    ni = np.repeat(nu, d)
    nl = np.tile(np.conj(nu), d)
    E = a.size
    # phase 1: p_k = a p_{k-1} + c from k = 0 to k0, for the two unit inputs (p_0, c) = (1, 0), (0, 1)
    t1 = np.zeros((E, 2, 2), dtype=nu.dtype)
    t1[:, 0, 0], t1[:, 0, 1], t1[:, 1, 1] = a, 1.0, 1.0
    p1 = _mat_power(t1, k0)
    # phase 2: [p, q, r, A1, A2, c] from k0 to k1
    t2 = np.zeros((E, 6, 6), dtype=nu.dtype)
    t2[:, :5, 0] = a[:, None]
    t2[:, :5, 5] = 1.0
    t2[:, 1, 1] = t2[:, 4, 1] = ni
    t2[:, 2, 2] = t2[:, 4, 2] = nl
    t2[:, 3, 3] = t2[:, 4, 4] = t2[:, 5, 5] = 1.0
    p2 = _mat_power(t2, k1 - k0)
    out = []
    for col in (0, 1):                            # response to P0 = 1, then to W = 1
        p_k0 = p1[:, 0, col]
        s0 = np.stack([p_k0, p_k0, p_k0, p_k0, p_k0, np.full(E, float(col))], axis=1)
        s = np.einsum("eij,ej->ei", p2, s0)
        out.append((s[:, 3].reshape(d, d), s[:, 4].reshape(d, d)))
    (x1, x2), (y1, y2) = out
    return x1, y1, x2, y2


# -- the error system ---------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class _ErrorSystem:
    """ξ_k = diag(ν) ξ_{k-1} + B u_k (k >= 1), Cov ξ_0 = P0, e_k = c ξ_k."""

    nu: np.ndarray
    P0: np.ndarray
    W: np.ndarray
    c: np.ndarray


def _error_system(sys, noise: NoiseSources, *, white: bool = True, walk: bool = True,
                  gm: bool = True) -> _ErrorSystem:
    """The modal error system of a linear estimator under the noise (module Notes)."""
    N = noise.n_gyros
    dt = noise.dt_s
    R = noise.R if white else np.zeros((N, N))
    # noise states: the N random walks (Φ = 1, from 0), then the Gauss–Markov gyros (stationary)
    gm_idx = np.flatnonzero(noise.gm_sigma_rad_s > 0) if gm else np.array([], int)
    phi_gm = np.exp(-dt / noise.gm_tau_s[gm_idx])
    s2 = noise.gm_sigma_rad_s[gm_idx] ** 2
    n_rw = N if walk and np.any(noise.Qb != 0) else 0
    ng = n_rw + gm_idx.size
    phi = np.concatenate([np.ones(n_rw), phi_gm])
    gout = np.zeros((N, ng))
    if n_rw:
        gout[:, :N] = np.eye(N)
    gout[gm_idx, n_rw + np.arange(gm_idx.size)] = 1.0
    qg = np.zeros((ng, ng))
    pgm1 = np.zeros((ng, ng))
    if n_rw:
        qg[:N, :N] = noise.Qb
    j = n_rw + np.arange(gm_idx.size)
    qg[j, j] = s2 * (1.0 - phi_gm ** 2)                              # σ²(1 − φ²)
    pgm1[j, j] = s2                                                  # stationary start
    lam = sys.lam
    kt = sys.S_inv @ sys.K                                           # K̃ = S⁻¹ K
    kg = kt @ gout
    den = phi[None, :] - lam[:, None]
    res = np.abs(den) < 1e-12
    if kg.size and np.any(np.abs(kg[res]) > 1e-9 * max(1.0, float(np.max(np.abs(kg))))):
        raise InputError("a filter mode resonates with a noise state (equal poles): the "
                         "predictor has no stationary decomposition for this estimator")
    X = np.where(res, 0.0, kg * phi[None, :] / np.where(res, 1.0, den))   # Λ X − X Φ = −K̃ G Φ
    D = lam.size
    B = np.zeros((D + ng, ng + N), dtype=np.result_type(lam, kt, float))
    B[:D, :ng] = kg - X
    B[:D, ng:] = kt
    B[D:, :ng] = np.eye(ng)
    U = np.zeros((ng + N, ng + N))
    U[:ng, :ng] = qg
    U[ng:, ng:] = R
    W = B @ U @ B.conj().T
    # start: x̂_0 = (A X0 + K) z_0, z_0 = G g_0 + v_0, g_0 = Φ g_{-1} + ε_0
    m0 = lam[:, None] * (sys.S_inv @ sys.X0) + kt                   # S⁻¹(A X0 + K)
    tg = np.vstack([m0 @ gout - X, np.eye(ng)])
    tv = np.vstack([m0, np.zeros((ng, N))])
    pg0 = phi[:, None] * pgm1 * phi[None, :] + qg
    P0 = tg @ pg0 @ tg.conj().T + tv @ R @ tv.conj().T
    cs = sys.C @ sys.S
    c = np.hstack([cs, cs @ X])
    return _ErrorSystem(nu=np.concatenate([lam, phi]), P0=P0, W=W, c=c)


@dataclass(frozen=True)
class Moments:
    """Second moments of the noise-driven rate error over a run (3×3 each) [rad²/s², rad²/s²·samples²].

    Attributes
    ----------
    ms_window : ndarray
        E[(1/n_W) Σ_W e eᵀ].
    sum_window : ndarray
        E[(Σ_W e)(Σ_W e)ᵀ].
    sum_full : ndarray
        E[(Σ_{k<n} e)(Σ_{k<n} e)ᵀ].
    n_window : int
    """

    ms_window: np.ndarray
    sum_window: np.ndarray
    sum_full: np.ndarray
    n_window: int

    def __add__(self, other: "Moments") -> "Moments":
        return Moments(self.ms_window + other.ms_window, self.sum_window + other.sum_window,
                       self.sum_full + other.sum_full, self.n_window)


def error_moments(sys, noise: NoiseSources, n: int, k0: int, **parts) -> Moments:
    """Exact second moments of the state-space part of the noise (white, RRW, Gauss–Markov).

    Parameters
    ----------
    sys : LinearSystem
    noise : NoiseSources
    n : int
        Samples in the run.
    k0 : int
        First scored sample (after the start-up).
    **parts
        ``white``, ``walk``, ``gm`` (bool): which noise terms to include.
    """
    es = _error_system(sys, noise, **parts)
    x1, y1, x2, y2 = window_sums(es.nu, k0, n - 1)
    c = es.c
    ch = c.conj().T
    ms = np.real(c @ (es.P0 * x1 + es.W * y1) @ ch) / (n - k0)
    sw = np.real(c @ (es.P0 * x2 + es.W * y2) @ ch)
    if k0 == 0:
        sf = sw
    else:
        _, _, fx2, fy2 = window_sums(es.nu, 0, n - 1)
        sf = np.real(c @ (es.P0 * fx2 + es.W * fy2) @ ch)
    return Moments(_sym(ms), _sym(sw), _sym(sf), n - k0)


def _sym(a):
    return 0.5 * (a + a.T)


def flicker_moments(sys, bi_rad_s: np.ndarray, n: int, k0: int, dt_s: float) -> Moments:
    """Second moments of the error from the simulator's flicker noise (module Notes).

    Each FFT frequency of the circular flicker process passes the filter's
    steady-state response; the window sums follow the Fejér kernel.
    """
    bi = np.asarray(bi_rad_s, dtype=float)
    zero = np.zeros((3, 3))
    if not np.any(bi > 0):
        return Moments(zero, zero, zero, n - k0)
    M = sfft.next_fast_len(2 * n, real=True)
    j = np.arange(1, M // 2 + 1, dtype=float)
    # variance of each sinusoid per B²: the simulator's line j carries S(f_j)·Δf = 1/(π j)
    # (S = B²/(π f) one-sided, Δf = 1/(M dt); core.physics.flicker_noise), not 2/(π j)
    v = 1.0 / (np.pi * j)
    if M % 2 == 0:
        v[-1] *= 0.5                                       # the Nyquist bin is real
    theta = 2.0 * np.pi * j / M

    def fejer(m, th):                                      # |Σ_{k<m} e^{jθk}|²
        s = np.sin(0.5 * th)
        return np.where(s == 0, float(m) ** 2, (np.sin(0.5 * m * th) / np.where(s == 0, 1, s)) ** 2)
    fw, ff = fejer(n - k0, theta), fejer(n, theta)
    ms, sw, sf = zero.copy(), zero.copy(), zero.copy()
    for lo in range(0, theta.size, 32768):                # bounded memory
        sl = slice(lo, lo + 32768)
        T = sys.response(theta[sl])                        # (t, 3, N)
        g = np.einsum("tai,tbi,i->tab", T, np.conj(T), bi ** 2).real * v[sl, None, None]
        ms += g.sum(axis=0)
        sw += np.einsum("tab,t->ab", g, fw[sl])
        sf += np.einsum("tab,t->ab", g, ff[sl])
    return Moments(ms, sw, sf, n - k0)


# -- motion ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Swing:
    """A sinusoidal body rate A·sin(2π f t) about each body axis in turn.

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


# -- the prediction -------------------------------------------------------------------

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
           FlickerTerm.source: flicker_moments(sys, noise.bi_rad_s, n, k0, dt)}
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


# -- scalar channels (the fast path of the design search) ---------------------------

def channel_filter(kind: str, dt_s: float, bandwidth_hz: float | None = None,
                   ratio: float | None = None):
    """One rate axis' filter as a single-input :class:`LinearSystem` (C is 1×D).

    Parameters
    ----------
    kind : {"none", "lowpass", "kf"}
        ``none``: ω̂ = y (a per-sample estimator); ``lowpass``: the comparison
        low-pass of ``gls``/``ols`` started on y_0; ``kf``: the steady-state
        Kalman filter on [ω, b] of a single input y = ω + b + v, started from
        [y_0, 0].
    dt_s : float
    bandwidth_hz : float
        −3 dB bandwidth [Hz] (``lowpass``, ``kf``).
    ratio : float
        ``kf``: q_b / r, the bias increment variance over the white variance the
        filter is designed for [-].

    Returns
    -------
    LinearSystem or None
        None when the Kalman filter cannot reach the bandwidth (below the
        floor that the rate random walk sets).

    Notes
    -----
    The single-input KF at bandwidth f has the closed form used here (the
    tests check it against the Riccati solution): its stable mode is the
    low-pass pole λ of f (:func:`gyroarray.estimators.kalman.lowpass_pole`),
    the observable sum ω + b has the prior variance P = r(1 − λ)/λ, so the
    summed increment variance is Q = P²/(P + r) = r(1 − λ)²/λ, q_ω·dt = Q − q_b,
    and the gain splits as K = (1 − λ)[κ, 1 − κ] with κ = q_ω·dt/Q, the DC gain
    of the rate estimate.
    """
    from gyroarray.estimators.kalman import lowpass_pole  # lazy: the estimators load pandas (core.measurement)
    from gyroarray.estimators.base import LinearSystem  # lazy: the estimators load pandas (core.measurement)
    one = np.ones((1, 1))
    if kind == "none":
        return LinearSystem(A=np.zeros((1, 1)), K=one, C=one, X0=np.zeros((1, 1)),
                            lam=np.zeros(1), S=one, S_inv=one)
    if bandwidth_hz is None:
        raise ValueError(f"channel filter {kind!r} needs bandwidth_hz")
    lam = lowpass_pole(float(bandwidth_hz), dt_s)
    if kind == "lowpass":
        return LinearSystem(A=lam * one, K=(1.0 - lam) * one, C=one, X0=one, lam=np.array([lam]),
                            S=one, S_inv=one)
    if kind != "kf":
        raise ValueError(f"unknown channel filter {kind!r}")
    if ratio is None:
        raise ValueError("the kf channel filter needs ratio")
    q_sum = (1.0 - lam) ** 2 / lam                                   # Q / r
    kappa = 1.0 - float(ratio) / q_sum
    if not kappa > 0.0:
        return None
    kw, kb = kappa * (1.0 - lam), (1.0 - kappa) * (1.0 - lam)
    K = np.array([[kw], [kb]])
    A = np.eye(2) - K @ np.ones((1, 2))                              # A = I − K [1 1]
    S = np.array([[kw, 1.0], [kb, -1.0]])                            # modes λ, 1
    return LinearSystem(A=A, K=K, C=np.array([[1.0, 0.0]]), X0=np.array([[1.0], [0.0]]),
                        lam=np.array([lam, 1.0]), S=S, S_inv=np.linalg.inv(S))


@dataclass(frozen=True)
class ChannelResponse:
    """Unit responses of one channel filter: the window moments per unit noise level.

    Each entry is (ms_window, sum_window, sum_full) for a unit white variance
    per sample (``white``), unit random-walk increment variance (``walk``),
    unit flicker coefficient B² (``flicker``) and unit Gauss–Markov variance
    (``gauss_markov``); ``motion`` the same three for the deterministic rate
    error of each body axis' motion (None: at rest), and ``dc_gain``. With a
    sensor filter everything is of the cascade (sensor, then channel filter);
    ``amplitude_ratio``/``phase_deg`` are the total at the swing frequency and
    the ``estimator_*``/``sensor_*`` fields its two factors.
    """

    white: tuple
    walk: tuple
    flicker: tuple
    gauss_markov: tuple
    motion: tuple | None
    dc_gain: float
    amplitude_ratio: float | None
    phase_deg: float | None
    estimator_amplitude_ratio: float | None = None
    estimator_phase_deg: float | None = None
    sensor_amplitude_ratio: float | None = None
    sensor_phase_deg: float | None = None


def channel_response(sys, dt_s: float, n: int, k0: int, *, bi: bool = False,
                     gm_tau_s: float | None = None, motion: np.ndarray | None = None,
                     swing_hz: float | None = None,
                     sensor: SensorBandwidth | None = None) -> ChannelResponse:
    """Unit responses of a single-input channel filter (see :class:`ChannelResponse`).

    Parameters
    ----------
    sys : LinearSystem
        From :func:`channel_filter`.
    dt_s : float
    n, k0 : int
        Run length and first scored sample.
    bi : bool
        Compute the flicker response.
    gm_tau_s : float, optional
        Gauss–Markov correlation time [s].
    motion : ndarray (n, 3), optional
        The body rate per axis [rad/s] (each axis through this channel).
    swing_hz : float, optional
        Frequency of the amplitude ratio and phase [Hz].
    sensor : SensorBandwidth, optional
        The gyros' own filter (one, as every gyro is alike), cascaded before the
        channel filter: a per-sample combination of alike filtered gyros is the
        filtered combination.
    """
    est_sys = sys
    sys = cascade(sys, sensor)

    def tri(m: Moments):
        return (float(m.ms_window[0, 0]), float(m.sum_window[0, 0]), float(m.sum_full[0, 0]))
    one, zero = np.ones((1, 1)), np.zeros((1, 1))
    none = np.zeros(1)
    unit = NoiseSources(R=one, Qb=zero, gm_sigma_rad_s=none, gm_tau_s=np.ones(1), bi_rad_s=none,
                        dt_s=dt_s)
    white = tri(error_moments(sys, unit, n, k0, white=True, walk=False, gm=False))
    walk = tri(error_moments(sys, replace_noise(unit, R=zero, Qb=one), n, k0, white=False,
                             walk=True, gm=False))
    flick = tri(flicker_moments(sys, np.ones(1), n, k0, dt_s)) if bi else (0.0, 0.0, 0.0)
    gmr = (0.0, 0.0, 0.0)
    if gm_tau_s is not None and gm_tau_s > 0:
        gmr = tri(error_moments(sys, replace_noise(unit, R=zero, gm_sigma_rad_s=np.ones(1),
                                                   gm_tau_s=np.array([gm_tau_s])),
                                n, k0, white=False, walk=False, gm=True))
    mot = None
    if motion is not None:
        w = np.asarray(motion, dtype=float)
        est = np.zeros(w.shape, dtype=complex if np.iscomplexobj(sys.lam) else float)
        x = sys.X0 @ w[:1]                                            # x̂_{-1} = X0 z_0 (per axis)
        # x̂ in modal coordinates: m_k = λ m_{k-1} + (S⁻¹K) z_k
        m0 = sys.S_inv @ x
        bk = sys.S_inv @ sys.K
        cs = sys.C @ sys.S
        for i, lam in enumerate(sys.lam):
            y, _ = signal.lfilter([1.0], [1.0, -lam], bk[i, 0] * w, axis=0,
                                  zi=(lam * m0[i]) * np.ones((1, 3)))
            est += cs[0, i] * y
        e = np.real(est) - w
        mot = (np.mean(e[k0:] ** 2, axis=0), np.sum(e[k0:], axis=0), np.sum(e, axis=0))
    split: dict[str, float | None] = {"amplitude_ratio": None, "phase_deg": None}
    if swing_hz is not None:
        te = complex(est_sys.response(2.0 * np.pi * swing_hz * dt_s)[0, 0, 0])
        fs = 1.0 + 0j if sensor is None else complex(sensor.response(swing_hz)[0])
        split = {}
        for key, z in (("", te * fs), ("estimator_", te), ("sensor_", fs)):
            split[f"{key}amplitude_ratio"] = float(abs(z))
            split[f"{key}phase_deg"] = float(-np.degrees(np.angle(z)))
    return ChannelResponse(white=white, walk=walk, flicker=flick, gauss_markov=gmr, motion=mot,
                           dc_gain=float(sys.dc_gain()[0, 0]), **split)


def replace_noise(noise: NoiseSources, **kw) -> NoiseSources:
    """A copy of ``noise`` with some fields replaced."""
    return replace(noise, **kw)
