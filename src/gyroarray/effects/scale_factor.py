"""``scale_factor``: output = (1 + ppm·1e-6)·input (residual ∝ the sensed rate)."""

from __future__ import annotations

from gyroarray.effects.fits.regress import fit_scale_and_nonlinearity, fit_scale_factor
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, with_term
from gyroarray.core.units import ppm_to_ratio


class ScaleFactor(RegressionEffect):
    """s·u added to the output, u the gyro's sensed input (after latency), s = ppm·1e-6."""

    name = "scale_factor"
    order = 9
    stage = Stage.SCALE
    needs = frozenset({"ref", "motion"})
    model_needs = frozenset({"ref"})      # calibrated: regressed on the reference rate
    rivals = ("misalignment",)
    channel = "rate"
    params = (Param("ppm", "ppm", "ratio", ppm_to_ratio, lo=-1e6, lo_open=True,
                    doc="scale-factor error: output = (1 + ppm·1e-6)·input"),)
    doc = "scale-factor error"

    def simulate(self, state, act, streams):
        return with_term(state, act.cols, act.p["ratio"] * state.u[:, act.cols])          # s·u

    def regress(self, ctx, gyro, e, r, q):
        """The slope on the gyro's residual; with a curvature of this gyro in the model, the slope
        fitted jointly with a correction of it.

        The curvature's own fit is joint with a slope (:func:`fit_scale_and_nonlinearity`) that
        the model does not keep, so its residual holds exactly that slope, whose spread is the
        joint fit's: tested alone, with the smaller σ of a slope by itself, its z is wider than
        N(0, 1) wherever u and u² are collinear (rates mostly of one sign; seed 109: z 4.17 for
        no scale factor at all). Tested jointly, z is the joint slope over its own σ.
        """
        e, ref, inst = self.against_reference(ctx, gyro, e)
        if any(x.gyro == gyro for x in ctx.entries("scale_nonlinearity")):
            return fit_scale_and_nonlinearity(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use,
                                              instrument=inst)[0]
        return fit_scale_factor(e, ref, ctx.H[gyro - 1], ctx.t, ctx.dt, r, q, gyro, use=ctx.use, instrument=inst)

    def channel_line(self, fit, x, xm, ym):
        return fit.params["ppm"] * 1e-6 * x * 3600.0, self._label(fit, "ppm", unit=" ppm")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"ppm": _draw.u(rng, 1000.0, 8000.0, True) * rng.choice([-1, 1])}
