"""Stamps that lie: is a clock's jitter in the sampling or only in its time stamps?

A logger that samples on a uniform clock but stamps each sample with a jittering
counter (1-ms steps of 9 and 11 ms on a nominal 10 ms) has stamps that lie: the
samples are uniform, the stamps are not. A reference rate derived from an angle
by :func:`numpy.gradient` over such stamps is then biased, because the
gradient's weights 1/h use the wrong steps h (its second-order interior formula
turns uniform increments over a pair of steps summing to 2 dt into a rate
1 + (h_i - h_{i-1})^2 / (2 h_{i-1} h_i) times the true one: always upward, the bias
does not average out).

The test here undoes :func:`numpy.gradient` over the stamps (a banded linear
system in the angle, rank n - 1, the first angle fixed at 0) and looks at the
angle's increments: if the stamps were true, an increment over a "9 ms" step
would be 0.9 of one over a 10 ms step; if they lie, it is 1.0. The slope of the
relative increment on the relative step error h_i/dt - 1 is that number
(1: the stamps are true, 0: they lie).

Core layer: numpy and scipy only. Units: times and periods in s (or any one
time unit, consistently), rates in the reference's own unit (deg/s in the
reader); the angle recovered is the rate's unit times the time unit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_banded

__all__ = ["StampsVerdict", "CorrectedReference", "stamps_lie", "corrected_reference",
           "undo_gradient", "slots", "LIE_SLOPE", "LIE_Z", "MIN_JITTER_STEPS"]

#: Largest increment slope [-] read as "the stamps lie" (0 lie, 1 true; halfway).
LIE_SLOPE = 0.5
#: Least distance from slope 1 [standard errors] to call the stamps lying.
LIE_Z = 5.0
#: Fewest jittered one-slot steps [-] that a verdict is drawn from.
MIN_JITTER_STEPS = 20
#: Smallest |h/dt - 1| [-] counted as a jittered step.
_JITTER_EPS = 1e-3


@dataclass(frozen=True)
class StampsVerdict:
    """Whether a reference was derived over stamps that lie, and the statistic.

    Attributes
    ----------
    lie : bool
        True when the reference's increments do not follow the stamps' steps:
        ``slope < LIE_SLOPE`` and ``z_true > LIE_Z``.
    slope : float
        Relative increment of the recovered angle per relative step error
        h_i/dt - 1 [-] (weighted least squares over one-slot steps): 1 when the
        stamps are true, 0 when the samples are uniform and the stamps lie.
    slope_se : float
        Heteroscedasticity-robust standard error of ``slope`` [-].
    z_true : float
        (1 - slope) / slope_se [-]: how far the data are from true stamps.
    ratio_short : float
        Mean increment over a step shorter than dt over the mean of its
        neighbours two steps either side [-] (0.9 for a true 9-ms step of 10).
    ref_jump_slope, gyro_jump_slope : float
        Relative jump of the reference (and of the gyro output, the control: a
        physical rate does not jump with the stamps) on the jump that
        numpy.gradient over the stamps predicts for uniform samples [-]
        (1: the column jumps as predicted, 0: it does not).
    n_steps : int
        Jittered one-slot steps used [-].
    period_s : float
        The uniform period the data prove [time unit]: stamp span / slots.
    n_slots : int
        Sample intervals on that grid [-] (gaps count their missing samples).
    reason : str
        The rule and statistic in one sentence.
    """

    lie: bool
    slope: float
    slope_se: float
    z_true: float
    ratio_short: float
    ref_jump_slope: float
    gyro_jump_slope: float
    n_steps: int
    period_s: float
    n_slots: int
    reason: str


@dataclass(frozen=True)
class CorrectedReference:
    """A reference re-derived on the uniform grid, and the bias it removes.

    Attributes
    ----------
    time_s : numpy.ndarray
        The uniform grid t0 + k * period_s, k = 0 .. n_slots [time unit].
    ref : numpy.ndarray
        The corrected reference on that grid, shape (n_slots + 1,) or
        (n_slots + 1, m) [rate unit]: numpy.gradient of the recovered angle
        (missing samples at gaps filled linearly in the angle).
    slot : numpy.ndarray
        Grid index of each input row [-].
    ref_at_rows : numpy.ndarray
        The corrected reference at the input rows [rate unit].
    period_s : float
        Uniform period [time unit].
    bias_rms, bias_max : float
        rms and max |ref - corrected| over the input rows [rate unit], of the
        column of largest rms (for a 2-D ``ref``).
    bias_mean : float
        mean(ref - corrected) of that column [rate unit].
    scale_ppm : float
        The input reference's scale against the corrected one,
        (sum ref*c / sum c^2 - 1) * 1e6 [ppm]: a gyro scale factor fitted
        against the input reference reads this much too low.
    """

    time_s: np.ndarray
    ref: np.ndarray
    slot: np.ndarray
    ref_at_rows: np.ndarray
    period_s: float
    bias_rms: float
    bias_max: float
    bias_mean: float
    scale_ppm: float


def slots(t, nominal_dt: float) -> tuple[np.ndarray, float]:
    """Grid index of each stamp and the uniform period the stamps span.

    Each step counts round(h / nominal_dt) slots, at least 1 (a 20-ms step of
    10 is a missing sample, a 9- or 11-ms step one slot); the period is the stamp
    span over the slots.

    Parameters
    ----------
    t : array_like
        Strictly increasing stamps [time unit].
    nominal_dt : float
        Nominal sample period [time unit].

    Returns
    -------
    slot : numpy.ndarray of int
        Grid index of each stamp, slot[0] = 0 [-].
    period : float
        (t[-1] - t[0]) / slot[-1] [time unit].
    """
    t = np.asarray(t, float)
    n = np.maximum(1, np.rint(np.diff(t) / nominal_dt)).astype(np.int64)
    slot = np.concatenate(([0], np.cumsum(n)))
    return slot, float((t[-1] - t[0]) / slot[-1])


def undo_gradient(t, ref) -> np.ndarray:
    """The angle whose numpy.gradient over the stamps ``t`` is ``ref``, first angle 0.

    numpy.gradient (edge_order=1) is first order one-sided at the ends and, inside,
    g_i = -h_i/(h_{i-1}(h_{i-1}+h_i)) th_{i-1} + (h_i-h_{i-1})/(h_{i-1}h_i) th_i
    + h_{i-1}/(h_i(h_{i-1}+h_i)) th_{i+1}; with th_0 = 0 the first n - 1 equations
    are a lower-banded system in th_1 .. th_{n-1}, solved exactly (the last
    equation is then met when ``ref`` is such a gradient).

    Parameters
    ----------
    t : array_like, shape (n,)
        Strictly increasing stamps [time unit].
    ref : array_like, shape (n,) or (n, m)
        Rate(s) [rate unit].

    Returns
    -------
    numpy.ndarray
        Angle(s), same shape as ``ref`` [rate unit * time unit].
    """
    t = np.asarray(t, float)
    g = np.asarray(ref, float)
    n = t.size
    h = np.diff(t)
    hm, hp = h[:-1], h[1:]
    a = -hp / (hm * (hm + hp))
    b = (hp - hm) / (hm * hp)
    c = hm / (hp * (hm + hp))
    ab = np.zeros((3, n - 1))
    ab[0, 0] = 1.0 / h[0]
    ab[0, 1:] = c
    ab[1, :n - 2] = b
    ab[2, :n - 3] = a[1:]
    th = solve_banded((2, 0), ab, g[:-1], check_finite=False)
    return np.concatenate((np.zeros((1,) + g.shape[1:]), th))


def _main_column(x: np.ndarray) -> np.ndarray:
    """The column with the largest rms (a 1-D array as it is)."""
    if x.ndim == 1:
        return x
    return x[:, int(np.argmax(np.sqrt(np.mean(x ** 2, axis=0))))]


def _wls_slope(x, y):
    """Slope of y = beta * x through 0 and its robust (HC0) standard error."""
    sxx = float(np.sum(x * x))
    if sxx <= 0:
        return float("nan"), float("inf")
    beta = float(np.sum(x * y)) / sxx
    se = float(np.sqrt(np.sum((x * (y - beta * x)) ** 2))) / sxx
    return beta, se


def _predicted_jump(h: np.ndarray, dt: float) -> np.ndarray:
    """Relative rate error of numpy.gradient at interior rows for uniform increments [-]."""
    hm, hp = h[:-1], h[1:]
    w = np.zeros(h.size + 1)
    w[1:-1] = (hm / hp + hp / hm) / (hm + hp) * dt - 1.0
    return w


def _jump_slope(x: np.ndarray, w: np.ndarray, use: np.ndarray) -> float:
    """Slope of a column's relative jump (against its neighbours +-2) on ``w``."""
    i = np.flatnonzero(use)
    i = i[(i >= 2) & (i < x.size - 2)]
    local = 0.5 * (x[i - 2] + x[i + 2])
    keep = np.abs(local) > 0.2 * float(np.sqrt(np.mean(x ** 2)) or 1.0)
    i, local = i[keep], local[keep]
    beta, _ = _wls_slope(w[i] * local, x[i] - local)
    return beta


def stamps_lie(t, gyro, ref, nominal_dt: float) -> StampsVerdict:
    """Whether ``ref`` was derived by numpy.gradient over stamps that lie.

    Rule: undo numpy.gradient over the stamps (:func:`undo_gradient`); over
    one-slot steps regress the angle increment's relative departure from its
    neighbours (two steps either side) on the step's relative error h/dt - 1.
    The stamps lie when the slope is below :data:`LIE_SLOPE` and more than
    :data:`LIE_Z` standard errors below 1, from at least
    :data:`MIN_JITTER_STEPS` jittered steps.

    Parameters
    ----------
    t : array_like, shape (n,)
        Strictly increasing stamps [time unit].
    gyro : array_like, shape (n,) or (n, N)
        Gyro output(s) at the rows [rate unit]: the control (a physical rate
        does not jump with the stamps); the column of largest rms is used.
    ref : array_like, shape (n,) or (n, m)
        Reference rate(s) [rate unit]; the column of largest rms is tested.
    nominal_dt : float
        Nominal sample period [time unit].

    Returns
    -------
    StampsVerdict
    """
    t = np.asarray(t, float)
    r = _main_column(np.asarray(ref, float))
    gy = _main_column(np.asarray(gyro, float))
    slot, period = slots(t, nominal_dt)
    h = np.diff(t)
    one = np.diff(slot) == 1
    x = h / period - 1.0
    nan = float("nan")
    if t.size < 8 or not np.all(np.isfinite(r)):
        return StampsVerdict(False, nan, nan, nan, nan, nan, nan, 0, period, int(slot[-1]),
                             "too few samples or a non-finite reference: no verdict")
    d = np.diff(undo_gradient(t, r))
    i = np.flatnonzero(one)
    i = i[(i >= 2) & (i < d.size - 2)]
    local = 0.5 * (d[i - 2] + d[i + 2])
    rms = float(np.sqrt(np.mean(d ** 2)))
    keep = (np.abs(local) > 0.2 * rms) & one[i - 2] & one[i + 2]
    i, local = i[keep], local[keep]
    x0 = float(np.median(x[i])) if i.size else 0.0
    jit = np.abs(x[i] - x0) > _JITTER_EPS
    n_steps = int(np.count_nonzero(jit))
    short = jit & (x[i] < x0)
    ratio_short = float(np.mean(d[i][short] / local[short])) if short.any() else nan
    if n_steps < MIN_JITTER_STEPS:
        return StampsVerdict(False, nan, nan, nan, ratio_short, nan, nan, n_steps, period,
                             int(slot[-1]), f"only {n_steps} jittered steps (at least "
                             f"{MIN_JITTER_STEPS} needed): no verdict, the stamps are taken as true")
    beta, se = _wls_slope(x[i] * local, d[i] - local)
    z = (1.0 - beta) / se if se > 0 else float("inf")
    w = _predicted_jump(h, period)
    rows = np.abs(w) > _JITTER_EPS
    ref_jump = _jump_slope(r, w, rows)
    gyro_jump = _jump_slope(gy, w, rows) if gy.size == r.size else nan
    lie = bool(beta < LIE_SLOPE and z > LIE_Z)
    reason = (f"increment slope {beta:.3f} +- {se:.3f} on the relative step error over "
              f"{n_steps} jittered steps (1 if the stamps were true, 0 if they lie; "
              f"{z:.1f} sigma from 1); a short step's increment is {ratio_short:.3f} of its "
              f"neighbours' (true stamps: {1 + float(np.mean(x[i][short])) if short.any() else nan:.3f}); "
              f"the reference jumps {ref_jump:.2f}, the gyro {gyro_jump:.2f} of the jump "
              "numpy.gradient over the stamps predicts for uniform samples")
    return StampsVerdict(lie, beta, se, float(z), ratio_short, ref_jump, gyro_jump, n_steps,
                         period, int(slot[-1]), reason)


def corrected_reference(t, ref, nominal_dt: float) -> CorrectedReference:
    """Undo numpy.gradient over the stamps and re-derive the rate on the uniform grid.

    Parameters
    ----------
    t : array_like, shape (n,)
        Strictly increasing stamps [time unit].
    ref : array_like, shape (n,) or (n, m)
        Reference rate(s) derived by numpy.gradient over ``t`` [rate unit].
    nominal_dt : float
        Nominal sample period [time unit]; the grid's period is the stamp span over
        the slots (:func:`slots`), the period the data prove.

    Returns
    -------
    CorrectedReference
    """
    t = np.asarray(t, float)
    r = np.asarray(ref, float)
    slot, period = slots(t, nominal_dt)
    th = undo_gradient(t, r)
    k = np.arange(int(slot[-1]) + 1)
    th2 = th.reshape(t.size, -1)
    full = np.column_stack([np.interp(k, slot, th2[:, j]) for j in range(th2.shape[1])])
    rate = np.gradient(full, period, axis=0)
    rate = rate.reshape((k.size,) + r.shape[1:])
    at_rows = rate[slot]
    main = 0 if r.ndim == 1 else int(np.argmax(np.sqrt(np.mean(r ** 2, axis=0))))
    c = at_rows if r.ndim == 1 else at_rows[:, main]
    rr = r if r.ndim == 1 else r[:, main]
    diff = rr - c
    cc = float(np.sum(c * c))
    scale = (float(np.sum(rr * c)) / cc - 1.0) * 1e6 if cc > 0 else 0.0
    return CorrectedReference(time_s=t[0] + k * period, ref=rate, slot=slot, ref_at_rows=at_rows,
                              period_s=period, bias_rms=float(np.sqrt(np.mean(diff ** 2))),
                              bias_max=float(np.max(np.abs(diff))),
                              bias_mean=float(np.mean(diff)), scale_ppm=scale)
