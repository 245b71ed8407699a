"""``gyroarray compare``, ``diagnose``, ``fit`` and ``ladder``: a measurement against a noise
model (calibrate, model band, diagnostics, fit, the ladder of added effects), with their text.

The chain (numpy, numba) and the compare report (matplotlib) are imported inside the commands,
so that building the parser (``gyroarray --help``, every other command) does not load them.
"""

from __future__ import annotations

import math
from pathlib import Path

from gyroarray.cli.common import (add_bag_options, bag_options, add_force, add_plugin, check_count, count, finite_float, float_in,
                                  measurement_inputs, nonneg_int, output)
from gyroarray.core.errors import InputError

__all__ = ["add_parser", "cmd_compare", "cmd_diagnose", "cmd_fit", "cmd_ladder"]

def _read(path, args):
    """One record of a compare-family command, read with the command's options."""
    from gyroarray.core.measurement import read_measurement  # deferred: numpy, pandas (a fast --help)
    # --gaps (fit only): dropped samples kept as gaps in the time stamps, never filled
    return read_measurement(path, repair=args.repair, gaps=getattr(args, "gaps", False), **bag_options(args))


def _comparison(args, window: bool = False):
    """Check the outputs, read the measurement (and model) of a compare-family
    command; build the chain. ``window`` (diagnose): a record over the memory budget is read
    as its longest window that fits (:mod:`gyroarray.chain.long_record`), ``args.window_plan``."""
    # deferred: the chain (numpy, numba) loads only when the command runs (a fast --help)
    from gyroarray.chain.compare import ModelComparison, check_record_needs
    from gyroarray.core.outputs import markdown_figures
    from gyroarray.effects.model import NoiseModel
    inputs = measurement_inputs(args)
    output(getattr(args, "out", None), args, "--out", inputs=inputs,
            suffixes=(".toml",) if args.command == "fit" else (".html", ".htm"))
    output(getattr(args, "md", None), args, "--md", inputs=inputs, suffixes=(".md",))
    output(getattr(args, "model_out", None), args, "--model-out", inputs=inputs, suffixes=(".toml",))
    if getattr(args, "md", None) is not None:      # its figures beside it, checked now too
        markdown_figures(args.md, inputs=inputs, force=args.force)
    args.window_plan = None
    if window and not bag_options(args):
        # deferred: the chain (numpy, numba) loads only when the command runs (a fast --help)
        from gyroarray.chain.long_record import read_plan, window_plan
        from gyroarray.core.bags import is_bag
        args.window_plan = None if is_bag(args.measurement) else window_plan(args.measurement)
    if args.window_plan is not None:
        if args.repair:
            raise InputError("--repair needs the record in memory, and this one is over the memory "
                             "budget (diagnosed on its longest window that fits); raise --max-memory "
                             "or repair a cut of it", file=str(args.measurement))
        meas = read_plan(args.window_plan)
        from gyroarray.core.measurement import constant_gyros  # deferred: numpy, pandas
        dead = constant_gyros(meas)
        args.window_gyros = [k for k in range(1, meas.n_gyros + 1) if k not in dead]
    else:
        meas = _read(args.measurement, args)
    # what reading the file said, every --repair included (the text `allan` prints): in the notes
    # of every compare-family command (the report lists them as "reading the file")
    args.read_notes = list(meas.notes)
    model = None
    if args.model is not None:
        model = NoiseModel.from_toml(args.model, n_gyros=meas.n_gyros)
    meas, model, args.entry_notes = _live_gyros(meas, model, args)
    check_record_needs(model, meas, fixed=bool(getattr(args, "validate", False)))
    _check_band_runs(args, meas)
    return ModelComparison(meas, model, n_runs=args.runs, seed=args.seed, ref_smooth_s=args.ref_smooth)


def _check_band_runs(args, meas) -> None:
    """Refuse ``--runs`` whose Monte-Carlo band would not fit the memory budget: each run keeps
    the ADEV and the Welch PSD of every gyro (kept three times over: the runs, their array and
    the quantiles), before any run."""
    from gyroarray.chain.localise import default_nperseg  # deferred: the chain (numpy, numba)
    n = max(int(meas.n_samples), 2)
    per_run = 3 * 8 * meas.n_gyros * (math.log2(n) + 1 + default_nperseg(n) // 2 + 1)
    check_count("--runs", args.runs, per_run,
                 f"Monte-Carlo runs of {n} samples x {meas.n_gyros} gyros")


def _live_gyros(meas, model, args):
    """Leave constant (dead or stuck) gyros out of a comparison, saying so; refuse when none is left."""
    from gyroarray.core.measurement import constant_gyros, constant_note, without_gyros  # deferred: numpy, pandas
    dead = constant_gyros(meas)
    if not dead:
        return meas, model, []
    note = constant_note(dead, meas)
    live = [k for k in range(1, meas.n_gyros + 1) if k not in dead]
    if not live:
        raise InputError(f"nothing to analyse: {note}", file=str(args.measurement))
    if model is not None and any(e.gyro is not None for e in model):
        raise InputError(f"{note}, and the model names gyros by number: leave the constant "
                         "gyro out of the record (and renumber the model) first",
                         file=str(args.model))
    mapping = ", ".join(f"{old} as {new}" for new, old in enumerate(live, 1) if old != new)
    args.left_out = (live, meas.n_gyros, note)      # a written model takes the record's numbers back
    note += (": left out; the analysis below numbers the others "
             + (mapping if mapping else "as before"))
    return without_gyros(meas, dead, note), model, [note]


def _model_lines(model) -> list[str]:
    from gyroarray.effects.names import ARW, RRW  # deferred: the effect registry (numpy, scipy, numba)
    out = []
    for e in model:
        if e.effect in (ARW, RRW):
            continue
        params = ", ".join(f"{k} = {_short_num(v)}" for k, v in e.params.items())
        out.append(f"  {e.label}: {params}")
    return out


def _short_num(v):
    return f"{v:.6g}" if isinstance(v, float) else str(v)


def _diagnosis_text(a, head: str) -> str:
    lines = [head, f"discrepancy D = {a.discrepancy:.3g} ({'consistent' if a.consistent else 'NOT consistent'}"
             f" with the model; D = max z / {a.z_crit:.2f}, the 1 % family-wise critical z of "
             f"{len(a.tests)} tests)", "",
             f"{'effect':<20} {'gyro':>4} {'score':>8}  sig  evidence"]
    for t in a.candidates:
        z = "nan" if not math.isfinite(t.z) else f"{t.z:8.2f}"
        lines.append(f"{t.effect:<20} {'-' if t.gyro is None else t.gyro:>4} {z:>8}  "
                     f"{'yes' if a.significant(t) else ' no'}  {t.evidence}")
    shared = a.shared_lines()
    if shared:
        lines += [""] + shared
    locked = a.motion_lines()
    if locked:
        lines += [""] + locked
    bands = [t for t in a.tests if t.kind == "adev_band" and a.significant(t)]
    if bands:
        lines += ["", "ADEV outside the model band:"] + [f"  {t.evidence} (z = {t.z:.1f})" for t in bands]
    where = a.where_it_fails()
    if where:
        lines += [""] + where
    if a.notes:
        lines += ["", "notes:"] + [f"  {n}" for n in a.notes]
    return "\n".join(lines)


def _write_report(comp, steps, args) -> dict:
    from gyroarray.reports.compare_report import write_compare_report  # deferred: matplotlib
    title = None
    if getattr(args, "validate", False):
        title = f"Validation: does the model ({comp.given_model.description or args.model}) predict {comp.name}?"
    return write_compare_report(comp, steps, args.out, args.md, title=title, force=args.force)


def _write_model(path: Path, model, args, notes: list | None = None, described: tuple = ()) -> str:
    """The fitted model as TOML at ``path`` (checked by :func:`_comparison`); returns the path.

    Fitted on a record with constant gyros left out (``args.left_out``), the model takes the
    record's gyro numbers back, the left-out gyros without entries of their own, said in its
    description and in ``notes``. ``described``: further notes for the model's description."""
    # deferred: numba and the effect registry load only when the command runs (a fast --help)
    from gyroarray.core.outputs import write_text
    from gyroarray.effects.model import NoiseModel
    model = NoiseModel(model.entries, description="; ".join([f"fitted to {args.measurement} by gyroarray "
                                                            f"{args.command}", *described]),
                       array=model.array, accelerometer=model.accelerometer, topic=model.topic)
    left = getattr(args, "left_out", None)
    if left is not None:
        live, n_all, why = left
        nums = ", ".join(map(str, live))
        note = (f"{why}: left out of the fit; the entries use the record's gyro numbers ({nums} of "
                f"1..{n_all}), the left-out gyro(s) have no entry of their own")
        model = model.renumbered(live, n_all, note)
        if notes is not None:
            notes.append(f"the model written to {path} keeps the record's gyro numbers ({nums}); {why}, "
                         "so it is left out of the model (no entry of its own; an all-gyros entry is "
                         "the analysed gyros' value)")
    return str(write_text(path, model.to_toml(), force=args.force))


def _array_fit(comp, notes: list):
    """The array model of a comparison's record (None with one gyro, or with a note when the
    record cannot give one): the ``[array]`` table that ``fit`` and ``ladder`` write."""
    # deferred: the chain (numpy, numba) loads only when the command runs (a fast --help)
    from gyroarray.chain.array_model import array_model, comparison_still
    if comp.N < 2:
        return None
    if comp.ref is not None and comp.gap_summary() is not None:
        notes.append("no array model ([array] table): a record with gaps and a reference rate is stitched "
                     "for the fits, and its static samples are not mapped back to the record's clock")
        return None
    try:
        return array_model(comp.m, still=comparison_still(comp))
    except InputError as err:
        notes.append(f"no array model ([array] table): {err.message}")
        return None


def _levels_across(comp, args, notes: list):
    """Each gyro's white level on the record and on ``args.more`` (other records of the same array:
    same gyros, same layout), combined (:func:`~gyroarray.chain.array_model.levels_across`)."""
    # deferred: the chain (numpy, numba) loads only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.chain.array_model import comparison_still, levels_across, record_levels
    if comp.N < 2:
        raise InputError("fit with several records combines the gyros of one array; this record has one gyro",
                         file=comp.name)
    from gyroarray.core.measurement import without_gyros  # deferred: numpy, pandas
    gyros = list(range(1, comp.N + 1))
    left = getattr(args, "left_out", None)          # the first record's constant gyros, left out
    levels = [record_levels(comp.m, gyros, still=comparison_still(comp))]
    for path in args.more:
        other = _read(path, args)
        if left is not None and other.n_gyros == left[1]:
            other = without_gyros(other, [k for k in range(1, left[1] + 1) if k not in left[0]], left[2])
        if other.n_gyros != comp.m.n_gyros or not np.allclose(other.layout.axes, comp.m.layout.axes, atol=1e-6):
            raise InputError(f"not a record of the same array: {other.n_gyros} gyros with another layout "
                             f"than {comp.name}'s {comp.m.n_gyros} (fit several records of one array only)",
                             file=str(path))
        if abs(other.dt_s - comp.m.dt_s) > 1e-9 * comp.m.dt_s:
            raise InputError(f"sampled every {other.dt_s:g} s, the first record every {comp.m.dt_s:g} s: "
                             "fit records of one rate together", file=str(path))
        levels.append(record_levels(other, gyros))
        notes.extend(n for n in other.notes if n not in notes)
    across = levels_across(levels)
    notes.append(f"the model's white levels (arw entries and [array]) are the random-effects mean over "
                 f"{len(levels)} records; the other terms are fitted on {comp.name}")
    return across


def _validation_text(comp, a, model_path) -> str:
    """``the model fitted on X predicts Y: consistent / not, worst at …``."""
    worst = max(a.tests, key=lambda t: t.z if math.isfinite(t.z) else -math.inf, default=None)
    where = comp.given_model.description or str(model_path)
    head = (f"the model ({where}) predicts {comp.name}: "
            + ("consistent" if a.consistent else "NOT consistent") + f" (D = {a.discrepancy:.3g})")
    if worst is not None and not a.consistent:
        head += f", worst: {worst.evidence} (z = {worst.z:.1f})"
    return head


def cmd_compare(args):
    comp = _comparison(args)
    if args.validate:
        if args.model is None:
            raise InputError("gyroarray compare --validate needs --model (the model to test)")
        a = comp.validate()
        steps = [(None, a)]
    else:
        # with a model beyond the baseline: the baseline first, then its effects one
        # by one, so the report shows the error falling
        steps = comp.steps_to_model()
        a = steps[-1][1]
    a.notes[:0] = args.entry_notes
    _write_report(comp, steps, args)
    d = a.to_json_dict()
    res = {"discrepancy": a.discrepancy, "consistent": a.consistent, "z_crit": a.z_crit,
           "n_tests": len(a.tests), "report": str(args.out),
           "steps": [{"added": None if add is None else {"effect": add[0], "gyro": add[1]},
                      "discrepancy": s.discrepancy, "consistent": s.consistent} for add, s in steps],
           "adev_band": d["adev_band"], "candidates": d["candidates"][:10],
           "localisation": d["localisation"], "notes": [*args.read_notes, *a.notes]}
    if args.md is not None:
        res["markdown"] = str(args.md)
    if args.validate:
        res["validated"] = True
        res["verdict"] = _validation_text(comp, a, args.model)
    fall = "" if len(steps) == 1 else f" (baseline alone: D = {steps[0][1].discrepancy:.3g})"
    if args.validate:
        fall = "\n" + res["verdict"]
    text = (f"{comp.name}: discrepancy D = {a.discrepancy:.3g} "
            f"({'consistent' if a.consistent else 'NOT consistent'} with the model){fall}\n"
            + "\n".join(f"  {t.effect}{'' if t.gyro is None else ':' + str(t.gyro)}  z = {t.z:.1f}  {t.evidence}"
                        for t in a.candidates[:5] if a.significant(t))
            + "".join("\n" + x for x in a.where_it_fails())
            + f"\nreport: {args.out}" + (f" and {args.md}" if args.md is not None else "")
            + "".join(f"\nnote: {n}" for n in [*args.read_notes, *args.entry_notes]))
    return res, text


def cmd_diagnose(args):
    comp = _comparison(args, window=not args.validate)
    if args.validate:
        if args.model is None:
            raise InputError("gyroarray diagnose --validate needs --model (the model to test)")
        a = comp.validate()
        a.notes[:0] = [*args.read_notes, *args.entry_notes]
        out = a.to_json_dict()
        out["validated"] = True
        out["verdict"] = _validation_text(comp, a, args.model)
        return out, out["verdict"] + "\n" + _diagnosis_text(a, f"{comp.name}: {comp.N} gyros, {comp.n * comp.dt:.0f} s")
    streamed = None
    if args.window_plan is not None:
        # deferred: the chain (numpy, numba) loads only when the command runs (a fast --help)
        from gyroarray.chain.long_record import streamed_whole, whole_record_check
        # before the comparison: the streaming's working memory does not add to its peak
        streamed = streamed_whole(args.window_plan, args.window_gyros)
    a = comp.diagnose()
    a.notes[:0] = [*args.read_notes, *args.entry_notes]
    out = a.to_json_dict()
    text = _diagnosis_text(a, f"{comp.name}: {comp.N} gyros, {comp.n * comp.dt:.0f} s")
    if args.window_plan is not None:
        check, note = whole_record_check(args.window_plan, a, comp.m, args.window_gyros, streamed)
        out.update(check)
        out["notes"] = [note, *out["notes"]]
        text = f"note: {note}\n" + text
    return out, text


def cmd_fit(args):
    from gyroarray.chain.compare import parse_add_all  # deferred: the chain (numpy, numba)
    comp = _comparison(args)
    add, add_notes = [], []
    for x in args.add or []:                 # EFFECT, EFFECT:all of a per-gyro effect: every gyro
        more, note = parse_add_all(x, comp.N)
        add += [a for a in more if a not in add]
        add_notes += [note] if note else []
    from gyroarray.chain.array_model import with_array_model  # deferred: the chain (numpy, numba)
    before, after = comp.fit(add)
    after.notes[:0] = args.entry_notes
    notes = [*args.read_notes, *args.entry_notes, *add_notes,
             # what a fitted entry says beside its value (a scale factor's two estimates, reconciled)
             *(f.extra["reconciled"] for f in after.fits.values() if f.extra.get("reconciled"))]
    arr = _array_fit(comp, notes)
    res = {"discrepancy_before": before.discrepancy, "discrepancy_after": after.discrepancy,
           "consistent": after.consistent, "effects": after.effects_json(),
           "notes": notes}
    bound_lines = _noise_bounds(comp, after, res, notes)
    gaps = comp.gap_summary()               # with --gaps: the contiguous parts the fits read
    if gaps is not None:
        res["gaps"] = gaps
        notes.append(f"{gaps['gaps']} gap(s) in time_s ({gaps['missing_samples']} sample(s) missing): fitted "
                     f"on its {gaps['parts']} contiguous part(s), {gaps['samples']} samples; no difference "
                     "or Allan average is read across a gap")
    if comp.N >= 2:
        res["array_model"] = None if arr is None else arr.to_json_dict()
    model = after.model if arr is None else with_array_model(after.model, arr)
    across = _levels_across(comp, args, notes) if args.more else None
    if across is not None:
        from gyroarray.chain.array_model import with_levels  # deferred: the chain (numpy, numba)
        model = with_levels(model, across)
        res["levels_across_records"] = across.to_json_dict()
    model, described = _with_accelerometer(model, comp.m, args, notes, res)
    if args.out is not None:
        res["model"] = _write_model(args.out, model, args, notes, described)
    text = "\n".join([f"{comp.name}: discrepancy {before.discrepancy:.3g} -> {after.discrepancy:.3g} "
                      f"({'consistent' if after.consistent else 'NOT consistent'})",
                      "fitted model (beyond ARW + RRW):"] + (_model_lines(after.model) or ["  (baseline only)"])
                     + bound_lines
                     + ([] if arr is None else arr.text_lines())
                     + ([] if across is None else across.text_lines())
                     + ([f"written to {args.out}"] if args.out is not None else [])
                     + [f"note: {n}" for n in notes])
    return res, text


def _bound_parts(comp, after) -> list:
    """The parts [start, stop) of a comparison's (stitched) record its noise terms are fitted on:
    the samples its stochastic fits read (``after.record``: the whole record, or its longest static
    part), cut at the joins of its stitched still parts (none across a join)."""
    lo, hi, _ = after.record.indices(int(comp.n))
    out = []
    for a, b in list(comp.parts) or [(0, int(comp.n))]:
        a, b = max(a, lo), min(b, hi)
        if b - a >= 3:
            out.append((a, b))
    return out or [(lo, hi)]


def _noise_bounds(comp, after, res: dict, notes: list) -> list[str]:
    """The Cramér–Rao bound and the efficiency of each stochastic term of each gyro's fitted
    entries (``fit --json``).

    Beside ``params`` and ``sigma`` of the ``arw``, ``rrw``, ``bias_instability``,
    ``quantization`` and ``gauss_markov`` entries: ``crb`` (1σ, the parameter's unit) and
    ``efficiency`` (CRB² over the fit's σ², dimensionless), from the bound of the gyro's fitted
    stochastic model at the fitted values (:func:`gyroarray.analysis.crb.crb`; the entries with
    a value > 0) over the parts the noise fits read (:func:`_bound_parts`); ``res["crb"]``
    says how. The terms a record cannot resolve (CRB >= half the value) and a σ below the bound
    go to ``notes``. Returns the text lines.
    """
    # deferred: numpy and the analysis load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.analysis import crb as crb_mod
    from gyroarray.cli.allan import OPTIMISTIC_EFFICIENCY, UNRESOLVABLE_CRB, datasheet_converters, too_short_notes
    from gyroarray.core import units
    from gyroarray.effects import names
    # effect -> (parameter, crb term, datasheet -> SI)
    terms = {names.ARW: (("n_deg_rt_h", "n", units.arw_deg_rt_h_to_rad_rt_s),),
             names.RRW: (("k_deg_h_rt_h", "k", units.rrw_deg_h_rt_h_to_rad_s_rt_s),),
             names.BIAS_INSTABILITY: (("b_deg_h", "b", units.deg_h_to_rad_s),),
             names.QUANTIZATION: (("q_deg", "q", units.deg_to_rad),),
             names.GAUSS_MARKOV: (("sigma_deg_h", "gm_sigma", units.deg_h_to_rad_s), ("tau_s", "gm_tau", float))}
    conv = datasheet_converters()
    parts = _bound_parts(comp, after)
    duration = sum(b - a for a, b in parts) * comp.dt
    res["crb"] = {"parts": len(parts), "duration_s": float(duration), "dt_s": float(comp.dt),
                  "method": crb_mod.Bound.method,
                  "model": "each gyro's fitted arw, rrw, bias_instability, quantization and gauss_markov "
                           "entries with a value > 0, at the fitted values",
                  "unresolvable_rule": f"CRB >= {UNRESOLVABLE_CRB:g} x the fitted value"}
    by_gyro: dict = {}
    for d in res["effects"]:
        if d["effect"] in terms and d["gyro"] is not None:
            d["crb"] = {p: None for p, _, _ in terms[d["effect"]]}
            d["efficiency"] = {p: None for p, _, _ in terms[d["effect"]]}
            by_gyro.setdefault(int(d["gyro"]), []).append(d)
    lines: list[str] = []
    short: dict = {}
    for g, entries in sorted(by_gyro.items()):
        values, where = {}, {}
        for d in entries:
            got = {t: to_si(d["params"][p]) for p, t, to_si in terms[d["effect"]]
                   if isinstance(d["params"].get(p), (int, float)) and d["params"][p] > 0}
            if len(got) == len(terms[d["effect"]]):      # Gauss–Markov: σ and τc, or not at all
                values.update({t: float(v) for t, v in got.items()})
                where.update({t: (d, p) for p, t, _ in terms[d["effect"]]})
        if not values:
            continue
        try:
            with np.errstate(all="ignore"):
                bound = crb_mod.crb(values, comp.dt, parts=parts)
        except (InputError, np.linalg.LinAlgError, ValueError, ArithmeticError) as err:
            why = err.message if isinstance(err, InputError) else f"it failed on these numbers ({err})"
            notes.append(f"gyro {g}: no Cramér–Rao bound: {why}")
            continue
        text = []
        for t, (d, p) in where.items():
            sd = bound.sd[t]
            sd = None if sd is None or not math.isfinite(sd) else sd
            if sd is None or sd >= UNRESOLVABLE_CRB * values[t]:
                short.setdefault(f"{d['effect']} {p}", []).append(g)
            if sd is None:
                continue
            d["crb"][p] = float(conv[t](sd))
            sig = d["sigma"].get(p)
            fitted = after.fits.get((d["effect"], d["gyro"]))
            if fitted is not None and fitted.extra.get("grid"):
                d["crb_note"] = ("read from the output's step grid, not from the noise: the bound of a noise "
                                 "estimate does not apply to it (no efficiency)")
            elif isinstance(sig, (int, float)) and sig > 0 and math.isfinite((d["crb"][p] / sig) ** 2):
                d["efficiency"][p] = float((d["crb"][p] / sig) ** 2)
                if d["efficiency"][p] > OPTIMISTIC_EFFICIENCY:
                    notes.append(f"gyro {g}: the fit's σ of {d['effect']} {p} ({sig:.3g}) is below the "
                                 f"Cramér–Rao bound ({d['crb'][p]:.3g}; efficiency {d['efficiency'][p]:.2f} > 1): "
                                 "that σ understates the uncertainty on this record (the fit's σ is a local, "
                                 "long-record one), read the bound as the least 1σ any estimator has")
            eff = d["efficiency"][p]
            text.append(f"{d['effect']} {p} {d['params'][p]:.4g} (CRB {d['crb'][p]:.2g}"
                        + ("" if eff is None else f", eff {eff:.2f}") + ")")
        if text:
            lines.append(f"  gyro {g}: " + ", ".join(text))
    notes += too_short_notes(short, duration, len(parts), 1.0 / comp.dt)
    return (["noise terms with their Cramér–Rao bound (1σ, the fitted model at its values, this "
             f"record's {duration:.4g} s in {len(parts)} part(s)) and efficiency (CRB² / σ²):"] + lines
            if lines else [])

def _with_accelerometer(model, meas, args, notes: list, res: dict):
    """``model`` with the record's ``[accelerometer]`` table and bag ``topic`` (``fit``): the terms of
    :func:`gyroarray.cli.allan.accel_noise`; without acc columns no table, said in the notes and in
    the model's description. Returns (model, the notes for its description)."""
    # deferred: the analysis (numpy, numba) loads only when the command runs (a fast --help)
    from dataclasses import replace
    from gyroarray.cli.allan import accel_noise
    from gyroarray.effects.model import ACCEL_TERMS
    table, acc_notes = accel_noise(meas, args)
    notes.extend(acc_notes)
    res["accelerometer"] = None if table is None else table.to_dict()
    # the [accelerometer] fields the model does not hold (never written as 0): all without a table
    res["accelerometer_missing"] = list(ACCEL_TERMS) if table is None else list(table.missing)
    # and by term the axes that lack it (a term held on z alone is missing on x and y)
    res["accelerometer_missing_axes"] = ({k: ["x", "y", "z"] for k in ACCEL_TERMS} if table is None
                                         else {k: list(v) for k, v in table.missing_axes.items()})
    topics = tuple(getattr(meas, "topics", ()) or ())
    return (replace(model, accelerometer=table, topic=topics[0] if len(topics) == 1 else model.topic),
            tuple(acc_notes) if table is None else ())


def cmd_ladder(args):
    # deferred: the chain and the effect registry (numpy, numba) loads only when the command runs (a fast --help)
    from gyroarray.chain.compare import LADDER_RULE, ModelComparison, holdout_candidates, split_measurement
    from gyroarray.effects.model import NoiseModel
    if args.more and args.model_out is None:
        raise InputError("more records give the model's white levels across records: add --model-out NEW.toml")
    comp = _comparison(args)
    held = None
    if args.holdout is not None:
        first, rest = split_measurement(comp.m, args.holdout)
        comp = ModelComparison(first, comp.given_model, n_runs=args.runs, seed=args.seed,
                               ref_smooth_s=args.ref_smooth)
        held = ModelComparison(rest, None, n_runs=args.runs, seed=args.seed, ref_smooth_s=args.ref_smooth)
    steps = comp.ladder(max_steps=args.max_steps)
    steps[-1][1].notes[:0] = args.entry_notes
    _write_report(comp, steps, args)
    final = steps[-1][1]
    res = {"steps": [{"added": None if add is None else {"effect": add[0], "gyro": add[1]},
                      "discrepancy": a.discrepancy, "consistent": a.consistent}
                     for add, a in steps],
           "discrepancy": final.discrepancy, "consistent": final.consistent,
           "effects": final.effects_json(), "unexplained": final.unexplained(),
           "localisation": list(final.localisation),
           "candidates_left": [{"effect": t.effect, "gyro": t.gyro, "score": t.z, "evidence": t.evidence}
                               for t in final.candidates if final.significant(t)],
           "notes": [*args.read_notes, *final.notes], "rule": LADDER_RULE, "report": str(args.out)}
    arr_lines: list[str] = []
    if args.model_out is not None:
        # deferred: the chain (numpy, numba)
        from gyroarray.chain.array_model import with_array_model
        arr = _array_fit(comp, res["notes"])
        if comp.N >= 2:
            res["array_model"] = None if arr is None else arr.to_json_dict()
        arr_lines = [] if arr is None else arr.text_lines()
        model = final.model if arr is None else with_array_model(final.model, arr)
        if args.more:
            from gyroarray.chain.array_model import with_levels  # deferred: the chain (numpy, numba)
            across = _levels_across(comp, args, res["notes"])
            model = with_levels(model, across)
            res["levels_across_records"] = across.to_json_dict()
            arr_lines += across.text_lines()
        res["model"] = _write_model(args.model_out, model, args, res["notes"])
    held_text = []
    if held is not None:
        model = NoiseModel(final.model.entries, description=f"the ladder on {comp.name}")
        v = ModelComparison(held.m, model, n_runs=args.runs, seed=args.seed, ref_smooth_s=args.ref_smooth)
        va = v.validate()
        verdict = _validation_text(v, va, comp.name)
        # the test of a model's structure is its own record: a model that fails there fails on the
        # held-out part for what it lacks, not because it does not transfer
        missing = [t for t in final.candidates if final.significant(t)]
        names = [t.effect if t.gyro is None else f"{t.effect}:{t.gyro}" for t in missing]
        # the term it lacks is the one that lowers the held-out D most (each candidate fitted in on
        # the fitted part, its model validated held out), not the fitted part's top candidate
        rows = [] if va.consistent else holdout_candidates(comp, final, held.m, held_out=va,
                                                           ref_smooth_s=args.ref_smooth)
        by_d = _holdout_best_text(rows, va.discrepancy)
        if not va.consistent and not final.consistent:
            structure = (f"the model is not consistent on the part it was fitted on either (D = "
                         f"{final.discrepancy:.3g} there, {va.discrepancy:.3g} held out): its structure "
                         f"lacks a term, not its transfer; the fitted part's significant candidates: "
                         f"{', '.join(names) if names else 'none named (see where it fails)'}; {by_d}")
        elif not va.consistent:
            structure = (f"consistent on the fitted part (D = {final.discrepancy:.3g}) but not held out "
                         f"(D = {va.discrepancy:.3g}): the model does not transfer; {by_d}")
        else:
            structure = f"the model transfers (D = {final.discrepancy:.3g} fitted, {va.discrepancy:.3g} held out)"
        best = next((r for r in rows if r["holdout_discrepancy"] < va.discrepancy), None)
        res["holdout"] = {"fraction": args.holdout, "discrepancy": va.discrepancy, "consistent": va.consistent,
                          "verdict": verdict, "structure": structure, "missing_terms": names,
                          "by_candidate": rows,
                          "best_candidate": None if best is None else {"effect": best["effect"], "gyro": best["gyro"]},
                          "candidates": va.to_json_dict()["candidates"][:10]}
        held_text = [f"held out ({args.holdout:g} of the record): {verdict}", f"  {structure}"]
    lines = [f"{comp.name}: the ladder"]
    for add, a in steps:
        what = "calibrated model" if add is None else f"+ {add[0]}{'' if add[1] is None else ':' + str(add[1])}"
        lines.append(f"  {what:<28} D = {a.discrepancy:8.3g}  {'consistent' if a.consistent else ''}")
    lines.append(f"  ({LADDER_RULE})")
    lines += ["fitted model (beyond ARW + RRW):"] + (_model_lines(final.model) or ["  (baseline only)"])
    left = [t.evidence for t in final.candidates if final.significant(t)]
    if not final.localisation:
        left = final.unexplained() + left
    lines += ["still unexplained:"] + ([f"  {x}" for x in left] or
                                       (["  nothing"] if not final.localisation else []))
    if final.localisation:
        lines += final.where_it_fails()
    lines += arr_lines
    lines += [f"note: {x}" for x in args.read_notes]
    lines += [f"note: {x}" for x in final.notes if x.startswith("the ladder")]
    lines += [f"note: {x}" for x in res["notes"] if x.startswith(("no array model", "the model written"))]
    lines += held_text
    lines.append(f"report: {args.out}")
    return res, "\n".join(lines)


def _holdout_best_text(rows: list, d_held: float) -> str:
    """``ladder --holdout``'s structure verdict: the candidate that lowers the held-out D most, with
    every tried candidate's held-out D (:func:`gyroarray.chain.compare.holdout_candidates`)."""
    if not rows:
        return "no candidate to try on the held-out part"

    def one(r) -> str:
        name = r["effect"] if r["gyro"] is None else f"{r['effect']}:{r['gyro']}"
        if not math.isfinite(r["holdout_discrepancy"]):
            return f"{name} (not fitted: {r.get('why', 'no fit')})"
        return f"{name} (held-out D {r['holdout_discrepancy']:.3g}, fitted {r['fitted_discrepancy']:.3g})"
    tried = "; ".join(one(r) for r in rows)
    best = rows[0]
    if math.isfinite(best["holdout_discrepancy"]) and best["holdout_discrepancy"] < d_held:
        name = best["effect"] if best["gyro"] is None else f"{best['effect']}:{best['gyro']}"
        return (f"by the held-out D, the term it lacks is {name}: it lowers the held-out D most "
                f"({d_held:.3g} -> {best['holdout_discrepancy']:.3g}); each candidate fitted in on the "
                f"fitted part and validated held out: {tried}")
    return (f"no candidate lowers the held-out D ({d_held:.3g}); each candidate fitted in on the fitted "
            f"part and validated held out: {tried}")


def _add_compare_args(p, *, out: bool):
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    add_bag_options(p)
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="noise model to calibrate (default: ARW + RRW on every gyro)")
    p.add_argument("--runs", type=count("--runs"), default=40, metavar="K",
                   help="Monte-Carlo runs of the model band (40)")
    p.add_argument("--seed", type=nonneg_int("--seed"), default=0, help="seed of the model band (0)")
    p.add_argument("--repair", action="store_true", help="repair short gaps, missing values, exact duplicate rows and a jittering clock (each listed)")
    p.add_argument("--ref-smooth", type=float_in("--ref-smooth", 0.0, unit="s"), default=0.0, metavar="SECONDS",
                   help="smooth a noisy reference rate (a differentiated encoder) by a centred moving "
                        "average of this length before comparing; scale factor, nonlinearity, misalignment "
                        "and latency are then fitted against the recorded reference with the smoothed one "
                        "as instrument (0: as recorded)")
    add_plugin(p)
    if out:
        add_force(p)
        p.add_argument("--out", type=Path, required=True, metavar="REPORT.html")
        p.add_argument("--md", type=Path, metavar="REPORT.md", help="also write a Markdown twin")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def add_parser(sub) -> None:
    """The ``compare``, ``diagnose``, ``fit`` and ``ladder`` subcommands (measurement vs model)."""
    p = sub.add_parser("compare", help="measurement vs model: calibrate, model band, diagnostics report")
    _add_compare_args(p, out=True)
    p.add_argument("--validate", action="store_true",
                   help="keep every parameter of --model fixed (only the starting biases are fitted): "
                        "does the model fitted on another run predict this one?")
    p.set_defaults(func=cmd_compare)

    p = sub.add_parser("diagnose", help="which effect is the model missing: candidates ranked by significance")
    _add_compare_args(p, out=False)
    p.add_argument("--validate", action="store_true",
                   help="keep every parameter of --model fixed: does it predict this record?")
    p.set_defaults(func=cmd_diagnose)

    p = sub.add_parser("fit", help="fit the model (plus --add EFFECT[:GYRO]) to a measurement")
    _add_compare_args(p, out=False)
    p.add_argument("more", nargs="*", type=Path, metavar="MORE.csv",
                   help="more records of the same array (same gyros and layout): each gyro's white level "
                        "is read on every record and the model says which gyros wander between them "
                        "(the other terms are fitted on the first record)")
    p.add_argument("--add", action="append", metavar="EFFECT[:GYRO]",
                   help="effect to add before fitting (repeatable), e.g. scale_factor:2, burst; an effect "
                        "that acts on one gyro at a time, without a gyro (or EFFECT:all), is added to every gyro")
    p.add_argument("--out", type=Path, metavar="NEW.toml", help="write the fitted model (readable by --model)")
    p.add_argument("--gaps", action="store_true",
                   help="accept gaps in the time stamps (dropped samples): the deviation is pooled over "
                        "the contiguous parts, nothing interpolated (gaps and missing samples counted)")
    add_force(p)
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("ladder", help="diagnose -> add the best effect -> fit, until consistent; report")
    _add_compare_args(p, out=True)
    p.add_argument("--max-steps", type=count("--max-steps"), default=8, metavar="K",
                   help="effects added at most (8)")
    p.add_argument("--model-out", type=Path, metavar="NEW.toml", help="write the final fitted model")
    p.add_argument("more", nargs="*", type=Path, metavar="MORE.csv",
                   help="with --model-out: more records of the same array; each gyro's white level in the "
                        "model is read across all of them (as fit MEAS MORE...)")
    p.add_argument("--holdout", type=finite_float("--holdout"), metavar="FRACTION",
                   help="run the ladder on the first part of the record, then validate its model on the "
                        "last FRACTION (e.g. 0.3)")
    p.set_defaults(func=cmd_ladder)

