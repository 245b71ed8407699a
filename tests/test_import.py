"""``gyroarray import imu_utils|allan_variance_ros FILE``: the tools users come from, read with
their true meanings (issue 42, item 7).

The files below are hand-written in each tool's real output layout:

* imu_utils: ``src/imu_an.cpp`` ``writeYAML`` (github.com/gaowenliang/imu_utils, commit 2cdda91,
  the layout of its ``data/A3_imu_param.yaml``): OpenCV ``%YAML:1.0``, ``type``, ``name``, ``Gyr`` and
  ``Acc`` with ``unit`` and ``avg-axis``/``x-axis``/``y-axis``/``z-axis`` maps. Meanings from
  ``src/gyr_lib/fitallan_gyr.cpp``: ``gyr_n = sqrt(freq)·σ_fit(1 s)`` (one sample's σ [rad/s]),
  ``gyr_w = min σ_fit(τ)`` (the ADEV floor, 0.664·B).
* allan_variance_ros: ``scripts/analysis.py`` (github.com/ori-drs/allan_variance_ros, commit
  1d54b60): ``yaml_file.write("accelerometer_noise_density: " + repr(worst...) + " \\n")``, so with
  numpy >= 2 ``np.float64(...)`` and a trailing space; ``rostopic`` / ``update_rate`` with
  ``#Make sure this is correct`` when written without ``--config``.

Expected numbers are hand arithmetic: 1 rad = 180/π deg, √h = 60 √s, h = 3600 s,
√(2 ln2/π) = 0.6642824703 (IEEE Std 952's flicker floor), 1 mg = 9.80665e-3 m/s².
"""

from __future__ import annotations

import json
import math
import re

import pytest

from gyroarray.chain.importers import FLICKER_ADEV, import_noise
from gyroarray.core.errors import InputError
from gyroarray.effects.model import NoiseModel
from hostile import assert_contract, run_cli

# Float tolerance of a conversion chain of a few multiplications: a few ulp; 1e-12 relative.
EXACT = 1e-12
# Hand-computed literals below are given to 9+ significant digits: 1e-8 relative.
LITERAL = 1e-8
# export writes "%.6e" (7 significant digits): at most 0.5e-6 relative rounding.
WRITTEN = 1e-6

IMU_UTILS = """%YAML:1.0
---
type: IMU
name: "hand"
Gyr:
   unit: " rad/s"
   avg-axis:
      gyr_n: 4.0000000000000000e-03
      gyr_w: 4.0000000000000000e-05
   x-axis:
      gyr_n: 2.0000000000000000e-03
      gyr_w: 2.0000000000000000e-05
   y-axis:
      gyr_n: 4.0000000000000000e-03
      gyr_w: 4.0000000000000000e-05
   z-axis:
      gyr_n: 6.0000000000000000e-03
      gyr_w: 6.0000000000000000e-05
Acc:
   unit: " m/s^2"
   avg-axis:
      acc_n: 4.0000000000000000e-02
      acc_w: 2.0000000000000000e-03
   x-axis:
      acc_n: 2.0000000000000000e-02
      acc_w: 1.0000000000000000e-03
   y-axis:
      acc_n: 4.0000000000000000e-02
      acc_w: 2.0000000000000000e-03
   z-axis:
      acc_n: 6.0000000000000000e-02
      acc_w: 3.0000000000000000e-03
"""

AVR = """#Accelerometer
accelerometer_noise_density: np.float64(0.002) 
accelerometer_random_walk: np.float64(5e-05) 

#Gyroscope
gyroscope_noise_density: np.float64(0.0001) 
gyroscope_random_walk: np.float64(1e-06) 

rostopic: '/sensors/imu' #Make sure this is correct
update_rate: 400.0 #Make sure this is correct

"""

# the same, as analysis.py writes it with --config (numpy < 2: plain repr)
AVR_CONFIG = """#Accelerometer
accelerometer_noise_density: 0.002 
accelerometer_random_walk: 5e-05 

#Gyroscope
gyroscope_noise_density: 0.0001 
gyroscope_random_walk: 1e-06 

rostopic: '/alphasense/imu' 
update_rate: 200.0 

"""

RATE = 400.0          # √400 = 20 exactly


def _write(tmp_path, text, name="tool.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _rel(a, b):
    return abs(a - b) / abs(b)


def _line_of(text: str, needle: str) -> int:
    """1-based line of the first line containing ``needle``."""
    return next(i for i, line in enumerate(text.split("\n"), 1) if needle in line)


def test_imu_utils_per_axis_values_are_per_sample_sigma_and_adev_floor(tmp_path):
    """gyr_n 2e-3 rad/s per sample at 400 Hz: N = 2e-3/20 = 1e-4 rad/√s = 1e-4·(180/π)·60 =
    0.343774677 deg/√h. gyr_w 2e-5 rad/s is the ADEV floor 0.664·B: B = 2e-5/0.66428 =
    3.0108e-5 rad/s = 6.21015353 deg/h (not a random walk: no rrw entry)."""
    model, summary = import_noise(_write(tmp_path, IMU_UTILS), "imu_utils", RATE)
    got = {(e.effect, e.gyro): e.params for e in model.entries}
    assert set(got) == {(eff, g) for eff in ("arw", "bias_instability") for g in (1, 2, 3)}
    for gyro, n_deg, b_deg in ((1, 0.343774677, 6.21015353), (2, 0.687549354, 12.4203071),
                               (3, 1.03132403, 18.6304606)):
        assert _rel(got[("arw", gyro)]["n_deg_rt_h"], n_deg) < LITERAL
        assert _rel(got[("bias_instability", gyro)]["b_deg_h"], b_deg) < LITERAL
    # SI beside the datasheet units: the model's own converters give the rad values back
    assert _rel(model.entries[0].si_params["n_rad_rt_s"], 1e-4) < EXACT
    assert _rel(model.entries[1].si_params["b_rad_s"], 2e-5 / 0.6642824703) < 1e-9
    assert abs(FLICKER_ADEV - 0.6642824703) < 1e-10
    # accelerometer: acc_n 2e-2 m/s² per sample -> N_a = 1e-3 m/s/√s = 0.06 m/s/√h; acc_w 1e-3 m/s²
    # floor -> B_a = 1e-3/0.66428 m/s² = 0.153506416 mg
    acc = model.accelerometer
    assert acc is not None and acc.axes == ("x", "y", "z")
    assert [_rel(a, b) < EXACT for a, b in zip(acc.n_m_s_rt_h, (0.06, 0.12, 0.18))] == [True] * 3
    assert [_rel(a, b) < LITERAL for a, b in zip(acc.b_mg, (0.153506416, 0.307012832, 0.460519248))] \
        == [True] * 3
    assert acc.k_m_s2_rt_h is None and acc.missing == ("k_m_s2_rt_h",)
    # where each number came from is in the model itself
    assert "gyr_n/√(400 Hz)" in model.description and "not a random walk" in model.description
    assert "avg-axis (not used): gyr_n 0.004, gyr_w 4e-05" in model.description
    assert any("k_m_s2_rt_h missing" in n for n in acc.notes)
    assert summary["gyros"][0]["axis"] == "x" and summary["rate_hz"] == RATE


def test_imu_utils_avg_axis_only_is_one_entry_for_every_gyro(tmp_path):
    text = re.sub(r"   [xyz]-axis:\n(      \w+: [^\n]*\n){2}", "", IMU_UTILS)
    assert "x-axis" not in text
    model, _ = import_noise(_write(tmp_path, text), "imu_utils", RATE)
    got = {(e.effect, e.gyro): e.params for e in model.entries}
    assert set(got) == {("arw", None), ("bias_instability", None)}
    # avg gyr_n 4e-3 at 400 Hz: N = 2e-4 rad/√s = 0.687549354 deg/√h
    assert _rel(got[("arw", None)]["n_deg_rt_h"], 0.687549354) < LITERAL
    assert model.accelerometer.n_m_s_rt_h == (0.12, 0.12, 0.12)


def test_allan_variance_ros_worst_axis_densities(tmp_path):
    """gyroscope_noise_density 1e-4 rad/s/√Hz = N = 0.343774677 deg/√h; gyroscope_random_walk
    1e-6 rad/s²/√Hz = K = 1e-6·(180/π)·3600·60 = 12.3758884 deg/h/√h; accelerometer 2e-3 m/s²/√Hz
    = 0.12 m/s/√h, 5e-5 m/s³/√Hz = 0.003 m/s²/√h. The np.float64(...) repr is read as the number;
    the default topic (no --config) is not taken."""
    model, summary = import_noise(_write(tmp_path, AVR), "allan_variance_ros")
    got = {(e.effect, e.gyro): e.params for e in model.entries}
    assert set(got) == {("arw", None), ("rrw", None)}
    assert _rel(got[("arw", None)]["n_deg_rt_h"], 0.343774677) < LITERAL
    assert _rel(got[("rrw", None)]["k_deg_h_rt_h"], 12.3758884) < LITERAL
    acc = model.accelerometer
    assert [_rel(v, 0.12) < EXACT for v in acc.n_m_s_rt_h] == [True] * 3
    assert [_rel(v, 0.003) < EXACT for v in acc.k_m_s2_rt_h] == [True] * 3
    assert acc.missing == ("b_mg",)
    assert model.topic is None and "default" in " ".join(summary["notes"])
    assert "worst axis" in model.description

    with_config, _ = import_noise(_write(tmp_path, AVR_CONFIG, "c.yaml"), "allan_variance_ros")
    assert with_config.topic == "/alphasense/imu"
    assert [e.params for e in with_config.entries] == [e.params for e in model.entries]


def test_cli_writes_a_model_that_reads_back_equal(tmp_path):
    src = _write(tmp_path, IMU_UTILS)
    before = src.read_bytes()
    out = tmp_path / "m.toml"
    o = run_cli(["import", "imu_utils", src, "--rate-hz", "400", "--out", out, "--json"])
    assert o.code == 0, o.err
    res = json.loads(o.out)
    assert res["out"] == str(out) and len(res["effects"]) == 6
    direct, _ = import_noise(src, "imu_utils", RATE)
    assert NoiseModel.from_toml(out) == direct
    assert NoiseModel.from_toml(out).accelerometer == direct.accelerometer
    assert src.read_bytes() == before
    o = run_cli(["import", "imu_utils", src, "--rate-hz", "400", "--out", out])
    assert_contract(o, "--force")          # an existing output needs --force
    text = run_cli(["import", "allan_variance_ros", _write(tmp_path, AVR, "a.yaml"), "--out",
                    tmp_path / "a.toml"])
    assert text.code == 0 and "RRW 12.376 deg/h/√h" in text.out, text.out


def _kalibr(tmp_path, model, rate, *extra):
    out = tmp_path / f"k{len(list(tmp_path.iterdir()))}.yaml"
    o = run_cli(["export", model, "--format", "kalibr", "--rate-hz", rate, "--out", out, *extra])
    assert o.code == 0, o.err
    text = out.read_text()

    def field(key):
        m = re.search(rf"^{key}:\s*([-+0-9.eE]+)", text, re.M)
        assert m, (key, text)
        return float(m.group(1))
    return field


def test_round_trip_to_kalibr_gives_the_tools_meaning(tmp_path):
    """import, then export --format kalibr.

    imu_utils x axis at 400 Hz: gyroscope_noise_density = gyr_n/√400 = 1e-4 rad/s/√Hz (pasting
    gyr_n as the density would be ×20 too large). imu_utils has no random walk; Kalibr's walk is
    export's stand-in for the bias instability: a flat floor u = (0.664·B)² = gyr_w² meets the ARW
    line N²/τ at τ₁ = N²/gyr_w² (25 s), and K_eq² = 3·u/τ₁, so K_eq = √3·gyr_w²/N =
    √3·4e-10/1e-4 = 6.92820323e-6 rad/s²/√Hz: 2.9× below gyr_w = 2e-5, the number users paste.

    allan_variance_ros: the densities, the accelerometer's too, come back as written (the same
    convention)."""
    model = tmp_path / "iu.toml"
    assert run_cli(["import", "imu_utils", _write(tmp_path, IMU_UTILS), "--rate-hz", "400",
                    "--out", model]).code == 0
    field = _kalibr(tmp_path, model, "400", "--axis", "1")
    assert _rel(field("gyroscope_noise_density"), 2e-3 / 20.0) < WRITTEN
    assert _rel(field("gyroscope_random_walk"), math.sqrt(3) * (2e-5) ** 2 / 1e-4) < WRITTEN
    assert _rel(field("update_rate"), 400.0) < EXACT
    # the accelerometer, the worst axis (z): acc_n 6e-2 m/s² per sample -> 6e-2/20 = 3e-3 m/s²/√Hz;
    # its walk is the stand-in for the floor acc_w 3e-3 m/s²: √3·(3e-3)²/3e-3 = 5.19615242e-3
    assert _rel(field("accelerometer_noise_density"), 6e-2 / 20.0) < WRITTEN
    assert _rel(field("accelerometer_random_walk"), math.sqrt(3) * 3e-3 ** 2 / 3e-3) < WRITTEN

    model = tmp_path / "avr.toml"
    assert run_cli(["import", "allan_variance_ros", _write(tmp_path, AVR, "a.yaml"),
                    "--out", model]).code == 0
    field = _kalibr(tmp_path, model, "400")
    assert _rel(field("gyroscope_noise_density"), 1e-4) < WRITTEN
    assert _rel(field("gyroscope_random_walk"), 1e-6) < WRITTEN
    assert _rel(field("accelerometer_noise_density"), 2e-3) < WRITTEN
    assert _rel(field("accelerometer_random_walk"), 5e-5) < WRITTEN


def _refused(tmp_path, tool, text, *extra, name=None):
    src = _write(tmp_path, text, "bad.yaml")
    out = tmp_path / "never.toml"
    o = run_cli(["import", tool, src, "--out", out, *extra])
    assert_contract(o, name)
    assert o.code == 2, (o.code, o.out)
    assert not out.exists()
    return o.err.strip()


def test_imu_utils_needs_the_rate(tmp_path):
    err = _refused(tmp_path, "imu_utils", IMU_UTILS, name="--rate-hz")
    assert "per-sample standard deviations" in err
    with pytest.raises(InputError, match="--rate-hz"):
        import_noise(_write(tmp_path, IMU_UTILS), "imu_utils", None)


@pytest.mark.parametrize("tool, text, needle, what", [
    ("imu_utils", IMU_UTILS.replace("      gyr_n: 4.0000000000000000e-03\n      gyr_w: 4.0000000000000000e-05\n   z",
                                    "      gyr_m: 4.0000000000000000e-03\n      gyr_w: 4.0000000000000000e-05\n   z"),
     "gyr_m", "did you mean 'gyr_n'"),
    ("imu_utils", IMU_UTILS.replace("gyr_w: 6.0000000000000000e-05", "gyr_w: 0.0"), "gyr_w: 0.0",
     "positive"),
    ("imu_utils", IMU_UTILS.replace("acc_n: 2.0000000000000000e-02", "acc_n: fast"), "acc_n: fast",
     "must be a number"),
    ("imu_utils", IMU_UTILS.replace('unit: " rad/s"', 'unit: " deg/s"'), "deg/s", "unit"),
    ("imu_utils", AVR, "accelerometer_noise_density", "allan_variance_ros"),
    ("allan_variance_ros", AVR.replace("gyroscope_random_walk", "gyroscope_randomwalk"),
     "gyroscope_randomwalk", "did you mean 'gyroscope_random_walk'"),
    ("allan_variance_ros", AVR.replace("np.float64(1e-06)", "np.float64(-1e-06)"), "-1e-06", "positive"),
    ("allan_variance_ros", AVR.replace("np.float64(0.0001)", ".nan"), ".nan", "finite"),
    ("allan_variance_ros", IMU_UTILS.replace("%YAML:1.0\n", ""), "type: IMU", "imu_utils"),
])
def test_bad_fields_are_refused_at_their_line(tmp_path, tool, text, needle, what):
    err = _refused(tmp_path, tool, text, "--rate-hz", "400")
    line = _line_of(text, needle)
    assert f"line {line}," in err and "column " in err, (err, line)
    assert what in err, err


def test_not_yaml_and_unsafe_tags_are_refused(tmp_path):
    err = _refused(tmp_path, "allan_variance_ros", "gyroscope_noise_density: [1e-4\nupdate_rate: 2\n")
    assert "not valid YAML" in err and "line " in err
    marker = tmp_path / "ran"
    evil = f'gyroscope_noise_density: !!python/object/apply:os.system ["touch {marker}"]\n'
    err = _refused(tmp_path, "allan_variance_ros", evil)
    assert "not valid YAML" in err and not marker.exists()
    err = _refused(tmp_path, "allan_variance_ros", "")
    assert "empty" in err
    err = _refused(tmp_path, "allan_variance_ros", "gyroscope_noise_density: 1e-4\n")
    assert "no gyroscope_random_walk" in err


def test_the_input_is_never_the_output(tmp_path):
    src = _write(tmp_path, AVR, "imu.toml")
    before = src.read_bytes()
    o = run_cli(["import", "allan_variance_ros", src, "--out", src, "--force"])
    assert_contract(o, "--out")
    assert o.code == 2 and src.read_bytes() == before
