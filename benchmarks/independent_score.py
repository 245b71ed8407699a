"""Score the diagnosis on records of an INDEPENDENT generator (``benchmarks/_indep_gen.py``).

``benchmarks/diagnosis_score.py`` scores ``ModelComparison`` on records of
our own simulator, which only shows that simulator and fitter agree. Here
the records come from a plain numpy/scipy generator written only from the
specs; each is written to disk in the measurement format and read back with
:func:`gyroarray.core.measurement.read_measurement`, as a user's file would be,
then scored exactly like ``diagnosis_score.score_case`` (shared
:func:`score_measurement`): found = top candidate is the hidden effect (and
gyro) and significant; falls = D halves after ``fit --add``; consistent
after; every returned parameter within max(10 %, 2σ) of the value set.

Misalignment: the generator sets the true ``axis`` and ``tilt_deg``; the
shared rule scores the fitted ``tilt_deg`` (``axis`` is in NOT_SCORED, and
the fit returns a tilt and its azimuth, not an axis).

Faults (``fault_step``, ``fault_drift``, ``fault_stuck``, ``fault_noise``; one
gyro, from ``start_s`` [s] to the end): the same rule, ``start_s`` included
(within max(10 % of ``start_s``, 2σ)). The shared rule skips a parameter the
fit does not return; for a fault that would pass ``fault_stuck`` (whose only
parameter is ``start_s``) without checking anything, so here a fault whose fit
leaves out a parameter set by the generator fails ``param_ok``.

Usage: ``python benchmarks/independent_score.py [--seeds 2] [--first-seed 500]
[--effects a,b] [--runs 20] [--json F] [--keep DIR]
[--bandwidth-method foh|bilinear|bilinear_prewarp] [--quantization-method round|white]``.
``--effects`` defaults to every effect of the generator, its four faults
included; ``--effects fault_step,fault_drift,fault_stuck,fault_noise`` scores
the faults alone.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _indep_gen as gen  # noqa: E402
from diagnosis_score import NOT_SCORED, score_measurement, summarise  # noqa: E402

from gyroarray.core.measurement import read_measurement  # noqa: E402


def _details(row: dict) -> dict:
    """What a failure needs: candidates before, everything the fit returned, worst tests after."""
    before, after = row.pop("_before"), row.pop("_after")
    cands = [[t.effect, t.gyro, round(float(t.z), 2), before.significant(t),
              None if t.explained_by is None else list(t.explained_by)] for t in before.candidates[:6]]
    worst = sorted(after.tests, key=lambda t: -t.z if np.isfinite(t.z) else math.inf)[:5]
    fit = after.fits.get((row["effect"], row["gyro"]))
    fitted = None
    if fit is not None:
        fitted = {k: (np.round(np.asarray(v, float), 6).tolist(),
                      np.round(np.nan_to_num(np.asarray(fit.sigma.get(k, np.nan) if fit.sigma.get(k) is not None
                                                        else np.nan, float)), 6).tolist())
                  for k, v in fit.params.items() if np.asarray(v).dtype.kind in "fiu"}
    return {"candidates_before": cands, "z_crit_before": round(float(before.z_crit), 2),
            "fitted_all": fitted, "after_worst5": [[t.kind, t.effect, t.gyro, round(float(t.z), 2),
                                                    t.evidence[:160]] for t in worst],
            "z_crit_after": round(float(after.z_crit), 2)}


def score_indep(effect: str, seed: int, n_runs: int = 20, keep_dir=None) -> dict:
    """Generate, write, read back and score one independent case."""
    case = gen.make_case(effect, seed)
    params = gen.effect_params(case)
    with tempfile.TemporaryDirectory() as tmp:
        path = gen.write_case(case, keep_dir or tmp)
        m = read_measurement(path)
    row = score_measurement(m, effect, case["gyro"], params, case["layout_name"], n_runs,
                            seed=seed, keep=True)
    row["baseline"] = {k: np.round(v, 3).tolist() for k, v in case["baseline"].items()}
    row["bookkeeping"] = {k: v for k, v in case["params"].items() if k in gen.BOOKKEEPING}
    row["not_returned"] = sorted(k for k in params if (effect, k) not in NOT_SCORED
                                 and k not in row["fit"])
    if effect in gen.FAULTS and row["not_returned"]:
        row["param_ok"] = False               # e.g. fault_stuck: start_s is its only parameter
    row["details"] = _details(row)
    return row


def _ok(r: dict) -> bool:
    return bool(r["found"] and r["consistent_after"] and r["param_ok"])


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--first-seed", type=int, default=500)
    ap.add_argument("--effects", default=",".join(gen.EFFECTS))
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--json", default=None)
    ap.add_argument("--keep", default=None, help="also keep the generated files in this directory")
    ap.add_argument("--bandwidth-method", default=gen.BANDWIDTH_METHOD,
                    help="generator's discretisation of the bandwidth filter (diagnosis)")
    ap.add_argument("--quantization-method", default=gen.QUANTIZATION_METHOD,
                    choices=["round", "white"], help="generator's quantizer (diagnosis)")
    a = ap.parse_args(argv)
    gen.BANDWIDTH_METHOD, gen.QUANTIZATION_METHOD = a.bandwidth_method, a.quantization_method
    rows = []
    for effect in a.effects.split(","):
        for s in range(a.first_seed, a.first_seed + a.seeds):
            r = score_indep(effect, s, a.runs, a.keep)
            rows.append(r)
            flag = "ok " if _ok(r) else "BAD"
            print(f"{flag} {effect:<19} g={r['gyro']!s:<4} {r['layout']:<10} seed {s}: top {r['top']} "
                  f"rank {r['rank']} D {r['d_before']:.2f} -> {r['d_after']:.2f} found {r['found']} "
                  f"falls {r['falls']} cons {r['consistent_after']} param {r['param_ok']} {r['fit']} "
                  f"not-returned {r['not_returned']} after-worst {r['after_worst']} ({r['seconds']} s)",
                  flush=True)
            if not _ok(r):
                d = r["details"]
                print(f"    set {r['params']} {r['bookkeeping']}")
                print(f"    candidates before (z_crit {d['z_crit_before']}): {d['candidates_before']}")
                print(f"    fitted {d['fitted_all']}")
                for w in d["after_worst5"]:
                    print(f"    after {w}")
    return summarise(rows, a.json, all_ok=_ok)


if __name__ == "__main__":
    main(sys.argv[1:])
    sys.exit(0)
