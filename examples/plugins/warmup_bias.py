"""A bias that settles after power-on: the gyro's warm-up, with its own term in the design predictor.

An effect of your own is this one file. Give it to any command that reads
models or records with ``--plugin warmup_bias.py``::

    gyroarray simulate my_scenario.toml --out runs/ --plugin warmup_bias.py
    gyroarray diagnose runs/my_run.csv.gz --plugin warmup_bias.py
    gyroarray fit runs/my_run.csv.gz --add warmup_bias:2 --plugin warmup_bias.py

A MEMS gyro that is switched on heats itself: its bias moves while the die
settles to its running temperature, roughly as a first-order lag. The output
carries b(t) = ``amp_deg_h``·exp(−t/``tau_s``), t the time since the first
sample (power-on), so the bias ends ``amp_deg_h`` below where it started.
None of the spec's effects is this shape: a rate ramp is straight, a
temperature bias needs the temperature, a Gauss–Markov process is random.

Fit side: the residual is regressed on exp(−t/τ) under the record's ARW +
random-walk noise (:func:`gyroarray.analysis.gls.gls_rw`, starting bias
free) for τ on a log grid from 20 samples to half the record; the best τ is
refined by the smallest χ², its 1σ read from the χ² curvature. z is the
regression's two-sided t at the best grid τ, Šidák-corrected for the grid's
independent tests (about 4 of the 16 time constants: neighbours are nearly
collinear; measured so that z ≈ N(0, 1) on records without the effect).

Predictor side (:meth:`WarmupBias.predictor_term`): a deterministic rate
error amp_i·exp(−t/τ_i) on each gyro over the stated motion's clock, so
``gyroarray.design.budget.error_budget`` shows the warm-up as its own term.

Run ``gyroarray.chain.testing.check_effect(WarmupBias)`` in your tests.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import optimize, special

from gyroarray.analysis.gls import NotIdentifiableError, gls_rw
from gyroarray.core.units import deg_h_to_rad_s, rad_s_to_deg_h
from gyroarray.effects.fitting import EffectFit
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, identity, with_term
from gyroarray.effects.terms import FunctionTerm, spread


def warmup(t: np.ndarray, tau_s) -> np.ndarray:
    """exp(−(t − t_0)/τ): 1 at power-on (the first sample), settling to 0 [-]."""
    t = np.asarray(t, dtype=float)
    return np.exp(-(t - t[0]) / tau_s)


class WarmupBias(RegressionEffect):
    """amp·exp(−t/τ): a bias settling after power-on (t from the first sample)."""

    name = "warmup_bias"
    stage = Stage.ADD
    channel = "time"
    slow = True
    rivals = ("rate_ramp", "gauss_markov")
    params = (Param("amp_deg_h", "deg/h", "amp_rad_s", deg_h_to_rad_s,
                    doc="bias at power-on above the settled bias"),
              Param("tau_s", "s", "tau_s", identity, lo=0.0, lo_open=True,
                    doc="settling time constant"))
    scored = ("amp_deg_h", "tau_s")
    doc = "bias settling exponentially after power-on (warm-up)"

    #: Time constants tried per record, log-spaced from 20 samples to half the record.
    N_TAU = 16
    #: Independent tests among them for the Šidák correction: neighbouring templates are
    #: nearly collinear (measured on white + random-walk records: with 4, z ≈ N(0, 1)).
    M_EFF = 4

    def placeholder(self):
        return {"amp_deg_h": 0.0, "tau_s": 60.0}

    def simulate(self, state, act, streams):
        t = state.ctx.time_s
        return with_term(state, act.cols, act.p["amp_rad_s"] * warmup(t[:, None], act.p["tau_s"]))

    def predictor_term(self, act, n_gyros):
        """A deterministic rate error amp_i·exp(−t/τ_i) on the stated motion's clock (t = 0 at power-on)."""
        amp = np.nan_to_num(spread(act, "amp_rad_s", n_gyros))
        tau = np.nan_to_num(spread(act, "tau_s", n_gyros), nan=1.0)
        return FunctionTerm(lambda motion: amp * warmup(motion.time_s[:, None], tau))

    def example(self, rng, n_gyros, max_rate_deg_s):
        return int(rng.integers(1, n_gyros + 1)), {
            "amp_deg_h": float(rng.uniform(40.0, 120.0) * rng.choice([-1.0, 1.0])),
            "tau_s": float(rng.uniform(60.0, 300.0))}

    def _fit_at(self, ctx, e, r, q, tau):
        return gls_rw(e, warmup(ctx.t, tau), r, q, use=ctx.use)

    def regress(self, ctx, gyro, e, r, q):
        span = float(ctx.t[-1] - ctx.t[0])
        lo, hi = 20.0 * ctx.dt, 0.5 * span
        if not hi > lo:
            return EffectFit(self.name, gyro, {"amp_deg_h": 0.0, "tau_s": float("nan")}, z=0.0,
                             evidence=f"gyro {gyro}: the record is too short for a warm-up fit",
                             extra={"identifiable": False, "reason": "the record is too short"})
        best = None
        for tau in np.geomspace(lo, hi, self.N_TAU):
            try:
                f = self._fit_at(ctx, e, r, q, tau)
            except NotIdentifiableError:
                continue
            t_stat = float(f.beta[0] / math.sqrt(f.cov[0, 0]))
            if best is None or abs(t_stat) > abs(best[0]):
                best = (t_stat, float(tau))
        if best is None:
            return EffectFit(self.name, gyro, {"amp_deg_h": 0.0, "tau_s": float("nan")}, z=0.0,
                             evidence=f"gyro {gyro}: no warm-up can be fitted on this record",
                             extra={"identifiable": False, "reason": "not identifiable"})
        t_stat, tau0 = best
        log_p1 = math.log(max(float(special.erfc(abs(t_stat) / math.sqrt(2))), 1e-300))
        m = self.M_EFF
        log_p = (math.log(-math.expm1(m * math.log1p(-math.exp(log_p1)))) if log_p1 > -30
                 else log_p1 + math.log(m))
        z = float(-special.ndtri(math.exp(log_p))) if log_p > -700 else abs(t_stat)

        def chi2(log_tau):
            try:
                return float(self._fit_at(ctx, e, r, q, math.exp(log_tau)).chi2)
            except NotIdentifiableError:
                return math.inf
        step = math.log(hi / lo) / (self.N_TAU - 1)
        a, b = math.log(tau0) - step, math.log(tau0) + step
        res = optimize.minimize_scalar(chi2, bounds=(max(a, math.log(lo)), min(b, math.log(hi))),
                                       method="bounded", options={"xatol": 1e-4})
        tau = float(math.exp(res.x))
        f = self._fit_at(ctx, e, r, q, tau)
        h = 0.05
        curv = (chi2(res.x + h) - 2.0 * f.chi2 + chi2(res.x - h)) / h ** 2
        s_tau = tau * math.sqrt(2.0 / curv) if curv > 0 else float("nan")
        amp, s_amp = float(rad_s_to_deg_h(f.beta[0])), float(rad_s_to_deg_h(math.sqrt(f.cov[0, 0])))
        sigma = {"amp_deg_h": s_amp}
        if math.isfinite(s_tau):
            sigma["tau_s"] = s_tau
        word = "settles by" if z > 3 else "shows no significant warm-up:"
        return EffectFit(self.name, gyro, {"amp_deg_h": amp, "tau_s": tau}, sigma, z=z,
                         evidence=(f"gyro {gyro} bias {word} {amp:.3g} ± {s_amp:.2g} deg/h with τ = "
                                   f"{tau:.3g} s (z over {self.N_TAU} time constants searched)"),
                         extra={"chi2": f.chi2, "t": t_stat})
