"""``temperature_bias``: a bias that follows ``temp_c``."""

from __future__ import annotations

from gyroarray.analysis.regress import fit_temperature_bias
from gyroarray.effects import _draw
from gyroarray.errors import InputError
from gyroarray.sim.protocol import Param, RegressionEffect, Stage, identity, same_noise_preference, with_term
from gyroarray.units import deg_h_to_rad_s


class TemperatureBias(RegressionEffect):
    """coeff·(temp_c − t0_c).

    Fit: the regression of the residual on the temperature under ARW + a
    random-walk bias (slow: tested again with the random walk re-estimated
    without it). ``t0_c`` and a constant bias are one parameter: the fit
    returns the coefficient at the record's mean temperature.
    """

    name = "temperature_bias"
    order = 12
    stage = Stage.ADD
    needs = frozenset({"temp"})
    slow = True
    rivals = ("rate_ramp",)
    channel = "temp"
    scored = ("deg_h_per_c",)
    params = (Param("deg_h_per_c", "deg/h/°C", "rad_s_per_c", deg_h_to_rad_s, doc="bias per °C"),
              Param("t0_c", "°C", "t0_c", identity, lo=-273.15, doc="temperature of zero bias"))
    doc = "bias proportional to temp_c − t0_c"

    def placeholder(self):
        return {"deg_h_per_c": 0.0, "t0_c": 25.0}

    def simulate(self, state, act, streams):
        temp = state.ctx.temp_c
        if temp is None:
            raise InputError(f"{act.label}: temperature_bias needs the temperature history: "
                             "pass temp_c (one value per sample, °C)")
        return with_term(state, act.cols, (temp[:, None] - act.p["t0_c"]) * act.p["rad_s_per_c"])

    def regress(self, ctx, gyro, e, r, q):
        return fit_temperature_bias(e, ctx.temp, ctx.t, ctx.dt, r, q, gyro, use=ctx.use)

    def prefer(self, mine, other, ctx):
        return same_noise_preference(self, mine, other, ctx)

    def channel_line(self, fit, x, xm, ym):
        return ym + fit.params["deg_h_per_c"] * (x - xm), self._label(fit, "deg_h_per_c", unit=" deg/h/°C")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"deg_h_per_c": _draw.u(rng, 10.0, 60.0, True) * rng.choice([-1, 1]),
                                          "t0_c": 25.0}
