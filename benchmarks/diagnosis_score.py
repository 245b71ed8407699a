"""Score ``gyroarray diagnose`` / ``fit`` the way the held-out set will: many effects, layouts, parameters.

Not a speed benchmark (``make bench`` does not run it): ``make score``, or
``python benchmarks/diagnosis_score.py [--seeds 2] [--effects a,b] [--json F]``.

The cases are :func:`gyroarray.sim.cases.single_effect_case`: records shaped
like the practice measurements, random conical layouts and per-gyro noise,
one hidden effect with random parameters. Per case, as a user would:
``analyse`` (diagnose) → is the top candidate the effect (and gyro) that
was set, and significant? → ``fit --add`` that effect → does D fall by
≥ 50 % and end consistent, is every parameter within 10 % or 2σ of the
value set (the issue's rule)?
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import numpy as np

from gyroarray.chain.compare import ModelComparison
from gyroarray.sim.cases import EFFECTS, NOT_SCORED, single_effect_case


def score_case(effect: str, seed: int, n_runs: int = 20) -> dict:
    """Diagnose and fit one case; the row of the score table."""
    c = single_effect_case(effect, seed)
    return score_measurement(c.measurement, effect, c.gyro, c.params, c.layout_name, n_runs, seed=seed)


def score_measurement(m, effect: str, gyro, params: dict, layout_name: str, n_runs: int = 20, *,
                      seed=None, keep: bool = False) -> dict:
    """Diagnose and fit one measurement whose hidden effect is known; the row of the score table.

    Shared with ``benchmarks/independent_score.py`` (records of an
    independent generator). ``keep=True`` adds the two analyses as
    ``_before``/``_after`` for callers that want more than the row.
    """
    t0 = time.perf_counter()
    before, after = ModelComparison(m, n_runs=n_runs).fit([(effect, gyro)])
    secs = time.perf_counter() - t0
    top = before.candidates[0]
    fit = after.fits.get((effect, gyro))
    param_ok, detail = True, {}
    for k, want in params.items():
        if (effect, k) in NOT_SCORED or fit is None or k not in fit.params:
            continue
        wants = np.atleast_1d(np.asarray(want, float))
        gots = np.atleast_1d(np.asarray(fit.params[k], float))
        sigs = np.nan_to_num(np.atleast_1d(np.asarray(fit.sigma.get(k, 0.0) or 0.0, float)))
        sigs = np.broadcast_to(sigs, wants.shape)
        for w, g_, s_ in zip(wants, gots, sigs):
            err = abs((g_ - w + 180.0) % 360.0 - 180.0) if k == "tilt_azimuth_deg" else abs(g_ - w)
            param_ok &= bool(err <= max(0.10 * abs(w), 2.0 * s_))
        detail[k] = (np.round(wants, 6).tolist(), np.round(gots, 6).tolist(), np.round(sigs, 6).tolist())
    rank = next((i for i, t in enumerate(before.candidates) if (t.effect, t.gyro) == (effect, gyro)), -1)
    worst = sorted(after.tests, key=lambda t: -t.z if np.isfinite(t.z) else math.inf)[:2]
    row = {"effect": effect, "gyro": gyro, "seed": seed, "layout": layout_name, "params": params,
           "top": [top.effect, top.gyro, round(float(top.z), 2)], "rank": rank,
           "found": (top.effect, top.gyro) == (effect, gyro) and before.significant(top),
           "d_before": round(before.discrepancy, 3), "d_after": round(after.discrepancy, 3),
           "falls": after.discrepancy <= 0.5 * before.discrepancy, "consistent_after": after.consistent,
           "param_ok": bool(param_ok), "fit": detail, "seconds": round(secs, 1),
           "after_worst": [[t.effect, t.gyro, round(float(t.z), 2)] for t in worst]}
    if keep:
        row["_before"], row["_after"] = before, after
    return row


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
            r = score_case(effect, s, a.runs)
            rows.append(r)
            flag = "ok " if r["found"] and r["consistent_after"] and r["param_ok"] else "BAD"
            print(f"{flag} {effect:<19} g={r['gyro']!s:<4} {r['layout']:<6} seed {s}: top {r['top']} "
                  f"rank {r['rank']} D {r['d_before']:.2f} -> {r['d_after']:.2f} "
                  f"cons {r['consistent_after']} param {r['param_ok']} {r['fit']} "
                  f"after-worst {r['after_worst']} ({r['seconds']} s)", flush=True)
    return summarise(rows, a.json)


def summarise(rows: list, json_path=None, **extra) -> dict:
    """Count the rows that pass each check, print the summary, write rows and summary to
    ``json_path``; ``extra``: more counts (name -> per-row predicate)."""
    summary = {k: sum(bool(r[k]) for r in rows) for k in ("found", "falls", "consistent_after", "param_ok")}
    summary.update({k: sum(bool(ok(r)) for r in rows) for k, ok in extra.items()})
    summary["cases"] = len(rows)
    print("summary:", summary)
    if json_path:
        with open(json_path, "w") as fh:
            json.dump({"summary": summary, "rows": rows}, fh, indent=1, default=str)
    return summary


if __name__ == "__main__":
    main(sys.argv[1:])
    sys.exit(0)
