"""Dynamic Allan deviation (DAVAR) with fixed or adaptive window length.

A rectangular window slides along the rate record; at each window position
the overlapping Allan (or Hadamard) deviation of the data inside the window
is computed at a common set of averaging times, giving a surface
``sigma(t, tau)`` and, from it, an angle-random-walk track ``N(t)``.  The
window length is either fixed (classic DAVAR, Galleani & Tavella) or adapted
sample by sample from the kurtosis and the sliding kurtosis contribution
coefficient of the windowed data (A-DAVAR, Song et al. 2018), with the
record extended by mirroring at both ends so that edge windows have full
length.

SI inside: rate [rad/s], ``tau`` and time [s], ARW [rad/√s]; datasheet units
only in :meth:`DavarResult.to_json_dict` and the figure (through
:mod:`gyroarray.core.units`).  The deviation of every window is
:func:`gyroarray.analysis.allan.deviation` itself.

Public API
----------
* :func:`davar`: fixed, single-window or adaptive DAVAR (a
  :class:`DavarResult`).
* :class:`AdaptiveWindow`: the A-DAVAR parameters (paper defaults).
* :func:`change_nodes`: where the window reacts to a change at a known time
  (the "Beginning"/"End" nodes of the paper's Table 1).
* The paper's simulated experiment beside its Table 1 is
  ``benchmarks/davar_paper.py``.
* The heat map of ``sigma(t, tau)`` with the ARW and window-length tracks
  is :func:`gyroarray.reports.davar_plots.plot_davar`.
"""

from __future__ import annotations

import contextlib
import functools
import math
import numbers
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy import special

from gyroarray.core.jit import numba, njit
from gyroarray.core import units
from gyroarray.core.errors import InputError

from gyroarray.analysis import _kernels
from gyroarray.analysis.allan import (KINDS, ONE_SIGMA, AllanResult, as_series, check_kind,
                                      check_tau0, first_non_finite, averaging_factors,
                                      confidence_interval, deviation, edf)
from gyroarray.analysis.noise_fit import fit_noise_terms, term_basis

__all__ = [
    "ARW_METHODS",
    "EXTENSIONS",
    "AdaptiveWindow",
    "DavarResult",
    "ChangeNodes",
    "davar",
    "change_nodes",
]

#: How the ARW of each window is obtained (see :func:`davar`).
ARW_METHODS = ("tau0", "fit")
#: Treatment of the record ends (see :func:`davar`).
EXTENSIONS = ("mirror", "none")

# Largest averaging factor as a fraction of the window (Song et al. 2018,
# sec. 4.1: "m generally take 1/3 the length of the data column").
_TAU_FRACTION = 3


# --------------------------------------------------------------------------
# Parameters and result


def _positive_int(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputError(f"{name} must be a whole number of samples, got "
                         f"{value!r}")
    if value < 1:
        raise InputError(f"{name} must be at least 1, got {value}")
    return int(value)


def finite_float(value, name: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise InputError(f"{name} must be finite, got {value!r}")
    return out


@dataclass(frozen=True)
class AdaptiveWindow:
    """Parameters of the A-DAVAR window-length control.

    Defaults are those of the paper's simulated experiment (Song et al.
    2018, sec. 5).  Lengths are in samples.

    Parameters
    ----------
    l_max : int, default 600
        Longest window ``L_max`` [samples], used where the signal is stable
        (and as the initial length).
    l_min : int, default 400
        Shortest window ``L_min`` [samples], used across changes.
    k1, k2 : float, default 2.5, 3.3
        Kurtosis band ``[K1, K2]`` [-] of a stable window (Gaussian: 3).
    s1, s2 : float, default 0, 0.07
        Band ``[S1, S2]`` [-] of the sliding kurtosis contribution
        coefficient of a stable window end.
    l_tail : int, default 100
        Length ``l`` [samples] of the trailing (newest) part of the window
        whose contribution to the kurtosis is tested; ``l_min - l_tail`` must
        be at least 4.
    dl_shrink : int, default 2
        ``ΔL1`` [samples]: decrease of the length per sample while the window
        is flagged unstable.  2 keeps the leading edge of the window fixed
        while its centre advances one sample.
    dl_grow : int, default 2
        ``ΔL0`` [samples]: increase of the length per sample while the window
        is stable.  2 keeps the trailing edge fixed.

    Raises
    ------
    InputError
        Non-integer or non-positive lengths, ``l_min > l_max``,
        ``l_min - l_tail < 4``, ``k1 > k2``, ``s1 > s2``, non-finite
        thresholds.
    """

    l_max: int = 600
    l_min: int = 400
    k1: float = 2.5
    k2: float = 3.3
    s1: float = 0.0
    s2: float = 0.07
    l_tail: int = 100
    dl_shrink: int = 2
    dl_grow: int = 2

    def __post_init__(self):
        for name in ("l_max", "l_min", "l_tail", "dl_shrink", "dl_grow"):
            object.__setattr__(self, name,
                               _positive_int(getattr(self, name), name))
        for name in ("k1", "k2", "s1", "s2"):
            object.__setattr__(self, name,
                               finite_float(getattr(self, name), name))
        if self.l_min > self.l_max:
            raise InputError(f"l_min ({self.l_min}) must not exceed l_max "
                             f"({self.l_max})")
        if self.l_min - self.l_tail < 4:
            raise InputError(f"l_tail ({self.l_tail}) must leave at least 4 "
                             f"samples of the shortest window (l_min = "
                             f"{self.l_min}) for the kurtosis of its front")
        if self.k1 > self.k2:
            raise InputError(f"k1 ({self.k1}) must not exceed k2 ({self.k2})")
        if self.s1 > self.s2:
            raise InputError(f"s1 ({self.s1}) must not exceed s2 ({self.s2})")


@dataclass(frozen=True)
class DavarResult:
    """Dynamic Allan (or Hadamard) deviation and ARW track (SI units).

    Window ``i`` holds the rate samples ``start[i] .. start[i] +
    window_length[i] - 1`` of the record; sample ``j`` covers the time
    ``[j tau0, (j+1) tau0)`` from the start of the record, so the window's
    centre is ``time_s[i] = (start[i] + window_length[i]/2) tau0``.  With
    ``extension="mirror"`` ``start`` can be negative and the window can
    reach past the last sample: those samples are mirror images.

    Parameters
    ----------
    kind : str
        "oadev" or "ohdev".
    tau0_s : float
        Sample interval [s].
    adaptive : bool
        Whether the window length was adapted (A-DAVAR).
    extension : str
        "mirror" or "none" (see :func:`davar`).
    params : AdaptiveWindow or None
        A-DAVAR parameters (``None`` for fixed windows).
    arw_method : str
        "tau0" or "fit" (see :func:`davar`).
    confidence : float
        Two-sided level of the ARW bounds.
    time_s : numpy.ndarray, shape (w,)
        Window centres [s].
    start : numpy.ndarray of int64, shape (w,)
        First sample of each window (negative: mirrored).
    window_length : numpy.ndarray of int64, shape (w,)
        Window lengths [samples].
    m : numpy.ndarray of int64, shape (k,)
        Averaging factors.
    taus_s : numpy.ndarray, shape (k,)
        Averaging times [s].
    adev_rad_s : numpy.ndarray, shape (w, k)
        Deviation of each window [rad/s].
    arw_rad_rt_s : numpy.ndarray, shape (w,)
        Angle random walk N of each window [rad/√s].
    arw_ci_low_rad_rt_s, arw_ci_high_rad_rt_s : numpy.ndarray, shape (w,)
        Confidence bounds of N [rad/√s] at level ``confidence``.
    kurtosis : numpy.ndarray or None, shape (w,)
        A-DAVAR only: kurtosis ``K`` of each window [-] (NaN for a constant
        window).
    contribution : numpy.ndarray or None, shape (w,)
        A-DAVAR only: sliding kurtosis contribution coefficient ``S`` of the
        window's trailing ``l_tail`` samples [-].
    unstable : numpy.ndarray of bool or None, shape (w,)
        A-DAVAR only: ``f = f1 f2``, the window is flagged unstable (its
        length shrinks at the next sample).
    """

    kind: str
    tau0_s: float
    adaptive: bool
    extension: str
    params: AdaptiveWindow | None
    arw_method: str
    confidence: float
    time_s: np.ndarray = field(repr=False)
    start: np.ndarray = field(repr=False)
    window_length: np.ndarray = field(repr=False)
    m: np.ndarray = field(repr=False)
    taus_s: np.ndarray
    adev_rad_s: np.ndarray = field(repr=False)
    arw_rad_rt_s: np.ndarray = field(repr=False)
    arw_ci_low_rad_rt_s: np.ndarray = field(repr=False)
    arw_ci_high_rad_rt_s: np.ndarray = field(repr=False)
    kurtosis: np.ndarray | None = field(default=None, repr=False)
    contribution: np.ndarray | None = field(default=None, repr=False)
    unstable: np.ndarray | None = field(default=None, repr=False)

    @property
    def n_windows(self) -> int:
        """Number of windows ``w``."""
        return int(self.time_s.size)

    def to_json_dict(self) -> dict:
        """JSON-ready dict in datasheet units (the CLI edge).

        Returns
        -------
        dict
            ``time_s`` [s], ``window_length`` [samples], ``taus_s`` [s],
            ``adev_deg_h`` [deg/h] as a list (one per window) of lists (one
            per tau), ``arw_deg_rt_h``, ``arw_ci_low_deg_rt_h``,
            ``arw_ci_high_deg_rt_h`` [deg/√h]; ``kind``, ``adaptive``,
            ``extension``, ``arw_method``, ``confidence``, ``tau0_s`` and
            ``params`` (the :class:`AdaptiveWindow` fields or ``None``); for
            A-DAVAR also ``kurtosis``, ``contribution`` [-] and ``unstable``
            (``None`` for fixed windows).  NaN becomes ``None``.
        """
        def floats(a):
            return [None if not math.isfinite(v) else float(v)
                    for v in np.asarray(a, dtype=float).ravel()]

        arw = units.arw_rad_rt_s_to_deg_rt_h
        adev = units.rad_s_to_deg_h(self.adev_rad_s)
        return {
            "kind": self.kind,
            "adaptive": self.adaptive,
            "extension": self.extension,
            "arw_method": self.arw_method,
            "confidence": float(self.confidence),
            "tau0_s": float(self.tau0_s),
            "params": None if self.params is None else asdict(self.params),
            "time_s": floats(self.time_s),
            "window_length": [int(v) for v in self.window_length],
            "taus_s": floats(self.taus_s),
            "adev_deg_h": [floats(row) for row in adev],
            "arw_deg_rt_h": floats(arw(self.arw_rad_rt_s)),
            "arw_ci_low_deg_rt_h": floats(arw(self.arw_ci_low_rad_rt_s)),
            "arw_ci_high_deg_rt_h": floats(arw(self.arw_ci_high_rad_rt_s)),
            "kurtosis": None if self.kurtosis is None
            else floats(self.kurtosis),
            "contribution": None if self.contribution is None
            else floats(self.contribution),
            "unstable": None if self.unstable is None
            else [bool(v) for v in self.unstable],
        }


# --------------------------------------------------------------------------
# Kernels


@njit(cache=True)
def _kurtosis(x, a, b):  # pragma: no cover - compiled
    """Kurtosis ``m4 / m2^2`` of ``x[a:b]`` (two passes; NaN if constant)."""
    n = b - a
    mu = 0.0
    for i in range(a, b):
        mu += x[i]
    mu /= n
    m2 = 0.0
    m4 = 0.0
    for i in range(a, b):
        d = x[i] - mu
        d2 = d * d
        m2 += d2
        m4 += d2 * d2
    if m2 == 0.0:
        return np.nan
    m2 /= n
    m4 /= n
    return m4 / (m2 * m2)


@njit(cache=True)
def _adaptive_lengths(x, first, count, l_max, l_min, k1, k2, s1, s2, l_tail,
                      dl_shrink, dl_grow, length, kurt, contrib,
                      unstable):  # pragma: no cover - compiled
    """Window-length recursion of A-DAVAR, one step per sample.

    The window centred on sample ``p`` of ``x`` (``p = first + j``,
    ``j < count``) holds ``x[p - L//2 : p - L//2 + L]``; its length,
    kurtosis, contribution coefficient and flag go to index ``j`` of the
    outputs.  NaN (constant data) fails every band test, so it flags the
    window unstable.
    """
    big_l = l_max
    for j in range(count):
        a = first + j - big_l // 2
        k = _kurtosis(x, a, a + big_l)                 # K of the L window
        km = _kurtosis(x, a, a + big_l - l_tail)       # K of its front L - l
        s = abs(k - km) / k                            # S = |K - Km| / K
        f1 = not (k1 <= k <= k2)
        f2 = not (s1 <= s <= s2)
        f = f1 and f2                                  # f = f1 f2
        length[j] = big_l
        kurt[j] = k
        contrib[j] = s
        unstable[j] = f
        if f:                                          # L - dL1, >= L_min
            big_l = max(l_min, big_l - dl_shrink)
        else:                                          # L + dL0, <= L_max
            big_l = min(l_max, big_l + dl_grow)


@contextlib.contextmanager
def _one_numba_thread(enabled: bool):
    """Run the block with one numba thread (restored afterwards).

    The deviation kernel parallelises over cache blocks of
    ``_kernels.BLOCK`` samples; a window within one block gives its
    ``prange`` a single iteration, so the thread team is pure overhead, and
    on a loaded machine its start-up costs milliseconds per call (measured:
    40 us -> 0.7-5 ms per 600-sample window).  ``numba.set_num_threads`` is
    thread-local.
    """
    if not enabled:
        yield
        return
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(before)


# --------------------------------------------------------------------------
# DAVAR


def _factors(l_short: int, tau0: float, taus, kind: str) -> np.ndarray:
    """Averaging factors common to all windows (shortest ``l_short``)."""
    d = KINDS[kind]
    if isinstance(taus, (str, numbers.Integral)) and not isinstance(taus,
                                                                    bool):
        # "octave" or a count: m up to a third of the shortest window (the
        # paper's rule), i.e. the factors averaging_factors gives a record
        # whose largest m is that cap.
        cap = min(l_short // _TAU_FRACTION, (l_short - 1) // d)
        if cap < 1:
            raise InputError(f"a window of {l_short} samples is too short for "
                             f"{kind}: need at least "
                             f"{max(_TAU_FRACTION, d + 1)}")
        return averaging_factors(d * cap + 2, tau0, taus, kind)
    # explicit taus: anything the shortest window can hold
    return averaging_factors(l_short + 1, tau0, taus, kind)


def _edf_at(kind: str, n_phase: int, m: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Greenhall's EDF of ``kind`` for ``n_phase`` phase points at factors ``m`` [-]."""
    return edf(kind, n_phase, m, alpha)


def _window_arw(kind: str, tau0: float, m: np.ndarray, adev: np.ndarray,
                lengths: np.ndarray, method: str, confidence: float):
    """ARW [rad/√s] of each window and its confidence bounds."""
    if method == "tau0":
        # N on the -1/2 line through sigma(tau0): sigma^2 = N^2 g(tau0)
        arw = adev[:, 0] / math.sqrt(float(term_basis(kind, "n", tau0)))
        low = np.empty_like(arw)
        high = np.empty_like(arw)
        for length in np.unique(lengths):
            sel = lengths == length
            nu = edf(kind, int(length) + 1, 1, 0)          # white FM at m = 1
            low[sel], high[sel] = confidence_interval(arw[sel], nu,
                                                      confidence)
        return arw, low, high
    # "fit": IEEE Std 952 least squares of each window's curve
    d = KINDS[kind]
    z = float(special.ndtri(0.5 + 0.5 * confidence))
    arw = np.empty(adev.shape[0])
    low = np.empty_like(arw)
    high = np.empty_like(arw)
    for i, length in enumerate(lengths):
        n_phase = int(length) + 1
        res = AllanResult(kind=kind, tau0_s=tau0, n_phase=n_phase, m=m,
                          taus_s=m * tau0, dev=adev[i],
                          n_terms=n_phase - d * m)
        fit = fit_noise_terms(res, functools.partial(_edf_at, kind, n_phase, m))
        value, sigma = fit.coefficient("n")
        assert value is not None                       # "n" is a term of both kinds
        sigma = math.nan if sigma is None else sigma
        arw[i] = value
        low[i] = max(value - z * sigma, 0.0)
        high[i] = value + z * sigma
    return arw, low, high


def _check_options(extension: str, arw: str, confidence: float, adaptive: bool,
                   window, params) -> None:
    """Refuse an unknown extension or ARW method, a confidence outside (0, 1) and a mix of the
    fixed and adaptive windows' options."""
    if extension not in EXTENSIONS:
        raise InputError(f"unknown extension {extension!r}; expected one of "
                         f"{EXTENSIONS}")
    if arw not in ARW_METHODS:
        raise InputError(f"unknown ARW method {arw!r}; expected one of "
                         f"{ARW_METHODS}")
    if not (0.0 < confidence < 1.0):
        raise InputError(f"confidence must be in (0, 1), got {confidence!r}")
    if adaptive and window is not None:
        raise InputError("the window length is adaptive: give its bounds as "
                         "params=AdaptiveWindow(l_max=..., l_min=...), not "
                         "window")
    if not adaptive and params is not None:
        raise InputError("params are the adaptive window's; pass "
                         "adaptive=True or drop them")


def _adaptive_windows(y: np.ndarray, params: AdaptiveWindow, step: int | None,
                      extension: str) -> tuple:
    """A-DAVAR windows: (padded series, pad, starts, lengths, l_long, l_short, kurtosis,
    contribution, unstable flag), starts and lengths [samples] every ``step`` centres."""
    n = y.size
    step = 1 if step is None else step
    l_long, l_short = params.l_max, params.l_min
    pad = (l_long + 1) // 2 + 1 if extension == "mirror" else 0
    x = np.pad(y, pad, mode="symmetric") if pad else y
    if extension == "mirror":
        first, last = 0, n - 1               # centres, record indices
    else:
        first = l_long // 2
        last = n - l_long + l_long // 2
    count = last - first + 1
    length = np.empty(count, dtype=np.int64)
    kurt = np.empty(count)
    contrib = np.empty(count)
    flag = np.empty(count, dtype=np.bool_)
    _adaptive_lengths(x, first + pad, count, params.l_max, params.l_min,
                      params.k1, params.k2, params.s1, params.s2,
                      params.l_tail, params.dl_shrink, params.dl_grow,
                      length, kurt, contrib, flag)
    keep = np.arange(0, count, step)
    lengths = length[keep]
    starts = first + keep - lengths // 2
    kurt, contrib, flag = kurt[keep], contrib[keep], flag[keep]
    return x, pad, starts, lengths, l_long, l_short, kurt, contrib, flag


def _fixed_windows(y: np.ndarray, window: int | None, step: int | None, extension: str) -> tuple:
    """Fixed windows (None: one over the record): (padded series, pad, starts, lengths, l_long,
    l_short), starts and lengths [samples]."""
    n = y.size
    if window is None:
        if step is not None:
            raise InputError("step needs a window length: the default "
                             "(window=None) is one window over the record")
        x, pad = y, 0
        l_long = l_short = n
        starts = np.zeros(1, dtype=np.int64)
        lengths = np.full(1, n, dtype=np.int64)
    else:
        big_l = _positive_int(window, "window")
        if big_l > n:
            raise InputError(f"window ({big_l} samples) is longer than the "
                             f"record ({n} samples)")
        step = max(1, big_l // 10) if step is None else step
        l_long = l_short = big_l
        if extension == "mirror":
            pad = (big_l + 1) // 2 + 1
            x = np.pad(y, pad, mode="symmetric")
            starts = np.arange(0, n, step, dtype=np.int64) - big_l // 2
        else:
            x, pad = y, 0
            starts = np.arange(0, n - big_l + 1, step, dtype=np.int64)
        lengths = np.full(starts.size, big_l, dtype=np.int64)
    return x, pad, starts, lengths, l_long, l_short


def davar(rate_rad_s, tau0_s: float, *, window: int | None = None,
          adaptive: bool = False, step: int | None = None, taus="octave",
          kind: str = "oadev", extension: str = "mirror",
          params: AdaptiveWindow | None = None, arw: str = "tau0",
          confidence: float = ONE_SIGMA) -> DavarResult:
    """Dynamic Allan (or Hadamard) deviation with a fixed or adaptive window.

    Parameters
    ----------
    rate_rad_s : array_like, shape (n,)
        Rate samples of one gyro [rad/s].
    tau0_s : float
        Sample interval [s].
    window : int or None, default None
        Fixed window length [samples], ``3 <= window <= n``.  ``None`` with
        ``adaptive=False``: one window holding the whole record (the
        deviation of :func:`~gyroarray.analysis.allan.deviation`, the null
        model of DAVAR).  Must be ``None`` when ``adaptive`` (the bounds are
        ``params.l_max``/``params.l_min``).
    adaptive : bool, default False
        Adapt the window length (A-DAVAR, see Notes).
    step : int or None, default None
        Samples between window centres.  Default: 1 for A-DAVAR (the
        recursion runs every sample in any case; ``step`` only thins the
        windows whose deviation is computed) and ``max(1, window // 10)``
        for a fixed window (90 % overlap: the work is about ``10 n k``
        whatever the window).  Must be ``None`` for the single window.
    taus : "octave", int or sequence of float, default "octave"
        Averaging times, common to all windows.  ``"octave"`` or a count
        (see :func:`~gyroarray.analysis.allan.averaging_factors`) stop at
        ``m <= L/3`` of the shortest window (the paper's rule, sec. 4.1); a
        sequence of taus [s] may go up to what the shortest window allows.
    kind : {"oadev", "ohdev"}, default "oadev"
        Overlapping Allan or overlapping Hadamard deviation.
    extension : {"mirror", "none"}, default "mirror"
        ``"mirror"``: the record is extended at both ends by its mirror
        image (``y[-1-j] = y[j]``, ``y[n+j] = y[n-1-j]``) and a window is
        centred on every ``step``-th sample from the first to the last, all
        at full length.  ``"none"``: only windows that fit in the record
        (centres from ``L_max/2`` to ``n - L_max/2``).
    params : AdaptiveWindow or None, default None
        A-DAVAR parameters; ``None`` with ``adaptive``: the paper's defaults
        ``AdaptiveWindow()``.  Must be ``None`` without ``adaptive``.
    arw : {"tau0", "fit"}, default "tau0"
        ARW of each window.  ``"tau0"``: read on the white-FM line through
        the deviation at the shortest averaging time, which must be
        ``tau0`` (:math:`N = \\sigma(\\tau_0)\\sqrt{\\tau_0}`), bounds from
        the chi-square interval with the white-FM EDF of that point.
        ``"fit"``: the ``n`` term of
        :func:`~gyroarray.analysis.noise_fit.fit_noise_terms` on each
        window's curve (the paper's least-squares definition), bounds
        ``N ± z sigma_N``; 30-200 ms per window, so use a coarse ``step``.
    confidence : float, default :data:`~gyroarray.analysis.allan.ONE_SIGMA`
        Two-sided level of the ARW bounds.

    Returns
    -------
    DavarResult

    Raises
    ------
    InputError
        Not 1-D, NaN or infinite samples, bad ``tau0_s``, a window longer
        than the record or too short for the taus, ``l_min > l_max`` (from
        :class:`AdaptiveWindow`), conflicting options (``window`` with
        ``adaptive``, ``params`` without, ``step`` with the single window),
        unknown ``kind``, ``extension`` or ``arw``, ``arw="tau0"`` without
        ``tau0`` among the taus, a zero deviation with ``arw="fit"``.

    Notes
    -----
    DAVAR (Galleani & Tavella 2009): the deviation of the data in a
    rectangular window of length :math:`L` centred at :math:`t`,

    .. math::

        \\sigma^2(t, \\tau) = \\frac{1}{2\\tau^2(L+1-2m)}
            \\sum_{i}(x_{i+2m} - 2x_{i+m} + x_i)^2,\\qquad \\tau = m\\tau_0,

    with :math:`x` the integrated rate in the window (see
    :func:`~gyroarray.analysis.allan.deviation`); paper eqs. (15)-(16) are
    this formula on the mirror-extended record.

    A-DAVAR (Song et al. 2018, sec. 4.2), at every sample :math:`p`, with
    the window :math:`w_p` of length :math:`L_p` centred there and
    :math:`K` the kurtosis :math:`m_4/m_2^2` (eq. 14):

    .. math::

        f_1 = [K(w_p) \\notin [K_1, K_2]],\\quad
        S = \\frac{|K(w_p) - K(w_p^{front})|}{K(w_p)},\\quad
        f_2 = [S \\notin [S_1, S_2]],\\quad f = f_1 f_2,

    where :math:`w_p^{front}` is :math:`w_p` without its trailing (newest)
    :math:`l` samples, and

    .. math::

        L_{p+1} = \\begin{cases}\\max(L_{min}, L_p - \\Delta L_1) & f = 1\\\\
                  \\min(L_{max}, L_p + \\Delta L_0) & f = 0\\end{cases},
        \\qquad L_0 = L_{max}.

    With :math:`\\Delta L = 2` a shrinking window keeps its leading edge
    (where the change was seen) and a growing one its trailing edge (paper
    eqs. 19 and 21: the centre moves :math:`(L - L_{min})/2` samples while
    the length drops by :math:`L - L_{min}`).

    Choices where the paper is ambiguous:

    * The paper's update rules (eqs. 20 and 22) read "L_max if
      L >= L_max" also for f = 1, which would never let a window shrink
      from L_max; the clamped form above is used.
    * "Inverted mirror extension" (sec. 4.1): the formula is the symmetric
      mirror repeating the end samples (``numpy.pad(mode="symmetric")``);
      an odd (point) reflection would offset the mirrored rate by twice the
      end sample and distort the kurtosis.
    * The contribution coefficient compares the whole window with its front
      :math:`L - l` samples (paper: "the kurtosis value Kmp of the front
      L-l length signal in the L window"), so it reacts to the newest
      samples; the window at :math:`p` holds samples
      :math:`p - \\lfloor L/2\\rfloor .. p - \\lfloor L/2\\rfloor + L - 1`.
    * ARW: the paper fits its eq. (7) by least squares to each window's
      curve; ``arw="fit"`` does this with the house GLS fit, the default
      ``"tau0"`` reads the white-FM line at :math:`\\tau_0` (the same in
      expectation for white rate noise, much faster, and not split between
      the quantization and ARW terms as a five-term fit of a short window
      does).

    Windows within one cache block run the deviation kernel on one numba
    thread (see ``_one_numba_thread``).

    References
    ----------
    .. [1] J. Song, Z. Shi, L. Wang, H. Wang, "Random error analysis of
       MEMS gyroscope based on an improved DAVAR algorithm",
       Micromachines 9(8), 373, 2018, doi:10.3390/mi9080373.
    .. [2] L. Galleani, P. Tavella, "The dynamic Allan variance", IEEE
       Trans. Ultrason. Ferroelectr. Freq. Control 56(3), 450-464, 2009.
    .. [3] W. J. Riley, "Handbook of Frequency Stability Analysis", NIST
       SP 1065, 2008.
    .. [4] IEEE Std 952-1997, Annex C.
    """
    check_kind(kind)
    tau0 = check_tau0(tau0_s)
    y = as_series(rate_rad_s, "rate")
    n = y.size
    if not np.all(np.isfinite(y)):
        raise first_non_finite(y, "rate")
    _check_options(extension, arw, confidence, adaptive, window, params)
    if step is not None:
        step = _positive_int(step, "step")

    kurt = contrib = flag = None
    if adaptive:
        params = AdaptiveWindow() if params is None else params
        if not isinstance(params, AdaptiveWindow):
            raise InputError(f"params must be an AdaptiveWindow, got "
                             f"{type(params).__name__}")
        if params.l_max > n:
            raise InputError(f"the longest window (l_max = {params.l_max}) "
                             f"is longer than the record ({n} samples)")
        (x, pad, starts, lengths, l_long, l_short, kurt, contrib,
         flag) = _adaptive_windows(y, params, step, extension)
    else:
        x, pad, starts, lengths, l_long, l_short = _fixed_windows(y, window, step, extension)

    m = _factors(int(l_short), tau0, taus, kind)
    if arw == "tau0" and m[0] != 1:
        raise InputError("arw='tau0' reads the deviation at tau0: include "
                         f"tau0 = {tau0!r} s in taus (or use arw='fit')")
    taus_s = m * tau0
    adev = np.empty((starts.size, m.size))
    with _one_numba_thread(int(l_long) <= _kernels.BLOCK):
        for i, (a, big_l) in enumerate(zip(starts + pad, lengths)):
            adev[i] = deviation(x[a:a + big_l], tau0, kind, taus_s).dev
    arw_n, low, high = _window_arw(kind, tau0, m, adev, lengths, arw,
                                   confidence)
    return DavarResult(
        kind=kind, tau0_s=tau0, adaptive=bool(adaptive), extension=extension,
        params=params, arw_method=arw, confidence=float(confidence),
        time_s=(starts + 0.5 * lengths) * tau0, start=starts,
        window_length=lengths, m=m, taus_s=taus_s, adev_rad_s=adev,
        arw_rad_rt_s=arw_n, arw_ci_low_rad_rt_s=low,
        arw_ci_high_rad_rt_s=high, kurtosis=kurt, contribution=contrib,
        unstable=flag)


# --------------------------------------------------------------------------
# Reaction to a change


@dataclass(frozen=True)
class ChangeNodes:
    """Where the window reacts to a change of the signal at ``change_s``.

    Parameters
    ----------
    change_s : float
        Time of the change [s].
    beginning_s : float
        Window centre [s] at which the window first senses the change, i.e.
        is flagged unstable so that its length decreases (A-DAVAR), or whose
        leading edge reaches it (fixed window, ``change_s - L tau0/2``).
        NaN: never detected.
    end_s : float
        Window centre [s] from which the window grows back to ``l_max``
        without interruption (A-DAVAR), or whose trailing edge leaves the
        change (fixed window, ``change_s + L tau0/2``).  NaN: not restored.
    restore_s : float
        A-DAVAR: first window centre [s] after ``beginning_s`` at full length
        ``l_max`` again and wholly after the change (the paper's "Restore
        600": "the window length restores to 600 ... and the window begins
        to intercept the signal in stable region", Table 3); NaN for a fixed
        window or if never restored.
    """

    change_s: float
    beginning_s: float
    end_s: float
    restore_s: float


def change_nodes(result: DavarResult, change_s: float) -> ChangeNodes:
    """Nodes of the window-length track around a change at a known time.

    Parameters
    ----------
    result : DavarResult
        A fixed or adaptive DAVAR.
    change_s : float
        Time of the change [s] (the boundary between the samples before and
        after it).

    Returns
    -------
    ChangeNodes

    Raises
    ------
    InputError
        ``change_s`` not finite, or a fixed-window result whose windows do
        not all have the same length.

    Notes
    -----
    The paper's Table 1 nodes (Song et al. 2018, sec. 5): "Beginning" is
    where "the window first senses the 3000 s data, and the window length
    should decrease", "End" where "the window lost senses the 3000 s data,
    and the window length should increase".  On an A-DAVAR track (windows
    :math:`i` with centre :math:`t_i`, first sample :math:`a_i`, length
    :math:`L_i`, change at sample boundary :math:`c`):

    * beginning: the first :math:`i` whose window straddles the change
      (:math:`a_i < c < a_i + L_i`) and is flagged unstable (:math:`f = 1`,
      so :math:`L_{i+1} < L_i` unless :math:`L_i = L_{min}`);
    * restore: the first :math:`j > i` with :math:`L_j = L_{max}` and
      :math:`a_j \\ge c`;
    * end: where the last growth to :math:`L_{max}` before the restore
      began: walking back from :math:`j` over windows at :math:`L_{max}`,
      then over strictly growing lengths, the first :math:`k` reached with
      :math:`L_k \\le L_{k-1}` (or :math:`k = i`).

    The ideal A-DAVAR (paper, discussion of its Fig. 24) gives
    :math:`c - L_{max}/2`, :math:`c + L_{min}/2`, :math:`c + L_{max}/2`.
    Resolution: the window spacing (``step``).

    References
    ----------
    .. [1] J. Song, Z. Shi, L. Wang, H. Wang, Micromachines 9(8), 373,
       2018, sec. 5, Tables 1-3.
    """
    change = finite_float(change_s, "change_s")
    t = result.time_s
    lengths = result.window_length
    if not result.adaptive:
        if np.unique(lengths).size != 1:
            raise InputError("a fixed-window result must have one window "
                             "length")
        half = 0.5 * float(lengths[0]) * result.tau0_s
        return ChangeNodes(change, change - half, change + half, math.nan)
    c = change / result.tau0_s
    straddle = (result.start < c) & (c < result.start + lengths)
    hits = np.flatnonzero(straddle & result.unstable)
    if hits.size == 0:
        return ChangeNodes(change, math.nan, math.nan, math.nan)
    i_b = int(hits[0])
    assert result.params is not None                   # adaptive
    l_max = result.params.l_max
    after = (lengths[i_b + 1:] == l_max) & (result.start[i_b + 1:] >= c)
    if not after.any():
        return ChangeNodes(change, float(t[i_b]), math.nan, math.nan)
    i_r = i_b + 1 + int(np.argmax(after))
    k = i_r
    while k > i_b and lengths[k - 1] == l_max:      # back over the plateau
        k -= 1
    while k > i_b and lengths[k] > lengths[k - 1]:  # back over the growth
        k -= 1
    return ChangeNodes(change, float(t[i_b]), float(t[k]), float(t[i_r]))
