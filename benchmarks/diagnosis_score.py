"""Score ``gyroarray diagnose`` / ``fit`` the way the held-out set will: many effects, layouts, parameters.

Not a speed benchmark (``make bench`` does not run it): ``make score``, or
``python benchmarks/diagnosis_score.py [--seeds 2] [--effects a,b] [--json F]``.

Each case is a record shaped like the practice measurements (the 3-axis
table session of :func:`gyroarray.sim.lab.table_profile`: 1200 s static,
900 s of steps and swings, 300 s static tail, 50 Hz, warming room): a
conical array (S1 with N = 4, 5, 6 at 54.74°, S2 with N = 6 at 63.43°),
every gyro with its own ARW (0.10–0.25 deg/√h), RRW (0–8 deg/h/√h) and
turn-on bias (σ 250 deg/h), and ONE extra effect with parameters drawn from
a plausible range. The case's random generator decides everything
(``numpy.random.default_rng([seed, case])``), so a score is reproducible.

Per case, as a user would: ``analyse`` (diagnose) → is the top candidate
the effect (and gyro) that was set, and significant? → ``fit --add`` that
effect → does D fall by ≥ 50 % and end consistent, is the parameter within
10 % or 2σ of the value set (the issue's rule)?
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from gyroarray.compare import ModelComparison
from gyroarray.layout import Layout
from gyroarray.sim.lab import lab_run
from gyroarray.sim.model import ModelEntry, NoiseModel

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
        "burst": lambda: (lambda s: {"start_s": s, "end_s": s + _u(rng, 150.0, 400.0),
                                     "variance_ratio": _u(rng, 2.0, 6.0)})(_u(rng, 100.0, 1700.0)),
    }[effect]()
    return (None if effect in ("correlation", "burst") else g), p


EFFECTS = ["bias_instability", "quantization", "rate_ramp", "gauss_markov", "sinusoid", "scale_factor",
           "scale_nonlinearity", "misalignment", "temperature_bias", "latency", "saturation", "correlation",
           "burst"]


def run_case(effect: str, seed: int, case: int, n_runs: int = 20) -> dict:
    rng = np.random.default_rng([seed, case])
    scheme, n, alpha = LAYOUTS[int(rng.integers(len(LAYOUTS)))]
    layout = Layout.conical(scheme, n, math.radians(alpha))
    base = []
    for g in range(1, n + 1):
        base += [ModelEntry("arw", g, {"n_deg_rt_h": _u(rng, 0.10, 0.25)}),
                 ModelEntry("rrw", g, {"k_deg_h_rt_h": _u(rng, 0.0, 8.0)}),
                 ModelEntry("constant_bias", g, {"bias_deg_h": float(rng.normal(0.0, 250.0))})]
    t = np.arange(0.0, 2160.0, 0.02)
    from gyroarray.sim.lab import table_profile
    max_rate = np.abs(table_profile(t, 1200.0) @ np.asarray(layout.axes).T).max(axis=0) / (math.pi / 180)
    gyro, params = draw_effect(effect, rng, n, max_rate)
    model = NoiseModel(tuple(base) + (ModelEntry(effect, gyro, params),))
    m = lab_run(model, layout, rng, static_s=1200.0, motion_s=900.0, tail_s=300.0, protocol="table")
    t0 = time.perf_counter()
    comp = ModelComparison(m, n_runs=n_runs)
    before, after = comp.fit([(effect, gyro)])
    secs = time.perf_counter() - t0
    top = before.candidates[0]
    fit = after.fits.get((effect, gyro))
    param_ok, detail = True, {}
    for k, want in params.items():
        if (effect, k) in NOT_SCORED or fit is None or k not in fit.params:
            continue
        got, sig = float(fit.params[k]), float(fit.sigma.get(k, 0.0) or 0.0)
        if k == "tilt_azimuth_deg":
            err = abs((got - want + 180.0) % 360.0 - 180.0)
        else:
            err = abs(got - want)
        ok = err <= max(0.10 * abs(want), 2.0 * sig)
        param_ok &= ok
        detail[k] = (round(want, 6), round(got, 6), round(sig, 6))
    rank = next((i for i, c in enumerate(before.candidates) if (c.effect, c.gyro) == (effect, gyro)), -1)
    return {"effect": effect, "gyro": gyro, "seed": seed, "case": case, "layout": f"S{scheme} N{n}",
            "params": params, "top": [top.effect, top.gyro, round(float(top.z), 2)],
            "rank": rank, "found": (top.effect, top.gyro) == (effect, gyro) and before.significant(top),
            "top_effect_right": top.effect == effect,
            "d_before": round(before.discrepancy, 3), "d_after": round(after.discrepancy, 3),
            "falls": after.discrepancy <= 0.5 * before.discrepancy, "consistent_after": after.consistent,
            "param_ok": bool(param_ok), "fit": detail, "seconds": round(secs, 1),
            "after_worst": [[t.effect, t.gyro, round(float(t.z), 2)] for t in
                            sorted(after.tests, key=lambda t: -t.z if np.isfinite(t.z) else math.inf)[:2]]}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--effects", default=",".join(EFFECTS))
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    rows = []
    for effect in a.effects.split(","):
        for s in range(a.first_seed, a.first_seed + a.seeds):
            r = run_case(effect, s, EFFECTS.index(effect), a.runs)
            rows.append(r)
            flag = "ok " if r["found"] and r["consistent_after"] and r["param_ok"] else "BAD"
            print(f"{flag} {effect:<19} g={r['gyro']!s:<4} {r['layout']:<6} seed {s}: top {r['top']} "
                  f"rank {r['rank']} D {r['d_before']:.2f} -> {r['d_after']:.2f} "
                  f"cons {r['consistent_after']} param {r['param_ok']} {r['fit']} "
                  f"after-worst {r['after_worst']} ({r['seconds']} s)", flush=True)
    keys = ["found", "falls", "consistent_after", "param_ok"]
    summary = {k: sum(r[k] for r in rows) for k in keys}
    summary["cases"] = len(rows)
    print("summary:", summary)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"summary": summary, "rows": rows}, fh, indent=1, default=str)
    return summary


if __name__ == "__main__":
    main(sys.argv[1:])
    sys.exit(0)
