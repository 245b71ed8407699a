"""The design result in words and JSON fields: design labels, equivalent designs, what would
change the choice, what the prediction leaves out, the assumptions (every input and its
source), the tracking limit and the g-sensitivity beside the noise, the decision line.
"""

from __future__ import annotations

from typing import Any

import math
from dataclasses import replace

import numpy as np

from gyroarray.core import units
from gyroarray.design.predict import AXES
from gyroarray.effects.names import ARW, BANDWIDTH, BIAS_INSTABILITY, CONSTANT_BIAS, CORRELATION, GAUSS_MARKOV, G_SENSITIVITY, MISALIGNMENT, QUANTIZATION, RRW, SCALE_FACTOR, SCALE_NONLINEARITY, TEMPERATURE_BIAS
from gyroarray.design.gyro_noise import COMMON_MODE_WORDS, GyroNoise
from gyroarray.design.moments import FLICKER_WORDS
from gyroarray.design.search import generic_or_fast
from gyroarray.design.search_space import (DesignSpace, EQUIVALENT_SHARE, OBJECTIVE_WORDS)


def _objective_value(d: dict) -> float:
    """What a design is ranked on: its worst case (decision) in the objective's unit, else the
    3-axis RMS of the single-ρ search."""
    wc = d.get("worst_case")
    if wc is not None:
        v = wc["rms_3axis_deg_s" if d.get("objective", "rate") == "rate" else "angle_deg"]
    else:
        v = d["rms_3axis_deg_s"]
    return v if math.isfinite(v) else math.inf


def _pct(share: float) -> str:
    """A share in percent with the digits that tell 0.9987 % from 1 %."""
    return f"{100.0 * share:.4g} %"


def _mirror_of(a: dict, b: dict) -> bool:
    """b is a's mounting mirror (same scheme and N, the cone at 180° − α or the other senses)."""
    if (a["scheme"], a["n"], a["estimator"]) != (b["scheme"], b["n"], b["estimator"]):
        return False
    sa, sb = a.get("mounting_signs"), b.get("mounting_signs")
    alpha_mirror = abs(a["alpha_deg"] + b["alpha_deg"] - 180.0) < 1e-3
    return alpha_mirror or (sa is not None and sb is not None and sa != sb
                            and abs(a["alpha_deg"] - b["alpha_deg"]) < 1e-3)


def equivalent_groups(designs: list[dict], share: float = EQUIVALENT_SHARE) -> list[dict]:
    """Designs that theory makes equal, and smaller arrays that reach the same worst case.

    Two kinds of group (best first), each with ``members`` (ranks), ``designs`` (labels),
    ``spread`` (largest relative difference of the objective), ``kind`` and ``reason``:

    * ``identical`` — same N, predictions equal to 1e-9: the same estimator in another form
      (kf_array = kf_single on a decoupled cone, gls = ols = naive where HᵀC⁻¹H is diagonal),
      the two schemes at their isotropic optimum, or the mounting mirror (identical at ρ = 0).
      Designs of different N, or merely close, are never merged;
    * ``fewer_gyros`` — a design with fewer gyros whose worst case lies within ``share`` of a
      larger array's: "k gyros saved at the same worst case", with the difference in percent.
    """
    groups = []
    used: set = set()
    for i, d in enumerate(designs):
        if i in used:
            continue
        base = _objective_value(d)
        members = [d]
        for j in range(i + 1, len(designs)):
            e = designs[j]
            if j in used or e["n"] != d["n"]:
                continue
            v = _objective_value(e)
            if math.isfinite(base) and abs(v - base) <= 1e-9 * max(abs(base), 1e-300):
                members.append(e)
                used.add(j)
        if len(members) > 1:
            spread = max(_objective_value(m) for m in members) / base - 1.0 if base > 0 else 0.0
            groups.append({"members": [m["rank"] for m in members],
                           "designs": [design_label(m) for m in members], "spread": spread,
                           "kind": "identical", "reason": _why_equal(members, spread)})
    # a smaller array at the same worst case (within the tie share): the gyros it saves
    best_by_n: dict = {}
    for d in designs:
        if math.isfinite(_objective_value(d)):
            best_by_n.setdefault(d["n"], d)
    ns = sorted(best_by_n)
    for big in reversed(ns):
        d = best_by_n[big]
        for small in ns:
            if small >= big:
                break
            e = best_by_n[small]
            vd, ve = _objective_value(d), _objective_value(e)
            if ve <= vd * (1.0 + share):
                diff = ve / vd - 1.0
                groups.append({"members": [e["rank"], d["rank"]],
                               "designs": [design_label(e), design_label(d)], "spread": diff,
                               "kind": "fewer_gyros",
                               "reason": (f"{big - small} gyro(s) saved at the same worst case: N = {small} "
                                          f"reaches {ve:.6g} against {vd:.6g} for N = {big} "
                                          f"({'+' if diff >= 0 else ''}{_pct(diff)}, within the "
                                          f"{_pct(share)} tie share)")})
                break
    return groups


def design_label(d: dict) -> str:
    """One line naming a design: ``scheme S, N = n, alpha = A deg, estimator (bandwidth)``."""
    bw = "no low-pass" if d["bandwidth_hz"] is None else f"{d['bandwidth_hz']:.3g} Hz"
    if d["estimator"] == "naive":
        bw = "no filter"
    rev = [k + 1 for k, v in enumerate(d.get("mounting_signs") or []) if v < 0]
    sense = "" if not rev else (" [gyro" + ("s " if len(rev) > 1 else " ") + ",".join(map(str, rev))
                                + " reversed]")
    return (f"scheme {d['scheme']}, N = {d['n']}, alpha = {d['alpha_deg']:.2f} deg{sense}, "
            f"{d['estimator']} ({bw})")


def _why_equal(members: list[dict], spread: float) -> str:
    """Why designs of one N have the same prediction (only reasons that apply are given)."""
    ests = {m["estimator"] for m in members}
    schemes = {m["scheme"] for m in members}
    bits = []
    if ests & {"kf_array", "kf_single"} == {"kf_array", "kf_single"}:
        bits.append("kf_array and kf_single are the same filter here: with alike gyros and equal "
                    "ARW/RRW correlation the array KF decouples per axis into the single-gyro KF "
                    "on the least-squares channel")
    if len(ests & {"gls", "ols", "naive"}) > 1:
        bits.append("gls, ols and naive have the same weights: HᵀC⁻¹H is diagonal and the axes "
                    "are eigenvectors of C on these cones")
    if len(schemes) > 1:
        bits.append("both schemes reach the isotropic optimum HᵀC⁻¹H ∝ I at their own cone angle, "
                    "so their GDOP (and every prediction) is the same")
    if any(_mirror_of(a, b) for a in members for b in members if a is not b):
        rhos = {tuple(m.get("rho_range") or [m.get("rho", 0.0)] * 2) for m in members}
        bits.append("mounting mirror: the same lines with the other sense, identical when the gyros' "
                    "noise is uncorrelated" + (" (ρ = 0 here)" if rhos <= {(0.0, 0.0)} else ""))
    if not bits:
        bits.append("the same N with predictions equal to 1e-9 (a symmetry of the array: a rotation "
                    "of the body frame or a global sign)")
    return (f"identical by theory (spread {_pct(spread)}): " if spread > 0 else "identical by theory: ") \
        + "; ".join(bits)


def tracking_limit(d: dict, space: DesignSpace, g: GyroNoise | None = None) -> dict | None:
    """Whether the sensors' own bandwidth or the estimator limits tracking of the swing.

    On the design's worst-tracked axis, the tracking error per unit swing
    amplitude of the gyros' own filter, |1 − F| (amplitude loss and lag
    together), is set against the estimator's, |1 − T|; the fused output
    passes their product T·F. None without a sensor bandwidth.
    """
    if space.sensor_bandwidth is None:
        return None
    fc, order = space.sensor_bandwidth
    what = f"the gyros' own {fc:g} Hz order-{int(order)} low-pass"
    if space.swing is None:
        return {"limited_by": None,
                "statement": f"{what} is cascaded before the estimator in every prediction (noise and "
                             "motion); give --swing AMP,FREQ to learn whether it or the estimator limits tracking"}
    p = d["predicted"]
    ax = min(AXES, key=lambda a: p[a]["amplitude_ratio"])
    q = p[ax]
    sa, ea = q["sensor_amplitude_ratio"], q["estimator_amplitude_ratio"]
    est = d["estimator"] + ("" if d["bandwidth_hz"] is None else f" at {d['bandwidth_hz']:.3g} Hz")
    f = space.swing.frequency_hz
    def err(amp, lag_deg):                                           # |1 − A e^{−jφ}|
        return abs(1.0 - amp * np.exp(-1j * np.radians(lag_deg)))
    se, ee = err(sa, q["sensor_phase_deg"]), err(ea, q["estimator_phase_deg"])
    nums = (f"{what} passes {sa:.4f} of the amplitude with a lag of {q['sensor_phase_deg'] + 0.0:.3g} deg "
            f"(tracking error {100 * se:.3g} % of the swing), the {est} {ea:.4f} with "
            f"{q['estimator_phase_deg'] + 0.0:.3g} deg ({100 * ee:.3g} %); the fused output "
            f"{q['amplitude_ratio']:.4f} with {q['phase_deg'] + 0.0:.3g} deg")
    if se > ee:
        text = (f"the sensor bandwidth, not the {d['estimator']}, limits tracking at {f:g} Hz: {nums}. "
                "A wider estimator bandwidth cannot win back the sensors' loss; gyros with a wider "
                "internal filter can")
        by = "sensor"
    else:
        text = f"the {d['estimator']}, not the sensor bandwidth, limits tracking at {f:g} Hz: {nums}"
        by = "estimator"
    if g is not None:
        bare = generic_or_fast(d["scheme"], d["n"], d["estimator"], math.radians(d["alpha_deg"]),
                                d["bandwidth_hz"], d.get("rho", g.rho_arw), g,
                                replace(space, sensor_bandwidth=None))["rms_3axis_deg_s"]
        text += (f". With an ideal sensor this design would predict {bare:.4g} deg/s 3-axis RMS "
                 f"instead of {d['rms_3axis_deg_s']:.4g}")
    return {"limited_by": by, "axis": ax, "swing_hz": f, "statement": text,
            "rms_3axis_without_sensor_filter_deg_s": None if g is None else float(bare),
            "sensor_tracking_error_share": float(se), "estimator_tracking_error_share": float(ee),
            "sensor_amplitude_ratio": sa, "sensor_phase_deg": q["sensor_phase_deg"],
            "estimator_amplitude_ratio": ea, "estimator_phase_deg": q["estimator_phase_deg"],
            "amplitude_ratio": q["amplitude_ratio"], "phase_deg": q["phase_deg"]}


def g_sensitivity_statement(d: dict, space: DesignSpace) -> str | None:
    """The g-sensitivity's rate error of a design beside its noise RMS, in words."""
    gs = d.get(G_SENSITIVITY)
    if gs is None or space.g_sensitivity_deg_s_per_g is None:
        return None
    k = ", ".join(f"{v:g}" for v in space.g_sensitivity_deg_s_per_g)
    ratio = gs["fused_rms_3axis_deg_s"] / d["rms_3axis_deg_s"] if d["rms_3axis_deg_s"] > 0 else math.inf
    xyz = " / ".join(f"{gs['fused_rms_deg_s'][a]:.3g}" for a in AXES)
    where = "the motion profile" if space.specific_force_m_s2 is not None else "the level table (gravity on z)"
    return (f"g-sensitivity ({k}) (deg/s)/g on every gyro, on {where}: {gs['per_gyro_rms_deg_s']:.4g} deg/s "
            f"RMS per gyro, {gs['fused_rms_3axis_deg_s']:.4g} deg/s 3-axis on the fused output "
            f"(x/y/z {xyz}), "
            f"{ratio:.3g} x the design's predicted 3-axis RMS from noise and tracking "
            f"({d['rms_3axis_deg_s']:.4g} deg/s)"
            + ("; it dominates: calibrate it out or choose gyros with less" if ratio > 1 else "")
            + ". Not part of the ranking: a deterministic bias that a calibration of k removes")


def short_fields(d: dict) -> dict:
    """The JSON fields of one design (the issue's keys first)."""
    keys = ("rank", "scheme", "n", "alpha_deg", "estimator", "bandwidth_hz", "predicted",
            "worst_gdop_after_failures", "rms_3axis_deg_s", "gdop", "fault_tolerance", "rho",
            "worst_rms_3axis_deg_s", "rms_by_rho", G_SENSITIVITY, "path", "axes", "mounting",
            "mounting_signs", "placement", "design_rho", "design_rho_note", "objective", "rho_range", "worst_case",
            "typical", "oracle_worst_case", "error_budget", "mdb_deg_s", "mdb_per_gyro_deg_s",
            "mdb_worst_gyro", "mdb_worst_gyros", "mdb_rho", "mdb_window_s", "mdb_threshold",
            "mdb_rho_grid", "mdb_statement", "far_per_h", "p_md", "tie", "excluded", "predicted_at", "scored")
    return {k: d[k] for k in keys if k in d}


def worst_words(d: dict) -> str:
    """A design's worst case in words, by its objective: value, unit, true ρ and failed gyros
    (e.g. "27.92 deg angle error at the horizon (ρ = -0.1, gyro 3 failed)")."""
    wc = d.get("worst_case")
    if not wc:
        return f"{d['rms_3axis_deg_s']:.4g} deg/s 3-axis RMS (ρ = {d.get('rho', math.nan):.4g}, no failure)"
    failed = ("no failure" if not wc["failed_gyros"] else
              ("gyro " if len(wc["failed_gyros"]) == 1 else "gyros ")
              + ", ".join(map(str, wc["failed_gyros"])) + " failed")
    v = (f"{wc['angle_deg']:.4g} deg angle error at the horizon" if d.get("objective") == "angle"
         else f"{wc['rms_3axis_deg_s']:.4g} deg/s 3-axis RMS")
    return f"{v} (ρ = {wc['rho']:.4g}, {failed})"


def _more(d: dict, ref: dict) -> str:
    """``d``'s worst case against ``ref``'s, by the objective, as "12 % more" / "3 % less"."""
    key = "angle_deg" if d.get("objective") == "angle" and "worst_case" in d else "rms_3axis_deg_s"
    a = d["worst_case"][key] if "worst_case" in d else d[key]
    b = ref["worst_case"][key] if "worst_case" in ref else ref[key]
    share = 100.0 * (a / b - 1.0)
    return f"{abs(share):.0f} % {'more' if share >= 0 else 'less'}"


def what_changes(designs: list[dict], g: GyroNoise, space: DesignSpace, rhos) -> list[str]:
    """Short sentences: what would change the recommendation."""
    rec = designs[0]
    out = []
    fewer = [d for d in designs if d["n"] < rec["n"]]
    if fewer:
        f = fewer[0]
        out.append(f"fewer gyros: the best N = {f['n']} design ({design_label(f)}) has a worst case of "
                   f"{worst_words(f)}, {_more(f, rec)} than the recommendation's {worst_words(rec)}")
    ft = rec.get("fault_tolerance", {})
    for k in ("1", "2"):
        if k in ft.get("three_axes_after", {}) and not ft["three_axes_after"][k]:
            alt = [d for d in designs if d.get("fault_tolerance", {}).get("three_axes_after", {}).get(k)]
            if alt:
                out.append(f"requiring a 3-axis rate after {k} failed gyro(s) (--failures {k}): "
                           f"{design_label(alt[0])}, worst case {worst_words(alt[0])}")
    if len(rhos) == 1:
        out.append("a correlation between the gyros: rerun with --rho-range LO,HI; the ranking "
                   "then holds per assumed ρ and the recommendation is the best worst case")
    if space.swing is None and space.motion is None:
        out.append("motion: at rest the bandwidth is a requirement (held at "
                   f"{space.bandwidth_hz[0]:g} Hz); with --swing or --motion it is traded against lag")
    return out


#: The error sources of a real gyro that a noise model may leave out, and why each matters.
_USUAL_EFFECTS = (
    (SCALE_FACTOR, "a rate error proportional to the body rate (ppm of the motion)"),
    (SCALE_NONLINEARITY, "a rate error growing with the square of the body rate"),
    (MISALIGNMENT, "each gyro's axis tilted from its mounted direction: cross-axis rate error"),
    (TEMPERATURE_BIAS, "a bias that follows the temperature swing"),
    (QUANTIZATION, "the output resolution (white angle noise)"),
    (CONSTANT_BIAS, "the turn-on bias: taken as calibrated at switch-on (biases start at zero)"),
)


def ignored_effects(g: GyroNoise, space: DesignSpace, budget_ignored=()) -> list[str]:
    """What the prediction leaves out, each as "name: why" (never empty while anything is).

    Parameters
    ----------
    g : GyroNoise
        Its ``ignored`` (effects of a source model the predictor does not model) and its
        model's effects (a usual error source absent from it is left out as zero).
    space : DesignSpace
        The g-sensitivity and the gyros' own low-pass, when stated.
    budget_ignored : sequence of str
        Effects the error budget could not evaluate on the stated motion
        (:attr:`gyroarray.design.budget.ErrorBudget.ignored`).

    Returns
    -------
    list of str
    """
    present = set() if g.model is None else {e.effect for e in g.model.entries}
    out = []
    for name in g.ignored:
        if (name == BANDWIDTH and space.sensor_bandwidth is not None) or (
                name == G_SENSITIVITY and space.g_sensitivity_deg_s_per_g is not None):
            continue
        out.append(f"{name}: in the model, not in the ranking's predictor (the error budget shows it "
                   "where the effect declares a term)")
    for name in budget_ignored:
        if not any(o.startswith(name + ":") for o in out):
            out.append(f"{name}: in the model, but the stated motion cannot excite or evaluate it "
                       "(e.g. a temperature coefficient without a temperature swing)")
    src = "the datasheet inputs" if g.model is None else "the model"
    for name, what in _USUAL_EFFECTS:
        if name not in present:
            out.append(f"{name}: not in {src}, taken as zero ({what})")
    if space.g_sensitivity_deg_s_per_g is None and G_SENSITIVITY not in present:
        out.append(f"{G_SENSITIVITY}: not in {src} (--g-sensitivity), taken as zero (a rate error "
                   "proportional to the specific force)")
    elif space.g_sensitivity_deg_s_per_g is not None:
        out.append(f"{G_SENSITIVITY}: stated; in the error budget and reported beside the ranking, "
                   "not ranked")
    if space.sensor_bandwidth is None and BANDWIDTH not in present:
        out.append(f"{BANDWIDTH}: not in {src} (--sensor-bandwidth), the gyros' own low-pass taken as flat")
    return out


def detection_assumption(space: DesignSpace, rec: dict | None = None) -> dict:
    """The minimum detectable bias's detector: its false-alarm rate [1/h], missed-detection
    probability [-] and (from a decided design ``rec``) its step window [s] and threshold."""
    out: dict[str, Any] = {"far_per_h": space.far_per_h, "p_md": space.p_md,
           "statement": (f"minimum detectable bias: the parity detector's step test, thresholds set for "
                         f"{space.far_per_h:g} false alarms per hour over its three test families, "
                         f"detection with probability 1 − {space.p_md:g}; worst over a "
                         "grid of the ρ range")}
    if rec is not None and rec.get("mdb_window_s") is not None:
        out.update({"window_s": rec["mdb_window_s"], "threshold": rec["mdb_threshold"]})
        out["statement"] += (f"; the recommendation's step window {rec['mdb_window_s']:.3g} s "
                             f"(threshold {rec['mdb_threshold']:.4g} σ of the whitened parity)")
    return out


def assumptions(g: GyroNoise, space: DesignSpace, rhos, single: bool) -> dict:
    """Every input of the search and where it came from (user / default / model)."""
    src = g.sources

    def item(value, source, unit=""):
        return {"value": value, "source": source, **({"unit": unit} if unit else {})}
    s = space.__dict__.get("_sources", {})
    return {
        ARW: item(g.arw_deg_rt_h, src.get(ARW, "user"), "deg/rt(h)"),
        RRW: item(g.rrw_deg_h_rt_h, src.get(RRW, "default"), "deg/h/rt(h)"),
        BIAS_INSTABILITY: item(g.bi_deg_h, src.get("bi", "default"), "deg/h"),
        GAUSS_MARKOV: item({"sigma_deg_h": g.gm_sigma_deg_h, "tau_s": g.gm_tau_s},
                             src.get(GAUSS_MARKOV, "default")),
        "rho": item(rhos[0] if single else list(rhos), src.get("rho_arw", "default"),
                    "common ARW and RRW correlation" if g.rho_arw == g.rho_rrw else
                    f"rho_arw {g.rho_arw:g}, rho_rrw {g.rho_rrw:g}"),
        "gyros": (item("alike: every gyro has the noise above (a model's gyros reduced to their "
                       "quadratic mean)", "assumption") if g.per_gyro is None else
                  item({"per_gyro": {k: [float(x) for x in v] for k, v in g.per_gyro.items()},
                        "statement": (f"each of the model's {g.n_gyros} gyros keeps its own parameters "
                                      f"(gyro k of the model at position k of the layout); the search is "
                                      f"over the layouts with N = {g.n_gyros}; the values above are "
                                      "quadratic means, shown for reference (--alike uses them instead)"
                                      if g.open_from is None else
                                      f"gyros 1–{g.open_from} of the model keep their own parameters "
                                      "(gyro k at position k of the layout), every other gyro the "
                                      "all-gyros entries (docs/model-format.md), listed above for "
                                      f"gyros 1–{g.n_levels}; the search is over N = "
                                      f"{', '.join(map(str, space.ns))}; the values above are quadratic "
                                      "means, shown for reference (--alike uses them instead)"),
                        CORRELATION: ("the model's matrices" if g.corr_arw is not None
                                        or g.corr_rrw is not None else "common ρ")},
                       src.get("per_gyro", "model"))),
        "rate_hz": item(space.rate_hz, s.get("rate_hz", "default"), "Hz"),
        "horizon_s": item(space.horizon_s, s.get("horizon_s", "default"), "s"),
        "settle_s": item(space.settle_s, "default", "s (start-up left out of the window metrics)"),
        "n": item(list(space.ns), s.get("ns", "default")),
        "schemes": item(list(space.schemes), "default"),
        "estimators": item(list(space.estimators), s.get("estimators", "default")),
        "failures": item(space.failures, s.get("failures", "default")),
        "motion": item(space.motion_name if space.swing is None else
                       {"swing_amplitude_deg_s": units.rad_s_to_deg_s(space.swing.amplitude_rad_s),
                        "swing_frequency_hz": space.swing.frequency_hz,
                        "about": "x, y and z at once (the same rate on every body axis)"}, s.get("motion", "default")),
        "bandwidth_hz": item(list(space.bandwidth_hz), s.get("bandwidth_hz", "default"),
                             "searched range (lo = hi: fixed)"),
        "alpha_search": item(f"{space.alpha_points} cone angles per scheme (Scheme 1 in (0, 90], "
                             "Scheme 2 in (0, 180) deg), refined continuously", "default"),
        "objective": item("3-axis RMS of the rate error about the truth over the horizon "
                          "(random-walk drift included), from the analytic predictor", "definition"),
        "biases": item("start at zero (calibrated at switch-on), as the simulator draws them",
                       "assumption"),
        "common_mode": item(g.common_mode, src.get("common_mode", "default"), COMMON_MODE_WORDS[g.common_mode]),
        "flicker_model": item(space.flicker_model, s.get("flicker_model", "default"),
                              FLICKER_WORDS[space.flicker_model]),
        "rho_bi": item("the ARW correlation (ρ, or the model's ARW matrix), at every ρ of the range"
                       if g.rho_bi is None else float(g.rho_bi), src.get("rho_bi", "default"),
                       "common correlation of the gyros' bias instability (flicker) in the predictor "
                       "(the ranking and the error budget; design --rho-bi); the Monte-Carlo check's "
                       "simulated flicker is independent between gyros and circular"),
        "temperature": item(space.temperature_statement(), s.get("temperature", "default"),
                            "the temperature swing the temperature terms are evaluated on (the error budget)"),
        "detection": item(detection_assumption(space), "user" if "user" in (s.get("far_per_h"), s.get("p_md"))
                          else "default"),
        "ignored_effects": item(ignored_effects(g, space), "model"),
        "sensor_bandwidth": item(None if space.sensor_bandwidth is None else
                                 {"cutoff_hz": space.sensor_bandwidth[0], "order": space.sensor_bandwidth[1]},
                                 s.get("sensor_bandwidth", "default"),
                                 "every gyro's own low-pass, cascaded before the estimator (None: none)"),
        G_SENSITIVITY: item(None if space.g_sensitivity_deg_s_per_g is None else
                              list(space.g_sensitivity_deg_s_per_g), s.get(G_SENSITIVITY, "default"),
                              "(deg/s)/g, platform frame, every gyro alike; reported, not ranked"),
    }


def decision_statement(designs: list[dict], space: DesignSpace, lo: float, hi: float) -> dict:
    """``objective``, ``decision`` (the recommendation's worst case in one line) and ``tie``."""
    rec = designs[0]
    wc = rec["worst_case"]
    failed = ("no failure" if not wc["failed_gyros"] else
              "gyro " + ", ".join(map(str, wc["failed_gyros"])) + " failed")
    rd = ("built without ρ" if rec["design_rho"] is None else f"weights built for ρ = {rec['design_rho']:.4g}")
    line = (f"ranked on the {rec['objective']} objective ({OBJECTIVE_WORDS[rec['objective']]}) by the worst "
            f"case over ρ in [{lo:g}, {hi:g}] x {space.failures} failed gyro(s); {design_label(rec)}, "
            f"{rec['mounting']}; {rd}; worst case at ρ = {wc['rho']:.4g}, {failed}: "
            f"{wc['rms_3axis_deg_s']:.4g} deg/s 3-axis RMS, {wc['angle_deg']:.4g} deg at the horizon")
    out = {"objective": rec["objective"], "decision": line}
    if "tie" in rec:
        out["tie"] = rec["tie"]
    return out
