"""``quantization``: the output's angle quantization (ADEV slope −1, σ² = 3Q²/τ²)."""

from __future__ import annotations

import math

import numpy as np

from gyroarray.effects import _draw
from gyroarray.effects.protocol import NoiseTermEffect, Param, Stage, with_term
from gyroarray.core.units import deg_to_rad


class Quantization(NoiseTermEffect):
    """The quantization noise of an angle counter of step q = √12·Q.

    One definition, for the simulator and the fitter alike, the spec's:
    Q is the coefficient of σ²(τ) = 3Q²/τ². A counter whose angle crosses
    many steps between samples leaves an angle error e_k that is uniform on
    [−q/2, q/2) and independent from sample to sample (the additive
    quantization-noise model of a dithered quantizer), variance q²/12 = Q²;
    the output carries its difference, (e_k − e_{k−1})/dt, whose Allan
    variance is exactly 3Q²/τ² at every τ. The simulator draws e from the
    effect's own stream (n + 1 uniforms); the fitter reads the same Q as one
    more column of the gyro's Allan model, and the model band simulates the
    same process. (A counter the noise barely dithers is not this process:
    its error follows the slow angle and its ADEV is not 3Q²/τ²; the spec's
    signature, slope −1, is that of the dithered counter.)
    """

    name = "quantization"
    order = 4
    stage = Stage.QUANTIZE
    rivals = ("bias_instability", "gauss_markov")
    params = (Param("q_deg", "deg", "q_rad", deg_to_rad, lo=0.0,
                    doc="angle quantization Q of σ² = 3Q²/τ² (step √12·Q)"),)
    doc = "angle quantization of the output"

    def predictor_term(self, act, n_gyros):
        """None: its noise (e_k − e_{k−1})/dt is differenced white noise, whose spectrum
        vanishes at DC and whose angle error stays bounded (±q): no white, walk, flicker or
        Gauss–Markov term is that process, so the predictor lists it as ignored."""
        return None

    def simulate(self, state, act, streams):
        ctx = state.ctx
        half = math.sqrt(3.0) * np.asarray(act.p["q_rad"], dtype=float)   # q/2 = √3·Q
        e = np.empty((ctx.n + 1, len(act.cols)))
        for j, c in enumerate(act.cols):
            e[:, j] = streams.stream(self.name, int(c) + 1).uniform(-half[j], half[j], ctx.n + 1)
        return with_term(state, act.cols, np.diff(e, axis=0) / ctx.dt_s)       # (e_k − e_{k−1})/dt

    def noise_term(self, ctx, entry):
        return {"terms": ("q",)}

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"q_deg": _draw.u(rng, 5e-4, 3e-3, True)}
