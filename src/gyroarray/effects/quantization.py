"""``quantization``: the output's angle counter (the spec's rounded integrated angle; σ² = 3Q²/τ² when it moves fast)."""

from __future__ import annotations

import math
from dataclasses import replace
from functools import partial

import numpy as np

from gyroarray.effects import _draw
from gyroarray.effects.protocol import NoiseTermEffect, Param, Stage, with_cols
from gyroarray.core.sensor import bandwidth_filter, output_lattice_step, quantize_rate
from gyroarray.analysis.allan import oadev
from gyroarray.core.units import arw_deg_rt_h_to_rad_rt_s, deg_to_rad, rad_s_to_deg_h, rad_to_deg
from gyroarray.effects.stochastic import fit_gyro_noise

#: The angle error counts as correlated (not white) when the output lies on a grid and the rms
#: count per still sample, y·dt/Δ, is below this [steps].
CORRELATED_BELOW = 2.0

#: :func:`quant_avar_shape` is 1 (the white angle error's 3Q²/τ²) from the τ on where the angle
#: noise has moved by this many steps (τ >= this² (Δ/N)²) [steps].
DECORRELATED_STEPS = 30.0

#: Samples of the simulation behind :func:`quant_avar_shape` (at least 64 per averaging factor
#: it reads; beyond, the shape is 1).
SHAPE_SAMPLES = 2 ** 19


def _counter(n_rad_rt_s: float, bias_rad_s: float, step_rad: float, dt_s: float, filt, samples: int):
    """(quantized, unquantized) simulated output of one gyro: white N plus a mean, through the
    model's filter ``filt`` ((cut-off [Hz], order) or None), a fixed seed (common draws)."""
    rng = np.random.default_rng(20261128)
    x = bias_rad_s + n_rad_rt_s / math.sqrt(dt_s) * rng.standard_normal(samples)
    if filt is not None:
        x = bandwidth_filter(x, dt_s, filt[0], filt[1])
    return quantize_rate(x, dt_s, step_rad), x


def quant_avar_shape(n_rad_rt_s: float, bias_rad_s: float, step_rad: float, dt_s: float, m,
                     filt=None) -> np.ndarray:
    """The spec's counter's excess Allan variance over 3Q²/τ² (Q = Δ/√12), white N and a mean.

    Parameters
    ----------
    n_rad_rt_s : float
        White rate noise N before the filter and the counter [rad/√s].
    bias_rad_s : float
        The gyro's mean rate, which also moves the counter [rad/s].
    step_rad : float
        Angle step Δ [rad].
    dt_s : float
        Sample step [s].
    m : array_like of int
        Averaging factors [-].
    filt : tuple (cut-off [Hz], order) or None
        The model's ``bandwidth`` on that gyro (before the counter).

    Returns
    -------
    ndarray
        (AVAR(quantized) − AVAR(unquantized))/(3Q²/τ²) at each factor [-], from one simulation
        of :data:`SHAPE_SAMPLES` samples (a fixed seed: a deterministic function of the inputs):
        1 for a white angle error, far below 1 at short τ in the correlated regime; 1 beyond
        :data:`DECORRELATED_STEPS`² (Δ/N)² or where the simulation holds fewer than 64 factors.
    """
    m = np.asarray(m, dtype=np.int64)
    dt = float(dt_s)
    y, x = _counter(n_rad_rt_s, bias_rad_s, step_rad, dt, filt, SHAPE_SAMPLES)
    tau_white = DECORRELATED_STEPS ** 2 * (step_rad / n_rad_rt_s) ** 2
    out = np.ones(m.size)
    sel = (m * 64 <= SHAPE_SAMPLES) & (m * dt < tau_white)
    if np.any(sel):
        taus = m[sel] * dt
        excess = oadev(y, dt, taus=taus).dev ** 2 - oadev(x, dt, taus=taus).dev ** 2
        out[sel] = np.maximum(excess / (step_rad ** 2 / (4.0 * taus ** 2)), 0.0)
    return out


class Quantization(NoiseTermEffect):
    """The spec's rate-integrating counter of angle step Δ = √12·Q.

    Simulated exactly as ``shared/spec/effects.md`` defines it: θ_k the
    integrated angle of everything the gyro outputs at this stage (after
    ``bandwidth``), y_k = (round(θ_k/Δ) − round(θ_{k−1}/Δ))·Δ/dt
    (:func:`gyroarray.core.sensor.quantize_rate`; no random draw).

    Fit, in two regimes:

    * the angle moves by many steps per sample: its error is white, variance
      Q², and the Allan variance 3Q²/τ² (IEEE 952): Q is one more column of the
      gyro's Allan model (a grid of the output is reported, not used: a rate
      quantizer's grid is no angle step);
    * the angle moves by less than :data:`CORRELATED_BELOW` steps per sample (a
      quiet gyro, a coarse step): the error follows the slow angle and is
      correlated; Δ comes from the output's grid alone, the Q² column is
      shaped by simulating the counter at the gyro's white level and mean
      (:func:`quant_avar_shape`), and the model band simulates the counter
      with the gyro's mean beside it (:meth:`band_entries`).

    In the correlated regime the counter's error depends on the motion
    (correlated at rest, white on a swing), so the stochastic tests read the
    still part (:meth:`static_noise_in`).
    """

    name = "quantization"
    order = 4
    stage = Stage.QUANTIZE
    rivals = ("bias_instability", "gauss_markov")
    params = (Param("q_deg", "deg", "q_rad", deg_to_rad, lo=0.0,
                    doc="angle quantization Q of σ² = 3Q²/τ² (step √12·Q)"),)
    doc = "angle quantization of the output"

    def predictor_term(self, act, n_gyros):
        """None: its angle error stays bounded (±Δ/2), so its rate noise has no power at DC, and it
        depends on the motion (white when the angle moves by many steps per sample, correlated
        when not): no white, walk, flicker or Gauss–Markov term is that process, so the
        predictor lists it as ignored."""
        return None

    def simulate(self, state, act, streams):
        """The spec's counter: y_k = (round(θ_k/Δ) − round(θ_{k−1}/Δ))·Δ/dt, Δ = √12·Q.

        θ_k = Σ_{j<=k} x_j·dt is the angle of everything the gyro outputs at this stage (the
        sensed rate, biases, noise, after ``bandwidth``), from θ_{−1} = 0; no random draw.
        """
        return with_cols(state, act.cols, quantize_rate(state.x[:, act.cols], state.ctx.dt_s,
                                                        math.sqrt(12.0) * np.asarray(act.p["q_rad"], dtype=float)))

    def lattice(self, ctx, gyro: int) -> dict:
        """What the gyro's output grid says (cached per record): ``step_rad`` Δ = c·dt from the grid
        c of the output values (NaN: none), ``counts_sd`` the spread of the per-sample counts
        y·dt/Δ on the static samples (the angle's motion per sample in steps), ``correlated``
        (a grid, and the angle moves by less than :data:`CORRELATED_BELOW` steps per sample),
        ``bias_rad_s`` the gyro's mean on the static samples beyond the reference (what moves
        its counter besides the noise) [rad/s]."""
        key = ("quantization_lattice", int(gyro))
        if key not in ctx.cache:
            g = int(gyro) - 1
            y = np.asarray(ctx.y[:, g], dtype=float)
            c = output_lattice_step(y)
            still = ctx.static if ctx.static is not None and np.any(ctx.static) else np.ones(y.size, bool)
            step = c * ctx.dt
            # the noise's motion of the angle per sample, in steps: what randomises the error (a
            # mean alone, however large, leaves a deterministic sawtooth)
            sd = float(np.std(y[still] * ctx.dt / step)) if math.isfinite(c) else math.nan
            ctx.cache[key] = {"step_rad": float(step), "counts_sd": sd,
                              "correlated": bool(math.isfinite(c) and sd < CORRELATED_BELOW),
                              "bias_rad_s": float(np.mean(ctx.E0[still, g]))}
        return ctx.cache[key]

    def fit(self, ctx, gyro, E):
        """The Allan column's Q (:meth:`NoiseTermEffect.fit`); in the correlated regime the output
        grid's Δ/√12 instead (the column's 3Q²/τ² is not that process's ADEV). In the white regime
        the grid is only reported: a rate quantizer's grid (a white rate, not angle, error: the
        ADIS16405's 0.05 deg/s) is no angle step."""
        f = super().fit(ctx, gyro, E)
        lat = self.lattice(ctx, int(gyro))
        step = lat["step_rad"]
        if not math.isfinite(step):
            return f
        q_deg = float(rad_to_deg(step / math.sqrt(12.0)))
        grid = (f"; output on a grid of {float(rad_to_deg(step / ctx.dt)):.6g} deg/s: angle step "
                f"Δ = {float(rad_to_deg(step)):.6g} deg, Q = Δ/√12 = {q_deg:.6g} deg")
        if lat["correlated"]:
            ev = (f"gyro {int(gyro)}{grid}; the angle moves by {lat['counts_sd']:.2g} steps per sample "
                  "(rms), so the angle error is correlated, not white: its ADEV is simulated, not 3Q²/τ²")
        else:        # white regime: the Allan column's Q (a rate quantizer's grid is no angle step)
            return replace(f, evidence=f"{f.evidence}{grid}; the angle moves by {lat['counts_sd']:.2g} steps "
                                       "per sample (rms): white angle error, Q read from the Allan column")
        return replace(f, params={"q_deg": q_deg}, sigma={"q_deg": 1e-6 * q_deg}, evidence=ev,
                       extra={**f.extra, "q_allan_deg": f.params["q_deg"], "grid": True,
                              "correlated": lat["correlated"], "counts_sd": lat["counts_sd"]})

    def noise_term(self, ctx, entry):
        """The 3Q²/τ² column. In the correlated regime that column is shaped by simulating the
        counter (:func:`quant_avar_shape`: its excess Allan variance over 3Q²/τ², the gyro's
        mean beside it), N read self-consistently (up to three passes
        of the gyro's Allan fit with the shaped column). N and Q² stay free; the Q² column keeps
        the quantizer's share of the estimates' covariance (a quiet counter's increments are far
        from Gaussian)."""
        if entry.gyro is None or ctx.Er is None:
            return {"terms": ("q",)}
        g = int(entry.gyro)
        lat = self.lattice(ctx, g)
        if not lat["correlated"]:
            return {"terms": ("q",)}
        step = math.sqrt(12.0) * float(deg_to_rad(entry.params["q_deg"]))
        # the counter alone: with the model's filter simulated before it the band at τ = dt read 2.4 %
        # low on tests/test_filter_quantization.py (z 3.8), without it inside (the filter's own
        # shape is the white column's, :meth:`Bandwidth.noise_term`)
        filt = None
        key = ("quantization_shape", g, step)
        if key not in ctx.cache:
            e = ctx.Er[:, g - 1]
            n_rad, shape = math.nan, None
            for _ in range(3):                   # N from the fit, the shape from N, the fit again
                f = fit_gyro_noise(e, ctx.dt, g, model_terms=("q",), quant_shape=shape)
                n_new = float(arw_deg_rt_h_to_rad_rt_s(f[0].params["n_deg_rt_h"]))
                if not n_new > 0 or (math.isfinite(n_rad) and abs(n_new - n_rad) <= 0.01 * n_rad):
                    break
                n_rad = n_new
                shape = partial(quant_avar_shape, n_rad, lat["bias_rad_s"], step, ctx.dt, filt=filt)
            ctx.cache[key] = shape
        shape = ctx.cache[key]
        return {"terms": ("q",)} if shape is None else {"terms": ("q",), "quant_shape": shape}

    def static_noise_in(self, ctx, entry):
        """In the correlated regime the counter's error depends on the motion (correlated at rest,
        white when the table turns): the stochastic tests then read the still part."""
        gyros = range(1, ctx.N + 1) if entry.gyro is None else [int(entry.gyro)]
        if any(self.lattice(ctx, g)["correlated"] for g in gyros):
            return "the quantizer's error depends on the motion (correlated at rest, white when turning)"
        return None

    def band_entries(self, ctx, entry):
        """Itself, and the gyro's mean beyond the reference (what moves its counter)."""
        if entry.gyro is None:
            return [entry]
        bias = self.lattice(ctx, int(entry.gyro))["bias_rad_s"]
        return [entry, ctx.model_entry("constant_bias", entry.gyro, {"bias_deg_h": float(rad_s_to_deg_h(bias))})]

    def example(self, rng, n_gyros, max_rate_deg_s):
        return _draw.gyro(rng, n_gyros), {"q_deg": _draw.u(rng, 5e-4, 3e-3, True)}
