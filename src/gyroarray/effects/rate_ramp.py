"""``rate_ramp``: a rate that grows linearly in time (ADEV slope +1)."""

from __future__ import annotations

import numpy as np

from gyroarray.analysis.gls import gls_rw, NotIdentifiableError
from gyroarray.core.units import rad_s_to_deg_h, ramp_rad_s2_to_deg_h2
from gyroarray.effects.fitting import (as_vector, EffectFit, fit_extra, not_identifiable, num, pm, Z_EVIDENT,
                                       z_two_sided)
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
        return fit_rate_ramp(e, ctx.t, ctx.dt, r, q, gyro, use=ctx.use, breaks=ctx.breaks)

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


# -- fit ----------------------------------------------------------------------------------
def fit_rate_ramp(e, time_s, dt_s: float, r: float, q: float, gyro: int, *, use=None,
                  breaks=None) -> EffectFit:
    """Rate ramp: a bias that grows linearly with time.

    Parameters
    ----------
    e : array_like, shape (n,)
        Residual [rad/s].
    time_s : array_like, shape (n,)
        Sample times [s].
    dt_s : float
        Sample step [s].
    r, q : float
        ARW variance per sample N²/dt and RRW increment variance K²·dt [rad²/s²].
    gyro : int
        1-based gyro number.
    use : array_like of bool, shape (n,), optional
        Samples to include (:func:`~gyroarray.analysis.gls.gls_rw`).
    breaks : array_like of int, optional
        First sample of each stitched part after the first: each part's offset
        is a free parameter (:func:`~gyroarray.analysis.gls.gls_rw`).

    Returns
    -------
    EffectFit
        ``rate_ramp``: ``r_deg_h2`` with sigma.

    Notes
    -----
    ::

        e_t = R·t + b_t + w_t      (t = time_s, absolute; R·t_0 joins b_0)
        Δe_t = R·Δt + v_t + w_t − w_{t−1}

    i.e. R is the mean drift of the random walk; its σ is ≈ K/√T for RRW K
    over a record of T seconds.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    t = as_vector(time_s, n, "time_s")
    try:
        fit = gls_rw(e, t - t[0], r, q, use=use, breaks=breaks)
    except NotIdentifiableError as err:
        return not_identifiable("rate_ramp", gyro, {"r_deg_h2": 0.0}, "no time passes", err)
    b, s = float(fit.beta[0]), float(fit.sigma[0])
    rr, rs = ramp_rad_s2_to_deg_h2(b), ramp_rad_s2_to_deg_h2(s)
    tt = b / s
    z = z_two_sided(tt)
    span = float(t[-1] - t[0])
    if z >= Z_EVIDENT:
        ev = (f"gyro {gyro} bias drifts linearly: {pm(rr, rs)} deg/h², "
              f"{num(rad_s_to_deg_h(b * span), 3)} deg/h over the {num(span, 4)} s record, "
              "beyond what its rate random walk explains")
    else:
        ev = (f"gyro {gyro} bias shows no significant linear drift beyond its rate random walk "
              f"({pm(rr, rs)} deg/h², z = {z:.1f})")
    return EffectFit("rate_ramp", gyro, {"r_deg_h2": rr}, {"r_deg_h2": rs}, z, ev, fit_extra(fit, t=tt))
