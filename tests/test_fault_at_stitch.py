"""Issue 44 item 7: no step fault at the join of stitched still parts.

A record without a reference whose middle moves is cut into its still parts and stitched, each
part's mean set to the first's (:class:`gyroarray.chain.compare.ModelComparison`); a drift
within the parts then leaves a step at the join, which the stitched fits already take as the
part's free offset. ``fault_step`` named it (the CATS full record: g1 z 17–19 and g3 z 10.5 at
183 603–183 606 s, its join). Records drawn in numpy here; the outside truth is where the join
and the real step are.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroarray.chain.compare import ModelComparison
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement
from gyroarray.effects.faults.fault_step import FaultStep
from gyroarray.effects.faults.scan import JOIN_GUARD, fit_fault

FS = 10.0                       # Hz
DT = 1.0 / FS
PART_S, MOVE_S = 800.0, 20.0    # two still parts and the turn between them [s]
SIGMA_DEG_S = 0.005             # white noise per sample [deg/s]
DRIFT_DEG_S = 0.02              # a warm-up drift over each part's length [deg/s]
OFFSET_DEG_S = 0.05             # the bias step the new orientation brings [deg/s]


def _record(seed: int, step_deg_s: float = 0.0, step_at_s: float = 1300.0,
            drift_deg_s: float = DRIFT_DEG_S) -> Measurement:
    """One gyro: still, a 20 s turn of 30 deg/s peak about its axis, still again; a bias drifting
    steadily through both parts (``drift_deg_s`` over each part's length), an offset with the new
    orientation, white noise; a real step of ``step_deg_s`` from ``step_at_s`` (measurement time)
    when asked."""
    rng = np.random.default_rng(seed)
    n_p, n_m = int(PART_S * FS), int(MOVE_S * FS)
    n = 2 * n_p + n_m
    t = np.arange(n) * DT
    rate = np.zeros(n)
    rate[n_p:n_p + n_m] = 30.0 * np.sin(np.pi * np.linspace(0.0, 1.0, n_m)) ** 2
    bias = drift_deg_s * t / PART_S + np.where(t >= PART_S + MOVE_S / 2, OFFSET_DEG_S, 0.0)
    y = rate + bias + SIGMA_DEG_S * rng.standard_normal(n) + np.where(t >= step_at_s, step_deg_s, 0.0)
    return Measurement(time_s=t, gyro_deg_s=y[:, None], layout=Layout(np.array([[0.0, 0.0, 1.0]])),
                       sample_rate_hz=FS)


def _step_test(comp: ModelComparison):
    a = comp.analyse()
    return a, next(t for t in a.tests if (t.effect, t.gyro) == ("fault_step", 1))


def _join_s(comp: ModelComparison) -> float:
    """The join's time on the stitched clock [s]."""
    return float(comp.t[comp.parts[1][0]])


def test_the_join_is_not_a_step_fault(monkeypatch):
    comp = ModelComparison(_record(1), n_runs=5)
    assert len(comp.parts) == 2
    a, t = _step_test(comp)
    assert not a.significant(t), t.evidence
    assert "stitched parts" in t.evidence
    # the record does put a step at the join: the scan run through it (as before) names it there,
    # at the drift's share left by the equalised means (DRIFT_DEG_S, less what the turn removed)
    monkeypatch.setattr(FaultStep, "reads_joins", False)
    old_a, old = _step_test(ModelComparison(_record(1), n_runs=5))
    assert old_a.significant(old), old.evidence
    assert abs(old.fit.params["start_s"] - _join_s(comp)) < 1.0, old.evidence
    assert old.fit.params["size_deg_s"] == pytest.approx(-DRIFT_DEG_S, rel=0.1)


def test_a_real_step_inside_a_part_is_still_found():
    step = 0.01                                          # deg/s: 2 σ per sample, 500 s of it
    comp = ModelComparison(_record(1, step_deg_s=step, step_at_s=1300.0), n_runs=5)
    a, t = _step_test(comp)
    assert a.significant(t), t.evidence
    # 1300 s of the measurement on the stitched clock: the second part's start moved back
    at = float(comp.t[comp.parts[1][0]]) + (1300.0 - comp.parts_s[1][0])
    start, sig = t.fit.params["start_s"], t.fit.sigma["start_s"]
    assert abs(start - at) < max(3.0 * sig, 2.0 * DT), (start, sig, at)
    assert t.fit.params["size_deg_s"] == pytest.approx(step, abs=3.0 * t.fit.sigma["size_deg_s"])


def test_scan_restarts_at_a_break_and_skips_onsets_near_it():
    """fit_fault on a plain series: a jump of 10 σ at a break is a step without ``breaks``, and
    nothing with them; a step of the same size JOIN_GUARD samples or more inside a part is found
    at its sample with them; one within the guard is not a candidate."""
    rng = np.random.default_rng(5)
    n, b, r = 6000, 3000, 1.0
    y = rng.standard_normal(n)
    y[b:] += 10.0
    q = 1e-6
    assert fit_fault("step", y, DT, r, q).z > 10.0
    joined = fit_fault("step", y, DT, r, q, breaks=np.array([b]))
    assert joined.z < 3.0, joined
    inside = y.copy()
    inside[4500:] += 10.0
    f = fit_fault("step", inside, DT, r, q, breaks=np.array([b]))
    assert f.z > 10.0 and abs(f.onset_s - 4500 * DT) <= 2 * DT, f
    near = y.copy()
    near[b + JOIN_GUARD // 2:] += 10.0                   # within the guard after the join
    g = fit_fault("step", near, DT, r, q, breaks=np.array([b]))
    assert not (abs(g.onset_s - (b + JOIN_GUARD // 2) * DT) < JOIN_GUARD * DT and g.z > 3.0), g
    # without breaks the result is the same bits as before (no stitched parts: one piece)
    assert fit_fault("step", inside, DT, r, q, breaks=None).z == fit_fault("step", inside, DT, r, q).z
    assert math.isfinite(f.size_sigma)
