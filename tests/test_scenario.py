"""Scenario files and the simulate chain (table -> effects -> measurement files)."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

from gyroarray.cli.main import main
from gyroarray.core.errors import InputError
from gyroarray.core.measurement import read_measurement
from gyroarray.sim.scenario import load_scenario, simulate, simulate_to_files
from gyroarray.core.units import arw_deg_rt_h_to_rad_rt_s, deg_s_to_rad_s

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "src" / "gyroarray" / "data" / "scenarios" / "examples" / "tetra_swing.toml"

BASE = """\
name = "t"
sample_rate_hz = 100.0
seed = 7
duration_s = 120.0
effects = [ {{ effect = "arw", n_deg_rt_h = 0.5 }} ]
{extra_top}
[layout]
scheme = 2
n_gyros = 5
alpha_deg = 65.9
[motion]
profile = "{profile}"
{extra}
"""


def write(tmp_path, *, profile="p003_swing_5dps_0p1hz", extra="", extra_top="", name="s.toml"):
    p = tmp_path / name
    p.write_text(BASE.format(profile=profile, extra=extra, extra_top=extra_top))
    return p


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GYROARRAY_CACHE", str(tmp_path / "cache"))


def test_example_scenario_runs_and_round_trips(tmp_path):
    sc = load_scenario(EXAMPLE)
    csv, toml, res = simulate_to_files(sc, tmp_path / "out")
    assert csv.name == "tetra_swing.csv.gz" and toml.name == "tetra_swing.toml"
    m = read_measurement(csv)
    assert m.n_samples == 30000 and m.n_gyros == 4
    # ref_* is the realised table rate (deg/s in the file; one rounding each way)
    np.testing.assert_allclose(deg_s_to_rad_s(m.ref_deg_s), res.truth.omega_body_rad_s, rtol=1e-15, atol=1e-18)
    # the swing about z: 5 deg/s amplitude, realised by the table to 1e-3 (its tracking report)
    assert np.max(np.abs(m.ref_deg_s[:, 2])) == pytest.approx(5.0, rel=1e-3)
    # temperature: 25 -> 30 degC with tau 600 s, exported as temp_c
    assert m.temp_c[0] == 25.0
    assert m.temp_c[-1] == pytest.approx(30 - 5 * math.exp(-299.99 / 600), rel=1e-12)
    assert m.site is not None and m.site.latitude_rad == pytest.approx(math.radians(34.25), rel=1e-15)
    # gyro 2 has +6000 ppm scale factor: its readings regress on the projected rate with slope 1.006
    proj = m.ref_deg_s @ m.layout.H.T
    slope = np.polyfit(proj[:, 1], m.gyro_deg_s[:, 1], 1)[0]
    # noise ~0.15 deg/rt(h) -> 0.025 deg/s per sample vs a 4 deg/s swing over 30000 samples:
    # slope standard error ~1e-4; allow 1e-3 (earth rate and temperature bias are not regressed out)
    assert slope == pytest.approx(1.006, abs=1e-3)


def test_arw_only_readings_have_the_right_noise(tmp_path):
    sc = load_scenario(write(tmp_path))
    res = simulate(sc)
    resid = res.readings_rad_s - res.truth.omega_body_rad_s @ sc.layout.H.T
    sigma = arw_deg_rt_h_to_rad_rt_s(0.5) / math.sqrt(0.01)
    n = resid.size
    # sample variance of n normal draws: relative sd sqrt(2/n); 5 sd bound
    assert np.var(resid) / sigma**2 == pytest.approx(1.0, abs=5 * math.sqrt(2 / n))
    assert abs(resid.mean()) < 5 * sigma / math.sqrt(n)


def test_same_seed_same_bits_and_files(tmp_path):
    sc = load_scenario(write(tmp_path))
    a = simulate(sc).readings_rad_s
    b = simulate(sc, cache=False).readings_rad_s
    assert a.tobytes() == b.tobytes()
    c1, _, _ = simulate_to_files(sc, tmp_path / "o1")
    c2, _, _ = simulate_to_files(sc, tmp_path / "o2")
    assert hashlib.sha256(c1.read_bytes()).digest() == hashlib.sha256(c2.read_bytes()).digest()
    other = simulate(sc, rng=np.random.default_rng(8)).readings_rad_s
    assert not np.array_equal(a, other)


@pytest.mark.parametrize("kw,fragment,column", [
    (dict(extra_top="colour = 'red'"), "unknown key 'colour'", "colour"),
    (dict(extra="[site]\nlatitude_deg = 10.0\nheading_deg = 0.0\nseed = 3"), "landed inside [site]", "site.seed"),
    (dict(profile="no_such_profile"), "unknown shipped motion profile 'no_such_profile'", "motion.profile"),
    (dict(profile="missing.toml"), "motion profile file 'missing.toml' not found", "motion.profile"),
    (dict(extra="[temperature]\nstart_c = 25.0"), "temperature takes exactly one form", "temperature"),
    (dict(extra="[temperature]\npoints = [[0.0, 25.0], [0.0, 26.0]]"), "strictly increasing", "temperature.points"),
    (dict(extra="[temperature]\nstart_c = 25.0\nend_c = 30.0\ntau_s = -1.0"), "tau_s must be > 0", "temperature.tau_s"),
])
def test_bad_scenarios_refused_with_key(tmp_path, kw, fragment, column):
    path = write(tmp_path, **kw)
    before = path.read_bytes()
    with pytest.raises(InputError) as info:
        load_scenario(path)
    err = info.value
    assert fragment in err.message and err.file == str(path) and err.column == column
    assert path.read_bytes() == before


def test_bad_effect_is_located(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text(BASE.format(profile="p003_static_1h", extra="", extra_top="").replace(
        'effect = "arw", n_deg_rt_h = 0.5', 'effect = "arww", n_deg_rt_h = 0.5'))
    with pytest.raises(InputError, match="arww") as info:
        load_scenario(p)
    assert info.value.file == str(p) and info.value.line == 5


def test_duration_longer_than_profile_refused(tmp_path):
    p = write(tmp_path)
    p.write_text(p.read_text().replace("duration_s = 120.0", "duration_s = 1e6"))
    with pytest.raises(InputError, match="longer than the motion profile"):
        load_scenario(p)


def test_cli_simulate_json_then_allan_reads_it(tmp_path, capsys):
    out_dir = tmp_path / "out"
    assert main([ "simulate", str(write(tmp_path)), "--out", str(out_dir), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["measurement"] == str(out_dir / "t.csv.gz") and out["n_samples"] == 12000
    assert out["effects"] == [{"effect": "arw", "gyro": None, "params": {"n_deg_rt_h": 0.5}}]
    assert out["tracking"][0]["kind"] == "sinusoid"
    assert out["tracking"][0]["amplitude_ratio"] == pytest.approx(1.0, abs=1e-3)
    # the simulated run goes wherever a lab measurement goes
    assert main(["allan", out["measurement"], "--gyro", "1", "--json"]) == 0
    allan = json.loads(capsys.readouterr().out)
    assert allan["signal"].startswith("gyro output minus layout")
    fit = allan["gyros"]["1"]["fit"]
    # 120 s of ARW 0.5 deg/rt(h): the fitted N within 10 % (about 30 sigma of its fit uncertainty
    # would be far too loose; 10 % is ~3x the ~3 % sd of a 2-minute record's N estimate)
    assert fit["arw_deg_rt_h"] == pytest.approx(0.5, rel=0.1)


def test_cli_simulate_bad_input_exit_2(tmp_path, capsys):
    bad = write(tmp_path, extra_top="colour = 1")
    assert main(["simulate", str(bad), "--out", str(tmp_path / "o"), "--json"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "unknown key 'colour'" in err
