"""Shared test fixtures."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.fixture(autouse=True)
def _registry_as_shipped():
    """Effects a test registers (a plugin, a checked class) do not leak into the next test."""
    from gyroarray import effects
    saved = (dict(effects._EFFECTS), dict(effects._SOURCE), dict(effects._PLUGINS))
    yield
    for live, copy in zip((effects._EFFECTS, effects._SOURCE, effects._PLUGINS), saved):
        live.clear()
        live.update(copy)


@pytest.fixture
def cli():
    """Run ``python -m gyroarray.cli ARGS...`` as a user would; ``check`` asserts exit 0 (stderr shown)."""
    def run(*args, check: bool = True, timeout: float = 900.0) -> subprocess.CompletedProcess:
        p = subprocess.run([sys.executable, "-m", "gyroarray.cli", *map(str, args)],
                           capture_output=True, text=True, timeout=timeout)
        if check:
            assert p.returncode == 0, p.stderr
        return p
    return run
