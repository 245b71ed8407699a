"""Spike sizes heavier-tailed than one Gaussian (issue 32, item 6): a scale mixture of two sizes.

Outside truth: the shared Xsens MTi-G record's own counts of samples beyond 2, 5 and 8 deg/s
(the thresholds of the issue, in deg/s: its noise σ is 0.114 deg/s, so they are 18-70 σ and
count spikes, not noise) against the counts the fitted law predicts, computed here with
scipy.stats from the fitted parameters alone (spike ~ N(0, s²) or N(0, s_w²), plus the record's
robust noise σ); a record written with numpy with spikes of known sizes and share; the
simulator's draws against the law with a Kolmogorov-Smirnov test.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import read_measurement
from gyroarray.effects.model import NoiseModel
from gyroarray.effects.outliers import find_spikes
from gyroarray.sim.effects import simulate_readings

XSENS = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "xsens_mtig_outliers.csv.gz"
DOCS = Path(__file__).resolve().parents[1] / "docs"


def _poisson95(k: int) -> tuple[float, float]:
    """Garwood's exact 95 % interval of a Poisson mean from one count ``k``."""
    lo = 0.0 if k == 0 else stats.chi2.ppf(0.025, 2 * k) / 2
    return lo, stats.chi2.ppf(0.975, 2 * k + 2) / 2


def _predicted(sp, n: int, noise: float, level: float) -> float:
    """Samples beyond ``level`` [deg/s] the fitted law predicts: every spike (the rate counts
    those below the threshold) plus the noise N(0, noise²), and the noise alone elsewhere."""
    k = sp.rate * n
    f = sp.wide_fraction if math.isfinite(sp.wide_fraction) else 0.0
    wide = sp.wide_size if f > 0 else sp.size
    p = ((1 - f) * 2 * stats.norm.sf(level, scale=math.hypot(sp.size, noise))
         + f * 2 * stats.norm.sf(level, scale=math.hypot(wide, noise)))
    return k * p + (n - k) * 2 * stats.norm.sf(level, scale=noise)


@pytest.fixture(scope="module")
def xsens():
    if not XSENS.exists():
        pytest.skip("needs ../shared/measurements/real")
    x = read_measurement(XSENS).gyro_deg_s[:, 0]
    x = x - np.median(x)
    return x, find_spikes(x), 1.4826 * float(np.median(np.abs(x)))


@pytest.mark.parametrize("level", [2.0, 5.0, 8.0])
def test_xsens_tail_counts_are_predicted(xsens, level):
    """One Gaussian size (4960 N(0, 1.445²) spikes) predicted 830 samples beyond 2 deg/s and 0
    beyond 8 where the record has 130 and 26; the two-size law is within their Poisson 95 %
    intervals."""
    x, sp, noise = xsens
    assert math.isfinite(sp.wide_fraction) and sp.wide_lr > 100
    observed = int(np.sum(np.abs(x) > level))
    lo, hi = _poisson95(observed)
    pred = _predicted(sp, x.size, noise, level)
    assert lo <= pred <= hi, (level, observed, pred, (lo, hi))


@pytest.mark.xfail(strict=True, reason="beyond 1.5 deg/s the record has 248 samples, the law predicts "
                   "~535 (one size: 1533): the ~2000 spikes just above the 6σ̂ threshold fall off "
                   "more steeply than any zero-centred size law held at threshold/1.96 allows; a "
                   "narrower law would hide 100 spikes per one seen (four samples in ten)")
def test_xsens_tail_count_beyond_1_5_deg_s(xsens):
    x, sp, noise = xsens
    observed = int(np.sum(np.abs(x) > 1.5))
    lo, hi = _poisson95(observed)
    assert lo <= _predicted(sp, x.size, noise, 1.5) <= hi


def _record(rng, n, spikes, fraction, size, wide_size):
    x = rng.standard_normal(n)
    where = rng.choice(n, spikes, replace=False)
    wide = rng.random(spikes) < fraction
    x[where] += np.where(wide, wide_size, size) * rng.standard_normal(spikes)
    return x


def test_two_sizes_are_recovered_within_their_ci():
    """4000 spikes on unit white noise, 5 % of them N(0, 40²), the rest N(0, 5²)."""
    sp = find_spikes(_record(np.random.default_rng(0), 200_000, 4000, 0.05, 5.0, 40.0))
    assert math.isfinite(sp.wide_fraction)
    for est, sig, true in ((sp.wide_fraction, sp.wide_fraction_sigma, 0.05),
                           (sp.wide_size, sp.wide_size_sigma, 40.0)):
        assert abs(est - true) < 1.96 * sig, (est, sig, true)            # within the 95 % CI
    assert abs(sp.size - 5.0) < 2.58 * sp.size_sigma                      # within the 99 % CI
    assert abs(sp.rate * 200_000 - 4000) < 0.15 * 4000


def test_one_gaussian_size_stays_one():
    """Spikes of one Gaussian size: no wide part (the likelihood ratio is below its 0.1 % point)."""
    sp = find_spikes(_record(np.random.default_rng(1), 100_000, 1000, 0.0, 8.0, 8.0))
    assert sp.index.size > 250 and math.isnan(sp.wide_fraction)


def test_the_simulator_draws_the_two_sizes():
    """The spikes a model with ``wide_fraction`` simulates follow the scale mixture (KS test)."""
    f, s, sw = 0.1, 0.5, 10.0
    model = NoiseModel.from_toml({"effects": [
        {"effect": "outliers", "gyro": 1, "rate_per_h": 3.6e4, "size_deg_s": s,
         "wide_fraction": f, "wide_size_deg_s": sw}]}, n_gyros=1)
    y = simulate_readings(model, np.zeros((20_000, 3)), Layout.from_axes([[1.0, 0.0, 0.0]]), 0.01,
                          np.random.default_rng(2))
    v = np.degrees(y[:, 0][y[:, 0] != 0])
    assert 1800 < v.size < 2200                                   # Poisson(2000)
    cdf = lambda u: (1 - f) * stats.norm.cdf(u, scale=s) + f * stats.norm.cdf(u, scale=sw)  # noqa: E731
    assert stats.kstest(v, cdf).pvalue > 1e-3
    rms = math.sqrt((1 - f) * s * s + f * sw * sw)                # one Gaussian of the same rms: refused
    assert stats.kstest(v, stats.norm(scale=rms).cdf).pvalue < 1e-6


def test_wide_parameters_go_together_and_are_documented():
    with pytest.raises(InputError, match="wide_size_deg_s"):
        NoiseModel.from_toml({"effects": [{"effect": "outliers", "gyro": 1, "rate_per_h": 1.0,
                                           "size_deg_s": 1.0, "wide_fraction": 0.1}]}, n_gyros=1)
    with pytest.raises(InputError, match="wide_fraction"):
        NoiseModel.from_toml({"effects": [{"effect": "outliers", "gyro": 1, "rate_per_h": 1.0,
                                           "size_deg_s": 1.0, "wide_fraction": 1.5,
                                           "wide_size_deg_s": 3.0}]}, n_gyros=1)
    text = "".join(p.read_text(encoding="utf-8") for p in DOCS.glob("*.md"))
    assert "wide_fraction" in text and "wide_size_deg_s" in text
