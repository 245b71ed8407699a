"""``gyroarray fuse --validate`` and the array model in ``fit`` and the estimators (issue 31, items 2-3).

Outside truth: a 6-gyro array simulated here with numpy alone (white noise with a known
non-diagonal covariance, an independent random walk), the GLS weights written with numpy
(W = (Hᵀ R⁻¹ H)⁻¹ Hᵀ R⁻¹), and the fused white variance wᵀ Σ w of the known covariance.
"""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from hostile import assert_contract, run_cli, write_measurement

RATE_HZ = 50.0
DT = 1.0 / RATE_HZ
N_GYRO = 6
#: Unit axes of the simulated array: three pairs at ±35° about x, y and z.
AXES = np.array([[0.82, 0.57, 0.0], [0.82, -0.57, 0.0], [0.0, 0.82, 0.57],
                 [0.0, 0.82, -0.57], [0.57, 0.0, 0.82], [-0.57, 0.0, 0.82]])
AXES = AXES / np.linalg.norm(AXES, axis=1, keepdims=True)
ARW = np.array([0.30, 0.40, 0.35, 0.50, 0.45, 0.38]) * np.pi / 180 / 60      # deg/rt(h) -> rad/rt(s)
RRW = np.array([2.0, 3.0, 2.5, 2.0, 3.0, 2.5]) * np.pi / 180 / 3600 / 60    # deg/h/rt(h) -> rad/s/rt(s)
#: White correlation: a common mode (0.45 between every pair) plus a stronger pair (gyros 5, 6).
CORR = 0.55 * np.eye(N_GYRO) + 0.45 * np.ones((N_GYRO, N_GYRO))
CORR[4, 5] = CORR[5, 4] = 0.7


def _sidecar() -> str:
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in r) + "]" for r in AXES)
    return f"sample_rate_hz = {RATE_HZ!r}\n[layout]\naxes = [{rows}]\n"


def _simulate(seconds: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Time [s] and outputs [deg/s] of the still array: white N(0, D C D / dt) + random walk."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE_HZ)
    sd = ARW / np.sqrt(DT)
    cov = CORR * np.outer(sd, sd)
    white = rng.standard_normal((n, N_GYRO)) @ np.linalg.cholesky(cov).T
    walk = np.cumsum(rng.standard_normal((n, N_GYRO)) * RRW * np.sqrt(DT), axis=0)
    return np.arange(n) * DT, np.degrees(white + walk)


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    folder = tmp_path_factory.mktemp("validate")
    t, g = _simulate(600.0, seed=3)
    return write_measurement(folder, "array6", t, g, sidecar=_sidecar(), gz=True)


@pytest.fixture(scope="module")
def validated(record):
    o = run_cli(["fuse", record, "--estimator", "gls", "--validate", "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    return o.json["validation"]


def _gls(h: np.ndarray, r: np.ndarray) -> np.ndarray:
    ri = np.linalg.inv(r)
    return np.linalg.solve(h.T @ ri @ h, h.T @ ri)


def test_fitted_covariance_prediction_is_consistent_at_nine_tenths_of_tau(validated):
    assert validated["holdout"] == 0.5 and validated["fit_s"] == pytest.approx(300.0, abs=0.1)
    for ax, d in validated["axes"].items():
        p = d["predicted"]["covariance"]
        assert p["fraction_inside"] >= 0.9, (ax, p["verdict"])
        assert p["consistent"] and p["verdict"].startswith("consistent")
        assert len(p["inside"]) == len(d["taus_s"]) == len(d["measured_adev_deg_h"])


def test_predicted_fused_arw_is_numpy_w_sigma_w_of_the_true_covariance(validated):
    """The fitted prediction's fused ARW equals sqrt(wᵀ Σ w) of the TRUE covariance within 6 %
    (300 s fit), and the independent one misses it by the correlation's factor."""
    w = _gls(AXES, CORR * np.outer(ARW, ARW))               # the estimator's weights, near enough
    true = np.sqrt(np.einsum("ai,ij,aj->a", w, CORR * np.outer(ARW, ARW), w)) * 180 / np.pi * 60
    indep = np.sqrt(np.einsum("ai,i,ai->a", w, ARW ** 2, w)) * 180 / np.pi * 60
    for a, ax in enumerate("xyz"):
        p = validated["axes"][ax]["predicted"]
        assert p["covariance"]["arw_deg_rt_h"] == pytest.approx(true[a], rel=0.06)
        assert validated["axes"][ax]["measured_arw_deg_rt_h"] == pytest.approx(true[a], rel=0.1)
        # the independent prediction uses the same weights with C = I: GLS designed with the
        # covariance cancels part of the common mode, so taking the gyros independent over-predicts
        assert p["independent"]["arw_deg_rt_h"] == pytest.approx(indep[a], rel=0.06)
        assert indep[a] > 1.15 * true[a]


def test_without_the_covariance_the_white_only_prediction_is_flagged_where_it_is_wrong(validated):
    for ax, d in validated["axes"].items():
        p = d["predicted"]["independent"]
        taus = np.array(d["taus_s"])
        ratio = np.array(d["measured_adev_deg_h"]) / np.array(p["adev_deg_h"])
        assert not p["consistent"], (ax, p["verdict"])
        assert "NOT consistent" in p["verdict"]
        # where white noise rules (tau up to 2.6 s, before the walk and the wide bands) the measured
        # ADEV is below the independent prediction by the correlation's factor (the cancelled
        # common mode), and those tau are flagged, as a correlation, on the side it is wrong
        white = taus <= 2.6
        assert np.all(ratio[white] < 0.87)
        flagged = np.array([v is False for v in p["inside"]])
        assert flagged[white].all()
        named = [m for m in p["misses"] if m["term"] == "correlation"]
        assert named and "correlation" in p["verdict"], p["verdict"]
        assert all(m["side"] == "below" for m in named)
        assert min(m["from_tau_s"] for m in named) <= taus[0] and max(m["to_tau_s"] for m in named) >= 2.5


def test_fit_writes_an_array_table_that_reads_back(tmp_path):
    from gyroarray.effects.model import NoiseModel
    t, g = _simulate(120.0, seed=5)
    path = write_measurement(tmp_path, "fit6", t, g, sidecar=_sidecar())
    out = tmp_path / "m.toml"
    o = run_cli(["fit", path, "--out", out, "--runs", "4", "--json"])
    assert_contract(o)
    assert o.code == 0, o.err
    assert o.json["array_model"]["gyros"] == list(range(1, N_GYRO + 1))
    text = out.read_text()
    assert "[array]" in text
    m = NoiseModel.from_toml(out, n_gyros=N_GYRO)
    assert m.array is not None and m.array.gyros == tuple(range(1, N_GYRO + 1))
    c = np.array(m.array.white_correlation)
    sig = np.array(m.array.sigma["white_correlation"])
    iu = np.triu_indices(N_GYRO, 1)
    assert np.all(np.abs(c - CORR)[iu] <= 4 * sig[iu] + 1e-3)
    # the file is what the JSON says, and the model drives fuse
    with open(out, "rb") as fh:
        assert tomllib.load(fh)["array"]["white_correlation"][0][1] == pytest.approx(c[0, 1])
    o = run_cli(["fuse", path, "--estimator", "gls", "--model", out, "--json"])
    assert o.code == 0, o.err
    assert o.json["design_noise"]["correlated"] is True


def test_gls_weights_with_an_array_table_equal_numpys():
    from gyroarray.core.layout import Layout
    from gyroarray.effects.model import ArrayNoise, ModelEntry, NoiseModel
    from gyroarray.estimators import make
    from gyroarray.estimators.noise import array_noise
    arw_deg = ARW * 180 / np.pi * 60
    entries = [ModelEntry("arw", k + 1, {"n_deg_rt_h": float(arw_deg[k])}) for k in range(N_GYRO)]
    rows = tuple(tuple(float(v) for v in r) for r in CORR)
    # a one-rho correlation entry too: the [array] table must win over it
    plain = NoiseModel(entries + [ModelEntry("correlation", None, {"rho_arw": 0.1})])
    model = plain.with_array(ArrayNoise(gyros=tuple(range(1, N_GYRO + 1)), white_correlation=rows))
    noise = array_noise(model, N_GYRO)
    np.testing.assert_allclose(noise.corr_arw, CORR, atol=0)
    r = CORR * np.outer(ARW, ARW) / DT
    np.testing.assert_allclose(noise.R(DT), r, rtol=1e-12)
    est = make("gls").fit(Layout.from_axes(AXES), noise, DT)
    np.testing.assert_allclose(est.weights_, _gls(AXES, r), rtol=1e-9, atol=1e-12)
    # and not the one-rho weights
    r1 = (0.9 * np.eye(N_GYRO) + 0.1) * np.outer(ARW, ARW) / DT
    assert np.max(np.abs(est.weights_ - _gls(AXES, r1))) > 1e-3
    # a table naming some gyros only: those rows from the table, the rest from the entry
    part = plain.with_array(ArrayNoise(gyros=(5, 6), white_correlation=((1.0, 0.7), (0.7, 1.0))))
    c = array_noise(part, N_GYRO).corr_arw
    assert c[4, 5] == 0.7 and c[0, 1] == pytest.approx(0.1) and c[0, 4] == 0.0


def test_holdout_without_validate_and_bad_holdout_are_one_line_refusals(record):
    for argv in (["--holdout", "0.3"], ["--validate", "--holdout", "1.5"], ["--validate", "--holdout", "0"]):
        o = run_cli(["fuse", record, "--estimator", "gls", *argv])
        assert_contract(o)
        assert o.code == 2 and "--holdout" in o.err and len(o.err.strip().splitlines()) == 1, o.err
