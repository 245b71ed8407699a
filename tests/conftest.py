"""Shared test fixtures."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys

import pytest


def _registry_state():
    """Copies of the effect registry's three dicts (effects._EFFECTS, _SOURCE, _PLUGINS), in order."""
    from gyroarray import effects
    return tuple(dict(d) for d in (effects._EFFECTS, effects._SOURCE, effects._PLUGINS))


def _restore_registry(saved) -> None:
    """The registry's dicts (the same objects, REGISTRY is a view of one) back to ``saved``, order too."""
    from gyroarray import effects
    for live, copy in zip((effects._EFFECTS, effects._SOURCE, effects._PLUGINS), saved):
        live.clear()
        live.update(copy)


@pytest.fixture(scope="session")
def _shipped_registry():
    """The registry as the package ships it (built-ins and installed entry points), read once."""
    return _registry_state()


@pytest.fixture(scope="module", autouse=True)
def _registry_as_shipped_per_module(_shipped_registry):
    """A module's own fixtures (scope="module", set up before any function fixture) may load a
    plugin (tests/test_plugins.py's ``record`` runs ``simulate --plugin``): the next module starts
    from the registry as shipped again. Before, thermostat_bias stayed registered for the rest of
    the worker and the MPU-6050 ladder (tests/test_real_mpu.py) tested it too: its fit taken out
    of the stochastic record moved quantization on gyro 1 from z 184.5 to 223.9 (issue 40)."""
    yield
    _restore_registry(_shipped_registry)


@pytest.fixture(autouse=True)
def _registry_as_shipped(_registry_as_shipped_per_module):
    """Effects a test registers (a plugin, a checked class) do not leak into the next test."""
    saved = _registry_state()
    yield
    _restore_registry(saved)


@pytest.fixture(autouse=True)
def _empty_content_caches():
    """A test starts with the content caches empty (analysis.memo): what it computes never
    depends on the tests the same worker ran before it."""
    from gyroarray.analysis.memo import clear_all
    clear_all()
    yield


@pytest.fixture
def cli(request):
    """Run ``gyroarray ARGS...`` as a user would, in this process (``gyroarray.cli.main.main`` with
    stdout/stderr captured: the interpreter's 2 s start-up and scipy's import are paid once per
    worker, not per call; tests/test_cli.py runs the installed entry point in a subprocess);
    ``check`` asserts exit 0 (stderr shown). Plugin tests keep a subprocess per call: a plugin
    loaded once must not be seen by the next call."""
    fresh = request.module.__name__.endswith("test_plugins")

    def run(*args, check: bool = True, timeout: float = 900.0) -> subprocess.CompletedProcess:
        from gyroarray.cli.main import main
        argv = [str(a) for a in args]
        if fresh:
            p = subprocess.run([sys.executable, "-m", "gyroarray.cli.main", *argv], capture_output=True,
                               text=True, timeout=timeout)
            assert not check or p.returncode == 0, p.stderr
            return p
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as stop:             # argparse's own refusals and --help
                code = stop.code if isinstance(stop.code, int) else (0 if stop.code is None else 2)
        p = subprocess.CompletedProcess([sys.executable, "-m", "gyroarray.cli.main", *argv], code or 0,
                                        out.getvalue(), err.getvalue())
        if check:
            assert p.returncode == 0, p.stderr
        return p
    return run
