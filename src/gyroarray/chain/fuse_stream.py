"""``gyroarray fuse`` on a record longer than memory: the fused rate written chunk by chunk.

:func:`streamed_fuse` does what :func:`gyroarray.chain.fuse.fuse` does for an estimator that is
a fixed linear filter (its :meth:`~gyroarray.estimators.base.Estimator.linear_system`: ``ols``,
``gls``, ``naive`` and ``svo``, a static matrix per sample, optionally low-passed; ``kf_array``
and ``kf_single``, steady-state Kalman filters), reading the record in chunks
(:func:`gyroarray.core.measurement.iter_record`) and never holding it whole:

1. **The single gyros** (:func:`gyroarray.analysis.allan_stream.streamed_allan`, two reads of
   the file): which gyros are constant, the sample period, and each gyro's octave Allan
   variance over the whole record, from which the estimator's noise is fitted when no model is
   given (the white + walk fit of :func:`~gyroarray.chain.fuse.white_walk_of_avar`, as in memory
   on a record whose analysed part is the whole record).
2. **The fused rate** (a third read): the estimator's filter run chunk by chunk with its state
   carried across chunks (:class:`ChunkFilter`: each mode of the filter through
   ``scipy.signal.lfilter`` with ``zi``; a static estimator is one matrix product per chunk),
   written to ``out`` (Parquet, CSV or CSV.GZ) chunk by chunk, and its mean summed.
3. **Its ADEV** (a fourth read): the fused rate again, its phase to temporary files and the
   overlapping ADEV at every start index (:class:`~gyroarray.analysis.allan_stream.PhaseFiles`,
   :func:`~gyroarray.analysis.allan_stream.phase_oadev`), with the CIs and noise fit as in
   memory.

The analysed part is the whole record (a record with reference: output − layout·ref; without
one, a record the still-part detector's window test finds still, as ``allan`` streams it). On a
record that fits in memory and is analysed whole there too, the fused rate and its ADEV equal
the in-memory ``fuse``'s to rounding (tested to 1e-12). Peak memory: the working budget
(:func:`gyroarray.core.limits.stream_work_bytes`) for chunks and phase windows, independent of
the record's length.

Not streamed (refused in one line, naming the estimators that stream): an estimator that is not
a fixed linear filter (``bound``, ``fdi``), ``svo`` without ``--model`` (its weights from the
record's Allan covariance need the record in memory), ``--validate`` and ``--repair``.
"""

from __future__ import annotations

import gzip
import math
import shutil
from pathlib import Path
from types import SimpleNamespace
from typing import cast

import numpy as np

from gyroarray import __version__
from gyroarray.analysis.allan import analysis_of
from gyroarray.analysis.allan_stream import (PhaseFiles, chunk_rows_for, phase_oadev,
                                             streamed_allan)
from gyroarray.core import outputs, units
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.limits import format_size, stream_work_bytes
from gyroarray.core.measurement import Measurement, RecordHead, iter_record
from gyroarray.estimators.base import LinearSystem
from gyroarray.estimators.kalman import modal_lfilter
from gyroarray.chain.fuse import (AXES, axes_json, best_single_of,
                                  check_geometry, fitted_noise, fused_sidecar, gain_of,
                                  noise_of_model, plain_params, predicted_arw, resolve_estimator,
                                  white_walk_of_avar)

__all__ = ["STREAMING_ESTIMATORS", "ChunkFilter", "streamed_fuse"]

#: The built-in estimators ``fuse`` streams (fixed linear filters).
STREAMING_ESTIMATORS = ("gls", "ols", "naive", "svo", "kf_array", "kf_single")


class ChunkFilter:
    """A fitted linear estimator run chunk by chunk, its state carried across chunks.

    The filter x̂_k = A x̂_{k-1} + K z_k, ω̂_k = C x̂_k, x̂_{-1} = X0 z_0
    (:class:`~gyroarray.estimators.base.LinearSystem`) in its modes m = S⁻¹ x̂:
    m_k = λ m_{k-1} + (S⁻¹K) z_k, each distinct λ through ``scipy.signal.lfilter`` with the
    previous chunk's final state as ``zi``; the unit modes (λ = 1, not driven) keep their start.
    A static estimator (every λ = 0) is ω̂ = z (C K)ᵀ. Calling it on the chunks of a record in
    order gives the rates the estimator gives on the whole record, to rounding.

    Parameters
    ----------
    system : LinearSystem
        The fitted estimator's (:meth:`Estimator.linear_system`).
    """

    def __init__(self, system: LinearSystem):
        lam, S, S_inv = (np.asarray(v) for v in (system.lam, system.S, system.S_inv))
        if any(np.iscomplexobj(v) and np.any(np.abs(np.imag(v)) > 0) for v in (lam, S, S_inv)):
            raise ValueError("complex modes")
        self.lam = np.real(lam).astype(float)
        self.unit = np.abs(1.0 - self.lam) <= 1e-12
        self.static = bool(np.all(self.lam == 0.0))
        self.m_out = np.real(np.asarray(system.C) @ S)                  # (3, D)
        self.m_in = np.real(S_inv @ np.asarray(system.K))               # (D, N)
        self.m_start = np.real(S_inv @ np.asarray(system.X0))           # (D, N)
        self.direct = np.asarray(system.C) @ np.asarray(system.K)       # static: ω̂ = M z
        live = np.flatnonzero(~self.unit)
        order = np.argsort(self.lam[live], kind="stable")
        self.live = live[order]
        self.state: np.ndarray | None = None                             # zi per live mode

    def __call__(self, z: np.ndarray) -> np.ndarray:
        """Rates (n, 3) [rad/s] of the next chunk of readings ``z`` (n, N) [rad/s]."""
        if self.static:
            return np.ascontiguousarray(z @ self.direct.T)
        live = self.live
        if self.state is None:
            m0 = self.m_start @ z[0]
            self.unit_part = self.m_out[:, self.unit] @ m0[self.unit]
            self.state = self.lam[live] * m0[live]
        u = (z @ self.m_in[live].T).T                                    # (d, n)
        y, self.state = modal_lfilter(self.lam[live], u, self.state)
        y = y.T
        out = y @ self.m_out[:, live].T
        out += self.unit_part
        return out


def _refuse(estimator: str, why: str, source: str) -> InputError:
    return InputError(f"fuse streams (a record over the memory budget, or --stream) only an "
                      f"estimator that is a fixed linear filter ({', '.join(STREAMING_ESTIMATORS)}, "
                      f"svo with --model): {why}; cut the record or raise --max-memory to fuse it "
                      "in memory", file=source)


class _FusedWriter:
    """The fused record written chunk by chunk to a temporary file, moved to ``path`` at the end
    (Parquet, CSV or CSV.GZ, the columns of :func:`gyroarray.chain.fuse.fused_files`)."""

    def __init__(self, path: Path, names: list[str], header: str):
        self.path = Path(path)
        self.names = names
        # a new hidden file beside the output (never through a link), named only at the end
        self._raw, self.staged = outputs.open_staged(self.path)
        low = self.path.name.lower()
        self.parquet = low.endswith(".parquet")
        self._pq = None
        try:
            if self.parquet:
                # deferred: pyarrow.parquet (with ssl) loads only for a Parquet output; pyarrow itself comes with pandas
                import pyarrow as pa
                import pyarrow.parquet as pq
                self._pa = pa
                self._pq = pq.ParquetWriter(self._raw, pa.schema([(c, pa.float64()) for c in names]),
                                            compression="zstd")
            else:
                self._fh = (gzip.GzipFile(filename="", fileobj=self._raw, mode="wb",
                                          compresslevel=6, mtime=0)
                            if low.endswith(".gz") else self._raw)
                self._fh.write((header + "\n" + ",".join(names) + "\n").encode("utf-8"))
                self._row = ",".join(["%r"] * len(names))
        except BaseException:
            self._raw.close()
            self.staged.discard()
            raise

    def write(self, table: np.ndarray) -> None:
        if self._pq is not None:
            self._pq.write_table(self._pa.table({c: table[:, j] for j, c in enumerate(self.names)}))
        else:
            self._fh.write(("\n".join(map(self._row.__mod__, map(tuple, table.tolist())))
                            + "\n").encode("utf-8"))

    def close(self, keep: bool):
        """Finish the file; the :class:`~gyroarray.core.outputs.Staged` handle when ``keep``
        (named later, with its sidecar), else the file is removed and None comes back."""
        try:
            if self._pq is not None:
                self._pq.close()
            elif self._fh is not self._raw:
                self._fh.close()
            self._raw.close()
        except BaseException:
            self.staged.discard()
            raise
        if keep:
            return self.staged
        self.staged.discard()
        return None


def streamed_fuse(head: RecordHead, estimator: str, *, model=None, model_name: str | None = None,
                  exclude=(), params: dict | None = None, out=None, whole: bool = False,
                  work_bytes: int | None = None, tmp_dir=None, site=None,
                  input_sha256: str | None = None, sidecar_sha256: str | None = None,
                  sidecar=None, force: bool = False) -> dict:
    """Fuse a record read in chunks (module docstring); the ``fuse --json`` object.

    Parameters
    ----------
    head : RecordHead
        From :func:`gyroarray.core.measurement.record_head`.
    estimator : str
        Registry name; a fixed linear filter (:data:`STREAMING_ESTIMATORS`).
    model : NoiseModel, optional
        The gyros' noise; None: fitted on the whole record's streamed octave Allan variance.
    model_name : str, optional
        The model's file (messages, provenance).
    exclude : iterable of int
        Gyros to leave out (1-based).
    params : dict, optional
        The estimator's hyperparameters.
    out : path, optional
        The fused record (``.parquet`` recommended, ``.csv``, ``.csv.gz``), written piece by
        piece to a hidden temporary file and named only when the whole analysis succeeded.
    sidecar : path, optional
        The fused record's sidecar, named together with it
        (:func:`~gyroarray.core.outputs.write_many`: a crash or a refusal never leaves a new
        record beside an old sidecar); None: the caller writes it from ``"sidecar_toml"``.
    force : bool
        Replace existing ``out`` and ``sidecar`` (checked by the caller before the work).
    whole : bool
        Analyse a record without reference whole even when it moves (``--all``).
    work_bytes : int, optional
        Working-memory budget [bytes] (default :func:`~gyroarray.core.limits.stream_work_bytes`).
    tmp_dir : path, optional
        Where the phase files go.
    site : Site, optional
        The input's site, copied to the fused sidecar.
    input_sha256, sidecar_sha256 : str, optional
        Provenance of the input, for the sidecar.

    Returns
    -------
    dict
        As :meth:`gyroarray.chain.fuse.FuseResult.to_json_dict`, plus ``"streamed"`` (chunk
        rows, working budget) and ``"sidecar_toml"`` (bytes; removed by the caller).

    Raises
    ------
    InputError
        As :func:`~gyroarray.chain.fuse.fuse`; an estimator that does not stream; the record's
        problems as the streamed reader says them.
    """
    name = head.source
    params = dict(params or {})
    cls, est = resolve_estimator(estimator, params)
    n_g = head.n_gyros
    excluded = sorted({int(k) for k in exclude})
    bad = [k for k in excluded if not 1 <= k <= n_g]
    if bad:
        raise InputError(f"--exclude {bad[0]} is out of range: the measurement has gyros 1..{n_g}",
                         file=name)
    if (model is None and "allan_covariance" in est.get_params()
            and est.get_params()["allan_covariance"] is None):
        raise _refuse(estimator, f"{estimator} without --model takes its weights from the record's "
                      "Allan covariance, which needs the record in memory", name)
    work = stream_work_bytes() if work_bytes is None else int(work_bytes)
    candidates = [k for k in range(1, n_g + 1) if k not in excluded]
    # 1. the single gyros, streamed: constant ones, the period, each one's octave Allan variance
    single_sa = streamed_allan(head, candidates, whole=whole, work_bytes=work, tmp_dir=tmp_dir)
    constant = [k for k, why in single_sa.skipped.items() if "is constant" in why]
    used = [k for k in candidates if k not in constant]
    axes_all = np.asarray(head.layout.axes)
    stand_in = cast(Measurement, SimpleNamespace(layout=head.layout, source=name, n_gyros=n_g))
    check_geometry(stand_in, used, excluded, constant)
    notes = list(single_sa.notes)
    if constant:
        which = "gyro " + str(constant[0]) if len(constant) == 1 else \
            "gyros " + ", ".join(map(str, constant))
        notes.insert(0, f"{which} left out: constant output (dead or stuck?)")
    dt, n = single_sa.dt_s, single_sa.n_samples
    idx = [k - 1 for k in used]
    h = axes_all[idx]
    missing = [k for k in used if k not in single_sa.analyses]
    single = None
    if not missing:
        a0 = single_sa.analyses[used[0]]
        avar = np.column_stack([single_sa.analyses[k].adev_rad_s ** 2 for k in used])
        single = white_walk_of_avar(a0.taus_s, avar, a0.m, n + 1)
    if model is None:
        if single is None:
            raise InputError(f"no --model, and the white + walk fit of gyro(s) "
                             f"{', '.join(map(str, missing)) or ', '.join(map(str, used))} failed on the "
                             "streamed record: give --model M.toml (e.g. from gyroarray fit on a part "
                             "of it)", file=name)
        arw = single.arw_rad_rt_s.copy()
        weak = arw <= 0
        if weak.any():               # a walk alone: the white level at the shortest tau
            first = np.array([single_sa.analyses[used[i]].adev_rad_s[0] for i in np.flatnonzero(weak)])
            arw[weak] = np.maximum(first * math.sqrt(dt), 1e-30)
        noise, source = fitted_noise(arw, single, used, notes,
                                     " (streamed: the whole record's overlapping Allan variance)")
    else:
        noise, source = noise_of_model(model, stand_in, used, cls.needs_arw, model_name, notes)
        notes.append("streamed: the model's white levels are used as they are, not checked against the "
                     "record first (a fuse in memory checks them: --off-levels)")
    try:
        est.fit(Layout.from_axes(h, source=name), noise, dt)
    except InputError as err:
        text = err.message if err.message.startswith(f"{estimator}:") else f"{estimator}: {err.message}"
        raise InputError(text, file=name if model is None else (model_name or name)) from None
    try:
        system = est.linear_system()
        ChunkFilter(system)
    except (InputError, NotImplementedError, AttributeError, ValueError, np.linalg.LinAlgError):
        raise _refuse(estimator, f"{estimator} is not one", name) from None
    gain, tconst = gain_of(est, dt)
    if excluded:
        notes.append(f"gyro(s) {', '.join(map(str, excluded))} left out (--exclude)")

    names = list(head.names)
    gcols = slice(1, 1 + n_g)
    has_ref = head.has_reference
    rcols = slice(names.index("ref_x"), names.index("ref_x") + 3) if has_ref else None
    extra = [j for j, c in enumerate(names) if c.startswith("ref_")]
    extra += [j for j, c in enumerate(names) if c == "temp_c"]
    extra += [j for j, c in enumerate(names) if c.startswith("acc_")]
    out_names = ["time_s", "gyro1", "gyro2", "gyro3", *(names[j] for j in extra)]
    rows = chunk_rows_for(len(names) + 6, work)

    def fused_chunks():
        """(chunk, fused [rad/s], fused − ref [rad/s]) over the record, the filter restarted."""
        filt = ChunkFilter(system)
        for chunk in iter_record(head, rows, check=False):     # checked by the first read
            y = units.deg_s_to_rad_s(chunk[:, gcols])[:, idx]
            fused = filt(y)
            e = fused - units.deg_s_to_rad_s(chunk[:, rcols]) if has_ref else fused
            yield chunk, fused, e

    # 2. the fused rate, written chunk by chunk; its mean
    writer = None
    if out is not None:
        writer = _FusedWriter(Path(out), out_names,
                              f"# written by gyroarray {__version__} (gyroarray fuse, estimator "
                              f"{estimator}, streamed): gyro1..3 = fused body rate about x, y, z [deg/s]")
    total = np.zeros(3)
    count = 0
    ok = False
    staged = None
    try:
        for chunk, fused, e in fused_chunks():
            total += e.sum(axis=0)
            count += chunk.shape[0]
            if writer is not None:
                writer.write(np.column_stack([chunk[:, 0], units.rad_s_to_deg_s(fused),
                                              chunk[:, extra]]))
        ok = True
    finally:
        if writer is not None:
            staged = writer.close(keep=ok and count == n)
    try:
        if count != n:
            raise InputError(f"the file changed while it was read: {n} rows before, {count} now; "
                             "rerun when it is complete", file=name)
        # 3. its ADEV: the phase of each axis to a temporary file, the sums at every start index
        mean = total / n
        adev: list = []
        folder = outputs.make_temp_dir("fuse", tmp_dir)   # named for this process (a SIGKILL's: removed by the next run)
        try:
            phases = PhaseFiles(folder, {a: mean[a] for a in range(3)}, n, name)
            try:
                for _, _, e in fused_chunks():
                    for a in range(3):
                        phases.add(a, e[:, a])
            finally:
                phases.close()
            results = [phase_oadev(phases.paths[a], n + 1, dt, "octave", work) for a in range(3)]
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        for a, res in enumerate(results):
            try:
                with np.errstate(all="ignore"):
                    adev.append(analysis_of(res))
            except (InputError, np.linalg.LinAlgError, ValueError, FloatingPointError) as err:
                adev.append(None)
                notes.append(f"fused {AXES[a]}: no ADEV ({getattr(err, 'message', err)})")
        fused_fit = white_walk_of_avar(results[0].taus_s, np.column_stack([r.dev ** 2 for r in results]),
                                       results[0].m, n + 1)
        predicted = predicted_arw(est, noise)
        arw_u = units.arw_rad_rt_s_to_deg_rt_h
        rrw_u = units.rrw_rad_s_rt_s_to_deg_h_rt_h
        single_json = None
        if single is not None:
            single_json = {str(k): {"arw_deg_rt_h": float(arw_u(single.arw_rad_rt_s[i])),
                                    "arw_deg_rt_h_sigma": float(arw_u(single.arw_sigma[i])),
                                    "rrw_deg_h_rt_h": float(rrw_u(single.rrw_rad_s_rt_s[i]))}
                           for i, k in enumerate(used)}
        if n < 256:
            notes.append(f"the record is {n} samples: its ADEV and fits are short")
        notes.append(f"streamed fuse: the record read in chunks of {rows} rows, four times (the single "
                     f"gyros' ADEV twice, the fused rate twice), working budget {format_size(work)}; "
                     "the estimator's filter ran chunk by chunk with its state carried across chunks")
        out_params = plain_params(est.get_params())
        analysed = ("the whole record, output minus layout·reference" if has_ref else
                    "the whole record (no reference rate; streamed: analysed whole)")
        res_json = {
            "measurement": name, "n_samples": n, "dt_s": dt,
            "estimator": estimator, "estimator_params": out_params, "model_source": source,
            "gyros_used": list(used), "excluded_gyros": excluded, "constant_gyros": constant,
            "design_noise": {
                "arw_deg_rt_h": [float(v) for v in arw_u(noise.arw_rad_rt_s)],
                "rrw_deg_h_rt_h": [float(v) for v in rrw_u(noise.rrw_rad_s_rt_s)],
                "correlated": bool(not np.array_equal(noise.corr_arw, np.eye(len(used))))},
            "analysed": analysed, "analysed_parts": [[0, n]],
            "analysed_parts_s": [[0.0, float(n * dt)]],
            "axes": axes_json(adev, fused_fit, best_single_of(single, used, axes_all), predicted),
            "single_gyros": single_json,
            "gain_definition": "gain = min over used gyros k of (ARW_k / |h_k,axis|) / fused ARW "
                               "of the axis; ARWs from the same white + walk Allan fit on the "
                               "analysed part",
            "notes": notes,
            "streamed": {"chunk_rows": rows, "work_bytes": work, "passes": 4,
                         "gain": None if gain is None else gain.tolist(), "time_constant_s": tconst},
        }
        description = (f"fused body rate of {name} by gyroarray fuse (estimator {estimator}, "
                       f"{len(used)} gyros): gyro1, gyro2, gyro3 are the rate about the platform x, y, z axes")
        res_json["sidecar_toml"] = fused_sidecar(estimator, out_params, source, used, excluded, constant,
                                                 noise, name, head.sample_rate_hz, description, site,
                                                 input_sha256=input_sha256, sidecar_sha256=sidecar_sha256)
        if staged is not None:  # the fused record and its sidecar named together, at the end
            items = [(out, staged)] + ([(sidecar, res_json["sidecar_toml"])] if sidecar else [])
            outputs.write_many(items, force=force)
            staged = None
    finally:
        if staged is not None:      # a failure after the record was written: nothing is named
            staged.discard()
    return res_json
