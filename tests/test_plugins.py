"""An effect of your own is one file: the worked example plugin, through the CLI as a user runs it.

``examples/plugins/thermostat_bias.py`` defines an effect that no built-in
covers (a bias switching between two levels with a period). The test runs
the README's walk-through: simulate a record with it, ``diagnose --plugin``
names it first, ``fit --add thermostat_bias:3 --plugin`` makes D fall to
consistent and gives the parameters back. Also: without ``--plugin`` the
name is unknown (data never runs code), a plugin that raises is one line
naming its file and line, a plugin cannot replace a built-in, and the
public conformance check accepts the example and rejects a broken effect.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from gyroarray.cli.main import main

PLUGIN = Path(__file__).resolve().parents[1] / "examples" / "plugins" / "thermostat_bias.py"

SCENARIO = '''
name = "thermostat_run"
description = "4-gyro array, 30 min static, a heater cycling on gyro 3"
sample_rate_hz = 50.0
duration_s = 1800.0
seed = 11
effects = [
  { effect = "arw", n_deg_rt_h = 0.15 },
  { effect = "rrw", k_deg_h_rt_h = 5.0 },
  { effect = "thermostat_bias", gyro = 3, amp_deg_h = 30.0, period_s = 40.0, phase_s = 35.0 },
]

[layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356

[motion]
profile = "p003_static_1h"
'''


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plugin")
    scen = folder / "thermostat_run.toml"
    scen.write_text(SCENARIO)
    code = main(["simulate", str(scen), "--out", str(folder / "out"), "--plugin", str(PLUGIN), "--json"])
    assert code == 0
    return folder / "out" / "thermostat_run.csv.gz"


@pytest.mark.slow   # 30 s; the plugin chain runs fast in test_predictor_terms, the refusal in test_plugin_checks
def test_diagnose_names_the_plugin_effect_and_fit_makes_d_fall(record, capsys):
    code, out, err = run(capsys, "diagnose", record, "--plugin", PLUGIN, "--runs", 20, "--json")
    assert code == 0, err
    d = json.loads(out)
    top = d["candidates"][0]
    assert (top["effect"], top["gyro"]) == ("thermostat_bias", 3) and top["significant"], d["candidates"][:3]
    code, out, err = run(capsys, "fit", record, "--add", "thermostat_bias:3", "--plugin", PLUGIN,
                         "--runs", 20, "--json")
    assert code == 0, err
    f = json.loads(out)
    assert f["discrepancy_before"] > 2.0 and f["discrepancy_after"] <= 1.0
    entry = next(e for e in f["effects"] if e["effect"] == "thermostat_bias")
    p, s = entry["params"], entry["sigma"]
    # the simulated wave: ±30 deg/h, 40 s; within 2σ of the fit or 10 %
    assert abs(p["amp_deg_h"] - 30.0) <= max(2 * s["amp_deg_h"], 3.0)
    assert abs(p["period_s"] - 40.0) <= max(2 * s.get("period_s", 0.0), 4.0)


def test_without_the_plugin_the_effect_is_unknown(tmp_path, cli):
    scen = tmp_path / "s.toml"
    scen.write_text(SCENARIO)
    p = cli("simulate", scen, "--out", tmp_path / "o", check=False)
    assert p.returncode == 2 and p.stderr.count("\n") == 1 and "unknown effect 'thermostat_bias'" in p.stderr


def test_a_plugin_that_raises_is_one_line_naming_file_and_line(tmp_path, capsys):
    bad = tmp_path / "bad_plugin.py"
    bad.write_text("x = 1\nraise RuntimeError('boom')\n")
    code, _, err = run(capsys, "diagnose", "nothing.csv", "--plugin", bad)
    assert code == 2 and err.count("\n") == 1
    assert str(bad) in err and "line 2" in err and "RuntimeError: boom" in err


def test_a_plugin_cannot_replace_a_builtin(tmp_path, capsys):
    p = tmp_path / "clash.py"
    p.write_text(PLUGIN.read_text().replace('name = "thermostat_bias"', 'name = "sinusoid"'))
    code, _, err = run(capsys, "diagnose", "nothing.csv", "--plugin", p)
    assert code == 2 and "already defined" in err and err.count("\n") == 1
    notpy = tmp_path / "plugin.txt"
    notpy.write_text("")
    code, _, err = run(capsys, "diagnose", "nothing.csv", "--plugin", notpy)
    assert code == 2 and "ending in .py" in err


def test_the_former_protocol_path_gives_the_same_objects():
    """``gyroarray.effects.protocol`` (the protocol's former home) and ``gyroarray.core.sensor`` re-export the
    very objects of ``gyroarray.effects.protocol`` and ``gyroarray.core.sensor``; each protocol path imports
    first in a fresh interpreter (the registry the package runs needs nothing from ``sim``)."""
    import gyroarray.effects.protocol as new
    import gyroarray.core.sensor as new_sensor
    import gyroarray.effects.protocol as old
    import gyroarray.core.sensor as old_sensor
    assert old.Effect is new.Effect
    for a, b in ((old, new), (old_sensor, new_sensor)):
        assert a.__all__ == b.__all__ and all(getattr(a, k) is getattr(b, k) for k in b.__all__)
    for mod in ("gyroarray.effects.protocol", "gyroarray.effects.protocol"):
        subprocess.run([sys.executable, "-c", f"import {mod}; {mod}.Effect"], check=True)


@pytest.mark.slow   # two 30-minute simulated sessions per statistical check (26 s): make score
def test_the_example_passes_the_public_conformance_check():
    from gyroarray.effects import load_plugin, REGISTRY
    from gyroarray.chain.testing import check_effect
    load_plugin(PLUGIN)
    check_effect(type(REGISTRY["thermostat_bias"]))


@pytest.mark.slow   # 30 s; the plugin chain runs fast in test_predictor_terms, the refusal in test_plugin_checks
def test_the_conformance_check_rejects_a_broken_effect():
    """A check that cannot fail is a defect: an effect whose fit is off by 50 % fails it."""
    from gyroarray.effects import load_plugin, REGISTRY
    from gyroarray.chain.testing import effect_checks
    load_plugin(PLUGIN)
    base = type(REGISTRY["thermostat_bias"])

    class HalfWrong(base):
        name = "thermostat_half_wrong"

        def regress(self, ctx, gyro, e, r, q):
            f = super().regress(ctx, gyro, e, r, q)
            params = dict(f.params, amp_deg_h=1.5 * f.params["amp_deg_h"])
            return type(f)(f.effect, f.gyro, params, f.sigma, f.z, f.evidence, f.extra)

    check = dict(effect_checks(HalfWrong))["simulate_then_fit"]
    with pytest.raises(AssertionError, match="amp_deg_h"):
        check()
