"""Sweep files (expansion, ids, seeds, validation) and the parallel, resumable runner.

Determinism is tested bit for bit: the same sweep must give identical
Parquet rows (float bits included) with 1 or 2 local workers, on a Dask
cluster, and after a SIGKILL + resume. Every worker runs with
OPENBLAS_NUM_THREADS=1 (the runner sets it for its process pool; the test's
Dask cluster sets it through ``distributed.nanny.pre-spawn-environ``).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from same_bits import assert_same_bits
from wall_bound import bound_s

from gyroarray.core.errors import InputError
from gyroarray.sweep.runner import load_results, run_sweep
from gyroarray.sweep.sweep import PARAM_KEYS, load_sweep, scenario_id, scenario_seed

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "src" / "gyroarray" / "data" / "scenarios" / "sweeps" / "design_quick.toml"

# Tiny runs: 20 s at 100 Hz, three estimators, 3 scenarios (the runner tests).
TINY = """\
name = "tiny"
seed = 7
{extra_top}
[base]
sample_rate_hz = 100.0
duration_s = 20.0
effects = [{{ effect = "arw", n_deg_rt_h = 0.1 }}, {{ effect = "rrw", k_deg_h_rt_h = 600.0 }}]
[base.layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356
[base.motion]
profile = "p003_sine_5dps_0p03hz"
{extra}
"""
TINY_GRID = """\
[grid]
n_gyros = [4, 6]
rho_arw = [0.0, 0.3]

[[points]]
scheme = 2
n_gyros = 5
alpha_deg = "optimal"
motion = "p003_static_1h"
"""


def write(folder: Path, extra: str = TINY_GRID, extra_top: str = "", name="sweep.toml") -> Path:
    if "estimators" not in extra_top:
        extra_top = 'estimators = ["kf_array", "gls", "ols"]\n' + extra_top
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / name
    p.write_text(TINY.format(extra=extra, extra_top=extra_top))
    return p


@pytest.fixture(scope="module")
def cache_env(tmp_path_factory):
    """A private truth cache, inherited by every worker process the tests start."""
    old = os.environ.get("GYROARRAY_CACHE")
    os.environ["GYROARRAY_CACHE"] = str(tmp_path_factory.mktemp("truth_cache"))
    yield
    if old is None:
        os.environ.pop("GYROARRAY_CACHE", None)
    else:
        os.environ["GYROARRAY_CACHE"] = old


# -- expansion -----------------------------------------------------------------

def test_expansion_ids_and_params(tmp_path):
    sw = load_sweep(write(tmp_path))
    assert len(sw) == 5                               # 2 x 2 grid + 1 point
    ids = [s.id for s in sw.scenarios]
    assert ids == sorted(ids) and len(set(ids)) == 5
    for s in sw.scenarios:
        assert s.id == scenario_id({k: s.params[k] for k in PARAM_KEYS})
        assert s.seed == scenario_seed(7, s.id) and 0 <= s.seed < 2**63
        sc = s.build()
        assert sc.layout.n_gyros == s.params["n_gyros"] and sc.seed == s.seed
        assert sc.duration_s == 20.0
    point = next(s for s in sw.scenarios if s.params["scheme"] == 2)
    assert point.params["alpha_deg"] == "optimal" and point.params["motion"] == "p003_static_1h"
    from gyroarray.core.gdop import optimal_alpha
    assert point.params["alpha_deg_value"] == np.degrees(optimal_alpha(2, 5, 0.0).alpha_rad)
    # rho swept: one correlation entry with that rho, on top of the base effects
    r3 = next(s for s in sw.scenarios if s.params["rho_arw"] == 0.3)
    model = r3.build().model
    assert [e.effect for e in model] == ["arw", "rrw", "correlation"]


def test_ids_and_seeds_do_not_depend_on_order(tmp_path):
    a = load_sweep(write(tmp_path / "a", "[grid]\nn_gyros = [4, 6, 8]\nrho_arw = [0.0, 0.3]\n"
                                         'motion = ["p003_static_1h", "p003_sine_5dps_0p03hz"]\n'))
    b = load_sweep(write(tmp_path / "b", '[grid]\nmotion = ["p003_sine_5dps_0p03hz", "p003_static_1h"]\n'
                                         "rho_arw = [0.3, 0.0]\nn_gyros = [8, 4, 6]\n"))
    key = lambda sw: {s.id: (s.seed, json.dumps(s.params, sort_keys=True)) for s in sw.scenarios}
    assert key(a) == key(b) and len(a) == 12
    # adding a grid value adds scenarios and leaves the others (ids and seeds) as they were
    c = load_sweep(write(tmp_path / "c", "[grid]\nn_gyros = [4, 5, 6, 8]\nrho_arw = [0.0, 0.3]\n"
                                         'motion = ["p003_static_1h", "p003_sine_5dps_0p03hz"]\n'))
    assert set(key(a).items()) < set(key(c).items()) and len(c) == 16
    # the same point given twice (grid and list) is one scenario
    d = load_sweep(write(tmp_path / "d", "[grid]\nn_gyros = [4, 6]\n[[points]]\nn_gyros = 6\n"))
    assert len(d) == 2
    # another sweep seed: same ids, other seeds
    e = load_sweep(write(tmp_path / "e", "[grid]\nn_gyros = [4, 6]\n").parent / "sweep.toml")
    f_path = tmp_path / "f" / "sweep.toml"
    f_path.parent.mkdir()
    f_path.write_text((tmp_path / "e" / "sweep.toml").read_text().replace("seed = 7", "seed = 8"))
    f = load_sweep(f_path)
    assert [s.id for s in e.scenarios] == [s.id for s in f.scenarios]
    assert all(s.seed != t.seed for s, t in zip(e.scenarios, f.scenarios))


def test_example_sweep_and_base_reference(tmp_path):
    sw = load_sweep(EXAMPLE)
    assert len(sw) == 48 and sw.estimators == ("kf_array", "kf_single", "gls", "ols", "naive", "bound")
    assert {s.params["scheme"] for s in sw.scenarios} == {1, 2}
    assert {s.params["n_gyros"] for s in sw.scenarios} == {4, 5, 6, 8}
    # base by reference to a shipped scenario (".toml" optional)
    p = tmp_path / "ref.toml"
    p.write_text('name = "ref"\nseed = 1\nbase = "paper003/swing_s1_n6"\n'
                 "[grid]\nduration_s = [30.0, 60.0]\n")
    ref = load_sweep(p)
    assert len(ref) == 2 and all(s.params["n_gyros"] == 6 for s in ref.scenarios)
    assert ref.scenarios[0].params["motion"] == "p003_sine_5dps_0p03hz"


def test_replicates_scenario_lists_and_skip_invalid(tmp_path):
    # replicates: K copies of each scenario, distinct ids and seeds, old ids unchanged
    one = load_sweep(write(tmp_path / "a", "[grid]\nn_gyros = [4, 6]\n"))
    rep = load_sweep(write(tmp_path / "b", "[grid]\nn_gyros = [4, 6]\n", "replicates = 3"))
    assert len(rep) == 6 and len({s.seed for s in rep.scenarios}) == 6
    assert sorted(s.params["replicate"] for s in rep.scenarios) == [0, 0, 1, 1, 2, 2]
    assert {s.id for s in one.scenarios}.isdisjoint({s.id for s in rep.scenarios})
    assert all("_rep" in s.id for s in rep.scenarios)
    assert all("replicate" not in s.params for s in one.scenarios)
    assert rep.scenarios[0].row_params()["replicate"] in (0, 1, 2)
    # a list of scenario files, run as they are, named in the rows
    p = tmp_path / "list.toml"
    p.write_text('name = "papers"\nseed = 3\nreplicates = 2\n'
                 'scenarios = ["paper003/swing_s1_n6", "paper002/constant_10dps.toml"]\n')
    lst = load_sweep(p)
    assert len(lst) == 4
    assert sorted({s.row_params()["scenario"] for s in lst.scenarios}) == [
        "paper002/constant_10dps", "paper003/swing_s1_n6"]
    s6 = next(s for s in lst.scenarios if s.params["scenario"] == "paper003/swing_s1_n6")
    assert s6.build().layout.n_gyros == 6 and s6.params["motion"] == "p003_sine_5dps_0p03hz"
    # skip_invalid: N = 8 with rho_rrw = -0.19 (below -1/7) is left out and listed
    q = write(tmp_path / "c", '[grid]\nn_gyros = [4, 8]\nrho_rrw = [-0.19, 0.0]\n',
              "skip_invalid = true")
    sk = load_sweep(q)
    assert len(sk) == 3 and len(sk.excluded) == 1
    assert "n8" in sk.excluded[0][0] and "-1/(N-1)" in sk.excluded[0][1]
    assert sk.manifest()["excluded"][0]["id"] == sk.excluded[0][0]
    # without it the same grid is refused
    with pytest.raises(InputError):
        load_sweep(write(tmp_path / "d", '[grid]\nn_gyros = [4, 8]\nrho_rrw = [-0.19, 0.0]\n'))
    # nothing valid left: refused, saying why
    with pytest.raises(InputError, match="no valid scenario"):
        load_sweep(write(tmp_path / "e", '[grid]\nn_gyros = [8]\nrho_rrw = [-0.19]\n',
                         "skip_invalid = true"))
    # scenarios and base exclude each other; bad replicates named
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\nseed = 1\nbase = "paper003/swing_s1_n6"\n'
                   'scenarios = ["paper003/swing_s1_n8"]\n')
    with pytest.raises(InputError, match="exclude each other"):
        load_sweep(bad)
    with pytest.raises(InputError) as info:
        load_sweep(write(tmp_path / "f", TINY_GRID, "replicates = 0"))
    assert info.value.column == "replicates" and info.value.line is not None


@pytest.mark.parametrize("extra_top, extra, key, words", [
    ("colour = 1", TINY_GRID, "colour", "unknown key"),
    ("", "[grid]\nn_gyro = [4]\n", "grid.n_gyro", "unknown key"),
    ("", "[grid]\nscheme = [3]\n", "grid.scheme", "1 or 2"),
    ("", "[grid]\nn_gyros = [4, 4]\n", "grid.n_gyros", "twice"),
    ("", "[grid]\nn_gyros = 4\n", "grid.n_gyros", "array"),
    ("", '[grid]\nalpha_deg = ["best"]\n', "grid.alpha_deg", "optimal"),
    ("", "[grid]\nrho_arw = [1.5]\n", "grid.rho_arw", "(-1, 1)"),
    ("", "[grid]\nduration_s = [-1]\n", "grid.duration_s", "> 0"),
    ("", "[grid]\nduration_s = [1e6]\n", "grid.duration_s", "longer than the motion"),
    ("", '[grid]\nmotion = ["no_such_profile"]\n', "grid.motion", "unknown shipped motion"),
    ("", '[grid]\neffects = ["nope"]\n', "grid.effects", "effect set"),
    ("", "[[points]]\nn_gyros = 4\nwidth = 3\n", "points[0].width", "unknown key"),
    # rho = -0.2 is singular for N = 6 (bound -1/(N-1)): named at the grid keys
    ("", '[grid]\nn_gyros = [6]\nrho_arw = [-0.2]\nalpha_deg = ["optimal"]\n', "grid.n_gyros",
     "singular"),
    ("", "[grid]\nn_gyros = [6]\nrho_arw = [-0.25]\n", "grid.n_gyros", "rho"),
    ('estimators = ["ols", "kalman"]', TINY_GRID, "estimators", "unknown estimator"),
    ("", '[effect_sets]\nbad = [{ effect = "arw", n_deg_rt_h = -1 }]\n', "effect_sets.bad",
     "n_deg_rt_h"),
])
def test_invalid_sweeps_are_refused_with_file_and_key(tmp_path, extra_top, extra, key, words):
    p = write(tmp_path, extra, extra_top)
    with pytest.raises(InputError) as info:
        load_sweep(p)
    err = info.value
    assert err.file == str(p), str(err)
    assert key in str(err.column), str(err)
    assert words in err.message, str(err)


def test_invalid_top_level(tmp_path):
    cases = {"seed": 'name = "x"\nbase = "paper003/swing_s1_n6"\n',
             "base": 'name = "x"\nseed = 1\nbase = "no/such/scenario"\n',
             "name": 'name = "a b"\nseed = 1\nbase = "paper003/swing_s1_n6"\n',
             "base.layout": 'name = "x"\nseed = 1\n[base]\nsample_rate_hz = 100.0\n'
                            '[base.motion]\nprofile = "p003_static_1h"\n'}
    for key, text in cases.items():
        p = tmp_path / f"{key}.toml"
        p.write_text(text)
        with pytest.raises(InputError) as info:
            load_sweep(p)
        assert info.value.file == str(p) and str(info.value.column).startswith(key), str(info.value)


# -- the runner ----------------------------------------------------------------

RUN_GRID = "[grid]\nn_gyros = [4, 6]\n[[points]]\nscheme = 2\nn_gyros = 5\nalpha_deg = \"optimal\"\n"


@pytest.fixture(scope="module")
def reference(tmp_path_factory, cache_env):
    """An uninterrupted run with 2 workers."""
    folder = tmp_path_factory.mktemp("ref")
    sweep_file = write(folder, RUN_GRID)
    summary = run_sweep(sweep_file, folder / "out", workers=2, progress=False)
    return sweep_file, summary, load_results(folder / "out")


def test_run_writes_one_file_per_scenario(reference):
    sweep_file, summary, df = reference
    sw = load_sweep(sweep_file)
    assert summary["complete"] and summary["ran"] == 3 and summary["skipped"] == 0
    out = Path(summary["out_dir"])
    assert sorted(p.stem for p in (out / "rows").glob("*.parquet")) == [s.id for s in sw.scenarios]
    assert len(df) == 3 * 3 * 3 == summary["rows_written"]       # scenarios x estimators x axes
    assert not df.duplicated(["scenario_id", "estimator", "axis"]).any()
    for col in ("scenario_id", "scenario_seed", "scheme", "n_gyros", "alpha_deg", "rho_arw",
                "motion", "duration_s", "estimator", "axis", "sigma_1_deg_s", "reduction"):
        assert col in df.columns
    # the dataset as pandas/pyarrow read the folder: the same rows
    direct = pd.read_parquet(out / "rows")
    assert len(direct) == len(df)
    manifest = json.loads((out / "sweep.json").read_text())
    assert [s["id"] for s in manifest["scenarios"]] == [s.id for s in sw.scenarios]
    # rerun: nothing left to do, the dataset unchanged
    again = run_sweep(sweep_file, out, workers=1, progress=False)
    assert again["ran"] == 0 and again["skipped"] == 3 and again["complete"]
    assert_same_bits(load_results(out), df)


def test_one_worker_equals_two_workers(reference, tmp_path):
    sweep_file, _, df = reference
    run_sweep(sweep_file, tmp_path / "one", workers=1, progress=False)
    assert_same_bits(load_results(tmp_path / "one"), df)


def test_refuses_to_resume_a_different_sweep(reference, tmp_path):
    _, summary, _ = reference
    other = write(tmp_path, RUN_GRID.replace("[4, 6]", "[4, 8]"))
    with pytest.raises(InputError) as info:
        run_sweep(other, summary["out_dir"], progress=False)
    assert "different sweep" in info.value.message and info.value.file.endswith("sweep.json")


#: A sweep run whose worker, after writing its first result file, marks it and waits to be killed.
KILL_AFTER_FIRST = """\
import os, sys, time
from pathlib import Path
from gyroarray.core import outputs
from gyroarray.sweep.runner import run_sweep

_write = outputs.write_bytes


def _write_then_wait(path, *args, **kw):
    done = _write(path, *args, **kw)
    if str(path).endswith(".parquet"):
        Path(os.environ["SWEEP_TEST_MARK"]).touch()
        time.sleep(3600)
    return done


outputs.write_bytes = _write_then_wait
if __name__ == "__main__":
    run_sweep(sys.argv[1], sys.argv[2], workers=1, progress=False)
"""


@pytest.mark.slow   # a sweep SIGKILLed and resumed (7 s on 2 cores; test_dask_sweep has the cluster's twin): make score
def test_sigkill_and_resume_gives_the_same_dataset(reference, tmp_path):
    """The sweep is killed on an event, not a clock: its worker writes its first result file,
    says so (a marker file) and waits; the kill lands then, however loaded the machine (polling
    for the first file and killing at once let a loaded run write all three first)."""
    sweep_file, _, df = reference
    out = tmp_path / "killed"
    mark = tmp_path / "first_written"
    child = tmp_path / "child.py"              # a file: the spawned worker imports it too
    child.write_text(KILL_AFTER_FIRST)
    proc = subprocess.Popen([sys.executable, str(child), str(sweep_file), str(out)],
                            start_new_session=True, env={**os.environ, "SWEEP_TEST_MARK": str(mark)})
    try:
        limit = bound_s(120.0)
        deadline = time.monotonic() + limit
        while not mark.exists():
            assert proc.poll() is None, "the sweep ended before it could be killed"
            assert time.monotonic() < deadline, f"no result file within {limit:.0f} s"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)          # the runner and its worker processes
        proc.wait()
    n_before = len(list((out / "rows").glob("*.parquet")))
    assert n_before == 1, "killed after the first result and before the rest"
    # a partly written temporary file must not count (nor break the dataset)
    (out / "rows" / ".garbage.999.tmp").write_bytes(b"PAR1 not a parquet file")
    summary = run_sweep(sweep_file, out, workers=1, progress=False)
    assert summary["complete"] and summary["skipped"] == n_before
    assert summary["ran"] == 3 - n_before
    assert_same_bits(load_results(out), df)
    assert len(pd.read_parquet(out / "rows")) == len(df)


@pytest.mark.slow   # a scheduler + workers started by hand (7 s; test_dask_sweep runs --dask local:2 fast): make score
def test_dask_cluster_equals_local(reference, tmp_path):
    sweep_file, _, df = reference
    try:
        import dask
        from distributed import LocalCluster
    except ImportError as err:
        pytest.skip(f"dask.distributed not importable: {err}")
    from gyroarray.sweep.runner import THREAD_ENV       # OPENBLAS_NUM_THREADS=1 etc.
    # numba's own count stays out of the nanny's pre-spawn environment, which it sets in this
    # process too: numba threads launched here with 1 would refuse the default later
    env = {k: v for k, v in THREAD_ENV.items() if k != "NUMBA_NUM_THREADS"}
    try:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": env}):
            cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=40)
    except Exception as err:                              # noqa: BLE001 - any start failure
        pytest.skip(f"a local dask.distributed cluster could not start here: {err!r}")
    with cluster:
        summary = run_sweep(sweep_file, tmp_path / "dask", scheduler=cluster.scheduler_address,
                            progress=False)
    assert summary["backend"] == "dask" and summary["complete"] and not summary["notes"]
    assert_same_bits(load_results(tmp_path / "dask"), df)


def test_truncated_and_emptied_results_are_run_again(reference, tmp_path):
    """A result file cut short or emptied is found on resume and redone: the same bits."""
    sweep_file, summary, df = reference
    out = tmp_path / "damaged"
    shutil.copytree(summary["out_dir"], out)
    files = sorted((out / "rows").glob("*.parquet"))
    data = files[0].read_bytes()
    files[0].write_bytes(data[: len(data) // 2])          # truncated
    files[1].write_bytes(b"")                             # 0 bytes
    with pytest.raises(InputError) as info:               # the report would refuse to read it
        load_results(out)
    assert info.value.file in (str(files[0]), str(files[1])) and "corrupt" in info.value.message
    again = run_sweep(sweep_file, out, workers=1, progress=False)
    assert again["ran"] == 2 and again["skipped"] == 1 and again["complete"]
    assert sum(files[0].name in n or files[1].name in n for n in again["notes"]) == 2
    assert_same_bits(load_results(out), df)


def test_altered_result_without_a_record_is_checked_by_its_footer(reference, tmp_path):
    """A folder whose checksum record is lost still detects a broken footer."""
    sweep_file, summary, df = reference
    out = tmp_path / "norecord"
    shutil.copytree(summary["out_dir"], out)
    (out / "rows.sha256").unlink()
    f = sorted((out / "rows").glob("*.parquet"))[2]
    f.write_bytes(f.read_bytes()[:-10])
    again = run_sweep(sweep_file, out, workers=1, progress=False)
    assert again["ran"] == 1 and any("not a complete Parquet file" in n for n in again["notes"])
    assert_same_bits(load_results(out), df)


def test_cli_report_refuses_a_corrupt_result_naming_it(reference, tmp_path, capsys):
    from gyroarray.cli.main import main
    _, summary, _ = reference
    out = tmp_path / "corrupt"
    shutil.copytree(summary["out_dir"], out)
    f = sorted((out / "rows").glob("*.parquet"))[0]
    f.write_bytes(f.read_bytes()[:100])
    code = main(["report", str(out), "--out", str(tmp_path / "r.html")])
    err = capsys.readouterr().err
    assert code == 2 and str(f) in err and "corrupt" in err and err.count("\n") == 1


def _descendants(pid: int) -> set[int]:
    """Every live process below ``pid`` (Linux /proc)."""
    kids = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            kids.setdefault(ppid, []).append(int(d.name))
    out, todo = set(), [pid]
    while todo:
        for k in kids.get(todo.pop(), []):
            out.add(k)
            todo.append(k)
    return out


def _alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_workers_die_with_a_sigkilled_sweep(reference, tmp_path):
    sweep_file, _, _ = reference
    code = ("import sys; from gyroarray.sweep.runner import run_sweep; "
            "run_sweep(sys.argv[1], sys.argv[2], workers=2, progress=False)")
    proc = subprocess.Popen([sys.executable, "-c", code, str(sweep_file), str(tmp_path / "k")],
                            env=os.environ.copy())
    workers: set[int] = set()
    try:
        # the parent's imports, its sweep read and its pool's two spawns: a few start-ups, polled
        # on the event (both workers in /proc) under a bound scaled to this machine's speed now
        limit = bound_s(60.0)
        deadline = time.monotonic() + limit
        while len(workers) < 2:                       # both workers started
            assert proc.poll() is None, f"the sweep ended (exit {proc.returncode}) before its workers were seen"
            assert time.monotonic() < deadline, f"no workers within {limit:.0f} s"
            workers = {p for p in _descendants(proc.pid)
                       if "spawn_main" in (Path("/proc") / str(p) / "cmdline").read_bytes().decode(errors="replace")}
            time.sleep(0.05)
        os.kill(proc.pid, signal.SIGKILL)             # the parent alone, no clean-up of its own
        proc.wait()
        # A started worker dies at once (PDEATHSIG) or within the watcher's 0.5 s poll. One
        # still importing when the parent died (seen under load: a fresh worker's imports take
        # 5-20 s on 2 busy cores) dies when its initializer runs and sees the parent gone. So
        # the test waits on the event, polled, with a bound that holds on a loaded machine;
        # it returns as soon as the last worker is gone.
        limit = bound_s(180.0)
        deadline = time.monotonic() + limit
        while any(_alive(p) for p in workers) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not any(_alive(p) for p in workers), f"a worker outlived the killed sweep by {limit:.0f} s"
    finally:
        for p in workers | _descendants(proc.pid):
            try:
                os.kill(p, signal.SIGKILL)
            except OSError:
                pass
