"""Named checks of the explanations offered for a disagreement with a paper.

An explanation is printed only with the simulation that tests it. Each
``[[experiment.check]]`` of ``scenarios/paper_values.toml`` states a
hypothesis and the change to the experiment's scenario that expresses it::

    [[experiment.check]]
    name = "p003_t3_m019_both_correlated"      # how the report names the simulation
    hypothesis = "The paper correlated the ARW too (rho_arw = rho_rrw = -0.19)."
    effects = [{ effect = "correlation", rho_arw = -0.19, rho_rrw = -0.19 }]  # replace these effects
    estimator_params = { bandwidth_hz = 0.5 }   # optional: the estimator's hyperparameters
    runs = 20                                   # optional (default 20)
    values = [{ axis = "z", metric = "arw_deg_rt_h", value = 0.0203 }]   # the paper's numbers

The report runs the changed scenario ``runs`` times through the same chain
as the paper reproduction (same metrics, same Allan fits; seeds from the
check's name) and compares each paper value with the changed model's 95 %
band (2.5–97.5 percentiles of its runs). The check **supports** the
hypothesis when every paper value lies inside the changed model's band,
and **does not support** it otherwise. The shipped model's band, when the
reproduction sweep has it, is shown beside.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from gyroarray.chain.check import scenarios_dir
from gyroarray.core.errors import InputError

__all__ = ["METRICS", "check_entry", "run_check", "MIN_RUNS"]

#: Metrics a check may name: result columns of the chain (gyroarray.chain.run.score).
METRICS = ("sigma_1_deg_s", "rms_deg_s", "mean_error_deg_s", "arw_deg_rt_h", "rrw_deg_h_rt_h",
           "bi_deg_h", "attenuation", "phase_deg", "noise_density_deg_s_rt_hz")
#: Fewest runs for a 95 % percentile band.
MIN_RUNS = 20
_KEYS = {"name", "hypothesis", "effects", "estimator_params", "values", "runs"}


def check_entry(c, where: str, file: str) -> dict:
    """Validate one ``[[experiment.check]]`` table; InputError names the key."""
    if not isinstance(c, dict):
        raise InputError("a check must be a table", file=file, column=where)
    bad = sorted(set(c) - _KEYS)
    if bad:
        raise InputError(f"unknown key {bad[0]!r} (known: {', '.join(sorted(_KEYS))})", file=file,
                         column=f"{where}.{bad[0]}")
    for key in ("name", "hypothesis"):
        if not isinstance(c.get(key), str) or not c[key].strip():
            raise InputError(f"{key} must be a non-empty string", file=file, column=f"{where}.{key}")
    if not isinstance(c.get("effects", []), list):
        raise InputError("effects must be an array of effect tables", file=file, column=f"{where}.effects")
    if not isinstance(c.get("estimator_params", {}), dict):
        raise InputError("estimator_params must be a table", file=file,
                         column=f"{where}.estimator_params")
    runs = c.get("runs", MIN_RUNS)
    if not (isinstance(runs, int) and not isinstance(runs, bool) and MIN_RUNS <= runs <= 1000):
        raise InputError(f"runs must be a whole number from {MIN_RUNS} (a 95 % band) to 1000",
                         file=file, column=f"{where}.runs")
    vals = c.get("values")
    if not isinstance(vals, list) or not vals:
        raise InputError("values must be a non-empty array", file=file, column=f"{where}.values")
    for j, v in enumerate(vals):
        ok = (isinstance(v, dict) and v.get("axis") in ("x", "y", "z") and v.get("metric") in METRICS
              and isinstance(v.get("value"), (int, float)) and not isinstance(v.get("value"), bool))
        if not ok:
            raise InputError(f"values[{j}] must be {{ axis = x|y|z, metric = one of "
                             f"{', '.join(METRICS)}, value = number }}", file=file,
                             column=f"{where}.values[{j}]")
    try:
        from gyroarray.effects.model import NoiseModel  # lazy: loads numba
        NoiseModel.from_toml({"effects": c.get("effects", [])})
    except InputError as err:
        raise InputError(err.message, file=file, column=f"{where}.effects") from None
    return c


def _scenario(ref: str, base: Path | None):
    from gyroarray.sim.scenario import load_scenario  # lazy: loads mujoco, numba
    for folder in ([base] if base is not None else []) + [Path(scenarios_dir())]:
        f = folder / f"{ref}.toml"
        if f.is_file():
            return load_scenario(f)
    raise InputError(f"scenario {ref!r} not found")


def _band(x):
    x = np.asarray([v for v in x if v is not None and np.isfinite(v)], dtype=float)
    if x.size < MIN_RUNS:
        return None, None, x
    return float(np.percentile(x, 2.5)), float(np.percentile(x, 97.5)), x


def run_check(experiment: dict, check: dict, *, shipped_rows=None, base: Path | None = None) -> dict:
    """Run the experiment's scenario as the check changes it and set the paper beside its band.

    Parameters
    ----------
    experiment : dict
        ``scenario`` and ``estimator`` of the experiment.
    check : dict
        One validated ``[[experiment.check]]``.
    shipped_rows : pandas.DataFrame, optional
        The reproduction sweep's rows of this experiment (the shipped model's band).
    base : Path, optional
        Folder to look for the scenario first (the values file's folder).

    Returns
    -------
    dict
        ``name``, ``hypothesis``, ``simulation`` (what was run), ``rows``:
        [{"axis", "metric", "paper", "changed_low", "changed_high",
        "changed_mean", "shipped_low", "shipped_high", "inside"}], ``verdict``.
    """
    from dataclasses import replace
    from gyroarray.chain.run import run_replicates  # lazy: loads numba, pandas
    from gyroarray.effects.model import NoiseModel  # lazy: loads numba
    sc = _scenario(experiment["scenario"], base)
    new = NoiseModel.from_toml({"effects": check.get("effects", [])})
    replaced = {e.effect for e in new.entries}
    entries = tuple(e for e in sc.model.entries if e.effect not in replaced) + tuple(new.entries)
    model = NoiseModel(entries, description=check["name"])
    model.check(sc.layout.n_gyros)
    changed = replace(sc, model=model)
    est = experiment["estimator"]
    params = dict(check.get("estimator_params", {}))
    runs = int(check.get("runs", MIN_RUNS))
    seed = int.from_bytes(hashlib.sha256(check["name"].encode()).digest()[:8], "little") >> 1
    rep = run_replicates(changed, [est], replicates=runs, seed=seed, predict=False,
                         params={est: params} if params else None)
    rows, inside = [], []
    for v in check["values"]:
        vals = []
        for r in rep.runs:
            t = r.table
            row = t[(t.estimator == est) & (t.axis == v["axis"])]
            x = row[v["metric"]].iloc[0] if len(row) else None
            vals.append(None if x is None else float(x))
        lo, hi, x = _band(vals)
        s_lo = s_hi = None
        if shipped_rows is not None and v["metric"] in shipped_rows:
            sel = shipped_rows[shipped_rows.axis == v["axis"]][v["metric"]].to_numpy(float)
            s_lo, s_hi, _ = _band(sel)
        ok = None if lo is None else bool(lo <= v["value"] <= hi)
        rows.append({"axis": v["axis"], "metric": v["metric"], "paper": float(v["value"]),
                     "changed_mean": float(np.mean(x)) if x.size else None,
                     "changed_low": lo, "changed_high": hi, "shipped_low": s_lo,
                     "shipped_high": s_hi, "inside": ok})
        inside.append(ok)
    what = "; ".join(f"{e.effect} " + ", ".join(f"{k} = {val}" for k, val in e.params.items())
                     for e in new.entries) or "the noise as shipped"
    if params:
        what += f"; {est} with " + ", ".join(f"{k} = {v}" for k, v in params.items())
    verdict = ("supports" if all(inside) else "does not support") if None not in inside else "undetermined"
    return {"name": check["name"], "hypothesis": " ".join(check["hypothesis"].split()),
            "simulation": f"{experiment['scenario']} with {what}, {runs} runs (seed {seed})",
            "rows": rows, "verdict": verdict}
