"""The CLI contract: --json everywhere, one JSON object on stdout, bad input -> exit 2 + one line."""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from gyroarray.cli.main import build_parser, main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def run_json(capsys, *argv):
    code, out, err = run(capsys, *argv, "--json")
    assert code == 0, err
    assert out.endswith("\n") and out.count("\n") == 1  # exactly one JSON object, one line
    return json.loads(out)


def test_every_subcommand_takes_json():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) >= {"gdop", "design", "allan", "check"}
    for name, p in sub.choices.items():
        assert any("--json" in a.option_strings for a in p._actions), name


def test_gdop_json(capsys):
    out = run_json(capsys, "gdop", "--scheme", "1", "--n", "6", "--alpha", "54.7356")
    # 54.7356 deg is the magic angle rounded to 1e-4 deg: GDOP within 1e-8 of 3/sqrt(6)
    assert out == {"gdop": pytest.approx(3 / math.sqrt(6), abs=1e-8)}
    out = run_json(capsys, "gdop", "--scheme", "2", "--n", "4", "--alpha", "45", "--rho", "0")
    assert out["gdop"] == pytest.approx(1.75119, abs=1e-5)


def test_design_json(capsys):
    out = run_json(capsys, "design", "--scheme", "1", "--n", "8", "--rho", "0")
    assert set(out) == {"alpha_opt_deg", "gdop_min"}
    assert out["alpha_opt_deg"] == pytest.approx(math.degrees(math.acos(1 / math.sqrt(3))), abs=1e-6)
    assert out["gdop_min"] == pytest.approx(3 / math.sqrt(8), rel=1e-12)


def test_design_paper_tables_json_and_text(capsys):
    out = run_json(capsys, "design", "--paper-tables")
    assert out["cells_not_reproduced"] == 4
    assert sum(not c["reproduces"] for c in out["paper_tables"]) == 4
    code, text, _ = run(capsys, "design", "--paper-tables")
    assert code == 0
    assert text.count("NO  (computed") == 4
    assert "1.5327" in text and "1.5275" in text


def test_design_plot_writes_png(capsys, tmp_path):
    path = tmp_path / "sub" / "gdop.png"
    out = run_json(capsys, "design", "--plot", str(path))
    assert out == {"plot": str(path)}
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 50_000  # a real multi-panel figure


@pytest.mark.parametrize("argv,fragment", [
    (["gdop", "--scheme", "1", "--n", "6", "--alpha", "54.7", "--rho", "2"], "outside"),
    (["gdop", "--scheme", "3", "--n", "6", "--alpha", "50"], "invalid choice"),
    (["gdop", "--scheme", "1", "--n", "six", "--alpha", "50"], "must be a whole number"),
    (["gdop", "--scheme", "1", "--n", "6", "--alpha", "nan"], "must be finite"),
    (["gdop", "--scheme", "1", "--n", "2", "--alpha", "50"], "must be from 3 to 128"),
    (["design", "--scheme", "1"], "--scheme and --n go together"),
    (["design", "--plot", "out.txt"], ".png, .svg or .pdf"),
    (["design", "--scheme", "1", "--n", "6", "--rho", "-0.2"], "singular"),
    (["nosuch"], "invalid choice"),
    ([], "required"),
])
def test_bad_input_one_line_exit_2(capsys, argv, fragment):
    code, out, err = run(capsys, *argv, "--json") if argv and argv[0] != "nosuch" else run(capsys, *argv)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1 and err.startswith("gyroarray: ")
    assert fragment in err
    assert "Traceback" not in err


def test_entry_point_subprocess_no_traceback():
    proc = subprocess.run([sys.executable, "-m", "gyroarray.cli.main", "gdop", "--scheme", "1", "--n", "4",
                           "--alpha", "60", "--rho", "-0.5", "--json"], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.strip().splitlines() == [
        "gyroarray: --rho: rho = -0.5 is outside [-1/(N-1), 1] = [-0.333333, 1] for N = 4"]


def test_every_subcommand_is_listed():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) == {"gdop", "design", "allan", "davar", "simulate", "run", "check", "sweep", "report",
                                "compare", "diagnose", "fit", "ladder", "fdi", "fuse", "convert",
                                "export", "plan", "parity", "import"}


@pytest.mark.parametrize("argv,fragment", [
    (["davar"], "give MEAS.csv"),
    (["davar", "x.csv"], "--gyro K is required"),
    (["davar", "x.csv", "--gyro", "1", "--window", "600", "--adaptive"], "exclude each other"),
    (["davar", "x.csv", "--gyro", "1", "--window", "0"], "--window must be >= 1"),
    (["run", "nope.toml"], "scenario file not found"),
    (["simulate", "nope.toml", "--out", "o"], "scenario file not found"),
])
def test_davar_run_simulate_bad_input(capsys, argv, fragment):
    code, out, err = run(capsys, *argv, "--json")
    assert code == 2 and out == "" and err.count("\n") == 1 and fragment in err


def test_davar_on_a_simulated_burst(capsys, tmp_path):
    # ARW with variance x4 (sd x2) over 60-90 s of a 150 s run: the fixed-window ARW track
    # inside the burst is about twice the one before it (windows of 10 s, step 1 s)
    from gyroarray.core.layout import Layout
    from gyroarray.core.measurement import Measurement, write_measurement
    from gyroarray.sim.effects import simulate_readings
    from gyroarray.effects.model import NoiseModel
    from gyroarray.core.units import rad_s_to_deg_s
    n, dt = 15000, 0.01
    model = NoiseModel.from_toml({"effects": [
        {"effect": "arw", "n_deg_rt_h": 1.0},
        {"effect": "burst", "start_s": 60.0, "end_s": 90.0, "variance_ratio": 4.0}]}, n_gyros=3)
    y = simulate_readings(model, np.zeros((n, 3)), Layout.triad(), dt, np.random.default_rng(1))
    t = np.arange(n) * dt
    csv, _ = write_measurement(Measurement(time_s=t, gyro_deg_s=rad_s_to_deg_s(y), layout=Layout.triad(),
                                           sample_rate_hz=100.0), tmp_path / "burst.csv")
    png = tmp_path / "d.png"
    code, out, err = run(capsys, "davar", str(csv), "--gyro", "2", "--window", "1000", "--step", "100",
                         "--plot", str(png), "--json")
    assert code == 0, err
    res = json.loads(out)
    time_s, arw = np.array(res["time_s"]), np.array(res["arw_deg_rt_h"], dtype=float)
    inside = arw[(time_s > 66) & (time_s < 84)].mean()
    before = arw[(time_s > 10) & (time_s < 54)].mean()
    # each window's ARW from sigma(tau0) over 1000 samples: ~2.2 % sd; means of ~18 and ~44
    # overlapping windows (~2 and ~5 independent): ratio 2 within ~4 %; allow 10 %
    assert inside / before == pytest.approx(2.0, rel=0.1)
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_check_cli_exit_codes(capsys, tmp_path):
    # a threshold the model cannot meet -> exit 1 with passed false; a bad file -> exit 2
    import shutil
    from pathlib import Path
    root = Path(__file__).resolve().parents[1] / "src" / "gyroarray" / "data" / "scenarios"
    shutil.copy(root / "paper003" / "static_s1_n6_rhob_0.toml", tmp_path / "s1n6.toml")
    bad_bound = tmp_path / "t.toml"
    # GLS on 6 gyros cannot reduce ARW by 10x (theory sqrt(6/3) = 1.41)
    bad_bound.write_text('[[check]]\nscenario = "s1n6"\nquick_duration_s = 60\nestimator = "gls"\n'
                         'axis = "x"\nmetric = "arw_reduction"\nmin = 10.0\n')
    code, out, err = run(capsys, "check", str(bad_bound), "--json")
    assert code == 1, err
    res = json.loads(out)
    assert res["passed"] is False and res["results"][0]["pass"] is False
    assert res["results"][0]["value"] == pytest.approx(1.414, rel=0.15)
    bad_bound.write_text('[[check]]\nscenario = "s1n6"\ncolour = 1\n')
    code, out, err = run(capsys, "check", str(bad_bound), "--json")
    assert code == 2 and out == "" and "colour" in err


def test_sweep_cli_runs_then_resumes(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("GYROARRAY_CACHE", str(tmp_path / "cache"))
    sweep = tmp_path / "tiny.toml"
    sweep.write_text("""name = "tiny"
seed = 7
estimators = ["gls"]
[base]
sample_rate_hz = 100.0
effects = [{ effect = "arw", n_deg_rt_h = 0.1 }]
[base.layout]
scheme = 1
n_gyros = 6
alpha_deg = 54.7356
[base.motion]
profile = "p003_static_1h"
[grid]
n_gyros = [4, 6]
duration_s = [20.0]
""")
    out = tmp_path / "out"
    code, text, err = run(capsys, "sweep", str(sweep), "--out", str(out), "--json")
    assert code == 0, err
    first = json.loads(text)
    assert first["scenarios"] == 2 and first["ran"] == 2 and first["rows_written"] == 2 * 3
    code, text, err = run(capsys, "sweep", str(sweep), "--out", str(out), "--json")
    again = json.loads(text)
    assert code == 0 and again["ran"] == 0 and again["skipped"] == 2 and again["complete"] is True
