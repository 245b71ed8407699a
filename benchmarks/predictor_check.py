"""The analytic predictor against the simulator on every design of the quick design sweep.

For each scenario of ``scenarios/sweeps/design_quick.toml`` (both schemes ×
N = 4, 5, 6, 8 at the optimal cone angle × ρ_arw ∈ {−0.1, 0, 0.5} × static and
0.03 Hz swing, 90 s at 100 Hz, paper 003 noise) and every linear estimator,
K replicates (default 30) are simulated with the sweep's own rate-table
truth through ``sim.effects.simulate_readings`` and the real estimators, and
the predictor's 1σ, RMS about the truth, mean error and angle error per axis
are compared with √(mean over the runs of x²) and its 95 % interval
(``gyroarray.chain.run.rms_ci``). Prints one line per scenario and a summary:
the share of predictions inside their interval (≈ 95 % expected when the
predictor is right; the comparisons within a scenario share their runs) and
the largest |prediction / simulation − 1|.

Usage: ``python benchmarks/predictor_check.py [--replicates K] [--json OUT]``
(``make score`` runs it).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ESTIMATORS = ("kf_array", "kf_single", "gls", "ols", "naive")
KEYS = ("rms_deg_s", "std_deg_s", "mean_deg_s", "angle_deg")


def check_scenario(spec, replicates: int, seed: int) -> dict:
    from gyroarray.core import units
    from gyroarray.analysis.replicates import replicate_rng, rms_ci
    from gyroarray.estimators import get_estimator
    from gyroarray.design.predict import predict, settle_start
    from gyroarray.sim.effects import simulate_readings
    from gyroarray.sim.truth import compute_truth
    sc = spec.build()
    truth = compute_truth(sc.profile, sc.sample_rate_hz, duration_s=sc.duration_s)
    w, t = truth.omega_body_rad_s, truth.time_s
    n, dt = t.size, 1.0 / sc.sample_rate_hz
    k0 = settle_start(n, dt, 2.0)
    ests = {e: get_estimator(e)().fit(sc.layout, sc.model, dt) for e in ESTIMATORS}
    preds = {e: predict(x, sc.model, n_samples=n, truth_rad_s=w) for e, x in ests.items()}
    runs = {e: [] for e in ESTIMATORS}
    for r in range(replicates):
        z = simulate_readings(sc.model, w, sc.layout, dt, replicate_rng(seed, r), time_s=t)
        for e, x in ests.items():
            err = x.estimate(z) - w
            q = err[k0:]
            runs[e].append(np.stack([np.sqrt(np.mean(q ** 2, 0)), np.std(q, 0, ddof=1),
                                     np.mean(q, 0), dt * err.sum(0)]))
    inside = total = 0
    worst = 0.0
    for e in ESTIMATORS:
        arr = np.array(runs[e])
        for a, ax in enumerate("xyz"):
            for m, key in enumerate(KEYS):
                conv = units.rad_to_deg if key == "angle_deg" else units.rad_s_to_deg_s
                ci = rms_ci(conv(arr[:, m, a]), gaussian=key in ("mean_deg_s", "angle_deg"))
                p = preds[e].axes[ax][key]
                total += 1
                inside += ci["ci_low"] <= p <= ci["ci_high"]
                if key in ("rms_deg_s", "std_deg_s"):
                    worst = max(worst, abs(p / ci["value"] - 1.0))
    return {"id": spec.id, "inside": inside, "total": total, "worst_rel_rms_std": worst}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--replicates", type=int, default=30)
    ap.add_argument("--seed", type=int, default=20260414)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    from gyroarray.sweep.sweep import load_sweep
    sweep = load_sweep(ROOT / "src" / "gyroarray" / "data" / "scenarios" / "sweeps" / "design_quick.toml")
    t0 = time.perf_counter()
    rows = []
    for spec in sweep.scenarios:
        r = check_scenario(spec, args.replicates, args.seed)
        rows.append(r)
        print(f"{r['id']:<60} {r['inside']:>3}/{r['total']} inside 95 %, "
              f"worst |pred/sim - 1| (RMS, 1sigma) {r['worst_rel_rms_std']:.3f}", flush=True)
    inside = sum(r["inside"] for r in rows)
    total = sum(r["total"] for r in rows)
    summary = {"scenarios": len(rows), "replicates": args.replicates, "inside": inside,
               "total": total, "share_inside": inside / total,
               "worst_rel_rms_std": max(r["worst_rel_rms_std"] for r in rows),
               "seconds": time.perf_counter() - t0}
    print(f"predictor vs {args.replicates} simulated runs, {len(rows)} designs x "
          f"{len(ESTIMATORS)} estimators x 3 axes x 4 metrics: {inside}/{total} = "
          f"{100 * inside / total:.1f} % inside their 95 % interval (expected ~95 %); "
          f"worst |pred/sim - 1| of RMS and 1sigma {summary['worst_rel_rms_std']:.3f}; "
          f"{summary['seconds']:.0f} s")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
