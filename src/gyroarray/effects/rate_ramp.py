"""``rate_ramp``: a rate that grows linearly in time (ADEV slope +1)."""

from __future__ import annotations

from gyroarray.effects.fits.regress import fit_rate_ramp
from gyroarray.effects import _draw
from gyroarray.effects.protocol import Kind, Param, RegressionEffect, Stage, same_noise_preference, with_term
from gyroarray.core.units import ramp_deg_h2_to_rad_s2


class RateRamp(RegressionEffect):
    """R·t with t = ``time_s`` (absolute: a record starting at 1000 s starts at R·1000 s).

    Candidate test: the time-domain likelihood ratio of the gyro's noise fit
    (K profiled); in a model: a regression on the residual (slow: tested
    again with the random walk re-estimated without it).
    """

    name = "rate_ramp"
    order = 5
    stage = Stage.ADD
    kind = Kind.DETERMINISTIC
    slow = True
    reads = "noise"
    rivals = ("temperature_bias",)
    channel = "time"
    params = (Param("r_deg_h2", "deg/h²", "r_rad_s2", ramp_deg_h2_to_rad_s2, doc="rate ramp R: R·t"),)
    doc = "rate ramp R·t"

    def simulate(self, state, act, streams):
        return with_term(state, act.cols, state.ctx.time_s[:, None] * act.p["r_rad_s2"])

    def regress(self, ctx, gyro, e, r, q):
        return fit_rate_ramp(e, ctx.t, ctx.dt, r, q, gyro, use=ctx.use)

    def test(self, ctx, gyro):
        return ctx.gyro_noise(int(gyro))[self.name]

    def noise_term(self, ctx, entry):
        """The ramp's regression took part of the random walk out with it (its slope): the Allan
        fit's K column says so when it reads the whole record the ramp was fitted on."""
        start, stop, _ = ctx.rec.indices(ctx.n)
        return {"ramp_taken_out": True} if (start, stop) == (0, ctx.n) else {}

    def prefer(self, mine, other, ctx):
        return same_noise_preference(self, mine, other, ctx)

    def channel_line(self, fit, x, xm, ym):
        return ym + fit.params["r_deg_h2"] * (x - xm) / 3600.0, self._label(fit, "r_deg_h2", unit=" deg/h²")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"r_deg_h2": _draw.u(rng, 100.0, 600.0, True) * rng.choice([-1, 1])}
