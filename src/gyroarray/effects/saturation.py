"""``saturation``: the output clipped at ±range."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.effects.fits.regress import fit_saturation
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, with_cols
from gyroarray.core.units import RAD_PER_DEG, deg_s_to_rad_s


class Saturation(RegressionEffect):
    """np.clip of the output at ±range: the last stage before faults.

    Fit: the plateau where the reference exceeds the range
    (:func:`gyroarray.effects.fits.regress.fit_saturation`). Its ranking score is
    the χ² the plateau explains, Σ (y − u)²/r where the reference is beyond
    it: a clipped output makes a scale factor look huge too. With a clip in
    the model the noise is read on the static part (no noise on a plateau).
    """

    name = "saturation"
    order = 14
    stage = Stage.SATURATE
    needs = frozenset({"ref", "motion"})
    model_needs = frozenset({"ref"})      # calibrated: the clip is read against the reference rate
    static_noise = "the model clips the output (no noise on the plateau)"
    channel = "rate"
    params = (Param("range_deg_s", "deg/s", "range_rad_s", deg_s_to_rad_s, lo=0.0, lo_open=True,
                    doc="output clipped at ±range"),)
    doc = "output clipped"

    def simulate(self, state, act, streams):
        r = act.p["range_rad_s"]
        return with_cols(state, act.cols, np.clip(state.x[:, act.cols], -r, r))

    def regress(self, ctx, gyro, e, r, q):
        u = ctx.ref @ ctx.H[gyro - 1]
        f = fit_saturation(u + e, u, r, gyro, use=ctx.use)
        if np.isfinite(f.z) and f.z >= 3.0:
            c = float(f.params["range_deg_s"]) * RAD_PER_DEG
            beyond = np.abs(u) > c + 3.0 * math.sqrt(r)
            z_eq = math.sqrt(float(np.sum(e[beyond] ** 2)) / r)
            f = replace(f, z=max(float(f.z), z_eq), extra={**f.extra, "z_plateau": float(f.z)})
        return f

    def predict(self, ctx, entry):
        """The clip acts on the input plus the gyro's bias b: on the plateau the residual is b, not 0."""
        truth = ctx.ref if ctx.ref is not None else np.zeros((ctx.n, 3))
        g = entry.gyro - 1
        a, b = ctx.longest
        u = truth @ ctx.H[g] + float(np.mean(ctx.E0[a:b, g]))
        c = float(entry.params["range_deg_s"]) * RAD_PER_DEG
        out = np.zeros((ctx.n, ctx.N))
        out[:, g] = np.clip(u, -c, c) - u
        return out

    def silent(self, ctx, entry):
        """The samples at the clip: the output sits on its full-scale code, no noise on it."""
        g = entry.gyro - 1
        c = float(entry.params["range_deg_s"]) * RAD_PER_DEG
        out = np.zeros((ctx.n, ctx.N), bool)
        out[:, g] = np.abs(ctx.y[:, g]) >= c * (1.0 - 1e-9)
        return out if out.any() else None

    def example(self, rng, n_gyros, max_rate_deg_s):
        g = _draw.gyro(rng, n_gyros)
        return g, {"range_deg_s": _draw.u(rng, 0.5, 0.85) * float(max_rate_deg_s[g - 1])}
