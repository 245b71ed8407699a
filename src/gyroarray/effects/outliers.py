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
* A heavy-tailed floor is not spikes (:func:`heavy_floor`): the white noise is fitted by
  likelihood as a scaled Student-t (ν free) and as a Gaussian within the threshold; when the t
  wins, its tail predicts the flags beyond c (at least a quarter of them, not fewer than seen,
  spread over the record, none next to holds), those flags are the floor's own, and only the
  values beyond the level where the floor expects 0.5 in the record are spikes, when their count
  is an excess over it (z > 3; else beyond its 1 % family-wise level). The finding states ν, the
  white level (the t's variance: a MAD understates it by 17 % at ν = 5) and the ADEV's interval
  at the shortest τ (√(1 + 1.5/(ν − 4)) wider). A phone stream (Samsung S5) read 5500–6550
  "isolated spikes" per gyro from such a floor: 5.4 % of its first differences beyond 6σ_MAD,
  excess kurtosis 3, 113–179 per 10 min everywhere, none next to holds.
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
        if sp.floor is not None:
            extra["heavy_tailed_floor"] = {**sp.floor.to_json_dict(), "candidate": self.name, "gyro": g,
                                           "sentence": sp.floor.sentence(g)}
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
            count = (f"{sp.count_excess} beyond the floor's {sp.threshold:.3g}σ̂ level against {sp.expected:.2g} "
                     f"expected" if sp.floor is not None else
                     f"{sp.count_excess} second-difference clusters beyond {4.5:g}σ against {sp.expected:.2g} expected")
            ev = (f"gyro {g} has {sp.index.size} isolated spikes (rms {size:.3g} deg/s, {rate:.3g} per hour "
                  f"counting those below the {sp.threshold:.3g}σ threshold{held}; {count}; first differences' excess "
                  f"kurtosis {sp.kurtosis:.3g})")
            if sp.floor is not None:
                ev += f"; {sp.floor.sentence(g)}"
        elif sp.floor is not None:
            ev = f"gyro {g} shows no spikes; {sp.floor.sentence(g)}"
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
    floor : HeavyFloor or None
        The noise floor is a scaled Student-t (:func:`heavy_floor`): then ``index`` holds the
        values beyond the floor's own level, and ``count_excess``, ``expected`` and ``z`` are
        their count, the floor's expectation there and its score (the second-difference count
        test is a Gaussian one). None for a Gaussian floor.
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
    floor: HeavyFloor | None = None


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


# -- a heavy-tailed floor -------------------------------------------------------------------
#: Largest Student-t ν read as a heavy-tailed floor: beyond it the t is a Gaussian for every count
#: a record can hold (t₃₀'s excess kurtosis is 0.23; a local σ̂ read to ±3 % makes a Gaussian look
#: like ν ≈ 80).
FLOOR_NU_MAX = 30.0
#: Likelihood-ratio statistic of the Student-t over the Gaussian above which the floor is a t:
#: the 0.1 % point of χ² with 1 degree of freedom (ν; on its boundary the ratio is a half χ²₁,
#: so this errs on the Gaussian side).
FLOOR_LR = float(stats.chi2.isf(1e-3, 1))
#: Running mean [samples] of the other samples, taken off the series before its floor is fitted
#: (a wander or a motion left in the residual is not the white noise's distribution). Linear, it
#: adds a Gaussian part of 1/200 of the variance (ν = 5 reads +0.03 on average over six records of
#: 60 000 samples, against a 1σ of 0.12); a running median instead reads ν 0.17 low.
FLOOR_MEAN_WINDOW = 201
#: Most samples the floor's likelihood reads (an even stride through longer records).
FLOOR_FIT_MAX = 200_000
#: Monte Carlo draws of the detector's neighbour median under the fitted floor (its σ̂ to 0.4 %).
FLOOR_MC = 100_000
#: Seed of those draws (the floor's tail is a deterministic function of ν).
FLOOR_SEED = 44
#: Flags beyond the threshold are what the floor predicts unless fewer than this lower
#: quantile of its Poisson count, and spread over the record unless the dispersion test's
#: p-value is below it.
FLOOR_P = 1e-3
#: Smallest share of the flags beyond the threshold that the floor must predict: when the flags
#: are mostly spikes, the spikes within the threshold are what make the body heavy (2 % of the
#: samples spikes of 5σ: a t of ν = 9.5 predicts 10 of their 825 flags), and the Gaussian
#: detector's reading stands.
FLOOR_SHARE = 0.25
#: Level [σ̂] at which the floor's tail is held to the record's own count of values beyond it
#: (a spike there is one among hundreds of the floor's).
FLOOR_CAL_LEVEL = 4.0
#: Values beyond the level where the floor expects this many in the record are the spikes, when
#: their count is an excess over it (:data:`FLOOR_Z_SPIKES`): each one is the floor's with chance
#: ≤ 0.5 / their count.
FLOOR_SPIKE_EXPECTED = 0.5
#: Normal score of that count above which those values are spikes; below it only the values
#: beyond the floor's own 1 % family-wise level are (as for a Gaussian floor).
FLOOR_Z_SPIKES = 3.0


@dataclass(frozen=True)
class HeavyFloor:
    """A heavy-tailed noise floor: the white noise is a scaled Student-t (:func:`heavy_floor`).

    Attributes
    ----------
    nu, nu_lo, nu_hi : float
        Degrees of freedom of the t and its 95 % interval (likelihood curvature in log ν) [-].
    lr : float
        Likelihood-ratio statistic of the t over a Gaussian on the same samples [-].
    flags : int
        Values of the detector's d beyond the Gaussian threshold (``threshold``·σ̂) [-].
    expected, expected_lo, expected_hi : float
        Their number the t floor predicts and its Poisson 99.9 % interval [-].
    z_flags : float
        Normal score of ``flags`` against ``expected`` (an excess the floor cannot tell apart
        value by value when large while ``z`` is small) [-].
    dispersion_p : float
        p-value of the flags' spread over blocks of the record against a uniform one (1 when
        too few to test) [-].
    level : float
        Level beyond which the values are the spikes [σ̂]: ``test_level`` when ``z`` is beyond
        :data:`FLOOR_Z_SPIKES`, else the floor's own 1 % family-wise level.
    test_level : float
        The floor's :data:`FLOOR_SPIKE_EXPECTED` level [σ̂].
    spikes_beyond, expected_beyond, z : int, float, float
        Values beyond ``test_level``, the floor's expectation there, and the normal score of
        their excess [-].
    white_ratio : float
        The t's standard deviation over its robust one (1.4826·MAD): how far a Gaussian read by
        its MAD understates the white level (inf for ν ≤ 2) [-].
    calibration : float
        Factor (≥ 1) on the white floor's tail so that it holds the values beyond
        :data:`FLOOR_CAL_LEVEL` (a low-passed floor's neighbours share its large values) [-].
    adev_ci_factor : float
        Widening of the ADEV's confidence interval at the shortest τ over a Gaussian floor of the
        same variance, √((κ − 1)/2) with κ the first differences' kurtosis 3 + 3/(ν − 4) (inf for
        ν ≤ 4); at long τ the averages are Gaussian and the interval is the white noise's [-].
    """

    nu: float
    nu_lo: float
    nu_hi: float
    lr: float
    flags: int
    expected: float
    expected_lo: float
    expected_hi: float
    z_flags: float
    dispersion_p: float
    level: float
    test_level: float
    spikes_beyond: int
    expected_beyond: float
    z: float
    white_ratio: float
    adev_ci_factor: float
    calibration: float = 1.0

    def sentence(self, gyro: int) -> str:
        """The finding as said to the user."""
        white = (f"its white level is the t's variance: a Gaussian read by its MAD understates it by "
                 f"{100 * (1 - 1 / self.white_ratio):.3g} %" if math.isfinite(self.white_ratio)
                 else "its variance is infinite (ν ≤ 2): no white level")
        adev = (f"the ADEV is that of white noise of that variance, its interval at the shortest τ "
                f"{self.adev_ci_factor:.3g}× a Gaussian's" if math.isfinite(self.adev_ci_factor)
                else "the ADEV's interval at the shortest τ has no finite width (ν ≤ 4)")
        excess = (f"; {self.flags} against {self.expected:.3g} is an excess the floor cannot tell apart "
                  f"value by value (z = {self.z_flags:.1f})" if self.z_flags > 5 and self.z < FLOOR_Z_SPIKES
                  else "")
        spikes = (f"spikes on it: {self.spikes_beyond} beyond {self.test_level:.3g}σ̂ where it predicts "
                  f"{self.expected_beyond:.2g} (z = {self.z:.1f})" if self.z >= FLOOR_Z_SPIKES else
                  f"no spikes: {self.spikes_beyond} beyond {self.test_level:.3g}σ̂ where it predicts "
                  f"{self.expected_beyond:.2g} (z = {self.z:.1f}), none named short of its 1 % level "
                  f"{self.level:.3g}σ̂")
        return (f"gyro {gyro}: a heavy-tailed noise floor: the white noise is a scaled Student-t, "
                f"ν = {self.nu:.3g} (95 % {self.nu_lo:.3g}–{self.nu_hi:.3g}; likelihood ratio {self.lr:.3g} "
                f"over a Gaussian); it predicts {self.expected:.3g} values beyond the Gaussian threshold "
                f"({self.expected_lo:.0f}–{self.expected_hi:.0f}), the record has {self.flags}, spread over it "
                f"(dispersion p = {self.dispersion_p:.2g}), held samples' neighbours left out{excess}; "
                f"{spikes}; {white}; {adev}")

    def to_json_dict(self) -> dict:
        """The finding as JSON (``kind`` "heavy_tailed_floor")."""
        return {"kind": "heavy_tailed_floor", "nu": self.nu, "nu_ci95": [self.nu_lo, self.nu_hi],
                "likelihood_ratio": self.lr, "flags": self.flags, "flags_expected": self.expected,
                "flags_interval": [self.expected_lo, self.expected_hi], "dispersion_p": self.dispersion_p,
                "spike_level_sigma": self.level, "test_level_sigma": self.test_level,
                "spikes_beyond": self.spikes_beyond,
                "expected_beyond": self.expected_beyond, "z": self.z, "white_ratio": self.white_ratio,
                "adev_ci_factor": self.adev_ci_factor, "calibration": self.calibration}


def _t_logpdf(z: np.ndarray, nu: float) -> np.ndarray:
    """log density of the standard Student-t with ν degrees of freedom at ``z``."""
    return (special.gammaln(0.5 * (nu + 1)) - special.gammaln(0.5 * nu) - 0.5 * math.log(nu * math.pi)
            - 0.5 * (nu + 1) * np.log1p(z * z / nu))


def fit_student_t(u, cut: float) -> tuple[float, float, float, float]:
    """Scaled Student-t and Gaussian fits, by likelihood, of the values ``u`` within ±``cut``.

    Both are zero-centred laws truncated to |u| < ``cut`` (what lies beyond, the spikes, is not
    read), so their likelihoods compare on the same samples.

    Parameters
    ----------
    u : array_like, shape (n,)
        The noise standardised by its robust σ [-].
    cut : float
        Truncation [same unit as ``u``].

    Returns
    -------
    nu, log_nu_sigma, scale, lr : float
        ν, the 1σ of log ν (likelihood curvature; NaN when on a bound), the t's scale [unit of
        ``u``] and the likelihood-ratio statistic 2·(ℓ_t − ℓ_Gauss).
    """
    u = np.asarray(u, dtype=float)
    u = u[np.abs(u) < cut]
    k = u.size
    u2 = u * u

    def nll_t(p):
        s, nu = math.exp(p[0]), math.exp(p[1])
        inside = 1.0 - 2.0 * float(stats.t.sf(cut / s, nu))
        if not inside > 0:
            return 1e300
        return -(float(np.sum(_t_logpdf(u / s, nu))) - k * math.log(s) - k * math.log(inside))

    def nll_g(ls):
        s = math.exp(ls)
        inside = 1.0 - float(special.erfc(cut / (s * math.sqrt(2.0))))
        return 0.5 * float(np.sum(u2)) / (s * s) + k * (ls + 0.5 * math.log(2 * math.pi)) + k * math.log(inside)

    g = optimize.minimize_scalar(nll_g, bounds=(math.log(cut) - 12.0, math.log(cut)), method="bounded")
    log_nu = (math.log(0.5), math.log(1e4))
    best = None
    for nu0 in (3.0, 10.0, 60.0):
        r = optimize.minimize(nll_t, (float(g.x), math.log(nu0)), method="L-BFGS-B",
                              bounds=[(g.x - 3.0, g.x + 1.0), log_nu])
        if best is None or r.fun < best.fun:
            best = r
    assert best is not None                 # three starts
    nu, s = math.exp(best.x[1]), math.exp(best.x[0])
    lr = max(2.0 * (float(g.fun) - float(best.fun)), 0.0)
    sig = math.nan
    if log_nu[0] + 1e-3 < best.x[1] < log_nu[1] - 1e-3:
        h = np.array([1e-3, 1e-3])
        x0 = np.asarray(best.x, dtype=float)
        hess = np.empty((2, 2))
        for i in range(2):
            for j in range(2):
                def at(di, dj):
                    p = x0.copy()
                    p[i] += di * h[i]
                    p[j] += dj * h[j]
                    return nll_t(p)
                hess[i, j] = (at(1, 1) - at(1, -1) - at(-1, 1) + at(-1, -1)) / (4 * h[i] * h[j])
        try:
            cov = np.linalg.inv(hess)
            if cov[1, 1] > 0:
                sig = math.sqrt(cov[1, 1])
        except np.linalg.LinAlgError:
            pass
    return nu, sig, s, lr


def floor_tail(nu: float):
    """P(|d| > L·σ̂) of the detector under a white Student-t floor with ν degrees of freedom.

    d = x_i − m_i, m_i the median of the four neighbours: for white noise x_i is independent
    of them, so P(|d| > a) = E_m[P(|x − m| > a)], the expectation over m by :data:`FLOOR_MC`
    draws (the median is light-tailed) and the probability exact; σ̂ = 1.4826·MAD(d) of the
    same draws (the detector's unit).

    Returns
    -------
    callable
        L [σ̂] ↦ the probability [-].
    """
    rng = np.random.default_rng(FLOOR_SEED)
    nb = np.sort(rng.standard_t(nu, (FLOOR_MC, 4)), axis=1)
    m = 0.5 * (nb[:, 1] + nb[:, 2])
    d = rng.standard_t(nu, FLOOR_MC) - m
    s = 1.4826 * float(np.median(np.abs(d - np.median(d))))
    m = m[:FLOOR_MC // 5]                  # a smooth expectation over a light-tailed m: 20 000 do

    def tail(level: float) -> float:
        a = level * s
        return float(np.mean(special.stdtr(nu, m - a) + special.stdtr(nu, -a - m)))
    return tail


def _level(tail, n: int, expected: float, start: float) -> float:
    """The level L ≥ ``start`` [σ̂] where n·tail(L) = ``expected`` (``start`` when already below)."""
    f = lambda lv: math.log(max(n * tail(lv), 1e-300)) - math.log(expected)   # noqa: E731
    if f(start) <= 0:
        return start
    hi = 2.0 * start
    while f(hi) > 0 and hi < 1e9:
        hi *= 2.0
    return float(optimize.brentq(f, start, hi, xtol=1e-4 * start))


def _dispersion_p(index: np.ndarray, judged: np.ndarray) -> float:
    """p-value of the χ² dispersion of the flags over blocks against their judged samples."""
    k = index.size
    if k < 20:
        return 1.0
    nb = int(min(max(k // 10, 2), 100))
    edges = np.linspace(0, judged.size, nb + 1).astype(np.int64)
    counts = np.add.reduceat(np.bincount(index, minlength=judged.size), edges[:-1])
    share = np.add.reduceat(judged.astype(float), edges[:-1])
    keep = share > 0
    e = k * share[keep] / share[keep].sum()
    chi2 = float(np.sum((counts[keep] - e) ** 2 / e))
    return float(stats.chi2.sf(chi2, max(int(keep.sum()) - 1, 1)))


def heavy_floor(x, d, local, c: float, flags, skip=None, alpha: float = 0.01):
    """Is the noise floor a heavy-tailed (Student-t) one, and which flags are then spikes?

    The floor: ``x`` less the running mean of its neighbours (:data:`FLOOR_MEAN_WINDOW`), over its local
    robust σ (a burst's level is not a tail), fitted as a zero-centred Student-t and as a
    Gaussian within ±c (:func:`fit_student_t`). It is a t floor when the t wins (likelihood
    ratio beyond :data:`FLOOR_LR`, ν ≤ :data:`FLOOR_NU_MAX`), the flags beyond c are not fewer
    than it predicts (:func:`floor_tail`; a body heavier than its tail, a two-scale mixture, is
    no t), it predicts at least :data:`FLOOR_SHARE` of them (else they are spikes, and they made
    the body heavy) and they are spread over the record (:data:`FLOOR_P`); samples in ``skip``
    (next to held ones) are neither fitted nor counted. The spikes on such a floor are the flags
    beyond the level where it expects :data:`FLOOR_SPIKE_EXPECTED` values, when their count is an
    excess (normal score beyond :data:`FLOOR_Z_SPIKES`), else those beyond its 1 % family-wise level.

    Parameters
    ----------
    x : array_like, shape (n,)
        The series [any unit].
    d, local : ndarray, shape (n,)
        The detector's departures from the neighbour median [unit of x] and local σ̂ [same].
    c : float
        The detector's (Gaussian) threshold [σ̂].
    flags : ndarray of int
        Samples beyond it (the detector's candidates after the re-judging).
    skip : ndarray of bool or None
        Samples not judged.
    alpha : float
        Family-wise false-alarm probability of a spike beyond the floor's own level [-].

    Returns
    -------
    (HeavyFloor, ndarray of int) or None
        The floor and the flags that are spikes on it; None for a Gaussian floor.
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    w = FLOOR_MEAN_WINDOW
    if n < 4 * w:
        return None
    e = x - (ndimage.uniform_filter1d(x, w, mode="mirror") * w - x) / (w - 1)
    s_e = 1.4826 * float(np.median(np.abs(e)))
    if not s_e > 0:
        return None
    u = e / _local_sigma(e, s_e)
    judged = np.ones(n, bool) if skip is None else ~skip
    u = u[judged]
    if u.size > FLOOR_FIT_MAX:
        u = u[::int(math.ceil(u.size / FLOOR_FIT_MAX))]
    body = u[np.abs(u) < c]
    # a quick screen: the body's excess kurtosis of t₃₀ truncated at 6σ is 0.2; a Gaussian's 0
    if body.size < 1000 or float(stats.kurtosis(body)) < max(0.1, 4.0 * math.sqrt(24.0 / body.size)):
        return None
    nu, lsig, _, lr = fit_student_t(body, c)
    if not (lr > FLOOR_LR and nu <= FLOOR_NU_MAX):
        return None
    n_j = int(np.count_nonzero(judged))
    tail = floor_tail(nu)
    flags = np.asarray(flags, dtype=np.int64)
    k_c, lam_c = int(flags.size), n_j * tail(c)
    # the count's interval: Poisson 99.9 % about the floor's expectation at ν's 95 % bounds
    # (a ν of 3.02 ± 0.035 moves it by ±3 %: 1307 flags against 1433 ± 38 would otherwise fail)
    wl = 1.96 * lsig if math.isfinite(lsig) else math.nan
    nu_lo, nu_hi = (nu * math.exp(-wl), nu * math.exp(wl)) if math.isfinite(wl) else (nu, nu)
    lam_lo = n_j * floor_tail(nu_hi)(c) if nu_hi != nu else lam_c
    lam_hi = n_j * floor_tail(nu_lo)(c) if nu_lo != nu else lam_c
    lo_c = float(stats.poisson.ppf(0.5 * FLOOR_P, min(lam_lo, lam_c)))
    hi_c = float(stats.poisson.isf(0.5 * FLOOR_P, max(lam_hi, lam_c)))
    disp = _dispersion_p(flags, judged)
    if k_c < lo_c or lam_c < FLOOR_SHARE * k_c or disp < FLOOR_P:
        return None
    # the level of the spikes: the floor's tail, scaled up (never down) to the values it has
    # beyond FLOOR_CAL_LEVEL, where spikes are few against the floor: a low-passed floor is not
    # white, and its neighbours share its large values (ν = 5 through 1 + 0.6·z⁻¹: 197 flags
    # where the white tail predicts 83)
    u_all = np.abs(d) / local
    k_cal = int(np.count_nonzero(u_all[judged] > FLOOR_CAL_LEVEL))
    cal = max(1.0, k_cal / max(n_j * tail(FLOOR_CAL_LEVEL), 1e-300))
    n_eff = int(round(cal * n_j))
    test_level = _level(tail, n_eff, FLOOR_SPIKE_EXPECTED, c)
    lam_s = n_eff * tail(test_level)
    u_flags = u_all[flags]
    k_s = int(np.count_nonzero(u_flags > test_level))
    z = _poisson_z(k_s, lam_s)
    level = test_level if z >= FLOOR_Z_SPIKES else _level(tail, n_eff, alpha, c)   # else its own 1 % level
    spikes = flags[u_flags > level]
    var_ratio = nu / (nu - 2.0) if nu > 2 else math.inf
    mad = float(stats.t.ppf(0.75, nu)) / float(stats.norm.ppf(0.75))
    white = math.sqrt(var_ratio) / mad if math.isfinite(var_ratio) else math.inf
    adev = math.sqrt(1.0 + 1.5 / (nu - 4.0)) if nu > 4 else math.inf
    floor = HeavyFloor(nu, nu_lo if math.isfinite(w) else math.nan, nu_hi if math.isfinite(w) else math.nan,
                       lr, k_c, lam_c, lo_c, hi_c, _poisson_z(k_c, lam_c), disp, level, test_level, k_s, lam_s,
                       z, white, adev, cal)
    return floor, spikes


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
    hf = heavy_floor(x, d, local, c, idx, skip, alpha)
    if hf is not None:
        # a Student-t floor: the flags it predicts are its own; the spikes are beyond its level
        hf, idx = hf
        c, k, lam, z = hf.level, hf.spikes_beyond, hf.expected_beyond, hf.z
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
                          wide.fraction, wide.wide_size, wide.fraction_sigma, wide.wide_size_sigma, wide.lr,
                          hf)
    return Spikes(idx, d[idx], sigma, c, k, lam, z, size, s_size, rate, kurt, at_floor, floor=hf)


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
