"""The decision's screening: every design scored by its worst case over ρ ∈ [lo, hi] × every
set of k failed gyros (:func:`gyroarray.design.robust.kept_sets`), with the estimator's
weights fixed at a design ρ, through the fast channel model; the grids of mounting pattern,
cone angle, bandwidth and design ρ, then their refinement: a continuous min-max in (α, ρ_d)
jointly (:func:`refine_joint`), then the bandwidth.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from typing import Callable, cast

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from gyroarray.core import units
from gyroarray.core.gdop import gdop_batch
from gyroarray.design.predict import (AXES, settle_start)
from gyroarray.design.robust import (ALL_PATTERNS_UP_TO, kept_sets, mounted_axes,
                                     mounting_patterns, worst_over_interval)
from gyroarray.design.channels import (Channels, add_motion, filter_bank, combine_moments, channel_responses,
                                       both_objectives, fixed_channels)
from gyroarray.design.gyro_noise import GyroNoise
from gyroarray.design.search_space import (DesignSpace, alpha_grid, bandwidth_grid, design_tags)


#: The built-ins whose weights depend on the design ρ (the others are built without it); the
#: search reads it from each estimator's design tags (``DesignTags.rho_weighted``).
RHO_WEIGHTED = ("gls", "kf_array")


def rho_weighted(est: str) -> bool:
    """Whether the weights of ``est`` depend on the design ρ (its design tags)."""
    return design_tags(est).rho_weighted

#: Largest |M H − I| of fixed weights taken as unbiased [-].
BIAS_TOL = 1e-9

#: Design ρ values tried on the grid before the joint refinement (min-max).
DESIGN_RHO_POINTS = 3

#: Arrangements whose grid best is within this share of the grid's best are refined jointly
#: too (at most :data:`MAX_ALTERNATES` besides the best): on the 3-point design-ρ grid a
#: pattern whose min-max design ρ lies near a steep rise can lose by a few per cent and win
#: once ρ_d is continuous (the demo's Scheme 1, N = 6: alternating senses 35.31° on the grid,
#: 33.72° refined, against 34.50° for the grid's best).
PATTERN_SHARE = 0.05
MAX_ALTERNATES = 7

#: Most objective evaluations of the joint refinement's Nelder–Mead polish.
NM_MAXFEV = 200


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
    #: The placement: ``slots[j]`` is the cone slot (0-based) model gyro j takes (None: gyro j
    #: in slot j). ``signs`` are per slot.
    slots: tuple[int, ...] | None = None
    #: Other arrangements (sign pattern, placement) whose grid best is within
    #: :data:`PATTERN_SHARE` of this one's, best first: the joint refinement tries them too
    #: (a pattern whose optimum lies between the grid's design ρ can lose on the grid).
    alternates: tuple["Candidate", ...] = ()


def candidate_axes(c: Candidate, alphas_rad=None) -> np.ndarray:
    """The axes (G, N, 3) [-] of a candidate as the model's gyros see them (row j: gyro j + 1,
    in its slot ``c.slots[j]``), at its cone angle or at ``alphas_rad`` [rad]."""
    al = np.array([c.alpha_rad]) if alphas_rad is None else np.asarray(alphas_rad, dtype=float)
    return placed_axes(c.scheme, c.n, al, c.signs, c.slots)


def row_signs(signs, slots) -> np.ndarray:
    """The mounting sign of each row of :func:`placed_axes` (gyro j: the sign of its slot),
    what the axis frame of the common mode reads (:meth:`GyroNoise.correlation`)."""
    s = np.asarray(signs, dtype=float)
    return s if slots is None else s[list(slots)]


def placed_axes(scheme: int, n: int, alphas_rad, signs, slots) -> np.ndarray:
    """:func:`gyroarray.design.robust.mounted_axes` (slot order, signs per slot) with the rows
    taken in the model's gyro order: row j is slot ``slots[j]`` (None: slot j)."""
    H = mounted_axes(scheme, n, alphas_rad, signs)
    return H if slots is None else H[:, list(slots)]


#: Above this many placements × sign patterns per scheme the per-gyro search keeps the
#: structured sign patterns only.
MAX_ARRANGEMENTS = 512


def gyro_classes(g: GyroNoise, n: int) -> list[int]:
    """A class label per gyro (0-based, first seen first): gyros with the same noise levels
    are in one class (alike gyros: all in class 0). A model with its own correlation matrix
    that is not equicorrelated makes every gyro its own class."""
    if g.per_gyro is None:
        return [0] * n
    for corr in (g.corr_arw, g.corr_rrw):
        if corr is not None:
            c = np.asarray(corr, dtype=float)[:n, :n]
            off = c[~np.eye(n, dtype=bool)]
            if off.size and np.ptp(off) > 1e-12:
                return list(range(n))
    rows = [tuple(float(np.asarray(v, dtype=float)[j]) for _, v in sorted(g.per_gyro.items()))
            for j in range(n)]
    seen: dict[tuple, int] = {}
    return [seen.setdefault(r, len(seen)) for r in rows]


def placements(classes: list[int]) -> list[tuple[int, ...] | None]:
    """Every distinct placement of the gyros in the slots (one per multiset permutation of the
    classes: gyros of one class are interchangeable); ``slots[j]`` the slot of gyro j. Alike
    gyros: [None] (gyro j in slot j)."""
    n = len(classes)
    if len(set(classes)) == 1:
        return [None]
    out, seen = [], set()
    for perm in itertools.permutations(range(n)):                   # perm[k]: the gyro in slot k
        key = tuple(classes[j] for j in perm)
        if key in seen:
            continue
        seen.add(key)
        slots = [0] * n
        for k, j in enumerate(perm):
            slots[j] = k
        out.append(None if slots == list(range(n)) else tuple(slots))
        if len(out) > MAX_ARRANGEMENTS:
            break
    return sorted(out, key=lambda t: () if t is None else t)


def all_sign_patterns(scheme: int, n: int) -> list[np.ndarray]:
    """Every sign pattern of the cone gyros without the alike-gyro reduction (no rotation or
    mirror classes): Scheme 1 up to a global sign (slot 1 +), Scheme 2 with the axial gyro +
    (reversing it is the cone at 180° − α, a rigid rotation of the whole array, which the
    cone-angle search covers). All + first."""
    m = n if scheme == 1 else n - 1
    head = [] if scheme == 1 else [1]
    cones = [c for c in itertools.product((1, -1), repeat=m) if scheme == 2 or c[0] == 1]
    cones.sort(key=lambda t: (sum(v < 0 for v in t), tuple(-v for v in t)))
    return [np.array(head + list(c), dtype=float) for c in cones]


def arrangements(g: GyroNoise, scheme: int, n: int) -> list[tuple[np.ndarray, tuple[int, ...] | None]]:
    """The (sign pattern per slot, placement) pairs the search tries for one scheme and N.

    In the axis frame of the common mode (``g.common_mode``) the all-+ pattern only. Alike
    gyros: :func:`gyroarray.design.robust.mounting_patterns` (one pattern per class of
    patterns a rotation, a mirror or a global sign make equal), gyro j in slot j. Gyros that
    are not alike (a per-gyro model): every placement of the unlike gyros (:func:`placements`)
    × every sign pattern (:func:`all_sign_patterns`), since a rotation that maps one pattern
    onto another also moves the gyros; above :data:`MAX_ARRANGEMENTS` (or N above
    :data:`gyroarray.design.robust.ALL_PATTERNS_UP_TO`) the structured patterns of
    :func:`mounting_patterns` at every placement.
    """
    places = placements(gyro_classes(g, n))
    if getattr(g, "common_mode", "output") == "axis":
        # the common mode follows each sensing axis: a reversed gyro reverses its signal and its
        # noise alike, a sign the estimator undoes, so every mounting equals the one with no gyro
        # reversed (the same worst case, exactly): that one pattern is searched
        return [(np.ones(n), p) for p in places]
    if places == [None]:
        return [(s, None) for s in mounting_patterns(scheme, n)]
    pats = all_sign_patterns(scheme, n) if n <= ALL_PATTERNS_UP_TO else mounting_patterns(scheme, n)
    if len(pats) * len(places) > MAX_ARRANGEMENTS:
        pats = mounting_patterns(scheme, n)
    return [(s, p) for p in places for s in pats]


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

    def channels(self, est, H, keep, rho_d, rho_t, signs=None):
        gd = self.cond(self.lo if rho_d is None else rho_d)
        return fixed_channels(est, H[:, list(keep)], gd, self.cond(rho_t), self.dt, keep=list(keep),
                              signs=signs)

    def resp(self, est, bw, ch):
        return channel_responses(self.bank, est, bw, ch, idx=0)

    def conditions(self, est, H, rho_d, *, with_combos: bool = False, signs=None):
        """The filter's design channels (intact array at the design ρ) and the channels of every
        (kept set, end of the range) stacked on a leading axis (fixed weights: each variance is
        linear in ρ, so the worst ρ is an end); ``with_combos``: also the (kept set, ρ) of each.
        ``signs``: the mounting signs of H's rows (the axis frame's correlation depends on them)."""
        G, n = H.shape[:2]
        keeps = kept_sets(n, self.space.failures)
        design = self.channels(est, H, keeps[0], rho_d, rho_d if rho_d is not None else self.lo, signs)
        gd = self.cond(self.lo if rho_d is None else rho_d)
        axis = self.g.common_mode == "axis" and signs is not None and bool(np.any(np.asarray(signs) < 0))
        if self.g.per_gyro is not None or axis:  # each kept set its own gyros' noise (or signs)
            chs, combos = [], []
            for keep in keeps:
                for rt in self.ends():
                    chs.append(fixed_channels(est, H[:, list(keep)], gd, self.cond(rt), self.dt,
                                              keep=list(keep), signs=signs))
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
    if not rho_weighted(est) or not dec.ranged:
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
    per_pattern: list[Candidate] = []
    for signs, slots in arrangements(dec.g, scheme, n):
        here = None
        H = placed_axes(scheme, n, alphas, signs, slots)
        alive = _alive(H, space.failures)
        if not alive.any():
            continue
        Ha, al = H[alive], alphas[alive]
        for rd in _rho_grid(dec, est):
            design, stacked = dec.conditions(est, Ha, rd, signs=row_signs(signs, slots))
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
                best = Candidate(scheme, n, est, signs, float(al[k]), bbw[k], rd, float(bobj[k]), slots)
            if here is None or bobj[k] < here.J * (1.0 - 1e-9):
                here = Candidate(scheme, n, est, signs, float(al[k]), bbw[k], rd, float(bobj[k]), slots)
        if here is not None:
            per_pattern.append(here)
    if best is not None and rho_weighted(est) and dec.hi > dec.lo and dec.space.design_rho is None:
        alt = sorted((p for p in per_pattern if p.J <= best.J * (1.0 + PATTERN_SHARE)
                      and not (np.array_equal(p.signs, best.signs) and p.slots == best.slots)),
                     key=lambda p: p.J)
        best = replace(best, alternates=tuple(alt[:MAX_ALTERNATES]))
    return best, alphas


def _objective_over_alpha(dec: Decider, c: Candidate, alphas_rad: np.ndarray, rd, bw,
                          alive: np.ndarray | None = None, which: str | None = None) -> np.ndarray:
    """The worst case (G,) (squared objective) of ``c`` at each cone angle of ``alphas_rad`` [rad]
    for the design ρ ``rd`` [-] and bandwidth ``bw`` [Hz]: max over ρ's ends × kept sets, inf
    where a failure leaves no 3-axis rate. ``which``: "rate" or "angle" (default the objective)."""
    H = candidate_axes(c, alphas_rad)
    ok = _alive(H, dec.space.failures) if alive is None else alive
    out = np.full(alphas_rad.size, np.inf)
    if ok.any():
        jr, ja = dec.worst_pair(c.est, bw, *dec.conditions(c.est, H[ok], rd, signs=row_signs(c.signs, c.slots)))
        out[ok] = jr if (which or dec.objective) == "rate" else ja
    return out


def _joint_profile(dec: Decider, c: Candidate, alphas: np.ndarray, xatol: float = 1e-4) -> Candidate:
    """The profile stage of :func:`refine_joint` for one arrangement: bounded Brent in ρ_d over
    [lo, hi] (to ``xatol``) of φ(ρ_d) = min over the cone angles ``alphas`` [rad] of J(α, ρ_d),
    the grid's design ρ values tried too. Returns the best (α, ρ_d, J) found (J = inf: none finite)."""
    alive = _alive(candidate_axes(c, alphas), dec.space.failures)
    tried: dict[float, tuple[float, float]] = {}

    def profile(rd: float) -> float:
        j = _objective_over_alpha(dec, c, alphas, rd, c.bw, alive)
        i = int(np.argmin(j))
        tried[float(rd)] = (float(j[i]), float(alphas[i]))
        return float(j[i])
    for r in [c.rho_d] + [float(v) for v in np.linspace(dec.lo, dec.hi, DESIGN_RHO_POINTS)]:
        profile(float(cast(float, r)))
    minimize_scalar(profile, bounds=(dec.lo, dec.hi), method="bounded", options={"xatol": xatol})
    rd = min(tried, key=lambda r: tried[r][0])
    j0, a0 = tried[rd]
    return replace(c, alpha_rad=a0, rho_d=rd, J=j0) if j0 < c.J * (1.0 - 1e-9) else c


def refine_joint(dec: Decider, c: Candidate, alphas: np.ndarray) -> Candidate:
    """The continuous min-max over (α, design ρ) jointly, started from the grid's best.

    The objective J(α, ρ_d) is the worst case over the true ρ ∈ [lo, hi] × every kept set (a max
    of smooth functions: kinked where two conditions tie, which is where a min-max optimum
    usually sits). Chosen method: nested bounded searches (:func:`scipy.optimize.minimize_scalar`,
    bounded Brent: no gradient needed, it tolerates the kinks). The outer one is in ρ_d over
    [lo, hi] (xatol 1e-3) on the profile φ(ρ_d) = min_α J(α, ρ_d), the inner min over the whole
    cone-angle grid (vectorised: one channel evaluation per ρ_d), so the best α may move anywhere with
    ρ_d (:func:`_joint_profile`); this for the grid's best arrangement and its ``alternates``
    (those within :data:`PATTERN_SHARE` on the grid; screened on every other grid angle with ρ_d
    to 2e-3; the winner, if an alternate, profiled again in full). The best is then polished in
    both at once by bounded Nelder–Mead (:func:`scipy.optimize.minimize`; α within two grid
    steps, ρ_d over [lo, hi]; xatol 1e-6, fatol 1e-8·J, at most :data:`NM_MAXFEV` evaluations;
    the survival of the failures checked at its end):
    a min-max optimum sits on a ridge where two conditions tie, on which a search in one
    coordinate at a time stalls (the brute force of tests/test_design_joint_refine.py: its
    Scheme 2, N = 5 was 0.27 % off after Brent polishes, one coordinate at a time). The result replaces ``c`` only where it is lower
    (by more than 1e-9 relative: a flat direction keeps the grid's value), so it is never
    worse than the grid's best.
    """
    starts = [replace(c, alternates=())] + [replace(a, alternates=()) for a in c.alternates]
    # the alternates screened on every other grid angle, ρ_d to 2e-3 (the winner again in full)
    prof = [_joint_profile(dec, starts[0], alphas, 1e-3)] + [_joint_profile(dec, a, alphas[::2], 2e-3)
                                                       for a in starts[1:]]
    best = min(prof, key=lambda p: p.J)
    if best is not prof[0]:             # an alternate won the screen: its full profile
        best = _joint_profile(dec, best, alphas, 1e-3)
    step = float(alphas[1] - alphas[0])

    live = np.ones(1, bool)

    def J(x) -> float:              # every α within two steps of a live grid angle: checked once, after
        return float(_objective_over_alpha(dec, best, np.array([x[0]]), float(x[1]), best.bw, live)[0])
    if math.isfinite(best.J):
        # Nelder–Mead on the kinked max: it walks along the ridge where two conditions tie,
        # which Brent in one coordinate at a time stalls on
        x0 = np.array([best.alpha_rad, float(cast(float, best.rho_d))])
        simplex = np.array([x0, x0 + [0.5 * step, 0.0], x0 + [0.0, 0.01 * (dec.hi - dec.lo)]])
        simplex[:, 1] = np.clip(simplex[:, 1], dec.lo, dec.hi)
        if simplex[2, 1] == x0[1]:
            simplex[2, 1] = x0[1] - 0.01 * (dec.hi - dec.lo)
        res = minimize(J, x0, method="Nelder-Mead",
                       bounds=[(best.alpha_rad - 2.0 * step, best.alpha_rad + 2.0 * step), (dec.lo, dec.hi)],
                       options={"initial_simplex": simplex, "xatol": 1e-6, "fatol": 1e-8 * best.J,
                                "maxfev": NM_MAXFEV})
        if (res.fun < best.J * (1.0 - 1e-9)
                and _alive(candidate_axes(best, np.array([res.x[0]])), dec.space.failures)[0]):
            best = replace(best, alpha_rad=float(res.x[0]), rho_d=float(res.x[1]), J=float(res.fun))
    return best if best.J < c.J * (1.0 - 1e-9) else replace(c, alternates=())


def refine_candidate(dec: Decider, c: Candidate, alphas: np.ndarray, bandwidth: bool) -> Candidate:
    """The joint continuous min-max over (α, design ρ) (:func:`refine_joint`) where the design ρ
    is searched (a ρ-weighted estimator over a range, no ``--design-rho``), else bounded Brent in
    α between the grid neighbours; then (``bandwidth``) bounded Brent in log bandwidth between
    the grid neighbours. Never worse than the grid's best (each step is kept only if lower)."""
    def J(alpha, rd, bw, which=None):
        H = candidate_axes(c, np.array([alpha]))
        if not _alive(H, dec.space.failures)[0]:
            return math.inf
        jr, ja = dec.worst_pair(c.est, bw, *dec.conditions(c.est, H, rd, signs=row_signs(c.signs, c.slots)))
        return float((jr if (which or dec.objective) == "rate" else ja)[0])
    if c.rho_d is not None and dec.space.design_rho is None and dec.hi > dec.lo:
        c = refine_joint(dec, c, alphas)
    else:
        k = int(np.argmin(np.abs(alphas - c.alpha_rad)))
        lo = alphas[k - 1] if k > 0 else alphas[k] * 0.5
        hi = alphas[k + 1] if k + 1 < alphas.size else alphas[k]
        if hi > lo:
            res = minimize_scalar(lambda a: J(a, c.rho_d, c.bw), bounds=(lo, hi), method="bounded",
                                  options={"xatol": 1e-7})
            if res.fun < c.J:
                c = replace(c, alpha_rad=float(res.x), J=float(res.fun))
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
    ch = dec.channels(c.est, H, keep, rho_d, rho_t, row_signs(c.signs, c.slots))
    resp = dec.resp(c.est, c.bw, dec.channels(c.est, H, tuple(range(c.n)), rho_d,
                                               rho_d if rho_d is not None else dec.lo,
                                               row_signs(c.signs, c.slots)))
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
    # oracle: every kept set at the range's ends, then a continuous search in ρ on the two
    # worst sets (the weights follow ρ: the worst may lie inside)
    if not oracle:
        # fixed weights: every error variance is linear in ρ (the RMS and angle its square
        # root), so the worst ρ of each kept set is an end, exactly: no search inside
        cases = [score_case(dec, c, H, keep, r, rd(r)) for keep in kept_sets(c.n, dec.space.failures)
                 for r in dec.ends()]
        return max(cases, key=lambda case: case[key])      # ties: the first (intact, lo first)
    ends = {keep: max(score_case(dec, c, H, keep, r, rd(r))[key] for r in dec.ends())
            for keep in kept_sets(c.n, dec.space.failures)}
    top = sorted(ends, key=lambda k: -ends[k])[:2]
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
