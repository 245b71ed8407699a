"""Issue 29: the layers above ``effects/`` ask the registry, never an effect's name.

Each question the simulator, the scenario reader and the sweep used to answer with a
hand list of effect names is now a declaration on the effect's class
(:class:`gyroarray.effects.protocol.Effect`): ``sim_needs`` (what ``simulate`` reads
beyond the rates), ``check_run`` (rules of a simulated run), ``sweep_axes`` (parameters
a sweep varies as axes of their own). A plugin effect, registered here and taken out
again after, that makes the same declaration as a built-in is treated as the built-in
is: the declarations are the dispatch.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import pytest

from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.effects import REGISTRY, register, unregister
from gyroarray.effects.model import ModelEntry, NoiseModel
from gyroarray.effects.protocol import Effect, Param, Stage, identity
from gyroarray.sim.lab import lab_run
from gyroarray.sweep.sweep import load_sweep
from hostile import assert_contract, run_cli

CONE4 = Layout.conical(1, 4, math.acos(1 / math.sqrt(3)))


class _Seer(Effect):
    """A plugin effect that changes nothing and records what the simulator handed it."""

    name = "zz_seer"
    stage = Stage.ADD
    per_gyro = False
    params = (Param("k", "-", "k", identity, required=False, default=0.0, doc="unused"),)
    doc = "records the inputs of its run"
    seen: ClassVar[list] = []

    def simulate(self, state, act, streams):
        ctx = state.ctx
        type(self).seen.append({"site": ctx.site is not None, "attitude": ctx.attitude is not None,
                                "temp": ctx.temp_c is not None})
        return state


def _plugin(name: str, **declared) -> type:
    """A :class:`_Seer` subclass called ``name`` with the class attributes ``declared``."""
    return type(f"Plugin_{name}", (_Seer,), {"name": name, "seen": [], **declared})


@pytest.fixture
def registered():
    """Register plugin classes for one test; every one is taken out again after it."""
    names: list[str] = []

    def add(cls: type) -> Effect:
        eff = register(cls, source="tests/test_registry_dispatch.py")
        names.append(eff.name)
        return eff
    yield add
    for name in names:
        unregister(name)
    assert not set(names) & set(REGISTRY)


def _lab(entries) -> None:
    lab_run(NoiseModel(tuple(entries)), CONE4, np.random.default_rng(3), static_s=4.0, motion_s=20.0,
            tail_s=2.0, latitude_deg=34.25)


# -- the lab builds what an effect declares it reads ----------------------------------

@pytest.mark.parametrize("like", ["earth_rate", "g_sensitivity", "temperature_bias", "arw"])
def test_the_lab_builds_for_a_plugin_what_it_builds_for_the_built_in(registered, like):
    builtin = REGISTRY[like]
    cls = _plugin(f"zz_like_{like}", sim_needs=builtin.sim_needs)
    registered(cls)
    _lab([ModelEntry(cls.name, None, {})])
    # what the lab gives the built-in (its docstring): the site for the Earth's rate, the
    # attitude for the Earth's rate and for gravity's direction
    site = like == "earth_rate"
    attitude = like in ("earth_rate", "g_sensitivity")
    assert cls.seen == [{"site": site, "attitude": attitude, "temp": True}]


def test_the_lab_builds_the_site_and_the_attitude_only_when_an_entry_declares_them(registered):
    blind = registered(_plugin("zz_blind"))
    sited = registered(_plugin("zz_sited", sim_needs=frozenset({"site"})))
    _lab([ModelEntry(blind.name, None, {})])
    assert type(blind).seen == [{"site": False, "attitude": False, "temp": True}]
    _lab([ModelEntry(blind.name, None, {}), ModelEntry(sited.name, None, {})])
    # one entry's declaration gives the whole run its input
    assert type(blind).seen[-1] == type(sited).seen[-1] == {"site": True, "attitude": False, "temp": True}


def test_a_declaration_outside_the_vocabulary_is_refused_when_registered():
    with pytest.raises(InputError, match="sim_needs must be a frozenset of temp, site, attitude, acc"):
        register(_plugin("zz_bad_needs", sim_needs=frozenset({"gps"})))
    with pytest.raises(InputError, match="sweep_axes must be a tuple of its parameter names"):
        register(_plugin("zz_bad_axes", sweep_axes=("rho_arw",)))
    assert "zz_bad_needs" not in REGISTRY and "zz_bad_axes" not in REGISTRY


# -- the scenario reader asks the effect ------------------------------------------------

def _scenario(tmp_path, effect_line: str, rate_hz: float = 100.0):
    (tmp_path / "p.toml").write_text('[[segment]]\nkind = "static"\nduration_s = 20.0\n')
    path = tmp_path / "sc.toml"
    path.write_text(f'name = "sc"\nsample_rate_hz = {rate_hz!r}\nseed = 3\nduration_s = 10.0\n'
                    f'effects = [{{ effect = "arw", n_deg_rt_h = 0.1 }}, {effect_line}]\n'
                    '[layout]\nscheme = 1\nn_gyros = 4\nalpha_deg = 54.7356\n[motion]\nprofile = "p.toml"\n')
    return path


def test_a_scenario_without_a_temperature_refuses_a_plugin_that_reads_one(registered, tmp_path):
    cls = registered(_plugin("zz_thermal", sim_needs=REGISTRY["temperature_bias"].sim_needs))
    o = run_cli(["simulate", _scenario(tmp_path, '{ effect = "zz_thermal" }'), "--out", tmp_path / "out"])
    assert_contract(o, "sc.toml")
    assert o.code == 2
    assert "column effects[1]: effects[1] (zz_thermal) needs a temperature: add a [temperature] table" in o.err
    assert type(cls).seen == []                                # refused before simulating
    # the built-in gets the same words
    o = run_cli(["simulate", _scenario(tmp_path, '{ effect = "temperature_bias", deg_h_per_c = 1.0, '
                                                 't0_c = 25.0 }'), "--out", tmp_path / "out"])
    assert o.code == 2 and "effects[1] (temperature_bias) needs a temperature" in o.err


class _Band(_Seer):
    """A plugin with a run rule, as the sinusoid has: its frequency below Nyquist."""

    name = "zz_band"
    params = (Param("freq_hz", "Hz", "freq_hz", identity, lo=0.0, doc="a frequency"),)

    def check_run(self, params, sample_rate_hz, duration_s):
        if params["freq_hz"] >= 0.5 * sample_rate_hz:
            raise InputError(f"freq_hz = {params['freq_hz']:g} Hz must be below the Nyquist frequency "
                             f"{0.5 * sample_rate_hz:g} Hz of sample_rate_hz = {sample_rate_hz:g} Hz",
                             column="freq_hz")


def test_a_plugin_run_rule_is_checked_where_the_built_in_one_is(registered, tmp_path):
    registered(_Band)
    o = run_cli(["simulate", _scenario(tmp_path, '{ effect = "zz_band", freq_hz = 60.0 }'),
                 "--out", tmp_path / "out"])
    assert_contract(o, "sc.toml")
    assert o.code == 2
    assert ("column effects[1].freq_hz: effects[1] (zz_band): freq_hz = 60 Hz must be below the Nyquist "
            "frequency 50 Hz of sample_rate_hz = 100 Hz") in o.err
    o = run_cli(["simulate", _scenario(tmp_path, '{ effect = "sinusoid", amp_deg_s = 0.1, freq_hz = 60.0 }'),
                 "--out", tmp_path / "out"])
    assert o.code == 2
    assert ("column effects[1].freq_hz: effects[1] (sinusoid): freq_hz = 60 Hz must be below the Nyquist "
            "frequency 50 Hz of sample_rate_hz = 100 Hz") in o.err
    o = run_cli(["simulate", _scenario(tmp_path, '{ effect = "zz_band", freq_hz = 5.0 }'),
                 "--out", tmp_path / "out"])
    assert o.code == 0, o.err


# -- the sweep's rho axes go to the effect that declares them -------------------------

class _Mixing(_Seer):
    """A plugin that owns the sweep's rho axes (as the correlation does)."""

    name = "zz_mixing"
    params = (Param("rho_arw", "-", "rho_arw", identity, required=False, default=0.0, doc="a rho"),
              Param("rho_rrw", "-", "rho_rrw", identity, required=False, default=0.0, doc="a rho"))
    sweep_axes = ("rho_arw", "rho_rrw")


def _sweep(tmp_path):
    (tmp_path / "p.toml").write_text('[[segment]]\nkind = "static"\nduration_s = 20.0\n')
    path = tmp_path / "sw.toml"
    path.write_text('name = "t"\nseed = 1\n[base]\nsample_rate_hz = 100.0\nduration_s = 10.0\n'
                    'effects = [{ effect = "arw", n_deg_rt_h = 0.1 }]\n'
                    '[base.layout]\nscheme = 1\nn_gyros = 6\nalpha_deg = 54.7356\n'
                    '[base.motion]\nprofile = "p.toml"\n[grid]\nrho_arw = [0.2]\n')
    return load_sweep(path)


def test_the_sweep_sets_the_rho_axes_on_the_effect_that_declares_them(registered, tmp_path, monkeypatch):
    (sc,) = _sweep(tmp_path).scenarios
    assert sc.data["effects"][-1] == {"effect": "correlation", "rho_arw": 0.2}
    # the correlation's declaration withdrawn, a plugin's taken: the same axis goes to the plugin
    monkeypatch.setattr(type(REGISTRY["correlation"]), "sweep_axes", ())
    registered(_Mixing)
    (sc,) = _sweep(tmp_path).scenarios
    assert sc.data["effects"][-1] == {"effect": "zz_mixing", "rho_arw": 0.2}
    assert sc.params["rho_arw"] == 0.2
