"""Coverage of the Gauss–Markov fit's 1σ through the chain: pulls of τc and σ_GM over many cases.

Not a speed benchmark: ``python benchmarks/gm_tau_coverage.py [--cases 40] [--first-seed 200]
[--noise-cases 20] [--noise-of 103] [--first-noise-seed 1] [--json F]``.

Cases: :func:`gyroarray.sim.cases.single_effect_case` ``("gauss_markov", seed)`` for seeds
``first_seed ..`` (parameters and noise both drawn), and ``--noise-cases`` records of one case's
model (``--noise-of``, default seed 103) with other noise realisations (``noise_seed``): the
parameter draw kept, the noise drawn again. Per case the chain fits as ``fit --add`` does,
``ModelComparison(m, n_runs=5).fit([("gauss_markov", gyro)])``, and, for comparison on the same
record, :func:`~gyroarray.effects.stochastic.fit_gyro_noise` directly on the gyro's residual
(output − H·ref) over the whole record and over the longest static part. Pull = (fit − true)/σ
(τc also in ln τc, σ_lnτ = σ_τ/τ). Printed: mean and sd of the pulls with their 90 % confidence
intervals (t for the mean, χ² for the sd) and the fractions within 1σ and 2σ (0.683, 0.954 for
a correct σ).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np
from scipy import stats

from gyroarray.effects.stochastic import fit_gyro_noise
from gyroarray.chain.compare import ModelComparison
from gyroarray.sim.cases import single_effect_case

EFFECT = "gauss_markov"


def _gm(f) -> tuple:
    """(τc, σ_τ, σ_GM, σ of σ_GM) of an EffectFit [s, s, deg/h, deg/h] (NaN when missing)."""
    if f is None:
        return (math.nan,) * 4
    return (float(f.params.get("tau_s", math.nan)), float(f.sigma.get("tau_s", math.nan)),
            float(f.params.get("sigma_deg_h", math.nan)), float(f.sigma.get("sigma_deg_h", math.nan)))


def _direct(x: np.ndarray, dt: float, gyro: int) -> tuple:
    fits = fit_gyro_noise(x - x.mean(), dt, gyro)
    return _gm(next(f for f in fits if f.effect == EFFECT))


def run_case(seed: int, noise_seed: int | None = None) -> dict:
    """One record: the chain's fit and the direct fits, with the true values."""
    c = single_effect_case(EFFECT, seed, noise_seed=noise_seed)
    g = int(c.gyro)
    t0 = time.perf_counter()
    comp = ModelComparison(c.measurement, n_runs=5)
    _, after = comp.fit([(EFFECT, g)])
    secs = time.perf_counter() - t0
    rec = after.record
    a, b = comp.longest
    e0 = comp.E0[:, g - 1]
    row = {"seed": seed, "noise_seed": noise_seed, "gyro": g, "layout": c.layout_name,
           "true_tau_s": float(c.params["tau_s"]), "true_sigma_deg_h": float(c.params["sigma_deg_h"]),
           "record": [int(rec.start or 0), int(rec.stop)], "n": int(comp.n), "longest": [int(a), int(b)],
           "chain": _gm(after.fits.get((EFFECT, g))), "whole": _direct(e0, comp.dt, g),
           "static": _direct(e0[a:b], comp.dt, g), "seconds": round(secs, 1)}
    return row


def pulls(rows: list, key: str) -> dict:
    """Pulls of τc (linear and log) and σ_GM of fit ``key`` against the true values."""
    tau = np.array([r[key][0] for r in rows])
    s_tau = np.array([r[key][1] for r in rows])
    sig = np.array([r[key][2] for r in rows])
    s_sig = np.array([r[key][3] for r in rows])
    t_tau = np.array([r["true_tau_s"] for r in rows])
    t_sig = np.array([r["true_sigma_deg_h"] for r in rows])
    return {"tau": (tau - t_tau) / s_tau, "ln_tau": np.log(tau / t_tau) / (s_tau / tau),
            "sigma": (sig - t_sig) / s_sig}


def summary(p: np.ndarray) -> dict:
    """Mean, sd with 90 % CIs, fractions within 1σ, 2σ, of the finite pulls."""
    p = p[np.isfinite(p)]
    n = p.size
    if n < 3:
        return {"n": n}
    mean, sd = float(p.mean()), float(p.std(ddof=1))
    half = stats.t.ppf(0.95, n - 1) * sd / math.sqrt(n)
    chi_hi, chi_lo = stats.chi2.ppf(0.95, n - 1), stats.chi2.ppf(0.05, n - 1)
    return {"n": n, "mean": mean, "mean_ci90": [mean - half, mean + half], "sd": sd,
            "sd_ci90": [sd * math.sqrt((n - 1) / chi_hi), sd * math.sqrt((n - 1) / chi_lo)],
            "sd_mad": float(1.4826 * np.median(np.abs(p - np.median(p)))),
            "within_1": float(np.mean(np.abs(p) <= 1.0)), "within_2": float(np.mean(np.abs(p) <= 2.0))}


def _line(name: str, s: dict) -> str:
    if s.get("n", 0) < 3:
        return f"  {name:<8} n={s.get('n', 0)}"
    return (f"  {name:<8} n={s['n']:3d} mean {s['mean']:+.2f} [{s['mean_ci90'][0]:+.2f}, {s['mean_ci90'][1]:+.2f}]"
            f"  sd {s['sd']:.2f} [{s['sd_ci90'][0]:.2f}, {s['sd_ci90'][1]:.2f}]  (MAD sd {s['sd_mad']:.2f})"
            f"  |p|<=1 {s['within_1']:.2f}  |p|<=2 {s['within_2']:.2f}")


def report(rows: list, title: str) -> dict:
    out = {}
    print(f"{title} ({len(rows)} records):")
    for key in ("chain", "whole", "static"):
        pl = pulls(rows, key)
        out[key] = {k: summary(v) for k, v in pl.items()}
        print(f" {key}:")
        for k, s in out[key].items():
            print(_line(k, s))
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=40, help="cases with parameters and noise drawn")
    ap.add_argument("--first-seed", type=int, default=200)
    ap.add_argument("--noise-cases", type=int, default=0, help="records of one case's model, noise redrawn")
    ap.add_argument("--noise-of", type=int, default=103, help="the seed of that case")
    ap.add_argument("--first-noise-seed", type=int, default=1)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    t_start = time.perf_counter()
    jobs = [(s, None) for s in range(a.first_seed, a.first_seed + a.cases)]
    jobs += [(a.noise_of, k) for k in range(a.first_noise_seed, a.first_noise_seed + a.noise_cases)]
    rows = []
    for seed, ns in jobs:
        r = run_case(seed, ns)
        rows.append(r)
        ch, wh, st = r["chain"], r["whole"], r["static"]
        print(f"seed {seed} noise {ns} g{r['gyro']} {r['layout']}: tau {r['true_tau_s']:.3g} s -> chain "
              f"{ch[0]:.3g} ± {ch[1]:.2g} (pull {(ch[0] - r['true_tau_s']) / ch[1]:+.2f}), whole {wh[0]:.3g} ± {wh[1]:.2g}, static "
              f"{st[0]:.3g} ± {st[1]:.2g}; sigma {r['true_sigma_deg_h']:.3g} -> {ch[2]:.3g} ± {ch[3]:.2g} "
              f"deg/h; record {r['record']} ({r['seconds']} s)", flush=True)
    out = {}
    if a.cases:
        out["drawn"] = report([r for r in rows if r["noise_seed"] is None], "parameters and noise drawn")
    if a.noise_cases:
        out["noise_only"] = report([r for r in rows if r["noise_seed"] is not None],
                                   f"seed {a.noise_of}'s model, noise redrawn")
        out["all"] = report(rows, "all")
    out["seconds"] = round(time.perf_counter() - t_start, 1)
    print(f"total {out['seconds']} s")
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"summary": out, "rows": rows}, fh, indent=1, default=float)
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
    sys.exit(0)
