"""``outliers``: isolated single-sample spikes (heavy-tailed first differences, not a noise level).

Isolated single-sample spikes in a gyro record: found, counted, sized, removed.

A spike is one sample that departs from its neighbours by far more than the
noise: the residual minus the median of its four neighbours (two on each
side, itself left out, so d is continuous and ≈ normal for Gaussian noise),
d, against the noise's robust standard deviation σ̂ = 1.4826·MAD(d). A spike moves one
sample's d and no median, so it stands out; a change of the noise level (a
burst) moves the MAD of a whole stretch and does not.

* σ̂ is local: 1.4826 × the running median of |d| over 2001 samples, so a
  noise level that changes over the record (a burst) is not read as a crowd
  of spikes; samples with d exactly 0 (a clipped stretch) are left out.
* Detection (which samples): |d| > c·σ̂ with c the Bonferroni threshold of a
  1 % family-wise false alarm over the record's samples (a clean Gaussian
  record shows a spike with probability 1 %), and at least 6: real noise has
  heavier tails than a Gaussian (the Xsens MTi-G record: 19 000 samples
  beyond 4σ̂, 2 000 beyond 6σ̂, its source's ~2 000 spikes).
  Each candidate is then judged again against the median of its nearest
  neighbours that are not candidates (two spikes three samples apart would
  otherwise lift the median of the samples between them, flag those, and
  be "cleaned" into each other); the same neighbours replace it.
* Held samples (a data pipeline repeated the sample before,
  :mod:`gyroarray.analysis.pipeline`): on a gyro that holds samples, no
  candidate within :data:`HOLD_WIDTH` samples of a held one is judged, and the
  count test counts only the clusters away from them (the jump where a held
  value resumes, and the ringing of the filter around it, are the
  processing, not outliers: a phone record with 6.7 % held samples read as
  6000 isolated spikes per gyro).
* Significance (is there an excess?): on the second difference
  d₂ = x_i − (x_{i−1} + x_{i+1})/2, linear and so Gaussian for any Gaussian
  noise however coloured (the median's d is not, on low-passed noise), the
  clusters of |d₂| > 4.5σ̂₂ against the Poisson expectation of the
  exceedances, λ₀ = n·P(|Z| > 4.5), as a normal score.
* Size: the detected values are the spikes' tails beyond c·σ̂; the rms spike
  size s of spikes ~ N(0, s²) (the spec's ``size_deg_s``) is the maximum
  likelihood of that two-sided truncated normal, and the rate counts the
  spikes the threshold missed: rate = K / (T·P(|N(0, s²)| > c·σ̂)). s is held
  at c·σ̂/1.96 or above (``size_at_floor``): the rate then counts at most 20
  spikes for each one seen.
* Heavier tails (:func:`wide_sizes`): from 20 spikes on, a scale mixture of two
  sizes, N(0, s²) and with probability f N(0, s_w²) (``wide_fraction``,
  ``wide_size_deg_s``), is fitted by the same truncated likelihood (each value
  at its own threshold, the detector's noise added to the law) and replaces one
  size when the likelihood ratio passes the 0.1 % point of χ²₂ (the Xsens
  record: one size predicted 830 samples beyond 2 deg/s and none beyond 8,
  where it has 130 and 26; two sizes 148 and 30).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, optimize, special, stats

from gyroarray.analysis.memo import by_content
from gyroarray.analysis.pipeline import gyro_holds, near_holds
from gyroarray.analysis.motion_events import (cluster_starts, locking_test, near_events, reference_events,
                                              window_samples)
from gyroarray.effects.fitting import EffectFit, z_from_log_p
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Effect, Kind, Param, Stage, identity, no_longer_seen, with_term
from gyroarray.core.errors import InputError
from gyroarray.core.units import deg_s_to_rad_s, rad_s_to_deg_s

#: Seconds per hour (the rate's unit).
_S_PER_H = 3600.0
#: Most spikes per hour a model may give [1/h]: one per sample at the highest sample rate a
#: scenario may have (1 MHz); beyond it the Poisson count of a run overflows.
MAX_RATE_PER_H = 1e6 * _S_PER_H


class Outliers(Effect):
    """Spikes on the output: in each gyro a Poisson number of them, ``rate_per_h``
    per hour on average, at samples drawn uniformly over the record (distinct),
    each of size N(0, ``size_deg_s``²) (rms ``size_deg_s``); with ``wide_fraction``
    that share of them N(0, ``wide_size_deg_s``²) instead (a heavier-tailed scale mixture). They act on the
    output after the sensor's filter (a spike is one sample: a glitch of the
    output, not of the rate the sensing element sees) and before saturation.

    Fit (:mod:`gyroarray.effects.outliers`): the samples that depart from
    their 5-sample running median by more than a Bonferroni threshold of the
    noise's robust σ are the spikes; z is the excess of the count beyond
    4.5σ over its Poisson expectation; the rms size by the truncated-normal
    likelihood of the detected values and the rate corrected for the spikes
    below the threshold. With outliers in the model the spikes are replaced
    by their median before any other fit reads the record (the noise fit, the
    ADEV and its band, the burst and the regressions): a robust record.
    Rivals: a burst or a Gauss–Markov read spikes as a raised noise level;
    once the spikes are out, they are no longer seen.
    """

    name = "outliers"
    order = 20
    stage = Stage.QUANTIZE          # after the filter and the quantization noise, before saturation
    kind = Kind.TIME
    reads = "noise"
    rivals = ("burst", "gauss_markov", "bias_instability", "sinusoid", "fault_noise")
    params = (Param("rate_per_h", "1/h", "rate_per_s", lambda x: x / _S_PER_H, lo=0.0, hi=MAX_RATE_PER_H,
                    doc="spikes per hour (mean of a Poisson count)"),
              Param("size_deg_s", "deg/s", "size_rad_s", deg_s_to_rad_s, lo=0.0,
                    doc="rms spike size (spikes ~ N(0, size²); with wide_fraction: of the narrow ones)"),
              Param("wide_fraction", "-", "wide_fraction", identity, lo=0.0, hi=1.0, required=False,
                    extension=True,
                    doc="share of the spikes drawn from a wide Gaussian instead (a scale mixture, "
                        "heavier-tailed; absent = 0: every spike N(0, size_deg_s²))"),
              Param("wide_size_deg_s", "deg/s", "wide_size_rad_s", deg_s_to_rad_s, lo=0.0, required=False,
                    extension=True, doc="rms size of the wide spikes (given with wide_fraction)"))
    scored = ("rate_per_h", "size_deg_s")
    doc = "isolated single-sample spikes"

    def check(self, params, gyro, n_gyros):
        if ("wide_fraction" in params) != ("wide_size_deg_s" in params):
            given, missing = (("wide_fraction", "wide_size_deg_s") if "wide_fraction" in params
                              else ("wide_size_deg_s", "wide_fraction"))
            raise InputError(f"{given} needs {missing} (the wide spikes' share and rms size go "
                             "together; leave both out for one Gaussian size)", column=missing)

    def simulate(self, state, act, streams):
        ctx = state.ctx
        term = np.zeros((ctx.n, len(act.cols)))
        span_s = ctx.n * ctx.dt_s
        for j, c in enumerate(act.cols):
            gen = streams.stream(self.name, int(c) + 1)
            k = int(min(gen.poisson(act.p["rate_per_s"][j] * span_s), ctx.n))
            where = gen.choice(ctx.n, size=k, replace=False)
            frac = act.p["wide_fraction"][j]
            if math.isfinite(frac) and frac > 0:
                # the scale mixture: each spike wide with probability wide_fraction
                wide = gen.random(k) < frac
                scale = np.where(wide, act.p["wide_size_rad_s"][j], act.p["size_rad_s"][j])
                term[where, j] = scale * gen.standard_normal(k)
            else:
                term[where, j] = gen.normal(0.0, act.p["size_rad_s"][j], k)
        return with_term(state, act.cols, term)

    # -- fit side -------------------------------------------------------------------
    def _spikes(self, ctx, gyro: int, x: np.ndarray, key: str):
        k = ("outliers", key, gyro)
        if k not in ctx.cache:
            ctx.cache[k] = find_spikes(x, skip=self._held(ctx, gyro, x.size))
        return ctx.cache[k]

    @staticmethod
    def _held(ctx, gyro: int, n: int) -> np.ndarray | None:
        """Samples (n,) bool within :data:`HOLD_WIDTH` of a held output of ``gyro`` (the record's
        pipeline repeated the sample before: :mod:`gyroarray.analysis.pipeline`), or None when the
        gyro holds no samples. Read on the outputs as recorded (a model taken out breaks repeats)."""
        key = ("outliers", "held", int(gyro))
        if key not in ctx.cache:
            y = ctx.y[:, int(gyro) - 1]
            ctx.cache[key] = near_holds(y, HOLD_WIDTH) if gyro_holds(y).significant else None
        m = ctx.cache[key]
        return None if m is None else m[:n]

    def fit(self, ctx, gyro, E):
        g = int(gyro)
        in_model = any(e.effect == self.name and e.gyro == g for e in ctx.entries(self.name))
        # in the model its spikes are already out of the residual: they are counted on the raw one.
        # A spike is judged against the noise around it (a running median), and at a burst's
        # edges that median mixes the two levels: the first samples inside read as a crowd of
        # spikes (scored burst cases, right model: z 3.7 on one gyro). The model knows the level.
        raw = ctx.cache.get(MOTION_RAW)
        if not in_model and raw is not None and E is raw[0]:
            E = raw[1]            # the analysis took the motion-locked spikes out: this test names them
        x = ctx.at_model_level(ctx.E0 if in_model else E, ctx.t)[:, g - 1]
        x = x[:ctx.noise_end]                           # not what the model leaves out to the end (frozen)
        sp = self._spikes(ctx, g, x, "raw" if in_model else "residual")
        span_h = x.size * ctx.dt / _S_PER_H
        rate = sp.rate * x.size / span_h if span_h > 0 else 0.0
        size = float(rad_s_to_deg_s(sp.size)) if math.isfinite(sp.size) else 0.0
        # spikes on the reference's reversals, plateau edges and jerks are the gyro's response to
        # the motion, not outliers: only those away from every event are tested (and counted)
        lock = self._motion_lock(ctx, x, sp)
        z, n_spikes = float(sp.z), int(sp.index.size)
        if lock is not None:
            rate *= lock.far / sp.index.size / max(1.0 - lock.fraction_chance, 1e-12)
            z, n_spikes = float(lock.z_far), lock.far
        sigma = {}
        if n_spikes:
            sigma["rate_per_h"] = float(rate / math.sqrt(n_spikes))       # Poisson
            if math.isfinite(sp.size_sigma):
                sigma["size_deg_s"] = float(rad_s_to_deg_s(sp.size_sigma))
        extra = {"n_spikes": n_spikes, "kurtosis": sp.kurtosis}
        if lock is not None:
            far = (f"away from them {lock.far} spikes, {lock.count_far} second-difference clusters beyond "
                   f"4.5σ against {lock.expected_far:.2g} expected (z = {lock.z_far:.1f})")
            ev = f"{lock.sentence(g)}; {far}"
            extra["motion_locked"] = {
                "kind": "motion_locked", "candidate": self.name, "gyro": g, "n_events": lock.near,
                "n_runs": lock.runs, "n_spikes": int(sp.index.size), "window_s": lock.window_s,
                "fraction_near": lock.fraction_near, "fraction_chance": lock.fraction_chance,
                "p_value": lock.p_value, "sentence": lock.sentence(g)}
        elif sp.z > 3:
            held = ("; at most, since the size is held at the threshold/1.96: those seen are too few "
                    "to say how many lie below it") if sp.size_at_floor else ""
            ev = (f"gyro {g} has {sp.index.size} isolated spikes (rms {size:.3g} deg/s, {rate:.3g} per hour "
                  f"counting those below the {sp.threshold:.1f}σ threshold{held}; {sp.count_excess} second-difference "
                  f"clusters beyond {4.5:g}σ against {sp.expected:.2g} expected; first differences' excess kurtosis "
                  f"{sp.kurtosis:.3g})")
        else:
            ev = (f"gyro {g} shows no spikes ({sp.count_excess} second-difference clusters beyond 4.5σ against "
                  f"{sp.expected:.2g} expected, z = {sp.z:.1f})")
        params = {"rate_per_h": float(rate), "size_deg_s": size}
        if math.isfinite(sp.wide_fraction):       # sizes heavier-tailed than one Gaussian
            params["wide_fraction"] = float(sp.wide_fraction)
            params["wide_size_deg_s"] = float(rad_s_to_deg_s(sp.wide_size))
            for key, val in (("wide_fraction", sp.wide_fraction_sigma),
                             ("wide_size_deg_s", rad_s_to_deg_s(sp.wide_size_sigma))):
                if math.isfinite(val):
                    sigma[key] = float(val)
            ev += (f"; sizes heavier-tailed than one Gaussian: {100 * sp.wide_fraction:.3g} % of the spikes "
                   f"rms {params['wide_size_deg_s']:.3g} deg/s (a scale mixture; likelihood ratio "
                   f"{sp.wide_lr:.3g} over one size)")
        return EffectFit(self.name, g, params, sigma, z=z, evidence=ev, extra=extra)

    def test(self, ctx, gyro):
        return self.fit(ctx, gyro, ctx.E)

    def motion_locked_spikes(self, ctx, gyro: int, x: np.ndarray) -> np.ndarray:
        """Samples of the spikes of ``x`` that lie near the reference's events, when the gyro's
        spikes are locked to them (:func:`motion_lock`); empty otherwise.

        ``x`` (n,) is the gyro's residual at the model's level, as :meth:`fit` reads it [rad/s];
        the spikes are the ones :meth:`fit` finds (held samples of a pipeline skipped)."""
        sp = self._spikes(ctx, int(gyro), x, "residual")
        lock = self._motion_lock(ctx, x, sp)
        if lock is None:
            return np.array([], dtype=np.int64)
        ev = ctx.cache[("motion_events",)]
        near = near_events(ev[ev < x.size], x.size, window_samples(ctx.dt))
        return sp.index[near[sp.index]]

    @staticmethod
    def _motion_lock(ctx, x: np.ndarray, sp: Spikes) -> MotionLock | None:
        """:func:`motion_lock` of the spikes against the reference's events (None without motion)."""
        if ctx.ref is None or not ctx.moving or not sp.index.size:
            return None
        key = ("motion_events",)
        if key not in ctx.cache:
            ctx.cache[key] = reference_events(ctx.ref, ctx.dt)
        return motion_lock(x, sp, ctx.cache[key], ctx.dt)

    def _clean_index(self, ctx, entry, x: np.ndarray) -> np.ndarray:
        return find_spikes(x, skip=self._held(ctx, entry.gyro, x.size)).index

    def exclude(self, ctx, entry):
        g = entry.gyro - 1
        mask = np.zeros(ctx.n, bool)
        mask[self._clean_index(ctx, entry, ctx.E0[:, g])] = True
        return mask if mask.any() else None

    def clean(self, ctx, entry, x):
        g = entry.gyro - 1
        x = np.array(x, copy=True)
        x[:, g] = clean_spikes(x[:, g], self._clean_index(ctx, entry, x[:, g]))
        return x

    def band_entries(self, ctx, entry):
        return []                           # the band is compared with the cleaned record

    def prefer(self, mine, other, ctx):
        g = int(mine.gyro)
        x = ctx.E[:, g - 1]
        idx = find_spikes(x, skip=self._held(ctx, g, x.size)).index
        if not idx.size:
            return None
        pred = np.zeros_like(ctx.E)
        pred[:, g - 1] = x - clean_spikes(x, idx)           # the spikes, as a "prediction" taken out
        return no_longer_seen(ctx.without(pred), other, ctx, f"the {idx.size} spikes of gyro {g} taken out")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"rate_per_h": _draw.u(rng, 60.0, 600.0, True),
                                          "size_deg_s": _draw.u(rng, 0.5, 3.0, True)}


# -- fit ----------------------------------------------------------------------------------
#: Running-median window [samples]: two neighbours on each side, the sample itself left out.
MEDIAN_WINDOW = 5


def _neighbour_median(x: np.ndarray) -> np.ndarray:
    """Median of the two samples on each side of every sample (the mean of the middle two of
    four; held values at the ends)."""
    p = np.pad(x, 2, mode="edge")
    nb = np.stack([p[:-4], p[1:-3], p[3:-1], p[4:]], axis=1)
    nb.sort(axis=1)
    return 0.5 * (nb[:, 1] + nb[:, 2])


def _clean_neighbour_median(x: np.ndarray, bad: np.ndarray, index: np.ndarray) -> np.ndarray:
    """At each sample of ``index``: the median of the two samples on each side of it that are not
    ``bad`` (two spikes a few samples apart would otherwise stand in each other's median)."""
    good = np.flatnonzero(~bad)
    if good.size == 0:
        return x[index]
    pos = np.searchsorted(good, index)
    cols = np.clip(pos[:, None] + np.array([-2, -1, 0, 1]), 0, good.size - 1)
    return np.median(x[good[cols]], axis=1)


#: Samples on each side of a held output (the record's pipeline) where no spike is judged: the
#: jump where the held value resumes moves the 5-sample median and the second difference of the
#: samples up to two away, a decimation filter's ringing around it a little further.
HOLD_WIDTH = 3
#: Threshold of the count test [σ̂].
COUNT_THRESHOLD = 4.5
#: Lowest detection threshold [σ̂].
MIN_THRESHOLD = 6.0
#: Samples in the running window of the local noise level (its σ̂ to ±3 %: the 4.5σ tail
#: probability moves by < 20 % with it).
LOCAL_WINDOW = 2001
#: The rms spike size is read no smaller than the threshold / 1.96: at least 5 % of the spikes
#: above it. Smaller, the rate would count 20 and more unseen spikes for each one seen, an
#: extrapolation the few seen cannot carry (on the MPU-6050 record 34 values beyond 6σ read as
#: spikes of 1.7σ and a rate of 0.89 per sample, 3.2e5 per hour; gyro 3's two as 4.8e12 per hour).
_Z_SEEN = float(stats.norm.isf(0.025))


@dataclass(frozen=True)
class Spikes:
    """The spikes of one series.

    Attributes
    ----------
    index : ndarray of int
        Samples detected as spikes (Bonferroni threshold).
    value : ndarray
        Their departure from the running median [input unit].
    sigma : float
        Robust standard deviation of d [input unit].
    threshold : float
        Detection threshold c [σ̂].
    count_excess : int
        Clusters of the second difference beyond :data:`COUNT_THRESHOLD`·σ̂₂.
    expected : float
        The Poisson expectation of the exceedances without spikes.
    z : float
        Normal score of the count's excess (≈ N(0, 1) without spikes).
    size : float
        rms spike size by truncated-normal ML [input unit] (NaN without spikes).
    size_sigma : float
        Its 1σ.
    rate : float
        Spikes per sample, corrected for the ones below the threshold.
    kurtosis : float
        Excess kurtosis of the first differences (a heavy tail's plain signature).
    """

    index: np.ndarray
    value: np.ndarray
    sigma: float
    threshold: float
    count_excess: int
    expected: float
    z: float
    size: float
    size_sigma: float
    rate: float
    kurtosis: float
    size_at_floor: bool = False
    wide_fraction: float = math.nan
    wide_size: float = math.nan
    wide_fraction_sigma: float = math.nan
    wide_size_sigma: float = math.nan
    wide_lr: float = math.nan


def _poisson_z(k: int, lam: float) -> float:
    """Normal score of P(K >= k) for K ~ Poisson(λ), mid-p (a continuous, N(0, 1)-like score)."""
    if lam <= 0:
        return 0.0
    log_p = float(np.logaddexp(stats.poisson.logsf(k, lam), math.log(0.5) + stats.poisson.logpmf(k, lam)))
    return z_from_log_p(min(log_p, math.log1p(-1e-16)))


def _local_sigma(d: np.ndarray, sigma: float, window: int = LOCAL_WINDOW) -> np.ndarray:
    """The robust σ of d per sample: 1.4826 × the running median of |d| over ``window`` samples
    centred on it (a noise level that changes over the record, a burst, is not a crowd of spikes;
    isolated spikes do not move a median). Samples whose d is exactly 0 carry no noise (a clipped
    stretch, a dead gyro) and are left out; a window with nothing else falls back to ``sigma``."""
    n = d.size
    if n < 2 * window:
        return np.full(n, sigma)
    a = np.abs(d)
    zero = a == 0
    if zero.any():
        # a zero sorts below every noise sample: push half of them above, so the median is the
        # median of the non-zero samples where they are many, and 0 (then ``sigma``) where not
        a = np.where(zero, np.where(np.arange(n) % 2 == 0, 0.0, np.inf), a)
    med = 1.4826 * ndimage.median_filter(a, size=window, mode="mirror")
    return np.where(np.isfinite(med) & (med > 0), med, sigma)


def _count_test(x: np.ndarray, sigma: float, away=None) -> tuple[int, float, float]:
    """(clusters beyond :data:`COUNT_THRESHOLD`, their expectation without spikes, z).

    ``away`` (n,) bool: count only the clusters that start on its samples, against the
    expectation over its share of the record (the spikes away from the motion's events).

    The test runs on the second difference d₂ = x_i − (x_{i−1} + x_{i+1})/2: linear in x, so its
    marginal is Gaussian for any Gaussian noise however coloured (a running median's d is not:
    on low-passed noise it has heavy tails and the count would fire without a spike).
    Exceedances within two samples of each other count once (a spike moves d₂ at i and i ± 1;
    correlated noise clusters its exceedances): the cluster count is at most the exceedance count
    whose expectation under Gaussian noise is n·P(|Z| > 4.5), so z errs on the quiet side.
    """
    n = x.size
    if n < 3:
        return 0, 0.0, 0.0
    d2 = np.empty(n)
    d2[1:-1] = x[1:-1] - 0.5 * (x[:-2] + x[2:])
    d2[0], d2[-1] = d2[1], d2[-2]
    s2 = 1.4826 * float(np.median(np.abs(d2 - np.median(d2))))
    if not s2 > 0:
        return 0, 0.0, 0.0
    hit = np.flatnonzero(np.abs(d2) > COUNT_THRESHOLD * _local_sigma(d2, s2))
    k = int(hit.size and 1 + np.count_nonzero(np.diff(hit) > 2))
    lam = n * float(special.erfc(COUNT_THRESHOLD / math.sqrt(2.0)))
    if away is not None:
        starts = hit[np.concatenate(([True], np.diff(hit) > 2))] if hit.size else hit
        k = int(np.count_nonzero(away[starts]))
        lam *= float(np.mean(away))
    return k, lam, _poisson_z(k, lam)


@by_content()
def find_spikes(x, alpha: float = 0.01, skip=None) -> Spikes:
    """Spikes of the series ``x`` (n,) (module docstring).

    ``skip`` (n,) bool or None: samples that are not judged (next to the samples a data pipeline
    held, :func:`~gyroarray.analysis.pipeline.near_holds`: the jump where a held value resumes,
    and a filter's ringing around it, are not outliers). No candidate is taken there, and the
    count test counts only the clusters that start elsewhere, against the expectation over the
    rest of the record."""
    skip = None if skip is None else np.asarray(skip, dtype=bool)
    if skip is not None and not skip.any():
        skip = None
    x = np.asarray(x, dtype=float)
    n = x.size
    d = x - _neighbour_median(x)
    mad = float(np.median(np.abs(d - np.median(d))))
    sigma = 1.4826 * mad
    local = _local_sigma(d, sigma)
    diff = np.diff(x)
    kurt = float(stats.kurtosis(diff)) if diff.size > 3 and np.std(diff) > 0 else 0.0
    if not sigma > 0:
        return Spikes(np.array([], int), np.array([]), sigma, math.inf, 0, 0.0, 0.0, math.nan,
                      math.nan, 0.0, kurt)
    c = max(float(-special.ndtri(0.5 * alpha / max(n, 1))), MIN_THRESHOLD)   # Bonferroni, two-sided
    idx = np.flatnonzero(np.abs(d) > c * local)
    if skip is not None:
        idx = idx[~skip[idx]]
    for _ in range(3):
        # spikes a few samples apart raise the median of the samples between them: each candidate is
        # judged again against its neighbours that are not candidates themselves
        bad = np.zeros(n, bool)
        bad[idx] = True
        d[idx] = x[idx] - _clean_neighbour_median(x, bad, idx)
        keep = np.abs(d[idx]) > c * local[idx]
        if keep.all():
            break
        idx = idx[keep]
    k, lam, z = _count_test(x, sigma, None if skip is None else ~skip)
    size, s_size, rate, at_floor = math.nan, math.nan, 0.0, False
    if idx.size:
        v = d[idx]
        cut = c * float(np.median(local[idx]))

        def nll(log_s):
            s = math.exp(log_s)
            return -(np.sum(stats.norm.logpdf(v, scale=s)) - v.size * math.log(float(special.erfc(cut / (s * math.sqrt(2))))))
        s0 = max(float(np.sqrt(np.mean(v * v))), cut)
        floor = cut / _Z_SEEN
        res = optimize.minimize_scalar(nll, bounds=(math.log(floor), math.log(s0 * 20)), method="bounded")
        size = math.exp(res.x)
        h = 1e-3
        d2 = (nll(res.x + h) - 2 * nll(res.x) + nll(res.x - h)) / h ** 2
        s_size = size / math.sqrt(d2) if d2 > 0 else math.nan
        at_floor = bool(res.x - math.log(floor) < 1e-3)
        if at_floor:
            s_size = math.nan                            # a bound, not a likelihood's curvature
        p_seen = float(special.erfc(cut / (size * math.sqrt(2))))
        rate = idx.size / p_seen / n
        wide = wide_sizes(v, c * local[idx], local[idx], floor)
        if wide is not None:
            size, s_size, at_floor = wide.size, wide.size_sigma, wide.at_floor
            rate = wide.spikes / n
            return Spikes(idx, d[idx], sigma, c, k, lam, z, size, s_size, rate, kurt, at_floor,
                          wide.fraction, wide.wide_size, wide.fraction_sigma, wide.wide_size_sigma, wide.lr)
    return Spikes(idx, d[idx], sigma, c, k, lam, z, size, s_size, rate, kurt, at_floor)


#: Fewest spikes seen for a two-size law to be tried (its three parameters need a tail to read).
MIN_WIDE_SPIKES = 20
#: Likelihood-ratio statistic above which the two-size law replaces one size: the 0.1 % point of
#: χ² with 2 degrees of freedom (the wide size and its share).
WIDE_LR = float(stats.chi2.isf(1e-3, 2))


@dataclass(frozen=True)
class WideSizes:
    """Spike sizes as a scale mixture of two Gaussians (:func:`wide_sizes`).

    Attributes
    ----------
    size, size_sigma : float
        rms of the narrow spikes and its 1σ (NaN when held at the floor) [input unit].
    at_floor : bool
        The narrow size is held at the floor (threshold / 1.96).
    wide_size, wide_size_sigma : float
        rms of the wide spikes and its 1σ [input unit].
    fraction, fraction_sigma : float
        Share of the wide spikes among all of them, and its 1σ [-].
    spikes : float
        The spikes in the record, those below the threshold counted (Σ 1 / P(seen)).
    lr : float
        Likelihood-ratio statistic of the two sizes over one.
    """

    size: float
    size_sigma: float
    at_floor: bool
    wide_size: float
    wide_size_sigma: float
    fraction: float
    fraction_sigma: float
    spikes: float
    lr: float


def wide_sizes(v, cut, noise, floor: float) -> WideSizes | None:
    """Two spike sizes, when the detected values say so (None when one size does).

    The detected departures ``v`` are a spike plus the detector's noise (a normal of the local σ̂
    ``noise``), seen because ``|v|`` > ``cut`` (each spike's own threshold): the likelihood of the
    spike law S = N(0, s²) with probability 1 − f, N(0, s_w²) with probability f, is that of the
    truncated normal mixture N(0, s² + σ̂ᵢ²) / N(0, s_w² + σ̂ᵢ²) beyond ``cutᵢ``; s is held at
    ``floor`` or above (as the one-size fit). The two sizes replace one when the likelihood ratio
    over one size (same noise, same truncation) exceeds :data:`WIDE_LR`. The 1σ from the
    likelihood's curvature.

    Parameters
    ----------
    v, cut, noise : array_like, shape (k,)
        Detected departures, their thresholds and their noise σ̂ [one unit].
    floor : float
        Smallest narrow size [same unit].
    """
    v = np.asarray(v, dtype=float)
    cut = np.asarray(cut, dtype=float)
    e2 = np.asarray(noise, dtype=float) ** 2
    if v.size < MIN_WIDE_SPIKES or not floor > 0:
        return None

    def parts(s, sw, f):
        va, vb = s * s + e2, sw * sw + e2
        dens = (1 - f) * np.exp(-0.5 * v * v / va) / np.sqrt(va) + f * np.exp(-0.5 * v * v / vb) / np.sqrt(vb)
        seen = (1 - f) * special.erfc(cut / np.sqrt(2 * va)) + f * special.erfc(cut / np.sqrt(2 * vb))
        return dens, seen

    def nll(p):
        dens, seen = parts(*p)
        if not (np.all(dens > 0) and np.all(seen > 0)):
            return 1e300
        return -float(np.sum(np.log(dens)) - np.sum(np.log(seen)))

    top = float(np.max(np.abs(v)))
    one = optimize.minimize_scalar(lambda ls: nll((math.exp(ls), math.exp(ls), 0.0)),
                                   bounds=(math.log(floor), math.log(max(20 * top, floor * 1.01))),
                                   method="bounded")
    # θ = (log s, log(s_w / s), logit f): the wide spikes wider, and fewer, than the narrow ones
    lo = (math.log(floor), math.log(1.5), -25.0)
    hi = (math.log(max(20 * top, floor * 1.01)), math.log(1e4), 0.0)

    def of(t):
        s = math.exp(t[0])
        return s, s * math.exp(t[1]), float(special.expit(t[2]))

    best = None
    for r0, f0 in ((3.0, -4.0), (10.0, -6.0), (1.0, -2.0)):
        t0 = (max(one.x, lo[0]), math.log(r0), f0)
        res = optimize.minimize(lambda t: nll(of(t)), t0, method="L-BFGS-B", bounds=list(zip(lo, hi)))
        if best is None or res.fun < best.fun:
            best = res
    assert best is not None              # the loop above runs three times
    lr = 2.0 * (one.fun - best.fun)
    if not lr > WIDE_LR:
        return None
    s, sw, f = of(best.x)
    at_floor = bool(best.x[0] - lo[0] < 1e-3)
    # 1σ from the curvature of the likelihood in (s, s_w, f); s left out when held at the floor
    x0 = np.array([s, sw, f])
    free = [1, 2] if at_floor else [0, 1, 2]
    h = np.array([1e-4 * s, 1e-4 * sw, 1e-4 * max(f, 1e-6)])
    hess = np.empty((len(free), len(free)))
    for a, i in enumerate(free):
        for b, j in enumerate(free):
            def at(di, dj):
                p = x0.copy()
                p[i] += di * h[i]
                p[j] += dj * h[j]
                return nll(tuple(p))
            hess[a, b] = (at(1, 1) - at(1, -1) - at(-1, 1) + at(-1, -1)) / (4 * h[i] * h[j])
    sig = np.full(3, math.nan)
    try:
        cov = np.linalg.inv(hess)
        sig[free] = np.sqrt(np.where(np.diag(cov) > 0, np.diag(cov), np.nan))
    except np.linalg.LinAlgError:
        pass
    _, seen = parts(s, sw, f)
    return WideSizes(s, float(sig[0]), at_floor, sw, float(sig[1]), f, float(sig[2]),
                     float(np.sum(1.0 / seen)), float(lr))


#: ``FitContext.cache`` key of (the residual with the motion-locked spikes taken out, the one
#: before): an analysis that takes them out before its tests read the record keeps both there, so
#: that the outliers test still reads, and names, them.
MOTION_RAW = ("outliers", "motion_raw")
#: The spikes are locked to the motion when the binomial p-value of their runs near the
#: reference's events (:func:`~gyroarray.analysis.motion_events.locking_test`) is below this.
MOTION_LOCK_P = 1e-3
#: ... and when at least this share of the runs start near an event: a response to the motion
#: is where the spikes are, not a few of many (on a lab run whose gyro 2 clips at 30 deg/s, 8
#: of 68 runs near a plateau edge, 11.8 % against 2.1 % by chance, p = 1e-4, are the clip's,
#: not a jerk's: taken out, they moved the ranking of the clip and a drift).
MOTION_LOCK_SHARE = 0.5


@dataclass(frozen=True)
class MotionLock:
    """Spikes of one series that sit on the reference's events (:func:`motion_lock`).

    Attributes
    ----------
    near, runs : int
        Runs of spikes (:func:`~gyroarray.analysis.motion_events.cluster_starts`) that start
        near an event, of all runs.
    window_s : float
        Near: within this of an event [s].
    fraction_near, fraction_chance, p_value : float
        Share of the runs near an event, share of the record near one (the chance of a run
        placed at random), and the binomial p-value of the runs near one.
    far : int
        Spikes away from every event.
    count_far, expected_far, z_far : int, float, float
        The count test (second-difference clusters beyond :data:`COUNT_THRESHOLD`) on the
        samples away from the events: the clusters, their expectation without spikes and z.
    """

    near: int
    runs: int
    window_s: float
    fraction_near: float
    fraction_chance: float
    p_value: float
    far: int
    count_far: int
    expected_far: float
    z_far: float

    def sentence(self, gyro: int) -> str:
        """The finding as said to the user."""
        return (f"gyro {gyro}: motion-locked response: {self.near} events within {self.window_s:g} s of the "
                f"reference's reversals/plateau edges/jerks ({100 * self.fraction_near:.1f} % vs "
                f"{100 * self.fraction_chance:.1f} % by chance, p = {self.p_value:.2g}); a jerk sensitivity or "
                f"the reference's own error, not random spikes")


def motion_lock(x, spikes: Spikes, events, dt_s: float) -> MotionLock | None:
    """Are the spikes of ``x`` locked to the reference's ``events``? None when not.

    Parameters
    ----------
    x : array_like, shape (n,)
        The series the spikes were found in (:func:`find_spikes`) [any unit].
    spikes : Spikes
        Its spikes.
    events : array_like of int
        Sample indices of the reference's events
        (:func:`~gyroarray.analysis.motion_events.reference_events`), in 0 … n − 1.
    dt_s : float
        Sample period [s].

    Returns
    -------
    MotionLock or None
        When the runs of spikes start near an event more often than chance
        (binomial p-value below :data:`MOTION_LOCK_P`) and most of them do (at
        least :data:`MOTION_LOCK_SHARE`): how many, and the count
        test on the samples away from every event (whether spikes remain there).
    """
    x = np.asarray(x, dtype=float)
    ev = np.asarray(events, dtype=np.int64)
    ev = ev[ev < x.size]
    if ev.size == 0 or spikes.index.size == 0 or not spikes.sigma > 0:
        return None
    w = window_samples(dt_s)                        # near: within WINDOW_S (0.1 s) of an event
    runs = cluster_starts(spikes.index, w)
    frac, chance, p = locking_test(ev, runs, x.size, w)
    if not (p < MOTION_LOCK_P and frac >= MOTION_LOCK_SHARE):
        return None
    away = ~near_events(ev, x.size, w)
    if not away.any():
        return None
    k, lam, z = _count_test(x, spikes.sigma, away)
    return MotionLock(int(round(frac * runs.size)), int(runs.size), w * dt_s, frac, chance, p,
                      int(np.count_nonzero(away[spikes.index])), k, lam, z)


def clean_spikes(x, index) -> np.ndarray:
    """``x`` with the samples at ``index`` replaced by the median of their four nearest neighbours
    that are not in ``index``."""
    x = np.array(x, dtype=float, copy=True)
    index = np.asarray(index, dtype=np.int64)
    if index.size:
        bad = np.zeros(x.size, bool)
        bad[index] = True
        x[index] = _clean_neighbour_median(x, bad, index)
    return x
