"""Layouts designed at the bound, beyond the cones (issue 46): a search over the sphere.

For N gyros of equal noise σ with common-mode correlation ρ >= 0 (C = (1 − ρ)I + ρ11ᵀ),
every layout has GDOP >= 3·√((1 − ρ)/N) (:func:`gdop_floor`), reached exactly by a tight
frame whose axes sum to zero (HᵀH = (N/3)I, Hᵀ1 = 0: the common mode lies in the parity
space). :func:`search_layout` designs the N unit axes (signs included) for the tool's robust
objective — the worst case over the ρ range × every set of ``failures`` failed gyros, with
the GLS weights fixed at a design ρ (:func:`gyroarray.design.robust.fixed_weights`,
:func:`~gyroarray.design.robust.kept_sets`, :func:`~gyroarray.design.robust.worst_over_interval`)
— under a minimum pairwise angle and a minimum parity angle (single-fault isolability).

Families: ``free`` (any unit axes; scipy SLSQP on normalised 3-vectors, several random
starts, then a second SLSQP stage that spreads the axes — largest minimum pairwise angle —
without leaving the optimum's worst case); ``triads`` (M = N/3 orthogonal triads, each with
its own rotation vector); ``faces`` (axes normal to faces of a cube, octahedron, dodecahedron
or icosahedron, a sign per axis; discrete search); ``cone1``/``cone2`` (paper 003's schemes
over the cone angle and the mounting patterns of :func:`gyroarray.design.robust.mounting_patterns`).

Everything here is geometric: GDOP in units of the per-gyro σ, white noise, one sample.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import minimize, minimize_scalar
from scipy.spatial.transform import Rotation

from gyroarray.core.errors import InputError
from gyroarray.design.robust import (fixed_weights, kept_sets, worst_over_interval, mounting_patterns,
                                     mounted_axes)
from gyroarray.design.search_space import alpha_grid
from gyroarray.estimators.fdi import isolability

__all__ = ["FAMILIES", "POLYHEDRA", "SphereDesign", "gdop_floor", "mdb_floor_factor", "search_layout",
           "evaluate_layout", "parity_angles_deg", "mdb_factors", "triad_gain", "coaligned_triads"]

#: The mounting families :func:`search_layout` designs.
FAMILIES = ("cone1", "cone2", "free", "triads", "faces")

#: Default minimum angle between two gyro axes, as lines [deg].
MIN_ANGLE_DEG = 10.0

#: Default minimum parity angle (between two gyros' parity directions, as lines) [deg];
#: applied where isolation is possible (N − 3 >= 2).
MIN_PARITY_ANGLE_DEG = 10.0

#: Points of the design-ρ grid the fixed weights are chosen on (min-max), ends included.
DESIGN_RHO_POINTS = 5

#: The worst case a spreading stage may give up, relative [-].
SPREAD_SLACK = 1e-7


def gdop_floor(n: int, rho: float) -> float:
    """The smallest GDOP any layout of N equal-noise gyros can have, 3·√((1 − ρ)/N) [-].

    Parameters
    ----------
    n : int
        Number of gyros N >= 3.
    rho : float
        Common-mode correlation ρ >= 0 of the gyros' white noise [-] (C = (1 − ρ)I + ρ11ᵀ).

    Returns
    -------
    float
        GDOP floor [-] (in units of the per-gyro σ). Reached if and only if HᵀH = (N/3)·I
        (a tight frame) and Hᵀ1 = 0 (the axes sum to zero, so the common mode lies in the
        parity space and drops out of the estimate).
    """
    if not n >= 3 or not 0.0 <= rho < 1.0:
        raise InputError(f"gdop_floor: N >= 3 and 0 <= rho < 1, got N = {n}, rho = {rho:g}")
    return 3.0 * math.sqrt((1.0 - rho) / n)


def mdb_floor_factor(n: int) -> float:
    """The tight frame's minimum-detectable-bias factor 1/√(1 − 3/N) [-].

    The tool's MDB (:func:`gyroarray.estimators.fdi.minimum_detectable`) is, for white noise,
    one window of L samples and no bias tracking, Baarda's and Sturza's
    MDB_j = δ₀·σ/√(L·(1 − h_jᵀ(HᵀH)⁻¹h_j)), δ₀ = z_α + z_β. The leverages h_jᵀ(HᵀH)⁻¹h_j
    sum to 3, so the worst gyro's is >= 3/N, with equality for a tight frame: this factor
    multiplies δ₀·σ/√L (the MDB of a gyro whose rate were known) and is the floor of the
    worst gyro's factor 1/√(1 − h_jᵀ(HᵀH)⁻¹h_j) (:func:`mdb_factors`).
    """
    if not n > 3:
        raise InputError(f"mdb_floor_factor: N > 3 (a parity space), got N = {n}")
    return 1.0 / math.sqrt(1.0 - 3.0 / n)


def _corr(n: int, rho: float) -> np.ndarray:
    return (1.0 - rho) * np.eye(n) + rho * np.ones((n, n))


def parity_angles_deg(H: np.ndarray) -> np.ndarray:
    """Angles between the gyros' parity directions, as lines [deg] (N, N), diagonal 90.

    The parity directions are the columns of an orthonormal parity basis V (V H = 0,
    V Vᵀ = I); VᵀV = I − H(HᵀH)⁻¹Hᵀ (the identical, uncorrelated weighting of
    :func:`gyroarray.estimators.fdi.isolability`), so cos_ij = Q_ij/√(Q_ii Q_jj).
    """
    H = np.asarray(H, dtype=float)
    Q = np.eye(H.shape[0]) - H @ np.linalg.solve(H.T @ H, H.T)
    d = np.sqrt(np.maximum(np.diag(Q), 1e-300))
    c = np.clip(np.abs(Q / np.outer(d, d)), 0.0, 1.0)
    np.fill_diagonal(c, 0.0)
    return np.degrees(np.arccos(c))


def mdb_factors(H: np.ndarray) -> np.ndarray:
    """Per gyro 1/√(1 − h_jᵀ(HᵀH)⁻¹h_j) [-]: the MDB in units of δ₀·σ/√L (:func:`mdb_floor_factor`)."""
    H = np.asarray(H, dtype=float)
    lev = np.einsum("ni,ij,nj->n", H, np.linalg.inv(H.T @ H), H)
    return 1.0 / np.sqrt(np.maximum(1.0 - lev, 1e-300))


# -- the robust objective, batched over layouts -------------------------------------------

def _worst_variances(H: np.ndarray, lo: float, hi: float, failures: int, rho_d: float) -> np.ndarray:
    """GDOP² (G, S, 2) of layouts H (G, N, 3) with GLS weights fixed at ``rho_d``, per kept set
    (:func:`kept_sets`) at both ends of [lo, hi] (the fixed-weight variance is linear in ρ);
    inf where a kept set loses an axis."""
    G, n, _ = H.shape
    sets = kept_sets(n, failures)
    out = np.full((G, len(sets), 2), np.inf)
    for s, keep in enumerate(sets):
        Hk = H[:, list(keep)]
        m = len(keep)
        info = np.einsum("gni,gnj->gij", Hk, Hk)
        w = np.linalg.eigvalsh(info)
        ok = w[:, 0] > 1e-9 * np.maximum(w[:, -1], 1e-300)
        if not ok.any():
            continue
        M = fixed_weights("gls", Hk[ok], _corr(m, rho_d))
        for e, r in enumerate((lo, hi)):
            out[ok, s, e] = np.einsum("gin,nk,gik->g", M, _corr(m, r), M)
    return out


def _robust_worst(H: np.ndarray, lo: float, hi: float, failures: int, rho_d: float):
    """(worst GDOP, ρ where, failed gyros 1-based) of one layout, continuously over [lo, hi]
    (:func:`worst_over_interval`) and over every kept set."""
    n = H.shape[0]
    best: tuple[float, float, tuple[int, ...]] = (-1.0, lo, ())
    for keep in kept_sets(n, failures):
        Hk = H[list(keep)]
        m = len(keep)
        if np.linalg.matrix_rank(Hk, tol=1e-9) < 3:
            return math.inf, lo, tuple(k + 1 for k in range(n) if k not in keep)
        M = fixed_weights("gls", Hk[None], _corr(m, rho_d))[0]
        v, r = worst_over_interval(lambda x: float(math.sqrt(np.einsum("in,nk,ik->", M, _corr(m, x), M))),
                                   lo, hi)
        if v > best[0]:
            best = (v, r, tuple(k + 1 for k in range(n) if k not in keep))
    return best


def _design_rho_grid(lo: float, hi: float) -> np.ndarray:
    return np.array([lo]) if hi <= lo else np.linspace(lo, hi, DESIGN_RHO_POINTS)


def _choose_design_rho(H: np.ndarray, lo: float, hi: float, failures: int) -> float:
    """The design ρ of the fixed weights, min-max over :data:`DESIGN_RHO_POINTS` grid points."""
    grid = _design_rho_grid(lo, hi)
    vals = [float(np.max(_worst_variances(H[None], lo, hi, failures, float(r))[0])) for r in grid]
    return float(grid[int(np.argmin(vals))])


# -- the result -------------------------------------------------------------------------

@dataclass(frozen=True)
class SphereDesign:
    """One layout designed by :func:`search_layout`, scored against the bound.

    Attributes
    ----------
    family : str
        One of :data:`FAMILIES`; ``detail`` says which cone, polyhedron or rotations.
    n : int
    axes : ndarray (N, 3)
        Mounted unit axes, platform frame [-] (row k: gyro k + 1).
    rho_range : (float, float)
        The ρ range designed for [-].
    failures : int
    design_rho : float
        The ρ the GLS weights are built for (min-max over the range) [-].
    rho_grid : ndarray
        ρ points [-] of ``gdop_at_rho`` / ``floor_at_rho``.
    gdop_at_rho, floor_at_rho : ndarray
        Intact GDOP (fixed weights) and :func:`gdop_floor` at each ρ of the grid [-].
    worst_gdop : float
        Worst GDOP over the ρ range × every set of ``failures`` failed gyros [-].
    worst_rho : float
        ρ of the worst case [-].
    worst_failed : tuple of int
        Failed gyros of the worst case (1-based; empty: intact).
    intact_worst_gdop, intact_worst_rho : float
        The worst case of the intact array over the range [-].
    bound_ratio : float
        The largest ratio of the intact GDOP (fixed weights) to :func:`gdop_floor` over the ρ
        range [-], at ``bound_ratio_rho``: 1 on the bound at every ρ of the range.
    worst_over_floor : float
        intact worst GDOP / :func:`gdop_floor` (N, ρ of that worst case) [-]. With a range from
        ρ = 0 the worst case is at 0, where every tight frame is on the floor: this ratio then
        hides what the common mode costs, which ``bound_ratio`` shows.
    failed_bound_ratio : float
        ``worst_gdop`` / :func:`gdop_floor` (gyros left, ``worst_rho``) [-] (= bound_ratio
        without failures).
    min_angle_deg, min_parity_angle_deg : float
        Smallest angle between two axes (as lines) and between two parity directions [deg]
        (0 where N − 3 < 2: no isolation).
    isolable : bool
        Every single fault attributable (:func:`gyroarray.estimators.fdi.isolability`).
    mdb_factor, mdb_floor : float
        The worst gyro's MDB factor (:func:`mdb_factors`) and :func:`mdb_floor_factor` [-],
        both in units of δ₀·σ/√L; ``mdb_ratio`` their ratio.
    detail : dict
        Family specifics (cone angle and signs, polyhedron and faces, triad rotation vectors
        [rad] and, for triads, ``gain_over_coaligned`` at ``gain_rho``).
    notes : tuple of str
    """

    family: str
    n: int
    axes: np.ndarray
    rho_range: tuple
    failures: int
    design_rho: float
    rho_grid: np.ndarray
    gdop_at_rho: np.ndarray
    floor_at_rho: np.ndarray
    worst_gdop: float
    worst_rho: float
    worst_failed: tuple
    intact_worst_gdop: float
    intact_worst_rho: float
    bound_ratio: float
    bound_ratio_rho: float
    worst_over_floor: float
    failed_bound_ratio: float
    min_angle_deg: float
    min_parity_angle_deg: float
    isolable: bool
    mdb_factor: float
    mdb_floor: float
    mdb_ratio: float
    detail: dict = field(default_factory=dict)
    notes: tuple = ()

    def to_dict(self) -> dict:
        """JSON-ready fields (lists, floats)."""
        return {"family": self.family, "n": self.n, "axes": np.round(self.axes, 12).tolist(),
                "rho_range": list(self.rho_range), "failures": self.failures,
                "design_rho": self.design_rho,
                "gdop_at_rho": {f"{r:g}": float(g) for r, g in zip(self.rho_grid, self.gdop_at_rho)},
                "floor_at_rho": {f"{r:g}": float(g) for r, g in zip(self.rho_grid, self.floor_at_rho)},
                "worst_gdop": self.worst_gdop, "worst_rho": self.worst_rho,
                "worst_failed_gyros": list(self.worst_failed),
                "intact_worst_gdop": self.intact_worst_gdop, "intact_worst_rho": self.intact_worst_rho,
                "floor": gdop_floor(self.n, max(self.intact_worst_rho, 0.0)),
                "bound_ratio": self.bound_ratio, "bound_ratio_rho": self.bound_ratio_rho,
                "worst_over_floor": self.worst_over_floor, "failed_bound_ratio": self.failed_bound_ratio,
                "min_angle_deg": self.min_angle_deg, "min_parity_angle_deg": self.min_parity_angle_deg,
                "isolable": self.isolable, "mdb_factor": self.mdb_factor, "mdb_floor": self.mdb_floor,
                "mdb_ratio": self.mdb_ratio, "detail": _jsonable(self.detail), "notes": list(self.notes)}


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    return v


def _min_angle_deg(H: np.ndarray) -> float:
    c = np.abs(H @ H.T)
    np.fill_diagonal(c, 0.0)
    return float(np.degrees(np.arccos(np.clip(np.max(c), 0.0, 1.0))))


def evaluate_layout(H, *, family: str = "free", rho_range=(0.0, 0.5), failures: int = 0,
                    design_rho: float | None = None, detail: dict | None = None,
                    notes=(), rho_points: int = 6) -> SphereDesign:
    """Score one layout against the bound (every field of :class:`SphereDesign`).

    Parameters
    ----------
    H : array_like (N, 3)
        Mounted axes [-] (normalised here).
    rho_range : (float, float)
        ρ range [-], LO >= 0 (the floor's condition).
    failures : int
    design_rho : float, optional
        ρ of the fixed GLS weights [-]; None: min-max over the range.
    rho_points : int
        Points of the reported ρ grid (the range's ends included; 0.2 added when inside).
    """
    H = np.asarray(H, dtype=float)
    H = H / np.linalg.norm(H, axis=1, keepdims=True)
    n = H.shape[0]
    lo, hi = (float(rho_range[0]), float(rho_range[1]))
    rd = _choose_design_rho(H, lo, hi, failures) if design_rho is None else float(design_rho)
    grid = np.array([lo]) if hi <= lo else np.unique(np.round(np.concatenate(
        [np.linspace(lo, hi, rho_points), [0.2] if lo < 0.2 < hi else []]), 12))
    M = fixed_weights("gls", H[None], _corr(n, rd))[0]
    g_at = np.array([math.sqrt(float(np.einsum("in,nk,ik->", M, _corr(n, r), M))) for r in grid])
    floor = np.array([gdop_floor(n, max(r, 0.0)) for r in grid])
    wg, wr, wf = _robust_worst(H, lo, hi, failures, rd)
    ig, ir, _ = _robust_worst(H, lo, hi, 0, rd)
    over_floor = ig / gdop_floor(n, max(ir, 0.0))
    ratio, ratio_rho = worst_over_interval(
        lambda x: math.sqrt(float(np.einsum("in,nk,ik->", M, _corr(n, x), M))) / gdop_floor(n, max(x, 0.0)),
        lo, hi)
    fratio = wg / gdop_floor(n - len(wf), max(wr, 0.0)) if n - len(wf) >= 3 else math.inf
    iso = isolability(H) if n > 3 else {"isolable": False}
    par = parity_angles_deg(H) if n - 3 >= 2 else None
    if par is not None:
        np.fill_diagonal(par, 90.0)
    mf = float(np.max(mdb_factors(H))) if n > 3 else math.inf
    mfl = mdb_floor_factor(n) if n > 3 else math.inf
    return SphereDesign(family=family, n=n, axes=H, rho_range=(lo, hi), failures=int(failures),
                        design_rho=rd, rho_grid=grid, gdop_at_rho=g_at, floor_at_rho=floor,
                        worst_gdop=float(wg), worst_rho=float(wr), worst_failed=tuple(wf),
                        intact_worst_gdop=float(ig), intact_worst_rho=float(ir), bound_ratio=float(ratio),
                        bound_ratio_rho=float(ratio_rho), worst_over_floor=float(over_floor),
                        failed_bound_ratio=float(fratio), min_angle_deg=_min_angle_deg(H),
                        min_parity_angle_deg=float(np.min(par)) if par is not None else 0.0,
                        isolable=bool(iso["isolable"]), mdb_factor=mf, mdb_floor=mfl,
                        mdb_ratio=mf / mfl if math.isfinite(mfl) else math.inf,
                        detail=dict(detail or {}), notes=tuple(notes))


# -- the constraints --------------------------------------------------------------------

def _iu(n):
    return np.triu_indices(n, 1)


def _constraint_values(H: np.ndarray, cos_min: float, cos_par: float | None) -> np.ndarray:
    """>= 0 where satisfied: cos²(min angle) − (h_i·h_j)², and cos²(min parity)·Q_ii·Q_jj − Q_ij²."""
    n = H.shape[0]
    i, j = _iu(n)
    out = [cos_min ** 2 - (H @ H.T)[i, j] ** 2]
    if cos_par is not None:
        A = H.T @ H
        try:
            Q = np.eye(n) - H @ np.linalg.solve(A, H.T)
        except np.linalg.LinAlgError:
            Q = np.zeros((n, n))
        d = np.diag(Q)
        out.append(cos_par ** 2 * d[i] * d[j] - Q[i, j] ** 2)
    return np.concatenate(out)


def _feasible(H, cos_min, cos_par, tol=1e-7) -> bool:
    return bool(np.all(_constraint_values(H, cos_min, cos_par) >= -tol))


# -- the continuous families (free, triads) ---------------------------------------------

def _free_axes(x: np.ndarray, n: int) -> np.ndarray:
    v = x.reshape(n, 3)
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


def _triad_axes(x: np.ndarray, n: int) -> np.ndarray:
    R = Rotation.from_rotvec(x.reshape(n // 3, 3)).as_matrix()      # (M, 3, 3), columns: the triad
    return np.swapaxes(R, 1, 2).reshape(n, 3)


def _floor2(n: int, lo: float, hi: float, failures: int) -> np.ndarray:
    """GDOP floor² (S, 2) per kept set (its gyro count) at both ρ ends."""
    return np.array([[9.0 * (1.0 - r) / len(k) for r in (lo, hi)] for k in kept_sets(n, failures)])


def _stage(axes_of, x0, terms, caps, cos_min, cos_par, maxiter):
    """Epigraph SLSQP: minimise s subject to s >= every term(x), caps(x) >= 0 and the
    geometric constraints (:func:`_constraint_values`)."""
    def finite(v):
        return np.nan_to_num(np.asarray(v, dtype=float), nan=-1e6, posinf=1e6, neginf=-1e6)

    def cons(z):
        x, t = z[:-1], z[-1]
        H = axes_of(x)
        parts = [t - finite(terms(H)), _constraint_values(H, cos_min, cos_par)]
        if caps is not None:
            parts.append(finite(caps(H)))
        return np.concatenate(parts)
    t0 = float(np.max(finite(terms(axes_of(x0)))))
    res = minimize(lambda z: z[-1], np.append(x0, t0), method="SLSQP",
                   jac=lambda z: np.append(np.zeros(z.size - 1), 1.0),
                   constraints=[{"type": "ineq", "fun": cons}],
                   options={"maxiter": maxiter, "ftol": 1e-14})
    return res.x[:-1]


def _score(v: np.ndarray, fl2: np.ndarray) -> tuple:
    """Lexicographic: the worst GDOP² (to 1e-9), then the intact array's worst ratio to the floor²."""
    w = float(np.max(v))
    return (round(w, 9) if math.isfinite(w) else math.inf, float(np.max(v[:2] / fl2[:2])))


def _flip_signs(v: np.ndarray, score) -> np.ndarray | None:
    """Greedy single sign flips of the rows of ``v`` (N, 3) while ``score`` improves; None: none did."""
    best, cur, changed = score(v), v.copy(), False
    improved = True
    while improved:
        improved = False
        for k in range(v.shape[0]):
            trial = cur.copy()
            trial[k] *= -1.0
            sc = score(trial)
            if sc < best:
                best, cur, changed, improved = sc, trial, True, True
    return cur if changed else None


def _continuous(family, n, lo, hi, failures, cos_min, cos_par, starts, rng, maxiter, spread, seeds=()):
    """Three SLSQP stages: (1) the robust worst GDOP² (the tool's objective), best of
    ``starts`` random starts; (2) the intact array's worst ratio to the floor over the ρ range,
    keeping (1)'s worst case (the ρ range's worst case can sit at an end where any tight frame
    is on the floor; this stage puts the rest of the range on the floor where it can be);
    (3) ``spread``: the largest minimum pairwise angle, keeping (1) and (2)."""
    base = _free_axes if family == "free" else _triad_axes

    def axes_of(x):
        return base(x, n)
    dim = 3 * n if family == "free" else n
    rho_d = 0.5 * (lo + hi)
    fl2 = _floor2(n, lo, hi, failures).ravel()

    def var(H):
        return _worst_variances(H[None], lo, hi, failures, rho_d)[0].ravel()
    best, best_w = None, math.inf
    # the random starts, then any seeds given (free: the best cones, so free is never worse)
    for k in range(starts + len(seeds)):
        x0 = (seeds[k - starts].ravel() if k >= starts else rng.normal(size=dim) if family == "free"
              else Rotation.random(n // 3, random_state=rng).as_rotvec().ravel())
        x = _stage(axes_of, x0, var, None, cos_min, cos_par, maxiter)
        if family == "free":                  # a sign flip is a jump SLSQP cannot make
            flipped = _flip_signs(x.reshape(n, 3), lambda v: _score(var(axes_of(v.ravel())), fl2))
            if flipped is not None:
                x = _stage(axes_of, flipped.ravel(), var, None, cos_min, cos_par, maxiter)
        H = axes_of(x)
        if not _feasible(H, cos_min, cos_par, tol=1e-6):
            continue
        w = float(np.max(var(H)))
        if w < best_w * (1.0 - 1e-10):
            best, best_w = x, w
    if best is None:
        return None
    cap1 = best_w * (1.0 + SPREAD_SLACK)

    def keep(x, caps_ok):
        H = axes_of(x)
        return _feasible(H, cos_min, cos_par) and caps_ok(H)
    def ratio(H):                              # the intact array's ratio to the floor² at both ends
        return var(H)[:2] / fl2[:2]
    x2 = _stage(axes_of, best, ratio, lambda H: cap1 - var(H), cos_min, cos_par, maxiter)
    if keep(x2, lambda H: np.max(var(H)) <= cap1 * (1 + 1e-9)) and \
            np.max(ratio(axes_of(x2))) <= np.max(ratio(axes_of(best))):
        best = x2
    if spread:
        cap2 = float(np.max(ratio(axes_of(best)))) * (1.0 + SPREAD_SLACK)
        i, j = _iu(n)

        def caps(H):
            return np.concatenate([cap1 - var(H), cap2 - ratio(H)])
        x3 = _stage(axes_of, best, lambda H: (H @ H.T)[i, j] ** 2, caps, cos_min, cos_par, maxiter)
        if keep(x3, lambda H: bool(np.all(caps(H) >= -1e-9 * cap1))):
            # polish: back onto the optimum next to the spread point (the slack above lets
            # HᵀH move by ~√slack; this stage ends at SLSQP's own tolerance)
            x4 = _stage(axes_of, x3, ratio, None if failures == 0 else (lambda H: cap1 - var(H)),
                        cos_min, cos_par, maxiter)
            sc3, sc4 = _score(var(axes_of(x3)), fl2), _score(var(axes_of(x4)), fl2)
            best = x4 if (_feasible(axes_of(x4), cos_min, cos_par) and sc4 <= sc3) else x3
    out = {"rotation_vectors_rad": best.reshape(n // 3, 3)} if family == "triads" else {}
    return axes_of(best), out


# -- the discrete families (faces, cones) -----------------------------------------------

def _polyhedra() -> dict:
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    cube = np.eye(3)
    octa = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1]], dtype=float)
    dodeca = np.array([[0, 1, phi], [0, 1, -phi], [1, phi, 0], [1, -phi, 0], [phi, 0, 1], [-phi, 0, 1]])
    ico = np.array([[1, 1, 1], [1, 1, -1], [1, -1, 1], [-1, 1, 1],
                    [0, 1 / phi, phi], [0, 1 / phi, -phi], [1 / phi, phi, 0], [1 / phi, -phi, 0],
                    [phi, 0, 1 / phi], [-phi, 0, 1 / phi]])
    return {name: v / np.linalg.norm(v, axis=1, keepdims=True)
            for name, v in (("cube", cube), ("octahedron", octa), ("dodecahedron", dodeca),
                            ("icosahedron", ico))}


#: Face-normal lines (one per pair of opposite faces) of the machinable polyhedra [-].
POLYHEDRA = _polyhedra()

#: Most (face set × sign) layouts the faces family scores exhaustively; above, a random sample.
FACES_MAX = 20000


def _best_of(H: np.ndarray, lo, hi, failures, cos_min, cos_par):
    """Index of the best feasible layout of a stack (G, N, 3) by the fixed-weight worst case."""
    rho_d = 0.5 * (lo + hi)
    v = _worst_variances(H, lo, hi, failures, rho_d).reshape(H.shape[0], -1)
    w = np.max(v, axis=1)
    r = np.max(v[:, :2] / _floor2(H.shape[1], lo, hi, 0).ravel()[None], axis=1)    # the intact array's
    ok = np.array([_feasible(h, cos_min, cos_par) for h in H]) & np.isfinite(w)
    if not ok.any():
        return None, math.inf
    idx = np.flatnonzero(ok)
    tied = idx[w[idx] <= np.min(w[idx]) * (1.0 + 1e-9)]       # then the worst ratio to the floor
    k = int(tied[np.argmin(r[tied])])
    return k, float(w[k])


def _faces(n, lo, hi, failures, cos_min, cos_par, rng):
    found = None
    for name, lines in POLYHEDRA.items():
        L = lines.shape[0]
        # a gyro per face: two opposite faces give one line twice, which the minimum angle refuses
        if n > L:
            continue
        combos = list(itertools.combinations(range(L), n))
        signs = np.array([(1,) + s for s in itertools.product((1, -1), repeat=n - 1)], dtype=float)
        total = len(combos) * len(signs)
        if total <= FACES_MAX:
            pick = [(c, s) for c in range(len(combos)) for s in range(len(signs))]
        else:
            pick = list(zip(rng.integers(len(combos), size=FACES_MAX), rng.integers(len(signs), size=FACES_MAX)))
        H = np.stack([lines[list(combos[c])] * signs[s][:, None] for c, s in pick])
        k, w = _best_of(H, lo, hi, failures, cos_min, cos_par)
        if k is not None and (found is None or w < found[2] * (1 - 1e-10)):
            c, s = pick[k]
            found = (H[k], {"polyhedron": name, "faces_lines": list(combos[c]),
                            "signs": signs[s].tolist(), "scored": len(pick), "of": total}, w)
    return None if found is None else found[:2]


def _cone(scheme, n, lo, hi, failures, cos_min, cos_par):
    alphas = alpha_grid(scheme, 200)
    rho_d = 0.5 * (lo + hi)
    found = None
    for signs in mounting_patterns(scheme, n):
        H = mounted_axes(scheme, n, alphas, signs)
        k, w = _best_of(H, lo, hi, failures, cos_min, cos_par)
        if k is None:
            continue
        step = alphas[1] - alphas[0]

        def f(a, signs=signs):
            h = mounted_axes(scheme, n, np.array([a]), signs)
            if not _feasible(h[0], cos_min, cos_par):
                return math.inf
            return float(np.max(_worst_variances(h, lo, hi, failures, rho_d)))
        r = minimize_scalar(f, bounds=(max(alphas[k] - step, 1e-6), min(alphas[k] + step, math.pi - 1e-6)),
                            method="bounded", options={"xatol": 1e-9})
        a, wa = (float(r.x), float(r.fun)) if r.fun < w else (float(alphas[k]), w)
        if found is None or wa < found[2] * (1 - 1e-10):
            found = (mounted_axes(scheme, n, np.array([a]), signs)[0],
                     {"scheme": scheme, "alpha_deg": math.degrees(a), "signs": signs.tolist()}, wa)
    return None if found is None else found[:2]


# -- triads: the gain of rotating them -----------------------------------------------------

def coaligned_triads(m: int) -> np.ndarray:
    """M triads mounted alike: (3M, 3), rows x, y, z repeated [-]."""
    return np.tile(np.eye(3), (m, 1))


def triad_gain(H: np.ndarray, rho: float, design_rho: float | None = None) -> dict:
    """What rotating M triads buys over mounting them alike, at correlation ρ.

    Both boards are fused with GLS weights built for ``design_rho`` (default ρ); per axis the
    variance of the fused rate [σ²] (M_a C(ρ) M_aᵀ). Returns the per-axis variances of both,
    their mean, the gain √(var co-aligned / var rotated) of the mean (a ratio of standard
    deviations) and each board's gain over one gyro (1/√var).
    """
    n = H.shape[0]
    rd = rho if design_rho is None else design_rho
    out = {}
    for key, h in (("rotated", H), ("coaligned", coaligned_triads(n // 3))):
        M = fixed_weights("gls", h[None], _corr(n, rd))[0]
        out[key] = np.einsum("in,nk,ik->i", M, _corr(n, rho), M)
    vr, vc = float(np.mean(out["rotated"])), float(np.mean(out["coaligned"]))
    return {"rho": float(rho), "design_rho": float(rd), "var_per_axis_rotated": out["rotated"].tolist(),
            "var_per_axis_coaligned": out["coaligned"].tolist(), "gain_over_coaligned": math.sqrt(vc / vr),
            "gain_over_one_gyro_rotated": 1.0 / math.sqrt(vr),
            "gain_over_one_gyro_coaligned": 1.0 / math.sqrt(vc)}


# -- the search ---------------------------------------------------------------------------

def search_layout(n: int, *, family: str = "free", rho_range=(0.0, 0.5), failures: int = 0,
                  min_angle_deg: float = MIN_ANGLE_DEG, min_parity_angle_deg: float | None = MIN_PARITY_ANGLE_DEG,
                  starts: int = 6, rng: np.random.Generator | None = None, maxiter: int = 300,
                  spread: bool = True, gain_rho: float | None = None) -> SphereDesign | None:
    """Design the N mounted axes of one family for the robust worst case, scored against the bound.

    Parameters
    ----------
    n : int
        Number of gyros N (4 to 32; ``triads``: a multiple of 3).
    family : str
        One of :data:`FAMILIES`.
    rho_range : (float, float)
        Range of the common-mode correlation ρ [-], 0 <= LO <= HI < 1.
    failures : int
        Failed gyros every kept set must survive (a 3-axis rate; the worst case covers them).
    min_angle_deg : float
        Smallest angle between two axes, as lines [deg].
    min_parity_angle_deg : float or None
        Smallest angle between two gyros' parity directions [deg] (isolability); applied where
        N − 3 >= 2; None: not constrained.
    starts : int
        Random starts of the continuous families (``free`` also starts from the best cone of
        each scheme, so it is never worse than the cones).
    rng : numpy.random.Generator
        The source of the random starts (required for ``free``, ``triads`` and a sampled
        ``faces`` search).
    maxiter : int
        SLSQP iterations per start.
    spread : bool
        ``free``/``triads``: the second stage (largest minimum pairwise angle at the optimum).
    gain_rho : float, optional
        ``triads``: the ρ of the gain over co-aligned triads [-] (default HI).

    Returns
    -------
    SphereDesign or None
        None where no layout of the family meets the constraints.
    """
    if family not in FAMILIES:
        raise InputError(f"family must be one of {', '.join(FAMILIES)}, got {family!r}")
    lo, hi = float(rho_range[0]), float(rho_range[1])
    if not 0.0 <= lo <= hi < 1.0:
        raise InputError(f"rho range must be 0 <= LO <= HI < 1, got [{lo:g}, {hi:g}]")
    if not 4 <= n <= 32:
        raise InputError(f"N must be from 4 to 32, got {n}")
    if family == "triads" and n % 3:
        raise InputError(f"family triads: N must be a multiple of 3 (M triads), got {n}")
    if n - failures < 3:
        raise InputError(f"N − failures must be >= 3, got {n} − {failures}")
    if family in ("free", "triads") and rng is None:
        raise InputError(f"family {family}: give rng, a numpy.random.Generator (the random starts)")
    cos_min = math.cos(math.radians(min_angle_deg))
    cos_par = (math.cos(math.radians(min_parity_angle_deg))
               if min_parity_angle_deg is not None and n - 3 >= 2 else None)
    notes = []
    if min_parity_angle_deg is not None and n - 3 < 2:
        notes.append(f"N = {n}: a {n - 3}-dimensional parity space detects a fault but cannot isolate it; "
                     "the parity angle is not constrained")
    if family in ("free", "triads"):
        seeds = []
        if family == "free":
            for sch in (1, 2):
                c = _cone(sch, n, lo, hi, failures, cos_min, cos_par)
                if c is not None:
                    seeds.append(np.asarray(c[0], dtype=float))
        got = _continuous(family, n, lo, hi, failures, cos_min, cos_par, starts,
                          rng, maxiter, spread, seeds=tuple(seeds))
    elif family == "faces":
        got = _faces(n, lo, hi, failures, cos_min, cos_par, rng if rng is not None else np.random.default_rng(0))
    else:
        got = _cone(1 if family == "cone1" else 2, n, lo, hi, failures, cos_min, cos_par)
    if got is None:
        return None
    H, detail = got
    if family == "triads":
        detail["gain"] = triad_gain(H, hi if gain_rho is None else float(gain_rho))
    d = evaluate_layout(H, family=family, rho_range=(lo, hi), failures=failures, detail=detail, notes=notes)
    if d.bound_ratio > 1.0 + 1e-6:
        d = _with_note(d, f"{family}, N = {n}: {100.0 * (d.bound_ratio - 1.0):.2f} % above the GDOP floor "
                          f"3·√((1 − ρ)/N) = {gdop_floor(n, d.bound_ratio_rho):.4f} at ρ = {d.bound_ratio_rho:.3g}")
    return d


def _with_note(d: SphereDesign, note: str) -> SphereDesign:
    return replace(d, notes=d.notes + (note,))
