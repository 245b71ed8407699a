"""Random single-effect lab runs: the records the diagnosis is scored on.

Each case is shaped like the practice measurements of the shared data (the
3-axis table session of :func:`gyroarray.sim.lab.table_profile`: 1200 s
static, 900 s of steps and swings, 300 s static tail, 50 Hz, warming room):
a conical array (S1 with N = 4, 5, 6 at 54.74°, S2 with N = 6 at 63.43°),
every gyro with its own ARW (0.10–0.25 deg/√h), RRW (0–8 deg/h/√h) and
turn-on bias (σ 250 deg/h), and ONE extra effect of the spec with its
parameters drawn from a plausible range (:func:`draw_effect`). The case's
generator ``numpy.random.default_rng([seed, case])`` decides everything, so
a case is reproducible from its two numbers.

Used by ``benchmarks/diagnosis_score.py`` (the score over many cases) and
the tests of :mod:`gyroarray.compare`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyroarray.layout import Layout
from gyroarray.measurement import Measurement
from gyroarray.sim.lab import lab_run, table_profile
from gyroarray.sim.model import ModelEntry, NoiseModel
from gyroarray.units import RAD_PER_DEG

__all__ = ["LAYOUTS", "EFFECTS", "NOT_SCORED", "draw_effect", "Case", "single_effect_case"]

#: The session [s] and sample rate [Hz] of every case (the practice set's).
STATIC_S, MOTION_S, TAIL_S, RATE_HZ = 1200.0, 900.0, 300.0, 50.0

LAYOUTS = [(1, 4, 54.7356), (1, 5, 54.7356), (1, 6, 54.7356), (2, 6, 63.4349)]
# parameters the fit does not return or cannot identify
NOT_SCORED = {("temperature_bias", "t0_c"), ("correlation", "rho_rrw"), ("sinusoid", "phase_deg")}


def _u(rng, lo, hi, log=False):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi)))) if log else float(rng.uniform(lo, hi))


def draw_effect(effect: str, rng: np.random.Generator, n_gyros: int, max_rate_deg_s: np.ndarray):
    """(gyro, params) of one hidden effect, spec units."""
    g = int(rng.integers(1, n_gyros + 1))
    p = {
        "bias_instability": lambda: {"b_deg_h": _u(rng, 5.0, 20.0, True)},
        "quantization": lambda: {"q_deg": _u(rng, 5e-4, 3e-3, True)},
        "rate_ramp": lambda: {"r_deg_h2": _u(rng, 100.0, 600.0, True) * rng.choice([-1, 1])},
        "gauss_markov": lambda: {"sigma_deg_h": _u(rng, 50.0, 300.0, True), "tau_s": _u(rng, 0.2, 20.0, True)},
        "sinusoid": lambda: {"amp_deg_s": _u(rng, 0.01, 0.06, True), "freq_hz": _u(rng, 1.0, 20.0),
                             "phase_deg": _u(rng, 0.0, 360.0)},
        "scale_factor": lambda: {"ppm": _u(rng, 1000.0, 8000.0, True) * rng.choice([-1, 1])},
        "scale_nonlinearity": lambda: {"k2_per_deg_s": _u(rng, 1e-5, 6e-5, True) * rng.choice([-1, 1])},
        "misalignment": lambda: {"tilt_deg": _u(rng, 0.2, 1.0, True), "tilt_azimuth_deg": _u(rng, 0.0, 360.0)},
        "temperature_bias": lambda: {"deg_h_per_c": _u(rng, 10.0, 60.0, True) * rng.choice([-1, 1]),
                                     "t0_c": 25.0},
        "latency": lambda: {"delay_s": _u(rng, 0.002, 0.01, True)},
        "saturation": lambda: {"range_deg_s": _u(rng, 0.5, 0.85) * float(max_rate_deg_s[g - 1])},
        "correlation": lambda: {"rho_arw": _u(rng, 0.15, 0.5), "rho_rrw": 0.0},
        "earth_rate": lambda: {"latitude_deg": 34.25},   # the site of the sidecar
        "burst": lambda: (lambda s: {"start_s": s, "end_s": s + _u(rng, 150.0, 400.0),
                                     "variance_ratio": _u(rng, 2.0, 6.0)})(_u(rng, 100.0, 1700.0)),
    }[effect]()
    return (None if effect in ("correlation", "burst", "earth_rate") else g), p


#: The effects a case can hide (every spec effect except the baseline's and constant_bias).
EFFECTS = ["bias_instability", "quantization", "rate_ramp", "gauss_markov", "sinusoid", "scale_factor",
           "scale_nonlinearity", "misalignment", "temperature_bias", "latency", "saturation", "correlation",
           "burst", "earth_rate"]



@dataclass(frozen=True)
class Case:
    """One scoring case: the measurement and what is hidden in it."""

    measurement: Measurement
    effect: str
    gyro: int | None
    params: dict
    layout_name: str


def single_effect_case(effect: str, seed: int, case: int | None = None) -> Case:
    """The lab run of ``effect`` hidden in a random baseline (``case`` defaults to the effect's index)."""
    case = EFFECTS.index(effect) if case is None else case
    rng = np.random.default_rng([seed, case])
    scheme, n, alpha = LAYOUTS[int(rng.integers(len(LAYOUTS)))]
    layout = Layout.conical(scheme, n, math.radians(alpha))
    base = []
    for g in range(1, n + 1):
        base += [ModelEntry("arw", g, {"n_deg_rt_h": _u(rng, 0.10, 0.25)}),
                 ModelEntry("rrw", g, {"k_deg_h_rt_h": _u(rng, 0.0, 8.0)}),
                 ModelEntry("constant_bias", g, {"bias_deg_h": float(rng.normal(0.0, 250.0))})]
    t = np.arange(0.0, STATIC_S + MOTION_S + TAIL_S, 1.0 / RATE_HZ)
    max_rate = np.abs(table_profile(t, STATIC_S, MOTION_S) @ np.asarray(layout.axes).T).max(axis=0) / RAD_PER_DEG
    gyro, params = draw_effect(effect, rng, n, max_rate)
    model = NoiseModel(tuple(base) + (ModelEntry(effect, gyro, params),))
    m = lab_run(model, layout, rng, rate_hz=RATE_HZ, static_s=STATIC_S, motion_s=MOTION_S, tail_s=TAIL_S,
                protocol="table")
    return Case(m, effect, gyro, params, f"S{scheme} N{n}")
