"""The Monte-Carlo check of the design result: the top designs (single ρ) or the
recommendation, the runner-up and the mounting mirror (decision) simulated with paired runs
beside their prediction, with 95 % intervals.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats

from gyroarray.analysis.replicates import mean_ci, replicate_rng, rms_ci
from gyroarray.core import units
from gyroarray.core.layout import Layout
from gyroarray.design.predict import (AXES, settle_start, swing_truth)
from gyroarray.effects.names import BIAS_INSTABILITY
from gyroarray.design.robust import mirror_pattern
from gyroarray.estimators import get_estimator
from gyroarray.sim.effects import simulate_readings
from gyroarray.design.channels import (estimator_kwargs, with_sensor)
from gyroarray.design.decision import decision_dict
from gyroarray.design.gyro_noise import GyroNoise
from gyroarray.design.scoring import rescore_exact
from gyroarray.design.screening import (Candidate, Decider)
from gyroarray.design.search_space import DesignSpace
from gyroarray.design.statements import design_label


#: ``--check auto``: the paired runs of the pilot that sizes the check, and the most runs it picks.
AUTO_PILOT = 20
AUTO_CAP = 400

#: The power at which a check is sized: K_needed runs resolve the predicted difference (the
#: 95 % interval of the paired mean excludes 0) in 80 % of checks.
SIZING_POWER = 0.8
SIZING_LEVEL = 0.95


def runs_needed(delta: float, sd: float, *, level: float = SIZING_LEVEL, power: float = SIZING_POWER,
                most: int = 10 ** 9) -> int | None:
    """Paired runs K that resolve a mean difference ``delta`` with per-run sd ``sd`` (same unit).

    The smallest K >= 2 with (t_{(1+level)/2, K−1} + t_{power, K−1}) · sd / √K <= |delta|:
    the Student-t interval (``level``) of the mean of K paired differences then excludes 0 in
    a fraction ``power`` of checks (the normal-theory sample size, with t quantiles).

    Parameters
    ----------
    delta : float
        Predicted mean of the paired difference [metric unit].
    sd : float
        Standard deviation of one run's paired difference [metric unit].
    level, power : float
        Confidence level of the interval and the power [-].
    most : int
        Above this many: None (no finite check resolves it in practice).

    Returns
    -------
    int or None
    """
    if not (math.isfinite(delta) and math.isfinite(sd)) or delta == 0.0:
        return None
    if sd <= 0.0:
        return 2
    za, zb = stats.norm.ppf(0.5 + level / 2), stats.norm.ppf(power)
    k = max(2, math.ceil(((za + zb) * sd / abs(delta)) ** 2))
    if k > most:
        return None
    while (stats.t.ppf(0.5 + level / 2, k - 1) + stats.t.ppf(power, k - 1)) * sd / math.sqrt(k) > abs(delta):
        k += 1
        if k > most:
            return None
    return k


def _objective_metric(objective: str, arr: np.ndarray) -> np.ndarray:
    """Each run's objective metric (R,): the 3-axis mean square of the rate error in the window
    [(deg/s)²] (rate) or the 3-axis squared angle error at the horizon [deg²] (angle), from the
    runs' stacks (R, 4, 3) [rad/s, rad]."""
    if objective == "rate":
        return units.rad_s_to_deg_s(1.0) ** 2 * np.sum(arr[:, 0, :] ** 2, axis=1)
    return units.rad_to_deg(1.0) ** 2 * np.sum(arr[:, 1, :] ** 2, axis=1)


def _predicted_metric(objective: str, d: dict) -> float:
    """The predictor's mean of :func:`_objective_metric` for a design at its worst case."""
    wc = d["worst_case"]
    return float(wc["rms_3axis_deg_s"] ** 2 if objective == "rate" else wc["angle_deg"] ** 2)


def check_sizing(objective: str, rec: dict, other: dict, pilot: np.ndarray, k: int, *,
                 cap: int | None = None) -> dict:
    """Whether K paired runs can resolve the recommendation from the runner-up, and how many would.

    The mean of the paired difference (runner-up − recommendation) of the objective metric
    (:func:`_objective_metric`) is the predictor's (each design at its worst case); its
    per-run standard deviation is not: the two designs' errors share the runs' noise streams
    through two different estimators (and after different failed gyros), a cross-covariance
    the predictor does not hold, so it is estimated from a pilot, the first paired runs, with
    its χ² 95 % interval. K_needed: :func:`runs_needed` (95 % interval, 80 % power).

    Parameters
    ----------
    objective : {"rate", "angle"}
    rec, other : dict
        The recommendation and the runner-up (decision designs with ``worst_case``).
    pilot : ndarray (P,)
        The pilot runs' paired differences [(deg/s)² or deg²].
    k : int
        Runs of the check.
    cap : int, optional
        ``--check auto``'s largest K.

    Returns
    -------
    dict
        ``metric``, ``unit``, ``predicted_mean_difference``, ``sd_paired_difference`` {value,
        ci_low, ci_high, unit, source}, ``k_needed`` (None: no finite K), ``k_needed_range``,
        ``k``, ``resolvable`` (K >= K_needed), ``level``, ``power``, ``statement``.
    """
    unit = "(deg/s)^2" if objective == "rate" else "deg^2"
    metric = ("3-axis mean square of the rate error in the window" if objective == "rate"
              else "3-axis squared angle error at the horizon")
    delta = _predicted_metric(objective, other) - _predicted_metric(objective, rec)
    p = int(pilot.size)
    sd = float(np.std(pilot, ddof=1)) if p >= 2 else math.nan
    lo = hi = None
    if p >= 2:
        lo = float(sd * math.sqrt((p - 1) / stats.chi2.ppf(0.975, p - 1)))
        hi = float(sd * math.sqrt((p - 1) / stats.chi2.ppf(0.025, p - 1)))
    need = runs_needed(delta, sd) if p >= 2 else None
    rng = [None if lo is None else runs_needed(delta, lo), None if hi is None else runs_needed(delta, hi)]
    resolvable = bool(need is not None and k >= need)
    src = (f"pilot: the first {p} paired runs of this check (the predictor does not hold the two "
           "designs' cross-covariance); 95 % interval from chi-square with "
           f"{p - 1} degrees of freedom")
    if need is None:
        says = (f"no finite check resolves them: predicted difference {delta:.4g} {unit}"
                if p >= 2 else f"a pilot of {p} run cannot size the check")
    elif resolvable:
        says = (f"{k} paired runs can resolve the recommendation from the runner-up (K_needed {need}, "
                f"95 % interval, {100 * SIZING_POWER:g} % power)")
    else:
        says = (f"{k} paired runs cannot resolve the recommendation from the runner-up; about {need} "
                f"would (95 % interval, {100 * SIZING_POWER:g} % power; {rng[0]}–{rng[1]} over the sd's "
                "95 % interval)")
        if cap is not None and need > cap:
            says += f"; even the cap of --check auto ({cap}) cannot"
    if need is not None:
        says += (f": predicted difference of the {metric} {delta:.4g} {unit} (runner-up − "
                 f"recommendation), sd of one paired difference {sd:.4g} {unit} ({p}-run pilot)")
    return {"metric": metric, "unit": unit, "predicted_mean_difference": delta,
            "sd_paired_difference": {"value": sd, "ci_low": lo, "ci_high": hi, "unit": unit, "source": src},
            "k_needed": need, "k_needed_range": rng, "k": int(k), "resolvable": resolvable,
            "cap": cap, "level": SIZING_LEVEL, "power": SIZING_POWER, "statement": says}


def _pick_for_check(designs: list[dict], top: int) -> list[dict]:
    """The first ``top`` designs of the ranking, one per distinct (layout, estimator family),
    plus the best ``naive`` design as the no-model baseline."""
    seen, out = set(), []
    for d in designs:
        # one of each set of designs the predictor says are the same (same layout, same RMS)
        key = (d["scheme"], d["n"], round(d["alpha_deg"], 3), f"{d['rms_3axis_deg_s']:.9g}")
        if key in seen:
            continue
        seen.add(key)
        out.append(d)
        if len(out) == top:
            break
    naive = next((d for d in designs if d["estimator"] == "naive"), None)
    if naive is not None and naive not in out:
        out.append(naive)
    return out


def monte_carlo_check(designs: list[dict], g: GyroNoise, space: DesignSpace, *,
                      replicates: int | str = 20, seed: int = 20260412, top: int = 4) -> dict:
    """Simulate the top designs with common random numbers and set the runs beside the prediction.

    Every replicate r draws the gyro noise from the same seed for every design
    (paired: gyro k's streams are the same in each layout), through the
    simulator's own effects (:func:`gyroarray.sim.effects.simulate_readings`)
    and the real estimators; the rate truth is the design's motion.

    ``replicates``: a number of runs, or "auto" (a decision's check sizes itself,
    :func:`check_decision`; the single-ρ ranking runs :data:`AUTO_PILOT`).

    Returns
    -------
    dict
        ``replicates``, ``seed``, ``designs``: per design its label, the
        predicted and simulated (RMS over the runs, 95 % CI) per axis of
        ``rms_deg_s``, ``std_deg_s``, ``mean_deg_s`` and ``angle_deg``, and
        ``paired``: the recommended design against each other one, the mean
        difference of the runs' 3-axis mean square with its 95 % CI
        (``resolved``: the interval excludes 0).
    """
    if g.open_from is not None:         # the designs' N only: a left-out N is not simulated
        g = g.sized(max(max(space.ns), g.open_from))
    if designs and "worst_case" in designs[0]:
        return check_decision(designs, g, space, replicates=replicates, seed=seed)
    if isinstance(replicates, str):     # "auto" sizes a decision's check; a single-ρ ranking: the pilot
        replicates = AUTO_PILOT
    picked = _pick_for_check(designs, top)
    dt = space.dt_s
    k0, t, truth = _check_run(space)
    setups = []
    for d in picked:
        rho = d.get("rho", g.rho_arw)
        gr = g.with_rho(rho) if g.rho_arw == g.rho_rrw else g
        layout = Layout.conical(d["scheme"], d["n"], math.radians(d["alpha_deg"]))
        model = with_sensor(gr.noise_model(d["n"]), space, g_sensitivity=False)
        bw = d["bandwidth_hz"]
        est = get_estimator(d["estimator"])(**estimator_kwargs(d["estimator"], bw, g)).fit(layout, model, dt)
        setups.append((d, layout, model, est))
    per: list[list[np.ndarray]] = [[] for _ in setups]                                        # runs × (4 metrics × 3 axes)
    for r in range(int(replicates)):
        for j, (d, layout, model, est) in enumerate(setups):
            z = simulate_readings(model, truth, layout, dt, replicate_rng(seed, r), time_s=t)
            e = est.estimate(z) - truth
            w = e[k0:]
            per[j].append(np.stack([np.sqrt(np.mean(w ** 2, axis=0)), np.std(w, axis=0, ddof=1),
                                    np.mean(w, axis=0), dt * e.sum(axis=0)]))
    keys = ("rms_deg_s", "std_deg_s", "mean_deg_s", "angle_deg")
    conv = {"rms_deg_s": units.rad_s_to_deg_s, "std_deg_s": units.rad_s_to_deg_s,
            "mean_deg_s": units.rad_s_to_deg_s, "angle_deg": units.rad_to_deg}
    out_designs = []
    for j, (d, *_rest) in enumerate(setups):
        arr = np.array(per[j])                                        # (R, 4, 3)
        axes: dict[str, Any] = {}
        for a, ax in enumerate(AXES):
            axes[ax] = {}
            for m, key in enumerate(keys):
                mc = rms_ci(conv[key](arr[:, m, a]), gaussian=key in ("mean_deg_s", "angle_deg"))
                pk = "angle_deg_at_horizon" if key == "angle_deg" else key
                p = d["predicted"][ax][pk]
                axes[ax][key] = {"predicted": p, "monte_carlo": mc,
                                 "agrees": bool(mc["ci_low"] <= p <= mc["ci_high"])
                                 if mc["ci_low"] is not None else None}
        tot = rms_ci(units.rad_s_to_deg_s(np.sqrt(np.sum(arr[:, 0, :] ** 2, axis=1))))
        out_designs.append({"label": design_label(d), "rank": d.get("rank"), "scheme": d["scheme"],
                            "n": d["n"], "alpha_deg": d["alpha_deg"], "estimator": d["estimator"],
                            "bandwidth_hz": d["bandwidth_hz"],
                            "rms_3axis_deg_s": {"predicted": d["rms_3axis_deg_s"], "monte_carlo": tot},
                            "axes": axes})
    paired = []
    ms0 = np.sum(np.array(per[0])[:, 0, :] ** 2, axis=1)
    for j in range(1, len(setups)):
        diff = units.rad_s_to_deg_s(1.0) ** 2 * (np.sum(np.array(per[j])[:, 0, :] ** 2, axis=1) - ms0)
        s = mean_ci(diff)
        paired.append({"against": out_designs[j]["label"], "mean_square_difference_deg2_s2": s,
                       "resolved": None if s["ci_low"] is None else bool(s["ci_low"] > 0 or s["ci_high"] < 0)})
    checked = [c for dd in out_designs for ax in dd["axes"].values() for c in ax.values()
               if c["agrees"] is not None]
    return {"replicates": int(replicates), "seed": int(seed), "designs": out_designs,
            "paired": paired, "inside_95": sum(c["agrees"] for c in checked),
            "compared": len(checked)}


def _mirror_design(rec: dict, g: GyroNoise, space: DesignSpace) -> dict:
    """The recommendation with its mounting mirrored (:func:`gyroarray.design.robust.mirror_pattern`),
    same estimator, bandwidth and design ρ, scored the same way (exactly: :func:`rescore_exact`)."""
    lo, hi = rec["rho_range"]
    dec = Decider(g, space, lo, hi, rec["objective"])
    alpha, signs = mirror_pattern(rec["scheme"], rec["alpha_deg"], np.asarray(rec["mounting_signs"], float))
    slot_of_gyro = (rec.get("placement") or {}).get("slot_of_gyro")     # 1-based slots, per gyro
    slots = None if slot_of_gyro is None else tuple(int(k) - 1 for k in slot_of_gyro)
    c = Candidate(rec["scheme"], rec["n"], rec["estimator"], signs, math.radians(alpha), rec["bandwidth_hz"],
                  rec["design_rho"], math.nan, slots)     # the same placement, mirrored
    d = decision_dict(dec, c, None)
    rescore_exact(d, dec)
    d.pop("_cand", None)
    return d


def _check_run(space: DesignSpace) -> tuple[int, np.ndarray, np.ndarray]:
    """What every simulated run of a check shares: the first sample after the settling time, the
    sample times [s] and the true body rate (n, 3) [rad/s] of the design's motion."""
    n, dt = space.n_samples, space.dt_s
    if space.motion is not None:
        truth = np.asarray(space.motion, dtype=float)[:n]
    elif space.swing is not None:
        truth = swing_truth(space.swing, n, dt)
    else:
        truth = np.zeros((n, 3))
    return settle_start(n, dt, space.settle_s), np.arange(n) * dt, truth


def honest_rms_ci(values, *, gaussian: bool = False) -> dict:
    """:func:`gyroarray.analysis.replicates.rms_ci` that never claims more than the runs show.

    Each run's mean square is a positive quadratic form of Gaussian noise, so it carries at
    least one degree of freedom: ν >= n runs. The Satterthwaite ν estimated from the spread
    of a few runs can be far larger than the truth when the error is dominated by a random
    walk (a handful of slow modes per run; four runs that happen to agree give a narrow
    interval around a low draw). The interval returned is the wider of the Satterthwaite one
    and the ν = n bound (exact for a zero-mean Gaussian; ``gaussian``: that one alone).
    """
    a = rms_ci(values, gaussian=True)
    if gaussian or a["ci_low"] is None:
        return a
    b = rms_ci(values)
    if b["ci_low"] is None:
        return a
    return {**a, "ci_low": min(a["ci_low"], b["ci_low"]), "ci_high": max(a["ci_high"], b["ci_high"]),
            "interval": "the wider of Satterthwaite and nu = n runs (at least one degree of freedom per run)"}


def _row_signs(d: dict):
    """The mounting sign of each row of a design's ``axes`` (gyro j: the sign of its slot)."""
    s = d.get("mounting_signs")
    slots = (d.get("placement") or {}).get("slot_of_gyro")
    return s if s is None or slots is None else [s[int(k) - 1] for k in slots]


def check_decision(designs: list[dict], g: GyroNoise, space: DesignSpace, *, replicates: int | str = 20,
                   seed: int = 20260412) -> dict:
    """Monte Carlo of the decision: the recommendation, the runner-up and the mounting mirror,
    each at its own worst case (true ρ, failed gyros), with the estimator as built.

    Each design's estimator is fitted once, for its design ρ, on the gyros left after its worst
    failure (weights recomputed for the design ρ on the remaining geometry); the readings are
    simulated at its worst true ρ. Run r draws from the same seed in every design (paired runs),
    so the difference of two designs' 3-axis mean squares is judged run by run (Student-t
    interval of the paired differences).

    The check is sized (:func:`check_sizing`) from a pilot, its first min(K, :data:`AUTO_PILOT`)
    runs: whether K runs can resolve the recommendation from the runner-up on the objective
    metric, and how many would. ``replicates="auto"``: K is that number, at least the pilot and
    at most :data:`AUTO_CAP`; where even the cap cannot resolve them only the pilot is run.

    Returns
    -------
    dict
        ``replicates``, ``seed``, ``designs`` (per design: ``role``, ``label``, ``at`` {rho,
        failed_gyros}, per axis the predicted and simulated ``rms_deg_s`` and ``angle_deg`` with
        95 % intervals, ``rms_3axis_deg_s``, ``inside_95`` of ``compared``), ``paired`` (the
        recommendation against each other one), ``inside_95``, ``compared`` and, with a
        runner-up, ``sizing`` (:func:`check_sizing`) with its ``k_needed``, ``resolvable`` and
        ``sd_paired_difference`` {value, unit} also at the top level.
    """
    auto = isinstance(replicates, str)
    if auto and replicates != "auto":
        raise ValueError(f"replicates: a whole number or 'auto', got {replicates!r}")
    rec = designs[0]
    other = [d for d in designs[1:] if (d["scheme"], d["n"]) != (rec["scheme"], rec["n"])] or designs[1:2]
    picked = [("recommended", rec)] + [("runner-up", d) for d in other[:1]]
    picked.append(("mounting mirror", _mirror_design(rec, g, space)))
    dt = space.dt_s
    k0, t, truth = _check_run(space)
    ranged = ((g.rho_arw == g.rho_rrw and g.corr_arw is None and g.corr_rrw is None)
              or rec["rho_range"][1] > rec["rho_range"][0])
    setups = []
    for role, d in picked:
        wc = d["worst_case"]
        keep = [k for k in range(d["n"]) if k + 1 not in wc["failed_gyros"]]
        layout = Layout(np.asarray(d["axes"], dtype=float)[keep])
        rd = d["design_rho"] if d["design_rho"] is not None else wc["rho"]
        g_design = g.with_rho(rd) if ranged else g
        g_true = g.with_rho(wc["rho"]) if ranged else g
        sg = _row_signs(d)                           # the axis frame's correlation reads them
        est = get_estimator(d["estimator"])(**estimator_kwargs(d["estimator"], d["bandwidth_hz"], g)).fit(
            layout, with_sensor(g_design.noise_model(len(keep), keep, sg), space, g_sensitivity=False), dt)
        model = with_sensor(g_true.noise_model(len(keep), keep, sg), space, g_sensitivity=False)
        setups.append((role, d, layout, model, est))
    per: list[list[np.ndarray]] = [[] for _ in setups]

    def simulate(runs) -> None:
        for r in runs:
            for j, (_, d, layout, model, est) in enumerate(setups):
                z = simulate_readings(model, truth, layout, dt, replicate_rng(seed, r), time_s=t)
                e = est.estimate(z) - truth
                w = e[k0:]
                per[j].append(np.stack([np.sqrt(np.mean(w ** 2, axis=0)), dt * e.sum(axis=0),
                                        np.std(w, axis=0, ddof=1), np.mean(w, axis=0)]))
    objective = rec.get("objective", "rate")
    sized = bool(other) and picked[1][0] == "runner-up"

    def differences() -> np.ndarray:
        return (_objective_metric(objective, np.array(per[1]))
                - _objective_metric(objective, np.array(per[0])))
    n_pilot = AUTO_PILOT if auto else min(int(replicates), AUTO_PILOT)
    simulate(range(n_pilot))
    sizing = None
    if auto:
        replicates = n_pilot
        if sized:
            need = check_sizing(objective, rec, picked[1][1], differences(), n_pilot, cap=AUTO_CAP)["k_needed"]
            if need is not None and need <= AUTO_CAP:
                replicates = max(n_pilot, need)
    if sized:
        sizing = check_sizing(objective, rec, picked[1][1], differences(), int(replicates),
                              cap=AUTO_CAP if auto else None)
    simulate(range(n_pilot, int(replicates)))
    out_designs = []
    for j, (role, d, *_rest) in enumerate(setups):
        arr = np.array(per[j])                                        # (R, 4, 3)
        wc = d["worst_case"]
        axes_out: dict[str, Any]
        axes_out, inside, compared = {}, 0, 0
        for a, ax in enumerate(AXES):
            axes_out[ax] = {}
            for m, key, conv in ((0, "rms_deg_s", units.rad_s_to_deg_s), (2, "std_deg_s", units.rad_s_to_deg_s),
                                 (3, "mean_deg_s", units.rad_s_to_deg_s), (1, "angle_deg", units.rad_to_deg)):
                mc = honest_rms_ci(conv(arr[:, m, a]), gaussian=key in ("mean_deg_s", "angle_deg"))
                p = wc["per_axis"][ax][key]
                ok = None if mc["ci_low"] is None else bool(mc["ci_low"] <= p <= mc["ci_high"])
                axes_out[ax][key] = {"predicted": p, "monte_carlo": mc, "agrees": ok}
                if ok is not None:
                    compared += 1
                    inside += ok
        tot = honest_rms_ci(units.rad_s_to_deg_s(np.sqrt(np.sum(arr[:, 0, :] ** 2, axis=1))))
        out_designs.append({"role": role, "label": design_label(d), "mounting": d["mounting"],
                            "scheme": d["scheme"], "n": d["n"], "alpha_deg": d["alpha_deg"],
                            "estimator": d["estimator"], "bandwidth_hz": d["bandwidth_hz"],
                            "design_rho": d["design_rho"],
                            "at": {"rho": wc["rho"], "failed_gyros": wc["failed_gyros"]},
                            "rms_3axis_deg_s": {"predicted": wc["rms_3axis_deg_s"], "monte_carlo": tot},
                            "axes": axes_out, "inside_95": inside, "compared": compared})
    paired = []
    ms0 = np.sum(np.array(per[0])[:, 0, :] ** 2, axis=1)
    for j in range(1, len(setups)):
        diff = units.rad_s_to_deg_s(1.0) ** 2 * (np.sum(np.array(per[j])[:, 0, :] ** 2, axis=1) - ms0)
        st = mean_ci(diff)
        paired.append({"against": out_designs[j]["label"], "role": out_designs[j]["role"],
                       "mean_square_difference_deg2_s2": st,
                       "resolved": None if st["ci_low"] is None else bool(st["ci_low"] > 0 or st["ci_high"] < 0),
                       "note": "paired: run r uses the same seed in both designs; Student-t interval "
                               "of the per-run differences"})
    if sizing is not None:
        diff_all = differences()
        st = mean_ci(diff_all)
        sizing["paired_objective_difference"] = {
            **st, "unit": sizing["unit"], "predicted": sizing["predicted_mean_difference"],
            "sd_over_runs": float(np.std(diff_all, ddof=1)) if diff_all.size > 1 else None,
            "resolved": None if st["ci_low"] is None else bool(st["ci_low"] > 0 or st["ci_high"] < 0)}
    extra: dict[str, Any] = {"auto": auto}
    if auto:
        extra["auto_rule"] = (f"K chosen from a pilot of {AUTO_PILOT} paired runs: the runs that resolve the "
                              f"recommendation from the runner-up (95 % interval, {100 * SIZING_POWER:g} % "
                              f"power), at least the pilot, at most {AUTO_CAP}; past the cap only the pilot "
                              "is run")
    if sizing is not None:
        extra.update({"sizing": sizing, "k_needed": sizing["k_needed"], "resolvable": sizing["resolvable"],
                      "sd_paired_difference": {"value": sizing["sd_paired_difference"]["value"],
                                               "unit": sizing["unit"], "metric": sizing["metric"]}})
    bi_levels = [float(g.bi_deg_h)] + [float(v) for v in (g.per_gyro or {}).get(BIAS_INSTABILITY, ())]
    if max(bi_levels) > 0 and (space.flicker_model != "circular" or g.rho_bi is None or g.rho_bi != 0):
        # the simulator's bias instability is the circular model, independent between gyros
        extra["flicker_mismatch"] = (
            f"the runs draw circular (stationary) flicker, independent between the gyros, while the prediction "
            f"uses the {space.flicker_model} model with the bias instability's correlation "
            f"{'following the ARW rho' if g.rho_bi is None else f'rho_bi {g.rho_bi:g}'}: the bias-instability "
            "part of predicted and simulated differs by the models, not by the predictor (compare with "
            "--flicker circular --rho-bi 0)")
    return {"replicates": int(replicates), "seed": int(seed), "designs": out_designs, "paired": paired,
            **extra,
            "inside_95": sum(d["inside_95"] for d in out_designs),
            "compared": sum(d["compared"] for d in out_designs),
            "what": "each design at its own worst case (true rho, failed gyros), estimator built for "
                    "its design rho on the remaining gyros"}
