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

Resuming: rerunning into the same folder skips the ids whose file exists
and is intact. ``out_dir/sweep.json`` (the manifest: the sweep file's
SHA-256 and the expanded scenario list with ids and seeds) refuses a folder
that holds a different sweep. Every finished file's SHA-256 and row count
are appended to ``out_dir/rows.sha256`` as it is written; on resume each
existing file is checked against that record (or, without a record, its
Parquet footer and row count are read), and a truncated, emptied or altered
file is run again (the summary's ``notes`` say which). :func:`load_results`
refuses a corrupt file, naming it, instead of reading it.

Workers die with the sweep: each worker process watches its parent (Linux
``PR_SET_PDEATHSIG`` and, everywhere, a thread that polls the parent's pid
twice a second) and exits when the parent is gone, also after a SIGKILL of
the parent, which runs no clean-up of its own.

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

import hashlib
import json
import os
import signal
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from pathlib import Path

import multiprocessing as mp

from gyroarray.errors import InputError

from gyroarray.scenarios.sweep import ScenarioSpec, Sweep, load_sweep

__all__ = ["run_sweep", "load_results", "run_one", "verify_rows_file", "THREAD_ENV"]

#: Environment of every worker process (bitwise-reproducible BLAS).
THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "NUMBA_NUM_THREADS": "1"}
MANIFEST = "sweep.json"
ROWS = "rows"
#: Checksums of the finished result files: ``<sha256> <rows> <id>.parquet`` per line.
CHECKSUMS = "rows.sha256"
_STR_COLS = ("estimator", "axis", "scenario_id", "motion", "effects", "sweep", "scenario")


def run_one(spec: ScenarioSpec, estimators, sweep_name: str):
    """Run one scenario (in a worker): its rows as a DataFrame with a fixed schema."""
    import pandas as pd

    from gyroarray.chain import run_scenario  # lazy: loads numba

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
    """Write a scenario's rows atomically and record the file's checksum beside the folder."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    final = folder / f"{sid}.parquet"
    tmp = folder / f".{sid}.{os.getpid()}.tmp"
    table = pa.Table.from_pandas(df, preserve_index=False)
    pq.write_table(table, tmp)
    with open(tmp, "rb") as fh:
        os.fsync(fh.fileno())
    digest = _sha256(tmp)
    os.replace(tmp, final)
    with open(folder.parent / CHECKSUMS, "a", encoding="utf-8") as fh:
        fh.write(f"{digest} {len(df)} {final.name}\n")
        fh.flush()
        os.fsync(fh.fileno())
    return final


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _recorded_checksums(out: Path) -> dict:
    """File name -> (sha256, rows) from ``rows.sha256``; the last record of a name wins,
    a torn last line (a crash while appending) is ignored."""
    path = out / CHECKSUMS
    records: dict[str, tuple[str, int]] = {}
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return records
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 3 and len(parts[0]) == 64 and parts[1].isdigit():
            records[parts[2]] = (parts[0], int(parts[1]))
    return records


def verify_rows_file(path: Path, record=None) -> str | None:
    """Why a result file cannot be trusted, or None when it is intact.

    With a ``record`` (sha256, rows) from ``rows.sha256`` the file's bytes must
    hash to it; without one, its Parquet footer must read and hold at least
    one row.
    """
    import pyarrow.parquet as pq

    try:
        if path.stat().st_size == 0:
            return "the file is empty"
        if record is not None:
            return None if _sha256(path) == record[0] else "its checksum differs from the one recorded"
        rows = pq.ParquetFile(path).metadata.num_rows
    except OSError as err:
        return f"cannot be read ({err.strerror or err})"
    except Exception as err:   # pyarrow raises ArrowInvalid and others on a broken footer
        return f"not a complete Parquet file ({type(err).__name__})"
    return None if rows > 0 else "it holds no rows"


def load_results(out_dir):
    """The dataset of a sweep folder (complete scenario files only), sorted by id, estimator, axis.

    Raises
    ------
    InputError
        A result file is corrupt (truncated, emptied, altered): named, with the way out.
    """
    import pandas as pd

    out = Path(out_dir)
    folder = out / ROWS
    files = sorted(folder.glob("*.parquet")) if folder.is_dir() else []
    if not files:
        return pd.DataFrame()
    records = _recorded_checksums(out)
    for f in files:
        why = verify_rows_file(f, records.get(f.name))
        if why is not None:
            raise InputError(f"corrupt sweep result: {why}; rerun the same `gyroarray sweep` command "
                             "into this folder to redo that scenario", file=str(f))
    df = pd.concat([pd.read_parquet(f) for f in files], ignore_index=True)
    return df.sort_values(["scenario_id", "estimator", "axis"], kind="stable").reset_index(drop=True)


def _watch_parent(parent_pid: int) -> None:
    """Worker initializer: one numba thread; exit as soon as the sweep process is gone (module
    docstring)."""
    # numba's thread count is set here, in the worker, not in the parent's environment while the
    # pool starts: a parent that launched numba's threads in that window would keep 1 and refuse
    # the default later ("Cannot set NUMBA_NUM_THREADS ... once the threads have been launched")
    os.environ["NUMBA_NUM_THREADS"] = "1"
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)      # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:
        os._exit(1)

    def watch():
        while True:
            time.sleep(0.5)
            if os.getppid() != parent_pid:
                os._exit(1)
    threading.Thread(target=watch, name="gyroarray-parent-watch", daemon=True).start()


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


def _scenarios_to_run(sweep: Sweep, rows_dir: Path, records: dict, notes: list) -> list:
    """The scenarios without a rows file or whose file fails its check (noted), in sweep order."""
    todo = []
    for s in sweep.scenarios:
        f = rows_dir / f"{s.id}.parquet"
        if not f.exists():
            todo.append(s)
            continue
        why = verify_rows_file(f, records.get(f.name))
        if why is not None:
            notes.append(f"{f}: {why}; run again")
            todo.append(s)
    return todo


def _run_in_processes(todo: list, sweep: Sweep, workers: int, done) -> None:
    """Run ``todo`` on a local spawn process pool, reporting each result to ``done``."""
    ctx = mp.get_context("spawn")
    blas = {k: v for k, v in THREAD_ENV.items() if k != "NUMBA_NUM_THREADS"}
    with _env(blas), ProcessPoolExecutor(max_workers=min(workers, len(todo)),
                                         mp_context=ctx, initializer=_watch_parent,
                                         initargs=(os.getpid(),)) as pool:
        futures = {pool.submit(run_one, s, sweep.estimators, sweep.name): s for s in todo}
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(finished, key=lambda fu: futures[fu].id):
                exc = fut.exception()
                done(futures[fut], None if exc else fut.result(), exc)


def _run_on_dask(todo: list, sweep: Sweep, scheduler: str, done, notes: list) -> None:
    """Run ``todo`` on a dask.distributed cluster, reporting each result to ``done``."""
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
        for dfut in as_completed(list(futures), loop=client.loop):
            spec = futures[dfut]
            if dfut.status == "error":
                done(spec, err=dfut.exception())
            else:
                done(spec, dfut.result())
    finally:
        client.close()


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
    notes: list[str] = []
    records = _recorded_checksums(out)
    todo = _scenarios_to_run(sweep, rows_dir, records, notes)
    # longest first (a better finish on few workers); results do not depend on the order
    todo.sort(key=lambda s: (-_cost(s), s.id))
    skipped = len(sweep.scenarios) - len(todo)
    bar = _Progress(len(sweep.scenarios), skipped, progress)
    failed, rows_written = [], 0

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
        _run_in_processes(todo, sweep, workers, done)
    elif todo:
        backend = "dask"
        assert scheduler is not None                          # the process pool took the None case
        _run_on_dask(todo, sweep, scheduler, done, notes)
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
