"""Scalar channels, the fast path of the design search: one body axis's filter
(:func:`channel_filter`: low-pass or steady-state KF at a bandwidth [Hz]) and its unit
responses to white, walk, flicker and Gauss–Markov noise and to the motion
(:class:`ChannelResponse`), so that every layout is a weighted sum of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from gyroarray.design.moments import (Moments, error_moments, flicker_moments)
from gyroarray.design.noise_sources import (NoiseSources, SensorBandwidth, replace_noise)
from gyroarray.design.sensor_response import cascade


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
                     sensor: SensorBandwidth | None = None,
                     flicker_model: str = "circular") -> ChannelResponse:
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
    flicker_model : {"circular", "kasdin"}
        The flicker model of the flicker response (:func:`gyroarray.design.moments.flicker_moments`).
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
    flick = tri(flicker_moments(sys, np.ones(1), n, k0, dt_s, model=flicker_model)) if bi else (0.0, 0.0, 0.0)
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
