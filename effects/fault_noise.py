"""``fault_noise``: from ``start_s`` on, the gyro's white (ARW) part × ``ratio``."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.effects._fault import START, FaultEffect
from gyroarray.effects import _fault_physics as faults
from gyroarray.effects.protocol import Param, Stage, identity


class FaultNoise(FaultEffect):
    """The gyro's ARW draw (after the cross-gyro correlation, where ``burst``
    scales it too) × ``ratio`` from ``start_s`` on.

    Fit: the GLR of a change of the innovation variance over the onset
    (:func:`gyroarray.analysis.fault_fit.fit_fault`). In a model it is
    simulated in the Monte-Carlo band, and the stochastic record is brought
    back to the gyro's level before the onset (:meth:`whiten`).
    """

    name = "fault_noise"
    order = 24
    fault_kind = "noise"
    stage = Stage.SHAPE
    stochastic = True
    params = (START, Param("ratio", "-", "ratio", identity, lo=0.0,
                           doc="factor on the gyro's ARW (white) part"))
    doc = "fault: the white (ARW) part × ratio from start_s on"

    def placeholder(self):
        return {"start_s": 1.0, "ratio": 1.0}

    def simulate(self, state, act, streams):
        ctx = state.ctx
        old = state.white.arw_gain                           # a burst's (n,), if any
        gain = np.ones((ctx.n, ctx.n_gyros))
        if old is not None:
            gain *= old[:, None] if old.ndim == 1 else old
        gain[:, act.cols] *= faults.noise_gain(ctx.time_s, act.p["start_s"], act.p["ratio"])
        return replace(state, white=replace(state.white, arw_gain=gain))

    def whiten(self, ctx, entry, x, t):
        after = t >= float(entry.params["start_s"])
        if not after.any():
            return x
        g = int(entry.gyro) - 1
        x = x.copy()
        level = x[after, g].mean()
        x[after, g] = level + (x[after, g] - level) / max(float(entry.params["ratio"]), 1e-6)
        return x
