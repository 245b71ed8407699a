"""Layouts designed at the bound (issue 46): gyroarray.design.sphere against numpy from outside.

Every outside number is computed here in numpy from the axes the search returns (GLS
covariance (HᵀC⁻¹H)⁻¹, the parity basis from an SVD, Baarda's leverage), never read back
from the module. Tolerances: the SLSQP stages stop at ftol 1e-14 on GDOP², so the layout sits
within ~1e-7 of the optimum (the tests ask 1e-6); GDOP within 0.1 % of the floor (the issue's).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gyroarray.design.sphere import gdop_floor, mdb_floor_factor, search_layout, triad_gain


def corr(n, rho):
    return (1.0 - rho) * np.eye(n) + rho * np.ones((n, n))


def gls_gdop(H, rho):
    """Oracle GLS GDOP, sqrt(trace((HᵀC⁻¹H)⁻¹)), numpy."""
    C = corr(H.shape[0], rho)
    return math.sqrt(np.trace(np.linalg.inv(H.T @ np.linalg.solve(C, H))))


def test_floor_and_mdb_factor_against_numpy():
    # the floor is reached by a sum-zero tight frame: the outward tetrahedron
    tet = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float) / math.sqrt(3)
    for rho in (0.0, 0.2, 0.5):
        assert gdop_floor(4, rho) == pytest.approx(gls_gdop(tet, rho), rel=1e-12)
    # the MDB factors 2.00, 1.58, 1.41, 1.26 (N = 4, 5, 6, 8), 1.11 at N = 16
    for n, v in ((4, 2.00), (5, 1.58), (6, 1.41), (8, 1.26), (16, 1.11)):
        assert round(mdb_floor_factor(n), 2) == v
    # Baarda's factor of the tetrahedron's gyros, from its leverage in numpy
    lev = np.diag(tet @ np.linalg.inv(tet.T @ tet) @ tet.T)
    assert mdb_floor_factor(4) == pytest.approx(1.0 / math.sqrt(1.0 - lev.max()), rel=1e-12)


def _check_on_bound(n, d):
    H = d.axes
    np.testing.assert_allclose(H.T @ H, n / 3.0 * np.eye(3), atol=1e-6)
    np.testing.assert_allclose(H.sum(axis=0), 0.0, atol=1e-6)
    for rho in (0.0, 0.2, 0.5):
        g = gls_gdop(H, rho)
        assert g == pytest.approx(3.0 * math.sqrt((1.0 - rho) / n), rel=1e-3)
    assert d.bound_ratio == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("n", [4, 6, 8])
def test_free_optimum_on_the_floor(n):
    d = search_layout(n, family="free", rho_range=(0.0, 0.5), rng=np.random.default_rng(5), starts=2)
    _check_on_bound(n, d)


@pytest.mark.slow
def test_free_optimum_on_the_floor_n12():
    d = search_layout(12, family="free", rho_range=(0.0, 0.5), rng=np.random.default_rng(5), starts=2)
    _check_on_bound(12, d)


def test_tetrahedron_recovered():
    d = search_layout(4, family="free", rho_range=(0.0, 0.5), rng=np.random.default_rng(11), starts=2)
    c = np.abs(d.axes @ d.axes.T)[np.triu_indices(4, 1)]
    np.testing.assert_allclose(c, 1.0 / 3.0, atol=1e-6)


def test_icosahedron_axes_recovered():
    # at rho = 0 every tight frame of 6 is optimal; the spreading stage picks the best line
    # packing of 6 lines, the icosahedron's axes (equiangular, |cos| = 1/sqrt(5))
    d = search_layout(6, family="free", rho_range=(0.0, 0.0), rng=np.random.default_rng(2), starts=2)
    c = np.abs(d.axes @ d.axes.T)[np.triu_indices(6, 1)]
    np.testing.assert_allclose(c, 1.0 / math.sqrt(5.0), atol=1e-5)


def test_n5_cone_recovered():
    # the issue: at N = 5 the free optimum at rho = 0.5 is the cone, GDOP 0.9542 (scheme 2:
    # gyro 1 on the axis, 4 on a cone; it cannot isolate, so isolability is not asked here).
    d = search_layout(5, family="free", rho_range=(0.5, 0.5), rng=np.random.default_rng(3), starts=4,
                      min_parity_angle_deg=None)
    H = d.axes
    # numpy: the best scheme-2 cone over a fine angle grid, GLS at rho = 0.5
    best = math.inf
    for a in np.radians(np.linspace(90.0, 150.0, 6001)):
        b = 2 * np.pi * np.arange(4) / 4
        Hc = np.vstack([[0, 0, 1], np.stack([np.sin(a) * np.cos(b), np.sin(a) * np.sin(b),
                                             np.full(4, np.cos(a))], 1)])
        best = min(best, gls_gdop(Hc, 0.5))
    assert round(best, 4) == 0.9542
    assert gls_gdop(H, 0.5) == pytest.approx(best, rel=2e-5)         # grid step 0.01 deg
    # a cone: one gyro makes the same angle with all four others, and those four lie on a cone
    # about it (equal |cos| to it) with a square's azimuths (opposite pairs share a cos)
    G = H @ H.T
    k = int(np.argmin([np.ptp(np.delete(G[i], i)) for i in range(5)]))
    assert np.ptp(np.delete(G[k], k)) < 1e-4


def _parity_numpy(H):
    u, _, _ = np.linalg.svd(H, full_matrices=True)
    V = u[:, 3:]                                   # columns span the null space of Hᵀ
    unit = V / np.linalg.norm(V, axis=1, keepdims=True)
    c = np.abs(unit @ unit.T)
    np.fill_diagonal(c, 0.0)
    return float(np.degrees(np.arccos(c.max())))


@pytest.mark.parametrize("n", [6, 8])
def test_parity_angle_and_mdb_against_numpy(n):
    d = search_layout(n, family="free", rho_range=(0.0, 0.5), rng=np.random.default_rng(7), starts=2)
    assert d.min_parity_angle_deg == pytest.approx(_parity_numpy(d.axes), abs=1e-6)
    assert d.min_parity_angle_deg >= 10.0 - 1e-6 and d.isolable
    lev = np.diag(d.axes @ np.linalg.inv(d.axes.T @ d.axes) @ d.axes.T)
    assert d.mdb_factor == pytest.approx(1.0 / math.sqrt(1.0 - lev.max()), rel=1e-9)
    # on the tight frame every leverage is 3/N: the MDB is on its floor
    assert d.mdb_factor == pytest.approx(1.0 / math.sqrt(1.0 - 3.0 / n), rel=1e-6)


def _gls_var_per_axis(H, rho):
    C = corr(H.shape[0], rho)
    return np.diag(np.linalg.inv(H.T @ np.linalg.solve(C, H)))


def _check_triads(M):
    d = search_layout(3 * M, family="triads", rho_range=(0.1, 0.1), rng=np.random.default_rng(2), starts=1)
    H = d.axes
    # each triad orthonormal (rows 3m..3m+2), axes summing to zero: on the floor. The sum is
    # asked to 1e-4: GDOP² exceeds the floor by O(|Σh|²) (~1e-8 relative there), below what
    # SLSQP's ftol 1e-14 on GDOP² resolves
    for m in range(M):
        np.testing.assert_allclose(H[3 * m:3 * m + 3] @ H[3 * m:3 * m + 3].T, np.eye(3), atol=1e-9)
    np.testing.assert_allclose(H.sum(axis=0), 0.0, atol=1e-4)
    assert gls_gdop(H, 0.1) == pytest.approx(3 * math.sqrt(0.9 / (3 * M)), rel=1e-6)
    co = np.tile(np.eye(3), (M, 1))
    vr, vc = _gls_var_per_axis(H, 0.1), _gls_var_per_axis(co, 0.1)
    gain = math.sqrt(vc.mean() / vr.mean())
    g = d.detail["gain"]
    assert g["gain_over_coaligned"] == pytest.approx(gain, rel=1e-6)
    # closed form: rotated 3(1-rho)/M per GDOP², co-aligned (1-rho)(2/M + 1/(M - 3 rho M²/(1 - rho + 3 M rho)))
    r = 0.1
    closed = math.sqrt((2 / M + 1 / (M - 3 * r * M * M / (1 - r + 3 * M * r))) / (3 / M))
    assert gain == pytest.approx(closed, rel=1e-6)
    assert triad_gain(co, 0.1)["gain_over_coaligned"] == pytest.approx(1.0, rel=1e-12)
    return gain


def test_triads_gain_over_coaligned_m3():
    # closed form at M = 3, rho = 0.1: M - 3 rho M²/(1 - rho + 3 M rho) = 1.5, so the gain is
    # sqrt((2/3 + 1/1.5)/1) = 2/sqrt(3)
    assert _check_triads(3) == pytest.approx(2 / math.sqrt(3), rel=1e-6)


@pytest.mark.slow
def test_triads_gain_over_coaligned_m8():
    assert round(_check_triads(8), 3) == 1.374     # the 8-IMU board (MIMU4444's count) at rho = 0.1


def test_cone_families_and_faces_scored_against_numpy():
    for fam in ("cone2", "faces"):
        d = search_layout(6, family=fam, rho_range=(0.0, 0.5))
        ratio = max(gls_gdop(d.axes, r) / (3 * math.sqrt((1 - r) / 6)) for r in (0.0, 0.5))
        # fixed weights at the design rho are GLS at that rho; at the ends they are >= the oracle
        assert d.bound_ratio >= ratio - 1e-9
        assert d.bound_ratio > 1.0 + 1e-3                   # neither reaches the floor at N = 6


def test_cli_family_refused(cli):
    p = cli("design", "--recommend", "--arw", "0.2", "--n", "6", "--family", "cone2,helix", check=False)
    assert p.returncode == 2 and "--family" in p.stderr and "Traceback" not in p.stderr
    p = cli("design", "--n", "6", "--scheme", "1", "--family", "free", check=False)
    assert p.returncode == 2 and "--family goes with --recommend" in p.stderr


@pytest.mark.slow
def test_cli_family_free_and_cones(cli, tmp_path):
    p = cli("design", "--recommend", "--arw", "0.2", "--n", "4,6", "--rho-range=0,0.5",
            "--family", "cone2,free", "--estimators", "gls", "--json")
    res = json.loads(p.stdout)
    lay = res["layouts"]
    fams = {(x["family"], x["n"]) for x in lay}
    assert {("free", 4), ("free", 6), ("cone2", 4), ("cone2", 6)} <= fams
    for x in lay:
        H = np.array(x["axes"])
        ratio = max(gls_gdop(H, r) / (3 * math.sqrt((1 - r) / x["n"])) for r in (0.0, 0.5))
        assert x["bound_ratio"] >= ratio - 1e-9
        if x["family"] == "free":
            assert x["bound_ratio"] == pytest.approx(1.0, abs=5e-3)
    for d in res["designs"]:
        assert "bound_ratio" in d
    p = cli("design", "--recommend", "--arw", "0.2", "--n", "6", "--rho-range=0,0.5",
            "--family", "cone2,free", "--estimators", "gls")
    assert "floor" in p.stdout and "ratio" in p.stdout


def test_a_range_below_zero_is_scored_over_its_part_at_or_above_zero():
    """The demo's ρ range [-0.1, 0.5]: the floor holds for ρ >= 0 only, so each design is scored
    against it over [0, 0.5] (said in a note), not left unscored. The scheme-1 N = 4 cone at the
    magic angle with alternating senses is a tetrahedron: bound_ratio 1 (numpy: its GDOP at ρ 0
    and 0.5 equals 3·√((1 − ρ)/4))."""
    import argparse
    import math

    from gyroarray.cli.design import _add_bounds
    from gyroarray.core.layout import Layout

    alpha = math.degrees(math.acos(1 / math.sqrt(3)))
    axes = Layout.conical(1, 4, math.radians(alpha)).axes * np.array([1, -1, 1, -1])[:, None]
    H = np.asarray(axes, float)
    for rho in (0.0, 0.5):
        C = (1 - rho) * np.eye(4) + rho * np.ones((4, 4))
        gdop = math.sqrt(np.trace(np.linalg.inv(H.T @ np.linalg.solve(C, H))))
        assert gdop == pytest.approx(3 * math.sqrt((1 - rho) / 4), rel=1e-9)
    res = {"designs": [{"scheme": 1, "axes": H.tolist()}], "notes": []}
    space = argparse.Namespace(failures=0)
    _add_bounds(res, argparse.Namespace(family=None), space, [-0.1, 0.2, 0.5], None)
    d = res["designs"][0]
    assert d["bound_ratio"] == pytest.approx(1.0, abs=1e-6)
    assert any("over [0, 0.5]" in n for n in res["notes"]), res["notes"]
