"""FDI on a record and in the chain: the ``gyroarray fdi`` object and scores
(its plot: :func:`gyroarray.reports.fdi_plots.plot_fdi`).

* :func:`analyse_measurement` — what ``gyroarray fdi MEAS.csv`` prints: the
  alarms, the false-alarm rate the thresholds are set for, the minimum
  detectable fault per gyro and kind, what was tested and what not (with
  the seconds and why), and notes (noise source, recovery).
* :func:`record_noise`, :func:`test_record` — its two stages: the per-sample
  levels and their between-part wander read on the record (a model's ARW is
  a long-τ level), and the detector run over the still parts (each with its
  common level) and the motion (after the parity self-calibration).
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
from gyroarray.chain.parity import (MIN_MOTION_DEG_S, MIN_SAMPLES_PER_UNKNOWN, fused_rate, jerk2,
                                    self_calibrate)
from gyroarray.core.errors import InputError
from gyroarray.core.limits import check_memory
from gyroarray.core.measurement import true_runs
from gyroarray.core.units import rad_s_to_deg_s
from gyroarray.effects.model import NoiseModel
from gyroarray.estimators.fdi import (FLAT_ONLY_SCALE, MIN_RECORD_SAMPLES, FaultDetector, clips_broken,
                                      common_scale, saturated_mask, FdiResult, estimate_noise, far_range_per_h,
                                      fuse, isolability, minimum_detectable, model_noise, noise_spread,
                                      parity_is_zero, parity_matrix, per_sample_noise)

__all__ = ["FDI_METRICS", "analyse_measurement", "record_noise", "test_record", "format_fdi", "recovery_errors",
           "true_faults", "score_faults", "add_fdi_metrics", "summarise_scores"]

#: Largest spread (times the white level) of the parity a moving array may leave after its fitted
#: scale-factor and axis errors for the detector to test a moving sample, its innovation widened by
#: that spread (:meth:`~gyroarray.chain.parity.ParityCalibration.excess_scale`); samples beyond it
#: are named untested (:func:`test_record`).
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
        ``{"alarms": [...], "far_per_h", "minimum_detectable": {gyro: {kind: ...}}, "tested",
        "notes"}`` (``tested``: the seconds tested still and moving, and each
        untested span with its reason, :func:`test_record`); ``calibration``
        too for a record that turns.
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
    noise, kappa, more = record_noise(meas, model, still)
    notes += more
    detector.variance_tolerance = kappa
    det = _fit(detector, meas, noise, model)
    other = [e for e in det.noise_.ignored_effects if not e.startswith("fault_")]
    if other:
        notes.append("the detector models ARW, RRW and their correlation only; also in the model: "
                     + ", ".join(other))
    res, more, info = test_record(det, z, meas.layout.H, dt, meas.time_s, still, trace=True)
    notes += more
    cal = info["calibration"]
    md = minimum_detectable(meas.layout, det.noise_, far_per_h, p_md, dt_s=dt, design=det.design_,
                            repeat_share=_repeat_share(z, still))
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
           "minimum_detectable": _md_json(md), "tested": info["tested"], "notes": notes}
    if cal is not None:                                        # only for a record that turns
        out["calibration"] = cal.to_json_dict()
    return out, res, det


def record_noise(meas, model, still) -> tuple:
    """The detector's noise for a record: (ArrayNoise or NoiseModel, κ or None, notes).

    Without a model each gyro's per-sample level is read on the record's still
    parts (:func:`~gyroarray.estimators.fdi.estimate_noise`). With one, its RRW
    and correlations are kept and its ARW, a long-τ white level, is replaced
    per gyro by the per-sample level of the still parts where that is higher
    (:func:`~gyroarray.estimators.fdi.per_sample_noise`). Either way the levels'
    wander between still parts (:func:`~gyroarray.estimators.fdi.noise_spread`,
    κ relative to the levels designed with) is allowed by the variance test.

    Raises
    ------
    InputError
        No noise in the reference span, or a model the detector cannot use
        (each naming the file).
    """
    z, dt = meas.gyro_rad_s, meas.dt_s
    notes: list[str] = []
    if model is None:
        try:
            noise, more = estimate_noise(z, meas.layout, dt, meas.ref_rad_s, still=still)
        except InputError as err:
            raise InputError(err.message, file=meas.source) from None
        notes += more
    else:
        src = getattr(model, "source", None) or meas.source
        try:
            noise = model_noise(model, meas.n_gyros)
        except InputError as err:
            raise InputError(err.message, file=src) from None
        if getattr(model, "array", None) is not None:          # its [array] correlations too
            notes.append("the model's [array] table gives the white and walk correlations of the "
                         "gyros it names")
        faults = sorted({e.effect for e in model.entries if e.effect.startswith("fault_")})
        if faults:
            notes.append(f"the model's {', '.join(faults)} entries are not used: the detector "
                         "looks for faults, it does not assume them")
        try:                                                   # the model's own R must be usable
            parity_matrix(meas.layout.H, noise.R(dt))
        except InputError as err:
            raise InputError(err.message, file=src) from None
        noise, more = per_sample_noise(noise, z, dt, still)
        notes += more
    kappa = None
    if still is not None:
        ref = np.asarray(noise.arw_rad_rt_s, dtype=float) ** 2 / dt
        k, more = noise_spread(z, dt, still, reference=ref)
        kappa = k if np.any(k > 1.0) else None
        notes += more
    return noise, kappa, notes



#: Samples of a moving stretch the detector needs to test it (one shortest variance block).
MIN_TESTED_SAMPLES = MIN_RECORD_SAMPLES


def test_record(det: FaultDetector, z: np.ndarray, H: np.ndarray, dt: float, time_s=None,
                still=None, *, trace: bool = False, test_motion: bool = False) -> tuple:
    """Run a fitted detector over a record, still parts and motion: (FdiResult, notes, info).

    Parameters
    ----------
    det : FaultDetector
        Fitted with the record's per-sample levels (:func:`record_noise`).
    z : ndarray, shape (n, N)
        Gyro outputs [rad/s].
    H : ndarray, shape (N, 3)
    dt : float
        Sample step [s].
    time_s : ndarray, shape (n,), optional
    still : ndarray of bool, shape (n,), optional
        Still samples; None (a reference rate, or too short to tell) or all
        True: the record is tested whole, as it is.
    trace : bool
    test_motion : bool
        Also test the moving samples whose spread after the calibration is at
        most :data:`MAX_MOTION_EXCESS` (default False: see Notes).

    Returns
    -------
    FdiResult, list of str, dict
        ``info``: ``calibration`` (:class:`~gyroarray.chain.parity.ParityCalibration`
        or None) and ``tested`` (:func:`_tested_json`).

    Notes
    -----
    Still parts are tested each on its own, their innovations widened by the
    part's common level c = max(1, median over the gyros of the part's
    variance over the level designed with): a level that rises on every gyro
    at once (the board after a hand rotation) is the environment, not a
    single gyro's noise fault, which leaves the median of the others alone.

    While the array turns, its parity follows the rate through each gyro's
    scale-factor and axis errors: they are fitted on the moving samples
    (:func:`~gyroarray.chain.parity.self_calibrate`) and taken out, and what
    the fit leaves is a spread √(1 + c²|ω̂|² + d²|ω̂'|²) of the white level
    (:meth:`~gyroarray.chain.parity.ParityCalibration.excess_scale`: c from the
    errors the calibration does not resolve, d from sampling instants that
    differ between the chips, a rate derivative times their timing spread).
    With ``test_motion`` the moving samples are tested with their
    innovations divided by it where it is at most :data:`MAX_MOTION_EXCESS`.
    It is off by default: on the MIMU4444 board (five records) the moving
    samples the spread model admits, the hand placements between still parts
    and the slow ends of the rotation, raise 3–8 false alarms per record,
    single-sample step statistics up to x5 the threshold (knocks whose
    parity the spread model, fitted over the whole rotation, does not
    follow). Every moving sample not tested is named with its reason: a gyro
    at its output limit (it reads the clip, not its rate), the spread beyond
    :data:`MAX_MOTION_EXCESS` (dominated by the rate's derivative, i.e.
    sampling instants that differ between the chips, or by the rate), or
    motion within it left untested. All of the motion is still watched for
    a stuck gyro (:func:`~gyroarray.estimators.fdi.flat_alarm`), which needs
    no parity model: on the raw outputs, a gyro's repeats at its own output
    limit broken first (a clipped gyro is not stuck).

    A record whose parity does not follow its motion (no significant
    calibration: a simulated or well-calibrated array) is tested whole,
    moving samples included, around its clipped samples.
    """
    z = np.asarray(z, dtype=float)
    n = z.shape[0]
    t = np.arange(n) * dt if time_s is None else np.asarray(time_s, dtype=float)
    notes: list[str] = []
    info: dict = {"calibration": None}
    if still is None or bool(np.all(still)):
        res = det.detect(z, t, trace=trace)
        info["tested"] = _tested_json(t, dt, np.ones(n, dtype=bool), np.zeros(n, dtype=bool), [])
        return res, notes, info
    still = np.asarray(still, dtype=bool)
    R = det.noise_.R(dt)
    sat, clip = saturated_mask(z)
    raw = z
    cal = _calibration(z, H, dt, R, still, sat)
    info["calibration"] = cal
    exc = np.ones(n)
    if cal is not None and cal.significant:
        # a motion-dependent parity is a calibration finding, not a fault: the fitted scale
        # factor and axis errors are taken out of the readings the detector watches
        zc = cal.correct(z, H, R)
        exc = cal.excess_scale(zc, H, dt, R)
        # the still parts keep their raw outputs: there the correction is E·ω̂ of a rate at rest
        # (a constant the trackers take as bias, plus 1 % of the fused noise), and a stuck
        # gyro's flat line must stay flat for the flat-line test
        z = np.where(still[:, None], z, zc)
        notes.append(f"calibration finding (not a fault): the parity follows the rate while the "
                     f"array turns ({100 * cal.explained:.0f} % of the moving parity variance; "
                     f"gyros off: {', '.join(map(str, cal.off)) or 'none'}); the fitted scale "
                     "factor and axis errors are removed before detection (see 'calibration', "
                     "or gyroarray parity MEAS)")
    parts: list[tuple] = []
    moving = ~still
    short = np.zeros(n, dtype=bool)
    flat_only = np.zeros(n, dtype=bool)
    if cal is None or not cal.significant:
        # the parity does not follow the motion: the record is tested through its moving samples
        # (a fault can look like motion to the still test: a step on one gyro), around the
        # clipped ones, each still run widened by its common level
        scale = np.ones(n)
        for a, b in true_runs(still):
            scale[a:b] = common_scale(z[a:b], R) if b - a >= MIN_RECORD_SAMPLES else 1.0
        for a, b in true_runs(~sat):
            if b - a >= MIN_RECORD_SAMPLES:
                parts.append((a, b, scale[a:b]))
    else:
        for a, b in true_runs(still):
            if b - a >= MIN_RECORD_SAMPLES:
                parts.append((a, b, common_scale(z[a:b], R)))
        ok = moving & ~sat & (exc <= MAX_MOTION_EXCESS)
        for a, b in true_runs(ok):
            if test_motion and b - a >= MIN_TESTED_SAMPLES:
                parts.append((a, b, np.maximum(exc[a:b], 1.0)))
            else:
                short[a:b] = True
        if not test_motion:
            # the rest of the motion is watched for a stuck gyro only: a flat line needs no
            # parity model (its innovations are divided by FLAT_ONLY_SCALE, so no parity
            # statistic can cross its threshold there)
            for a, b in true_runs(moving):
                if b - a >= MIN_RECORD_SAMPLES:
                    parts.append((a, b, FLAT_ONLY_SCALE))
                    flat_only[a:b] = True
    parts.sort(key=lambda x: x[0])
    tested = np.zeros(n, dtype=bool)
    for a, b, _ in parts:
        tested[a:b] = True
    tested &= ~flat_only
    spans = []
    for a, b in true_runs(moving & ~tested):
        spans += _untested_spans(a, b, sat, exc, short, cal, dt, z, H, R)
    info["tested"] = _tested_json(t, dt, tested, moving, spans)
    widened = [float(np.max(sc)) for _, _, sc in parts if np.max(sc) > 1.0]
    if widened:
        notes.append(f"{len(widened)} stretch(es) tested with their innovations widened by up to "
                     f"x{max(widened):.3g}: still parts whose level rose on every gyro at once, "
                     f"moving ones by the spread the calibration leaves (at most x{MAX_MOTION_EXCESS:g})")
    tt = info["tested"]
    notes.append(f"tested for faults: {tt['still_s']:.1f} s still and {tt['moving_s']:.1f} s of "
                 f"{tt['moving_s'] + tt['untested_s']:.1f} s moving; not tested: "
                 + (", ".join(f"{k} {v:.1f} s" for k, v in tt["untested_by_reason_s"].items()) or "none")
                 + " (see 'tested')")
    if flat_only.any():
        # watched by the flat line on the raw outputs (a stuck gyro's corrected output is not
        # flat), whose repeats at a gyro's own output limit are broken first: a clipped gyro
        # repeats its limit, it is not stuck
        z = clips_broken(raw, z, flat_only, clip)
    res = det.detect_parts(z, parts, t, trace=trace)
    return res, notes, info


def _calibration(z, H, dt, R, still, sat):
    """The parity self-calibration of the moving, unsaturated samples, or None (too little motion)."""
    use = ~still & ~sat
    need = MIN_SAMPLES_PER_UNKNOWN * 3 * z.shape[1]
    if use.sum() < need:
        return None
    om = fused_rate(z[use], H, R)
    d = om - om.mean(axis=0)
    if float(rad_s_to_deg_s(math.sqrt(float(np.mean(np.sum(d * d, axis=1)))))) < MIN_MOTION_DEG_S:
        return None
    return self_calibrate(z, H, dt, R=R, use=use)


def _untested_spans(a: int, b: int, sat, exc, left, cal, dt, z, H, R) -> list:
    """(start, stop, reason) pieces of an untested moving stretch [a, b)."""
    names = ("a gyro at its output limit (watched for another gyro stuck only)",
             "rate derivative x inter-chip timing: parity spread beyond the calibration "
             "(watched for a stuck gyro only)",
             "rate: parity spread beyond the calibration (watched for a stuck gyro only)",
             "motion within the calibration's spread, not tested by parity (watched for a stuck "
             "gyro only)")
    timing = np.zeros(b - a, dtype=bool)
    if cal is not None and cal.significant:
        c2, d2 = cal.excess
        om = fused_rate(z[a:b], H, R)
        timing = d2 * jerk2(om, dt) >= c2 * np.sum(om * om, axis=1)
    reason = np.where(sat[a:b], 0, np.where(left[a:b] | (exc[a:b] <= MAX_MOTION_EXCESS), 3,
                                            np.where(timing, 1, 2)))
    edges = np.r_[0, np.flatnonzero(np.diff(reason)) + 1, b - a]
    return [(a + int(i0), a + int(i1), names[int(reason[i0])]) for i0, i1 in zip(edges[:-1], edges[1:])]


def _tested_json(t, dt, tested, moving, spans) -> dict:
    """What was tested: seconds still and moving, and the untested spans with their reasons.

    Returns
    -------
    dict
        ``still_s``, ``moving_s`` (tested) and ``untested_s`` [s];
        ``untested_by_reason_s`` {reason: s}; ``untested``: list of
        ``{"start_s", "end_s", "reason"}``.
    """
    by: dict[str, float] = {}
    for a, b, why in spans:
        by[why] = by.get(why, 0.0) + (b - a) * dt
    return {"still_s": float(np.sum(tested & ~moving) * dt),
            "moving_s": float(np.sum(tested & moving) * dt),
            "untested_s": float(sum((b - a) for a, b, _ in spans) * dt),
            "untested_by_reason_s": by,
            "untested": [{"start_s": float(t[a]), "end_s": float(t[b - 1] + dt), "reason": why}
                         for a, b, why in spans]}


def _repeat_share(z, still):
    """Share of each gyro's still samples that repeat the previous output (None: not known)."""
    if still is None:
        return None
    keep = np.asarray(still, dtype=bool)[1:] & np.asarray(still, dtype=bool)[:-1]
    if keep.sum() < MIN_RECORD_SAMPLES:
        return None
    return np.mean(z[1:][keep] == z[:-1][keep], axis=0)


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
                 "tested": _all_tested(meas), "notes": notes}, res, None)
    det = _fit(detector, meas, model, model)
    md = minimum_detectable(meas.layout, det.noise_, far_per_h, p_md, dt_s=meas.dt_s,
                            design=det.design_)
    notes.append(f"minimum_detectable: found with probability {1 - p_md:g} at {far_per_h:g} false "
                 f"alarms/h; drift within {md['drift_window_s']:g} s; stuck_static_s for a gyro "
                 "stuck at rest; the record itself has none of the noise the model gives")
    return ({"alarms": [], "far_per_h": float(far_per_h), "minimum_detectable": _md_json(md),
             "tested": _all_tested(meas), "notes": notes}, res, det)


def _all_tested(meas) -> dict:
    """``tested`` of a record whose parity is zero: every sample answered (no fault)."""
    n = meas.gyro_rad_s.shape[0]
    return _tested_json(np.asarray(meas.time_s), meas.dt_s, np.ones(n, dtype=bool),
                        np.zeros(n, dtype=bool), [])


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
    tested = out.get("tested")
    if tested is not None:
        lines.append(f"tested for faults: {tested['still_s']:.1f} s still, {tested['moving_s']:.1f} s "
                     f"moving; not tested: {tested['untested_s']:.1f} s")
        for why, sec in tested["untested_by_reason_s"].items():
            spans = [u for u in tested["untested"] if u["reason"] == why]
            shown = ", ".join(f"{u['start_s']:.2f}-{u['end_s']:.2f}" for u in spans[:6])
            more = f" and {len(spans) - 6} more" if len(spans) > 6 else ""
            lines.append(f"  {sec:7.1f} s  {why}: {shown}{more} s")
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
