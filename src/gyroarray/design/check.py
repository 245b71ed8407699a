"""The Monte-Carlo check of the design result: the top designs (single ρ) or the
recommendation, the runner-up and the mounting mirror (decision) simulated with paired runs
beside their prediction, with 95 % intervals.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gyroarray.analysis.replicates import mean_ci, replicate_rng, rms_ci
from gyroarray.core import units
from gyroarray.core.layout import Layout
from gyroarray.design.predict import (AXES, settle_start, swing_truth)
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
                      replicates: int = 20, seed: int = 20260412, top: int = 4) -> dict:
    """Simulate the top designs with common random numbers and set the runs beside the prediction.

    Every replicate r draws the gyro noise from the same seed for every design
    (paired: gyro k's streams are the same in each layout), through the
    simulator's own effects (:func:`gyroarray.sim.effects.simulate_readings`)
    and the real estimators; the rate truth is the design's motion.

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


def check_decision(designs: list[dict], g: GyroNoise, space: DesignSpace, *, replicates: int = 20,
                   seed: int = 20260412) -> dict:
    """Monte Carlo of the decision: the recommendation, the runner-up and the mounting mirror,
    each at its own worst case (true ρ, failed gyros), with the estimator as built.

    Each design's estimator is fitted once, for its design ρ, on the gyros left after its worst
    failure (weights recomputed for the design ρ on the remaining geometry); the readings are
    simulated at its worst true ρ. Run r draws from the same seed in every design (paired runs),
    so the difference of two designs' 3-axis mean squares is judged run by run (Student-t
    interval of the paired differences).

    Returns
    -------
    dict
        ``replicates``, ``seed``, ``designs`` (per design: ``role``, ``label``, ``at`` {rho,
        failed_gyros}, per axis the predicted and simulated ``rms_deg_s`` and ``angle_deg`` with
        95 % intervals, ``rms_3axis_deg_s``, ``inside_95`` of ``compared``), ``paired`` (the
        recommendation against each other one), ``inside_95``, ``compared``.
    """
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
    for r in range(int(replicates)):
        for j, (_, d, layout, model, est) in enumerate(setups):
            z = simulate_readings(model, truth, layout, dt, replicate_rng(seed, r), time_s=t)
            e = est.estimate(z) - truth
            w = e[k0:]
            per[j].append(np.stack([np.sqrt(np.mean(w ** 2, axis=0)), dt * e.sum(axis=0),
                                    np.std(w, axis=0, ddof=1), np.mean(w, axis=0)]))
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
    return {"replicates": int(replicates), "seed": int(seed), "designs": out_designs, "paired": paired,
            "inside_95": sum(d["inside_95"] for d in out_designs),
            "compared": sum(d["compared"] for d in out_designs),
            "what": "each design at its own worst case (true rho, failed gyros), estimator built for "
                    "its design rho on the remaining gyros"}
