"""The details of a decided design: its minimum detectable bias [deg/s] (with failures >= 1)
and its error budget at the worst case (:func:`gyroarray.design.budget.error_budget`).
"""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from gyroarray.core import units
from gyroarray.core.layout import Layout
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.names import BIAS_INSTABILITY
from gyroarray.effects.terms import Motion
from gyroarray.estimators import get_estimator
from gyroarray.estimators.fdi import design_parity, minimum_detectable
from gyroarray.estimators.noise import array_noise, model_terms
from gyroarray.design.budget import error_budget, undetected_fault
from gyroarray.design.channels import (estimator_kwargs, with_sensor)
from gyroarray.design.gyro_noise import COMMON_MODES, GyroNoise, predictor_noise
from gyroarray.design.predict import AXES, Swing, predict, swing_truth
from gyroarray.design.robust import kept_sets
from gyroarray.design.search_space import sized_for
from gyroarray.design.screening import (Candidate, Decider, candidate_axes, row_signs)
from gyroarray.design.statements import design_label, ignored_effects


#: Points of the ρ grid the minimum detectable bias is evaluated on (the range's ends included):
#: the MDB of fixed weights is not linear in ρ and peaks inside the range.
MDB_RHO_POINTS = 41

#: Every this many grid points the MDB is evaluated first; about the coarse maximum the step is
#: then halved down to one grid point (the MDB is smooth in ρ with one peak; each point is one
#: parity design: 6 + 6 of the 41 points instead of all).
MDB_COARSE_STRIDE = 8

#: The undetected fault of the error budget, as a share of the MDB [-]: a bias step at the MDB is
#: missed with probability p_md, any smaller one more often, so the budget carries the largest step
#: the detector may miss at its stated rate, the limit of the steps "just below the MDB" (the row is
#: linear in the step: a smaller step scales it down in proportion).
UNDETECTED_FAULT_SHARE = 1.0

#: Gyros whose MDB lies within this share of the largest are tied as the worst [-].
MDB_TIE_SHARE = 1e-9


def mdb_rho_grid(lo: float, hi: float, points: int = MDB_RHO_POINTS) -> np.ndarray:
    """The ρ grid of the MDB [-]: ``points`` evenly spaced values from lo to hi (one if lo = hi)."""
    return np.array([float(lo)]) if hi <= lo else np.linspace(float(lo), float(hi), int(points))


def _mdb_at(H: np.ndarray, dec: Decider, rho: float, signs) -> dict:
    """The parity detector's minimum detectable bias step per gyro at one true ρ [rad/s], with
    its step window [samples] and threshold (:func:`gyroarray.estimators.fdi.minimum_detectable`)."""
    model = dec.cond(rho).noise_model(H.shape[0], None, signs)
    nz = array_noise(model, H.shape[0])
    d = design_parity(H, nz, dec.dt, far_per_h=dec.space.far_per_h)
    m = minimum_detectable(Layout(H), nz, dec.space.far_per_h, dec.space.p_md, dt_s=dec.dt, design=d)
    return {"step": np.asarray(m["step_rad_s"], dtype=float), "window": int(d.scales["step"][-1]),
            "u": float(d.thresholds["step"])}


def _mdb(H: np.ndarray, dec: Decider, signs=None) -> dict:
    """Minimum detectable bias step per gyro [deg/s], worst over the ρ range, from the parity
    detector (:func:`gyroarray.estimators.fdi.minimum_detectable`).

    The range is gridded (:func:`mdb_rho_grid`, :data:`MDB_RHO_POINTS` points, ends included):
    every :data:`MDB_COARSE_STRIDE`-th point first, then, about the largest so far, the points
    half, a quarter ... one grid step away. Per gyro the largest value found; ``mdb_rho`` where the worst gyro's is;
    ``mdb_worst_gyros`` every gyro within :data:`MDB_TIE_SHARE` of it (a tie), and
    ``mdb_worst_gyro`` the first of them. ``signs``: the mounting signs of H's rows (the axis
    frame's correlation reads them)."""
    cache = dec.space.__dict__.setdefault("_mdb_cache", {})
    sg = None if signs is None or dec.g.common_mode != "axis" else tuple(float(v) for v in signs)
    key = (np.round(H, 9).tobytes(), dec.lo, dec.hi, dec.space.far_per_h, dec.space.p_md,
           dec.g.common_mode, sg)
    if key not in cache:
        grid = mdb_rho_grid(dec.lo, dec.hi)
        at: dict = {}

        def value(i):
            if i not in at:
                at[i] = _mdb_at(H, dec, float(grid[i]), sg)
            return float(np.max(at[i]["step"]))
        coarse = sorted(set(range(0, grid.size, MDB_COARSE_STRIDE)) | {grid.size - 1})
        peak = max(coarse, key=value)
        step = MDB_COARSE_STRIDE // 2
        while step >= 1:                # halve the step about the largest value found so far
            for i in (peak - step, peak + step):
                if 0 <= i < grid.size:
                    value(i)
            peak = max(sorted(at), key=value)
            step //= 2
        worst = max(sorted(at), key=value)
        per = np.max(np.stack([at[i]["step"] for i in sorted(at)]), axis=0)
        cache[key] = (units.rad_s_to_deg_s(per), float(grid[worst]), at[worst], len(at), grid.size)
    per, rho_w, info, evaluated, points = cache[key]
    top = float(np.max(per))
    tied = [int(k) + 1 for k in np.flatnonzero(per >= top * (1.0 - MDB_TIE_SHARE))]
    window_s = info["window"] * dec.dt
    out = {"mdb_deg_s": top, "mdb_per_gyro_deg_s": [float(v) for v in per],
           "mdb_worst_gyro": tied[0], "far_per_h": dec.space.far_per_h, "p_md": dec.space.p_md,
           "mdb_worst_gyros": tied, "mdb_rho": rho_w,
           "mdb_window_s": window_s, "mdb_threshold": info["u"],
           "mdb_rho_grid": {"lo": dec.lo, "hi": dec.hi, "points": points, "evaluated": evaluated}}
    who = (f"gyro {tied[0]}" if len(tied) == 1 else
           f"a tie of gyros {', '.join(map(str, tied))} (equal within {MDB_TIE_SHARE:g})")
    out["mdb_statement"] = (
        f"minimum detectable bias step {top:.4g} deg/s, worst over ρ in [{dec.lo:g}, {dec.hi:g}] "
        f"(largest at ρ = {rho_w:.4g}, {points}-point grid), {who}: the parity detector's step test "
        f"over a {window_s:.3g} s window ({info['window']} samples, threshold {info['u']:.4g} σ), "
        f"false alarms {dec.space.far_per_h:g} per hour over the three test families, missed "
        f"detection {dec.space.p_md:g}")
    return out


def _error_budget(d: dict, dec: Decider, c: Candidate, H: np.ndarray, signs=None) -> dict:
    """The error budget of a design at its worst case: per term, RMS [deg/s] and angle [deg].

    SINGLE CALL SITE for :func:`gyroarray.design.budget.error_budget`: the estimator as built
    for the design ρ on the gyros left, every effect of the model that declares a term."""
    wc = d["worst_case"]
    keep = tuple(k for k in range(c.n) if k + 1 not in wc["failed_gyros"])
    Hk = H[0, list(keep)]
    gd = dec.cond(c.rho_d if c.rho_d is not None else wc["rho"])
    est = get_estimator(c.est)(**estimator_kwargs(c.est, c.bw, dec.g)).fit(
        Layout(Hk), gd.noise_model(len(keep), keep, signs), dec.dt)
    motion: Swing | Motion | np.ndarray | None = dec.space.swing if dec.space.swing is not None else (
        None if dec.space.motion is None else np.asarray(dec.space.motion)[:dec.space.n_samples])
    temp = dec.space.temperature_history()
    if temp is not None:                   # the stated temperature swing beside the motion
        n = dec.space.n_samples
        omega = (swing_truth(motion, n, dec.dt) if isinstance(motion, Swing) else
                 np.zeros((n, 3)) if motion is None else np.asarray(motion, dtype=float))
        motion = Motion(omega_rad_s=omega, temp_swing_k=temp)
    b = error_budget(est.linear_system(), Hk,
                     with_sensor(budget_model(dec.cond(wc["rho"]), keep, signs), dec.space),
                     n_samples=dec.space.n_samples, dt_s=dec.dt,
                     settle_s=dec.space.settle_s, motion=motion,
                     bi_correlation=dec.cond(wc["rho"]).correlation(len(keep), BIAS_INSTABILITY, keep, signs),
                     flicker_model=dec.space.flicker_model)
    out = {"at": {"rho": wc["rho"], "failed_gyros": wc["failed_gyros"]}, **b.to_dict(),
           "ignored_effects": ignored_effects(dec.g, dec.space, b.ignored)}
    if d.get("mdb_deg_s") is not None:
        out["undetected_fault"] = _undetected_fault(d, dec, c, H, signs)
    return out


def _undetected_fault(d: dict, dec: Decider, c: Candidate, H: np.ndarray, signs=None) -> dict:
    """The error budget's ``undetected_fault`` row: a bias step of :data:`UNDETECTED_FAULT_SHARE`
    × the MDB on the MDB's worst gyro, present from t = 0 and never isolated, through the intact
    array's estimator (built for the design ρ on every gyro) to the horizon
    (:func:`gyroarray.design.budget.undetected_fault`)."""
    wc = d["worst_case"]
    keep = tuple(range(c.n))
    Hk = H[0]
    gd = dec.cond(c.rho_d if c.rho_d is not None else wc["rho"])
    est = get_estimator(c.est)(**estimator_kwargs(c.est, c.bw, dec.g)).fit(
        Layout(Hk), gd.noise_model(len(keep), keep, signs), dec.dt)
    gyro = int(d["mdb_worst_gyro"])
    step = UNDETECTED_FAULT_SHARE * float(d["mdb_deg_s"])
    row = undetected_fault(est.linear_system(), c.n, gyro, units.deg_s_to_rad_s(step),
                           n_samples=dec.space.n_samples, dt_s=dec.dt, settle_s=dec.space.settle_s,
                           sensor=dec.space.sensor(c.n))
    row["share_of_mdb"] = UNDETECTED_FAULT_SHARE
    row["statement"] = (
        f"undetected fault: a bias step of {step:.4g} deg/s ({UNDETECTED_FAULT_SHARE:g} × the MDB, the "
        f"largest step the detector misses with probability {dec.space.p_md:g}; smaller ones more often) "
        f"on gyro {gyro} (the MDB's worst), present from t = 0 and never isolated, through the intact "
        f"array's estimator: {row['rms_deg_s']:.4g} deg/s 3-axis RMS over the window, "
        f"{row['angle_deg']:.4g} deg at the {dec.space.n_samples * dec.dt:g} s horizon (not in the total: "
        "the total is the fault-free worst case)")
    return row


def budget_model(g: GyroNoise, keep, signs=None):
    """The model the error budget reads for the kept gyros: the user's own model (every effect,
    a plugin's included, its per-gyro entries renumbered to the kept gyros) with the
    condition's correlation in place of the model's; the typical gyro's model for alike gyros.
    ``signs``: the mounting signs of the array's rows (the axis frame's correlation reads them)."""
    keep = list(keep)
    if g.model is None:
        return g.noise_model(len(keep), keep, signs)
    from gyroarray.effects.terms import CorrelationTerm  # lazy: with the registry
    if g.per_gyro is None:
        # alike gyros: the typical gyro's noise, and the model's other all-gyros effects (a
        # temperature coefficient, a plugin's term) beside it, so that their terms reach the budget
        own = g.noise_model(len(keep), keep, signs)
        have = {e.effect for e in own.entries}
        corr = {eff.name for eff, t in model_terms(g.model, 1) if isinstance(t, CorrelationTerm)}
        extra = tuple(e for e in g.model.entries if e.gyro is None and e.effect not in have | corr)
        model = NoiseModel(own.entries + extra, description=g.model.description)
        model.check(len(keep))
        return model
    corr = {eff.name for eff, t in model_terms(g.model, cast(int, g.n_levels)) if isinstance(t, CorrelationTerm)}
    own = g.noise_model(len(keep), keep, signs)
    own_corr = [e for e in own.entries if e.gyro is None]               # the condition's correlation
    pos = {k + 1: j + 1 for j, k in enumerate(keep)}
    entries = []
    for e in g.model.entries:
        if e.effect in corr:
            continue
        if e.gyro is None:
            entries.append(e)
        elif e.gyro in pos:
            entries.append(ModelEntry(e.effect, pos[e.gyro], dict(e.params), dict(e.sigma)))
    model = NoiseModel(tuple(entries) + tuple(own_corr), description=g.model.description)
    model.check(len(keep))
    return model


def add_details(d: dict, dec: Decider) -> None:
    """The minimum detectable bias (failures >= 1) and the error budget of one design."""
    c = d.pop("_cand")
    H = candidate_axes(c)                       # rows in the model's gyro order (placement)
    sg = row_signs(c.signs, c.slots)            # the axis frame's correlation reads them
    if dec.space.failures:
        d.update(_mdb(H[0], dec, sg))
    d["error_budget"] = _error_budget(d, dec, c, H, sg)


def design_row_signs(d: dict) -> np.ndarray:
    """The mounting sign (±1) of each row of a decided design's ``axes`` (gyro j: the sign of
    the slot it takes, ``placement``)."""
    s = np.asarray(d["mounting_signs"], dtype=float)
    slots = (d.get("placement") or {}).get("slot_of_gyro")
    return s if slots is None else s[[int(k) - 1 for k in slots]]


def worst_as_built(d: dict, g_design: GyroNoise, g_true: GyroNoise, space, lo: float, hi: float) -> dict:
    """A decided design's worst case with its estimator built for ``g_design`` (the frame it was
    chosen in) and the true noise ``g_true`` (another common-mode frame), exactly.

    Per kept set (:func:`gyroarray.design.robust.kept_sets`) the registry's estimator is fitted
    for the design ρ on the gyros left, and :func:`gyroarray.design.predict.predict` gives its
    error with the true noise at both ends of [lo, hi] (a fixed estimator's error variance is
    linear in the true covariance, hence in ρ, in either frame: the worst ρ is an end).

    Returns
    -------
    dict
        ``rho``, ``failed_gyros`` (1-based), ``rms_3axis_deg_s`` [deg/s] and ``angle_deg`` [deg]
        of the worst (kept set, ρ) by the design's objective.
    """
    H = np.asarray(d["axes"], dtype=float)
    n = int(d["n"])
    sg = design_row_signs(d)
    ranged = hi > lo or (g_design.rho_arw == g_design.rho_rrw and g_design.corr_arw is None
                         and g_design.corr_rrw is None)

    def at(g, r):
        return g.with_rho(r) if ranged else g
    rd = lo if d["design_rho"] is None else d["design_rho"]
    motion = None if space.motion is None else np.asarray(space.motion, dtype=float)[:space.n_samples]
    key = "rms_3axis_deg_s" if d.get("objective", "rate") == "rate" else "angle_deg"
    worst = None
    for keep in kept_sets(n, space.failures):
        est = get_estimator(d["estimator"])(**estimator_kwargs(d["estimator"], d["bandwidth_hz"], g_design)).fit(
            Layout(H[list(keep)]), with_sensor(at(g_design, rd).noise_model(len(keep), keep, sg), space,
                                               g_sensitivity=False), space.dt_s)
        for rt in ([lo] if hi <= lo else [lo, hi]):
            model = with_sensor(at(g_true, rt).noise_model(len(keep), keep, sg), space, g_sensitivity=False)
            model = predictor_noise(at(g_true, rt), model, len(keep), keep, sg, space.dt_s,
                                    space.flicker_model)    # the flicker correlated, the space's model
            p = predict(est, model, n_samples=space.n_samples, settle_s=space.settle_s, truth_rad_s=motion,
                        swing=None if motion is not None else space.swing)
            case: dict[str, Any] = {"rho": float(rt), "failed_gyros": [k + 1 for k in range(n) if k not in keep],
                    "rms_3axis_deg_s": float(np.sqrt(sum(p.axes[a]["rms_deg_s"] ** 2 for a in AXES))),
                    "angle_deg": float(np.sqrt(sum(p.axes[a]["angle_deg"] ** 2 for a in AXES)))}
            if worst is None or case[key] > worst[key]:
                worst = case
    return cast(dict, worst)


def _short_case(d: dict, wc: dict) -> dict:
    return {"design": design_label(d), "mounting_signs": list(d["mounting_signs"]),
            "worst_case": {k: wc[k] for k in ("rho", "failed_gyros", "rms_3axis_deg_s", "angle_deg")}}


def frame_comparison(res: dict, g: GyroNoise, space, rhos, *, other: dict | None = None) -> dict:
    """The decision under both common-mode frames (``design --common-mode``): what the chosen
    frame assumes, the recommendation's worst case when the correlated noise lives in each
    frame, and what reversing gyros buys in each.

    Parameters
    ----------
    res : dict
        :func:`gyroarray.design.recommend.recommend` for ``g`` (its frame: ``g.common_mode``).
    g : GyroNoise
    space : DesignSpace
    rhos : sequence of float or None
        The ρ values of the decision (None: the ρ of ``g``).
    other : dict, optional
        The same decision in the other frame (computed when not given).

    Returns
    -------
    dict
        ``chosen`` (the frame), ``frames`` {frame: {``recommendation`` (the recommended array
        as built, its estimator for the chosen frame, with the correlated noise in this frame),
        ``best_design`` (the decision made in this frame), ``best_all_positive`` (the best array
        with no gyro reversed: the same in both frames, no sign enters its correlation),
        ``reversal_buys_share`` (1 − best / best all-positive, by the objective [-]),
        ``recommendation_vs_best_share`` (recommendation / best − 1 [-]), ``statement``}},
        ``what``.
    """
    from gyroarray.design.recommend import recommend  # deferred: recommend imports this module (a cycle)
    chosen = g.common_mode
    alt = next(f for f in COMMON_MODES if f != chosen)
    if other is None:
        other = recommend(g.in_frame(alt), space, rhos=rhos, details=False)    # its ranking only
    g_s, space_s = sized_for(g, space, [])
    lo, hi = (g_s.rho_arw, g_s.rho_arw) if rhos is None else (min(rhos), max(rhos))
    decided = {chosen: res, alt: other}
    rec = res["recommended"]
    key = "rms_3axis_deg_s" if rec.get("objective", "rate") == "rate" else "angle_deg"
    unit = "deg/s 3-axis RMS" if key == "rms_3axis_deg_s" else "deg angle error at the horizon"
    # the best array with no gyro reversed: in the axis frame every mounting is equal to it
    pos = [d for d in decided["axis"]["designs"] if all(v > 0 for v in d["mounting_signs"])]
    pos_d = pos[0] if pos else None
    frames = {}
    for f in COMMON_MODES:
        wc = (rec["worst_case"] if f == chosen else
              worst_as_built(rec, g_s, g_s.in_frame(f), space_s, lo, hi))
        best = decided[f]["recommended"]
        entry: dict = {"recommendation": _short_case(rec, wc), "best_design": _short_case(best, best["worst_case"])}
        if pos_d is not None:
            entry["best_all_positive"] = _short_case(pos_d, pos_d["worst_case"])
            b, p = best["worst_case"][key], pos_d["worst_case"][key]
            share = float(1.0 - b / p) if p > 0 else 0.0
            entry["reversal_buys_share"] = 0.0 if abs(share) < 1e-9 else share    # rounding: none
        vs = float(wc[key] / best["worst_case"][key] - 1.0)
        entry["recommendation_vs_best_share"] = 0.0 if abs(vs) < 1e-9 else vs
        buys = entry.get("reversal_buys_share")
        entry["statement"] = (
            f"{f} frame: the recommendation as built gives {wc[key]:.4g} {unit} at its worst "
            f"(ρ = {wc['rho']:.4g}, " + (f"gyro(s) {', '.join(map(str, wc['failed_gyros']))} failed"
                                         if wc["failed_gyros"] else "no failure")
            + f"); the best design decided in this frame {best['worst_case'][key]:.4g}"
            + ("" if buys is None or pos_d is None else
               f"; the best array with no gyro reversed {pos_d['worst_case'][key]:.4g}, so reversing "
               f"gyros buys {100 * buys:.3g} %"))
        frames[f] = entry
    return {"chosen": chosen, "frames": frames,
            "what": ("the recommendation of the chosen frame as built (its estimator built for that frame) "
                     "with the correlated noise living in each frame, beside the best design decided in "
                     "each frame and the best array with no gyro reversed (its correlation has no sign to "
                     "follow: the same in both frames)")}
