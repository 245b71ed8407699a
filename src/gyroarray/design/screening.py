"""The decision's screening: every design scored by its worst case over ρ ∈ [lo, hi] × every
set of k failed gyros (:func:`gyroarray.design.robust.kept_sets`), with the estimator's
weights fixed at a design ρ, through the fast channel model; the grids of mounting pattern,
cone angle, bandwidth and design ρ, then their bounded refinement.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable, cast

import numpy as np
from scipy.optimize import minimize_scalar

from gyroarray.core import units
from gyroarray.core.gdop import gdop_batch
from gyroarray.design.predict import (AXES, settle_start)
from gyroarray.design.robust import (kept_sets, mounted_axes,
                                     mounting_patterns, worst_over_interval)
from gyroarray.design.channels import (Channels, add_motion, filter_bank, combine_moments, channel_responses,
                                       both_objectives, fixed_channels)
from gyroarray.design.gyro_noise import GyroNoise
from gyroarray.design.search_space import (DesignSpace, alpha_grid, bandwidth_grid)


#: Estimators whose weights depend on the design ρ (the others are built without it).
RHO_WEIGHTED = ("gls", "kf_array")

#: Largest |M H − I| of fixed weights taken as unbiased [-].
BIAS_TOL = 1e-9

#: Design ρ values tried on the grid before the bounded refinement (min-max).
DESIGN_RHO_POINTS = 3


def _noise_at(g: GyroNoise, rho: float | None) -> GyroNoise:
    """The gyros at a common correlation ρ (None, or unequal ARW/RRW ρ without a range: as given)."""
    return g if rho is None else g.with_rho(rho)


@dataclass
class Candidate:
    """One candidate design of the decision search."""

    scheme: int
    n: int
    est: str
    signs: np.ndarray
    alpha_rad: float
    bw: float | None
    rho_d: float | None
    J: float


class Decider:
    """Scores designs over ρ ∈ [lo, hi] × every set of k failed gyros with fixed weights."""

    def __init__(self, g: GyroNoise, space: DesignSpace, lo: float, hi: float, objective: str):
        self.g, self.space, self.lo, self.hi, self.objective = g, space, lo, hi, objective
        # a model's own correlation matrices stay unless a range (or --rho) replaces them
        self.ranged = hi > lo or (g.rho_arw == g.rho_rrw and g.corr_arw is None and g.corr_rrw is None)
        self.bank = filter_bank(space, g)
        self.dt = space.dt_s
        self._conds: dict = {}

    def cond(self, rho):
        key = None if not self.ranged else float(rho)
        if key not in self._conds:
            self._conds[key] = _noise_at(self.g, key)
        return self._conds[key]

    def ends(self):
        return [self.lo] if self.hi <= self.lo else [self.lo, self.hi]

    def channels(self, est, H, keep, rho_d, rho_t):
        gd = self.cond(self.lo if rho_d is None else rho_d)
        return fixed_channels(est, H[:, list(keep)], gd, self.cond(rho_t), self.dt, keep=list(keep))

    def resp(self, est, bw, ch):
        return channel_responses(self.bank, est, bw, ch, idx=0)

    def conditions(self, est, H, rho_d, *, with_combos: bool = False):
        """The filter's design channels (intact array at the design ρ) and the channels of every
        (kept set, end of the range) stacked on a leading axis (fixed weights: each variance is
        linear in ρ, so the worst ρ is an end); ``with_combos``: also the (kept set, ρ) of each."""
        G, n = H.shape[:2]
        keeps = kept_sets(n, self.space.failures)
        design = self.channels(est, H, keeps[0], rho_d, rho_d if rho_d is not None else self.lo)
        gd = self.cond(self.lo if rho_d is None else rho_d)
        if self.g.per_gyro is not None:          # each kept set has its own gyros' noise
            chs, combos = [], []
            for keep in keeps:
                for rt in self.ends():
                    chs.append(fixed_channels(est, H[:, list(keep)], gd, self.cond(rt), self.dt,
                                              keep=list(keep)))
                    combos.append((keep, rt))
            s_white, s_walk, s_flicker, s_gm = (np.stack([getattr(c, f) for c in chs])
                                                for f in ("white", "walk", "flicker", "gm"))
            stacked = Channels(s_white, s_walk, s_flicker, s_gm, None, True, design.kf_single_ratio,
                                bias=np.stack([cast(np.ndarray, c.bias) for c in chs]))  # fixed weights set bias
            return (design, stacked, combos) if with_combos else (design, stacked)
        parts, combos = [], []
        for rt in self.ends():
            ch = fixed_channels(est, H, gd, self.cond(rt), self.dt)
            parts.append(ch)
            combos.append((keeps[0], rt))
        if len(keeps) > 1:                       # every failed set at once: (K·G, N − k, 3)
            Hk = np.concatenate([H[:, list(k)] for k in keeps[1:]], axis=0)
            for rt in self.ends():
                ch = fixed_channels(est, Hk, gd, self.cond(rt), self.dt)
                K = len(keeps) - 1
                k_white, k_walk, k_flicker, k_gm = (a.reshape(K, G, 3)
                                                    for a in (ch.white, ch.walk, ch.flicker, ch.gm))
                parts.append(Channels(k_white, k_walk, k_flicker, k_gm, None, True, ch.kf_single_ratio,
                                       bias=cast(np.ndarray, ch.bias).reshape(K, G)))   # fixed weights set bias
                combos += [(k, rt) for k in keeps[1:]]
        arr = [np.concatenate([p_.__dict__[f][None] if p_.white.ndim == 2 else p_.__dict__[f]
                               for p_ in parts]) for f in ("white", "walk", "flicker", "gm")]
        bias = np.concatenate([cast(np.ndarray, p_.bias)[None] if p_.white.ndim == 2 else cast(np.ndarray, p_.bias)
                               for p_ in parts])
        a_white, a_walk, a_flicker, a_gm = arr
        stacked = Channels(a_white, a_walk, a_flicker, a_gm, None, True, design.kf_single_ratio, bias=bias)
        return (design, stacked, combos) if with_combos else (design, stacked)

    def worst_pair(self, est, bw, design: Channels, stacked: Channels) -> tuple[np.ndarray, np.ndarray]:
        """Worst rate and angle objectives (G,) (squared) over the stacked conditions."""
        resp = self.resp(est, bw, design)
        if any(r is None for r in resp):
            inf = np.full(design.white.shape[0], np.inf)
            return inf, inf
        jr, ja = both_objectives(stacked, resp, self.dt)
        # weights that do not reproduce the motion (naive after a failure: HᵀH not diagonal)
        # leave a motion error the channel model does not hold: not a design that survives
        ok = np.isfinite(jr) & np.isfinite(ja) & (cast(np.ndarray, stacked.bias) <= BIAS_TOL)   # fixed weights
        jr, ja = np.where(ok, jr, np.inf), np.where(ok, ja, np.inf)
        return np.max(jr, axis=0), np.max(ja, axis=0)

    def worst(self, est, H, rho_d, bw) -> np.ndarray:
        """The objective's worst value (G,) (squared) over ρ's ends × kept sets."""
        jr, ja = self.worst_pair(est, bw, *self.conditions(est, H, rho_d))
        return jr if self.objective == "rate" else ja


def _alive(H: np.ndarray, failures: int) -> np.ndarray:
    """Layouts (G,) that keep a 3-axis rate intact and after every set of failed gyros."""
    ok = np.ones(H.shape[0], bool)
    for keep in kept_sets(H.shape[1], failures):
        ok &= np.isfinite(gdop_batch(H[:, list(keep)], np.eye(len(keep))))
    return ok


def _rho_grid(dec: Decider, est: str) -> list:
    if est not in RHO_WEIGHTED or not dec.ranged:
        return [None]
    if dec.space.design_rho is not None:
        return [float(dec.space.design_rho)]
    if dec.hi <= dec.lo:
        return [dec.lo]
    return [float(r) for r in np.linspace(dec.lo, dec.hi, DESIGN_RHO_POINTS)]


def grid_best(dec: Decider, scheme: int, n: int, est: str) -> tuple[Candidate | None, np.ndarray]:
    """Best (pattern, α, bandwidth, design ρ) of one scheme, N, estimator on the grids."""
    space = dec.space
    alphas = alpha_grid(scheme, space.alpha_points)
    best = None
    for signs in mounting_patterns(scheme, n):
        H = mounted_axes(scheme, n, alphas, signs)
        alive = _alive(H, space.failures)
        if not alive.any():
            continue
        Ha, al = H[alive], alphas[alive]
        for rd in _rho_grid(dec, est):
            design, stacked = dec.conditions(est, Ha, rd)
            # per α: the bandwidth that minimises the rate objective (a unit-DC-gain filter's
            # bandwidth barely moves the angle: ranked on angle alone the narrowest filter would
            # win and give up tracking the motion); the objective at that bandwidth
            bj = np.full(al.size, np.inf)
            bobj = np.full(al.size, np.inf)
            bbw: list = [None] * al.size
            for bw in bandwidth_grid(space, est):
                jr, ja = dec.worst_pair(est, bw, design, stacked)
                better = jr < bj
                bj = np.where(better, jr, bj)
                bobj = np.where(better, jr if dec.objective == "rate" else ja, bobj)
                for i in np.flatnonzero(better):
                    bbw[i] = bw
            k = int(np.argmin(bobj))
            if not np.isfinite(bobj[k]):
                continue
            k = int(np.flatnonzero(bobj <= bobj[k] * (1.0 + 1e-9))[0])     # ties: the smaller α
            if best is None or bobj[k] < best.J * (1.0 - 1e-9):            # ties: the first pattern
                best = Candidate(scheme, n, est, signs, float(al[k]), bbw[k], rd, float(bobj[k]))
    return best, alphas


def refine_candidate(dec: Decider, c: Candidate, alphas: np.ndarray, bandwidth: bool) -> Candidate:
    """Bounded Brent in α between the grid neighbours, then in the design ρ over the range,
    then (``bandwidth``) in log bandwidth between the grid neighbours."""
    def J(alpha, rd, bw, which=None):
        H = mounted_axes(c.scheme, c.n, np.array([alpha]), c.signs)
        if not _alive(H, dec.space.failures)[0]:
            return math.inf
        jr, ja = dec.worst_pair(c.est, bw, *dec.conditions(c.est, H, rd))
        return float((jr if (which or dec.objective) == "rate" else ja)[0])
    k = int(np.argmin(np.abs(alphas - c.alpha_rad)))
    lo = alphas[k - 1] if k > 0 else alphas[k] * 0.5
    hi = alphas[k + 1] if k + 1 < alphas.size else alphas[k]
    if hi > lo:
        res = minimize_scalar(lambda a: J(a, c.rho_d, c.bw), bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-7})
        if res.fun < c.J:
            c = replace(c, alpha_rad=float(res.x), J=float(res.fun))
    if c.rho_d is not None and dec.space.design_rho is None and dec.hi > dec.lo:
        res = minimize_scalar(lambda r: J(c.alpha_rad, r, c.bw), bounds=(dec.lo, dec.hi),
                              method="bounded", options={"xatol": 1e-6})
        if res.fun < c.J:
            c = replace(c, rho_d=float(res.x), J=float(res.fun))
    if bandwidth and c.bw is not None and dec.space.bandwidth_hz[0] != dec.space.bandwidth_hz[1]:
        grid = [f for f in bandwidth_grid(dec.space, c.est) if f is not None]
        k = int(np.argmin(np.abs(np.log(np.array(grid) / c.bw))))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        if b > a:                                   # the bandwidth: by the rate objective
            res = minimize_scalar(lambda lb: J(c.alpha_rad, c.rho_d, float(round(math.exp(lb), 3)), "rate"),
                                  bounds=(math.log(a), math.log(b)), method="bounded",
                                  options={"xatol": 1e-3})
            if res.fun < J(c.alpha_rad, c.rho_d, c.bw, "rate"):
                bw = float(round(math.exp(res.x), 3))
                c = replace(c, bw=bw, J=J(c.alpha_rad, c.rho_d, bw))
    return c


def score_case(dec: Decider, c: Candidate, H: np.ndarray, keep, rho_t: float, rho_d) -> dict:
    """Per axis and 3-axis: RMS rate error and angle error of one (kept set, true ρ)."""
    ch = dec.channels(c.est, H, keep, rho_d, rho_t)
    resp = dec.resp(c.est, c.bw, dec.channels(c.est, H, tuple(range(c.n)), rho_d,
                                               rho_d if rho_d is not None else dec.lo))
    m = combine_moments(ch, slice(None), resp)
    ms, sumw2, sumf2 = add_motion(m, resp)
    to = units.rad_s_to_deg_s
    ang = units.rad_to_deg(dec.dt * np.sqrt(sumf2[0]))
    n = dec.space.n_samples
    nw = n - settle_start(n, dec.dt, dec.space.settle_s)
    mean2 = sumw2[0] / nw ** 2
    std = np.sqrt(np.maximum(nw / (nw - 1.0) * (ms[0] - mean2), 0.0))
    return {"rho": float(rho_t), "failed_gyros": [k + 1 for k in range(c.n) if k not in keep],
            "rms_3axis_deg_s": float(to(math.sqrt(np.sum(ms[0])))),
            "angle_deg": float(math.sqrt(np.sum(ang ** 2))),
            "per_axis": {ax: {"rms_deg_s": float(to(math.sqrt(ms[0, a]))),
                              "std_deg_s": float(to(std[a])), "mean_deg_s": float(to(math.sqrt(mean2[a]))),
                              "angle_deg": float(ang[a])} for a, ax in enumerate(AXES)},
            "_moments": (m, ms, sumw2, sumf2, ch, resp)}


def worst_case_of(dec: Decider, c: Candidate, H: np.ndarray, *, oracle: bool = False) -> dict:
    """The worst (true ρ, failed set) of a design, ρ found continuously for each kept set.

    ``oracle``: weights (and filter) follow the true ρ instead of the design ρ."""
    key = "rms_3axis_deg_s" if dec.objective == "rate" else "angle_deg"

    def rd(r):
        return (r if oracle else c.rho_d) if c.rho_d is not None else None
    # every kept set at the range's ends, then a continuous search in ρ on the worst set(s)
    # (fixed weights: linear in ρ, the search confirms an end; oracle: the worst may lie inside)
    ends = {keep: max(score_case(dec, c, H, keep, r, rd(r))[key] for r in dec.ends())
            for keep in kept_sets(c.n, dec.space.failures)}
    top = sorted(ends, key=lambda k: -ends[k])[:2 if oracle else 1]
    worst = None
    for keep in top:
        # cast: mypy cannot infer a lambda whose default argument binds the loop's kept set
        v, r = worst_over_interval(cast("Callable[[float], float]",
                                        lambda rt, keep=keep: score_case(dec, c, H, keep, rt, rd(rt))[key]),
                                   dec.lo, dec.hi, xatol=1e-6)
        if worst is None or v > worst[0]:
            worst = (v, r, keep)
    _, r, keep = cast(tuple, worst)                     # set: top holds at least one kept set
    return score_case(dec, c, H, keep, r, rd(r))


def nominal_rho(dec: Decider, c: Candidate) -> float:
    """The typical condition: the design ρ, else (ρ-free estimators) ρ = 0 if in range, else the
    range's middle."""
    if c.rho_d is not None:
        return c.rho_d
    return 0.0 if dec.lo <= 0.0 <= dec.hi else 0.5 * (dec.lo + dec.hi)


def public_fields(case: dict) -> dict:
    return {k: v for k, v in case.items() if not k.startswith("_")}


def predicted_at(rho: float, dec: Decider) -> dict:
    """Where a design's ``predicted``, ``rms_3axis_deg_s`` and ``rho`` are: the intact array at
    the true ρ where its objective is worst over the range (weights for the design ρ)."""
    return {"rho": float(rho), "failed_gyros": [],
            "what": (f"the intact array at the true ρ = {rho:.4g} where its {dec.objective} objective is "
                     f"worst over ρ in [{dec.lo:g}, {dec.hi:g}] (the estimator built for the design ρ); "
                     "the worst case over failures is `worst_case`")}
