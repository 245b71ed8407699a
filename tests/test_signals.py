"""No temporary file outlives a signal, and none is ever left under an output's final name.

Every file gyroarray writes is staged in a hidden temporary file beside it, named for the
machine and the process (``.NAME.gyroarray-tmp-<host>-<pid>-<random>.tmp``,
:data:`gyroarray.core.outputs.TEMP_MARK`), and given its name at the end. Here:

* in this process (fast): the names; a temporary of a process that is gone removed by the next
  write into the folder (a file, a folder), those of live processes, other machines and other
  programs left alone; a SIGTERM turned into :class:`~gyroarray.core.outputs.Terminated` in the
  middle of a write leaves nothing; an ignored SIGHUP (``nohup``) stays ignored;
* in a subprocess (slow: a fresh interpreter per command, several on a loaded machine): each
  command that writes (convert of a bag, fuse --out in memory and streamed, simulate --out,
  sweep --out, export --out, fit --out, report --out) is held the moment its first temporary is
  written and synced (a ``sitecustomize`` that pauses ``os.fsync`` on such a file, in the
  sweep's workers too), then SIGTERMed (also SIGHUP, SIGINT): it exits ``128 + signal`` with one
  line, no temporary is left and nothing is under the final name; SIGKILLed: the temporary stays
  (no handler runs) and the next run of the same command removes it and writes the output.

Every wait is on the event (the hold's flag file, the process's exit), polled, under a bound
scaled to this machine's speed now (:func:`wall_bound.bound_s`).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gyroarray.core import outputs
from hostile import run_cli, tiny_sweep
from wall_bound import as_from_a_terminal, bound_s

MARK = outputs.TEMP_MARK

HOLD = '''\
import os
_dir = os.environ.get("GYROARRAY_TEST_HOLD_DIR")
if _dir:
    import time
    _real = os.fsync

    def _hold(fd):
        """Sync, then (once) pause for ever when ``fd`` is a gyroarray temporary under _dir."""
        _real(fd)
        try:
            where = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            return
        if ".gyroarray-tmp-" in os.path.basename(where) and where.startswith(_dir):
            try:
                os.close(os.open(os.environ["GYROARRAY_TEST_HOLD_FLAG"],
                                 os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            except FileExistsError:
                return
            time.sleep(3600)
    os.fsync = _hold
'''




def _marked(folder: Path) -> list[str]:
    """Every gyroarray temporary (file or folder) under ``folder``."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if MARK in p.name)


def _dead_pid() -> int:
    """The pid of a process that has ended and been reaped."""
    p = subprocess.Popen(["true"])
    p.wait()
    return p.pid


# -- in this process ------------------------------------------------------------------------

def test_a_temporary_is_named_for_its_output_host_and_process(tmp_path):
    fh, staged = outputs.open_staged(tmp_path / "run42.csv.gz")
    fh.close()
    name = Path(staged.tmp).name
    assert name.startswith(".run42.csv.gz" + MARK) and name.endswith(".tmp")
    host, pid = name[len(".run42.csv.gz" + MARK):].split("-")[:2]
    assert len(host) == 8 and int(pid) == os.getpid()
    assert not outputs.stale_temp(name)                 # this process lives
    staged.discard()
    assert list(tmp_path.iterdir()) == []


def test_the_next_write_removes_what_a_dead_process_left_and_only_that(tmp_path):
    host = outputs._host_tag()
    dead, alive = _dead_pid(), os.getppid()
    stale_file = tmp_path / f".out.csv{MARK}{host}-{dead}-abcd1234.tmp"
    stale_dir = tmp_path / f"gyroarray-fuse{MARK}{host}-{dead}-efgh5678"
    live_file = tmp_path / f".out.csv{MARK}{host}-{alive}-abcd1234.tmp"
    elsewhere = tmp_path / f".out.csv{MARK}{(int(host, 16) ^ 1):08x}-{dead}-abcd1234.tmp"
    theirs = tmp_path / ".out.csv.999.tmp"              # not gyroarray's mark: never touched
    for p in (stale_file, live_file, elsewhere, theirs):
        p.write_bytes(b"partial")
    stale_dir.mkdir()
    (stale_dir / "phase_1.bin").write_bytes(b"\0" * 64)
    outputs.write_text(tmp_path / "other.txt", "hello\n")
    assert (tmp_path / "other.txt").read_text() == "hello\n"
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted([live_file.name, elsewhere.name, theirs.name, "other.txt"])


def test_a_temporary_folder_of_a_dead_process_is_removed_by_the_next_one(tmp_path):
    stale = tmp_path / f"gyroarray-allan{MARK}{outputs._host_tag()}-{_dead_pid()}-zz99zz99"
    stale.mkdir()
    (stale / "phase.bin").write_bytes(b"x")
    made = outputs.make_temp_dir("allan", tmp_path)
    try:
        assert sorted(p.name for p in tmp_path.iterdir()) == [Path(made).name]
        assert Path(made).name.startswith("gyroarray-allan" + MARK)
    finally:
        os.rmdir(made)


def test_a_sigterm_in_the_middle_of_a_write_leaves_nothing(tmp_path, monkeypatch):
    """Terminated raised while the second of two files is staged: neither name appears, no
    temporary stays (the clean-up on the way out ran)."""
    real = outputs._write_all
    calls = []

    def interrupted(fd, data):
        calls.append(len(data))
        if len(calls) == 2:
            raise outputs.Terminated(signal.SIGTERM)
        real(fd, data)
    monkeypatch.setattr(outputs, "_write_all", interrupted)
    with pytest.raises(outputs.Terminated) as stop:
        outputs.write_many([(tmp_path / "a.html", b"<html>"), (tmp_path / "a.md", b"# a")])
    assert stop.value.exit_code == 143 and str(stop.value) == "terminated by SIGTERM"
    assert calls == [6, 3] and list(tmp_path.iterdir()) == []
    assert not [q for q in outputs._LIVE if q.startswith(str(tmp_path))]


def test_handle_termination_keeps_an_ignored_sighup():
    saved = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGHUP)}
    try:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        signal.signal(signal.SIGHUP, signal.SIG_IGN)     # started under nohup
        outputs.handle_termination()
        assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN
        handler = signal.getsignal(signal.SIGTERM)
        assert callable(handler)
        with pytest.raises(outputs.Terminated) as stop:
            handler(signal.SIGTERM, None)
        assert stop.value.exit_code == 143
        assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL   # a second one: at once
    finally:
        for s, h in saved.items():
            signal.signal(s, h)


# -- commands in a subprocess, held while they write -----------------------------------------

@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A scenario, its measurement, a fitted model, a ROS bag, a sweep and its finished folder
    (for report), made once in this process; plus the hold's sitecustomize."""
    root = tmp_path_factory.mktemp("signal_inputs")
    old = os.environ.get("GYROARRAY_CACHE")
    os.environ["GYROARRAY_CACHE"] = str(root / "cache")
    try:
        (root / "static60.toml").write_text('[[segment]]\nkind = "static"\nduration_s = 60.0\n')
        (root / "sc.toml").write_text(
            'name = "sc"\nsample_rate_hz = 50.0\nseed = 1\n'
            'effects = [ { effect = "arw", n_deg_rt_h = 0.1 }, { effect = "rrw", k_deg_h_rt_h = 600.0 } ]\n'
            '[layout]\nscheme = 1\nn_gyros = 4\nalpha_deg = 54.7356\n[motion]\nprofile = "static60.toml"\n')
        assert run_cli(["simulate", root / "sc.toml", "--out", root / "sim"], timeout=600).code == 0
        meas = root / "sim" / "sc.csv.gz"
        o = run_cli(["fit", meas, "--out", root / "model.toml"], timeout=600)
        assert o.code == 0, o.err
        from test_bags import record, write_bag
        bag = write_bag(root, "imu", "bag", {"/imu0": record(4)})
        (root / "tiny.toml").write_text(tiny_sweep(estimators=["ols"]))
        from gyroarray.sweep.runner import run_sweep
        run_sweep(root / "tiny.toml", root / "swept", workers=1, progress=False)
    finally:
        if old is None:
            os.environ.pop("GYROARRAY_CACHE", None)
        else:
            os.environ["GYROARRAY_CACHE"] = old
    (root / "hook").mkdir()
    (root / "hook" / "sitecustomize.py").write_text(HOLD)
    return {"root": root, "scenario": root / "sc.toml", "meas": meas, "model": root / "model.toml",
            "bag": bag, "sweep": root / "tiny.toml", "swept": root / "swept",
            "cache": root / "cache", "hook": root / "hook"}


def _argv(command: str, i: dict, out: Path) -> tuple[list, Path]:
    """The command's arguments writing into ``out`` and the folder its temporaries appear in."""
    table = {
        "simulate": (["simulate", i["scenario"], "--out", out], out),
        "fuse": (["fuse", i["meas"], "--estimator", "gls", "--out", out / "f.csv.gz"], out),
        "fuse_stream": (["fuse", i["meas"], "--estimator", "gls", "--stream", "--out",
                         out / "f.csv.gz"], out),
        "fit": (["fit", i["meas"], "--out", out / "m.toml"], out),
        "export": (["export", i["model"], "--format", "kalibr", "--rate-hz", "50", "--out",
                    out / "k.yaml"], out),
        "convert": (["convert", i["bag"], "--topic", "/imu0", "--out", out / "c.csv.gz"], out),
        "report": (["report", i["swept"], "--out", out / "r.html"], out),
        "sweep": (["sweep", i["sweep"], "--out", out / "sw", "--workers", "2"], out / "sw" / "rows"),
        "sweep_dask": (["sweep", i["sweep"], "--out", out / "sw", "--dask", "local:2"],
                       out / "sw" / "rows"),
    }
    argv, where = table[command]
    return [str(a) for a in argv], where


def _held(argv: list, where: Path, i: dict, tmp_path: Path) -> subprocess.Popen:
    """Start ``gyroarray ARGV`` held at its first synced temporary under ``where``; return once
    it is held (the flag file), failing if it ends or hangs before."""
    flag = tmp_path / "held.flag"
    env = os.environ.copy()
    env.update(PYTHONPATH=os.pathsep.join(filter(None, [str(i["hook"]), env.get("PYTHONPATH")])),
               GYROARRAY_TEST_HOLD_DIR=str(where), GYROARRAY_TEST_HOLD_FLAG=str(flag),
               GYROARRAY_CACHE=str(i["cache"]), OPENBLAS_NUM_THREADS="1",
               TMPDIR=str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir(exist_ok=True)
    proc = subprocess.Popen([sys.executable, "-m", "gyroarray.cli.main", *argv], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=as_from_a_terminal)
    limit = bound_s(120.0)
    deadline = time.monotonic() + limit
    while not flag.exists():
        if proc.poll() is not None:
            raise AssertionError(f"ended (exit {proc.returncode}) before writing: {proc.stderr.read()}")
        if time.monotonic() > deadline:
            _kill_all(proc)
            raise AssertionError(f"no temporary written within {limit:.0f} s")
        time.sleep(0.05)
    return proc


def _kill_all(proc: subprocess.Popen) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    proc.wait()


def _ended(proc: subprocess.Popen) -> tuple[int, str]:
    try:
        _, err = proc.communicate(timeout=bound_s(60.0, starts=5.0))
    except subprocess.TimeoutExpired:
        _kill_all(proc)
        raise AssertionError("still running after the signal") from None
    return proc.returncode, err


def _finals(command: str, out: Path) -> list[str]:
    """The output files under their final names (the sweep: its complete result files only)."""
    if command.startswith("sweep"):
        from gyroarray.sweep.runner import verify_rows_file
        rows = out / "sw" / "rows"
        bad = [p.name for p in rows.glob("*.parquet") if verify_rows_file(p) is not None]
        assert not bad, f"incomplete result files under their names: {bad}"
        return []
    return sorted(p.name for p in out.iterdir() if not p.name.startswith("."))


COMMANDS = ["simulate", "fuse", "fuse_stream", "fit", "export", "convert", "report", "sweep",
            "sweep_dask"]


@pytest.mark.slow      # a fresh interpreter per command (several on a loaded machine)
@pytest.mark.parametrize("command", COMMANDS)
def test_sigterm_while_writing_leaves_no_temporary_and_no_half_output(inputs, tmp_path, command):
    out = tmp_path / "out"
    argv, where = _argv(command, inputs, out)
    proc = _held(argv, where, inputs, tmp_path)
    try:
        assert _marked(out), "held, but no temporary seen"
        os.kill(proc.pid, signal.SIGTERM)
        code, err = _ended(proc)
    finally:
        _kill_all(proc)
    assert code == 128 + signal.SIGTERM, err
    assert err.strip().splitlines()[-1] == "gyroarray: terminated by SIGTERM", err
    assert "Traceback" not in err, err
    assert _marked(out) == [] and _marked(tmp_path / "tmp") == []
    assert _finals(command, out) == []


@pytest.mark.slow
@pytest.mark.parametrize("signame, code", [("SIGHUP", 129), ("SIGINT", 130)])
def test_sighup_and_sigint_clean_up_too(inputs, tmp_path, signame, code):
    out = tmp_path / "out"
    argv, where = _argv("simulate", inputs, out)
    proc = _held(argv, where, inputs, tmp_path)
    try:
        os.kill(proc.pid, getattr(signal, signame))
        got, err = _ended(proc)
    finally:
        _kill_all(proc)
    assert got == code and "Traceback" not in err, err
    assert _marked(out) == [] and _finals("simulate", out) == []


@pytest.mark.slow
@pytest.mark.parametrize("command", COMMANDS)
def test_after_a_sigkill_the_next_run_removes_the_stale_temporary(inputs, tmp_path, command):
    out = tmp_path / "out"
    argv, where = _argv(command, inputs, out)
    proc = _held(argv, where, inputs, tmp_path)
    try:
        os.kill(proc.pid, signal.SIGKILL)        # no handler runs: the temporary stays
        proc.wait()
        if command.startswith("sweep"):   # its workers die with it (PDEATHSIG, Dask's own watch)
            deadline = time.monotonic() + bound_s(60.0, starts=5.0)
            while any(outputs.stale_temp(Path(t).name) is False for t in _marked(out)) \
                    and time.monotonic() < deadline:
                time.sleep(0.05)
    finally:
        _kill_all(proc)
    stale = _marked(out)
    assert stale and all(outputs.stale_temp(Path(t).name) for t in stale), stale
    old = os.environ.get("GYROARRAY_CACHE")
    os.environ["GYROARRAY_CACHE"] = str(inputs["cache"])
    try:
        again = run_cli(argv, timeout=600)
    finally:
        if old is None:
            os.environ.pop("GYROARRAY_CACHE", None)
        else:
            os.environ["GYROARRAY_CACHE"] = old
    assert again.code == 0, again.err
    assert _marked(out) == []
    if command.startswith("sweep"):
        from gyroarray.sweep.runner import load_results
        assert len(load_results(out / "sw")) > 0
    else:
        assert _finals(command, out), "the rerun wrote nothing"
        sizes = [p.stat().st_size for p in out.iterdir()]
        assert np.min(sizes) > 0
