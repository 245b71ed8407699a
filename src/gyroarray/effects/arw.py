"""``arw``: angle random walk, white rate noise (part of the baseline of every model)."""

from __future__ import annotations

import math

from gyroarray.effects import _draw
from gyroarray.effects.protocol import NoiseTermEffect, Param, Stage, unit_draws, with_term
from gyroarray.effects.terms import WhiteTerm, spread
from gyroarray.core.units import arw_deg_rt_h_to_rad_rt_s


class AngleRandomWalk(NoiseTermEffect):
    """White rate noise of standard deviation σ = N/√dt per sample (ADEV slope −1/2).

    Its draws are correlated across gyros by ``correlation`` and scaled over
    time by ``burst`` (and ``fault_noise``) through the chain's white shaping.
    """

    name = "arw"
    order = 1
    stage = Stage.ADD
    baseline = True
    baseline_term = "white"
    candidate = False
    params = (Param("n_deg_rt_h", "deg/√h", "n_rad_rt_s", arw_deg_rt_h_to_rad_rt_s, lo=0.0,
                    doc="angle random walk N: white rate noise σ = N/√dt"),)
    doc = "angle random walk (white rate noise)"

    def typical(self, rng):
        return {"n_deg_rt_h": _draw.u(rng, 0.10, 0.25)}

    def placeholder(self):
        return {"n_deg_rt_h": 0.1}

    def predictor_term(self, act, n_gyros):
        """White rate noise of density N [rad/√s] (per sample N²/dt)."""
        return WhiteTerm(spread(act, "n_rad_rt_s", n_gyros))

    def simulate(self, state, act, streams):
        ctx = state.ctx
        e = unit_draws("arw", state.white.arw, act.cols, ctx.n, ctx.n_gyros, streams)
        term = e * (act.p["n_rad_rt_s"] / math.sqrt(ctx.dt_s))   # σ = N/√dt
        gain = state.white.arw_gain
        if gain is not None:
            term *= gain[:, act.cols] if gain.ndim == 2 else gain[:, None]
        return with_term(state, act.cols, term)
