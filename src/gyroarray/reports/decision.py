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
import re
import textwrap
from typing import Any

import numpy as np

from gyroarray.analysis.adev_curves import AdevFigure
from gyroarray.core import units
from gyroarray.design.evidence import (GdopRobustnessRow, fused_single_ratio, mirror_comparison,
                                       noise_and_space, record_rho, what_would_change)
from gyroarray.design.recommend import design_label as _recommend_label
from gyroarray.design.recommend import estimator_kwargs
from gyroarray.reports.design_plots import agg_figure, array_fig, figure_png, accuracy_vs_n_fig
from gyroarray.effects.names import G_SENSITIVITY

__all__ = ["write_sections", "decision_summary", "decision_block", "adev_section", "adev_fig",
           "equivalence_rows", "pct", "rho_candidates", "best_at_rho", "robustness_rows",
           "motion_words"]

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


OBJECTIVES = {"rate": "the 3-axis RMS of the rate error about the truth over the horizon",
              "angle": "the 3-axis angle error at the horizon"}


def pct(x: float) -> str:
    """A relative difference in per cent with enough digits that it never rounds onto a bound
    (0.9987 % reads 0.9987 %, not 1 %)."""
    v = 100.0 * float(x)
    if abs(v) < 1e-7:
        return "0 %"
    return f"{v:.4g} %" if abs(v) < 10 else f"{v:.3g} %"


def _failed(gyros) -> str:
    g = list(gyros or [])
    if not g:
        return "no gyro failed"
    return ("gyro " if len(g) == 1 else "gyros ") + ", ".join(map(str, g)) + " failed"


def _rho_range(res: dict, d: dict) -> tuple[float, float] | None:
    rr = d.get("rho_range")
    if rr is None:
        v = res["assumptions"].get("rho", {}).get("value")
        rr = v if isinstance(v, list) else ([v, v] if v is not None else None)
    return None if rr is None else (float(min(rr)), float(max(rr)))


def _case_text(c: dict, horizon: float) -> str:
    return (f"at ρ = {c['rho']:.4g} with {_failed(c.get('failed_gyros'))}: "
            f"{c['rms_3axis_deg_s']:.4g} deg/s 3-axis RMS about the truth, "
            f"{c['angle_deg']:.4g} deg angle error at the horizon ({horizon:g} s)")


def _mirror_sentence(res: dict, r: dict) -> str | None:
    """Why the recommendation is mounted as it is (α > 90° or reversed gyros), with numbers."""
    signs = r.get("mounting_signs") or []
    reversed_ = [k + 1 for k, v in enumerate(signs) if v < 0]
    if not (r["alpha_deg"] > 90.0 or reversed_):
        return None
    rr = _rho_range(res, r) or (0.0, 0.0)
    if r["alpha_deg"] > 90.0 and r["scheme"] == 2 and not reversed_:
        what = (f"α = {r['alpha_deg']:.2f}° > 90° is the {180.0 - r['alpha_deg']:.2f}° cone with its "
                "axial gyro mounted reversed (on −z)")
    elif r["alpha_deg"] > 90.0:
        what = (f"α = {r['alpha_deg']:.2f}° > 90° with gyro(s) {', '.join(map(str, reversed_))} reversed "
                "is a mounting sense of the cone")
    else:
        what = f"gyro(s) {', '.join(map(str, reversed_))} mounted reversed"
    why = ("with correlated noise, reversing gyros relative to the others moves the common-mode "
           "noise into the parity space, where the estimator cancels it (at ρ = 0 both mountings "
           "are identical)")
    mirror = next((c for c in (res.get("check") or {}).get("designs", [])
                   if c.get("role") == "mounting mirror"), None)
    wc = r.get("worst_case")
    if mirror is not None and wc:
        m = mirror["rms_3axis_deg_s"]["predicted"]
        return (f"Why this mounting: {what}; {why}: worst case {wc['rms_3axis_deg_s']:.4g} deg/s "
                f"3-axis RMS (ρ = {wc['rho']:.4g}, {_failed(wc['failed_gyros'])}) against "
                f"{m:.4g} deg/s for its mounting mirror (ρ = {mirror['at']['rho']:.4g}, "
                f"{_failed(mirror['at']['failed_gyros'])}), {m / wc['rms_3axis_deg_s']:.3g}× "
                "(the predictor; the simulation check below tests both).")
    fails = res["assumptions"].get("failures", {}).get("value", 0) or 0
    mc = mirror_comparison(r, rr, int(fails))
    if mc is None:
        return f"Why this mounting: {what}; {why}."
    a, b = mc["design"], mc["mirror"]
    mir = (f"α = {mc['mirror_alpha_deg']:.2f}°" + (", gyro(s) " + ", ".join(map(str, mc["mirror_reversed"]))
                                                   + " reversed" if mc["mirror_reversed"] else ", every gyro +"))
    return (f"Why this mounting: {what}; {why}: worst white-noise GDOP of the least squares with "
            f"weights fixed for ρ = {mc['design_rho']:.4g}, over ρ in [{rr[0]:g}, {rr[1]:g}] and "
            f"{fails} failed gyro(s), {a['gdop']:.4g} (ρ = {a['rho']:.4g}, {_failed(a['failed_gyros'])}) "
            f"against {b['gdop']:.4g} for its mirror ({mir}; ρ = {b['rho']:.4g}, "
            f"{_failed(b['failed_gyros'])}), {mc['ratio']:.3g}×.")


def decision_block(doc, res: dict):
    """The decision block: the array as mounted, the design ρ, the objective, the worst
    case and its accuracy, the runner-up's worst case, what would change the choice, the
    error budget and, when the array has α > 90° or reversed gyros, why.

    Designs without a ``worst_case`` (results of older versions) get the summary only.
    """
    r = res["recommended"]
    a = res["assumptions"]
    horizon = a["horizon_s"]["value"]
    wc = r.get("worst_case")
    if wc is None:
        for s in decision_summary(res):
            doc.p(s, "decision")
        return
    doc.p(f"Build: {_label(r)}.", "decision")
    if r.get("mounting"):
        doc.p(f"Mounting: {r['mounting']}.", "decision")
    rr = _rho_range(res, r)
    obj = res.get("objective") or r.get("objective") or "rate"
    src = a.get("design_rho", {}).get("source") if isinstance(a.get("design_rho"), dict) else None
    if r.get("design_rho") is None:
        doc.p(f"Estimator: {r['estimator']}; its weights do not depend on ρ.", "decision")
    else:
        how = ("given by the user" if src == "user" else
               "chosen min-max over the ρ range" if rr and rr[1] > rr[0] else "the stated ρ")
        doc.p(f"Estimator: {r['estimator']}, its weights built once for the design ρ = "
              f"{r['design_rho']:.4g} ({how}) and kept at every true ρ; after an isolated failure "
              "it drops that gyro and recomputes its weights for the same design ρ.", "decision")
    rng = f" over ρ in [{rr[0]:g}, {rr[1]:g}]" if rr else ""
    fails = a.get("failures", {}).get("value", 0) or 0
    doc.p(f"Objective: {obj} ({OBJECTIVES.get(obj, obj)}), ranked by its worst case{rng} × every set "
          f"of {fails} failed gyro(s).", "decision")
    s = f"Worst case: {_case_text(wc, horizon)}."
    if r.get("typical"):
        s += f" Typical (design ρ, every gyro): {_case_text(r['typical'], horizon)}."
    if r.get("oracle_worst_case"):
        o = r["oracle_worst_case"]
        s += (f" Oracle (weights that know the true ρ, not buildable; for comparison only): worst "
              f"{o['rms_3axis_deg_s']:.4g} deg/s, {o['angle_deg']:.4g} deg.")
    doc.p(s, "decision")
    if r.get("mdb_statement"):
        # the window, threshold, rho grid and tied gyros the MDB was computed with, as stated
        doc.p(f"Detection: {r['mdb_statement']}.", "decision")
    elif r.get("mdb_deg_s") is not None:
        tied = r.get("mdb_worst_gyros") or [r.get("mdb_worst_gyro", "?")]
        doc.p(f"Minimum detectable bias {r['mdb_deg_s']:.3g} deg/s (worst gyro"
              f"{'s (tied)' if len(tied) > 1 else ''}: {', '.join(map(str, tied))}; false alarms "
              f"{r.get('far_per_h', '?')} per hour, missed detection {r.get('p_md', '?')}).", "decision")
    cm = res.get("common_mode")
    if cm and a.get("common_mode"):
        # the common-mode frame the design rests on, and the decision under the other frame
        doc.p(f"Common mode: the {cm['chosen']} frame ({a['common_mode'].get('source', 'default')}): "
              f"{a['common_mode'].get('unit', '')}.", "decision")
        for f in cm.get("frames", {}).values():
            if f.get("statement"):
                doc.p(f["statement"], "note")
    if a.get("flicker_model"):
        doc.p(f"Flicker model: {a['flicker_model'].get('unit', '')}.", "note")
    if res.get("tie") or r.get("tie"):
        doc.p("Tie: " + (res.get("tie") or r.get("tie")) + ".", "note")
    ru = res.get("runner_up")
    if ru and ru.get("worst_case"):
        doc.p(f"Runner-up: {_label(ru)}" + (f" ({ru['mounting']})" if ru.get("mounting") else "")
              + f"; its worst case {_case_text(ru['worst_case'], horizon)}.", "decision")
    why = _mirror_sentence(res, r)
    if why:
        doc.p(why, "decision")
    chk = next((c for c in (res.get("check") or {}).get("designs", []) if c.get("role") == "recommended"),
               None)
    if chk:
        t = chk["rms_3axis_deg_s"]["monte_carlo"]
        doc.p(f"{res['check']['replicates']} paired simulated runs at the worst case give a 3-axis "
              f"RMS of {_ci_text(t)} deg/s against the predicted {chk['rms_3axis_deg_s']['predicted']:.4g}.",
              "decision")
    doc.p("What would change the choice:")
    doc.ul(res.get("what_changes_the_choice") or what_would_change(res) or ["nothing computed"])
    _budget(doc, r, horizon)
    if r.get("axes"):
        doc.figure("array_mounted", figure_png(array_fig(r["axes"], _label(r), r.get("mounting_signs"))),
                   f"The recommended array as mounted: {r.get('mounting', _label(r))} "
                   "(arrows: each gyro's sensitive axis, signs included; red: reversed)")


def _budget(doc, r: dict, horizon: float):
    b = r.get("error_budget")
    if not b or not b.get("terms"):
        return
    at = b.get("at", {})
    big_r, big_a = b.get("largest_rms_term"), b.get("largest_angle_term")
    rows = []
    for name, t in b["terms"].items():
        mark = " / ".join(w for w, k in (("largest RMS", big_r), ("largest angle", big_a)) if k == name)
        rows.append([name, t.get("rms_deg_s"), t.get("angle_deg"), mark])
    if b.get("tracking"):
        rows.append(["tracking (lag on the motion)", b["tracking"].get("rms_deg_s"),
                     b["tracking"].get("angle_deg"), ""])
    if b.get("total"):
        rows.append(["total", b["total"].get("rms_deg_s"), b["total"].get("angle_deg"), ""])
    doc.p(f"Error budget of the recommendation at ρ = {at.get('rho', math.nan):.4g}, "
          f"{_failed(at.get('failed_gyros'))} (its worst case); angle at the horizon "
          f"{b.get('horizon_s', horizon):g} s:")
    doc.table(["term", "RMS [deg/s]", "angle @T [deg]", "largest"], rows)
    if b.get("undetected_fault"):
        doc.p(b["undetected_fault"].get("statement", "undetected fault"), "note")
    ign = b.get("ignored_effects")
    if ign is not None:
        doc.p("Left out of the predictor: " + (", ".join(map(str, ign)) if ign else
                                               "nothing listed") + ".", "note")


#: Each reason recommend() may give for an equivalence group, and when it applies.
_REASONS = (
    ("kf_array and kf_single are the same filter", "kf_pair"),
    ("the Kalman filters are the low-passed least squares", "kf_ls"),
    ("gls, ols and naive have the same weights", "ls_pair"),
    ("both schemes reach the isotropic optimum", "schemes"),
)


def _geometry(d: dict) -> tuple:
    return (d["scheme"], d["n"], round(d["alpha_deg"], 6), tuple(d.get("mounting_signs") or ()))


def _applies(kind: str, members: list[dict]) -> bool:
    by_geo: dict = {}
    for m in members:
        by_geo.setdefault(_geometry(m), set()).add(m["estimator"])
    if kind == "kf_pair":
        return any({"kf_array", "kf_single"} <= e for e in by_geo.values())
    if kind == "kf_ls":
        return any(e & {"kf_array", "kf_single"} and e & {"gls", "ols"} for e in by_geo.values())
    if kind == "ls_pair":
        return any(len(e & {"gls", "ols", "naive"}) > 1 for e in by_geo.values())
    if kind == "schemes":
        ns = {m["n"] for m in members}
        gd: list[Any] = [m.get("gdop") for m in members]         # checked free of None below
        return (len({m["scheme"] for m in members}) > 1 and len(ns) == 1 and None not in gd
                and max(gd) - min(gd) <= 1e-6 * max(gd))
    return False


def _objective(d: dict, obj: str) -> float | None:
    wc = d.get("worst_case")
    if wc:
        return wc.get("angle_deg" if obj == "angle" else "rms_3axis_deg_s")
    return d.get("rms_3axis_deg_s")


def equivalence_rows(res: dict) -> list[dict]:
    """The equivalence groups of a result as the report prints them.

    Per group: ``members`` (ranks), ``spread`` (largest / smallest worst-case objective − 1,
    recomputed from the members), ``reason`` (only the reasons of the result that apply to
    these members, and the spread with enough digits), ``dropped`` (reasons given that do
    not apply).
    """
    by_rank = {d.get("rank"): d for d in res.get("designs", [])}
    obj = res.get("objective") or res["recommended"].get("objective") or "rate"
    out = []
    for g in res.get("equivalent", []):
        members = [by_rank[k] for k in g["members"] if k in by_rank]
        vals = [v for v in (_objective(m, obj) for m in members) if v is not None]
        spread = (max(vals) / min(vals) - 1.0) if vals and min(vals) > 0 else abs(g.get("spread", 0.0))
        text = re.sub(r"^(identical by theory( \(spread [^)]*\))?|within 1 %): ", "", g.get("reason", ""))
        bits, dropped = [], []
        for bit in (b.strip() for b in text.split("; ") if b.strip()):
            kind = next((k for key, k in _REASONS if bit.startswith(key)), None)
            if bit.startswith("the predictions differ by"):
                continue                      # restated below with enough digits
            if kind is None or _applies(kind, members):
                bits.append(bit)
            else:
                dropped.append(bit)
        unit = "deg at the horizon" if obj == "angle" else "deg/s"
        if not vals:
            bits.append("no worst case given")
        elif spread < 1e-9:
            bits.append(f"their worst cases are equal to rounding ({min(vals):.6g} {unit})")
        else:
            bits.append(f"their worst cases differ by {pct(spread)} ({min(vals):.6g} to {max(vals):.6g} {unit})")
        out.append({"members": list(g["members"]), "spread": spread, "kind": g.get("kind"),
                    "reason": "; ".join(bits), "dropped": dropped})
    return out


def _worst_case_summary(res: dict) -> list[str]:
    r = res["recommended"]
    horizon = res["assumptions"]["horizon_s"]["value"]
    obj = res.get("objective") or r.get("objective") or "rate"
    rd = r.get("design_rho")
    lines = [f"Build: {_label(r)}" + (f"; {r['mounting']}" if r.get("mounting") else "") + "."]
    lines.append(f"Ranked on the {obj} objective by the worst case"
                 + (f"; estimator weights built for the design ρ = {rd:.4g}" if rd is not None else "")
                 + f"; worst case {_case_text(r['worst_case'], horizon)}.")
    ru = res.get("runner_up")
    if ru and ru.get("worst_case"):
        lines.append(f"Runner-up: {_label(ru)}; worst case {_case_text(ru['worst_case'], horizon)}.")
    if res.get("tracking_limit"):
        lines.append("Tracking: " + res["tracking_limit"]["statement"] + ".")
    if res.get(G_SENSITIVITY):
        lines.append(res[G_SENSITIVITY]["statement"] + ".")
    return lines


def decision_summary(res: dict) -> list[str]:
    """The decision in a few sentences (also printed by ``make demo``)."""
    r = res["recommended"]
    p = r["predicted"]
    a = res["assumptions"]
    horizon = a["horizon_s"]["value"]
    chk = _check_of(res, r)
    if r.get("worst_case") is not None:
        return _worst_case_summary(res)
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
    if res.get(G_SENSITIVITY):
        lines.append(res[G_SENSITIVITY]["statement"] + ".")
    return lines


# -- the designs scored at each ρ (the per-ρ and robustness tables) -----------------

#: Relative agreement the predictor, set up from a result's assumptions, must reach with the
#: decision's own per-ρ score of the recommendation before its mounting mirrors are scored the
#: same way (the two are one computation: they agree to ~1e-15 on the demo).
REPRODUCE_RTOL = 1e-6


def _key(d: dict) -> tuple:
    return (d["scheme"], d["n"], d["estimator"], d.get("bandwidth_hz"), round(float(d["alpha_deg"]), 6),
            tuple(int(v) for v in (d.get("mounting_signs") or ())),
            None if d.get("design_rho") is None else round(float(d["design_rho"]), 9))


def _intact_ms(d: dict, g, space, rho_t: float, rho_fit: float) -> float:
    """Mean square [(rad/s)²] of the 3-axis rate error of design ``d`` (its cone, mounting
    signs, estimator and bandwidth), intact, its estimator built for ``rho_fit`` and run on
    gyros of correlation ``rho_t`` [-] (:func:`gyroarray.design.predict.predict`)."""
    # deferred: the predictor and the estimators load only when the per-ρ tables are drawn
    from gyroarray.core.layout import Layout
    from gyroarray.design.predict import predict
    from gyroarray.design.robust import mounted_axes
    from gyroarray.estimators import get_estimator
    signs = np.asarray(d.get("mounting_signs") or [1] * d["n"], dtype=float)
    H = mounted_axes(d["scheme"], d["n"], np.array([math.radians(d["alpha_deg"])]), signs)[0]
    est = get_estimator(d["estimator"])(**estimator_kwargs(d["estimator"], d.get("bandwidth_hz"), g))
    est.fit(Layout(H), g.with_rho(rho_fit).noise_model(d["n"]), space.dt_s)
    p = predict(est, g.with_rho(rho_t).noise_model(d["n"]), n_samples=space.n_samples,
                settle_s=space.settle_s, swing=space.swing)
    return float(sum(units.deg_s_to_rad_s(v["rms_deg_s"]) ** 2 for v in p.axes.values()))


def _scores_by_rho(d: dict, g, space, rhos: list[str], lo: float, hi: float) -> dict:
    """3-axis RMS [deg/s] of design ``d`` intact at each ρ of ``rhos``: the estimator is built
    once (for its design ρ; a ρ-free estimator at the range's low end, as the decision builds
    it) and fixed, so its error variance is linear in the true ρ and two predictions (the
    range's ends) give every ρ exactly."""
    rd = d.get("design_rho")
    fit = lo if rd is None else float(rd)
    ms_lo = _intact_ms(d, g, space, lo, fit)
    ms_hi = ms_lo if hi <= lo else _intact_ms(d, g, space, hi, fit)
    out = {}
    for r in rhos:
        t = 0.0 if hi <= lo else (float(r) - lo) / (hi - lo)
        out[r] = float(units.rad_s_to_deg_s(math.sqrt(max(ms_lo + t * (ms_hi - ms_lo), 0.0))))
    return out


def rho_candidates(res: dict) -> dict | None:
    """Every candidate of a ranged decision scored at each ρ of its grid (intact array).

    The candidates are the designs of the result (each at the mounting sense, cone angle,
    bandwidth and design ρ the decision chose for the range, with the decision's own
    ``rms_by_rho``) and, for each, its mounting mirror
    (:func:`gyroarray.design.robust.mirror_pattern`: the same cone, estimator, bandwidth and
    design ρ with the other mounting sense, a pattern the decision's search scored too),
    predicted here by :func:`gyroarray.design.predict.predict`. Without the mirrors the
    best design at ρ < 0 is missed: reversing gyros pays only at ρ > 0.

    The mirrors are scored only when the predictor, set up from the result's assumptions,
    reproduces the decision's own per-ρ scores of the recommendation to
    :data:`REPRODUCE_RTOL` (else ``mirror_note`` says why they are left out).

    Parameters
    ----------
    res : dict
        A ``design --recommend`` result with ``per_rho``.

    Returns
    -------
    dict or None
        ``rhos`` (the grid, as the result's keys), ``candidates`` (design dicts with
        ``rms_by_rho`` {ρ: 3-axis RMS [deg/s]} and ``source``), ``mirror_note`` (None when
        the mirrors were scored); None without a per-ρ grid.
    """
    rhos = [r for r, ds in (res.get("per_rho") or {}).items()]
    if not rhos:
        return None
    cands, seen = [], set()
    for d in res.get("designs", []):
        by = d.get("rms_by_rho") or {}
        if not all(by.get(r) is not None for r in rhos) or _key(d) in seen:
            continue
        seen.add(_key(d))
        cands.append({**d, "rms_by_rho": {r: float(by[r]) for r in rhos},
                      "source": f"rank {d.get('rank', '?')} of the decision"})
    note = None
    lo, hi = min(float(r) for r in rhos), max(float(r) for r in rhos)
    rec = res["recommended"]
    try:
        g, space = noise_and_space(res["assumptions"])
        own = _scores_by_rho(rec, g, space, rhos, lo, hi)
        ref = rec.get("rms_by_rho") or {}
        bad = max((abs(own[r] / ref[r] - 1.0) for r in rhos if ref.get(r)), default=math.inf)
    except (KeyError, TypeError, ValueError) as e:      # a result of another version
        g, space = None, None
        bad, note = math.inf, f"the result's assumptions do not rebuild its predictor ({e})"
    if note is None and not bad <= REPRODUCE_RTOL:
        note = ("the predictor set up from the result's assumptions does not reproduce the "
                f"decision's own scores of the recommendation (relative difference {bad:.3g}; a "
                "per-gyro model, a motion profile or a sensor filter the assumptions do not carry)")
    if note is None:
        # deferred: the design layer's geometry loads only when the per-ρ tables are drawn
        from gyroarray.design.robust import mirror_pattern
        for c in list(cands):
            m_alpha, m_signs = mirror_pattern(c["scheme"], c["alpha_deg"],
                                              np.asarray(c.get("mounting_signs") or [1] * c["n"], float))
            m = {k: c[k] for k in ("scheme", "n", "estimator", "bandwidth_hz", "design_rho") if k in c}
            m.update(alpha_deg=float(m_alpha), mounting_signs=[int(v) for v in m_signs])
            if _key(m) in seen:
                continue
            seen.add(_key(m))
            m["rms_by_rho"] = _scores_by_rho(m, g, space, rhos, lo, hi)
            m["source"] = f"mounting mirror of {c['source']} (predictor)"
            cands.append(m)
    return {"rhos": rhos, "candidates": cands, "mirror_note": note}


def best_at_rho(rc: dict, rho: str) -> dict:
    """The candidate of :func:`rho_candidates` with the smallest 3-axis RMS at ``rho``."""
    return min(rc["candidates"], key=lambda c: c["rms_by_rho"][rho])


def robustness_rows(rc: dict, rec: dict) -> list[dict]:
    """The design best at each assumed ρ̂ (and the recommendation, min-max over the range),
    evaluated at every ρ of the grid.

    Returns
    -------
    list of dict
        ``chosen_for`` (the ρ̂ keys, or ``"min-max (the recommendation)"``), ``design`` (the
        candidate), ``at`` {ρ: (3-axis RMS [deg/s], excess over that ρ's best [-])}.
    """
    best = {r: best_at_rho(rc, r)["rms_by_rho"][r] for r in rc["rhos"]}
    rows: list[dict] = []
    for r in rc["rhos"]:
        c = best_at_rho(rc, r)
        row = next((x for x in rows if _key(x["design"]) == _key(c)), None)
        if row is None:
            rows.append({"chosen_for": [r], "design": c})
        else:
            row["chosen_for"].append(r)
    own = next((c for c in rc["candidates"] if _key(c) == _key(rec)), None)
    if own is not None:
        rows.append({"chosen_for": "min-max (the recommendation)", "design": own})
    for row in rows:
        row["at"] = {r: (row["design"]["rms_by_rho"][r], row["design"]["rms_by_rho"][r] / best[r] - 1.0)
                     for r in rc["rhos"]}
    return rows


def motion_words(m) -> str:
    """The motion a result's check and ADEV record simulate, in words (``assumptions.motion.value``).

    A swing is A·sin(2π f t) on every body axis at once (:func:`gyroarray.design.predict.swing_truth`:
    the same rate about x, y and z, i.e. a rotation about the (1, 1, 1) diagonal at √3·A), not
    about each axis in turn."""
    if not isinstance(m, dict):
        return "at rest" if m in (None, "none", "static") else str(m)
    a, f = float(m.get("swing_amplitude_deg_s") or 0.0), float(m.get("swing_frequency_hz") or 0.0)
    return (f"swing A·sin(2π f t), A = {a:g} deg/s, f = {f:g} Hz, about x, y and z at once (the same "
            f"rate on every body axis: a rotation about the (1, 1, 1) diagonal at √3·A = "
            f"{math.sqrt(3.0) * a:.4g} deg/s)")


# -- sections ---------------------------------------------------------------------

def write_sections(doc, res: dict, top: int = 15,
                   gdop_rows: list[GdopRobustnessRow] | None = None, *,
                   rho_candidates: dict | None = None) -> dict:
    """Add the decision, assumptions and evidence sections to a report document.

    ``gdop_rows``: :func:`gyroarray.design.evidence.gdop_robustness_table` over the
    result's ρ range (drawn with the ρ robustness; none: that table is left out).
    ``rho_candidates``: :func:`rho_candidates` of ``res`` when already computed (saved
    beside the result by the report); None: computed here.
    """
    doc.h2("Decision")
    decision_block(doc, res)
    eqs = equivalence_rows(res)
    eq = [g for g in eqs if res["recommended"].get("rank") in g["members"]]
    if eq:
        doc.p("Close to the recommendation (ranks " + ", ".join(map(str, eq[0]["members"])) + "): "
              + eq[0]["reason"] + ".", "note")
    if res["recommended"].get("worst_case") is None:
        doc.p("What would change the choice:")
        doc.ul(res.get("what_changes_the_choice", []))
    _assumptions(doc, res["assumptions"])
    doc.h2("Evidence: the prediction and the simulation")
    _check(doc, res)
    doc.h3("Every design, best first (analytic predictor)")
    worst = any(d.get("worst_case") for d in res["designs"][:top])
    doc.p("3-axis RMS about the truth = √(Σ over x, y, z of the mean square over the horizon). "
          + ("The worst-case columns are each design's worst over the ρ range × failures, at the ρ "
             "and with the failed gyros they name (the ranking objective); the other columns are "
             "the intact design at the ρ of the column 'at ρ'. " if worst else
             "Every column is at the ρ of the column 'at ρ'. ")
          + "Per axis (mean over x, y, z shown): RMS about the truth and "
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
        wc = d.get("worst_case") or {}
        row = [d["rank"], d["scheme"], d["n"], d["alpha_deg"], _reversed(d), d["estimator"],
               "none" if d["bandwidth_hz"] is None else d["bandwidth_hz"]]
        if worst:
            row += [wc.get("rho"), _failed(wc.get("failed_gyros")) if wc else None,
                    wc.get("rms_3axis_deg_s"), wc.get("angle_deg")]
        row += [d.get("rho"), d["rms_3axis_deg_s"], mean("rms_deg_s"), mean("std_deg_s"),
                mean("mean_deg_s"), mean("angle_deg_at_horizon"), mean("arw_long_deg_rt_h"),
                mean("rrw_long_deg_h_rt_h"), mean("dc_gain"), d.get("gdop"),
                ft.get("worst_gdop_after", {}).get("1"), ft.get("worst_gdop_after", {}).get("2")]
        rows.append(row)
    doc.table(["rank", "scheme", "N", "α [deg]", "reversed", "estimator", "bandwidth [Hz]"]
              + (["worst at ρ", "worst: failed", "worst 3-axis RMS [deg/s]", "worst angle @T [deg]"]
                 if worst else [])
              + ["at ρ", "3-axis RMS [deg/s]", "RMS/axis [deg/s]", "1σ/axis [deg/s]",
                 "mean error RMS [deg/s]", "angle @T [deg]", "fused ARW long-τ [deg/√h]",
                 "fused RRW long-τ [deg/h/√h]", "DC gain [-]", "GDOP (worst over ρ)",
                 "worst GDOP 1 fail", "worst GDOP 2 fail"], rows)
    if eqs:
        doc.p("Designs the search groups (equal by theory, or fewer gyros at the same worst case), "
              "with only the reasons that apply to the members and how far apart their worst cases "
              "are (each over the ρ range × failures):")
        doc.table(["ranks", "worst-case spread [%]", "why"],
                  [[", ".join(map(str, g["members"])), pct(g["spread"])[:-2], g["reason"]]
                   for g in eqs[:8]])
    doc.figure("accuracy_vs_n", figure_png(accuracy_vs_n_fig(res)),
               ("Predicted 3-axis RMS about the truth vs N at one condition: each design's worst "
                "case over the ρ range × failures (the ranking's condition), the best design per N, "
                "scheme and estimator; the simulated check with its 95 % interval as error bars, "
                "each at its design's worst case (ρ and failed gyros in the legend)"
                if worst else
                "Predicted 3-axis RMS about the truth vs N (best cone angle and bandwidth per "
                "scheme and estimator); simulated check with its 95 % interval as error bars"))
    _fault_tolerance(doc, res)
    if res.get("per_rho"):
        _rho(doc, res, gdop_rows or [], rho_candidates)
    return {"recommended": res["recommended"], "summary": decision_summary(res)}


def _reversed(d: dict) -> str:
    rev = [k + 1 for k, v in enumerate(d.get("mounting_signs") or []) if v < 0]
    return ", ".join(map(str, rev)) if rev else "none"


def _assumptions(doc, a: dict):
    doc.h2("Assumptions")
    rows = []
    for key, item in a.items():
        v = item.get("value")
        if isinstance(v, (list, dict)):
            v = json.dumps(v)
        if key == "motion":                      # the motion the check and the ADEV record simulate
            v = motion_words(item.get("value"))
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
        at = d.get("at")
        where = (f"ρ = {at['rho']:.4g}, {_failed(at.get('failed_gyros'))}" if at else
                 f"ρ = {d.get('rho', math.nan):.4g}")
        for ax in AXES:
            cells = [(f"{d.get('role', '')}: " if d.get("role") else "") + d["label"] if ax == "x" else "",
                     where if ax == "x" else "", ax]
            bad = False
            for key in ("rms_deg_s", "std_deg_s", "mean_deg_s", "angle_deg"):
                e = d["axes"][ax][key]
                cells += [e["predicted"], _ci_text(e["monte_carlo"])]
                bad |= e["agrees"] is False
            rows.append(cells)
            flags.append(bad)
    doc.table(["design", "at (true ρ, failures)", "axis", "RMS pred.", "RMS sim. [95 %]", "1σ pred.", "1σ sim.",
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
    doc.p("Worst-case GDOP over every choice of failed gyros, at each design's cone angle and "
          "mounting, at the ρ of the column 'at ρ' (the design's typical ρ); "
          "'3 axes' says whether every choice keeps a 3-axis rate. Detectable: a single fault "
          "shows in the parity residual (every gyro has a parity signature, N ≥ 4); isolable: no "
          "two gyros share a parity direction. The detection machinery itself is separate.", "note")
    seen, rows = set(), []
    for d in res["designs"]:
        key = (d["scheme"], d["n"], round(d["alpha_deg"], 2), _reversed(d))
        if key in seen:
            continue
        seen.add(key)
        ft = d.get("fault_tolerance", {})
        at = (d.get("typical") or {}).get("rho", d.get("design_rho", d.get("rho")))
        rows.append([d["scheme"], d["n"], d["alpha_deg"], _reversed(d), at, ft.get("gdop"),
                     ft.get("worst_gdop_after", {}).get("1"), ft.get("three_axes_after", {}).get("1"),
                     ft.get("worst_gdop_after", {}).get("2"), ft.get("three_axes_after", {}).get("2"),
                     ft.get("detectable"), ft.get("isolable"),
                     ft.get("lost_axis_example", {}).get("2") or ""])
    rows.sort(key=lambda r: (r[1], r[0]))
    doc.table(["scheme", "N", "α [deg]", "reversed", "at ρ", "GDOP", "worst after 1", "3 axes", "worst after 2",
               "3 axes", "detectable", "isolable", "how an axis is lost (2 failures)"], rows)


def _rho(doc, res: dict, gdop_rows: list[GdopRobustnessRow], rc: dict | None = None):
    doc.h3("The correlation ρ is a condition, not a choice")
    rho = res["assumptions"]["rho"]["value"]
    continuous = res["recommended"].get("worst_case") is not None
    doc.p(f"The gyros' common correlation is not known exactly: the search was run at each ρ in "
          f"{rho} and the recommendation is the design whose worst "
          + ("objective over the whole interval (continuously, not only these grid points) × "
             "failures is smallest (min-max); the tables below are at the grid points named in "
             "their columns." if continuous else
             "predicted 3-axis RMS over that range is smallest (min-max)."))
    rc = rc if rc is not None else rho_candidates(res)
    if rc is None or not rc["candidates"]:
        doc.p("The result carries no per-ρ scores of its designs: no per-ρ table.", "note")
        _gdop_robustness(doc, gdop_rows)
        return
    rec = res["recommended"]
    own = next((c for c in rc["candidates"] if _key(c) == _key(rec)), None)
    doc.p(f"Candidates: the {sum(not c['source'].startswith('mounting') for c in rc['candidates'])} "
          "designs of the decision (each as chosen for the range: mounting sense, cone angle, "
          "bandwidth and design ρ, scored by the decision)"
          + (f" and their {sum(c['source'].startswith('mounting') for c in rc['candidates'])} mounting "
             "mirrors (the same cone, estimator, bandwidth and design ρ with the other mounting "
             "sense, scored by the predictor the same way)" if rc["mirror_note"] is None else
             f"; their mounting mirrors are left out: {rc['mirror_note']}")
          + ". Each is the intact array, its estimator built once and fixed, at the true ρ of the "
          "row; the best design at a ρ is the smallest 3-axis RMS over these candidates.", "note")
    rows = []
    for r in rc["rhos"]:
        b = best_at_rho(rc, r)
        v = b["rms_by_rho"][r]
        ref = "–" if own is None else f"{own['rms_by_rho'][r]:.4g} (+{100 * (own['rms_by_rho'][r] / v - 1):.1f} %)"
        rows.append([r, _label(b), b["source"], v, ref])
    doc.table(["assumed ρ", "best design at that ρ", "from", "3-axis RMS [deg/s]",
               "the recommendation there [deg/s]"], rows)
    rob = robustness_rows(rc, rec)
    doc.p("Robustness: the design best at each assumed ρ̂, and the min-max recommendation, "
          "evaluated at every ρ of the range (intact array; in brackets: how much worse than that "
          "ρ's own best):")
    doc.table(["chosen for ρ̂", "design"] + [f"at ρ = {r}" for r in rc["rhos"]],
              [[x["chosen_for"] if isinstance(x["chosen_for"], str) else ", ".join(x["chosen_for"]),
                _label(x["design"])]
               + [f"{x['at'][r][0]:.4g} (+{100 * x['at'][r][1]:.1f} %)" for r in rc["rhos"]]
               for x in rob])
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
    fig, note = adev_fig(res, a)
    doc.h3("Allan deviation of the recommended design")
    doc.figure("adev_recommended", figure_png(fig), note)


def adev_fig(res: dict, a: AdevFigure):
    """The figure and the note of :func:`adev_section` (a matplotlib Figure on an Agg canvas, str)."""
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
    rho = a.rho if a.rho is not None else record_rho(d)
    dt = a.dt_s
    # the label is long (mounting and bandwidth): wrapped, so the title stays inside the figure
    title = textwrap.fill(f"{_label(d)}; ρ = {rho:.3g}, one {a.record_s:g} s record", width=64)
    ax.set(xlabel="averaging time τ [s]", ylabel="Allan deviation [deg/h]")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    m = res["assumptions"].get("motion", {}).get("value")
    moving = isinstance(m, dict)               # the record simulates a swing only (evidence.recommended_adev)
    ratio = fused_single_ratio(a)
    per = ratio["per_axis"]
    measured = (f"; measured fused/single ratio at τ ≥ {ratio['min_tau_s']:g} s (median over τ) x/y/z "
                + " / ".join(f"{per[x]:.3g}" for x in AXES if x in per)
                + f" against √(3/N) = {ratio['reference']:.3g}") if per else ""
    if moving:
        gap = ("The record has the motion of the result on (the swing), so the fused error also holds "
               "the filter's lag on the swing, which does not average over the gyros: where a fused "
               "curve stays above the dashed √(3/N) line, that lag (not a correlation) is the gap" + measured
               + " (without motion, at ρ = 0 and unity DC gain, it falls to √(3/N) at long τ).")
    else:
        gap = ("The record is static (no motion): at τ above the filter's time constants the fused "
               "curves meet the dashed √(3/N) line when the DC gain is 1 and ρ = 0"
               + (", and stay above it with ρ > 0 (the common part does not average out)" if rho > 0 else "")
               + measured + ".")
    note = (f"One simulated record of the recommended array as mounted, {a.record_s:g} s at {1 / dt:g} Hz "
            f"(seed {a.seed}), gyro correlation of the record ρ = {rho:.4g} (the design ρ its "
            f"estimator is built for), estimator {a.estimator}; bands: 1σ confidence of each point. "
            + gap + " Predicted long-τ fused ARW x/y/z "
            + " / ".join(f"{v:.4g}" for v in a.predicted_arw_long_deg_rt_h)
            + " deg/√h.")
    return fig, note
