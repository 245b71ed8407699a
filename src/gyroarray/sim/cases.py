"""Random single-effect lab runs: the records the diagnosis is scored on.

Each case is shaped like the practice measurements of the shared data (the
3-axis table session of :func:`gyroarray.sim.lab.table_profile`: 1200 s
static, 900 s of steps and swings, 300 s static tail, 50 Hz, warming room):
a conical array (S1 with N = 4, 5, 6 at 54.74°, S2 with N = 6 at 63.43°),
every gyro with its own baseline noise and turn-on bias (each effect's
``Effect.typical``: ARW 0.10–0.25 deg/√h, RRW 0–8 deg/h/√h, bias σ 250
deg/h), and ONE extra effect with its parameters drawn from a plausible range
(``Effect.example``, :func:`draw_effect`). The case's
generator ``numpy.random.default_rng([seed, case])`` decides everything, so
a case is reproducible from its two numbers.

Used by ``benchmarks/diagnosis_score.py`` (the score over many cases) and
the tests of :mod:`gyroarray.chain.compare`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyroarray.effects import REGISTRY, get_effect
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement
from gyroarray.sim.lab import lab_run, table_profile
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.protocol import Effect
from gyroarray.core.units import RAD_PER_DEG

__all__ = ["LAYOUTS", "EFFECTS", "NOT_SCORED", "draw_effect", "Case", "single_effect_case"]

#: The session [s] and sample rate [Hz] of every case (the practice set's).
STATIC_S, MOTION_S, TAIL_S, RATE_HZ = 1200.0, 900.0, 300.0, 50.0

LAYOUTS = [(1, 4, 54.7356), (1, 5, 54.7356), (1, 6, 54.7356), (2, 6, 63.4349)]


def _scorable(eff: Effect) -> bool:
    return type(eff).example is not Effect.example


#: The effects a case can hide: every registered effect that draws an example of itself
#: (``Effect.example``: not the baseline's, not ``constant_bias``), registry order.
EFFECTS = [e.name for e in REGISTRY.values() if _scorable(e)]

#: (effect, parameter) pairs the fit does not return or cannot identify (``Effect.scored``).
NOT_SCORED = {(e.name, p.name) for e in REGISTRY.values() if _scorable(e) and e.scored is not None
              for p in e.params if p.name not in e.scored}


def draw_effect(effect: str, rng: np.random.Generator, n_gyros: int, max_rate_deg_s: np.ndarray):
    """(gyro, params) of one hidden effect, spec units (the effect's own ``example``)."""
    return get_effect(effect).example(rng, n_gyros, max_rate_deg_s)


@dataclass(frozen=True)
class Case:
    """One scoring case: the measurement and what is hidden in it."""

    measurement: Measurement
    effect: str
    gyro: int | None
    params: dict
    layout_name: str


def single_effect_case(effect: str, seed: int, case: int | None = None, noise_seed: int | None = None) -> Case:
    """The lab run of ``effect`` hidden in a random baseline (``case`` defaults to the effect's index).

    ``noise_seed``: the same layout and parameters (drawn from ``(seed, case)``) recorded with
    another noise realisation, from ``numpy.random.default_rng([seed, case, noise_seed])``;
    None: the case's own generator draws the record too.
    """
    case = EFFECTS.index(effect) if case is None else case
    rng = np.random.default_rng([seed, case])
    scheme, n, alpha = LAYOUTS[int(rng.integers(len(LAYOUTS)))]
    layout = Layout.conical(scheme, n, math.radians(alpha))
    typical = [e for e in REGISTRY.values() if type(e).typical is not Effect.typical]
    base = [ModelEntry(eff.name, g, eff.typical(rng)) for g in range(1, n + 1) for eff in typical]
    t = np.arange(0.0, STATIC_S + MOTION_S + TAIL_S, 1.0 / RATE_HZ)
    max_rate = np.abs(table_profile(t, STATIC_S, MOTION_S) @ np.asarray(layout.axes).T).max(axis=0) / RAD_PER_DEG
    gyro, params = draw_effect(effect, rng, n, max_rate)
    model = NoiseModel(tuple(base) + (ModelEntry(effect, gyro, params),))
    if noise_seed is not None:
        rng = np.random.default_rng([seed, case, int(noise_seed)])
    m = lab_run(model, layout, rng, rate_hz=RATE_HZ, static_s=STATIC_S, motion_s=MOTION_S, tail_s=TAIL_S,
                protocol="table")
    return Case(m, effect, gyro, params, f"S{scheme} N{n}")
