"""The sensor's response in the analytic predictor: the gyros' bandwidth cascaded before the
estimator (:func:`cascade`), the swing response through both, and the deterministic errors
(g-sensitivity [(rad/s)/(m/s²)] on the specific force, the declared deterministic terms on a
motion).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import block_diag

from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.sensor import g_sensitivity_bias
from gyroarray.effects.terms import (ForceTerm, Motion)
from gyroarray.design.noise_sources import (AXES, NoiseSources, SensorBandwidth, force_coeffs)


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
    return force_coeffs(det, n_gyros)


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
