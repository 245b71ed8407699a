"""The design decision under what the user does not know (issue 30): ρ range, failures,
mounting sense, fixed-weight estimators, the objective.

Each check sets the tool's answer against a computation written out here: the conical
axes (paper 003 §2.2) with the mounting signs, GLS weights built once for the design ρ,
the first-order low-pass in closed form, a fine ρ grid and every set of failed gyros.
"""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from hostile import assert_contract, run_cli

from gyroarray.design.recommend import DesignSpace, GyroNoise, recommend
from gyroarray.design.robust import mounted_axes, mounting_patterns, mounting_words

RHO = (-0.1, 0.5)


def _corr(n: int, rho: float) -> np.ndarray:
    return (1.0 - rho) * np.eye(n) + rho * np.ones((n, n))


def _cone(scheme: int, n: int, alpha: float, signs) -> np.ndarray:
    rows = [] if scheme == 1 else [[0.0, 0.0, 1.0]]
    m = n if scheme == 1 else n - 1
    for k in range(m):
        b = 2 * math.pi * k / m
        rows.append([math.sin(alpha) * math.cos(b), math.sin(alpha) * math.sin(b), math.cos(alpha)])
    return np.array(rows) * np.asarray(signs, float)[:, None]


def _lowpass_coefficients(f_hz: float, dt: float, n: int, k0: int) -> tuple[float, float]:
    """Window mean of E[y_k²] per unit white variance and per unit walk increment variance for
    y_k = a y_{k-1} + (1 − a) x_k started on y_{-1} = x_0 (−3 dB at f), the walk b_k = Σ_{i<=k} ε_i:
    y_k = a^k x_0 + (1 − a) Σ_{j=1..k} a^{k−j} x_j, so Σ h² = a^{2k} + (1 − a)²(1 − a^{2k})/(1 − a²)
    and the walk's weights are 1 (i = 0) and 1 − a^{k−i+1} (i >= 1)."""
    c = 2.0 - math.cos(2.0 * math.pi * f_hz * dt)
    a = c - math.sqrt(c * c - 1.0)
    k = np.arange(n, dtype=float)
    a2k = a ** (2 * k)
    white = a2k + (1 - a) ** 2 * (1 - a2k) / (1 - a * a)
    walk = 1 + k - 2 * a * (1 - a ** k) / (1 - a) + a * a * (1 - a2k) / (1 - a * a)
    return float(np.mean(white[k0:])), float(np.mean(walk[k0:]))


def _fixed_gls_worst(axes, rho_d, arw, rrw, f_hz, dt, n, k0, failures, grid) -> float:
    """3-axis RMS rate error [deg/s], worst over the ρ grid × every set of failed gyros, with
    GLS weights built for ρ_d on the gyros left, low-pass at f_hz, white + walk."""
    H = np.asarray(axes, float)
    N = H.shape[0]
    s2 = (math.radians(arw) / 60.0) ** 2 / dt                # white variance per sample [rad²/s²]
    q = (math.radians(rrw) / 3600.0 / 60.0) ** 2 * dt        # walk increment variance [rad²/s²]
    cw, cq = _lowpass_coefficients(f_hz, dt, n, k0)
    worst = 0.0
    sets = [tuple(range(N))] + list(itertools.combinations(range(N), N - failures)) * (failures > 0)
    for keep in sets:
        h = H[list(keep)]
        ci = np.linalg.inv(_corr(len(keep), rho_d))
        W = np.linalg.inv(h.T @ ci @ h) @ h.T @ ci             # built once, for ρ_d
        for r in grid:
            cov = W @ _corr(len(keep), r) @ W.T
            ms = float(np.trace(cov)) * (s2 * cw + q * cq)
            worst = max(worst, ms)
    return math.degrees(math.sqrt(worst))


def _json(argv) -> dict:
    o = run_cli(argv, timeout=300)
    assert_contract(o)
    assert o.code == 0, o.err
    return json.loads(o.out)


def test_worst_case_is_the_fixed_weight_gls_over_rho_and_failures():
    # at rest: every GLS design low-passed at the default 10 Hz, 100 Hz, 30 s, 2 s settle
    res = _json(["design", "--recommend", "--arw", "0.1", "--rrw", "50", "--n", "4,6",
                 "--horizon-s", "30", "--failures", "1", "--rho-range=-0.1,0.5",
                 "--estimators", "gls", "--objective", "rate", "--json"])
    dt, n, k0 = 0.01, 3000, 200
    grid = np.linspace(RHO[0], RHO[1], 1201)
    worst = []
    for d in res["designs"] + [res["recommended"]]:
        assert d["objective"] == "rate" and d["estimator"] == "gls"
        assert len(d["axes"]) == d["n"] and np.allclose(np.linalg.norm(d["axes"], axis=1), 1.0)
        mine = _fixed_gls_worst(d["axes"], d["design_rho"], 0.1, 50.0, 10.0, dt, n, k0, 1, grid)
        assert d["worst_case"]["rms_3axis_deg_s"] == pytest.approx(mine, rel=1e-6), d["mounting"]
        assert min(abs(d["worst_case"]["rho"] - r) for r in RHO) < 1e-6   # linear in ρ: an end
        assert len(d["worst_case"]["failed_gyros"]) in (0, 1)
        typ = _fixed_gls_worst(d["axes"], d["design_rho"], 0.1, 50.0, 10.0, dt, n, k0, 0,
                               [d["design_rho"]])
        assert d["typical"]["rms_3axis_deg_s"] == pytest.approx(typ, rel=1e-6)
        assert d["mdb_deg_s"] is None or d["mdb_deg_s"] > 0
        worst.append(mine)
    # the recommendation has the smallest worst case of all designs
    assert res["recommended"]["worst_case"]["rms_3axis_deg_s"] <= min(worst) * (1 + 1e-9)
    assert "worst case" in res["decision"] and res["objective"] == "rate"


def test_the_demo_winner_no_longer_wins_when_its_worst_case_is_worse():
    # the demo's gyros and question at rest, GLS only: the old answer was scheme 2, N = 8,
    # alpha = 119.21 deg, every gyro +; at rho = 0.5 losing its axial gyro costs GDOP 1.666
    g = GyroNoise(arw_deg_rt_h=0.1, rrw_deg_h_rt_h=600.0)
    space = DesignSpace(rate_hz=100.0, horizon_s=60.0, ns=(8,), estimators=("gls",), failures=1,
                        objective="rate")
    res = recommend(g, space, rhos=RHO)
    old = _cone(2, 8, math.radians(119.21), np.ones(8))
    h = np.delete(old, 0, axis=0)
    gd = math.sqrt(np.trace(np.linalg.inv(h.T @ np.linalg.inv(_corr(7, 0.5)) @ h)))
    assert round(gd, 3) == 1.666                                       # the number
    dt, n = 0.01, 6000
    grid = np.array(RHO)
    old_best = min(_fixed_gls_worst(old, rd, 0.1, 600.0, 10.0, dt, n, 200, 1, grid)
                   for rd in np.linspace(RHO[0], RHO[1], 61))
    rec = res["recommended"]
    assert rec["worst_case"]["rms_3axis_deg_s"] < old_best
    assert not (rec["scheme"] == 2 and abs(rec["alpha_deg"] - 119.21) < 0.5
                and all(s > 0 for s in rec["mounting_signs"]))
    # and its own worst case is the written-out computation
    mine = _fixed_gls_worst(rec["axes"], rec["design_rho"], 0.1, 600.0, 10.0, dt, n, 200, 1,
                            np.linspace(RHO[0], RHO[1], 601))
    assert rec["worst_case"]["rms_3axis_deg_s"] == pytest.approx(mine, rel=1e-6)


def test_scheme1_with_one_gyro_reversed_is_tried_and_named():
    # the issue: Scheme 1, N = 8 with one gyro reversed reaches a min-max GDOP of 1.081
    # over rho in [-0.1, 0.5], against 1.250 with every gyro +
    def minmax(signs):
        best = math.inf
        for a in np.radians(np.arange(30.0, 70.0, 0.05)):
            H = _cone(1, 8, a, signs)
            w = max(math.sqrt(np.trace(np.linalg.inv(H.T @ np.linalg.inv(_corr(8, r)) @ H)))
                    for r in np.linspace(-0.1, 0.5, 61))
            best = min(best, w)
        return best
    one = [1] * 7 + [-1]
    assert round(minmax(one), 3) == 1.081 and round(minmax([1] * 8), 2) == 1.25
    pats = [tuple(int(v) for v in p) for p in mounting_patterns(1, 8)]
    assert sum(v < 0 for v in pats[1]) == 1 and pats[0] == (1,) * 8
    # every pattern for N <= 6 up to a rotation and a global sign: N = 4 has 4 classes
    assert len(mounting_patterns(1, 4)) == 4
    # the words say which gyro points where
    assert "gyro 1 on −z" in mounting_words(2, 8, np.array([-1.0] + [1.0] * 7), 60.79)
    assert "gyro 8 mounted reversed" in mounting_words(1, 8, np.array(one, float), 52.74)
    H = mounted_axes(1, 8, np.radians([52.74]), np.array(one, float))[0]
    assert np.allclose(H, _cone(1, 8, math.radians(52.74), one))


def test_objective_angle_ranks_by_the_angle_at_the_horizon():
    res = _json(["design", "--recommend", "--arw", "0.15", "--bi", "3", "--rrw", "1",
                 "--horizon-s", "3600", "--rate-hz", "10", "--n", "4,6", "--estimators", "gls,ols",
                 "--objective", "angle", "--json"])
    assert res["objective"] == "angle" and res["recommended"]["objective"] == "angle"
    ang = [d["worst_case"]["angle_deg"] for d in res["designs"]]
    # ranked by the worst angle (ties within 1 % ordered by the typical case)
    for a, b in zip(ang, ang[1:]):
        assert b >= a * (1 - 0.0101)
    assert res["recommended"]["worst_case"]["angle_deg"] == pytest.approx(min(ang), rel=0.0101)
    # bias instability makes most of the hour's angle error (the issue: 0.96 of 1.02 deg)
    eb = res["recommended"]["error_budget"]
    terms = {k: v["angle_deg"] for k, v in eb["terms"].items()}
    assert max(terms, key=terms.get) in ("bias_instability", "flicker")


def test_design_rho_outside_the_range_is_one_line():
    o = run_cli(["design", "--recommend", "--arw", "0.1", "--rho-range=0,0.5", "--design-rho", "0.7"])
    assert_contract(o, "--design-rho")
    assert o.code == 2


@pytest.mark.slow   # every design gets its rho-gridded MDB under --mdb-max (18 s): make score
def test_mdb_max_excludes_the_designs_above_it_and_says_so():
    base = ["design", "--recommend", "--arw", "0.1", "--rrw", "60", "--n", "5,6", "--horizon-s", "20",
            "--rho-range=-0.1,0.5", "--estimators", "gls", "--failures", "1", "--objective", "rate",
            "--json"]
    free = _json(base)
    mdbs = sorted(d["mdb_deg_s"] for d in free["designs"])
    assert free["recommended"]["far_per_h"] == 0.01 and free["recommended"]["p_md"] == 0.001
    limit = 0.5 * (mdbs[0] + mdbs[-1])
    assert mdbs[0] < limit < mdbs[-1]
    res = _json(base + ["--mdb-max", f"{limit!r}"])
    ok = [d for d in res["designs"] if "excluded" not in d]
    out = [d for d in res["designs"] if "excluded" in d]
    assert out and all(d["mdb_deg_s"] > limit and "--mdb-max" in d["excluded"] for d in out)
    assert all(d["mdb_deg_s"] <= limit for d in ok)
    assert res["designs"].index(ok[-1]) < res["designs"].index(out[0])     # excluded go last
    assert res["recommended"]["mdb_deg_s"] <= limit
    w = [d["worst_case"]["rms_3axis_deg_s"] for d in ok]
    assert res["recommended"]["worst_case"]["rms_3axis_deg_s"] <= min(w) * (1 + 0.0101)
