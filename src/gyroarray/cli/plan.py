"""``gyroarray plan``: how long to record for a precision on ARW, bias instability and RRW
(:mod:`gyroarray.chain.plan`); with ``--sensor acc`` on the accelerometer's velocity random
walk, bias instability and acceleration random walk.

The chain (numpy, scipy) is imported inside the command, so that building the parser
(``gyroarray --help``, every other command) does not load it.
"""

from __future__ import annotations

from pathlib import Path

from gyroarray.cli.common import float_in, positive_int
from gyroarray.core.errors import InputError

__all__ = ["add_parser", "cmd_plan", "parse_precision"]


def parse_precision(text: str) -> float:
    """``10%`` or ``0.1`` -> 0.1 (a relative half-width in (0, 1))."""
    raw = text.strip()
    pct = raw.endswith("%")
    try:
        value = float(raw[:-1] if pct else raw)
    except ValueError:
        raise InputError(f"--precision must be a percentage like 10% or a fraction like 0.1, "
                         f"got {text!r}") from None
    value = value / 100.0 if pct else value
    if not 0.0 < value < 1.0:
        raise InputError(f"--precision must be between 0 and 100 % (exclusive), got {text!r}")
    return value


def _fmt_len(seconds) -> str:
    if seconds is None:
        return "not within 10 years"
    if seconds < 120:
        return f"{seconds:.3g} s"
    if seconds < 2 * 3600:
        return f"{seconds / 60:.3g} min ({seconds:.0f} s)"
    return f"{seconds / 3600:.3g} h ({seconds:.0f} s)"


def _gyros(model, asked):
    from gyroarray.effects.names import ARW, BIAS_INSTABILITY, RRW  # deferred: the effect registry (numpy, scipy, numba)
    if asked is not None:
        return [asked]
    own = sorted({e.gyro for e in model if e.gyro is not None
                  and e.effect in (ARW, BIAS_INSTABILITY, RRW)})
    return own or [1]


def _fitted_rel(model, gyro: int) -> dict:
    """Relative 1σ the model file carries for each coefficient (``fit --out`` writes them)."""
    from gyroarray.effects.names import ARW, BIAS_INSTABILITY, RRW  # deferred: the effect registry (numpy, scipy, numba)
    keys = {ARW: ("n", "n_deg_rt_h"), BIAS_INSTABILITY: ("b", "b_deg_h"),
            RRW: ("k", "k_deg_h_rt_h")}
    out = {}
    for overriding in (False, True):
        for e in model:
            if e.effect in keys and (e.gyro == gyro if overriding else e.gyro is None):
                term, key = keys[e.effect]
                v, s = e.params.get(key), e.sigma.get(key)
                if v and s is not None:
                    out[term] = float(s) / float(v)
    return out


#: The coefficient options of each sensor: (option, upper bound, datasheet unit).
_OPTION_BOUNDS = {
    "gyro": (("--arw", 1e6, "deg/√h"), ("--bi", 1e6, "deg/h"), ("--rrw", 1e7, "deg/h/√h")),
    "acc": (("--vrw", 1e6, "m/s/√h"), ("--acc-bi", 1e6, "mg"), ("--acc-rw", 1e6, "m/s²/√h")),
}
#: The same with each option's argparse dest: (option, dest, upper bound, datasheet unit).
_SENSOR_OPTIONS = {sensor: tuple((opt, opt[2:].replace("-", "_"), hi, unit) for opt, hi, unit in opts)
                   for sensor, opts in _OPTION_BOUNDS.items()}


def _accel_fitted_rel(table, axis: str) -> dict:
    """Relative 1σ the ``[accelerometer]`` table carries for each term of one axis."""
    i = table.axes.index(axis)
    out = {}
    for term, key in (("n", "n_m_s_rt_h"), ("b", "b_mg"), ("k", "k_m_s2_rt_h")):
        values, sigma = getattr(table, key), table.sigma.get(key)
        if values is not None and sigma is not None and values[i] is not None and sigma[i] is not None:
            out[term] = float(sigma[i]) / float(values[i])
    return out


def _accel_cases(args):
    """``(axis, coef SI, relative 1σ of the file)`` per accelerometer axis of ``--model``."""
    from gyroarray.chain.plan import model_accel_terms  # deferred: chain.plan loads numpy, scipy
    from gyroarray.effects.model import NoiseModel   # deferred: the effect registry
    model = NoiseModel.from_toml(args.model)
    if model.accelerometer is None:
        raise InputError("--sensor acc: the model has no [accelerometer] table (fit --out writes it from "
                         "a record with acc_x, acc_y, acc_z columns); give --vrw, --acc-bi, --acc-rw",
                         file=str(args.model))
    table = model.accelerometer
    cases = []
    for axis in ([args.axis] if args.axis is not None else list(table.axes)):
        coef = model_accel_terms(model, axis)
        if not any(v > 0 for v in coef.values()):
            raise InputError(f"the model's [accelerometer] table has no term for any axis ({', '.join(table.missing)} "
                             "missing: see its notes)", file=str(args.model))
        cases.append((axis, coef, _accel_fitted_rel(table, axis)))
    return cases


def cmd_plan(args):
    # deferred: the chain (numpy, scipy) loads only when the command runs
    from gyroarray.chain.plan import ACC_TERM_NAMES, TERM_NAMES, model_terms
    from gyroarray.core import units
    sensor = getattr(args, "sensor", "gyro")
    other = "acc" if sensor == "gyro" else "gyro"
    wrong = [o for o, dest, _, _ in _SENSOR_OPTIONS[other] if getattr(args, dest, None) is not None]
    if wrong:
        raise InputError(f"{'/'.join(wrong)} {'is' if len(wrong) == 1 else 'are'} for --sensor {other}; "
                         f"with --sensor {sensor} give "
                         f"{', '.join(o for o, *_ in _SENSOR_OPTIONS[sensor])}")
    if sensor == "gyro" and getattr(args, "axis", None) is not None:
        raise InputError("--axis picks an accelerometer axis of the model: use it with --sensor acc "
                         "(the gyros: --gyro)")
    if sensor == "acc" and args.gyro is not None:
        raise InputError("--gyro picks a gyro of the model: with --sensor acc use --axis x|y|z")
    given = [o for o, dest, _, _ in _SENSOR_OPTIONS[sensor] if getattr(args, dest, None) is not None]
    if args.model is not None and given:
        raise InputError(f"give either --model or {'/'.join(given)}, not both")
    parse_precision(args.precision)                     # a bad --precision is refused before any file is read
    if sensor == "acc" and args.model is not None:
        return _plan_cases(args, sensor, _accel_cases(args), ACC_TERM_NAMES)
    if sensor == "acc":
        if not given:
            raise InputError("--sensor acc: give the noise (--vrw, --acc-bi, --acc-rw) or a model with an "
                             "[accelerometer] table (--model M.toml)")
        from gyroarray.chain.plan import MIN_COEF_DATASHEET  # deferred: chain.plan loads numpy, scipy
        for opt, dest, hi, unit in _SENSOR_OPTIONS["acc"]:
            v = getattr(args, dest)
            if v is not None and 0.0 < v < MIN_COEF_DATASHEET:
                raise InputError(f"{opt} must be 0 (not in the model) or in "
                                 f"[{MIN_COEF_DATASHEET:g}, {hi:g}] {unit}, got {v:g}")
        coef = {"n": units.vrw_m_s_rt_h_to_si(args.vrw or 0.0), "b": units.mg_to_m_s2(args.acc_bi or 0.0),
                "k": units.accel_rw_m_s2_rt_h_to_si(args.acc_rw or 0.0)}
        if not any(v > 0 for v in coef.values()):
            raise InputError("--vrw/--acc-bi/--acc-rw: at least one must be > 0")
        return _plan_cases(args, sensor, [(None, coef, {})], ACC_TERM_NAMES)
    if args.model is not None:
        from gyroarray.effects.model import NoiseModel   # deferred: the effect registry
        model = NoiseModel.from_toml(args.model)
        cases = []
        for g in _gyros(model, args.gyro):
            coef = model_terms(model, g)
            if not any(v > 0 for v in coef.values()):
                raise InputError(f"the model has no arw, bias_instability or rrw for gyro {g}; "
                                 "pick another with --gyro", file=str(args.model))
            cases.append((g, coef, _fitted_rel(model, g)))
    else:
        if not given:
            raise InputError("give the noise (--arw, --bi, --rrw) or a model (--model M.toml)")
        from gyroarray.chain.plan import MIN_COEF_DATASHEET  # deferred: chain.plan loads numpy, scipy
        for opt, v, hi, unit in (("--arw", args.arw, 1e6, "deg/√h"), ("--bi", args.bi, 1e6, "deg/h"),
                                 ("--rrw", args.rrw, 1e7, "deg/h/√h")):
            if v is not None and 0.0 < v < MIN_COEF_DATASHEET:     # before SI can underflow it
                raise InputError(f"{opt} must be 0 (not in the model) or in "
                                 f"[{MIN_COEF_DATASHEET:g}, {hi:g}] {unit}, got {v:g}")
        coef = {"n": units.arw_deg_rt_h_to_rad_rt_s(args.arw or 0.0),
                "b": units.deg_h_to_rad_s(args.bi or 0.0),
                "k": units.rrw_deg_h_rt_h_to_rad_s_rt_s(args.rrw or 0.0)}
        if not any(v > 0 for v in coef.values()):
            raise InputError("--arw/--bi/--rrw: at least one must be > 0")
        cases = [(None, coef, {})]
    return _plan_cases(args, sensor, cases, TERM_NAMES)


#: How ``t_crb_s`` is computed (``plan --json``'s ``t_crb_method``).
_CRB_METHOD = ("shortest one-part record whose Cramér–Rao bound (Whittle Fisher information of the "
               "first differences, the planned terms jointly: analysis.crb) gives a relative 1σ of "
               "precision/z, z the two-sided normal quantile of the confidence; at least 64 samples")


def _crb_lengths(plan, precision: float, confidence: float) -> dict:
    """term -> T_CRB [s] (None: not within ten years) for the plan's terms jointly."""
    # deferred: numpy, scipy load only when the command runs
    from gyroarray.analysis.crb import crb_length
    from gyroarray.chain.plan import MAX_PLAN_S
    import math
    from scipy import special
    z = float(2.0 ** 0.5 * special.erfinv(confidence))
    # a confidence near 0 (z -> 0) asks for almost nothing: the shortest record (a finite target)
    rel = precision / z if z > 0.0 and math.isfinite(precision / z) else 1e300
    values = {t: float(v) for t, v in plan.coef.items()}
    return {t: crb_length(values, plan.rate_hz, t, min(rel, 1e300), max_s=MAX_PLAN_S) for t in values}


def _whittle_kappa(rate_hz: float) -> float:
    """The default taper's variance inflation κ [-] (analysis.whittle.TAPER) of an hour's record
    at ``rate_hz`` (at most 2^20 samples; κ is 1.026 for any record longer than a few hundred)."""
    # deferred: numpy loads only when the command runs
    from gyroarray.analysis.whittle import TAPER, taper_inflation, tukey
    m = int(min(max(3600.0 * rate_hz, 256), 2 ** 20))
    return float(taper_inflation(tukey(m, TAPER)))


def _plan_cases(args, sensor: str, cases, names):
    """The plan of each ``(gyro or axis, coef SI, relative 1σ of the model)``: JSON and text."""
    # deferred: the chain (numpy, scipy) loads only when the command runs
    from gyroarray.chain.plan import plan_record
    from gyroarray.core import units
    precision = parse_precision(args.precision)
    at_s = None if args.at_h is None else args.at_h * units.S_PER_H
    what, label = ("axes", "axis") if sensor == "acc" else ("gyros", "gyro")
    result = {"sensor": sensor, "precision": precision, "confidence": args.confidence,
              "rate_hz": args.rate_hz, what: []}
    lines = [f"record length for ±{precision:.1%} relative half-width ({args.confidence:.1%} "
             f"two-sided) at {args.rate_hz:g} Hz (Allan GLS fit, allan's EDF; T_CRB: the "
             f"Cramér–Rao bound, any unbiased estimator; the band-limited Whittle fit: κ·T_CRB)"
             + (", accelerometer:" if sensor == "acc" else ":")]
    for g, coef, fitted in cases:
        try:
            plan = plan_record(coef, args.rate_hz, precision, confidence=args.confidence, at_s=at_s,
                               sensor=sensor)
        except InputError as err:
            if args.model is None or err.file is not None:
                raise
            raise err.with_file(str(args.model)) from None
        d = plan.to_json_dict()
        d[label] = g
        bound_s = _crb_lengths(plan, precision, args.confidence)
        kappa = _whittle_kappa(plan.rate_hz)
        for t, t_crb in bound_s.items():
            row = d["terms"][names[t][0]]
            row["t_crb_s"] = t_crb
            row["t_crb_h"] = None if t_crb is None else t_crb / units.S_PER_H
            gls_s = plan.duration_s.get(t)
            row["allan_efficiency_vs_crb"] = (None if t_crb is None or gls_s is None
                                              else t_crb / gls_s)
            # the band-limited Whittle fit (allan's default where it applies): its variance is the
            # taper's κ times the bound, and a relative σ falls as 1/√T, so it needs κ·T_CRB
            row["t_whittle_s"] = None if t_crb is None else kappa * t_crb
            row["whittle_kappa"] = kappa
        d["t_crb_method"] = _CRB_METHOD
        for t, rel in fitted.items():
            if names[t][0] in d["terms"]:
                d["terms"][names[t][0]]["model_sigma_rel"] = rel
        result[what].append(d)
        if g is not None:
            lines.append(f"{'acc_' if sensor == 'acc' else 'gyro '}{g}:")
        for t in plan.coef:
            name, unit, conv = names[t]
            row = (f"  {name} = {conv(plan.coef[t]):.5g} {unit}: {_fmt_len(plan.duration_s[t])}; "
                   f"the bound (T_CRB): {_fmt_len(bound_s[t])}"
                   + ("" if bound_s[t] is None else
                      f"; the band-limited Whittle fit (allan --method whittle, κ = {kappa:.4g}): "
                      f"{_fmt_len(kappa * bound_s[t])}"))
            if at_s is not None:
                row += f"; a {args.at_h:g} h record gives ±{plan.at_precision[t]:.1%}"
            if t in fitted:
                row += f"; the model's own 1σ: ±{fitted[t]:.1%}"
            lines.append(row)
    return result, "\n".join(lines)


def add_parser(sub) -> None:
    """The ``plan`` subcommand."""
    p = sub.add_parser("plan", help="how long to record for a precision on ARW, bias instability "
                                    "and RRW (--sensor acc: VRW, BI and acceleration RW)")
    p.add_argument("--sensor", choices=("gyro", "acc"), default="gyro",
                   help="plan for the gyro (default: --arw, --bi, --rrw) or the accelerometer (--vrw, "
                        "--acc-bi, --acc-rw, or --model's [accelerometer] table)")
    p.add_argument("--arw", type=float_in("--arw", 0.0, 1e6, unit="deg/√h"), metavar="N",
                   help="angle random walk [deg/√h]")
    p.add_argument("--bi", type=float_in("--bi", 0.0, 1e6, unit="deg/h"), metavar="B",
                   help="bias instability [deg/h]")
    p.add_argument("--rrw", type=float_in("--rrw", 0.0, 1e7, unit="deg/h/√h"), metavar="K",
                   help="rate random walk [deg/h/√h]")
    p.add_argument("--vrw", type=float_in("--vrw", 0.0, 1e6, unit="m/s/√h"), metavar="N",
                   help="--sensor acc: velocity random walk [m/s/√h] (60 × m/s²/√Hz)")
    p.add_argument("--acc-bi", type=float_in("--acc-bi", 0.0, 1e6, unit="mg"), metavar="B",
                   help="--sensor acc: bias instability [mg]")
    p.add_argument("--acc-rw", type=float_in("--acc-rw", 0.0, 1e6, unit="m/s²/√h"), metavar="K",
                   help="--sensor acc: acceleration random walk [m/s²/√h] (60 × m/s²/√s)")
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="take ARW, bias instability and RRW from a noise model instead (--sensor acc: "
                        "its [accelerometer] table)")
    p.add_argument("--gyro", type=positive_int("--gyro"), metavar="K",
                   help="the model's gyro K (default: each gyro the model names)")
    p.add_argument("--axis", choices=("x", "y", "z"),
                   help="--sensor acc: the model's accelerometer axis (default: each axis of its table)")
    p.add_argument("--rate-hz", required=True, type=float_in("--rate-hz", 1e-3, 1e6, unit="Hz"),
                   metavar="R", help="sample rate [Hz]")
    p.add_argument("--precision", default="10%", metavar="P",
                   help="relative half-width asked for, e.g. 10%% or 0.1 (default 10%%)")
    p.add_argument("--confidence", type=float_in("--confidence", 0.0, 0.999999, lo_open=True),
                   default=0.6826894921370859, metavar="C",
                   help="two-sided confidence of the half-width (default 0.683, allan's 1σ bands)")
    p.add_argument("--at-h", type=float_in("--at-h", 0.0, 87660.0, lo_open=True, unit="h"),
                   metavar="H", help="also give the precision a record of H hours reaches")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_plan)
