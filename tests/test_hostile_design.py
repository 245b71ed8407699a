"""Hostile inputs for ``design``, ``gdop``, ``parity`` and ``fit --out``: each gives an answer with
numbers or exit 2 with one located line naming the option and its valid range.

Outside truth written here with plain numpy: the rule N − failures >= 3 of the failure search, the
samples of a run after the 2 s start-up, the rank of a measured layout, the fused rate's spread of
a still record, the one parity equation's response c = Σ v_i e_i of a 4-gyro array with known
scale factors, and the white level of each gyro of a record with a dead gyro.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from hostile import assert_contract, axes_sidecar, run_cli, write_measurement

RATE = 100.0


def _refused(o, *names):
    assert_contract(o)
    assert o.code == 2, (o.code, o.out[:300])
    for n in names:
        assert n in o.err, (n, o.err)
    return o.err


# -- design --recommend: failures, --n, horizon -----------------------------------------------

@pytest.mark.parametrize("n, failures", [(3, 2), (4, 2), (3, 1)])
def test_failures_beyond_what_n_gyros_survive_are_refused_with_the_rule(n, failures):
    err = _refused(run_cli(["design", "--recommend", "--arw", "0.1", "--n", n, "--failures", failures]),
                   f"--failures {failures} with --n {n}", "N − failures must be ≥ 3")
    assert f"{n} − {failures} = {n - failures}" in err and f"N ≥ {failures + 3}" in err


def test_failures_beyond_a_four_gyro_model_are_refused(tmp_path):
    m = tmp_path / "m4.toml"
    m.write_text("effects = [\n" + "\n".join(f'  {{effect = "arw", gyro = {k}, n_deg_rt_h = 0.1}},'
                                             for k in range(1, 5)) + "\n]\n")
    _refused(run_cli(["design", "--recommend", "--model", m, "--failures", "2"]),
             "m4.toml", "--failures 2 with the model's 4 gyros", "N − failures must be ≥ 3")


def test_a_search_with_no_feasible_n_refuses_with_the_reason():
    from gyroarray.core.errors import InputError
    from gyroarray.design.recommend import DesignSpace, GyroNoise, recommend
    with pytest.raises(InputError, match=r"no design meets the requirements: N = 4: 2 failed gyro\(s\) "
                                         r"leave 2, fewer than the 3"):
        recommend(GyroNoise(arw_deg_rt_h=0.1), DesignSpace(ns=(4,), failures=2, estimators=("ols",)))


def test_repeated_n_is_refused_not_deduplicated():
    _refused(run_cli(["design", "--recommend", "--arw", "0.1", "--n", "4,4,4"]),
             "--n 4,4,4", "N = 4 is listed more than once")


def _min_samples(rate: float, settle: float = 2.0) -> int:
    """First sample at t >= settle, plus the 2 the metrics need (numpy, as chain.run.score)."""
    t = np.arange(int(math.ceil(settle * rate)) + 3) / rate
    return int(np.argmax(t >= settle)) + 2


@pytest.mark.parametrize("h", ["0", "1e-300", "-1", "1.99", "2.01", "3.2e7", "1e12", "1e300"])
def test_recommend_horizon_outside_the_run_is_refused_with_the_range(h):
    lo = _min_samples(RATE)
    assert lo == 202
    err = _refused(run_cli(["design", "--recommend", "--arw", "0.1", "--horizon-s", h]), "--horizon-s")
    assert f"from {lo / RATE:g} to {2e7 / RATE:g} s at 100 Hz" in err


@pytest.mark.parametrize("v", ["inf", "nan"])
def test_recommend_horizon_not_finite_is_refused(v):
    _refused(run_cli(["design", "--recommend", "--arw", "0.1", "--horizon-s", v]), "--horizon-s must be finite")


@pytest.mark.parametrize("argv, name", [
    (["--arw", "1e-300"], "--arw must be in [1e-09, 6e+06]"),
    (["--arw", "0.1", "--sensor-bandwidth", "1e-300"], "--sensor-bandwidth: the cut-off must be from 0.0001 Hz"),
    (["--arw", "0.1", "--sensor-bandwidth", "0"], "--sensor-bandwidth"),
    (["--arw", "0.1", "--rate-hz", "1e300"], "--rate-hz"),
    (["--arw", "0.1", "--rho", "1e300"], "--rho"),
    (["--arw", "0.1", "--failures", "-1"], "--failures"),
    (["--arw", "0.1", "--bandwidth-hz", "1e300"], "--bandwidth-hz"),
    (["--arw", "0.1", "--swing", "5,1e300"], "--swing"),
    (["--arw", "0.1", "--far-per-h", "1e-300", "--failures", "1"], "--far-per-h"),
    (["--arw", "0.1", "--p-md", "0", "--failures", "1"], "--p-md"),
    (["--arw", "0.1", "--mdb-max", "0", "--failures", "1"], "--mdb-max"),
])
def test_recommend_float_extremes_are_refused_naming_the_option(argv, name):
    _refused(run_cli(["design", "--recommend", "--n", "4", *argv]), name)


@pytest.mark.parametrize("opt, v", [(o, v) for o in ("--alpha", "--rho", "--n")
                                    for v in ("0", "1e-300", "1e300", "inf", "nan", "-1")])
def test_gdop_float_extremes_answer_or_refuse_naming_the_option(opt, v):
    a = {"--alpha": "54.7356", "--rho": "0", "--n": "4", opt: v}
    o = run_cli(["gdop", "--scheme", "1", "--n", a["--n"], "--alpha", a["--alpha"], "--rho", a["--rho"], "--json"])
    assert_contract(o)
    if o.code == 2:
        assert opt in o.err, o.err
    else:                                # alpha 0 or 1e-300: every axis on +z, no 3-axis rate: said
        assert opt == "--alpha" or (opt == "--rho" and float(v) == pytest.approx(0.0))
        res = o.json
        if opt == "--alpha":             # the answer is "infinite", with the reason (GDOP null in JSON)
            assert res["gdop"] is None and "all axes are parallel" in res["note"]
        else:
            assert res["gdop"] == pytest.approx(3 / 2, rel=1e-3)        # near-tetrahedron: 3/√N


# -- design --layout-from -----------------------------------------------------------------------

def _model(path: Path, n: int) -> Path:
    path.write_text("effects = [\n" + "\n".join(f'  {{effect = "arw", gyro = {k}, n_deg_rt_h = 0.1}},'
                                                for k in range(1, n + 1)) + "\n]\n")
    return path


def _axes_record(tmp_path, name, axes, n=2000):
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in a) + "]" for a in axes)
    side = f"sample_rate_hz = {RATE!r}\n[layout]\naxes = [{rows}]\n"
    rng = np.random.default_rng(1)
    return write_measurement(tmp_path, name, np.arange(n) / RATE, rng.normal(0, 1e-3, (n, len(axes))),
                             sidecar=side)


@pytest.mark.parametrize("h", ["0", "-1", "1e-300", "3.2e7", "1e12", "1e300"])
def test_layout_from_horizon_is_checked_before_any_allocation(tmp_path, h):
    meas = write_measurement(tmp_path, "rec4", np.arange(500) / RATE, np.zeros((500, 4)),
                             sidecar=axes_sidecar(4, RATE))
    err = _refused(run_cli(["design", "--model", _model(tmp_path / "m.toml", 4), "--layout-from", meas,
                            "--horizon-s", h]), "--horizon-s")
    assert "from 2.02 to 200000 s at 100 Hz" in err


def test_layout_from_a_record_shorter_than_the_start_up_names_horizon(tmp_path):
    meas = write_measurement(tmp_path, "short", np.arange(150) / RATE, np.zeros((150, 4)),
                             sidecar=axes_sidecar(4, RATE))
    _refused(run_cli(["design", "--model", _model(tmp_path / "m.toml", 4), "--layout-from", meas]),
             "short.csv", "the record has 150 samples", "give --horizon-s from 2.02 to 200000 s")


@pytest.mark.parametrize("name, axes, words", [
    ("coplanar", [[1, 0, 0], [0, 1, 0], [math.sqrt(0.5), math.sqrt(0.5), 0]],
     "the axes of gyros 1, 2, 3 are coplanar: rank 2 of 3"),
    ("flat4", [[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], "gyros 1, 2, 3, 4 are coplanar: rank 2 of 3"),
    ("same", [[0, 0, 1]] * 4, "are collinear (identical or opposite): rank 1 of 3"),
    ("two", [[1, 0, 0], [0, 1, 0]], "the array has 2 gyro(s); a 3-axis rate needs at least 3"),
])
def test_layout_from_an_array_with_no_3_axis_rate_is_refused(tmp_path, name, axes, words):
    H = np.asarray(axes, float)
    assert np.linalg.matrix_rank(H) < 3                      # the outside truth: no 3-D span
    meas = _axes_record(tmp_path, name, axes)
    _refused(run_cli(["design", "--model", _model(tmp_path / "m.toml", len(axes)), "--layout-from", meas]),
             f"{name}.csv", "--layout-from", words)


def test_layout_from_an_unknown_estimator_lists_the_known(tmp_path):
    meas = write_measurement(tmp_path, "rec4", np.arange(500) / RATE, np.zeros((500, 4)),
                             sidecar=axes_sidecar(4, RATE))
    err = _refused(run_cli(["design", "--model", _model(tmp_path / "m.toml", 4), "--layout-from", meas,
                            "--estimators", "nope"]), "--estimators: nope is not an estimator")
    assert all(e in err for e in ("gls", "ols", "kf_array", "svo", "naive"))


def test_layout_from_the_shortest_horizon_answers_with_the_static_closed_form(tmp_path):
    # at the shortest run the GLS prediction still stands: its white ADEV at tau = dt is
    # σ √(w·w) for alike gyros (w the pseudo-inverse's row), written here
    meas = write_measurement(tmp_path, "rec4", np.arange(500) / RATE, np.zeros((500, 4)),
                             sidecar=axes_sidecar(4, RATE))
    o = run_cli(["design", "--model", _model(tmp_path / "m.toml", 4), "--layout-from", meas,
                 "--horizon-s", "2.02", "--estimators", "gls", "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    from gyroarray.core.measurement import read_measurement
    H = np.asarray(read_measurement(meas).layout.axes, float)
    sigma = math.radians(0.1 / 60.0) / math.sqrt(1.0 / RATE)            # per-sample white [rad/s]
    W = np.linalg.pinv(H)
    for a, ax in enumerate("xyz"):
        p = o.json["estimators"]["gls"][ax]["adev_deg_s"][0]
        assert p["tau_s"] == pytest.approx(1.0 / RATE)
        assert p["adev_deg_s"] == pytest.approx(math.degrees(sigma * np.linalg.norm(W[a])), rel=1e-9)


# -- parity ----------------------------------------------------------------------------------

def _sidecar(H):
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in h) + "]" for h in H)
    return f"sample_rate_hz = {RATE!r}\n[layout]\naxes = [{rows}]\n"


def test_parity_on_a_static_record_says_why_with_the_spread(tmp_path):
    rng = np.random.default_rng(3)
    n = 3000
    y = 0.01 * rng.normal(size=(n, 4))                                  # deg/s, at rest
    path = write_measurement(tmp_path, "still", np.arange(n) / RATE, y, sidecar=axes_sidecar(4, RATE))
    err = _refused(run_cli(["parity", path, "--json"]), "still.csv", "the record has no motion",
                   "at least 5 deg/s rms")
    spread = float(re.search(r"the rate's spread is ([0-9.e+-]+) deg/s", err).group(1))
    from gyroarray.core.measurement import read_measurement
    H = np.asarray(read_measurement(path).layout.axes, float)
    om = y @ np.linalg.pinv(H).T                                         # OLS; GLS on near-equal gyros
    d = om - om.mean(axis=0)
    assert spread == pytest.approx(math.sqrt(np.mean(np.sum(d * d, axis=1))), rel=0.1)


def test_parity_on_three_samples_says_how_many_it_needs(tmp_path):
    path = write_measurement(tmp_path, "three", np.arange(3) / RATE, np.ones((3, 4)) * [1, 2, 3, 4],
                             sidecar=axes_sidecar(4, RATE))
    _refused(run_cli(["parity", path]), "three.csv", "the record has 3 samples",
             "needs at least 48 moving samples")          # 4 per unknown x 3 unknowns x 4 gyros


def test_parity_on_a_constant_record_says_it_has_no_motion(tmp_path):
    path = write_measurement(tmp_path, "const", np.arange(2000) / RATE, np.full((2000, 4), 0.5),
                             sidecar=axes_sidecar(4, RATE))
    err = _refused(run_cli(["parity", path, "--json"]), "const.csv", "the record has no motion")
    assert float(re.search(r"spread is ([0-9.e+-]+) deg/s", err).group(1)) < 1e-9


def test_parity_on_four_gyros_reports_the_observable_combination_not_per_gyro_errors(tmp_path):
    # truth: scale factors 2000, 0, 0, −3000 ppm; one parity equation sees only c = Σ v_i s_i h_i
    H = np.array([[0.8 * math.cos(2.0 * math.pi * k / 4 + 0.3 * k), 0.8 * math.sin(2.0 * math.pi * k / 4 + 0.3 * k),
                   0.6 * (-1) ** k] for k in range(4)])
    H /= np.linalg.norm(H, axis=1)[:, None]
    s = np.array([2000e-6, 0.0, 0.0, -3000e-6])
    n, dt = 6000, 1.0 / RATE
    t = np.arange(n) * dt
    om = np.stack([3.0 * np.sin(2 * np.pi * 0.31 * t), 2.5 * np.sin(2 * np.pi * 0.17 * t + 1.0),
                   3.5 * np.sin(2 * np.pi * 0.23 * t + 2.0)], axis=1)      # rad/s, all three axes
    rng = np.random.default_rng(5)
    y = om @ (H * (1.0 + s)[:, None]).T + 0.002 + 0.002 * rng.normal(size=(n, 4))
    path = write_measurement(tmp_path, "four", t, np.degrees(y), sidecar=_sidecar(H))
    o = run_cli(["parity", path, "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    cal = o.json["calibration"]
    assert cal["gauge_dependent"] is True and cal["off"] == []
    assert not any(g["off"] for g in cal["gyros"].values())
    v = np.linalg.svd(H.T)[2][-1]                                        # vᵀH = 0, unit
    v *= np.sign(v[np.argmax(np.abs(v))])
    truth = (v * s) @ H * 1e6                                            # [ppm]
    ob = cal["observable"]
    assert ob["parity_vector"] == pytest.approx(list(v), abs=1e-9)
    for a, ax in enumerate("xyz"):
        sig = ob["sigma_ppm"][ax]
        assert 0 < sig < 100
        assert abs(ob["response_ppm"][ax] - truth[a]) < 4 * sig, (ax, ob["response_ppm"][ax], truth[a], sig)
    assert "gauge-dependent" in ob["statement"] and "not per-gyro errors" in ob["statement"]
    assert cal["significant"]
    text = run_cli(["parity", path]).out
    assert "NOT per-gyro errors" in text and "off: cannot be told with 4 gyros" in text


def test_parity_on_five_gyros_is_not_gauge_dependent(tmp_path):
    rng = np.random.default_rng(8)
    H = rng.normal(size=(5, 3))
    H /= np.linalg.norm(H, axis=1)[:, None]
    n = 3000
    t = np.arange(n) / RATE
    om = np.stack([3.0 * np.sin(2 * np.pi * 0.31 * t), 2.5 * np.sin(2 * np.pi * 0.17 * t + 1.0),
                   3.5 * np.sin(2 * np.pi * 0.23 * t + 2.0)], axis=1)
    y = om @ H.T + 0.002 * rng.normal(size=(n, 5))
    o = run_cli(["parity", write_measurement(tmp_path, "five", t, np.degrees(y), sidecar=_sidecar(H)), "--json"])
    assert_contract(o)
    assert o.code == 0 and o.json["calibration"]["gauge_dependent"] is False
    assert "observable" not in o.json["calibration"]


# -- fit --out on a record with a dead gyro ---------------------------------------------------

def test_renumbered_model_keeps_the_records_gyro_numbers_and_round_trips():
    from gyroarray.effects.model import ArrayNoise, ModelEntry, NoiseModel
    C = ((1.0, 0.2, 0.1), (0.2, 1.0, 0.3), (0.1, 0.3, 1.0))
    m = NoiseModel((ModelEntry("arw", None, {"n_deg_rt_h": 0.2}),
                    ModelEntry("arw", 2, {"n_deg_rt_h": 0.5}),
                    ModelEntry("scale_factor", 3, {"ppm": 1500.0}),
                    ModelEntry("correlation", None, {"rho_arw": C})),
                   description="fitted",
                   array=ArrayNoise(gyros=(1, 2, 3), white_n_deg_rt_h=(0.2, 0.5, 0.2), white_correlation=C,
                                    shared=({"f_hz": 17.6, "band_hz": (17.2, 17.9), "gyros": (1, 3),
                                             "coherence": 0.5},),
                                    notes=("slow part not seen on gyro(s) 2, 3",)))
    r = m.renumbered([1, 3, 4], 4, "gyro 2 left out")
    assert [(e.effect, e.gyro) for e in r] == [("arw", None), ("arw", 3), ("scale_factor", 4), ("correlation", None)]
    full = np.asarray(r.entries[3].params["rho_arw"])
    assert full.shape == (4, 4) and np.array_equal(full[np.ix_([0, 2, 3], [0, 2, 3])], np.asarray(C))
    assert np.array_equal(full[1], [0, 1, 0, 0]) and np.array_equal(full[:, 1], [0, 1, 0, 0])
    assert r.array.gyros == (1, 3, 4) and tuple(r.array.shared[0]["gyros"]) == (1, 4)
    assert r.array.notes == ("slow part not seen on gyro(s) 3, 4", "gyro 2 left out")
    assert r.description == "fitted; gyro 2 left out"
    back = NoiseModel.from_toml(__import__("tomllib").loads(r.to_toml()), n_gyros=4)
    assert back == r


@pytest.mark.slow
def test_fit_out_on_a_record_with_a_dead_gyro_keeps_its_numbers_and_fuse_takes_it(tmp_path):
    rng = np.random.default_rng(4)
    n = 6000
    t = np.arange(n) / RATE
    white = np.array([0.03, 0.0, 0.05, 0.08])                          # deg/s per sample
    g = white * rng.normal(size=(n, 4))
    g[:, 1] = 0.25                                                     # gyro 2 dead
    meas = write_measurement(tmp_path, "dead2", t, g, sidecar=axes_sidecar(4, RATE))
    out = tmp_path / "new.toml"
    o = run_cli(["fit", meas, "--out", out, "--json"], timeout=600)
    assert_contract(o)
    assert o.code == 0, o.err
    assert any("keeps the record's gyro numbers (1, 3, 4); gyro 2 is constant" in x for x in o.json["notes"])
    from gyroarray.effects.model import NoiseModel
    model = NoiseModel.from_toml(out, n_gyros=4)
    assert {e.gyro for e in model if e.gyro is not None} == {1, 3, 4}
    assert model.array is None or model.array.gyros == (1, 3, 4)
    assert "gyro 2 is constant" in model.description
    # each written ARW is its own gyro's white level, N = σ √dt [deg/√s] x 60
    arw = {e.gyro: e.params["n_deg_rt_h"] for e in model if e.effect == "arw" and e.gyro is not None}
    for k in (1, 3, 4):
        assert arw[k] == pytest.approx(np.std(g[:, k - 1]) * math.sqrt(1.0 / RATE) * 60.0, rel=0.05), k
    f = run_cli(["fuse", meas, "--model", out, "--estimator", "gls", "--out", tmp_path / "fused.csv", "--json"],
                timeout=600)
    assert_contract(f)
    assert f.code == 0, f.err


@pytest.mark.parametrize("opt, v", [("--rate-hz", "50"), ("--failures", "1"), ("--swing", "5,0.1")])
def test_layout_from_refuses_the_searchs_options_instead_of_ignoring_them(tmp_path, opt, v):
    meas = write_measurement(tmp_path, "rec4", np.arange(500) / RATE, np.zeros((500, 4)),
                             sidecar=axes_sidecar(4, RATE))
    _refused(run_cli(["design", "--model", _model(tmp_path / "m.toml", 4), "--layout-from", meas, opt, v]),
             f"--layout-from: {opt} does not apply")


@pytest.mark.slow          # about 2 s: the search's set-up runs before every N is left out
def test_a_rho_range_no_n_can_have_is_refused_naming_the_options():
    # ρ = −0.5 is below −1/(N − 1) = −1/3 for N = 4: no equicorrelated 4-gyro array has it
    _refused(run_cli(["design", "--recommend", "--arw", "0.1", "--n", "4", "--rho-range=-0.5,0.5",
                      "--estimators", "ols"]),
             "no design meets the requirements", "rho = -0.5 is not a correlation 4 gyros can have",
             "--rho-range")


@pytest.mark.slow
def test_the_default_n_list_with_two_failures_leaves_n_4_out_and_says_so():
    o = run_cli(["design", "--recommend", "--arw", "0.1", "--failures", "2", "--estimators", "ols", "--json"],
                timeout=600)
    assert_contract(o)
    assert o.code == 0, o.err
    res = o.json
    assert {d["n"] for d in res["designs"]} == {5, 6, 8}
    assert any(n.startswith("N = 4: 2 failed gyro(s) leave 2, fewer than the 3") for n in res["notes"])
    # every design keeps 3 gyros after its worst pair of failures: a finite worst case
    assert all(len(d["worst_case"]["failed_gyros"]) == 2 and math.isfinite(d["worst_case"]["rms_3axis_deg_s"])
               for d in res["designs"])


@pytest.mark.slow
def test_the_shortest_horizon_is_answered():
    o = run_cli(["design", "--recommend", "--arw", "0.1", "--n", "4", "--estimators", "ols",
                 "--horizon-s", "2.02", "--json"], timeout=600)
    assert_contract(o)
    assert o.code == 0, o.err
    w = o.json["recommended"]["worst_case"]
    assert math.isfinite(w["rms_3axis_deg_s"]) and w["rms_3axis_deg_s"] > 0
