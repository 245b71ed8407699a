"""``gyroarray export``: noise files for Kalibr, OpenVINS, VINS-Fusion, ORB-SLAM3 and MATLAB
(issue 33, item 2 and 3).

Outside checks: each value against a hand computation of the tool's convention, and against
published pairs describing one sensor (the EuRoC MAV IMU, an ADIS16448 at 200 Hz):

* Kalibr/OpenVINS ``config/euroc_mav/kalibr_imu_chain.yaml`` (rpng/open_vins):
  gyroscope_noise_density 1.6968e-04 rad/s/√Hz, gyroscope_random_walk 1.9393e-05 rad/s²/√Hz,
  update_rate 200;
* ORB-SLAM3 ``Examples/Stereo-Inertial/EuRoC.yaml``: IMU.NoiseGyro 1.7e-04 (its comment:
  1.6968e-04), IMU.GyroWalk 1.9393e-05, IMU.Frequency 200: the same continuous densities
  (Tracking.cc multiplies by √200 itself);
* VINS-Fusion ``config/euroc/euroc_stereo_imu_config.yaml``: gyr_n 0.01, gyr_w 0.0001, read as
  per-sample standard deviations (integration_base.h). 0.01 / 1.6968e-4 = 58.9 = √200 (the
  continuous -> discrete conversion) × 4.17 (an inflation the authors chose).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from gyroarray.chain import export as ex
from gyroarray.effects.model import NoiseModel
from hostile import assert_contract, run_cli

EUROC_RATE = 200.0
EUROC_N = 1.6968e-04           # rad/s/√Hz
EUROC_K = 1.9393e-05           # rad/s²/√Hz
VINS_EUROC_GYR_N = 0.01
#: An accelerometer table (VRW m/s/√h, acc. RW m/s²/√h per axis), so that a file is complete.
ACCEL = '\n[accelerometer]\naxes = ["x", "y", "z"]\nn_m_s_rt_h = [0.05, 0.05, 0.05]\nk_m_s2_rt_h = [0.002, 0.002, 0.002]\n'


def _model(tmp_path, text: str, name: str = "m.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _plain(n_deg_rt_h=0.1, k_deg_h_rt_h=2.0, extra=""):
    return (f'effects = [{{effect = "arw", n_deg_rt_h = {n_deg_rt_h!r}}}, '
            f'{{effect = "rrw", k_deg_h_rt_h = {k_deg_h_rt_h!r}}}{extra}]\n')


def _field(text: str, key: str) -> float:
    """The number after ``key:`` (YAML) or ``gyro.key =`` (MATLAB) in a written file."""
    m = re.search(rf"^\s*{re.escape(key)}:\s*([-+0-9.eE]+)", text, re.M) or \
        re.search(rf"^gyro\.{re.escape(key)}\s*=\s*([-+0-9.eE]+);", text, re.M)
    assert m, (key, text)
    return float(m.group(1))


@pytest.mark.parametrize("fmt", list(ex.FORMATS))
def test_each_format_writes_the_hand_computed_numbers(tmp_path, fmt):
    """ARW 0.1 deg/√h and RRW 2 deg/h/√h, converted by hand: density = N·π/180/60,
    walk = K·π/180/3600/60; VINS multiplies the density by √(2·rate) (per-sample σ times the √2 of
    integration_base.h's mid-point covariance, issue 42 item 6: was √rate) and the walk by √rate."""
    rate = 200.0
    n_c = 0.1 * math.pi / 180.0 / 60.0
    k_c = 2.0 * math.pi / 180.0 / 3600.0 / 60.0
    model = _model(tmp_path, _plain())
    out = tmp_path / ("n.m" if fmt == "matlab" else "n.yaml")
    o = run_cli(["export", model, "--format", fmt, "--rate-hz", rate, "--out", out, "--json"])
    assert_contract(o)
    assert o.code == 0
    text = out.read_text()
    keys = {"kalibr": ("gyroscope_noise_density", "gyroscope_random_walk", 1.0, 1.0),
            "openvins": ("gyroscope_noise_density", "gyroscope_random_walk", 1.0, 1.0),
            "orbslam3": ("IMU.NoiseGyro", "IMU.GyroWalk", 1.0, 1.0),
            "vins": ("gyr_n", "gyr_w", math.sqrt(2.0 * rate), math.sqrt(rate)),
            "matlab": ("NoiseDensity", "RandomWalk", 1.0, 1.0)}[fmt]
    assert _field(text, keys[0]) == pytest.approx(n_c * keys[2], rel=1e-6)
    assert _field(text, keys[1]) == pytest.approx(k_c * keys[3], rel=1e-6)
    assert o.json["values"][keys[0]] == pytest.approx(n_c * keys[2], rel=1e-12)
    # the header states the convention, the rate and what is left for the user
    assert ("DISCRETE" if fmt == "vins" else "CONTINUOUS") in text
    assert "200 Hz" in text and "accelerometer" in text and "bias instability" in text
    if fmt == "orbslam3":
        assert "Ng*sf" in text and _field(text, "IMU.Frequency") == rate
    if fmt in ("kalibr", "openvins"):
        assert _field(text, "update_rate") == rate


def test_euroc_published_pairs(tmp_path):
    """The EuRoC IMU as Kalibr/OpenVINS/ORB-SLAM3 publish it round-trips to the same digits;
    VINS-Fusion's published gyr_n is √400 = √2·√200 (the convention, √2 of the mid-point covariance)
    × 2.95 (their inflation) above it (it was √200 × 4.17 before issue 42 item 6's √2)."""
    n_deg_rt_h = EUROC_N * 180.0 / math.pi * 60.0                # 0.5833 deg/√h
    k_deg_h_rt_h = EUROC_K * 180.0 / math.pi * 3600.0 * 60.0     # 240.0 deg/h/√h
    noise = ex.gyro_noise(NoiseModel.from_toml(_model(tmp_path, _plain(n_deg_rt_h, k_deg_h_rt_h))), 1)
    kal = ex.exported_values(noise, "kalibr", EUROC_RATE)
    assert f"{kal['gyroscope_noise_density']:.4e}" == "1.6968e-04"
    assert f"{kal['gyroscope_random_walk']:.4e}" == "1.9393e-05"
    orb = ex.exported_values(noise, "orbslam3", EUROC_RATE)
    assert orb["IMU.NoiseGyro"] == pytest.approx(1.7e-4, rel=2e-3)      # their rounding
    assert orb["IMU.GyroWalk"] == pytest.approx(EUROC_K, rel=1e-9)
    vins = ex.exported_values(noise, "vins", EUROC_RATE)
    assert vins["gyr_n"] / kal["gyroscope_noise_density"] == pytest.approx(math.sqrt(400.0))
    published_ratio = VINS_EUROC_GYR_N / EUROC_N                    # the "59×"
    assert published_ratio == pytest.approx(58.93, abs=0.01)
    inflation = VINS_EUROC_GYR_N / vins["gyr_n"]                    # 58.93 / 20 (was / 14.14 = 4.167)
    assert inflation == pytest.approx(2.946, abs=0.01)
    # all the tools read the same discrete process from their own numbers
    d_kal = ex.tool_discrete("kalibr", kal, EUROC_RATE)
    for fmt in ("openvins", "orbslam3", "vins", "matlab"):
        assert ex.tool_discrete(fmt, ex.exported_values(noise, fmt, EUROC_RATE), EUROC_RATE) == \
            pytest.approx(d_kal, rel=1e-12)


def test_orbslam3_wrong_rate_moves_noise_and_walk_apart():
    """Tracking.cc: Ng·√f and Ngw/√f: a rate 4× too high doubles the white σ and halves the
    bias step (Kalibr #63/#354, imu_utils #36)."""
    v = {"IMU.NoiseGyro": 1e-4, "IMU.GyroWalk": 1e-5}
    w1, b1 = ex.tool_discrete("orbslam3", v, 100.0)
    w4, b4 = ex.tool_discrete("orbslam3", v, 400.0)
    assert w4 / w1 == pytest.approx(2.0) and b4 / b1 == pytest.approx(0.5)


def test_bias_instability_stand_in_bounds_the_floor(tmp_path):
    """K_eq = 0.664·B·√(3/τ1), τ1 where the flicker floor meets the ARW line; the stand-in's
    ADEV is >= the floor for τ >= τ1 and within ×2 up to τ2 = 4·τ1."""
    n, b = 0.2, 5.0                                               # deg/√h, deg/h
    text = _plain(n, 0.0, ', {effect = "bias_instability", b_deg_h = 5.0}')
    noise = ex.gyro_noise(NoiseModel.from_toml(_model(tmp_path, text)), 1)
    si = ex.stand_in(noise, 100.0, keeps_b=False)
    n_si = n * math.pi / 180.0 / 60.0
    floor2 = 2.0 * math.log(2.0) / math.pi * (b * math.pi / 180.0 / 3600.0) ** 2
    assert si.tau1_s == pytest.approx(n_si ** 2 / floor2, rel=0.02)   # 801-point grid
    assert si.k_eq_rad_s_rt_s == pytest.approx(math.sqrt(3.0 * floor2 / si.tau1_s), rel=1e-9)
    taus = np.logspace(math.log10(si.tau1_s), 6, 50)
    line = si.k_eq_rad_s_rt_s ** 2 * taus / 3.0
    assert np.all(line >= floor2 * (1 - 1e-9))
    assert np.sqrt(si.k_eq_rad_s_rt_s ** 2 * si.tau2_s / 3.0 / floor2) == pytest.approx(2.0)
    # MATLAB keeps B itself: no stand-in, BiasInstability = B [rad/s]
    assert ex.stand_in(noise, 100.0, keeps_b=True).covers == ()
    assert ex.exported_values(noise, "matlab", 100.0)["BiasInstability"] == \
        pytest.approx(b * math.pi / 180.0 / 3600.0)
    assert "stand-in random walk" in ex.render(noise, "kalibr", 100.0)


def test_verify_passes_on_white_plus_walk_and_flags_bias_instability(tmp_path):
    """A white + walk model round-trips through every format; a model with a strong flicker
    floor cannot be reproduced by Kalibr's two numbers and is flagged (exit 1, as check)."""
    # an [accelerometer] table: without one the file lacks Kalibr's required accelerometer fields
    # and --verify fails on the re-read (issue 42 item 1; tests/test_export_consumers.py)
    good = _model(tmp_path, _plain(0.5, 20.0) + ACCEL, "good.toml")
    o = run_cli(["export", good, "--format", "kalibr", "--rate-hz", 100, "--out",
                 tmp_path / "g.yaml", "--verify", "--json"])
    assert o.code == 0, o.err
    v = o.json["verify"]
    assert v["passed"] and v["band"]["inside_fraction"] >= 0.9
    assert abs(v["coefficients"]["arw_deg_rt_h"]["z"]) < 3
    bad = _model(tmp_path, _plain(0.5, 0.0, ', {effect = "bias_instability", b_deg_h = 30.0}') + ACCEL,
                 "bi.toml")
    o = run_cli(["export", bad, "--format", "kalibr", "--rate-hz", 100, "--out",
                 tmp_path / "b.yaml", "--verify"])
    assert o.code == 1 and "verify: FAILED" in o.out and "cannot reproduce" in o.out
    assert "Traceback" not in o.err and o.err == ""
    assert (tmp_path / "b.yaml").exists()               # the file is written all the same


def test_round_trip_of_a_pure_walk_finds_the_sampling_term(tmp_path):
    """A walk sampled every dt has Allan variance K²dt(2m²+1)/(6m) (sum of the squared
    weights of its increments in the difference of two m-sample means): a white term
    N² = K²dt²/6 beside K²τ/3. With no ARW in the file, the round trip re-identifies exactly
    that N, and K."""
    noise = ex.gyro_noise(NoiseModel.from_toml(_model(tmp_path, _plain(0.0, 3.0))), 1)
    v = ex.verify_export(noise, "kalibr", 100.0, 1.0, np.random.default_rng(5), seconds=1200)
    k = 3.0 * math.pi / 180.0 / 3600.0 / 60.0
    n_deg_rt_h = k * 0.01 / math.sqrt(6.0) * 180.0 / math.pi * 60.0
    c = v["coefficients"]["arw_deg_rt_h"]
    assert c["file"] == pytest.approx(n_deg_rt_h, rel=1e-9)
    assert c["reidentified"] == pytest.approx(n_deg_rt_h, rel=0.02)
    assert v["passed"], v["problems"]


def test_verify_catches_the_classic_convention_error(tmp_path, monkeypatch):
    """Kalibr's continuous densities pasted into a VINS-Fusion config (read there per sample)
    describe √rate less noise than the gyro has: the round trip must flag it."""
    noise = ex.gyro_noise(NoiseModel.from_toml(_model(tmp_path, _plain(0.5, 20.0))), 1)
    right = ex.verify_export(noise, "vins", 100.0, 1.0, np.random.default_rng(3), seconds=600)
    assert right["passed"], right["problems"]
    real = ex.exported_values

    def pasted(noise_, fmt, rate_hz, inflate=1.0):
        v = real(noise_, "kalibr", rate_hz, inflate)
        return {"gyr_n": v["gyroscope_noise_density"], "gyr_w": v["gyroscope_random_walk"]}
    monkeypatch.setattr(ex, "exported_values", pasted)
    wrong = ex.verify_export(noise, "vins", 100.0, 1.0, np.random.default_rng(3), seconds=600)
    assert not wrong["passed"]
    assert wrong["band"]["file_understates"] > wrong["band"]["n_taus"] // 2


def test_inflate_auto_is_one_for_a_complete_model_and_grows_with_unmodelled_effects(tmp_path):
    """NIS of a white + walk bias filter: ≈1 when the filter's model is the truth; > 1 when
    quantization, which the format cannot hold, is in the record (it shows at one sample)."""
    plain = ex.gyro_noise(NoiseModel.from_toml(_model(tmp_path, _plain(0.5, 5.0), "p.toml")), 1)
    a = ex.auto_inflation(plain, "kalibr", 100.0, np.random.default_rng(1), seconds=1500)
    assert a["factor"] == pytest.approx(1.0, abs=0.05)
    gm = _plain(0.5, 5.0, ', {effect = "quantization", q_deg = 0.002}')
    q = ex.gyro_noise(NoiseModel.from_toml(_model(tmp_path, gm, "q.toml")), 1)
    b = ex.auto_inflation(q, "kalibr", 100.0, np.random.default_rng(1), seconds=1500)
    assert b["factor"] > 1.2
    assert max(b["nis"], key=b["nis"].get) == "0.01"     # quantization shows at one sample
    o = run_cli(["export", _model(tmp_path, gm, "q2.toml"), "--format", "orbslam3", "--rate-hz",
                 100, "--out", tmp_path / "q.yaml", "--inflate", "auto", "--json"])
    assert o.code == 0 and o.json["inflate"] == pytest.approx(o.json["inflate_auto"]["factor"])
    assert "inflation: ×" in (tmp_path / "q.yaml").read_text()


@pytest.mark.parametrize("argv_tail,fragment", [
    (["--format", "kalibr", "--rate-hz", "100", "--out", "x.m"], ".yaml"),
    (["--format", "matlab", "--rate-hz", "100", "--out", "x.yaml"], ".m"),
    (["--format", "kalibr", "--rate-hz", "0", "--out", "x.yaml"], "--rate-hz"),
    (["--format", "kalibr", "--rate-hz", "100", "--out", "x.yaml", "--gyro", "4"], "gyro 4"),
    (["--format", "kalibr", "--rate-hz", "100", "--out", "x.yaml", "--inflate", "0"], "--inflate"),
    (["--format", "ros", "--rate-hz", "100", "--out", "x.yaml"], "--format"),
])
def test_bad_arguments_are_refused_in_one_line(tmp_path, argv_tail, fragment):
    text = ('effects = [{effect = "arw", gyro = 1, n_deg_rt_h = 0.1}, '
            '{effect = "arw", gyro = 2, n_deg_rt_h = 0.2}]\n')
    model = _model(tmp_path, text)
    argv = ["export", model] + [str(tmp_path / a) if a.startswith("x.") else a for a in argv_tail]
    o = run_cli(argv)
    assert_contract(o)
    assert o.code == 2 and fragment in o.err
    assert not list(tmp_path.glob("x.*"))


def test_existing_output_needs_force(tmp_path):
    model = _model(tmp_path, _plain())
    out = tmp_path / "imu.yaml"
    out.write_text("keep me")
    o = run_cli(["export", model, "--format", "kalibr", "--rate-hz", 200, "--out", out])
    assert_contract(o)
    assert o.code == 2 and out.read_text() == "keep me"
    o = run_cli(["export", model, "--format", "kalibr", "--rate-hz", 200, "--out", out, "--force"])
    assert o.code == 0 and "gyroscope_noise_density" in out.read_text()


def test_every_axis_is_read_and_the_worst_is_written_by_default(tmp_path):
    """A 3-gyro model whose z gyro has 2.64x the x gyro's RRW (the ADIS16405's 200.6 against 75.9
    deg/h/√h): by default the file gets gyro 3 and says so, listing every gyro's numbers; --axis 1
    writes gyro 1, --axis mean the mean (hand-computed: (N1 + N2 + N3)/3)."""
    model = _model(tmp_path, "\n".join([
        "effects = [",
        '  {effect = "arw", gyro = 1, n_deg_rt_h = 0.30}, {effect = "rrw", gyro = 1, k_deg_h_rt_h = 75.9},',
        '  {effect = "arw", gyro = 2, n_deg_rt_h = 0.32}, {effect = "rrw", gyro = 2, k_deg_h_rt_h = 120.0},',
        '  {effect = "arw", gyro = 3, n_deg_rt_h = 0.31}, {effect = "rrw", gyro = 3, k_deg_h_rt_h = 200.6},',
        "]"]) + "\n")
    out = tmp_path / "imu.yaml"
    o = run_cli(["export", model, "--format", "kalibr", "--rate-hz", 100, "--out", out, "--json"])
    assert o.code == 0, o.err
    assert o.json["gyro"] == 3 and "worst" in o.json["axis"]
    assert [g["gyro"] for g in o.json["gyros"]] == [1, 2, 3]
    text = out.read_text()
    assert "gyro 3, the worst of the model's 3 gyros" in text.splitlines()[0]
    assert "every gyro of the model" in text
    k3 = 200.6 * math.pi / 180 / 3600 / 60
    assert o.json["values"]["gyroscope_random_walk"] == pytest.approx(k3, rel=1e-12)
    one = run_cli(["export", model, "--format", "kalibr", "--rate-hz", 100, "--out", tmp_path / "one.yaml",
                   "--axis", "1", "--json"])
    assert one.code == 0 and one.json["gyro"] == 1
    mean = run_cli(["export", model, "--format", "kalibr", "--rate-hz", 100, "--out", tmp_path / "mean.yaml",
                    "--axis", "mean", "--json"])
    assert mean.code == 0, mean.err
    n_mean = (0.30 + 0.32 + 0.31) / 3 * math.pi / 180 / 60
    assert mean.json["values"]["gyroscope_noise_density"] == pytest.approx(n_mean, rel=1e-12)
    bad = run_cli(["export", model, "--format", "kalibr", "--rate-hz", 100, "--out", tmp_path / "b.yaml",
                   "--axis", "sideways"])
    assert bad.code == 2 and "--axis" in bad.err
