"""``bias_instability``: flicker (1/f) rate noise, the ADEV floor 0.664·B."""

from __future__ import annotations

from gyroarray.effects import _draw
from gyroarray.core.physics import flicker_noise
from gyroarray.effects.protocol import NoiseTermEffect, Param, Stage, with_term
from gyroarray.effects.terms import FlickerTerm, spread
from gyroarray.core.units import deg_h_to_rad_s


class BiasInstability(NoiseTermEffect):
    """True 1/f noise by FFT shaping (:func:`gyroarray.core.physics.flicker_noise`).

    Fit: one more column, B², of the gyro's Allan model (ADEV flat at 0.664·B).
    """

    name = "bias_instability"
    order = 3
    stage = Stage.ADD
    rivals = ("gauss_markov", "quantization")
    params = (Param("b_deg_h", "deg/h", "b_rad_s", deg_h_to_rad_s, lo=0.0,
                    doc="bias instability B: flicker noise, ADEV plateau 0.664·B"),)
    doc = "bias instability (1/f flicker rate noise)"

    def predictor_term(self, act, n_gyros):
        """Flicker noise of coefficient B [rad/s], independent between gyros."""
        return FlickerTerm(spread(act, "b_rad_s", n_gyros))

    def simulate(self, state, act, streams):
        ctx = state.ctx
        gens = [streams.stream(self.name, int(c) + 1) for c in act.cols]
        return with_term(state, act.cols, flicker_noise(ctx.n, ctx.dt_s, act.p["b_rad_s"], gens))

    def noise_term(self, ctx, entry):
        return {"terms": ("b",)}

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"b_deg_h": _draw.u(rng, 5.0, 20.0, True)}
