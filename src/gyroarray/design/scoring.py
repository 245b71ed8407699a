"""Exact re-scoring of screened designs: the registry's estimator as built for the design ρ on
the gyros left after each failure, predicted by the full predictor
(:func:`gyroarray.design.predict.predict`) at both ends of the ρ range.
"""

from __future__ import annotations

import math

import numpy as np

from gyroarray.core.layout import Layout
from gyroarray.design.predict import (AXES, predict)
from gyroarray.design.robust import kept_sets
from gyroarray.estimators import get_estimator
from gyroarray.design.channels import (prediction_axes, estimator_kwargs, with_sensor)
from gyroarray.design.gyro_noise import GyroNoise, predictor_noise
from gyroarray.design.screening import (Candidate, Decider, nominal_rho, predicted_at, candidate_axes,
                                        row_signs)
from gyroarray.design.search_space import design_tags, CLOSED_FORM_WEIGHTS


#: Designs at the top of the screening re-scored exactly (the estimator as built, the full
#: predictor), besides the recommendation, the runner-up and the mounting mirror.
EXACT_TOP = 8


def screening_is_exact(est: str, g: GyroNoise) -> bool:
    """Whether the screening's channel model is the estimator itself (then re-scoring changes
    nothing): per-sample weights with their low-pass always; ``kf_single`` on alike gyros (the
    same filter on every gyro commutes with the least-squares combination); never ``kf_array``
    (after a failure or with reversed gyros its bias states couple the axes)."""
    tags = design_tags(est)
    if tags.bias_states == "array" or tags.weights not in CLOSED_FORM_WEIGHTS:
        return False                    # a plugin's weights are read from its DC gain: re-scored
    return not (tags.bias_states == "per_gyro" and g.per_gyro is not None)


def _prediction_case(p, keep, n: int, rho_t: float) -> dict:
    """A :func:`score_case`-shaped dict from a full :class:`~gyroarray.design.predict.Prediction`."""
    ax = p.axes
    return {"rho": float(rho_t), "failed_gyros": [k + 1 for k in range(n) if k not in keep],
            "rms_3axis_deg_s": float(math.sqrt(sum(ax[a]["rms_deg_s"] ** 2 for a in AXES))),
            "angle_deg": float(math.sqrt(sum(ax[a]["angle_deg"] ** 2 for a in AXES))),
            "per_axis": {a: {k: float(ax[a][k]) for k in ("rms_deg_s", "std_deg_s", "mean_deg_s", "angle_deg")}
                         for a in AXES}}


def exact_predictions(dec: Decider, c: Candidate, H: np.ndarray, extra_rhos=()) -> dict:
    """Every (kept set, true ρ at an end of the range) of a design predicted exactly.

    The estimator is built as the Monte-Carlo check builds it: the registry's estimator with
    :func:`estimator_kwargs`, fitted once per kept set for the design ρ on the gyros left
    (weights and filter recomputed on the remaining geometry); its linear system is then
    predicted (:func:`gyroarray.design.predict.predict`) with the noise of the true ρ on
    those gyros. With the estimator fixed, every error variance is linear in the true noise
    covariance, hence in ρ: the worst ρ of each kept set is an end of the range.

    Parameters
    ----------
    dec : Decider
    c : Candidate
    H : ndarray (1, N, 3)
        The mounted axes [-].
    extra_rhos : sequence of float
        Further true ρ for the intact array (the typical case).

    Returns
    -------
    dict
        (kept set, ρ) -> Prediction.
    """
    space = dec.space
    motion = None if space.motion is None else np.asarray(space.motion, dtype=float)[:space.n_samples]
    gd = dec.cond(dec.lo if c.rho_d is None else c.rho_d)
    sg = row_signs(c.signs, c.slots)                 # the axis frame's correlation reads them
    out = {}
    for keep in kept_sets(c.n, space.failures):
        Hk = H[0, list(keep)]
        est = get_estimator(c.est)(**estimator_kwargs(c.est, c.bw, dec.g)).fit(
            Layout(Hk), with_sensor(gd.noise_model(len(keep), keep, sg), space, g_sensitivity=False), dec.dt)
        rts = list(dec.ends()) + (list(extra_rhos) if len(keep) == c.n else [])
        for rt in rts:
            if (keep, float(rt)) in out:
                continue
            model = with_sensor(dec.cond(rt).noise_model(len(keep), keep, sg), space, g_sensitivity=False)
            # the flicker correlated (--rho-bi) and of the space's model (--flicker)
            noise = predictor_noise(dec.cond(rt), model, len(keep), keep, sg, dec.dt, space.flicker_model)
            out[(keep, float(rt))] = predict(est, noise, n_samples=space.n_samples, settle_s=space.settle_s,
                                             truth_rad_s=motion, swing=None if motion is not None else space.swing)
    return out


def rescore_exact(d: dict, dec: Decider) -> None:
    """Replace a screened design's scores by the exact ones (:func:`exact_predictions`).

    ``worst_case`` (worst over the kept sets × the range's ends, by the objective),
    ``typical``, ``predicted`` / ``rms_3axis_deg_s`` / ``rho`` (the intact array at its worst
    end of the range), ``worst_rms_3axis_deg_s`` and ``rms_by_rho`` (linear in ρ between the
    ends, exact for a fixed estimator) are recomputed; ``scored`` says how. Designs whose
    screening is already exact (:func:`screening_is_exact`) are only marked.
    """
    c = d["_cand"]
    if screening_is_exact(c.est, dec.g):
        d["scored"] = "exact (the screening's channel model is this estimator)"
        return
    H = candidate_axes(c)
    rho_typ = nominal_rho(dec, c)
    preds = exact_predictions(dec, c, H, extra_rhos=(rho_typ,))
    key = "rms_3axis_deg_s" if dec.objective == "rate" else "angle_deg"
    cases = {k: _prediction_case(p, k[0], c.n, k[1]) for k, p in preds.items()}
    ends = [k for k in cases if k[1] in dec.ends()]
    wk = max(ends, key=lambda k: cases[k][key])
    full = tuple(range(c.n))
    ik = max((k for k in ends if k[0] == full), key=lambda k: cases[k][key])
    p = preds[ik]
    pred = prediction_axes(p)
    d.update({"rho": ik[1], "rms_3axis_deg_s": cases[ik]["rms_3axis_deg_s"], "predicted": pred,
              "predicted_at": predicted_at(ik[1], dec),
              "worst_case": cases[wk], "worst_rms_3axis_deg_s": cases[wk]["rms_3axis_deg_s"],
              "typical": {**cases[(full, float(rho_typ))], "failed_gyros": []}})
    if "rms_by_rho" in d and dec.hi > dec.lo:
        ms_lo = cases[(full, float(dec.lo))]["rms_3axis_deg_s"] ** 2
        ms_hi = cases[(full, float(dec.hi))]["rms_3axis_deg_s"] ** 2
        d["rms_by_rho"] = {r: math.sqrt(ms_lo + (float(r) - dec.lo) / (dec.hi - dec.lo) * (ms_hi - ms_lo))
                           for r in d["rms_by_rho"]}
    d["scored"] = ("exact: the estimator as built for the design ρ on the gyros left after each failure, "
                   "predicted by the full predictor at both ends of the ρ range (a fixed estimator's "
                   "error variance is linear in ρ)")
