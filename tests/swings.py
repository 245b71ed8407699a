"""Table motion shared by the localisation tests: still, two swings with minimum-jerk envelopes, still."""

from __future__ import annotations

import math

import numpy as np


def two_swings(t, first=(100.0, 200.0), second=(220.0, 320.0), ramp_s: float = 3.0) -> np.ndarray:
    """Body rate (n, 3) [rad/s]: 30 deg/s at 0.5 Hz about (1,1,1)/√3 over ``first`` [s], then
    20 deg/s at 1.3 Hz about (1,−1,0)/√2 over ``second`` [s]; minimum-jerk in and out over ``ramp_s``."""
    t = np.asarray(t, dtype=float)

    def envelope(t0, t1):
        def s(x):
            return x**3 * (10 - 15 * x + 6 * x * x)
        return s(np.clip((t - t0) / ramp_s, 0, 1)) * s(np.clip((t1 - t) / ramp_s, 0, 1))

    a1 = np.array([1.0, 1.0, 1.0]) / math.sqrt(3)
    a2 = np.array([1.0, -1.0, 0.0]) / math.sqrt(2)
    return (math.radians(30) * (envelope(*first) * np.sin(2 * math.pi * 0.5 * (t - first[0])))[:, None] * a1
            + math.radians(20) * (envelope(*second) * np.sin(2 * math.pi * 1.3 * (t - second[0])))[:, None] * a2)
