"""A regular (non-editable) install works on its own, run from outside the source tree.

The top-level folders (sim/, analysis/, reports/, ...) are mapped into the ``gyroarray``
package by pyproject.toml; an editable install hides mistakes in that mapping (a relative
import that reaches over it, a data file left out of the wheel). This test builds a plain
``pip install --target`` from a copy of the sources and runs the CLI from an empty
directory with only that install on PYTHONPATH.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# What pyproject.toml builds the package from (its [tool.setuptools.package-dir]).
SOURCES = ("pyproject.toml", "README.md", "src")

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("setuptools") is None or importlib.util.find_spec("wheel") is None,
    reason="building offline needs setuptools and wheel in the environment")


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(site directory, empty working directory) of a fresh non-editable install."""
    base = tmp_path_factory.mktemp("install")
    src, site, cwd = base / "src", base / "site", base / "cwd"
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "demo"))
        else:
            src.mkdir(exist_ok=True)
            shutil.copy2(ROOT / name, src / name)
    # --no-build-isolation: build with this environment's setuptools, no network.
    proc = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps",
                           "--no-build-isolation", "--no-compile", "--target", str(site), str(src)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    cwd.mkdir()
    return site, cwd


def _run(installed, *args):
    site, cwd = installed
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(PYTHONPATH=str(site), OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def test_every_module_comes_from_the_install(installed):
    site, _ = installed
    code = ("import sys, gyroarray.cli.main, gyroarray.reports.design_plots, gyroarray.analysis.davar, "
            "gyroarray.estimators, gyroarray.sim.scenario, gyroarray.sweep.runner, "
            "gyroarray.effects, gyroarray.chain.check; "
            "print('\\n'.join(sorted(getattr(m, '__file__', None) or '' for n, m in "
            "list(sys.modules.items()) if n == 'gyroarray' or n.startswith('gyroarray.'))))")
    files = _run(installed, "-c", code).split()
    assert len(files) > 20
    outside = [f for f in files if not Path(f).is_relative_to(site)]
    assert outside == []


def test_package_data_is_installed(installed):
    site, _ = installed
    for rel in ("data/paper003_tables.toml", "data/scenarios/thresholds.toml",
                "data/scenarios/paper_values.toml", "data/scenarios/examples/tetra_swing.toml"):
        assert (site / "gyroarray" / rel).is_file(), rel


def test_gdop_matches_closed_form(installed):
    # Scheme 1 puts all N axes on one cone, equally spaced in azimuth (N >= 3), so
    # H'H = N diag(sin^2(a)/2, sin^2(a)/2, cos^2(a)) and GDOP^2 = 4/(N sin^2 a) + 1/(N cos^2 a).
    out = json.loads(_run(installed, "-m", "gyroarray.cli.main", "gdop", "--scheme", "1", "--n", "4",
                          "--alpha", "60", "--json"))
    a = math.radians(60.0)
    assert out["gdop"] == pytest.approx(math.sqrt(4 / (4 * math.sin(a) ** 2)
                                                  + 1 / (4 * math.cos(a) ** 2)), abs=1e-12)


def test_paper_tables_read_the_packaged_data(installed):
    out = json.loads(_run(installed, "-m", "gyroarray.cli.main", "design", "--paper-tables", "--json"))
    cells = {c["label"]: c for c in out["paper_tables"]}
    cell = cells["Scheme 1, N=8, alpha=60 deg, rho=0"]
    # the closed form above with N = 8, a = 60 deg: sqrt(7/6); the paper prints 1.0801
    assert cell["computed"] == pytest.approx(math.sqrt(7 / 6), abs=1e-12)
    assert cell["paper"] == 1.0801 and cell["reproduces"]
    assert out["cells_not_reproduced"] == 4
