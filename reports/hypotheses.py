"""Named checks of the explanations offered for a disagreement with a paper.

An explanation is printed only with the simulation that tests it. Each
``[[experiment.check]]`` of ``scenarios/paper_values.toml`` states a
hypothesis and the change to the experiment's scenario that expresses it::

    [[experiment.check]]
    name = "p003_t3_m019_both_correlated"      # how the report names the simulation
    hypothesis = "The paper correlated the ARW too (rho_arw = rho_rrw = -0.19)."
    effects = [{ effect = "correlation", rho_arw = -0.19, rho_rrw = -0.19 }]  # replace these effects
    estimator_params = { bandwidth_hz = 0.5 }   # optional: the estimator's hyperparameters
    values = [{ axis = "z", metric = "arw_long_deg_rt_h", value = 0.0203 }]   # the paper's numbers

The report predicts the metrics (:mod:`gyroarray.predict`: exact
expectations, no seed) for the scenario as shipped and as changed, and
says what the change gave beside the paper: it **supports** the hypothesis
when every value moves at least half-way from the shipped model's
prediction to the paper's, otherwise it **does not support** it.
"""

from __future__ import annotations

from pathlib import Path

from gyroarray.errors import InputError

__all__ = ["METRICS", "check_entry", "run_check"]

#: Metrics a check may name: the predictor's per-axis outputs.
METRICS = ("rms_deg_s", "std_deg_s", "mean_deg_s", "angle_deg", "amplitude_ratio", "phase_deg",
           "arw_long_deg_rt_h", "rrw_long_deg_h_rt_h", "bi_long_deg_h", "dc_gain")
_KEYS = {"name", "hypothesis", "effects", "estimator_params", "values"}


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
        from gyroarray.sim.model import NoiseModel
        NoiseModel.from_toml({"effects": c.get("effects", [])})
    except InputError as err:
        raise InputError(err.message, file=file, column=f"{where}.effects") from None
    return c


def _scenario(ref: str):
    from gyroarray.check import scenarios_dir
    from gyroarray.sim.scenario import load_scenario
    return load_scenario(Path(scenarios_dir()) / f"{ref}.toml")


def _predict(scenario, model, estimator: str, params: dict):
    from gyroarray.chain import _with_swing, swing_frequency
    from gyroarray.estimators import get_estimator
    from gyroarray.predict import predict
    from gyroarray.sim.truth import compute_truth
    dt = 1.0 / scenario.sample_rate_hz
    truth = compute_truth(scenario.profile, scenario.sample_rate_hz, duration_s=scenario.duration_s)
    est = get_estimator(estimator)(**params).fit(scenario.layout, model, dt)
    p = predict(est, model, n_samples=truth.time_s.size, truth_rad_s=truth.omega_body_rad_s)
    sw = swing_frequency(scenario.profile)
    return _with_swing(p, est, sw[0]) if sw is not None else p


def run_check(experiment: dict, check: dict) -> dict:
    """Predict the experiment's scenario as shipped and as the check changes it.

    Returns ``{"name", "hypothesis", "simulation", "rows": [{"axis", "metric",
    "paper", "shipped", "changed", "toward"}], "verdict"}``.
    """
    from gyroarray.sim.model import ModelEntry, NoiseModel
    sc = _scenario(experiment["scenario"])
    new = NoiseModel.from_toml({"effects": check.get("effects", [])})
    replaced = {e.effect for e in new.entries}
    entries = tuple(e for e in sc.model.entries if e.effect not in replaced) + tuple(new.entries)
    changed_model = NoiseModel(entries, description=f"{check['name']}")
    changed_model.check(sc.layout.n_gyros)
    params = dict(check.get("estimator_params", {}))
    base = _predict(sc, sc.model, experiment["estimator"], {})
    mod = _predict(sc, changed_model, experiment["estimator"], params)
    rows, toward = [], []
    for v in check["values"]:
        b = base.axes[v["axis"]][v["metric"]]
        m = mod.axes[v["axis"]][v["metric"]]
        ok = None if b is None or m is None else abs(m - v["value"]) <= 0.5 * abs(b - v["value"])
        rows.append({"axis": v["axis"], "metric": v["metric"], "paper": float(v["value"]),
                     "shipped": b, "changed": m, "toward": ok})
        toward.append(bool(ok))
    what = ", ".join(f"{e.effect} " + ", ".join(f"{k} = {val}" for k, val in e.params.items())
                     for e in new.entries) or "no noise change"
    if params:
        what += "; " + experiment["estimator"] + " with " + ", ".join(f"{k} = {v}" for k, v in params.items())
    return {"name": check["name"], "hypothesis": " ".join(check["hypothesis"].split()),
            "simulation": f"{experiment['scenario']} with {what} (analytic predictor, expectations)",
            "rows": rows, "verdict": "supports" if all(toward) else "does not support"}
