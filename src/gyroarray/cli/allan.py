"""``gyroarray allan`` and ``gyroarray davar``: the Allan (or Hadamard) deviation of each gyro with
its noise fit, and the dynamic Allan deviation of one gyro, with their text.

numpy and the analysis modules (numba) are imported inside the commands, so that building the
parser (``gyroarray --help``, every other command) does not load them.
"""

from __future__ import annotations

import math
from pathlib import Path

from gyroarray.cli.common import add_force, check_plot, measurement_inputs, positive_int
from gyroarray.core.errors import InputError

__all__ = ["MAX_TAUS", "add_parser", "allan_signal", "cmd_allan", "cmd_davar"]


#: Most taus ``allan --taus`` may ask for (an octave grid of 1e9 samples has 30).
MAX_TAUS = 10_000


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
    from gyroarray.core.measurement import read_measurement
    from gyroarray.reports.allan_plots import plot_allan
    taus = _parse_taus(args.taus)
    check_plot(args, inputs=measurement_inputs(args))
    meas = read_measurement(args.measurement, repair=args.repair)
    if args.gyro is not None and not 1 <= args.gyro <= meas.n_gyros:
        raise InputError(f"--gyro {args.gyro} is out of range: the measurement has "
                         f"gyros 1..{meas.n_gyros}", file=str(args.measurement))
    gyros = [args.gyro] if args.gyro is not None else list(range(1, meas.n_gyros + 1))
    signal, what = allan_signal(meas, raw=args.raw)
    tau_note = None
    if isinstance(taus, int):       # within what the record gives and the noise fit takes
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


def _allan_each(meas, signal, gyros: list[int], taus, args) -> tuple[dict, dict]:
    """The Allan analysis of each gyro; a gyro that cannot be analysed is noted, not fatal.

    Returns ``(analyses by gyro, reason by gyro not analysed)``; refuses
    (one line, every reason) when no gyro can be analysed.
    """
    # deferred: numpy and the analysis (numba) load only when the command runs (a fast --help)
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
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_allan)

    p = sub.add_parser("davar", help="dynamic Allan deviation (fixed or adaptive window, paper 000)")
    p.add_argument("measurement", type=Path, nargs="?", metavar="MEAS.csv")
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

