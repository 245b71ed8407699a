"""The design search, fault tolerance and ρ as a condition, against plain computations.

The geometry (GDOP after failures, robustness over ρ) is recomputed here from
its definition, sqrt(trace((HᵀC⁻¹H)⁻¹)) with the axes written out; the fast
path of the search is checked against the full predictor.
"""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest

from gyroarray.cli.main import main
from gyroarray.core.gdop import fault_tolerance, gdop_robustness, minmax_alpha, optimal_alpha
from gyroarray.core.layout import Layout
from gyroarray.design.predict import Swing
from gyroarray.design.recommend import (DesignSpace, GyroNoise, generic_design, generic_or_fast,
                                 equivalent_groups, recommend)


def _axes(scheme: int, n: int, alpha: float) -> np.ndarray:
    """Conical axes written out (paper 003 §2.2)."""
    rows = [] if scheme == 1 else [[0.0, 0.0, 1.0]]
    m = n if scheme == 1 else n - 1
    for k in range(m):
        b = 2 * math.pi * k / m
        rows.append([math.sin(alpha) * math.cos(b), math.sin(alpha) * math.sin(b), math.cos(alpha)])
    return np.array(rows)


def _plain_gdop(h: np.ndarray) -> float:
    info = h.T @ h
    if np.linalg.matrix_rank(info, tol=1e-9) < 3:
        return math.inf
    return math.sqrt(np.trace(np.linalg.inv(info)))


def _plain_worst(h: np.ndarray, k: int) -> float:
    return max(_plain_gdop(np.delete(h, list(c), axis=0))
               for c in itertools.combinations(range(h.shape[0]), k))


@pytest.mark.parametrize("n, after_one", [(4, 2.121), (5, 1.643), (6, 1.414), (8, 1.162)])
def test_gdop_after_one_failure_at_the_optimum(n, after_one):
    # the issue's numbers, and a plain recomputation to 1e-12
    for scheme in (1, 2):
        alpha = optimal_alpha(scheme, n, 0.0).alpha_rad
        ft = fault_tolerance(Layout.conical(scheme, n, alpha))
        plain = _plain_worst(_axes(scheme, n, alpha), 1)
        assert ft["worst_gdop_after"]["1"] == pytest.approx(plain, rel=1e-12)
        assert round(plain, 3) == after_one
        assert ft["three_axes_after"]["1"]
        assert ft["detectable"]


def test_two_failures_separate_the_schemes():
    a1 = optimal_alpha(1, 5, 0.0).alpha_rad
    a2 = optimal_alpha(2, 5, 0.0).alpha_rad
    f1 = fault_tolerance(Layout.conical(1, 5, a1))
    f2 = fault_tolerance(Layout.conical(2, 5, a2))
    assert f1["gdop"] == pytest.approx(f2["gdop"], rel=1e-12)        # equal intact
    assert f1["worst_gdop_after"]["2"] == pytest.approx(_plain_worst(_axes(1, 5, a1), 2), rel=1e-12)
    assert round(f1["worst_gdop_after"]["2"], 3) == 3.047
    assert f1["three_axes_after"]["2"]
    assert f2["worst_gdop_after"]["2"] == math.inf == _plain_worst(_axes(2, 5, a2), 2)
    assert not f2["three_axes_after"]["2"]
    assert "unobservable" in f2["lost_axis_example"]["2"]


def test_detectable_and_isolable_from_the_parity_space():
    # N = 4: one parity equation, every gyro in it: detectable, not isolable
    t = fault_tolerance(Layout.conical(1, 4, optimal_alpha(1, 4, 0.0).alpha_rad))
    assert t["detectable"] and not t["isolable"]
    # N = 6 Scheme 1: no two gyros share a parity direction
    s = fault_tolerance(Layout.conical(1, 6, optimal_alpha(1, 6, 0.0).alpha_rad))
    assert s["detectable"] and s["isolable"]
    # a triad has no parity space at all
    tri = fault_tolerance(Layout.triad())
    assert not tri["detectable"] and not tri["isolable"]


def test_robustness_over_rho_matches_the_issue():
    rows = gdop_robustness(2, 8, [0.0, 0.5], alpha_rad=math.radians(116.8254))
    at0, at5 = rows
    assert round(at5["gdop"], 3) == 0.788
    assert round(at0["gdop"], 3) == 1.063
    assert round(at0["gdop_opt"], 4) == 1.0607
    # min-max: the worst GDOP over the range at the chosen angle is the smallest worst case
    mm = minmax_alpha(2, 8, [0.0, 0.5])
    grid = np.radians(np.arange(1.0, 179.0, 0.5))
    from gyroarray.core.gdop import gdop_vs_alpha
    worst = np.maximum(gdop_vs_alpha(2, 8, grid, 0.0), gdop_vs_alpha(2, 8, grid, 0.5))
    assert mm.gdop <= worst.min() + 1e-9


def test_fast_path_equals_the_full_predictor():
    g = GyroNoise(arw_deg_rt_h=0.15, rrw_deg_h_rt_h=40.0, bi_deg_h=5.0, gm_sigma_deg_h=20.0,
                  gm_tau_s=3.0, rho_arw=0.3, rho_rrw=0.3)
    space = DesignSpace(rate_hz=100.0, horizon_s=30.0, swing=Swing(math.radians(5.0), 0.2),
                        bandwidth_hz=(0.5, 40.0))
    for scheme, n, alpha in ((1, 6, 0.9), (2, 5, 1.2)):
        for est, bw in (("kf_array", 3.0), ("kf_single", 7.0), ("gls", 2.0), ("ols", None),
                        ("naive", None)):
            fast = generic_or_fast(scheme, n, est, alpha, bw, 0.3, g, space)
            full = generic_design(scheme, n, est, alpha, bw, 0.3, space, g, 0)
            for ax in "xyz":
                for k, v in full["predicted"][ax].items():
                    if v is not None:
                        assert fast["predicted"][ax][k] == pytest.approx(v, rel=1e-9), (est, ax, k)


def _run_cli(argv, capsys):
    code = main(argv)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_recommend_json_is_the_issue_object(capsys):
    code, out, err = _run_cli(["design", "--recommend", "--arw", "0.1", "--rrw", "10", "--rate-hz",
                               "100", "--horizon-s", "600", "--n", "4,5,6,8", "--failures", "1",
                               "--json"], capsys)
    assert code == 0, err
    res = json.loads(out)
    assert {"recommended", "designs", "equivalent", "assumptions"} <= set(res)
    rec = res["recommended"]
    assert {"scheme", "n", "alpha_deg", "estimator", "bandwidth_hz", "predicted",
            "worst_gdop_after_failures"} <= set(rec)
    for ax in "xyz":
        assert {"rms_deg_s", "std_deg_s", "angle_deg_at_horizon"} <= set(rec["predicted"][ax])
    # failure GDOPs are the geometry
    for d in res["designs"]:
        h = _axes(d["scheme"], d["n"], math.radians(d["alpha_deg"]))
        assert d["worst_gdop_after_failures"] == pytest.approx(_plain_worst(h, 1), rel=1e-9)
    # the GLS designs' white-noise level is the closed form N·√diag((HᵀH)⁻¹) (unity DC gain)
    for d in (d for d in res["designs"] if d["estimator"] == "gls"):
        h = _axes(d["scheme"], d["n"], math.radians(d["alpha_deg"]))
        closed = 0.1 * np.sqrt(np.diag(np.linalg.inv(h.T @ h)))
        got = [d["predicted"][a]["arw_long_deg_rt_h"] for a in "xyz"]
        np.testing.assert_allclose(got, closed, rtol=1e-9)
    # every input says where it came from
    a = res["assumptions"]
    assert a["arw"]["source"] == "user" and a["bias_instability"]["source"] == "default"
    assert a["failures"]["value"] == 1 and a["bandwidth_hz"]["source"] == "default"
    # kf_array and kf_single at the same layout and bandwidth are one group, said why
    assert any("kf_array and kf_single" in g["reason"] for g in res["equivalent"])


def test_equal_designs_are_grouped_with_the_reason():
    g = GyroNoise(arw_deg_rt_h=0.1, rrw_deg_h_rt_h=0.0)
    res = recommend(g, DesignSpace(ns=(6,), horizon_s=20.0, estimators=("gls", "ols", "naive")))
    groups = equivalent_groups([dict(d) for d in res["designs"]])
    top = groups[0]
    assert top["spread"] < 1e-9 and top["reason"].startswith("identical by theory")


def test_rho_range_ranks_per_rho_and_reports_the_worst_case(capsys):
    code, out, err = _run_cli(["design", "--recommend", "--arw", "0.1", "--rrw", "100", "--n", "6",
                               "--horizon-s", "30", "--rho-range=-0.1,0.5",
                               "--estimators", "gls", "--json"], capsys)
    assert code == 0, err
    res = json.loads(out)
    assert set(res["per_rho"]) == {"-0.1", "0.05", "0.2", "0.35", "0.5", "0"}
    rec = res["recommended"]
    assert rec["worst_rms_3axis_deg_s"] == pytest.approx(rec["rms_3axis_deg_s"])
    # the recommendation's worst case (weights fixed at its design ρ, issue 30: no longer the
    # oracle per-ρ winners) is no worse than any design's, and no better than at any ρ shown
    key = "rms_3axis_deg_s" if rec["objective"] == "rate" else "angle_deg"
    for d in res["designs"]:
        assert rec["worst_case"][key] <= d["worst_case"][key] * (1 + 0.0101)
    assert rec["worst_rms_3axis_deg_s"] >= max(rec["rms_by_rho"].values()) * (1 - 1e-9)


def test_model_file_gives_the_typical_gyro(tmp_path, capsys):
    m = tmp_path / "m.toml"
    m.write_text('effects = [ {effect = "arw", gyro = 1, n_deg_rt_h = 0.3},\n'
                 ' {effect = "arw", gyro = 2, n_deg_rt_h = 0.4},\n'
                 ' {effect = "rrw", k_deg_h_rt_h = 5.0} ]\n')
    code, out, err = _run_cli(["design", "--recommend", "--model", str(m), "--n", "4",
                               "--horizon-s", "20", "--json"], capsys)
    assert code == 0, err
    a = json.loads(out)["assumptions"]
    assert a["arw"]["value"] == pytest.approx(math.sqrt((0.09 + 0.16) / 2))
    assert a["arw"]["source"].startswith("model")


@pytest.mark.parametrize("argv, message", [
    (["design", "--recommend", "--rrw", "3"], "give the gyro noise"),
    (["design", "--recommend", "--arw", "0.1", "--rho", "0.1", "--rho-range", "0,0.5"], "exclude"),
    (["design", "--recommend", "--arw", "0.1", "--n", "4,x"], "--n"),
    (["design", "--recommend", "--arw", "0.1", "--n", "100000"], "outside 3..24"),
    (["design", "--recommend", "--arw", "0.1", "--swing", "5"], "--swing"),
    (["design", "--arw", "0.1"], "goes with --recommend"),
])
def test_recommend_bad_input_is_one_line(argv, message, capsys):
    code, out, err = _run_cli(argv, capsys)
    assert code == 2 and message in err and err.count("\n") == 1


def test_gdop_and_design_survive_a_lost_axis(capsys):
    code, out, err = _run_cli(["gdop", "--scheme", "1", "--n", "6", "--alpha", "90", "--json"], capsys)
    assert code == 0, err
    res = json.loads(out)
    assert res["gdop"] is None                       # inf is not JSON: null, with the note
    assert "z is unobservable: all axes lie in the x-y plane" in res["note"]
    code, out, err = _run_cli(["design", "--scheme", "2", "--n", "3", "--json"], capsys)
    assert code == 0, err
    assert "unobservable" in json.loads(out)["note"]


def test_run_refuses_an_unobservable_layout(tmp_path, capsys):
    s = tmp_path / "flat.toml"
    s.write_text('name = "flat"\nsample_rate_hz = 100.0\nseed = 1\nduration_s = 5.0\n'
                 'effects = [{ effect = "arw", n_deg_rt_h = 0.1 }]\n'
                 '[layout]\nscheme = 1\nn_gyros = 6\nalpha_deg = 90.0\n'
                 '[motion]\nprofile = "p003_static_1h"\n')
    code, out, err = _run_cli(["run", str(s)], capsys)
    assert code == 2
    assert "z is unobservable: all axes lie in the x-y plane" in err and err.count("\n") == 1


def test_paired_sweep_gives_every_design_the_same_seed(tmp_path):
    from gyroarray.sweep.sweep import load_sweep
    text = ('name = "p"\nseed = 3\npaired = true\nreplicates = 2\n'
            'base = "paper003/static_s1_n6_rhob_0"\n[grid]\nn_gyros = [4, 6]\nscheme = [1, 2]\n'
            'duration_s = [10.0]\n')
    (tmp_path / "p.toml").write_text(text)
    sw = load_sweep(tmp_path / "p.toml")
    seeds = {}
    for s in sw.scenarios:
        seeds.setdefault(s.params["replicate"], set()).add(s.seed)
    assert len(sw) == 8 and all(len(v) == 1 for v in seeds.values())   # one seed per replicate
    assert seeds[0] != seeds[1]
    (tmp_path / "u.toml").write_text(text.replace("paired = true\n", ""))
    unpaired = load_sweep(tmp_path / "u.toml")
    assert len({s.seed for s in unpaired.scenarios}) == 8
