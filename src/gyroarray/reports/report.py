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
  (simulated once and saved) and, from the sweeps, the best static design and the
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
  simulation tests (:mod:`gyroarray.chain.hypotheses`); a check that can only
  reject is withdrawn with its reason (:data:`WITHDRAWN_CHECKS`).

Nothing is simulated here (the per-ρ tables of a design result add the predictor's
scores of its designs' mounting mirrors, :func:`gyroarray.reports.decision.rho_candidates`,
a few seconds): :func:`render_report` draws a
:class:`gyroarray.sweep.report_results.ReportResults`, which
:func:`~gyroarray.sweep.report_results.collect_report_results` gathers from the
sweeps' rows and the saved results (``hypotheses.json`` and ``adev.json`` in the
sweep folders, ``<design stem>.adev.json`` beside a design result); a second
report of the same inputs simulates nothing. :func:`write_report` does both.

The HTML has its figures as ``data:image/png;base64`` URIs, its style inline
and no script: it opens anywhere, offline. The Markdown twin has the same
tables and links the same figures, written as PNG files into
``<md stem>_figures/`` beside it.

Units are in the column names (deg/s, deg/√h, deg/h/√h: the datasheet edge).
"""

from __future__ import annotations

import base64
import html
import time
from pathlib import Path

import numpy as np
import pandas as pd

from gyroarray.analysis.adev_curves import AdevFigure
from gyroarray.core import units
from gyroarray.core import outputs
from gyroarray.core.errors import InputError
from gyroarray.core.result_cache import ResultCache, input_key
from gyroarray.reports import decision as dec
from gyroarray.reports.design_plots import agg_figure, figure_png, design_fig, plot_series
from gyroarray.sweep.report_results import (AGREEMENT_LEVEL, MIN_BAND_RUNS, ReportResults,
                                            collect_report_results)

__all__ = ["write_report", "render_report", "adev_figure_png"]

AXES = ("x", "y", "z")
_LABELS = {"sigma_1_deg_s": "1σ error [deg/s]", "rms_deg_s": "RMS about truth [deg/s]",
           "mean_error_deg_s": "mean error [deg/s]", "arw_deg_rt_h": "ARW [deg/√h]",
           "rrw_deg_h_rt_h": "RRW [deg/h/√h]", "bi_deg_h": "bias instability [deg/h]",
           "noise_density_deg_s_rt_hz": "noise density [deg/s/√Hz]",
           "attenuation": "amplitude ratio [-]", "phase_deg": "phase lag [deg]",
           "efficiency": "efficiency vs bound [-]", "reduction": "1σ reduction [-]"}


# -- figures -------------------------------------------------------------------

def _ranking_fig(ranking: pd.DataFrame) -> bytes:
    """Best 1σ vs N per scheme and estimator, one panel per motion, at one ρ (the first
    listed; ρ is a condition, not a series), error bars: 95 % CI over the runs."""
    motions = list(dict.fromkeys(ranking.motion))
    fig, axs = agg_figure(5.2 * len(motions), 4.4, len(motions))
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
    return figure_png(fig)


def _estimator_fig(comp: pd.DataFrame) -> bytes:
    motions = list(dict.fromkeys(comp.motion))
    fig, axs = agg_figure(5.0 * len(motions), 4.0, len(motions))
    for ax, motion in zip(axs, motions):
        sub = comp[comp.motion == motion].sort_values("sigma_1_deg_s")
        ax.barh(sub.estimator, sub.sigma_1_deg_s, color="C0")
        for y, (s, e) in enumerate(zip(sub.sigma_1_deg_s, sub.efficiency)):
            if np.isfinite(e):
                ax.text(s, y, f"  eff {e:.2f}", va="center", fontsize=8)
        ax.set(title=f"{motion}: median 1σ error by estimator", xlabel="1σ error [deg/s]")
        ax.grid(alpha=0.3, axis="x")
    return figure_png(fig)


def _paper_fig(pvm: list[dict]) -> bytes:
    """Paper / model ratio of every compared value, with the model's 95 % band."""
    items = [(e, v) for e in pvm for v in e["values"] if np.isfinite(v["ratio"])]
    fig, axs = agg_figure(9.0, max(3.0, 0.22 * len(items) + 1.2))
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
    return figure_png(fig)


def adev_figure_png(a: AdevFigure) -> tuple[bytes, str]:
    """Draw a sweep scenario's ADEV (single gyros grey, fused x/y/z coloured, √(3/N) dashed): (PNG, caption)."""
    fig, axs = agg_figure(8.0, 5.0)
    ax = axs[0]
    to = units.rad_s_to_deg_h
    styles = {c.label: ("0.55", 0.12) if c.single else (f"C{AXES.index(c.label[-1])}", 0.25)
              for c in a.curves}
    for c in a.curves:
        color, alpha = styles[c.label]
        ax.fill_between(c.taus_s, to(c.ci_low_rad_s), to(c.ci_high_rad_s), color=color,
                        alpha=alpha, lw=0)
        ax.loglog(c.taus_s, to(c.adev_rad_s), color=color, lw=0.8 if c.single else 1.6,
                  label=c.label if (not c.single or c.label == "gyro 1") else None)
    first = a.singles[0]
    k = a.reference_factor
    ax.loglog(first.taus_s, to(first.adev_rad_s) * k, "k--", lw=1.0,
              label=f"gyro 1 × √(3/N) = ×{k:.3f}")
    ax.set(title=f"{a.title}\n(one {a.record_s:.0f} s record)", xlabel="averaging time τ [s]",
           ylabel="Allan deviation [deg/h]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, title="(grey: every single gyro)", title_fontsize=7)
    single = np.mean([c.arw_fit_deg_rt_h for c in a.singles])
    fused = [c.arw_fit_deg_rt_h for c in a.fused]
    note = (f"{a.estimator} on {a.n_gyros} gyros, seed {a.seed}, record "
            f"{a.record_s:.0f} s: Allan-fit ARW single {single:.4g} deg/√h, fused "
            "x/y/z " + " / ".join(f"{f:.4g}" for f in fused) + " (a fit of the filtered output: "
            "it holds at the filter's bandwidth; the long-τ value is the dashed √(3/N) line for a "
            "unity-DC-gain filter); bands: 1σ confidence of each point (Greenhall EDF).")
    return figure_png(fig), note


# -- rendering -----------------------------------------------------------------

def format_value(v, digits=4) -> str:
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
            body.append(f"<tr{cls}>" + "".join(f"<td>{html.escape(format_value(c))}</td>" for c in r)
                        + "</tr>")
        c = f' class="{cls}"' if cls else ""
        self.html.append(f"<table{c}><thead><tr>{h}</tr></thead><tbody>{''.join(body)}</tbody></table>")
        self.md.append("| " + " | ".join(headers) + " |")
        self.md.append("|" + "---|" * len(headers))
        for r in rows:
            self.md.append("| " + " | ".join(format_value(c).replace("|", "\\|") for c in r) + " |")
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


def _section_design(doc: Doc, rec: dict | None = None):
    doc.h2("Cone geometry: GDOP vs α and ρ (paper 003 Figs. 8–10)")
    drawn = rec is not None and rec.get("axes") is not None
    doc.p("GDOP = √trace((Hᵀ C⁻¹ H)⁻¹): the fused rate error of a unit-noise gyro array, per "
          "layout (H) and ARW correlation (C). Dots mark each N's optimal cone angle. The paper's "
          "arrays have every gyro mounted +"
          + ("; the bold black line on its scheme's GDOP-vs-ρ panel is the recommended array as "
             "mounted, its reversed gyros included (the correlation in the gyros' output frame)."
             if drawn else "."))
    doc.figure("gdop", figure_png(design_fig(rec if drawn else None), dpi=80),
               "GDOP vs cone angle α and vs correlation ρ"
               + ("; bold: the recommended array as mounted (reversed gyros included)" if drawn else ""))


def _section_ranking(doc: Doc, res: ReportResults, top: int) -> pd.DataFrame | None:
    design = res.design_sweeps
    doc.h2("Design ranking")
    if not design or res.ranking is None:
        doc.p("No design sweep given (only paper reproductions): nothing to rank.", "note")
        return None
    rows = pd.concat([d.rows for d in design], ignore_index=True)
    ranking = res.ranking
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


def _section_adev(doc: Doc, res: ReportResults, heading: bool = True):
    if heading:
        doc.h2("Allan deviation: single gyros vs fused output (paper 003 Figs. 14, 22)")
    else:
        doc.h3("From the sweeps (paper 003 Figs. 14, 22)")
    done = 0
    for item in res.adev:
        if item.figure is None:
            label = "Best static design" if item.name == "adev_best" else item.label
            doc.p(f"{label}: not re-simulated ({item.why}).", "note")
            continue
        png, note = adev_figure_png(item.figure)
        doc.figure(item.name, png, note)
        done += 1
    if not done and not res.adev and heading:
        doc.p("No static scenario in the given sweeps to draw.", "note")


def _section_estimators(doc: Doc, rows: pd.DataFrame, comp: pd.DataFrame):
    doc.h2("Estimator comparison")
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


_GAIN_WHY = ("withdrawn: this check can only reject. Its value is paper 002's filtered / original "
             "amplitude (Table 4), and the paper's original (raw) gyro reads the 20 deg/s swing as "
             "22.45–23.11 deg/s, a scale factor of about +12 % (to +16 %), while its filtered output "
             "reads 20.10–20.78 deg/s: the ratio of about 0.9 is that raw scale factor (1/1.12 = "
             "0.89). The model simulates no scale-factor error on the raw gyro, so the simulated "
             "ratio is the filter's own gain at the swing, about 1 at every bandwidth, and no "
             "filter setting can reach 0.9: the hypothesis is never supported whatever the filter "
             "does, so the check tests nothing (it comes back when the +12 % scale factor is "
             "simulated)")

#: Paper checks the report withdraws, with the reason it prints ({check name: reason}). A
#: check of the paper values file may also say ``withdrawn = "reason"`` itself (read the same way).
WITHDRAWN_CHECKS = {"p002_t4_0p1_constant_gain": _GAIN_WHY, "p002_t4_0p5_constant_gain": _GAIN_WHY}


def withdrawn_reason(check: dict) -> str | None:
    """Why a paper check is withdrawn from the report (None: it is shown)."""
    why = check.get("withdrawn") or WITHDRAWN_CHECKS.get(check.get("name", ""))
    if not why:
        return None
    return why if str(why).startswith("withdrawn") else f"withdrawn: {why}"


def _section_paper(doc: Doc, res: ReportResults) -> list[dict]:
    doc.h2("Paper vs model")
    if not res.paper:
        doc.p("No paper reproduction sweep given (run scenarios/sweeps/paper_reproduction.toml, "
              "e.g. make paper, and pass its folder too).", "note")
        return []
    pvm = res.paper_vs_model
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
                    v["model_sd"], f"{format_value(v['model_min'])} – {format_value(v['model_max'])}",
                    f"{format_value(v['low'])} – {format_value(v['high'])}", v["ratio"],
                    "undetermined (< 20 runs)" if v["flag"] is None else ("no" if v["flag"] else "yes")]
                   for v in e["values"]],
                  flags=[bool(v["flag"]) for v in e["values"]])
        live = [c for c in e["checks"] if withdrawn_reason(c) is None]
        if e["flagged"] and not live:
            doc.p("Unexplained: no explanation of this disagreement has been tested"
                  + (" (its check is withdrawn, below)" if e["checks"] else "") + ".", "reason")
        for c, r in zip(e["checks"], e.get("check_results", [])):
            why = withdrawn_reason(c)
            if why is not None:
                doc.p(f"Check {c['name']}: {why}.", "reason")
                continue
            if isinstance(r, str):
                doc.p(f"Check {c['name']}: could not run ({r}).", "reason")
                continue
            doc.p(f"Hypothesis: {r.hypothesis} Simulation {r.name}: {r.simulation}. "
                  f"Result: it {r.verdict} the hypothesis (supports: every paper value inside "
                  "the changed model's 95 % band).", "reason")
            doc.table(["axis", "metric", "paper", "changed model: mean", "its 95 % band",
                       "shipped model's 95 % band", "paper inside"],
                      [[x.axis, _LABELS.get(x.metric, x.metric), x.paper,
                        x.changed_mean, f"{format_value(x.changed_low)} – {format_value(x.changed_high)}",
                        f"{format_value(x.shipped_low)} – {format_value(x.shipped_high)}", x.inside]
                       for x in r.rows])
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
    _check_suffixes(out_html, out_md)
    results = collect_report_results(dirs, design=design, paper_values=paper_values)
    rc = cached_rho_candidates(results.design, design if isinstance(design, (str, Path)) else None)
    out = render_report(results, out_html, out_md, top=top, force=force, rho_candidates=rc)
    out["seconds"] = time.perf_counter() - t0
    return out


def per_rho_file(design_path) -> Path:
    """Where a design result's per-ρ candidates are saved: ``<design stem>.per_rho.json`` beside it."""
    p = Path(design_path)
    return p.with_name(p.stem + ".per_rho.json")


def cached_rho_candidates(res: dict | None, design_path=None) -> dict | None:
    """:func:`gyroarray.reports.decision.rho_candidates` of a design result, read from
    ``<design stem>.per_rho.json`` when saved under the same inputs, else computed (the
    predictor on the mounting mirrors, a few seconds) and saved there, so that a second
    report of the same result computes nothing. None without a result or a per-ρ grid."""
    if res is None or not res.get("per_rho"):
        return None
    cache = ResultCache(per_rho_file(design_path) if design_path is not None else None, "per_rho")
    key = input_key("design_per_rho", res.get("designs"), res.get("recommended"), res.get("assumptions"),
                    list(res["per_rho"]), dec.REPRODUCE_RTOL)
    hit = cache.get(key)
    if hit is not None and isinstance(hit.get("candidates"), list) and isinstance(hit.get("rhos"), list):
        return hit
    rc = dec.rho_candidates(res)
    if rc is not None:
        cache.put(key, rc)
        cache.save()
    return rc


def _check_suffixes(out_html, out_md) -> None:
    if Path(out_html).suffix.lower() not in (".html", ".htm"):
        raise InputError("the report must end in .html", file=str(out_html))
    if out_md is not None and Path(out_md).suffix.lower() != ".md":
        raise InputError("the Markdown twin must end in .md", file=str(out_md))


def render_report(results: ReportResults, out_html, out_md=None, *, top: int = 15,
                  force: bool = True, rho_candidates: dict | None = None) -> dict:
    """Draw a :class:`~gyroarray.sweep.report_results.ReportResults`: nothing is simulated here.

    Parameters and returns as :func:`write_report` (which collects the results and calls this);
    ``rho_candidates``: :func:`cached_rho_candidates` of the design result (None: computed
    here when the result has a per-ρ grid).
    """
    t0 = time.perf_counter()
    _check_suffixes(out_html, out_md)
    out_html = Path(out_html)
    res = results.design
    data = results.sweeps
    doc = Doc("gyroarray design report" if res is not None else "gyroarray design comparison report")
    notes = list(results.notes)
    for n in notes:
        doc.p("Note: " + n, "note")
    decision = (dec.write_sections(doc, res, top, results.gdop_robustness, rho_candidates=rho_candidates)
                if res is not None else None)
    _section_design(doc, None if res is None else res.get("recommended"))
    if res is not None and results.design_adev is not None:
        doc.h2("Allan deviation: single gyros vs fused output")
        dec.adev_section(doc, res, results.design_adev)
    ranking = (_section_ranking(doc, results, top) if results.design_sweeps or res is None
               else None)
    if data:
        _section_adev(doc, results, heading=res is None)
        all_rows = pd.concat([d.rows for d in (results.design_sweeps or data)], ignore_index=True)
        assert results.estimators is not None                  # collected with the sweeps
        _section_estimators(doc, all_rows, results.estimators)
    pvm = _section_paper(doc, results) if data else []
    pvm = [{**e, "check_results": [r.to_dict() for c, r in zip(e["checks"], e.get("check_results", []))
                                   if not isinstance(r, str) and withdrawn_reason(c) is None],
            "withdrawn_checks": {c["name"]: withdrawn_reason(c) for c in e["checks"]
                                 if withdrawn_reason(c) is not None}} for e in pvm]

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
