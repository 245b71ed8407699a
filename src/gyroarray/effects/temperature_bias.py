"""``temperature_bias``: a bias that follows ``temp_c``."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.effects.fits.effect_fit import EffectFit
from gyroarray.effects.fits.regress import (NotIdentifiableError, fit_temperature_bias, gls_rw, temperature_columns,
                                       temperature_rates)
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, identity, same_noise_preference, with_term
from gyroarray.core.units import deg_h_to_rad_s, rad_s_to_deg_h

#: Each half of a record must span this much temperature [°C], and this share of the whole
#: record's span, for the cross-half test (a warm-up that is over by mid-record is not two periods).
MIN_SPAN_C = 0.5
MIN_SPAN_SHARE = 0.3


class TemperatureBias(RegressionEffect):
    """coeff·(temp_c − t0_c).

    Fit: the regression of the residual on the temperature under ARW + a
    random-walk bias (:func:`gyroarray.effects.fits.regress.fit_temperature_bias`),
    with a thermal-lag column (dT/dt of the smoothed reading) when the data ask
    for it; the levels' coefficient (an ordinary regression with an intercept,
    no random walk) is reported beside it. The CATS tag's gyro 2: 92 ± 8 with a
    lag of about 246 s; without the lag column 60 ± 3, the levels 96.
    ``t0_c`` and a constant bias are one parameter: the fit returns the
    coefficient relative to the first temperature.

    Test: a cross-half prediction when each half of the record spans at least
    0.5 °C and 30 % of the whole record's span: the coefficient fitted on one half, its sign and size carried to
    the other, where the score of the regression in that direction is ≈ N(0, 1)
    without a temperature effect (the two directions averaged); a coefficient
    that does not transfer between the halves is not significant. Otherwise
    the whole record's Wald z, and the evidence says why.
    """

    name = "temperature_bias"
    order = 12
    stage = Stage.ADD
    needs = frozenset({"temp"})
    model_needs = predict_needs = frozenset({"temp"})     # bias = k·(temp_c − t0): nothing without it
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

    def _rates(self, ctx) -> dict:
        """The record's thermal-lag columns (one temperature for every gyro and every refit)."""
        key = ("temperature_rates",)
        if key not in ctx.cache:
            ctx.cache[key] = temperature_rates(ctx.temp, ctx.dt)
        return ctx.cache[key]

    def regress(self, ctx, gyro, e, r, q):
        f = fit_temperature_bias(e, ctx.temp, ctx.t, ctx.dt, r, q, gyro, use=ctx.use, rates=self._rates(ctx))
        if not f.extra.get("identifiable", True):
            return f
        # the levels' coefficient beside it: an ordinary regression with an intercept, the
        # random walk taken as nothing (what a plain regression of bias on temperature gives)
        X = np.column_stack([np.ones(e.size), ctx.temp - ctx.temp.mean()])
        keep = slice(None) if ctx.use is None else ctx.use
        levels = float(rad_s_to_deg_h(np.linalg.lstsq(X[keep], e[keep], rcond=None)[0][1]))
        return replace(f, extra={**f.extra, "levels_deg_h_per_c": levels})

    def test(self, ctx, gyro):
        f = ctx.fitted(self, gyro, ctx.E)
        cross = self._cross_half(ctx, int(gyro), f)
        return f if cross is None else cross

    def _cross_half(self, ctx, gyro: int, whole: EffectFit) -> EffectFit | None:
        """The whole record's fit with a z from the cross-half prediction, or None (halves too flat)."""
        g = gyro - 1
        n = ctx.n
        halves = (slice(0, n // 2), slice(n // 2, n))
        temp = ctx.temp
        need = max(MIN_SPAN_C, MIN_SPAN_SHARE * float(np.ptp(temp)))
        if min(float(np.ptp(temp[h])) for h in halves) < need:
            return replace(whole, evidence=whole.evidence + f" (one half of the record spans less than "
                                                               f"{need:.2g} °C: no cross-half check)")
        r, q = float(ctx.r[g]), float(ctx.q[g])
        sm = whole.extra.get("lag_smoothing_s")         # the whole fit's thermal-lag column, if any
        X = temperature_columns(temp, None if sm is None else self._rates(ctx)[sm])
        betas, scores = [], []
        for fit_on, other in (halves, halves[::-1]):
            use_fit = None if ctx.use is None else ctx.use[fit_on]
            try:
                fa = gls_rw(ctx.E[fit_on, g], X[fit_on], r, q, use=use_fit)
            except (NotIdentifiableError, ValueError):
                return None
            beta = float(fa.beta[0])
            betas.append(beta)
            use_other = None if ctx.use is None else ctx.use[other]
            try:                               # the score on the other half, in the direction found
                fb = gls_rw(ctx.E[other, g], X[other], r, q, use=use_other)
            except (NotIdentifiableError, ValueError):
                return None
            scores.append(math.copysign(1.0, beta) * float(fb.beta[0] / fb.sigma[0]))
        z = float(sum(scores) / math.sqrt(2.0))
        k = [float(rad_s_to_deg_h(b)) for b in betas]
        lv = whole.extra.get("levels_deg_h_per_c")
        ev = (f"{whole.evidence}; halves {k[0]:.3g} and {k[1]:.3g} deg/h/°C, each confirmed on the other "
              f"half with z = {scores[0]:.1f} and {scores[1]:.1f}"
              + (f"; the levels alone (no random walk) give {lv:.3g}" if lv is not None else ""))
        return replace(whole, z=z, evidence=ev,
                       extra={**whole.extra, "z_whole": float(whole.z), "half_coefficients": k,
                              "cross_scores": scores})

    def prefer(self, mine, other, ctx):
        return same_noise_preference(self, mine, other, ctx)

    def channel_line(self, fit, x, xm, ym):
        return ym + fit.params["deg_h_per_c"] * (x - xm), self._label(fit, "deg_h_per_c", unit=" deg/h/°C")

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"deg_h_per_c": _draw.u(rng, 10.0, 60.0, True) * rng.choice([-1, 1]),
                                          "t0_c": 25.0}
