"""The noise and the sensor the analytic predictor reads from a noise model: :class:`NoiseSources`
(per-sample covariances [rad²/s²], flicker and Gauss–Markov levels [rad/s], the deterministic
terms) and the gyros' own bandwidth (:class:`SensorBandwidth`, cut-off [Hz]), from the terms
the model's effects declare.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import signal

from gyroarray.core.sensor import bandwidth_filter, bandwidth_sos
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.terms import (CorrelationTerm, DeterministicTerm, FlickerTerm, ForceTerm, GaussMarkovTerm,
                                     SensorFilter, WalkTerm, WhiteTerm, root_sum_square)


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
    bi_corr : ndarray, shape (N, N), or None
        Correlation of the gyros' flicker processes [-] (None: independent, as simulated);
        the flicker covariance is B Bᵀ ∘ bi_corr (the design's ``--rho-bi``).
    flicker_model : {"circular", "kasdin"}
        The flicker model of the moments (:func:`gyroarray.design.moments.flicker_moments`):
        ``circular`` (the simulator's, the default) or ``kasdin`` (1/f from switch-on).
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
    bi_corr: np.ndarray | None = None
    flicker_model: str = "circular"

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
                        g_sensitivity_rad_s_per_m_s2=force_coeffs(det, n_gyros), deterministic=det)


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


def force_coeffs(det: tuple, n_gyros: int) -> np.ndarray | None:
    """The sum of the :class:`~gyroarray.effects.terms.ForceTerm` coefficients (N, 3), or None."""
    k = [np.nan_to_num(np.asarray(t.coeff_rad_s_per_m_s2, dtype=float)) for _, t in det
         if isinstance(t, ForceTerm)]
    if not k:
        return None
    return k[0] if len(k) == 1 else np.sum(k, axis=0)


def replace_noise(noise: NoiseSources, **kw) -> NoiseSources:
    """A copy of ``noise`` with some fields replaced."""
    return replace(noise, **kw)
