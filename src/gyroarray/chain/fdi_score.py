"""FDI on a record and in the chain: the ``gyroarray fdi`` object and scores
(its plot: :func:`gyroarray.reports.fdi_plots.plot_fdi`).

* :func:`analyse_measurement` — what ``gyroarray fdi MEAS.csv`` prints: the
  alarms, the false-alarm rate the thresholds are set for, the minimum
  detectable fault per gyro and kind, and notes (noise source, recovery).
* :func:`recovery_errors` — the fused rate before, during and after each
  exclusion, with and without the recovery.
* :func:`score_faults` — for a simulated run whose model holds ``fault_*``
  effects: detection delay, missed detection, false alarms per hour, correct
  isolation and kind, onset error, fused error with and without recovery.
  :func:`add_fdi_metrics` puts them in the chain's table (``fdi`` rows);
  :func:`summarise_scores` aggregates runs (missed-detection probability).

Units: SI inside; deg/s, deg/s², s at the edges (keys say which).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from gyroarray.analysis.motion import still_mask
from gyroarray.chain.parity import calibrate_measurement
from gyroarray.core.errors import InputError
from gyroarray.core.limits import check_memory
from gyroarray.core.measurement import true_runs
from gyroarray.core.units import rad_s_to_deg_s
from gyroarray.effects.model import NoiseModel
from gyroarray.estimators.fdi import (MIN_RECORD_SAMPLES, FaultDetector, FdiResult, estimate_noise, far_range_per_h,
                                      fuse, isolability, minimum_detectable, model_noise, noise_spread,
                                      parity_is_zero)

__all__ = ["FDI_METRICS", "analyse_measurement", "format_fdi", "recovery_errors",
           "true_faults", "score_faults", "add_fdi_metrics", "summarise_scores"]

#: Largest spread (times the white level) of the parity a moving array may leave after its fitted
#: scale-factor and axis errors for the detector to watch it while it turns, widened by that spread
#: (:meth:`~gyroarray.chain.parity.ParityCalibration.excess_scale`); beyond it only the still parts
#: are tested.
MAX_MOTION_EXCESS = 2.0

#: Columns :func:`add_fdi_metrics` adds to the chain's table (``gyroarray check`` may bound them).
FDI_METRICS = ("fdi_detected", "fdi_detection_delay_s", "fdi_onset_error_s", "fdi_correct_isolation",
               "fdi_correct_kind", "fdi_false_alarms_per_h", "fdi_fused_dev_during_deg_s",
               "fdi_fused_dev_after_recovered_deg_s", "fdi_fused_dev_after_unrecovered_deg_s")


# -- the measurement ------------------------------------------------------------

def analyse_measurement(meas, model=None, *, far_per_h: float = 0.01, p_md: float = 0.001):
    """Run the detector on a measurement: the ``gyroarray fdi`` JSON object.

    Parameters
    ----------
    meas : gyroarray.core.measurement.Measurement
    model : NoiseModel, optional
        ARW, RRW and correlation of the gyros; without it they are estimated
        from the record (:func:`gyroarray.estimators.fdi.estimate_noise`).
    far_per_h : float
        False-alarm rate the thresholds are set for [1/h].
    p_md : float
        Missed-detection probability of ``minimum_detectable`` [-].

    Returns
    -------
    out : dict
        ``{"alarms": [...], "far_per_h", "minimum_detectable": {gyro: {kind: ...}}, "notes"}``.
    result : FdiResult
    detector : FaultDetector or None
        None for a record whose parity is zero (below), analysed without a model.

    Raises
    ------
    InputError
        Checked before any work: ``far_per_h`` outside :func:`far_range_per_h`
        (the argument and its range named), fewer than 4 gyros, fewer than
        :data:`~gyroarray.estimators.fdi.MIN_RECORD_SAMPLES` samples, more
        memory than the budget (:func:`gyroarray.core.limits.check_memory`); a
        model the detector cannot use (named with its file).

    Notes
    -----
    The test windows are bounded by the record: the drift and variance
    windows (600 s and 40 s) are cut to the record's span, and every window
    to :data:`~gyroarray.estimators.fdi.MAX_WINDOW_SAMPLES` samples, so the
    work and memory grow with the record, never with the sample rate alone.

    A record whose outputs are exactly consistent with one body rate at
    every sample (identical gyros, constant or noise-free outputs:
    :func:`~gyroarray.estimators.fdi.parity_is_zero`) has **no fault**: any
    single-gyro fault would make the parity non-zero. That is the answer,
    with a note; the statistics are not run (they would read the missing
    noise as a fault of every direction at once). Without a model its
    minimum detectable faults are null (no noise to size them from).
    """
    z = meas.gyro_rad_s
    dt = meas.dt_s
    far_lo, far_hi = far_range_per_h(dt)
    if not (math.isfinite(far_per_h) and far_per_h > 0):
        raise InputError(f"--far-per-h must be a rate > 0 [1/h] (between {far_lo:g} and "
                         f"{far_hi:.4g} for this record), got {far_per_h!r}")
    if not far_lo <= far_per_h <= far_hi:
        raise InputError(f"--far-per-h must be between {far_lo:g} and {far_hi:.4g} false alarms/h "
                         f"at this record's {1.0 / dt:.6g} Hz (at most one per 100 samples), got "
                         f"{far_per_h!r}", file=meas.source)
    notes = list(meas.notes)
    if meas.n_gyros < 4:
        raise InputError(f"fault detection needs at least 4 gyros, the measurement has {meas.n_gyros}",
                         file=meas.source)
    n = z.shape[0]
    if n < MIN_RECORD_SAMPLES:
        raise InputError(f"fault detection needs at least {MIN_RECORD_SAMPLES} samples (one "
                         f"{MIN_RECORD_SAMPLES - 1}-sample variance block after the first), the "
                         f"record has {n}: give a longer record", file=meas.source)
    check_memory(_memory_needed(n, meas.n_gyros),
                 f"fault detection on {n} samples x {meas.n_gyros} gyros",
                 "split the record into shorter ones", file=meas.source)
    span_s = (n - 1) * dt                                      # windows bounded by the record
    detector = FaultDetector(far_per_h=far_per_h, drift_window_s=min(600.0, span_s),
                             variance_window_s=min(40.0, span_s))
    if parity_is_zero(z, meas.layout.H):
        return _no_parity_noise(meas, model, detector, far_per_h, p_md, notes)
    still = _still(meas)
    if model is None:
        try:
            noise, more = estimate_noise(z, meas.layout, dt, meas.ref_rad_s, still=still)
        except InputError as err:
            raise InputError(err.message, file=meas.source) from None
        notes += more
        if still is not None:
            kappa, more = noise_spread(z, dt, still)
            detector.variance_tolerance = kappa if np.any(kappa > 1.0) else None
            notes += more
    else:
        noise = model
        if getattr(model, "array", None) is not None:          # its [array] correlations too
            try:
                noise = model_noise(model, meas.n_gyros)
            except InputError as err:
                raise InputError(err.message, file=getattr(model, "source", None) or meas.source) from None
            notes.append("the model's [array] table gives the white and walk correlations of the "
                         "gyros it names")
        faults = sorted({e.effect for e in model.entries if e.effect.startswith("fault_")})
        if faults:
            notes.append(f"the model's {', '.join(faults)} entries are not used: the detector "
                         "looks for faults, it does not assume them")
    det = _fit(detector, meas, noise, model)
    other = [e for e in det.noise_.ignored_effects if not e.startswith("fault_")]
    if other:
        notes.append("the detector models ARW, RRW and their correlation only; also in the model: "
                     + ", ".join(other))
    cal, scale, parts = None, None, None
    if still is not None and not still.all():
        R = det.noise_.R(dt)
        cal = calibrate_measurement(meas, R=R, still=still)
        if cal is not None and cal.significant:
            # a motion-dependent parity is a calibration finding, not a fault: the fitted scale
            # factor and axis errors are taken out of the readings the detector watches
            z = cal.correct(z, meas.layout.H, R)
            notes.append(f"calibration finding (not a fault): the parity follows the rate while the "
                         f"array turns ({100 * cal.explained:.0f} % of the moving parity variance; "
                         f"gyros off: {', '.join(map(str, cal.off)) or 'none'}); the fitted scale "
                         "factor and axis errors are removed before detection (see 'calibration', "
                         "or gyroarray parity MEAS)")
            scale = cal.excess_scale(z, meas.layout.H, dt, R)
            if float(scale.max()) > MAX_MOTION_EXCESS:
                # what the motion leaves beyond them is not white noise of a known level (e.g.
                # sampling instants that differ between the gyros): the moving parts are not
                # tested, the still parts are, each on its own
                parts = [(a, b) for a, b in true_runs(still)]
                moving = float(np.sum(~still)) * dt
                notes.append(f"the parity left after them still follows the motion (its spread up "
                             f"to x{float(scale.max()):.3g} the white level at the fastest "
                             f"changes): the {moving:.1f} s where the array turns are not tested "
                             "for faults, the still parts are (each on its own)")
                scale = None
            elif float(scale.max()) > 1.0:
                notes.append(f"the parity left after them grows with the motion: the tests are "
                             f"widened by up to x{float(scale.max()):.3g} where the array turns")
    if parts is not None:
        res = det.detect_parts(z, parts, meas.time_s, trace=True)
    else:
        res = det.detect(z, meas.time_s, trace=True, innovation_scale=scale)
    md = minimum_detectable(meas.layout, det.noise_, far_per_h, p_md, dt_s=dt, design=det.design_)
    notes.append(f"minimum_detectable: found with probability {1 - p_md:g} at {far_per_h:g} false "
                 f"alarms/h; drift within {md['drift_window_s']:g} s; stuck_static_s for a gyro "
                 "stuck at rest")
    iso = det.design_.groups
    if any(len(g) > 1 for g in iso):
        shared = "; ".join("gyros " + ", ".join(str(det.design_.gyros[p] + 1) for p in g)
                           for g in iso if len(g) > 1)
        notes.append(f"not isolable by parity: {shared} share one parity direction")
    notes += list(res.notes)
    notes += _recovery_notes(z, meas, det, res)
    out = {"alarms": [a.to_json_dict() for a in res.alarms], "far_per_h": float(far_per_h),
           "minimum_detectable": _md_json(md), "notes": notes}
    if cal is not None:                                        # only for a record that turns
        out["calibration"] = cal.to_json_dict()
    return out, res, det


def _still(meas):
    """Still samples of a record without a reference rate (None: a reference, or too short)."""
    if meas.ref_rad_s is not None:
        return None
    try:
        return still_mask(meas.gyro_rad_s, meas.layout.H, meas.dt_s)
    except InputError:
        return None


def _memory_needed(n: int, n_gyros: int) -> float:
    """Peak memory of fault detection on n samples of N gyros [bytes] (generous).

    The scan, the fits after an alarm and the recovery each keep about a
    dozen (n, N) arrays of float64; the window weights of the thresholds are
    at most n × (N − 3) (windows bounded by the record).
    """
    return 8.0 * n * (16.0 * n_gyros + 48.0)


def _fit(detector, meas, noise, model):
    """``detector.fit`` with a refusal that names the model's file (or the record's)."""
    try:
        return detector.fit(meas.layout, noise, meas.dt_s)
    except InputError as err:
        if err.file is not None:
            raise
        src = getattr(model, "source", None) if model is not None else None
        raise InputError(err.message, file=src or meas.source) from None


def _no_parity_noise(meas, model, detector, far_per_h, p_md, notes):
    """The answer for a record whose parity is zero at every sample: no fault (see Notes above)."""
    notes.append("the gyros' outputs are exactly consistent with one body rate at every sample "
                 "(parity zero to rounding: identical, constant or noise-free outputs?): no "
                 "single-gyro fault is present, since any would make the parity non-zero")
    res = FdiResult(alarms=(), exclusions=(), time_s=np.asarray(meas.time_s), trace={},
                    notes=())
    if model is None:
        iso = isolability(meas.layout)                         # as minimum_detectable's
        single = {j for g in iso["groups"] if len(g) == 1 for j in g}
        md = {str(g): {"step_deg_s": None, "drift_deg_s2": None, "noise_ratio": None,
                       "stuck_static_s": None, "isolable": iso["parity_dim"] >= 2 and g in single}
              for g in range(1, meas.n_gyros + 1)}
        notes.append("minimum_detectable: not available, the record has no noise to size the "
                     "thresholds from (give --model MODEL.toml with the gyros' ARW and RRW)")
        return ({"alarms": [], "far_per_h": float(far_per_h), "minimum_detectable": md,
                 "notes": notes}, res, None)
    det = _fit(detector, meas, model, model)
    md = minimum_detectable(meas.layout, det.noise_, far_per_h, p_md, dt_s=meas.dt_s,
                            design=det.design_)
    notes.append(f"minimum_detectable: found with probability {1 - p_md:g} at {far_per_h:g} false "
                 f"alarms/h; drift within {md['drift_window_s']:g} s; stuck_static_s for a gyro "
                 "stuck at rest; the record itself has none of the noise the model gives")
    return ({"alarms": [], "far_per_h": float(far_per_h), "minimum_detectable": _md_json(md),
             "notes": notes}, res, det)


def _md_json(md: dict) -> dict:
    out = {}
    for g in range(md["step_rad_s"].size):
        out[str(g + 1)] = {"step_deg_s": _finite(rad_s_to_deg_s(md["step_rad_s"][g])),
                           "drift_deg_s2": _finite(rad_s_to_deg_s(md["drift_rad_s2"][g])),
                           "noise_ratio": _finite(md["noise_ratio"][g]),
                           "stuck_static_s": _finite(md["stuck_static_s"][g]),
                           "isolable": bool(md["isolable"][g])}
    return out


def _finite(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _recovery_notes(z, meas, det, res) -> list:
    out = []
    truth = meas.ref_rad_s
    for a, row in zip(res.alarms, recovery_errors(z, meas.layout.H, det.noise_, meas.dt_s,
                                                  res.exclusions, res.alarms, meas.time_s, truth)):
        what = "error vs ref" if truth is not None else "shift of the fused rate by the fault"
        parts = []
        for span in ("before", "during", "after"):
            v = row[span]
            if v["n"]:
                if truth is not None:
                    parts.append(f"{span} {v['recovered_deg_s']:.4g} (without recovery "
                                 f"{v['unrecovered_deg_s']:.4g})")
                else:
                    parts.append(f"{span} {v['shift_deg_s']:.4g}")
        out.append(f"fused rate at alarm {a.detected_s:.2f} s, {what} [deg/s rms of the worst axis]: "
                   + ", ".join(parts))
    return out


def recovery_errors(z, H, noise, dt_s, exclusions, alarms, time_s, truth_rad_s=None) -> list:
    """Fused rate before (to the onset), during (onset to exclusion) and after each alarm.

    Parameters
    ----------
    z : ndarray, shape (n, N)
    H : ndarray, shape (N, 3)
    noise : ArrayNoise
    dt_s : float
    exclusions : sequence of (int, int)
    alarms : sequence of Alarm
    time_s : ndarray, shape (n,)
    truth_rad_s : ndarray, shape (n, 3), optional
        Body rate truth (reference); without it only the shift is given.

    Returns
    -------
    list of dict
        Per alarm and span: ``n`` samples, ``recovered_deg_s`` and
        ``unrecovered_deg_s`` (rms error of the worst axis, with a reference),
        ``shift_deg_s`` (rms of recovered − unrecovered, worst axis).
    """
    rec = fuse(z, H, noise, dt_s, exclusions)
    raw = fuse(z, H, noise, dt_s, ())
    t = np.asarray(time_s)
    n = t.size
    out = []
    for a in alarms:
        on = int(np.searchsorted(t, a.onset_s))
        off = n if a.isolated_s is None else int(np.searchsorted(t, a.isolated_s, side="right"))
        spans = {"before": slice(0, on), "during": slice(on, off), "after": slice(off, n)}
        row = {}
        for name, sl in spans.items():
            m = sl.stop - sl.start
            d: dict[str, float] = {"n": int(max(m, 0))}
            if m > 0:
                d["shift_deg_s"] = _rms_worst(rec[sl] - raw[sl])
                if truth_rad_s is not None:
                    d["recovered_deg_s"] = _rms_worst(rec[sl] - truth_rad_s[sl])
                    d["unrecovered_deg_s"] = _rms_worst(raw[sl] - truth_rad_s[sl])
            row[name] = d
        out.append(row)
    return out


def _rms_worst(e: np.ndarray) -> float:
    return float(rad_s_to_deg_s(np.max(np.sqrt(np.mean(e * e, axis=0)))))


def format_fdi(out: dict, source: str = "") -> str:
    """The ``gyroarray fdi`` object as a readable table."""
    lines = [f"{source}: {len(out['alarms'])} alarm(s) at {out['far_per_h']:g} false alarms/h"]
    if out["alarms"]:
        lines.append(f"  {'gyro':>4} {'kind':<6} {'onset_s':>10} {'detected_s':>11} {'size':>11} "
                     f"{'unit':<8} isolated")
        for a in out["alarms"]:
            g = "-" if a["gyro"] is None else str(a["gyro"])
            lines.append(f"  {g:>4} {a['kind']:<6} {a['onset_s']:>10.3f} {a['detected_s']:>11.3f} "
                         f"{a['size']:>11.4g} {a['size_unit']:<8} "
                         f"{'yes' if a['isolated'] else 'detected, not isolable'}")
            lines.append(f"       {a['evidence']}")
    else:
        lines.append("  no fault found")
    lines.append("minimum detectable (probability of detection as in the notes):")
    lines.append(f"  {'gyro':>4} {'step_deg_s':>11} {'drift_deg_s2':>13} {'noise_ratio':>12} "
                 f"{'stuck_static_s':>15} isolable")
    for g, d in out["minimum_detectable"].items():
        def f(v, fmt):
            return "-" if v is None else format(v, fmt)
        lines.append(f"  {g:>4} {f(d['step_deg_s'], '.4g'):>11} {f(d['drift_deg_s2'], '.4g'):>13} "
                     f"{f(d['noise_ratio'], '.4g'):>12} {f(d['stuck_static_s'], '.4g'):>15} "
                     f"{'yes' if d['isolable'] else 'no'}")
    lines += [f"note: {n}" for n in out["notes"]]
    return "\n".join(lines)


# -- scores of simulated runs ------------------------------------------------------

def true_faults(model) -> list[dict]:
    """The ``fault_*`` entries of a noise model: ``{"gyro", "kind", "start_s", "size"}`` (spec units)."""
    out = []
    for e in model.entries:
        if e.effect.startswith("fault_"):
            kind = e.effect[len("fault_"):]
            size = {"step": "size_deg_s", "drift": "rate_deg_s2", "noise": "ratio"}.get(kind)
            out.append({"gyro": e.gyro, "kind": kind, "start_s": float(e.params["start_s"]),
                        "size": None if size is None else float(e.params[size])})
    return sorted(out, key=lambda f: f["start_s"])


def score_faults(result, faults: list[dict], time_s, *, readings=None, clean_readings=None,
                 H=None, noise=None, dt_s=None) -> dict:
    """Scores of one run against its true faults.

    Parameters
    ----------
    result : FdiResult
    faults : list of dict
        :func:`true_faults`.
    time_s : ndarray
    readings, clean_readings : ndarray, shape (n, N), optional
        The run, and the same run without its faults (same noise draws: the
        simulator's streams do not depend on the fault entries).
    H, noise, dt_s : optional
        Layout axes, ArrayNoise and period for the fusion.

    Returns
    -------
    dict
        ``fdi_detected`` (1/0, first fault; NaN without fault),
        ``fdi_detection_delay_s``, ``fdi_onset_error_s``,
        ``fdi_correct_isolation`` (1 right gyro, 0 wrong gyro, NaN not
        isolated), ``fdi_correct_kind``, ``fdi_false_alarms_per_h`` (alarms
        before the first fault's start, per hour of that clean part), and how
        far the fused rate moves from the fault-free all-gyro GLS (rms of the
        worst axis [deg/s]): ``fdi_fused_dev_during_deg_s`` (onset to
        exclusion), ``fdi_fused_dev_after_recovered_deg_s`` (after it, GLS
        without the gyro: the price of N − 1) and
        ``fdi_fused_dev_after_unrecovered_deg_s`` (after it, had the gyro
        stayed in).
    """
    t = np.asarray(time_s, dtype=float)
    t0, t1 = float(t[0]), float(t[-1])
    first = faults[0] if faults else None
    clean_end = min(first["start_s"], t1) if first else t1
    false = [a for a in result.alarms if a.detected_s < clean_end]
    hours = max(clean_end - t0, 0.0) / 3600.0
    nan = math.nan
    out = {k: nan for k in FDI_METRICS}
    out["fdi_false_alarms_per_h"] = len(false) / hours if hours > 0 else nan
    if first is None or first["start_s"] > t1:
        return out
    hits = [a for a in result.alarms if a.detected_s >= first["start_s"]]
    if not hits:
        out["fdi_detected"] = 0.0
        return out
    a = hits[0]
    out["fdi_detected"] = 1.0
    out["fdi_detection_delay_s"] = a.detected_s - first["start_s"]
    out["fdi_onset_error_s"] = a.onset_s - first["start_s"]
    out["fdi_correct_isolation"] = nan if a.gyro is None else float(a.gyro == first["gyro"])
    out["fdi_correct_kind"] = float(a.kind == first["kind"])
    if readings is not None and clean_readings is not None:
        out.update(_fused_deviation(result, a, first, t, readings, clean_readings, H, noise, dt_s))
    return out


def _fused_deviation(result, alarm, fault, t, z, z_clean, H, noise, dt_s) -> dict:
    ref = fuse(z_clean, H, noise, dt_s, ())                   # fault-free, every gyro
    raw = fuse(z, H, noise, dt_s, ())
    rec = fuse(z, H, noise, dt_s, result.exclusions)
    on = int(np.searchsorted(t, fault["start_s"]))
    off = t.size if alarm.isolated_s is None else int(np.searchsorted(t, alarm.isolated_s, side="right"))
    out = {}
    if off > on:
        out["fdi_fused_dev_during_deg_s"] = _rms_worst(raw[on:off] - ref[on:off])
    if off < t.size:
        out["fdi_fused_dev_after_recovered_deg_s"] = _rms_worst(rec[off:] - ref[off:])
        out["fdi_fused_dev_after_unrecovered_deg_s"] = _rms_worst(raw[off:] - ref[off:])
    return out


def add_fdi_metrics(run_result, scenario, sim_result, detector):
    """The chain's hook: the ``fdi`` rows of ``run_result.table`` gain :data:`FDI_METRICS`.

    Parameters
    ----------
    run_result : gyroarray.chain.run.RunResult
    scenario : Scenario
    sim_result : SimulationResult
    detector : FaultDetector
        Fitted on the scenario's layout and model.

    Returns
    -------
    RunResult
        A copy; other estimators' rows get NaN in the new columns. With
        faults, the scenario is simulated once more without them (same seed,
        same noise draws) for the fused-rate deviations.
    """
    from gyroarray.sim.scenario import simulate  # deferred: the simulator loads mujoco, only for a simulated run
    truth = sim_result.truth
    z = sim_result.readings_rad_s
    res = detector.detect(z, truth.time_s)
    faults = true_faults(scenario.model)
    z_clean = None
    if faults:
        kept = tuple(e for e in scenario.model.entries if not e.effect.startswith("fault_"))
        clean = replace(scenario, model=NoiseModel(kept, description=scenario.model.description))
        z_clean = simulate(clean).readings_rad_s
    sc = score_faults(res, faults, truth.time_s, readings=z, clean_readings=z_clean,
                      H=scenario.layout.H, noise=detector.noise_, dt_s=detector.dt_s_)
    table = run_result.table.copy()
    is_fdi = table["estimator"] == "fdi"
    for k in FDI_METRICS:
        table[k] = np.where(is_fdi, sc[k], np.nan)
    notes = tuple(run_result.notes) + tuple(f"fdi: {a.evidence}" for a in res.alarms)
    return replace(run_result, table=table, notes=notes)


def summarise_scores(scores: list[dict]) -> dict:
    """Across runs: missed-detection probability, mean delay, isolation and kind rates, FAR.

    Returns
    -------
    dict
        ``p_missed`` (share of runs with a fault not detected), ``delay_s_mean``,
        ``delay_s_median``, ``correct_isolation`` (share of isolated alarms on
        the right gyro), ``isolated_share``, ``correct_kind``,
        ``false_alarms_per_h`` (mean of the runs' rates), ``runs``.
    """
    det = np.array([s["fdi_detected"] for s in scores], dtype=float)
    det = det[np.isfinite(det)]
    delay = np.array([s["fdi_detection_delay_s"] for s in scores], dtype=float)
    delay = delay[np.isfinite(delay)]
    iso = np.array([s["fdi_correct_isolation"] for s in scores], dtype=float)
    kind = np.array([s["fdi_correct_kind"] for s in scores], dtype=float)
    far = np.array([s["fdi_false_alarms_per_h"] for s in scores], dtype=float)
    return {"runs": len(scores),
            "p_missed": float(1.0 - det.mean()) if det.size else math.nan,
            "delay_s_mean": float(delay.mean()) if delay.size else math.nan,
            "delay_s_median": float(np.median(delay)) if delay.size else math.nan,
            "correct_isolation": float(np.nanmean(iso)) if np.isfinite(iso).any() else math.nan,
            "isolated_share": float(np.mean(np.isfinite(iso))) if iso.size else math.nan,
            "correct_kind": float(np.nanmean(kind)) if np.isfinite(kind).any() else math.nan,
            "false_alarms_per_h": float(np.nanmean(far)) if np.isfinite(far).any() else math.nan}
