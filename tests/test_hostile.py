"""The hostile corpus of issue 17 (items 1-8 of it that are not output paths or geometry).

Each case is generated into a temporary folder and run through
``gyroarray.cli.main.main`` in this process under an alarm (processes only where
the case needs one: HOME, a read-only install). The contract of
:func:`hostile.assert_contract` holds for every case: exit 0 with finite
numbers, or exit 2 with one line naming the file; no internal error, no
traceback, no hang. Cases that would need gigabytes are refused with the
size named, in under a second of CPU time (measured in the process, after
the imports).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hostile import (SIDECAR_3, assert_contract, finite_numbers, gzip_bomb, run_cli,
                     write_measurement, write_scenario)

N = 2500                       # diagnose needs 2048 samples of a static part
DT = 0.02


@pytest.fixture(scope="module")
def d(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hostile")
    rng = np.random.default_rng(17)
    t = np.arange(N) * DT
    g = rng.normal(0.0, 0.05, (N, 3))
    write_measurement(folder, "plain", t, g)
    dead = g.copy()
    dead[:, 1] = 0.25
    write_measurement(folder, "dead_gyro", t, dead)
    write_measurement(folder, "all_constant", t, np.full((N, 3), 0.1))
    write_measurement(folder, "subnormal_values", t, g * 1e-310)
    write_measurement(folder, "huge_1e300", t, g * 1e302)
    spike = g.copy()
    spike[100, 0] = 1e200
    write_measurement(folder, "spike_1e200", t, spike)
    write_measurement(folder, "subnormal_step", np.arange(N) * 5e-324, g)
    write_measurement(folder, "epoch", 1.7e9 + np.arange(N) / 50.0, g)
    fast = g.copy()
    fast[10, 2] = 2e5
    write_measurement(folder, "omega_2e5", t, fast)
    lsb = g.copy()
    lsb[:, 0] = np.where(np.arange(N) % 7 == 0, 0.061, 0.0)
    write_measurement(folder, "near_constant", t, lsb)
    head = b"time_s,gyro1,gyro2,gyro3\n0,1,2,3\n0.02,1,2,3\n"
    gzip_bomb(folder / "bomb_blank.csv.gz", head, b"\n", 64 << 20)
    (folder / "bomb_blank.toml").write_text(SIDECAR_3)
    gzip_bomb(folder / "bomb_comments.csv.gz", b"# " + b"x" * 100, b"x", 200 << 20)
    (folder / "bomb_comments.toml").write_text(SIDECAR_3)
    with open(folder / "sparse_4g.csv", "wb") as fh:
        fh.write(b"time_s,gyro1,gyro2,gyro3\n")
        fh.truncate(4 << 30)
    (folder / "sparse_4g.toml").write_text(SIDECAR_3)
    os.mkfifo(folder / "fifo_csv.csv")
    (folder / "fifo_csv.toml").write_text(SIDECAR_3)
    write_measurement(folder, "fifo_side", t[:50], g[:50])
    (folder / "fifo_side.toml").unlink()
    os.mkfifo(folder / "fifo_side.toml")
    (folder / "dir_csv.csv").mkdir()
    (folder / "dir_csv.toml").write_text(SIDECAR_3)
    write_measurement(folder, "deep_side", t, g, sidecar=SIDECAR_3 + "x = " + "[" * 5000 + "]" * 5000 + "\n")
    write_measurement(folder, "long_string", t, g,
                      sidecar=f'description = "{"a" * (2 ** 20 + 1)}"\n' + SIDECAR_3)
    os.mkfifo(folder / "fifo_model.toml")
    (folder / "deep_model.toml").write_text("effects = " + "[" * 5000 + "]" * 5000 + "\n")
    return folder


def fast(argv, timeout=60):
    """The second of two runs (the first pays the imports): its CPU time is the refusal's own."""
    run_cli(argv, timeout=timeout)
    return run_cli(argv, timeout=timeout)


def ok(o, name=None):
    assert_contract(o, name)
    assert o.code == 0, o.err
    return o.json


def refused(o, name, *fragments):
    assert_contract(o, name)
    assert o.code == 2, o.out[:300]
    for f in fragments:
        assert f in o.err, o.err
    return o.err


# -- degenerate data is data ------------------------------------------------------

def test_dead_gyro_is_named_and_the_others_analysed(d):
    res = ok(run_cli(["allan", d / "dead_gyro.csv", "--json"]))
    assert sorted(res["gyros"]) == ["1", "3"]
    assert "gyro 2 is constant (dead or stuck?)" in res["not_analysed"]["2"]
    plain = ok(run_cli(["allan", d / "plain.csv", "--json"]))
    for k in ("1", "3"):   # the live gyros' answer is the one of the same data without the dead gyro
        assert res["gyros"][k]["adev_deg_h"] == plain["gyros"][k]["adev_deg_h"]
    assert finite_numbers(res["gyros"])


def test_dead_gyro_in_diagnose_is_left_out_and_said(d):
    res = ok(run_cli(["diagnose", d / "dead_gyro.csv", "--runs", "3", "--json"]))
    assert any("gyro 2 is constant (dead or stuck?)" in n and "3 as 2" in n for n in res["notes"])
    assert np.isfinite(res["discrepancy"])


@pytest.mark.parametrize("case", ["all_constant", "subnormal_values"])
@pytest.mark.parametrize("command", ["allan", "diagnose"])
def test_nothing_to_analyse_is_one_line(d, case, command):
    refused(run_cli([command, d / f"{case}.csv"]), f"{case}.csv", "nothing to analyse",
            "constant (dead or stuck?)")


@pytest.mark.parametrize("case, line, column", [("huge_1e300", 2, "gyro1"), ("spike_1e200", 102, "gyro1"),
                                                ("omega_2e5", 12, "gyro3")])
def test_rates_beyond_any_gyro_are_refused_with_the_line(d, case, line, column):
    err = refused(run_cli(["diagnose", d / f"{case}.csv"]), f"{case}.csv", "beyond the 100000 deg/s")
    assert f"line {line}, column {column}" in err


def test_subnormal_time_step_is_refused(d):
    refused(run_cli(["allan", d / "subnormal_step.csv"]), "subnormal_step.csv, line 3, column time_s",
            "time step of 5e-324 s")


def test_near_constant_gyro_is_analysed(d):
    res = ok(run_cli(["allan", d / "near_constant.csv", "--json"]))
    assert finite_numbers(res["gyros"]) and sorted(res["gyros"]) == ["1", "2", "3"]


def test_epoch_stamps_read_like_relative_ones(d):
    """Unix-epoch stamps (spec: valid) are analysed from the first stamp; diagnose no longer refuses."""
    epoch = ok(run_cli(["allan", d / "epoch.csv", "--json"]))
    plain = ok(run_cli(["allan", d / "plain.csv", "--json"]))
    # the same samples: equal ADEV to rounding (the epoch's median step is 0.02 to 1e-7)
    np.testing.assert_allclose(epoch["gyros"]["1"]["adev_deg_h"], plain["gyros"]["1"]["adev_deg_h"],
                               rtol=1e-6)
    res = ok(run_cli(["diagnose", d / "epoch.csv", "--runs", "3", "--json"]))
    assert np.isfinite(res["discrepancy"])


# -- sizes before allocating ---------------------------------------------------------

@pytest.mark.parametrize("case", ["bomb_blank.csv.gz", "bomb_comments.csv.gz", "sparse_4g.csv"])
def test_memory_heavy_files_are_refused_fast_with_the_size(d, case):
    o = fast(["allan", d / case, "--max-memory", "1G"])
    refused(o, case)
    assert "MiB" in o.err or "GiB" in o.err
    assert o.cpu_s < 1.0, o.cpu_s


def test_too_many_taus_and_gyros_are_refused_fast(d):
    o = fast(["allan", d / "plain.csv", "--taus", "100000000"])
    refused(o, None, "--taus asks for 100000000")
    assert o.cpu_s < 1.0
    refused(run_cli(["design", "--scheme", "1", "--n", "100000"]), None, "--n must be from 3 to 128")


# -- regular files of sane shape -----------------------------------------------------

@pytest.mark.parametrize("case, name, what", [
    ("fifo_csv.csv", "fifo_csv.csv", "not a regular file"),
    ("fifo_side.csv", "fifo_side.toml", "FIFO"),
    ("dir_csv.csv", "dir_csv.csv", "not a regular file"),
    ("deep_side.csv", "deep_side.toml, line 6", "nested more than 32"),
    ("long_string.csv", "long_string.toml", "strings are at most"),
])
def test_irregular_or_misshapen_files_are_refused_without_blocking(d, case, name, what):
    refused(run_cli(["allan", d / case], timeout=30), name, what)


@pytest.mark.parametrize("model, what", [("fifo_model.toml", "FIFO"), ("deep_model.toml", "nested")])
def test_model_fifo_and_deep_model(d, model, what):
    refused(run_cli(["diagnose", d / "plain.csv", "--model", d / model], timeout=30), model, what)


# -- scenarios: refused when they load, with file, line and key ----------------------

SCENARIOS = [
    ("duration_1ms", dict(extra="duration_s = 0.001"), "line 4, column duration_s", "0.02 samples"),
    ("rate_1e-3", dict(rate=1e-3), "line 2, column sample_rate_hz", "at least 100"),
    ("two_samples", dict(extra="duration_s = 0.1"), "column duration_s", "gives 2 samples"),
    ("latency_huge", dict(effects='{ effect = "latency", delay_s = 1e6 }'), "line 5, column effects[1].delay_s",
     "not shorter than the run"),
    ("sinusoid_above_nyquist", dict(effects='{ effect = "sinusoid", amp_deg_s = 0.1, freq_hz = 15.0 }'),
     "line 5, column effects[1].freq_hz", "Nyquist"),
    ("param_huge_ppm", dict(effects='{ effect = "scale_factor", ppm = 1e300 }'), "column effects[1].ppm",
     "beyond what a gyro can have"),
    ("param_huge_arw", dict(effects='{ effect = "rrw", k_deg_h_rt_h = 1e300 }'),
     "column effects[1].k_deg_h_rt_h", "beyond what a gyro can have"),
    ("long_1000h", dict(rate=100.0, profile="static1000h.toml",
                        profile_text='[[segment]]\nkind = "static"\nduration_s = 3.6e6\n'),
     "column sample_rate_hz", "1000 h at 100 Hz x 4 gyros needs about"),
    ("rate_1e9", dict(rate=1e9), "column sample_rate_hz", "above the 1e+06 Hz"),
    ("table_1e9", dict(profile="fast.toml", profile_text='[[segment]]\nkind = "constant_rate"\n'
                       'axis = [0, 0, 1]\nrate_deg_s = 1e9\nduration_s = 10.0\nramp_s = 1.0\n'),
     "column motion.profile", "beyond the rate table's 1000 deg/s"),
    ("deep_profile", dict(profile="deep.toml", profile_text="x = " + "[" * 5000 + "]" * 5000),
     "deep.toml, line 1", "nested more than 32"),
]


@pytest.mark.parametrize("name, kw, where, what", SCENARIOS, ids=[s[0] for s in SCENARIOS])
@pytest.mark.parametrize("command", ["simulate", "run"])
def test_bad_scenarios_are_refused_at_load(tmp_path, name, kw, where, what, command):
    path = write_scenario(tmp_path, name, **kw)
    argv = [command, path] + (["--out", tmp_path / "out"] if command == "simulate" else [])
    o = fast(argv)
    refused(o, where, what)
    assert o.cpu_s < 1.0, o.cpu_s          # refused before anything is simulated
    assert not (tmp_path / "out" / f"{name}.csv.gz").exists()


def test_fifo_profile_csv_does_not_block(tmp_path):
    os.mkfifo(tmp_path / "rates.csv")
    path = write_scenario(tmp_path, "fifo_profile", profile="p.toml",
                          profile_text='[[segment]]\nkind = "rate_csv"\nfile = "rates.csv"\n')
    refused(run_cli(["simulate", path, "--out", tmp_path / "out"], timeout=30),
            "p.toml, line 3, column segment[1].file", "FIFO")


def test_scenario_toml_nested_deep(tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text('name = "x"\n' + "y = " + "[" * 5000 + "]" * 5000 + "\n")
    refused(run_cli(["simulate", path, "--out", tmp_path]), "deep.toml, line 2", "nested")


# -- sweeps: counted before expanding, every scenario checked before any runs --------

SWEEP = '''name = "{name}"
seed = 1
[base]
sample_rate_hz = 20.0
effects = [ {{ effect = "arw", n_deg_rt_h = 0.1 }} ]
[base.layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356
[base.motion]
profile = "{profile}"
[grid]
{grid}
'''


def test_sweep_with_an_impossible_scenario_is_refused_before_running(tmp_path):
    (tmp_path / "static10.toml").write_text('[[segment]]\nkind = "static"\nduration_s = 10.0\n')
    path = tmp_path / "sw.toml"
    path.write_text(SWEEP.format(name="sw", profile="static10.toml",
                                 grid="n_gyros = [4, 5]\neffects = [\"base\", \"tone\"]\n")
                    + '[effect_sets]\ntone = [{ effect = "sinusoid", amp_deg_s = 0.1, freq_hz = 15.0 }]\n')
    o = run_cli(["sweep", path, "--out", tmp_path / "out"], timeout=60)
    refused(o, "sw.toml", "Nyquist")
    assert not (tmp_path / "out" / "rows").exists()


def test_huge_grid_is_counted_not_expanded(tmp_path):
    (tmp_path / "static10.toml").write_text('[[segment]]\nkind = "static"\nduration_s = 10.0\n')
    grid = "alpha_deg = [" + ", ".join(f"{10 + i * 0.01:.2f}" for i in range(1000)) + "]\n" \
           + "rho_arw = [" + ", ".join(f"{i * 0.001:.3f}" for i in range(200)) + "]\n"
    path = tmp_path / "big.toml"
    path.write_text(SWEEP.format(name="big", profile="static10.toml", grid=grid))
    o = fast(["sweep", path, "--out", tmp_path / "out"])
    refused(o, "big.toml", "the grid has 200000 scenarios")
    assert o.cpu_s < 1.0


def test_deep_sweep_and_thresholds(tmp_path):
    for command, name in (("sweep", "s.toml"), ("check", "t.toml")):
        path = tmp_path / name
        path.write_text("a = " + "[" * 3000 + "]" * 3000 + "\n")
        argv = [command, path] + (["--out", tmp_path / "out"] if command == "sweep" else [])
        refused(run_cli(argv), f"{name}, line 1", "nested more than 32")


# -- report: what is in the folder must be this sweep --------------------------------

def _sweep_dir(folder: Path, manifest, rows: dict) -> Path:
    import pandas as pd
    folder.mkdir()
    (folder / "sweep.json").write_text(json.dumps(manifest))
    (folder / "rows").mkdir()
    for sid, frame in rows.items():
        pd.DataFrame(frame).to_parquet(folder / "rows" / f"{sid}.parquet")
    return folder


ROW = {"scenario_id": ["a"], "estimator": ["gls"], "axis": ["x"], "sigma_1_deg_s": [0.1]}


@pytest.mark.parametrize("case, fragment", [
    ("list", "not a gyroarray sweep manifest"),
    ("no_ids", "not a gyroarray sweep manifest"),
    ("foreign", "copied from another sweep"),
    ("schema", "columns differ"),
])
def test_report_refuses_what_is_not_this_sweep(tmp_path, case, fragment):
    manifest = {"name": "s", "scenarios": [{"id": "a"}, {"id": "b"}]}
    rows = {"a": ROW}
    if case == "list":
        manifest = [1, 2]
    elif case == "no_ids":
        manifest = {"scenarios": [{"seed": 1}]}
    elif case == "foreign":
        rows["zzz"] = {**ROW, "scenario_id": ["zzz"]}
    else:
        rows["b"] = {**ROW, "scenario_id": ["b"], "scenario": ["paper003/x"]}
    folder = _sweep_dir(tmp_path / "sw", manifest, rows)
    refused(run_cli(["report", folder, "--out", tmp_path / "r.html"]), "sw", fragment)


def test_report_refuses_the_same_folder_twice(tmp_path):
    folder = _sweep_dir(tmp_path / "sw", {"scenarios": [{"id": "a"}]}, {"a": ROW})
    refused(run_cli(["report", folder, tmp_path / "." / "sw", "--out", tmp_path / "r.html"]),
            "sw", "given twice")


# -- no writable HOME, no writable install ---------------------------------------------

_READ_ONLY = """
import os, sys
real = os.access
os.access = lambda p, m, **k: False if m & os.W_OK else real(p, m, **k)   # an install and HOME we cannot write
import gyroarray.core.jit                       # where numba is first loaded, and its cache chosen
os.access = real
assert os.environ["NUMBA_CACHE_DIR"].startswith(os.environ["TMPDIR"]), os.environ.get("NUMBA_CACHE_DIR")
from gyroarray.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow   # a fresh interpreter with no writable home runs the chain (10 s on 2 cores): make score
def test_runs_without_a_writable_home_or_install(d, tmp_path):
    """HOME=/nonexistent, and (emulated) a read-only install: numba caches in a private temp folder."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(HOME="/nonexistent", TMPDIR=str(tmp_path), GYROARRAY_CACHE="")
    for code in (None, _READ_ONLY):
        argv = ([sys.executable, "-m", "gyroarray.cli.main"] if code is None else [sys.executable, "-c", code])
        p = subprocess.run(argv + ["allan", str(d / "plain.csv"), "--json"], env=env,
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr
        assert p.stderr == "" and finite_numbers(json.loads(p.stdout)["gyros"])
    assert any((tmp_path / f"gyroarray-numba-{os.getuid()}").iterdir())


# -- lab time stamps: --repair -------------------------------------------------------

MPU = Path(__file__).resolve().parents[2] / "shared" / "measurements" / "real" / "mpu6050_yaw_medium_raw.csv.gz"


@pytest.mark.skipif(not MPU.exists(), reason="../shared/measurements/real not present")
def test_mpu_duplicates_and_jitter_repaired_only_with_the_flag():
    """The MPU-6050 log (device stamps: 27 exact duplicate rows, ~1 ms jitter) as it comes."""
    import pandas as pd
    from gyroarray.core.errors import InputError
    from gyroarray.core.measurement import read_measurement
    with pytest.raises(InputError) as info:
        read_measurement(MPU)
    assert "--repair" in info.value.message and "repair=True" not in info.value.message.replace(
        "(repair=True in Python)", "")
    m = read_measurement(MPU, repair=True)
    raw = pd.read_csv(MPU, comment="#")
    dups = int(raw.duplicated().sum())                       # independent: pandas on the raw file
    assert dups == 27
    assert sum("exact duplicate" in n for n in m.notes) == 10 + 1   # ten listed, then the count
    assert any(f"and {dups - 10} more exact duplicate rows dropped" in n for n in m.notes)
    resampled = [n for n in m.notes if "resampled" in n]
    assert len(resampled) == 1 and "linear interpolation" in resampled[0]
    assert np.allclose(np.diff(m.time_s), 0.01, rtol=0, atol=1e-9)   # the nominal 100 Hz grid
    # linear interpolation onto the grid keeps a slow signal: compare with numpy's interp
    # of the deduplicated raw record at the same times (the gap rows are interpolated too)
    dedup = raw.drop_duplicates()
    expect = np.interp(m.time_s, dedup["time_s"], dedup["gyro3"])
    np.testing.assert_allclose(m.gyro_deg_s[:, 2], expect, rtol=0, atol=1e-9)


def test_conflicting_duplicates_are_refused_even_with_repair(tmp_path):
    from gyroarray.core.errors import InputError
    from gyroarray.core.measurement import read_measurement
    t = np.arange(100) * 0.02
    g = np.zeros((100, 3)) + np.arange(100)[:, None] * 1e-3
    t2, g2 = np.insert(t, 11, t[10]), np.insert(g, 11, g[10] + 1.0, axis=0)
    path = write_measurement(tmp_path, "conflict", t2, g2)
    with pytest.raises(InputError) as info:
        read_measurement(path, repair=True)
    assert info.value.line == 13 and "line 12 and line 13" in info.value.message
    t3, g3 = np.insert(t, 11, t[10]), np.insert(g, 11, g[10], axis=0)
    same = read_measurement(write_measurement(tmp_path, "dup", t3, g3), repair=True)
    np.testing.assert_array_equal(same.gyro_deg_s, g)         # the duplicate dropped, nothing else
    assert any("dropped line 13" in n for n in same.notes)
