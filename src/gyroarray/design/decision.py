"""The decision under uncertainty (:func:`decide`): screening, exact re-scoring of the top
designs, the ranking by worst case (ties by the typical case), the details of the first ones.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from gyroarray.core.gdop import fault_tolerance, worst_gdop_over_rho
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.design.robust import mounting_words
from gyroarray.design.channels import (predicted_axes, g_sensitivity_terms, white_covariance)
from gyroarray.design.details import add_details
from gyroarray.design.gyro_noise import GyroNoise
from gyroarray.design.scoring import (EXACT_TOP, rescore_exact, screening_is_exact)
from gyroarray.design.screening import (Candidate, Decider, score_case, grid_best, nominal_rho,
                                        predicted_at, refine_candidate, public_fields, worst_case_of,
                                        candidate_axes, rho_weighted, gyro_classes, row_signs)
from gyroarray.design.search import REFINE_TOP
from gyroarray.design.search_space import (DesignSpace, EQUIVALENT_SHARE, OBJECTIVES,
                                           resolve_objective, sized_for, design_tags, design_weights)


#: Designs at the top of the decision whose detection (MDB) and error budget are computed
#: (all of them with an MDB limit).
DETAIL_TOP = 12


def decision_dict(dec: Decider, c: Candidate, rhos_shown) -> dict:
    """Every field of one design of the decision (JSON units)."""
    space, g = dec.space, dec.g
    H = candidate_axes(c)
    wc = worst_case_of(dec, c, H)
    rho_typ = nominal_rho(dec, c)
    typ = score_case(dec, c, H, tuple(range(c.n)), rho_typ, c.rho_d)
    # the intact array at its worst ρ: the per-axis prediction (the old `predicted`)
    key = "rms_3axis_deg_s" if dec.objective == "rate" else "angle_deg"
    # fixed weights: linear in ρ, so the intact array's worst ρ is an end of the range, exactly
    intact = max((score_case(dec, c, H, tuple(range(c.n)), r, c.rho_d) for r in dec.ends()),
                 key=lambda case: case[key])              # ties: the lower end
    r_int = intact["rho"]
    m, ms, sumw2, sumf2, ch, resp = intact["_moments"]
    dt = space.dt_s
    pred = predicted_axes(ms, sumw2, sumf2, ch, resp, space)
    Hm = H[0]
    sg = row_signs(c.signs, c.slots)
    # the GDOP's correlation in the common-mode frame: the axis frame's (1 − ρ)I + ρssᵀ on the
    # mounted axes S H is the output frame's (1 − ρ)I + ρ11ᵀ on the unreversed axes H
    Hg = Hm * sg[:, None] if g.common_mode == "axis" else Hm
    gd_rho, gd_r = worst_gdop_over_rho(Hg, dec.lo, dec.hi, 0)
    ft = fault_tolerance(Layout(Hg), rho_typ if dec.ranged else g.rho_arw)
    if space.failures:
        wg, _ = worst_gdop_over_rho(Hg, dec.lo, dec.hi, space.failures)
    else:
        wg = gd_rho
    gdes = dec.cond(c.rho_d if c.rho_d is not None else rho_typ)
    dcg = np.array([r.dc_gain for r in resp])
    gs = (g_sensitivity_terms(space, dcg[:, None] * design_weights(c.est, H, white_covariance(c.n, gdes, dt, sg), dt)[0])
          if space.g_sensitivity_deg_s_per_g is not None else {})
    d: dict[str, Any] = {
        "scheme": c.scheme, "n": c.n, "alpha_deg": float(np.degrees(c.alpha_rad)),
        "estimator": c.est, "bandwidth_hz": c.bw, "rho": r_int,
        "rms_3axis_deg_s": intact["rms_3axis_deg_s"], "predicted": pred,
        "predicted_at": predicted_at(r_int, dec),
        "gdop": gd_rho,
        **gs, "worst_gdop_after_failures": wg, "fault_tolerance": json.loads(json.dumps(ft)),
        "axes": [[float(v) for v in row] for row in Hm],
        "mounting_signs": [int(s) for s in c.signs],
        "mounting": mounting_words(c.scheme, c.n, c.signs, float(np.degrees(c.alpha_rad))),
        "design_rho": c.rho_d, "objective": dec.objective,
        "rho_range": [dec.lo, dec.hi],
        "worst_case": public_fields(wc), "typical": {**public_fields(typ), "failed_gyros": []},
        "worst_rms_3axis_deg_s": wc["rms_3axis_deg_s"],
    }
    if c.slots is not None or g.per_gyro is not None:
        d["placement"] = placement_fields(c, gyro_classes(g, c.n))
        d["mounting"] += "; " + d["placement"]["statement"]
    if c.rho_d is None and not dec.ranged and rho_weighted(c.est):
        d["design_rho_note"] = (f"{c.est} is built for the model's own correlation matrices (no ρ range "
                                "given)")
    elif c.rho_d is None:
        d["design_rho_note"] = (f"{c.est} is built without ρ (its weights do not use the correlation); "
                                f"typical case at ρ = {rho_typ:g}")
    if rho_weighted(c.est) and dec.hi > dec.lo:
        d["oracle_worst_case"] = {**public_fields(worst_case_of(dec, c, H, oracle=True)),
                                  "note": "oracle: weights built for the true ρ (no real array knows it)"}
    if rhos_shown:
        d["rms_by_rho"] = {f"{r:g}": score_case(dec, c, H, tuple(range(c.n)), r, c.rho_d)["rms_3axis_deg_s"]
                           for r in rhos_shown if dec.lo <= r <= dec.hi}
    d["_cand"] = c
    return d


def placement_fields(c: Candidate, classes: list[int]) -> dict:
    """Where each of the model's gyros sits (a per-gyro model): ``slot_of_gyro`` and
    ``gyro_in_slot`` (1-based), and a statement naming the unlike gyros' slots (the slot
    numbers are those of ``mounting`` and ``mounting_signs``)."""
    n = c.n
    slots = list(range(n)) if c.slots is None else list(c.slots)
    inv = [0] * n
    for j, k in enumerate(slots):
        inv[k] = j
    common = max(set(classes), key=classes.count)
    odd = [j for j in range(n) if classes[j] != common]

    def where(k):
        if c.scheme == 2 and k == 0:
            return "slot 1, the axial slot on " + ("+z" if c.signs[0] > 0 else "−z")
        first = 0 if c.scheme == 1 else 1
        az = 360.0 * (k - first) / (n - first)
        return f"slot {k + 1}, on the cone at azimuth {az:.4g}°"
    said = "; ".join(f"gyro {j + 1} in {where(slots[j])}" for j in odd) or "every gyro alike"
    moved = c.slots is not None
    return {"slot_of_gyro": [k + 1 for k in slots], "gyro_in_slot": [j + 1 for j in inv],
            "statement": (f"placement searched (the gyros are not alike): {said}"
                          + ("" if moved else " (each gyro in its own numbered slot)")
                          + "; the mounting words and signs number the slots")}


def _rank_decision(designs: list[dict], objective: str, mdb_max: float | None) -> list[dict]:
    """Best worst case first; designs within 1 % of a group's first worst case are ranked by
    their typical case (and marked ``tie``); designs above ``mdb_max`` go last, ``excluded``."""
    key = "rms_3axis_deg_s" if objective == "rate" else "angle_deg"

    def w(d):
        v = d["worst_case"][key]
        return v if math.isfinite(v) else math.inf
    for d in designs:
        d.pop("tie", None)
    ok = [d for d in designs if mdb_max is None or (d.get("mdb_deg_s") or 0.0) <= mdb_max]
    bad = [d for d in designs if d not in ok]
    for d in bad:
        d["excluded"] = (f"minimum detectable bias {d['mdb_deg_s']:.4g} deg/s above --mdb-max "
                         f"{mdb_max:g} deg/s")
    out = []
    for part in (ok, bad):
        rest = sorted(part, key=w)
        i = 0
        while i < len(rest):
            j = i + 1
            while j < len(rest) and w(rest[j]) <= w(rest[i]) * (1.0 + EQUIVALENT_SHARE):
                j += 1
            grp = sorted(rest[i:j], key=lambda d: (d["typical"][key], w(d)))
            if len(grp) > 1:
                for d in grp:
                    d["tie"] = (f"worst case within {100 * EQUIVALENT_SHARE:g} % of "
                                f"{len(grp) - 1} other design(s): ranked by the typical case")
            out += grp
            i = j
    for k, d in enumerate(out):
        d["rank"] = k + 1
    return out


def decide(g: GyroNoise, space: DesignSpace, rho_lo: float, rho_hi: float, *,
           rhos_shown=None, details: bool = True) -> tuple[list[dict], list[str]]:
    """Every scheme × N × estimator at its best mounting sense, cone angle, bandwidth and design
    ρ, scored by its worst case over ρ ∈ [lo, hi] × every set of k failed gyros with weights
    fixed at the design ρ; ranked (best worst case first).

    Parameters
    ----------
    g : GyroNoise
    space : DesignSpace
        ``failures`` (k), ``design_rho`` (None: min-max over the range),
        ``objective`` (None: :func:`resolve_objective`), ``mdb_max``.
    rho_lo, rho_hi : float
        The range of the gyros' common correlation [-] (lo == hi: one ρ).
    rhos_shown : sequence of float, optional
        ρ values at which ``rms_by_rho`` is reported.
    details : bool
        False: no MDB and error budget unless ``mdb_max`` ranks by the MDB (a decision asked for
        its ranking only: the other common-mode frame's, :func:`~gyroarray.design.details.frame_comparison`).

    Returns
    -------
    (designs, notes)
    """
    objective = resolve_objective(space)
    if objective not in OBJECTIVES:
        raise InputError(f"the objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    g, space = sized_for(g, space)
    dec = Decider(g, space, rho_lo, rho_hi, objective)
    notes = []
    cands = []
    for scheme in space.schemes:
        for n in space.ns:
            if n - space.failures < 3:
                notes.append(f"N = {n}: {space.failures} failed gyro(s) leave {n - space.failures}, "
                             "fewer than the 3 a 3-axis rate needs (N − failures must be ≥ 3); "
                             "left out")
                continue
            floor = -1.0 / (n - space.failures - 1) if n - space.failures > 1 else 0.0
            if dec.ranged and rho_lo <= floor:
                notes.append(f"scheme {scheme}, N = {n}: rho = {rho_lo:g} is not a correlation "
                             f"{n - space.failures} gyros can have (below {floor:.4g}); left out")
                continue
            for est in space.estimators:
                best, alphas = grid_best(dec, scheme, n, est)
                if best is None:
                    notes.append(f"scheme {scheme}, N = {n}, {est}: no cone angle keeps an unbiased "
                                 f"3-axis rate after {space.failures} failed gyro(s) (naive: its per-axis "
                                 "projection is biased once HᵀH is not diagonal), or no bandwidth is "
                                 "reachable; left out")
                    continue
                cands.append((best, alphas))
    cands.sort(key=lambda t: t[0].J)
    if not cands:                       # nothing survives: recommend() refuses, with these notes
        return [], notes
    refined = [refine_candidate(dec, c, a, bandwidth=i < REFINE_TOP) for i, (c, a) in enumerate(cands)]
    designs = _rank_decision([decision_dict(dec, c, rhos_shown) for c in refined], objective, None)
    # the screening is approximate for the array KF: the top designs, then the recommendation
    # and the runner-up until both are exact, are re-scored with the estimator as built
    for d in designs[:EXACT_TOP]:
        rescore_exact(d, dec)
    while True:
        designs = _rank_decision(designs, objective, None)
        rec = designs[0]
        other = [d for d in designs[1:] if (d["scheme"], d["n"]) != (rec["scheme"], rec["n"])]
        todo = [d for d in [rec] + other[:1] if "scored" not in d]
        if not todo:
            break
        for d in todo:
            rescore_exact(d, dec)
    for d in designs:
        if "scored" not in d:
            d["scored"] = ("exact (the screening's channel model is this estimator)"
                           if screening_is_exact(d["estimator"], g) else
                           f"screening only (below the first {EXACT_TOP}): the single-input filter on "
                           "the fixed-weight least-squares channel")
    top = designs if space.mdb_max is not None else designs[:DETAIL_TOP] if details else []
    for d in top:
        add_details(d, dec)
    for d in designs[len(top):]:
        d.pop("_cand")
        d["details_note"] = (f"detection (MDB) and error budget computed for the first {DETAIL_TOP} "
                             "designs only" if details else "detection (MDB) and error budget not computed "
                             "(a decision asked for its ranking only)")
        if space.failures:
            d["mdb_deg_s"] = None
        d["error_budget"] = None
    if g.per_gyro is not None and g.open_from is not None:
        notes.append(f"the model's gyros 1–{g.open_from} keep their own noise (gyro k at position k), "
                     "every other gyro the model's all-gyros entries; the search is over the layouts "
                     f"with N = {', '.join(map(str, space.ns))} (--alike: one typical gyro)")
    elif g.per_gyro is not None:
        notes.append(f"the model's {g.n_gyros} gyros keep their own noise (gyro k at position k); the "
                     f"search is over the layouts with N = {g.n_gyros} (--alike: one typical gyro, any N)")
        if any(design_tags(e).bias_states != "none" for e in space.estimators):
            notes.append("kf_array and kf_single on gyros with unequal noise are screened as the single-input "
                         "filter on the fixed-weight least-squares channel, designed for the typical "
                         f"gyro's q_b/r (each gyro's own filter differs); the first {EXACT_TOP} designs, the "
                         "recommendation and the runner-up are re-scored exactly")
    coupled = [e for e in space.estimators if design_tags(e).bias_states == "array"]
    if coupled and (space.failures or any(
            np.any(np.asarray(d["mounting_signs"]) < 0) for d in designs if d["estimator"] in coupled)):
        notes.append("kf_array after a failed gyro or with reversed gyros is screened as the single-input "
                     "KF on the fixed-weight GLS channel (exact on an intact symmetric cone, where the "
                     f"array KF decouples); the first {EXACT_TOP} designs, the recommendation and the "
                     "runner-up are then re-scored exactly (the filter as built on the gyros left, full "
                     "predictor) and re-ranked: each design's `scored` says which")
    return (_rank_decision(designs, objective, space.mdb_max) if space.mdb_max is not None
            else designs), notes
