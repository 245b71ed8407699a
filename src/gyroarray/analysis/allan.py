"""Overlapping Allan and Hadamard deviations of gyro rate, with confidence
intervals and IEEE Std 952 noise-term fits.

Rate samples play the role of fractional frequency ``y`` and the integrated
angle the role of phase ``x`` in the time-and-frequency literature (NIST SP
1065).  SI inside: rate [rad/s], angle [rad], averaging time ``tau`` [s];
the only datasheet-unit output is :meth:`AllanAnalysis.to_json_dict` (via
:mod:`gyroarray.core.units`).

Public API
----------
* :func:`oadev`, :func:`ohdev`: deviation of rate samples;
  :func:`deviation_from_angle`: the same from angle (phase) samples.
  All return an :class:`AllanResult`.
* :func:`averaging_factors`: the averaging factors ``m`` of a tau request.
* :func:`edf`, :func:`edf_simple`, :func:`edf_greenhall`: equivalent degrees
  of freedom; :func:`confidence_interval`: chi-square bounds.
* :func:`allan_analysis`: deviation + noise fit + confidence intervals in
  one call (what the CLI uses); its log-log figure is
  :func:`gyroarray.reports.allan_plots.plot_allan`.

The sums run in a numba kernel (:mod:`gyroarray.analysis._kernels`): cache
blocked, SIMD, parallel over blocks and bit-identical for any number of
threads.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy import special

from gyroarray.core import units
from gyroarray.core.errors import InputError

from gyroarray.analysis import _kernels
from gyroarray.analysis.noise_fit import NoiseFit, fit_noise_terms

__all__ = [
    "KINDS",
    "MAX_FIT_TAUS",
    "ONE_SIGMA",
    "fit_tau_count",
    "AllanResult",
    "AllanAnalysis",
    "averaging_factors",
    "oadev",
    "ohdev",
    "deviation",
    "deviation_from_angle",
    "edf",
    "edf_simple",
    "edf_greenhall",
    "confidence_interval",
    "allan_analysis",
    "analysis_of",
]

#: Deviation kinds and the order of the phase difference each one uses:
#: overlapping Allan (second difference) and overlapping Hadamard (third).
KINDS = {"oadev": 2, "ohdev": 3}

#: Confidence of a 1-sigma band, erf(1/sqrt(2)) = 0.6827 (Stable32's default).
ONE_SIGMA = math.erf(1.0 / math.sqrt(2.0))

# Normalisation of the sum of squared differences: 1/2 (Allan), 1/6 (Hadamard)
# = 1 / sum of squared binomial weights of the (d-1)-th difference of rate.
_NORM = {2: 2.0, 3: 6.0}
# Smallest number of summands of a reported point (as allantools).
_MIN_TERMS = 2

#: Most taus :func:`allan_analysis` fits at once: the generalised least-squares noise fit
#: costs about the cube of the number of taus per iteration (3000 samples: 43 taus 1 s,
#: 136 taus over a minute; a dense curve beyond this shows nothing an octave grid hides).
MAX_FIT_TAUS = 64


# --------------------------------------------------------------------------
# Deviations


@dataclass(frozen=True)
class AllanResult:
    """Overlapping Allan or Hadamard deviation at a set of averaging times.

    Parameters
    ----------
    kind : str
        "oadev" (overlapping Allan) or "ohdev" (overlapping Hadamard).
    tau0_s : float
        Sample interval [s].
    n_phase : int
        Number of phase (angle) points the sums ran over; rate input of
        ``n`` samples gives ``n + 1``.
    m : numpy.ndarray of int64
        Averaging factors, ``tau = m * tau0``.
    taus_s : numpy.ndarray
        Averaging times [s].
    dev : numpy.ndarray
        Deviation [rad/s] (for rate in rad/s; in general the unit of rate).
    n_terms : numpy.ndarray of int64
        Number of squared differences summed, ``n_phase - d m`` (d = 2 for
        Allan, 3 for Hadamard): Stable32's ``#`` column.
    """

    kind: str
    tau0_s: float
    n_phase: int
    m: np.ndarray = field(repr=False)
    taus_s: np.ndarray
    dev: np.ndarray
    n_terms: np.ndarray = field(repr=False)

    @property
    def avar(self) -> np.ndarray:
        """Variance ``dev**2`` [(rad/s)²]."""
        return self.dev ** 2


def check_kind(kind: str) -> int:
    if kind not in KINDS:
        raise InputError(f"unknown deviation kind {kind!r}; expected one of "
                         f"{sorted(KINDS)}")
    return KINDS[kind]


def check_tau0(tau0_s) -> float:
    try:
        tau0 = float(tau0_s)
    except (TypeError, ValueError):
        raise InputError(f"tau0_s must be a number, got {tau0_s!r}") from None
    if not (math.isfinite(tau0) and tau0 > 0):
        raise InputError(f"tau0_s must be finite and positive, got {tau0_s!r}")
    return tau0


def as_series(data, name: str) -> np.ndarray:
    """1-D float64 C-contiguous view (copy only when needed)."""
    arr = np.ascontiguousarray(data, dtype=np.float64)
    if arr.ndim != 1:
        raise InputError(f"{name} must be a 1-D array, got shape {arr.shape}")
    return arr


def first_non_finite(arr: np.ndarray, name: str) -> InputError:
    i = int(np.flatnonzero(~np.isfinite(arr))[0])
    return InputError(f"{name} has a non-finite value ({arr[i]!r}) at index "
                      f"{i}")


def averaging_factors(n_phase: int, tau0_s: float, taus="octave",
                      kind: str = "oadev") -> np.ndarray:
    """Averaging factors ``m`` (``tau = m tau0``) for a tau request.

    Parameters
    ----------
    n_phase : int
        Number of phase points (rate samples + 1).
    tau0_s : float
        Sample interval [s].
    taus : "octave", int or sequence of float, default "octave"
        ``"octave"``: ``m = 1, 2, 4, ...``; an int ``count``: ``count``
        log-spaced values of ``m`` from 1 to the largest allowed, rounded to
        integers and de-duplicated (so possibly fewer than ``count`` at small
        ``m``); a sequence: averaging times [s], strictly increasing, each an
        integer multiple of ``tau0_s``.
    kind : {"oadev", "ohdev"}, default "oadev"
        Sets the largest allowed ``m``.

    Returns
    -------
    numpy.ndarray of int64
        Increasing averaging factors, each with at least 2 summands
        (``n_phase - d m >= 2``, d = 2 Allan, 3 Hadamard; the allantools
        rule, so octave requests give the same taus as ``allantools``).

    Raises
    ------
    InputError
        Unknown keyword, count < 1, a tau that is not a positive integer
        multiple of ``tau0_s`` (relative tolerance 1e-9), not increasing, or
        too long for the data.

    Notes
    -----
    Stable32 stops earlier (``m <= n_phase/4`` for OADEV/OHDEV); the last
    octaves here have few summands and wide confidence intervals, which the
    noise fit weights accordingly.
    """
    d = check_kind(kind)
    tau0 = check_tau0(tau0_s)
    m_max = (int(n_phase) - _MIN_TERMS) // d
    if m_max < 1:
        raise InputError(f"{n_phase - 1} samples are too few for {kind}: "
                         f"need at least {d + _MIN_TERMS - 1}")
    if isinstance(taus, str):
        if taus != "octave":
            raise InputError(f"unknown tau keyword {taus!r}; use 'octave', a "
                             "count of log-spaced taus or a list of taus [s]")
        return 2 ** np.arange(int(math.floor(math.log2(m_max))) + 1,
                              dtype=np.int64)
    if isinstance(taus, numbers.Integral) and not isinstance(taus, bool):
        if taus < 1:
            raise InputError(f"the number of taus must be at least 1, got "
                             f"{taus}")
        grid = np.logspace(0.0, math.log10(m_max), int(taus))
        return np.unique(np.clip(np.rint(grid), 1, m_max).astype(np.int64))
    try:
        t = np.asarray(taus, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"taus must be 'octave', an int or a sequence of "
                         f"numbers [s], got {taus!r}") from None
    if t.ndim != 1 or t.size == 0:
        raise InputError("taus must be a non-empty 1-D sequence of times [s]")
    if not np.all(np.isfinite(t)) or np.any(t <= 0):
        raise InputError("taus must be finite and positive [s]")
    ratio = t / tau0
    m = np.rint(ratio)
    bad = np.abs(ratio - m) > 1e-9 * np.maximum(ratio, 1.0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"tau {t[i]!r} s is not an integer multiple of "
                         f"tau0 = {tau0!r} s")
    if np.any(np.diff(m) <= 0):
        raise InputError("taus must be strictly increasing")
    if m[-1] > m_max:
        raise InputError(f"tau {t[-1]!r} s is too long for {kind} of "
                         f"{n_phase - 1} samples: the largest is "
                         f"{m_max * tau0!r} s (m = {m_max})")
    return m.astype(np.int64)


def fit_tau_count(n_phase: int, tau0_s: float, count: int, kind: str = "oadev"
                  ) -> tuple[int, str | None]:
    """The count of log-spaced taus to ask :func:`allan_analysis` for, and a note when it is
    not ``count``.

    A count gives at most as many distinct averaging factors as the record holds (``m`` up to
    about a half (Allan) or a third (Hadamard) of the samples, each an integer), and the noise
    fit takes at most :data:`MAX_FIT_TAUS`. Beyond either, the largest count within both is
    used and the note says what was asked and what is analysed.

    Parameters
    ----------
    n_phase : int
        Number of phase points (rate samples + 1).
    tau0_s : float
        Sample interval [s].
    count : int
        Log-spaced taus asked for (>= 1).
    kind : {"oadev", "ohdev"}

    Returns
    -------
    (int, str or None)
        The count to pass as ``taus``; the note (None: ``count`` as asked).
    """
    def distinct(c: int) -> int:
        return int(averaging_factors(n_phase, tau0_s, int(c), kind).size)

    got = distinct(count)
    if got >= count:
        return count, None
    samples = f"{n_phase - 1} samples give"
    if got <= MAX_FIT_TAUS:
        return count, (f"--taus {count}: {samples} only {got} distinct log-spaced averaging "
                       f"times for {kind} (integer multiples of the sample interval up to the "
                       f"longest the record holds); analysed those {got}")
    lo, hi = 1, count                       # the largest count with <= MAX_FIT_TAUS distinct
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if distinct(mid) <= MAX_FIT_TAUS:
            lo = mid
        else:
            hi = mid - 1
    return lo, (f"--taus {count}: {samples} {got} distinct log-spaced averaging times for "
                f"{kind}; analysed {distinct(lo)} of them, the most the noise fit takes "
                f"({MAX_FIT_TAUS}; its cost grows with the cube of the count)")


def _deviation_of_phase(x: np.ndarray, dev_scale: float, tau0: float,
                        kind: str, taus) -> AllanResult:
    """Deviation of phase ``x``; ``dev = sqrt(S/(c N)) / (m dev_scale)``."""
    d = KINDS[kind]
    m = averaging_factors(x.size, tau0, taus, kind)
    sums = _kernels.difference_sums(x, m, d, _kernels.BLOCK)
    n_terms = x.size - d * m
    dev = np.sqrt(sums / (_NORM[d] * n_terms)) / (m * dev_scale)
    return AllanResult(kind=kind, tau0_s=tau0, n_phase=int(x.size), m=m,
                       taus_s=m * tau0, dev=dev, n_terms=n_terms)


def deviation(rate_rad_s, tau0_s: float, kind: str = "oadev",
              taus="octave") -> AllanResult:
    """Overlapping Allan or Hadamard deviation of rate samples.

    Parameters
    ----------
    rate_rad_s : array_like, shape (n,)
        Rate samples [rad/s] (any unit works; the deviation has the same).
    tau0_s : float
        Sample interval [s].
    kind : {"oadev", "ohdev"}, default "oadev"
        Overlapping Allan or overlapping Hadamard deviation.
    taus : "octave", int or sequence of float, default "octave"
        Averaging times; see :func:`averaging_factors`.

    Returns
    -------
    AllanResult
        Deviation [rad/s] at the requested taus.

    Raises
    ------
    InputError
        Not 1-D, non-finite values, too short, bad ``tau0_s`` or ``taus``.

    Notes
    -----
    With phase :math:`x_0 = 0`, :math:`x_{i+1} = x_i + \\tau_0 (y_i -
    \\bar y)` (:math:`N = n + 1` points; subtracting the mean rate leaves
    both deviations unchanged and keeps :math:`x` small, avoiding
    cancellation in the differences),

    .. math::

        \\sigma_y^2(m\\tau_0) = \\frac{1}{2(m\\tau_0)^2(N-2m)}
            \\sum_{i=0}^{N-2m-1}(x_{i+2m} - 2x_{i+m} + x_i)^2

        \\sigma_H^2(m\\tau_0) = \\frac{1}{6(m\\tau_0)^2(N-3m)}
            \\sum_{i=0}^{N-3m-1}(x_{i+3m} - 3x_{i+2m} + 3x_{i+m} - x_i)^2

    (NIST SP 1065 eqs. 11 and 20; IEEE Std 952 Annex C for gyros).  The
    Hadamard variance cancels a constant rate ramp.

    References
    ----------
    .. [1] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST
       SP 1065, 2008, sec. 5.2.4 and 5.2.7.
    .. [2] IEEE Std 952-1997, Annex C.
    .. [3] D. W. Allan, "Statistics of atomic frequency standards",
       Proc. IEEE 54(2), 1966.
    """
    d = check_kind(kind)
    tau0 = check_tau0(tau0_s)
    y = as_series(rate_rad_s, "rate")
    if y.size < d + _MIN_TERMS - 1:
        raise InputError(f"{y.size} rate samples are too few for {kind}: "
                         f"need at least {d + _MIN_TERMS - 1}")
    mean = float(np.mean(y))
    if not math.isfinite(mean):  # any NaN/inf makes the mean non-finite
        raise first_non_finite(y, "rate")
    x = np.empty(y.size + 1)
    _kernels.integrate_rate(y, mean, x)
    # x is in rate x samples; tau0 cancels: dev = sqrt(S/(c N)) / m.
    return _deviation_of_phase(x, 1.0, tau0, kind, taus)


def oadev(rate_rad_s, tau0_s: float, taus="octave") -> AllanResult:
    """Overlapping Allan deviation of rate samples.

    ``deviation(rate_rad_s, tau0_s, "oadev", taus)``; see :func:`deviation`
    for the math and references.

    Parameters
    ----------
    rate_rad_s : array_like, shape (n,)
        Rate samples [rad/s].
    tau0_s : float
        Sample interval [s].
    taus : "octave", int or sequence of float, default "octave"
        Averaging times; see :func:`averaging_factors`.

    Returns
    -------
    AllanResult
        Deviation [rad/s] at the requested taus.
    """
    return deviation(rate_rad_s, tau0_s, "oadev", taus)


def ohdev(rate_rad_s, tau0_s: float, taus="octave") -> AllanResult:
    """Overlapping Hadamard deviation of rate samples.

    ``deviation(rate_rad_s, tau0_s, "ohdev", taus)``; see :func:`deviation`
    for the math and references.

    Parameters
    ----------
    rate_rad_s : array_like, shape (n,)
        Rate samples [rad/s].
    tau0_s : float
        Sample interval [s].
    taus : "octave", int or sequence of float, default "octave"
        Averaging times; see :func:`averaging_factors`.

    Returns
    -------
    AllanResult
        Deviation [rad/s] at the requested taus.
    """
    return deviation(rate_rad_s, tau0_s, "ohdev", taus)


def deviation_from_angle(angle_rad, tau0_s: float, kind: str = "oadev",
                         taus="octave") -> AllanResult:
    """Overlapping Allan or Hadamard deviation of angle (phase) samples.

    Parameters
    ----------
    angle_rad : array_like, shape (N,)
        Integrated angle [rad] sampled every ``tau0_s`` (the time-and-
        frequency "phase" x; for clocks, time error [s]).
    tau0_s : float
        Sample interval [s].
    kind : {"oadev", "ohdev"}, default "oadev"
        Overlapping Allan or overlapping Hadamard deviation.
    taus : "octave", int or sequence of float, default "octave"
        Averaging times; see :func:`averaging_factors`.

    Returns
    -------
    AllanResult
        Deviation of the rate [rad/s] (fractional frequency for clock phase
        in s).

    Raises
    ------
    InputError
        Not 1-D, non-finite values, too short, bad ``tau0_s`` or ``taus``.

    Notes
    -----
    The formulas of :func:`deviation` applied to the given ``x`` as is (no
    mean or trend removal).

    References
    ----------
    .. [1] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST
       SP 1065, 2008, eqs. 11 and 20.
    """
    d = check_kind(kind)
    tau0 = check_tau0(tau0_s)
    x = as_series(angle_rad, "angle")
    if x.size < d + _MIN_TERMS:
        raise InputError(f"{x.size} angle samples are too few for {kind}: "
                         f"need at least {d + _MIN_TERMS}")
    if not np.all(np.isfinite(x)):
        raise first_non_finite(x, "angle")
    return _deviation_of_phase(x, tau0, tau0, kind, taus)


# --------------------------------------------------------------------------
# Equivalent degrees of freedom and confidence intervals


def edf_simple(n_phase, m, alpha) -> np.ndarray:
    """EDF of the overlapping Allan variance, simple approximations.

    Parameters
    ----------
    n_phase : int or array_like
        Number of phase points N.
    m : int or array_like
        Averaging factor (``tau = m tau0``).
    alpha : int or array_like
        Noise type, exponent of the rate PSD ``S(f) ~ f^alpha``: +2 white
        PM, +1 flicker PM, 0 white FM, -1 flicker FM, -2 random-walk FM.

    Returns
    -------
    numpy.ndarray
        Equivalent degrees of freedom [-], broadcast over the inputs.

    Raises
    ------
    InputError
        ``alpha`` outside +2..-2.

    Notes
    -----
    NIST SP 1065 Table 5 (Howe, Allan, Barnes 1981), for the overlapping
    Allan variance only:

    * WPM: :math:`(N+1)(N-2m)/(2(N-m))`
    * FPM: :math:`\\exp\\sqrt{\\ln\\frac{N-1}{2m}\\,
      \\ln\\frac{(2m+1)(N-1)}{4}}`
    * WFM: :math:`\\left[\\frac{3(N-1)}{2m} - \\frac{2(N-2)}{N}\\right]
      \\frac{4m^2}{4m^2+5}`
    * FFM: :math:`2(N-2)/(2.3N-4.9)` for m = 1,
      :math:`5N^2/(4m(N+3m))` for m >= 2
    * RWFM: :math:`\\frac{N-2}{m(N-3)^2}
      \\left[(N-1)^2 - 3m(N-1) + 4m^2\\right]`

    References
    ----------
    .. [1] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST
       SP 1065, 2008, sec. 5.3.3, Table 5.
    .. [2] D. A. Howe, D. W. Allan, J. A. Barnes, "Properties of signal
       sources and measurement methods", Proc. 35th Freq. Control Symp., 1981.
    """
    n, m, a = np.broadcast_arrays(np.asarray(n_phase, dtype=float),
                                  np.asarray(m, dtype=float),
                                  np.asarray(alpha))
    if not np.all(np.isin(a, (2, 1, 0, -1, -2))):
        raise InputError("alpha must be one of +2, +1, 0, -1, -2")
    out = np.empty(n.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        wpm = (n + 1) * (n - 2 * m) / (2 * (n - m))
        fpm = np.exp(np.sqrt(np.log((n - 1) / (2 * m))
                             * np.log((2 * m + 1) * (n - 1) / 4)))
        wfm = ((3 * (n - 1) / (2 * m) - 2 * (n - 2) / n)
               * (4 * m ** 2 / (4 * m ** 2 + 5)))
        ffm = np.where(m == 1, 2 * (n - 2) / (2.3 * n - 4.9),
                       5 * n ** 2 / (4 * m * (n + 3 * m)))
        rwfm = ((n - 2) / (m * (n - 3) ** 2)
                * ((n - 1) ** 2 - 3 * m * (n - 1) + 4 * m ** 2))
    for value, formula in ((2, wpm), (1, fpm), (0, wfm), (-1, ffm),
                           (-2, rwfm)):
        out = np.where(a == value, formula, out)
    return out


# Greenhall & Riley (2003) tables for unmodified variances, keyed by
# (alpha, d): Table 2 (a0, a1) and Table 3 (b0, b1, alpha = +1 only).
_GREENHALL_T2 = {
    (1, 2): (790.0, 410.0), (1, 3): (9950.0, 6520.0),
    (0, 2): (2.0 / 3.0, 1.0 / 3.0), (0, 3): (7.0 / 9.0, 1.0 / 2.0),
    (-1, 2): (0.852, 0.375), (-1, 3): (0.997, 0.617),
    (-2, 2): (1.079, 0.368), (-2, 3): (1.033, 0.607),
}
_GREENHALL_T3 = {2: (15.23, 12.0), 3: (47.8, 40.0)}
_GREENHALL_JMAX = 100


def _gh_sw(t: np.ndarray, alpha: int) -> np.ndarray:
    """Greenhall's sw(t) (eq. 7), up to a sign that cancels in the edf."""
    a = np.abs(np.asarray(t, dtype=float))
    if alpha % 2 == 0:  # -|t|, |t|^3, -|t|^5, ... for alpha = 2, 0, -2, ...
        return a ** (3 - alpha)
    with np.errstate(divide="ignore", invalid="ignore"):  # t^2 ln|t|, ...
        return np.where(a > 0, a ** (3 - alpha) * np.log(a), 0.0)


def _gh_sx(t: np.ndarray, f: float, alpha: int) -> np.ndarray:
    """sx(t) (eq. 8): the filter of the averaging, ``f = inf`` as the limit."""
    if math.isinf(f):
        return _gh_sw(t, alpha + 2)
    return f * f * (2.0 * _gh_sw(t, alpha) - _gh_sw(t - 1.0 / f, alpha)
                    - _gh_sw(t + 1.0 / f, alpha))


def _gh_sz(t: float | np.ndarray, f: float, alpha: int, d: int) -> np.ndarray:
    """sz(t) (eq. 9): the d-th difference, binomial weights of order 2d."""
    t = np.asarray(t, dtype=float)
    out = np.zeros_like(t)
    for k in range(-d, d + 1):
        out = out + (-1) ** k * special.comb(2 * d, d + k, exact=True) \
            * _gh_sx(t + k, f, alpha)
    return out


def _gh_basic_sum(j: int, big_m: float, s: float, f: float, alpha: int,
                  d: int) -> float:
    """BasicSum (eq. 10)."""
    first = _gh_sz(0.0, f, alpha, d) ** 2
    second = (1.0 - j / big_m) * _gh_sz(j / s, f, alpha, d) ** 2
    jj = np.arange(1, j)
    third = np.sum(2.0 * (1.0 - jj / big_m) * _gh_sz(jj / s, f, alpha, d) ** 2)
    return float(first + second + third)


_GREENHALL_T1 = {   # Table 1 (modified variances, d = 2): (a0, a1) by alpha
    2: (7.0 / 9.0, 0.5), 1: (0.997, 0.616), 0: (1.033, 0.607), -1: (1.048, 0.534),
    -2: (1.302, 0.535)}


def _edf_greenhall_modified(n: int, m: int, alpha: int, d: int) -> float:
    """Greenhall's EDF for the overlapping modified variance (S = m, F = 1; case 1)."""
    big_m = n - (d + 1) * m + 1           # M = 1 + floor(S (N - L)/m), L = m + d m
    s = float(m)
    j = min(big_m, (d + 1) * m)
    r = big_m / s
    jmax = _GREENHALL_JMAX
    if j <= jmax:
        inv = (_gh_basic_sum(j, big_m, s, 1.0, alpha, d)
               / (float(_gh_sz(0.0, 1.0, alpha, d)) ** 2 * big_m))
    elif r > d + 1:
        a0, a1 = _GREENHALL_T1[alpha]
        inv = (a0 - a1 / r) / r
    else:
        mp = jmax / r
        inv = (_gh_basic_sum(jmax, jmax, mp, 1.0, alpha, d)
               / (float(_gh_sz(0.0, 1.0, alpha, d)) ** 2 * jmax))
    return 1.0 / inv


def _edf_greenhall_one(n: int, m: int, alpha: int, d: int,
                       filtered: bool) -> float:
    """Greenhall's EDF for an overlapping, unmodified variance (S = m).

    ``filtered``: filter factor F = m for alpha <= 0 where Greenhall & Riley
    use it (m (d+1) <= J_max); otherwise F = infinity.
    """
    big_m = n - d * m          # M = 1 + floor(S (N - L)/m), L = 1 + d m
    s = float(m)               # stride factor of the overlapping estimator
    j = min(big_m, (d + 1) * m)
    r = big_m / s
    jmax = _GREENHALL_JMAX
    if alpha <= 0:                                          # case 2
        if j <= jmax:
            f = float(m) if filtered and m * (d + 1) <= jmax else math.inf
            inv = (_gh_basic_sum(j, big_m, s, f, alpha, d)
                   / (float(_gh_sz(0.0, f, alpha, d)) ** 2 * big_m))
        elif r > d + 1:
            a0, a1 = _GREENHALL_T2[(alpha, d)]
            inv = (a0 - a1 / r) / r
        else:
            mp = jmax / r
            inv = (_gh_basic_sum(jmax, jmax, mp, math.inf, alpha, d)
                   / (float(_gh_sz(0.0, math.inf, alpha, d)) ** 2 * jmax))
    elif alpha == 1:                                        # case 3
        if j <= jmax:
            inv = (_gh_basic_sum(j, big_m, s, float(m), 1, d)
                   / (float(_gh_sz(0.0, float(m), 1, d)) ** 2 * big_m))
        else:
            b0, b1 = _GREENHALL_T3[d]
            norm = (b0 + b1 * math.log(m)) ** 2
            if r > d + 1:
                a0, a1 = _GREENHALL_T2[(1, d)]
                inv = (a0 - a1 / r) / (norm * r)
            else:
                mp = jmax / r
                inv = _gh_basic_sum(jmax, jmax, mp, mp, 1, d) / (norm * jmax)
    else:                                                   # case 4, WPM
        k_max = math.ceil(r)
        c2d = special.comb(2 * d, d, exact=True)
        if k_max <= d:
            k = np.arange(1 - k_max, k_max)
            w = np.array([special.comb(2 * d, d - abs(int(i)), exact=True)
                          for i in k], dtype=float) / c2d
            inv = float(np.sum((1.0 - np.abs(k) / r) * w ** 2)) / big_m
        else:
            a0 = special.comb(4 * d, 2 * d, exact=True) / c2d ** 2
            inv = (a0 - d / (2.0 * r)) / big_m
    return 1.0 / inv


def edf_greenhall(n_phase, m, alpha, d: int, *,
                  filter_factor: str = "m", modified: bool = False) -> np.ndarray:
    """EDF of an overlapping (unmodified) Allan or Hadamard variance.

    Parameters
    ----------
    n_phase : int
        Number of phase points N.
    m : int or array_like of int
        Averaging factors.
    alpha : int or array_like of int
        Noise type (rate PSD exponent), +2 .. -2, broadcast against ``m``.
    d : {2, 3}
        Order of the phase difference: 2 overlapping Allan, 3 overlapping
        Hadamard.
    filter_factor : {"m", "inf"}, default "m"
        Greenhall's filter factor F for white, flicker and random-walk FM
        (alpha <= 0).  ``"m"``: the phase is smoothed over one sample, F = m
        where Greenhall & Riley use it (:math:`m(d+1) \\le J_{max}`), as in
        Stable32 and allantools.  ``"inf"``: the phase is sampled exactly,
        which is the case for rate samples that are averages over their
        interval (the phase is their cumulative sum); for white FM this is
        the exact EDF of the estimator (see Notes).  Both agree for
        :math:`m(d+1) > 100`.
    modified : bool, default False
        The overlapping *modified* variance (MVAR for ``d = 2``): Greenhall's case 1,
        filter factor F = 1, :math:`M = N - (d+1)m + 1`, Table 1 asymptote (``d = 2`` only);
        ``filter_factor`` is then unused.

    Returns
    -------
    numpy.ndarray
        Equivalent degrees of freedom [-], shape of ``m`` and ``alpha``
        broadcast.

    Raises
    ------
    InputError
        ``d`` not 2 or 3, ``alpha`` outside +2..-2, bad ``filter_factor``,
        or fewer than one summand (``N - d m < 1``).

    Notes
    -----
    Greenhall's algorithm (Greenhall & Riley 2003, as in NIST SP 1065 sec.
    5.3.3 and Stable32) for the overlapping estimator (stride factor
    :math:`S = m`, filter factor :math:`F = m`), with
    :math:`M = N - dm` summands, :math:`J = \\min(M, (d+1)m)`,
    :math:`r = M/m`, :math:`J_{max} = 100`:

    * :math:`\\alpha \\le 0`: exact sum (eq. 10) if :math:`J \\le J_{max}`,
      with :math:`F = m` if ``filter_factor="m"`` and
      :math:`m(d+1) \\le J_{max}`, else :math:`F = \\infty`;
      else the asymptote :math:`1/\\nu = (a_0 - a_1/r)/r` (Table 2) if
      :math:`r > d+1`, else the sum with :math:`m' = J_{max}/r`,
      :math:`F=\\infty`.
    * :math:`\\alpha = 1`: the same with the :math:`(b_0 + b_1\\ln m)^2`
      normalisation of Table 3.
    * :math:`\\alpha = 2` (white PM): differences more than :math:`dm`
      apart are independent, so with :math:`K = \\lceil r\\rceil`,
      :math:`1/\\nu = \\frac1M\\sum_{|k|<K}(1 - |k|/r)\\,
      [\\binom{2d}{d-k}/\\binom{2d}{d}]^2` if :math:`K \\le d`, else
      :math:`\\frac1M[\\binom{4d}{2d}/\\binom{2d}{d}^2 - d/(2r)]`
      (the same sum over all :math:`|k| \\le d`).

    Confidence intervals with ``filter_factor="m"`` agree with Stable32's
    printed bounds (see ``tests/test_allan_ci.py``).  With ``"inf"`` the
    white-FM and white-PM values equal the exact EDF
    :math:`\\mathrm{tr}(Q)^2/\\mathrm{tr}(Q^2)` of the estimator written as
    a quadratic form :math:`y^TQy` of i.i.d. samples; with ``"m"`` they
    differ from it by up to +20 % (m = 1) and -12 % (m = 3-4) for small m.

    References
    ----------
    .. [1] C. A. Greenhall, W. J. Riley, "Uncertainty of stability variances
       based on finite differences", Proc. 35th PTTI Meeting, 2003.
    .. [2] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST
       SP 1065, 2008, sec. 5.3.3.
    """
    if d not in (2, 3):
        raise InputError(f"d must be 2 (Allan) or 3 (Hadamard), got {d!r}")
    if filter_factor not in ("m", "inf"):
        raise InputError(f"filter_factor must be 'm' or 'inf', got "
                         f"{filter_factor!r}")
    filtered = filter_factor == "m"
    mm, aa = np.broadcast_arrays(np.asarray(m, dtype=np.int64),
                                 np.asarray(alpha, dtype=np.int64))
    if not np.all(np.isin(aa, (2, 1, 0, -1, -2))):
        raise InputError("alpha must be one of +2, +1, 0, -1, -2")
    n = int(n_phase)
    if modified and d != 2:
        raise InputError("the modified-variance EDF is implemented for d = 2 (MVAR) only")
    if np.any(mm < 1) or np.any(n - (d + modified) * mm + modified < 1):
        raise InputError("edf needs m >= 1 and at least one summand "
                         "(n_phase - d m >= 1; modified: n_phase - 3 m + 1 >= 1)")
    out = np.empty(mm.shape)
    cache: dict = {}
    for idx in np.ndindex(mm.shape):
        key = (int(mm[idx]), int(aa[idx]))
        if key not in cache:
            cache[key] = (_edf_greenhall_modified(n, key[0], key[1], d) if modified else
                          _edf_greenhall_one(n, key[0], key[1], d, filtered))
        out[idx] = cache[key]
    return out


def edf(kind: str, n_phase: int, m, alpha, *,
        method: str = "sampled") -> np.ndarray:
    """Equivalent degrees of freedom of an overlapping deviation.

    Parameters
    ----------
    kind : {"oadev", "ohdev"}
        The deviation.
    n_phase : int
        Number of phase points (``AllanResult.n_phase``).
    m : int or array_like of int
        Averaging factors.
    alpha : int or array_like of int
        Noise type per factor (rate PSD exponent +2 .. -2).
    method : {"sampled", "stable32", "simple"}, default "sampled"
        ``"sampled"``: :func:`edf_greenhall` with ``filter_factor="inf"``
        (phase = cumulative sum of rate samples, exact for white noise);
        ``"stable32"``: :func:`edf_greenhall` with ``filter_factor="m"``
        (reproduces Stable32 and allantools); ``"simple"``:
        :func:`edf_simple` (NIST SP 1065 Table 5, "oadev" only).

    Returns
    -------
    numpy.ndarray
        Equivalent degrees of freedom [-].

    Raises
    ------
    InputError
        Unknown kind or method, or "simple" with "ohdev".

    References
    ----------
    .. [1] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST
       SP 1065, 2008, sec. 5.3.3.
    .. [2] C. A. Greenhall, W. J. Riley, "Uncertainty of stability variances
       based on finite differences", Proc. 35th PTTI Meeting, 2003.
    """
    d = check_kind(kind)
    if method == "sampled":
        return edf_greenhall(n_phase, m, alpha, d, filter_factor="inf")
    if method == "stable32":
        return edf_greenhall(n_phase, m, alpha, d, filter_factor="m")
    if method == "simple":
        if kind != "oadev":
            raise InputError("the simple EDF formulas (NIST SP 1065 Table 5) "
                             "exist for the overlapping Allan variance only")
        return edf_simple(n_phase, m, alpha)
    raise InputError(f"unknown edf method {method!r}; expected 'sampled', "
                     "'stable32' or 'simple'")


def confidence_interval(dev, edf_, confidence: float = ONE_SIGMA
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Chi-square confidence interval of a deviation.

    Parameters
    ----------
    dev : array_like
        Estimated deviation [rad/s].
    edf_ : array_like
        Equivalent degrees of freedom [-] (positive).
    confidence : float, default :data:`ONE_SIGMA` (0.6827)
        Two-sided confidence level, in (0, 1).

    Returns
    -------
    (low, high) : tuple of numpy.ndarray
        Bounds of the deviation [rad/s].

    Raises
    ------
    InputError
        ``confidence`` outside (0, 1) or non-positive ``edf_``.

    Notes
    -----
    :math:`\\nu\\hat\\sigma^2/\\sigma^2 \\sim \\chi^2_\\nu`, so with
    :math:`p = (1 - c)/2`,

    .. math::

        \\sigma_{low} = \\hat\\sigma\\sqrt{\\nu/\\chi^2_{1-p,\\nu}},\\qquad
        \\sigma_{high} = \\hat\\sigma\\sqrt{\\nu/\\chi^2_{p,\\nu}}.

    References
    ----------
    .. [1] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST
       SP 1065, 2008, sec. 5.3.2, eq. 45.
    """
    if not (0.0 < confidence < 1.0):
        raise InputError(f"confidence must be in (0, 1), got {confidence!r}")
    dev = np.asarray(dev, dtype=float)
    nu = np.asarray(edf_, dtype=float)
    if np.any(~(nu > 0)):
        raise InputError("edf must be positive")
    p = 0.5 * (1.0 - confidence)
    # chi-square quantiles via special.chdtri (upper-tail inverse):
    # chi2.ppf(q, nu) = chdtri(nu, 1 - q); scipy.stats is not imported for it
    # (half a second of CLI start-up).
    low = dev * np.sqrt(nu / special.chdtri(nu, p))
    high = dev * np.sqrt(nu / special.chdtri(nu, 1.0 - p))
    return low, high


# --------------------------------------------------------------------------
# One-call analysis and plot


@dataclass(frozen=True)
class AllanAnalysis:
    """Deviation curve with confidence intervals and noise fit (SI units).

    Parameters
    ----------
    kind : str
        "oadev" or "ohdev"; the ``adev_*`` fields hold this deviation.
    tau0_s : float
        Sample interval [s].
    taus_s : numpy.ndarray
        Averaging times [s].
    m : numpy.ndarray of int64
        Averaging factors.
    n_terms : numpy.ndarray of int64
        Summands per point.
    adev_rad_s : numpy.ndarray
        Deviation [rad/s].
    ci_low_rad_s, ci_high_rad_s : numpy.ndarray
        Confidence bounds [rad/s] at level ``confidence``.
    edf : numpy.ndarray
        Equivalent degrees of freedom per point [-] (:func:`edf`, default
        method "sampled"), for the noise type in ``fit.alpha``.
    confidence : float
        Two-sided confidence level of the bounds.
    fit : NoiseFit
        IEEE Std 952 noise terms.
    info : dict, optional
        JSON-ready extras merged into :meth:`to_json_dict` (e.g. the lag-1 noise
        identification per tau, the EDF formula; :mod:`~gyroarray.analysis.deviations`).
    """

    kind: str
    tau0_s: float
    taus_s: np.ndarray
    m: np.ndarray = field(repr=False)
    n_terms: np.ndarray = field(repr=False)
    adev_rad_s: np.ndarray = field(repr=False)
    ci_low_rad_s: np.ndarray = field(repr=False)
    ci_high_rad_s: np.ndarray = field(repr=False)
    edf: np.ndarray = field(repr=False)
    confidence: float
    fit: NoiseFit
    info: dict = field(default_factory=dict, repr=False, compare=False)

    def to_json_dict(self) -> dict:
        """JSON-ready dict in datasheet units (the CLI edge).

        Returns
        -------
        dict
            ``kind``, ``confidence``, ``taus_s`` [s], ``adev_deg_h``,
            ``ci_low_deg_h``, ``ci_high_deg_h`` [deg/h], ``edf`` [-] as lists,
            and ``fit``: :meth:`NoiseFit.to_datasheet_dict`.
        """
        def deg_h(a):
            return [float(v) for v in units.rad_s_to_deg_h(np.asarray(a))]
        return {
            "kind": self.kind,
            "confidence": float(self.confidence),
            "taus_s": [float(t) for t in self.taus_s],
            "adev_deg_h": deg_h(self.adev_rad_s),
            "ci_low_deg_h": deg_h(self.ci_low_rad_s),
            "ci_high_deg_h": deg_h(self.ci_high_rad_s),
            "edf": [float(v) for v in self.edf],
            "fit": self.fit.to_datasheet_dict(),
            **self.info,
        }


def allan_analysis(rate_rad_s, tau0_s: float, taus="octave",
                   kind: str = "oadev", *, confidence: float = ONE_SIGMA,
                   terms: Sequence[str] | None = None,
                   fit_method: str = "gls",
                   edf_method: str = "sampled") -> AllanAnalysis:
    """Deviation, confidence intervals and IEEE Std 952 noise fit in one call.

    Parameters
    ----------
    rate_rad_s : array_like, shape (n,)
        Rate samples of one gyro [rad/s].
    tau0_s : float
        Sample interval [s].
    taus : "octave", int or sequence of float, default "octave"
        Averaging times; see :func:`averaging_factors`.
    kind : {"oadev", "ohdev"}, default "oadev"
        Overlapping Allan or overlapping Hadamard deviation.
    confidence : float, default :data:`ONE_SIGMA`
        Two-sided level of ``ci_low_rad_s``/``ci_high_rad_s`` (1-sigma band,
        as Stable32).
    terms : sequence of str, optional
        Noise terms to fit (subset of ``("q", "n", "b", "k", "r")``);
        default all the deviation can see.
    fit_method : {"gls", "wls"}, default "gls"
        Least squares with (``"gls"``) or without (``"wls"``) the
        correlation between the estimates at different taus; see
        :func:`~gyroarray.analysis.noise_fit.fit_noise_terms`.
    edf_method : {"sampled", "stable32", "simple"}, default "sampled"
        Equivalent degrees of freedom used for the weights and the
        confidence intervals; see :func:`edf` ("stable32" reproduces
        Stable32's bounds; "simple" only for "oadev").

    Returns
    -------
    AllanAnalysis

    Raises
    ------
    InputError
        Bad input (see :func:`deviation`, :func:`fit_noise_terms`).

    Notes
    -----
    The EDF of each point depends on the noise type there, which depends on
    the fit, whose weights depend on the EDF.  :func:`fit_noise_terms`
    iterates: first every point is taken as white FM; after each fit the
    term contributing most to the fitted variance at a tau sets its noise
    type (quantization: white PM, ARW: white FM, bias instability: flicker
    FM, RRW and rate ramp: random-walk FM), the EDF (:func:`edf`, Greenhall's
    algorithm for exactly sampled phase) is recomputed and the fit repeated
    until the types settle.  The confidence interval of each point uses the
    final EDF.  The fit is a generalised least squares that accounts for
    the correlation between the estimates at different taus, and adds a
    relative model error when the IEEE terms cannot explain the curve
    (``fit.model_error``; real sensors typically need 5-30%), so that the
    reported coefficient sigmas stay honest.

    References
    ----------
    .. [1] IEEE Std 952-1997, Annex C.
    .. [2] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST
       SP 1065, 2008.
    .. [3] C. A. Greenhall, W. J. Riley, "Uncertainty of stability variances
       based on finite differences", Proc. 35th PTTI Meeting, 2003.
    """
    res = deviation(rate_rad_s, tau0_s, kind, taus)
    return analysis_of(res, confidence=confidence, terms=terms, fit_method=fit_method,
                       edf_method=edf_method)


def analysis_of(res: AllanResult, *, confidence: float = ONE_SIGMA,
                terms: Sequence[str] | None = None, fit_method: str = "gls",
                edf_method: str = "sampled") -> AllanAnalysis:
    """The confidence intervals and noise fit of a computed deviation (the second half of
    :func:`allan_analysis`, for a deviation computed elsewhere, e.g. streamed from a file by
    :mod:`gyroarray.analysis.allan_stream`).

    Parameters
    ----------
    res : AllanResult
        The deviation [rad/s] at its taus, with ``n_phase`` and ``m``.
    confidence, terms, fit_method, edf_method
        As :func:`allan_analysis`.

    Returns
    -------
    AllanAnalysis
    """
    kind = res.kind
    if np.any(res.dev <= 0):
        i = int(np.flatnonzero(res.dev <= 0)[0])
        raise InputError(f"the {kind} is zero at tau = {float(res.taus_s[i]):g} s: "
                         "the rate is constant (or exactly linear there)")
    _check_fit_range(res.taus_s, res.dev, kind)
    fit = fit_noise_terms(
        res, lambda alpha: edf(kind, res.n_phase, res.m, alpha,
                               method=edf_method),
        terms=terms, method=fit_method)
    low, high = confidence_interval(res.dev, fit.edf, confidence)
    return AllanAnalysis(kind=kind, tau0_s=res.tau0_s, taus_s=res.taus_s,
                         m=res.m, n_terms=res.n_terms, adev_rad_s=res.dev,
                         ci_low_rad_s=low, ci_high_rad_s=high, edf=fit.edf,
                         confidence=float(confidence), fit=fit)


#: The noise fit works with tau^-2 .. tau^2 and deviation^2: taus [s] and
#: deviations [rad/s] must lie within these bounds for those to be normal doubles.
_FIT_RANGE = (1e-150, 1e150)


def _check_fit_range(taus, dev, kind: str) -> None:
    """Refuse taus or deviations whose squares (and inverse squares) a double cannot hold."""
    lo, hi = _FIT_RANGE
    for name, values, unit in (("tau", taus, "s"), (kind, dev, "rad/s")):
        bad = ~((values > lo) & (values < hi))
        if bad.any():
            raise InputError(f"cannot fit noise terms: {name} = {float(values[bad][0]):g} {unit} is "
                             f"outside [{lo:g}, {hi:g}] (the fit squares it)")
