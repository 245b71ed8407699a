"""``gyroarray diagnose`` on a record over the memory budget: its longest window that fits, and
the whole record's streamed ADEV beside the window's model.

A comparison holds about :data:`~gyroarray.chain.compare.COMPARISON_BYTES_PER_CELL` bytes per
sample and column beyond :data:`~gyroarray.chain.compare.FIXED_BYTES`
(:func:`~gyroarray.chain.compare.comparison_memory`). A record whose comparison (or reading it
whole) would pass the memory budget is diagnosed on its **window**: the longest contiguous block
of whole samples from the record's start that the comparison's memory model fits in the budget,
with a margin (:func:`window_plan`), read through the chunked reader
(:func:`gyroarray.core.measurement.read_window`: never beyond the window). The rest of the record
is not diagnosed; what it says is checked by the whole record's overlapping ADEV, streamed
(:func:`gyroarray.analysis.allan_stream.streamed_allan`, bounded memory), set beside the white +
walk prediction σ²(τ) = N²/τ + K²τ/3 of the baseline fitted on the window, at every octave τ,
those beyond the window's longest τ marked, and a τ flagged where the streamed ADEV's 68.3 % CI
and the window model's 68.3 % band (N and K at their 1σ ends) are disjoint
(:func:`whole_record_check`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gyroarray.analysis.allan_stream import chunk_rows_for, streamed_allan
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.limits import format_size, max_memory, stream_work_bytes
from gyroarray.core.measurement import Measurement, RecordHead, read_window, record_head

from gyroarray.chain.compare import COMPARISON_BYTES_PER_CELL, FIXED_BYTES, comparison_memory

__all__ = ["MIN_WINDOW", "WINDOW_SHARE", "WindowPlan", "window_plan", "check_work_bytes", "read_plan", "streamed_whole",
           "whole_record_check"]

#: Fewest samples a diagnosed window may have (below it the budget is refused as too small).
MIN_WINDOW = 1024
#: Share of the budget beyond :data:`~gyroarray.chain.compare.FIXED_BYTES` and the streamed
#: check's memory that the window's comparison is planned to use [-]: the memory model is an
#: estimate (``diagnose`` of a window of 1.14e6 samples x 4 gyros planned for all of 1 GiB
#: peaked at 1.155 GB RSS, 8 % over it; runs vary by about 5 %).
WINDOW_SHARE = 0.75


@dataclass(frozen=True)
class WindowPlan:
    """The window of a record over the budget that ``diagnose`` analyses.

    Attributes
    ----------
    head : RecordHead
        The record (no sample read).
    n_window : int
        Samples of the window (the first ones of the record).
    columns : int
        Columns the comparison holds per sample (gyros, reference, temperature, specific force).
    budget : int
        The memory budget [bytes].
    need : float
        What the whole record would need [bytes] (the comparison's memory model, or reading it
        whole when that is more; a lower bound for a CSV, whose rows are not counted ahead).
    """

    head: RecordHead
    n_window: int
    columns: int
    budget: int
    need: float


def window_plan(path) -> WindowPlan | None:
    """The window ``diagnose`` analyses when the record at ``path`` is over the memory budget,
    else None (a record that fits is read whole as before).

    The window is ``WINDOW_SHARE × (budget − FIXED_BYTES − W) // (COMPARISON_BYTES_PER_CELL ×
    columns)`` samples, W the streamed check's working memory (:func:`check_work_bytes`, and a
    Parquet file's largest row group, decoded): the
    most :func:`~gyroarray.chain.compare.comparison_memory` fits in the budget beside the
    streamed check, less a margin for the model's error (:data:`WINDOW_SHARE`).

    Raises
    ------
    InputError
        A budget that leaves fewer than :data:`MIN_WINDOW` samples; the record's head problems.
    """
    head = record_head(path)
    columns = len(head.names) - 1
    budget = max_memory()
    read_need = head.in_memory_bytes()
    cmp_need = comparison_memory(head.n_rows, columns) if head.n_rows is not None else 0.0
    need = max(read_need, cmp_need)
    if need <= budget:
        return None
    work = check_work_bytes(budget) + _row_group_bytes(head)
    room = WINDOW_SHARE * (budget - FIXED_BYTES - work)
    n_window = max(int(room) // (COMPARISON_BYTES_PER_CELL * columns), 0)
    if head.n_rows is not None:
        n_window = min(n_window, head.n_rows)
    if n_window < MIN_WINDOW:
        raise InputError(f"the record needs about {format_size(need)} to diagnose, more than the "
                         f"limit of {format_size(budget)}, and that limit leaves room for "
                         f"{n_window} samples, fewer than the {MIN_WINDOW} of the shortest window "
                         "diagnosed; gyroarray allan streams a record this long (--stream); raise "
                         "the limit with --max-memory SIZE", file=head.source)
    return WindowPlan(head=head, n_window=int(n_window), columns=columns, budget=budget, need=need)


def _row_group_bytes(head: RecordHead) -> int:
    """What the streamed reader holds of a Parquet file beyond its working budget [bytes]: its
    largest row group, decoded, with its compressed pages (0 for a CSV, read in chunks): from the
    footer :func:`~gyroarray.core.measurement.record_head` checked (the file is not opened again)."""
    return int(head.group_bytes) if head.n_rows is not None else 0


def check_work_bytes(budget: int) -> int:
    """Working memory [bytes] of the whole record's streamed ADEV beside a window's comparison:
    :func:`~gyroarray.core.limits.stream_work_bytes`, at most a quarter of what the budget leaves
    beyond :data:`~gyroarray.chain.compare.FIXED_BYTES` (at least 64 KiB)."""
    return int(max(1 << 16, min(stream_work_bytes(), (budget - FIXED_BYTES) // 4)))


def read_plan(plan: WindowPlan) -> Measurement:
    """The window's samples as a measurement (read in chunks, never beyond the window)."""
    rows = chunk_rows_for(len(plan.head.names), stream_work_bytes())
    return read_window(plan.head, plan.n_window, rows)


def streamed_whole(plan: WindowPlan, gyros):
    """The whole record's overlapping ADEV of ``gyros``, streamed (analysed whole, motion
    included; :func:`~gyroarray.analysis.allan_stream.streamed_allan`). Run it before the
    window's comparison: its working memory then does not add to the comparison's peak."""
    return streamed_allan(plan.head, list(gyros), whole=True, work_bytes=check_work_bytes(plan.budget))


def whole_record_check(plan: WindowPlan, analysis, window: Measurement, gyros,
                       streamed=None) -> tuple[dict, str]:
    """The whole record's streamed ADEV beside the window's fitted white + walk prediction.

    Parameters
    ----------
    plan : WindowPlan
    analysis : Analysis
        The window's diagnosis (:meth:`~gyroarray.chain.compare.Analysis.baseline_noise`
        gives each gyro's N and K).
    window : Measurement
        The window analysed.
    gyros : sequence of int
        The gyros diagnosed (1-based, the record's numbering; the analysis numbers them 1, 2, ...
        in this order, constant gyros left out).
    streamed : StreamedAllan, optional
        :func:`streamed_whole` of these gyros (computed here when not given).

    Returns
    -------
    json : dict
        ``window`` (what was analysed) and ``whole_record`` (per gyro: τ, the streamed ADEV, its
        CI, the prediction, beyond the window, outside the CI), datasheet units.
    note : str
        One line: "record of X h over the memory budget Y: diagnosed on its window a–b s
        (Z h); the whole record's ADEV (streamed) is ...".
    """
    head = plan.head
    res = streamed_whole(plan, gyros) if streamed is None else streamed
    n, dt = res.n_samples, res.dt_s
    t0 = float(window.time_s[0])
    a_s, b_s = 0.0, float(window.time_s[-1] - t0 + window.dt_s)
    longest = float(np.max(analysis.adev["taus_s"])) if len(analysis.adev.get("taus_s", [])) else 0.0
    per: dict = {}
    said = []
    number = {k: j for j, k in enumerate(gyros, 1)}        # record gyro -> the analysis's number
    for k, an in res.analyses.items():
        (big_n, sn), (big_k, sk) = analysis.baseline_noise(number[k], sigma=True)
        taus = np.asarray(an.taus_s, float)

        def model(n_deg, k_deg):
            nn = units.arw_deg_rt_h_to_rad_rt_s(max(n_deg, 0.0))
            kk = units.rrw_deg_h_rt_h_to_rad_s_rt_s(max(k_deg, 0.0))
            return np.sqrt(nn ** 2 / taus + kk ** 2 * taus / 3.0)
        n0, k0 = big_n or 0.0, big_k or 0.0
        pred = model(n0, k0)
        # the window model's 68.3 % band: N and K each at their 1-sigma ends
        band_lo = model(n0 - (sn or 0.0), k0 - (sk or 0.0))
        band_hi = model(n0 + (sn or 0.0), k0 + (sk or 0.0))
        lo, hi = np.asarray(an.ci_low_rad_s), np.asarray(an.ci_high_rad_s)
        beyond = taus > longest * (1.0 + 1e-9)
        adev = np.asarray(an.adev_rad_s)
        outside = (hi < band_lo) | (lo > band_hi)          # the two 68.3 % intervals disjoint
        dh = units.rad_s_to_deg_h
        per[str(k)] = {"taus_s": taus.tolist(), "adev_deg_h": dh(adev).tolist(),
                       "ci_low_deg_h": dh(lo).tolist(), "ci_high_deg_h": dh(hi).tolist(),
                       "model_deg_h": dh(pred).tolist(), "model_low_deg_h": dh(band_lo).tolist(),
                       "model_high_deg_h": dh(band_hi).tolist(), "beyond_window": beyond.tolist(),
                       "outside_ci": outside.tolist(),
                       "model_n_deg_rt_h": big_n, "model_n_sigma": sn,
                       "model_k_deg_h_rt_h": big_k, "model_k_sigma": sk}
        show = np.flatnonzero(beyond)
        if show.size:
            bits = [f"{taus[i]:.4g} s {dh(adev[i]):.4g} (model {dh(pred[i]):.4g} "
                    f"[{dh(band_lo[i]):.4g}, {dh(band_hi[i]):.4g}]{', outside' if outside[i] else ''})"
                    for i in show]
            said.append(f"gyro {k}: " + ", ".join(bits))
        else:
            said.append(f"gyro {k}: no tau beyond the window's {longest:.4g} s")
    hours = n * dt / 3600.0
    flagged = sum(int(np.sum(np.asarray(d["outside_ci"]) & np.asarray(d["beyond_window"])))
                  for d in per.values())
    note = (f"record of {hours:.3g} h over the memory budget {format_size(plan.budget)} (it needs "
            f"about {format_size(plan.need)}): diagnosed on its window {a_s:g}–{b_s:g} s "
            f"({(b_s - a_s) / 3600.0:.3g} h, samples 1–{window.n_samples} of {n}); the whole "
            f"record's ADEV (streamed) is, at the tau beyond the window [deg/h], beside the "
            f"window's N/K prediction: {'; '.join(said)}"
            + (f" ({flagged} tau where the whole record's ADEV and its CI lie outside the window "
               "model's 68.3 % band: the window's model does not hold there)" if flagged else
               " (its CI meets the window model's 68.3 % band at every such tau)"))
    out = {"window": {"start_s": a_s, "stop_s": b_s, "first_sample": 1,
                      "last_sample": int(window.n_samples), "samples": int(window.n_samples),
                      "hours": (b_s - a_s) / 3600.0, "budget_bytes": int(plan.budget),
                      "record_needs_bytes": float(plan.need), "record_samples": int(n),
                      "record_hours": hours, "longest_tau_s": longest},
           "whole_record": {"streamed": True, "signal": res.signal, "gyros": per,
                            "notes": list(res.notes),
                            "method": "overlapping ADEV of the whole record streamed from its file "
                                      "(every start index); model = sqrt(N^2/tau + K^2 tau/3) of the "
                                      "baseline fitted on the window, its band from N and K at "
                                      "their 1-sigma ends; ci_low/high: the streamed ADEV's own "
                                      "68.3 % CI; outside_ci = that CI and the model's band "
                                      "disjoint"}}
    if not math.isfinite(hours):
        raise InputError("the time stamps give no sample period", file=head.source)
    return out, note
