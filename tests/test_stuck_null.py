"""The stuck-output test's null: a terminal run compared with the record's own runs.

Outside truth: independent repeats among three equally likely values give runs of
geometric length, P(run >= r) = (1/3)^(r-1), a closed form; numpy-written quantized outputs
whose record ends with its longest run are no stuck gyro — a rate quantizer of a few LSB
levels (white noise of 0.25-0.4 LSB and a slow random walk) and the spec's angle counter
(increments floor(θ) steps, θ moving 0.1 step per sample: a ternary output) — and the i.i.d.
repeat rate written out here calls some of them stuck (z > 3) where the record's own runs do
not; a frozen tail appended to a counter and to a fine-grained output is still found.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroarray.effects.faults.scan import (_fit_stuck_output, _z_of_logp, log_p_run_at_least,
                                           run_lengths)
from gyroarray.effects.fitting import Z_EVIDENT

DT = 0.01


def _counter(seed: int, sigma_lsb: float, n: int = 100_000) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.round(sigma_lsb * rng.standard_normal(n) + np.cumsum(rng.standard_normal(n)) * 1e-3)


def _iid_z(out: np.ndarray) -> float:
    """The former null, written out: the terminal run against independent repeats at the rate
    of the record before it, anywhere among its samples."""
    L = run_lengths(out)
    run = int(L[-1])
    before = out[:out.size - run + 1]
    p0 = (np.sum(before[1:] == before[:-1]) + 1.0) / (before.size + 1.0)
    log_np = math.log(out.size) + (run - 1) * math.log(p0)
    return _z_of_logp(min(math.log(-math.expm1(-math.exp(log_np))), 0.0))


def test_geometric_runs_are_the_closed_form():
    rng = np.random.default_rng(7)
    lengths = run_lengths(rng.integers(0, 3, 300_000))
    for r in (2, 4, 9, 14):
        log_p, how = log_p_run_at_least(lengths, r)
        # ~2e5 runs: up to u = 3 the empirical survival (rel. error ~ 1/sqrt(2e4 runs)); beyond,
        # the tail fitted on the ~2e4 runs >= u (its mean excess to ~1 %, so log p to ~1 %),
        # also at r = 14 where ~0.1 run is expected: 3 %
        assert log_p == pytest.approx((r - 1) * math.log(1 / 3), rel=0.03), (r, how)


@pytest.mark.parametrize("sigma_lsb", [0.25, 0.4])
def test_a_quiet_counter_ending_in_its_longest_run_is_not_stuck(sigma_lsb):
    old = []
    for seed in range(4):
        out = _counter(seed, sigma_lsb)
        L = run_lengths(out)
        starts = np.r_[0, np.cumsum(L)[:-1]]
        i = int(np.argmax(np.where(starts > out.size // 5, L, 0)))
        cut = out[:starts[i] + L[i]]                  # the record ends with its longest run
        fit = _fit_stuck_output(cut, np.arange(cut.size) * DT, DT)
        assert fit.z < Z_EVIDENT, (seed, L[i], fit.z, fit.notes)
        old.append(_iid_z(cut))
    assert max(old) > Z_EVIDENT, old                  # the i.i.d. null called one stuck


def test_a_quiet_angle_counter_ending_in_its_longest_run_is_not_stuck():
    old = []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        y = np.diff(np.floor(np.cumsum(0.1 * rng.standard_normal(100_001))))   # steps per sample
        assert np.unique(y).size <= 5
        L = run_lengths(y)
        starts = np.r_[0, np.cumsum(L)[:-1]]
        i = int(np.argmax(np.where(starts > y.size // 5, L, 0)))
        cut = y[:starts[i] + L[i]]
        fit = _fit_stuck_output(cut, np.arange(cut.size) * DT, DT)
        assert fit.z < Z_EVIDENT, (seed, L[i], fit.z, fit.notes)
        old.append(_iid_z(cut))
    assert min(old) > Z_EVIDENT, old                  # the i.i.d. null called every one stuck


@pytest.mark.parametrize("sigma_lsb,q,frozen,z_min", [(1.0, 1e-3, 50, 10.0), (0.4, 1.0, 2000, 10.0)])
def test_a_frozen_tail_is_still_found(sigma_lsb, q, frozen, z_min):
    rng = np.random.default_rng(11)
    n = 100_000
    out = np.round((sigma_lsb * rng.standard_normal(n) + np.cumsum(rng.standard_normal(n)) * 1e-3) / q) * q
    out[-frozen:] = out[-frozen - 1]
    fit = _fit_stuck_output(out, np.arange(n) * DT, DT)
    # the onset: the first frozen sample, or earlier where the value before it repeated by chance
    assert fit.z > z_min and (n - frozen - 50) * DT <= fit.params["start_s"] <= (n - frozen) * DT
