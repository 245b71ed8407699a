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

The chain (:func:`run_check`) runs the changed scenario ``runs`` times through the same chain
as the paper reproduction (same metrics, same Allan fits; seeds from the
check's name) and compares each paper value with the changed model's 95 %
band (2.5–97.5 percentiles of its runs). The check **supports** the
hypothesis when every paper value lies inside the changed model's band,
and **does not support** it otherwise. The shipped model's band, when the
reproduction sweep has it, is shown beside.

The result is a :class:`HypothesisCheck` (JSON through ``to_dict``/``from_dict``);
:func:`run_checks` computes each check once and keeps it in a
:class:`~gyroarray.core.result_cache.ResultCache` (``hypotheses.json`` in the
reproduction sweep's folder), keyed by a hash of the check's table, the
experiment's scenario file and estimator and the package version: the design
report re-renders from it without running the chain again, and a changed input
is recomputed, never read stale.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from gyroarray.chain.check import scenarios_dir
from gyroarray.chain.run import run_replicates
from gyroarray.core.errors import InputError
from gyroarray.core.result_cache import ResultCache, file_digest, input_key
from gyroarray.effects.model import NoiseModel

__all__ = ["METRICS", "MIN_RUNS", "CHECKS_FILE", "CheckRow", "HypothesisCheck", "check_entry",
           "run_check", "run_checks"]

#: Metrics a check may name: result columns of the chain (gyroarray.chain.run.score).
METRICS = ("sigma_1_deg_s", "rms_deg_s", "mean_error_deg_s", "arw_deg_rt_h", "rrw_deg_h_rt_h",
           "bi_deg_h", "attenuation", "phase_deg", "noise_density_deg_s_rt_hz",
           "estimator_amplitude_ratio")
#: Fewest runs for a 95 % percentile band.
MIN_RUNS = 20
#: The saved checks in a reproduction sweep's folder.
CHECKS_FILE = "hypotheses.json"
_KEYS = {"name", "hypothesis", "effects", "estimator_params", "values", "runs"}


@dataclass
class CheckRow:
    """One paper value of a check beside the changed (and the shipped) model's band.

    Attributes
    ----------
    axis : str
        ``x``, ``y`` or ``z``.
    metric : str
        A chain result column (:data:`METRICS`); its unit is in its name (``_deg_s``, ...).
    paper : float
        The paper's value, in the metric's unit.
    changed_mean : float or None
        Mean of the changed model's runs, in the metric's unit.
    changed_low, changed_high : float or None
        2.5 and 97.5 percentiles of the changed model's runs (None: fewer than
        :data:`MIN_RUNS` finite runs).
    shipped_low, shipped_high : float or None
        The same band of the shipped model (the reproduction sweep's runs), when given.
    inside : bool or None
        The paper value lies in the changed model's band (None: no band).
    """

    axis: str
    metric: str
    paper: float
    changed_mean: float | None
    changed_low: float | None
    changed_high: float | None
    shipped_low: float | None = None
    shipped_high: float | None = None
    inside: bool | None = None

    def to_dict(self) -> dict:
        """JSON-ready dict (the keys are the attributes)."""
        return {"axis": self.axis, "metric": self.metric, "paper": self.paper,
                "changed_mean": self.changed_mean, "changed_low": self.changed_low,
                "changed_high": self.changed_high, "shipped_low": self.shipped_low,
                "shipped_high": self.shipped_high, "inside": self.inside}

    @classmethod
    def from_dict(cls, d: dict) -> "CheckRow":
        """The inverse of :meth:`to_dict`."""
        return cls(axis=str(d["axis"]), metric=str(d["metric"]), paper=float(d["paper"]),
                   changed_mean=d.get("changed_mean"), changed_low=d.get("changed_low"),
                   changed_high=d.get("changed_high"), shipped_low=d.get("shipped_low"),
                   shipped_high=d.get("shipped_high"), inside=d.get("inside"))


@dataclass
class HypothesisCheck:
    """The result of one named hypothesis check: everything the report shows of it.

    Attributes
    ----------
    name, hypothesis : str
        The check's name and its hypothesis (whitespace collapsed).
    simulation : str
        What was run (scenario, changed effects, estimator parameters, runs, seed).
    runs : int
        Runs of the changed scenario.
    seed : int
        Root seed of the runs (from the check's name).
    rows : list of CheckRow
        One per paper value.
    verdict : str
        ``supports`` (every paper value inside the changed model's band),
        ``does not support`` or ``undetermined`` (a band missing).
    """

    name: str
    hypothesis: str
    simulation: str
    runs: int
    seed: int
    rows: list[CheckRow] = field(default_factory=list)
    verdict: str = "undetermined"

    def to_dict(self) -> dict:
        """JSON-ready dict; ``rows`` as :meth:`CheckRow.to_dict`."""
        return {"name": self.name, "hypothesis": self.hypothesis, "simulation": self.simulation,
                "runs": int(self.runs), "seed": int(self.seed),
                "rows": [r.to_dict() for r in self.rows], "verdict": self.verdict}

    @classmethod
    def from_dict(cls, d: dict) -> "HypothesisCheck":
        """The inverse of :meth:`to_dict`."""
        return cls(name=str(d["name"]), hypothesis=str(d["hypothesis"]),
                   simulation=str(d["simulation"]), runs=int(d["runs"]), seed=int(d["seed"]),
                   rows=[CheckRow.from_dict(r) for r in d["rows"]], verdict=str(d["verdict"]))

    def with_shipped(self, shipped_rows) -> "HypothesisCheck":
        """A copy with the shipped model's band of each row from the reproduction sweep's rows.

        Parameters
        ----------
        shipped_rows : pandas.DataFrame or None
            The sweep's rows of this experiment (its estimator); None: no shipped band.
        """
        rows = []
        for r in self.rows:
            lo = hi = None
            if shipped_rows is not None and r.metric in shipped_rows:
                sel = shipped_rows[shipped_rows.axis == r.axis][r.metric].to_numpy(float)
                lo, hi, _ = _band(sel)
            rows.append(replace(r, shipped_low=lo, shipped_high=hi))
        return replace(self, rows=rows)


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
        NoiseModel.from_toml({"effects": c.get("effects", [])})
    except InputError as err:
        raise InputError(err.message, file=file, column=f"{where}.effects") from None
    return c


def _scenario_file(ref: str, base: Path | None) -> Path:
    for folder in ([base] if base is not None else []) + [Path(scenarios_dir())]:
        f = folder / f"{ref}.toml"
        if f.is_file():
            return f
    raise InputError(f"scenario {ref!r} not found")


def _band(x):
    x = np.asarray([v for v in x if v is not None and np.isfinite(v)], dtype=float)
    if x.size < MIN_RUNS:
        return None, None, x
    return float(np.percentile(x, 2.5)), float(np.percentile(x, 97.5)), x


def check_key(experiment: dict, check: dict, base: Path | None = None) -> str:
    """The hash of a check's inputs: its table, the experiment's scenario file and estimator.

    Raises
    ------
    InputError
        The experiment's scenario file is not found.
    """
    f = _scenario_file(experiment["scenario"], base)
    return input_key("hypothesis", experiment["scenario"], experiment["estimator"], check,
                     file_digest(f))


def run_check(experiment: dict, check: dict, *, shipped_rows=None, base: Path | None = None,
              cache: ResultCache | None = None) -> HypothesisCheck:
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
    cache : ResultCache, optional
        Saved checks: a check of the same inputs (:func:`check_key`) is read
        from it, not run; a new one is added to it.

    Returns
    -------
    HypothesisCheck
    """
    key = check_key(experiment, check, base) if cache is not None else ""
    hit = cache.get(key) if cache is not None else None
    if hit is not None:
        try:
            return HypothesisCheck.from_dict(hit).with_shipped(shipped_rows)
        except (KeyError, TypeError, ValueError):
            pass                            # a damaged entry: run it again and replace it
    res = _run(experiment, check, base)
    if cache is not None:
        cache.put(key, res.to_dict())
    return res.with_shipped(shipped_rows)


def run_checks(experiment: dict, *, shipped_rows=None, base: Path | None = None,
               cache: ResultCache | None = None) -> list[HypothesisCheck | InputError]:
    """Every check of an experiment (:func:`run_check`); a check that cannot run gives its InputError."""
    out: list[HypothesisCheck | InputError] = []
    for c in experiment.get("check", []):
        try:
            out.append(run_check(experiment, c, shipped_rows=shipped_rows, base=base, cache=cache))
        except InputError as err:
            out.append(err)
    return out


def _run(experiment: dict, check: dict, base: Path | None) -> HypothesisCheck:
    from gyroarray.sim.scenario import load_scenario  # lazy: loads mujoco only to run a check
    sc = load_scenario(_scenario_file(experiment["scenario"], base))
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
        ok = None if lo is None else bool(lo <= v["value"] <= hi)
        mean = float(np.mean(x)) if x.size else None
        rows.append(CheckRow(axis=v["axis"], metric=v["metric"], paper=float(v["value"]),
                             changed_mean=None if mean is None or not math.isfinite(mean) else mean,
                             changed_low=lo, changed_high=hi, inside=ok))
        inside.append(ok)
    what = "; ".join(f"{e.effect} " + ", ".join(f"{k} = {val}" for k, val in e.params.items())
                     for e in new.entries) or "the noise as shipped"
    if params:
        what += f"; {est} with " + ", ".join(f"{k} = {v}" for k, v in params.items())
    verdict = ("supports" if all(inside) else "does not support") if None not in inside else "undetermined"
    return HypothesisCheck(name=check["name"], hypothesis=" ".join(check["hypothesis"].split()),
                           simulation=f"{experiment['scenario']} with {what}, {runs} runs (seed {seed})",
                           runs=runs, seed=seed, rows=rows, verdict=verdict)
