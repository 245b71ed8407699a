"""Random draws of plausible effect parameters, for the scoring cases (:mod:`gyroarray.sim.cases`).

Each effect's ``example(rng, n_gyros, max_rate_deg_s)`` draws the gyro first
(also an array-wide effect, which then discards it), then its parameters, so a
case is reproducible from its generator alone.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["u", "gyro", "sign"]


def u(rng: np.random.Generator, lo: float, hi: float, log: bool = False) -> float:
    """Uniform in [lo, hi), or log-uniform with ``log``."""
    if log:
        return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    return float(rng.uniform(lo, hi))


def gyro(rng: np.random.Generator, n_gyros: int) -> int:
    """A gyro 1..N."""
    return int(rng.integers(1, n_gyros + 1))


def sign(rng: np.random.Generator) -> int:
    """±1."""
    return int(rng.choice([-1, 1]))
