"""A step fault must beat the record's own wander (issue 44, item 4 of what to build; break 3).

Outside truth: a record written here with numpy whose wander is a sinusoid A·sin(ωt): the step
statistic S_w(t) = mean of the w after t less the mean of the w before is, exactly,
(2A/(ωw))·(1 − cos ωw)·cos ωt, so the share of times where |S_w| ≥ S is (2/π)·arccos(S/M_w),
M_w = 2A(1 − cos ωw)/(ωw), for phases spread uniformly; a brute-force loop of plain means for the
statistic itself; the same step on a record without the wander.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroarray.core.errors import InputError
from gyroarray.effects.faults.wander import (WANDER_SHARE, beats_wander, step_statistic, wander_quantile,
                                             windows_for)

DT, PERIOD, AMP, STEP, NOISE = 1.0, 8000.0, 0.03, 0.02, 0.002     # [s], [s], [deg/s], [deg/s], [deg/s]
N = 80_000                                                         # ten periods of the wander
T0 = 20_000.0 + PERIOD / 4                                         # at a crest: S_w of the wander is 0 there


def _record(wander: bool, seed: int = 0) -> np.ndarray:
    t = np.arange(N) * DT
    x = np.random.default_rng(seed).normal(0.0, NOISE, N)
    if wander:
        x += AMP * np.sin(2 * np.pi * t / PERIOD)
    return x + np.where(t >= T0, STEP, 0.0)


def _share(w_s: float) -> float:
    """(2/π)·arccos(S/M_w): the share of phases where the sinusoid's statistic reaches the step."""
    om = 2 * np.pi / PERIOD
    m = 2 * AMP * (1 - math.cos(om * w_s)) / (om * w_s)
    return 0.0 if STEP >= m else 2 / np.pi * math.acos(STEP / m)


def test_step_statistic_is_the_difference_of_plain_means():
    x = np.random.default_rng(1).normal(0.0, 1.0, 500)
    x[37] = np.nan
    s = step_statistic(x, 20)
    for t in (20, 37, 200, 480):
        a, b = x[t:t + 20], x[t - 20:t]
        assert s[t] == pytest.approx(np.nanmean(a) - np.nanmean(b), abs=1e-12)
    assert np.isnan(s[19]) and np.isnan(s[481]) and np.isfinite(s[480])


def test_a_wander_is_no_step():
    """The issue's pattern: the step's size is rarely reached with short windows and often with
    long ones (S = 0.02 against M_w = 0.0070 / 0.0224 / 0.0435 deg/s: shares 0, 0.30, 0.70)."""
    q = wander_quantile(_record(True), DT, T0, windows_s=(300.0, 1000.0, 3000.0))
    for qi in q:
        # the size at the crest is the step (the wander's statistic is 0 there; noise σ·√(2/w) ≤ 2e-4)
        assert qi.size == pytest.approx(STEP, abs=5 * NOISE * math.sqrt(2 / qi.window_s))
        # the share over ten periods: the excluded ±w around the onset and the ends leave whole
        # phases out (≤ 2w of 72 000 s each way): ±0.06 at 3000 s, the noise adds < 0.01
        assert qi.share == pytest.approx(_share(qi.window_s), abs=0.06), (qi.window_s, qi.share)
    assert q[0].share < WANDER_SHARE < q[1].share
    assert not beats_wander(q)


def test_a_step_beats_a_flat_record():
    q = wander_quantile(_record(False), DT, T0)
    assert [qi.window_s for qi in q] == [300.0, 1000.0, 3000.0]
    # noise only: the step is 0.02 / (0.002·√(2/300)) = 122σ of the statistic at 300 s
    assert all(qi.share == 0.0 for qi in q) and beats_wander(q)


def test_a_given_size_and_short_records():
    x = _record(True)
    q = wander_quantile(x, DT, T0, windows_s=(3000.0,), size=0.0)
    assert q[0].share == 1.0 and q[0].size == 0.0                  # every time reaches a size of 0
    # a 10 min record cannot hold 300 s windows and eight other ones: shorter windows are taken
    assert windows_for(600.0, 300.0) == pytest.approx((600 / 12 / 10, 600 / 12 / 3, 600 / 12))
    short = wander_quantile(x[:600], DT, 300.0)
    assert len(short) == 3 and all(qi.judged for qi in short[1:])
    assert not short[0].judged                                     # 5 samples: too few for a mean
    with pytest.raises(InputError):
        wander_quantile(x, DT, -5.0)
    with pytest.raises(InputError):
        wander_quantile(x, 0.0, 10.0)
