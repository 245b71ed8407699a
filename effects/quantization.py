"""``quantization``: the output angle counted in steps (ADEV slope −1)."""

from __future__ import annotations

import math

import numpy as np

from gyroarray.effects import _draw
from gyroarray.physics import quantize_angle
from gyroarray.sim.protocol import NoiseTermEffect, Param, Stage, with_cols
from gyroarray.units import deg_to_rad


class Quantization(NoiseTermEffect):
    """A real quantizer of the accumulated output angle, step q = √12·Q.

    Simulate: :func:`gyroarray.physics.quantize_angle`, the counter's start
    phase drawn once per gyro. Its Allan variance is 3Q²/τ² (the spec's
    definition) when the angle crosses many steps between samples in a way
    that varies along the record. Fit: one more column, Q², of the gyro's
    Allan model.
    """

    name = "quantization"
    order = 4
    stage = Stage.QUANTIZE
    rivals = ("bias_instability", "gauss_markov")
    static_noise = "the model quantizes the output angle (its noise depends on the rate)"
    params = (Param("q_deg", "deg", "q_rad", deg_to_rad, lo=0.0,
                    doc="angle quantization Q of σ² = 3Q²/τ² (step √12·Q)"),)
    doc = "angle quantization of the output"

    def simulate(self, state, act, streams):
        ctx = state.ctx
        phase = np.array([streams.stream(self.name, int(c) + 1).random() for c in act.cols])
        q = math.sqrt(12.0) * act.p["q_rad"]                     # step q = √12·Q
        return with_cols(state, act.cols, quantize_angle(state.x[:, act.cols], ctx.dt_s, q, phase))

    def noise_term(self, entry):
        return {"terms": ("q",)}

    def band_noise(self, entry, n: int, dt: float, rng: np.random.Generator) -> np.ndarray:
        """Its part of one Monte-Carlo run of the model band (n,) [rad/s]: white angle noise of σ Q, differenced."""
        q_rad = float(entry.params["q_deg"]) * math.pi / 180.0
        return np.diff(rng.normal(0.0, q_rad, n + 1)) / dt

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"q_deg": _draw.u(rng, 5e-4, 3e-3, True)}
