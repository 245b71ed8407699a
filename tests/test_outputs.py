"""Nothing the user gave is modified: every output path is checked before any work.

Each destructive case of the robustness issue is a test here, and each
checks the user's file by its hash before and after. The CLI is run
in-process (:func:`gyroarray.cli.main.main`): the refusals come before any
analysis, so these tests take milliseconds each.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from gyroarray.core import outputs
from gyroarray.cli.main import main
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.measurement import Measurement, write_measurement

EXAMPLE = Path(__file__).resolve().parents[1] / "src" / "gyroarray" / "data" / "scenarios" / "examples" / "tetra_swing.toml"


def sha(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def refused(capsys, *argv, words=()):
    code, out, err = run(capsys, *argv)
    assert code == 2, (code, err)
    assert err.count("\n") == 1 and err.startswith("gyroarray: ") and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    return err


@pytest.fixture
def meas(tmp_path):
    """A small static 3-gyro measurement (csv.gz + sidecar) and the hashes of both files."""
    rng = np.random.default_rng(1)
    n = 400
    m = Measurement(time_s=np.arange(n) * 0.01, gyro_deg_s=rng.normal(0, 0.01, (n, 3)),
                    layout=Layout.from_axes(np.eye(3)), sample_rate_hz=100.0)
    csv, toml = write_measurement(m, tmp_path / "run42.csv.gz")
    return csv, toml, {csv: sha(csv), toml: sha(toml)}


def unchanged(hashes):
    for path, h in hashes.items():
        assert sha(path) == h, f"{path} was modified"


# -- the measurement's own sidecar -------------------------------------------------

@pytest.mark.parametrize("given", ["csv", "stem"])
def test_fit_out_onto_the_sidecar_is_refused(capsys, meas, given):
    csv, toml, hashes = meas
    arg = csv if given == "csv" else csv.parent / "run42"
    refused(capsys, "fit", arg, "--out", toml, words=("input of this command", str(toml)))
    refused(capsys, "fit", arg, "--out", toml, "--force", words=("input of this command",))
    unchanged(hashes)


def test_ladder_model_out_and_compare_out_onto_inputs_are_refused(capsys, meas, tmp_path):
    csv, toml, hashes = meas
    model = tmp_path / "m.toml"
    model.write_text('effects = [{effect = "arw", n_deg_rt_h = 0.1}]\n')
    hashes[model] = sha(model)
    refused(capsys, "ladder", csv, "--out", tmp_path / "r.html", "--model-out", toml, "--force",
            words=("--model-out",))
    refused(capsys, "ladder", csv, "--model", model, "--out", tmp_path / "r.html",
            "--model-out", model, words=("--model-out",))
    refused(capsys, "fit", csv, "--model", model, "--out", model, "--force")
    # a report over the CSV itself: the suffix alone refuses it, the input check would too
    refused(capsys, "compare", csv, "--out", csv, words=("--out",))
    unchanged(hashes)


# -- simulate ---------------------------------------------------------------------

def test_simulate_into_the_scenario_folder_never_overwrites_the_scenario(capsys, tmp_path):
    folder = tmp_path / "work"
    folder.mkdir()
    scen = folder / "tetra_swing.toml"          # named like its output sidecar
    shutil.copy(EXAMPLE, scen)
    before = sha(scen)
    for extra in ((), ("--force",)):
        refused(capsys, "simulate", scen, "--out", folder, *extra, words=("input of this command",))
    assert sha(scen) == before
    assert sorted(p.name for p in folder.iterdir()) == ["tetra_swing.toml"]


def test_simulate_never_writes_through_a_symlink(capsys, tmp_path):
    target = tmp_path / "precious.csv.gz"
    target.write_bytes(b"the user's own data")
    out = tmp_path / "out"
    out.mkdir()
    (out / "tetra_swing.csv.gz").symlink_to(target)
    before = sha(target)
    refused(capsys, "simulate", EXAMPLE, "--out", out, words=("exists", "--force"))
    assert sha(target) == before
    # with --force the link itself is replaced by the new file; its target is untouched
    code, _, err = run(capsys, "simulate", EXAMPLE, "--out", out, "--force", "--json")
    assert code == 0, err
    assert sha(target) == before
    link = out / "tetra_swing.csv.gz"
    assert not link.is_symlink() and link.stat().st_size > 1000


def test_simulate_refuses_existing_outputs_without_force(capsys, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "tetra_swing.toml").write_text("# mine\n")
    before = sha(out / "tetra_swing.toml")
    refused(capsys, "simulate", EXAMPLE, "--out", out, words=("exists",))
    assert sha(out / "tetra_swing.toml") == before
    assert not (out / "tetra_swing.csv.gz").exists()     # refused before anything was written


# -- output paths that cannot be written --------------------------------------------

@pytest.mark.parametrize("name, words", [
    ("a.txt", ("must end in .png",)),
    ("run42.csv.gz", ("must end in .png",)),
    ("somedir", ("is a folder",)),
])
def test_bad_plot_paths_are_one_line_refusals(capsys, meas, name, words):
    csv, _, hashes = meas
    (csv.parent / "somedir").mkdir()
    plot = csv.parent / name
    refused(capsys, "allan", csv, "--plot", plot, words=words)
    refused(capsys, "design", "--plot", plot, words=words)
    unchanged(hashes)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder_is_a_one_line_refusal(capsys, meas, tmp_path):
    csv, _, _ = meas
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        refused(capsys, "allan", csv, "--plot", ro / "a.png", words=("not writable",))
    finally:
        ro.chmod(0o700)


def test_read_only_folder_check_by_access(tmp_path, monkeypatch):
    """The same refusal where root could write anyway: the check reads os.access."""
    monkeypatch.setattr(outputs.os, "access", lambda *a, **k: False)
    with pytest.raises(InputError, match="not writable"):
        outputs.check_output(tmp_path / "a.png", what="--plot")


def test_missing_folder_is_created_and_a_file_in_the_way_refused(capsys, meas, tmp_path):
    csv, _, _ = meas
    code, _, err = run(capsys, "allan", csv, "--plot", tmp_path / "new" / "deeper" / "a.png")
    assert code == 0, err
    assert (tmp_path / "new" / "deeper" / "a.png").stat().st_size > 1000
    (tmp_path / "file").write_text("x")
    refused(capsys, "allan", csv, "--plot", tmp_path / "file" / "a.png", words=("not a folder",))
    # an existing plot is replaced only with --force
    refused(capsys, "allan", csv, "--plot", tmp_path / "new" / "deeper" / "a.png", words=("exists",))
    code, _, err = run(capsys, "allan", csv, "--plot", tmp_path / "new" / "deeper" / "a.png", "--force")
    assert code == 0, err


def test_report_out_suffix_and_existing(capsys, tmp_path):
    refused(capsys, "report", tmp_path, "--out", tmp_path / "r.txt", words=("must end in .html",))
    (tmp_path / "r.html").write_text("mine")
    refused(capsys, "report", tmp_path, "--out", tmp_path / "r.html", words=("exists",))
    assert (tmp_path / "r.html").read_text() == "mine"


# -- the writer itself ---------------------------------------------------------------

def test_write_is_create_new_without_force(tmp_path):
    p = tmp_path / "x.txt"
    outputs.write_text(p, "one")
    with pytest.raises(InputError, match="exists"):
        outputs.write_text(p, "two")
    assert p.read_text() == "one"
    outputs.write_text(p, "three", force=True)
    assert p.read_text() == "three"
    assert [q.name for q in tmp_path.iterdir()] == ["x.txt"]     # no temporary file left


def test_measurement_files_cover_every_spelling(tmp_path):
    names = {q.name for q in outputs.measurement_files(tmp_path / "run42")}
    assert {"run42.csv", "run42.csv.gz", "run42.toml"} <= names
    for given in ("run42.csv", "run42.csv.gz", "run42.toml", "RUN42.CSV.GZ"):
        stems = {q.name.lower() for q in outputs.measurement_files(tmp_path / given)}
        assert "run42.toml" in stems, given
