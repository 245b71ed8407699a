"""Predictions beside simulated replicates: the shared Monte-Carlo loop of the predictor tests."""

from __future__ import annotations

import numpy as np

from gyroarray.core import units
from gyroarray.analysis.replicates import replicate_rng, rms_ci
from gyroarray.design.predict import settle_start
from gyroarray.sim.effects import simulate_readings

#: The predicted metrics each replicate measures, in this order.
KEYS = ("rms_deg_s", "std_deg_s", "mean_deg_s", "angle_deg")


def predictions_outside(ests: dict, preds: dict, model, layout, truth: np.ndarray, dt: float, *,
                        reps: int, seed: int, level: float, settle_s: float = 2.0) -> list:
    """Simulate ``reps`` runs of ``truth`` through the model and every estimator; return the
    (estimator, axis, metric, predicted, interval) whose prediction lies outside the runs'
    interval for √E[x²] at ``level`` (exact χ² for the Gaussian mean and angle errors)."""
    n = truth.shape[0]
    t = np.arange(n) * dt
    k0 = settle_start(n, dt, settle_s)
    runs = {nm: [] for nm in ests}
    for r in range(reps):
        z = simulate_readings(model, truth, layout, dt, replicate_rng(seed, r), time_s=t)
        for nm, e in ests.items():
            err = e.estimate(z) - truth
            w = err[k0:]
            runs[nm].append(np.stack([np.sqrt(np.mean(w ** 2, 0)), np.std(w, 0, ddof=1),
                                      np.mean(w, 0), dt * err.sum(0)]))
    outside = []
    for nm, vals in runs.items():
        arr = np.array(vals)
        for a, ax in enumerate("xyz"):
            for m, key in enumerate(KEYS):
                conv = units.rad_to_deg if key == "angle_deg" else units.rad_s_to_deg_s
                ci = rms_ci(conv(arr[:, m, a]), level, gaussian=key in ("mean_deg_s", "angle_deg"))
                p = preds[nm].axes[ax][key]
                if not ci["ci_low"] <= p <= ci["ci_high"]:
                    outside.append((nm, ax, key, p, ci))
    return outside
