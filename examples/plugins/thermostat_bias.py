"""A bias that switches between two levels with a period: a thermostat cycling.

An effect of your own is this one file. Give it to any command that reads
models or records with ``--plugin thermostat_bias.py``::

    gyroarray simulate my_scenario.toml --out runs/ --plugin thermostat_bias.py
    gyroarray diagnose runs/my_run.csv.gz --plugin thermostat_bias.py
    gyroarray fit runs/my_run.csv.gz --add thermostat_bias:3 --plugin thermostat_bias.py

A heater that a thermostat switches on and off shifts a MEMS gyro's bias by
a step every half period: the output carries a square wave of amplitude
``amp_deg_h`` (the bias is +amp while the heater is on, −amp while it is off)
and period ``period_s``, switching on at ``phase_s`` (seconds after t = 0).
None of the spec's effects is a square wave: a sinusoid fits its
fundamental (81 % of the amplitude, 4/π·amp), and a Gauss–Markov or a
random walk takes its slow part.

Fit side: the fundamental of a square wave is a sinusoid at 1/period, so
the period comes from the largest line of the residual's spectrum between
three cycles per record and a tenth of the sample rate (an FFT of the
record, the peak refined by a parabola through its neighbours); the
switch-on time from a regression of the residual on the square wave at 8
switch-on times across half a period, under the record's ARW +
random-walk noise (:func:`gyroarray.analysis.gls.gls_rw`, starting bias
free). Its z is that regression's two-sided t, Šidák-corrected for the
frequencies searched. The switch times are then located one by one (the
step of largest mean difference within a quarter period of each predicted
one), the period and phase come from a straight line through them (with
their 1σ), and the amplitude from the regression on the refined wave. The
effect is ``slow``: once found, the chain estimates the random walk again
without it (a few large steps read as random walk) and fits once more.

Run ``gyroarray.chain.testing.check_effect(ThermostatBias)`` in your tests.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

from gyroarray.effects.fitting import EffectFit, chi2_to_z
from gyroarray.analysis.gls import NotIdentifiableError, gls_rw
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, explains_away, identity, with_term
from gyroarray.core.errors import InputError
from gyroarray.core.units import deg_h_to_rad_s, rad_s_to_deg_h


def square_wave(t: np.ndarray, period_s: float, phase_s: float) -> np.ndarray:
    """+1 for the first half of each period after ``phase_s``, −1 for the second half."""
    frac = np.mod((np.asarray(t, float) - phase_s) / period_s, 1.0)
    return np.where(frac < 0.5, 1.0, -1.0)


class ThermostatBias(RegressionEffect):
    """±amp: a bias switching between two levels every half period."""

    name = "thermostat_bias"
    stage = Stage.ADD
    channel = "time"
    params = (Param("amp_deg_h", "deg/h", "amp_rad_s", deg_h_to_rad_s, lo=0.0,
                    doc="half the jump between the two bias levels"),
              Param("period_s", "s", "period_s", identity, lo=0.0, lo_open=True,
                    doc="time between two switch-ons"),
              Param("phase_s", "s", "phase_s", identity, required=False, default=0.0,
                    doc="a switch-on time (s after t = 0)"))
    scored = ("amp_deg_h", "period_s")
    slow = True
    # a square wave also makes an ADEV hump, a flat stretch and a line at its fundamental
    rivals = ("gauss_markov", "bias_instability", "sinusoid")
    doc = "bias switching between two levels with a period (a thermostat cycling)"

    #: Switch-on times tried per period, over half a period.
    N_PHASES = 8

    def check(self, params, gyro, n_gyros):
        if params.get("phase_s", 0.0) < 0.0:
            raise InputError("phase_s must be >= 0 (a switch-on time after t = 0)", column="phase_s")

    def placeholder(self):
        return {"amp_deg_h": 0.0, "period_s": 1.0}

    def simulate(self, state, act, streams):
        t = state.ctx.time_s
        waves = np.stack([square_wave(t, p, ph) for p, ph in zip(act.p["period_s"], act.p["phase_s"])],
                         axis=1)
        return with_term(state, act.cols, waves * act.p["amp_rad_s"])

    def _fundamental(self, ctx, e: np.ndarray) -> tuple[float, int]:
        """(frequency [Hz] of the largest spectral line in the allowed band, frequencies searched)."""
        x = e - e.mean()
        spec = np.abs(np.fft.rfft(x, n=4 * x.size)) ** 2       # 4× zero-padded
        f = np.fft.rfftfreq(4 * x.size, ctx.dt)
        span = x.size * ctx.dt
        band = (f >= 3.0 / span) & (f <= 0.1 / ctx.dt)
        if band.sum() < 3:
            return float("nan"), 0
        i = int(np.flatnonzero(band)[np.argmax(spec[band])])
        if 0 < i < f.size - 1:                                  # parabola through the peak
            a, b, c = np.log(spec[i - 1:i + 2] + 1e-300)
            shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) < 0 else 0.0
            fi = f[i] + shift * (f[1] - f[0])
        else:
            fi = f[i]
        return float(fi), int(band.sum() // 4)                 # independent frequencies

    def regress(self, ctx, gyro, e, r, q):
        freq, m = self._fundamental(ctx, e)
        best = None
        if np.isfinite(freq) and freq > 0:
            period = 1.0 / freq
            for k in range(self.N_PHASES):
                phase = (ctx.t[0] + period * k / (2 * self.N_PHASES)) % period
                try:
                    f = gls_rw(e, square_wave(ctx.t, period, phase), r, q, use=ctx.use)
                except NotIdentifiableError:
                    continue
                t_stat = float(f.beta[0] / f.sigma[0])
                if best is None or abs(t_stat) > abs(best[0]):
                    best = (t_stat, f, period, phase)
        if best is None:
            return EffectFit(self.name, gyro, {"amp_deg_h": 0.0, "period_s": float("nan")}, z=0.0,
                             evidence=f"gyro {gyro}: no square wave can be fitted on this record",
                             extra={"identifiable": False, "reason": "the record is too short"})
        t_stat, _, period, phase = best
        m = max(m, 1) * self.N_PHASES // 2
        log_p1 = math.log(max(float(special.erfc(abs(t_stat) / math.sqrt(2))), 1e-300))
        log_p = (math.log(-math.expm1(m * math.log1p(-math.exp(log_p1)))) if log_p1 > -30
                 else log_p1 + math.log(m))
        z = float(-special.ndtri(math.exp(log_p))) if log_p > -700 else chi2_to_z(t_stat * t_stat, 1)
        sign = 1.0 if t_stat > 0 else -1.0
        period, phase, s_period, s_phase = self._refine(ctx, e, period, phase, sign)
        f = gls_rw(e, square_wave(ctx.t, period, phase), r, q, use=ctx.use)
        beta, s = float(f.beta[0]), float(f.sigma[0])
        if beta < 0:                                 # the same wave half a period later
            beta, phase = -beta, (phase + period / 2) % period
        amp, s_amp = float(rad_s_to_deg_h(beta)), float(rad_s_to_deg_h(s))
        word = "switches" if z > 3 else "shows no significant square wave:"
        sigma = {"amp_deg_h": s_amp}
        if math.isfinite(s_period):
            sigma.update(period_s=s_period, phase_s=s_phase)
        return EffectFit(self.name, gyro,
                         {"amp_deg_h": amp, "period_s": float(period), "phase_s": float(phase)}, sigma, z=z,
                         evidence=(f"gyro {gyro} bias {word} ±{amp:.3g} ± {s_amp:.2g} deg/h every "
                                   f"{period / 2:.4g} s (period {period:.4g} s; z over {m} "
                                   f"frequencies and switch-on times searched)"),
                         extra={"chi2": f.chi2, "t": t_stat})

    def prefer(self, mine, other, ctx):
        return explains_away(self, mine, other, ctx)

    @staticmethod
    def _refine(ctx, e: np.ndarray, period: float, phase: float, sign: float):
        """Period, phase and their 1σ from the switch times located one by one."""
        t, dt = ctx.t, ctx.dt
        half = period / 2.0
        j0 = math.ceil((t[0] - phase) / half)
        j1 = math.floor((t[-1] - phase) / half)
        idx, times = [], []
        for j in range(j0, j1 + 1):
            lo = np.searchsorted(t, phase + j * half - half / 2)
            hi = np.searchsorted(t, phase + j * half + half / 2)
            x = e[lo:hi]
            if x.size < 8:
                continue
            c = np.cumsum(x - x.mean())
            k = np.arange(1, x.size)
            # the step of largest |left mean − right mean|, weighted for the split (CUSUM)
            stat = c[:-1] / np.sqrt(k * (x.size - k) / x.size)
            direction = sign * (1.0 if j % 2 == 0 else -1.0)   # up at even switches of a + wave
            i = int(np.argmax(-direction * stat))
            idx.append(j)
            times.append(t[lo + i] + dt / 2)
        if len(idx) < 3:
            return period, phase, float("nan"), float("nan")
        A = np.column_stack([np.ones(len(idx)), np.asarray(idx, float)])
        coef, res, *_ = np.linalg.lstsq(A, np.asarray(times), rcond=None)
        dof = len(idx) - 2
        s2 = float(res[0]) / dof if res.size and dof > 0 else (dt * dt / 12.0)
        cov = np.linalg.inv(A.T @ A) * max(s2, dt * dt / 12.0)
        new_period = 2.0 * float(coef[1])
        if not (0.5 * period < new_period < 2.0 * period):
            return period, phase, float("nan"), float("nan")
        return (new_period, float(coef[0]) % new_period, 2.0 * math.sqrt(cov[1, 1]),
                math.sqrt(cov[0, 0]))

    def example(self, rng, n_gyros, max_rate_deg_s):
        return int(rng.integers(1, n_gyros + 1)), {
            "amp_deg_h": float(rng.uniform(40.0, 120.0)), "period_s": float(rng.uniform(60.0, 300.0)),
            "phase_s": float(rng.uniform(0.0, 60.0))}
