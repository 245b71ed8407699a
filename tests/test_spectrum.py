"""analysis.spectrum.welch against the reference implementation, scipy.signal.welch."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from gyroarray.analysis.spectrum import welch


@pytest.mark.parametrize("detrend", ["constant", "linear", False])
@pytest.mark.parametrize("n, nperseg, noverlap", [(5000, 512, None), (4099, 257, None), (3000, 300, 100),
                                                  (1024, 1024, None)])
def test_equals_scipy_welch(detrend, n, nperseg, noverlap):
    """Same frequencies and PSD as scipy (1e-12 of the largest value: rounding of the sums),
    several columns, odd and even segments, any overlap, a trend and a mean in the data."""
    rng = np.random.default_rng(n + nperseg)
    x = rng.standard_normal((n, 3)) + np.linspace(0.0, 4.0, n)[:, None] + 7.0
    f0, p0 = signal.welch(x, fs=50.0, window="hann", nperseg=nperseg, noverlap=noverlap,
                          detrend=detrend, axis=0)
    f1, p1 = welch(x, 50.0, nperseg, noverlap, detrend=detrend, axis=0)
    np.testing.assert_array_equal(f0, f1)
    assert p1.shape == p0.shape
    np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-12 * p0.max())


def test_one_dimensional_and_last_axis():
    rng = np.random.default_rng(1)
    x = rng.standard_normal((2, 4000))
    f0, p0 = signal.welch(x, fs=1.0, nperseg=256, detrend="constant", axis=-1)
    f1, p1 = welch(x, 1.0, 256, axis=-1)
    np.testing.assert_allclose(p1, p0, rtol=1e-12)
    f0, p0 = signal.welch(x[0], fs=1.0, nperseg=256, detrend="linear")
    f1, p1 = welch(x[0], 1.0, 256, detrend="linear")
    np.testing.assert_allclose(p1, p0, rtol=1e-12)


def test_white_noise_level():
    """Closed form: white noise of variance σ² sampled at fs has the one-sided density 2σ²/fs."""
    rng = np.random.default_rng(2)
    x = 0.3 * rng.standard_normal(2 ** 18)
    f, p = welch(x, 100.0, 1024)
    # 511 segments, ~1.9 dof each: the mean over 400 bins is within 1 % of 2σ²/fs (sd ≈ 0.2 %)
    assert abs(p[50:450].mean() / (2 * 0.09 / 100.0) - 1.0) < 0.01


def test_bad_segment():
    with pytest.raises(ValueError):
        welch(np.zeros(100), 1.0, 200)
    with pytest.raises(ValueError):
        welch(np.zeros(100), 1.0, 50, detrend="quadratic")
