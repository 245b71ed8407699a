"""``gyroarray fdi``: the issue's JSON object, the table, the plot, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gyroarray.cli.main import main
from gyroarray.core.gdop import optimal_alpha
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, write_measurement
from gyroarray.sim.effects import simulate_readings
from gyroarray.effects.model import NoiseModel
from gyroarray.core.units import rad_s_to_deg_s

DT = 0.01
PAPER = [{"effect": "arw", "n_deg_rt_h": 0.1}, {"effect": "rrw", "k_deg_h_rt_h": 600.0}]
ALARM_KEYS = {"gyro", "kind", "onset_s", "detected_s", "size", "size_unit", "isolated", "evidence"}


def _record(tmp_path, name, faults=(), n_gyros=6, n=12000):
    lay = Layout.conical(1, n_gyros, optimal_alpha(1, n_gyros).alpha_rad)
    m = NoiseModel.from_toml({"effects": PAPER + list(faults)})
    t = np.arange(n) * DT
    ref = np.zeros((n, 3))
    z = simulate_readings(m, ref, lay, DT, np.random.default_rng(8), time_s=t)
    meas = Measurement(time_s=t, gyro_deg_s=rad_s_to_deg_s(z), layout=lay, sample_rate_hz=1 / DT,
                       ref_deg_s=ref)
    csv, _ = write_measurement(meas, tmp_path / f"{name}.csv.gz")
    return csv


@pytest.fixture
def model_file(tmp_path):
    p = tmp_path / "model.toml"
    p.write_text('effects = [{effect = "arw", n_deg_rt_h = 0.1}, {effect = "rrw", k_deg_h_rt_h = 600.0}]\n')
    return p


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_step_record_gives_the_issues_object(tmp_path, capsys, model_file):
    csv = _record(tmp_path, "step", [{"effect": "fault_step", "gyro": 5, "start_s": 60.0,
                                      "size_deg_s": 0.1}])
    out = _json(capsys, ["fdi", str(csv), "--model", str(model_file), "--json"])
    assert set(out) == {"alarms", "far_per_h", "minimum_detectable", "tested", "notes"}
    assert out["far_per_h"] == 0.01
    # a record at rest: every sample tested, nothing untested
    assert out["tested"]["untested"] == [] and out["tested"]["moving_s"] == 0.0
    assert out["tested"]["still_s"] > 100.0
    a, = out["alarms"]
    assert set(a) == ALARM_KEYS
    assert (a["gyro"], a["kind"], a["isolated"], a["size_unit"]) == (5, "step", True, "deg/s")
    assert abs(a["onset_s"] - 60.0) <= 2.0 and abs(a["size"] - 0.1) < 0.02
    md = out["minimum_detectable"]
    assert set(md) == {str(g) for g in range(1, 7)}
    assert set(md["1"]) == {"step_deg_s", "drift_deg_s2", "noise_ratio", "stuck_static_s", "isolable"}
    assert 0.0 < md["1"]["step_deg_s"] < 0.1                   # the fault was above it
    # the readable table and the plot
    png = tmp_path / "stat.png"
    assert main(["fdi", str(csv), "--model", str(model_file), "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "step" in text and "minimum detectable" in text and png.stat().st_size > 10_000


def test_clean_record_without_a_model_has_no_alarm(tmp_path, capsys):
    csv = _record(tmp_path, "clean", n_gyros=5)
    out = _json(capsys, ["fdi", str(csv), "--json"])
    assert out["alarms"] == []
    assert any("estimated from the record" in n for n in out["notes"])


@pytest.mark.parametrize("argv,fragment", [
    (["--far-per-h", "-1"], "--far-per-h"),
    (["--model", "nope.toml"], "nope.toml"),
    (["--far-per-h", "nan"], "finite"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, fragment):
    csv = _record(tmp_path, "bad", n=3000)
    assert main(["fdi", str(csv), *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("gyroarray: ") and err.count("\n") == 1 and fragment in err


def test_too_few_gyros_in_the_measurement(tmp_path, capsys):
    lay = Layout.triad()
    t = np.arange(3000) * DT
    meas = Measurement(time_s=t, gyro_deg_s=np.random.default_rng(0).standard_normal((3000, 3)),
                       layout=lay, sample_rate_hz=100.0)
    csv, _ = write_measurement(meas, tmp_path / "triad.csv")
    assert main(["fdi", str(csv)]) == 2
    assert "at least 4 gyros" in capsys.readouterr().err


def test_plot_never_overwrites_an_input(tmp_path, capsys):
    csv = _record(tmp_path, "guard", n=3000)
    sidecar = tmp_path / "guard.toml"
    before = sidecar.read_bytes()
    assert main(["fdi", str(csv), "--plot", str(sidecar), "--force"]) == 2
    assert "--plot" in capsys.readouterr().err and sidecar.read_bytes() == before
