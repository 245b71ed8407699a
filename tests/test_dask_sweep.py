"""Sweeps on Dask (issue 34): ``--dask local:N``, batched tasks whose workers write their own
result files, failures reported per scenario, a lost worker's scenarios run elsewhere, resume.

Every comparison is bit for bit against ``--workers 1`` (the local process pool). The cluster
tests share one LocalCluster of 2 single-thread workers (:func:`gyroarray.sweep.runner.local_cluster`,
set up as the process pool's workers are); events are awaited by polling with generous bounds,
never by sleeping a fixed time.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from hostile import assert_contract, run_cli
from same_bits import assert_same_bits
from wall_bound import bound_s

from gyroarray.core.errors import InputError
from gyroarray.sweep.runner import (TaskBatches, load_results, local_cluster, parse_dask,
                                    run_sweep)
from gyroarray.sweep.sweep import load_sweep

distributed = pytest.importorskip("distributed")

# 6 scenarios of 10 s at 50 Hz: 3 run, 3 fail (kf_array's bias states need RRW; "arwonly" has none)
SWEEP = """\
name = "dask_tiny"
seed = 11
estimators = ["kf_array", "ols"]
[base]
sample_rate_hz = 50.0
duration_s = 10.0
effects = [{ effect = "arw", n_deg_rt_h = 0.1 }, { effect = "rrw", k_deg_h_rt_h = 600.0 }]
[base.layout]
scheme = 1
n_gyros = 4
alpha_deg = 54.7356
[base.motion]
profile = "p003_sine_5dps_0p03hz"
[effect_sets]
arwonly = [{ effect = "arw", n_deg_rt_h = 0.1 }]
[grid]
n_gyros = [4, 5, 6]
effects = ["base", "arwonly"]
"""


@pytest.fixture(scope="module")
def sweep_file(tmp_path_factory):
    """The sweep file, with a private truth cache every worker inherits."""
    old = os.environ.get("GYROARRAY_CACHE")
    os.environ["GYROARRAY_CACHE"] = str(tmp_path_factory.mktemp("truth_cache"))
    path = tmp_path_factory.mktemp("sweep") / "dask_tiny.toml"
    path.write_text(SWEEP)
    yield path
    if old is None:
        os.environ.pop("GYROARRAY_CACHE", None)
    else:
        os.environ["GYROARRAY_CACHE"] = old


@pytest.fixture(scope="module")
def reference(sweep_file, tmp_path_factory):
    """``--workers 1``: the summary and the dataset every other run must equal."""
    out = tmp_path_factory.mktemp("ref") / "out"
    summary = run_sweep(sweep_file, out, workers=1, progress=False)
    return summary, load_results(out)


@pytest.fixture(scope="module")
def cluster(sweep_file):
    """One LocalCluster of 2 single-thread workers for the module (started after the cache
    variable is set, so its workers inherit it)."""
    try:
        with local_cluster(2) as c:
            yield c
    except InputError as err:
        pytest.skip(f"a local Dask cluster could not start here: {err.message}")


def failing_ids(sweep_file) -> list[str]:
    return sorted(s.id for s in load_sweep(sweep_file).scenarios if "arwonly" in s.id)


# -- refusals and the task sizing (no cluster) ------------------------------------------------

@pytest.mark.parametrize("text", ["local:0", "foo", "local:", "local:2:3", "local:99999",
                                  "tcp://127.0.0.1:8786", "local:\u0662"])
def test_bad_dask_text_is_one_line_exit_2(tmp_path, text):
    (tmp_path / "s.toml").write_text(SWEEP)
    o = run_cli(["sweep", tmp_path / "s.toml", "--out", tmp_path / "out", "--dask", text])
    assert o.code == 2
    assert_contract(o, "--dask")
    assert "local:N" in o.err and not (tmp_path / "out").exists()
    with pytest.raises(InputError):
        parse_dask(text)


def test_dask_excludes_workers_and_scheduler(tmp_path):
    (tmp_path / "s.toml").write_text(SWEEP)
    for extra in (["--workers", "2"], ["--scheduler", "tcp://127.0.0.1:8786"]):
        o = run_cli(["sweep", tmp_path / "s.toml", "--out", tmp_path / "out", "--dask", "local:2",
                     *extra])
        assert o.code == 2 and "--dask" in o.err
        assert_contract(o)
    assert parse_dask("local:16") == 16 and parse_dask(" LOCAL:3") == 3


class _Spec:
    def __init__(self, sid):
        self.id = sid


def test_tasks_are_sized_from_the_measured_time():
    specs = [_Spec(f"s{i:03d}") for i in range(100)]
    costs = {s.id: 1.0 for s in specs}
    b = TaskBatches(specs, slots=2, costs=costs, target_s=5.0)
    first = [b.take() for _ in range(4)]                  # nothing measured: one per task
    assert [len(t[0]) for t in first] == [1, 1, 1, 1] and not any(t[1] for t in first)
    b.measured("s000", 1.0)                               # 1 s per scenario: 5 per task
    assert len(b.take()[0]) == 5
    b.measured("s001", 3.0)                               # now 2 s per scenario: 2 per task
    assert len(b.take()[0]) == 2
    # the tail: at most ceil(left / (2 slots)) per task, so the last tasks spread over the slots
    b2 = TaskBatches(specs[:6], slots=2, costs=costs, target_s=100.0)
    b2.measured("s000", 0.01)
    sizes = []
    while (t := b2.take()) is not None:
        sizes.append(len(t[0]))
    assert sizes == [2, 1, 1, 1, 1] and sum(sizes) == 6
    # a task that failed as a whole comes back one scenario per task, marked isolated
    b2.split(specs[:3])
    assert [b2.take() for _ in range(3)] == [([specs[i]], True) for i in range(3)]
    assert b2.take() is None


class _PoolLike:
    """Test only: a process pool as the dispatcher sees it, run by hand. A task holding the
    culprit ``bad`` breaks the pool: every task in flight fails (``BrokenProcessPool``), as a
    ``ProcessPoolExecutor`` does when one worker dies; the others finish one by one."""

    retry_lost = True
    serial_retry = True

    def __init__(self, bad):
        self.bad, self.flight, self.tasks = bad, [], []
        self.suspects: list = []      # the scenarios in flight when the pool broke
        self.after: list = []         # (task, tasks in flight) of each submit after the break

    def submit(self, fn, *args):
        from concurrent.futures import Future
        fut = Future()
        if fn.__name__ == "run_batch":
            ids = [s.id for s in args[0]]
            self.tasks.append(ids)
            self.flight.append((fut, ids))
            if self.suspects:
                self.after.append((ids, len(self.flight)))
        else:
            fut.set_result("truth")
        return fut

    def wait_any(self, pending):
        from concurrent.futures.process import BrokenProcessPool
        done = [f for f in pending if f.done()]
        if done:
            return [(f, f.exception()) for f in done]
        if any(self.bad in ids for _, ids in self.flight):
            out = [(f, BrokenProcessPool("a worker died")) for f, _ in self.flight]
            self.suspects = self.suspects or sorted(i for _, ids in self.flight for i in ids)
            self.flight.clear()
            return out
        fut, ids = self.flight.pop(0)
        fut.set_result([{"id": i, "file": f"{i}.parquet", "sha256": "0", "rows": 1,
                         "seconds": 0.1} for i in ids])
        return [(fut, None)]

    @staticmethod
    def result(fut):
        return fut.result()


def test_a_broken_pool_loses_only_the_scenario_that_breaks_it():
    """The local pool's dispatch (no processes): after a break, the tasks in flight run again
    one scenario at a time with nothing else in flight, so only the culprit is lost."""
    from types import SimpleNamespace

    from gyroarray.sweep.runner import _dispatch
    specs = [_Spec(f"s{i:02d}") for i in range(12)]
    backend = _PoolLike(bad="s05")
    ok, lost = [], []
    _dispatch(backend, 2, specs, SimpleNamespace(estimators=["ols"], name="t"), Path("."),
              {s.id: 1.0 for s in specs}, lambda rec: ok.append(rec["id"]),
              lambda spec, err: lost.append((spec.id, type(err).__name__)))
    assert lost == [("s05", "BrokenProcessPool")]
    assert sorted(ok) == sorted(s.id for s in specs if s.id != "s05")     # each once
    # the break caught the culprit beside others; each of them ran again alone, then the rest
    k = len(backend.suspects)
    assert k >= 2 and "s05" in backend.suspects
    assert sorted(i for ids, _ in backend.after[:k] for i in ids) == backend.suspects
    assert all(len(ids) == 1 and n == 1 for ids, n in backend.after[:k])
    assert max(n for _, n in backend.after[k:]) > 1          # then the pool is used in full


@pytest.mark.slow   # a real pool broken and restarted (~5 s on 2 cores; the dispatch's part is tested above without processes): make score
def test_a_pool_worker_killed_mid_sweep_costs_nothing(sweep_file, reference, tmp_path, capfd):
    """``--workers 2``: a worker SIGKILLed while scenarios are in flight breaks the process
    pool as a whole; the pool starts again and the same dataset comes out, with only the
    chain's own failures reported (each on its own line under the progress bar). The workers
    are frozen (SIGSTOP) at the first result file, so that the kill lands while work is left,
    however loaded the machine."""
    psutil = pytest.importorskip("psutil")
    _, ref = reference
    me = psutil.Process()
    before = {c.pid for c in me.children(recursive=True)}
    n_ok = len(ref["scenario_id"].unique())
    for attempt in range(3):              # a sweep that finished before the freeze: again
        out = tmp_path / f"killed{attempt}"
        state: dict = {}

        def killer():
            rows = out / "rows"
            deadline = time.monotonic() + 300
            while not (rows.exists() and list(rows.glob("*.parquet"))):
                if time.monotonic() > deadline or "done" in state:
                    return
                time.sleep(0.002)
            # the pool's workers (not multiprocessing's resource tracker)
            pool = [c for c in me.children(recursive=True) if c.pid not in before
                    and "spawn_main" in " ".join(c.cmdline())]
            for c in pool:
                c.send_signal(signal.SIGSTOP)
            state["left"] = n_ok - len(list(rows.glob("*.parquet")))
            pool[0].send_signal(signal.SIGKILL)
            for c in pool[1:]:
                c.send_signal(signal.SIGCONT)
            state["killed"] = pool[0].pid

        t = threading.Thread(target=killer, daemon=True)
        t.start()
        capfd.readouterr()
        summary = run_sweep(sweep_file, out, workers=2, progress=True)
        state["done"] = True
        t.join(60)
        if state.get("left", 0) > 0:
            break
    assert state.get("left", 0) > 0, "every try finished before a worker could be killed"
    assert sorted(f["id"] for f in summary["failed"]) == failing_ids(sweep_file)
    assert summary["ran"] == 3 and any("died" in n for n in summary["notes"])
    assert_same_bits(load_results(out), ref)
    err = capfd.readouterr().err
    assert "6/6" in err and "Traceback" not in err
    said = [line for line in err.splitlines() if " failed: " in line]
    assert sorted(line.split()[1] for line in said) == failing_ids(sweep_file)
    assert all(line.startswith("sweep: ") for line in said)
    assert all("rate random walk" in line for line in said)


# -- on a cluster ----------------------------------------------------------------------------

@pytest.mark.slow   # 13 s (a local Dask cluster started): make score
def test_dask_local_gives_the_same_bits_and_names_each_failure(sweep_file, reference, tmp_path):
    """``--dask local:2`` (a cluster started and closed by the command): the same dataset as
    ``--workers 1``, each failing scenario named with its reason, the others complete."""
    ref_summary, ref = reference
    out = tmp_path / "dask"
    o = run_cli(["sweep", sweep_file, "--out", out, "--dask", "local:2", "--json"], timeout=bound_s(300.0))
    assert "Traceback" not in o.err
    summary = json.loads(o.out)
    assert o.code == 1 and summary["backend"] == "dask" and summary["workers"] == 2
    assert sorted(f["id"] for f in summary["failed"]) == failing_ids(sweep_file)
    assert sorted(f["id"] for f in ref_summary["failed"]) == failing_ids(sweep_file)
    assert all("rate random walk" in f["error"] and "\n" not in f["error"]
               for f in summary["failed"])
    assert summary["ran"] == 3 and summary["rows_written"] == len(ref)
    assert_same_bits(load_results(out), ref)
    # the workers wrote the files, this process recorded their checksums: all verify
    lines = (out / "rows.sha256").read_text().splitlines()
    assert len(lines) == 3 and all(len(x.split()) == 3 for x in lines)
    # where the time went: the phases add up to the command's run time (the summary's clock);
    # every scenario ran in one of the two workers, inside its span
    prof = summary["profile"]
    assert list(prof["phases_s"]) == ["prepare", "cluster", "warm", "truth", "scenarios", "closed"]
    assert sum(prof["phases_s"].values()) == pytest.approx(summary["seconds"], abs=0.01)
    assert len(prof["workers"]) == 2 and sum(w["scenarios"] for w in prof["workers"].values()) == 6
    assert prof["busy_s"] == pytest.approx(summary["worker_seconds"], abs=0.01)
    for w in prof["workers"].values():
        assert 0 < w["first_start_s"] < w["last_end_s"] <= summary["seconds"]
        assert w["write_s"] <= w["busy_s"] and w["between_s"] >= -0.01
        assert 0 < w["cpu_s"] <= w["busy_s"] * 1.02 + 0.01    # a thread's CPU time ≤ its wall time


def test_sweep_profile_adds_up():
    """The profile of hand-made phase marks and runs, by hand."""
    from gyroarray.sweep.runner import sweep_profile
    stamps = {"prepare": 0.5, "truth": 2.0, "scenarios": 10.0, "closed": 10.25}
    runs = [("a", 2.0, 3.0, 2.5, 0.1), ("a", 5.5, 4.0, 4.0, 0.2), ("b", 2.1, 5.0, 5.0, 0.3)]
    prof = sweep_profile(stamps, runs)
    assert prof["phases_s"] == {"prepare": 0.5, "truth": 1.5, "scenarios": 8.0, "closed": 0.25}
    assert prof["busy_s"] == 12.0 and prof["cpu_s"] == 11.5 and prof["write_s"] == 0.6
    a, b = prof["workers"]["a"], prof["workers"]["b"]
    assert (a["first_start_s"], a["last_end_s"], a["between_s"], a["scenarios"]) == (2.0, 9.5, 0.5, 2)
    assert (b["last_end_s"], b["between_s"]) == (7.1, 0.0)
    assert prof["first_scenario_s"] == 2.0 and prof["tail_s"] == pytest.approx(2.9)
    assert prof["between_s"] == 0.5
    assert sweep_profile({}, [])["tail_s"] is None


class _KillOnce(distributed.WorkerPlugin):
    """Test only: the first worker to start a scenario batch dies (``os._exit``) as soon as a
    result file appears, once per test (a flag file); a restarted worker is left alone."""

    name = "gyroarray-test-kill-once"

    def __init__(self, flag_dir: str, rows_dir: str):
        self.flag_dir, self.rows_dir = flag_dir, rows_dir

    def transition(self, key, start, finish, **kwargs):
        if finish != "executing" or "run_batch" not in str(key):
            return
        try:
            os.close(os.open(os.path.join(self.flag_dir, "armed"), os.O_CREAT | os.O_EXCL))
        except FileExistsError:
            return
        rows = Path(self.rows_dir)

        def later():
            n0 = len(list(rows.glob("*.parquet")))
            deadline = time.monotonic() + 300
            while len(list(rows.glob("*.parquet"))) <= n0 and time.monotonic() < deadline:
                time.sleep(0.005)
            Path(self.flag_dir, "killed").write_text(str(os.getpid()))
            os._exit(1)

        threading.Thread(target=later, daemon=True).start()


@pytest.mark.slow   # a worker killed mid-sweep on the shared cluster (~15 s on 2 busy cores): make score
def test_a_worker_killed_mid_sweep_costs_only_its_scenarios(sweep_file, reference, cluster,
                                                             tmp_path):
    import cloudpickle
    _, ref = reference
    out = tmp_path / "killed"
    flags = tmp_path / "flags"
    flags.mkdir()
    cloudpickle.register_pickle_by_value(sys.modules[__name__])   # the plugin class goes by value
    client = distributed.Client(cluster, set_as_default=False)
    try:
        client.register_plugin(_KillOnce(str(flags), str(out / "rows")))
        summary = run_sweep(sweep_file, out, scheduler=cluster.scheduler_address, progress=False)
    finally:
        client.unregister_worker_plugin(_KillOnce.name)
        client.close()
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    assert (flags / "killed").exists(), "no worker was killed during the sweep"
    assert sorted(f["id"] for f in summary["failed"]) == failing_ids(sweep_file)
    assert summary["ran"] == 3
    assert_same_bits(load_results(out), ref)
    assert not [p for p in (out / "rows").iterdir() if not p.name.endswith(".parquet")
                and not p.name.startswith(".")]


@pytest.mark.slow   # a SIGKILLed sweep on the shared cluster, then resumed (~15 s on 2 busy cores): make score
def test_resume_after_an_interrupted_dask_sweep(sweep_file, reference, cluster, tmp_path):
    _, ref = reference
    out = tmp_path / "interrupted"
    code = ("import sys; from gyroarray.sweep.runner import run_sweep; "
            "run_sweep(sys.argv[1], sys.argv[2], scheduler=sys.argv[3], progress=False)")
    proc = subprocess.Popen([sys.executable, "-c", code, str(sweep_file), str(out),
                             cluster.scheduler_address], env=os.environ.copy())
    try:
        limit = bound_s(300.0)                       # scaled to this machine's speed now
        deadline = time.monotonic() + limit
        while not list((out / "rows").glob("*.parquet")):
            assert proc.poll() is None, "the sweep ended before it could be killed"
            assert time.monotonic() < deadline, f"no result file within {limit:.0f} s"
            time.sleep(0.02)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    summary = run_sweep(sweep_file, out, scheduler=cluster.scheduler_address, progress=False)
    assert summary["skipped"] >= 1 and summary["ran"] + summary["skipped"] == 3
    assert sorted(f["id"] for f in summary["failed"]) == failing_ids(sweep_file)
    assert_same_bits(load_results(out), ref)
