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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage, optimize, special, stats

from gyroarray.analysis.memo import by_content
from gyroarray.effects.fitting import EffectFit, z_from_log_p
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Effect, Kind, Param, Stage, no_longer_seen, with_term
from gyroarray.core.units import deg_s_to_rad_s, rad_s_to_deg_s

#: Seconds per hour (the rate's unit).
_S_PER_H = 3600.0
#: Most spikes per hour a model may give [1/h]: one per sample at the highest sample rate a
#: scenario may have (1 MHz); beyond it the Poisson count of a run overflows.
MAX_RATE_PER_H = 1e6 * _S_PER_H


class Outliers(Effect):
    """Spikes on the output: in each gyro a Poisson number of them, ``rate_per_h``
    per hour on average, at samples drawn uniformly over the record (distinct),
    each of size N(0, ``size_deg_s``²) (rms ``size_deg_s``). They act on the
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
                    doc="rms spike size (spikes ~ N(0, size²))"))
    scored = ("rate_per_h", "size_deg_s")
    doc = "isolated single-sample spikes"

    def simulate(self, state, act, streams):
        ctx = state.ctx
        term = np.zeros((ctx.n, len(act.cols)))
        span_s = ctx.n * ctx.dt_s
        for j, c in enumerate(act.cols):
            gen = streams.stream(self.name, int(c) + 1)
            k = int(min(gen.poisson(act.p["rate_per_s"][j] * span_s), ctx.n))
            where = gen.choice(ctx.n, size=k, replace=False)
            term[where, j] = gen.normal(0.0, act.p["size_rad_s"][j], k)
        return with_term(state, act.cols, term)

    # -- fit side -------------------------------------------------------------------
    def _spikes(self, ctx, gyro: int, x: np.ndarray, key: str):
        k = ("outliers", key, gyro)
        if k not in ctx.cache:
            ctx.cache[k] = find_spikes(x)
        return ctx.cache[k]

    def fit(self, ctx, gyro, E):
        g = int(gyro)
        in_model = any(e.effect == self.name and e.gyro == g for e in ctx.entries(self.name))
        # in the model its spikes are already out of the residual: they are counted on the raw one.
        # A spike is judged against the noise around it (a running median), and at a burst's
        # edges that median mixes the two levels: the first samples inside read as a crowd of
        # spikes (scored burst cases, right model: z 3.7 on one gyro). The model knows the level.
        x = ctx.at_model_level(ctx.E0 if in_model else E, ctx.t)[:, g - 1]
        x = x[:ctx.noise_end]                           # not what the model leaves out to the end (frozen)
        sp = self._spikes(ctx, g, x, "raw" if in_model else "residual")
        span_h = x.size * ctx.dt / _S_PER_H
        rate = sp.rate * x.size / span_h if span_h > 0 else 0.0
        size = float(rad_s_to_deg_s(sp.size)) if math.isfinite(sp.size) else 0.0
        sigma = {}
        if sp.index.size:
            sigma["rate_per_h"] = float(rate / math.sqrt(sp.index.size))       # Poisson
            if math.isfinite(sp.size_sigma):
                sigma["size_deg_s"] = float(rad_s_to_deg_s(sp.size_sigma))
        if sp.z > 3:
            held = ("; at most, since the size is held at the threshold/1.96: those seen are too few "
                    "to say how many lie below it") if sp.size_at_floor else ""
            ev = (f"gyro {g} has {sp.index.size} isolated spikes (rms {size:.3g} deg/s, {rate:.3g} per hour "
                  f"counting those below the {sp.threshold:.1f}σ threshold{held}; {sp.count_excess} second-difference "
                  f"clusters beyond {4.5:g}σ against {sp.expected:.2g} expected; first differences' excess kurtosis "
                  f"{sp.kurtosis:.3g})")
        else:
            ev = (f"gyro {g} shows no spikes ({sp.count_excess} second-difference clusters beyond 4.5σ against "
                  f"{sp.expected:.2g} expected, z = {sp.z:.1f})")
        return EffectFit(self.name, g, {"rate_per_h": float(rate), "size_deg_s": size}, sigma, z=float(sp.z),
                         evidence=ev, extra={"n_spikes": int(sp.index.size), "kurtosis": sp.kurtosis})

    def test(self, ctx, gyro):
        return self.fit(ctx, gyro, ctx.E)

    def _clean_index(self, ctx, entry, x: np.ndarray) -> np.ndarray:
        return find_spikes(x).index

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
        idx = find_spikes(x).index
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


def _count_test(x: np.ndarray, sigma: float) -> tuple[int, float, float]:
    """(clusters beyond :data:`COUNT_THRESHOLD`, their expectation without spikes, z).

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
    return k, lam, _poisson_z(k, lam)


@by_content()
def find_spikes(x, alpha: float = 0.01) -> Spikes:
    """Spikes of the series ``x`` (n,) (module docstring)."""
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
    k, lam, z = _count_test(x, sigma)
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
    return Spikes(idx, d[idx], sigma, c, k, lam, z, size, s_size, rate, kurt, at_floor)


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
