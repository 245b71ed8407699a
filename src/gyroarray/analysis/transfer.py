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
from scipy import optimize, stats

__all__ = ["NoSpectralLines", "LineResponse", "ZeroFrequencyGain", "TransferCheck", "fundamental_hz", "line_responses",
           "shown_lines", "transfer_check", "line_cap", "P_RULED_OUT",
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
#: Fewest lines through which |H| is extrapolated to f → 0 (a + c·f², one degree of freedom left
#: for its χ²); with fewer the gain is |H| at the fundamental, as read (issue 44 item 2).
MIN_LINES_EXTRAPOLATED = 3

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
        how = ("|H| at the line" if len(k) == 1 else
               f"|H| fitted as a + c·f² and read at f → 0 (χ² = {self.chi2:.3g} for {self.dof} dof)")
        if len(k) == 1 and self.dropped:
            how += (f" (no extrapolation to f → 0: fewer than {MIN_LINES_EXTRAPOLATED} lines fit a + c·f² "
                    "with a χ² to check it)")
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
        has a tail probability below this (|H| curves there). Fewer than
        :data:`MIN_LINES_EXTRAPOLATED` lines left: |H| at the fundamental, not
        extrapolated (two lines fix a + c·f² with no χ² to check the model).

    Returns
    -------
    ZeroFrequencyGain

    Notes
    -----
    ::

        |H(f_k)| = a + c·f_k²,   |H(0)| = a

    weighted by 1/σ_k²; σ_a scaled by √(χ²/dof) when that exceeds 1; χ² and its
    dof (K − 2) are reported. With fewer than three lines, |H(0)| = |H(f0)| (no
    gradient correction).
    """
    used = list(lines)
    if not used:
        raise NoSpectralLines("no harmonic of the motion stands above the reference's noise")
    dropped = []
    a, sa, c, sc, chi2, dof = _fit_f2(used)
    while len(used) >= MIN_LINES_EXTRAPOLATED and dof > 0 and stats.chi2.sf(chi2, dof) < p_curved:
        dropped.append(used.pop())
        a, sa, c, sc, chi2, dof = _fit_f2(used)
    if len(used) < MIN_LINES_EXTRAPOLATED:
        # two lines fix a + c·f² exactly, with no check of the model: (4|H1| − |H2|)/3 of the
        # fundamental and 2nd harmonic read 1.33 on the MPU record. The fundamental alone, as read
        dropped.extend(reversed(used[1:]))
        used = used[:1]
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


# -- the record's own limits on a candidate's transfer function (issue 44 item 1) ---------------

#: Tail probability of the lines' χ² below which a candidate's transfer function is ruled out by the
#: lines it would have to match [-] (z ≈ 3.1 one-sided: 1 chance in 1000 for a right candidate).
P_RULED_OUT = 1e-3


@dataclass(frozen=True)
class TransferCheck:
    """A candidate's H(f) against the lines the gyro shows (:func:`transfer_check`).

    Attributes
    ----------
    chi2 : float
        Σ_k |h_k − g·H(f_k)|²/σ_k², both parts of each complex line, at the best real gain g
        (and the best nuisance, when there is one) [-].
    dof : int
        2·(lines) − 1 − (nuisance parameters).
    p : float
        Tail probability of χ²(dof) ≥ chi2 [-].
    gain : float
        The best g [-] (the scale factor's part: a gain H does not set).
    nuisance : float
        The best nuisance value (``nan`` without one) [its unit].
    lines : tuple of LineResponse
        The lines used (the gyro shows each: |h| > GYRO_LINE_Z σ).
    amp_ratio : tuple of (float, float, float)
        Per line k > 1: (measured |h_k|/|h_1|, its σ, the candidate's |H(f_k)|/|H(f_1)|) [-].
    phase_delay_s : tuple of (float, float, float)
        Per line: (measured −arg h_k/(2π f_k), its σ, the candidate's) [s].
    param : float
        The candidate's parameter where the χ² is least [its unit].
    scale : float
        The factor the lines' σ were scaled by: √(χ²/dof) of a smooth fit of no model, at
        least 1 (:func:`_smooth_scale2`) [-].
    """

    chi2: float
    dof: int
    p: float
    gain: float
    nuisance: float
    lines: tuple
    amp_ratio: tuple
    phase_delay_s: tuple
    param: float = math.nan
    scale: float = 1.0

    @property
    def ruled_out(self) -> bool:
        """The lines rule the candidate out (p < :data:`P_RULED_OUT`)."""
        return bool(self.p < P_RULED_OUT)

    def describe(self, what: str) -> str:
        """One sentence: the candidate ``what`` against the lines (the worst line named)."""
        k = [ln.harmonic for ln in self.lines]
        f0 = self.lines[0].freq_hz / self.lines[0].harmonic
        out = (f"{what} against the gyro's transfer function at {len(k)} line(s) of the motion "
               f"(harmonics {', '.join(map(str, k))} of {f0:.4g} Hz): χ² = {self.chi2:.4g} for {self.dof} dof "
               f"(p = {self.p:.2g}"
               + (f", the lines' σ scaled by {self.scale:.3g}, their roughness about a smooth H" if self.scale > 1 else "")
               + ")")
        if self.amp_ratio:
            j = int(np.argmax([abs(m - c) / s if s > 0 else 0.0 for m, s, c in self.amp_ratio]))
            m, s, c = self.amp_ratio[j]
            out += (f"; |H(h{k[j + 1]})|/|H(h{k[0]})| would be {c:.4f}, measured {m:.4f} ± {s:.2g}")
        d = self.phase_delay_s
        out += (f"; its phase delay would be {d[0][2] * 1e3:.4g}–{d[-1][2] * 1e3:.4g} ms from h{k[0]} to h{k[-1]}, "
                f"measured {d[0][0] * 1e3:.4g} ± {d[0][1] * 1e3:.2g} to {d[-1][0] * 1e3:.4g} ± {d[-1][1] * 1e3:.2g} ms")
        return out


def shown_lines(y, x, dt_s: float, *, use=None) -> tuple[float, list] | str:
    """The motion's fundamental and the lines of the reference that the gyro shows.

    Parameters
    ----------
    y, x : array_like, shape (n,)
        Output and reference [same unit], uniform step ``dt_s``.
    dt_s : float
        Sample step [s].
    use : array_like of bool, shape (n,), optional
        Samples that may be read (:func:`line_responses`).

    Returns
    -------
    (float, list of LineResponse) or str
        f0 [Hz] and the lines with |h| > :data:`GYRO_LINE_Z` σ (lowest first), or a phrase saying
        why there are none (no periodic motion, too short).
    """
    try:
        f0 = fundamental_hz(np.asarray(x, dtype=float), dt_s)
        lines = line_responses(y, x, dt_s, f0, use=use)
    except NoSpectralLines as err:
        return str(err)
    shown = [ln for ln in lines if ln.gain > GYRO_LINE_Z * ln.sigma]
    if not shown:
        return "the gyro shows none of the motion's lines"
    return f0, shown


def transfer_check(lines, model, p_hat: float, sigma_p: float = math.nan, *, free_delay: bool = False,
                   free_curvature: bool = True, lower: float = -math.inf) -> TransferCheck:
    """A candidate's transfer function H(f; p) against measured lines, a real gain left free.

    Parameters
    ----------
    lines : sequence of LineResponse
        The lines the gyro shows (:func:`shown_lines`), lowest first; at least one.
    model : callable
        ``model(f_hz, p) -> complex ndarray``: the candidate's H at the lines' frequencies [Hz]
        for its parameter p [its unit].
    p_hat, sigma_p : float
        The candidate's fitted parameter and its 1σ [its unit]: p is profiled with the penalty
        ((p − p_hat)/σ_p)² (the lines and the fit must agree on one value); fixed at p_hat when
        σ_p is not a positive number.
    free_delay : bool
        A pure delay exp(−i 2π f τ) left free too (a rival delay the model does not have yet,
        which a low-pass must not be refused for).
    free_curvature : bool
        The gain's own f² curvature left free, (g + b·f²)·H: a reference differentiated by
        centred differences reads sin(x)/x of the rate (x = 2π f dt: +1.2 % at 4 Hz and 100 Hz
        on the MPU record, whose |h| rises from 1.0060 at h1 to 1.0126 at h9), which no
        candidate of the gyro's own models; a low-pass then has its phase dispersion and its
        amplitude beyond f² to match, a delay its flat phase delay.
    lower : float
        Smallest p the model takes (a cut-off above 0).

    Returns
    -------
    TransferCheck
        ``nuisance``: the free delay [s] (nan without); the lines' χ² and the penalty together.

    Notes
    -----
    With h_k the measured lines and σ_k the σ of |h_k| (taken as the σ of each part of the
    complex ratio: a circular error), H_k = model(f_k, p)·exp(−i 2π f_k τ)::

        g = Σ Re(conj(H_k)·h_k)/σ_k² / Σ |H_k|²/σ_k²
        χ² = min over p (and τ) of Σ |h_k − g·H_k|²/σ_k² + ((p − p̂)/σ_p)²

    (with ``free_curvature``, g·H_k becomes (g + b·f_k²)·H_k, b real and free) with 2K − 1
    degrees of freedom, one fewer for each of the free delay and the curvature. The gain g is
    free because a scale factor (not the candidate's) sets it; what the candidate must match
    are the amplitude ratios |h_k|/|h_1| and the phase delays −arg h_k/(2π f_k), together.
    """
    lines = list(lines)
    f = np.array([ln.freq_hz for ln in lines])
    h = np.array([ln.h for ln in lines])
    s = np.array([max(ln.sigma, 1e-300) for ln in lines])
    w = 1.0 / s ** 2
    profiled = math.isfinite(sigma_p) and sigma_p > 0.0

    sw = np.sqrt(w)
    target = np.concatenate([(h * sw).real, (h * sw).imag])

    def chi2_g(H):
        """(χ², g, b/g) of h ≈ (g + b·f²)·H, g and b real, by weighted least squares."""
        cols = [H * sw] + ([H * f ** 2 * sw] if free_curvature else [])
        A = np.column_stack([np.concatenate([c.real, c.imag]) for c in cols])
        coef, *_ = np.linalg.lstsq(A, target, rcond=None)
        bg = float(coef[1] / coef[0]) if free_curvature and coef[0] != 0 else 0.0
        return float(np.sum((A @ coef - target) ** 2)), float(coef[0]), bg

    scale2 = _smooth_scale2(f, h, s)

    def at(p):
        """(χ², g, τ, b/g) at p, the delay profiled; the lines' χ² over the smooth fit's scale²."""
        H = np.asarray(model(f, p), dtype=complex)
        pen = ((p - p_hat) / sigma_p) ** 2 if profiled else 0.0
        if not free_delay:
            c, g, bg = chi2_g(H)
            return c / scale2 + pen, g, math.nan, bg
        tau0 = float(-np.angle(h[0] / H[0]) / (2 * math.pi * f[0]))
        half = 0.5 / float(f.max())

        def c_of(tau):
            return chi2_g(H * np.exp(-2j * math.pi * f * tau))[0]
        taus = tau0 + np.linspace(-half, half, 21)
        j = int(np.argmin([c_of(x) for x in taus]))
        res = optimize.minimize_scalar(c_of, bounds=(taus[max(j - 1, 0)], taus[min(j + 1, 20)]),
                                       method="bounded", options={"xatol": 1e-9})
        tau = float(res.x)
        c, g, bg = chi2_g(H * np.exp(-2j * math.pi * f * tau))
        return c / scale2 + pen, g, tau, bg

    p = float(p_hat)
    if profiled:
        grid = p_hat + sigma_p * np.linspace(-8.0, 8.0, 33)
        grid = grid[grid > lower] if np.any(grid > lower) else np.array([p_hat])
        vals = [at(x)[0] for x in grid]
        j = int(np.argmin(vals))
        lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
        if hi > lo:
            res = optimize.minimize_scalar(lambda x: at(x)[0], bounds=(lo, hi), method="bounded")
            p = float(res.x) if res.fun < vals[j] else float(grid[j])
        else:
            p = float(grid[j])
    chi2, g, tau, bg = at(p)
    H = np.asarray(model(f, p), dtype=complex) * (1.0 + bg * f ** 2)
    if free_delay:
        H = H * np.exp(-2j * math.pi * f * tau)
    dof = max(2 * len(lines) - 1 - (1 if free_delay else 0) - (1 if free_curvature else 0), 1)
    amp = tuple((float(abs(h[k]) / abs(h[0])),
                 float(abs(h[k]) / abs(h[0]) * math.hypot(s[k] / abs(h[k]), s[0] / abs(h[0]))),
                 float(abs(H[k]) / abs(H[0]))) for k in range(1, len(lines)))
    delay = tuple((float(-np.angle(h[k]) / (2 * math.pi * f[k])), float(s[k] / abs(h[k]) / (2 * math.pi * f[k])),
                   float(-np.angle(H[k]) / (2 * math.pi * f[k]))) for k in range(len(lines)))
    return TransferCheck(chi2, int(dof), float(stats.chi2.sf(chi2, dof)), g, tau, tuple(lines), amp, delay,
                         float(p), float(math.sqrt(scale2)))


def _smooth_scale2(f: np.ndarray, h: np.ndarray, s: np.ndarray) -> float:
    """χ²/dof (at least 1) of the lines about a smooth transfer function of no particular model:
    ln|h| on (1, f², f⁴) and arg h on (f, f³), each weighted by (|h|/σ)² [-].

    The lines' own σ (coherence, jackknife) leave out what varies from harmonic to harmonic
    without a model's shape (an encoder's line errors): on the MPU record the best pure delay
    has χ² 153 for 20 dof, and this smooth fit about as much. The candidate's χ² is read over
    this scale, so that it is refused for its shape or its value, not for the lines' roughness.
    1 with fewer than 4 lines (2K − 5 < 3 degrees of freedom)."""
    k = f.size
    if 2 * k - 5 < 3:
        return 1.0
    wt = (np.abs(h) / s) ** 2
    sw = np.sqrt(wt)
    amp = np.log(np.abs(h))
    ph = np.unwrap(np.angle(h))
    chi2 = 0.0
    for y, cols in ((amp, [np.ones_like(f), f ** 2, f ** 4]), (ph, [f, f ** 3])):
        A = np.column_stack(cols) * sw[:, None]
        coef, *_ = np.linalg.lstsq(A, y * sw, rcond=None)
        chi2 += float(np.sum((A @ coef - y * sw) ** 2))
    return max(1.0, chi2 / (2 * k - 5))


def line_cap(y, x2, dt_s: float, f0_hz: float, harmonic: int = 2, *, use=None) -> tuple[float, float] | str:
    """The gyro's line at ``harmonic``·f0 over a regressor's line there: a cap on its coefficient.

    Parameters
    ----------
    y : array_like, shape (n,)
        The gyro's output [rad/s] (the residual plus the sensed reference).
    x2 : array_like, shape (n,)
        The regressor (u² for a rate-squared term) [its unit].
    dt_s : float
        Sample step [s].
    f0_hz : float
        The motion's fundamental [Hz].
    harmonic : int
        The line read (2: a rate² term of a periodic motion puts its first line at 2 f0).
    use : array_like of bool, shape (n,), optional
        Samples that may be read.

    Returns
    -------
    (float, float) or str
        |Y/X2| at the line and its σ [unit of y over unit of x2] (the instrumental-variable
        ratio of :func:`line_responses`), or why not (the regressor has no line there).
    """
    try:
        lines = line_responses(y, x2, dt_s, f0_hz, use=use, max_harmonics=harmonic)
    except NoSpectralLines as err:
        return str(err)
    at = [ln for ln in lines if ln.harmonic == harmonic]
    if not at:
        return f"the regressor has no line at {harmonic} f0 = {harmonic * f0_hz:.4g} Hz"
    return at[0].gain, at[0].sigma
