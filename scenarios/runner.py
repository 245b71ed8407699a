"""Run a sweep in parallel into a resumable Parquet dataset.

:func:`run_sweep` runs every scenario of a sweep (:mod:`gyroarray.scenarios.sweep`)
in worker processes — a local ``ProcessPoolExecutor`` (spawned workers), or a
``dask.distributed`` cluster when ``scheduler`` is its address
(``tcp://HOST:PORT``) — and writes, as each scenario finishes, its rows to
``out_dir/rows/<id>.parquet``: one row per estimator × body axis (the
chain's metric table) plus the scenario's parameters, id and seed. Each file
is written to a hidden temporary file and moved into place with
``os.replace``, so the dataset (``pandas.read_parquet(out_dir / "rows")`` or
:func:`load_results`) is always the set of complete scenarios.

A scenario that raises (in the chain) is reported in the summary's
``failed`` list (id and error) and the others go on; it has no file, so a
rerun tries it again.

Resuming: rerunning into the same folder skips the ids whose file exists.
``out_dir/sweep.json`` (the manifest: the sweep file's SHA-256 and the
expanded scenario list with ids and seeds) refuses a folder that holds a
different sweep.

Determinism: every scenario runs in a worker process (also with
``workers=1``) whose environment has ``OPENBLAS_NUM_THREADS=1`` (and
``OMP_NUM_THREADS``/``MKL_NUM_THREADS``/``NUMBA_NUM_THREADS=1``: one thread per
worker, no oversubscription), so BLAS products do not depend on
thread scheduling; a scenario's seed comes from the sweep seed and its id.
The same sweep therefore gives the same bits whatever the number of workers
or the order scenarios finish in. Dask workers get the variables from the
cluster (``distributed.nanny.pre-spawn-environ``, which sets the BLAS/OpenMP
ones to 1 by default; add ``NUMBA_NUM_THREADS=1`` against oversubscription);
:func:`run_sweep` checks ``OPENBLAS_NUM_THREADS`` on every worker and says
so in the summary's ``notes`` when it is not 1.
"""

from __future__ import annotations

import json
import os
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from pathlib import Path

import multiprocessing as mp

from gyroarray.errors import InputError

from .sweep import ScenarioSpec, Sweep, load_sweep

__all__ = ["run_sweep", "load_results", "run_one", "THREAD_ENV"]

#: Environment of every worker process (bitwise-reproducible BLAS).
THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "NUMBA_NUM_THREADS": "1"}
MANIFEST = "sweep.json"
ROWS = "rows"
_STR_COLS = ("estimator", "axis", "scenario_id", "motion", "effects", "sweep", "scenario")


def run_one(spec: ScenarioSpec, estimators, sweep_name: str):
    """Run one scenario (in a worker): its rows as a DataFrame with a fixed schema."""
    import pandas as pd

    from gyroarray.chain import run_scenario

    result = run_scenario(spec.build(), list(estimators) if estimators else None)
    table = result.table.copy()
    out = pd.DataFrame({"sweep": [sweep_name] * len(table)})
    for k, v in spec.row_params().items():
        out[k] = [v] * len(table)
    for col in table.columns:
        if col in ("estimator", "axis"):
            out[col] = table[col].astype(str).to_numpy()
        else:
            # metrics are numbers or None (not applicable): float64 with NaN
            out[col] = pd.to_numeric(table[col].astype(object).where(table[col].notna(), None),
                                     errors="raise").astype("float64").to_numpy()
    return _typed(out)


def _typed(df):
    import pandas as pd
    for col in df.columns:
        if col in _STR_COLS:
            df[col] = df[col].astype(object)
        elif col in ("scheme",):
            df[col] = pd.array(df[col], dtype="Int64")
        elif col in ("n_gyros", "scenario_seed", "replicate"):
            df[col] = df[col].astype("int64")
        elif col == "alpha_optimal":
            df[col] = df[col].astype(bool)
        else:
            df[col] = pd.to_numeric(df[col].astype(object).where(df[col].notna(), None)
                                    ).astype("float64")
    return df


def _write_rows(df, folder: Path, sid: str) -> Path:
    import pyarrow as pa
    import pyarrow.parquet as pq

    final = folder / f"{sid}.parquet"
    tmp = folder / f".{sid}.{os.getpid()}.tmp"
    table = pa.Table.from_pandas(df, preserve_index=False)
    pq.write_table(table, tmp)
    with open(tmp, "rb") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, final)
    return final


def load_results(out_dir):
    """The dataset of a sweep folder (complete scenario files only), sorted by id, estimator, axis."""
    import pandas as pd

    folder = Path(out_dir) / ROWS
    files = sorted(folder.glob("*.parquet")) if folder.is_dir() else []
    if not files:
        return pd.DataFrame()
    df = pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)
    return df.sort_values(["scenario_id", "estimator", "axis"], kind="stable").reset_index(drop=True)


def _check_manifest(out: Path, sweep: Sweep) -> None:
    path = out / MANIFEST
    mine = sweep.manifest()
    if path.exists():
        try:
            theirs = json.loads(path.read_text())
        except (OSError, ValueError) as err:
            raise InputError(f"unreadable sweep manifest: {err}", file=str(path)) from None
        for key in ("sweep_sha256", "seed", "estimators", "scenarios"):
            if theirs.get(key) != json.loads(json.dumps(mine[key])):
                raise InputError(
                    f"this folder holds a different sweep ({theirs.get('name')!r}, {key} differs); "
                    "resume only with the same sweep file, or use a new folder", file=str(path),
                    column=key)
        return
    if (out / ROWS).is_dir() and any((out / ROWS).glob("*.parquet")):
        raise InputError("the folder has results but no sweep.json: not resuming into it",
                         file=str(out))
    tmp = out / f".{MANIFEST}.tmp"
    tmp.write_text(json.dumps(mine, indent=1))
    os.replace(tmp, path)


@contextmanager
def _env(values: dict):
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class _Progress:
    def __init__(self, total: int, done: int, enabled):
        self.total, self.done, self.t0 = total, done, time.perf_counter()
        self.start = done
        self.on = sys.stderr.isatty() if enabled is None else bool(enabled)
        self.show()

    def show(self, final=False):
        if not self.on:
            return
        if final:
            sys.stderr.write("\n")
            sys.stderr.flush()
            return
        el = time.perf_counter() - self.t0
        ran = self.done - self.start
        left = self.total - self.done
        eta = f", eta {el / ran * left:.0f} s" if ran and left else ""
        width = 30
        fill = int(width * self.done / max(self.total, 1))
        sys.stderr.write(f"\rsweep [{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total} "
                         f"{el:.0f} s{eta}   " + ("\n" if final else ""))
        sys.stderr.flush()

    def step(self):
        self.done += 1
        self.show()


def _cost(spec: ScenarioSpec) -> float:
    """Rough work of a scenario: samples × gyros (for scheduling only)."""
    sc = spec.build()
    duration = sc.duration_s if sc.duration_s is not None else sc.profile.duration_s
    return duration * sc.sample_rate_hz * sc.layout.n_gyros


def _dask_client(scheduler: str):
    try:
        from distributed import Client
    except ImportError:
        raise InputError("a scheduler address needs dask[distributed] installed") from None
    try:
        return Client(scheduler, timeout="20s", set_as_default=False)
    except (OSError, TimeoutError) as err:
        raise InputError(f"cannot connect to the Dask scheduler {scheduler}: {err}") from None


def run_sweep(sweep, out_dir, *, workers: int = 1, scheduler: str | None = None,
              progress=None) -> dict:
    """Run (or resume) a sweep into ``out_dir``; one Parquet file per finished scenario.

    Parameters
    ----------
    sweep : Sweep or path
        A loaded sweep or a sweep file.
    out_dir : path
        Output folder: ``sweep.json`` and ``rows/<id>.parquet``.
    workers : int
        Local worker processes (ignored with ``scheduler``).
    scheduler : str, optional
        A ``dask.distributed`` scheduler address (``tcp://HOST:PORT``): run there.
    progress : bool or None
        Progress bar on stderr; None: when stderr is a terminal.

    Returns
    -------
    dict
        ``sweep``, ``out_dir``, ``dataset``, ``scenarios``, ``ran``, ``skipped``,
        ``failed`` (list of {id, error}), ``complete``, ``rows_written``,
        ``seconds``, ``workers``, ``backend``, ``notes``, ``excluded`` (grid
        combinations left out by ``skip_invalid``: {id, reason}).
    """
    t0 = time.perf_counter()
    if not isinstance(sweep, Sweep):
        sweep = load_sweep(sweep)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers must be an integer >= 1, got {workers!r}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("the output must be a folder", file=str(out))
    (out / ROWS).mkdir(parents=True, exist_ok=True)
    _check_manifest(out, sweep)
    rows_dir = out / ROWS
    todo = [s for s in sweep.scenarios if not (rows_dir / f"{s.id}.parquet").exists()]
    # longest first (a better finish on few workers); results do not depend on the order
    todo.sort(key=lambda s: (-_cost(s), s.id))
    skipped = len(sweep.scenarios) - len(todo)
    bar = _Progress(len(sweep.scenarios), skipped, progress)
    failed, rows_written = [], 0
    notes = []

    def done(spec, df=None, err=None):
        nonlocal rows_written
        if err is not None:
            failed.append({"id": spec.id, "error": f"{type(err).__name__}: {err}"})
        else:
            _write_rows(df, rows_dir, spec.id)
            rows_written += len(df)
        bar.step()

    if todo and scheduler is None:
        backend = "processes"
        ctx = mp.get_context("spawn")
        with _env(THREAD_ENV), ProcessPoolExecutor(max_workers=min(workers, len(todo)),
                                                   mp_context=ctx) as pool:
            futures = {pool.submit(run_one, s, sweep.estimators, sweep.name): s for s in todo}
            pending = set(futures)
            while pending:
                finished, pending = wait(pending, return_when=FIRST_COMPLETED)
                for f in sorted(finished, key=lambda f: futures[f].id):
                    exc = f.exception()
                    done(futures[f], None if exc else f.result(), exc)
    elif todo:
        backend = "dask"
        from distributed import as_completed
        client = _dask_client(scheduler)
        try:
            envs = client.run(lambda: {k: os.environ.get(k) for k in THREAD_ENV})
            off = sorted(w for w, e in envs.items() if e.get("OPENBLAS_NUM_THREADS") != "1")
            if off:
                notes.append(f"{len(off)} Dask worker(s) without OPENBLAS_NUM_THREADS=1: results "
                             "may differ in the last bits from a local run")
            futures = {client.submit(run_one, s, sweep.estimators, sweep.name, key=f"sweep-{s.id}",
                                     pure=False): s for s in todo}
            for f in as_completed(list(futures), loop=client.loop):
                spec = futures[f]
                if f.status == "error":
                    done(spec, err=f.exception())
                else:
                    done(spec, f.result())
        finally:
            client.close()
    else:
        backend = "none (all done)"
    bar.show(final=True)
    complete = not failed and all((rows_dir / f"{s.id}.parquet").exists() for s in sweep.scenarios)
    return {"sweep": sweep.name, "out_dir": str(out), "dataset": str(rows_dir),
            "scenarios": len(sweep.scenarios), "ran": len(todo) - len(failed), "skipped": skipped,
            "failed": failed, "complete": complete, "rows_written": rows_written,
            "seconds": time.perf_counter() - t0,
            "workers": None if scheduler else workers, "scheduler": scheduler,
            "backend": backend, "notes": notes,
            "excluded": [{"id": i, "reason": r} for i, r in sweep.excluded]}
