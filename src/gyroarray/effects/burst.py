"""``burst``: the white noise level rises over a time window."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.effects.fits.stochastic_fit import fit_burst
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Effect, Kind, Param, Stage, identity


class Burst(Effect):
    """ARW variance × ``variance_ratio`` for start_s <= time_s < end_s (ARW only,
    common-mode part included).

    Fit: a change of the white level in sample-to-sample differences, its
    window by profile likelihood and the z calibrated for the scan
    (:func:`gyroarray.effects.fits.stochastic_fit.fit_burst`); it reads the whole
    record (a slow deterministic residual barely touches differences, and a
    burst may run on into the dynamic part) unless the model's noise differs
    between still and moving parts (``static_noise``). With a burst in the
    model the regressions leave its window out, and the stochastic record is
    brought back to the level outside it.
    """

    name = "burst"
    order = 17
    per_gyro = False
    stage = Stage.SHAPE
    kind = Kind.TIME
    stochastic = True
    reads = "noise"
    changes_adev = True
    channel = "window"
    params = (Param("start_s", "s", "start_s", identity, doc="window start (time_s)"),
              Param("end_s", "s", "end_s", identity, doc="window end, exclusive"),
              Param("variance_ratio", "-", "variance_ratio", identity, lo=0.0,
                    doc="ARW variance multiplier inside the window"))
    doc = "ARW variance × ratio over [start_s, end_s)"

    def check(self, params, gyro, n_gyros):
        if not params["end_s"] > params["start_s"]:
            raise InputError(f"end_s = {params['end_s']:g} must be after start_s = {params['start_s']:g}",
                             column="end_s")

    def placeholder(self):
        return {"start_s": 0.0, "end_s": 1.0, "variance_ratio": 1.0}

    def clip(self, params, n_gyros=None):
        out = super().clip(params, n_gyros)
        if "variance_ratio" in out:
            out["variance_ratio"] = max(out["variance_ratio"], 1e-6)
        return out

    def simulate(self, state, act, streams):
        t = state.ctx.time_s
        inside = (t >= act.p["start_s"]) & (t < act.p["end_s"])
        gain = np.where(inside, math.sqrt(act.p["variance_ratio"]), 1.0)
        old = state.white.arw_gain
        gain = gain if old is None else (old * gain if old.ndim == 1 else old * gain[:, None])
        return replace(state, white=replace(state.white, arw_gain=gain))

    def fit(self, ctx, gyro, E):
        if ctx.static_record:
            x, t = E[ctx.rec], ctx.t[ctx.rec]
        else:                             # not what the model leaves out to the end (a frozen gyro)
            x, t = E[:ctx.noise_end], ctx.t[:ctx.noise_end]
        # at the model's level (a noise fault in the model is no burst), but not its own
        return fit_burst(ctx.at_model_level(x, t, but=(self.name, None)), t, ctx.dt)

    def _window(self, t, entry) -> np.ndarray:
        return (t >= float(entry.params["start_s"])) & (t < float(entry.params["end_s"]))

    def exclude(self, ctx, entry):
        inside = self._window(ctx.t, entry)
        return inside if inside.any() and not inside.all() else None

    def whiten(self, ctx, entry, x, t):
        inside = self._window(t, entry)
        if not inside.any():
            return x
        x = x.copy()
        level = x[inside].mean(axis=0)
        x[inside] = level + (x[inside] - level) / math.sqrt(max(float(entry.params["variance_ratio"]), 1e-12))
        return x

    def example(self, rng, n_gyros, max_rate_deg_s):
        _draw.gyro(rng, n_gyros)
        start = _draw.u(rng, 100.0, 1700.0)
        return None, {"start_s": start, "end_s": start + _draw.u(rng, 150.0, 400.0),
                      "variance_ratio": _draw.u(rng, 2.0, 6.0)}
