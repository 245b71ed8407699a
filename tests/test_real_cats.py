"""The CATS tag IMU, 25 h static with a thermal cycle (../shared/measurements/real/cats_thermal_p1).

Outside truth written here: an ordinary least-squares regression of each gyro's rate on the
temperature (gyro 2: 96 deg/h/°C, and the same sensor's two other periods, kept back by the
issue's authors, give 93 and 93: the coefficient transfers between periods).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gyroarray.compare import ModelComparison
from gyroarray.measurement import read_measurement
from gyroarray.units import rad_s_to_deg_h

CATS = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "cats_thermal_p1.csv.gz"
pytestmark = pytest.mark.skipif(not CATS.exists(), reason="needs ../shared/measurements/real")


@pytest.fixture(scope="module")
def fitted():
    m = read_measurement(CATS)
    _, after = ModelComparison(m, n_runs=5).fit([("temperature_bias", 2)])
    return m, after.fits[("temperature_bias", 2)]


def _ols_slope(m, g: int) -> float:
    y = rad_s_to_deg_h(m.gyro_rad_s[:, g - 1])
    return float(np.polyfit(np.asarray(m.temp_c, float), y, 1)[0])


def test_gyro_2_temperature_coefficient_is_positive_and_significant(fitted):
    m, fit = fitted
    k, s = fit.params["deg_h_per_c"], fit.sigma["deg_h_per_c"]
    assert _ols_slope(m, 2) == pytest.approx(96.1, abs=0.5)          # the number, recomputed
    assert k > 5 * s and 0 < k < _ols_slope(m, 2)


@pytest.mark.xfail(strict=True, reason=(
    "not met: the GLS with a random-walk bias (the RRW the record's ADEV supports) reads the "
    "coefficient from the fast temperature changes and gives 59.6 ± 3.4 deg/h/°C; the plain "
    "regression on the levels gives 96.1 and transfers between the sensor's periods. A thermal "
    "lag of the temperature reading (0–2400 s) lowers the GLS value, a dT/dt term raises it only "
    "to 68 ± 4: the slow response is frequency dependent and no model term here describes it"))
def test_gyro_2_temperature_coefficient_within_10_percent_of_the_plain_regression(fitted):
    m, fit = fitted
    assert fit.params["deg_h_per_c"] == pytest.approx(_ols_slope(m, 2), rel=0.10)
