"""Run a sweep in parallel into a resumable Parquet dataset.

:func:`run_sweep` runs every scenario of a sweep (:mod:`gyroarray.sweep.sweep`)
in worker processes — a local ``ProcessPoolExecutor`` (spawned workers), or a
``dask.distributed`` cluster when ``scheduler`` is its address
(``tcp://HOST:PORT``), or a ``LocalCluster`` it starts and closes itself
(``dask="local:N"``, :func:`local_cluster`) — and the worker that ran a scenario
writes its rows to ``out_dir/rows/<id>.parquet``: one row per estimator × body
axis (the chain's metric table) plus the scenario's parameters, id and seed.
Each file is written to a hidden temporary file and moved into place with
``os.replace``, so the dataset (``pandas.read_parquet(out_dir / "rows")`` or
:func:`load_results`) is always the set of complete scenarios. Only a small
record (file name, SHA-256, rows, run time) travels back; this process checks
the file against it and appends the checksum to ``rows.sha256``.

Tasks are sized for the engine (:class:`TaskBatches`): one scenario per task
until one has been timed, then as many as fit in :data:`TASK_TARGET_S`
seconds, fewer at the end so the tail spreads over every worker. Before the
scenarios, one task per distinct rate-table truth (profile, rate, duration)
fills the truth cache, so the physics of a profile runs once per machine.
Every worker warms once (:func:`warm_worker`: the imports, one numba thread).
A Dask worker lost mid-sweep costs only its tasks: Dask runs them again on
another worker (a task is retried :data:`TASK_RETRIES` times; a task that
killed its workers past ``distributed.scheduler.allowed-failures`` is split and
its scenarios run one per task, so only the culprit is reported failed). The
file a dying worker was writing is a hidden temporary, never a result; it is
removed when the sweep ends (its workers stopped and waited for, also on an
error or a SIGTERM) or, after a SIGKILL of the sweep, by the next run into the
folder (:func:`gyroarray.core.outputs.remove_stale_temps`).

Workers are budgets: ``workers`` and ``dask="local:N"`` are refused past
:data:`~gyroarray.core.parallel.MAX_WORKERS_PER_CPU` per CPU, and when the
workers (each an idle worker process,
:data:`~gyroarray.core.parallel.WORKER_BASELINE_BYTES`, plus the sweep's
largest scenario's working memory) need more than the memory budget
(``--max-memory``), before any work; a LocalCluster's workers are bounded at
run time by their share of the budget (:func:`local_cluster`).

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

import asyncio
import ctypes
import hashlib
import json
import logging
import math
import os
import re
import signal
import socket
import sys
import threading
import time
from collections import deque
from concurrent.futures import FIRST_COMPLETED, CancelledError, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import ExitStack, contextmanager
from pathlib import Path

import multiprocessing as mp

import pandas as pd
import pyarrow as pa

from gyroarray.core import outputs
from gyroarray.core.errors import InputError
from gyroarray.core.limits import open_regular, read_json, read_regular

from gyroarray.sweep.sweep import ScenarioSpec, Sweep, load_sweep

__all__ = ["run_sweep", "load_results", "run_one", "run_batch", "prepare_truth", "warm_worker",
           "verify_rows_file", "encode_rows", "local_cluster", "parse_dask", "TaskBatches",
           "THREAD_ENV", "TASK_TARGET_S"]

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
    from gyroarray.chain.run import run_scenario  # lazy: loads numba

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


def encode_rows(df) -> tuple[bytes, str]:
    """A scenario's rows as the bytes of its Parquet file and their SHA-256 (hex)."""
    import pyarrow.parquet as pq  # deferred: pyarrow.parquet loads only when rows are written

    sink = pa.BufferOutputStream()
    pq.write_table(pa.Table.from_pandas(df, preserve_index=False), sink)
    data = sink.getvalue().to_pybytes()
    return data, hashlib.sha256(data).hexdigest()


def write_rows(df, folder: Path, sid: str, inputs=()) -> Path:
    """Write a scenario's rows atomically and record the file's checksum beside the folder.

    Both go through :mod:`gyroarray.core.outputs`: the Parquet file is replaced
    atomically (a symbolic link at its name is replaced, never written
    through), the checksum line is appended with
    :func:`~gyroarray.core.outputs.append_line` (no symbolic link, no input of the
    command, no partial line on a full disk).
    """
    final = folder / f"{sid}.parquet"
    data, digest = encode_rows(df)
    outputs.write_bytes(final, data, force=True)      # a rerun replaces a corrupt file
    outputs.append_line(folder.parent / CHECKSUMS, f"{digest} {len(df)} {final.name}",
                        inputs=inputs, what="sweep checksum file (rows.sha256)")
    return final


# -- the worker's side: warm once, run a batch, write its files, return small records ----------

_WARM: dict = {}


def warm_worker() -> dict:
    """Make this worker process ready for scenarios, once: the imports and one numba thread.

    Loads the simulator, the estimators and the scorer (mujoco, numba, scipy;
    1-2 s on a fresh process) and pyarrow's Parquet writer, so that a worker
    pays them once and not in its first task's timing. Sets numba's thread
    count to 1 for the calling thread (a Dask worker started without
    ``NUMBA_NUM_THREADS=1`` would otherwise run a thread team per worker on
    every core). Returns the worker's thread variables (:data:`THREAD_ENV`).
    Idempotent; called by every task, so a worker that joins later (a restarted
    one) warms itself.
    """
    if not _WARM:
        # deferred on purpose: the heavy engine loads in the workers, never when the CLI parses
        import pyarrow.parquet  # noqa: F401
        import gyroarray.chain.run  # noqa: F401
        _WARM["pid"] = os.getpid()
    from gyroarray.core.jit import numba  # deferred: numba (loaded above already; a dict look-up)
    if numba.get_num_threads() != 1:
        numba.set_num_threads(1)      # per calling thread: the executor thread of a Dask worker
    return {k: os.environ.get(k) for k in THREAD_ENV}


def prepare_truth(spec: ScenarioSpec) -> str:
    """Compute (or read) a scenario's rate-table truth into the cache folder, in a worker.

    One such task per distinct (profile, rate, duration) runs before the
    scenarios, so the physics of a profile runs once on a machine and not in
    every worker that meets it first. Returns the cache key.
    """
    warm_worker()
    from gyroarray.sim.truth import compute_truth  # deferred: mujoco (warm_worker loaded it)

    sc = spec.build()
    return compute_truth(sc.profile, sc.sample_rate_hz, duration_s=sc.duration_s).meta.key


def one_line(err: BaseException) -> str:
    """``Type: message`` on one line (a scenario's failure as the summary lists it)."""
    return " ".join(f"{type(err).__name__}: {err}".split())


def run_batch(specs, estimators, sweep_name: str, rows_dir) -> list[dict]:
    """Run scenarios in a worker; each one's rows are written there, small records come back.

    Each scenario's Parquet file is written by the worker itself
    (``rows_dir/<id>.parquet``, atomically: a temporary file, then
    ``os.replace``), so the rows never travel through a Dask scheduler or a
    pipe; the caller checks the file's SHA-256 and appends it to
    ``rows.sha256``. A scenario that raises is recorded and the others go on.

    Returns
    -------
    list of dict
        Per scenario: ``id``, ``seconds`` (its run time in the worker [s]),
        ``cpu_seconds`` (the CPU time of the thread that ran it [s]),
        ``write_seconds`` (of which its Parquet file's encoding and writing
        [s]), ``started`` (its start, Unix time [s]), ``worker`` (``host:pid``)
        and either
        ``file``, ``sha256``, ``rows`` (written), ``error`` (it raised: one
        line), or ``write_error`` and ``file`` (its file could not be written).
    """
    warm_worker()
    folder = Path(rows_dir)
    out = []
    worker = f"{socket.gethostname()}:{os.getpid()}"
    for spec in specs:
        t0, c0, started = time.perf_counter(), time.thread_time(), time.time()
        try:
            df = run_one(spec, estimators, sweep_name)
        except Exception as err:          # noqa: BLE001 - a scenario's failure is reported, not fatal
            out.append({"id": spec.id, "error": one_line(err), "seconds": time.perf_counter() - t0,
                        "cpu_seconds": time.thread_time() - c0, "started": started,
                        "worker": worker})
            continue
        final = folder / f"{spec.id}.parquet"
        t_write = time.perf_counter()
        data, digest = encode_rows(df)
        try:
            outputs.write_bytes(final, data, force=True)      # a rerun replaces a corrupt file
        except InputError as err:
            out.append({"id": spec.id, "write_error": err.message, "file": str(final),
                        "seconds": time.perf_counter() - t0})
            break                          # a full disk: the caller stops the sweep
        t1 = time.perf_counter()
        out.append({"id": spec.id, "file": final.name, "sha256": digest, "rows": len(df),
                    "seconds": t1 - t0, "cpu_seconds": time.thread_time() - c0,
                    "write_seconds": t1 - t_write, "started": started, "worker": worker})
    return out


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open_regular(path, "sweep result file") as fh:     # never blocks on a FIFO
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _recorded_checksums(out: Path) -> dict:
    """File name -> (sha256, rows) from ``rows.sha256``; the last record of a name wins,
    a torn last line (a crash while appending) is ignored."""
    path = out / CHECKSUMS
    records: dict[str, tuple[str, int]] = {}
    if not (path.exists() or path.is_symlink()):
        return records
    # a regular file only (a FIFO is refused, never waited on), at most the size of a
    # 100,000-scenario record with room to spare
    text = read_regular(path, "sweep checksum file (rows.sha256)",
                        max_bytes=64 * 2**20).decode("utf-8", errors="replace")
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
    import pyarrow.parquet as pq  # deferred: pyarrow.parquet loads only when rows are read

    try:
        if path.stat().st_size == 0:
            return "the file is empty"
        if record is not None:
            return None if _sha256(path) == record[0] else "its checksum differs from the one recorded"
        rows = pq.ParquetFile(path).metadata.num_rows
    except OSError as err:
        return f"cannot be read ({err.strerror or err})"
    except InputError as err:  # not a regular file (open_regular)
        return err.message
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
    # a terminal's Ctrl-C reaches the whole process group: the sweep process answers it (one
    # line, exit 130, the pool stopped); a worker's own KeyboardInterrupt would print a traceback
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)      # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent_pid:
        os._exit(1)
    threading.Thread(target=_watch, args=(parent_pid,), name="gyroarray-parent-watch",
                     daemon=True).start()
    warm_worker()           # once per worker process: the imports before its first task


def _watch(parent_pid: int) -> None:
    """Poll the parent's pid twice a second; exit when the sweep process is gone."""
    while True:
        time.sleep(0.5)
        if os.getppid() != parent_pid:
            os._exit(1)


_RECORD_END = re.compile(r"[0-9a-f]{64} [0-9]+ [^ ]+\.parquet\r?$")
_TORN = re.compile(r"[0-9a-f]{0,64}(?: [0-9]*(?: [^ ]*)?)?\r?")


def _sweep_inputs(sweep: Sweep) -> list:
    """The files a sweep reads: the sweep file, its base scenario files and motion profiles."""
    files = {sweep.source} if sweep.source else set()
    for s in sweep.scenarios:
        if s.file:
            files.add(s.file)
        motion = s.data.get("motion")
        ref = motion.get("profile") if isinstance(motion, dict) else None
        if isinstance(ref, str) and (ref.endswith(".toml") or "/" in ref):
            here = s.data.get("_base_dir") or (Path(s.file).parent if s.file else Path("."))
            files.add(str(Path(here) / ref))
    return sorted(files)


def check_out(out: Path, inputs) -> None:
    """The output folder (created if needed, writable) and the files gyroarray keeps in it
    (``sweep.json``, ``rows.sha256``): regular files of this user, never a symbolic link,
    never an input of the command; ``rows.sha256`` must hold checksum lines only."""
    outputs.check_output_dir(out, what="--out")
    outputs.check_own_file(out / MANIFEST, inputs=inputs, what="sweep manifest (sweep.json)")
    path = outputs.check_own_file(out / CHECKSUMS, inputs=inputs,
                                  what="sweep checksum file (rows.sha256)")
    if path.exists():
        lines = read_regular(path, "sweep checksum file (rows.sha256)",
                             max_bytes=64 * 2**20).decode("utf-8", errors="replace").split("\n")
        for i, line in enumerate(lines):
            # a record, or a record torn by a crash (alone, or glued to the next record by
            # an older gyroarray): anything else is not ours
            if not (_RECORD_END.search(line) or _TORN.fullmatch(line)):
                raise InputError("not a gyroarray checksum file (lines of <sha256> <rows> "
                                 "<id>.parquet); gyroarray appends to it: move it away, or use "
                                 "a new --out folder", file=str(path), line=i + 1)


def _check_manifest(out: Path, sweep: Sweep) -> None:
    path = out / MANIFEST
    mine = sweep.manifest()
    if path.exists() or path.is_symlink():
        # a regular file, a JSON object, bounded in size and depth (else one line naming it)
        theirs = read_json(path, "sweep manifest")
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
    outputs.write_text(path, json.dumps(mine, indent=1), force=True)


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
    """The sweep's progress bar on stderr (tqdm): scenarios done of the sweep's, rate and time
    left; a scenario that fails is said on its own line as it is reported."""

    def __init__(self, total: int, done: int, enabled):
        from tqdm import tqdm  # deferred: only a sweep draws a bar
        on = sys.stderr.isatty() if enabled is None else bool(enabled)
        self.bar = tqdm(total=total, initial=done, disable=not on, file=sys.stderr,
                        desc="sweep", unit="scenario", dynamic_ncols=True, leave=True)

    def step(self, failed: str | None = None) -> None:
        if failed is not None and not self.bar.disable:
            self.bar.write(f"sweep: {failed}", file=sys.stderr)
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


def _cost(spec: ScenarioSpec) -> float:
    """Rough work of a scenario: samples × gyros (for scheduling only)."""
    return _cost_and_memory(spec)[0]


def _cost_and_memory(spec: ScenarioSpec) -> tuple[float, float]:
    """A scenario's work (:func:`_cost`) and its working memory in a worker [bytes]
    (:func:`gyroarray.sim.scenario.memory_needed` of its run: simulation and scoring), from one
    build."""
    from gyroarray.sim.scenario import memory_needed  # deferred: loaded by spec.build already
    sc = spec.build()
    duration = sc.duration_s if sc.duration_s is not None else sc.profile.duration_s
    return duration * sc.sample_rate_hz * sc.layout.n_gyros, memory_needed(sc, "run")


def _check_workers_fit(todo: list, sized: dict, workers: int, n_local: int | None,
                       scheduler: str | None) -> int | None:
    """Refuse, before any worker starts, local workers whose memory passes the budget
    (:func:`gyroarray.core.parallel.check_workers_memory`: each an idle worker plus the largest
    scenario's working memory); returns a Dask worker's share of the budget [bytes] (None:
    nothing starts here, or a remote cluster, whose memory is its own)."""
    if not todo or scheduler is not None:
        return None
    from gyroarray.core.parallel import (DASK_WORKER_EXTRA_BYTES, WORKER_BASELINE_BYTES,
                                         check_workers_memory)  # deferred: a light module
    work = max(v[1] for v in sized.values())
    if n_local is not None:         # a LocalCluster starts all N, whatever is left to run
        return check_workers_memory(n_local, work, "--dask", "local:{n}",
                                    baseline_bytes=WORKER_BASELINE_BYTES + DASK_WORKER_EXTRA_BYTES)
    check_workers_memory(min(workers, len(todo)), work, "--workers",
                         baseline_bytes=WORKER_BASELINE_BYTES, asked=workers)
    return None


#: Longest wait for the Dask scheduler to answer, name lookup included [s].
SCHEDULER_TIMEOUT_S = 10.0
#: Address schemes of dask.distributed that reach another process (``inproc://`` lives inside
#: one Python process; ``ucx://`` needs the separate distributed-ucxx package).
SCHEDULER_SCHEMES = ("tcp", "tls", "ws", "wss")
_HOST_RE = re.compile(r"[A-Za-z0-9_](?:[A-Za-z0-9_.-]{0,252}[A-Za-z0-9_])?|\[[0-9A-Fa-f:.]{2,45}\]")


def parse_scheduler(address) -> tuple[str, str, int]:
    """``(scheme, host, port)`` of a Dask scheduler address, refused up front when malformed.

    Accepted: ``SCHEME://HOST:PORT`` with a scheme of :data:`SCHEDULER_SCHEMES`, or
    ``HOST:PORT`` (tcp, as dask.distributed reads it); HOST a name, an IPv4 address or a
    bracketed IPv6 address; PORT a whole number 1..65535.

    Raises
    ------
    InputError
        One line naming ``--scheduler``, what is wrong and the expected form.
    """
    text = str(address)
    form = "give tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786 (what `dask scheduler` prints)"
    shown = text if len(text) <= 80 and text.isprintable() else repr(text[:80]) + "..."
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    scheme = scheme.lower()
    if scheme == "inproc":
        raise InputError(f"--scheduler {shown}: an inproc:// address lives only inside one Python "
                         f"process; {form}")
    if scheme not in SCHEDULER_SCHEMES:
        raise InputError(f"--scheduler {shown}: the scheme {scheme}:// is not supported (use one of "
                         f"{', '.join(s + '://' for s in SCHEDULER_SCHEMES)}); {form}")
    host, colon, port = rest.rpartition(":")
    if not colon or not _HOST_RE.fullmatch(host):
        raise InputError(f"--scheduler {shown}: not a scheduler address (HOST:PORT expected); {form}")
    if not (port.isascii() and port.isdigit() and 1 <= int(port) <= 65535):
        raise InputError(f"--scheduler {shown}: the port must be a whole number from 1 to 65535, "
                         f"got {port!r}; {form}")
    return scheme, host.strip("[]"), int(port)


def _probe_scheduler(scheduler: str, host: str, port: int, timeout: float) -> None:
    """Refuse a scheduler whose host does not resolve or whose port does not accept a
    connection, within ``timeout`` seconds in all (name lookup included: it runs on a thread)."""
    outcome: list = []

    def probe():
        try:
            socket.create_connection((host, port), timeout=timeout).close()
            outcome.append(None)
        except OSError as err:
            outcome.append(err.strerror or str(err) or type(err).__name__)

    t = threading.Thread(target=probe, name="gyroarray-scheduler-probe", daemon=True)
    t.start()
    t.join(timeout)
    why = outcome[0] if outcome else "no answer"
    if why is not None:
        raise InputError(f"--scheduler: cannot reach the Dask scheduler at {scheduler}: {why} (waited at most "
                         f"{timeout:g} s); check the address, or start one with `dask scheduler`")


def _ask_identity(scheduler: str, timeout: float) -> None:
    """Refuse a port that accepts connections but does not answer Dask's ``identity`` as a
    scheduler within ``timeout`` seconds (``distributed.Client`` waits for ever on a silent one)."""
    # deferred: dask.distributed is optional (only for --scheduler) and slow to import
    from distributed.comm import connect
    from distributed.security import Security

    async def ask():
        comm = await connect(scheduler, timeout=timeout, **Security().get_connection_args("client"))
        try:
            await comm.write({"op": "identity", "reply": True})
            return await comm.read()
        finally:
            comm.abort()

    try:
        answer = asyncio.run(asyncio.wait_for(ask(), timeout))
    except (asyncio.TimeoutError, TimeoutError):
        why = "no answer to the Dask handshake"
    except OSError as err:
        why = " ".join(str(err).split()) or type(err).__name__
    except Exception as err:      # noqa: BLE001 - what the other end sent is not Dask's protocol
        why = (f"it answered, but not as a Dask scheduler ({type(err).__name__}: "
               f"{' '.join(str(err).split())[:160]})")
    else:
        if isinstance(answer, dict) and answer.get("type") == "Scheduler":
            return
        why = f"it answered, but not as a Dask scheduler (a {type(answer).__name__})"
    raise InputError(f"--scheduler: cannot reach the Dask scheduler at {scheduler}: {why} (waited at most "
                     f"{timeout:g} s); check the address and that a Dask scheduler of a compatible "
                     "version runs there")


def _dask_client(scheduler: str):
    """A ``distributed.Client`` on ``scheduler``, or a one-line refusal within
    :data:`SCHEDULER_TIMEOUT_S` (twice that at most: the probe, then the handshake)."""
    _, host, port = parse_scheduler(scheduler)
    try:
        from distributed import Client  # deferred: optional dask.distributed, only for --scheduler
    except ImportError:
        raise InputError("a scheduler address needs dask[distributed] installed") from None
    _probe_scheduler(scheduler, host, port, SCHEDULER_TIMEOUT_S)
    _ask_identity(scheduler, SCHEDULER_TIMEOUT_S)

    class _Client(Client):
        """A Client whose failed start does not wait again (and print a traceback) when the
        half-built object is collected at exit."""

        def __init__(self, *args, **kwargs):
            try:
                super().__init__(*args, **kwargs)
            except BaseException:
                try:
                    self.close(timeout=2)
                except Exception:                         # noqa: BLE001 - it never started
                    pass
                self.status = "closed"                    # __del__ then closes nothing
                raise

    try:
        return _Client(scheduler, timeout=f"{SCHEDULER_TIMEOUT_S:g}s", set_as_default=False)
    except (OSError, TimeoutError) as err:
        why = " ".join(str(err).split()) or type(err).__name__
    except Exception as err:      # noqa: BLE001 - the other end answered, but not as Dask
        why = (f"it answered, but not as a Dask scheduler ({type(err).__name__}: "
               f"{' '.join(str(err).split())[:160]})")
    raise InputError(f"--scheduler: cannot reach the Dask scheduler at {scheduler}: {why} (waited at most "
                     f"{SCHEDULER_TIMEOUT_S:g} s); check the address and that a Dask scheduler of "
                     "a compatible version runs there")


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


#: Target run time of one task (a batch of scenarios) [s]: long beside a task's own cost (a
#: round trip through the scheduler, a few ms), short beside a sweep (the tail stays balanced).
TASK_TARGET_S = 5.0
#: Times Dask reruns a task that raised (a lost worker's task is rescheduled besides, up to
#: ``distributed.scheduler.allowed-failures``).
TASK_RETRIES = 2


class TaskBatches:
    """The scenarios to run, grouped into tasks of about ``target_s`` seconds each.

    Until one scenario has been timed, a task holds one scenario. From then on
    the measured time per unit of work (samples × gyros, :func:`_cost`) gives
    each next task as many scenarios (in queue order: longest first) as fit in
    ``target_s``, and at most ``ceil(left / (2 slots))`` so that the last tasks
    still spread over every worker. The scenarios of a task that failed as a
    whole (its worker died past Dask's retries) come back one per task
    (``isolated``), so that only the scenario that kills its worker is lost.

    Parameters
    ----------
    todo : list of ScenarioSpec
        In the order to run them.
    slots : int
        Worker threads of the pool or cluster.
    costs : dict
        Scenario id -> work (samples × gyros).
    target_s : float
        Target run time of a task [s].
    """

    def __init__(self, todo, slots: int, costs: dict, target_s: float = TASK_TARGET_S):
        self.queue = deque(todo)
        self.slots = max(1, int(slots))
        self.costs = costs
        self.target_s = float(target_s)
        self.retry: deque = deque()
        self.spent_s = 0.0
        self.spent_cost = 0.0

    def measured(self, sid: str, seconds: float) -> None:
        """Count a scenario's measured run time [s] in the time per unit of work."""
        self.spent_s += float(seconds)
        self.spent_cost += float(self.costs.get(sid, 0.0))

    def split(self, specs) -> None:
        """Run these scenarios again, one per task."""
        self.retry.extend(specs)

    def take(self):
        """The next task: ``(scenarios, isolated)``, or None when nothing is left."""
        if self.retry:
            return [self.retry.popleft()], True
        if not self.queue:
            return None
        batch = [self.queue.popleft()]
        if self.spent_cost > 0:
            rate = self.spent_s / self.spent_cost
            cap = max(1, math.ceil((len(self.queue) + 1) / (2 * self.slots)))
            est = rate * self.costs.get(batch[0].id, 0.0)
            while (self.queue and len(batch) < cap
                   and est + rate * self.costs.get(self.queue[0].id, 0.0) <= self.target_s):
                spec = self.queue.popleft()
                batch.append(spec)
                est += rate * self.costs.get(spec.id, 0.0)
        return batch, False


def _truth_group(spec: ScenarioSpec) -> tuple:
    sc = spec.build()
    return (sc.profile.fingerprint, float(sc.sample_rate_hz), sc.duration_s)


class _Processes:
    """The local process pool as the dispatcher sees it.

    A worker that dies (a native abort, the kernel's out-of-memory killer, a
    signal) breaks a ``ProcessPoolExecutor`` as a whole: every task in flight
    fails with ``BrokenProcessPool``, whichever worker died. The pool is then
    started again (:meth:`submit`), and the dispatcher runs the scenarios of
    those tasks again one at a time with nothing else in flight
    (``serial_retry``), so that a scenario that kills its worker again is the
    only one reported lost.
    """

    retry_lost = True
    serial_retry = True
    #: Most times the pool is started again in one sweep, and in a row without a task that
    #: finished in between (a pool that cannot start, a machine that kills every worker): then
    #: the tasks fail, each scenario reported, instead of starting workers forever.
    MAX_RESTARTS = 32
    MAX_FRUITLESS = 3

    def __init__(self, start):
        self.start = start
        self.pool = start()
        self.restarts = 0
        self.fruitless = 0

    def submit(self, fn, *args):
        try:
            return self.pool.submit(fn, *args)
        except BrokenProcessPool as err:           # a worker died: a fresh pool for what is left
            if self.restarts >= self.MAX_RESTARTS or self.fruitless >= self.MAX_FRUITLESS:
                fut: Future = Future()
                fut.set_exception(err)
                return fut
            self.restarts += 1
            self.fruitless += 1
            _stop_pool(self.pool)
            self.pool = self.start()
            return self.pool.submit(fn, *args)

    def wait_any(self, pending):
        finished, _ = wait(pending, return_when=FIRST_COMPLETED)
        out = [(f, f.exception()) for f in sorted(finished, key=id)]
        if any(exc is None for _, exc in out):
            self.fruitless = 0
        return out

    @staticmethod
    def result(fut):
        return fut.result()

    def close(self):
        _stop_pool(self.pool)


def _stop_pool(pool, grace_s: float = 10.0) -> None:
    """Shut a process pool down now: queued tasks cancelled, its workers terminated and waited
    for (killed after ``grace_s`` seconds), so that the files they were writing are those of
    dead processes when the caller clears them (:func:`gyroarray.core.outputs.remove_stale_temps`)."""
    procs = dict(getattr(pool, "_processes", None) or {})   # before shutdown clears it
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs.values():
        try:
            proc.terminate()
        except (OSError, AttributeError, ValueError):
            pass
    end = time.monotonic() + grace_s
    for proc in procs.values():
        try:
            proc.join(max(0.0, end - time.monotonic()))
            if proc.exitcode is None:
                proc.kill()
                proc.join(1.0)
        except (OSError, AttributeError, ValueError, AssertionError):
            pass


class _Dask:
    """A dask.distributed client as the dispatcher sees it (lost workers' tasks run elsewhere)."""

    retry_lost = True
    serial_retry = False          # a lost worker costs only its own tasks: Dask reruns them

    def __init__(self, client, gone):
        # deferred: dask.distributed is optional (only for --scheduler/--dask) and slow to import
        from distributed import as_completed
        from distributed.comm.core import CommClosedError
        self.client, self.gone = client, gone
        self.finished = as_completed(loop=client.loop)      # every submitted task, as it ends
        self.lost = (CancelledError, CommClosedError, TimeoutError)
        self.count = 0
        self.token = os.urandom(4).hex()     # keys of this run only (a shared scheduler)

    def submit(self, fn, *args):
        self.count += 1
        first = getattr(args[0], "id", None) or getattr((args[0] or [None])[0], "id", "task")
        try:
            fut = self.client.submit(fn, *args, key=f"gyroarray-{fn.__name__}-{self.token}-{self.count}-{first}",
                                     pure=False, retries=TASK_RETRIES)
        except self.lost as exc:
            raise self.gone(exc) from None
        self.finished.add(fut)
        return fut

    def wait_any(self, pending):
        try:
            finished = [next(self.finished)] + self.finished.next_batch(block=False)
            out = []
            for f in finished:
                if f.cancelled():
                    raise CancelledError(f"task {f.key} was cancelled (the scheduler restarted?)")
                out.append((f, f.exception() if f.status == "error" else None))
            return out
        except self.lost as exc:
            raise self.gone(exc) from None

    def result(self, fut):
        try:
            return fut.result()
        except self.lost as exc:
            raise self.gone(exc) from None


def _dispatch(backend, slots: int, todo: list, sweep: Sweep, rows_dir: Path, costs: dict,
              record, lost, stamp=lambda name: None) -> None:
    """Run ``todo`` on ``backend``: the truths first (one task per distinct truth), then the
    scenarios in batches (:class:`TaskBatches`), at most two tasks per slot in flight; each
    scenario's record goes to ``record``, a scenario whose task failed as a whole to ``lost``."""
    firsts: dict = {}
    for spec in todo:
        try:
            firsts.setdefault(_truth_group(spec), spec)
        except Exception:                  # noqa: BLE001 - the scenario itself will report it
            pass
    pending: dict = {backend.submit(prepare_truth, spec): None for spec in firsts.values()}
    while pending:
        for fut, _exc in backend.wait_any(pending):  # a failed truth: its scenarios report it
            pending.pop(fut)
    stamp("truth")
    batches = TaskBatches(todo, slots, costs)

    def fill():
        while len(pending) < 2 * max(1, slots):
            if backend.serial_retry and pending and (
                    batches.retry or any(task[1] for task in pending.values() if task)):
                return                      # suspects of a broken pool: one at a time, alone
            nxt = batches.take()
            if nxt is None:
                return
            pending[backend.submit(run_batch, nxt[0], sweep.estimators, sweep.name,
                                   str(rows_dir))] = nxt

    fill()
    while pending:
        for fut, exc in backend.wait_any(pending):
            specs, isolated = pending.pop(fut)
            if exc is None:
                for rec in sorted(backend.result(fut), key=lambda r: r["id"]):
                    batches.measured(rec["id"], rec["seconds"])
                    record(rec)
            elif backend.retry_lost and not isolated and (
                    len(specs) > 1 or backend.serial_retry):
                batches.split(specs)        # run again one by one: only the culprit is lost
            else:
                for spec in specs:
                    lost(spec, exc)
        fill()
    stamp("scenarios")


def _run_in_processes(todo: list, sweep: Sweep, workers: int, rows_dir: Path, costs: dict,
                      record, lost, notes: list, stamp) -> None:
    """Run ``todo`` on a local spawn process pool (:func:`_dispatch`); a worker that died and
    the pool's restarts are said in ``notes``."""
    ctx = mp.get_context("spawn")
    blas = {k: v for k, v in THREAD_ENV.items() if k != "NUMBA_NUM_THREADS"}
    n = min(workers, len(todo))

    def start():
        return ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_watch_parent,
                                   initargs=(os.getpid(),))

    with _env(blas):                # the workers start at the first submit (and at a restart)
        backend = _Processes(start)
        try:
            _dispatch(backend, n, todo, sweep, rows_dir, costs, record, lost, stamp)
        finally:
            # also on a result that cannot be recorded (a full disk) or an interrupt: stop now,
            # do not run the rest first (a rerun resumes; a file being written is a hidden
            # temporary)
            backend.close()
            if backend.restarts:
                notes.append(f"a worker process died {backend.restarts} time(s) (killed, out of "
                             "memory or a native abort): the pool started again and the scenarios "
                             "it was running ran again one at a time")


#: Most worker processes ``--dask local:N`` starts.
MAX_LOCAL_WORKERS = 1024


def parse_dask(text) -> int:
    """The worker count N of a ``--dask local:N`` request, refused up front when malformed.

    Raises
    ------
    InputError
        One line naming ``--dask``, what is wrong and the expected form.
    """
    t = str(text)
    shown = t if len(t) <= 80 and t.isprintable() else repr(t[:80]) + "..."
    form = ("give local:N (a Dask LocalCluster of N single-thread worker processes on this "
            "machine, e.g. local:4); for a running cluster use --scheduler tcp://HOST:PORT")
    kind, sep, n = t.partition(":")
    if kind.strip().lower() != "local" or not sep:
        raise InputError(f"--dask {shown}: not a cluster gyroarray can start; {form}")
    n = n.strip()
    if not (n.isascii() and n.isdigit() and 1 <= int(n) <= MAX_LOCAL_WORKERS):
        raise InputError(f"--dask {shown}: N must be a whole number from 1 to "
                         f"{MAX_LOCAL_WORKERS}, got {n!r}; {form}")
    return int(n)


@contextmanager
def local_cluster(n_workers: int, memory_limit: int | None = None):
    """A dask.distributed ``LocalCluster`` of ``n_workers`` single-thread worker processes,
    set up as the local process pool's workers are (:data:`THREAD_ENV`), closed on exit.

    ``memory_limit`` [bytes]: each worker's bound (the memory budget over the workers,
    :func:`run_sweep`); a worker whose memory passes it is ended by its nanny and its task runs
    again (then is reported lost, :data:`TASK_RETRIES`). Dask's pausing and spilling are off: a
    worker holds no results (they are on disk), and one paused near its bound would wait for
    ever. None: Dask's default (the machine's memory over the workers).

    The BLAS/OpenMP variables reach the workers through
    ``distributed.nanny.pre-spawn-environ`` (set in this process while the
    cluster lives, then restored), ``NUMBA_NUM_THREADS=1`` through the
    workers' own environment (never this process's: numba here keeps its
    default), the workers' statistical profiler is off (it samples the
    running task's stack every 10 ms) and the event loops' health check runs
    once a second instead of every 20 ms. On exit the workers are ended at
    once (:func:`_stop_workers`).

    Raises
    ------
    InputError
        The cluster did not start (one line, with the way out).
    """
    try:
        import dask  # deferred: dask.distributed is optional (only for --dask) and slow to import
        from distributed import LocalCluster  # deferred: as dask, just above
    except ImportError:
        raise InputError("--dask needs dask[distributed] installed (pip install "
                         "'gyroarray[dask]'), or use --workers N") from None
    blas = {k: v for k, v in THREAD_ENV.items() if k != "NUMBA_NUM_THREADS"}
    config = {"distributed.nanny.pre-spawn-environ": blas,
              "distributed.worker.profile.enabled": False,
              # the event loops' health check wakes every loop (scheduler, nannies, workers)
              # each 20 ms by default: 0.6 s of CPU per 10 s here and 0.2 s per worker, idle
              # (measured), taken from the scenarios when every core runs one; once a second
              # it costs a tenth of that and still warns of a loop blocked 3 s
              "distributed.admin.tick.interval": "1s"}
    if memory_limit is not None:
        config.update({"distributed.worker.memory.target": False,
                       "distributed.worker.memory.spill": False,
                       "distributed.worker.memory.pause": False,
                       "distributed.worker.memory.terminate": 1.0})
    with _env(blas), dask.config.set(config):
        try:
            cluster = LocalCluster(n_workers=int(n_workers), threads_per_worker=1, processes=True,
                                   # its HTTP routes on a free local port: never a warning
                                   # that another cluster holds Dask's default 8787
                                   dashboard_address="127.0.0.1:0", silence_logs=logging.CRITICAL,
                                   env={"NUMBA_NUM_THREADS": "1"},
                                   memory_limit="auto" if memory_limit is None else int(memory_limit))
        except Exception as err:                  # noqa: BLE001 - any start failure, in one line
            raise InputError(f"--dask local:{n_workers}: the local Dask cluster did not start "
                             f"({one_line(err)[:200]}); use --workers {n_workers} (local "
                             "processes) instead") from None
        try:
            yield cluster
        finally:
            _wait_gone(_stop_workers(cluster))
            try:
                cluster.close(timeout=10)
            except Exception:                      # noqa: BLE001 - closing what is already gone
                pass


def _stop_workers(cluster) -> list[int]:
    """End a LocalCluster's worker processes at once, before the cluster closes.

    A worker asked to close exits its interpreter in full (the engine's modules torn
    down: 0.5 s, measured, per worker and in series with the sweep's end). Every
    result is on disk (written atomically) and recorded by then, so the nannies are
    told not to restart their workers and the processes are killed, as the local
    process pool's are (:func:`_stop_pool`). Returns the pids killed.
    """
    pids = []
    for nanny in list(getattr(cluster, "workers", {}).values()):
        try:
            nanny.close_gracefully(reason="gyroarray-sweep-done")   # no restart of its worker
            proc = nanny.process.process
            if proc is not None and proc.pid:
                os.kill(proc.pid, signal.SIGKILL)
                pids.append(proc.pid)
        except (AttributeError, OSError, ProcessLookupError):       # not started, already gone
            pass
    return pids


def _wait_gone(pids, timeout_s: float = 10.0) -> None:
    """Wait (polled, at most ``timeout_s``) until the processes ``pids`` no longer run (a zombie
    counts as gone), so that their temporary files can be told from a live writer's."""
    end = time.monotonic() + timeout_s
    left = [int(p) for p in pids]
    while left and time.monotonic() < end:
        left = [p for p in left if not outputs.pid_gone(p)]
        if left:
            time.sleep(0.02)


def _run_on_dask(todo: list, sweep: Sweep, scheduler: str | None, n_local: int | None,
                 rows_dir: Path, costs: dict, record, lost, notes: list, stamp,
                 memory_limit: int | None = None) -> None:
    """Run ``todo`` on a dask.distributed cluster (``scheduler``) or on a LocalCluster of
    ``n_local`` workers started here (:func:`_dispatch`), each bounded to ``memory_limit``
    bytes (:func:`local_cluster`)."""
    # deferred: dask.distributed is optional (only for --scheduler/--dask) and slow to import
    from distributed.comm.core import CommClosedError
    lost_conn = (CancelledError, CommClosedError, TimeoutError)
    where = f"the Dask scheduler at {scheduler}" if scheduler else f"the local Dask cluster (local:{n_local})"

    def gone(err) -> InputError:
        return InputError(f"{'--scheduler' if scheduler else '--dask'}: lost the connection to "
                          f"{where} ({type(err).__name__}: {' '.join(str(err).split())[:160]}); the "
                          "scenarios finished so far are kept: run the same command again to resume")

    log = logging.getLogger("distributed")
    level = log.level
    log.setLevel(logging.CRITICAL)        # its reconnection errors: stderr carries one line at most
    client = None
    try:
        with ExitStack() as stack:
            if scheduler is None:
                from distributed import Client  # deferred: optional dask.distributed
                cluster = stack.enter_context(local_cluster(n_local or 1, memory_limit=memory_limit))
                client = Client(cluster, set_as_default=False)
            else:
                client = _dask_client(scheduler)
            stamp("cluster")
            try:
                # every worker warms once (imports, numba) and says its thread variables
                envs = client.run(warm_worker)
                slots = sum(client.nthreads().values()) or 1
                stamp("warm")
            except lost_conn as exc:
                raise gone(exc) from None
            except Exception as err:              # noqa: BLE001 - a worker without gyroarray
                raise InputError(f"the Dask workers cannot run gyroarray ({one_line(err)[:200]}): "
                                 "install the same gyroarray on every worker") from None
            off = sorted(w for w, e in envs.items() if e.get("OPENBLAS_NUM_THREADS") != "1")
            if off:
                notes.append(f"{len(off)} Dask worker(s) without OPENBLAS_NUM_THREADS=1: results "
                             "may differ in the last bits from a local run")
            try:
                _dispatch(_Dask(client, gone), slots, todo, sweep, rows_dir, costs, record, lost,
                          stamp)
            finally:
                try:
                    client.close(timeout=5)
                except Exception:                      # noqa: BLE001 - a scheduler already gone
                    pass
    finally:
        log.setLevel(level)


def sweep_profile(stamps: dict, runs: list) -> dict:
    """Where a sweep's wall time went, from the runner's phase marks and the scenarios' runs.

    Parameters
    ----------
    stamps : dict
        Phase name -> its end, seconds after the sweep started: ``prepare`` (the
        sweep expanded, the folder checked, the finished scenarios verified),
        ``cluster`` and ``warm`` (Dask: connected or started; every worker warm),
        ``truth`` (the truth tasks done), ``scenarios`` (the last result
        recorded), ``closed`` (the pool or cluster closed).
    runs : list of (worker, start [s after the sweep started], seconds, CPU seconds,
    write seconds)
        Each scenario's run in its worker.

    Returns
    -------
    dict
        ``phases_s`` (each phase's duration [s], in order), ``first_scenario_s``
        (the first scenario's start [s]: start-up and truth before it),
        ``busy_s`` (the scenarios' run times summed [s]), ``cpu_s`` (the CPU
        time their threads got, summed [s]: below ``busy_s`` when the workers
        waited for a core, e.g. more workers than cores, or a shared machine),
        ``write_s`` (of ``busy_s``: the Parquet files encoded and written [s]),
        ``between_s`` (summed over workers, the time between a worker's first
        start and last end in which it ran no scenario: its tasks' round trips
        [s]), ``workers`` (per worker: the same, ``first_start_s``,
        ``last_end_s``, ``scenarios``) and
        ``tail_s`` (the last result minus the earliest worker's last end [s]: the
        time some worker had nothing left to run). Clock offsets between
        machines enter ``first_start_s`` and ``last_end_s`` on a remote cluster.
    """
    order = ["prepare", "cluster", "warm", "truth", "scenarios", "closed"]
    phases, last = {}, 0.0
    for name in order:
        if name in stamps:
            phases[name] = round(stamps[name] - last, 3)
            last = stamps[name]
    per: dict = {}
    for worker, start, seconds, cpu, write in runs:
        w = per.setdefault(str(worker), {"busy_s": 0.0, "cpu_s": 0.0, "write_s": 0.0,
                                         "first_start_s": math.inf, "last_end_s": -math.inf,
                                         "scenarios": 0})
        w["busy_s"] += seconds
        w["cpu_s"] += cpu if math.isfinite(cpu) else seconds
        w["write_s"] += write
        w["first_start_s"] = min(w["first_start_s"], start)
        w["last_end_s"] = max(w["last_end_s"], start + seconds)
        w["scenarios"] += 1
    for w in per.values():
        # between its first start and last end, the time the worker ran no scenario: the
        # round trips of its tasks (scheduling, serialisation, the records sent back)
        w["between_s"] = w["last_end_s"] - w["first_start_s"] - w["busy_s"]
        for k in ("busy_s", "cpu_s", "write_s", "between_s", "first_start_s", "last_end_s"):
            w[k] = round(w[k], 3)
    end = stamps.get("scenarios")
    return {"phases_s": phases,
            "first_scenario_s": min((w["first_start_s"] for w in per.values()), default=None),
            "busy_s": round(sum(w["busy_s"] for w in per.values()), 3),
            "cpu_s": round(sum(w["cpu_s"] for w in per.values()), 3),
            "write_s": round(sum(w["write_s"] for w in per.values()), 3),
            "between_s": round(sum(w["between_s"] for w in per.values()), 3),
            "workers": per,
            "tail_s": round(end - min(w["last_end_s"] for w in per.values()), 3)
            if per and end is not None else None}


def run_sweep(sweep, out_dir, *, workers: int = 1, scheduler: str | None = None,
              dask: str | None = None, progress=None) -> dict:
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
    dask : str, optional
        ``"local:N"``: start a Dask ``LocalCluster`` of N single-thread worker
        processes (:func:`local_cluster`), run there, close it after.
    progress : bool or None
        Progress bar on stderr; None: when stderr is a terminal.

    Returns
    -------
    dict
        ``sweep``, ``out_dir``, ``dataset``, ``scenarios``, ``ran``, ``skipped``,
        ``failed`` (list of {id, error}), ``complete``, ``rows_written``,
        ``seconds``, ``worker_seconds`` (the scenarios' run times in their
        workers, summed [s]), ``workers``, ``scheduler``, ``dask``, ``backend``,
        ``notes``, ``excluded`` (grid combinations left out by ``skip_invalid``:
        {id, reason}), ``profile`` (where the wall time went: :func:`sweep_profile`).
    """
    t0, t0_unix = time.perf_counter(), time.time()
    stamps: dict = {}

    def stamp(name: str) -> None:
        stamps[name] = time.perf_counter() - t0

    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers must be an integer >= 1, got {workers!r}")
    if scheduler is not None and dask is not None:
        raise InputError("--scheduler and --dask exclude each other: give one cluster")
    if scheduler is not None:
        parse_scheduler(scheduler)                          # a malformed address: refused before work
    n_local = parse_dask(dask) if dask is not None else None
    # deferred: the machine's cores and the workers' memory (a light module)
    from gyroarray.core.parallel import check_worker_count
    if n_local is not None:                     # this machine's cores: refused before any work
        check_worker_count(n_local, "--dask", "local:{n}")
    elif scheduler is None:
        check_worker_count(workers, "--workers")
    out = Path(out_dir)
    # the folder and the files gyroarray keeps there, before the (possibly long) expansion
    if out.exists() or out.is_symlink():
        check_out(out, [sweep.source if isinstance(sweep, Sweep) else sweep])
    if not isinstance(sweep, Sweep):
        sweep = load_sweep(sweep)
    inputs = _sweep_inputs(sweep)
    # the workers' memory against the budget, before the folder is made or written: each worker
    # may meet the sweep's largest scenario
    sized = {s.id: _cost_and_memory(s) for s in sweep.scenarios}
    memory_limit = _check_workers_fit(sweep.scenarios, sized, workers, n_local, scheduler)
    check_out(out, inputs)
    outputs.check_output_dir(out / ROWS, what="--out")
    _check_manifest(out, sweep)
    rows_dir = out / ROWS
    outputs.remove_stale_temps(rows_dir)      # what workers of a SIGKILLed sweep were writing
    notes: list[str] = []
    records = _recorded_checksums(out)
    todo = _scenarios_to_run(sweep, rows_dir, records, notes)
    # longest first (a better finish on few workers); results do not depend on the order
    costs = {s.id: sized[s.id][0] for s in todo}
    todo.sort(key=lambda s: (-costs[s.id], s.id))
    skipped = len(sweep.scenarios) - len(todo)
    bar = _Progress(len(sweep.scenarios), skipped, progress)
    failed, rows_written, busy = [], 0, [0.0]
    runs: list = []                 # (worker, start, seconds) of each scenario [s from t0]
    stamp("prepare")

    def record(rec: dict) -> None:
        """A scenario's record from its worker: its file checked here and its checksum kept."""
        nonlocal rows_written
        busy[0] += rec.get("seconds", 0.0)
        if "started" in rec:
            runs.append((rec.get("worker"), rec["started"] - t0_unix, rec.get("seconds", 0.0),
                         rec.get("cpu_seconds", math.nan), rec.get("write_seconds", 0.0)))
        if "write_error" in rec:                  # a full disk: stop (a rerun resumes)
            raise InputError(rec["write_error"], file=rec["file"])
        if "error" in rec:
            fail(rec["id"], rec["error"])
            return
        path = rows_dir / rec["file"]
        if not (path.exists() or path.is_symlink()):
            raise InputError(f"a worker wrote {rec['file']} but it is not in this folder: --out "
                             "must be a folder every Dask worker and this machine share (a "
                             "network file system), or run with --workers N", file=str(rows_dir))
        try:
            same = _sha256(path) == rec["sha256"]
        except (OSError, InputError):
            same = False
        if not same:                          # changed since its worker wrote it: not kept
            fail(rec["id"], "its file differs from what its worker wrote; run the same command "
                 "again to redo it")
            return
        outputs.append_line(out / CHECKSUMS, f"{rec['sha256']} {rec['rows']} {path.name}",
                            inputs=inputs, what="sweep checksum file (rows.sha256)")
        rows_written += rec["rows"]
        bar.step()

    def fail(sid: str, error: str) -> None:
        failed.append({"id": sid, "error": error})
        bar.step(f"{sid} failed: {error}")

    def lost(spec: ScenarioSpec, err: BaseException) -> None:
        """A scenario whose task failed as a whole (its worker died, the pool broke)."""
        fail(spec.id, f"its task failed: {one_line(err)}")

    try:
        if todo and scheduler is None and n_local is None:
            backend = "processes"
            _run_in_processes(todo, sweep, workers, rows_dir, costs, record, lost, notes, stamp)
        elif todo:
            backend = "dask"
            _run_on_dask(todo, sweep, scheduler, n_local, rows_dir, costs, record, lost, notes,
                         stamp, memory_limit=memory_limit)
        else:
            backend = "none (all done)"
    finally:
        bar.close()
        # the workers are stopped by now (also on an error or a SIGTERM): the files they were
        # writing when they were ended are hidden temporaries of dead processes, removed here
        outputs.remove_stale_temps(rows_dir)
    stamp("closed")
    complete = not failed and all((rows_dir / f"{s.id}.parquet").exists() for s in sweep.scenarios)
    return {"sweep": sweep.name, "out_dir": str(out), "dataset": str(rows_dir),
            "scenarios": len(sweep.scenarios), "ran": len(todo) - len(failed), "skipped": skipped,
            "failed": failed, "complete": complete, "rows_written": rows_written,
            "seconds": time.perf_counter() - t0, "worker_seconds": busy[0],
            "workers": n_local if n_local else (None if scheduler else workers),
            "scheduler": scheduler, "dask": dask, "backend": backend, "notes": notes,
            "profile": sweep_profile(stamps, runs),
            "excluded": [{"id": i, "reason": r} for i, r in sweep.excluded]}
