"""Issue 28: files the tool writes, appends to and reads, under hostile conditions.

* sweep bookkeeping (``rows.sha256``, ``sweep.json``): a symbolic link, a
  folder, a FIFO, an input of the command, a file that is not a checksum
  list, a read-only ``--out``, a full disk: one-line refusal (exit 2), the
  user's file untouched, nothing corrupt kept;
* JSON read through :func:`gyroarray.core.limits.read_json`: ``/dev/zero``, a FIFO,
  a JSON list, 100,000-deep nesting: one-line refusal naming the file, fast,
  never blocking;
* output files get ``0o666`` less the umask (022 and 077);
* a Markdown twin's figure files are checked before the work, and a refusal
  while writing leaves no HTML behind;
* matplotlib writes nothing under ``$HOME``.

Every CLI call runs in this process under an alarm (:func:`hostile.run_cli`).
"""

from __future__ import annotations

import errno
import json
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from gyroarray.core import outputs
from gyroarray.core.errors import InputError
from gyroarray.core.limits import MAX_JSON_DEPTH, read_json
from hostile import assert_contract, run_cli, tiny_sweep

TINY = tiny_sweep(estimators=["ols"])
LINE = "0" * 64 + " 3 a.parquet\n"


def refused(o, name: str, *words: str):
    """Exit 2, one stderr line naming ``name`` and holding each of ``words``."""
    assert_contract(o, name)
    assert o.code == 2, (o.code, o.out, o.err)
    for w in words:
        assert w in o.err, (w, o.err)
    return o.err


@pytest.fixture
def tiny(tmp_path):
    p = tmp_path / "tiny.toml"
    p.write_text(TINY)
    return p


def _tmp_files(folder: Path) -> list:
    return sorted(q.name for q in folder.rglob(".*.tmp"))


# -- sweep bookkeeping: never written through, never an input ---------------------------

def test_sweep_refuses_a_symlinked_checksum_file_and_leaves_its_target(tiny, tmp_path):
    target = tmp_path / "precious.txt"
    target.write_text("the user's own notes\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / "rows.sha256").symlink_to(target)
    o = run_cli(["sweep", tiny, "--out", out], timeout=60)
    refused(o, "rows.sha256", "symbolic link")
    assert target.read_text() == "the user's own notes\n"
    assert not (out / "sweep.json").exists() and not (out / "rows").exists()


def test_sweep_refuses_a_symlinked_manifest(tiny, tmp_path):
    target = tmp_path / "elsewhere.json"
    out = tmp_path / "out"
    out.mkdir()
    (out / "sweep.json").symlink_to(target)             # dangling: would be created through it
    refused(run_cli(["sweep", tiny, "--out", out], timeout=60), "sweep.json", "symbolic link")
    assert not target.exists()


def test_sweep_refuses_appending_to_its_own_sweep_file(tmp_path):
    d = tmp_path / "d"
    d.mkdir()
    sweep = d / "rows.sha256"
    sweep.write_text(TINY)
    refused(run_cli(["sweep", sweep, "--out", d], timeout=60), "rows.sha256", "input of this command")
    assert sweep.read_text() == TINY
    assert sorted(q.name for q in d.iterdir()) == ["rows.sha256"]


def test_sweep_refuses_a_checksum_file_that_is_not_one(tiny, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "rows.sha256").write_text("my shopping list\nmilk\n")
    refused(run_cli(["sweep", tiny, "--out", out], timeout=60), "rows.sha256", "not a gyroarray checksum file")
    assert (out / "rows.sha256").read_text() == "my shopping list\nmilk\n"


def test_a_checksum_file_torn_by_a_crash_is_still_ours(tmp_path):
    """Resuming after a crash: a torn record (alone, or glued to the next one by an older
    gyroarray) does not make the folder refused."""
    from gyroarray.sweep.runner import check_out
    rec = "ab" * 32 + " 12 s1_n4-0123.parquet"
    (tmp_path / "rows.sha256").write_text(f"{rec}\n{rec[:40]}\n{rec[:70]}{rec}\n{rec[:20]}")
    check_out(tmp_path, [])
    (tmp_path / "rows.sha256").write_text(f"{rec}\nname = 'tiny'\n")
    with pytest.raises(InputError, match="not a gyroarray checksum file"):
        check_out(tmp_path, [])


@pytest.mark.parametrize("kind", ["folder", "fifo"])
def test_sweep_refuses_bookkeeping_that_is_not_a_regular_file(tiny, tmp_path, kind):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("rows.sha256", "sweep.json"):
        p = out / name
        os.mkdir(p) if kind == "folder" else os.mkfifo(p)
        o = run_cli(["sweep", tiny, "--out", out], timeout=60)     # a FIFO must not block
        refused(o, name, "a folder" if kind == "folder" else "FIFO")
        os.rmdir(p) if kind == "folder" else os.unlink(p)


def test_sweep_refuses_a_manifest_that_is_a_json_list(tiny, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "sweep.json").write_text("[1, 2, 3]\n")
    refused(run_cli(["sweep", tiny, "--out", out], timeout=120), "sweep.json", "JSON object")
    assert (out / "sweep.json").read_text() == "[1, 2, 3]\n"


def test_sweep_refuses_a_read_only_out(tiny, tmp_path, monkeypatch):
    parent = tmp_path / "ro"
    parent.mkdir()
    if os.geteuid() == 0:            # root writes anywhere: emulate a folder we cannot write
        real = os.access
        monkeypatch.setattr(os, "access", lambda p, m, **k: False if m & os.W_OK else real(p, m, **k))
    else:
        parent.chmod(0o555)
    try:
        refused(run_cli(["sweep", tiny, "--out", parent / "out"], timeout=120), "out", "not writable")
        refused(run_cli(["sweep", tiny, "--out", parent], timeout=120), "ro", "not writable")
    finally:
        parent.chmod(0o755)
    assert list(parent.iterdir()) == []


def _no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_sweep_on_a_full_disk_refuses_and_keeps_nothing(tiny, tmp_path, monkeypatch):
    out = tmp_path / "out"
    monkeypatch.setattr(os, "write", _no_space)
    o = run_cli(["sweep", tiny, "--out", out], timeout=120)
    monkeypatch.undo()
    refused(o, "sweep.json", "No space left", "free some space")
    assert not (out / "sweep.json").exists() and _tmp_files(out) == []


def test_rows_written_on_a_full_disk_leave_no_partial_line(tmp_path, monkeypatch):
    """The result file and its checksum line: a write that fails keeps nothing corrupt."""
    import pandas as pd

    from gyroarray.sweep.runner import write_rows, load_results
    rows = tmp_path / "out" / "rows"
    rows.mkdir(parents=True)
    df = pd.DataFrame({"scenario_id": ["a"], "estimator": ["ols"], "axis": ["x"], "value": [1.0]})
    write_rows(df, rows, "a")
    before = (tmp_path / "out" / "rows.sha256").read_bytes()
    real = os.write

    def half_then_full(fd, data):                 # the disk fills in the middle of a write
        if len(data) > 8:
            real(fd, bytes(data[:8]))
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(os, "write", half_then_full)
    with pytest.raises(InputError, match="No space left"):
        write_rows(df, rows, "b")
    monkeypatch.undo()
    assert not (rows / "b.parquet").exists() and _tmp_files(tmp_path) == []
    assert (tmp_path / "out" / "rows.sha256").read_bytes() == before
    assert list(load_results(tmp_path / "out").scenario_id) == ["a"]


# -- append_line and write_bytes on their own --------------------------------------------

def test_append_line_guards(tmp_path, monkeypatch):
    f = tmp_path / "log"
    outputs.append_line(f, "one")
    f.write_bytes(f.read_bytes() + b"torn")           # a crash in the middle of a line
    outputs.append_line(f, "two")
    assert f.read_text() == "one\ntorn\ntwo\n"
    target = tmp_path / "target"
    target.write_text("keep\n")
    link = tmp_path / "link"
    link.symlink_to(target)
    with pytest.raises(InputError, match="symbolic link"):
        outputs.append_line(link, "x")
    with pytest.raises(InputError, match="input of this command"):
        outputs.append_line(target, "x", inputs=[link])       # the same file by another name
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(InputError, match="FIFO"):
        outputs.append_line(tmp_path / "fifo", "x")          # no reader: must not block
    assert target.read_text() == "keep\n"
    size = f.stat().st_size
    real = os.write
    monkeypatch.setattr(os, "write", lambda fd, data: (real(fd, bytes(data[:3])), _no_space())[1])
    with pytest.raises(InputError, match="No space left"):
        outputs.append_line(f, "three")
    monkeypatch.undo()
    assert f.stat().st_size == size                   # cut back: no partial line


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_files_follow_the_umask(tmp_path, umask):
    old = os.umask(umask)
    try:
        a = outputs.write_text(tmp_path / "a.txt", "x")
        b = outputs.append_line(tmp_path / "b.log", "x")
        c, = outputs.write_many([(tmp_path / "c.bin", b"x")])
    finally:
        os.umask(old)
    for p in (a, b, c):
        assert stat.S_IMODE(p.stat().st_mode) == 0o666 & ~umask, (p, oct(p.stat().st_mode))


def test_write_many_leaves_nothing_when_one_file_fails(tmp_path):
    (tmp_path / "late.png").write_bytes(b"someone else's")   # appears after the checks
    items = [(tmp_path / "r.html", b"<html>"), (tmp_path / "late.png", b"png"),
             (tmp_path / "r.md", b"md")]
    with pytest.raises(InputError, match="late.png"):
        outputs.write_many(items)
    assert sorted(q.name for q in tmp_path.iterdir()) == ["late.png"]
    assert (tmp_path / "late.png").read_bytes() == b"someone else's"


# -- JSON: one guarded reader ------------------------------------------------------------

def test_read_json_refusals(tmp_path):
    os.mkfifo(tmp_path / "fifo.json")
    (tmp_path / "list.json").write_text("[1, 2]")
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (tmp_path / "deep70.json").write_text("[" * 70 + "]" * 70)
    (tmp_path / "nan.json").write_text('{"a": NaN}')
    (tmp_path / "bad.json").write_text('{"a":\n')
    (tmp_path / "big.json").write_text('{"a": "' + "x" * 2000 + '"}')
    cases = {"/dev/zero": "character device", tmp_path / "fifo.json": "FIFO",
             tmp_path / "list.json": "JSON object", tmp_path / "deep.json": f"{MAX_JSON_DEPTH} deep",
             tmp_path / "deep70.json": f"{MAX_JSON_DEPTH} deep", tmp_path / "nan.json": "NaN",
             tmp_path / "bad.json": "line 2", tmp_path / "big.json": "more than"}
    for path, words in cases.items():
        with pytest.raises(InputError) as err:
            read_json(path, "design result", max_bytes=1000 if "big" in str(path) else None)
        assert str(path) in str(err.value) and words in str(err.value), str(err.value)
        assert "\n" not in str(err.value)
    assert read_json(tmp_path / "list.json", expect=None) == [1, 2]


def test_report_design_hostile_json(tmp_path):
    os.mkfifo(tmp_path / "design.json")
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    for design, words in (("/dev/zero", "character device"), (tmp_path / "design.json", "FIFO"),
                          (tmp_path / "deep.json", f"{MAX_JSON_DEPTH} deep")):
        o = run_cli(["report", "--design", design, "--out", tmp_path / "r.html"], timeout=60)
        refused(o, str(design), words)
    assert not (tmp_path / "r.html").exists()


def test_report_on_a_fifo_manifest_does_not_block(tmp_path):
    d = tmp_path / "sw"
    (d / "rows").mkdir(parents=True)
    os.mkfifo(d / "sweep.json")
    refused(run_cli(["report", d, "--out", tmp_path / "r.html"], timeout=60), "sweep.json", "FIFO")
    (d / "sweep.json").unlink()
    (d / "sweep.json").write_text('["not", "a", "manifest"]')
    refused(run_cli(["report", d, "--out", tmp_path / "r.html"], timeout=60), "sweep.json",
            "not a gyroarray sweep manifest")
    (d / "sweep.json").write_text(json.dumps({"scenarios": [{"id": "a"}]}))
    os.mkfifo(d / "rows.sha256")
    (d / "rows" / "a.parquet").write_bytes(b"PAR1")
    o = run_cli(["report", d, "--out", tmp_path / "r.html"], timeout=60)
    refused(o, "rows.sha256", "FIFO")


# -- Markdown figures: checked before the work, nothing left on a refusal ----------------

def test_report_md_figure_clash_is_refused_up_front(tmp_path):
    figs = tmp_path / "r_figures"
    figs.mkdir()
    (figs / "gdop.png").write_bytes(b"an older report's figure")
    o = run_cli(["report", tmp_path / "no_such_sweep", "--out", tmp_path / "r.html",
                 "--md", tmp_path / "r.md"], timeout=60)
    err = refused(o, "r.md", "r_figures", "--force")
    assert "appeared while" not in err
    assert sorted(q.name for q in tmp_path.iterdir()) == ["r_figures"]
    assert (figs / "gdop.png").read_bytes() == b"an older report's figure"
    (tmp_path / "r_figures").rename(tmp_path / "gone")
    (tmp_path / "r_figures").write_text("a file, not a folder")
    refused(run_cli(["report", tmp_path / "no_such_sweep", "--out", tmp_path / "r.html",
                     "--md", tmp_path / "r.md"], timeout=60), "r.md", "not a folder")


def test_report_write_leaves_no_html_when_a_figure_clashes(tmp_path):
    """A figure that appears after the checks: refused, and the HTML is not left behind."""
    from gyroarray.reports.report import Doc
    doc = Doc("t")
    doc.figure("gdop", b"\x89PNG fake", "caption")
    (tmp_path / "r_figures").mkdir()
    (tmp_path / "r_figures" / "gdop.png").write_bytes(b"theirs")
    with pytest.raises(InputError, match="gdop.png"):
        doc.write(tmp_path / "r.html", tmp_path / "r.md", "sub", force=False)
    assert sorted(q.name for q in tmp_path.iterdir()) == ["r_figures"]
    assert [q.name for q in (tmp_path / "r_figures").iterdir()] == ["gdop.png"]
    (tmp_path / "r_figures" / "gdop.png").unlink()
    (tmp_path / "r_figures").rmdir()
    doc.write(tmp_path / "r.html", tmp_path / "r.md", "sub", force=False)
    assert (tmp_path / "r_figures" / "gdop.png").read_bytes() == b"\x89PNG fake"


# -- matplotlib: nothing under HOME --------------------------------------------------------

def test_plotting_writes_nothing_in_home(tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("MPL", "XDG_")) and k != "GYROARRAY_CACHE"}
    env.update(HOME=str(home), TMPDIR=str(tmp_path))
    p = subprocess.run(["/bin/sh", "-c", f'umask 077; exec "{sys.executable}" -m gyroarray.cli.main '
                        f'design --plot "{tmp_path / "p.png"}"'], env=env, capture_output=True,
                       text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert list(home.rglob("*")) == [], list(home.rglob("*"))
    assert stat.S_IMODE((tmp_path / "p.png").stat().st_mode) == 0o600
    mpl = tmp_path / f"gyroarray-mpl-{os.geteuid()}"
    assert mpl.is_dir() and stat.S_IMODE(mpl.stat().st_mode) == 0o700


# -- --force never replaces a device, FIFO or socket ------------------------------------

@pytest.mark.skipif(os.geteuid() != 0, reason="mknod of a character device needs root")
def test_force_does_not_replace_a_device_node(tmp_path):
    """As root, ``--plot /dev/null --force`` replaced /dev/null with a PNG (found while fuzzing).
    A device node made here (the same major/minor as /dev/null) must stay a device."""
    node = tmp_path / "null.png"
    os.mknod(node, stat.S_IFCHR | 0o644, os.makedev(1, 3))
    o = run_cli(["design", "--plot", node, "--force"])
    assert_contract(o, "null.png")
    assert o.code == 2 and "character device" in o.err, o.err
    assert stat.S_ISCHR(os.lstat(node).st_mode)


def test_force_does_not_replace_a_fifo(tmp_path):
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    o = run_cli(["design", "--plot", fifo, "--force"])
    assert o.code == 2 and "FIFO" in o.err, o.err
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_name_too_long_is_refused(tmp_path):
    o = run_cli(["design", "--plot", tmp_path / ("y" * 300 + ".png")])
    assert_contract(o)
    assert o.code == 2 and "too long" in o.err, o.err
    o = run_cli(["simulate", Path(__file__).parents[1] / "src" / "gyroarray" / "data" / "scenarios" / "examples" / "tetra_swing.toml",
                 "--out", tmp_path / "x" / ("y" * 300)])
    assert_contract(o)
    assert o.code == 2 and "too long" in o.err, o.err
