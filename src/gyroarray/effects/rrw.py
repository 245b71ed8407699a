"""``rrw``: rate random walk (part of the baseline of every model)."""

from __future__ import annotations

import math

import numpy as np

from gyroarray.effects import _draw
from gyroarray.effects.protocol import NoiseTermEffect, Param, Stage, unit_draws, with_term
from gyroarray.effects.terms import WalkTerm, spread
from gyroarray.core.units import rrw_deg_h_rt_h_to_rad_s_rt_s


class RateRandomWalk(NoiseTermEffect):
    """A random-walk bias b_k = Σ_{j<=k} K√dt e_j (ADEV slope +1/2)."""

    name = "rrw"
    order = 2
    stage = Stage.ADD
    baseline = True
    baseline_term = "walk"
    candidate = False
    params = (Param("k_deg_h_rt_h", "deg/h/√h", "k_rad_s_rt_s", rrw_deg_h_rt_h_to_rad_s_rt_s, lo=0.0,
                    doc="rate random walk K: increments σ = K√dt"),)
    doc = "rate random walk"

    def typical(self, rng):
        return {"k_deg_h_rt_h": _draw.u(rng, 0.0, 8.0)}

    def placeholder(self):
        return {"k_deg_h_rt_h": 10.0}

    def predictor_term(self, act, n_gyros):
        """A rate random walk of coefficient K [rad/s/√s] (increments K²·dt)."""
        return WalkTerm(spread(act, "k_rad_s_rt_s", n_gyros))

    def simulate(self, state, act, streams):
        ctx = state.ctx
        e = unit_draws("rrw", state.white.rrw, act.cols, ctx.n, ctx.n_gyros, streams)
        inc = e * (act.p["k_rad_s_rt_s"] * math.sqrt(ctx.dt_s))   # increments σ = K√dt
        return with_term(state, act.cols, np.cumsum(inc, axis=0))
