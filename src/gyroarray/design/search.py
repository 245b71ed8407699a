"""The single-ρ search: every scheme × N × estimator at its best cone angle [rad] and bandwidth
[Hz] at one correlation ρ, through the fast channel model (:mod:`gyroarray.design.channels`),
the full predictor where the array KF does not decouple (:func:`generic_design`).
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from scipy.optimize import minimize_scalar

from gyroarray.core import units
from gyroarray.core.gdop import gdop_batch, correlation_matrix, fault_tolerance
from gyroarray.core.layout import Layout, conical_axes
from gyroarray.design.predict import predict
from gyroarray.estimators import get_estimator
from gyroarray.design.channels import (predicted_axes, prediction_axes, add_motion, filter_bank,
                                       channel_levels, combine_moments, estimator_kwargs, evaluate_channels,
                                       g_sensitivity_terms, white_covariance, channel_responses, single_ratio,
                                       channel_weights, with_sensor)
from gyroarray.design.gyro_noise import GyroNoise, predictor_noise
from gyroarray.design.search_space import (weight_kind, DesignSpace, alpha_grid, bandwidth_grid, sized_for)


def _survives(H: np.ndarray, rho: float, k: int) -> np.ndarray:
    """Worst-case GDOP (G,) over every choice of k failed gyros (inf: an axis is lost)."""
    G, N, _ = H.shape
    if k == 0:
        return gdop_batch(H, np.linalg.cholesky(correlation_matrix(N, rho)))
    if N - k < 3:
        return np.full(G, math.inf)
    worst = np.zeros(G)
    chol = np.linalg.cholesky(correlation_matrix(N - k, rho))
    for keep in itertools.combinations(range(N), N - k):
        worst = np.maximum(worst, gdop_batch(H[:, list(keep)], chol))
    return worst


@dataclass
class _Best:
    scheme: int
    n: int
    est: str
    alpha_rad: float
    bw: float | None
    objective: float
    resp: list
    rho: float


def _search_one(bank, space, g: GyroNoise, scheme: int, n: int, est: str, rho: float,
                alive: np.ndarray, alphas: np.ndarray, H: np.ndarray, evaluate: bool = True):
    """Best (α, bandwidth) of one scheme, N and estimator at one ρ (``evaluate`` False:
    only the channels)."""
    gr = g.with_rho(rho) if g.rho_arw == g.rho_rrw else g
    ch = channel_levels(est, H, gr, space.dt_s)
    ch.kf_single_ratio = single_ratio(g, space)
    if est == "kf_array" and ch.decoupled:
        assert ch.ratio is not None                                  # channel_levels sets it for kf_array
        r0 = ch.ratio[alive][0] if alive.any() else ch.ratio[0]
        if np.any(np.abs(ch.ratio[alive] - r0) > 1e-9 * np.abs(r0) + 1e-300):
            ch.decoupled = False
    if not ch.decoupled or not evaluate:
        return None, ch
    best = None
    for bw in bandwidth_grid(space, est):
        resp = channel_responses(bank, est, bw, ch, idx=int(np.argmax(alive)) if alive.any() else 0)
        J, _ = evaluate_channels(est, resp, ch, slice(None))
        J = np.where(alive & np.isfinite(J), J, np.inf)
        k = int(np.argmin(J))
        if np.isfinite(J[k]):                       # ties (α and 180° − α at ρ = 0): the smaller α
            k = int(np.flatnonzero(J <= J[k] * (1.0 + 1e-9))[0])
        if np.isfinite(J[k]) and (best is None or J[k] < best.objective):
            best = _Best(scheme, n, est, float(alphas[k]), bw, float(J[k]), resp, rho)
    return best, ch


def _refine_alpha(best: _Best, space: DesignSpace, g: GyroNoise, alphas: np.ndarray,
                  failures: int) -> _Best:
    """Continuous α around the best grid point (bounded Brent), same bandwidth."""
    k = int(np.argmin(np.abs(alphas - best.alpha_rad)))
    lo = alphas[k - 1] if k > 0 else alphas[k] * 0.5
    hi = alphas[k + 1] if k + 1 < alphas.size else alphas[k]
    gr = g.with_rho(best.rho) if g.rho_arw == g.rho_rrw else g

    def f(alpha):
        H = conical_axes(best.scheme, best.n, np.array([alpha]))
        if failures and not np.isfinite(_survives(H, best.rho, failures)[0]):
            return math.inf
        ch = channel_levels(best.est, H, gr, space.dt_s)
        ch.kf_single_ratio = single_ratio(g, space)
        J, _ = evaluate_channels(best.est, best.resp, ch, slice(None))
        return float(J[0]) if np.isfinite(J[0]) else math.inf
    if hi <= lo:
        return best
    res = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-7})
    if res.fun < best.objective:
        return replace(best, alpha_rad=float(res.x), objective=float(res.fun))
    return best


@lru_cache(maxsize=4096)
def _fault_tolerance(scheme: int, n: int, alpha_rad: float, rho: float) -> dict:
    """:func:`gyroarray.core.gdop.fault_tolerance` of a conical layout (cached; copy before changing)."""
    return fault_tolerance(Layout.conical(scheme, n, alpha_rad), rho)


def _design_dict(b: _Best, space: DesignSpace, g: GyroNoise, failures: int) -> dict:
    """The predicted metrics of one design (fast path), in datasheet units."""
    gr = g.with_rho(b.rho) if g.rho_arw == g.rho_rrw else g
    H = conical_axes(b.scheme, b.n, np.array([b.alpha_rad]))
    ch = channel_levels(b.est, H, gr, space.dt_s)
    m = combine_moments(ch, slice(None), b.resp)
    ms, sumw2, sumf2 = add_motion(m, b.resp)
    to = units.rad_s_to_deg_s
    pred = predicted_axes(ms, sumw2, sumf2, ch, b.resp, space)
    ft = _fault_tolerance(b.scheme, b.n, b.alpha_rad, b.rho if g.rho_arw == g.rho_rrw else g.rho_arw)
    dcg = np.array([r.dc_gain for r in b.resp])
    kind = weight_kind(b.est)
    gs = g_sensitivity_terms(space, dcg[:, None] * channel_weights(kind, H, white_covariance(b.n, gr, space.dt_s))[0])
    return {"scheme": b.scheme, "n": b.n, "alpha_deg": float(np.degrees(b.alpha_rad)),
            "estimator": b.est, "bandwidth_hz": b.bw, "rho": b.rho,
            "rms_3axis_deg_s": float(to(math.sqrt(b.objective))),
            "predicted": pred, "gdop": ft["gdop"], **gs,
            "worst_gdop_after_failures": ft["worst_gdop_after"][str(failures)] if failures else ft["gdop"],
            "fault_tolerance": json.loads(json.dumps(ft))}


def generic_design(scheme, n, est, alpha, bw, rho, space: DesignSpace, g: GyroNoise,
                    failures: int) -> dict:
    """A design predicted by the full predictor (used where the fast path does not apply)."""
    gr = g.with_rho(rho) if g.rho_arw == g.rho_rrw else g
    layout = Layout.conical(scheme, n, alpha)
    model = gr.noise_model(n)
    e = get_estimator(est)(**estimator_kwargs(est, bw, g)).fit(layout, model, space.dt_s)
    motion = space.motion[:space.n_samples] if space.motion is not None else None
    noise = predictor_noise(gr, with_sensor(model, space, g_sensitivity=False), n, None, None, space.dt_s,
                            space.flicker_model)             # the flicker correlated, the space's model
    p = predict(e, noise, n_samples=space.n_samples,
                settle_s=space.settle_s, truth_rad_s=motion, swing=space.swing)
    rms2 = sum(units.deg_s_to_rad_s(v["rms_deg_s"]) ** 2 for v in p.axes.values())
    pred = prediction_axes(p)
    ft = _fault_tolerance(scheme, n, alpha, gr.rho_arw)
    return {"scheme": scheme, "n": n, "alpha_deg": float(np.degrees(alpha)), "estimator": est,
            "bandwidth_hz": bw, "rho": rho, "rms_3axis_deg_s": float(units.rad_s_to_deg_s(math.sqrt(rms2))),
            "predicted": pred, "gdop": ft["gdop"],
            **g_sensitivity_terms(space, e.linear_system().dc_gain()),
            "worst_gdop_after_failures": ft["worst_gdop_after"][str(failures)] if failures else ft["gdop"],
            "fault_tolerance": json.loads(json.dumps(ft)),
            "path": "full predictor (the array KF does not decouple here)"}


def _rank_key(d: dict) -> float:
    return d["rms_3axis_deg_s"] if math.isfinite(d["rms_3axis_deg_s"]) else math.inf


def search(g: GyroNoise, space: DesignSpace, rho: float) -> tuple[list[dict], list[str]]:
    """Every scheme × N × estimator at its best cone angle and bandwidth, at one ρ, ranked.

    Returns the designs (best first) and notes (what was left out and why).
    """
    g, space = sized_for(g, space)
    bank = filter_bank(space, g)
    designs, notes = [], []
    for scheme in space.schemes:
        alphas = alpha_grid(scheme, space.alpha_points)
        for n in space.ns:
            lo = -1.0 / (n - 1)
            if not (g.rho_arw == g.rho_rrw and rho > lo) and not (g.rho_arw != g.rho_rrw
                                                                  and min(g.rho_arw, g.rho_rrw) > lo):
                notes.append(f"scheme {scheme}, N = {n}: rho = {rho:g} is not a correlation N = {n} "
                             f"gyros can have (below -1/(N-1) = {lo:.4g}); left out")
                continue
            H = conical_axes(scheme, n, alphas)
            alive = np.isfinite(_survives(H, rho if g.rho_arw == g.rho_rrw else g.rho_arw,
                                          space.failures))
            if not alive.any():
                notes.append(f"scheme {scheme}, N = {n}: no cone angle keeps a 3-axis rate after "
                             f"{space.failures} failed gyro(s); left out")
                continue
            found: dict[str, _Best | None] = {}
            for est in space.estimators:
                best, ch = _search_one(bank, space, g, scheme, n, est, rho, alive, alphas, H)
                if best is None and est == "kf_array" and not ch.decoupled:
                    found[est] = None                                # after kf_single
                    continue
                if best is None:
                    notes.append(f"scheme {scheme}, N = {n}, {est}: no bandwidth in range is reachable")
                    continue
                best = _refine_alpha(best, space, g, alphas, space.failures)
                found[est] = best
                designs.append(_design_dict(best, space, g, space.failures))
            if "kf_array" in found and found["kf_array"] is None:
                ref = found.get("kf_single")
                if ref is not None:
                    designs.append(generic_design(scheme, n, "kf_array", ref.alpha_rad, ref.bw, rho,
                                                   space, g, space.failures))
                    notes.append(f"scheme {scheme}, N = {n}, kf_array: its z axis does not decouple "
                                 "(unequal ARW and RRW correlation); predicted by the full predictor "
                                 "at kf_single's cone angle and bandwidth")
    designs = _ranked(designs, space.estimators)
    designs = _refine_top_bandwidths(designs, g, space, rho)
    return designs, notes


#: Designs at the top of a ranking whose bandwidth is refined off the grid.
REFINE_TOP = 8


def _refine_top_bandwidths(designs: list[dict], g: GyroNoise, space: DesignSpace, rho: float) -> list[dict]:
    """Bounded Brent in log(bandwidth) between the grid neighbours, for the top designs."""
    lo, hi = space.bandwidth_hz
    if lo == hi:
        return designs
    out = list(designs)
    for i, d in enumerate(designs[:REFINE_TOP]):
        bw = d["bandwidth_hz"]
        if bw is None:
            continue
        grid = [f for f in bandwidth_grid(space, d["estimator"]) if f is not None]
        k = int(np.argmin(np.abs(np.log(np.array(grid) / bw))))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        alpha = math.radians(d["alpha_deg"])

        def f(logbw):
            e = generic_or_fast(d["scheme"], d["n"], d["estimator"], alpha, float(np.exp(logbw)),
                                 rho, g, space)
            return e["rms_3axis_deg_s"] if math.isfinite(e["rms_3axis_deg_s"]) else math.inf
        if b <= a:
            continue
        res = minimize_scalar(f, bounds=(math.log(a), math.log(b)), method="bounded",
                              options={"xatol": 1e-3})
        if res.fun < d["rms_3axis_deg_s"]:
            new = generic_or_fast(d["scheme"], d["n"], d["estimator"], alpha,
                                   float(round(math.exp(res.x), 3)), rho, g, space)
            new["rank"] = d.get("rank")
            out[i] = new
    return _ranked(out, space.estimators)


def _ranked(designs: list[dict], estimators) -> list[dict]:
    """Best RMS first; designs equal to 1e-9 are ordered by fault tolerance (worst GDOP
    after two failures), Scheme 1 first, a cone opening upwards, then the estimator order."""
    designs = sorted(designs, key=_rank_key)
    out, i = [], 0
    order = {e: k for k, e in enumerate(estimators)}
    while i < len(designs):
        j = i + 1
        while j < len(designs) and designs[j]["rms_3axis_deg_s"] <= designs[i]["rms_3axis_deg_s"] * (1 + 1e-9):
            j += 1
        out += sorted(designs[i:j], key=lambda d: (
            round(d.get("fault_tolerance", {}).get("worst_gdop_after", {}).get("2", math.inf), 9),
            d["scheme"], d["alpha_deg"] > 90.0, order.get(d["estimator"], 99)))
        i = j
    for k, d in enumerate(out):
        d["rank"] = k + 1
    return out


def _evaluate_design(d: dict, g: GyroNoise, space: DesignSpace, rho: float) -> dict:
    """One fixed design (scheme, N, α, estimator, bandwidth) predicted at another ρ."""
    return generic_or_fast(d["scheme"], d["n"], d["estimator"], math.radians(d["alpha_deg"]),
                            d["bandwidth_hz"], rho, g, space)


def generic_or_fast(scheme, n, est, alpha, bw, rho, g, space) -> dict:
    gr = g.with_rho(rho) if g.rho_arw == g.rho_rrw else g
    H = conical_axes(scheme, n, np.array([alpha]))
    if weight_kind(est) is None:                 # weights read from the fitted filter: full predictor
        return generic_design(scheme, n, est, alpha, bw, rho, space, g, space.failures)
    ch = channel_levels(est, H, gr, space.dt_s)
    ch.kf_single_ratio = single_ratio(g, space)
    if not ch.decoupled:
        return generic_design(scheme, n, est, alpha, bw, rho, space, g, space.failures)
    bank = filter_bank(space, g)
    resp = channel_responses(bank, est, bw, ch)
    J, _ = evaluate_channels(est, resp, ch, slice(None))
    b = _Best(scheme, n, est, alpha, bw, float(J[0]), resp, rho)
    return _design_dict(b, space, g, space.failures)
