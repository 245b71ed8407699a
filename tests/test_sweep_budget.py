"""A sweep's workers are budgets: the machine's cores and the memory budget (``--max-memory``).

``--workers K`` and ``--dask local:N`` are refused beyond
:data:`~gyroarray.core.parallel.MAX_WORKERS_PER_CPU` per CPU this process may use, and when N
workers, each an idle worker process with its imports
(:data:`~gyroarray.core.parallel.WORKER_BASELINE_BYTES`, measured) plus the sweep's largest
scenario's working memory (:func:`gyroarray.sim.scenario.memory_needed`), need more than the
budget: the refusal says how much, for how many workers, and how many fit. Both come before
any work (the output folder is not even made). A LocalCluster's workers are bounded at run
time by their share of the budget (``memory_limit``), with Dask's pausing off.
"""

from __future__ import annotations

import pytest

from gyroarray.core import parallel
from gyroarray.core.errors import InputError
from gyroarray.core.limits import format_size, memory_budget
from gyroarray.sim.scenario import memory_needed
from gyroarray.sweep.sweep import load_sweep
from hostile import assert_contract, run_cli, tiny_sweep

GiB, MiB = 2**30, 2**20


@pytest.fixture
def three(tmp_path):
    """A sweep of three short scenarios (N = 4, 5, 6)."""
    p = tmp_path / "three.toml"
    p.write_text(tiny_sweep(estimators=["ols"]) + "[grid]\nn_gyros = [4, 5, 6]\n")
    return p


@pytest.fixture
def cpus(monkeypatch):
    """This process may use 3 CPUs: at most 12 workers."""
    monkeypatch.setattr(parallel, "available_cpus", lambda: 3)
    return 3


def _largest_work(sweep_file) -> float:
    return max(memory_needed(s.build(), "run") for s in load_sweep(sweep_file).scenarios)


def _refused(o, option: str) -> str:
    assert_contract(o, option)
    assert o.code == 2, (o.code, o.err)
    return o.err.strip()


def test_worker_counts_past_four_per_cpu_are_refused(cpus):
    assert parallel.max_workers() == 12
    parallel.check_worker_count(12, "--dask", "local:{n}")
    with pytest.raises(InputError) as err:
        parallel.check_worker_count(13, "--dask", "local:{n}")
    assert err.value.message == (
        "--dask local:13: 13 worker processes on 3 CPU(s) are more than 4 per CPU (each scenario "
        "runs on one core, so the others only wait for one, each holding about 320 MiB): give "
        "--dask local:1 to local:12")
    with pytest.raises(InputError, match=r"--workers 13: .* give --workers 1 to 12$"):
        parallel.check_worker_count(13, "--workers")


@pytest.mark.parametrize("argv, option", [(["--dask", "local:1024"], "--dask local:1024"),
                                          (["--workers", "200"], "--workers 200")])
def test_an_absurd_count_is_refused_before_any_work(three, tmp_path, cpus, argv, option):
    out = tmp_path / "out"
    err = _refused(run_cli(["sweep", three, "--out", out, *argv], timeout=120), option)
    assert "3 CPU(s)" in err and "to " in err
    assert not out.exists()


def test_dask_workers_that_pass_the_memory_budget_are_refused_with_how_many_fit(three, tmp_path, cpus):
    out = tmp_path / "out"
    each = parallel.WORKER_BASELINE_BYTES + parallel.DASK_WORKER_EXTRA_BYTES + _largest_work(three)
    assert 300 * MiB < each < 400 * MiB                  # an idle worker dominates a tiny scenario
    err = _refused(run_cli(["sweep", three, "--out", out, "--dask", "local:12", "--max-memory", "1G"],
                           timeout=120), "--dask local:12")
    assert f"needs about {format_size(12 * each)} for 12 worker(s) ({format_size(each)} each" in err
    assert "the memory budget is 1 GiB" in err
    assert int(GiB // each) == 2 and "use at most 2 worker(s) (--dask local:2)" in err
    assert not out.exists()


def test_process_workers_count_only_those_that_start(three, tmp_path, cpus):
    each = parallel.WORKER_BASELINE_BYTES + _largest_work(three)
    budget = int(2.5 * each)                              # two fit, three do not
    o = run_cli(["sweep", three, "--out", tmp_path / "a", "--workers", "8", "--max-memory",
                 str(budget)], timeout=120)
    err = _refused(o, "--workers 8")
    # three scenarios: three workers start, not eight
    assert f"--workers 8 needs about {format_size(3 * each)} for 3 worker(s) (one per scenario" in err
    assert "use at most 2 worker(s) (--workers 2)" in err
    o = run_cli(["sweep", three, "--out", tmp_path / "b", "--max-memory", str(int(each / 2))],
                timeout=120)
    err = _refused(o, "--workers 1")
    assert f"not even one worker fits; raise --max-memory to at least {format_size(each)}" in err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_each_dask_worker_gets_its_share_of_the_budget():
    with memory_budget(GiB):
        assert parallel.check_workers_memory(2, 10 * MiB, "--dask", "local:{n}") == GiB // 2
        assert parallel.check_workers_memory(3, 10 * MiB, "--dask", "local:{n}") == GiB // 3
        with pytest.raises(InputError, match="use at most 3 worker"):
            parallel.check_workers_memory(4, 10 * MiB, "--dask", "local:{n}")


@pytest.mark.slow      # a LocalCluster of two worker processes started and closed (10-30 s loaded)
def test_a_local_cluster_bounds_each_worker_at_its_share():
    pytest.importorskip("distributed")
    from distributed import Client

    from gyroarray.sweep.runner import local_cluster
    limit = 700 * MiB
    with local_cluster(2, memory_limit=limit) as cluster:
        client = Client(cluster, set_as_default=False)
        try:
            seen = client.run(lambda dask_worker: (dask_worker.memory_manager.memory_limit,
                                                   dask_worker.memory_manager.memory_pause_fraction))
        finally:
            client.close()
    assert sorted(seen.values()) == [(limit, False), (limit, False)]
