"""``constant_bias``: a constant offset (the baseline's unknown starting bias, fitted on request)."""

from __future__ import annotations

import math

import numpy as np

from gyroarray.effects.fitting import EffectFit
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, with_term
from gyroarray.core.units import deg_h_to_rad_s, rad_s_to_deg_h


class ConstantBias(RegressionEffect):
    """A constant bias. Every model already fits each gyro's starting bias, so it
    is never a candidate; ``fit --add constant_bias:K`` reports its value: the
    mean of the longest static part, with the σ of ARW + RRW over that part."""

    name = "constant_bias"
    order = 8
    stage = Stage.ADD
    candidate = False
    params = (Param("bias_deg_h", "deg/h", "bias_rad_s", deg_h_to_rad_s, doc="constant bias"),)
    doc = "constant bias"

    def simulate(self, state, act, streams):
        return with_term(state, act.cols, np.broadcast_to(act.p["bias_rad_s"], (state.ctx.n, len(act.cols))))

    def typical(self, rng):
        return {"bias_deg_h": float(rng.normal(0.0, 250.0))}   # a MEMS turn-on bias

    def why_not(self, ctx):
        return "is the baseline's unknown starting bias (always fitted)"

    def regress(self, ctx, gyro, e, r, q):
        a, b = ctx.longest
        x = e[a:b]
        span = (b - a) * ctx.dt
        var = r / (b - a) + q / ctx.dt * span / 3.0
        v = float(np.mean(x))
        s = math.sqrt(var)
        return EffectFit(self.name, gyro, {"bias_deg_h": float(rad_s_to_deg_h(v))},
                         {"bias_deg_h": float(rad_s_to_deg_h(s))}, z=0.0,
                         evidence=(f"gyro {gyro} starting bias {rad_s_to_deg_h(v):.4g} ± "
                                   f"{rad_s_to_deg_h(s):.2g} deg/h (part of the baseline's "
                                   f"unknown starting bias, never a candidate)"))
