"""What ``diagnose`` keeps instead of recomputing gives the bits it would have recomputed.

The ranking of rivals (:func:`gyroarray.chain.compare._rank_rivals`) cuts the record by each
winner's fit and tests the rival again; the cut, the winner's prediction, the entry simulations,
the per-gyro noise (r, q), the bandwidth's motion likelihood and the reference's events are
now made once and kept (by identity of the fit, or by content of the arrays). Each is checked
here against the computation it replaces, bit for bit (``np.array_equal`` on the float64
arrays, ``==`` on the floats): the same answers, not approximations.

The record: :func:`gyroarray.sim.lab.lab_run` (240 s static, 300 s of steps and swings, 60 s
static, 50 Hz) of 4 gyros with a 6 Hz order-2 ``bandwidth`` on gyro 2, its baseline calibrated
once (a module fixture).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gyroarray.analysis.memo import ContentMemo, content_key
from gyroarray.analysis.motion_events import reference_events
from gyroarray.chain.compare import ModelComparison
from gyroarray.core.layout import Layout
from gyroarray.core.sensor import bandwidth_filter
from gyroarray.effects import get_effect
from gyroarray.effects.bandwidth import _lowpassed, _residual_minus_filter
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.protocol import KEPT_PREDICTIONS, KeptPrediction, drop_kept, kept_prediction
from gyroarray.sim.lab import lab_run

BASE = (ModelEntry("arw", None, {"n_deg_rt_h": 0.15}), ModelEntry("rrw", None, {"k_deg_h_rt_h": 5.0}))
LAYOUT = Layout.conical(1, 4, math.radians(54.7356))


@pytest.fixture(scope="module")
def analysed():
    model = NoiseModel(BASE + (ModelEntry("bandwidth", 2, {"cutoff_hz": 6.0, "order": 2}),))
    m = lab_run(model, LAYOUT, np.random.default_rng(11), static_s=240.0, motion_s=300.0, tail_s=60.0)
    comp = ModelComparison(m, n_runs=4)
    ctx = comp._context(comp.model)                     # calibrated, the stochastic record the whole one
    comp.calibrate(ctx)
    ctx.rec = slice(0, comp.n)
    ctx.Er = ctx.E.copy()
    return comp, ctx


def _same(a, b) -> bool:
    return (a is None and b is None) or (a is not None and b is not None and a.dtype == b.dtype
                                         and a.shape == b.shape and np.array_equal(a, b))


def test_kept_prediction_cuts_the_record_as_without_does(analysed):
    comp, ctx = analysed
    checked = 0
    for name, gyro in (("scale_factor", 1), ("latency", 2), ("fault_step", 3), ("earth_rate", None)):
        eff = get_effect(name)
        fit = eff.test(ctx, gyro)
        pred = ctx.fit_prediction(eff, fit)
        kept = kept_prediction(ctx, eff, fit)
        if pred is None:
            assert kept is None
            continue
        assert kept_prediction(ctx, eff, fit) is kept            # made once per context and fit
        assert (kept.full is None) == (gyro is not None)         # a per-gyro fit: its column only
        want, got = ctx.without(pred), kept.cut(ctx)
        assert _same(want.E, got.E) and _same(want.Er, got.Er)
        assert got.cache == {} and got.services.ctx is got
        checked += 1
    assert checked >= 1
    drop_kept(ctx)
    assert KEPT_PREDICTIONS not in ctx.cache


def test_kept_prediction_keeps_the_live_columns_only():
    x = np.zeros((50, 4))
    x[:, 2] = np.linspace(-1.0, 1.0, 50)
    x[7, 0] = -0.0                                      # a negative zero is not +0.0: kept
    k = KeptPrediction(x)
    assert k.cols.tolist() == [0, 2] and k.full is None
    assert _same(k.dense(x.shape), x) and np.signbit(k.dense(x.shape)[7, 0])


def test_entry_simulation_is_kept_and_returned_anew(analysed):
    comp, _ = analysed
    entry = ModelEntry("scale_factor", 3, {"ppm": 1234.5})
    first = comp.simulate_entry(entry)
    again = comp.simulate_entry(entry)
    fresh = comp._simulate_entry(entry)
    assert _same(first, fresh) and _same(again, fresh) and again is not first
    again[:] = 1.0                                      # a caller's array: the kept one is untouched
    assert _same(comp.simulate_entry(entry), fresh)
    assert np.count_nonzero(fresh[:, [0, 1, 3]]) == 0 and np.count_nonzero(fresh[:, 2]) > 0


def test_other_sites_share_the_records_inputs(analysed):
    comp, _ = analysed
    e1 = ModelEntry("earth_rate", None, {"latitude_deg": 34.25})
    e2 = ModelEntry("earth_rate", None, {"latitude_deg": 12.5})
    a1, a2 = comp.simulate_entry(e1), comp.simulate_entry(e2)
    assert not np.array_equal(a1, a2)
    sites = list(comp._sim_inputs.values())
    assert len(sites) >= 2 and all(s.omega_body_rad_s is sites[0].omega_body_rad_s for s in sites)
    # the shared inputs give what a context of its own gives
    from gyroarray.sim.effects import sim_context, simulate_on
    own = sim_context(comp.ref, comp.m.layout, comp.dt, time_s=comp.t_sim, temp_c=comp.temp,
                      site=(12.5 * math.pi / 180.0, comp.m.site.heading_rad), specific_force=comp.acc,
                      attitude=comp.attitude())
    sim = simulate_on(NoiseModel((e2,)), own, np.random.default_rng(0)) - comp.ref @ comp.H.T
    assert _same(comp._simulate_entry(e2), sim)


def test_noise_rq_is_kept_by_content(analysed):
    comp, ctx = analysed
    e = np.array(ctx.E[:, 1], copy=True)
    r, q = comp._noise_rq(e, 2)
    comp._rq_kept.clear()
    assert comp._noise_rq(e, 2) == (r, q)
    assert comp._noise_rq(e.copy(), 2) == (r, q) and len(comp._rq_kept) == 1


def test_lowpassed_is_bandwidth_filter_bit_for_bit():
    rng = np.random.default_rng(3)
    u = np.cumsum(rng.standard_normal(4000)) * 1e-3
    u[:500] = 0.0
    u[2000:2400] = 5e-322                               # denormal stretches, as a table's truth has
    for fc, order in ((0.4, 1), (3.3, 2), (24.0, 2)):
        assert _same(_lowpassed(u, 0.02, fc, order), bandwidth_filter(u, 0.02, fc, order))


def test_reference_events_are_kept_read_only(analysed):
    comp, _ = analysed
    ev = reference_events(comp.ref, comp.dt)
    assert not ev.flags.writeable
    assert reference_events(comp.ref.copy(), comp.dt) is ev
    assert _same(ev, reference_events.__wrapped__(comp.ref, comp.dt))


def test_content_memo_slots():
    memo = ContentMemo(maxsize=2)
    x = np.arange(5.0)
    s = memo.slot(x, 1.0)
    s["a"] = 1
    assert memo.slot(x.copy(), 1.0) is s and memo.slot(x, 2.0) is not s
    assert content_key(x, object()) is None and memo.slot(object()) == {}
    memo.slot(x, 3.0)                                   # the third key: the oldest goes
    assert "a" not in memo.slot(x, 1.0)


def test_zero_tail_shortcut_is_the_full_residual_bit_for_bit():
    rng = np.random.default_rng(5)
    n, t0 = 30000, 6000
    u = np.zeros(n)
    u[:t0] = np.sin(np.arange(t0) * 0.01) * 0.5
    e = rng.normal(0.0, 1e-3, n)
    e_zero = e.copy()
    e_zero[20000] = 0.0                                  # the tail's bound fails: filtered in full
    u_live = u.copy()
    u_live[t0:] = rng.normal(0.0, 1e-3, n - t0)          # no zero tail: 'u[t0:]' is not zero
    for fc, order in ((0.4, 1), (8.0, 2), (30.0, 2)):
        for ee in (e, e_zero):
            full = ee - (_lowpassed(u, 0.01, fc, order) - u)
            assert _same(_residual_minus_filter(ee, u, t0, 0.01, fc, order), full)
    nz = np.flatnonzero(u_live)
    assert int(nz[-1]) + 1 == n                          # the caller finds no tail to skip


def test_zero_lead_shortcut_is_the_full_residual_bit_for_bit():
    """The static start of a table record (u exactly +0.0 there) is not filtered: the filter
    rests at its zero state, e - (+0.0 - +0.0) is e - 0.0; the same bits as filtering it all,
    written into a reused buffer or a fresh array."""
    from gyroarray.effects.bandwidth import _LEAD_MIN, _MotionLR

    def bits(a, b):
        return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))

    rng = np.random.default_rng(9)
    n, lead, t0 = 40000, 12000, 20000
    u = np.zeros(n)
    u[lead:t0] = np.sin(np.arange(t0 - lead) * 0.01) * 0.5
    e = rng.normal(0.0, 1e-3, n)
    e[100] = -0.0                                        # a negative zero in the skipped part
    buf = np.full(n, np.nan)
    for fc, order in ((0.4, 1), (8.0, 2), (30.0, 2)):
        full = e - (_lowpassed(u, 0.01, fc, order) - u)
        for out in (None, buf):
            got = _residual_minus_filter(e, u, t0, 0.01, fc, order, lead, out)
            assert bits(got, full)
        assert bits(_residual_minus_filter(e, u, t0, 0.01, fc, order, _LEAD_MIN - 1), full)  # too short
    assert _MotionLR(e, u, 0.01, 1e-6, 1e-12, None)._lead == lead + 1     # sin(0): +0.0 too
    u_neg = u.copy()
    u_neg[5] = -0.0                                      # -0.0 in the lead: the lead ends there
    assert _MotionLR(e, u_neg, 0.01, 1e-6, 1e-12, None)._lead == 5


def test_explains_away_keeps_the_last_cut_record_only(monkeypatch):
    """The same winner against its rivals in a row: one cut record (read-only), shared by their
    tests; another winner in between: cut again (only the last cut is kept), dropped with the
    kept predictions."""
    from gyroarray.effects import protocol as P
    from gyroarray.effects.fitting import EffectFit
    n, N = 60, 3
    seen = []

    class Eff:
        name = "fake"

        def test(self, cut, gyro):
            seen.append(cut)
            return EffectFit("other", gyro, {}, z=10.0)

    class Services:
        def effect(self, name):
            return Eff()

        def derive(self, ctx):
            return self

    E = np.random.default_rng(3).normal(size=(n, N))
    ctx = P.FitContext(name="t", H=np.eye(N, 3), t=np.arange(n) * 0.1, dt=0.1, y=E.copy(), E0=E.copy(),
                       ref=None, temp=None, acc=None, positions=None, site=None, static=np.ones(n, bool),
                       longest=(0, n), moving=False, services=Services(), E=E, z_crit=3.0)
    preds = {2: np.zeros((n, N)), 3: np.zeros((n, N))}
    preds[2][:, 1], preds[3][:, 2] = 1.0, 2.0
    monkeypatch.setattr(P.FitContext, "fit_prediction", lambda self, effect, fit: preds[fit.gyro])
    a, b = EffectFit("fake", 2, {}, z=5.0), EffectFit("fake", 3, {}, z=5.0)
    other = EffectFit("other", 2, {}, z=4.0)
    for mine in (a, a, b, a):
        assert P.explains_away(Eff(), mine, other, ctx) is None          # still seen (z 10)
    assert seen[0] is seen[1] and seen[2] is not seen[0] and seen[3] is not seen[0]
    for cut, mine in zip(seen, (a, a, b, a)):
        assert not cut.E.flags.writeable
        assert np.array_equal(cut.E, E - preds[mine.gyro])
    drop_kept(ctx)
    assert KEPT_PREDICTIONS not in ctx.cache
