"""The details of a decided design: its minimum detectable bias [deg/s] (with failures >= 1)
and its error budget at the worst case (:func:`gyroarray.design.budget.error_budget`).
"""

from __future__ import annotations

from typing import cast

import numpy as np

from gyroarray.core import units
from gyroarray.core.layout import Layout
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.design.robust import mounted_axes
from gyroarray.estimators import get_estimator
from gyroarray.estimators.fdi import minimum_detectable
from gyroarray.estimators.noise import model_terms
from gyroarray.design.budget import error_budget
from gyroarray.design.channels import (estimator_kwargs, with_sensor)
from gyroarray.design.gyro_noise import GyroNoise
from gyroarray.design.screening import (Candidate, Decider)
from gyroarray.design.statements import ignored_effects


def _mdb(H: np.ndarray, dec: Decider) -> dict:
    """Minimum detectable bias step per gyro [deg/s], worst over the ρ range's ends, from the
    parity detector (:func:`gyroarray.estimators.fdi.minimum_detectable`)."""
    cache = dec.space.__dict__.setdefault("_mdb_cache", {})
    key = (np.round(H, 9).tobytes(), dec.lo, dec.hi, dec.space.far_per_h, dec.space.p_md)
    if key not in cache:
        per = np.zeros(H.shape[0])
        for r in dec.ends():
            model = dec.cond(r).noise_model(H.shape[0])
            m = minimum_detectable(Layout(H), model, dec.space.far_per_h, dec.space.p_md,
                                   dt_s=dec.dt)
            per = np.maximum(per, units.rad_s_to_deg_s(np.asarray(m["step_rad_s"], dtype=float)))
        cache[key] = per
    per = cache[key]
    return {"mdb_deg_s": float(np.max(per)), "mdb_per_gyro_deg_s": [float(v) for v in per],
            "mdb_worst_gyro": int(np.argmax(per)) + 1, "far_per_h": dec.space.far_per_h,
            "p_md": dec.space.p_md}


def _error_budget(d: dict, dec: Decider, c: Candidate, H: np.ndarray) -> dict:
    """The error budget of a design at its worst case: per term, RMS [deg/s] and angle [deg].

    SINGLE CALL SITE for :func:`gyroarray.design.budget.error_budget`: the estimator as built
    for the design ρ on the gyros left, every effect of the model that declares a term."""
    wc = d["worst_case"]
    keep = tuple(k for k in range(c.n) if k + 1 not in wc["failed_gyros"])
    Hk = H[0, list(keep)]
    gd = dec.cond(c.rho_d if c.rho_d is not None else wc["rho"])
    est = get_estimator(c.est)(**estimator_kwargs(c.est, c.bw, dec.g)).fit(
        Layout(Hk), gd.noise_model(len(keep), keep), dec.dt)
    motion = dec.space.swing if dec.space.swing is not None else (
        None if dec.space.motion is None else np.asarray(dec.space.motion)[:dec.space.n_samples])
    b = error_budget(est.linear_system(), Hk,
                     with_sensor(budget_model(dec.cond(wc["rho"]), keep), dec.space),
                     n_samples=dec.space.n_samples, dt_s=dec.dt,
                     settle_s=dec.space.settle_s, motion=motion)
    return {"at": {"rho": wc["rho"], "failed_gyros": wc["failed_gyros"]}, **b.to_dict(),
            "ignored_effects": ignored_effects(dec.g, dec.space, b.ignored)}


def budget_model(g: GyroNoise, keep):
    """The model the error budget reads for the kept gyros: the user's own model (every effect,
    a plugin's included, its per-gyro entries renumbered to the kept gyros) with the
    condition's correlation in place of the model's; the typical gyro's model for alike gyros."""
    keep = list(keep)
    if g.model is None or g.per_gyro is None:
        return g.noise_model(len(keep), keep)
    from gyroarray.effects.terms import CorrelationTerm  # lazy: with the registry
    corr = {eff.name for eff, t in model_terms(g.model, cast(int, g.n_levels)) if isinstance(t, CorrelationTerm)}
    own = g.noise_model(len(keep), keep)
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
    H = mounted_axes(c.scheme, c.n, np.array([c.alpha_rad]), c.signs)
    if dec.space.failures:
        d.update(_mdb(H[0], dec))
    d["error_budget"] = _error_budget(d, dec, c, H)
