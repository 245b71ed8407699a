"""Issue 28, items 6 and 8: models the record cannot carry, extreme arguments and model values,
refusals that name no file or run over several lines.

Every case goes through ``gyroarray.cli.main.main`` (:func:`hostile.run_cli`) and must keep the
contract of :func:`hostile.assert_contract`: exit 0 with finite numbers, or exit 2 with one
stderr line naming the file or the argument; never an internal error. The refusals of a model
come before any work, so these cases take milliseconds each (the few right answers seconds).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hostile import SIDECAR_3, assert_contract, finite_numbers, run_cli, write_measurement, write_scenario

from gyroarray.effects import REGISTRY
from gyroarray.effects.protocol import RECORD_NEEDS
from gyroarray.core.errors import InputError, one_line

N = 3000
RATE = 50.0
BASE = '{effect = "arw", n_deg_rt_h = 0.1},\n {effect = "rrw", k_deg_h_rt_h = 1.0},\n'

#: An entry of each effect that needs record data, and the column its refusal names.
NEEDING = [
    ('{effect = "latency", delay_s = 0.01}', "latency", "ref_x"),
    ('{effect = "misalignment", gyro = 2, tilt_deg = 0.5}', "misalignment", "ref_x"),
    ('{effect = "saturation", range_deg_s = 100}', "saturation", "ref_x"),
    ('{effect = "scale_factor", ppm = 100}', "scale_factor", "ref_x"),
    ('{effect = "scale_nonlinearity", k2_per_deg_s = 1e-6}', "scale_nonlinearity", "ref_x"),
    ('{effect = "earth_rate", latitude_deg = 45}', "earth_rate", "ref_x"),
    ('{effect = "temperature_bias", deg_h_per_c = 1, t0_c = 25}', "temperature_bias", "temp_c"),
]


def write_model(folder, name: str, entry: str) -> str:
    """A model file: the baseline on lines 2-3, ``entry`` on line 4."""
    path = folder / name
    path.write_text(f"effects = [\n {BASE} {entry},\n]\n")
    return str(path)


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hostile_models")
    rng = np.random.default_rng(28)
    t = np.arange(N) / RATE
    g = rng.normal(0.0, 1e-4, (N, 3))
    write_measurement(folder, "noref", t, g)                   # outputs only
    cols = np.column_stack([g, np.zeros((N, 3)), np.full(N, 25.0)])
    write_measurement(folder, "static", t, cols, header="time_s,gyro1,gyro2,gyro3,ref_x,ref_y,ref_z,temp_c")
    write_measurement(folder, "short", t[:500], g[:500])
    return folder


def _compare_family(command: str, meas, model, out) -> list:
    extra = {"compare": ["--out", out / "r.html", "--force"], "diagnose": [], "fit": [],
             "ladder": ["--out", out / "r.html", "--force", "--max-steps", "1"]}[command]
    return [command, meas, "--model", model, "--runs", "2", *extra]


# -- 1. a model's effect that needs data the record lacks ---------------------------------

@pytest.mark.parametrize("entry, effect, column", NEEDING, ids=[n[1] for n in NEEDING])
@pytest.mark.parametrize("command", ["compare", "diagnose", "fit", "ladder"])
def test_model_needing_data_the_record_lacks_is_refused_before_work(d, tmp_path, entry, effect, column,
                                                                     command):
    model = write_model(tmp_path, f"m_{effect}.toml", entry)
    o = run_cli(_compare_family(command, d / "noref.csv", model, tmp_path))
    assert_contract(o, model)
    assert o.code == 2
    line = o.err.strip()
    assert f"{model}, line 4, column effects[2]:" in line
    assert effect in line and column in line and "noref.csv" in line
    assert o.cpu_s < 5.0, o.cpu_s                  # refused before the calibration
    assert not (tmp_path / "r.html").exists()


@pytest.mark.parametrize("command", [["diagnose", "--validate"], ["compare", "--validate"]])
def test_validating_a_temperature_model_without_temperature_is_refused(d, tmp_path, command):
    model = write_model(tmp_path, "m_temp.toml", NEEDING[-1][0])
    o = run_cli([*command, d / "noref.csv", "--model", model, "--runs", "2", "--out", tmp_path / "r.html"]
                if command[0] == "compare" else [*command, d / "noref.csv", "--model", model, "--runs", "2"])
    assert_contract(o, model)
    assert o.code == 2 and "temp_c" in o.err and "effects[2]" in o.err and "line 4" in o.err


def test_validating_a_reference_model_on_a_record_without_one_is_answered(d, tmp_path):
    """Fixed parameters need no reference: the record is analysed as static, the answer is finite."""
    model = write_model(tmp_path, "m_sf.toml", '{effect = "scale_factor", ppm = 100}')
    o = run_cli(["diagnose", "--validate", d / "noref.csv", "--model", model, "--runs", "4", "--json"])
    assert_contract(o)
    assert o.code == 0 and o.json["validated"] and finite_numbers(o.json["discrepancy"])


def test_the_same_model_on_a_record_with_the_data_is_not_refused(d, tmp_path):
    model = write_model(tmp_path, "m_lat.toml", NEEDING[0][0])
    o = run_cli(["diagnose", "--validate", d / "static.csv", "--model", model, "--runs", "2", "--json"])
    assert_contract(o)
    assert o.code == 0


def test_every_effect_declares_record_data_the_check_knows():
    for eff in REGISTRY.values():
        assert set(eff.model_needs) <= set(RECORD_NEEDS), eff.name
        assert set(eff.predict_needs) <= set(eff.model_needs), eff.name
    for entry, name, column in NEEDING:
        assert REGISTRY[name].model_needs, name


# -- 2. extreme arguments ----------------------------------------------------------------

LONG = "a" * 300 + ".png"


@pytest.mark.parametrize("argv, arg", [
    (["compare", "{static}", "--seed", "-5", "--out", "{tmp}/r.html"], "--seed"),
    (["diagnose", "{static}", "--seed", "-5"], "--seed"),
    (["fit", "{static}", "--seed", "-5"], "--seed"),
    (["ladder", "{static}", "--seed", "-5", "--out", "{tmp}/r.html"], "--seed"),
    (["diagnose", "{static}", "--ref-smooth", "1e300"], "--ref-smooth"),
    (["diagnose", "{static}", "--ref-smooth", "-1"], "--ref-smooth"),
    (["diagnose", "{static}", "--ref-smooth", "100"], "--ref-smooth"),
    (["design", "--recommend", "--arw", "1e300"], "--arw"),
    (["design", "--recommend", "--arw", "0.1", "--rrw", "1e300"], "--rrw"),
    (["design", "--recommend", "--arw", "0.1", "--bi", "1e300"], "--bi"),
    (["design", "--recommend", "--arw", "0.1", "--rate-hz", "1e-300"], "--rate-hz"),
    (["gdop", "--scheme", "1", "--n", "4", "--alpha", "1e300"], "--alpha"),
    (["allan", "{static}", "--plot", "{tmp}/" + LONG], "--plot"),
    (["davar", "{static}", "--gyro", "1", "--plot", "{tmp}/" + LONG], "--plot"),
    (["design", "--scheme", "1", "--n", "4", "--plot", "{tmp}/" + LONG], "--plot"),
], ids=lambda v: v if isinstance(v, str) else " ".join(v[:1] + v[2:4]))
def test_extreme_arguments_are_refused_naming_the_argument(d, tmp_path, argv, arg):
    argv = [a.format(static=d / "static.csv", tmp=tmp_path) for a in argv]
    o = run_cli(argv, timeout=60)
    assert_contract(o, arg)
    assert o.code == 2
    assert o.cpu_s < 5.0, o.cpu_s


# -- 3. extreme model values ----------------------------------------------------------------

EXTREME = [
    ('{effect = "gauss_markov", sigma_deg_h = 1.0, tau_s = 1e300}', "tau_s"),
    ('{effect = "outliers", rate_per_h = 1e300, size_deg_s = 1.0}', "rate_per_h"),
    ('{effect = "bandwidth", cutoff_hz = 1e-300, order = 1}', "cutoff_hz"),
    ('{effect = "bandwidth", cutoff_hz = 1e-300, order = 2}', "cutoff_hz"),
]
EXTREME_IDS = ["gm_tau", "outliers_rate", "bandwidth1_cutoff", "bandwidth2_cutoff"]


@pytest.mark.parametrize("entry, key", EXTREME, ids=EXTREME_IDS)
@pytest.mark.parametrize("command", [["diagnose", "--validate"], ["fit"], ["design", "--recommend"]])
def test_extreme_model_values_are_refused_at_load_with_line_and_key(d, tmp_path, entry, key, command):
    model = write_model(tmp_path, "extreme.toml", entry)
    if command[0] == "design":
        argv = [*command, "--model", model]
    else:
        argv = [*command, d / "static.csv", "--model", model, "--runs", "2"]
    o = run_cli(argv)
    assert_contract(o, model)
    assert o.code == 2 and f"line 4, column effects[2].{key}:" in o.err


@pytest.mark.parametrize("entry, key", EXTREME, ids=EXTREME_IDS)
@pytest.mark.parametrize("command", ["run", "simulate"])
def test_extreme_scenario_values_are_refused_at_load(tmp_path, entry, key, command):
    path = write_scenario(tmp_path, "extreme", effects=entry)
    argv = [command, path] + (["--out", tmp_path / "out.csv.gz"] if command == "simulate" else [])
    o = run_cli(argv)
    assert_contract(o, str(path))
    assert o.code == 2 and key in o.err and "line" in o.err


@pytest.mark.parametrize("command", [["diagnose", "--validate"], ["fit"]])
def test_bandwidth_above_the_records_nyquist_names_model_key_and_record(d, tmp_path, command):
    model = write_model(tmp_path, "bw.toml", '{effect = "bandwidth", cutoff_hz = 1000, order = 2}')
    o = run_cli([*command, d / "static.csv", "--model", model, "--runs", "2"])
    assert_contract(o, model)
    assert o.code == 2
    assert "line 4, column effects[2].cutoff_hz" in o.err and "25 Hz" in o.err and "static.csv" in o.err


@pytest.mark.parametrize("command", ["run", "simulate"])
def test_bandwidth_above_the_scenarios_nyquist_names_the_scenario(tmp_path, command):
    path = write_scenario(tmp_path, "bwhi", effects='{effect = "bandwidth", cutoff_hz = 1000, order = 1}')
    argv = [command, path] + (["--out", tmp_path / "out.csv.gz"] if command == "simulate" else [])
    o = run_cli(argv)
    assert_contract(o, str(path))
    assert o.code == 2 and "cutoff_hz" in o.err and "10 Hz" in o.err


def test_a_latency_as_long_as_the_record_is_refused_with_the_model(d, tmp_path):
    model = write_model(tmp_path, "lat.toml", '{effect = "latency", delay_s = 1e300}')
    o = run_cli(["diagnose", "--validate", d / "static.csv", "--model", model, "--runs", "2"])
    assert_contract(o, model)
    assert o.code == 2 and "delay_s" in o.err


def test_model_lines_in_the_array_of_tables_form(d, tmp_path):
    model = tmp_path / "aot.toml"
    model.write_text('[[effects]]\neffect = "arw"\nn_deg_rt_h = 0.1\n\n[[effects]]\neffect = "rrw"\n'
                     'k_deg_h_rt_h = 1.0\n\n[[effects]]\neffect = "gauss_markov"\nsigma_deg_h = 1.0\n'
                     'tau_s = 1e300\n')
    o = run_cli(["fit", d / "static.csv", "--model", model])
    assert_contract(o, str(model))
    assert o.code == 2 and "line 9, column effects[2].tau_s" in o.err


# -- 4. refusals name the file ----------------------------------------------------------------

@pytest.mark.parametrize("argv", [
    ["davar", "{short}", "--gyro", "1"],
    ["davar", "{short}", "--gyro", "1", "--window", "1000000"],
])
def test_refusals_deep_in_an_analysis_name_the_file(d, argv):
    o = run_cli([a.format(short=d / "short.csv") for a in argv])
    assert_contract(o, str(d / "short.csv"))
    assert o.code == 2


# -- 5. one line, whatever the file name or message holds --------------------------------------

def test_a_path_with_a_newline_is_refused_on_one_line(tmp_path):
    folder = tmp_path / "x\ny"
    folder.mkdir()
    t = np.arange(100) / RATE
    path = write_measurement(folder, "new\nline\r", t, np.zeros((100, 3)), sidecar=SIDECAR_3)
    o = run_cli(["allan", path, "--gyro", "9"])
    assert_contract(o)
    assert o.code == 2 and "new\\nline\\r" in o.err and "x\\ny" in o.err


def test_a_plugin_exception_with_newlines_is_one_line(d, tmp_path):
    plugin = tmp_path / "plug.py"
    plugin.write_text('raise ValueError("first\\nsecond\\x1b[31m")\n')
    o = run_cli(["fit", d / "static.csv", "--plugin", plugin])
    assert_contract(o, str(plugin))
    assert o.code == 2 and "first\\nsecond\\x1b[31m" in o.err


def test_an_internal_error_with_newlines_is_one_line(d, monkeypatch):
    import gyroarray.cli.main as cli

    def boom(args):
        raise RuntimeError("line one\nline two")
    parser = cli.build_parser
    monkeypatch.setattr(cli, "build_parser", lambda: _with_func(parser(), "gdop", boom))
    o = run_cli(["gdop", "--scheme", "1", "--n", "4", "--alpha", "50"])
    assert o.code == 1
    assert len(o.err.strip().splitlines()) == 1 and "line one\\nline two" in o.err


def _with_func(parser, command: str, func):
    for action in parser._subparsers._group_actions:
        action.choices[command].set_defaults(func=func)
    return parser


def test_input_error_is_one_line_and_takes_a_file_once():
    err = InputError("bad\nvalue\x00", file="a\nb.csv", line=2, column="c\rd")
    assert "\n" not in str(err) and "\r" not in str(err) and "\x00" not in str(err)
    assert str(err) == "a\\nb.csv, line 2, column c\\rd: bad\\nvalue\\x00"
    assert InputError("m").with_file("f.toml").file == "f.toml"
    assert InputError("m", file="g.csv").with_file("f.toml").file == "g.csv"
    assert one_line("plain é ü") == "plain é ü" and math.isfinite(1.0)
