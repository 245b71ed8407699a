"""Statistics of independent replicate runs: their seeds and confidence intervals.

Knows nothing of effects or estimators: used by the chain (``run --replicates``), the
design check (``design --recommend --check``) and the reports.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

__all__ = ["CI_LEVEL", "replicate_rng", "mean_ci", "rms_ci"]

#: Two-sided level of the replicate confidence intervals.
CI_LEVEL = 0.95

def replicate_rng(seed: int, i: int) -> np.random.Generator:
    """The Generator of replicate ``i`` of a run seeded ``seed`` (same seed, same bits)."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(i),)))


def mean_ci(values, level: float = CI_LEVEL) -> dict:
    """Mean and Student-t confidence interval of the mean of independent runs.

    Returns ``{"mean", "ci_low", "ci_high", "n"}`` (None where undefined: no
    finite value, or one run for the interval).
    """
    x = np.asarray([v for v in values if v is not None and np.isfinite(v)], dtype=float)
    n = int(x.size)
    if n == 0:
        return {"mean": None, "ci_low": None, "ci_high": None, "n": 0}
    m = float(np.mean(x))
    if n < 2:
        return {"mean": m, "ci_low": None, "ci_high": None, "n": n}
    half = float(stats.t.ppf(0.5 + level / 2, n - 1) * np.std(x, ddof=1) / np.sqrt(n))
    return {"mean": m, "ci_low": m - half, "ci_high": m + half, "n": n}


def rms_ci(values, level: float = CI_LEVEL, *, gaussian: bool = False) -> dict:
    """√(mean of x²) over runs, with a confidence interval for √E[x²].

    The mean square m of n runs is taken as E[x²]·χ²_ν/ν with the
    Satterthwaite degrees of freedom ν = 2 n m² / var(x²) (exact, ν = n, when
    x is a zero-mean Gaussian such as a run's mean error or angle error; large
    when each x² is itself a long average), so the interval is
    [m ν/χ²_ν(0.975), m ν/χ²_ν(0.025)]: it never reaches below zero and
    covers the skewed small-sample case that a t-interval of x² misses.
    ``gaussian``: x is known to be a zero-mean Gaussian (linear in the noise),
    so ν = n exactly.
    """
    x = np.asarray([float(v) ** 2 for v in values if v is not None and np.isfinite(v)], dtype=float)
    n = int(x.size)
    if n == 0:
        return {"value": None, "ci_low": None, "ci_high": None, "n": 0}
    m = float(np.mean(x))
    if n < 2 or m == 0.0:
        return {"value": float(np.sqrt(m)), "ci_low": None, "ci_high": None, "n": n}
    var = float(np.var(x, ddof=1))
    nu = float(n) if gaussian else (2.0 * n * m * m / var if var > 0 else 1e9)
    a = 1.0 - level
    lo = m * nu / stats.chi2.ppf(1.0 - a / 2, nu)
    hi = m * nu / stats.chi2.ppf(a / 2, nu)
    return {"value": float(np.sqrt(m)), "ci_low": float(np.sqrt(lo)), "ci_high": float(np.sqrt(hi)),
            "n": n}
