"""Isolated single-sample spikes in a gyro record: found, counted, sized, removed.

A spike is one sample that departs from its neighbours by far more than the
noise: the residual minus the median of its four neighbours (two on each
side, itself left out, so d is continuous and ≈ normal for Gaussian noise),
d, against the noise's robust standard deviation σ̂ = 1.4826·MAD(d). A spike moves one
sample's d and no median, so it stands out; a change of the noise level (a
burst) moves the MAD of a whole stretch and does not.

* σ̂ is local: the MAD of d in blocks of 2000 samples, so a noise level that
  changes over the record (a burst) is not read as a crowd of spikes.
* Detection (which samples): |d| > c·σ̂ with c the Bonferroni threshold of a
  1 % family-wise false alarm over the record's samples (a clean Gaussian
  record shows a spike with probability 1 %), and at least 6: real noise has
  heavier tails than a Gaussian (the Xsens MTi-G record: 19 000 samples
  beyond 4σ̂, 2 000 beyond 6σ̂, its source's ~2 000 spikes).
* Significance (is there an excess?): the count of |d| > 4.5σ̂ against its
  Poisson expectation under Gaussian noise, λ₀ = n·P(|d/σ| > 4.5) with d's
  own variance (a sample minus a median of five), as a normal score.
* Size: the detected values are the spikes' tails beyond c·σ̂; the rms spike
  size s of spikes ~ N(0, s²) (the spec's ``size_deg_s``) is the maximum
  likelihood of that two-sided truncated normal, and the rate counts the
  spikes the threshold missed: rate = K / (T·P(|N(0, s²)| > c·σ̂)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, special, stats

from gyroarray.analysis.effect_fit import z_from_log_p

__all__ = ["Spikes", "find_spikes", "clean_spikes", "COUNT_THRESHOLD", "MEDIAN_WINDOW"]

#: Running-median window [samples]: two neighbours on each side, the sample itself left out.
MEDIAN_WINDOW = 5


def _neighbour_median(x: np.ndarray) -> np.ndarray:
    """Median of the two samples on each side of every sample (the mean of the middle two of
    four; held values at the ends)."""
    p = np.pad(x, 2, mode="edge")
    nb = np.stack([p[:-4], p[1:-3], p[3:-1], p[4:]], axis=1)
    nb.sort(axis=1)
    return 0.5 * (nb[:, 1] + nb[:, 2])
#: Threshold of the count test [σ̂].
COUNT_THRESHOLD = 4.5
#: Lowest detection threshold [σ̂].
MIN_THRESHOLD = 6.0
#: Samples per block of the local noise level.
LOCAL_BLOCK = 2000


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
        Samples beyond :data:`COUNT_THRESHOLD`·σ̂.
    expected : float
        Their Poisson expectation without spikes.
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


def _poisson_z(k: int, lam: float) -> float:
    """Normal score of P(K >= k) for K ~ Poisson(λ), mid-p (a continuous, N(0, 1)-like score)."""
    if lam <= 0:
        return 0.0
    log_p = float(np.logaddexp(stats.poisson.logsf(k, lam), math.log(0.5) + stats.poisson.logpmf(k, lam)))
    return z_from_log_p(min(log_p, math.log1p(-1e-16)))


def _local_sigma(d: np.ndarray, sigma: float, block: int = LOCAL_BLOCK) -> np.ndarray:
    """The robust σ of d in blocks of ``block`` samples, per sample (a noise level that changes over
    the record, a burst, is not a crowd of spikes; isolated spikes do not move a block's MAD)."""
    n = d.size
    nb = n // block
    if nb < 2:
        return np.full(n, sigma)
    mads = 1.4826 * np.median(np.abs(d[:nb * block].reshape(nb, block)), axis=1)
    mads = np.where(mads > 0, mads, sigma)
    per = np.repeat(mads, block)
    return np.concatenate([per, np.full(n - per.size, mads[-1])])


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
    # count test: the tail of d/σ̂ beyond 4.5 for Gaussian noise (d's own spread: σ̂ estimates it)
    k = int(np.sum(np.abs(d) > COUNT_THRESHOLD * local))
    lam = n * float(special.erfc(COUNT_THRESHOLD / math.sqrt(2.0)))
    z = _poisson_z(k, lam)
    size, s_size, rate = math.nan, math.nan, 0.0
    if idx.size:
        v = d[idx]
        cut = c * float(np.median(local[idx]))

        def nll(log_s):
            s = math.exp(log_s)
            return -(np.sum(stats.norm.logpdf(v, scale=s)) - v.size * math.log(float(special.erfc(cut / (s * math.sqrt(2))))))
        s0 = max(float(np.sqrt(np.mean(v * v))), cut)
        res = optimize.minimize_scalar(nll, bounds=(math.log(cut * 0.05), math.log(s0 * 20)), method="bounded")
        size = math.exp(res.x)
        h = 1e-3
        d2 = (nll(res.x + h) - 2 * nll(res.x) + nll(res.x - h)) / h ** 2
        s_size = size / math.sqrt(d2) if d2 > 0 else math.nan
        p_seen = float(special.erfc(cut / (size * math.sqrt(2))))
        rate = idx.size / max(p_seen, 1e-12) / n
    return Spikes(idx, d[idx], sigma, c, k, lam, z, size, s_size, rate, kurt)


def clean_spikes(x, index) -> np.ndarray:
    """``x`` with the samples at ``index`` replaced by the median of their four neighbours."""
    x = np.array(x, dtype=float, copy=True)
    if len(index):
        x[index] = _neighbour_median(x)[index]
    return x
