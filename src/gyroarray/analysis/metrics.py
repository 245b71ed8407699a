"""Scoring metrics of a rate estimate against the table truth (pure functions, SI).

The same metrics score every estimator and the single gyros, per body axis:

* 1σ error and mean error of ``estimate − truth`` (paper 002, Eq. 19: the
  standard deviation of the estimated error) [rad/s];
* attenuation and phase lag at a swing frequency: the amplitude and phase of
  a least-squares sinusoid fitted to the estimate, against the same fit to
  the truth [-], [rad];
* noise density of the error from a Welch PSD [rad/s/√Hz];
* Allan noise terms of the error (ARW, bias instability, RRW with their 1σ)
  through :func:`gyroarray.analysis.allan.allan_analysis`.

References
----------
Paper 002 (``shared/papers/002_*.txt``), §4, Tables 3–4; paper 003 §4–5,
Tables 3–9.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from gyroarray.core.errors import InputError


@dataclass(frozen=True)
class SineFit:
    """``y ≈ a·sin(2π f t + φ) + c``.

    Attributes
    ----------
    amplitude : float
        a ≥ 0 [unit of y].
    phase_rad : float
        φ in (−π, π] [rad].
    offset : float
        c [unit of y].
    """

    amplitude: float
    phase_rad: float
    offset: float


def sine_fit(time_s, y, freq_hz: float) -> SineFit:
    """Least-squares sinusoid of known frequency plus offset.

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Times [s].
    y : array_like, shape (n,)
        Samples.
    freq_hz : float
        Frequency [Hz] (> 0).

    Notes
    -----
    Linear least squares on ``[sin ωt, cos ωt, 1]``: y = s·sin + c·cos + o
    gives a = √(s² + c²), φ = atan2(c, s).
    """
    t = np.asarray(time_s, dtype=float)
    w = 2.0 * math.pi * float(freq_hz)
    a = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    (s, c, o), *_ = np.linalg.lstsq(a, np.asarray(y, dtype=float), rcond=None)
    return SineFit(amplitude=float(math.hypot(s, c)), phase_rad=float(math.atan2(c, s)), offset=float(o))


def attenuation_and_lag(time_s, estimate, truth, freq_hz: float) -> tuple[float, float]:
    """Amplitude ratio estimate/truth [-] and phase lag [rad] at ``freq_hz``.

    The lag is the truth's phase minus the estimate's, wrapped to (−π, π]:
    positive when the estimate lags.
    """
    est, tru = sine_fit(time_s, estimate, freq_hz), sine_fit(time_s, truth, freq_hz)
    if tru.amplitude == 0.0:
        raise InputError("the truth has no component at the swing frequency")
    lag = (tru.phase_rad - est.phase_rad + math.pi) % (2.0 * math.pi) - math.pi
    return est.amplitude / tru.amplitude, lag


def noise_density(error, dt_s: float, band_hz: tuple[float, float] | None = None) -> float:
    """Noise density of an error signal [unit/√Hz] from a Welch PSD.

    Parameters
    ----------
    error : array_like, shape (n,)
        Error samples [unit].
    dt_s : float
        Sample period [s].
    band_hz : (float, float), optional
        Frequency band [Hz] over which the one-sided PSD is summarised
        (median); default 0.1 Hz to a quarter of the sample rate — below
        the KF/low-pass corner of a 100 Hz array, above the bias drift.

    Returns
    -------
    float
        √(median PSD) in the band [unit/√Hz].

    Notes
    -----
    ``scipy.signal.welch`` with Hann windows of 2¹⁴ samples (or the whole
    record when shorter), 50 % overlap, one-sided density.
    """
    x = np.asarray(error, dtype=float)
    fs = 1.0 / dt_s
    lo, hi = band_hz if band_hz is not None else (0.1, fs / 4.0)
    f, p = signal.welch(x, fs=fs, nperseg=min(x.size, 2**14), detrend="constant")
    sel = (f >= lo) & (f <= hi)
    if not sel.any():
        raise InputError(f"the record is too short for a PSD in {lo:g}-{hi:g} Hz")
    return float(math.sqrt(np.median(p[sel])))
