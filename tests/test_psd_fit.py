"""The spectral likelihood of analysis.psd_fit: its redundancy factor (closed form) and the
null calibration of the filter score on white + random-walk records."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroarray.analysis import psd_fit
from gyroarray.core.units import arw_deg_rt_h_to_rad_rt_s, rrw_deg_h_rt_h_to_rad_s_rt_s

DT = 0.02


def test_bin_redundancy_of_hann_is_closed_form():
    """Hann: neighbouring DFT ordinates correlate 2/3 and 1/6 (Percival & Walden 6.17),
    so the squared moduli 4/9 and 1/36: 1 + 2(4/9 + 1/36) = 35/18."""
    assert math.isclose(psd_fit._BIN_REDUNDANCY, 35.0 / 18.0, rel_tol=1e-12)
    assert math.isclose(psd_fit._bin_redundancy("boxcar", 256), 1.0, rel_tol=1e-12)


def _null_scores(n_records: int, n: int):
    N = arw_deg_rt_h_to_rad_rt_s(0.2)
    K = rrw_deg_h_rt_h_to_rad_s_rt_s(3.0)
    lr = np.empty(n_records)
    for s in range(n_records):
        rng = np.random.default_rng([17, s])
        x = N / math.sqrt(DT) * rng.standard_normal(n) + np.cumsum(K * math.sqrt(DT) * rng.standard_normal(n))
        lr[s] = psd_fit.fit_psd(x, DT).lr_filter
    return lr, np.array([psd_fit.filter_z(v) for v in lr])


@pytest.mark.slow   # a calibration study of 14 s: make score
def test_filter_score_is_calibrated_without_a_filter():
    """200 records of 15 000 samples, no filter. The scan's maximum, the bins' overlap counted
    once, is one χ²₁/2 + δ₀/2 test: mean 2Δℓ 0.59 and P(z > 1) 0.17 over 500 records (summing
    the bins as independent: mean 1.15, and 1 % of the records above z = 3). Bands: 99.9 %
    binomial for P(z > 1) around 0.159 (±0.085), ±3.3 standard errors (sd of 2Δℓ ≈ 1.1) for
    the mean around 0.55."""
    lr, z = _null_scores(200, 15_000)
    assert 0.074 < np.mean(z > 1.0) < 0.244
    assert 0.29 < lr.mean() < 0.81
    assert np.mean(z > 3.0) <= 0.02


def test_dispersion_is_one_when_the_model_holds_the_spectrum():
    """White noise through the spec's filter (scipy's sosfilt, gyroarray.core.sensor), 20 records of
    2e5 samples per setting: the robust dispersion of the fit's Pearson residuals averages 1
    (measured 1.00–1.02; its sd over records is about 0.12, so the mean's 3.3 standard errors
    are ±0.09), so the cut-off's σ is the profile's own on such records."""
    from gyroarray.core.sensor import bandwidth_filter
    for fc, order, dt in ((20.0, 2, 0.01), (3.0, 1, 0.02)):
        d = [psd_fit.fit_psd(bandwidth_filter(np.random.default_rng([5, s]).standard_normal(200_000),
                                               dt, fc, order), dt).dispersion for s in range(20)]
        assert abs(np.mean(d) - 1.0) < 0.09, (fc, order, np.mean(d))
