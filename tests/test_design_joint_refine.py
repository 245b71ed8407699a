"""Issue 43 item 4 (second bullet): the design ρ and the cone angle refined jointly.

* the joint min-max (:func:`gyroarray.design.screening.refine_joint`) is never worse than
  the grid's best, and finds the demo's Scheme 1, N = 6 optimum the old α-then-ρ_d pass
  missed (alternating senses, about 33.72° against 34.50°);
* outside check: for N <= 6 a numpy brute force over every sign pattern × a dense cone-angle
  grid × a dense design-ρ grid finds nothing better than the recommendation or the runner-up
  by more than one brute-force grid step's effect. Its objective is an independent closed form
  (fixed-weight GLS on equicorrelated gyros), itself verified against the tool's worst-case
  function on a few points.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from gyroarray.core import units
from gyroarray.design.decision import decide
from gyroarray.design.gyro_noise import GyroNoise
from gyroarray.design.predict import Swing
from gyroarray.design.screening import (Candidate, Decider, _objective_over_alpha, grid_best,
                                        refine_candidate)
from gyroarray.design.search_space import DesignSpace, sized_for

LO, HI = -0.1, 0.5


# ---------------------------------------------------------------- the independent objective
def cone_axes(scheme: int, n: int, alpha_rad: np.ndarray) -> np.ndarray:
    """Unit axes (A, N, 3) of a cone written from scratch: Scheme 1 all N on the cone, Scheme 2
    gyro 1 on +z and N − 1 on the cone, azimuths evenly spaced from 0 (a rotation about z of the
    tool's convention, which the objective below does not see)."""
    m = n if scheme == 1 else n - 1
    az = 2.0 * np.pi * np.arange(m) / m
    a = np.asarray(alpha_rad, dtype=float)[:, None]
    cone = np.stack([np.sin(a) * np.cos(az), np.sin(a) * np.sin(az), np.cos(a) * np.ones_like(az)], axis=-1)
    if scheme == 1:
        return cone
    axial = np.broadcast_to(np.array([0.0, 0.0, 1.0]), (a.shape[0], 1, 3))
    return np.concatenate([axial, cone], axis=1)


def worst_trace(H: np.ndarray, rho_d: np.ndarray, failures: int) -> np.ndarray:
    """max over ρ_t ∈ {LO, HI} × every kept set of tr(M C(ρ_t) Mᵀ), M the GLS weights for the
    equicorrelation C(ρ_d) on the kept gyros; H (A, N, 3) as mounted (signs applied), output
    (A, R) for the R design ρ. Closed form: with C = (1 − ρ)I + ρ11ᵀ, C⁻¹ = (I − c11ᵀ)/(1 − ρ),
    c = ρ/(1 + (n − 1)ρ), so every matrix product reduces to A = HᵀH and b = Hᵀ1:
    P = HᵀC_d⁻¹H = (A − c bbᵀ)/(1 − ρ_d), HᵀC_d⁻¹C_tC_d⁻¹H = x A + y bbᵀ, M C_t Mᵀ =
    P⁻¹(x A + y bbᵀ)P⁻¹."""
    n = H.shape[1]
    keeps = [tuple(range(n))] + list(itertools.combinations(range(n), n - failures))
    rd = np.asarray(rho_d, dtype=float)[None, :, None, None]
    out = np.full((H.shape[0], np.size(rho_d)), -np.inf)
    for keep in keeps:
        Hk = H[:, list(keep)]
        k = len(keep)
        A = np.einsum("ani,anj->aij", Hk, Hk)[:, None]
        b = Hk.sum(axis=1)[:, None]
        bb = b[..., :, None] * b[..., None, :]
        c = rd / (1.0 + (k - 1) * rd)
        P = (A - c * bb) / (1.0 - rd)
        Pi = np.linalg.inv(P)
        for rt in (LO, HI):
            # C_d⁻¹ C_t C_d⁻¹ = (I − c11ᵀ)((1 − ρ_t)I + ρ_t 11ᵀ)(I − c11ᵀ)/(1 − ρ_d)²
            #                 = x I + y 11ᵀ (11ᵀ11ᵀ = k 11ᵀ)
            u = (1.0 - c * k)                           # (I − c11ᵀ)1 = u 1
            x = (1.0 - rt) / (1.0 - rd) ** 2
            y = ((1.0 - rt) * (-2.0 * c + c * c * k) + rt * u * u) / (1.0 - rd) ** 2
            Q = x * A + y * bb
            tr = np.einsum("arij,arjk,arki->ar", Pi, Q, Pi)
            out = np.maximum(out, tr)
    return out


def direct_worst_trace(H: np.ndarray, rho_d: float, failures: int) -> float:
    """The same worst trace by plain matrix algebra (no closed form), one layout (N, 3)."""
    n = H.shape[0]
    keeps = [tuple(range(n))] + list(itertools.combinations(range(n), n - failures))
    worst = -np.inf
    for keep in keeps:
        Hk = H[list(keep)]
        k = len(keep)
        Cd = (1 - rho_d) * np.eye(k) + rho_d * np.ones((k, k))
        M = np.linalg.solve(Hk.T @ np.linalg.solve(Cd, Hk), Hk.T @ np.linalg.inv(Cd))
        for rt in (LO, HI):
            Ct = (1 - rt) * np.eye(k) + rt * np.ones((k, k))
            worst = max(worst, float(np.trace(M @ Ct @ M.T)))
    return worst


def all_patterns(scheme: int, n: int) -> list[np.ndarray]:
    """Every sign pattern: Scheme 1 up to the global sign, Scheme 2 with the axial gyro +."""
    # Scheme 1: slot 1 + (a global sign negates M, not tr(M C Mᵀ)); Scheme 2: the axial slot +
    # (reversed, it is the cone at 180° − α rotated, on the α grid): both fix the first sign
    return [np.array((1,) + c, float) for c in itertools.product((1, -1), repeat=n - 1)]


# ---------------------------------------------------------------- the small design
#: ARW and RRW alike and equicorrelated with one ρ, no swing, gls only: every error variance of
#: the fixed-weight GLS is the common filter-and-window factor × tr(M C(ρ_t) Mᵀ), so the tool's
#: rate objective is proportional to :func:`worst_trace` (checked below, ratio constant to 1e-9).
G = GyroNoise(arw_deg_rt_h=0.1, rrw_deg_h_rt_h=600.0)
SPACE = DesignSpace(rate_hz=50.0, horizon_s=20.0, ns=(4, 5, 6), schemes=(1, 2), estimators=("gls",),
                    failures=1, bandwidth_hz=(8.0, 8.0), objective="rate")


@pytest.fixture(scope="module")
def decided():
    g, space = sized_for(G, SPACE)
    designs, _ = decide(g, space, LO, HI, details=False)
    return g, space, designs


def test_objective_matches_tool():
    """The closed form against plain matrix algebra (1e-10, rounding) and against the tool's
    worst-case function (:func:`_objective_over_alpha`): the ratio tool / closed form is one
    constant over patterns, N, schemes, α and ρ_d (relative spread < 1e-9: both are exact, the
    constant is the filter's and window's noise factor)."""
    g, space = sized_for(G, SPACE)
    dec = Decider(g, space, LO, HI, "rate")
    ratios = []
    for scheme, n, signs, alpha_deg, rd in [(1, 5, (1, -1, 1, 1, -1), 50.0, 0.1), (1, 6, (1, -1) * 3, 54.7, -0.08),
                                            (2, 6, (1, 1, 1, 1, -1, -1), 116.0, 0.3),
                                            (2, 4, (1, 1, 1, -1), 70.0, 0.45), (1, 4, (1,) * 4, 30.0, 0.0)]:
        s = np.array(signs, float)
        H = cone_axes(scheme, n, np.radians([alpha_deg])) * s[None, :, None]
        closed = float(worst_trace(H, np.array([rd]), 1)[0, 0])
        assert closed == pytest.approx(direct_worst_trace(H[0], rd, 1), rel=1e-10)
        c = Candidate(scheme, n, "gls", s, math.radians(alpha_deg), 8.0, rd, math.inf)
        tool = float(_objective_over_alpha(dec, c, np.radians([alpha_deg]), rd, 8.0)[0])
        ratios.append(tool / closed)
    assert np.ptp(ratios) / np.mean(ratios) < 1e-9, ratios


def _brute(scheme: int, n: int, coarse=(1.0, 0.02), fine=(0.05, 0.001), keep_cells: int = 3):
    """Brute force of :func:`worst_trace` over every sign pattern: a coarse grid of α [deg] × ρ_d
    over the whole of both, then, around each pattern's ``keep_cells`` best coarse points, a fine
    grid one coarse step either side. Returns the minimum and the largest relative change of the
    objective one fine step from the minimiser (α ± step, ρ_d ± step): the brute force's own
    resolution."""
    hi = 90.0 if scheme == 1 else 180.0
    ca, cr = coarse
    fa, fr = fine
    al = np.radians(np.arange(ca, hi - 1e-9, ca))
    rds = np.arange(LO, HI + 1e-12, cr)
    best = (math.inf, None)
    for s in all_patterns(scheme, n):
        J = worst_trace(cone_axes(scheme, n, al) * s[None, :, None], rds, 1)
        J = np.where(np.isfinite(J), J, np.inf)
        for flat in np.argsort(J, axis=None)[:keep_cells]:
            i, k = np.unravel_index(int(flat), J.shape)
            a0, r0 = math.degrees(al[i]), rds[k]
            fa_grid = np.radians(np.clip(np.arange(a0 - ca, a0 + ca + 1e-9, fa), fa, hi - fa))
            fr_grid = np.clip(np.arange(r0 - cr, r0 + cr + 1e-12, fr), LO, HI)
            Jf = worst_trace(cone_axes(scheme, n, fa_grid) * s[None, :, None], fr_grid, 1)
            Jf = np.where(np.isfinite(Jf), Jf, np.inf)
            ii, kk = np.unravel_index(int(np.argmin(Jf)), Jf.shape)
            if Jf[ii, kk] < best[0]:
                best = (float(Jf[ii, kk]), (s, fa_grid[ii], fr_grid[kk]))
    j0, (s, a, r) = best
    step = 0.0
    for da, dr in ((fa, 0.0), (-fa, 0.0), (0.0, fr), (0.0, -fr)):
        rr = min(max(r + dr, LO), HI)
        v = float(worst_trace(cone_axes(scheme, n, np.radians([math.degrees(a) + da])) * s[None, :, None],
                              np.array([rr]), 1)[0, 0])
        step = max(step, abs(v - j0) / j0)
    return j0, step


@pytest.mark.slow
def test_brute_force_finds_nothing_better(decided):
    """The recommendation and the runner-up against the brute force of their (scheme, N), and the
    recommendation against the best of every (scheme, N). The tool's design is evaluated by the
    closed form from its own fields (``axes`` as mounted, ``design_rho``), so the comparison does
    not depend on the tool's objective. The brute force: every pattern on a 1° × 0.02 grid, then
    a 0.05° × 0.001 grid one coarse step about each pattern's 3 best coarse points. Tolerance:
    the objective's largest relative change one fine step from the brute-force optimum (here
    below 0.4 %): the brute force resolves the optimum no finer than that, so a tool design
    within it is not beaten. It is asserted < 1 %, below the misses issue 43 found (1.3–2.3 %),
    so the check can fail."""
    _, _, designs = decided
    rec = designs[0]
    ru = next(d for d in designs[1:] if (d["scheme"], d["n"]) != (rec["scheme"], rec["n"]))

    def tool_value(d):
        return float(worst_trace(np.asarray(d["axes"], float)[None], np.array([d["design_rho"]]), 1)[0, 0])
    brute = {(s, n): _brute(s, n) for s in (1, 2) for n in (4, 5, 6)}
    for d in (rec, ru):
        j0, tol = brute[(d["scheme"], d["n"])]
        assert tol < 0.01
        assert tool_value(d) <= j0 * (1.0 + tol), (d["scheme"], d["n"], tool_value(d), j0, tol)
    # and every (scheme, N) the tool ranked (one gls design each): the joint search's polish is
    # what the others rest on (before it, Scheme 2, N = 5 was 0.27 % above its brute force)
    assert len(designs) == len(brute)
    for d in designs:
        j0, tol = brute[(d["scheme"], d["n"])]
        assert tool_value(d) <= j0 * (1.0 + tol), (d["scheme"], d["n"], tool_value(d), j0, tol)
    j_all = min(v[0] for v in brute.values())
    tol_all = max(v[1] for v in brute.values())
    assert tool_value(rec) <= j_all * (1.0 + tol_all)


# ---------------------------------------------------------------- never worse than the grid
DEMO_G = GyroNoise(arw_deg_rt_h=0.1, rrw_deg_h_rt_h=600.0)
DEMO_SPACE = DesignSpace(rate_hz=100.0, horizon_s=600.0, ns=(6,), schemes=(1, 2), estimators=("gls",),
                         failures=1, swing=Swing(amplitude_rad_s=units.deg_s_to_rad_s(5.0), frequency_hz=0.03),
                         objective="angle")


@pytest.mark.slow
def test_joint_refinement_never_worse_than_grid():
    """Refined J <= grid J for every (scheme, N, estimator) tried (exactly: a step is kept only
    where lower), and on the demo's Scheme 1, N = 6 the joint search finds the alternating
    pattern's optimum: about 33.72° (issue 43's brute force; the old pass gave 34.50°), i.e.
    more than 2 % below the grid's best, where the grid's 3 design ρ miss it."""
    g, space = sized_for(DEMO_G, DEMO_SPACE)
    dec = Decider(g, space, LO, HI, "angle")
    for scheme in (1, 2):
        grid, alphas = grid_best(dec, scheme, 6, "gls")
        assert grid is not None
        ref = refine_candidate(dec, grid, alphas, bandwidth=False)
        assert ref.J <= grid.J
        if scheme == 1:
            deg = units.rad_to_deg(math.sqrt(ref.J))
            assert units.rad_to_deg(math.sqrt(grid.J)) > 34.5
            assert deg == pytest.approx(33.72, abs=0.02)           # the 33.72, 2 decimals
            assert list(ref.signs) == [1, -1, 1, -1, 1, -1]
