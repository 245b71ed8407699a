"""Speed of the model-vs-measurement loop on a real 1e6-row record (issue: real records).

Targets: ``diagnose``, ``fit`` (one effect added) and ``compare --validate``
on the ADIS16405 record (1 000 000 rows × 3 gyros, 2.78 h at 100 Hz) <= 30 s
each; ``ladder`` to its end <= 90 s. The reference in the same run is the
same first step done plainly in numpy: each gyro's residual, its overlapping
Allan deviation at octave τ (cumulative sums) and an ordinary least-squares
fit of N and K to it; the ratio says how many such plain passes a diagnosis
costs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _timing import best_of

from gyroarray.chain.compare import ModelComparison
from gyroarray.core.measurement import read_measurement
from gyroarray.effects.model import NoiseModel

ADIS = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "adis16405_static.csv.gz"


def _plain(y: np.ndarray, dt: float) -> list:
    """Numpy only: OADEV at octave τ from the cumulative angle, then N², K² by least squares."""
    out = []
    for g in range(y.shape[1]):
        x = y[:, g] - y[:, g].mean()
        theta = np.concatenate([[0.0], np.cumsum(x) * dt])
        m = 2 ** np.arange(int(np.log2(x.size // 8)) + 1)
        tau = m * dt
        avar = np.array([np.mean((theta[2 * k:] - 2 * theta[k:-k] + theta[:-2 * k]) ** 2) / (2 * (k * dt) ** 2)
                         for k in m])
        A = np.column_stack([1.0 / tau, tau / 3.0])
        out.append(np.linalg.lstsq(A / avar[:, None], np.ones_like(avar), rcond=None)[0])
    return out


def main() -> dict:
    if not ADIS.exists():
        print(f"skipped: {ADIS} not found")
        return {"skipped": True}
    m = read_measurement(ADIS)
    ModelComparison(m, n_runs=2).analyse()                     # numba caches warm
    t_ref, _ = best_of(lambda: _plain(m.gyro_rad_s, m.dt_s), 1)
    t_diag, a = best_of(lambda: ModelComparison(m).analyse(), 1)
    top = a.candidates[0]
    t_fit, (_, after) = best_of(lambda: ModelComparison(m).fit([(top.effect, top.gyro)]), 1)
    model = NoiseModel(after.model.entries, description="fitted on the same record")
    t_val, v = best_of(lambda: ModelComparison(m, model).validate(), 1)
    t_lad, steps = best_of(lambda: ModelComparison(m).ladder(), 1)
    rows = [("diagnose ADIS16405 1e6 x 3", t_diag, 30.0), (f"fit --add {top.effect}:{top.gyro}", t_fit, 30.0),
            ("compare --validate", t_val, 30.0), (f"ladder ({len(steps) - 1} steps)", t_lad, 90.0)]
    print(f"{'job':<40} {'time s':>8} {'target s':>9} {'x plain numpy':>14}")
    for name, t, target in rows:
        print(f"{name:<40} {t:8.2f} {target:9.0f} {t / t_ref:14.1f}  {'ok' if t <= target else 'SLOW'}")
    print(f"plain numpy OADEV + N/K fit, 3 gyros: {t_ref:.2f} s; diagnose D = {a.discrepancy:.3g}; "
          f"validate D = {v.discrepancy:.3g}; ladder final D = {steps[-1][1].discrepancy:.3g}")
    return {"diagnose_s": t_diag, "fit_s": t_fit, "validate_s": t_val, "ladder_s": t_lad, "plain_s": t_ref,
            "ok": all(t <= target for _, t, target in rows)}
