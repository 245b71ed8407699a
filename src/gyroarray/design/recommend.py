"""Which array to build: the design search behind ``gyroarray design --recommend``.

For gyros that are alike (one datasheet, or the typical gyro of a fitted
model), the search runs scheme × N × cone angle α × estimator × bandwidth
through the analytic predictor (:mod:`gyroarray.design.predict`) and ranks the
designs by the predicted RMS of the rate error about the truth over the
horizon (root-sum-square over the body axes, random-walk drift included).

The fast path. On a conical layout with identical, equicorrelated gyros the
problem falls apart into one scalar channel per body axis:

* a per-sample estimator (``gls``, ``ols``, ``naive``) with weights m_a gives
  y_a = ω_a + m_aᵀ(b + v): white variance m_aᵀRm_a, random-walk variance
  m_aᵀQ_bm_a, flicker Σ m_ai² B², whatever the layout; the low-pass acts on y_a;
* ``kf_single`` is the same single-gyro filter on every gyro, so it commutes
  with the OLS combination: the filter acts on the OLS channel;
* ``kf_array`` decouples when HᵀR⁻¹H is diagonal and every whitened axis is
  an eigenvector of the whitened bias covariance (every conical layout when
  the ARW and RRW correlations are equal; Scheme 1 always): it is the
  single-input KF on the GLS channel, designed for that channel's noise.

A channel filter's unit responses (:func:`gyroarray.design.predict.channel_response`)
are computed once per bandwidth, so every α and N is a weighted sum of them.
The gyros' own low-pass (``DesignSpace.sensor_bandwidth``, the spec's
``bandwidth`` on every gyro) commutes with every per-sample combination of
alike gyros, so it is cascaded in front of each channel filter
(:func:`gyroarray.design.predict.cascade`): the noise and the motion pass it, and the
swing response splits into the estimator's and the sensor's factors
(:func:`tracking_limit` says which one limits tracking). A g-sensitivity
(``DesignSpace.g_sensitivity_deg_s_per_g``) is reported beside the noise:
per gyro k · f, fused through the design's DC gain.

The decision (:func:`decide`) treats what the user does not know as
conditions: every design is scored by its worst case over the ρ range (found
continuously) × every set of k failed gyros, with the estimator built once for
a design ρ (weights fixed; after a failure recomputed for the same design ρ on
the gyros left); the mounting sense of each gyro is searched
(:mod:`gyroarray.design.robust`), the objective is the rate or the angle error,
and designs tying within 1 % are ranked by their typical case. The fast channel
model screens; the first :data:`EXACT_TOP` designs, the recommendation, the
runner-up and the mounting mirror are then re-scored exactly
(:func:`rescore_exact`: the registry's estimator built for the design ρ on the
gyros left, :func:`gyroarray.design.predict.predict` at both ends of the ρ
range, the error of a fixed estimator being linear in ρ) and re-ranked.

The tests check the fast path against the full predictor. Where
``kf_array`` does not decouple (Scheme 2 with unequal ARW and RRW
correlation) it is predicted exactly by the full predictor at the cone angle
and bandwidth found for ``kf_single``, and the assumptions say so.

The chain, one job per module (every name stays importable from here):
:mod:`~gyroarray.design.gyro_noise` (the gyros' noise), :mod:`~gyroarray.design.search_space`
(what is searched), :mod:`~gyroarray.design.channels` (the fast channel model),
:mod:`~gyroarray.design.search` (the single-ρ search), :mod:`~gyroarray.design.screening`
(worst case over ρ × failed gyros, fixed weights), :mod:`~gyroarray.design.scoring` (exact
re-scoring), :mod:`~gyroarray.design.details` (MDB and error budget),
:mod:`~gyroarray.design.decision` (:func:`decide`), :mod:`~gyroarray.design.check` (the Monte
Carlo), :mod:`~gyroarray.design.statements` (words and JSON fields),
:mod:`~gyroarray.design.as_built` (an array as built); :func:`recommend` joins them.
"""

from __future__ import annotations

import time
from typing import Any

from gyroarray.core.errors import InputError
from gyroarray.effects.names import G_SENSITIVITY
from gyroarray.design.gyro_noise import (MIN_ARW_DEG_RT_H, GyroNoise, PER_GYRO_KEYS,  # noqa: F401 (re-exported)
                                         model_gyro_count, model_open_from, model_gyro_refusal,
                                         per_gyro_noise, kept_levels, kept_covariances,
                                         equicorrelation)
from gyroarray.design.search_space import (ESTIMATORS, DEFAULT_BANDWIDTH_HZ, ALPHA_POINTS,  # noqa: F401 (re-exported)
                                           BW_PER_DECADE, EQUIVALENT_SHARE, sized_for, DesignSpace,
                                           bandwidth_grid, alpha_grid, OBJECTIVES,
                                           resolve_objective, OBJECTIVE_WORDS, WEIGHT_KIND, weight_kind)
from gyroarray.design.channels import (channel_weights, Channels, channel_levels, combine_moments,  # noqa: F401 (re-exported)
                                       add_motion, with_sensor, white_covariance,
                                       g_sensitivity_terms, evaluate_channels, channel_responses,
                                       estimator_kwargs, filter_bank, single_ratio, fixed_channels,
                                       both_objectives)
from gyroarray.design.search import (generic_design, search, REFINE_TOP, generic_or_fast)  # noqa: F401 (re-exported)
from gyroarray.design.statements import (equivalent_groups, design_label, tracking_limit,  # noqa: F401 (re-exported)
                                         g_sensitivity_statement, short_fields, worst_words,
                                         what_changes, ignored_effects, assumptions,
                                         decision_statement)
from gyroarray.design.screening import (RHO_WEIGHTED, BIAS_TOL, DESIGN_RHO_POINTS, Candidate,  # noqa: F401 (re-exported)
                                        Decider, grid_best, refine_candidate, score_case,
                                        worst_case_of, nominal_rho, public_fields, predicted_at)
from gyroarray.design.scoring import (EXACT_TOP, screening_is_exact, exact_predictions,  # noqa: F401 (re-exported)
                                      rescore_exact)
from gyroarray.design.details import (budget_model, add_details)  # noqa: F401 (re-exported)
from gyroarray.design.decision import (DETAIL_TOP, decision_dict, decide)  # noqa: F401 (re-exported)
from gyroarray.design.check import (monte_carlo_check, honest_rms_ci, check_decision)  # noqa: F401 (re-exported)
from gyroarray.design.as_built import (AS_BUILT_ESTIMATORS, MAX_IMPULSE, impulse_response,  # noqa: F401 (re-exported)
                                       allan_variance_linear, as_built_taus, predict_as_built)

__all__ = ["GyroNoise", "DesignSpace", "recommend", "design_label", "ESTIMATORS", "DEFAULT_BANDWIDTH_HZ"]


def recommend(g: GyroNoise, space: DesignSpace, *, rhos=None, details: bool = True) -> dict:
    """Rank the designs and recommend one (the ``--recommend`` JSON object).

    Parameters
    ----------
    g : GyroNoise
    space : DesignSpace
    rhos : sequence of float, optional
        Correlations the gyros may have (ρ is a condition, not a choice): every
        design is scored continuously over [min, max] of them (and at each of
        them in ``rms_by_rho``). None: the ρ of ``g``.
    details : bool
        False: the ranking only, no MDB and error budget (:func:`decide`).

    Returns
    -------
    dict
        ``recommended``, ``designs``, ``equivalent``, ``assumptions``, ``notes``,
        ``runner_up``, ``what_changes_the_choice``, ``objective``, ``decision``
        (one line), ``tie`` (when the recommendation tied), ``seconds`` and, with
        a ρ range, ``per_rho`` (the designs as built ranked at each ρ). Each design
        (:func:`decide`) carries ``axes``, ``mounting``, ``design_rho``,
        ``objective``, ``worst_case`` {rho, failed_gyros, rms_3axis_deg_s,
        angle_deg}, ``typical``, ``error_budget`` and, with failures,
        ``mdb_deg_s``.
    """
    t0 = time.perf_counter()
    single = rhos is None
    rho_list = [g.rho_arw] if single else [float(r) for r in rhos]
    notes: list[str] = []
    g, space = sized_for(g, space, notes)
    lo, hi = (g.rho_arw, g.rho_arw) if single else (min(rho_list), max(rho_list))
    designs, nt = decide(g, space, lo, hi, rhos_shown=None if single else rho_list, details=details)
    notes += nt
    if not designs:
        why = "; ".join(sorted(set(notes))[:3]) or "failures, rho or bandwidth"
        raise InputError(f"no design meets the requirements: {why}")
    rec = designs[0]
    other = [d for d in designs[1:] if (d["scheme"], d["n"]) != (rec["scheme"], rec["n"])]
    out: dict[str, Any] = {"recommended": short_fields(rec),
                           "runner_up": short_fields(other[0]) if other else None,
                           "designs": [short_fields(d) for d in designs],
                           "equivalent": equivalent_groups(designs),
                           "assumptions": assumptions(g, space, rho_list, single),
                           "what_changes_the_choice": what_changes(designs, g, space, rho_list),
                           "notes": sorted(set(notes))}
    out.update(decision_statement(designs, space, lo, hi))
    out["assumptions"]["objective"] = {"value": rec["objective"], "source": "user" if space.objective
                                       else "default (angle when a horizon is given, else rate)",
                                       "unit": OBJECTIVE_WORDS[rec["objective"]]}
    lim = tracking_limit(rec, space, g)
    if lim is not None:
        out["tracking_limit"] = lim
    gst = g_sensitivity_statement(rec, space)
    if gst is not None:
        out[G_SENSITIVITY] = {**rec[G_SENSITIVITY], "statement": gst}
    if not single:
        # the designs as decided (weights fixed at their design ρ), ranked at each true ρ
        out["per_rho"] = {}
        for r in rho_list:
            at = [d for d in designs if f"{r:g}" in d.get("rms_by_rho", {})]
            at = sorted(at, key=lambda d: d["rms_by_rho"][f"{r:g}"])[:10]
            out["per_rho"][f"{r:g}"] = [{**short_fields(d), "rms_3axis_deg_s": d["rms_by_rho"][f"{r:g}"],
                                         "rho": r} for d in at]
    out["seconds"] = time.perf_counter() - t0
    return out
