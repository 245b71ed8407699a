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
import re
import sys
import warnings
from pathlib import Path
from typing import Any, Callable

from gyroarray.core.errors import InputError, one_line

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exit code 2."""

    plugin_help = False          # True: --help lists the installed plugins

    def error(self, message: str):  # noqa: D401 - argparse API
        raise InputError(f"{message} (see '{self.prog} --help')")

    def format_help(self) -> str:
        text = super().format_help()
        return text + _plugins_help() if getattr(self, "plugin_help", False) else text


def _plugins_help() -> str:
    """What installed third-party code scenario, model and sweep files may load by name."""
    from gyroarray.core.plugins import EFFECTS_GROUP as EFFECTS, ESTIMATORS_GROUP as ESTIMATORS, installed

    def listed(pairs):
        return "\n".join(f"  {name} = {value}" for name, value in pairs) or "  (none installed)"
    return (f"\ninstalled effect plugins (entry-point group {EFFECTS!r}; imported when the effect "
            f"registry loads, named by scenario and model files):\n{listed(installed(EFFECTS))}\n"
            f"installed estimator plugins (group {ESTIMATORS!r}; imported when --estimators or a "
            f"sweep file names one):\n{listed(installed(ESTIMATORS))}\n"
            "--plugin PATH.py runs that file. --scheduler tcp://... exchanges pickled tasks: use only "
            "a scheduler you trust (README: 'What gyroarray trusts').\n")


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


def _float_in(name: str, lo: float = -math.inf, hi: float = math.inf, *, lo_open: bool = False,
              unit: str = "") -> Callable[[str], float]:
    """An argparse type: a finite number in [lo, hi] (``(lo`` when ``lo_open``), refused in one
    line naming the argument and the range."""
    finite = _finite_float(name)
    if hi == math.inf:
        span = (">" if lo_open else ">=") + f" {lo:g}"
    else:
        span = "in " + ("(" if lo_open else "[") + f"{lo:g}, {hi:g}]"
    span += f" {unit}" if unit else ""

    def parse(text: str) -> float:
        value = finite(text)
        if value < lo or (lo_open and value == lo) or value > hi:
            raise argparse.ArgumentTypeError(f"{name} must be {span}, got {text}")
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
    """Check an output file the user named, before any work (:mod:`gyroarray.core.outputs`)."""
    from gyroarray.core.outputs import check_output
    if path is None:
        return None
    return check_output(path, inputs=inputs, force=getattr(args, "force", False), what=what,
                        suffixes=suffixes)


def _measurement_inputs(args) -> list:
    """The files of a command's measurement and model arguments."""
    from gyroarray.core.outputs import measurement_files
    files = measurement_files(args.measurement) if getattr(args, "measurement", None) else []
    if getattr(args, "model", None) is not None:
        files.append(args.model)
    return files


def _add_plugin(p):
    p.add_argument("--plugin", action="append", type=Path, metavar="PATH.py",
                   help="load the effects and estimators defined in this Python file (repeatable), "
                        "once they pass the conformance checks; the only way user code runs: "
                        "scenario, model and measurement files are never executed")


def _add_force(p):
    p.add_argument("--force", action="store_true",
                   help="replace output files that exist (never an input of the command)")


# -- gdop / design ------------------------------------------------------------

#: Most gyros a design question may ask about (the search costs O(N³) per angle).
MAX_DESIGN_GYROS = 128
#: Most taus ``allan --taus`` may ask for (an octave grid of 1e9 samples has 30).
MAX_TAUS = 10_000


#: Caps of the counts a user passes (issue 28: each is checked before any work, with the
#: reason and the way out in the refusal). ``(cap, why)`` per option.
COUNT_CAPS = {
    "--runs": (1000, "the model band's 95 % limits settle within 1 % long before that"),
    "--replicates": (1000, "a 95 % confidence interval from 1000 runs is already within 5 % of "
                           "its width; run several seeds for more"),
    "--check": (1000, "1000 paired runs resolve differences of a few per cent"),
    "--workers": (256, "more processes than CPUs only wait for them"),
    "--max-steps": (64, "each step adds one effect; no model needs more"),
}


def _count(name: str) -> Callable[[str], int]:
    """A whole number from 1 to the cap of ``name`` in :data:`COUNT_CAPS`, refused at parse
    time (before any file is read) with the reason and the way out."""
    cap, why = COUNT_CAPS[name]
    positive = _positive_int(name)

    def parse(text: str) -> int:
        value = positive(text)
        if value > cap:
            raise argparse.ArgumentTypeError(f"{name} {value} is more than {cap}, the most "
                                             f"gyroarray runs ({why}); give {name} {cap} or less")
        return value
    return parse


def _check_count(name: str, value: int, bytes_per: float, what: str) -> None:
    """Refuse a count whose memory (``value`` x ``bytes_per`` [bytes]) passes the budget,
    before the work (:func:`gyroarray.core.limits.check_memory`)."""
    from gyroarray.core.limits import check_memory
    check_memory(value * float(bytes_per), f"{name} {value} ({what})", f"lower {name}")


def _bounded_int(name: str, lo: int, hi: int) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a whole number, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{name} must be from {lo} to {hi}, got {value}")
        return value
    return parse


def _add_layout_args(p: argparse.ArgumentParser, *, alpha: bool, required: bool):
    p.add_argument("--scheme", type=int, choices=(1, 2), required=required,
                   help="conical scheme: 1 all gyros on the cone, 2 gyro 1 on +z")
    p.add_argument("--n", type=_bounded_int("--n", 3, MAX_DESIGN_GYROS), required=required, metavar="N",
                   help=f"number of gyros (3 to {MAX_DESIGN_GYROS})")
    if alpha:
        p.add_argument("--alpha", type=_float_in("--alpha", 0.0, 180.0, unit="deg"), required=True, metavar="DEG",
                       help="cone angle from +z [deg]")
    p.add_argument("--rho", type=_finite_float("--rho"), default=0.0, metavar="R",
                   help="common ARW correlation factor [-] (default 0)")


def cmd_gdop(args) -> tuple[dict, str]:
    from gyroarray.core.gdop import gdop, gdop_note
    from gyroarray.core.layout import Layout
    from gyroarray.core.units import deg_to_rad
    layout = Layout.conical(args.scheme, args.n, deg_to_rad(args.alpha))
    g = gdop(layout, args.rho)
    note = gdop_note(layout, args.rho)
    text = f"GDOP = {g:.6f}  (scheme {args.scheme}, N = {args.n}, alpha = {args.alpha:g} deg, rho = {args.rho:g})"
    out: dict[str, float | str] = {"gdop": g}
    if note:
        out["note"] = note
        text += f"\nnote: {note}"
    return out, text


def cmd_design(args) -> tuple[dict, str]:
    from gyroarray.core import gdop as design
    from gyroarray.core.units import rad_to_deg
    if args.recommend:
        return _design_recommend(args)
    rec_only = [o for o, v in (("--model", args.model), ("--arw", args.arw), ("--rrw", args.rrw),
                                ("--bi", args.bi), ("--rho-range", args.rho_range),
                                ("--swing", args.swing), ("--motion", args.motion),
                                ("--failures", args.failures), ("--estimators", args.estimators),
                                ("--check", args.check), ("--out", args.out),
                                ("--bandwidth-hz", args.bandwidth_hz), ("--rate-hz", args.rate_hz),
                                ("--sensor-bandwidth", args.sensor_bandwidth),
                                ("--g-sensitivity", args.g_sensitivity),
                                ("--horizon-s", args.horizon_s)) if v is not None]
    if rec_only:
        raise InputError(f"gyroarray design: {rec_only[0]} goes with --recommend")
    out: dict = {}
    lines: list[str] = []
    from gyroarray.core.outputs import PLOT_SUFFIXES
    _output(args.plot, args, "--plot", suffixes=PLOT_SUFFIXES)
    rho = 0.0 if args.rho is None else args.rho
    if args.scheme is not None or args.n is not None:
        if args.scheme is None or args.n is None:
            raise InputError("gyroarray design: --scheme and --n go together")
        n = _single_n(args.n)
        opt = design.optimal_alpha(args.scheme, n, rho)
        out.update({"alpha_opt_deg": rad_to_deg(opt.alpha_rad), "gdop_min": opt.gdop})
        lines.append(f"scheme {args.scheme}, N = {n}, rho = {rho:g}: "
                     f"optimal alpha = {rad_to_deg(opt.alpha_rad):.4f} deg, GDOP min = {opt.gdop:.6f}")
        from gyroarray.core.layout import Layout
        note = design.gdop_note(Layout.conical(args.scheme, n, opt.alpha_rad), rho)
        if note:
            out["note"] = f"no cone angle gives a 3-axis rate: {note}"
            lines.append(f"note: {out['note']}")
    if args.paper_tables:
        cells = design.paper003_cells()
        out["paper_tables"] = [c.to_dict() for c in cells]
        out["cells_not_reproduced"] = sum(not c.reproduces for c in cells)
        lines.append(_format_paper_cells(cells))
    if args.plot is not None:
        from gyroarray.reports.design_plots import design_figure
        path = design_figure(args.plot, force=args.force)
        out["plot"] = str(path)
        lines.append(f"wrote {path}")
    if not out:
        table = design.optimum_table()
        out["optima"] = table
        lines.append(_format_optimum_table(table))
    return out, "\n".join(lines)


def _single_n(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise InputError(f"--n must be one whole number here (a list like 4,5,6,8 goes with "
                         f"--recommend), got {text!r}") from None
    if not 3 <= n <= MAX_DESIGN_GYROS:
        raise InputError(f"--n must be from 3 to {MAX_DESIGN_GYROS}, got {n}")
    return n


def _number_list(text: str, name: str, *, integer: bool = False) -> list:
    vals = []
    for part in text.split(","):
        part = part.strip()
        try:
            v = int(part) if integer else float(part)
        except ValueError:
            raise InputError(f"{name} must be a comma-separated list of "
                             f"{'whole numbers' if integer else 'numbers'}, got {text!r}") from None
        if not integer and not math.isfinite(v):
            raise InputError(f"{name} must hold finite numbers, got {text!r}")
        vals.append(v)
    return vals


#: Largest N the design search takes (every failure combination is enumerated).
MAX_DESIGN_N = 24


def _design_noise(args):
    """The GyroNoise of ``design --recommend`` (model file or datasheet, ρ) and the ρ range to
    test (None: a single ρ)."""
    import numpy as np
    from gyroarray.design.recommend import GyroNoise
    if args.model is not None and any(v is not None for v in (args.arw, args.rrw, args.bi)):
        raise InputError("gyroarray design: give the noise as --model MODEL.toml or as a datasheet "
                         "(--arw, --rrw, --bi), not both")
    if args.model is not None:
        from gyroarray.effects.model import NoiseModel
        g = GyroNoise.from_model(NoiseModel.from_toml(args.model), source=f"model {args.model}")
    elif args.arw is not None:
        g = GyroNoise(arw_deg_rt_h=args.arw, rrw_deg_h_rt_h=args.rrw or 0.0, bi_deg_h=args.bi or 0.0,
                      sources={"arw": "user", "rrw": "user" if args.rrw is not None else "default",
                               "bi": "user" if args.bi is not None else "default",
                               "gauss_markov": "default", "rho_arw": "default", "rho_rrw": "default"})
    else:
        raise InputError("gyroarray design --recommend: give the gyro noise: --model MODEL.toml (from "
                         "gyroarray fit --out) or --arw N_DEG_RT_H [--rrw K] [--bi B]")
    if args.rho is not None and args.rho_range is not None:
        raise InputError("gyroarray design: --rho and --rho-range exclude each other")
    rhos = None
    if args.rho is not None:
        g = g.with_rho(args.rho)
        g = GyroNoise(**{**g.__dict__, "sources": {**g.sources, "rho_arw": "user", "rho_rrw": "user"}})
    if args.rho_range is not None:
        lo, hi = (_number_list(args.rho_range, "--rho-range") + [None, None])[:2]
        if hi is None or len(args.rho_range.split(",")) != 2 or not -1 < lo < hi < 1:
            raise InputError(f"--rho-range must be LO,HI with -1 < LO < HI < 1, got {args.rho_range!r}")
        rhos = sorted(set(np.round(np.linspace(lo, hi, 5), 12).tolist() + ([0.0] if lo < 0 < hi else [])))
        g = GyroNoise(**{**g.with_rho(0.0).__dict__,
                         "sources": {**g.sources, "rho_arw": "user", "rho_rrw": "user"}})
    return g, rhos


def _design_motion(args, rate: float, horizon: float):
    """(swing, motion [rad/s] or None, its name, its specific force [m/s²] or None) of ``design``."""
    from gyroarray.design.predict import Swing
    from gyroarray.core.units import deg_s_to_rad_s
    force = None
    swing, motion, motion_name = None, None, "at rest"
    if args.swing is not None and args.motion is not None:
        raise InputError("gyroarray design: --swing and --motion exclude each other")
    if args.swing is not None:
        vals = _number_list(args.swing, "--swing")
        if len(vals) != 2 or not vals[0] > 0 or not 0 < vals[1] < 0.5 * rate:
            raise InputError(f"--swing must be AMP_DPS,FREQ_HZ with AMP > 0 and 0 < FREQ < Nyquist, "
                             f"got {args.swing!r}")
        swing = Swing(deg_s_to_rad_s(vals[0]), vals[1])
        motion_name = f"swing {vals[0]:g} deg/s at {vals[1]:g} Hz about each axis"
    if args.motion is not None:
        from gyroarray.sim.profiles import load_profile
        from gyroarray.sim.scenario import resolve_profile
        from gyroarray.sim.truth import compute_truth
        prof = load_profile(resolve_profile(args.motion, Path.cwd()))
        dur = min(horizon, prof.duration_s)
        if dur < horizon:
            raise InputError(f"--motion {args.motion} lasts {prof.duration_s:g} s, shorter than "
                             f"--horizon-s {horizon:g}")
        mtruth = compute_truth(prof, rate, duration_s=horizon)
        motion = mtruth.omega_body_rad_s
        motion_name = f"profile {args.motion} (rate-table truth)"
        force = mtruth.specific_force_m_s2
    return swing, motion, motion_name, force


def _design_bandwidth(args, rate: float, at_rest: bool, src: dict) -> list:
    """[LO, HI] of the rate band [Hz]: the user's, else the default at rest or 0.1 Hz to 0.45 fs
    in motion."""
    from gyroarray.design.recommend import DEFAULT_BANDWIDTH_HZ
    if args.bandwidth_hz is not None:
        bw = _number_list(args.bandwidth_hz, "--bandwidth-hz")
        if len(bw) == 1:
            bw = [bw[0], bw[0]]
        if len(bw) != 2 or not 0 < bw[0] <= bw[1] < 0.5 * rate:
            raise InputError(f"--bandwidth-hz must be F or LO,HI with 0 < LO <= HI < Nyquist "
                             f"({0.5 * rate:g} Hz), got {args.bandwidth_hz!r}")
        src["bandwidth_hz"] = "user"
    elif at_rest:
        bw = [DEFAULT_BANDWIDTH_HZ, DEFAULT_BANDWIDTH_HZ]
    else:
        bw = [0.1, 0.45 * rate]
    return bw


def _design_space(args):
    """The DesignSpace and GyroNoise of ``design --recommend`` (every default recorded)."""
    from gyroarray.design.recommend import ESTIMATORS, DesignSpace
    src = {}
    g, rhos = _design_noise(args)
    rate = 100.0 if args.rate_hz is None else args.rate_hz
    if not rate > 0:
        raise InputError(f"--rate-hz must be > 0, got {rate:g}")
    horizon = 600.0 if args.horizon_s is None else args.horizon_s
    if not horizon > 0:
        raise InputError(f"--horizon-s must be > 0, got {horizon:g}")
    if horizon * rate > 2e7:
        raise InputError(f"--horizon-s {horizon:g} at {rate:g} Hz is {horizon * rate:.3g} samples "
                         "(at most 2e7): shorten the horizon or lower the rate")
    ns = tuple(_number_list(args.n, "--n", integer=True)) if args.n is not None else (4, 5, 6, 8)
    bad = [n for n in ns if not 3 <= n <= MAX_DESIGN_N]
    if bad:
        raise InputError(f"--n {bad[0]} is outside 3..{MAX_DESIGN_N} (every failure combination is "
                         "enumerated)")
    failures = 0 if args.failures is None else args.failures
    if failures < 0 or failures > 2:
        raise InputError(f"--failures must be 0, 1 or 2, got {failures}")
    ests = ESTIMATORS
    if args.estimators is not None:
        ests = tuple(e.strip() for e in args.estimators.split(",") if e.strip())
        unknown = [e for e in ests if e not in ESTIMATORS]
        if unknown or not ests:
            raise InputError(f"--estimators: {unknown[0] if unknown else '(none)'} is not one the "
                             f"design search predicts ({', '.join(ESTIMATORS)})")
    swing, motion, motion_name, force = _design_motion(args, rate, horizon)
    bw = _design_bandwidth(args, rate, swing is None and motion is None, src)
    sensor_bw, src["sensor_bandwidth"] = _sensor_bandwidth_arg(args, rate)
    gsens = None
    if args.g_sensitivity is not None:
        gsens = _number_list(args.g_sensitivity, "--g-sensitivity")
        if len(gsens) == 1:
            gsens = [0.0, 0.0, gsens[0]]
        if len(gsens) != 3:
            raise InputError(f"--g-sensitivity must be K or KX,KY,KZ [(deg/s)/g], got {args.g_sensitivity!r}")
        src["g_sensitivity"] = "user"
    for key, v in (("rate_hz", args.rate_hz), ("horizon_s", args.horizon_s), ("ns", args.n),
                   ("estimators", args.estimators), ("failures", args.failures),
                   ("motion", args.swing or args.motion)):
        src[key] = "user" if v is not None else "default"
    space = DesignSpace(rate_hz=rate, horizon_s=horizon, ns=ns, estimators=ests, failures=failures,
                        bandwidth_hz=(float(bw[0]), float(bw[1])), swing=swing, motion=motion,
                        motion_name=motion_name, sensor_bandwidth=sensor_bw,
                        g_sensitivity_deg_s_per_g=None if gsens is None else tuple(gsens),
                        specific_force_m_s2=force)
    object.__setattr__(space, "_sources", src)
    return g, space, rhos


def parse_sensor_bandwidth(text: str, rate_hz: float) -> tuple[float, int]:
    """``HZ[,ORDER]`` of ``--sensor-bandwidth``: the gyros' own −3 dB cut-off [Hz] and filter
    order (1, default, or 2 = Butterworth), checked against the Nyquist frequency."""
    vals = _number_list(text, "--sensor-bandwidth")
    nyq = 0.5 * rate_hz
    if len(vals) not in (1, 2):
        raise InputError(f"--sensor-bandwidth must be HZ or HZ,ORDER, got {text!r}")
    fc = vals[0]
    order = vals[1] if len(vals) == 2 else 1
    if not fc > 0:
        raise InputError(f"--sensor-bandwidth: the cut-off must be > 0 Hz, got {fc:g}")
    if order not in (1, 2):
        raise InputError(f"--sensor-bandwidth: the order must be 1 or 2 (Butterworth), got {order:g}")
    if not fc < nyq:
        raise InputError(f"--sensor-bandwidth: the cut-off {fc:g} Hz must lie below the Nyquist "
                         f"frequency {nyq:g} Hz of --rate-hz {rate_hz:g}")
    return float(fc), int(order)


def _sensor_bandwidth_arg(args, rate: float):
    """The sensor bandwidth of ``design --recommend`` and its source: the flag, else the
    model's ``bandwidth`` (its lowest cut-off, the worst gyro), else none."""
    if args.sensor_bandwidth is not None:
        return parse_sensor_bandwidth(args.sensor_bandwidth, rate), "user"
    if args.model is not None:
        from gyroarray.effects.model import NoiseModel
        ents = [e for e in NoiseModel.from_toml(args.model).entries if e.effect == "bandwidth"]
        if ents:
            e = min(ents, key=lambda e: float(e.params["cutoff_hz"]))
            fc, order = float(e.params["cutoff_hz"]), int(e.params["order"])
            if not fc < 0.5 * rate:
                raise InputError(f"the model's bandwidth cut-off {fc:g} Hz is not below the Nyquist "
                                 f"frequency {0.5 * rate:g} Hz of --rate-hz {rate:g}", file=args.model)
            return (fc, order), f"model {args.model} (lowest cut-off)"
    return None, "default"


def _design_recommend(args) -> tuple[dict, str]:
    from gyroarray.design.recommend import monte_carlo_check, recommend
    _output(args.out, args, "--out", inputs=[args.model] if args.model is not None else [],
            suffixes=(".json",))
    g, space, rhos = _design_space(args)
    res = recommend(g, space, rhos=rhos)
    if args.check:
        res["check"] = monte_carlo_check(res["designs"], g, space, replicates=args.check,
                                         seed=20260412 if args.seed is None else args.seed)
    if args.out is not None:
        _write_json(args.out, res, args)
        res["written"] = str(args.out)
    return res, _recommend_text(res)


def _write_json(path: Path, obj: dict, args) -> None:
    """The result as JSON at ``path``, atomically (checked before the work by _design_recommend)."""
    from gyroarray.core.outputs import write_text
    write_text(path, json.dumps(_json_safe(obj), indent=1, allow_nan=False), force=args.force)


def _recommend_text(res: dict) -> str:
    from gyroarray.design.recommend import _label
    r = res["recommended"]
    lines = ["Designs, best predicted 3-axis RMS about the truth first:",
             f"{'rank':>4} {'design':<62} {'RMS 3-axis':>11} {'worst GDOP':>10}"]
    for d in res["designs"][:15]:
        lines.append(f"{d['rank']:>4} {_label(d):<62} {d['rms_3axis_deg_s']:>11.4g} "
                     f"{d['worst_gdop_after_failures']:>10.4g}")
    for grp in res["equivalent"][:6]:
        lines.append(f"equivalent (ranks {', '.join(map(str, grp['members']))}): {grp['reason']}")
    if "check" in res:
        c = res["check"]
        lines.append(f"Monte-Carlo check ({c['replicates']} paired runs): {c['inside_95']} of "
                     f"{c['compared']} predictions inside the runs' 95 % CI")
        for d in c["designs"]:
            t = d["rms_3axis_deg_s"]
            lines.append(f"  {d['label']}: predicted {t['predicted']:.4g}, simulated {t['monte_carlo']['value']:.4g} "
                         f"[{t['monte_carlo']['ci_low']:.4g}, {t['monte_carlo']['ci_high']:.4g}] deg/s")
    if "tracking_limit" in res:
        lines.append("tracking: " + res["tracking_limit"]["statement"])
    if "g_sensitivity" in res:
        lines.append(res["g_sensitivity"]["statement"])
    lines += [f"what would change the choice: {w}" for w in res["what_changes_the_choice"]]
    lines += [f"note: {n}" for n in res["notes"]]
    p = r["predicted"]
    lines += ["", "RECOMMENDED: " + _label(r),
              "  predicted RMS about the truth x/y/z: " + " / ".join(f"{p[a]['rms_deg_s']:.4g}" for a in "xyz")
              + " deg/s; angle error at the horizon: " + " / ".join(f"{p[a]['angle_deg_at_horizon']:.3g}" for a in "xyz")
              + " deg",
              f"  worst GDOP after {res['assumptions']['failures']['value']} failure(s): "
              f"{r['worst_gdop_after_failures']:.4g}; runner-up: "
              + (_label(res["runner_up"]) if res.get("runner_up") else "none")]
    return "\n".join(lines)


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
        if text.count(",") >= MAX_TAUS:
            raise InputError(f"--taus lists {text.count(',') + 1} taus; at most {MAX_TAUS}")
        try:
            taus = [float(v) for v in text.split(",")]
        except ValueError:
            raise InputError(f"--taus list must hold numbers of seconds, got {text[:60]!r}") from None
        if not all(math.isfinite(t) and t > 0 for t in taus):
            raise InputError("--taus list must hold finite taus > 0 s")
        from gyroarray.analysis.allan import MAX_FIT_TAUS
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
    from gyroarray.analysis.allan import plot_allan
    from gyroarray.core.measurement import read_measurement
    from gyroarray.core.outputs import PLOT_SUFFIXES
    taus = _parse_taus(args.taus)
    _output(args.plot, args, "--plot", inputs=_measurement_inputs(args), suffixes=PLOT_SUFFIXES)
    meas = read_measurement(args.measurement, repair=args.repair)
    if args.gyro is not None and not 1 <= args.gyro <= meas.n_gyros:
        raise InputError(f"--gyro {args.gyro} is out of range: the measurement has "
                         f"gyros 1..{meas.n_gyros}", file=str(args.measurement))
    gyros = [args.gyro] if args.gyro is not None else list(range(1, meas.n_gyros + 1))
    signal, what = allan_signal(meas, raw=args.raw)
    tau_note = None
    if isinstance(taus, int):       # within what the record gives and the noise fit takes
        from gyroarray.analysis.allan import fit_tau_count
        try:
            taus, tau_note = fit_tau_count(meas.n_samples + 1, meas.dt_s, taus, args.kind)
        except InputError:          # too short for any tau: said per gyro below
            pass
    analyses, skipped = _allan_each(meas, signal, gyros, taus, args)
    notes = [*meas.notes, *([tau_note] if tau_note else []),
             *_reference_noise_notes(meas, what != "gyro output", gyros), *skipped.values()]
    out = {"gyros": {str(k): a.to_json_dict() for k, a in analyses.items()},
           "signal": what, "notes": notes,
           "not_analysed": {str(k): why for k, why in skipped.items()}}
    lines = [f"{args.measurement}: {meas.n_samples} samples at {1 / meas.dt_s:g} Hz, "
             f"{meas.n_gyros} gyros; analysed: {what}", *[f"note: {n}" for n in notes]]
    for k, a in analyses.items():
        lines.append(_format_allan(k, a.to_json_dict()))
    if args.plot is not None:
        path = plot_allan({f"gyro {k}": a for k, a in analyses.items()}, args.plot, force=args.force)
        out["plot"] = str(path)
        lines.append(f"wrote {path}")
    return out, "\n".join(lines)


def _reference_noise_notes(meas, minus_ref: bool, gyros: list[int]) -> list[str]:
    """Notes for a reference with noise of its own that the analysed signal (output minus
    layout·ref) holds: which gyros read it (:mod:`~gyroarray.analysis.reference_noise`)."""
    if not minus_ref:
        return []
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


def _allan_each(meas, signal, gyros: list[int], taus, args) -> tuple[dict, dict]:
    """The Allan analysis of each gyro; a gyro that cannot be analysed is noted, not fatal.

    Returns ``(analyses by gyro, reason by gyro not analysed)``; refuses
    (one line, every reason) when no gyro can be analysed.
    """
    import numpy as np
    from gyroarray.analysis.allan import allan_analysis
    from gyroarray.core.measurement import constant_gyros, constant_note
    dead = set(constant_gyros(meas))
    analyses, skipped = {}, {}
    for k in gyros:
        if k in dead:
            skipped[k] = constant_note([k], meas) + ": not analysed"
            continue
        try:
            with np.errstate(all="ignore"):
                analyses[k] = allan_analysis(signal[:, k - 1], meas.dt_s, taus, kind=args.kind)
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
    from gyroarray.analysis import davar as dv
    if args.measurement is None:
        raise InputError("gyroarray davar: give MEAS.csv (paper 000's Table 1: "
                         "python benchmarks/davar_paper.py)")
    if args.gyro is None:
        raise InputError("gyroarray davar: --gyro K is required (one gyro at a time)")
    if args.window is not None and args.adaptive:
        raise InputError("gyroarray davar: --window L and --adaptive exclude each other "
                         "(the adaptive window runs between --l-min and --l-max)")
    from gyroarray.core.measurement import read_measurement
    from gyroarray.core.outputs import PLOT_SUFFIXES
    _output(args.plot, args, "--plot", inputs=_measurement_inputs(args), suffixes=PLOT_SUFFIXES)
    meas = read_measurement(args.measurement, repair=args.repair)
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
    from gyroarray.core.limits import check_memory
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


def _nonneg_int(name: str) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a whole number, got {text!r}") from None
        if not 0 <= value < 2 ** 63:
            raise argparse.ArgumentTypeError(f"{name} must be in [0, 2^63), got {value}")
        return value
    return parse


# -- simulate -----------------------------------------------------------------

def tracking_datasheet(tracking) -> list[dict]:
    """The rate table's tracking report per segment, in deg/s and deg (the CLI edge)."""
    from gyroarray.core.units import rad_s_to_deg_s, rad_to_deg

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
    from gyroarray.sim.scenario import load_scenario, simulate_to_files
    scenario = load_scenario(args.scenario)
    csv_path, toml_path, result = simulate_to_files(scenario, args.out, cache=not args.no_cache,
                                                    force=args.force)
    effects: list[dict[str, Any]] = [{"effect": e.effect, "gyro": e.gyro,
                                      "params": _plain_params(e.params)}
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
    from gyroarray.chain.run import run_scenario
    from gyroarray.sim.scenario import check_size, load_scenario
    names = [n.strip() for n in args.estimators.split(",") if n.strip()] if args.estimators else None
    if names is not None:
        from gyroarray.estimators import available
        unknown = [n for n in names if n not in available()]
        if unknown or not names:
            raise InputError(f"--estimators: unknown estimator {(unknown or [args.estimators])[0]!r} "
                             f"(available: {', '.join(available())})")
    scenario = load_scenario(args.scenario)
    check_size(scenario, "run")
    if args.replicates is not None or args.seed is not None:
        return _run_replicates(args, scenario, names)
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
    lines += _sensor_lines(result)
    sg = out["single_gyro"]
    lines.append(f"single gyro (mean of {len(sg['gyros'])}): 1sigma {sg['sigma_1_deg_s']:.4g} deg/s, "
                 f"ARW {sg['arw_deg_rt_h']:.4g} deg/rt(h), BI {sg['bi_deg_h']:.4g} deg/h, "
                 f"RRW {sg['rrw_deg_h_rt_h']:.4g} deg/h/rt(h)")
    return out, "\n".join(lines)


def _sensor_lines(result) -> list[str]:
    """The sensors' share of the swing response and the g-sensitivity's rate error, in words."""
    lines = []
    t, sg = result.table, result.single_gyro
    if "sensor_amplitude_ratio" in sg and sg["sensor_amplitude_ratio"].notna().any():
        sw = t[t.sensor_amplitude_ratio.notna()]
        r = sw.iloc[0]
        lines.append(f"swing {result.swing_hz:g} Hz: the gyros' own response (measured on the raw "
                     f"gyros) {r.sensor_amplitude_ratio:.5f}, lag {r.sensor_phase_deg:.3g} deg; "
                     "each estimator's attenuation = its own share x the sensors':")
        for row in sw.itertuples():
            lines.append(f"  {row.estimator:<10} {row.axis}: total {row.attenuation:.5f} "
                         f"({row.phase_deg:.3g} deg) = estimator {row.estimator_amplitude_ratio:.5f} "
                         f"({row.estimator_phase_deg:.3g} deg) x sensor {row.sensor_amplitude_ratio:.5f} "
                         f"({row.sensor_phase_deg:.3g} deg)")
    if "g_sensitivity_rms_deg_s" in sg:
        per = ", ".join(f"{v:.4g}" for v in sg["g_sensitivity_rms_deg_s"])
        lines.append(f"g-sensitivity rate error on this motion (RMS over the scored window, deg/s): "
                     f"per gyro {per}")
        for name, grp in t.groupby("estimator", sort=False):
            v = grp.g_sensitivity_rms_deg_s.tolist()
            if all(x is not None and x == x for x in v):
                lines.append(f"  {name:<10} fused (DC gain x per-gyro) x/y/z: "
                             + " / ".join(f"{x:.4g}" for x in v))
    return lines


_REP_COLUMNS = (("sigma_1_deg_s", "1sigma[deg/s]"), ("rms_deg_s", "RMS[deg/s]"),
                ("angle_error_deg", "angle@T[deg]"), ("attenuation", "atten."),
                ("phase_deg", "phase[deg]"))


def _run_replicates(args, scenario, names) -> tuple[dict, str]:
    from gyroarray.chain.run import run_replicates
    k = 1 if args.replicates is None else args.replicates
    rep = run_replicates(scenario, names, replicates=k, seed=args.seed, cache=not args.no_cache)
    summ = rep.summary()
    comp = rep.comparison()
    checked = [c for e in comp.values() for a in e.values() for c in a.values() if c["agrees"] is not None]
    inside = sum(c["agrees"] for c in checked)
    out = {"scenario": rep.scenario, "replicates": k, "seed": rep.seed,
           "swing_hz": rep.runs[0].swing_hz, "estimators": summ,
           "single_gyro": rep.single_gyro_summary(), "predicted": comp,
           "agreement": {"compared": len(checked), "inside_95": inside,
                         "note": "each comparison at 95 %: about 5 % fall outside by chance"},
           "notes": list(rep.notes)}

    def ci(d):
        if d["mean"] is None:
            return "-"
        if d["ci_low"] is None:
            return f"{d['mean']:.4g}"
        return f"{d['mean']:.4g} [{d['ci_low']:.3g}, {d['ci_high']:.3g}]"
    lines = [f"scenario {scenario.name}: {k} runs (seed {rep.seed}), mean and 95 % CI of the mean",
             f"{'estimator':<10} {'axis':<4} " + " ".join(f"{h:>30}" for _, h in _REP_COLUMNS)]
    for name, axes in summ.items():
        for axis, m in axes.items():
            lines.append(f"{name:<10} {axis:<4} " + " ".join(f"{ci(m[c]) if c in m else '-':>30}"
                                                              for c, _ in _REP_COLUMNS))
    if comp:
        lines += ["", "predicted vs these runs (RMS over runs for std/RMS/mean/angle; mean for "
                      "amplitude and phase; 95 % CI):"]
        for name, axes in comp.items():
            for axis, m in axes.items():
                cells = []
                for key, c in m.items():
                    mc = c["monte_carlo"]
                    tag = "" if c["agrees"] is None else (" ok" if c["agrees"] else " OUTSIDE")
                    rng = "" if mc["ci_low"] is None else f" [{mc['ci_low']:.3g}, {mc['ci_high']:.3g}]"
                    cells.append(f"{key} {c['predicted']:.4g} vs {mc['value']:.4g}{rng}{tag}")
                lines.append(f"  {name:<10} {axis}: " + "; ".join(cells))
        lines.append(f"{inside} of {len(checked)} predictions inside the runs' 95 % CI "
                     "(about 5 % fall outside by chance)")
    lines += [f"note: {n}" for n in rep.notes]
    return out, "\n".join(lines)


# -- sweep --------------------------------------------------------------------

def cmd_sweep(args):
    from gyroarray.sweep.runner import run_sweep
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
    from gyroarray.reports.report import write_report
    if args.top < 1:
        raise InputError("gyroarray report: --top must be >= 1")
    from gyroarray.core.outputs import same_path
    for i, d in enumerate(args.dirs):
        twice = next((e for e in args.dirs[:i] if same_path(d, e)), None)
        if twice is not None:
            raise InputError(f"the sweep folder is given twice ({twice} and {d}): its results "
                             "would count twice", file=str(d))
    inputs = [args.paper_values] if args.paper_values is not None else []
    if args.design is not None:
        inputs.append(args.design)
    _output(args.out, args, "--out", inputs=inputs, suffixes=(".html", ".htm"))
    _output(args.md, args, "--md", inputs=inputs, suffixes=(".md",))
    if args.md is not None:      # its figures beside it, checked before the work too
        from gyroarray.core.outputs import markdown_figures
        markdown_figures(args.md, inputs=inputs, force=args.force)
    res = write_report(args.dirs, args.out, args.md, design=args.design,
                       paper_values=args.paper_values, top=args.top, force=args.force)
    lines = [f"report: {res['html']}" + (f" (Markdown twin {res['markdown']})" if res["markdown"] else "")
             + f", {res['figures']} figures, {res['seconds']:.1f} s"]
    if res.get("decision"):
        lines += res["decision"]["summary"]
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
    from gyroarray.chain.check import format_check, run_check
    result = run_check(args.thresholds, quick=not args.full)
    return result, format_check(result), (EXIT_OK if result["passed"] else EXIT_FAIL)


# -- fdi ----------------------------------------------------------------------

def cmd_fdi(args):
    from gyroarray.chain.fdi_score import analyse_measurement, format_fdi, plot_fdi
    from gyroarray.core.measurement import read_measurement
    from gyroarray.core.outputs import PLOT_SUFFIXES
    from gyroarray.effects.model import NoiseModel
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
    from gyroarray.chain.compare import ModelComparison
    from gyroarray.core.measurement import read_measurement
    from gyroarray.effects.model import NoiseModel
    inputs = _measurement_inputs(args)
    _output(getattr(args, "out", None), args, "--out", inputs=inputs,
            suffixes=(".toml",) if args.command == "fit" else (".html", ".htm"))
    _output(getattr(args, "md", None), args, "--md", inputs=inputs, suffixes=(".md",))
    _output(getattr(args, "model_out", None), args, "--model-out", inputs=inputs, suffixes=(".toml",))
    if getattr(args, "md", None) is not None:      # its figures beside it, checked now too
        from gyroarray.core.outputs import markdown_figures
        markdown_figures(args.md, inputs=inputs, force=args.force)
    meas = read_measurement(args.measurement, repair=args.repair)
    model = None
    if args.model is not None:
        model = NoiseModel.from_toml(args.model, n_gyros=meas.n_gyros)
    meas, model, args.entry_notes = _live_gyros(meas, model, args)
    from gyroarray.chain.compare import check_record_needs
    check_record_needs(model, meas, fixed=bool(getattr(args, "validate", False)))
    _check_band_runs(args, meas)
    return ModelComparison(meas, model, n_runs=args.runs, seed=args.seed, ref_smooth_s=args.ref_smooth)


def _check_band_runs(args, meas) -> None:
    """Refuse ``--runs`` whose Monte-Carlo band would not fit the memory budget: each run keeps
    the ADEV and the Welch PSD of every gyro (kept three times over: the runs, their array and
    the quantiles), before any run."""
    import math as _m
    from gyroarray.chain.localise import default_nperseg
    n = max(int(meas.n_samples), 2)
    per_run = 3 * 8 * meas.n_gyros * (_m.log2(n) + 1 + default_nperseg(n) // 2 + 1)
    _check_count("--runs", args.runs, per_run,
                 f"Monte-Carlo runs of {n} samples x {meas.n_gyros} gyros")


def _live_gyros(meas, model, args):
    """Leave constant (dead or stuck) gyros out of a comparison, saying so; refuse when none is left."""
    from gyroarray.core.measurement import constant_gyros, constant_note, without_gyros
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
    note += (": left out; the analysis below numbers the others "
             + (mapping if mapping else "as before"))
    return without_gyros(meas, dead, note), model, [note]


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
    where = a.where_it_fails()
    if where:
        lines += [""] + where
    if a.notes:
        lines += ["", "notes:"] + [f"  {n}" for n in a.notes]
    return "\n".join(lines)


def _write_report(comp, steps, args) -> dict:
    from gyroarray.reports.compare_report import write_compare_report
    title = None
    if getattr(args, "validate", False):
        title = f"Validation: does the model ({comp.given_model.description or args.model}) predict {comp.name}?"
    return write_compare_report(comp, steps, args.out, args.md, title=title, force=args.force)


def _write_model(path: Path, model, args) -> str:
    """The fitted model as TOML at ``path`` (checked by :func:`_comparison`); returns the path."""
    from gyroarray.core.outputs import write_text
    from gyroarray.effects.model import NoiseModel
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
    a.notes[:0] = args.entry_notes
    _write_report(comp, steps, args)
    d = a.to_json_dict()
    res = {"discrepancy": a.discrepancy, "consistent": a.consistent, "z_crit": a.z_crit,
           "n_tests": len(a.tests), "report": str(args.out),
           "steps": [{"added": None if add is None else {"effect": add[0], "gyro": add[1]},
                      "discrepancy": s.discrepancy, "consistent": s.consistent} for add, s in steps],
           "adev_band": d["adev_band"], "candidates": d["candidates"][:10],
           "localisation": d["localisation"], "notes": a.notes}
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
            + "".join(f"\nnote: {n}" for n in args.entry_notes))
    return res, text


def cmd_diagnose(args):
    comp = _comparison(args)
    if args.validate:
        if args.model is None:
            raise InputError("gyroarray diagnose --validate needs --model (the model to test)")
        a = comp.validate()
        a.notes[:0] = args.entry_notes
        out = a.to_json_dict()
        out["validated"] = True
        out["verdict"] = _validation_text(comp, a, args.model)
        return out, out["verdict"] + "\n" + _diagnosis_text(a, f"{comp.name}: {comp.N} gyros, {comp.n * comp.dt:.0f} s")
    a = comp.diagnose()
    a.notes[:0] = args.entry_notes
    return a.to_json_dict(), _diagnosis_text(a, f"{comp.name}: {comp.N} gyros, {comp.n * comp.dt:.0f} s")


def cmd_fit(args):
    from gyroarray.chain.compare import parse_add
    comp = _comparison(args)
    add = [parse_add(x, comp.N) for x in (args.add or [])]
    before, after = comp.fit(add)
    after.notes[:0] = args.entry_notes
    res = {"discrepancy_before": before.discrepancy, "discrepancy_after": after.discrepancy,
           "consistent": after.consistent, "effects": after.effects_json(),
           "notes": list(args.entry_notes)}
    if args.out is not None:
        res["model"] = _write_model(args.out, after.model, args)
    text = "\n".join([f"{comp.name}: discrepancy {before.discrepancy:.3g} -> {after.discrepancy:.3g} "
                      f"({'consistent' if after.consistent else 'NOT consistent'})",
                      "fitted model (beyond ARW + RRW):"] + (_model_lines(after.model) or ["  (baseline only)"])
                     + ([f"written to {args.out}"] if args.out is not None else [])
                     + [f"note: {n}" for n in args.entry_notes])
    return res, text


def cmd_ladder(args):
    comp = _comparison(args)
    held = None
    if args.holdout is not None:
        from gyroarray.chain.compare import ModelComparison, split_measurement
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
           "notes": list(final.notes), "report": str(args.out)}
    if args.model_out is not None:
        res["model"] = _write_model(args.model_out, final.model, args)
    held_text = []
    if held is not None:
        from gyroarray.chain.compare import ModelComparison
        from gyroarray.effects.model import NoiseModel
        model = NoiseModel(final.model.entries, description=f"the ladder on {comp.name}")
        v = ModelComparison(held.m, model, n_runs=args.runs, seed=args.seed, ref_smooth_s=args.ref_smooth)
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
    left = [t.evidence for t in final.candidates if final.significant(t)]
    if not final.localisation:
        left = final.unexplained() + left
    lines += ["still unexplained:"] + ([f"  {x}" for x in left] or
                                       (["  nothing"] if not final.localisation else []))
    if final.localisation:
        lines += final.where_it_fails()
    lines += [f"note: {x}" for x in final.notes if x.startswith("the ladder")]
    lines += held_text
    lines.append(f"report: {args.out}")
    return res, "\n".join(lines)


def _add_compare_args(p, *, out: bool):
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="noise model to calibrate (default: ARW + RRW on every gyro)")
    p.add_argument("--runs", type=_count("--runs"), default=40, metavar="K",
                   help="Monte-Carlo runs of the model band (40)")
    p.add_argument("--seed", type=_nonneg_int("--seed"), default=0, help="seed of the model band (0)")
    p.add_argument("--repair", action="store_true", help="repair short gaps, missing values, exact duplicate rows and a jittering clock (each listed)")
    p.add_argument("--ref-smooth", type=_float_in("--ref-smooth", 0.0, unit="s"), default=0.0, metavar="SECONDS",
                   help="smooth a noisy reference rate (a differentiated encoder) by a centred moving "
                        "average of this length before comparing; scale factor, nonlinearity, misalignment "
                        "and latency are then fitted against the recorded reference with the smoothed one "
                        "as instrument (0: as recorded)")
    _add_plugin(p)
    if out:
        _add_force(p)
        p.add_argument("--out", type=Path, required=True, metavar="REPORT.html")
        p.add_argument("--md", type=Path, metavar="REPORT.md", help="also write a Markdown twin")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def _add_design_parsers(sub) -> None:
    """The ``gdop`` and ``design`` subcommands (layouts, cone angle, recommendation)."""
    p = sub.add_parser("gdop", help="GDOP of a conical layout")
    _add_layout_args(p, alpha=True, required=True)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_gdop)

    p = sub.add_parser("design", help="optimal cone angle, paper 003 tables, GDOP plots; "
                                      "--recommend: which array to build")
    p.add_argument("--scheme", type=int, choices=(1, 2),
                   help="conical scheme: 1 all gyros on the cone, 2 gyro 1 on +z")
    p.add_argument("--n", metavar="N", help="number of gyros (>= 3); with --recommend a list "
                                            "(default 4,5,6,8)")
    p.add_argument("--rho", type=_finite_float("--rho"), metavar="R",
                   help="common correlation of the gyros' noise [-] (default 0; with --recommend "
                        "it applies to ARW and RRW)")
    p.add_argument("--recommend", action="store_true",
                   help="search scheme x N x cone angle x estimator x bandwidth with the "
                        "analytic predictor and recommend a design")
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="--recommend: the gyro noise from a model (gyroarray fit --out)")
    p.add_argument("--arw", type=_float_in("--arw", 0.0, 6e6, lo_open=True, unit="deg/√h"), metavar="DEG_RT_H",
                   help="--recommend: angle random walk [deg/rt(h)]")
    p.add_argument("--rrw", type=_float_in("--rrw", 0.0, 3.6e8, unit="deg/h/√h"), metavar="DEG_H_RT_H",
                   help="--recommend: rate random walk [deg/h/rt(h)] (default 0)")
    p.add_argument("--bi", type=_float_in("--bi", 0.0, 3.6e8, unit="deg/h"), metavar="DEG_H",
                   help="--recommend: bias instability [deg/h] (default 0)")
    p.add_argument("--rho-range", metavar="LO,HI",
                   help="--recommend: the correlations the gyros may have; ranked per rho, "
                        "recommended: the best worst case (a negative LO: --rho-range=-0.1,0.5)")
    p.add_argument("--rate-hz", type=_float_in("--rate-hz", 1e-3, 1e6, unit="Hz"), metavar="HZ",
                   help="--recommend: sample rate (default 100)")
    p.add_argument("--horizon-s", type=_finite_float("--horizon-s"), metavar="T",
                   help="--recommend: run length the accuracy refers to (default 600)")
    p.add_argument("--swing", metavar="AMP_DPS,FREQ_HZ",
                   help="--recommend: a swing about each body axis (the bandwidth is traded against lag)")
    p.add_argument("--motion", metavar="PROFILE",
                   help="--recommend: a motion profile (shipped name or .toml file) instead of a swing")
    p.add_argument("--bandwidth-hz", metavar="F|LO,HI",
                   help="--recommend: filter bandwidth, fixed or searched (default: 10 at rest, "
                        "0.1..0.45*rate with motion)")
    p.add_argument("--sensor-bandwidth", metavar="HZ[,ORDER]",
                   help="--recommend: the gyros' own low-pass (-3 dB cut-off, order 1 or 2 = "
                        "Butterworth; default from --model, else none), cascaded before every estimator")
    p.add_argument("--g-sensitivity", metavar="K|KX,KY,KZ",
                   help="--recommend: every gyro's g-sensitivity [(deg/s)/g], platform frame (K alone: "
                        "0,0,K, along gravity at rest); its rate error is reported beside the noise")
    p.add_argument("--failures", type=int, metavar="K",
                   help="--recommend: a 3-axis rate must survive K failed gyros (0, 1, 2; default 0)")
    p.add_argument("--estimators", metavar="A,B,...",
                   help="--recommend: estimators compared (default kf_array,kf_single,gls,ols,naive)")
    p.add_argument("--check", type=_count("--check"), metavar="K",
                   help="--recommend: simulate the top designs K times (paired) beside the prediction")
    p.add_argument("--seed", type=_nonneg_int("--seed"), metavar="S",
                   help="--recommend --check: root seed of the paired runs")
    p.add_argument("--out", type=Path, metavar="FILE.json",
                   help="--recommend: also write the whole result (for gyroarray report --design)")
    p.add_argument("--paper-tables", action="store_true",
                   help="paper 003 Tables 1-2 beside the computed values, cell by cell")
    p.add_argument("--plot", type=Path, metavar="OUT.png",
                   help="write GDOP vs alpha and vs rho (paper 003 Figs. 8-10)")
    _add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_design)


def _add_deviation_parsers(sub) -> None:
    """The ``allan`` and ``davar`` subcommands (Allan and dynamic Allan deviation)."""
    p = sub.add_parser("allan", help="Allan deviation with confidence intervals and noise fit")
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    p.add_argument("--gyro", type=int, metavar="K", help="only gyro K (1-based)")
    p.add_argument("--taus", default="octave", metavar="octave|N|T1,T2,...",
                   help="octave taus (default), N log-spaced taus, or a list of taus [s]")
    p.add_argument("--kind", choices=("oadev", "ohdev"), default="oadev",
                   help="overlapping Allan (default) or Hadamard deviation")
    p.add_argument("--repair", action="store_true",
                   help="repair short gaps, missing values, exact duplicate rows and a jittering clock (each listed)")
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
    p.add_argument("--repair", action="store_true", help="repair short gaps, missing values, exact duplicate rows and a jittering clock (each listed)")
    p.add_argument("--plot", type=Path, metavar="OUT.png", help="heat map + ARW and window tracks")
    _add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_davar)


def _add_simulation_parsers(sub) -> None:
    """The ``simulate``, ``run``, ``sweep`` and ``report`` subcommands."""
    p = sub.add_parser("simulate", help="simulate a scenario into a measurement (CSV.GZ + TOML)")
    p.add_argument("scenario", type=Path, metavar="SCENARIO.toml")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    p.add_argument("--no-cache", action="store_true", help="recompute the rate-table truth")
    _add_force(p)
    _add_plugin(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_simulate)
    p.plugin_help = True

    p = sub.add_parser("run", help="simulate a scenario and score fusion estimators")
    p.add_argument("scenario", type=Path, metavar="SCENARIO.toml")
    p.add_argument("--estimators", metavar="A,B,...",
                   help="registry names (default: kf_array, kf_single, gls, ols, naive, bound)")
    p.add_argument("--no-cache", action="store_true", help="recompute the rate-table truth")
    _add_plugin(p)
    p.add_argument("--replicates", type=_count("--replicates"), metavar="K",
                   help="run K times with independent seeds: mean and 95 %% CI of every metric, "
                        "beside the analytic prediction")
    p.add_argument("--seed", type=_nonneg_int("--seed"), metavar="S",
                   help="root seed of the replicates (default: the scenario's seed)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_run)
    p.plugin_help = True

    p = sub.add_parser("sweep", help="run a sweep of scenarios in parallel into a Parquet dataset (resumable)")
    p.add_argument("sweep", type=Path, metavar="SWEEP.toml")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output directory")
    p.add_argument("--workers", type=_count("--workers"), metavar="K",
                   help="local worker processes (default 1)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="a Dask distributed scheduler")
    p.add_argument("--json", action="store_true", help="print one JSON object (no progress bar)")
    p.set_defaults(func=cmd_sweep)
    p.plugin_help = True

    p = sub.add_parser("report", help="design comparison report (HTML + Markdown) from sweep folders")
    p.add_argument("dirs", type=Path, nargs="*", metavar="DIR", help="gyroarray sweep --out folders")
    p.add_argument("--design", type=Path, metavar="FILE.json",
                   help="a gyroarray design --recommend --out result: the decision opens the report")
    p.add_argument("--out", type=Path, required=True, metavar="REPORT.html")
    p.add_argument("--md", type=Path, metavar="REPORT.md", help="also write a Markdown twin")
    p.add_argument("--paper-values", type=Path, metavar="FILE",
                   help="paper values to compare with (default: the shipped scenarios/paper_values.toml)")
    p.add_argument("--top", type=int, default=15, metavar="K", help="designs listed per motion (15)")
    _add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_report)


def _add_compare_parsers(sub) -> None:
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
    p.add_argument("--add", action="append", metavar="EFFECT[:GYRO]",
                   help="effect to add before fitting (repeatable), e.g. scale_factor:2, burst")
    p.add_argument("--out", type=Path, metavar="NEW.toml", help="write the fitted model (readable by --model)")
    _add_force(p)
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser("ladder", help="diagnose -> add the best effect -> fit, until consistent; report")
    _add_compare_args(p, out=True)
    p.add_argument("--max-steps", type=_count("--max-steps"), default=8, metavar="K",
                   help="effects added at most (8)")
    p.add_argument("--model-out", type=Path, metavar="NEW.toml", help="write the final fitted model")
    p.add_argument("--holdout", type=_finite_float("--holdout"), metavar="FRACTION",
                   help="run the ladder on the first part of the record, then validate its model on the "
                        "last FRACTION (e.g. 0.3)")
    p.set_defaults(func=cmd_ladder)


def _add_fdi_and_check_parsers(sub) -> None:
    """The ``fdi`` (fault detection) and ``check`` (regression thresholds) subcommands."""
    p = sub.add_parser("fdi", help="fault detection and isolation on a measurement (parity space)")
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="ARW/RRW/correlation of the gyros (default: estimated from the record)")
    p.add_argument("--far-per-h", type=_finite_float("--far-per-h"), default=0.01, metavar="RATE",
                   help="false alarms per hour the thresholds are set for (0.01; from 1e-12 to "
                        "one per 100 samples)")
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


def build_parser() -> argparse.ArgumentParser:
    """The ``gyroarray`` argument parser: one subparser per subcommand, each with ``--max-memory``."""
    parser = _Parser(prog="gyroarray", description=__doc__.splitlines()[0])
    parser.plugin_help = True
    parser.add_argument("--version", action="version", version=f"gyroarray {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    _add_design_parsers(sub)
    _add_deviation_parsers(sub)
    _add_simulation_parsers(sub)
    _add_compare_parsers(sub)
    _add_fdi_and_check_parsers(sub)
    for p in sub.choices.values():
        p.add_argument("--max-memory", type=_size, metavar="SIZE",
                       help="memory gyroarray may plan to use, e.g. 8G (default: half the "
                            "machine's; or $GYROARRAY_MAX_MEMORY); larger runs are refused up front")
    return parser


def _size(text: str) -> int:
    from gyroarray.core.limits import parse_size
    try:
        return parse_size(text)
    except InputError as err:
        raise argparse.ArgumentTypeError(err.message) from None


def _version() -> str:
    from gyroarray import __version__
    return __version__


#: The argument naming a command's one input file, first found (a refusal that names neither a
#: file nor an argument is about it).
_INPUT_ARGS = ("measurement", "scenario", "sweep")


def _located_input_error(err: InputError, args, argv=()) -> InputError:
    """``err`` located for the user when it names neither a file nor an argument.

    With the command's input file (``MEAS.csv``, ``SCENARIO.toml``, ``SWEEP.toml``) as its
    file: a refusal deep in an analysis then still says which file it is about. A command
    without one (``design``, ``gdop``) gets the option the user gave whose name the message
    uses (``rho = 1 makes ...`` comes from ``--rho``; ``unknown shipped motion profile`` from
    ``--motion``).
    """
    if err.file is not None or args is None or "--" in err.message or err.message.startswith("gyroarray "):
        return err
    for name in _INPUT_ARGS:
        value = getattr(args, name, None)
        if isinstance(value, (str, os.PathLike)):
            return err.with_file(value)
    words = set(re.findall(r"[a-z_]+", err.message.lower()))
    for item in argv or ():
        opt = str(item).split("=", 1)[0]
        dest = opt[2:].replace("-", "_")
        if (opt.startswith("--") and len(dest) >= 3          # not --n: "for N = 4" is no reference
                and any(w == dest or w.startswith(dest + "_") for w in words)):
            return InputError(f"{opt}: {err.message}", line=err.line, column=err.column)
    return err


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0 ok, 1 failure, 2 bad input)."""
    from gyroarray.core.limits import memory_budget
    from gyroarray.core.outputs import private_matplotlib_dir
    private_matplotlib_dir()            # matplotlib's font cache not in the user's home
    parser = build_parser()
    try:
        with warnings.catch_warnings():
            if not os.environ.get("GYROARRAY_DEBUG"):   # stderr carries one line at most
                warnings.simplefilter("ignore")
            args = parser.parse_args(argv)
            if sys.stdout is None:          # started with stdout closed (`>&-`): refuse before work
                print("gyroarray: cannot write the output to standard output: it is closed; "
                      "redirect it to a file or to /dev/null", file=sys.stderr)
                return EXIT_USAGE
            if getattr(args, "plugin", None):
                from gyroarray.chain.plugins import load_plugins  # deferred: loads numba, the registries
                load_plugins(args.plugin)
            with memory_budget(getattr(args, "max_memory", None)):
                result, text, *code = args.func(args)
    except InputError as err:
        print(f"gyroarray: {_located_input_error(err, locals().get('args'), argv if argv is not None else sys.argv[1:])}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("gyroarray: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # an internal bug, not bad input: keep stderr to one line
        if os.environ.get("GYROARRAY_DEBUG"):
            raise
        print(f"gyroarray: internal error: {type(err).__name__}: {one_line(err)} "
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
        _stdout_to_devnull()
    except OSError as err:   # a full disk (`> /dev/full`), a read-only descriptor: the user's setup
        _stdout_to_devnull()
        print(f"gyroarray: cannot write the output to standard output: "
              f"{err.strerror or err}; free some space or redirect it elsewhere", file=sys.stderr)
        return EXIT_USAGE
    return code[0] if code else EXIT_OK


def _stdout_to_devnull() -> None:
    """Point file descriptor 1 at /dev/null after a failed write to stdout, so that the
    interpreter's own flush at exit finds a sink and prints no "Exception ignored" traceback."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, ValueError, OSError):       # not a real file (a test's StringIO)
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, fd)
    finally:
        os.close(null)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
