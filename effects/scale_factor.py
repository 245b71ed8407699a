"""``scale_factor``: output = (1 + ppm·1e-6)·input (residual ∝ the sensed rate)."""

from __future__ import annotations

from gyroarray.analysis.regress import fit_scale_factor
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, with_term
from gyroarray.units import ppm_to_ratio


class ScaleFactor(RegressionEffect):
    """s·u added to the output, u the gyro's sensed input (after latency), s = ppm·1e-6."""

    name = "scale_factor"
    order = 9
    stage = Stage.SCALE
    needs = frozenset({"ref", "motion"})
    rivals = ("misalignment",)
    channel = "rate"
    params = (Param("ppm", "ppm", "ratio", ppm_to_ratio, lo=-1e6, lo_open=True,
                    doc="scale-factor error: output = (1 + ppm·1e-6)·input"),)
    doc = "scale-factor error"

    def simulate(self, state, act, streams):
        return with_term(state, act.cols, act.p["ratio"] * state.u[:, act.cols])          # s·u

    def regress(self, ctx, gyro, e, r, q):
        e, ref, inst = self.against_reference(ctx, gyro, e)
        return fit_scale_factor(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use, instrument=inst)

    def channel_line(self, fit, x, xm, ym):
        return fit.params["ppm"] * 1e-6 * x * 3600.0, self._label(fit, "ppm", unit=" ppm")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"ppm": _draw.u(rng, 1000.0, 8000.0, True) * rng.choice([-1, 1])}
