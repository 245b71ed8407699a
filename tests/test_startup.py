"""The command line starts light, and an interrupt ends it as one line and exit 130.

* ``import gyroarray.cli.main``, ``gyroarray --help`` and every ``gyroarray SUB --help`` load
  none of the heavy libraries (docs/layout.md: the parser is light);
* SIGINT (Ctrl-C) at any moment (while the command line loads, in ``main`` before the parser, in
  a command's heavy imports or its work, while the output is written, at the interpreter's exit)
  gives exit code 130 and stderr the one line ``gyroarray: interrupted``, no traceback;
* a comment that says a function-level import is deferred so as not to load a library
  (``# lazy: loads numba``) is true: a plain import of its module does not load that library.

Each run is a fresh interpreter (``sys.modules`` of this one has everything loaded). The moments
of an interrupt are events, never a wall-clock time: the process sends SIGINT to itself when a
named module starts to import or its output is written, or this test sends it once the process
reports (``-X importtime``) that a named module has loaded.
"""

from __future__ import annotations

import ast
import io
import json
import os
import re
import signal
import subprocess
import sys
import time
import tokenize
from pathlib import Path

import pytest

from wall_bound import as_from_a_terminal

SRC = Path(__file__).resolve().parents[1] / "src"
SCRIPT = Path(sys.executable).with_name("gyroarray")   # the console script of this venv

#: Libraries the command line must not load to build its parser.
HEAVY = ("numpy", "scipy", "numba", "pandas", "matplotlib", "pyarrow", "mujoco", "dask")

INTERRUPTED = "gyroarray: interrupted"

#: A command that runs for many minutes (1000 paired Monte-Carlo runs of 10 h at 100 Hz): it is
#: always still at work when the interrupt comes.
LONG = ["design", "--recommend", "--arw", "0.1", "--check", "1000", "--horizon-s", "36000", "--json"]




def _env() -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    env.pop("GYROARRAY_DEBUG", None)
    return env


def _python(code: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=_env(), timeout=timeout, preexec_fn=as_from_a_terminal)


_HEAVY_LOADED = f"sorted({{m.split('.')[0] for m in sys.modules}} & set({HEAVY!r}))"


def test_import_of_the_cli_loads_no_heavy_library():
    r = _python(f"import sys, gyroarray.cli.main; print({_HEAVY_LOADED})")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


def test_help_of_every_subcommand_loads_no_heavy_library():
    code = f"""
import argparse, contextlib, io, json, sys
from gyroarray.cli.main import build_parser, main
sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
found = {{}}
for argv in [["--help"]] + [[name, "--help"] for name in sub.choices]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            main(argv)
        except SystemExit as stop:
            assert stop.code == 0, (argv, stop.code)
    assert "usage: gyroarray" in out.getvalue(), argv
    found[" ".join(argv)] = {_HEAVY_LOADED}
print(json.dumps(found))
"""
    r = _python(code)
    assert r.returncode == 0, r.stderr
    found = json.loads(r.stdout)
    assert len(found) >= 20          # --help and the 19 subcommands (gdop ... parity)
    assert {argv: mods for argv, mods in found.items() if mods} == {}


# --- SIGINT -----------------------------------------------------------------------------------

def _interrupt_at_import(module: str, argv: list[str]) -> str:
    """A program like the console script that sends itself SIGINT when ``module`` starts to
    import (an import hook: no timing)."""
    return f"""
import importlib.abc, os, signal, sys
class Interrupt(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == {module!r}:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, Interrupt())
from gyroarray.cli.main import main
sys.exit(main({argv!r}))
"""


def _assert_interrupted(r) -> None:
    lines = [ln for ln in r.stderr.splitlines() if not ln.startswith("import time:")]
    assert lines == [INTERRUPTED], r.stderr[-3000:]
    assert r.returncode == 130


GDOP = ["gdop", "--scheme", "1", "--n", "4", "--alpha", "54.74", "--json"]


@pytest.mark.parametrize("module, argv", [
    ("argparse", GDOP),                  # cli.main's own imports, right after its handler
    ("gyroarray.cli.allan", GDOP),       # the subcommands' modules
    ("gyroarray.core.limits", GDOP),     # main(), before the parser is built
    ("numpy", GDOP),                     # the command's imports, inside cmd_gdop
])
def test_sigint_while_loading_exits_130_with_one_line(module, argv):
    _assert_interrupted(_python(_interrupt_at_import(module, argv)))


def test_sigint_while_the_output_is_written_exits_130_with_one_line():
    code = f"""
import os, signal, sys
class Stdout:
    def write(self, text):
        os.kill(os.getpid(), signal.SIGINT)
        return len(text)
    def flush(self):
        pass
from gyroarray.cli.main import main
sys.stdout = Stdout()
sys.exit(main({GDOP!r}))
"""
    _assert_interrupted(_python(code))


def test_sigint_at_the_interpreters_exit_exits_130_with_one_line():
    code = f"""
import os, signal, sys
from gyroarray.cli.main import main
code = main({GDOP!r})
os.kill(os.getpid(), signal.SIGINT)
sys.exit(code)
"""
    r = _python(code)
    assert json.loads(r.stdout) == {"gdop": pytest.approx(1.5, rel=1e-6)}   # the output stands
    _assert_interrupted(r)


def test_main_called_in_process_keeps_the_callers_sigint_handler():
    code = f"""
import importlib, signal, sys
cli = importlib.import_module("gyroarray.cli.main")     # as a library or a test imports it
assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
code = cli.main({GDOP!r})
print(code, signal.getsignal(signal.SIGINT) is signal.default_int_handler)
"""
    r = _python(code)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-1] == "0 True"


def _interrupt_once_loaded(marker: str, argv: list[str], tmp_path) -> subprocess.CompletedProcess:
    """Run the console script; send SIGINT once ``-X importtime`` says ``marker`` has loaded."""
    err = tmp_path / "stderr.txt"
    with open(err, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-X", "importtime", str(SCRIPT), *argv],
                                stdout=subprocess.DEVNULL, stderr=fh, env=_env(),
                                preexec_fn=as_from_a_terminal)
    loaded = re.compile(r"^import time:.*\| +" + re.escape(marker) + r"$", re.M)
    try:
        deadline = time.monotonic() + 300          # generous: a loaded machine
        while not loaded.search(err.read_text()):
            assert proc.poll() is None, err.read_text()[-3000:]
            assert time.monotonic() < deadline, f"{marker} never loaded"
            time.sleep(0.02)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return subprocess.CompletedProcess(proc.args, proc.returncode, "", err.read_text())


@pytest.mark.skipif(not SCRIPT.exists(), reason="the gyroarray console script is not installed")
def test_sigint_right_after_start_exits_130_with_one_line(tmp_path):
    _assert_interrupted(_interrupt_once_loaded("gyroarray.cli.common", LONG, tmp_path))


@pytest.mark.slow
@pytest.mark.skipif(not SCRIPT.exists(), reason="the gyroarray console script is not installed")
@pytest.mark.parametrize("marker", ["numpy", "gyroarray.design.recommend"])
def test_sigint_during_the_work_exits_130_with_one_line(marker, tmp_path):
    _assert_interrupted(_interrupt_once_loaded(marker, LONG, tmp_path))


# --- deferred-import comments -----------------------------------------------------------------

#: A library a comment may say an import defers (the dotted name when it names a submodule).
_LIBRARY = re.compile(r"\b(numpy|scipy(?:\.[a-z_]+)?|numba|pandas|matplotlib|pyarrow(?:\.[a-z_]+)?|"
                      r"mujoco|dask(?:\.distributed)?|rosbags|llvmlite)\b")
_CLAIM = re.compile(r"#\s*(?:deferred|lazy)\b")


def deferral_claims(src: Path = SRC) -> list[tuple[str, int, str, list[str]]]:
    """``(module, line, comment, libraries)`` for each function-level import under ``src`` whose
    comment (on the statement, or the comment line just above its block, as
    tests/test_layers.py reads them) says it is deferred or lazy and names libraries before any
    ``;`` (what follows is a remark: ``pyarrow itself comes with pandas``)."""
    out = []
    for path in sorted(src.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        tree = ast.parse(text)
        comment, only = {}, set()
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type == tokenize.COMMENT:
                comment[tok.start[0]] = tok.string
                if not tok.line[:tok.start[1]].strip():
                    only.add(tok.start[0])
        imports = sorted((n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))),
                         key=lambda n: n.lineno)
        ends = {n.end_lineno: n for n in imports}
        inner = {id(n) for fn in ast.walk(tree) if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef))
                 for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))}
        module = ".".join(path.relative_to(src).with_suffix("").parts).removesuffix(".__init__")
        for node in imports:
            if id(node) not in inner:
                continue
            said = [comment[i] for i in range(node.lineno, node.end_lineno + 1) if i in comment]
            if not said:
                first = node
                while first.lineno - 1 in ends and first.lineno - 1 not in only:
                    first = ends[first.lineno - 1]
                said = [comment[first.lineno - 1]] if first.lineno - 1 in only else []
            text_said = " ".join(said)
            claim = _CLAIM.search(text_said)
            # the claim is what follows "deferred"/"lazy" up to a ";" (then remarks)
            libraries = (sorted(set(_LIBRARY.findall(text_said[claim.end():].split(";")[0])))
                         if claim else [])
            if libraries:
                out.append((module, node.lineno, text_said, libraries))
    return out


def false_deferrals(claims, modules_of=None) -> list[str]:
    """The claims whose library a plain import of their module loads (one interpreter per
    module, or ``modules_of(module)``: the set of modules loaded by importing it)."""
    def loaded(module):
        r = _python(f"import json, sys, {module}; print(json.dumps(sorted(sys.modules)))")
        assert r.returncode == 0, r.stderr[-2000:]
        return set(json.loads(r.stdout.splitlines()[-1]))
    modules_of = modules_of or loaded
    seen, bad = {}, []
    for module, line, said, libraries in claims:
        if module not in seen:
            seen[module] = modules_of(module)
        wrong = [lib for lib in libraries if lib in seen[module]]
        if wrong:
            bad.append(f"{module}:{line}: {said.strip()} (a plain import loads {', '.join(wrong)})")
    return bad


def test_the_deferral_check_can_fail(tmp_path):
    fake = tmp_path / "gyroarray"
    fake.mkdir()
    (fake / "m.py").write_text(
        "import numpy\n"
        "def f():\n"
        "    import scipy  # lazy: loads scipy\n"
        "    # deferred: numba loads only here\n"
        "    import numba\n"
        "    import pandas  # not deferred: numpy loads pandas (a claim of nothing)\n"
        "    import pyarrow  # a local name\n")
    claims = deferral_claims(tmp_path)
    assert [(c[1], c[3]) for c in claims] == [(3, ["scipy"]), (5, ["numba"])]
    bad = false_deferrals(claims, modules_of=lambda m: {"numpy", "numba", m})
    assert [b.split(": ")[0] for b in bad] == ["gyroarray.m:5"]


def test_deferral_comments_of_the_cli_are_true():
    """The command modules together load none of the libraries their comments defer (a sample
    of the check below, in one interpreter: the command line is light)."""
    claims = [c for c in deferral_claims() if c[0].startswith("gyroarray.cli.")]
    assert len(claims) > 50
    modules = sorted({c[0] for c in claims})
    r = _python(f"import json, sys, {', '.join(modules)}; print(json.dumps(sorted(sys.modules)))")
    assert r.returncode == 0, r.stderr
    together = set(json.loads(r.stdout))
    assert false_deferrals(claims, modules_of=lambda m: together) == []


@pytest.mark.slow
def test_every_deferral_comment_is_true():
    """Each module with a claim, imported alone (about 35 interpreters)."""
    bad = false_deferrals(deferral_claims())
    assert bad == [], ("function-level imports whose comment says they defer a library that a "
                       "plain import of their module loads already (move the import to module "
                       "level, or say what it defers):\n" + "\n".join(bad))
