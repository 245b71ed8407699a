"""A lab record as it comes: the MPU-6050 on a stepper shaft (../shared/measurements/real).

Device time stamps with duplicate rows and jitter, no static part, a
reference that is itself noisy (a differentiated 0.088° encoder). Repaired
on request, smoothed on request, diagnosed on continuous motion. Outside
truth written here: a plain least-squares regression of the gyro on the same
smoothed reference (the scale factor), and the lag of the largest
cross-correlation (the latency).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gyroarray.compare import ModelComparison
from gyroarray.errors import InputError
from gyroarray.measurement import read_measurement

MPU = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "mpu6050_yaw_medium_raw.csv.gz"
pytestmark = pytest.mark.skipif(not MPU.exists(), reason="needs ../shared/measurements/real")

SMOOTH_S = 0.05


def _centred(x: np.ndarray, length: int) -> np.ndarray:
    return np.convolve(x, np.ones(length) / length, mode="same")


@pytest.fixture(scope="module")
def analysis():
    m = read_measurement(MPU, repair=True)
    return m, ModelComparison(m, n_runs=5, ref_smooth_s=SMOOTH_S).analyse()


def test_refused_without_repair_and_the_message_names_the_flag():
    with pytest.raises(InputError, match="--repair"):
        read_measurement(MPU)


def test_no_static_part_is_diagnosed_from_what_the_reference_leaves(analysis):
    m, a = analysis
    assert any("repaired" in n for n in m.notes)
    assert any("no static part" in n for n in a.notes) and any("--ref-smooth" in n for n in a.notes)


def test_scale_factor_and_latency_of_the_z_gyro_agree_with_plain_estimates(analysis):
    m, a = analysis
    y = m.gyro_deg_s[:, 2]
    ref = _centred(m.ref_deg_s[:, 2], int(round(SMOOTH_S / m.dt_s)))
    X = np.column_stack([np.ones_like(ref), ref])
    plain_ppm = (np.linalg.lstsq(X, y, rcond=None)[0][1] - 1.0) * 1e6
    sf = next(t for t in a.candidates if (t.effect, t.gyro) == ("scale_factor", 3))
    assert a.significant(sf)
    assert abs(sf.fit.params["ppm"] - plain_ppm) <= 3000.0, (sf.fit.params["ppm"], plain_ppm)   # 0.3 %
    lags = np.arange(-10, 11)
    c = [np.corrcoef(np.roll(ref, k)[20:-20], y[20:-20])[0, 1] for k in lags]
    plain_lag_s = lags[int(np.argmax(c))] * m.dt_s
    lat = next(t for t in a.candidates if (t.effect, t.gyro) == ("latency", 3))
    assert a.significant(lat)
    assert abs(lat.fit.params["delay_s"] - plain_lag_s) <= 0.005, (lat.fit.params["delay_s"], plain_lag_s)


def test_a_significant_gauss_markov_hump_has_a_positive_amplitude(analysis):
    """The rate runs continuously, so the ADEV of gyros 1 and 2 exceeds ARW + RRW sevenfold at
    0.3–20 s. The Gauss–Markov scan's score sees that excess, but refitted, the hump's σ² comes
    out <= 0. A Gauss–Markov ADEV is proportional to σ², so a zero amplitude cannot explain an
    excess: such a hump is not named significant, and it says why."""
    _, a = analysis
    gms = [t for t in a.tests if t.effect == "gauss_markov" and t.fit is not None]
    assert gms
    for t in gms:
        if a.significant(t):
            assert t.fit.params["sigma_deg_h"] > 0
    flat = [t for t in gms if "does not fit it" in t.evidence]
    assert flat and all(not a.significant(t) for t in flat)
