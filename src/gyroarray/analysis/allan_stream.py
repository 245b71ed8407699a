"""The overlapping Allan deviation of a record longer than memory, streamed from its file.

:func:`streamed_allan` reads a measurement (Parquet, CSV or CSV.GZ) in chunks
(:func:`gyroarray.core.measurement.iter_record`) and never holds it whole:

1. **First pass** (one read of the file): the sample count, the sums that give each gyro's
   mean rate, the spread of each gyro (a constant gyro is noted, not analysed), whether the
   reference rate ever moves, and, for a record without reference, the one-second window
   statistics of the still-part detector (:func:`gyroarray.analysis.motion.still_mask`'s window
   test: window means against their running median, window noise against its typical level).
2. **Second pass**: the analysed rate of each gyro (as ``gyroarray allan`` analyses it: the
   output, or output minus layout·ref when the reference moves), minus its mean, is integrated
   to the phase ``x`` (``x[0] = 0``, ``x[i+1] = x[i] + (y[i] - mean)``, in file order: the same
   sequential sums as :func:`gyroarray.analysis.allan.deviation`) and written to a temporary
   float64 file per gyro (8 bytes per sample and gyro of disk).
3. **Sums**: for each averaging factor ``m``, ``S(m) = sum_i (x[i+2m] - 2 x[i+m] + x[i])^2``
   over every ``i`` (the fully overlapping estimator, nothing decimated), windows of ``x`` read
   back from the file at the three offsets ``i``, ``i + m``, ``i + 2m``; then the deviation,
   its EDF, confidence intervals and noise fit as in memory
   (:func:`gyroarray.analysis.allan.analysis_of`).

Peak memory is the working budget (:func:`gyroarray.core.limits.stream_work_bytes`, chunks and
windows), plus the one-second window statistics of the first pass (48 bytes per second of
record and gyro analysed), independent of the record's length otherwise. The result equals the
in-memory one to rounding (about 1e-15 relative; the mean is summed in chunks and the squared
differences in windows, so the last bits may differ).

What a streamed analysis does not do (said in its notes): ``--kind`` other than ``oadev``,
``--repair``, ``--robust``, ``--gaps``, the spike count, the lag-1 noise identification per tau,
the white-level check and the reference-noise check, all of which need the record in memory;
and it analyses the record whole: a record without reference that the window test finds moving
is refused unless ``--all``.
"""

from __future__ import annotations

import math
import os
import shutil
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.ndimage import median_filter

from gyroarray.core import units
from gyroarray.core.constants import EARTH_RATE_RAD_S
from gyroarray.core.errors import InputError
from gyroarray.core.jit import njit
from gyroarray.core.limits import format_size, stream_work_bytes
from gyroarray.core.measurement import MIN_SPREAD_DEG_S, RecordHead, iter_record

from gyroarray.analysis.allan import AllanAnalysis, AllanResult, analysis_of, averaging_factors
from gyroarray.analysis.motion import MAD_TO_SIGMA, MEAN_AD_TO_SIGMA

__all__ = ["StreamedAllan", "streamed_allan", "chunk_rows_for", "oadev_of_phase_file",
           "PhaseFiles", "phase_oadev"]

#: Independent partial sums of the squared-difference kernel (as the in-memory kernel's).
LANES = 64
# the window test of motion.still_mask (its defaults)
_Z, _BASELINE_S, _NOISE_S, _MAX_RATIO, _WINDOW_S = 6.0, 30.0, 10.0, 10.0, 1.0
_FLOOR_RAD_S = 2.0 * EARTH_RATE_RAD_S


@dataclass(frozen=True)
class StreamedAllan:
    """What :func:`streamed_allan` found: the analyses and what was read.

    Parameters
    ----------
    analyses : dict
        Gyro (1-based) -> :class:`~gyroarray.analysis.allan.AllanAnalysis`.
    skipped : dict
        Gyro -> why it was not analysed (constant output, a fit that failed).
    n_samples : int
        Samples read.
    dt_s : float
        Sample period [s] (the sidecar's, when the time stamps agree with it).
    signal : str
        What was analysed (output, or output minus layout·ref).
    notes : list of str
        What the streaming did and did not do.
    chunk_rows : int
        Rows per chunk read.
    work_bytes : int
        The working-memory budget [bytes].
    """

    analyses: dict
    skipped: dict
    n_samples: int
    dt_s: float
    signal: str
    notes: list = field(default_factory=list)
    chunk_rows: int = 0
    work_bytes: int = 0


def chunk_rows_for(n_columns: int, work_bytes: int | None = None) -> int:
    """Rows per chunk so that a chunk and its copies (about 16 float64 arrays of its size) stay
    within ``work_bytes`` (default :func:`~gyroarray.core.limits.stream_work_bytes`)."""
    work = stream_work_bytes() if work_bytes is None else int(work_bytes)
    return max(256, work // (16 * 8 * max(1, n_columns)))


@njit(cache=True)
def _second_difference_sum(a, b, c):  # pragma: no cover - compiled
    """``sum_j (c[j] - 2 b[j] + a[j])^2`` in ``LANES`` partial sums (vectorised, strict IEEE)."""
    n = a.size
    acc = np.zeros(LANES)
    n_full = n - n % LANES
    for j in range(0, n_full, LANES):
        for u in range(LANES):
            d = c[j + u] - 2.0 * b[j + u] + a[j + u]
            acc[u] += d * d
    tail = 0.0
    for j in range(n_full, n):
        d = c[j] - 2.0 * b[j] + a[j]
        tail += d * d
    s = 0.0
    for u in range(LANES):
        s += acc[u]
    return s + tail


def _read_window(fd: int, start: int, count: int) -> np.ndarray:
    """``x[start:start + count]`` of a float64 phase file."""
    raw = os.pread(fd, 8 * count, 8 * start)
    if len(raw) != 8 * count:                       # a file cut short under us: internal
        raise OSError(f"phase file ends early: {len(raw)} of {8 * count} bytes at {8 * start}")
    return np.frombuffer(raw, dtype=np.float64)


def oadev_of_phase_file(path, n_phase: int, m: np.ndarray, window: int) -> np.ndarray:
    """The sums ``S(m) = sum_i (x[i+2m] - 2 x[i+m] + x[i])^2``, ``i = 0 .. n_phase - 2m - 1``,
    of a phase stored as raw float64 in ``path``, reading windows of ``window`` start indices.

    Parameters
    ----------
    path : str or os.PathLike
        Raw float64 file of ``n_phase`` phase samples.
    n_phase : int
        Phase samples in the file.
    m : ndarray of int64
        Averaging factors, increasing, each with ``n_phase - 2 m >= 1``.
    window : int
        Start indices per step; memory is about ``(3 + 4) * 8 * window`` bytes.

    Returns
    -------
    ndarray
        ``S(m)`` per averaging factor (units of the phase squared).
    """
    sums = np.zeros(m.size)
    fd = os.open(path, os.O_RDONLY)
    try:
        for i0 in range(0, n_phase, window):
            base_len = min(3 * window, n_phase - i0)
            base = _read_window(fd, i0, base_len)
            kept: tuple[int, np.ndarray] | None = None     # the last far window (offset 2m)

            def win(offset: int, count: int) -> np.ndarray:
                nonlocal kept
                if offset + count <= base_len:
                    return base[offset:offset + count]
                if kept is not None and kept[0] == offset and kept[1].size >= count:
                    return kept[1][:count]
                return _read_window(fd, i0 + offset, count)

            for k, mm in enumerate(m.tolist()):
                count = min(window, n_phase - 2 * mm - i0)
                if count <= 0:
                    continue
                c = win(2 * mm, count)
                sums[k] += _second_difference_sum(win(0, count), win(mm, count), c)
                kept = (2 * mm, c)
    finally:
        os.close(fd)
    return sums


class PhaseFiles:
    """The phases of several rate series, each to its own temporary raw float64 file.

    ``x[0] = 0``, ``x[i+1] = x[i] + (y[i] - mean)``, summed in file order chunk by chunk (the
    sequential sums of :func:`gyroarray.analysis.allan.deviation`): call :meth:`add` with each
    chunk of every series, in order; then :meth:`close` and read :attr:`paths`.

    Parameters
    ----------
    folder : str
        Where the files go (a temporary folder the caller removes).
    means : dict
        Series key -> its mean (subtracted from every sample) [unit of the series].
    n_samples : int
        Samples each series will have (for the disk check).
    source : str
        The record, for the refusal when the disk lacks the room.
    """

    def __init__(self, folder: str, means: dict, n_samples: int, source: str):
        need = 8 * (n_samples + 1) * len(means)
        free = shutil.disk_usage(folder).free
        if need > free:
            raise InputError(f"streaming the Allan deviation writes the phase of {len(means)} "
                             f"series to temporary files: {format_size(need)}, more than the "
                             f"{format_size(free)} free in {os.path.dirname(folder)}; set TMPDIR "
                             "to a folder with room, or analyse fewer gyros (--gyro K)",
                             file=source)
        self.means = dict(means)
        self.paths = {k: os.path.join(folder, f"phase{k}.f64") for k in self.means}
        self._handles = {k: open(self.paths[k], "wb") for k in self.means}
        self._last = {k: 0.0 for k in self.means}
        for fh in self._handles.values():
            np.zeros(1).tofile(fh)

    def add(self, key, y: np.ndarray) -> None:
        """Append the next samples ``y`` (1-D) of series ``key``."""
        inc = np.array(y, dtype=float) - self.means[key]
        inc[0] += self._last[key]
        x = np.cumsum(inc)
        x.tofile(self._handles[key])
        self._last[key] = float(x[-1])

    def close(self) -> None:
        """Close every file (idempotent)."""
        for fh in self._handles.values():
            fh.close()


def phase_oadev(path, n_phase: int, dt: float, taus, work: int) -> AllanResult:
    """The overlapping Allan deviation of a phase file written by :class:`PhaseFiles` (every
    start index, windows of ``x`` read back within ``work`` bytes), as an
    :class:`~gyroarray.analysis.allan.AllanResult` ready for
    :func:`~gyroarray.analysis.allan.analysis_of`."""
    m = averaging_factors(n_phase, dt, taus, "oadev")
    window = max(LANES, work // (8 * 8))
    sums = oadev_of_phase_file(path, n_phase, m, window)
    n_terms = n_phase - 2 * m
    dev = np.sqrt(sums / (2.0 * n_terms)) / m
    return AllanResult(kind="oadev", tau0_s=dt, n_phase=n_phase, m=m, taus_s=m * dt, dev=dev,
                       n_terms=n_terms)


def _median_dt(steps_median: list[float], nominal: float) -> float:
    """The sample period: the nominal one when the chunks' median steps agree with it to 1e-6
    relative (as :attr:`Measurement.dt_s`), else the median of the chunks' medians."""
    med = float(np.median(steps_median))
    return nominal if abs(med - nominal) <= 1e-6 * nominal else med


def _moving_windows(means: np.ndarray, sw: np.ndarray, L: int) -> np.ndarray:
    """The one-second windows the still-part detector's window test calls moving (bool (B,))."""
    kn = 2 * int(_NOISE_S / _WINDOW_S / 2) + 1
    kb = 2 * int(_BASELINE_S / _WINDOW_S / 2) + 1
    base = median_filter(means, size=(kb, 1), mode="nearest")
    sig = np.median(sw, axis=0)
    se = np.maximum(MAD_TO_SIGMA * np.median(np.abs(means - base), axis=0), sig / np.sqrt(L))
    sw_loc = median_filter(sw, size=(kn, 1), mode="nearest")
    ratio = np.divide(sw_loc, sig, out=np.ones_like(sw), where=sig > 0)
    rough = np.any(np.divide(sw, sig, out=np.zeros_like(sw), where=sig > 0) > _MAX_RATIO, axis=1)
    thr = np.maximum(_Z * se * np.clip(ratio, 1.0, _MAX_RATIO), _FLOOR_RAD_S)
    return np.any(np.abs(means - base) > thr, axis=1) | rough


def streamed_allan(head: RecordHead, gyros: list[int], *, taus="octave", raw: bool = False,
                   whole: bool = False, work_bytes: int | None = None,
                   tmp_dir=None) -> StreamedAllan:
    """The overlapping Allan deviation, EDF, confidence intervals and noise fit of each gyro of
    a record read in chunks (see the module docstring for the passes and what they compute).

    Parameters
    ----------
    head : RecordHead
        From :func:`gyroarray.core.measurement.record_head`.
    gyros : list of int
        The gyros (1-based) to analyse.
    taus : "octave", int or sequence of float
        As :func:`gyroarray.analysis.allan.averaging_factors`.
    raw : bool
        Analyse the output even when the reference moves (``allan --raw``).
    whole : bool
        Analyse a record without reference whole even when it moves (``allan --all``).
    work_bytes : int, optional
        Working-memory budget [bytes] (default
        :func:`~gyroarray.core.limits.stream_work_bytes`).
    tmp_dir : str or os.PathLike, optional
        Where the phase files go (default: the system's temporary folder).

    Returns
    -------
    StreamedAllan

    Raises
    ------
    InputError
        The file's problems (as :func:`~gyroarray.core.measurement.iter_record` says them), a
        record without reference that moves (without ``whole``), too little temporary disk, or
        no gyro that can be analysed.
    """
    work = stream_work_bytes() if work_bytes is None else int(work_bytes)
    names = head.names
    n_cols = len(names)
    rows = chunk_rows_for(n_cols, work)
    N = head.n_gyros
    gcols = slice(1, 1 + N)
    has_ref = head.has_reference
    rcols = slice(names.index("ref_x"), names.index("ref_x") + 3) if has_ref else None
    H = np.asarray(head.layout.H, dtype=float)
    keep = [k - 1 for k in gyros]
    nominal = 1.0 / head.sample_rate_hz
    L = max(2, round(_WINDOW_S / nominal))
    h = head.layout.axes[keep]
    proj = np.linalg.pinv(h).T if np.linalg.matrix_rank(h) == 3 else None

    # -- first pass: count, sums, spread, reference motion, window statistics ------------------
    n = 0
    sum_out = np.zeros(N)
    sum_minus = np.zeros(N)
    lo, hi = np.full(N, np.inf), np.full(N, -np.inf)
    ref_moves = False
    step_medians: list[float] = []
    t_first = t_last = None
    carry = None
    means, sws = [], []
    for chunk in iter_record(head, rows):
        t = chunk[:, 0]
        steps = np.diff(t if t_last is None else np.concatenate(([t_last], t)))
        if steps.size:
            step_medians.append(float(np.median(steps)))
        t_first = float(t[0]) if t_first is None else t_first
        t_last = float(t[-1])
        g_deg = chunk[:, gcols]
        lo, hi = np.minimum(lo, g_deg.min(axis=0)), np.maximum(hi, g_deg.max(axis=0))
        y = units.deg_s_to_rad_s(g_deg)
        sum_out += y.sum(axis=0)
        if has_ref:
            ref = units.deg_s_to_rad_s(chunk[:, rcols])
            ref_moves = ref_moves or bool(ref.any())
            sum_minus += (y - ref @ H.T).sum(axis=0)
        else:
            s = y[:, keep] @ proj if proj is not None else y[:, keep]
            buf = s if carry is None else np.vstack([carry, s])
            nb = buf.shape[0] // L
            if nb:
                blocks = buf[:nb * L].reshape(nb, L, -1)
                means.append(blocks.mean(axis=1))
                d = np.diff(blocks, axis=1)
                sws.append(MEAN_AD_TO_SIGMA / np.sqrt(2.0)
                           * np.abs(d - np.median(d, axis=1, keepdims=True)).mean(axis=1))
            carry = buf[nb * L:]
        n += chunk.shape[0]
    if n < 3:
        raise InputError(f"{n} samples are too few for oadev: need at least 3", file=head.source)
    dt = _median_dt(step_medians or [nominal], nominal)
    notes = [f"streamed: the record ({n} samples x {N} gyros) was read in chunks of {rows} rows, "
             f"twice, with a working budget of {format_size(work)} (the phase of each gyro went to "
             "a temporary file); the overlapping Allan deviation is computed at every start index "
             "(nothing decimated) and equals the in-memory result to rounding"]
    minus_ref = has_ref and ref_moves and not raw
    what = ("gyro output minus layout·ref (motion removed)" if minus_ref else "gyro output")
    if not has_ref:
        B = sum(a.shape[0] for a in means)
        if B >= 3:
            moving = _moving_windows(np.vstack(means), np.vstack(sws), L)
            if moving.any() and not whole:
                raise InputError(
                    f"the streamed record moves: {int(moving.sum())} of its {B} one-second windows "
                    "(no reference rate; the still-part detector's window test); a streamed record "
                    "is analysed whole, and the Allan deviation of motion is not noise: rerun with "
                    "--all to analyse it whole anyway, or cut out the still parts (a record that "
                    "fits the memory budget has its still parts found and analysed)",
                    file=head.source)
            if moving.any():
                notes.append(f"--all: the whole record analysed, {int(moving.sum()) * L * dt:.1f} s "
                             "of it moving (one-second windows found moving in the outputs): the "
                             "motion counts as noise in every term")
            else:
                notes.append(f"streamed: no reference rate; the still-part detector's window test "
                             f"finds all {B} one-second windows still, so the record is analysed "
                             "whole (its per-sample edges are not refined as in memory)")
    notes.append("streamed: not done on a streamed record (they need it in memory): the spike "
                 "count, the lag-1 noise identification per tau, the white-level and "
                 "reference-noise checks")

    # -- second pass: the phase of each analysed gyro to a temporary file ----------------------
    dead = {k for k in gyros if hi[k - 1] - lo[k - 1] < MIN_SPREAD_DEG_S}
    todo = [k for k in gyros if k not in dead]
    skipped = {k: (f"gyro {k} is constant (dead or stuck?) at {lo[k - 1]:.6g} deg/s: not analysed")
               for k in sorted(dead)}
    mean = (sum_minus if minus_ref else sum_out) / n
    analyses: dict = {}
    if todo:
        from gyroarray.core.outputs import make_temp_dir  # deferred: only a streamed ADEV
        folder = make_temp_dir("allan", tmp_dir)   # named for this process (a SIGKILL's: removed by the next run)
        try:
            phases = PhaseFiles(folder, {k: mean[k - 1] for k in todo}, n, head.source)
            paths = phases.paths
            try:
                again = 0
                for chunk in iter_record(head, rows, check=False):    # checked in the first pass
                    again += chunk.shape[0]
                    y = units.deg_s_to_rad_s(chunk[:, gcols])
                    if minus_ref:
                        y = y - units.deg_s_to_rad_s(chunk[:, rcols]) @ H.T
                    for k in todo:
                        phases.add(k, y[:, k - 1])
            finally:
                phases.close()
            if again != n:
                raise InputError(f"the file changed while it was read: {n} rows in the first pass, "
                                 f"{again} in the second; rerun when it is complete",
                                 file=head.source)
            n_phase = n + 1
            for k in todo:
                res = phase_oadev(paths[k], n_phase, dt, taus, work)
                try:
                    with np.errstate(all="ignore"):
                        a: AllanAnalysis = analysis_of(res)
                except InputError as err:
                    skipped[k] = f"gyro {k} not analysed: {err.message}"
                    continue
                except (np.linalg.LinAlgError, ValueError, FloatingPointError) as err:
                    skipped[k] = f"gyro {k} not analysed: the noise fit failed on its data ({err})"
                    continue
                analyses[k] = _with_info(a)
                os.unlink(paths[k])
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    if not analyses:
        raise InputError("nothing to analyse: " + "; ".join(skipped.values()), file=head.source)
    if not math.isfinite(dt):
        raise InputError("the time stamps give no sample period", file=head.source)
    return StreamedAllan(analyses=analyses, skipped=skipped, n_samples=n, dt_s=dt, signal=what,
                         notes=notes, chunk_rows=rows, work_bytes=work)


def _with_info(a: AllanAnalysis) -> AllanAnalysis:
    """``a`` with the EDF formula and the streaming said in its ``info``."""
    return replace(a, info={**a.info, "edf_method": "Greenhall's sampled EDF, noise type per tau "
                            "from the noise fit", "streamed": True})
