"""What a data pipeline did to a record before it was handed over: held samples and a brick-wall roll-off.

A phone, a logger or a driver often processes the samples before anyone sees
them: it repeats the last value when a sample is late (*held samples*), and it
decimates a fast stream with a sharp, zero-phase low-pass (*a brick-wall
roll-off*: no lag, the spectrum falls by decades within a narrow band below
Nyquist). Both are properties of the record, not of the sensor; no effect of
the sensor should be fitted to them. This module only detects and describes
them (it knows no effect):

* **Holds.** A held sample equals the one before it exactly. Without holds a
  record shows exact repeats only by chance: as many as there are first
  differences at one of ±q, q the smallest non-zero step, times
  (c₁/c₂)^(1/3), c₁ and c₂ the counts per level at ±q and ±2q (a density
  of the differences that is Gaussian near 0, extrapolated to 0), q a quantized
  record's grid step, read where most of the lowest percent of the non-zero
  differences share one value to 0.1 %; else the smallest difference: a
  record in floating point has next to none). The
  repeats beyond that chance level, by more than :data:`HOLD_Z` Poisson
  standard deviations and at least :data:`MIN_HOLD_FRACTION` of the samples,
  and beyond the record's own exact repeats at lags 2 and 3 (their line
  extrapolated to lag 1, at least the lag-2 count) by :data:`HOLD_Z` times
  the excess's own spread over :data:`HOLD_BLOCKS` blocks,
  are holds: a held sample repeats the one just before it, not the one two or
  three before, while a coarse quantizer whose signal moves less than one
  step per sample repeats at every lag alike (the spec's angle counter at
  0.1 step per sample: its increments are not Gaussian near 0, and the
  density's extrapolation read 37 800 repeats as 2 800 beyond chance, z 15;
  at lag 2 it repeats more often than at lag 1). A record whose differences
  are correlated (a low-pass below the grid, a decimator) repeats more at
  lag 1 than at lag 2 by its colour alone (the ADIS16405 and MIMU4444
  records: up to 1.8 times, at chance by the density), so the density's test
  is kept (both must say holds); a *run* is a maximal stretch of samples each
  equal to the one before. Repeats at the series' lowest or highest value
  (a clipped range, saturation) and runs longer than :data:`MAX_HOLD_RUN`
  (a stuck output) are the sensor's, not holds, and are not counted.
* **Roll-off.** On the Welch spectrum (mean over the gyros of each one's
  log-PSD, the held samples bridged linearly first), the lowest frequency
  from which the level falls by :data:`ROLLOFF_DECADES` decades within a
  frequency ratio of :data:`ROLLOFF_RATIO`, below :data:`ROLLOFF_TOP` ×
  Nyquist (at least ~4 decades of power per octave: a Butterworth of order 7
  or more, a zero-phase filter applied forward and back, a decimator's FIR).
  It is a brick wall when it falls from the corner to :data:`ROLLOFF_DECADES` below it within a frequency
  ratio of :data:`STOP_RATIO` (a causal filter of order 4 with a floor of
  quantization below it falls as far, but over a wider band), and beyond
  it the fall does not speed up towards Nyquist (the fall per Hz over the
  upper half of the rest at most 1.5 × the lower half's + 0.3 decade: a
  floor, or a slope that flattens; a causal filter made by the bilinear
  transform falls ever faster into its null at Nyquist instead). The corner is where
  the level first falls to half (−3 dB) of the passband just below the fall.
  A causal filter of high order with its corner near Nyquist and a floor
  below it cannot be told from a zero-phase one by the spectrum alone (that
  needs the lag on motion).

* **Resampling.** A record resampled onto uniform stamps by linear
  interpolation (from another rate, or a jittering clock repaired) has a
  noise level that beats: samples that fall on an original one keep its
  variance, those halfway between two lose half of it, in a pattern that
  repeats at the beat |f_s − k·f₀|. The power of the second difference of
  the high band (above 0.3 × Nyquist, so that motion does not enter) then
  has one strong line: at least :data:`BEAT_RATIO` times its mean
  periodogram ordinate, at or above :data:`BEAT_MIN_HZ`. It is reported
  (the beat [Hz]); no test is changed by it.

A sensor's own first- or second-order low-pass falls by about one decade per
octave at most and is not reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

#: Holds are reported when the exact repeats exceed their chance level by this many Poisson σ.
HOLD_Z = 5.0
#: Consecutive blocks whose spread gives the spread of the repeats' excess over their lag chance.
HOLD_BLOCKS = 20
#: Fewest held samples reported [share of the samples]: a quantized record resampled by linear
#: interpolation (a repaired clock) keeps some of its chance repeats exactly, off the grid the
#: chance level is read on (the MPU-6050 record after --repair: 0.2 %, at chance on its raw grid).
MIN_HOLD_FRACTION = 0.005
#: Longest run of repeats counted as held [samples]: a pipeline repeats a late sample a few
#: times; a longer run is a stuck output (a fault of the sensor).
MAX_HOLD_RUN = 8
#: A roll-off is read within this frequency ratio (f_end / f_start).
ROLLOFF_RATIO = 1.3
#: Fewest decades of power the level must fall within :data:`ROLLOFF_RATIO` to be a brick wall.
ROLLOFF_DECADES = 1.5
#: The fall must end at or below this fraction of Nyquist (a bilinear filter's null sits at Nyquist).
ROLLOFF_TOP = 0.92
#: Lowest start of a roll-off [fraction of Nyquist] (below it a fall is the noise's shape, not a filter).
ROLLOFF_BOTTOM = 0.1
#: From the corner (−3 dB) to the floor (within 0.3 decade of it) within this frequency ratio at most.
STOP_RATIO = 1.4
#: τ·corner below which a brick-wall roll-off moves the Allan variance of white noise by more
#: than 5 % (it takes ≈ 1.5/(π²·τ·f_c) of it away).
TAU_CORNERS = 3.0
#: A resampling beat: the strongest line of the high band's second-difference power carries at
#: least this many times the mean periodogram ordinate (clean records: 15–50; a linear
#: interpolation from 98 to 100 Hz: 3000; the MPU-6050 record after its clock repair: 1e4).
BEAT_RATIO = 1000.0
#: Lowest beat frequency [Hz] read (and at least 50 cycles over the record): slower changes of
#: the noise level are motion, temperature or a burst, not an interpolation's pattern.
BEAT_MIN_HZ = 0.5
#: Samples read for the beat (the first ones): enough for its line, bounded in time.
BEAT_SAMPLES = 1 << 18
#: Welch segment length [samples] (at most; a record shorter than 8 of them uses n // 8).
NPERSEG = 1024


@dataclass(frozen=True)
class GyroHolds:
    """Held samples of one gyro.

    Attributes
    ----------
    n_held : int
        Samples exactly equal to the sample before them.
    n_runs : int
        Maximal runs of such samples.
    fraction : float
        ``n_held`` / samples.
    chance : float
        Exact repeats expected without holds (first differences at the smallest non-zero step).
    significant : bool
        ``n_held`` exceeds ``chance`` by more than :data:`HOLD_Z` Poisson σ and is at least
        :data:`MIN_HOLD_FRACTION` of the samples: the record holds samples.
    """

    n_held: int
    n_runs: int
    fraction: float
    chance: float
    significant: bool


@dataclass(frozen=True)
class PipelineReport:
    """What :func:`detect_pipeline` found in a record.

    Attributes
    ----------
    dt_s : float
        Sample interval [s].
    n : int
        Samples.
    holds : tuple of GyroHolds
        Per gyro, in column order.
    corner_hz : float or None
        −3 dB corner of a brick-wall roll-off [Hz]; None when none is seen.
    rolloff_hz : tuple of float or None
        (corner, where the level reaches its floor) [Hz]; None when none is seen.
    drop_decades : float
        Fall of the power from the passband to the floor [decades] (0 when none is seen).
    beat_hz : float or None
        Beat of a resampling by interpolation [Hz]; None when none is seen.
    """

    dt_s: float
    n: int
    holds: tuple
    corner_hz: float | None
    rolloff_hz: tuple | None
    drop_decades: float
    beat_hz: float | None = None

    @property
    def nyquist_hz(self) -> float:
        """Nyquist frequency [Hz]."""
        return 0.5 / self.dt_s

    @property
    def held(self) -> bool:
        """Some gyro holds samples."""
        return any(h.significant for h in self.holds)

    @property
    def filtered(self) -> bool:
        """A brick-wall roll-off is seen."""
        return self.corner_hz is not None

    @property
    def resampled(self) -> bool:
        """A resampling beat is seen."""
        return self.beat_hz is not None

    @property
    def processed(self) -> bool:
        """The record shows a pipeline (holds, a brick-wall roll-off or a resampling)."""
        return self.held or self.filtered or self.resampled

    @property
    def tau_s(self) -> float:
        """τ below which the ADEV reflects the processing [s]: :data:`TAU_CORNERS` / corner with a
        roll-off (a brick wall at f_c takes ≈ 0.15/(τ·f_c) of white noise's Allan variance away,
        5 % at τ = 3/f_c), else 4 samples with holds (runs of a few samples), else 0."""
        held = 4.0 * self.dt_s if self.held else 0.0
        if self.corner_hz is not None:
            return max(TAU_CORNERS / self.corner_hz, held)
        return held

    def hold_mask(self, x, width: int = 3) -> np.ndarray:
        """Samples (n, n_gyros) bool within ``width`` samples of a held sample, on the gyros that
        hold samples (:attr:`GyroHolds.significant`); all False elsewhere."""
        x = np.asarray(x, dtype=float)
        x = x.reshape(x.shape[0], -1)
        out = np.zeros(x.shape, bool)
        for g, h in enumerate(self.holds):
            if h.significant and g < x.shape[1]:
                out[:, g] = near_holds(x[:, g], width)
        return out

    def verdict(self) -> str:
        """One sentence: what processed the record, and which τ and band reflect it ('' if none)."""
        if not self.processed:
            return ""
        parts = []
        if self.held:
            per = "; ".join(f"gyro {g + 1}: {h.n_held} in {h.n_runs} runs, {100 * h.fraction:.2g} %"
                            for g, h in enumerate(self.holds) if h.significant)
            parts.append(f"held samples ({per})")
        if self.filtered:
            assert self.rolloff_hz is not None
            parts.append(f"a zero-phase decimation filter (a brick-wall roll-off at {self.corner_hz:.3g} Hz, "
                         f"{self.drop_decades:.2g} decades down by {self.rolloff_hz[1]:.3g} Hz)")
        if self.resampled:
            parts.append(f"a resampling by interpolation (its noise level beats at {self.beat_hz:.4g} Hz)")
        where = []
        if self.tau_s > 0:
            where.append(f"τ below {self.tau_s:.2g} s")
        if self.filtered:
            where.append(f"the band above {self.corner_hz:.3g} Hz")
        if self.resampled:
            where.append(f"a line at {self.beat_hz:.4g} Hz in the noise level")
        return (f"this record was processed by {' and '.join(parts)} before you got it; {' and '.join(where)} "
                "reflect the processing, not the sensor")

    def to_json_dict(self) -> dict:
        """A plain JSON object (numbers finite or None)."""
        return {"processed": self.processed,
                "holds": [{"gyro": g + 1, "n_held": h.n_held, "n_runs": h.n_runs, "fraction": h.fraction,
                           "chance": h.chance, "significant": h.significant} for g, h in enumerate(self.holds)],
                "corner_hz": self.corner_hz,
                "rolloff_hz": None if self.rolloff_hz is None else list(self.rolloff_hz),
                "drop_decades": self.drop_decades,
                "beat_hz": self.beat_hz,
                "tau_s": self.tau_s,
                "verdict": self.verdict()}


def near_holds(x, width: int = 3) -> np.ndarray:
    """Samples within ``width`` samples of a held one (a sample exactly equal to the one before) (n,) bool.

    Parameters
    ----------
    x : array_like (n,)
        One series [any unit].
    width : int
        Samples on each side of a held sample also marked.
    """
    held = held_samples(x)
    if width <= 0 or not held.any():
        return held
    k = np.ones(2 * width + 1)
    return np.convolve(held.astype(float), k, mode="same") > 0


def held_samples(x) -> np.ndarray:
    """Samples (n,) bool exactly equal to the sample before them, in runs of at most
    :data:`MAX_HOLD_RUN`, and not at the series' lowest or highest value: a clipped, saturated
    stretch repeats its value too, and a stuck output for long; that is the sensor, not the
    pipeline.

    Parameters
    ----------
    x : array_like (n,)
        One series [any unit].
    """
    x = np.asarray(x, dtype=float)
    held = np.zeros(x.size, bool)
    if x.size < 2:
        return held
    held[1:] = np.diff(x) == 0
    fin = x[np.isfinite(x)]
    if held.any() and fin.size:
        held &= (x != fin.max()) & (x != fin.min())
    if held.any():
        edges = np.diff(np.concatenate(([0], held.view(np.int8), [0])))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        for a, b in zip(starts, stops):
            if b - a > MAX_HOLD_RUN:
                held[a:b] = False
    return held


def _step(a: np.ndarray) -> float:
    """The smallest step of the non-zero |first differences| ``a``: a quantized record's grid step
    (most of their lowest percent one value, to 0.1 %: a grid written with a few decimals), else
    the smallest one."""
    k = max(1, a.size // 100)
    low = np.partition(a, k - 1)[:k] if k < a.size else a
    q = float(np.median(low))
    return q if np.mean(np.abs(low - q) <= 1e-3 * q) >= 0.5 else float(low.min())


def gyro_holds(x) -> GyroHolds:
    """Held samples of one series (module docstring).

    Parameters
    ----------
    x : array_like (n,)
        One gyro's output [any unit].
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    if n < 3:
        return GyroHolds(0, 0, 0.0, 0.0, False)
    d = np.diff(x)
    held = held_samples(x)[1:]
    n_held = int(held.sum())
    n_runs = int(np.count_nonzero(held[1:] & ~held[:-1]) + held[0])
    a = np.abs(d[np.isfinite(d) & (d != 0)])
    a = a[a > 1e-9 * float(np.max(np.abs(x[np.isfinite(x)]), initial=0.0))]   # not rounding
    if a.size:
        q = _step(a)
        c1 = 0.5 * float(np.count_nonzero(np.abs(a - q) <= 0.5 * q))          # per level at ±q
        c2 = 0.5 * float(np.count_nonzero(np.abs(a - 2 * q) <= 0.5 * q))      # at ±2q
        chance = c1 * max(c1 / c2, 1.0) ** (1.0 / 3.0) if c2 > 0 else c1     # log-quadratic to 0
    else:
        chance = float(n_held)                                   # a constant series: nothing to tell
    significant = bool(n_held > chance + HOLD_Z * math.sqrt(chance + 1.0) and n_held >= MIN_HOLD_FRACTION * n)
    if significant:              # and beyond the record's own repeats at the next lags
        lag_chance, lag_sigma = _lag_chance(x, held_samples(x))
        significant = n_held > lag_chance + HOLD_Z * lag_sigma
        chance = max(chance, lag_chance)
    return GyroHolds(n_held, n_runs, n_held / n, chance, significant)


def _lag_chance(x: np.ndarray, held: np.ndarray) -> tuple[float, float]:
    """(repeats at lag 1 expected from the record's own repeats at lags 2 and 3, the spread of the
    excess [repeats]) (module docstring, "Holds").

    ``c_L`` counts the samples equal to the one ``L`` before (the range's ends and the runs longer
    than :data:`MAX_HOLD_RUN` left out, as :func:`held_samples` does); chance at lag 1 is
    ``max(c_2, 2·c_2 − c_3)``, the line through lags 2 and 3 (i.i.d. samples on a grid: ``c_L`` the
    same at every lag; a level crossed at a steady rate: linear in ``L``). The spread is the
    excess's own over :data:`HOLD_BLOCKS` consecutive blocks (√B × their sd: repeats come in runs,
    they are not independent), at least the Poisson σ of the chance count."""
    n = x.size
    raw = np.zeros(n, bool)
    raw[1:] = np.diff(x) == 0
    fin = x[np.isfinite(x)]
    ok = np.isfinite(x) & (x != fin.max()) & (x != fin.min())
    long = raw & ~held & ok                      # repeats in a run longer than MAX_HOLD_RUN
    ok &= ~(long | np.concatenate((long[1:], [False])))
    rep = [held]
    for lag in (2, 3):
        r = np.zeros(n, bool)
        r[lag:] = (x[lag:] == x[:-lag]) & ok[lag:] & ok[:-lag]
        rep.append(r)

    def excess(a: int, b: int) -> tuple[int, float]:
        c1, c2, c3 = (int(np.count_nonzero(r[a:b])) for r in rep)
        return c1, float(max(c2, 2 * c2 - c3))

    c1, chance = excess(0, n)
    blocks = min(HOLD_BLOCKS, n // 50)
    sd = 0.0
    if blocks >= 2:
        edges = np.linspace(0, n, blocks + 1).astype(int)
        e = [c - ch for c, ch in (excess(a, b) for a, b in zip(edges[:-1], edges[1:]))]
        sd = math.sqrt(blocks) * float(np.std(e, ddof=1))
    return chance, max(sd, math.sqrt(chance + 1.0))


def _bridged(x: np.ndarray) -> np.ndarray:
    """``x`` with each held sample replaced by the line between its unheld neighbours."""
    held = held_samples(x)
    if not held.any() or held.all():
        return x
    k = np.arange(x.size)
    out = x.copy()
    out[held] = np.interp(k[held], k[~held], x[~held])
    return out


def _rolloff(x: np.ndarray, dt_s: float, bridge: np.ndarray) -> tuple:
    """(corner [Hz], floor start [Hz], drop [decades]) of a brick-wall roll-off, or (None, None, 0)."""
    n = x.shape[0]
    nper = min(NPERSEG, n // 8)
    if nper < 64:
        return None, None, 0.0
    fs = 1.0 / dt_s
    fn = 0.5 * fs
    logs = []
    for g in range(x.shape[1]):
        col = _bridged(x[:, g]) if bridge[g] else x[:, g]
        f, p = signal.welch(col - col.mean(), fs=fs, nperseg=nper, detrend=False)
        if not np.all(p[1:] > 0):
            continue
        logs.append(np.log10(p[1:]))
    if not logs:
        return None, None, 0.0
    f = f[1:]
    L = np.mean(logs, axis=0)
    L = np.convolve(L, np.ones(5) / 5, mode="same")          # ±2 bins: the Welch scatter
    L[:2], L[-2:] = L[2], L[-3]
    lo = np.searchsorted(f, ROLLOFF_BOTTOM * fn)
    top = np.searchsorted(f, ROLLOFF_TOP * fn, side="right") - 1
    bi = -1
    for i in range(lo, top):                                     # the lowest start of a deep fall
        j = min(np.searchsorted(f, ROLLOFF_RATIO * f[i], side="right") - 1, top)
        if j <= i:
            break
        if float(L[i] - L[i:j + 1].min()) >= ROLLOFF_DECADES:
            bi = i
            break
    if bi < 0:
        return None, None, 0.0
    pass_band = (f >= 0.7 * f[bi]) & (f <= f[bi])
    level = float(np.median(L[pass_band])) if pass_band.any() else float(L[bi])
    half = level - math.log10(2.0)
    below = np.flatnonzero((f >= 0.7 * f[bi]) & (L < half))
    if below.size == 0:
        return None, None, 0.0
    c = int(below[0])
    c0 = max(c - 1, 0)                                          # between the bins around half power
    corner = float(f[c0] + (half - L[c0]) * (f[c] - f[c0]) / (L[c] - L[c0])) if L[c0] != L[c] else float(f[c])
    reach = np.flatnonzero((f > corner) & (L <= half - ROLLOFF_DECADES))
    if reach.size == 0:
        return None, None, 0.0
    s = int(reach[0])
    stop = float(f[s])
    if stop > STOP_RATIO * corner or stop > ROLLOFF_TOP * fn:
        return None, None, 0.0                                  # a gradual fall: a sensor's low-pass
    end = min(int(np.searchsorted(f, 0.98 * fn)), f.size - 1)
    tail = L[s:end + 1]
    if end - s >= 4:
        mid = s + int(np.searchsorted(f[s:end + 1], 0.5 * (f[s] + f[end])))
        lower, upper = float(L[s] - L[mid]), float(L[mid] - L[end])
        if upper > 1.5 * max(lower, 0.0) + 0.3:
            return None, None, 0.0                              # it falls ever faster: a null at Nyquist
    floor = float(np.median(tail)) if tail.size else float(L[s])
    return corner, stop, level - floor


def _beat(x: np.ndarray, dt_s: float) -> float | None:
    """The beat of a resampling by interpolation [Hz] (module docstring), or None."""
    x = x[:BEAT_SAMPLES]
    n = x.shape[0]
    fs = 1.0 / dt_s
    lo = max(BEAT_MIN_HZ, 50.0 / (n * dt_s))
    if n < 1024 or lo >= 0.5 * fs:
        return None
    sos = signal.butter(4, 0.15 * fs, btype="high", fs=fs, output="sos")
    found = []
    for g in range(x.shape[1]):
        h = signal.sosfiltfilt(sos, x[:, g] - x[:, g].mean())
        d2 = h[1:-1] - 0.5 * (h[:-2] + h[2:])
        v = d2 * d2
        f, p = signal.periodogram(v - v.mean(), fs=fs, detrend=False)
        use = f >= lo
        if not use.any() or not p[1:].mean() > 0:
            continue
        k = int(np.argmax(np.where(use, p, -np.inf)))
        if p[k] >= BEAT_RATIO * float(p[1:].mean()):
            found.append(float(f[k]))
    return float(np.median(found)) if found and len(found) * 2 > x.shape[1] else None


def detect_pipeline(x, dt_s: float) -> PipelineReport:
    """Held samples and a brick-wall roll-off of a record (module docstring).

    Parameters
    ----------
    x : array_like (n, n_gyros) or (n,)
        The gyros' outputs as recorded [any unit, e.g. deg/s]; the comparison is of values, so
        pass them before any arithmetic (a model taken out breaks exact repeats).
    dt_s : float
        Sample interval [s].

    Returns
    -------
    PipelineReport
        Per-gyro hold statistics, the roll-off's corner and band [Hz] and its depth [decades],
        a resampling's beat [Hz].
    """
    x = np.asarray(x, dtype=float)
    x = x.reshape(x.shape[0], -1)
    holds = tuple(gyro_holds(x[:, g]) for g in range(x.shape[1]))
    if not (math.isfinite(dt_s) and dt_s > 0) or not np.all(np.isfinite(x)):
        return PipelineReport(float(dt_s), int(x.shape[0]), holds, None, None, 0.0)
    corner, stop, drop = _rolloff(x, float(dt_s), np.array([h.significant for h in holds]))
    return PipelineReport(float(dt_s), int(x.shape[0]), holds, corner,
                          None if corner is None else (corner, stop), float(drop), _beat(x, float(dt_s)))


def passband_change(x, dt_s: float, start: int, report: PipelineReport, held=None,
                    stop: int | None = None) -> tuple:
    """A change of the noise level from sample ``start`` on (to ``stop``), read where the pipeline
    does not act.

    The held samples are bridged (the line between their unheld neighbours),
    and the series is band-passed (zero-phase Butterworth of order 4) to
    [0.15, 1] × the top of the band the processing leaves alone: 0.7 × the
    roll-off's corner, or 0.5 × Nyquist without a roll-off. The variance after
    ``start`` (to ``stop``: a window) over the one of the rest is χ²-distributed
    with 2·B·T degrees of freedom each side (B the band [Hz], T each side's
    span [s]).

    Parameters
    ----------
    x : array_like (n,)
        One gyro's residual [any unit].
    dt_s : float
        Sample interval [s].
    start : int
        First sample of the second part.
    stop : int, optional
        End of the second part (exclusive; default the record's end): the rest of the record,
        both sides of it, is the first part.
    report : PipelineReport
        The record's pipeline (:func:`detect_pipeline`).
    held : array_like (n,) of bool, optional
        Held samples of the outputs as recorded (:func:`held_samples`; their repeats are lost in
        a residual); by default those of ``x``.

    Returns
    -------
    ratio, z : float
        Variance of the second part / the first's in the band, and |ln ratio| over its standard
        error (≈ |N(0, 1)| for no change); (1, NaN) when either part is too short (less than one
        period of the band's lower edge) or the record shorter than 64 of them: not read.
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    held = held_samples(x) if held is None else np.asarray(held, dtype=bool)
    if held.any() and not held.all():
        k = np.arange(n)
        x = x.copy()
        x[held] = np.interp(k[held], k[~held], x[~held])
    fn = 0.5 / dt_s
    top = 0.7 * report.corner_hz if report.corner_hz is not None else 0.5 * fn
    lo = 0.15 * top
    edge = int(math.ceil(4.0 / (lo * dt_s)))
    stop = n if stop is None else int(min(max(stop, start), n))
    inside = np.zeros(n, bool)
    inside[start:stop] = True
    keep = np.zeros(n, bool)
    keep[edge:n - edge] = True
    if n < 16 * edge or min(np.count_nonzero(inside & keep), np.count_nonzero(~inside & keep)) < edge / 4:
        return 1.0, math.nan
    v = signal.sosfiltfilt(signal.butter(4, [lo, top], btype="band", fs=1.0 / dt_s, output="sos"), x - x.mean())
    a, b = v[~inside & keep], v[inside & keep]
    va, vb = float(np.mean(a * a)), float(np.mean(b * b))
    if not (va > 0 and vb > 0):
        return 1.0, math.nan
    nu_a, nu_b = 2.0 * (top - lo) * a.size * dt_s, 2.0 * (top - lo) * b.size * dt_s
    ratio = vb / va
    return ratio, abs(math.log(ratio)) / math.sqrt(2.0 / nu_a + 2.0 / nu_b)
