"""Everything the design report shows, computed from saved results (issue 29: results in, pictures out).

:func:`collect_report_results` reads ``gyroarray sweep`` folders and a
``design --recommend --out`` result and gathers what
:func:`gyroarray.reports.report.render_report` draws into a :class:`ReportResults`:

* the sweeps' rows (:func:`load_sweep_dir`), the design ranking and the
  estimator comparison (:func:`design_ranking`, :func:`estimator_comparison`);
* the Allan deviation of the best static design and of paper 003's Figs. 14
  and 22 (:class:`gyroarray.sweep.adev.SweepAdev`: saved in each sweep's
  ``adev.json``, simulated only when missing or stale);
* paper vs model (:func:`paper_vs_model`) with each experiment's named
  hypothesis checks (:func:`gyroarray.chain.hypotheses.run_check`: saved in the
  reproduction sweep's ``hypotheses.json``, run only when missing or stale);
* for a design result: the recommended design's ADEV
  (:func:`gyroarray.design.evidence.cached_recommended_adev`, saved in
  ``<design stem>.adev.json`` beside it) and the GDOP robustness table.

A second report of the same inputs reads every simulated result from those
files: it renders in seconds and simulates nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from gyroarray.analysis.adev_curves import AdevFigure
from gyroarray.analysis.replicates import mean_ci
from gyroarray.chain.hypotheses import CHECKS_FILE, HypothesisCheck, check_entry, run_check
from gyroarray.core.data import data_path
from gyroarray.core.errors import InputError
from gyroarray.core.limits import read_json
from gyroarray.core.result_cache import ResultCache
from gyroarray.core.tomlio import load_toml
from gyroarray.design.evidence import (GdopRobustnessRow, adev_file, cached_recommended_adev,
                                       gdop_robustness_table)
from gyroarray.sweep.adev import SweepAdev
from gyroarray.sweep.runner import MANIFEST, load_results

__all__ = ["AGREEMENT_LEVEL", "MIN_BAND_RUNS", "SINGLE_FROM", "PAPER_ADEV", "SweepData",
           "AdevItem", "ReportResults", "load_design", "load_sweep_dir", "default_paper_values",
           "load_paper_values", "design_ranking", "estimator_comparison", "paper_vs_model",
           "collect_report_results"]

AXES = ("x", "y", "z")
#: Two-sided level of the paper-vs-model band (percentiles of the model's runs).
AGREEMENT_LEVEL = 0.95
#: Fewest model runs whose percentiles make a 95 % band (fewer: no band, no verdict).
MIN_BAND_RUNS = 20
_METRICS = ("sigma_1_deg_s", "rms_deg_s", "mean_error_deg_s", "arw_deg_rt_h", "rrw_deg_h_rt_h", "bi_deg_h",
            "noise_density_deg_s_rt_hz", "attenuation", "phase_deg", "efficiency", "reduction")
#: Single-gyro value of a metric: the estimator's value × the matching reduction column.
SINGLE_FROM = {"sigma_1_deg_s": "reduction", "arw_deg_rt_h": "arw_reduction",
                "rrw_deg_h_rt_h": "rrw_reduction", "bi_deg_h": "bi_reduction"}

# -- reading -------------------------------------------------------------------

@dataclass
class SweepData:
    """One sweep folder: its manifest and result rows."""

    path: Path
    name: str
    manifest: dict
    rows: pd.DataFrame
    missing: int = 0          # scenarios of the manifest without results (not finished)
    adev: SweepAdev | None = field(default=None, repr=False)   # its saved ADEV curves (adev.json)

    @property
    def is_paper(self) -> bool:
        """Rows that come from listed scenario files (a paper reproduction)."""
        return "scenario" in self.rows and bool((self.rows["scenario"].astype(str) != "").any())


def load_sweep_dir(path) -> SweepData:
    """Read a ``gyroarray sweep`` output folder (complete scenario files only)."""

    path = Path(path)
    man = path / MANIFEST
    if not path.is_dir():
        raise InputError("not a folder (give the --out folder of gyroarray sweep)", file=str(path))
    if not (man.exists() or man.is_symlink()):
        raise InputError(f"no {MANIFEST}: not a gyroarray sweep folder", file=str(path))
    # a regular file only (a FIFO is refused, never waited on), bounded in size and depth
    manifest = read_json(man, "sweep manifest", expect=None)     # its shape is checked below
    scenarios = manifest.get("scenarios") if isinstance(manifest, dict) else None
    if not (isinstance(scenarios, list) and all(
            isinstance(s, dict) and isinstance(s.get("id"), str) for s in scenarios)):
        raise InputError("not a gyroarray sweep manifest: it must be a JSON object whose "
                         "\"scenarios\" is a list of objects with an \"id\" (was it edited?)",
                         file=str(man))
    ids = {s["id"] for s in scenarios}
    _check_row_files(path, ids)
    rows = load_results(path)
    if rows.empty:
        raise InputError("the sweep has no finished scenario yet (rows/ is empty)",
                         file=str(path))
    if "scenario_id" not in rows:
        raise InputError("the result rows have no scenario_id column: not gyroarray sweep results",
                         file=str(path / "rows"))
    done = set(rows["scenario_id"])
    foreign = sorted(done - ids)
    if foreign:
        raise InputError(f"rows/ holds results of {len(foreign)} scenario(s) that {MANIFEST} does not "
                         f"list (e.g. {foreign[0]}): copied from another sweep? Move them out of rows/",
                         file=str(path / "rows"))
    missing = sum(1 for s in scenarios if s["id"] not in done)
    if "scenario" not in rows:
        rows["scenario"] = ""
    if "replicate" not in rows:
        rows["replicate"] = 0
    return SweepData(path=path, name=str(manifest.get("name", path.name)), manifest=manifest,
                     rows=rows, missing=missing, adev=SweepAdev(path, manifest))


def _check_row_files(path: Path, ids: set) -> None:
    """Every ``rows/<id>.parquet`` belongs to the manifest and has the schema of the others."""
    import pyarrow.parquet as pq  # lazy: pyarrow.parquet only to check the row files' schemas
    files = sorted((path / "rows").glob("*.parquet")) if (path / "rows").is_dir() else []
    schema, first = None, None
    for f in files:
        if f.stem not in ids:
            raise InputError("a result file of a scenario that sweep.json does not list (copied "
                             "from another sweep?); move it out of rows/", file=str(f))
        try:
            names = sorted(pq.read_schema(f).names)
        except Exception:      # a broken footer: load_results names it with the way out
            continue
        if schema is None:
            schema, first = names, f
        elif names != schema:
            assert first is not None                           # set with schema
            diff = sorted(set(names) ^ set(schema))
            raise InputError(f"its columns differ from those of {first.name} ({', '.join(diff[:5])}): "
                             "not a result of this sweep; move it out of rows/", file=str(f))


def default_paper_values() -> Path:
    """The shipped ``scenarios/paper_values.toml``."""
    return Path(str(data_path("scenarios"))) / "paper_values.toml"


def load_paper_values(path=None) -> list[dict]:
    """The experiments of a paper-values file (see the file's header), checked."""
    path = Path(path) if path is not None else default_paper_values()
    data = load_toml(path, "paper values file").data
    exps = data.get("experiment")
    if not isinstance(exps, list) or not exps:
        raise InputError("no [[experiment]] tables", file=str(path))
    for i, e in enumerate(exps):
        where = f"experiment[{i}]"
        for key, typ in (("title", str), ("scenario", str), ("estimator", str), ("values", list)):
            if not isinstance(e.get(key), typ):
                raise InputError(f"{where}.{key} is missing or not a {typ.__name__}",
                                 file=str(path), column=f"{where}.{key}")
        for j, v in enumerate(e["values"]):
            ok = (isinstance(v, dict) and v.get("axis") in (*AXES, "single")
                  and v.get("metric") in _METRICS and isinstance(v.get("value"), (int, float))
                  and not isinstance(v.get("value"), bool))
            if not ok or (v["axis"] == "single" and v["metric"] not in SINGLE_FROM):
                raise InputError(f"{where}.values[{j}] must be {{ axis = x|y|z|single, metric = "
                                 f"one of {', '.join(_METRICS)} (single: {', '.join(SINGLE_FROM)}),"
                                 f" value = number }}, got {v!r}", file=str(path),
                                 column=f"{where}.values[{j}]")
        checks = e.get("check", [])
        if not isinstance(checks, list):
            raise InputError(f"{where}.check must be an array of tables ([[experiment.check]])",
                             file=str(path), column=f"{where}.check")
        for j, c in enumerate(checks):
            check_entry(c, f"{where}.check[{j}]", str(path))
    return exps


# -- tables --------------------------------------------------------------------

_DESIGN_KEYS = ["motion", "scheme", "n_gyros", "alpha_deg", "rho_arw", "rho_rrw", "effects",
                "estimator"]


def design_ranking(rows: pd.DataFrame) -> pd.DataFrame:
    """One row per design × estimator, ranked within each motion and correlation (ρ is a condition).

    Means over the body axes and the replicates: ``sigma_1_deg_s`` (the run's
    1σ, its mean removed), ``rms_deg_s`` (RMS about the truth, paper 002 Eq. 19:
    1σ and mean error together), ``arw_deg_rt_h`` and ``rrw_deg_h_rt_h`` (Allan
    fits of the filtered output: they hold at the estimator's bandwidth);
    ``ci_low``/``ci_high``: the 95 % interval of the mean 1σ over the runs
    (None with one run); ``resolved``: the interval lies above the best
    design's (None when either has one run); ``attenuation`` is the one
    farthest from 1 over the swinging axes; ``runs`` the number of scenario
    runs; ``rank`` within the motion and ρ. The offline ``bound`` is not a
    design choice and is left out.
    """
    df = rows[rows.estimator != "bound"].copy()
    df = df.assign(**{k: df[k].astype(object).where(df[k].notna(), "none")
                      for k in ("scheme", "rho_arw", "rho_rrw")})
    if "rms_deg_s" not in df:
        df["rms_deg_s"] = np.sqrt(df.sigma_1_deg_s ** 2 + df.mean_error_deg_s ** 2)
    g = df.groupby(_DESIGN_KEYS, sort=False, dropna=False)
    att = g["attenuation"].agg(lambda a: np.nan if a.isna().all()
                               else float(a.dropna().iloc[np.argmax(np.abs(a.dropna() - 1.0))]))
    per_run = g.apply(lambda x: x.groupby("scenario_id").sigma_1_deg_s.mean().to_list(),
                      include_groups=False).rename("per_run")
    out = g.agg(sigma_1_deg_s=("sigma_1_deg_s", "mean"), rms_deg_s=("rms_deg_s", "mean"),
                arw_deg_rt_h=("arw_deg_rt_h", "mean"), rrw_deg_h_rt_h=("rrw_deg_h_rt_h", "mean"),
                reduction=("reduction", "mean"), runs=("scenario_id", "nunique")
                ).join(att).join(per_run).reset_index()
    cis = [mean_ci(v) for v in out.per_run]
    out["ci_low"] = [c["ci_low"] for c in cis]
    out["ci_high"] = [c["ci_high"] for c in cis]
    out = out.drop(columns="per_run")
    cond = ["motion", "rho_arw", "rho_rrw"]
    out = out.sort_values(cond + ["sigma_1_deg_s"], kind="stable")
    out["rank"] = out.groupby(cond, sort=False).cumcount() + 1
    best_hi = out.groupby(cond, sort=False).ci_high.transform("first")
    out["resolved"] = [None if pd.isna(lo) or pd.isna(h) else bool(lo > h)
                       for lo, h in zip(out.ci_low, best_hi)]
    out.loc[out["rank"] == 1, "resolved"] = None
    return out.reset_index(drop=True)


def estimator_comparison(rows: pd.DataFrame) -> pd.DataFrame:
    """Per motion and estimator: medians over designs, axes and runs.

    ``sigma_1_deg_s``, ``reduction``, ``attenuation`` and ``phase_deg`` (swinging
    axes only), ``efficiency`` (1σ of the bound / 1σ of the estimator; needs
    ``bound`` in the sweep) and its minimum.
    """
    g = rows.groupby(["motion", "estimator"], sort=True)
    out = g.agg(sigma_1_deg_s=("sigma_1_deg_s", "median"), reduction=("reduction", "median"),
                attenuation=("attenuation", "median"), phase_deg=("phase_deg", "median"),
                efficiency=("efficiency", "median"), efficiency_min=("efficiency", "min"),
                runs=("scenario_id", "nunique"))
    return out.reset_index()


def paper_vs_model(rows: pd.DataFrame, experiments: list[dict]) -> list[dict]:
    """Each experiment with its values beside the model's spread over the replicates.

    Returns a list of ``{"title", "scenario", "estimator", "runs", "flagged",
    "checks", "values": [{"axis", "metric", "paper", "model_mean", "model_sd",
    "model_min", "model_max", "n", "ratio", "low", "high", "flag"}]}`` for the
    experiments whose scenario is in ``rows``. ``low``/``high``: the 2.5 and
    97.5 percentiles of the model's runs, where one more run falls with 95 %
    probability (a band of positive runs never reaches below zero); with
    fewer than :data:`MIN_BAND_RUNS` runs there is no band and ``flag`` is
    None (undetermined). ``flag``: the paper's value is outside the band.
    ``ratio`` = paper / model mean. ``checks``: the experiment's named
    hypothesis checks (scenarios/paper_values.toml), run by the report.
    """
    out = []
    for e in experiments:
        sub = rows[(rows.scenario == e["scenario"]) & (rows.estimator == e["estimator"])]
        if sub.empty:
            continue
        vals = []
        for v in e["values"]:
            if v["axis"] == "single":
                per_run = (sub[v["metric"]] * sub[SINGLE_FROM[v["metric"]]]).groupby(
                    sub.scenario_id).mean()
            else:
                per_run = sub[sub.axis == v["axis"]].set_index("scenario_id")[v["metric"]]
            x = per_run.dropna().to_numpy(float)
            n = x.size
            mean = float(np.mean(x)) if n else math.nan
            sd = float(np.std(x, ddof=1)) if n > 1 else math.nan
            if n >= MIN_BAND_RUNS:
                q = 100.0 * (1.0 - AGREEMENT_LEVEL) / 2.0
                low, high = (float(np.percentile(x, q)), float(np.percentile(x, 100.0 - q)))
                flag = not (low <= v["value"] <= high)
            else:
                low = high = math.nan
                flag = None
            vals.append({"axis": v["axis"], "metric": v["metric"], "paper": float(v["value"]),
                         "model_mean": mean, "model_sd": sd,
                         "model_min": float(np.min(x)) if n else math.nan,
                         "model_max": float(np.max(x)) if n else math.nan, "n": int(n),
                         "ratio": float(v["value"]) / mean if n and mean else math.nan,
                         "low": low, "high": high, "flag": flag})
        flagged = any(v["flag"] for v in vals)
        out.append({"title": e["title"], "scenario": e["scenario"], "estimator": e["estimator"],
                    "runs": int(sub.scenario_id.nunique()), "flagged": flagged,
                    "checks": list(e.get("check", [])), "values": vals})
    return out


# -- the results of a report -----------------------------------------------------

#: The paper's ADEV figures drawn from a reproduction sweep: (scenario, figure name, title).
PAPER_ADEV = (("paper003/static_s1_n6_rhob_0", "adev_fig14",
               "Paper 003 Fig. 14: 6-gyro Scheme 1, 1 h static, kf_array"),
              ("paper003/tetra_static", "adev_fig22",
               "Paper 003 Fig. 22: 4-gyro tetrahedral array (Table 8 noise), kf_array"))
#: The estimator of the paper's ADEV figures.
PAPER_ADEV_ESTIMATOR = "kf_array"


@dataclass
class AdevItem:
    """One ADEV figure of the report, or why it is missing.

    Attributes
    ----------
    name : str
        The figure's file name (``adev_best``, ``adev_fig14``, ...).
    label : str
        What it shows (its title).
    figure : AdevFigure or None
        The curves (None: not available, see ``why``).
    why : str
        Why there is no figure ("" when there is one).
    """

    name: str
    label: str
    figure: AdevFigure | None = None
    why: str = ""


@dataclass
class ReportResults:
    """Everything a design report shows (:func:`gyroarray.reports.report.render_report` draws it).

    Attributes
    ----------
    sweeps : list of SweepData
        Every sweep folder given (design sweeps and paper reproductions).
    design : dict or None
        The ``design --recommend`` result (its keys carry their units).
    design_adev : AdevFigure or None
        One simulated record of the recommended design (single gyros vs fused).
    gdop_robustness : list of GdopRobustnessRow
        GDOP alone over the design's ρ range (with a ρ range only).
    ranking : pandas.DataFrame or None
        :func:`design_ranking` of the design sweeps (None: none given).
    estimators : pandas.DataFrame or None
        :func:`estimator_comparison` of the design sweeps (or of every sweep when there is none).
    adev : list of AdevItem
        The sweeps' ADEV figures (best static design, paper 003 Figs. 14 and 22).
    paper_vs_model : list of dict
        :func:`paper_vs_model` of the reproduction sweeps; each experiment with
        ``check_results``: a :class:`~gyroarray.chain.hypotheses.HypothesisCheck`
        or the message of why the check could not run, per named check.
    notes : list of str
        Unfinished sweeps, results that could not be saved.
    """

    sweeps: list[SweepData] = field(default_factory=list)
    design: dict | None = None
    design_adev: AdevFigure | None = None
    gdop_robustness: list[GdopRobustnessRow] = field(default_factory=list)
    ranking: pd.DataFrame | None = None
    estimators: pd.DataFrame | None = None
    adev: list[AdevItem] = field(default_factory=list)
    paper_vs_model: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def paper(self) -> list[SweepData]:
        """The paper reproduction sweeps."""
        return [d for d in self.sweeps if d.is_paper]

    @property
    def design_sweeps(self) -> list[SweepData]:
        """The design sweeps."""
        return [d for d in self.sweeps if not d.is_paper]


def load_design(path) -> dict:
    """Read a ``design --recommend --out`` JSON file (checked for the keys the report needs)."""
    p = Path(path)
    # regular files only, bounded in size and depth (a FIFO or /dev/zero is refused at once)
    data = read_json(p, "design result", expect=None)
    need = ("recommended", "designs", "equivalent", "assumptions")
    if not isinstance(data, dict) or any(k not in data for k in need):
        raise InputError("not a gyroarray design --recommend result (needs keys "
                         + ", ".join(need) + ")", file=str(p))
    return data


def _sweep_adev(res: ReportResults, ranking: pd.DataFrame | None) -> None:
    """The best static design's ADEV (design sweeps) and the paper's Figs. 14 and 22."""
    done = 0
    if ranking is not None:
        static = ranking[ranking.motion.str.contains("static")]
        if not static.empty:
            best = static.iloc[0]
            for d in res.design_sweeps:
                sel = d.rows
                for k in ("scheme", "n_gyros", "alpha_deg", "motion", "estimator"):
                    sel = sel[sel[k].astype(object) == best[k]]
                if sel.empty:
                    continue
                label = (f"Best static design: scheme {best.scheme}, N = {best.n_gyros}, "
                         f"α = {best.alpha_deg:.2f}°, {best.estimator}")
                assert d.adev is not None                      # set by load_sweep_dir
                fig, why = d.adev.figure(sel.scenario_id.iloc[0], best.estimator, label)
                res.adev.append(AdevItem("adev_best", label, fig, why))
                done += 1
                break
    for scen, name, label in PAPER_ADEV:
        for d in res.paper:
            sel = d.rows[(d.rows.scenario == scen) & (d.rows.replicate == 0)]
            if sel.empty:
                continue
            assert d.adev is not None
            fig, why = d.adev.figure(sel.scenario_id.iloc[0], PAPER_ADEV_ESTIMATOR, label)
            res.adev.append(AdevItem(name, label, fig, why))
            break


def _paper(res: ReportResults, values_path) -> None:
    """Paper vs model of the reproduction sweeps, with each experiment's hypothesis checks."""
    paper = res.paper
    if not paper:
        return
    rows = pd.concat([d.rows for d in paper], ignore_index=True)
    pvm = paper_vs_model(rows, load_paper_values(values_path))
    base = Path(values_path).parent if values_path is not None else None
    cache = ResultCache(paper[0].path / CHECKS_FILE, "hypotheses")
    for e in pvm:
        shipped = rows[(rows.scenario == e["scenario"]) & (rows.estimator == e["estimator"])]
        results: list[HypothesisCheck | str] = []
        for c in e["checks"]:
            try:
                results.append(run_check(e, c, shipped_rows=shipped, base=base, cache=cache))
            except InputError as err:
                results.append(err.message)
        e["check_results"] = results
    cache.save()
    if cache.why_not:
        res.notes.append(f"the hypothesis checks could not be saved ({cache.why_not}): the next "
                         "report runs them again")
    res.paper_vs_model = pvm


def collect_report_results(dirs=(), *, design=None, paper_values=None) -> ReportResults:
    """Gather what the design report shows, from saved results where they are (module docstring).

    Parameters
    ----------
    dirs : sequence of path
        ``gyroarray sweep`` output folders (design sweeps and/or paper reproductions).
    design : path or dict, optional
        A ``gyroarray design --recommend --out`` result (a path: its ADEV curves are
        saved beside it as ``<stem>.adev.json``).
    paper_values : path, optional
        Paper values file (default: the shipped ``scenarios/paper_values.toml``).

    Returns
    -------
    ReportResults
    """
    res = ReportResults()
    design_path = Path(design) if isinstance(design, (str, Path)) else None
    res.design = load_design(design_path) if design_path is not None else design
    res.sweeps = [load_sweep_dir(d) for d in dirs]
    res.notes += [f"{d.name}: {d.missing} scenario(s) of the sweep not finished — rerun the sweep "
                  "command to complete it" for d in res.sweeps if d.missing]
    if res.design is not None:
        cache = ResultCache(adev_file(design_path) if design_path is not None else None, "adev")
        res.design_adev = cached_recommended_adev(res.design, cache)
        cache.save()
        if cache.why_not:
            res.notes.append(f"the recommended design's ADEV could not be saved ({cache.why_not})")
        if res.design.get("per_rho"):
            res.gdop_robustness = gdop_robustness_table([float(r) for r in res.design["per_rho"]])
    designs = res.design_sweeps
    if designs:
        res.ranking = design_ranking(pd.concat([d.rows for d in designs], ignore_index=True))
    if res.sweeps:
        _sweep_adev(res, res.ranking)
        for d in res.sweeps:
            assert d.adev is not None
            why = d.adev.save()
            if why:
                res.notes.append(f"{d.name}: the ADEV curves could not be saved ({why})")
        all_rows = pd.concat([d.rows for d in (designs or res.sweeps)], ignore_index=True)
        res.estimators = estimator_comparison(all_rows)
        _paper(res, paper_values)
    return res
