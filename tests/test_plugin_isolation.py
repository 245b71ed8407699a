"""A plugin loaded and taken out again leaves nothing behind (issue 40).

The MPU-6050 ladder (tests/test_real_mpu.py) failed after tests/test_plugins.py in one process:
that module's ``record`` fixture (scope="module", set up before the function-scoped registry
snapshot of tests/conftest.py) registered thermostat_bias, which then stayed for the rest of the
worker, and the ladder tested it too (its fit taken out of the stochastic record moved quantization
on gyro 1 from z 184.5 to 223.9, and the path changed). With the plugin taken out again (unregister)
the ladder's first three steps were the same bits as in a fresh process (D, every candidate's z,
every fit): the rest of the library keeps no state of it. These tests pin both halves.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from gyroarray import effects

PLUGIN = Path(__file__).resolve().parents[1] / "examples" / "plugins" / "thermostat_bias.py"


def _state():
    return list(effects._EFFECTS.items()), dict(effects._SOURCE), dict(effects._PLUGINS)


def test_unregister_leaves_the_registry_as_it_was_and_the_plugin_loads_again():
    before = _state()
    assert "thermostat_bias" not in effects.REGISTRY           # the shipped registry
    assert effects.load_plugin(PLUGIN) == ["thermostat_bias"]
    assert "thermostat_bias" in effects.REGISTRY and effects._PLUGINS
    effects.unregister("thermostat_bias")
    assert _state() == before                                   # names, instances, order, sources, files
    # the file's entry went with it: loading it again registers the effect again (before, the
    # stale entry returned the name with nothing registered)
    assert effects.load_plugin(PLUGIN) == ["thermostat_bias"]
    assert "thermostat_bias" in effects.REGISTRY
    effects.unregister("thermostat_bias")
    assert _state() == before


_MODULE_A = f'''
import pytest
from gyroarray import effects

@pytest.fixture(scope="module")
def record():
    effects.load_plugin({str(PLUGIN)!r})      # as tests/test_plugins.py's record does, via the CLI
    return None

def test_uses_the_plugin(record):
    assert "thermostat_bias" in effects.REGISTRY
'''

_MODULE_B = f'''
from gyroarray import effects

def test_the_next_module_sees_the_shipped_registry():
    assert "thermostat_bias" not in effects.REGISTRY, list(effects.REGISTRY)
    assert not effects._PLUGINS
    assert effects.load_plugin({str(PLUGIN)!r}) == ["thermostat_bias"]   # and can load it again
'''


@pytest.mark.slow   # a pytest run in a subprocess (imports the effects: about 18 s on 2 cores): make score
def test_a_plugin_a_module_fixture_loads_is_gone_in_the_next_module(tmp_path):
    """The repository's conftest, two modules in one process: the first's module fixture loads the
    plugin, the second must not see it (before: it did, and its last assert failed as well)."""
    shutil.copy(Path(__file__).with_name("conftest.py"), tmp_path / "conftest.py")
    (tmp_path / "test_a.py").write_text(_MODULE_A)
    (tmp_path / "test_b.py").write_text(_MODULE_B)
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:randomly",
                        "-p", "no:xdist", str(tmp_path / "test_a.py"), str(tmp_path / "test_b.py")],
                       capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert p.returncode == 0 and "2 passed" in p.stdout, p.stdout + p.stderr
