"""``latency``: the output lags the input (residual ∝ angular acceleration)."""

from __future__ import annotations

import numpy as np

from gyroarray.effects.fits.regress import fit_latency
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.core.physics import fractional_delay
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, identity, with_cols


class Latency(RegressionEffect):
    """u_k(t) ← u_k(t − d): cubic Lagrange fractional delay of the sensed input
    (:func:`gyroarray.core.physics.fractional_delay`); before the record the first
    sample is held; a delay as long as the record is refused."""

    name = "latency"
    order = 13
    stage = Stage.DELAY
    needs = frozenset({"ref", "motion"})
    model_needs = frozenset({"ref"})      # calibrated: regressed on the reference rate
    channel = "accel"
    params = (Param("delay_s", "s", "delay_s", identity, lo=0.0, doc="delay of the sensed input"),)
    doc = "output lags the input"

    def simulate(self, state, act, streams):
        ctx = state.ctx
        d = act.p["delay_s"] / ctx.dt_s
        if np.any(d >= ctx.n - 1):
            raise InputError(f"{act.label}: delay_s = {float(np.max(act.p['delay_s'])):g} s is not "
                             f"shorter than the record ({(ctx.n - 1) * ctx.dt_s:g} s)", column="delay_s")
        return with_cols(state, act.cols, fractional_delay(state.x[:, act.cols], d))

    def check_record(self, params, dt_s, span_s):
        if params["delay_s"] >= span_s - dt_s:
            raise InputError(f"delay_s = {params['delay_s']:g} s is not shorter than the record "
                             f"({span_s:g} s long)", column="delay_s")

    def regress(self, ctx, gyro, e, r, q):
        e, ref, inst = self.against_reference(ctx, gyro, e)
        return fit_latency(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use, instrument=inst)

    def channel_line(self, fit, x, xm, ym):
        return -fit.params["delay_s"] * x * 3600.0, "delay " + self._label(fit, "delay_s", 1e3, " ms")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"delay_s": _draw.u(rng, 0.002, 0.01, True)}
