"""The design report: one self-contained HTML file and a Markdown twin, the decision first.

:func:`write_report` takes a ``gyroarray design --recommend --out`` result
(``design``) and/or sweep folders (``gyroarray sweep`` output: ``sweep.json``
+ ``rows/*.parquet``) and writes, top first:

* with a design result (:mod:`gyroarray.reports.decision`): the **decision**
  (array, estimator, bandwidth, predicted accuracy with the simulated check,
  runner-up, what would change the choice), the **assumptions** (each input
  and its source), and the **evidence** from the analytic predictor and its
  paired Monte-Carlo check, fault tolerance and ρ robustness;
* **GDOP vs α and vs ρ** (paper 003 Figs. 8–10; from the layouts);
* **Allan deviation of single gyros vs the fused output** with confidence
  bands and the √(3/N) reference line, for the recommended design
  (re-simulated) and, from the sweeps, the best static design and the
  paper's 6-gyro and 4-gyro static arrays (paper 003 Figs. 14 and 22);
* from design sweeps: the **design ranking** per motion and per ρ (ρ is a
  condition of the gyros, not a design choice), 1σ with its 95 % interval
  over the runs, RMS about the truth, Allan-fit ARW/RRW labelled as such;
  the **estimator comparison** (1σ, reduction, attenuation, phase lag,
  efficiency against the offline bound);
* **paper vs model** for each reproduced experiment of
  ``scenarios/paper_values.toml``: the paper's value beside the model's runs
  (mean, sd, min–max) and its 95 % band, the 2.5–97.5 percentiles of ≥ 20
  runs (where one more run falls 95 % of the time; positive like the runs),
  a flag outside it, and for a disagreement only explanations that a named
  simulation tests (:mod:`gyroarray.reports.hypotheses`).

The HTML has its figures as ``data:image/png;base64`` URIs, its style inline
and no script: it opens anywhere, offline. The Markdown twin has the same
tables and links the same figures, written as PNG files into
``<md stem>_figures/`` beside it.

Units are in the column names (deg/s, deg/√h, deg/h/√h: the datasheet edge).
"""

from __future__ import annotations

import base64
import html
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from gyroarray.core import units
from gyroarray.core import outputs
from gyroarray.core.errors import InputError
from gyroarray.core.limits import read_json
from gyroarray.reports import decision as dec
from gyroarray.reports.design_plots import _figure, _png, design_fig, plot_series
from gyroarray.reports.hypotheses import check_entry, run_check
from gyroarray.sweep.runner import MANIFEST, load_results
from gyroarray.sweep.sweep import load_sweep
from gyroarray.core.tomlio import load_toml
from gyroarray.core.data import data_path

__all__ = ["SweepData", "load_sweep_dir", "design_ranking", "estimator_comparison",
           "paper_vs_model", "load_paper_values", "write_report", "default_paper_values"]

#: Two-sided level of the paper-vs-model band (percentiles of the model's runs).
AGREEMENT_LEVEL = 0.95
#: Fewest model runs whose percentiles make a 95 % band (fewer: no band, no verdict).
MIN_BAND_RUNS = 20
AXES = ("x", "y", "z")
_METRICS = ("sigma_1_deg_s", "rms_deg_s", "mean_error_deg_s", "arw_deg_rt_h", "rrw_deg_h_rt_h", "bi_deg_h",
            "noise_density_deg_s_rt_hz", "attenuation", "phase_deg", "efficiency", "reduction")
#: Single-gyro value of a metric: the estimator's value × the matching reduction column.
_SINGLE_FROM = {"sigma_1_deg_s": "reduction", "arw_deg_rt_h": "arw_reduction",
                "rrw_deg_h_rt_h": "rrw_reduction", "bi_deg_h": "bi_reduction"}
_LABELS = {"sigma_1_deg_s": "1σ error [deg/s]", "rms_deg_s": "RMS about truth [deg/s]",
           "mean_error_deg_s": "mean error [deg/s]", "arw_deg_rt_h": "ARW [deg/√h]",
           "rrw_deg_h_rt_h": "RRW [deg/h/√h]", "bi_deg_h": "bias instability [deg/h]",
           "noise_density_deg_s_rt_hz": "noise density [deg/s/√Hz]",
           "attenuation": "amplitude ratio [-]", "phase_deg": "phase lag [deg]",
           "efficiency": "efficiency vs bound [-]", "reduction": "1σ reduction [-]"}


# -- reading -------------------------------------------------------------------

@dataclass
class SweepData:
    """One sweep folder: its manifest and result rows."""

    path: Path
    name: str
    manifest: dict
    rows: pd.DataFrame
    missing: int = 0          # scenarios of the manifest without results (not finished)
    _specs: dict | None = field(default=None, repr=False)   # id -> ScenarioSpec, or why not
    _specs_why: str = field(default="", repr=False)

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
                     rows=rows, missing=missing)


def _check_row_files(path: Path, ids: set) -> None:
    """Every ``rows/<id>.parquet`` belongs to the manifest and has the schema of the others."""
    import pyarrow.parquet as pq
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
            if not ok or (v["axis"] == "single" and v["metric"] not in _SINGLE_FROM):
                raise InputError(f"{where}.values[{j}] must be {{ axis = x|y|z|single, metric = "
                                 f"one of {', '.join(_METRICS)} (single: {', '.join(_SINGLE_FROM)}),"
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
    from gyroarray.analysis.replicates import mean_ci
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
                per_run = (sub[v["metric"]] * sub[_SINGLE_FROM[v["metric"]]]).groupby(
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


# -- figures -------------------------------------------------------------------

def _ranking_fig(ranking: pd.DataFrame) -> bytes:
    """Best 1σ vs N per scheme and estimator, one panel per motion, at one ρ (the first
    listed; ρ is a condition, not a series), error bars: 95 % CI over the runs."""
    motions = list(dict.fromkeys(ranking.motion))
    fig, axs = _figure(5.2 * len(motions), 4.4, len(motions))
    for ax, motion in zip(axs, motions):
        sub = ranking[ranking.motion == motion]
        rho = (sub.rho_arw.iloc[0], sub.rho_rrw.iloc[0])
        sub = sub[(sub.rho_arw == rho[0]) & (sub.rho_rrw == rho[1])]
        series = {}
        for (scheme, est), grp in sub.groupby(["scheme", "estimator"], sort=True):
            best = grp.loc[grp.groupby("n_gyros")["sigma_1_deg_s"].idxmin()].sort_values("n_gyros")
            err = np.vstack([best.sigma_1_deg_s - best.ci_low, best.ci_high - best.sigma_1_deg_s])
            series[(scheme, est)] = (best.n_gyros.to_numpy(), best.sigma_1_deg_s.to_numpy(),
                                     None if np.isnan(err.astype(float)).any() else err)
        plot_series(ax, series, rtol=1e-9)
        ax.set(title=f"{motion}, ρ_arw = {rho[0]}, ρ_rrw = {rho[1]}: best 1σ per N",
               xlabel="gyros N [-]", ylabel="1σ error [deg/s]", yscale="log")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    return _png(fig)


def _estimator_fig(comp: pd.DataFrame) -> bytes:
    motions = list(dict.fromkeys(comp.motion))
    fig, axs = _figure(5.0 * len(motions), 4.0, len(motions))
    for ax, motion in zip(axs, motions):
        sub = comp[comp.motion == motion].sort_values("sigma_1_deg_s")
        ax.barh(sub.estimator, sub.sigma_1_deg_s, color="C0")
        for y, (s, e) in enumerate(zip(sub.sigma_1_deg_s, sub.efficiency)):
            if np.isfinite(e):
                ax.text(s, y, f"  eff {e:.2f}", va="center", fontsize=8)
        ax.set(title=f"{motion}: median 1σ error by estimator", xlabel="1σ error [deg/s]")
        ax.grid(alpha=0.3, axis="x")
    return _png(fig)


def _paper_fig(pvm: list[dict]) -> bytes:
    """Paper / model ratio of every compared value, with the model's 95 % band."""
    items = [(e, v) for e in pvm for v in e["values"] if np.isfinite(v["ratio"])]
    fig, axs = _figure(9.0, max(3.0, 0.22 * len(items) + 1.2))
    ax = axs[0]
    labels = []
    for i, (e, v) in enumerate(items):
        m = v["model_mean"]
        lo, hi = v["low"] / m, v["high"] / m
        if np.isfinite(lo) and np.isfinite(hi) and m > 0:
            ax.plot([lo, hi], [i, i], color="0.7", lw=5, solid_capstyle="butt")
        color = "0.4" if v["flag"] is None else ("C3" if v["flag"] else "C2")
        ax.plot(v["ratio"], i, "o", color=color, ms=5)
        labels.append(f"{e['scenario'].split('/')[-1]} {v['axis']} {v['metric'].split('_')[0]}")
    ax.axvline(1.0, color="k", lw=0.8)
    finite = [v["ratio"] for _, v in items if v["ratio"] > 0]
    ax.set_xlim(min([0.05, *[r / 2 for r in finite]]), max([20.0, *[2 * r for r in finite]]))
    ax.set_yticks(range(len(items)), labels, fontsize=7)
    ax.invert_yaxis()
    ax.set(xscale="log", xlabel="paper / model mean [-]  (grey bar: 2.5–97.5 percentiles of the "
           "model's runs; red: outside; dark grey dot: < 20 runs, no band)", title="Paper vs model")
    ax.grid(alpha=0.3, axis="x", which="both")
    return _png(fig)


@dataclass
class _Adev:
    title: str
    png: bytes
    note: str = ""


def _adev_fig(title: str, spec, estimator: str) -> _Adev:
    """Re-simulate one sweep scenario: ADEV of the single gyros and of the fused axes."""
    from gyroarray.analysis.allan import allan_analysis  # lazy: loads numba
    from gyroarray.chain.run import SETTLE_S  # lazy: loads numba
    from gyroarray.estimators import get_estimator  # lazy: loads numba
    from gyroarray.sim.scenario import simulate  # lazy: loads mujoco, numba

    sc = spec.build()
    res = simulate(sc)
    dt = 1.0 / sc.sample_rate_hz
    est = get_estimator(estimator)().fit(sc.layout, sc.model, dt).estimate(res.readings_rad_s)
    t = res.truth.time_s
    keep = t >= t[0] + SETTLE_S
    truth = res.truth.omega_body_rad_s
    gyro_err = (res.readings_rad_s - truth @ sc.layout.H.T)[keep]
    fused_err = (est - truth)[keep]
    fig, axs = _figure(8.0, 5.0)
    ax = axs[0]
    to = units.rad_s_to_deg_h
    curves = [(f"gyro {k + 1}", gyro_err[:, k], "0.55", 0.12) for k in range(gyro_err.shape[1])]
    curves += [(f"fused {a}", fused_err[:, i], f"C{i}", 0.25) for i, a in enumerate(AXES)]
    lines = []
    for label, series, color, alpha in curves:
        an = allan_analysis(series, dt)
        ax.fill_between(an.taus_s, to(an.ci_low_rad_s), to(an.ci_high_rad_s), color=color,
                        alpha=alpha, lw=0)
        ax.loglog(an.taus_s, to(an.adev_rad_s), color=color,
                  lw=0.8 if label.startswith("gyro") else 1.6,
                  label=label if (not label.startswith("gyro") or label == "gyro 1") else None)
        lines.append((label, an))
    first = next(an for lab, an in lines if lab == "gyro 1")
    n_g = gyro_err.shape[1]
    ax.loglog(first.taus_s, to(first.adev_rad_s) * np.sqrt(3.0 / n_g), "k--", lw=1.0,
              label=f"gyro 1 × √(3/N) = ×{np.sqrt(3.0 / n_g):.3f}")
    ax.set(title=f"{title}\n(one {t[keep][-1] - t[keep][0]:.0f} s record)", xlabel="averaging time τ [s]",
           ylabel="Allan deviation [deg/h]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, title="(grey: every single gyro)", title_fontsize=7)
    single = np.mean([an.fit.to_datasheet_dict()["arw_deg_rt_h"] for lab, an in lines
                      if lab.startswith("gyro")])
    fused = [an.fit.to_datasheet_dict()["arw_deg_rt_h"] for lab, an in lines
             if lab.startswith("fused")]
    note = (f"{estimator} on {sc.layout.n_gyros} gyros, seed {spec.seed}, record "
            f"{t[keep][-1] - t[keep][0]:.0f} s: Allan-fit ARW single {single:.4g} deg/√h, fused "
            "x/y/z " + " / ".join(f"{f:.4g}" for f in fused) + " (a fit of the filtered output: "
            "it holds at the filter's bandwidth; the long-τ value is the dashed √(3/N) line for a "
            "unity-DC-gain filter); bands: 1σ confidence of each point (Greenhall EDF).")
    return _Adev(title=title, png=_png(fig), note=note)


def _find_spec(data: SweepData, pick):
    """The ScenarioSpec of the sweep's own file for a chosen result row (None: not found)."""

    if data._specs is None:
        data._specs, data._specs_why = {}, ""
        src = data.manifest.get("source")
        if not src or not Path(src).is_file():
            data._specs_why = f"the sweep file {src} is not available to re-simulate from"
        else:
            try:
                sweep = load_sweep(src)
            except InputError as err:
                data._specs_why = f"the sweep file no longer loads: {err}"
            else:
                if sweep.sha256 != data.manifest.get("sweep_sha256"):
                    data._specs_why = f"the sweep file {src} changed since the run"
                else:
                    data._specs = {s.id: s for s in sweep.scenarios}
    return data._specs.get(pick), data._specs_why


# -- rendering -----------------------------------------------------------------

def _fmt(v, digits=4) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        a = abs(float(v))
        if a != 0 and (a < 1e-3 or a >= 1e5):
            return f"{float(v):.{digits - 1}e}"
        return f"{float(v):.{digits}g}"
    return str(v)


class Doc:
    """Builds the HTML and the Markdown side by side."""

    def __init__(self, title: str):
        self.title = title
        self.html: list[str] = []
        self.md: list[str] = [f"# {title}", ""]
        self.figures: list[tuple[str, bytes]] = []
        self.toc: list[tuple[str, str]] = []

    def h2(self, text: str):
        anchor = "s" + str(len(self.toc) + 1)
        self.toc.append((anchor, text))
        self.html.append(f'<h2 id="{anchor}">{html.escape(text)}</h2>')
        self.md += [f"## {text}", ""]

    def h3(self, text: str):
        self.html.append(f"<h3>{html.escape(text)}</h3>")
        self.md += [f"### {text}", ""]

    def p(self, text: str, cls: str = ""):
        c = f' class="{cls}"' if cls else ""
        self.html.append(f"<p{c}>{html.escape(text)}</p>")
        self.md += [text, ""]

    def ul(self, items: list[str]):
        self.html.append("<ul>" + "".join(f"<li>{html.escape(i)}</li>" for i in items) + "</ul>")
        self.md += [f"* {i}" for i in items] + [""]

    def table(self, headers: list[str], rows: list[list], flags: list[bool] | None = None,
              cls: str = ""):
        h = "".join(f"<th>{html.escape(x)}</th>" for x in headers)
        body = []
        for i, r in enumerate(rows):
            cls = ' class="flag"' if flags and flags[i] else ""
            body.append(f"<tr{cls}>" + "".join(f"<td>{html.escape(_fmt(c))}</td>" for c in r)
                        + "</tr>")
        c = f' class="{cls}"' if cls else ""
        self.html.append(f"<table{c}><thead><tr>{h}</tr></thead><tbody>{''.join(body)}</tbody></table>")
        self.md.append("| " + " | ".join(headers) + " |")
        self.md.append("|" + "---|" * len(headers))
        for r in rows:
            self.md.append("| " + " | ".join(_fmt(c).replace("|", "\\|") for c in r) + " |")
        self.md.append("")

    def figure(self, name: str, png: bytes, caption: str):
        self.figures.append((name, png))
        b64 = base64.b64encode(png).decode("ascii")
        self.html.append(f'<figure><img src="data:image/png;base64,{b64}" alt="{html.escape(caption)}">'
                         f"<figcaption>{html.escape(caption)}</figcaption></figure>")
        self.md += [f"![{caption}]({{FIGDIR}}/{name}.png)", "", f"*{caption}*", ""]

    def render_html(self, subtitle: str) -> str:
        toc = "".join(f'<li><a href="#{a}">{html.escape(t)}</a></li>' for a, t in self.toc)
        return _HTML.format(title=html.escape(self.title), subtitle=html.escape(subtitle),
                            toc=toc, body="\n".join(self.html))

    def render_md(self, figdir: str) -> str:
        return "\n".join(self.md).replace("{FIGDIR}", figdir) + "\n"

    def write(self, out_html: Path, out_md, subtitle: str, *, css: str = "",
              force: bool = True) -> Path | None:
        """Write the HTML (``css`` appended to the page's style) and, if ``out_md``,
        the Markdown twin with its figures as PNGs in ``<stem>_figures/``, each
        file atomically through :mod:`gyroarray.core.outputs` (``force``: replace
        existing files). Returns the Markdown path or None."""
        page = self.render_html(subtitle)
        if css:
            page = page.replace("</style>", css + "</style>", 1)
        outputs.check_output_dir(Path(out_html).parent, what="the report's folder")
        files: list[tuple[Path, bytes]] = [(Path(out_html), page.encode("utf-8"))]
        md_path = None if out_md is None else Path(out_md)
        made = None
        if md_path is not None:
            figdir = markdown_figure_dir(md_path)
            made = None if figdir.exists() else figdir
            outputs.check_output_dir(figdir, what="the Markdown figures' folder")
            files += [(figdir / f"{name}.png", png) for name, png in self.figures]
            files.append((md_path, (f"*{subtitle}*\n\n" + self.render_md(figdir.name)).encode("utf-8")))
        try:
            # all or nothing: a refusal leaves neither the HTML nor some of the figures behind
            outputs.write_many(files, force=force)
        except BaseException:
            if made is not None:
                try:
                    made.rmdir()            # the figures' folder this call made, if still empty
                except OSError:
                    pass
            raise
        return md_path


def markdown_figure_dir(md_path) -> Path:
    """The folder of a Markdown twin's figures: ``<stem>_figures/`` beside it."""
    md_path = Path(md_path)
    return md_path.with_name(md_path.stem + "_figures")


_HTML = """<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title}</title>
<style>
body {{ font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto;
       max-width: 1200px; padding: 0 1em; color: #222; line-height: 1.45; }}
h1 {{ margin-bottom: 0.1em; }} .sub {{ color: #666; margin-top: 0; }}
h2 {{ border-bottom: 2px solid #ddd; padding-bottom: 0.2em; margin-top: 2em; }}
table {{ border-collapse: collapse; margin: 0.6em 0 1.2em; font-size: 0.88em; }}
th, td {{ border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }}
th {{ background: #f2f2f2; }} td:first-child, th:first-child {{ text-align: left; }}
tr.flag td {{ background: #fde8e8; }}
figure {{ margin: 1em 0; }} figure img {{ max-width: 100%; border: 1px solid #eee; }}
figcaption {{ color: #555; font-size: 0.9em; }}
.note {{ color: #555; font-size: 0.92em; }} .reason {{ background: #fff6e0; padding: 0.5em;
       border-left: 4px solid #e0a800; }}
nav ol {{ columns: 2; }}
p.decision {{ font-size: 1.08em; background: #eef6ee; padding: 0.4em 0.7em; margin: 0.3em 0;
       border-left: 4px solid #3a8a3a; }}
table.assumptions {{ background: #f7f7fb; }}
</style></head>
<body>
<h1>{title}</h1>
<p class="sub">{subtitle}</p>
<nav><ol>{toc}</ol></nav>
{body}
</body></html>
"""


def _section_design(doc: Doc):
    doc.h2("Cone geometry: GDOP vs α and ρ (paper 003 Figs. 8–10)")
    doc.p("GDOP = √trace((Hᵀ C⁻¹ H)⁻¹): the fused rate error of a unit-noise gyro array, per "
          "layout (H) and ARW correlation (C). Dots mark each N's optimal cone angle.")
    doc.figure("gdop", _png(design_fig(), dpi=80), "GDOP vs cone angle α and vs correlation ρ")


def _section_ranking(doc: Doc, design: list[SweepData], top: int) -> pd.DataFrame | None:
    rows = pd.concat([d.rows for d in design], ignore_index=True) if design else None
    doc.h2("Design ranking")
    if rows is None:
        doc.p("No design sweep given (only paper reproductions): nothing to rank.", "note")
        return None
    ranking = design_ranking(rows)
    one_run = int(ranking.runs.max()) < 2
    doc.p(f"{rows.scenario_id.nunique()} scenarios from {', '.join(d.name for d in design)}; "
          "ranked within each motion and each correlation ρ (a condition of the gyros, not a "
          "choice), best mean 1σ first (means over x/y/z and the runs; amplitude ratio: the "
          "swinging axis farthest from 1). RMS about the truth and 1σ are separate columns; the "
          "fused ARW/RRW here are Allan fits of the filtered output and hold at the estimator's "
          "bandwidth (10 Hz for the KFs by default), not the long-τ values."
          + (" One run per design: a single run's 1σ scatters by 13–20 %, so designs within "
             "that of each other are not resolved by this sweep (no interval; the analytic "
             "predictor ranks them)." if one_run else
             " 'resolved': the design's 95 % interval lies above the best one's."))
    doc.figure("ranking", _ranking_fig(ranking), "Best 1σ error per N, scheme and estimator "
               "(error bars: 95 % CI over the runs; identical series merged)")
    for (motion, ra, rr), sub in ranking.groupby(["motion", "rho_arw", "rho_rrw"], sort=False):
        doc.h3(f"Motion {motion}, ρ_arw = {ra}, ρ_rrw = {rr}: the {min(top, len(sub))} best of {len(sub)}")
        doc.table(["rank", "scheme", "N", "α [deg]", "estimator", "1σ [deg/s]", "95 % CI",
                   "RMS about truth [deg/s]", "resolved", "reduction [-]",
                   "ARW Allan fit [deg/√h]", "RRW Allan fit [deg/h/√h]", "amplitude ratio [-]",
                   "runs"],
                  [[r["rank"], r.scheme, r.n_gyros, r.alpha_deg, r.estimator, r.sigma_1_deg_s,
                    "–" if pd.isna(r.ci_low) else f"{r.ci_low:.4g} – {r.ci_high:.4g}", r.rms_deg_s,
                    "–" if r.resolved is None else r.resolved, r.reduction, r.arw_deg_rt_h,
                    r.rrw_deg_h_rt_h, r.attenuation, r.runs] for _, r in sub.head(top).iterrows()])
    return ranking


def _section_adev(doc: Doc, design: list[SweepData], paper: list[SweepData],
                  ranking: pd.DataFrame | None, heading: bool = True):
    if heading:
        doc.h2("Allan deviation: single gyros vs fused output (paper 003 Figs. 14, 22)")
    else:
        doc.h3("From the sweeps (paper 003 Figs. 14, 22)")
    done = 0
    if ranking is not None:
        static = ranking[ranking.motion.str.contains("static")]
        if not static.empty:
            best = static.iloc[0]
            for d in design:
                sel = d.rows
                for k in ("scheme", "n_gyros", "alpha_deg", "motion", "estimator"):
                    sel = sel[sel[k].astype(object) == best[k]]
                if sel.empty:
                    continue
                spec, why = _find_spec(d, sel.scenario_id.iloc[0])
                if spec is None:
                    doc.p(f"Best static design: not re-simulated ({why}).", "note")
                    break
                a = _adev_fig(f"Best static design: scheme {best.scheme}, N = {best.n_gyros}, "
                              f"α = {best.alpha_deg:.2f}°, {best.estimator}", spec, best.estimator)
                doc.figure("adev_best", a.png, a.note)
                done += 1
                break
    for scen, fig_name, label in (("paper003/static_s1_n6_rhob_0", "adev_fig14",
                                   "Paper 003 Fig. 14: 6-gyro Scheme 1, 1 h static, kf_array"),
                                  ("paper003/tetra_static", "adev_fig22",
                                   "Paper 003 Fig. 22: 4-gyro tetrahedral array (Table 8 noise), kf_array")):
        for d in paper:
            sel = d.rows[(d.rows.scenario == scen) & (d.rows.replicate == 0)]
            if sel.empty:
                continue
            spec, why = _find_spec(d, sel.scenario_id.iloc[0])
            if spec is None:
                doc.p(f"{label}: not re-simulated ({why}).", "note")
            else:
                a = _adev_fig(label, spec, "kf_array")
                doc.figure(fig_name, a.png, a.note)
                done += 1
            break
    if not done and heading:
        doc.p("No static scenario in the given sweeps to draw.", "note")


def _section_estimators(doc: Doc, rows: pd.DataFrame):
    doc.h2("Estimator comparison")
    comp = estimator_comparison(rows)
    has_bound = "bound" in set(rows.estimator)
    doc.p("Medians over every design, axis and run of each motion. Amplitude ratio and phase "
          "lag on the swinging axes only. " + (
              "Efficiency = 1σ of the offline bound (KF + RTS smoother on the full model) / 1σ "
              "of the estimator: 1 is the best any estimator can do with these data."
              if has_bound else
              "Efficiency needs the offline bound: add \"bound\" to the sweep's estimators."))
    doc.figure("estimators", _estimator_fig(comp), "Median 1σ error by estimator")
    doc.table(["motion", "estimator", "1σ [deg/s]", "reduction [-]", "amplitude ratio [-]",
               "phase lag [deg]", "efficiency [-]", "efficiency min [-]", "runs"],
              [[r.motion, r.estimator, r.sigma_1_deg_s, r.reduction, r.attenuation, r.phase_deg,
                r.efficiency, r.efficiency_min, r.runs] for _, r in comp.iterrows()])
    return comp


def _section_paper(doc: Doc, paper: list[SweepData], values_path) -> list[dict]:
    doc.h2("Paper vs model")
    if not paper:
        doc.p("No paper reproduction sweep given (run scenarios/sweeps/paper_reproduction.toml, "
              "e.g. make paper, and pass its folder too).", "note")
        return []
    rows = pd.concat([d.rows for d in paper], ignore_index=True)
    pvm = paper_vs_model(rows, load_paper_values(values_path))
    vals = [v for e in pvm for v in e["values"]]
    n_flag = sum(v["flag"] is True for v in vals)
    n_und = sum(v["flag"] is None for v in vals)
    doc.p(f"{len(pvm)} experiments, {len(vals)} published values; {n_flag} lie outside the "
          f"model's {AGREEMENT_LEVEL:.0%} band (red rows): the 2.5–97.5 percentiles of the "
          f"model's runs, where one more run falls 95 % of the time"
          + (f"; {n_und} have fewer than {MIN_BAND_RUNS} runs, so no band and no verdict"
             if n_und else "") + ". A disagreement is explained only where a named simulation "
          "tests the explanation; the rest are reported as unexplained.")
    if pvm:
        doc.figure("paper_vs_model", _paper_fig(pvm), "Paper value / model mean, with the model's "
                   "95 % percentile band of its runs (none where fewer than 20 runs)")
    for e in pvm:
        doc.h3(e["title"])
        doc.p(f"scenario {e['scenario']}, estimator {e['estimator']}, {e['runs']} runs", "note")
        doc.table(["axis", "metric", "paper", "model mean", "model sd", "model min–max",
                   "95 % band (percentiles)", "paper/model", "agrees"],
                  [[v["axis"], _LABELS.get(v["metric"], v["metric"]), v["paper"], v["model_mean"],
                    v["model_sd"], f"{_fmt(v['model_min'])} – {_fmt(v['model_max'])}",
                    f"{_fmt(v['low'])} – {_fmt(v['high'])}", v["ratio"],
                    "undetermined (< 20 runs)" if v["flag"] is None else ("no" if v["flag"] else "yes")]
                   for v in e["values"]],
                  flags=[bool(v["flag"]) for v in e["values"]])
        if e["flagged"] and not e["checks"]:
            doc.p("Unexplained: no explanation of this disagreement has been tested.", "reason")
        shipped = rows[(rows.scenario == e["scenario"]) & (rows.estimator == e["estimator"])]
        base = Path(values_path).parent if values_path is not None else None
        for c in e["checks"]:
            try:
                r = run_check(e, c, shipped_rows=shipped, base=base)
            except InputError as err:
                doc.p(f"Check {c['name']}: could not run ({err.message}).", "reason")
                continue
            e.setdefault("check_results", []).append(r)
            doc.p(f"Hypothesis: {r['hypothesis']} Simulation {r['name']}: {r['simulation']}. "
                  f"Result: it {r['verdict']} the hypothesis (supports: every paper value inside "
                  "the changed model's 95 % band).", "reason")
            doc.table(["axis", "metric", "paper", "changed model: mean", "its 95 % band",
                       "shipped model's 95 % band", "paper inside"],
                      [[x["axis"], _LABELS.get(x["metric"], x["metric"]), x["paper"],
                        x["changed_mean"], f"{_fmt(x['changed_low'])} – {_fmt(x['changed_high'])}",
                        f"{_fmt(x['shipped_low'])} – {_fmt(x['shipped_high'])}", x["inside"]]
                       for x in r["rows"]])
    return pvm


def write_report(dirs, out_html, out_md=None, *, design=None, paper_values=None, top: int = 15,
                 force: bool = True) -> dict:
    """Write the report: the decision first, then the evidence (see the module docstring).

    Parameters
    ----------
    dirs : sequence of path
        ``gyroarray sweep`` output folders (design sweeps and/or paper reproductions);
        may be empty when ``design`` is given.
    out_html : path
        The HTML file (figures embedded).
    out_md : path, optional
        The Markdown twin; its figures go to ``<stem>_figures/`` beside it.
    design : path or dict, optional
        A ``gyroarray design --recommend --out`` result: the decision, the
        assumptions and the predictor's evidence open the report.
    paper_values : path, optional
        Paper values file (default: the shipped ``scenarios/paper_values.toml``).
    top : int
        Designs listed per motion in the ranking.
    force : bool
        Replace existing output files (the CLI passes ``--force``).

    Returns
    -------
    dict
        ``html``, ``markdown``, ``figures`` (count), ``sweeps`` (name, folder,
        scenarios, missing), ``best`` (the top design per motion of the sweeps),
        ``decision`` (the recommended design and the summary sentences, with
        ``design``), ``paper_vs_model`` (see :func:`paper_vs_model`), ``seconds``.
    """
    t0 = time.perf_counter()
    dirs = [Path(d) for d in dirs]
    if not dirs and design is None:
        raise InputError("gyroarray report: give at least one sweep folder or --design FILE.json")
    out_html = Path(out_html)
    if out_html.suffix.lower() not in (".html", ".htm"):
        raise InputError("the report must end in .html", file=str(out_html))
    if out_md is not None and Path(out_md).suffix.lower() != ".md":
        raise InputError("the Markdown twin must end in .md", file=str(out_md))
    res = dec.load_design(design) if isinstance(design, (str, Path)) else design
    data = [load_sweep_dir(d) for d in dirs]
    paper = [d for d in data if d.is_paper]
    designs = [d for d in data if not d.is_paper]
    doc = Doc("gyroarray design report" if res is not None else "gyroarray design comparison report")
    notes = [f"{d.name}: {d.missing} scenario(s) of the sweep not finished — rerun the sweep "
             "command to complete it" for d in data if d.missing]
    for n in notes:
        doc.p("Note: " + n, "note")
    decision = dec.write_sections(doc, res, top) if res is not None else None
    _section_design(doc)
    if res is not None:
        doc.h2("Allan deviation: single gyros vs fused output")
        dec.adev_section(doc, res)
    ranking = _section_ranking(doc, designs, top) if designs or res is None else None
    if data:
        _section_adev(doc, designs, paper, ranking, heading=res is None)
        all_rows = pd.concat([d.rows for d in (designs or data)], ignore_index=True)
        _section_estimators(doc, all_rows)
    pvm = _section_paper(doc, paper, paper_values) if data else []

    stamp = time.strftime("%Y-%m-%d %H:%M", time.localtime())
    subtitle = f"{stamp}" + ("" if not data else " · sweeps: " + ", ".join(
        f"{d.name} ({d.rows.scenario_id.nunique()} scenarios)" for d in data))
    if res is not None:
        subtitle += " · decision from the analytic predictor"
    md_path = doc.write(out_html, out_md, subtitle, force=force)
    best = []
    if ranking is not None:
        for motion, sub in ranking.groupby("motion", sort=False):
            r = sub.iloc[0]
            best.append({"motion": motion, "scheme": None if r.scheme == "none" else int(r.scheme),
                         "n_gyros": int(r.n_gyros), "alpha_deg": float(r.alpha_deg),
                         "rho_arw": None if r.rho_arw == "none" else float(r.rho_arw),
                         "estimator": r.estimator, "sigma_1_deg_s": float(r.sigma_1_deg_s),
                         "rms_deg_s": float(r.rms_deg_s)})
    return {"html": str(out_html), "markdown": None if md_path is None else str(md_path),
            "figures": len(doc.figures),
            "sweeps": [{"name": d.name, "folder": str(d.path),
                        "scenarios": int(d.rows.scenario_id.nunique()), "missing": d.missing,
                        "paper": d.is_paper} for d in data],
            "best": best, "decision": decision, "paper_vs_model": pvm, "notes": notes,
            "seconds": time.perf_counter() - t0}
