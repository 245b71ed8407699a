"""``sinusoid``: a sinusoidal rate error (a PSD line, a ripple in the ADEV)."""

from __future__ import annotations


import numpy as np

from gyroarray.effects.fits.regress import fit_sinusoid
from gyroarray.effects import _draw
from gyroarray.core.errors import InputError
from gyroarray.effects.protocol import Param, RegressionEffect, Stage, explains_away, identity, with_term
from gyroarray.core.units import RAD_PER_DEG, deg_s_to_rad_s, deg_to_rad


class Sinusoid(RegressionEffect):
    """amp·sin(2π f t + phase), t = ``time_s``.

    Fit: a line search over frequency with the amplitude and phase by GLS
    (:func:`gyroarray.effects.fits.regress.fit_sinusoid`); its candidate test
    reads the stochastic record and knows the gyro's white angle noise (a
    quantizer's blue spectrum is not a line).
    """

    name = "sinusoid"
    order = 7
    stage = Stage.ADD
    reads = "noise"
    channel = "spectrum"
    scored = ("amp_deg_s", "freq_hz")
    params = (Param("amp_deg_s", "deg/s", "amp_rad_s", deg_s_to_rad_s, lo=0.0, doc="amplitude"),
              Param("freq_hz", "Hz", "freq_hz", identity, lo=0.0, doc="frequency (below Nyquist)"),
              Param("phase_deg", "deg", "phase_rad", deg_to_rad, required=False, default=0.0,
                    doc="phase of amp·sin(2π f t + phase), t = time_s"))
    doc = "sinusoidal rate error"
    # a line near Nyquist lifts the shortest-τ ADEV as a τ^-1 slope: quantization (the
    # independent generator's 17.3 Hz line at 50 Hz: quantization z 211 ranked above the line's 179)
    rivals = ("gauss_markov", "bias_instability", "quantization")

    def check_record(self, params, dt_s, span_s):
        nyquist = 0.5 / dt_s
        if params["freq_hz"] >= nyquist:
            raise InputError(f"freq_hz = {params['freq_hz']:g} Hz must be below the Nyquist frequency "
                             f"{nyquist:g} Hz (half the sample rate)", column="freq_hz")

    def simulate(self, state, act, streams):
        ctx = state.ctx
        nyquist = 0.5 / ctx.dt_s
        if np.any(act.p["freq_hz"] >= nyquist):
            raise InputError(f"{act.label}: freq_hz must be below the Nyquist frequency "
                             f"{nyquist:g} Hz of this run (dt = {ctx.dt_s:g} s)", column="freq_hz")
        arg = 2.0 * np.pi * ctx.time_s[:, None] * act.p["freq_hz"] + act.p["phase_rad"]
        return with_term(state, act.cols, act.p["amp_rad_s"] * np.sin(arg))

    def regress(self, ctx, gyro, e, r, q):
        return fit_sinusoid(e, ctx.t, ctx.dt, r, q, gyro, use=ctx.use)

    def test(self, ctx, gyro):
        g = int(gyro) - 1
        return fit_sinusoid(ctx.Er[:, g], ctx.tr, ctx.dt, float(ctx.r[g]), float(ctx.q[g]), int(gyro),
                            q_angle_rad=_white_angle_noise(ctx, int(gyro)))

    def prefer(self, mine, other, ctx):
        """A tone of a few Hz is also an ADEV hump near τ = 1/(2.6 f), and one near Nyquist a τ^-1
        slope at the shortest τ: the line wins when, taken out of the record, the rival is no
        longer seen."""
        return explains_away(self, mine, other, ctx)

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"amp_deg_s": _draw.u(rng, 0.01, 0.06, True),
                                          "freq_hz": _draw.u(rng, 1.0, 20.0),
                                          "phase_deg": _draw.u(rng, 0.0, 360.0)}


def _white_angle_noise(ctx, gyro: int) -> float:
    """Q [rad] of the gyro's white angle noise in the model (0 without one)."""
    for term in ctx.noise_terms(gyro):
        if "q_deg" in term.params:
            return float(term.params["q_deg"]) * RAD_PER_DEG
    return 0.0
