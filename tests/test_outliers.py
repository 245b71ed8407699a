"""Outliers: isolated spikes found, counted and sized, kept out of the noise model, never a burst.

Outside truth: a Gaussian record has no spikes (the detection threshold is
a 1 % family-wise one); spikes set by the simulator are counted and sized
back (their number is Poisson, their size Gaussian: within the sampling
spread); on the real Xsens MTi-G record the count agrees with the ~2 000
spikes its source states (``../shared/measurements/README.md``: the
robust-estimation showcase of SMAC-Group/imudata ``cont.imu1``) and lies
between two independent counts written here (a three-point second
difference beyond 4 and 5 of its own robust σ), and the burst the spikes
made is no longer seen once they are out.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gyroarray.effects.outliers import clean_spikes, find_spikes
from gyroarray.chain.compare import ModelComparison
from gyroarray.core.measurement import read_measurement
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.core.layout import Layout

XSENS = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "xsens_mtig_outliers.csv.gz"


def test_gaussian_noise_has_no_spikes_and_a_standard_score():
    rng = np.random.default_rng(0)
    found, zs = 0, []
    for _ in range(40):
        s = find_spikes(rng.normal(0.0, 1.0, 100_000))
        found += s.index.size > 0
        zs.append(s.z)
    # P(any false spike) <= 1 % per record: 2 or more of 40 has probability 6 %; 4 or more 0.1 %
    assert found <= 3
    # the count score: a mid-p Poisson score with λ ≈ 0.7 is N(0, 1)-like but discrete (sd < 1)
    assert abs(np.mean(zs)) < 0.5 and 0.4 < np.std(zs) < 1.2


def test_simulated_spikes_are_counted_and_sized():
    n, dt, rate_h, size = 360_000, 0.01, 600.0, 0.5          # 1 h at 100 Hz: 600 spikes of 0.5 deg/s rms
    model = NoiseModel.from_toml({"effects": [{"effect": "arw", "n_deg_rt_h": 0.2},
                                              {"effect": "outliers", "gyro": 1, "rate_per_h": rate_h,
                                               "size_deg_s": size}]}, n_gyros=1)
    y = simulate_readings(model, np.zeros((n, 3)), Layout.from_axes([[1.0, 0.0, 0.0]]), dt,
                          np.random.default_rng(4))
    s = find_spikes(y[:, 0])
    hours = n * dt / 3600.0
    # Poisson count of 600: sd 24.5; the threshold's correction adds the size's uncertainty: 15 %
    assert abs(s.rate * n / hours - rate_h) < 0.15 * rate_h
    assert abs(math.degrees(s.size) - size) < 0.1 * size
    assert s.z > 20


@pytest.mark.skipif(not XSENS.exists(), reason="needs ../shared/measurements/real")
def test_xsens_spikes_are_named_counted_and_not_a_burst():
    m = read_measurement(XSENS)
    x = m.gyro_rad_s[:, 0]
    # independent counts: |x_k − (x_{k−1} + x_{k+1})/2| beyond 4 and 5 robust σ of that statistic
    d2 = x[1:-1] - 0.5 * (x[:-2] + x[2:])
    dev = np.abs(d2 - np.median(d2))
    sig = 1.4826 * np.median(dev)
    loose, strict = int(np.sum(dev > 4.0 * sig)), int(np.sum(dev > 5.0 * sig))
    a = ModelComparison(m, n_runs=10).analyse()
    top = a.candidates[0]
    assert (top.effect, top.gyro) == ("outliers", 1) and a.significant(top)
    n_spikes = top.fit.extra["n_spikes"]
    assert abs(n_spikes - 2000) <= 0.2 * 2000, n_spikes            # the source's ~2 000
    assert strict <= n_spikes <= loose, (strict, n_spikes, loose)
    burst = next(t for t in a.candidates if t.effect == "burst")
    # the burst's own z is above the critical z (the spikes raise a window's variance), but with
    # the spikes out it is not: a burst is never a significant candidate beside them
    assert "no longer seen" in burst.evidence and burst.z > a.z_crit
    assert burst.explained_by == ("outliers", 1) and not a.significant(burst)
    assert not any(c["effect"] == "burst" and c["significant"] for c in a.to_json_dict()["candidates"])


def test_close_spikes_are_found_and_cleaned_separately():
    """Two spikes three samples apart: each is found, the samples between them (whose
    four-neighbour median holds one spike) are not, and cleaning leaves every sample within
    the noise (the plain neighbour median would put half a spike into the samples between)."""
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 1.0, 20_000)
    x[5000] += 80.0
    x[5003] -= 150.0
    s = find_spikes(x)
    assert list(s.index) == [5000, 5003]
    cleaned = clean_spikes(x, s.index)
    assert np.abs(cleaned[4995:5010]).max() < 5.0
    np.testing.assert_array_equal(cleaned[5001:5003], x[5001:5003])


def test_a_few_values_just_beyond_the_threshold_do_not_make_an_impossible_rate():
    """Two values of 7.5σ in plain Gaussian noise (6.98 and 8.19 σ̂ of the detector's differences): the truncated normal's likelihood would read
    them as the tail of tiny spikes and the rate as one spike per sample or more (the MPU-6050's
    gyro 3 read 4.8e12 per hour at 100 Hz). The size is held at the threshold/1.96, so at least
    5 % of the spikes lie beyond it: the rate is at most 20 × 2 over the record, and the size's
    σ, a bound's and not a curvature's, is not given."""
    rng = np.random.default_rng(8)
    x = rng.standard_normal(200_000)
    x[[50_000, 150_000]] = [7.5, -7.5]
    sp = find_spikes(x)
    assert set(sp.index.tolist()) == {50_000, 150_000}
    assert sp.size_at_floor and math.isnan(sp.size_sigma)
    # the floor: the threshold in the detector's σ̂ (its local value ≈ the record's), over 1.96
    assert sp.size == pytest.approx(sp.threshold * sp.sigma / 1.959964, rel=0.05)
    assert sp.rate * x.size <= 20.0 * 2 * 1.001
