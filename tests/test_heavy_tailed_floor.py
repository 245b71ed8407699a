"""A heavy-tailed noise floor is not spikes (issue 44, item 4 of what to build; break 3).

Outside truth: records written here with numpy whose white noise is drawn from a Student-t with
ν = 5 (10 min at 100 Hz, the issue's phone-like check), with and without 30 isolated spikes of
20σ at known samples; the t's own moments (scipy.stats) and the record's own standard deviation
against its robust one for the finding's effect on the white level; a Gaussian record for the
floor that must not be read.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement
from gyroarray.effects.outliers import find_spikes

N, NU, SIGMA_DEG_S = 60_000, 5.0, 0.05          # 10 min at 100 Hz; the t's standard deviation [deg/s]


def _floor(seed: int) -> np.ndarray:
    """White Student-t noise (ν = 5) of standard deviation SIGMA_DEG_S [deg/s]."""
    rng = np.random.default_rng(seed)
    return rng.standard_t(NU, N) * SIGMA_DEG_S / math.sqrt(NU / (NU - 2.0))


def _with_spikes(x: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """30 isolated spikes of ±20σ (σ the floor's standard deviation) at distinct samples."""
    rng = np.random.default_rng(seed)
    where = np.sort(rng.choice(N, 30, replace=False))
    y = x.copy()
    y[where] += 20.0 * SIGMA_DEG_S * rng.choice([-1.0, 1.0], 30)
    return y, where


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_student_t_floor_is_recognised_and_names_no_spikes(seed):
    x = _floor(seed)
    sp = find_spikes(x)
    f = sp.floor
    assert f is not None
    # ν's 95 % interval (likelihood curvature: ±0.24 at 60 000 samples) holds the truth
    assert f.nu_lo <= NU <= f.nu_hi, (f.nu, f.nu_lo, f.nu_hi)
    assert f.nu_hi - f.nu_lo < 1.0
    # the Gaussian detector's flags (34-41 here; a Gaussian floor: 0.01 in the record) are what
    # the t floor predicts: within its Poisson 99.9 % interval
    assert f.flags >= 20 and f.expected_lo <= f.flags <= f.expected_hi, (f.flags, f.expected)
    # no outliers: nothing beyond the floor's own 1 % family-wise level, the score not significant
    assert sp.index.size == 0 and sp.z < 3.0


def test_floor_effect_on_the_white_level_is_the_t_variance():
    """The finding's white_ratio (the t's σ over its 1.4826·MAD) against the record's own sample
    σ over its robust σ: for ν = 5 the ratio is √(5/3)/(t₅'s MAD/0.6745) = 1.198; the record's
    own reads it to ±3 % (the sample σ of a t₅ has a heavy-tailed spread: kurtosis 9)."""
    x = _floor(3)
    f = find_spikes(x).floor
    assert f is not None
    exact = math.sqrt(NU / (NU - 2.0)) / (stats.t.ppf(0.75, NU) / stats.norm.ppf(0.75))
    own = float(np.std(x)) / (1.4826 * float(np.median(np.abs(x - np.median(x)))))
    assert f.white_ratio == pytest.approx(exact, rel=0.06)       # ν ± 0.24 moves it by < 2 %
    assert f.white_ratio == pytest.approx(own, rel=0.06)
    # the ADEV's interval at the shortest τ: √((κ − 1)/2), κ = 3 + 3/(ν − 4) the first differences'
    assert f.adev_ci_factor == pytest.approx(math.sqrt(1.0 + 1.5 / (NU - 4.0)), rel=0.2)


@pytest.mark.parametrize("seed", [0, 1])
def test_isolated_spikes_on_the_floor_are_still_found(seed):
    y, where = _with_spikes(_floor(seed), seed + 10)
    sp = find_spikes(y)
    assert sp.floor is not None and sp.floor.nu_lo <= NU <= sp.floor.nu_hi
    found = np.intersect1d(sp.index, where).size
    assert found >= 28, found
    # beyond the floor's 0.5-expected level it predicts 0.5 values: at most a few of the named
    # are the floor's (Poisson(0.5) ≥ 4: 0.2 %)
    assert sp.index.size - found <= 3
    assert sp.z > 5.0


def test_floor_with_held_samples_names_no_spikes():
    """A phone-like stream: 6.7 % of the samples hold the one before (the pipeline's repeats);
    the detector judges nothing within HOLD_WIDTH of them, and the floor is read on the rest."""
    from gyroarray.analysis.pipeline import gyro_holds, near_holds
    from gyroarray.effects.outliers import HOLD_WIDTH
    x = _floor(5)
    held = np.flatnonzero(np.random.default_rng(9).random(N) < 0.067)
    for i in held[held > 0]:
        x[i] = x[i - 1]
    assert gyro_holds(x).significant
    sp = find_spikes(x, skip=near_holds(x, HOLD_WIDTH))
    assert sp.floor is not None and sp.floor.nu_lo <= NU <= sp.floor.nu_hi
    assert sp.index.size == 0 and sp.z < 3.0


def test_gaussian_floor_is_not_read_as_heavy():
    for seed in range(3):
        x = np.random.default_rng(100 + seed).normal(0.0, SIGMA_DEG_S, N)
        assert find_spikes(x).floor is None


@pytest.mark.slow
def test_the_analysis_names_no_outliers_on_a_t_floor():
    """The effect's test as the analysis runs it: on the t floor the outliers candidate is not
    significant and says it is a floor; the floor finding travels in its fit's extra."""
    from gyroarray.chain.compare import ModelComparison
    x = _floor(4)
    m = Measurement(time_s=np.arange(N) * 0.01, gyro_deg_s=x[:, None], layout=Layout.from_axes([[1.0, 0.0, 0.0]]),
                    sample_rate_hz=100.0)
    a = ModelComparison(m, n_runs=10).analyse()
    out = next(t for t in a.candidates if t.effect == "outliers")
    assert not a.significant(out)
    assert "heavy-tailed noise floor" in out.evidence
    hf = out.fit.extra["heavy_tailed_floor"]
    assert hf["kind"] == "heavy_tailed_floor" and hf["nu_ci95"][0] <= NU <= hf["nu_ci95"][1]
