"""Timing shared by the benchmarks."""

from __future__ import annotations

import math
import time


def best_of(fn, repeat: int = 3) -> tuple[float, object]:
    """Best wall time [s] of ``repeat`` calls of ``fn()`` and the last result."""
    best, out = math.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out
