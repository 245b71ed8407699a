"""The gain of a sensor at zero frequency from the lines of a periodic motion.

A rig that sweeps back and forth puts the reference's power into a few
spectral lines: the motion's fundamental and its harmonics. At those lines
the sensor's transfer function H(f) = Y(f)/X(f) is measured with almost no
help from the noise, and without any plateau of the motion:

* the gain |H| does not see a pure delay (a latency turns H's phase only),
  so it is read from the magnitude, not from the in-phase part Re H (which
  a 12 ms lag at 1.4 Hz lowers by 0.6 %);
* a sensor's own response (a low-pass, a resonance) changes |H| as
  1 + c·f² at low frequencies, so |H| is fitted as a line in f² over the
  harmonics and read at f → 0 (the gradient correction);
* the reference's own noise (a differentiated encoder) biases a plain
  cross-spectral ratio S_yx/S_xx low by S_nn/S_xx (errors in variables).
  The estimate here is an instrumental-variable ratio: the record is cut into
  segments of whole cycles, and each segment's line is compared with the
  *next* segment's line of the reference, whose noise is independent of the
  first's: H_k = Σ_j Y_jk·conj(X_j+1,k) / Σ_j X_jk·conj(X_j+1,k). The common
  phase advance from segment to segment cancels in the ratio; the noise
  enters numerator and denominator only to first order, with zero mean.

The module knows nothing of gyroscopes: ``y`` is any output, ``x`` its
reference, both in the same unit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

__all__ = ["NoSpectralLines", "LineResponse", "ZeroFrequencyGain", "fundamental_hz", "line_responses",
           "zero_frequency_gain", "cross_spectral_gain"]

#: Line power of the reference over its floor (the mean power halfway between harmonics) that a
#: harmonic needs to be used [-]: a coherence of about 0.9 and more.
MIN_LINE_SNR = 10.0

#: Fewest cycles of the fundamental in one segment: the Hann window's main lobe (±2 bins) then
#: stays clear of the neighbouring harmonic.
MIN_CYCLES = 4

#: Segments aimed at (fewer on a short record; at least 3 are needed).
TARGET_SEGMENTS = 16

#: Most harmonics read (the fundamental counts as one).
MAX_HARMONICS = 12

#: The f² line over the harmonics is refitted without the highest line while its χ² has a
#: tail probability below this (the response is no longer quadratic there).
P_CURVED = 0.01
#: A line of the reference is read only when the gyro shows it: |h| > GYRO_LINE_Z σ (issue 44
#: item 2: an encoder's 2nd-harmonic error is a line of the reference that the rate does not have,
#: |h| ≈ 0 there, and it pulled the f² extrapolation: on the shared MPU record with its reference
#: corrected for its stamps, +32 % instead of the +0.6 % of the fundamental's whole-cycle DFT).
GYRO_LINE_Z = 3.0

#: Smallest |Σ X_j·conj(X_j+1)| / Σ |X_j|·|X_j+1| of a harmonic: below it the line's phase
#: wanders from segment to segment (the motion is not periodic at that line) [-].
MIN_PHASE_LOCK = 0.5


#: Largest fraction of a segment's samples outside ``use`` (bridged) for the segment to be read.
MAX_FILLED = 0.05


class NoSpectralLines(ValueError):
    """The reference has no line the estimate can use; the message says why (one phrase)."""


@dataclass(frozen=True)
class LineResponse:
    """The response at one line of the motion.

    Attributes
    ----------
    harmonic : int
        k of f_k = k·f0 [-].
    freq_hz : float
        f_k [Hz].
    h : complex
        The instrumental-variable ratio Y/X at the line [-] (module notes).
    h1 : complex
        The plain cross-spectral ratio S_yx/S_xx averaged over the segments [-].
    coherence : float
        γ² = |S_yx|²/(S_xx·S_yy) [-].
    snr : float
        The reference's line power over its floor (halfway to the next harmonic) [-].
    sigma_coherence : float
        σ of |h| from the coherence (Bendat & Piersol): |h|·√((1 − γ²)/(2·n_d·γ²)) [-].
    sigma_spread : float
        σ of |h| from the spread over the segments (delete-one jackknife) [-].
    n_segments : int
        n_d.
    """

    harmonic: int
    freq_hz: float
    h: complex
    h1: complex
    coherence: float
    snr: float
    sigma_coherence: float
    sigma_spread: float
    n_segments: int

    @property
    def gain(self) -> float:
        """|h| [-]."""
        return float(abs(self.h))

    @property
    def sigma(self) -> float:
        """σ of :attr:`gain`: the larger of the coherence's and the segments' spread [-]."""
        return float(max(self.sigma_coherence, self.sigma_spread))


@dataclass(frozen=True)
class ZeroFrequencyGain:
    """|H| read at f → 0 from the lines (:func:`zero_frequency_gain`).

    Attributes
    ----------
    gain, sigma : float
        |H(0)| and its 1σ [-].
    slope_per_hz2, sigma_slope : float
        c of |H(f)| ≈ |H(0)| + c·f² and its σ [1/Hz²] (0 and nan with one line).
    lines : tuple of LineResponse
        The lines the fit used, lowest first.
    dropped : tuple of LineResponse
        Lines left out, highest first, because |H| is no longer a line in f² there.
    chi2 : float
        χ² of the f² fit [-] (0 with one or two lines).
    dof : int
        Its degrees of freedom.
    fundamental_hz : float
        f0 [Hz].
    cycles_per_segment : int
        Whole cycles of f0 in one segment.
    not_shown : tuple of LineResponse
        Lines of the reference that the gyro does not show (|h| within
        :data:`GYRO_LINE_Z` σ of 0): the reference's own error (an encoder's
        harmonic), left out (:func:`cross_spectral_gain`).
    """

    gain: float
    sigma: float
    slope_per_hz2: float
    sigma_slope: float
    lines: tuple
    dropped: tuple
    chi2: float
    dof: int
    fundamental_hz: float
    cycles_per_segment: int
    not_shown: tuple = ()

    @property
    def n_segments(self) -> int:
        """Segments averaged."""
        return int(self.lines[0].n_segments)

    def describe(self) -> str:
        """One phrase: which lines, how the gain was read."""
        k = [ln.harmonic for ln in self.lines]
        what = (f"the motion's {self.fundamental_hz:.4g} Hz fundamental" if k == [1] else
                f"{len(k)} lines of the motion (harmonics {', '.join(map(str, k))} of {self.fundamental_hz:.4g} Hz)")
        how = ("|H| at the line" if len(k) == 1 else "|H| fitted as a line in f² and read at f → 0")
        out = f"{what}, {self.n_segments} segments of {self.cycles_per_segment} cycles; {how}"
        if self.not_shown:
            out += (f"; harmonic(s) {', '.join(str(ln.harmonic) for ln in self.not_shown)} of the reference "
                    f"left out: the gyro does not show them (|h| within {GYRO_LINE_Z:g} σ of 0, the reference's own error)")
        return out


def fundamental_hz(x, dt_s: float, *, min_snr: float = 100.0) -> float:
    """The frequency of the strongest spectral line of ``x`` [Hz].

    Parameters
    ----------
    x : array_like, shape (n,)
        A record of a periodic signal [any unit], uniform step ``dt_s``.
    dt_s : float
        Sample step [s].
    min_snr : float
        Power of the line over the median power of the bins from half to twice
        its frequency [-]: below it the record has no line (a random or a
        one-off motion).

    Returns
    -------
    float
        The line's frequency [Hz], refined between bins by a parabola through the
        logarithm of the Hann-windowed spectrum's magnitude.

    Raises
    ------
    NoSpectralLines
        No line stands out, or it is so slow that the record holds fewer than
        2·MIN_CYCLES of its cycles.
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    if n < 64:
        raise NoSpectralLines(f"the record is too short ({n} samples) to show a line")
    p = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(n))) ** 2
    low = 2 * MIN_CYCLES                                          # bin i: i cycles in the record
    if p.size <= low + 4:
        raise NoSpectralLines(f"the record is too short ({n} samples) to show a line")
    p[:low] = 0.0                                                 # the mean, a drift, too few cycles
    i = int(np.argmax(p))
    if p[i] <= 0.0:
        raise NoSpectralLines("the reference does not move")
    # the floor: the bins from half to twice the line's frequency, its main lobe left out (a red
    # spectrum, a wandering rate, has no bin that stands out of that)
    around = np.concatenate([p[max(i // 2, low):max(i - 3, low)], p[i + 4:2 * i + 1]])
    floor = float(np.median(around)) if around.size else 0.0
    if floor > 0.0 and p[i] < min_snr * floor:
        raise NoSpectralLines(f"the motion has no spectral line (its strongest bin is {p[i] / floor:.3g}× "
                              f"the floor around it, below {min_snr:g})")
    delta = 0.0
    if 1 <= i < p.size - 1 and min(p[i - 1], p[i + 1]) > 0.0:
        a, b, c = np.log(p[i - 1]), np.log(p[i]), np.log(p[i + 1])
        den = a - 2.0 * b + c
        delta = float(0.5 * (a - c) / den) if den < 0.0 else 0.0
    f0 = (i + max(-0.5, min(0.5, delta))) / (n * dt_s)
    if f0 * n * dt_s < 2 * MIN_CYCLES:
        raise NoSpectralLines(f"the motion's line at {f0:.3g} Hz repeats only {f0 * n * dt_s:.1f} times "
                              f"in the record (at least {2 * MIN_CYCLES} needed)")
    return float(f0)


def _segments(n: int, dt_s: float, f0_hz: float, target: int, min_cycles: int) -> tuple[int, int, int]:
    """(cycles per segment, samples per segment, segments) for segments of whole cycles."""
    cycles_total = f0_hz * n * dt_s
    c = max(min_cycles, int(cycles_total // target))
    length = int(round(c / (f0_hz * dt_s)))
    return c, length, n // length if length > 0 else 0


def line_responses(y, x, dt_s: float, f0_hz: float, *, use=None, max_harmonics: int = MAX_HARMONICS,
                   f_max_hz: float | None = None, min_snr: float = MIN_LINE_SNR,
                   target_segments: int = TARGET_SEGMENTS, min_cycles: int = MIN_CYCLES) -> list[LineResponse]:
    """The response of ``y`` to ``x`` at the lines k·f0 that ``x`` holds.

    Parameters
    ----------
    y, x : array_like, shape (n,)
        Output and reference [same unit], uniform step ``dt_s``.
    dt_s : float
        Sample step [s].
    f0_hz : float
        The motion's fundamental [Hz] (:func:`fundamental_hz`).
    use : array_like of bool, shape (n,), optional
        Samples that may be read: ``y`` is bridged linearly over the others (short
        glitches), and a segment with more than MAX_FILLED of them is left out.
    max_harmonics : int
        Most lines returned (lowest first).
    f_max_hz : float, optional
        Highest line read [Hz]; default 0.4 of the Nyquist frequency.
    min_snr : float
        Smallest line power of ``x`` over its floor (the mean power halfway
        between harmonics) [-].
    target_segments : int
        Segments aimed at: the cycles per segment are the record's cycles over
        this, at least ``min_cycles``.
    min_cycles : int
        Fewest whole cycles of f0 per segment.

    Returns
    -------
    list of LineResponse
        Lowest line first; empty when no harmonic qualifies.

    Raises
    ------
    NoSpectralLines
        Fewer than 3 segments of whole cycles are left to read.

    Notes
    -----
    Each segment of L = round(c/(f0·dt)) samples is detrended to its mean,
    Hann-windowed and transformed; line k is read at its bin k·c (a fraction of
    a bin off f_k at most, the same window loss in x and y, which cancels). With
    X_jk, Y_jk the demodulated reference and output of segment j::

        h_k   = Σ_j Y_jk·conj(X_j+1,k) / Σ_j X_jk·conj(X_j+1,k)   (instrumental variable)
        h1_k  = Σ_j Y_jk·conj(X_jk) / Σ_j |X_jk|²                  (S_yx/S_xx)
        γ²_k  = |Σ Y·conj(X)|² / (Σ |X|² · Σ |Y|²)

    σ of |h_k|: the larger of Bendat & Piersol's |h|·√((1 − γ²)/(2·n_d·γ²)) and the
    delete-one jackknife over the segment pairs.
    """
    y = np.asarray(y, dtype=float)
    x = np.asarray(x, dtype=float)
    n = x.size
    c, length, n_seg = _segments(n, dt_s, f0_hz, target_segments, min_cycles)
    starts = np.arange(n_seg) * length
    if use is not None:
        use = np.asarray(use, dtype=bool)
        if not use.any():
            raise NoSpectralLines("no sample may be read")
        if not use.all():                        # short glitches left out: bridged in y, linearly
            kept = np.flatnonzero(use)
            y = np.interp(np.arange(n), kept, y[kept])
        starts = np.array([s for s in starts if np.mean(~use[s:s + length]) <= MAX_FILLED], dtype=int)
    if starts.size < 3:
        raise NoSpectralLines(f"fewer than 3 segments of {c} whole cycles ({length * dt_s:.3g} s) to read")
    f_top = 0.4 * 0.5 / dt_s if f_max_hz is None else float(f_max_hz)
    ks = np.arange(1, int(f_top // f0_hz) + 1)
    if ks.size == 0:
        return []
    idx = starts[:, None] + np.arange(length)[None, :]
    w = np.hanning(length)
    ys = (y[idx] - y[idx].mean(axis=1, keepdims=True)) * w
    xs = (x[idx] - x[idx].mean(axis=1, keepdims=True)) * w
    # the bin of each line and the bin halfway to the next (the floor); a line a fraction of a bin
    # off its bin is read with the same window loss in x and y, which the ratios cancel
    per_bin = f0_hz * length * dt_s / c                               # bins per cycle of a segment: ≈ 1
    lines_bin = np.rint(ks * c * per_bin).astype(int)
    floor_bin = np.rint((ks + 0.5) * c * per_bin).astype(int)
    keep = floor_bin <= length // 2
    ks, lines_bin, floor_bin = ks[keep], lines_bin[keep], floor_bin[keep]
    XF, YF = np.fft.rfft(xs, axis=1), np.fft.rfft(ys, axis=1)
    X, Y = XF[:, lines_bin], YF[:, lines_bin]
    floor_x = np.mean(np.abs(XF[:, floor_bin]) ** 2, axis=0)
    out: list[LineResponse] = []
    m = starts.size
    for j, k in enumerate(ks):
        xk, yk = X[:, j], Y[:, j]
        pxx = float(np.mean(np.abs(xk) ** 2))
        snr = pxx / floor_x[j] if floor_x[j] > 0.0 else math.inf
        if snr < min_snr:
            continue
        cross = yk[:-1] * np.conj(xk[1:])                              # Y_j·conj(X_j+1)
        inst = xk[:-1] * np.conj(xk[1:])                               # X_j·conj(X_j+1)
        lock = abs(inst.sum()) / float(np.sum(np.abs(inst)))
        if lock < MIN_PHASE_LOCK:
            continue
        h = complex(cross.sum() / inst.sum())
        jack = np.array([abs((cross.sum() - cross[i]) / (inst.sum() - inst[i])) for i in range(m - 1)])
        sig_spread = float(math.sqrt((m - 2) / (m - 1) * np.sum((jack - jack.mean()) ** 2))) if m > 2 else math.inf
        syx, sxx, syy = complex(np.sum(yk * np.conj(xk))), float(np.sum(np.abs(xk) ** 2)), float(np.sum(np.abs(yk) ** 2))
        g2 = min(abs(syx) ** 2 / (sxx * syy), 1.0) if sxx > 0.0 and syy > 0.0 else 0.0
        sig_coh = abs(h) * math.sqrt((1.0 - g2) / (2.0 * m * g2)) if g2 > 0.0 else math.inf
        out.append(LineResponse(int(k), float(k * f0_hz), h, syx / sxx, float(g2), float(snr), float(sig_coh),
                                sig_spread, int(m)))
        if len(out) >= max_harmonics:
            break
    return out


def _fit_f2(lines) -> tuple[float, float, float, float, float, int]:
    """(a, σa, c, σc, χ², dof) of |h| = a + c·f² weighted by 1/σ² (σ scaled by √(χ²/dof) when > 1)."""
    g = np.array([ln.gain for ln in lines])
    s = np.array([ln.sigma for ln in lines])
    if len(lines) == 1:
        return float(g[0]), float(s[0]), 0.0, math.nan, 0.0, 0
    f2 = np.array([ln.freq_hz for ln in lines]) ** 2
    A = np.column_stack([np.ones_like(f2), f2]) / s[:, None]
    coef, *_ = np.linalg.lstsq(A, g / s, rcond=None)
    cov = np.linalg.inv(A.T @ A)
    dof = len(lines) - 2
    chi2 = float(np.sum((A @ coef - g / s) ** 2))
    scale = max(1.0, chi2 / dof) if dof > 0 else 1.0
    return (float(coef[0]), float(math.sqrt(cov[0, 0] * scale)), float(coef[1]),
            float(math.sqrt(cov[1, 1] * scale)), chi2, dof)


def zero_frequency_gain(lines, fundamental: float, cycles_per_segment: int, *,
                        p_curved: float = P_CURVED) -> ZeroFrequencyGain:
    """|H| at f → 0 from the lines (gradient-corrected over the harmonics).

    Parameters
    ----------
    lines : sequence of LineResponse
        Lowest first (:func:`line_responses`); at least one.
    fundamental : float
        f0 [Hz].
    cycles_per_segment : int
        Whole cycles per segment (for the description).
    p_curved : float
        With three lines or more, the highest is left out while the f² fit's χ²
        has a tail probability below this (|H| curves there).

    Returns
    -------
    ZeroFrequencyGain

    Notes
    -----
    ::

        |H(f_k)| = a + c·f_k²,   |H(0)| = a

    weighted by 1/σ_k²; σ_a scaled by √(χ²/dof) when that exceeds 1. With one
    line, |H(0)| = |H(f0)| (no gradient correction).
    """
    used = list(lines)
    if not used:
        raise NoSpectralLines("no harmonic of the motion stands above the reference's noise")
    dropped = []
    a, sa, c, sc, chi2, dof = _fit_f2(used)
    while len(used) >= 3 and dof > 0 and stats.chi2.sf(chi2, dof) < p_curved:
        dropped.append(used.pop())
        a, sa, c, sc, chi2, dof = _fit_f2(used)
    return ZeroFrequencyGain(a, sa, c, sc, tuple(used), tuple(dropped), chi2, dof, float(fundamental),
                             int(cycles_per_segment))


def cross_spectral_gain(y, x, dt_s: float, *, use=None, f0_hz: float | None = None,
                        max_harmonics: int = MAX_HARMONICS, f_max_hz: float | None = None,
                        min_snr: float = MIN_LINE_SNR, target_segments: int = TARGET_SEGMENTS,
                        min_cycles: int = MIN_CYCLES) -> ZeroFrequencyGain:
    """The gain of ``y`` over ``x`` at zero frequency, read from the lines of a periodic ``x``.

    Parameters
    ----------
    y, x : array_like, shape (n,)
        Output and reference [same unit], uniform step ``dt_s`` [s].
    dt_s : float
        Sample step [s].
    use : array_like of bool, shape (n,), optional
        Samples that may be read (:func:`line_responses`).
    f0_hz : float, optional
        The motion's fundamental [Hz]; default :func:`fundamental_hz` of ``x``.
    max_harmonics, f_max_hz, min_snr, target_segments, min_cycles
        As :func:`line_responses`.

    Returns
    -------
    ZeroFrequencyGain
        ``gain − 1`` is the scale-factor error of ``y`` [-].

    Raises
    ------
    NoSpectralLines
        ``x`` is not periodic, or too short, or no line stands above its noise
        (the message says which).
    """
    x = np.asarray(x, dtype=float)
    f0 = fundamental_hz(x, dt_s) if f0_hz is None else float(f0_hz)
    c, _, _ = _segments(x.size, dt_s, f0, target_segments, min_cycles)
    lines = line_responses(y, x, dt_s, f0, use=use, max_harmonics=max_harmonics, f_max_hz=f_max_hz,
                           min_snr=min_snr, target_segments=target_segments, min_cycles=min_cycles)
    shown = [ln for ln in lines if ln.gain > GYRO_LINE_Z * ln.sigma]
    not_shown = tuple(ln for ln in lines if ln.gain <= GYRO_LINE_Z * ln.sigma)
    if lines and not shown:
        raise NoSpectralLines(f"the gyro shows none of the reference's {len(lines)} line(s) (|h| within "
                              f"{GYRO_LINE_Z:g} σ of 0 at each)")
    return replace(zero_frequency_gain(shown, f0, c), not_shown=not_shown)
