"""The ``gyroarray`` command line.

Every subcommand takes ``--json``: then stdout carries exactly one JSON
object and nothing else. Bad input gives one line on stderr naming the
file/line/column and the problem, and exit code 2 — never a traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path
from typing import Callable

from .errors import InputError

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exit code 2."""

    def error(self, message: str):  # noqa: D401 - argparse API
        raise InputError(f"{message} (see '{self.prog} --help')")


def _finite_float(name: str) -> Callable[[str], float]:
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name} must be finite, got {text!r}")
        return value
    return parse


def _json_safe(obj):
    """Replace non-finite floats by None so the output is strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    return obj


def _output(path, args, what: str, *, inputs=(), suffixes=None):
    """Check an output file the user named, before any work (:mod:`gyroarray.outputs`)."""
    from .outputs import check_output
    if path is None:
        return None
    return check_output(path, inputs=inputs, force=getattr(args, "force", False), what=what,
                        suffixes=suffixes)


def _measurement_inputs(args) -> list:
    """The files of a command's measurement and model arguments."""
    from .outputs import measurement_files
    files = measurement_files(args.measurement) if getattr(args, "measurement", None) else []
    if getattr(args, "model", None) is not None:
        files.append(args.model)
    return files


def _add_plugin(p):
    p.add_argument("--plugin", action="append", type=Path, metavar="PATH.py",
                   help="load the effects defined in this Python file (repeatable); the only way "
                        "user code runs: scenario, model and measurement files are never executed")


def _add_force(p):
    p.add_argument("--force", action="store_true",
                   help="replace output files that exist (never an input of the command)")


# -- gdop / design ------------------------------------------------------------

def _add_layout_args(p: argparse.ArgumentParser, *, alpha: bool, required: bool):
    p.add_argument("--scheme", type=int, choices=(1, 2), required=required,
                   help="conical scheme: 1 all gyros on the cone, 2 gyro 1 on +z")
    p.add_argument("--n", type=int, required=required, metavar="N", help="number of gyros (>= 3)")
    if alpha:
        p.add_argument("--alpha", type=_finite_float("--alpha"), required=True, metavar="DEG",
                       help="cone angle from +z [deg]")
    p.add_argument("--rho", type=_finite_float("--rho"), default=0.0, metavar="R",
                   help="common ARW correlation factor [-] (default 0)")


def cmd_gdop(args) -> tuple[dict, str]:
    from .design import gdop
    from .layout import Layout
    from .units import deg_to_rad
    layout = Layout.conical(args.scheme, args.n, deg_to_rad(args.alpha))
    g = gdop(layout, args.rho)
    text = f"GDOP = {g:.6f}  (scheme {args.scheme}, N = {args.n}, alpha = {args.alpha:g} deg, rho = {args.rho:g})"
    return {"gdop": g}, text


def cmd_design(args) -> tuple[dict, str]:
    from . import design
    from .units import rad_to_deg
    out: dict = {}
    lines: list[str] = []
    from .outputs import PLOT_SUFFIXES
    _output(args.plot, args, "--plot", suffixes=PLOT_SUFFIXES)
    if args.scheme is not None or args.n is not None:
        if args.scheme is None or args.n is None:
            raise InputError("gyroarray design: --scheme and --n go together")
        opt = design.optimal_alpha(args.scheme, args.n, args.rho)
        out.update({"alpha_opt_deg": rad_to_deg(opt.alpha_rad), "gdop_min": opt.gdop})
        lines.append(f"scheme {args.scheme}, N = {args.n}, rho = {args.rho:g}: "
                     f"optimal alpha = {rad_to_deg(opt.alpha_rad):.4f} deg, GDOP min = {opt.gdop:.6f}")
    if args.paper_tables:
        cells = design.paper003_cells()
        out["paper_tables"] = [c.to_dict() for c in cells]
        out["cells_not_reproduced"] = sum(not c.reproduces for c in cells)
        lines.append(_format_paper_cells(cells))
    if args.plot is not None:
        from .reports.design_plots import design_figure
        path = design_figure(args.plot, force=args.force)
        out["plot"] = str(path)
        lines.append(f"wrote {path}")
    if not out:
        table = design.optimum_table()
        out["optima"] = table
        lines.append(_format_optimum_table(table))
    return out, "\n".join(lines)


def _format_optimum_table(rows: list[dict]) -> str:
    head = f"{'scheme':>6} {'N':>3} {'rho':>6} {'alpha_opt_deg':>14} {'gdop_min':>9} {'3/sqrt(N)':>9}"
    body = [f"{r['scheme']:>6} {r['n']:>3} {r['rho']:>6g} {r['alpha_opt_deg']:>14.4f} "
            f"{r['gdop_min']:>9.4f} {3 / math.sqrt(r['n']):>9.4f}" for r in rows]
    return "Optimal cone angles (GDOP = sqrt(trace((H' C^-1 H)^-1)))\n" + "\n".join([head, *body])


def _format_paper_cells(cells) -> str:
    head = f"{'table':<10} {'cell':<40} {'quantity':<9} {'paper':>9} {'computed':>10}  reproduces"
    body = []
    for c in cells:
        mark = "yes" if c.reproduces else f"NO  (computed {c.computed:.4f}, diff {c.computed - c.paper_value:+.4f})"
        body.append(f"{c.table:<10} {c.label:<40} {c.quantity:<9} {c.paper:>9} {c.computed:>10.4f}  {mark}")
    bad = sum(not c.reproduces for c in cells)
    foot = (f"{bad} of {len(cells)} printed cells do not reproduce within one unit of their last "
            "printed digit (the paper has errata; computed values are gyroarray's).")
    return "Paper 003 Tables 1, 2 and the Section 3 optima beside gyroarray\n" + "\n".join([head, *body, foot])


# -- allan --------------------------------------------------------------------

def _parse_taus(text: str):
    """``octave``, a count of log-spaced taus, or a comma-separated list of taus [s]."""
    if text == "octave":
        return "octave"
    if "," in text:
        try:
            return [float(v) for v in text.split(",")]
        except ValueError:
            raise InputError(f"--taus list must hold numbers of seconds, got {text!r}") from None
    try:
        count = int(text)
    except ValueError:
        raise InputError("--taus must be 'octave', a whole number of log-spaced taus or a "
                         f"comma-separated list of taus in s, got {text!r}") from None
    if count < 2:
        raise InputError(f"--taus needs at least 2 log-spaced taus, got {count}")
    return count


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
    from .analysis.allan import allan_analysis, plot_allan
    from .measurement import read_measurement
    from .outputs import PLOT_SUFFIXES
    taus = _parse_taus(args.taus)
    _output(args.plot, args, "--plot", inputs=_measurement_inputs(args), suffixes=PLOT_SUFFIXES)
    meas = read_measurement(args.measurement, repair=args.repair)
    if args.gyro is not None and not 1 <= args.gyro <= meas.n_gyros:
        raise InputError(f"--gyro {args.gyro} is out of range: the measurement has "
                         f"gyros 1..{meas.n_gyros}", file=str(args.measurement))
    gyros = [args.gyro] if args.gyro is not None else list(range(1, meas.n_gyros + 1))
    signal, what = allan_signal(meas, raw=args.raw)
    analyses = {}
    for k in gyros:
        try:
            analyses[k] = allan_analysis(signal[:, k - 1], meas.dt_s, taus, kind=args.kind)
        except InputError as err:
            raise InputError(f"gyro {k}: {err.message}", file=str(args.measurement)) from None
    out = {"gyros": {str(k): a.to_json_dict() for k, a in analyses.items()},
           "signal": what, "notes": list(meas.notes)}
    lines = [f"{args.measurement}: {meas.n_samples} samples at {1 / meas.dt_s:g} Hz, "
             f"{meas.n_gyros} gyros; analysed: {what}", *[f"note: {n}" for n in meas.notes]]
    for k, a in analyses.items():
        lines.append(_format_allan(k, a.to_json_dict()))
    if args.plot is not None:
        path = plot_allan({f"gyro {k}": a for k, a in analyses.items()}, args.plot, force=args.force)
        out["plot"] = str(path)
        lines.append(f"wrote {path}")
    return out, "\n".join(lines)


def _format_allan(k: int, d: dict) -> str:
    fit = d["fit"]

    def val(key: str, fmt: str = ".4g") -> str:
        v, s = fit.get(key), fit.get(key + "_sigma")
        if v is None:
            return "-"
        return f"{v:{fmt}} ± {s:{fmt}}" if s is not None else f"{v:{fmt}}"
    rows = [f"gyro {k} ({d['kind']}, {100 * d['confidence']:.1f}% CI)",
            f"  {'tau_s':>10} {'adev_deg_h':>12} {'ci_low':>12} {'ci_high':>12}"]
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


# -- davar --------------------------------------------------------------------

def cmd_davar(args) -> tuple[dict, str]:
    from .analysis import davar as dv
    if args.paper_table1:
        table = dv.paper_table1(tuple(range(args.seeds)))
        return table.to_json_dict(), dv.format_paper_table1(table)
    if args.measurement is None:
        raise InputError("gyroarray davar: give MEAS.csv (or --paper-table1)")
    if args.gyro is None:
        raise InputError("gyroarray davar: --gyro K is required (one gyro at a time)")
    if args.window is not None and args.adaptive:
        raise InputError("gyroarray davar: --window L and --adaptive exclude each other "
                         "(the adaptive window runs between --l-min and --l-max)")
    from .measurement import read_measurement
    from .outputs import PLOT_SUFFIXES
    _output(args.plot, args, "--plot", inputs=_measurement_inputs(args), suffixes=PLOT_SUFFIXES)
    meas = read_measurement(args.measurement, repair=args.repair)
    if not 1 <= args.gyro <= meas.n_gyros:
        raise InputError(f"--gyro {args.gyro} is out of range: the measurement has gyros "
                         f"1..{meas.n_gyros}", file=str(args.measurement))
    signal, what = allan_signal(meas)
    adaptive = args.adaptive or args.window is None
    params = dv.AdaptiveWindow(l_max=args.l_max, l_min=args.l_min) if adaptive else None
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
        out["plot"] = str(dv.plot_davar(res, args.plot, force=args.force))
        lines.append(f"wrote {out['plot']}")
    return out, "\n".join(lines)


def _positive_int(name: str) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a whole number, got {text!r}") from None
        if value < 1:
            raise argparse.ArgumentTypeError(f"{name} must be >= 1, got {value}")
        return value
    return parse


# -- simulate -----------------------------------------------------------------

def tracking_datasheet(tracking) -> list[dict]:
    """The rate table's tracking report per segment, in deg/s and deg (the CLI edge)."""
    from .units import rad_s_to_deg_s, rad_to_deg

    def opt(x, conv):
        return None if x is None else conv(x)
    return [{"segment": s.index, "kind": s.kind, "label": s.label, "start_s": s.start_s,
             "end_s": s.end_s, "rms_error_deg_s": rad_s_to_deg_s(s.rms_error_rad_s),
             "max_error_deg_s": rad_s_to_deg_s(s.max_error_rad_s),
             "steady_rate_error_deg_s": [rad_s_to_deg_s(v) for v in s.steady_rate_error_rad_s],
             "amplitude_ratio": s.amplitude_ratio,
             "phase_lag_deg": opt(s.phase_lag_rad, rad_to_deg),
             "hold_attitude_error_deg": opt(s.hold_attitude_error_rad, rad_to_deg)}
            for s in tracking.segments]


def cmd_simulate(args) -> tuple[dict, str]:
    from .sim.scenario import load_scenario, simulate_to_files
    scenario = load_scenario(args.scenario)
    csv_path, toml_path, result = simulate_to_files(scenario, args.out, cache=not args.no_cache,
                                                    force=args.force)
    effects = [{"effect": e.effect, "gyro": e.gyro, "params": _plain_params(e.params)}
               for e in scenario.model.entries]
    out = {"scenario": scenario.name, "measurement": str(csv_path), "sidecar": str(toml_path),
           "n_samples": int(result.truth.time_s.size), "n_gyros": scenario.layout.n_gyros,
           "sample_rate_hz": scenario.sample_rate_hz, "seed": scenario.seed,
           "effects": effects, "tracking": tracking_datasheet(result.truth.tracking)}
    lines = [f"simulated {scenario.name}: {out['n_samples']} samples x {out['n_gyros']} gyros "
             f"at {scenario.sample_rate_hz:g} Hz (seed {scenario.seed})",
             f"wrote {csv_path}", f"wrote {toml_path}", "effects:"]
    lines += [f"  {e['effect']}" + (f" (gyro {e['gyro']})" if e["gyro"] else "")
              + ": " + ", ".join(f"{k} = {v}" for k, v in e["params"].items()) for e in effects]
    lines += ["rate table tracking (realised vs commanded):", result.truth.tracking.table()]
    return out, "\n".join(lines)


def _plain_params(params) -> dict:
    import numpy as np
    return {k: (np.asarray(v).tolist() if isinstance(v, (list, tuple, np.ndarray)) else v)
            for k, v in params.items()}


# -- run --------------------------------------------------------------------

_RUN_COLUMNS = (("sigma_1_deg_s", "1sigma[deg/s]", ".4g"), ("reduction", "reduct.", ".3g"),
                ("attenuation", "atten.", ".5f"), ("phase_deg", "phase[deg]", ".3g"),
                ("arw_deg_rt_h", "ARW[deg/rt h]", ".4g"), ("bi_deg_h", "BI[deg/h]", ".4g"),
                ("rrw_deg_h_rt_h", "RRW[deg/h/rt h]", ".4g"), ("efficiency", "effic.", ".3f"))


def cmd_run(args) -> tuple[dict, str]:
    from .chain import run_scenario
    from .sim.scenario import load_scenario
    names = [n.strip() for n in args.estimators.split(",") if n.strip()] if args.estimators else None
    scenario = load_scenario(args.scenario)
    result = run_scenario(scenario, names, cache=not args.no_cache)
    out = result.to_json_dict()

    def cell(v, fmt):
        return "-" if v is None or (isinstance(v, float) and v != v) else format(v, fmt)
    head = f"{'estimator':<10} {'axis':<4} " + " ".join(f"{h:>15}" for _, h, _ in _RUN_COLUMNS)
    lines = [f"scenario {scenario.name}" + (f" (swing {result.swing_hz:g} Hz)" if result.swing_hz else ""), head]
    for row in result.table.to_dict("records"):
        lines.append(f"{row['estimator']:<10} {row['axis']:<4} "
                     + " ".join(f"{cell(row.get(k), f):>15}" for k, _, f in _RUN_COLUMNS))
    lines += [f"note: {n}" for n in result.notes]
    sg = out["single_gyro"]
    lines.append(f"single gyro (mean of {len(sg['gyros'])}): 1sigma {sg['sigma_1_deg_s']:.4g} deg/s, "
                 f"ARW {sg['arw_deg_rt_h']:.4g} deg/rt(h), BI {sg['bi_deg_h']:.4g} deg/h, "
                 f"RRW {sg['rrw_deg_h_rt_h']:.4g} deg/h/rt(h)")
    return out, "\n".join(lines)


# -- sweep --------------------------------------------------------------------

def cmd_sweep(args):
    from .scenarios.runner import run_sweep
    if args.workers is not None and args.scheduler is not None:
        raise InputError("gyroarray sweep: --workers and --scheduler exclude each other")
    summary = run_sweep(args.sweep, args.out, workers=args.workers or 1,
                        scheduler=args.scheduler, progress=None if not args.json else False)
    lines = [f"sweep {summary['sweep']}: {summary['scenarios']} scenarios, ran {summary['ran']}, "
             f"skipped {summary['skipped']} (already done), failed {len(summary['failed'])}, "
             f"{summary['rows_written']} rows in {summary['seconds']:.1f} s -> {summary['dataset']}"]
    lines += [f"failed {f['id']}: {f['error']}" for f in summary["failed"]]
    lines += [f"note: {n}" for n in summary.get("notes", [])]
    lines += [f"left out (skip_invalid) {x['id']}: {x['reason']}" for x in summary["excluded"]]
    return summary, "\n".join(lines), (EXIT_OK if summary["complete"] else EXIT_FAIL)


# -- report -------------------------------------------------------------------

def cmd_report(args):
    from .reports.report import write_report
    if args.top < 1:
        raise InputError("gyroarray report: --top must be >= 1")
    inputs = [args.paper_values] if args.paper_values is not None else []
    _output(args.out, args, "--out", inputs=inputs, suffixes=(".html", ".htm"))
    _output(args.md, args, "--md", inputs=inputs, suffixes=(".md",))
    res = write_report(args.dirs, args.out, args.md, paper_values=args.paper_values, top=args.top,
                       force=args.force)
    lines = [f"report: {res['html']}" + (f" (Markdown twin {res['markdown']})" if res["markdown"] else "")
             + f", {res['figures']} figures, {res['seconds']:.1f} s"]
    for b in res["best"]:
        lines.append(f"best for {b['motion']}: scheme {b['scheme']}, N = {b['n_gyros']}, "
                     f"alpha = {b['alpha_deg']:.2f} deg, rho_arw = {b['rho_arw']}, {b['estimator']}: "
                     f"1-sigma {b['sigma_1_deg_s']:.4g} deg/s")
    flagged = [(e["title"], v) for e in res["paper_vs_model"] for v in e["values"] if v["flag"]]
    n_all = sum(len(e["values"]) for e in res["paper_vs_model"])
    if n_all:
        lines.append(f"paper vs model: {n_all - len(flagged)} of {n_all} published values inside "
                     "the model's 95 % band")
    lines += [f"note: {n}" for n in res["notes"]]
    return res, "\n".join(lines)


# -- check --------------------------------------------------------------------

def cmd_check(args):
    from .check import format_check, run_check
    result = run_check(args.thresholds, quick=not args.full)
    return result, format_check(result), (EXIT_OK if result["passed"] else EXIT_FAIL)


# -- fdi ----------------------------------------------------------------------

def cmd_fdi(args):
    from .analysis.fdi_score import analyse_measurement, format_fdi, plot_fdi
    from .measurement import read_measurement
    from .outputs import PLOT_SUFFIXES
    from .sim.model import NoiseModel
    _output(args.plot, args, "--plot", inputs=_measurement_inputs(args), suffixes=PLOT_SUFFIXES)
    meas = read_measurement(args.measurement, repair=args.repair)
    model = None if args.model is None else NoiseModel.from_toml(args.model, n_gyros=meas.n_gyros)
    out, res, _ = analyse_measurement(meas, model, far_per_h=args.far_per_h)
    text = format_fdi(out, str(args.measurement))
    if args.plot is not None:
        path = plot_fdi(res, args.plot, title=f"{args.measurement}: parity statistics",
                        force=args.force)
        text += f"\nwrote {path}"
    return out, text


# -- entry point --------------------------------------------------------------

# -- model vs measurement: compare / diagnose / fit / ladder ------------------------

def _comparison(args):
    """Check the outputs, read the measurement (and model) of a compare-family
    command; build the chain."""
    from .compare import ModelComparison
    from .measurement import read_measurement
    from .sim.model import NoiseModel
    inputs = _measurement_inputs(args)
    _output(getattr(args, "out", None), args, "--out", inputs=inputs,
            suffixes=(".toml",) if args.command == "fit" else (".html", ".htm"))
    _output(getattr(args, "md", None), args, "--md", inputs=inputs, suffixes=(".md",))
    _output(getattr(args, "model_out", None), args, "--model-out", inputs=inputs, suffixes=(".toml",))
    meas = read_measurement(args.measurement, repair=args.repair)
    model = None
    if args.model is not None:
        model = NoiseModel.from_toml(args.model, n_gyros=meas.n_gyros)
    return ModelComparison(meas, model, n_runs=args.runs, seed=args.seed)


def _model_lines(model) -> list[str]:
    out = []
    for e in model:
        if e.effect in ("arw", "rrw"):
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
    bands = [t for t in a.tests if t.kind == "adev_band" and a.significant(t)]
    if bands:
        lines += ["", "ADEV outside the model band:"] + [f"  {t.evidence} (z = {t.z:.1f})" for t in bands]
    un = a.unexplained()
    if un:
        lines += ["", "unexplained:"] + [f"  {u}" for u in un]
    if a.notes:
        lines += ["", "notes:"] + [f"  {n}" for n in a.notes]
    return "\n".join(lines)


def _write_report(comp, steps, args) -> dict:
    from .reports.compare_report import write_compare_report
    title = None
    if getattr(args, "validate", False):
        title = f"Validation: does the model ({comp.given_model.description or args.model}) predict {comp.name}?"
    return write_compare_report(comp, steps, args.out, args.md, title=title, force=args.force)


def _write_model(path: Path, model, args) -> str:
    """The fitted model as TOML at ``path`` (checked by :func:`_comparison`); returns the path."""
    from .outputs import write_text
    from .sim.model import NoiseModel
    model = NoiseModel(model.entries, description=f"fitted to {args.measurement} by gyroarray {args.command}")
    return str(write_text(path, model.to_toml(), force=args.force))


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
    _write_report(comp, steps, args)
    d = a.to_json_dict()
    res = {"discrepancy": a.discrepancy, "consistent": a.consistent, "z_crit": a.z_crit,
           "n_tests": len(a.tests), "report": str(args.out),
           "steps": [{"added": None if add is None else {"effect": add[0], "gyro": add[1]},
                      "discrepancy": s.discrepancy, "consistent": s.consistent} for add, s in steps],
           "adev_band": d["adev_band"], "candidates": d["candidates"][:10], "notes": a.notes}
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
            + f"\nreport: {args.out}" + (f" and {args.md}" if args.md is not None else ""))
    return res, text


def cmd_diagnose(args):
    comp = _comparison(args)
    if args.validate:
        if args.model is None:
            raise InputError("gyroarray diagnose --validate needs --model (the model to test)")
        a = comp.validate()
        out = a.to_json_dict()
        out["validated"] = True
        out["verdict"] = _validation_text(comp, a, args.model)
        return out, out["verdict"] + "\n" + _diagnosis_text(a, f"{comp.name}: {comp.N} gyros, {comp.n * comp.dt:.0f} s")
    a = comp.analyse()
    return a.to_json_dict(), _diagnosis_text(a, f"{comp.name}: {comp.N} gyros, {comp.n * comp.dt:.0f} s")


def cmd_fit(args):
    from .compare import parse_add
    comp = _comparison(args)
    add = [parse_add(x, comp.N) for x in (args.add or [])]
    before, after = comp.fit(add)
    res = {"discrepancy_before": before.discrepancy, "discrepancy_after": after.discrepancy,
           "consistent": after.consistent, "effects": after.effects_json()}
    if args.out is not None:
        res["model"] = _write_model(args.out, after.model, args)
    text = "\n".join([f"{comp.name}: discrepancy {before.discrepancy:.3g} -> {after.discrepancy:.3g} "
                      f"({'consistent' if after.consistent else 'NOT consistent'})",
                      "fitted model (beyond ARW + RRW):"] + (_model_lines(after.model) or ["  (baseline only)"])
                     + ([f"written to {args.out}"] if args.out is not None else []))
    return res, text


def cmd_ladder(args):
    comp = _comparison(args)
    held = None
    if args.holdout is not None:
        from .compare import ModelComparison, split_measurement
        first, rest = split_measurement(comp.m, args.holdout)
        comp = ModelComparison(first, comp.given_model, n_runs=args.runs, seed=args.seed)
        held = ModelComparison(rest, None, n_runs=args.runs, seed=args.seed)
    steps = comp.ladder(max_steps=args.max_steps)
    _write_report(comp, steps, args)
    final = steps[-1][1]
    res = {"steps": [{"added": None if add is None else {"effect": add[0], "gyro": add[1]},
                      "discrepancy": a.discrepancy, "consistent": a.consistent}
                     for add, a in steps],
           "discrepancy": final.discrepancy, "consistent": final.consistent,
           "effects": final.effects_json(), "unexplained": final.unexplained(),
           "candidates_left": [{"effect": t.effect, "gyro": t.gyro, "score": t.z, "evidence": t.evidence}
                               for t in final.candidates if final.significant(t)],
           "notes": list(final.notes), "report": str(args.out)}
    if args.model_out is not None:
        res["model"] = _write_model(args.model_out, final.model, args)
    held_text = []
    if held is not None:
        from .compare import ModelComparison
        from .sim.model import NoiseModel
        model = NoiseModel(final.model.entries, description=f"the ladder on {comp.name}")
        v = ModelComparison(held.m, model, n_runs=args.runs, seed=args.seed)
        va = v.validate()
        verdict = _validation_text(v, va, comp.name)
        res["holdout"] = {"fraction": args.holdout, "discrepancy": va.discrepancy, "consistent": va.consistent,
                          "verdict": verdict, "candidates": va.to_json_dict()["candidates"][:10]}
        held_text = [f"held out ({args.holdout:g} of the record): {verdict}"]
    lines = [f"{comp.name}: the ladder"]
    for add, a in steps:
        what = "calibrated model" if add is None else f"+ {add[0]}{'' if add[1] is None else ':' + str(add[1])}"
        lines.append(f"  {what:<28} D = {a.discrepancy:8.3g}  {'consistent' if a.consistent else ''}")
    lines += ["fitted model (beyond ARW + RRW):"] + (_model_lines(final.model) or ["  (baseline only)"])
    left = final.unexplained() + [t.evidence for t in final.candidates if final.significant(t)]
    lines += ["still unexplained:"] + ([f"  {x}" for x in left] or ["  nothing"])
    lines += [f"note: {x}" for x in final.notes if x.startswith("the ladder")]
    lines += held_text
    lines.append(f"report: {args.out}")
    return res, "\n".join(lines)


def _add_compare_args(p, *, out: bool):
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="noise model to calibrate (default: ARW + RRW on every gyro)")
    p.add_argument("--runs", type=_positive_int("--runs"), default=40, metavar="K",
                   help="Monte-Carlo runs of the model band (40)")
    p.add_argument("--seed", type=int, default=0, help="seed of the model band (0)")
    p.add_argument("--repair", action="store_true", help="repair short gaps and isolated NaNs")
    _add_plugin(p)
    if out:
        _add_force(p)
        p.add_argument("--out", type=Path, required=True, metavar="REPORT.html")
        p.add_argument("--md", type=Path, metavar="REPORT.md", help="also write a Markdown twin")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="gyroarray", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"gyroarray {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("gdop", help="GDOP of a conical layout")
    _add_layout_args(p, alpha=True, required=True)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_gdop)

    p = sub.add_parser("design", help="optimal cone angle, paper 003 tables, GDOP plots")
    _add_layout_args(p, alpha=False, required=False)
    p.add_argument("--paper-tables", action="store_true",
                   help="paper 003 Tables 1-2 beside the computed values, cell by cell")
    p.add_argument("--plot", type=Path, metavar="OUT.png",
                   help="write GDOP vs alpha and vs rho (paper 003 Figs. 8-10)")
    _add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_design)

    p = sub.add_parser("allan", help="Allan deviation with confidence intervals and noise fit")
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    p.add_argument("--gyro", type=int, metavar="K", help="only gyro K (1-based)")
    p.add_argument("--taus", default="octave", metavar="octave|N|T1,T2,...",
                   help="octave taus (default), N log-spaced taus, or a list of taus [s]")
    p.add_argument("--kind", choices=("oadev", "ohdev"), default="oadev",
                   help="overlapping Allan (default) or Hadamard deviation")
    p.add_argument("--repair", action="store_true",
                   help="repair short gaps and isolated NaNs (reported) instead of refusing them")
    p.add_argument("--raw", action="store_true",
                   help="analyse the raw gyro output even when a moving reference is present")
    p.add_argument("--plot", type=Path, metavar="OUT.png", help="write the ADEV plot")
    _add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_allan)

    p = sub.add_parser("davar", help="dynamic Allan deviation (fixed or adaptive window, paper 000)")
    p.add_argument("measurement", type=Path, nargs="?", metavar="MEAS.csv")
    p.add_argument("--gyro", type=int, metavar="K", help="gyro K (1-based)")
    p.add_argument("--adaptive", action="store_true",
                   help="adaptive window A-DAVAR (the default when --window is not given)")
    p.add_argument("--window", type=_positive_int("--window"), metavar="L", help="fixed window [samples]")
    p.add_argument("--step", type=_positive_int("--step"), metavar="S",
                   help="samples between windows (default: 1 adaptive, L/10 fixed)")
    p.add_argument("--l-max", type=_positive_int("--l-max"), default=600, metavar="L",
                   help="adaptive: longest window [samples] (default 600)")
    p.add_argument("--l-min", type=_positive_int("--l-min"), default=400, metavar="L",
                   help="adaptive: shortest window [samples] (default 400)")
    p.add_argument("--repair", action="store_true", help="repair short gaps and isolated NaNs")
    p.add_argument("--plot", type=Path, metavar="OUT.png", help="heat map + ARW and window tracks")
    _add_force(p)
    p.add_argument("--paper-table1", action="store_true",
                   help="reproduce paper 000 Table 1 (simulated) over --seeds realisations")
    p.add_argument("--seeds", type=_positive_int("--seeds"), default=20, metavar="N")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_davar)

    p = sub.add_parser("simulate", help="simulate a scenario into a measurement (CSV.GZ + TOML)")
    p.add_argument("scenario", type=Path, metavar="SCENARIO.toml")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    p.add_argument("--no-cache", action="store_true", help="recompute the rate-table truth")
    _add_force(p)
    _add_plugin(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("run", help="simulate a scenario and score fusion estimators")
    p.add_argument("scenario", type=Path, metavar="SCENARIO.toml")
    p.add_argument("--estimators", metavar="A,B,...",
                   help="registry names (default: kf_array, kf_single, gls, ols, naive, bound)")
    p.add_argument("--no-cache", action="store_true", help="recompute the rate-table truth")
    _add_plugin(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("sweep", help="run a sweep of scenarios in parallel into a Parquet dataset (resumable)")
    p.add_argument("sweep", type=Path, metavar="SWEEP.toml")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    p.add_argument("--workers", type=_positive_int("--workers"), metavar="K",
                   help="local worker processes (default 1)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a Dask distributed scheduler")
    p.add_argument("--json", action="store_true", help="print one JSON object (no progress bar)")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("report", help="design comparison report (HTML + Markdown) from sweep folders")
    p.add_argument("dirs", type=Path, nargs="+", metavar="DIR", help="gyroarray sweep --out folders")
    p.add_argument("--out", type=Path, required=True, metavar="REPORT.html")
    p.add_argument("--md", type=Path, metavar="REPORT.md", help="also write a Markdown twin")
    p.add_argument("--paper-values", type=Path, metavar="FILE",
                   help="paper values to compare with (default: the shipped scenarios/paper_values.toml)")
    p.add_argument("--top", type=int, default=15, metavar="K", help="designs listed per motion (15)")
    _add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_report)

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
    p.add_argument("--add", action="append", metavar="EFFECT[:GYRO]",
                   help="effect to add before fitting (repeatable), e.g. scale_factor:2, burst")
    p.add_argument("--out", type=Path, metavar="NEW.toml", help="write the fitted model (readable by --model)")
    _add_force(p)
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("ladder", help="diagnose -> add the best effect -> fit, until consistent; report")
    _add_compare_args(p, out=True)
    p.add_argument("--max-steps", type=_positive_int("--max-steps"), default=8, metavar="K",
                   help="effects added at most (8)")
    p.add_argument("--model-out", type=Path, metavar="NEW.toml", help="write the final fitted model")
    p.add_argument("--holdout", type=_finite_float("--holdout"), metavar="FRACTION",
                   help="run the ladder on the first part of the record, then validate its model on the "
                        "last FRACTION (e.g. 0.3)")
    p.set_defaults(func=cmd_ladder)

    p = sub.add_parser("fdi", help="fault detection and isolation on a measurement (parity space)")
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="ARW/RRW/correlation of the gyros (default: estimated from the record)")
    p.add_argument("--far-per-h", type=_finite_float("--far-per-h"), default=0.01, metavar="RATE",
                   help="false alarms per hour the thresholds are set for (0.01)")
    p.add_argument("--plot", type=Path, metavar="OUT.png", help="statistics vs threshold over time")
    p.add_argument("--repair", action="store_true", help="repair short gaps and isolated NaNs")
    _add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_fdi)

    p = sub.add_parser("check", help="regression thresholds: run the threshold scenarios, exit 1 on a failure")
    p.add_argument("thresholds", type=Path, nargs="?", metavar="THRESHOLDS.toml",
                   help="default: the shipped scenarios/thresholds.toml")
    p.add_argument("--full", action="store_true",
                   help="run each scenario at its full length (slow; default: the quick version)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_check)
    return parser


def _version() -> str:
    from . import __version__
    return __version__


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0 ok, 1 failure, 2 bad input)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if getattr(args, "plugin", None):
            from .effects import plugin_effects
            plugin_effects(args.plugin)
        result, text, *code = args.func(args)
    except InputError as err:
        print(f"gyroarray: {err}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("gyroarray: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # an internal bug, not bad input: keep stderr to one line
        if os.environ.get("GYROARRAY_DEBUG"):
            raise
        print(f"gyroarray: internal error: {type(err).__name__}: {err} "
              "(set GYROARRAY_DEBUG=1 for the traceback)", file=sys.stderr)
        return EXIT_FAIL
    try:
        if getattr(args, "json", False):
            json.dump(_json_safe(result), sys.stdout, allow_nan=False)
            sys.stdout.write("\n")
        else:
            print(text)
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. piped into `head`: not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return code[0] if code else EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
