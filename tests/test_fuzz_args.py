"""Fuzzing every command-line argument of the CLI with extreme values (issue 28).

The arguments are read from the parser itself (:func:`gyroarray.cli.main.build_parser`),
so an option added later is fuzzed without touching this file. Each option
of a command draws from a pool of hostile values: numbers at the float
extremes (``1e-300``, ``1e300``, ``5e-324``), negative, zero, huge counts,
``nan``, ``inf``, text, empty strings; paths that do not exist, are folders,
FIFOs, devices (inputs only), 300-character names, names with a newline,
and the command's own input (for an output option: it must be refused).

The properties, for every generated command line:

* exit 0 with finite numbers, or exit 2 with exactly one stderr line
  naming the file or the argument (``hostile.assert_contract``); never
  exit 1 (an internal error), never 134, never a traceback;
* nothing the user gave is modified (every input file's bytes and mode
  are hashed before and after);
* memory stays bounded: the process's address space is capped (as
  ``prlimit --as`` does) at what it holds before the call plus
  :data:`AS_HEADROOM`, with ``--max-memory`` at :data:`BUDGET`; a command
  that ignored its budget dies with a ``MemoryError`` (an internal error,
  which the first property catches) instead of taking the machine.

``make test`` runs a small derandomized sample; ``make fuzz`` runs
``GYROARRAY_FUZZ_EXAMPLES`` examples per test with random seeds.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import resource
import stat
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gyroarray.core.errors import one_line
from hostile import (assert_contract, axes_sidecar, finite_numbers, run_cli, write_measurement,
                     write_scenario)

LONG = int(os.environ.get("GYROARRAY_FUZZ_EXAMPLES", "0"))
#: examples per command: a bounded, derandomized sample in make test; in make fuzz 4 % of the
#: run's total each (tests/test_fuzz.py says how the total is shared)
FUZZ = settings(max_examples=max(LONG * 4 // 100, 1) if LONG else 6, deadline=None, derandomize=not LONG, database=None,
                suppress_health_check=list(HealthCheck))

#: --max-memory given to every call
BUDGET = "1G"
#: address space allowed beyond what the process holds before the call [bytes]: the budget,
#: plus numba/LLVM's JIT and the interpreter's arenas (a command that plans within 1 GiB
#: never comes near it; one that ignores the budget does)
AS_HEADROOM = 3 * 2**30

NUMBERS = ["0", "-0", "1", "2", "3", "-1", "-5", "2.5", "0.5", "1e-300", "-1e-300", "5e-324",
           "1e300", "-1e300", "1e308", "nan", "inf", "-inf", "10000000", "1000000000000",
           "99999999999999999999999", "abc", "", " ", "1,2", "0x10"]
LISTS = ["1,2", "0,0", "-0.1,0.5", "1e300,1e-300", "nan,1", "a,b", ",", "1,2,3,4,5,6,7,8,9",
         "0.1", "-1,-2", "5,0.03", "1e-300,1e300"]

# commands fuzzed, with what their positional argument is (None: no positional)
COMMANDS = {"allan": "measurement", "davar": "measurement", "diagnose": "measurement",
            "fit": "measurement", "fdi": "measurement", "gdop": None, "design": None,
            "simulate": "scenario", "run": "scenario",
            # the surfaces added since (issue 40): plan, export, fuse, parity
            "plan": None, "export": "model", "fuse": "measurement", "parity": "measurement"}
#: options left alone: they select long jobs by design (their counts are fuzzed elsewhere) or
#: name code to run
SKIP = {"--help", "--version", "--plugin", "--max-memory", "--scheduler", "--paper-tables",
        "--no-cache"}


def _parser_actions(command: str):
    from gyroarray.cli.main import build_parser
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[command]._actions


def _vm_bytes() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    return 0


class _AddressSpaceCap:
    """``prlimit --as`` on this process for the duration of one call."""

    def __enter__(self):
        self.old = resource.getrlimit(resource.RLIMIT_AS)
        cap = _vm_bytes() + AS_HEADROOM
        if self.old[1] != resource.RLIM_INFINITY:
            cap = min(cap, self.old[1])
        resource.setrlimit(resource.RLIMIT_AS, (cap, self.old[1]))
        return self

    def __exit__(self, *exc):
        resource.setrlimit(resource.RLIMIT_AS, self.old)
        return False


def _fingerprint(paths) -> dict:
    out = {}
    for p in paths:
        p = Path(p)
        try:
            st_ = os.lstat(p)
        except OSError:
            out[str(p)] = None
            continue
        if stat.S_ISREG(st_.st_mode):
            out[str(p)] = (st_.st_mode, hashlib.sha256(p.read_bytes()).hexdigest())
        else:
            out[str(p)] = (st_.st_mode, None)
    return out


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A small valid measurement, model, scenario and the hostile paths, shared by the examples."""
    folder = tmp_path_factory.mktemp("args")
    rng = np.random.default_rng(28)
    n = 3000
    t = np.arange(n) / 50.0
    # six gyros on a cone: enough for fdi (N >= 4) and for every analysis
    g = rng.normal(0.0, 0.05, (n, 6)) + np.cumsum(rng.normal(0.0, 1e-3, (n, 6)), axis=0)
    meas = write_measurement(folder, "meas", t, g, sidecar=axes_sidecar(6))
    model = folder / "model.toml"
    model.write_text('effects = [ { effect = "arw", n_deg_rt_h = 3.0 }, '
                     '{ effect = "rrw", k_deg_h_rt_h = 30.0 } ]\n')
    scen = write_scenario(folder, "scen", rate=20.0)
    (folder / "adir").mkdir()
    fifo = folder / "fifo"
    os.mkfifo(fifo)
    return {"folder": folder, "measurement": meas, "model": model, "scenario": scen,
            "fifo": fifo, "dir": folder / "adir"}


def _path_values(inputs, output: bool):
    f = inputs["folder"]
    vals = [f / "missing.toml", inputs["dir"], f / ("x" * 300 + ".png"), f / "new\nline.png",
            inputs["measurement"], inputs["model"]]
    if output:
        # the command's inputs (must be refused, --force or not) and fresh names
        vals += [f / "out_a.png", f / "out_b.json", f / "sub" / "out.toml", f / "out_c.html"]
    else:
        vals += [inputs["fifo"], Path("/dev/zero"), inputs["scenario"]]
    return vals


def _is_output(action) -> bool:
    return any(s in ("--out", "--plot", "--md", "--model-out") for s in action.option_strings)


@st.composite
def command_lines(draw, command: str, inputs: dict):
    argv = [command]
    if command == "design" and draw(st.booleans()):
        argv += ["--recommend", "--arw", "0.3", "--n", "4,6"]    # a question the drawn options vary
    pos = COMMANDS[command]
    if pos is not None:
        argv.append(str(inputs[pos]))
    actions = [a for a in _parser_actions(command)
               if a.option_strings and not set(a.option_strings) & SKIP]
    # one to three optional arguments an example (most of them then reach the work, instead of
    # all dying at the first of many hostile values), plus the required ones
    optional = [a for a in actions if not a.required]
    chosen = set(draw(st.lists(st.sampled_from(range(len(optional))), min_size=1, max_size=3,
                               unique=True))) if optional else set()
    for action in actions:
        opt = action.option_strings[-1]
        if not action.required and optional.index(action) not in chosen:
            continue
        if action.nargs == 0:                          # a flag
            argv.append(opt)
            continue
        if action.choices:
            value = draw(st.sampled_from([str(c) for c in action.choices] + ["nonsense"]))
        elif opt == "--estimator":                     # a name the work then reaches
            value = draw(st.sampled_from(["gls", "ols", "kf_array", "naive", "nonsense"]))
        elif action.type is Path or action.metavar in ("DIR",) or _is_output(action):
            if command in ("simulate",) and opt == "--out":
                value = str(draw(st.sampled_from([inputs["folder"] / "simout", inputs["measurement"],
                                                  inputs["folder"] / "x" / ("y" * 300)])))
            else:
                value = str(draw(st.sampled_from(_path_values(inputs, _is_output(action)))))
        elif action.metavar and "," in str(action.metavar):
            value = draw(st.sampled_from(LISTS + NUMBERS))
        else:
            value = draw(st.sampled_from(NUMBERS))
        argv += [f"{opt}={value}"] if value.startswith("-") else [opt, value]
    if "--force" not in argv and draw(st.booleans()):
        argv.append("--force")
    argv += ["--max-memory", BUDGET, "--json"]
    return argv


def _given(argv, inputs) -> list:
    """The files this command line reads: its positional input (with the measurement's sidecar,
    the scenario's profile) and the file of every option that is not an output. An output
    option may name one of the fixture's files: with --force that file is the user's to
    replace, unless the same command also reads it."""
    out, outputs = [], {"--out", "--plot", "--md", "--model-out"}
    pos = COMMANDS[argv[0]]
    if pos is not None:
        out += {"measurement": [inputs["measurement"], inputs["folder"] / "meas.toml"],
                "scenario": [inputs["scenario"], inputs["folder"] / "static10.toml"],
                "model": [inputs["model"]]}[pos]
    for opt, value in zip(argv, argv[1:]):
        if opt.startswith("--") and opt not in outputs and "/" in value:
            out.append(Path(value))
    return out


def _check(argv, inputs):
    given_files = _given(argv, inputs)
    before = _fingerprint(given_files)
    with _AddressSpaceCap():
        o = run_cli(argv, timeout=300)
    assert _fingerprint(given_files) == before, ("an input was modified", argv)
    assert_contract(o)
    if o.code == 2:
        line = o.err.strip()
        named = [a.split("=")[0] for a in argv if a.startswith("--")] + \
                [one_line(Path(a).name) for a in argv if "/" in a] + [argv[0], "--max-memory"]
        assert any(n and n in line for n in named) or "argument" in line or "usage" in line, \
            ("the refusal names no file or argument", argv, line)
    else:
        assert finite_numbers(o.json), argv


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_argument_at_its_extremes(command, inputs):
    @FUZZ
    @given(data=st.data())
    def one(data):
        argv = data.draw(command_lines(command, inputs))
        _check(argv, inputs)
    one()


def test_a_huge_count_is_refused_before_work(inputs):
    """Counts a user passes are checked before work (the issue's reproductions, in-process)."""
    meas = str(inputs["measurement"])
    for argv, opt in ((["diagnose", meas, "--runs", "10000000"], "--runs"),
                      (["allan", meas, "--taus", "10000"], None),
                      (["run", str(inputs["scenario"]), "--replicates", "1000000"], "--replicates"),
                      (["design", "--recommend", "--arw", "0.1", "--check", "100000"], "--check")):
        with _AddressSpaceCap():
            o = run_cli(argv + ["--json"], timeout=120)
        assert_contract(o)
        if opt is not None:
            assert o.code == 2 and opt in o.err, (argv, o.err)


def test_address_space_cap_catches_an_unbounded_allocation():
    """The cap works: a 64 GiB allocation under it fails instead of taking the machine."""
    with _AddressSpaceCap(), pytest.raises(MemoryError):
        np.ones(2**33)


def test_refusals_of_commands_without_an_input_file_name_the_option():
    """Found by this fuzzer: ``gdop --rho 1`` and ``design --motion 0`` were refused without
    naming the option (the message spoke of "rho" and "motion profile")."""
    for argv, opt in ((["gdop", "--scheme", "1", "--n", "3", "--alpha", "0", "--rho", "1"], "--rho:"),
                      (["design", "--recommend", "--arw", "0.3", "--motion", "0"], "--motion:")):
        o = run_cli(argv)
        assert_contract(o)
        assert o.code == 2 and o.err.startswith(f"gyroarray: {opt}"), (argv, o.err)


def test_design_check_without_rate_random_walk():
    """Found by this fuzzer: ``design --recommend --arw 0.3 --check K`` (no --rrw) recommended
    the array KF, then could not build it for the check (bias states with no process noise).
    The check now builds the estimator as the predictor designs it (no bias states without a
    random walk), and the prediction lies inside the simulated 95 % interval: an outside check,
    since the runs are the simulator's own effects and the real estimator."""
    o = run_cli(["design", "--recommend", "--arw", "0.3", "--n", "4,6", "--check", "12",
                 "--seed", "5", "--json"], timeout=300)
    assert_contract(o)
    assert o.code == 0, o.err
    top = o.json["check"]["designs"][0]
    mc = top["rms_3axis_deg_s"]["monte_carlo"]
    assert mc["ci_low"] <= top["rms_3axis_deg_s"]["predicted"] <= mc["ci_high"], top
