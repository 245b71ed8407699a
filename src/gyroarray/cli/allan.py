"""``gyroarray allan`` and ``gyroarray davar``: the Allan (or Hadamard) deviation of each gyro with
its noise fit, and the dynamic Allan deviation of one gyro, with their text.

numpy and the analysis modules (numba) are imported inside the commands, so that building the
parser (``gyroarray --help``, every other command) does not load them.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from gyroarray.cli.common import add_bag_options, bag_options, add_force, check_plot, measurement_inputs, positive_int, stream_reason
from gyroarray.core.errors import InputError

__all__ = ["MAX_TAUS", "MIN_STILL_PART", "REF_STILL_RAD_S", "SENSORS", "CRB_TERMS", "DISAGREE_Z",
           "METHODS", "ESTIMATE_CANDIDATES", "MIN_WHITTLE_ORDINATES", "AUTO_RULE", "efficient_estimates",
           "OPTIMISTIC_EFFICIENCY", "UNRESOLVABLE_CRB", "accel_parts", "accel_noise", "add_parser",
           "allan_signal", "cmd_allan", "cmd_davar", "datasheet_converters", "noise_bounds", "too_short_notes"]


#: Most taus ``allan --taus`` may ask for (an octave grid of 1e9 samples has 30).
MAX_TAUS = 10_000
#: Shortest still part [samples] ``allan`` analyses (as ``fuse``'s ``MIN_PART``).
MIN_STILL_PART = 256
#: The sensors ``allan --sensor`` analyses: the gyros, the accelerometer (``acc_x..z``), or both.
SENSORS = ("gyro", "acc", "all")
#: Largest reference rate [rad/s] (0.2 deg/h) at which the table counts as still for the
#: accelerometer: while it turns, gravity's projection moves and is no noise.
REF_STILL_RAD_S = 1e-6


def _parse_taus(text: str):
    """``octave``, a count of log-spaced taus, or a comma-separated list of taus [s]."""
    if text == "octave":
        return "octave"
    if "," in text:
        if text.count(",") >= MAX_TAUS:
            raise InputError(f"--taus lists {text.count(',') + 1} taus; at most {MAX_TAUS}")
        try:
            taus = [float(v) for v in text.split(",")]
        except ValueError:
            raise InputError(f"--taus list must hold numbers of seconds, got {text[:60]!r}") from None
        if not all(math.isfinite(t) and t > 0 for t in taus):
            raise InputError("--taus list must hold finite taus > 0 s")
        from gyroarray.analysis.allan import MAX_FIT_TAUS  # deferred: numba (a --taus list only)
        if len(taus) > MAX_FIT_TAUS:
            raise InputError(f"--taus lists {len(taus)} taus; the noise fit takes at most "
                             f"{MAX_FIT_TAUS} (its cost grows with the cube of the count): list "
                             "fewer, or give a count (N) to have them spread log-evenly")
        return taus
    try:
        count = int(text)
    except ValueError:
        raise InputError("--taus must be 'octave', a whole number of log-spaced taus or a "
                         f"comma-separated list of taus in s, got {text[:60]!r}") from None
    if not 2 <= count <= MAX_TAUS:
        raise InputError(f"--taus asks for {count} log-spaced taus; give 2 to {MAX_TAUS}")
    return count


def _parse_band(text: str) -> tuple:
    """``LO,HI``: the Whittle fit's frequency band [Hz], 0 <= LO < HI."""
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--band must be LO,HI in Hz (two numbers), got {text[:60]!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi):
        raise argparse.ArgumentTypeError(f"--band {text}: give 0 <= LO < HI Hz")
    return lo, hi


def allan_signal(meas, *, raw: bool = False):
    """The rate series the Allan analysis looks at, per gyro [rad/s].

    With a reference rate that moves, the gyro output minus the projected
    reference (gyro − H·ref) is analysed, so the table's motion does not
    swamp the noise; otherwise (static, no reference, or ``raw``) the gyro
    output itself. Returns ``(signal (n, N), description)``.
    """
    gyro = meas.gyro_rad_s
    ref = meas.ref_rad_s
    if raw or ref is None or not ref.any():
        return gyro, "gyro output"
    return gyro - ref @ meas.layout.H.T, "gyro output minus layout·ref (motion removed)"


def cmd_allan(args) -> tuple[dict, str]:
    # deferred: numpy and the analysis (numba) load only when the command runs (a fast --help)
    from gyroarray.analysis.allan import fit_tau_count
    from gyroarray.analysis.deviations import RANGE_KIND, canonical_kind
    from gyroarray.analysis.pipeline import detect_pipeline
    from gyroarray.core.measurement import read_measurement
    from gyroarray.reports.allan_plots import gyro_panel, plot_allan_panels
    kind = canonical_kind(args.kind)
    taus = _parse_taus(args.taus)
    check_plot(args, inputs=measurement_inputs(args))
    sensor = getattr(args, "sensor", "gyro")
    if sensor == "acc" and args.gyro is not None:
        raise InputError(f"--gyro {args.gyro} picks a gyro, and --sensor acc analyses the accelerometer "
                         "(acc_x..z, every axis): leave out --gyro, or use --sensor all")
    streamed = stream_reason(args)                    # a record too long for memory: in chunks
    if streamed is not None:
        if sensor != "gyro":
            raise InputError(f"--sensor {sensor} needs the record in memory, and this one is streamed "
                             f"({streamed}): analyse the gyros (--sensor gyro) or a cut of the record",
                             file=str(args.measurement))
        return _cmd_allan_streamed(args, kind, taus, streamed)
    # --gaps: dropped samples kept as gaps, never filled; _analysed_parts pools around them
    meas = read_measurement(args.measurement, repair=args.repair, gaps=bool(args.gaps), **bag_options(args))
    if sensor != "gyro" and not meas.has_acc:
        raise InputError(f"--sensor {sensor}: the record has no accelerometer columns (acc_x, acc_y, acc_z "
                         "[m/s²]); --sensor gyro analyses its gyros", file=str(args.measurement))
    if sensor == "acc":
        out, text, acc_analyses = _cmd_allan_acc(args, meas, kind, taus)
        if args.plot is not None:       # the accelerometer's panel alone, in m/s²
            path, _ = plot_allan_panels([_accel_panel(out, acc_analyses)], args.plot, force=args.force)
            out["plot"] = str(path)
            text += f"\nwrote {path} (the accelerometer's curves, in m/s²)"
        return out, text
    if args.gyro is not None and not 1 <= args.gyro <= meas.n_gyros:
        raise InputError(f"--gyro {args.gyro} is out of range: the measurement has "
                         f"gyros 1..{meas.n_gyros}", file=str(args.measurement))
    gyros = [args.gyro] if args.gyro is not None else list(range(1, meas.n_gyros + 1))
    signal, what = allan_signal(meas, raw=args.raw)
    parts, part_notes, part_info = _analysed_parts(meas, gyros, args)
    tau_note = None
    if isinstance(taus, int):       # within what the record gives and the noise fit takes
        try:
            taus, tau_note = fit_tau_count(max(b - a for a, b in parts) + 1, meas.dt_s, taus,
                                           RANGE_KIND[kind])
        except InputError:          # too short for any tau: said per gyro below
            pass
    signal, spike_notes, spike_info = _spikes(meas, signal, gyros, parts, taus, kind, args)
    analyses, skipped = _allan_each(meas, signal, gyros, taus, args, kind=kind, parts=parts)
    notes = [*meas.notes, *part_notes, *([tau_note] if tau_note else []),
             *_reference_noise_notes(meas, what != "gyro output", gyros), *skipped.values(),
             *spike_notes, *_white_notes(meas, signal, parts, analyses)]
    pipe = detect_pipeline(meas.gyro_rad_s, meas.dt_s)        # held samples, a decimation filter
    if pipe.processed:
        notes.append(f"{pipe.verdict()}: the ADEV there (ARW, quantization, a hump) is the pipeline's; "
                     f"read the noise terms at τ above {pipe.tau_s:.2g} s")
    out = {"gyros": {str(k): a.to_json_dict() for k, a in analyses.items()},
           "signal": what, "notes": notes,
           "not_analysed": {str(k): why for k, why in skipped.items()}}
    white = _white_levels(signal, meas.dt_s, parts, analyses)
    for k, w in white.items():
        out["gyros"][str(k)]["white_level"] = w
    bound_lines = noise_bounds(signal if getattr(args, "whittle", False) else None, meas.dt_s, parts, analyses,
                               out["gyros"], notes)
    method = getattr(args, "method", "auto")
    est_lines = efficient_estimates(signal if method != "allan" else None, meas.dt_s, parts, analyses,
                                    out["gyros"], notes, method=method, band=getattr(args, "band", None))
    out["method"] = {"asked": method, "rule": AUTO_RULE}
    if pipe.processed:
        out["pipeline"] = pipe.to_json_dict()
    if part_info is not None:
        out["analysed_parts"] = part_info
    if spike_info:
        out["spikes"] = spike_info
    lines = [f"{args.measurement}: {meas.n_samples} samples at {1 / meas.dt_s:g} Hz, "
             f"{meas.n_gyros} gyros; analysed: {what}", *[f"note: {n}" for n in notes]]
    for k, a in analyses.items():
        lines.append(_format_allan(k, a.to_json_dict()))
        if k in white:
            w = white[k]
            lines.append(f"  white level: N = ADEV({w['tau_s']:.4g} s)·√τ = {w['n_deg_rt_h']:.4g} ± "
                         f"{w['n_deg_rt_h_sigma']:.2g} deg/√h (the one fit, fuse and the [array] table read)")
        lines += bound_lines.get(k, [])
        lines += est_lines.get(k, [])
    if sensor == "all":
        acc_out, acc_text, acc_analyses = _cmd_allan_acc(args, meas, kind, taus)
        out["accelerometer"] = acc_out
        lines.append(acc_text)
    if args.plot is not None:
        panels = [gyro_panel({f"gyro {k}": a for k, a in analyses.items()}, "gyros")]
        if sensor == "all":             # a panel of its own: m/s², not deg/h
            panels.append(_accel_panel(acc_out, acc_analyses))
        path, _ = plot_allan_panels(panels, args.plot, force=args.force)
        out["plot"] = str(path)
        lines.append(f"wrote {path}" + (" (the gyros in deg/h, the accelerometer in m/s², side by side)"
                                        if sensor == "all" else ""))
    return out, "\n".join(lines)


def _accel_panel(acc_out: dict, analyses: dict):
    """The accelerometer's panel of the ``--plot`` figure (m/s²), each axis's fit labelled with the
    terms ``allan --sensor acc`` resolved (datasheet units, as its JSON)."""
    from gyroarray.reports.allan_plots import accel_panel  # deferred: matplotlib only to draw
    names = (("vrw_m_s_rt_h", "VRW", "m/s/√h"), ("accel_rw_m_s2_rt_h", "acc RW", "m/s²/√h"), ("bi_mg", "BI", "mg"))
    labels = {}
    for axis in analyses:
        fit = acc_out["axes"][axis]["fit"]
        terms = [f"{name} {fit[key]:.3g} {unit}" for key, name, unit in names
                 if fit.get(key) is not None and fit.get(key + "_resolved")]
        labels[f"acc_{axis}"] = f"acc_{axis} fit" + (f": {', '.join(terms)}" if terms else "")
    return accel_panel({f"acc_{a}": x for a, x in analyses.items()}, "accelerometer acc_x..z", labels)


def accel_parts(meas, args) -> tuple[list, list[str], dict | None]:
    """Where the accelerometer's noise is read: ``[start, stop)`` ranges, notes, JSON.

    As the gyros' (:func:`_analysed_parts`: the still parts found in the gyro outputs, the whole
    record with ``--all``, split at gaps), except with a reference rate that moves: there the parts
    where the table is still (every reference component within :data:`REF_STILL_RAD_S`), because
    a turning table moves gravity's projection on the accelerometer axes, and that is no noise.
    """
    # deferred: numpy and the analysis load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.analysis.deviations import contiguous_segments, cut_at_segments
    from gyroarray.core.measurement import true_runs
    ref = meas.ref_rad_s
    if ref is None or not ref.any():
        return _analysed_parts(meas, list(range(1, meas.n_gyros + 1)), args)
    n, dt = meas.n_samples, meas.dt_s
    still = np.abs(ref).max(axis=1) <= REF_STILL_RAD_S
    notes: list[str] = []
    if args.all:
        parts = [(0, n)]
        notes.append(f"--all: the accelerometer analysed over the whole record, {(n - int(still.sum())) * dt:.1f} s "
                     "of it turning (the reference rate): gravity's moving projection counts as noise")
    else:
        parts = [(a, b) for a, b in true_runs(still) if b - a >= MIN_STILL_PART]
        if not parts:
            raise InputError(f"the table turns throughout (reference rate above {REF_STILL_RAD_S:g} rad/s): no still "
                             f"part of at least {MIN_STILL_PART} samples for the accelerometer, whose ADEV would "
                             "be gravity's moving projection; record a still part, or rerun with --all",
                             file=str(args.measurement))
        notes.append(f"accelerometer: analysed only the {len(parts)} part(s) where the reference rate is still, "
                     f"{sum(b - a for a, b in parts) * dt:.1f} s of {n * dt:.1f} s (the Allan sums pooled over them)")
    segments, missing = contiguous_segments(meas.time_s, dt)
    if len(segments) > 1:
        parts = cut_at_segments(parts, segments)
        if not parts:
            raise InputError("the gaps in the time stamps leave no contiguous still part of at least 4 samples",
                             file=str(args.measurement))
        notes.append(f"{len(segments) - 1} gap(s) in the time stamps ({missing} sample(s) missing): the "
                     "accelerometer's deviation is pooled over the contiguous parts")
    return parts, notes, {"parts_s": [[float(meas.time_s[a] - meas.time_s[0]),
                                       float(meas.time_s[b - 1] - meas.time_s[0] + dt)] for a, b in parts]}


def _cmd_allan_acc(args, meas, kind: str, taus) -> tuple[dict, str, dict]:
    """``allan --sensor acc``: the Allan deviation of ``acc_x..z`` [m/s²] with its CIs and the
    accelerometer's terms (:mod:`gyroarray.analysis.accel`); also the analyses by axis (for
    ``--plot``)."""
    # deferred: numpy and the analysis (numba) load only when the command runs (a fast --help)
    from gyroarray.analysis.accel import accel_fit, analysis_json
    from gyroarray.analysis.allan import fit_tau_count
    from gyroarray.analysis.deviations import RANGE_KIND
    parts, notes, info = accel_parts(meas, args)
    if isinstance(taus, int):
        try:
            taus, tau_note = fit_tau_count(max(b - a for a, b in parts) + 1, meas.dt_s, taus, RANGE_KIND[kind])
            notes += [tau_note] if tau_note else []
        except InputError:
            pass
    if args.robust:
        notes.append("--robust takes spikes out of the gyros only; the accelerometer is analysed as recorded")
    try:
        fit = accel_fit(meas.acc_m_s2, meas.dt_s, parts, taus, kind)
    except InputError as err:
        raise InputError(err.message, file=str(args.measurement)) from None
    notes += list(fit.notes)
    axes = {a: analysis_json(x) for a, x in fit.analyses.items()}
    out = {"axes": axes, "terms": fit.to_json_dict(),
           "signal": "specific force acc_x..z [m/s²] (a constant, gravity included, does not change the ADEV)",
           "notes": [*([] if args.sensor == "all" else meas.notes), *notes],
           "not_analysed": dict(fit.skipped)}
    if info is not None:
        out["analysed_parts"] = info
    lines = [f"{args.measurement}: accelerometer, {meas.n_samples} samples at {1 / meas.dt_s:g} Hz; analysed: "
             "acc_x..z [m/s²]", *[f"note: {n}" for n in out["notes"]]]
    lines += [_format_acc(a, d) for a, d in axes.items()]
    return out, "\n".join(lines), dict(fit.analyses)


def _format_acc(axis: str, d: dict) -> str:
    fit = d["fit"]

    def val(key: str) -> str:
        v, s = fit.get(key), fit.get(key + "_sigma")
        if v is None:
            return "-"
        text = f"{v:.4g} ± {s:.2g}" if s is not None else f"{v:.4g}"
        return text + ("" if fit.get(key + "_resolved") else " (not resolved)")
    rows = [f"acc_{axis} ({d['kind']}, {100 * d['confidence']:.1f}% CI)",
            f"  {'tau_s':>10} {d['kind'] + '_m_s2':>12} {'ci_low':>12} {'ci_high':>12}"]
    rows += [f"  {t:>10.4g} {a:>12.5g} {lo:>12.5g} {hi:>12.5g}"
             for t, a, lo, hi in zip(d["taus_s"], d["adev_m_s2"], d["ci_low_m_s2"], d["ci_high_m_s2"])]
    rows.append(f"  fit: VRW {val('vrw_m_s_rt_h')} m/s/rt(h), acc RW {val('accel_rw_m_s2_rt_h')} m/s^2/rt(h), "
                f"BI {val('bi_mg')} mg")
    return "\n".join(rows)


def accel_noise(meas, args=None):
    """The ``[accelerometer]`` table of a model fitted to ``meas`` (``fit --out``), and notes.

    Returns ``(AccelNoise or None, notes)``: None, with a note saying why, when the record has no
    ``acc_*`` columns or no axis can be analysed; a term not resolved is left out of the table
    (never a 0) and the table's ``notes`` say which and why. Read over the still parts, as
    ``allan --sensor acc`` reads them.
    """
    # deferred: numpy and the analysis (numba) load only when the command runs (a fast --help)
    from types import SimpleNamespace
    from gyroarray.analysis.accel import ACC_TERMS, accel_fit
    from gyroarray.effects.model import AccelNoise
    if not meas.has_acc:
        return None, ["no [accelerometer] table: the record has no accelerometer columns (acc_x, acc_y, acc_z); "
                      "its fields n_m_s_rt_h, k_m_s2_rt_h, b_mg are missing"]
    opts = SimpleNamespace(all=False, measurement=getattr(args, "measurement", meas.source))
    try:
        parts, _, _ = accel_parts(meas, opts)
        fit = accel_fit(meas.acc_m_s2, meas.dt_s, parts)
    except InputError as err:
        return None, [f"no [accelerometer] table: {err.message}"]
    keys = {"n": "n_m_s_rt_h", "k": "k_m_s2_rt_h", "b": "b_mg"}

    def conv(t, values):          # per axis, None where the axis does not resolve the term
        return None if values is None else tuple(None if v is None else float(ACC_TERMS[t][2](v)) for v in values)
    values = {keys[t]: conv(t, fit.values[t]) for t in keys}
    sigma = {keys[t]: conv(t, fit.sigmas[t]) for t in keys if fit.sigmas[t] is not None}
    used_s = sum(b - a for a, b in parts) * meas.dt_s
    unresolved = _accel_unresolved(fit, keys, meas.dt_s)
    notes = [f"fitted as gyroarray allan --sensor acc fits (octave oadev, generalised least squares, 1σ) "
             f"over {used_s:.1f} s of the record"]
    notes += [n.replace("vrw_m_s_rt_h", "n_m_s_rt_h").replace("accel_rw_m_s2_rt_h", "k_m_s2_rt_h")
             .replace("bi_mg", "b_mg") for n in fit.notes]
    table = AccelNoise(axes=fit.axes, sigma=sigma, notes=tuple(notes), unresolved=unresolved,
                       record_s=float(used_s), **values)
    lack = table.missing_axes
    return table, ([f"[accelerometer]: {key} not resolved on acc_{', acc_'.join(axes)}, left out there "
                    "(see its notes and unresolved)" for key, axes in lack.items()])


def _accel_unresolved(fit, keys: dict, dt_s: float) -> dict:
    """The ``unresolved`` entries of an ``[accelerometer]`` table: by term, by axis that does not
    resolve it, the fit's estimate and 1σ [datasheet unit], why, and ``resolve_s``, the record
    length [s] at which ``plan --sensor acc`` predicts the estimate (with the axis's other
    estimates) would stand at RESOLVED_Z σ (absent when the estimate is 0 or cannot be planned)."""
    # deferred: numpy, scipy and the plan's GLS fit load only when fit --out writes the table
    from gyroarray.analysis.accel import ACC_TERMS, RESOLVED_Z
    from gyroarray.analysis.allan import ONE_SIGMA
    from gyroarray.chain.plan import plan_record
    out: dict = {}
    for t, key in keys.items():
        for axis, (value, sigma, why) in fit.per_axis[t].items():
            if value is not None:
                continue
            est, sig, _ = fit.estimates[t][axis]
            conv = ACC_TERMS[t][2]
            entry = {"estimate": float(conv(est))}
            if sig is not None:
                entry["sigma"] = float(conv(sig))
            if est > 0:
                coef = {u: fit.estimates[u][axis][0] for u in keys}
                try:
                    plan = plan_record(coef, 1.0 / dt_s, 1.0 / RESOLVED_Z, confidence=ONE_SIGMA, sensor="acc")
                    need = plan.duration_s.get(t)
                except InputError:
                    need = None
                if need is not None:
                    entry["resolve_s"] = float(need)
            entry["why"] = why
            out.setdefault(key, {})[axis] = entry
    return out


def _cmd_allan_streamed(args, kind: str, taus, why: str) -> tuple[dict, str]:
    """``allan`` on a record read in chunks (:mod:`gyroarray.analysis.allan_stream`): the
    overlapping Allan deviation of the whole record, equal to the in-memory one to rounding."""
    # deferred: numpy and the analysis (numba) load only when the command runs (a fast --help)
    from gyroarray.analysis.allan import MAX_FIT_TAUS
    from gyroarray.analysis.allan_stream import streamed_allan
    from gyroarray.core.measurement import record_head
    from gyroarray.reports.allan_plots import plot_allan
    name = str(args.measurement)
    way = ("; raise --max-memory to read it whole" if why != "--stream" else "; leave out --stream")
    if kind != "oadev":
        raise InputError(f"a streamed record is analysed with --kind oadev only ({why}){way}",
                         file=name)
    for flag, on in (("--repair", args.repair), ("--robust", args.robust),
                     ("--gaps", getattr(args, "gaps", False))):
        if on:
            raise InputError(f"{flag} needs the record in memory, and this one is streamed ({why})"
                             f"{way}", file=name)
    head = record_head(args.measurement)
    if args.gyro is not None and not 1 <= args.gyro <= head.n_gyros:
        raise InputError(f"--gyro {args.gyro} is out of range: the measurement has "
                         f"gyros 1..{head.n_gyros}", file=name)
    gyros = [args.gyro] if args.gyro is not None else list(range(1, head.n_gyros + 1))
    tau_note = []
    if isinstance(taus, int) and taus > MAX_FIT_TAUS:
        tau_note = [f"--taus {taus}: at most {MAX_FIT_TAUS} log-spaced taus on a streamed record "
                    "(the most the noise fit takes); analysed those"]
        taus = MAX_FIT_TAUS
    res = streamed_allan(head, gyros, taus=taus, raw=args.raw, whole=args.all)
    notes = [*head.notes, f"streamed ({why})", *res.notes, *tau_note, *res.skipped.values()]
    gyros_json = {str(k): a.to_json_dict() for k, a in res.analyses.items()}
    # the bound needs only the fitted values, the rate and the length (the whole record, streamed);
    # the Whittle fit would need the record's periodogram in memory
    bound_lines = noise_bounds(None, res.dt_s, [(0, res.n_samples)], res.analyses, gyros_json, notes)
    method = getattr(args, "method", "auto")
    if method == "whittle":
        notes.append("--method whittle: the Whittle fit needs the record's periodogram in memory, and this "
                     f"record is streamed ({why}): the Allan GLS is reported")
    est_lines = efficient_estimates(None, res.dt_s, [(0, res.n_samples)], res.analyses, gyros_json, notes,
                                    method=method, why_none=f"the record is streamed ({why})")
    out = {"gyros": gyros_json,
           "signal": res.signal, "notes": notes,
           "not_analysed": {str(k): why_not for k, why_not in res.skipped.items()},
           "streamed": {"chunk_rows": res.chunk_rows, "work_bytes": res.work_bytes,
                        "n_samples": res.n_samples},
           "method": {"asked": method, "rule": AUTO_RULE}}
    lines = [f"{args.measurement}: {res.n_samples} samples at {1 / res.dt_s:g} Hz, "
             f"{head.n_gyros} gyros; analysed: {res.signal}", *[f"note: {n}" for n in notes]]
    for k, a in res.analyses.items():
        lines.append(_format_allan(k, a.to_json_dict()))
        lines += bound_lines.get(k, [])
        lines += est_lines.get(k, [])
    if args.plot is not None:
        path = plot_allan({f"gyro {k}": a for k, a in res.analyses.items()}, args.plot,
                          force=args.force)
        out["plot"] = str(path)
        lines.append(f"wrote {path}")
    return out, "\n".join(lines)


def _reference_noise_notes(meas, minus_ref: bool, gyros: list[int]) -> list[str]:
    """Notes for a reference with noise of its own that the analysed signal (output minus
    layout·ref) holds: which gyros read it (:mod:`~gyroarray.analysis.reference_noise`)."""
    if not minus_ref:
        return []
    # deferred: numpy and the analysis (numba) load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.analysis.reference_noise import describe, reference_own_noise
    out = []
    for d in reference_own_noise(meas.ref_rad_s, meas.gyro_rad_s, meas.layout.H, meas.dt_s):
        hit = [k for k in gyros if abs(float(np.asarray(meas.layout.H)[k - 1, d["axis"]])) > 0.1]
        if hit:
            out.append(describe(d) + f": the ADEV of gyro{'s' if len(hit) > 1 else ''} "
                       f"{', '.join(map(str, hit))} (output minus layout·ref) holds it, and its short-τ terms "
                       "(quantization, white noise) are then the reference's, not the gyro's; --raw analyses "
                       "the output alone")
    return out


def _white_levels(signal, dt_s: float, parts, analyses) -> dict:
    """Each analysed gyro's white level read as ``fit``, ``fuse`` and the ``[array]`` table read it:
    N = ADEV(τ1)·√τ1 pooled over the analysed parts, τ1 ≈ 1 s
    (:func:`~gyroarray.analysis.white_level.pooled_white_level`); empty when no part is longer
    than 2τ1. JSON-ready (deg/√h)."""
    # deferred: numpy and the analysis load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.analysis.white_level import pooled_white_level
    from gyroarray.core import units
    out = {}
    for k in analyses:
        lev = pooled_white_level(np.asarray(signal, float)[:, k - 1], dt_s, parts)
        if lev is None:
            continue
        out[k] = {"n_deg_rt_h": float(units.arw_rad_rt_s_to_deg_rt_h(lev[0][0])),
                  "n_deg_rt_h_sigma": float(units.arw_rad_rt_s_to_deg_rt_h(lev[1][0])),
                  "tau_s": float(lev[2]), "edf": float(lev[3])}
    return out


#: The Allan fit's terms the Cramér–Rao bound knows: (key of the ``fit`` dict, term of
#: :mod:`gyroarray.analysis.crb`, name in the text). The rate ramp ``r_deg_h2`` has no bound: a
#: drift, not a stationary noise of the first differences (its ``_crb`` is None).
CRB_TERMS = (("arw_deg_rt_h", "n", "ARW"), ("bi_deg_h", "b", "BI"), ("rrw_deg_h_rt_h", "k", "RRW"),
             ("q_deg", "q", "Q"))
#: A term is not resolvable by a record when its CRB (1σ) is at least this fraction of its value:
#: no unbiased estimator could then tell it from 0 at 2σ.
UNRESOLVABLE_CRB = 0.5
#: An efficiency above this says the fit's own σ is too small (no unbiased estimator beats the
#: bound; the Allan σ is itself an estimate, ~10-20 % off on a record the fit reads well).
OPTIMISTIC_EFFICIENCY = 1.2
#: The Allan and the Whittle estimates of a term disagree when they lie more than this many
#: combined σ apart (√(σ_Allan² + σ_Whittle²)).
DISAGREE_Z = 3.0


def datasheet_converters():
    """SI -> datasheet converter of each term of :data:`CRB_TERMS` (and the Gauss–Markov ones)."""
    from gyroarray.core import units  # deferred: numpy (a fast --help)
    return {"n": units.arw_rad_rt_s_to_deg_rt_h, "b": units.rad_s_to_deg_h,
            "k": units.rrw_rad_s_rt_s_to_deg_h_rt_h, "q": units.rad_to_deg,
            "gm_sigma": units.rad_s_to_deg_h, "gm_tau": float}


def noise_bounds(signal, dt_s: float, parts, analyses: dict, gyros_json: dict, notes: list) -> dict:
    """The Cramér–Rao bound of each fitted noise term, its efficiency, and a Whittle fit beside.

    For each gyro the fitted model is the Allan fit's terms of :data:`CRB_TERMS` with a value > 0
    (a term fitted to 0 is not in it: its ``_crb`` is None); the bound is
    :func:`gyroarray.analysis.crb.crb` of that model at the fitted values, for this record's step
    and still parts (each its own periodogram, none across a join). Adds to each gyro's ``fit``
    ``<term>_crb`` (1σ, the term's datasheet unit) and ``<term>_efficiency`` (CRB² over the Allan
    fit's σ², dimensionless; None without a σ), to the gyro a ``crb`` block (the model, its SI
    values, the terms the record cannot resolve: CRB >= :data:`UNRESOLVABLE_CRB` × value) and a
    ``whittle`` block (the tapered Whittle maximum-likelihood fit of the same model,
    :func:`gyroarray.analysis.whittle.fit_whittle`, in datasheet units; not computed when
    ``signal`` is None, a streamed record), and to ``notes`` the terms a record cannot resolve.

    Parameters
    ----------
    signal : ndarray, shape (n, N), or None
        The analysed rates [rad/s] (None: no Whittle fit).
    dt_s : float
        Sample step [s].
    parts : list of (int, int)
        The analysed still parts, [start, stop) samples.
    analyses : dict
        Gyro (1-based) -> :class:`~gyroarray.analysis.allan.AllanAnalysis`.
    gyros_json : dict
        ``str(gyro)`` -> that gyro's JSON (``to_json_dict``), extended in place.
    notes : list of str
        Extended in place.

    Returns
    -------
    dict
        Gyro -> text lines.
    """
    # deferred: numpy and the analysis load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.analysis import crb as crb_mod
    conv = datasheet_converters()
    lines: dict = {}
    short: dict = {}
    duration = sum(b - a for a, b in parts) * dt_s
    for k, a in analyses.items():
        fit = gyros_json[str(k)]["fit"]
        gyros_json[str(k)]["crb"] = gyros_json[str(k)]["whittle"] = None     # set below when they can be
        values, sigmas = {}, {}
        for key, term, _ in CRB_TERMS:
            v, s = a.fit.coefficient(term)
            fit[key + "_crb"] = None
            fit[key + "_efficiency"] = None
            if v is not None and math.isfinite(v) and v > 0.0:
                values[term], sigmas[term] = float(v), s
        fit["r_deg_h2_crb"] = fit["r_deg_h2_efficiency"] = None
        if not values:
            continue
        try:
            with np.errstate(all="ignore"):
                bound = crb_mod.crb(values, dt_s, parts=parts)
        except (InputError, np.linalg.LinAlgError, ValueError, ArithmeticError) as err:
            why = err.message if isinstance(err, InputError) else f"it failed on these numbers ({err})"
            notes.append(f"gyro {k}: no Cramér–Rao bound: {why}")
            continue
        unresolved, text = [], []
        for key, term, name in CRB_TERMS:
            if term not in values:
                continue
            sd, sig = bound.sd[term], sigmas[term]
            sd = None if sd is None or not math.isfinite(sd) else sd
            if sd is not None:
                fit[key + "_crb"] = float(conv[term](sd))
                if sig is not None and math.isfinite(sig) and sig > 0.0 and math.isfinite((sd / sig) ** 2):
                    fit[key + "_efficiency"] = float((sd / sig) ** 2)
            if sd is None or sd >= UNRESOLVABLE_CRB * values[term]:
                unresolved.append(key)
                short.setdefault(name, []).append(k)
            eff = fit[key + "_efficiency"]
            if eff is not None and eff > OPTIMISTIC_EFFICIENCY:
                notes.append(f"gyro {k}: the Allan fit's σ of {name} ({conv[term](sig):.3g}) is below the "
                             f"Cramér–Rao bound ({fit[key + '_crb']:.3g}; efficiency {eff:.2f} > 1): that σ "
                             "understates the uncertainty on this record (the fit's σ is a local, long-record "
                             "one), read the bound as the least 1σ any estimator has")
            text.append(f"{name} {'-' if sd is None else format(fit[key + '_crb'], '.2g')}"
                        + ("" if eff is None else f" (eff {eff:.2f})"))
        r_value = a.fit.coefficient("r")[0]
        block = {"model": [key for key, term, _ in CRB_TERMS if term in values],
                 "not_in_model": [key for key, term, _ in CRB_TERMS if term not in values],
                 "values_si": dict(values), "duration_s": float(duration), "parts": len(parts),
                 "dt_s": float(dt_s), "unresolvable": unresolved,
                 "unresolvable_rule": f"CRB >= {UNRESOLVABLE_CRB:g} x the fitted value",
                 "method": bound.method}
        if r_value is not None and r_value > 0.0:
            block["left_out"] = ["r_deg_h2 (a rate ramp is a drift, not a stationary noise: no bound)"]
        gyros_json[str(k)]["crb"] = block
        lines[k] = ["  CRB 1σ (the fitted model at its values, this record): " + ", ".join(text)]
        if signal is None:
            continue
        wb, wline = _whittle_block(np.asarray(signal, float)[:, k - 1], dt_s, parts, tuple(values), conv)
        gyros_json[str(k)]["whittle"] = wb
        lines[k].append(wline)
        if wb is None:
            notes.append(f"gyro {k}: {wline.strip()}")
            continue
        apart = []
        for key, term, name in CRB_TERMS:
            sa, sw = fit.get(key + "_sigma"), wb["sigma"].get(key)
            if term in values and sa is not None and sw is not None and \
                    abs(wb["values"][key] - fit[key]) > DISAGREE_Z * math.hypot(sa, sw):
                apart.append(f"{name} {fit[key]:.3g} vs {wb['values'][key]:.3g}")
        if apart:
            notes.append(f"gyro {k}: the Allan fit and the Whittle fit of the same model disagree beyond "
                         f"{DISAGREE_Z:g} σ ({'; '.join(apart)}): the record does not follow that model at "
                         "every frequency (a filter, lines, a missing term), and its Cramér–Rao bound holds "
                         "only for the model the record follows")
    notes += too_short_notes(short, duration, len(parts), 1.0 / dt_s)
    notes += walk_in_bias_notes(gyros_json)
    return lines


def walk_in_bias_notes(gyros_json: dict) -> list[str]:
    """Why ``allan``'s K is not ``fit``'s: where the five-term fit puts the long-τ rise into the
    bias instability and reads no walk (K at its bound 0), while the ADEV's +½ slope reads one.

    ``fit``'s default model is white + walk (no bias instability), so on such a record it reads
    the rise as a walk: the two K differ by model, not by data. The note names both readings and
    the command that fits allan's terms (``fit --add bias_instability``)."""
    out = []
    for k, g in gyros_json.items():
        fit = g.get("fit") or {}
        k_fit, b_fit = fit.get("rrw_deg_h_rt_h"), fit.get("bi_deg_h")
        k_slope = fit.get("slope_rrw_deg_h_rt_h")
        if (k_fit == 0.0 and b_fit is not None and b_fit > 0.0 and k_slope is not None
                and math.isfinite(k_slope) and k_slope > 0.0):
            sig = fit.get("rrw_deg_h_rt_h_sigma")
            out.append(f"gyro {k}: the five-term fit reads no rate random walk (K 0"
                       + (f" ± {sig:.3g}" if sig is not None and math.isfinite(sig) else "")
                       + f" deg/h/√h) and a bias instability of {b_fit:.3g} deg/h: on this record the "
                       f"rise at long τ is not told apart between the two (the +½ slope at the longest τ "
                       f"reads K ≈ {k_slope:.3g}). `fit` (white + walk by default) reads that rise as "
                       "the walk, so its K is not this one: the models differ, not the data; "
                       "`fit --add bias_instability` fits the bias instability beside the walk")
    return out


def too_short_notes(short: dict, duration_s: float, n_parts: int, rate_hz: float) -> list[str]:
    """The notes of the terms a record is too short to resolve (``allan`` and ``fit``): ``short``
    maps a term's name to the gyros whose Cramér–Rao bound (1σ) is at least half the fitted
    value; one note per set of gyros, for a record of ``duration_s`` [s] in ``n_parts`` still
    parts at ``rate_hz`` [Hz]."""
    by_gyros: dict = {}
    for name, ks in short.items():
        by_gyros.setdefault(tuple(ks), []).append(name)
    out = []
    for ks, names in by_gyros.items():
        who = f"gyro {ks[0]}" if len(ks) == 1 else f"gyros {', '.join(map(str, ks))}"
        out.append(f"{who}: the record ({duration_s:.4g} s in {n_parts} part(s) at {rate_hz:g} Hz) "
                   f"is too short to resolve {', '.join(names)} at the fitted value: the Cramér–Rao "
                   f"bound (1σ) is at least half of it, so no estimator could tell it from 0; a "
                   "longer record (plan) resolves it, if the model holds")
    return out


def _whittle_block(x, dt_s: float, parts, terms: tuple, conv: dict) -> tuple:
    """The Whittle fit of one gyro's rate ``x`` [rad/s] over ``parts``: (JSON in datasheet units
    or None, its text line)."""
    # deferred: numpy, scipy and the analysis load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.analysis.whittle import fit_whittle
    keys = {term: key for key, term, _ in CRB_TERMS}
    try:
        with np.errstate(all="ignore"):
            w = fit_whittle(x, dt_s, terms, parts=parts)
    except (InputError, np.linalg.LinAlgError, ValueError, ArithmeticError) as err:
        why = err.message if isinstance(err, InputError) else f"the fit failed on these numbers: {err}"
        return None, f"  Whittle ML fit: not computed ({why})"

    def ds(d):
        return {keys[p]: None if v is None or not math.isfinite(v) else float(conv[p](v)) for p, v in d.items()}
    block = {"method": "tapered Whittle maximum likelihood on the first differences of each still part "
                       "(analysis.whittle)",
             "model": [keys[t] for t in terms], "values": ds(w.values), "sigma": ds(w.sigma),
             "crb": ds(w.crb), "efficiency": {keys[p]: None if v is None or not math.isfinite(v) else float(v)
                                              for p, v in w.efficiency.items()},
             "taper": f"Tukey, cosine ramps over {w.taper:g} of each part",
             "taper_fraction": w.taper, "band": w.band, "n_freq": w.n_freq,
             "converged": w.converged, "notes": list(w.notes)}
    vals = block["values"]
    text = [f"{name} {vals[key]:.4g}" + ("" if block["sigma"][key] is None else f" ± {block['sigma'][key]:.2g}")
            for key, term, name in CRB_TERMS if term in terms]
    return block, "  Whittle ML fit (second estimate): " + ", ".join(text)


#: ``allan --method``: the Allan GLS, the band-limited Whittle ML fit, or the choice between them.
METHODS = ("auto", "whittle", "allan")
#: The models ``allan`` chooses between by BIC (analysis.noise_select) for its white/walk/BI
#: estimate: white + walk, and + bias instability (the terms it reports from the Whittle fit; the
#: Gauss–Markov and quantization candidates cost seconds a gyro on a million samples, and Q and
#: the rate ramp stay the Allan GLS's).
ESTIMATE_CANDIDATES = (("n", "k"), ("n", "k", "b"))
#: Fewest periodogram ordinates in the band for ``auto`` to use the Whittle fit: its σ and
#: efficiency are asymptotic (the inverse information), held within a few % from ~10³ ordinates.
MIN_WHITTLE_ORDINATES = 2048
#: The ``auto`` rule in words (``--json``'s ``method.rule`` and the docs).
AUTO_RULE = ("auto: the band-limited Whittle ML fit (band by analysis.whittle.BAND_RULE, model by least "
             "BIC among white+walk and +BI) is the reported ARW/BI/RRW when its band holds at least "
             f"{MIN_WHITTLE_ORDINATES} ordinates, it converged with a finite σ for every term of the "
             "model, and the model check passes (every half-octave bin of the band within 1 ± max(5 %, "
             "3σ) of the fitted spectrum); else the Allan GLS. Efficient: its variance is κ = 1.026 times "
             "the band's Cramér–Rao bound (the Allan GLS's K reaches 0.72–0.82 of the bound on "
             "white + walk records, issue 45). Q and the rate ramp are always the Allan GLS's")

_EST_KEYS = (("n", "arw_deg_rt_h", "ARW", "deg/rt(h)"), ("b", "bi_deg_h", "BI", "deg/h"),
             ("k", "rrw_deg_h_rt_h", "RRW", "deg/h/rt(h)"))


def _allan_terms(fit: dict) -> dict:
    """The Allan GLS's ARW/BI/RRW/Q/RR of a gyro's ``fit`` dict, each with its σ, CRB and
    efficiency (datasheet units)."""
    out = {}
    for key in ("arw_deg_rt_h", "bi_deg_h", "rrw_deg_h_rt_h", "q_deg", "r_deg_h2"):
        out[key] = {"value": fit.get(key), "sigma": fit.get(key + "_sigma"), "crb": fit.get(key + "_crb"),
                    "efficiency": fit.get(key + "_efficiency"), "from": "allan"}
    return out


def efficient_estimates(signal, dt_s: float, parts, analyses: dict, gyros_json: dict, notes: list, *,
                        method: str = "auto", band=None, why_none: str | None = None) -> dict:
    """The reported ARW/BI/RRW of each gyro: the band-limited Whittle ML fit or the Allan GLS.

    Adds to each gyro's JSON an ``estimate`` block: ``method`` (``whittle`` or ``allan``), ``why``,
    ``terms`` (ARW, BI, RRW from the method chosen, Q and RR from the Allan GLS; each ``value``,
    ``sigma`` (1σ), ``crb``, ``efficiency``, ``from``; datasheet units), and with the Whittle fit
    ``band`` (:func:`gyroarray.analysis.whittle.choose_band`), ``selection``
    (:func:`gyroarray.analysis.noise_select.select_model`), ``model_check`` and
    ``k_by_model`` (K of each candidate). The rule is :data:`AUTO_RULE`.

    Parameters
    ----------
    signal : ndarray, shape (n, N), or None
        The analysed rates [rad/s] (None: the Allan GLS only, ``why_none`` says why).
    dt_s : float
        Sample step [s].
    parts : list of (int, int)
        The analysed still parts, [start, stop) samples.
    analyses : dict
        Gyro (1-based) -> :class:`~gyroarray.analysis.allan.AllanAnalysis`.
    gyros_json : dict
        ``str(gyro)`` -> that gyro's JSON, extended in place.
    notes : list of str
        Extended in place.
    method : {"auto", "whittle", "allan"}
        ``--method``.
    band : (float, float), optional
        ``--band`` [Hz] (default: chosen from the record).
    why_none : str, optional
        Why no Whittle fit (with ``signal`` None).

    Returns
    -------
    dict
        Gyro -> text lines.
    """
    # deferred: numpy, scipy and the analysis load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.analysis.noise_select import select_model
    from gyroarray.analysis.whittle import choose_band, model_check
    conv = datasheet_converters()
    lines: dict = {}
    for k in analyses:
        g = gyros_json[str(k)]
        terms = _allan_terms(g["fit"])
        est: dict = {"method": "allan", "asked": method, "terms": terms}
        g["estimate"] = est
        if signal is None:
            est["why"] = ("--method allan" if method == "allan" else
                          f"no Whittle fit: {why_none or 'not asked'}")
            lines[k] = [_estimate_line(est)]
            continue
        x = np.asarray(signal, float)[:, k - 1]
        try:
            with np.errstate(all="ignore"):
                choice = choose_band(x, dt_s, parts=parts, f_lo_hz=0.0 if band is None else band[0],
                                     f_hi_hz=None if band is None else band[1])
                sel = select_model(x, dt_s, parts=parts, band_hz=choice.band_hz, candidates=ESTIMATE_CANDIDATES,
                                   known=[choice.pilot])
                passed, worst = model_check(x, dt_s, sel.fit, parts=parts)
        except (InputError, np.linalg.LinAlgError, ValueError, ArithmeticError) as err:
            why = err.message if isinstance(err, InputError) else f"it failed on these numbers ({err})"
            est["why"] = f"the Whittle fit could not be made: {why}"
            if method == "whittle":
                notes.append(f"gyro {k}: --method whittle: {est['why']}; the Allan GLS is reported")
            lines[k] = [_estimate_line(est)]
            continue
        fit = sel.fit
        band_json = choice.to_json_dict()
        est["band"] = band_json
        est["selection"] = sel.to_json_dict()
        est["model_check"] = {"passed": bool(passed), "worst_bin": worst,
                              "rule": "every half-octave bin of the band (>= 32 ordinates) within "
                                      "1 ± max(0.05, 3σ) of the fitted spectrum"}
        k_by_model: dict = {lab: {"k_deg_h_rt_h": float(conv["k"](f.values["k"])),
                                   "sigma": None if f.sigma.get("k") is None else float(conv["k"](f.sigma["k"])),
                                   "crb": None if f.crb.get("k") is None else float(conv["k"](f.crb["k"]))}
                            for lab, f in sel.fits.items()}
        est["k_by_model"] = k_by_model
        finite = all(fit.sigma.get(p) is not None and math.isfinite(fit.sigma[p]) for p in fit.values)
        reasons = []
        if fit.n_freq < MIN_WHITTLE_ORDINATES:
            reasons.append(f"the band holds {fit.n_freq} ordinates (< {MIN_WHITTLE_ORDINATES})")
        if not fit.converged or not finite:
            reasons.append("the fit did not converge to a finite σ for every term")
        if not passed:
            reasons.append(f"the model check fails (bin {worst['f_lo_hz']:.3g}–{worst['f_hi_hz']:.3g} Hz "
                           f"reads {worst['ratio']:.3f} × the fitted spectrum, σ {worst['sigma']:.2g})")
        use = method == "whittle" or (method == "auto" and not reasons)
        lo, hi = choice.band_hz
        if use:
            est["method"] = "whittle"
            est["why"] = ("--method whittle" if method == "whittle" else "auto: the record is long enough and "
                          "the model check passes") + (f" (note: {'; '.join(reasons)})" if reasons else "")
            for term, key, _, _ in _EST_KEYS:
                if term not in fit.values:
                    terms[key] = {"value": 0.0, "sigma": None, "crb": None, "efficiency": None,
                                  "from": "whittle", "not_in_model": True}
                    continue
                terms[key] = {"value": float(conv[term](fit.values[term])),
                              "sigma": None if fit.sigma[term] is None else float(conv[term](fit.sigma[term])),
                              "crb": None if fit.crb[term] is None else float(conv[term](fit.crb[term])),
                              "efficiency": fit.efficiency.get(term),
                              "crb_full_band": (None if fit.crb_full.get(term) is None
                                                else float(conv[term](fit.crb_full[term]))),
                              "efficiency_full_band": fit.efficiency_full.get(term), "from": "whittle"}
            est["allan"] = _allan_terms(g["fit"])
            if reasons:
                notes.append(f"gyro {k}: --method whittle reported although {'; '.join(reasons)}")
        else:
            est["why"] = "--method allan" if method == "allan" else "auto: " + "; ".join(reasons)
        text = [_estimate_line(est),
                f"    band {lo:.4g}–{hi:.4g} Hz ({'stated' if band is not None else 'from the record'}"
                f"{', cut below Nyquist' if choice.cut else ''}); model {sel.label} by least BIC ("
                + ", ".join(f"{lab} ΔBIC {b - sel.bic[sel.label]:.1f}" for lab, b in sel.bic.items()
                            if lab != sel.label) + "); model check " + ("passes" if passed else "fails"),
                "    K by model: " + ", ".join(
                    f"{lab} {v['k_deg_h_rt_h']:.4g}" + ("" if v["sigma"] is None else f" ± {v['sigma']:.2g}")
                    for lab, v in k_by_model.items()) + " deg/h/rt(h)"]
        lines[k] = text
    return lines


def _estimate_line(est: dict) -> str:
    """The text line of a gyro's reported estimate."""
    parts = []
    for _, key, name, unit in _EST_KEYS:
        t = est["terms"][key]
        v = t["value"]
        if v is None:
            parts.append(f"{name} -")
            continue
        s = "" if t["sigma"] is None else f" ± {t['sigma']:.2g}"
        extra = [] if t["crb"] is None else [f"CRB {t['crb']:.2g}"]
        if t.get("efficiency") is not None:
            extra.append(f"eff {t['efficiency']:.2g}")
        parts.append(f"{name} {v:.4g}{s} {unit}" + (f" ({', '.join(extra)})" if extra else ""))
    return f"  estimate ({est['method']}; {est['why']}): " + ", ".join(parts)


def _analysed_parts(meas, gyros: list[int], args) -> tuple[list, list[str], dict | None]:
    """Where the noise is read: ``[start, stop)`` sample ranges, their notes and their JSON.

    Without ``--all``: the still parts of a record with no reference rate, found by
    :func:`gyroarray.analysis.motion.still_mask` (the detector ``fuse``'s ``still_parts`` and the
    array model use; parts of at least :data:`MIN_STILL_PART` samples), refusing a record that
    moves throughout; with ``--all``: the whole record. Either way a gap in the time stamps
    (dropped samples) splits the parts: no difference spans it (the sums are pooled).
    """
    # deferred: numpy and the analysis load only when the command runs (a fast --help)
    from gyroarray.analysis.deviations import contiguous_segments, cut_at_segments
    from gyroarray.analysis.motion import still_mask
    from gyroarray.core.measurement import true_runs
    n, dt = meas.n_samples, meas.dt_s
    segments, missing = contiguous_segments(meas.time_s, dt)
    notes, info = [], None
    parts = [(0, n)]
    if not meas.has_reference:
        keep = [k - 1 for k in gyros]
        try:
            still = still_mask(meas.gyro_rad_s[:, keep], meas.layout.axes[keep], dt)
        except InputError:                      # fewer than 3 one-second windows: all of it
            still = None
        if still is not None and not still.all() and args.all:
            notes.append(f"--all: the whole record analysed, {(n - int(still.sum())) * dt:.1f} s of it "
                         "moving (found in the outputs): the motion counts as noise in every term")
        elif still is not None and not still.all():
            parts = [(a, b) for a, b in true_runs(still) if b - a >= MIN_STILL_PART]
            desc = (f"{len(parts)} still part(s), {sum(b - a for a, b in parts) * dt:.1f} s of "
                    f"{n * dt:.1f} s (no reference rate: still parts found in the outputs as diagnose "
                    "and fuse find them, each part's mean taken out)")
        if not parts:
            raise InputError(f"the record moves throughout: no still part of at least {MIN_STILL_PART} "
                             "samples in the outputs (no reference rate), and the Allan deviation of "
                             "motion is not noise; record a still part, give the reference rate, or "
                             "rerun with --all to analyse the whole record anyway",
                             file=str(args.measurement))
        if parts != [(0, n)]:
            total = sum(b - a for a, b in parts) * dt
            notes.append(f"analysed only the still parts: {desc}; longest "
                         f"{max(b - a for a, b in parts) * dt:.1f} s; the Allan sums are pooled over "
                         "the parts (no difference spans two parts); --all analyses the whole record, "
                         "motion included")
            t = meas.time_s - meas.time_s[0]
            info = {"parts_s": [[float(t[a]), float(t[b - 1] + dt)] for a, b in parts],
                    "still_s": float(total), "record_s": float(n * dt)}
    if len(segments) > 1:
        parts = cut_at_segments(parts, segments)
        if not parts:
            raise InputError(f"the {len(segments) - 1} gap(s) in the time stamps leave no contiguous "
                             "part of at least 4 samples to analyse; record without dropping samples",
                             file=str(args.measurement))
        notes.append(f"{len(segments) - 1} gap(s) in the time stamps ({missing} sample(s) missing): "
                     f"the deviation is computed over the {len(parts)} contiguous part(s) and their "
                     "sums pooled, nothing interpolated")
        info = {**(info or {}), "gaps": len(segments) - 1, "missing_samples": missing,
                "segments": len(parts)}
    return parts, notes, info


def _spikes(meas, signal, gyros: list[int], parts, taus, kind: str, args):
    """Spikes in the analysed parts (:func:`gyroarray.effects.outliers.find_spikes`), what they
    do to the ARW, and with ``--robust`` the signal with them taken out.

    Returns ``(signal, notes, JSON by gyro)``; the signal is a copy with each spike replaced by
    the linear interpolation of its non-spike neighbours (``--robust``), else the input.
    """
    # deferred: numpy and the effects load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.core import units
    from gyroarray.effects.outliers import find_spikes
    notes, info, clean = [], {}, None
    for k in gyros:
        col = signal[:, k - 1]
        found = [a + find_spikes(col[a:b]).index for a, b in parts if b - a >= 16]
        idx = np.concatenate(found) if found else np.array([], int)
        if not idx.size or not np.ptp(col):
            continue
        fixed = np.array(col, dtype=float)
        bad = np.zeros(col.size, bool)
        bad[idx] = True
        for a, b in parts:
            good = np.flatnonzero(~bad[a:b])
            if good.size >= 2 and bad[a:b].any():
                t = np.arange(b - a)
                fixed[a:b][bad[a:b]] = np.interp(t[bad[a:b]], good, col[a:b][good])
        arw: list = []                      # the ARW of each series [rad/rt(s)], None where unfitted
        for series in (col, fixed):
            try:
                with np.errstate(all="ignore"):
                    arw.append(_arw_of(series, parts, meas.dt_s, taus, kind))
            except (InputError, np.linalg.LinAlgError, ValueError, FloatingPointError):
                arw.append(None)
        change = (arw[0] / arw[1] - 1.0) if None not in arw and arw[1] > 0 else None
        deg = [None if v is None else float(units.arw_rad_rt_s_to_deg_rt_h(v)) for v in arw]
        info[str(k)] = {"count": int(idx.size), "arw_with_deg_rt_h": deg[0],
                        "arw_without_deg_rt_h": deg[1], "taken_out": bool(args.robust)}
        said = (f"ARW {deg[0]:.4g} deg/rt(h) with them, {deg[1]:.4g} without ({100 * change:+.0f} %)"
                if change is not None else "their effect on the ARW could not be fitted")
        heavy = change is not None and abs(change) > 0.05
        if args.robust:
            notes.append(f"gyro {k}: --robust took out {idx.size} spike(s) (find_spikes; each replaced by "
                         f"the linear interpolation of its neighbours): {said}; the figures are without them")
            if clean is None:
                clean = np.array(signal, dtype=float)
            clean[:, k - 1] = fixed
        else:
            notes.append(f"gyro {k}: {idx.size} isolated spike(s) in the analysed samples (find_spikes): "
                         f"{said}" + ("; they make the short-tau terms (Q, ARW) describe the spikes, not "
                                      "the noise: rerun with --robust to take them out" if heavy else
                                      "; --robust takes them out"))
    return (signal if clean is None else clean), notes, info


def _arw_of(series, parts, dt: float, taus, kind: str) -> float:
    """The fitted ARW [rad/√s] of one gyro's series over ``parts`` (0 when not fitted)."""
    # deferred: numpy and the analysis (numba) load only when the command runs (a fast --help)
    from gyroarray.analysis.allan import allan_analysis
    from gyroarray.analysis.deviations import analyse_parts
    if parts == [(0, series.size)] and kind in ("oadev", "ohdev"):
        fit = allan_analysis(series, dt, taus, kind=kind).fit
    else:
        fit = analyse_parts([series[a:b] for a, b in parts], dt, taus, kind).fit
    value = fit.coefficient("n")[0]
    return float(value) if value is not None else 0.0


def _white_notes(meas, signal, parts, analyses: dict) -> list[str]:
    """A note per gyro whose per-sample white level and ADEV at tau >= 1 s disagree by > 20 %
    (lines, bumps, filtering, holds or quantization: the spectrum is not white at short tau)."""
    # deferred: numpy loads only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.core import units
    out, found = [], []
    dt = meas.dt_s
    for k, a in analyses.items():
        if a.kind not in ("oadev", "totdev"):
            continue
        at = np.flatnonzero(a.taus_s >= 1.0)
        if not at.size or dt >= 1.0:
            continue
        i = int(at[0])
        diffs = [np.diff(signal[p:q, k - 1]) for p, q in parts if q - p >= 3]
        d = np.concatenate(diffs) if diffs else np.array([])
        if d.size < 10:
            continue
        per_sample = float(np.std(d) / np.sqrt(2.0) * np.sqrt(dt))              # rad/√s
        at_tau = float(a.adev_rad_s[i] * np.sqrt(a.taus_s[i]))                     # rad/√s
        if not (per_sample > 0 and at_tau > 0) or abs(per_sample / at_tau - 1.0) <= 0.20:
            continue
        ps, tt = (float(units.arw_rad_rt_s_to_deg_rt_h(v)) for v in (per_sample, at_tau))
        found.append((k, 100 * (per_sample / at_tau - 1)))
        out.append(f"gyro {k}: the spectrum is not white at short tau: the per-sample white level "
                   f"({ps:.4g} deg/rt(h), from the sample-to-sample differences) and the ADEV at tau = "
                   f"{a.taus_s[i]:g} s ({tt:.4g} deg/rt(h) x sqrt(tau)) differ by "
                   f"{found[-1][1]:+.0f} %: " + _NOT_WHITE)
    if len(found) > 3:                  # one line for many gyros
        pct = [p for _, p in found]
        out = [f"gyros {', '.join(str(k) for k, _ in found)}: the spectrum is not white at short tau: "
               "the per-sample white level (from the sample-to-sample differences) and the ADEV at the "
               f"first tau >= 1 s (x sqrt(tau)) differ by {min(pct):+.0f} to {max(pct):+.0f} %: " + _NOT_WHITE]
    return out


_NOT_WHITE = ("lines, bumps, a filter, held samples or quantization; the fitted ARW and Q then describe "
              "that, not a white-noise density (read the ARW from the ADEV at tau >= 1 s)")


def _allan_each(meas, signal, gyros: list[int], taus, args, *, kind: str | None = None,
                parts=None) -> tuple[dict, dict]:
    """The Allan analysis of each gyro; a gyro that cannot be analysed is noted, not fatal.

    ``parts``: ``[start, stop)`` ranges analysed (default the whole record); several, or a kind
    beyond oadev/ohdev, go through :func:`gyroarray.analysis.deviations.analyse_parts`.
    Returns ``(analyses by gyro, reason by gyro not analysed)``; refuses
    (one line, every reason) when no gyro can be analysed.
    """
    # deferred: numpy and the analysis (numba) load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.analysis.allan import allan_analysis
    from gyroarray.analysis.deviations import analyse_parts, with_noise_id
    from gyroarray.core.measurement import constant_gyros, constant_note
    kind = kind or args.kind
    parts = parts or [(0, meas.n_samples)]
    dead = set(constant_gyros(meas))
    analyses, skipped = {}, {}
    for k in gyros:
        if k in dead:
            skipped[k] = constant_note([k], meas) + ": not analysed"
            continue
        try:
            with np.errstate(all="ignore"):
                col = signal[:, k - 1]
                if parts == [(0, meas.n_samples)] and kind in ("oadev", "ohdev"):
                    analyses[k] = with_noise_id(allan_analysis(col, meas.dt_s, taus, kind=kind), col)
                else:
                    analyses[k] = analyse_parts([col[a:b] for a, b in parts], meas.dt_s, taus, kind)
        except InputError as err:
            skipped[k] = f"gyro {k} not analysed: {err.message}"
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as err:
            # a fit that cannot be computed on these numbers: said, the other gyros go on
            skipped[k] = f"gyro {k} not analysed: the noise fit failed on its data ({err})"
    if not analyses:
        dead_asked = [k for k in gyros if k in dead]
        why = ([constant_note(dead_asked, meas)] if dead_asked else []) + [
            v for k, v in skipped.items() if k not in dead]
        raise InputError("nothing to analyse: " + "; ".join(why), file=str(args.measurement))
    return analyses, skipped


def _format_allan(k: int, d: dict) -> str:
    fit = d["fit"]

    def val(key: str, fmt: str = ".4g") -> str:
        v, s = fit.get(key), fit.get(key + "_sigma")
        if v is None:
            return "-"
        return f"{v:{fmt}} ± {s:{fmt}}" if s is not None else f"{v:{fmt}}"
    rows = [f"gyro {k} ({d['kind']}, {100 * d['confidence']:.1f}% CI)",
            f"  {'tau_s':>10} {d['kind'] + '_deg_h':>12} {'ci_low':>12} {'ci_high':>12}"]
    rows += [f"  {t:>10.4g} {a:>12.5g} {lo:>12.5g} {hi:>12.5g}"
             for t, a, lo, hi in zip(d["taus_s"], d["adev_deg_h"], d["ci_low_deg_h"], d["ci_high_deg_h"])]
    rows.append(f"  fit: ARW {val('arw_deg_rt_h')} deg/rt(h), BI {val('bi_deg_h')} deg/h, "
                f"RRW {val('rrw_deg_h_rt_h')} deg/h/rt(h), Q {val('q_deg')} deg, RR {val('r_deg_h2')} deg/h^2")
    slope = [f"{name} {fit[key]:.4g}" for name, key in (("N(1 s)", "slope_arw_deg_rt_h"),
                                                         ("K(3 s)", "slope_rrw_deg_h_rt_h"),
                                                         ("B(min/0.664)", "slope_bi_deg_h"))
             if fit.get(key) is not None]
    if slope:
        rows.append("  slope-line readings: " + ", ".join(slope))
    return "\n".join(rows)


def cmd_davar(args) -> tuple[dict, str]:
    # deferred: numpy and the analysis (numba) load only when the command runs (a fast --help)
    from gyroarray.analysis import davar as dv
    from gyroarray.core.limits import check_memory
    from gyroarray.core.measurement import read_measurement
    from gyroarray.reports.davar_plots import plot_davar
    if args.measurement is None:
        raise InputError("gyroarray davar: give MEAS.csv (paper 000's Table 1: "
                         "python benchmarks/davar_paper.py)")
    if args.gyro is None:
        raise InputError("gyroarray davar: --gyro K is required (one gyro at a time)")
    if args.window is not None and args.adaptive:
        raise InputError("gyroarray davar: --window L and --adaptive exclude each other "
                         "(the adaptive window runs between --l-min and --l-max)")
    check_plot(args, inputs=measurement_inputs(args))
    meas = read_measurement(args.measurement, repair=args.repair, **bag_options(args))
    if not 1 <= args.gyro <= meas.n_gyros:
        raise InputError(f"--gyro {args.gyro} is out of range: the measurement has gyros "
                         f"1..{meas.n_gyros}", file=str(args.measurement))
    signal, what = allan_signal(meas)
    adaptive = args.adaptive or args.window is None
    params = dv.AdaptiveWindow(l_max=args.l_max, l_min=args.l_min) if adaptive else None
    # windows x taus of the result (arrays and their JSON text), before the work
    longest = min(args.l_max if adaptive else args.window, meas.n_samples)
    step = args.step if args.step is not None else (1 if adaptive else max(1, longest // 10))
    taus = math.log2(max(longest, 2)) + 1
    windows = max(1, meas.n_samples // step)
    check_memory(windows * (200 * taus + 200), f"davar of {windows} windows (--step {step}) x "
                 f"{taus:.0f} taus", "give a larger --step", file=str(args.measurement))
    res = dv.davar(signal[:, args.gyro - 1], meas.dt_s, window=None if adaptive else args.window,
                   adaptive=adaptive, step=args.step, params=params)
    out = res.to_json_dict()
    out["signal"] = what
    arw = out["arw_deg_rt_h"]
    finite = [v for v in arw if v is not None]
    lines = [f"{args.measurement} gyro {args.gyro}: {'adaptive' if adaptive else 'fixed'} DAVAR, "
             f"{len(out['time_s'])} windows of {min(out['window_length'])}-{max(out['window_length'])} "
             f"samples, {len(out['taus_s'])} taus; analysed: {what}",
             f"ARW track [deg/rt(h)]: min {min(finite):.4g}, median {sorted(finite)[len(finite) // 2]:.4g}, "
             f"max {max(finite):.4g}"]
    if args.plot is not None:
        out["plot"] = str(plot_davar(res, args.plot, force=args.force))
        lines.append(f"wrote {out['plot']}")
    return out, "\n".join(lines)


def add_parser(sub) -> None:
    """The ``allan`` and ``davar`` subcommands (Allan and dynamic Allan deviation)."""
    p = sub.add_parser("allan", help="Allan deviation with confidence intervals and noise fit")
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    add_bag_options(p)
    p.add_argument("--gyro", type=int, metavar="K", help="only gyro K (1-based)")
    p.add_argument("--sensor", choices=SENSORS, default="gyro",
                   help="the gyros (default), the accelerometer acc_x..z (ADEV in m/s², VRW in m/s/√h, "
                        "acc RW in m/s²/√h, BI in mg) or all of them")
    p.add_argument("--taus", default="octave", metavar="octave|N|T1,T2,...",
                   help="octave taus (default), N log-spaced taus, or a list of taus [s]")
    p.add_argument("--kind", choices=("oadev", "mdev", "hdev", "ohdev", "totdev"), default="oadev",
                   help="overlapping Allan (default), modified Allan, Hadamard (hdev, non-overlapping "
                        "as Stable32's HDEV), overlapping Hadamard (ohdev) or total deviation")
    p.add_argument("--all", action="store_true",
                   help="analyse the whole record, motion included (default: only its still parts)")
    p.add_argument("--robust", action="store_true",
                   help="take isolated spikes out first (each replaced by its neighbours' interpolation; counted)")
    p.add_argument("--repair", action="store_true",
                   help="repair short gaps, missing values, exact duplicate rows and a jittering clock (each listed)")
    p.add_argument("--gaps", action="store_true",
                   help="accept gaps in the time stamps (dropped samples): the deviation is pooled over "
                        "the contiguous parts, nothing interpolated (gaps and missing samples counted)")
    p.add_argument("--raw", action="store_true",
                   help="analyse the raw gyro output even when a moving reference is present")
    p.add_argument("--whittle", action="store_true",
                   help="add a second estimate, the tapered Whittle maximum-likelihood fit of each gyro's "
                        "noise terms (its cost grows with the samples: ~4 s per gyro and million samples "
                        "per minor term); the Cramér–Rao bounds are given either way")
    p.add_argument("--method", choices=METHODS, default="auto",
                   help="the estimate reported for ARW, BI and RRW: the Allan GLS fit, the band-limited "
                        "Whittle maximum-likelihood fit (model chosen by BIC), or auto (default): Whittle "
                        "when the record is long enough and the model check passes, else Allan; the "
                        "other is kept beside it and the choice printed")
    p.add_argument("--band", type=_parse_band, metavar="LO,HI",
                   help="the frequency band [Hz] of the Whittle fit (default: chosen from the record, "
                        "below the frequency where the periodogram departs from the fitted model)")
    p.add_argument("--stream", action="store_true",
                   help="read the record in chunks, never whole (automatic for a record estimated "
                        "beyond 2 GiB or --max-memory; Parquet recommended): the overlapping ADEV of "
                        "the whole record, --kind oadev")
    p.add_argument("--plot", type=Path, metavar="OUT.png",
                   help="write the ADEV plot: the gyros in deg/h, with --sensor acc the accelerometer "
                        "in m/s², with --sensor all both side by side")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_allan)

    p = sub.add_parser("davar", help="dynamic Allan deviation (fixed or adaptive window, paper 000)")
    p.add_argument("measurement", type=Path, nargs="?", metavar="MEAS.csv")
    add_bag_options(p)
    p.add_argument("--gyro", type=int, metavar="K", help="gyro K (1-based)")
    p.add_argument("--adaptive", action="store_true",
                   help="adaptive window A-DAVAR (the default when --window is not given)")
    p.add_argument("--window", type=positive_int("--window"), metavar="L", help="fixed window [samples]")
    p.add_argument("--step", type=positive_int("--step"), metavar="S",
                   help="samples between windows (default: 1 adaptive, L/10 fixed)")
    p.add_argument("--l-max", type=positive_int("--l-max"), default=600, metavar="L",
                   help="adaptive: longest window [samples] (default 600)")
    p.add_argument("--l-min", type=positive_int("--l-min"), default=400, metavar="L",
                   help="adaptive: shortest window [samples] (default 400)")
    p.add_argument("--repair", action="store_true", help="repair short gaps, missing values, exact duplicate rows and a jittering clock (each listed)")
    p.add_argument("--plot", type=Path, metavar="OUT.png", help="heat map + ARW and window tracks")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_davar)

