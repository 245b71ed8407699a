"""The accelerometer: ``allan --sensor acc|all``, ``fit --out``'s ``[accelerometer]`` table and
:class:`~gyroarray.effects.model.AccelNoise` (issue 42, item 2).

Outside checks: allantools' OADEV of the same numpy record (white specific force plus a random
walk, written here with plain numpy, not gyroarray's simulator), the truth the record was drawn
with, datasheet conversions worked by hand, and the real ADIS16405 record held out by halves.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import special

from gyroarray.analysis.accel import accel_analyses, accel_fit
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, write_measurement
from gyroarray.effects.model import AccelNoise, NoiseModel
from hostile import assert_contract, run_cli

ADIS = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "adis16405_imu.csv.gz"
if not ADIS.exists():                                   # the checkout's own shared/ (device copies)
    ADIS = Path(__file__).resolve().parents[1] / "shared" / "measurements" / "real" / "adis16405_imu.csv.gz"

DT = 0.01                                               # [s], 100 Hz
N_A = 1e-3                                              # VRW [m/s²/√Hz] = 0.06 m/s/√h
K_A = 5.8e-5                                            # acc RW [m/s²/√s] = 3.48e-3 m/s²/√h
G0 = 9.80665                                            # [m/s²] gravity's offset on z
#: z of a two-sided 99.7 % interval: √2·erfinv(0.997) = 2.968.
Z997 = float(math.sqrt(2.0) * special.erfinv(0.997))


def _acc_record(n: int, seed: int, n_a: float = N_A, k_a: float = K_A) -> np.ndarray:
    """White specific force (PSD level n_a²) plus a random walk (k_a²/s per second), (n, 3) [m/s²]."""
    rng = np.random.default_rng(seed)
    white = n_a / math.sqrt(DT) * rng.standard_normal((n, 3))
    walk = np.cumsum(k_a * math.sqrt(DT) * rng.standard_normal((n, 3)), axis=0)
    return white + walk


def _write(tmp_path, name: str, n: int, seed: int, acc: bool = True) -> Path:
    rng = np.random.default_rng(seed + 1)
    gyro = np.degrees(1e-4 / math.sqrt(DT) * rng.standard_normal((n, 3)))     # [deg/s]
    a = _acc_record(n, seed) + np.array([0.0, 0.0, G0]) if acc else None
    m = Measurement(time_s=np.arange(n) * DT, gyro_deg_s=gyro, layout=Layout(np.eye(3)),
                    sample_rate_hz=1.0 / DT, acc_m_s2=a)
    csv, _ = write_measurement(m, tmp_path / name)
    return csv


# ---------------------------------------------------------------- (a) numpy record, allantools


def test_datasheet_conversions_by_hand():
    """N_a = 0.06 m/s/√h: 0.06 m/s / √(3600 s) = 0.001 m/s/√s = 0.001 m/s²/√Hz; the same factor
    60 = √3600 for K_a; 1 mg = 1e-3 · 9.80665 m/s²."""
    assert units.vrw_m_s_rt_h_to_si(0.06) == pytest.approx(0.001, rel=1e-15)
    assert units.vrw_si_to_m_s_rt_h(0.001) == pytest.approx(0.06, rel=1e-15)
    assert units.accel_rw_m_s2_rt_h_to_si(0.06) == pytest.approx(0.001, rel=1e-15)
    assert units.accel_rw_si_to_m_s2_rt_h(5.8e-5) == pytest.approx(3.48e-3, rel=1e-15)
    assert units.mg_to_m_s2(1.0) == pytest.approx(9.80665e-3, rel=1e-15)
    assert units.m_s2_to_mg(9.80665) == pytest.approx(1000.0, rel=1e-15)


@pytest.mark.slow   # allantools on three long axes (12 s): make score
def test_acc_adev_equals_allantools_and_gravity_changes_nothing():
    """Our OADEV of each axis equals allantools.oadev (frequency data, the same taus) to 1e-12
    relative (measured 2.7e-15; both are sums of the same second differences, rounding apart);
    adding 9.80665 m/s² to z changes neither the curve (to 1e-12: the constant cancels in every
    difference, only the phase's rounding moves, measured 1e-14) nor the fitted terms."""
    allantools = pytest.importorskip("allantools")
    acc = _acc_record(400_000, seed=42)
    with_g = acc + np.array([0.0, 0.0, G0])
    plain, _ = accel_analyses(acc, DT)
    grav, _ = accel_analyses(with_g, DT)
    assert set(plain) == set(grav) == {"x", "y", "z"}
    for i, axis in enumerate("xyz"):
        a, g = plain[axis], grav[axis]
        taus, adev, _, _ = allantools.oadev(with_g[:, i], rate=1.0 / DT, data_type="freq", taus=g.taus_s)
        np.testing.assert_allclose(taus, g.taus_s, rtol=1e-12)
        np.testing.assert_allclose(g.adev_rad_s, adev, rtol=1e-12, atol=0.0)
        np.testing.assert_allclose(g.adev_rad_s, a.adev_rad_s, rtol=1e-12, atol=0.0)
        for term in ("n", "k"):
            np.testing.assert_allclose(g.fit.coefficient(term)[0], a.fit.coefficient(term)[0], rtol=1e-9)


def test_vrw_and_acc_rw_fitted_within_their_stated_sigma_of_the_truth():
    """N_a and K_a of each axis within z(99.7 %)·σ = 2.97σ of the truth the record was drawn
    with, σ the fit's own 1σ. Derivation: the GLS fit is unbiased for these terms and its 1σ is
    honest (the z-scores of the same fit have standard deviations 0.94–1.02 on simulated
    records, tests/test_allan_fit.py; tests/test_plan.py checks the same 1σ against the spread
    of fits), so each |z| <= 2.97 with probability 0.997 (measured |z| <= 2.1, six values). The
    JSON carries the same numbers in datasheet units; BI (not in the record) is not given, and
    the notes say why, never a 0."""
    acc = _acc_record(400_000, seed=42) + np.array([0.0, 0.0, G0])
    fit = accel_fit(acc, DT)
    assert fit.axes == ("x", "y", "z")
    for term, truth in (("n", N_A), ("k", K_A)):
        values, sigmas = fit.values[term], fit.sigmas[term]
        assert values is not None and len(values) == 3
        for v, s in zip(values, sigmas):
            assert 0.0 < s < 0.25 * truth                     # resolved: well inside its truth
            assert abs(v - truth) <= Z997 * s, (term, v, s, truth)
    d = fit.to_json_dict()
    np.testing.assert_allclose(d["vrw_m_s_rt_h"], [60.0 * v for v in fit.values["n"]], rtol=1e-15)
    np.testing.assert_allclose(d["accel_rw_m_s2_rt_h_sigma"], [60.0 * s for s in fit.sigmas["k"]], rtol=1e-15)
    assert fit.values["b"] is None and d["bi_mg"] is None
    assert any(n.startswith("bi_mg [mg] not resolved") for n in fit.notes)


# ---------------------------------------------------------------- (b) the real ADIS16405


@pytest.fixture(scope="module")
def adis_acc():
    if not ADIS.exists():
        pytest.skip("shared/measurements/real not present")
    from gyroarray.core.measurement import read_measurement
    return read_measurement(ADIS)


def test_adis_allan_sensor_acc_json_gives_every_term_with_its_ci():
    """``allan --sensor acc --json`` on the ADIS16405 (2.78 h, 100 Hz, acc in m/s², z about
    -1.016 g): VRW, acc RW and BI on every axis, each with a 1σ well below its value (resolved),
    and every ADEV inside its confidence interval. The values are those of a MEMS IMU of this
    class (VRW 0.22–0.28 m/s/√h, BI 0.30–0.41 mg, acc RW 0.013–0.021 m/s²/√h as measured)."""
    o = run_cli(["allan", ADIS, "--sensor", "acc", "--json"], timeout=300)
    assert_contract(o)
    assert o.code == 0, o.err
    out = json.loads(o.out)
    terms = out["terms"]
    assert terms["axes"] == ["x", "y", "z"]
    for key, lo, hi in (("vrw_m_s_rt_h", 0.1, 0.5), ("bi_mg", 0.1, 1.0), ("accel_rw_m_s2_rt_h", 0.003, 0.06)):
        for v, s in zip(terms[key], terms[key + "_sigma"]):
            assert lo < v < hi and 0.0 < s < 0.5 * v, (key, v, s)
    for axis, d in out["axes"].items():
        adev, low, high = (np.array(d[k]) for k in ("adev_m_s2", "ci_low_m_s2", "ci_high_m_s2"))
        assert np.all(low < adev) and np.all(adev < high)
        assert d["confidence"] == pytest.approx(0.6827, abs=1e-4) and len(adev) >= 15
        assert d["fit"]["vrw_m_s_rt_h_resolved"]


def _prediction_z(first, second) -> np.ndarray:
    """z of the second half's Allan variance against the first half's fitted model, per tau.

    The band's relative 1σ on the variance combines the second half's own scatter (2/ν, ν its
    EDF), the first half's fitted model error ε (the relative misfit the fit adds so that its
    χ² equals its dof) and the first half's coefficient covariance carried to the curve.
    """
    from gyroarray.analysis.noise_fit import TERM_EXPONENTS, TERMS
    fit = first.fit
    taus = second.taus_s
    model = fit.model_avar(taus)
    g = np.array([[t ** TERM_EXPONENTS[k] for k in TERMS] for t in taus])
    param = np.einsum("ij,jk,ik->i", g, fit.coef_cov, g)
    rel = np.sqrt(2.0 / second.edf + fit.model_error ** 2 + param / model ** 2)
    return np.log(second.adev_rad_s ** 2 / model) / rel


def test_adis_acc_fit_on_the_first_half_holds_on_the_second(adis_acc):
    """The house rule: the accelerometer terms fitted on the first 1.39 h predict the ADEV of
    the other 1.39 h. Every tau up to 164 s (each half's EDF >= 34 there) lies within the
    99.7 % band (|z| <= 2.97; measured max 2.6, at 0.64 s on y); over all taus at least 2/3 of
    them per axis (measured 15/18, 18/18, 16/18). The fraction is not the band's 99.7 %: at
    328–1311 s the second half of x and z is quieter than the first half's fit, which holds the
    warm-up drift (z = -3.0 to -3.6 there: the record is not stationary on those scales); the
    2/3 leaves those top octaves (EDF < 20) and no more."""
    acc = adis_acc.acc_m_s2
    half = acc.shape[0] // 2
    first, _ = accel_analyses(acc[:half], adis_acc.dt_s)
    second, _ = accel_analyses(acc[half:], adis_acc.dt_s)
    for axis in "xyz":
        a, b = first[axis], second[axis]
        np.testing.assert_allclose(a.taus_s, b.taus_s)
        z = _prediction_z(a, b)
        short = b.taus_s <= 164.0
        assert np.all(np.abs(z[short]) <= Z997), (axis, z)
        assert np.mean(np.abs(z) <= Z997) >= 2.0 / 3.0, (axis, z)


# ---------------------------------------------------------------- (c) fit --out


def test_accel_noise_round_trips_through_toml_exactly(tmp_path):
    table = AccelNoise(axes=("x", "y", "z"), n_m_s_rt_h=(0.28, 0.215, 0.2755), k_m_s2_rt_h=(0.0213, 0.0156, 0.0126),
                       b_mg=(0.406, 0.315, 0.299), sigma={"n_m_s_rt_h": (0.016, 0.0095, 0.0104)},
                       notes=("fitted here", "quote \" and ü"))
    model = NoiseModel((), description="d", accelerometer=table, topic="/imu0")
    path = tmp_path / "m.toml"
    path.write_text(model.to_toml())
    back = NoiseModel.from_toml(path)
    assert back == model and back.accelerometer == table and back.topic == "/imu0"
    assert back.accelerometer.missing == ()
    partial = AccelNoise(axes=("z",), n_m_s_rt_h=(0.06,))
    assert partial.missing == ("k_m_s2_rt_h", "b_mg")
    text = NoiseModel((), accelerometer=partial).to_toml()
    assert "k_m_s2_rt_h" not in text and "b_mg" not in text           # absent, never 0
    path.write_text(text)
    assert NoiseModel.from_toml(path).accelerometer == partial


@pytest.mark.slow   # two fits with the per-axis accelerometer plans and the noise bounds (17 s): make score
def test_fit_out_writes_the_accelerometer_table_and_says_what_is_missing(tmp_path):
    """A record with acc columns: ``fit --out`` writes ``[accelerometer]``, read back equal to
    the JSON's table; its VRW within 2.97σ of the 0.06 m/s/√h drawn; the acc RW and BI a 200 s
    record cannot resolve are left out and named. A record without acc columns: no table, and
    the JSON, the notes and the model's description name the three missing fields."""
    csv = _write(tmp_path, "acc.csv", 20_000, seed=3)
    out = tmp_path / "M.toml"
    o = run_cli(["fit", csv, "--out", out, "--json"], timeout=300)
    assert_contract(o)
    assert o.code == 0, o.err
    res = json.loads(o.out)
    back = NoiseModel.from_toml(out)
    table = back.accelerometer
    assert table is not None and table.to_dict() == res["accelerometer"]
    assert table == AccelNoise.from_dict(res["accelerometer"])
    for v, s in zip(table.n_m_s_rt_h, table.sigma["n_m_s_rt_h"]):
        assert abs(v - 0.06) <= Z997 * s, (v, s)
    assert res["accelerometer_missing"] == list(table.missing)
    assert res["accelerometer_missing_axes"] == {k: list(v) for k, v in table.missing_axes.items()}
    assert all(res["accelerometer_missing_axes"][k] == list(table.axes) for k in table.missing)
    for key in table.missing:
        assert any(n.startswith(key) for n in table.notes)

    bare = _write(tmp_path, "bare.csv", 20_000, seed=3, acc=False)
    out2 = tmp_path / "M2.toml"
    o = run_cli(["fit", bare, "--out", out2, "--json"], timeout=300)
    assert o.code == 0, o.err
    res = json.loads(o.out)
    model = NoiseModel.from_toml(out2)
    assert model.accelerometer is None and res["accelerometer"] is None
    assert res["accelerometer_missing"] == ["n_m_s_rt_h", "k_m_s2_rt_h", "b_mg"]
    assert res["accelerometer_missing_axes"] == {k: ["x", "y", "z"] for k in res["accelerometer_missing"]}
    said = [n for n in res["notes"] if "no [accelerometer] table" in n]
    assert said and all(k in said[0] for k in res["accelerometer_missing"])
    assert "no [accelerometer] table" in model.description
    assert "[accelerometer]" not in out2.read_text().replace(model.description, "")


# ---------------------------------------------------------------- (d) bad tables


@pytest.mark.parametrize("body,column,line,fragment", [
    ('axes = ["x"]\nn_m_s_rt_h = [0.06]\nvrw = [0.1]\n', "accelerometer.vrw", 6, "unknown key 'vrw'"),
    ('axes = ["x", "y"]\nn_m_s_rt_h = [0.06]\n', "accelerometer.n_m_s_rt_h", 5, "2 numbers"),
    ('axes = ["x"]\nb_mg = [-0.3]\n', "accelerometer.b_mg", 5, "b_mg[0] must be a finite number > 0"),
    ('axes = ["x"]\nb_mg = [0.0]\n', "accelerometer.b_mg", 5, "> 0"),
    ('axes = ["x"]\nn_m_s_rt_h = [0.06]\nsigma = {k_m_s2_rt_h = [0.001]}\n',
     "accelerometer.sigma.k_m_s2_rt_h", 6, "a 1σ needs its term"),
    ('axes = ["x", "w"]\n', "accelerometer.axes", 4, "axes must be"),
])
def test_bad_accelerometer_tables_are_refused_with_file_line_and_column(tmp_path, body, column, line, fragment):
    path = tmp_path / "bad.toml"
    path.write_text('description = "x"\neffects = []\n[accelerometer]\n' + body)
    with pytest.raises(InputError) as err:
        NoiseModel.from_toml(path)
    e = err.value
    assert e.file == str(path) and e.column == column and e.line == line, (e.file, e.line, e.column)
    assert fragment in e.message, e.message
    o = run_cli(["plan", "--sensor", "acc", "--model", path, "--rate-hz", 100])
    assert_contract(o, str(path))
    assert o.code == 2 and f"line {line}" in o.err


# ---------------------------------------------------------------- (e) and the CLI's output


def test_allan_sensor_acc_without_acc_columns_is_refused_in_one_line(tmp_path):
    bare = _write(tmp_path, "bare.csv", 2_000, seed=5, acc=False)
    for sensor in ("acc", "all"):
        o = run_cli(["allan", bare, "--sensor", sensor])
        assert_contract(o, str(bare))
        assert o.code == 2 and "no accelerometer columns" in o.err
    o = run_cli(["allan", _write(tmp_path, "acc.csv", 2_000, seed=5), "--sensor", "acc", "--gyro", 1])
    assert_contract(o)
    assert o.code == 2 and "--gyro" in o.err


@pytest.mark.parametrize("kind", ["oadev", "hdev"])
def test_allan_sensor_all_json_is_coherent_and_text_names_its_columns(tmp_path, kind):
    """``--sensor all``: the gyros as ``--sensor gyro`` gives them and the accelerometer as
    ``--sensor acc`` gives it, under ``accelerometer``; the text heads each table by the kind
    and the unit (``oadev_deg_h`` for the gyros, ``oadev_m_s2`` for the accelerometer)."""
    csv = _write(tmp_path, "acc.csv", 6_000, seed=7)
    both = run_cli(["allan", csv, "--sensor", "all", "--kind", kind, "--json"])
    gyro = run_cli(["allan", csv, "--kind", kind, "--json"])
    acc = run_cli(["allan", csv, "--sensor", "acc", "--kind", kind, "--json"])
    for o in (both, gyro, acc):
        assert_contract(o)
        assert o.code == 0, o.err
    both, gyro, acc = (json.loads(o.out) for o in (both, gyro, acc))
    assert both["gyros"] == gyro["gyros"]
    assert both["accelerometer"]["axes"] == acc["axes"] and both["accelerometer"]["terms"] == acc["terms"]
    assert set(both["accelerometer"]["axes"]) == {"x", "y", "z"}
    text = run_cli(["allan", csv, "--sensor", "all", "--kind", kind]).out
    heads = [line.split() for line in text.splitlines() if line.strip().startswith("tau_s")]
    assert heads.count(["tau_s", f"{kind}_deg_h", "ci_low", "ci_high"]) == 3
    assert heads.count(["tau_s", f"{kind}_m_s2", "ci_low", "ci_high"]) == 3
    assert "acc_z (" in text and "m/s/rt(h)" in text
