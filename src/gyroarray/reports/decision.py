"""The decision part of the design report: what to build, under which assumptions, and why.

Input: the result of ``gyroarray design --recommend --out FILE.json``
(:func:`gyroarray.design.recommend.recommend`, with its Monte-Carlo ``check`` when
``--check K`` was given). The sections come top first, as a navigation
engineer reads them:

1. **Decision**: the recommended array, estimator and bandwidth, the
   predicted RMS about the truth and angle error (with the simulated
   check's 95 % interval beside it), the runner-up, the designs equal to it,
   and what would change the choice.
2. **Assumptions**: every input and whether the user gave it, a model
   file gave it, or it is a default.
3. **Evidence**: the prediction beside the paired simulation, the ranked
   designs (RMS and 1σ in separate columns, long-τ ARW/RRW of the fused
   rate, fault tolerance), accuracy vs N with error bars, ρ robustness, and
   the Allan deviation of the recommended design against the single gyros
   with the √(3/N) reference.
"""

from __future__ import annotations

import json
import math

import numpy as np

from gyroarray.analysis.adev_curves import AdevFigure
from gyroarray.core import units
from gyroarray.design.evidence import GdopRobustnessRow
from gyroarray.design.recommend import design_label as _recommend_label
from gyroarray.reports.design_plots import agg_figure, figure_png, accuracy_vs_n_fig

__all__ = ["write_sections", "decision_summary", "adev_section"]

AXES = ("x", "y", "z")


def _label(d: dict) -> str:
    return _recommend_label(d)


def _ci_text(mc: dict | None, digits: int = 4) -> str:
    if not mc or mc.get("value") is None:
        return "–"
    if mc.get("ci_low") is None:
        return f"{mc['value']:.{digits}g}"
    return f"{mc['value']:.{digits}g} [{mc['ci_low']:.{digits - 1}g}, {mc['ci_high']:.{digits - 1}g}]"


def _check_of(res: dict, d: dict) -> dict | None:
    """The Monte-Carlo check entry of a design, if it was simulated."""
    for c in (res.get("check") or {}).get("designs", []):
        if (c["scheme"], c["n"], c["estimator"], c["bandwidth_hz"]) == (
                d["scheme"], d["n"], d["estimator"], d["bandwidth_hz"]) and \
                abs(c["alpha_deg"] - d["alpha_deg"]) < 1e-6:
            return c
    return None


def decision_summary(res: dict) -> list[str]:
    """The decision in a few sentences (also printed by ``make demo``)."""
    r = res["recommended"]
    p = r["predicted"]
    a = res["assumptions"]
    horizon = a["horizon_s"]["value"]
    chk = _check_of(res, r)
    lines = [f"Build: {_label(r)}."]
    rms = " / ".join(f"{p[x]['rms_deg_s']:.3g}" for x in AXES)
    ang = " / ".join(f"{p[x]['angle_deg_at_horizon']:.3g}" for x in AXES)
    s = (f"Expected over {horizon:g} s: RMS rate error about the truth x/y/z {rms} deg/s, "
         f"angle error at the end {ang} deg (predicted")
    if r.get("rms_by_rho"):
        s += (f" at ρ = {r['rho']:g}, the worst case of the range; 3-axis RMS at each ρ: "
              + ", ".join(f"{k}: {v:.4g}" for k, v in r["rms_by_rho"].items()) + " deg/s")
    s += ")"
    if chk:
        t = chk["rms_3axis_deg_s"]["monte_carlo"]
        s += (f"; {res['check']['replicates']} paired simulated runs give a 3-axis RMS of "
              f"{_ci_text(t)} deg/s against the predicted {r['rms_3axis_deg_s']:.4g}")
    lines.append(s + ".")
    ft = r.get("fault_tolerance", {})
    fails = a["failures"]["value"]
    lines.append(f"GDOP {r.get('gdop', float('nan')):.4g}; worst GDOP after {fails} failed gyro(s) "
                 f"{r['worst_gdop_after_failures']:.4g}; after 2: "
                 + ("3 axes kept" if ft.get("three_axes_after", {}).get("2") else "an axis can be lost")
                 + f"; one failure {'detectable' if ft.get('detectable') else 'not detectable'}"
                 + f" and {'isolable' if ft.get('isolable') else 'not isolable'} from the geometry.")
    if res.get("runner_up"):
        ru = res["runner_up"]
        lines.append(f"Runner-up: {_label(ru)} ({ru['rms_3axis_deg_s']:.4g} deg/s 3-axis RMS).")
    if res.get("tracking_limit"):                      # the sensor's own bandwidth (issue 15)
        lines.append("Tracking: " + res["tracking_limit"]["statement"] + ".")
    if res.get("g_sensitivity"):
        lines.append(res["g_sensitivity"]["statement"] + ".")
    return lines


# -- sections ---------------------------------------------------------------------

def write_sections(doc, res: dict, top: int = 15,
                   gdop_rows: list[GdopRobustnessRow] | None = None) -> dict:
    """Add the decision, assumptions and evidence sections to a report document.

    ``gdop_rows``: :func:`gyroarray.design.evidence.gdop_robustness_table` over the
    result's ρ range (drawn with the ρ robustness; none: that table is left out).
    """
    doc.h2("Decision")
    for s in decision_summary(res):
        doc.p(s, "decision")
    eq = [g for g in res["equivalent"] if res["recommended"].get("rank") in g["members"]]
    if eq:
        doc.p("Equal to the recommendation within 1 % (ranks "
              + ", ".join(map(str, eq[0]["members"])) + "): " + eq[0]["reason"] + ".", "note")
    doc.p("What would change the choice:")
    doc.ul(res.get("what_changes_the_choice", []))
    _assumptions(doc, res["assumptions"])
    doc.h2("Evidence: the prediction and the simulation")
    _check(doc, res)
    doc.h3("Every design, best first (analytic predictor)")
    doc.p("3-axis RMS about the truth = √(Σ over x, y, z of the mean square over the horizon): "
          "the ranking objective. Per axis (mean over x, y, z shown): RMS about the truth and "
          "the run's own 1σ (mean removed) are separate columns, as is the RMS of the run's mean "
          "error (random-walk drift, paper 002 Eq. 19). Fused ARW/RRW are the long-τ values of "
          "the fused rate (the readings' terms through the estimator's low-frequency gain), not "
          "an Allan fit of the filtered output.", "note")
    rows = []
    for d in res["designs"][:top]:
        p = d["predicted"]

        def mean(key):
            v = [p[a].get(key) for a in AXES if p[a].get(key) is not None]
            return float(np.mean(v)) if v else None
        ft = d.get("fault_tolerance", {})
        rows.append([d["rank"], d["scheme"], d["n"], d["alpha_deg"], d["estimator"],
                     "none" if d["bandwidth_hz"] is None else d["bandwidth_hz"],
                     d["rms_3axis_deg_s"], mean("rms_deg_s"), mean("std_deg_s"), mean("mean_deg_s"),
                     mean("angle_deg_at_horizon"), mean("arw_long_deg_rt_h"),
                     mean("rrw_long_deg_h_rt_h"), mean("dc_gain"), d.get("gdop"),
                     ft.get("worst_gdop_after", {}).get("1"), ft.get("worst_gdop_after", {}).get("2")])
    doc.table(["rank", "scheme", "N", "α [deg]", "estimator", "bandwidth [Hz]",
               "3-axis RMS [deg/s]", "RMS/axis [deg/s]", "1σ/axis [deg/s]", "mean error RMS [deg/s]",
               "angle @T [deg]", "fused ARW long-τ [deg/√h]", "fused RRW long-τ [deg/h/√h]",
               "DC gain [-]", "GDOP", "worst GDOP 1 fail", "worst GDOP 2 fail"], rows)
    if res["equivalent"]:
        doc.p("Designs within 1 % of each other (grouped, with the reason):")
        doc.table(["ranks", "spread [%]", "why"],
                  [[", ".join(map(str, g["members"])), 100 * g["spread"], g["reason"]]
                   for g in res["equivalent"][:8]])
    doc.figure("accuracy_vs_n", figure_png(accuracy_vs_n_fig(res)),
               "Predicted 3-axis RMS about the truth vs N (best cone angle and bandwidth per "
               "scheme and estimator); simulated check with its 95 % interval as error bars")
    _fault_tolerance(doc, res)
    if res.get("per_rho"):
        _rho(doc, res, gdop_rows or [])
    return {"recommended": res["recommended"], "summary": decision_summary(res)}


def _assumptions(doc, a: dict):
    doc.h2("Assumptions")
    rows = []
    for key, item in a.items():
        v = item.get("value")
        if isinstance(v, (list, dict)):
            v = json.dumps(v)
        rows.append([key, v, item.get("unit", ""), item.get("source", "")])
    doc.table(["input", "value", "unit / meaning", "from"], rows, cls="assumptions")
    user = [k for k, i in a.items() if i.get("source") == "user"]
    doc.p("Given by the user: " + (", ".join(user) if user else "nothing") + ". Everything "
          "marked 'default' is the tool's choice; 'assumption' and 'definition' rows say how the "
          "prediction is made.", "note")


def _check(doc, res: dict):
    c = res.get("check")
    if not c:
        doc.p("No simulation check in this result (rerun design --recommend with --check K).", "note")
        return
    doc.p(f"The top designs were simulated {c['replicates']} times with common random numbers "
          f"(replicate r draws the same gyro noise in every design; seed {c['seed']}), through "
          "the simulator's own noise generator and the real estimators. Simulated values are "
          "√(mean over runs of x²) with a 95 % interval (χ², Satterthwaite ν; exact for the "
          "Gaussian mean and angle errors). Because the runs are paired, their deviations from "
          "the prediction move together across designs. "
          f"{c['inside_95']} of {c['compared']} predictions lie inside their interval.")
    rows, flags = [], []
    for d in c["designs"]:
        for ax in AXES:
            cells = [d["label"] if ax == "x" else "", ax]
            bad = False
            for key in ("rms_deg_s", "std_deg_s", "mean_deg_s", "angle_deg"):
                e = d["axes"][ax][key]
                cells += [e["predicted"], _ci_text(e["monte_carlo"])]
                bad |= e["agrees"] is False
            rows.append(cells)
            flags.append(bad)
    doc.table(["design", "axis", "RMS pred.", "RMS sim. [95 %]", "1σ pred.", "1σ sim.",
               "mean-error pred.", "mean-error sim.", "angle@T pred. [deg]", "angle@T sim."],
              rows, flags=flags)
    if c.get("paired"):
        doc.p("Paired differences against the recommended design (mean over runs of the "
              "difference of the 3-axis mean square, 95 % CI; 'resolved' when it excludes 0):")
        doc.table(["against", "mean difference [(deg/s)²]", "95 % CI", "resolved"],
                  [[p["against"], p["mean_square_difference_deg2_s2"]["mean"],
                    f"{p['mean_square_difference_deg2_s2']['ci_low']:.3g} – "
                    f"{p['mean_square_difference_deg2_s2']['ci_high']:.3g}"
                    if p["mean_square_difference_deg2_s2"]["ci_low"] is not None else "–",
                    p["resolved"]] for p in c["paired"]])


def _fault_tolerance(doc, res: dict):
    doc.h3("Fault tolerance (geometry)")
    doc.p("Worst-case GDOP over every choice of failed gyros, at each design's cone angle; "
          "'3 axes' says whether every choice keeps a 3-axis rate. Detectable: a single fault "
          "shows in the parity residual (every gyro has a parity signature, N ≥ 4); isolable: no "
          "two gyros share a parity direction. The detection machinery itself is separate.", "note")
    seen, rows = set(), []
    for d in res["designs"]:
        key = (d["scheme"], d["n"], round(d["alpha_deg"], 2))
        if key in seen:
            continue
        seen.add(key)
        ft = d.get("fault_tolerance", {})
        rows.append([d["scheme"], d["n"], d["alpha_deg"], ft.get("gdop"),
                     ft.get("worst_gdop_after", {}).get("1"), ft.get("three_axes_after", {}).get("1"),
                     ft.get("worst_gdop_after", {}).get("2"), ft.get("three_axes_after", {}).get("2"),
                     ft.get("detectable"), ft.get("isolable"),
                     ft.get("lost_axis_example", {}).get("2") or ""])
    rows.sort(key=lambda r: (r[1], r[0]))
    doc.table(["scheme", "N", "α [deg]", "GDOP", "worst after 1", "3 axes", "worst after 2",
               "3 axes", "detectable", "isolable", "how an axis is lost (2 failures)"], rows)


def _rho(doc, res: dict, gdop_rows: list[GdopRobustnessRow]):
    doc.h3("The correlation ρ is a condition, not a choice")
    rho = res["assumptions"]["rho"]["value"]
    doc.p(f"The gyros' common correlation is not known exactly: the search was run at each ρ in "
          f"{rho} and the recommendation is the design whose worst predicted 3-axis RMS over "
          "that range is smallest (min-max).")
    doc.table(["assumed ρ", "best design at that ρ", "3-axis RMS [deg/s]"],
              [[r, _label(ds[0]), ds[0]["rms_3axis_deg_s"]] for r, ds in res["per_rho"].items() if ds])
    rows = []
    rhos = list(res["per_rho"])
    for row in res.get("robustness", []):
        rows.append([row["chosen_for_rho"], row["design"]] + [
            "–" if row["at_rho"].get(r) is None else
            f"{row['at_rho'][r]['rms_3axis_deg_s']:.4g} (+{100 * row['at_rho'][r]['vs_best_at_rho']:.1f} %)"
            for r in rhos])
    doc.p("Robustness: the design chosen for each assumed ρ̂, evaluated at every ρ of the range "
          "(in brackets: how much worse than that ρ's own best):")
    doc.table(["chosen for ρ̂", "design"] + [f"at ρ = {r}" for r in rhos], rows)
    _gdop_robustness(doc, gdop_rows)


def _gdop_robustness(doc, gdop_rows: list[GdopRobustnessRow]):
    rows = [[r.scheme, r.n, r.chosen_for_rho, r.alpha_deg, r.worst_rho, r.gdop, r.gdop_best,
             r.excess_percent, r.minmax_alpha_deg, r.minmax_gdop] for r in gdop_rows]
    doc.p("GDOP alone: the cone angle optimal at the largest ρ, evaluated where it is worst, and "
          "the min-max cone angle over the range:")
    doc.table(["scheme", "N", "chosen for ρ", "its α [deg]", "worst at ρ", "its GDOP there",
               "best GDOP there", "excess [%]", "min-max α [deg]", "min-max worst GDOP"], rows)


def adev_section(doc, res: dict, a: AdevFigure):
    """Draw the recommended design's fused ADEV against its single gyros (computed by
    :func:`gyroarray.design.evidence.recommended_adev`).

    One run of the design's horizon (at least 600 s); dashed: gyro 1's ADEV × √(3/N)
    (what averaging N alike gyros gives per axis at long τ).
    """
    d = res["recommended"]
    fig, axs = agg_figure(8.5, 5.2)
    ax = axs[0]
    to = units.rad_s_to_deg_h
    k = a.reference_factor
    for i, c in enumerate(a.singles):
        ax.loglog(c.taus_s, to(c.adev_rad_s), color="0.6", lw=0.7,
                  label="single gyros (each)" if i == 0 else None)
        if i == 0:
            ax.loglog(c.taus_s, to(c.adev_rad_s) * k, "k--", lw=1.0,
                      label=f"gyro 1 × √(3/N) = ×{k:.3f}")
    for i, (c, axis) in enumerate(zip(a.fused, AXES)):
        ax.fill_between(c.taus_s, to(c.ci_low_rad_s), to(c.ci_high_rad_s), color=f"C{i}",
                        alpha=0.2, lw=0)
        ax.loglog(c.taus_s, to(c.adev_rad_s), color=f"C{i}", lw=1.6,
                  label=f"fused {axis} ({a.estimator})")
    rho = a.rho if a.rho is not None else math.nan
    dt = a.dt_s
    ax.set(title=f"{_label(d)}, ρ = {rho:g}: one {a.record_s:g} s record", xlabel="averaging time τ [s]",
           ylabel="Allan deviation [deg/h]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    note = (f"Record length {a.record_s:g} s at {1 / dt:g} Hz (seed {a.seed}), gyro correlation ρ = {rho:g} "
            "(with ρ > 0 the common part does not average out: the fused curves stay above the "
            "dashed line); bands: 1σ confidence of "
            "each point. At τ above the filter's time constants the fused curves meet the dashed "
            "√(3/N) line when the DC gain is 1; predicted long-τ fused ARW x/y/z "
            + " / ".join(f"{v:.4g}" for v in a.predicted_arw_long_deg_rt_h)
            + " deg/√h.")
    doc.h3("Allan deviation of the recommended design")
    doc.figure("adev_recommended", figure_png(fig), note)
