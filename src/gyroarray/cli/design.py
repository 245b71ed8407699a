"""``gyroarray gdop`` and ``gyroarray design``: GDOP of a layout, the optimal cone angle, paper
003's tables and plots, and ``design --recommend`` (which array to build), with their text.

numpy and the design chain are imported inside the commands, so that building the parser
(``gyroarray --help``, every other command) does not load them.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from gyroarray.core.errors import InputError
from gyroarray.core.units import deg_s_to_rad_s, deg_to_rad, rad_to_deg
from gyroarray.cli.common import (add_force, add_plugin, bounded_int, check_plot, count, finite_float,
                                  float_in, nonneg_int, output, write_json)

__all__ = ["MAX_DESIGN_GYROS", "MAX_DESIGN_N", "add_parser", "cmd_gdop", "cmd_design",
           "parse_sensor_bandwidth"]


#: Most gyros a design question may ask about (the search costs O(N³) per angle).
MAX_DESIGN_GYROS = 128


#: Largest N the design search takes (every failure combination is enumerated).
MAX_DESIGN_N = 24


def _add_layout_args(p: argparse.ArgumentParser, *, alpha: bool, required: bool):
    p.add_argument("--scheme", type=int, choices=(1, 2), required=required,
                   help="conical scheme: 1 all gyros on the cone, 2 gyro 1 on +z")
    p.add_argument("--n", type=bounded_int("--n", 3, MAX_DESIGN_GYROS), required=required, metavar="N",
                   help=f"number of gyros (3 to {MAX_DESIGN_GYROS})")
    if alpha:
        p.add_argument("--alpha", type=float_in("--alpha", 0.0, 180.0, unit="deg"), required=True, metavar="DEG",
                       help="cone angle from +z [deg]")
    p.add_argument("--rho", type=finite_float("--rho"), default=0.0, metavar="R",
                   help="common ARW correlation factor [-] (default 0)")


def cmd_gdop(args) -> tuple[dict, str]:
    # deferred: numpy and the design chain load only when the command runs (a fast --help)
    from gyroarray.core.gdop import gdop, gdop_note
    from gyroarray.core.layout import Layout
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
    # deferred: numpy and the design chain load only when the command runs (a fast --help)
    from gyroarray.core import gdop as design
    from gyroarray.core.layout import Layout
    if args.layout_from is not None:
        if args.recommend:
            raise InputError("gyroarray design: --layout-from predicts the array as built; it does not "
                             "go with --recommend (a search over layouts)")
        return _design_as_built(args)
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
                                ("--objective", args.objective), ("--design-rho", args.design_rho),
                                ("--far-per-h", args.far_per_h), ("--p-md", args.p_md),
                                ("--mdb-max", args.mdb_max), ("--common-mode", args.common_mode),
                                ("--rho-bi", args.rho_bi), ("--flicker", args.flicker),
                                ("--temperature-swing", args.temperature_swing),
                                ("--temperature-period", args.temperature_period),
                                ("--horizon-s", args.horizon_s), ("--family", args.family),
                                ("--alike", args.alike or None)) if v is not None]
    if rec_only:
        raise InputError(f"gyroarray design: {rec_only[0]} goes with --recommend")
    out: dict = {}
    lines: list[str] = []
    check_plot(args)
    rho = 0.0 if args.rho is None else args.rho
    if args.scheme is not None or args.n is not None:
        if args.scheme is None or args.n is None:
            raise InputError("gyroarray design: --scheme and --n go together")
        n = _single_n(args.n)
        opt = design.optimal_alpha(args.scheme, n, rho)
        out.update({"alpha_opt_deg": rad_to_deg(opt.alpha_rad), "gdop_min": opt.gdop})
        lines.append(f"scheme {args.scheme}, N = {n}, rho = {rho:g}: "
                     f"optimal alpha = {rad_to_deg(opt.alpha_rad):.4f} deg, GDOP min = {opt.gdop:.6f}")
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
        from gyroarray.reports.design_plots import design_figure  # deferred: matplotlib, only for a plot
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


def _design_noise(args):
    """The GyroNoise of ``design --recommend`` (model file or datasheet, ρ) and the ρ range to
    test (None: a single ρ)."""
    # deferred: numpy and the design chain load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.design.recommend import GyroNoise
    from gyroarray.effects.names import ARW, GAUSS_MARKOV, RRW
    if args.model is not None and any(v is not None for v in (args.arw, args.rrw, args.bi)):
        raise InputError("gyroarray design: give the noise as --model MODEL.toml or as a datasheet "
                         "(--arw, --rrw, --bi), not both")
    if args.model is not None:
        from gyroarray.effects.model import NoiseModel  # deferred: numba (--model only)
        g = GyroNoise.from_model(NoiseModel.from_toml(args.model), source=f"model {args.model}",
                                 alike=bool(args.alike))
    elif args.alike:
        raise InputError("gyroarray design: --alike goes with --model (a datasheet's gyros are alike)")
    elif args.arw is not None:
        g = GyroNoise(arw_deg_rt_h=args.arw, rrw_deg_h_rt_h=args.rrw or 0.0, bi_deg_h=args.bi or 0.0,
                      sources={ARW: "user", RRW: "user" if args.rrw is not None else "default",
                               "bi": "user" if args.bi is not None else "default",
                               GAUSS_MARKOV: "default", "rho_arw": "default", "rho_rrw": "default"})
    elif args.family is not None and not set(_families(args)) & {"cone1", "cone2"}:
        # layouts designed by geometry alone (free/triads/faces): their GDOP and bound ratio do
        # not depend on the noise of equal gyros; the accuracies are then a unit gyro's, said so
        g = GyroNoise(arw_deg_rt_h=GEOMETRY_ARW_DEG_RT_H,
                      sources={ARW: GEOMETRY_SOURCE, RRW: "default", "bi": "default",
                               GAUSS_MARKOV: "default", "rho_arw": "default", "rho_rrw": "default"})
    else:
        raise InputError("gyroarray design --recommend: give the gyro noise: --model MODEL.toml (from "
                         "gyroarray fit --out) or --arw N_DEG_RT_H [--rrw K] [--bi B]"
                         + (" (only --family free, triads or faces design by geometry without it)"
                            if args.family is not None else ""))
    if args.rho is not None and args.rho_range is not None:
        raise InputError("gyroarray design: --rho and --rho-range exclude each other")
    g = GyroNoise(**{**g.in_frame(args.common_mode or "output").__dict__,
                     "sources": {**g.sources, "common_mode": "user" if args.common_mode else "default"}})
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
    if args.rho_bi is not None:                      # else the BI correlation follows the ARW ρ
        g = GyroNoise(**{**g.__dict__, "rho_bi": float(args.rho_bi),
                         "sources": {**g.sources, "rho_bi": "user"}})
    return g, rhos


def _design_motion(args, rate: float, horizon: float):
    """(swing, motion [rad/s] or None, its name, its specific force [m/s²] or None) of ``design``."""
    # deferred: numpy and the design chain load only when the command runs (a fast --help)
    from gyroarray.design.predict import Swing
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
        motion_name = f"swing {vals[0]:g} deg/s at {vals[1]:g} Hz about x, y and z at once"
    if args.motion is not None:
        # deferred: numba and the simulator, only for --motion
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
    from gyroarray.design.recommend import DEFAULT_BANDWIDTH_HZ  # deferred: numpy and the design chain
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
    from gyroarray.design.recommend import ESTIMATORS, DesignSpace  # deferred: numpy and the design chain
    from gyroarray.effects.names import G_SENSITIVITY  # deferred: the effect registry (numpy, scipy, numba)
    src = {}
    g, rhos = _design_noise(args)
    rate = 100.0 if args.rate_hz is None else args.rate_hz
    if not rate > 0:
        raise InputError(f"--rate-hz must be > 0, got {rate:g}")
    horizon = 600.0 if args.horizon_s is None else args.horizon_s
    # the samples DesignSpace.n_samples counts (gyroarray.sim.table.n_samples, without its import)
    _check_horizon(horizon, rate, max(1, math.ceil(round(horizon * rate, 9))) if horizon > 0 else 0)
    ns = tuple(_number_list(args.n, "--n", integer=True)) if args.n is not None else (4, 5, 6, 8)
    dup = sorted({n for n in ns if ns.count(n) > 1})
    if dup:
        raise InputError(f"--n {args.n}: N = {dup[0]} is listed more than once; give each N once "
                         "(refused, not deduplicated)")
    if g.n_gyros is not None:             # a per-gyro model: its gyro count fixes N
        if args.n is not None and set(ns) != {g.n_gyros}:
            raise InputError(f"--n {args.n}: the model {args.model} has {g.n_gyros} gyros, each with its "
                             f"own parameters, so N = {g.n_gyros}; give --n {g.n_gyros}, or --alike to "
                             "reduce them to one typical gyro and search other N", file=args.model)
        ns = (g.n_gyros,)
        src["ns"] = f"model {args.model} (its {g.n_gyros} gyros)"
    bad = [n for n in ns if not 3 <= n <= MAX_DESIGN_N]
    if bad:
        raise InputError(f"--n {bad[0]} is outside 3..{MAX_DESIGN_N} (every failure combination is "
                         "enumerated)")
    failures = 0 if args.failures is None else args.failures
    if failures < 0 or failures > 2:
        raise InputError(f"--failures must be 0, 1 or 2, got {failures}")
    short = [n for n in ns if n - failures < 3]
    if short and (args.n is not None or g.n_gyros is not None):
        # the design search asks for a 3-axis rate (GDOP finite) from the gyros left after every
        # set of `failures` failed ones (design.robust.kept_sets): 3 must remain; the minimum
        # detectable bias needs a parity of the intact array, N >= 4, which N - failures >= 3
        # with failures >= 1 gives (the default list leaves such N out with a note)
        n = short[0]
        what = f"the model's {n} gyros" if g.n_gyros is not None else f"--n {n}"
        raise InputError(f"--failures {failures} with {what}: N − failures must be ≥ 3 (a 3-axis "
                         f"rate needs 3 gyros left after every set of {failures} failed one(s)); "
                         f"{n} − {failures} = {n - failures}: give N ≥ {failures + 3} or --failures "
                         f"≤ {max(n - 3, 0)}", file=args.model if g.n_gyros is not None else None)
    ests = ESTIMATORS
    if args.estimators is not None:
        ests = tuple(e.strip() for e in args.estimators.split(",") if e.strip())
        from gyroarray.design.search_space import design_refusal   # by the estimators' design tags
        why = next(((e, r) for e in ests if (r := design_refusal(e)) is not None), None)
        if why is not None or not ests:
            raise InputError(f"--estimators: {why[1] if why else '(none) given'} (the built-ins the "
                             f"design search predicts: {', '.join(ESTIMATORS)})")
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
        src[G_SENSITIVITY] = "user"
    for key, v in (("rate_hz", args.rate_hz), ("horizon_s", args.horizon_s), ("ns", args.n),
                   ("estimators", args.estimators), ("failures", args.failures),
                   ("motion", args.swing or args.motion), ("far_per_h", args.far_per_h),
                   ("p_md", args.p_md)):
        src.setdefault(key, "user" if v is not None else "default")
    space = DesignSpace(rate_hz=rate, horizon_s=horizon, ns=ns, estimators=ests, failures=failures,
                        schemes=_cone_schemes(_families(args)),
                        bandwidth_hz=(float(bw[0]), float(bw[1])), swing=swing, motion=motion,
                        motion_name=motion_name, sensor_bandwidth=sensor_bw,
                        g_sensitivity_deg_s_per_g=None if gsens is None else tuple(gsens),
                        specific_force_m_s2=force, objective=args.objective,
                        design_rho=args.design_rho,
                        far_per_h=0.01 if args.far_per_h is None else args.far_per_h,
                        p_md=0.001 if args.p_md is None else args.p_md, mdb_max=args.mdb_max,
                        **({} if args.flicker is None else {"flicker_model": args.flicker}),
                        temperature_swing_k=args.temperature_swing, temperature_period_s=args.temperature_period)
    src.setdefault("flicker_model", "user" if args.flicker is not None else "default")
    src.setdefault("temperature", "user" if args.temperature_swing is not None else "default")
    if args.temperature_period is not None and args.temperature_swing is None:
        raise InputError("--temperature-period S needs --temperature-swing C (the swing's amplitude [K])")
    if args.mdb_max is not None and not failures:
        raise InputError("--mdb-max needs --failures K (K >= 1): the detection limit is about "
                         "isolating a failed gyro")
    if args.design_rho is not None:
        lo, hi = (min(rhos), max(rhos)) if rhos else (g.rho_arw, g.rho_arw)
        if not lo <= args.design_rho <= hi:
            raise InputError(f"--design-rho {args.design_rho:g} lies outside the correlation range "
                             f"[{lo:g}, {hi:g}]: give a value inside --rho-range (or --rho)")
    object.__setattr__(space, "_sources", src)
    return g, space, rhos


#: Lowest sensor cut-off, as a share of the sample rate [-].
MIN_SENSOR_BANDWIDTH_SHARE = 1e-6

#: Lowest datasheet ARW [deg/√h] (design.recommend.MIN_ARW_DEG_RT_H; below it the white
#: variance per sample underflows).
MIN_ARW_DEG_RT_H = 1e-9

#: Most samples a design prediction runs over (its arrays are this long).
MAX_DESIGN_SAMPLES = 20_000_000

#: Start-up the design's window metrics leave out [s] (DesignSpace.settle_s, predict_as_built).
DESIGN_SETTLE_S = 2.0


def _horizon_range(rate: float) -> tuple[int, int]:
    """Fewest and most samples a design run may have at ``rate`` [Hz]: the start-up of
    :data:`DESIGN_SETTLE_S` and 2 samples after it, at most :data:`MAX_DESIGN_SAMPLES`."""
    from gyroarray.design.predict import settle_start  # deferred: numpy
    k0 = settle_start(int(math.ceil(DESIGN_SETTLE_S * rate)) + 3, 1.0 / rate, DESIGN_SETTLE_S)
    return k0 + 2, MAX_DESIGN_SAMPLES


def _check_horizon(horizon: float, rate: float, n: int, *, option: str = "--horizon-s") -> None:
    """Refuse a run of ``n`` samples (``horizon`` [s] at ``rate`` [Hz]) outside
    :func:`_horizon_range`, naming ``option`` and the valid range in seconds."""
    lo, hi = _horizon_range(rate)
    if not (horizon > 0 and lo <= n <= hi):
        raise InputError(f"{option} must be from {lo / rate:g} to {hi / rate:g} s at {rate:g} Hz "
                         f"({lo} to {hi:.3g} samples: the first {DESIGN_SETTLE_S:g} s are the start-up "
                         f"the metrics leave out, and 2 samples must follow), got {horizon:g}")


def parse_sensor_bandwidth(text: str, rate_hz: float) -> tuple[float, int]:
    """``HZ[,ORDER]`` of ``--sensor-bandwidth``: the gyros' own −3 dB cut-off [Hz] and filter
    order (1, default, or 2 = Butterworth), checked against the Nyquist frequency."""
    vals = _number_list(text, "--sensor-bandwidth")
    nyq = 0.5 * rate_hz
    if len(vals) not in (1, 2):
        raise InputError(f"--sensor-bandwidth must be HZ or HZ,ORDER, got {text!r}")
    fc = vals[0]
    order = vals[1] if len(vals) == 2 else 1
    if not fc >= MIN_SENSOR_BANDWIDTH_SHARE * rate_hz:
        # far below it the filter's pole rounds to 1 (a singular steady state)
        raise InputError(f"--sensor-bandwidth: the cut-off must be from {MIN_SENSOR_BANDWIDTH_SHARE * rate_hz:g} "
                         f"Hz ({MIN_SENSOR_BANDWIDTH_SHARE:g} of --rate-hz {rate_hz:g}) to below the "
                         f"Nyquist frequency {nyq:g} Hz, got {fc:g}")
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
        from gyroarray.effects.model import NoiseModel  # deferred: numba and the effect registry
        from gyroarray.effects.names import BANDWIDTH  # deferred: the effect registry (numpy, scipy, numba)
        ents = [e for e in NoiseModel.from_toml(args.model).entries if e.effect == BANDWIDTH]
        if ents:
            e = min(ents, key=lambda e: float(e.params["cutoff_hz"]))
            fc, order = float(e.params["cutoff_hz"]), int(e.params["order"])
            if not fc < 0.5 * rate:
                raise InputError(f"the model's bandwidth cut-off {fc:g} Hz is not below the Nyquist "
                                 f"frequency {0.5 * rate:g} Hz of --rate-hz {rate:g}", file=args.model)
            if not fc >= MIN_SENSOR_BANDWIDTH_SHARE * rate:
                raise InputError(f"the model's bandwidth cut-off {fc:g} Hz is below "
                                 f"{MIN_SENSOR_BANDWIDTH_SHARE * rate:g} Hz ({MIN_SENSOR_BANDWIDTH_SHARE:g} "
                                 f"of --rate-hz {rate:g}), the lowest the design predicts", file=args.model)
            return (fc, order), f"model {args.model} (lowest cut-off)"
    return None, "default"


def _design_recommend(args) -> tuple[dict, str]:
    from gyroarray.design.recommend import monte_carlo_check, recommend  # deferred: numpy and the design chain
    output(args.out, args, "--out", inputs=[args.model] if args.model is not None else [],
            suffixes=(".json",))
    g, space, rhos = _design_space(args)
    try:
        res = recommend(g, space, rhos=rhos)
    except InputError as err:
        if not err.message.startswith("no design meets"):
            raise
        raise InputError(f"{err.message} (the search's conditions: --n, --failures, --rho-range, "
                         "--bandwidth-hz)", file=err.file) from None
    # deferred: numpy and the design chain (a fast --help)
    from gyroarray.design.details import frame_comparison
    from gyroarray.design.statements import detection_assumption
    res["common_mode"] = frame_comparison(res, g, space, rhos)
    if space.failures:
        res["assumptions"]["detection"]["value"] = detection_assumption(space, res["recommended"])
    _add_bounds(res, args, space, rhos, g)
    if GEOMETRY_SOURCE in g.sources.values():
        res.setdefault("notes", []).append(
            f"no gyro noise given: the layouts are designed and ranked by geometry alone (worst GDOP, bound "
            f"ratio), which do not depend on the noise of equal gyros; every rate and angle error here is "
            f"for a unit white noise of {GEOMETRY_ARW_DEG_RT_H:g} deg/√h and no walk (give --arw/--rrw or "
            "--model for the gyros' own)")
    if args.check:
        res["check"] = monte_carlo_check(res["designs"], g, space, replicates=args.check,
                                         seed=20260412 if args.seed is None else args.seed)
    if args.out is not None:
        write_json(args.out, res, args)
        res["written"] = str(args.out)
    return res, _recommend_text(res) + _layouts_text(res)


#: The unit gyro ``design --recommend --family free|triads|faces`` takes when no noise is given
#: [deg/√h]: the layouts' GDOP and bound ratio are the same for any equal gyros.
GEOMETRY_ARW_DEG_RT_H = 1.0
GEOMETRY_SOURCE = "unit gyro (no noise given: the layouts are designed by geometry alone)"


#: The mounting families of ``design --recommend --family`` (gyroarray.design.sphere.FAMILIES).
FAMILY_NAMES = ("cone1", "cone2", "free", "triads", "faces")


def _families(args) -> tuple:
    """The ``--family`` list (default: the cones, today's search)."""
    if args.family is None:
        return ("cone1", "cone2")
    fams = tuple(f.strip() for f in args.family.split(",") if f.strip())
    bad = [f for f in fams if f not in FAMILY_NAMES]
    if bad or not fams:
        raise InputError(f"--family must be a comma list of {', '.join(FAMILY_NAMES)}, got {args.family!r}")
    if len(set(fams)) != len(fams):
        raise InputError(f"--family {args.family}: a family is listed more than once")
    return fams


def _cone_schemes(fams) -> tuple:
    """The cone schemes the noise-based ranking searches: those named, else both (the cones
    the other families are compared with)."""
    return tuple(s for s, f in ((1, "cone1"), (2, "cone2")) if f in fams) or (1, 2)


def _add_bounds(res: dict, args, space, rhos, g) -> None:
    """``bound_ratio`` on every ranked design (its axes against the GDOP floor over the ρ range),
    and with ``--family`` the designed layouts of each family and N (``layouts``), ranked by
    their worst GDOP (fixed GLS weights, worst over ρ x failed gyros)."""
    import numpy as np  # deferred: numpy and the design chain
    from gyroarray.design.sphere import evaluate_layout, search_layout  # deferred: numpy, scipy
    lo, hi = (min(rhos), max(rhos)) if rhos else (g.rho_arw, g.rho_arw)
    if hi < 0 or hi >= 1:
        res.setdefault("notes", []).append(
            f"bound_ratio: the GDOP floor 3·√((1 − ρ)/N) holds for 0 <= ρ < 1; the range [{lo:g}, {hi:g}] "
            "has no part there, so no design is scored against it")
        return
    if lo < 0:
        # the floor is a floor only for ρ >= 0 (anti-correlated gyros gain from axes that do not
        # sum to zero): the designs are scored against it over the range's part at or above 0
        res.setdefault("notes", []).append(
            f"bound_ratio: the GDOP floor 3·√((1 − ρ)/N) holds for ρ >= 0; the designs are scored "
            f"against it over [0, {hi:g}], the part of the range [{lo:g}, {hi:g}] where it holds"
            + (" (and --family designs its layouts for that part)" if args.family is not None else ""))
        lo = 0.0
    seen: dict = {}

    def bound(d):
        key = np.asarray(d["axes"], dtype=float).round(12).tobytes()
        if key not in seen:
            seen[key] = evaluate_layout(np.asarray(d["axes"], dtype=float), family=f"cone{d['scheme']}",
                                        rho_range=(lo, hi), failures=space.failures)
        e = seen[key]
        return {"bound_ratio": e.bound_ratio, "bound_ratio_rho": e.bound_ratio_rho,
                "worst_gdop": e.worst_gdop, "floor": e.worst_gdop / e.failed_bound_ratio,
                "worst_over_floor": e.failed_bound_ratio, "min_parity_angle_deg": e.min_parity_angle_deg}
    for d in res["designs"]:
        if "axes" in d:
            d.update(bound(d))
    for k in ("recommended", "runner_up"):
        if res.get(k) and "axes" in res[k]:
            res[k].update(bound(res[k]))
    if args.family is None:
        return
    rng = np.random.default_rng(20260412 if args.seed is None else args.seed)
    layouts: list[dict] = []
    notes: list[str] = []
    for fam in _families(args):
        for n in space.ns:
            if fam == "triads" and n % 3:
                notes.append(f"triads, N = {n}: not a multiple of 3 (M orthogonal triads); left out")
                continue
            if n < 4:
                notes.append(f"{fam}, N = {n}: the sphere search designs N >= 4; left out")
                continue
            d = search_layout(n, family=fam, rho_range=(lo, hi), failures=space.failures, rng=rng,
                              starts=4)
            if d is None:
                notes.append(f"{fam}, N = {n}: no layout of the family meets the minimum pairwise angle "
                             "and parity angle (isolability); left out")
                continue
            layouts.append(d.to_dict())
    layouts.sort(key=lambda x: (x["worst_gdop"], x["bound_ratio"]))
    for i, x in enumerate(layouts):
        x["rank"] = i + 1
    res["layouts"] = layouts
    res["layout_notes"] = notes
    res["layout_objective"] = (f"worst GDOP (GLS weights fixed at the design rho) over rho in [{lo:g}, {hi:g}] "
                               f"x every set of {space.failures} failed gyro(s); floor 3·sqrt((1 − rho)/N); "
                               "these layouts are ranked by geometry alone, beside (not inside) the "
                               "noise-model ranking of the cones above")


def _layouts_text(res: dict) -> str:
    r = res["recommended"]
    lines = []
    if "bound_ratio" in r:
        lines.append(f"  bound: worst case GDOP {r['worst_gdop']:.4f}, floor {r['floor']:.4f} "
                     f"(ratio {r['worst_over_floor']:.4f}); largest GDOP/floor over the rho range "
                     f"{r['bound_ratio']:.4f} at rho {r['bound_ratio_rho']:.3g}")
    if "layouts" not in res:
        return ("\n" + "\n".join(lines)) if lines else ""
    lines += ["", "Layouts by family (" + res["layout_objective"] + "):",
              f"{'rank':>4} {'family':<7} {'N':>3} {'worst GDOP':>10} {'floor':>7} {'ratio':>7} "
              f"{'bound_ratio':>11} {'min angle':>9} {'parity':>7} {'isolable':>8} {'MDB/floor':>9}"]
    for x in res["layouts"]:
        fl = x["worst_gdop"] / x["failed_bound_ratio"]
        lines.append(f"{x['rank']:>4} {x['family']:<7} {x['n']:>3} {x['worst_gdop']:>10.4f} {fl:>7.4f} "
                     f"{x['failed_bound_ratio']:>7.4f} {x['bound_ratio']:>11.4f} {x['min_angle_deg']:>8.1f}° "
                     f"{x['min_parity_angle_deg']:>6.1f}° {'yes' if x['isolable'] else 'no':>8} "
                     f"{x['mdb_ratio']:>9.4f}")
    for x in res["layouts"]:
        lines.append(f"  {x['family']}, N = {x['n']}: worst case {x['worst_gdop']:.4f}, floor "
                     f"{x['worst_gdop'] / x['failed_bound_ratio']:.4f} (ratio {x['failed_bound_ratio']:.4f})")
        gain = x["detail"].get("gain")
        if gain:
            lines.append(f"    {x['n'] // 3} IMUs (triads), each rotated: at rho = {gain['rho']:g} the fused rate's "
                         f"standard deviation per axis is {gain['gain_over_coaligned']:.3f}x smaller than with "
                         f"the triads mounted alike ({gain['gain_over_one_gyro_rotated']:.2f}x against one gyro, "
                         f"co-aligned {gain['gain_over_one_gyro_coaligned']:.2f}x)")
        lines += [f"    note: {t}" for t in x["notes"]]
    if res["layouts"]:
        best = res["layouts"][0]
        cones = [x for x in res["layouts"] if x["family"].startswith("cone")]
        cone = (f"; the best cone: {cones[0]['family']}, N = {cones[0]['n']}, worst GDOP "
                f"{cones[0]['worst_gdop']:.4f} (bound_ratio {cones[0]['bound_ratio']:.4f})") if cones else ""
        lines.append(f"best layout by GDOP: {best['family']}, N = {best['n']}, worst GDOP {best['worst_gdop']:.4f} "
                     f"(bound_ratio {best['bound_ratio']:.4f}){cone}")
    lines += [f"note: {t}" for t in res["layout_notes"]]
    return "\n" + "\n".join(lines)


def _design_as_built(args) -> tuple[dict, str]:
    """``design --model ARRAY.toml --layout-from MEAS``: each estimator's fused ADEV, RMS and
    angle error on the measured array's axes with the model's per-gyro noise and covariance."""
    # deferred: numpy, numba and the design chain load only when the command runs (a fast --help)
    import numpy as np
    from gyroarray.core.measurement import read_measurement
    from gyroarray.design.recommend import predict_as_built
    from gyroarray.effects.model import NoiseModel
    from gyroarray.effects.names import CORRELATION
    if args.model is None:
        raise InputError("gyroarray design --layout-from: give the array's noise model, --model ARRAY.toml "
                         "(gyroarray fit --out on the record)")
    extra = [o for o, v in (("--n", args.n), ("--scheme", args.scheme), ("--alike", args.alike or None),
                            ("--arw", args.arw), ("--rrw", args.rrw), ("--bi", args.bi),
                            ("--rho", args.rho), ("--rho-range", args.rho_range),
                            # the search's own options: the record fixes the rate, nothing is searched
                            ("--rate-hz", args.rate_hz), ("--swing", args.swing), ("--motion", args.motion),
                            ("--failures", args.failures), ("--bandwidth-hz", args.bandwidth_hz),
                            ("--sensor-bandwidth", args.sensor_bandwidth),
                            ("--g-sensitivity", args.g_sensitivity), ("--objective", args.objective),
                            ("--design-rho", args.design_rho), ("--far-per-h", args.far_per_h),
                            ("--p-md", args.p_md), ("--mdb-max", args.mdb_max), ("--check", args.check),
                            ("--common-mode", args.common_mode),
                            ("--rho-bi", args.rho_bi), ("--flicker", args.flicker),
                            ("--temperature-swing", args.temperature_swing),
                            ("--temperature-period", args.temperature_period),
                            ("--seed", args.seed), ("--paper-tables", args.paper_tables or None),
                            ("--plot", args.plot)) if v is not None]
    if extra:
        raise InputError(f"gyroarray design --layout-from: {extra[0]} does not apply (the layout and the "
                         "sample rate are the measurement's, the noise the model's, and nothing is "
                         "searched; --horizon-s, --estimators and --out apply)")
    output(args.out, args, "--out", inputs=[args.model, args.layout_from], suffixes=(".json",))
    meas = read_measurement(args.layout_from)
    axes = np.asarray(meas.layout.axes, dtype=float)
    _check_as_built_layout(axes, str(args.layout_from))
    model = NoiseModel.from_toml(args.model)
    ests = None if args.estimators is None else tuple(e.strip() for e in args.estimators.split(",") if e.strip())
    rate = 1.0 / meas.dt_s
    if args.horizon_s is None:
        n = meas.n_samples
        lo, hi = _horizon_range(rate)
        if not lo <= n <= hi:
            raise InputError(f"the record has {n} samples ({n * meas.dt_s:g} s), outside the {lo} to "
                             f"{hi:.3g} a prediction runs over (the first {DESIGN_SETTLE_S:g} s are the "
                             f"start-up, 2 samples must follow): give --horizon-s from {lo / rate:g} to "
                             f"{hi / rate:g} s", file=str(args.layout_from))
    else:
        n = int(round(args.horizon_s / meas.dt_s)) if args.horizon_s > 0 else 0
        _check_horizon(args.horizon_s, rate, n)
    from gyroarray.core.limits import check_memory  # deferred with the rest of the command
    check_memory(AS_BUILT_BYTES_PER_SAMPLE * n, f"the prediction over {n} samples",
                 "shorten --horizon-s")
    res = predict_as_built(model, axes, meas.dt_s, n_samples=n, estimators=ests, source=str(args.model))
    res["measurement"] = str(args.layout_from)
    res["model"] = str(args.model)
    if args.out is not None:
        write_json(args.out, res, args)
        res["written"] = str(args.out)
    lines = [f"Predicted on {args.layout_from} as built ({res['n_gyros']} gyros, "
             f"{'per-gyro noise' if res['per_gyro'] else 'alike gyros'}, {res[CORRELATION]}), "
             f"over {res['horizon_s']:g} s:",
             f"{'estimator':<10} {'axis':<4} {'ARW deg/rt(h)':>13} {'RMS deg/s':>10} {'angle deg':>10}  "
             "ADEV deg/s at tau = " + ", ".join(f"{t:g}" for t in res["taus_s"][::3]) + " s"]
    for name, axes in res["estimators"].items():
        for ax, v in axes.items():
            lines.append(f"{name:<10} {ax:<4} {v['arw_deg_rt_h']:>13.4g} {v['rms_deg_s']:>10.4g} "
                         f"{v['angle_deg']:>10.4g}  " + ", ".join(f"{p['adev_deg_s']:.3g}"
                                                                   for p in v["adev_deg_s"][::3]))
    lines += [f"note: {t}" for t in res["notes"]]
    return res, "\n".join(lines)


#: Peak memory of ``design --layout-from`` per sample of the run [bytes] (a few float64 arrays
#: of the run's length: the start-up's time axis, the predictor's windows).
AS_BUILT_BYTES_PER_SAMPLE = 32


def _check_as_built_layout(axes, source: str) -> None:
    """Refuse a measured layout that cannot give a 3-axis rate: fewer than 3 gyros, or axes
    that do not span 3-D (naming the gyros whose axes are coplanar or collinear)."""
    import numpy as np  # deferred: numpy
    from gyroarray.core.gdop import unobservable_reason  # deferred: numpy
    n = axes.shape[0]
    if n < 3:
        raise InputError(f"--layout-from: the array has {n} gyro(s); a 3-axis rate needs at least 3 "
                         "whose axes span 3-D", file=source)
    rank = int(np.linalg.matrix_rank(axes, tol=1e-9 * max(1.0, float(np.abs(axes).max()))))
    if rank < 3:
        gyros = ", ".join(str(k + 1) for k in range(n))
        shape = "coplanar" if rank == 2 else "collinear (identical or opposite)" if rank == 1 else "zero"
        raise InputError(f"--layout-from: the axes of gyros {gyros} are {shape}: rank {rank} of 3, so no "
                         "3-axis rate; check the sidecar's [layout]", file=source)
    why = unobservable_reason(axes)
    if why is not None:
        raise InputError(f"--layout-from: the measured axes give no 3-axis rate: {why}; check the "
                         "sidecar's [layout]", file=source)


def _recommend_text(res: dict) -> str:
    from gyroarray.design.recommend import design_label  # deferred: numpy and the design chain
    from gyroarray.effects.names import G_SENSITIVITY  # deferred: the effect registry (numpy, scipy, numba)
    r = res["recommended"]
    lo, hi = r.get("rho_range", [None, None])
    lines = [f"Designs, best worst case first ({r.get('objective', 'rate')} objective; worst over "
             f"rho in [{lo:g}, {hi:g}] x every set of {res['assumptions']['failures']['value']} failed "
             "gyro(s), weights fixed at the design rho):",
             f"{'rank':>4} {'design':<62} {'worst RMS':>10} {'worst angle':>11} {'at rho':>7} "
             f"{'failed':>6} {'design rho':>10} {'worst GDOP':>10}"]
    for d in res["designs"][:15]:
        w = d["worst_case"]
        rd = "-" if d["design_rho"] is None else f"{d['design_rho']:.3g}"
        lines.append(f"{d['rank']:>4} {design_label(d):<62} {w['rms_3axis_deg_s']:>10.4g} "
                     f"{w['angle_deg']:>11.4g} {w['rho']:>7.3g} "
                     f"{','.join(map(str, w['failed_gyros'])) or '-':>6} {rd:>10} "
                     f"{d['worst_gdop_after_failures']:>10.4g}")
    for grp in res["equivalent"][:6]:
        lines.append(f"equivalent (ranks {', '.join(map(str, grp['members']))}): {grp['reason']}")
    if "check" in res:
        c = res["check"]
        lines.append(f"Monte-Carlo check ({c['replicates']} paired runs{', K chosen by --check auto' if c.get('auto') else ''}): "
                     f"{c['inside_95']} of {c['compared']} predictions inside the runs' 95 % CI")
        for d in c["designs"]:
            t = d["rms_3axis_deg_s"]
            lines.append(f"  {d['label']}: predicted {t['predicted']:.4g}, simulated {t['monte_carlo']['value']:.4g} "
                         f"[{t['monte_carlo']['ci_low']:.4g}, {t['monte_carlo']['ci_high']:.4g}] deg/s")
        if c.get("sizing"):
            sz, po = c["sizing"], c["sizing"]["paired_objective_difference"]
            lines.append(f"  check sizing: {sz['statement']}")
            if po["ci_low"] is not None:
                lines.append(f"  runs: paired difference {po['mean']:.4g} [{po['ci_low']:.4g}, {po['ci_high']:.4g}] "
                             f"{sz['unit']} (predicted {po['predicted']:.4g}); sd over the {po['n']} runs "
                             f"{po['sd_over_runs']:.4g} {sz['unit']}; resolved: {'yes' if po['resolved'] else 'no'}")
        if c.get("flicker_mismatch"):
            lines.append(f"  note: {c['flicker_mismatch']}")
    if "tracking_limit" in res:
        lines.append("tracking: " + res["tracking_limit"]["statement"])
    if G_SENSITIVITY in res:
        lines.append(res[G_SENSITIVITY]["statement"])
    lines += [f"what would change the choice: {w}" for w in res["what_changes_the_choice"]]
    lines += [f"note: {n}" for n in res["notes"]]
    a = res["assumptions"]
    if "common_mode" in res:
        cm = res["common_mode"]
        lines.append(f"common mode: chosen the {cm['chosen']} frame ({a['common_mode']['source']}): "
                     + a["common_mode"]["unit"])
        lines += [f"  {cm['frames'][f]['statement']}" for f in cm["frames"]]
    if "flicker_model" in a:
        lines.append(f"flicker model: {a['flicker_model']['unit']}")
    if "temperature" in a:
        lines.append(f"temperature: {a['temperature']['value']}")
    if r.get("mdb_statement"):
        lines.append(f"detection: {r['mdb_statement']}")
    w, t, ru = r["worst_case"], r["typical"], res.get("runner_up")
    failed = ("no failure" if not w["failed_gyros"] else
              "gyro " + ", ".join(map(str, w["failed_gyros"])) + " failed")
    rd = ("built without rho" if r["design_rho"] is None else f"weights built for rho = {r['design_rho']:.4g}")
    mdb = ""
    if r.get("mdb_deg_s"):
        tied = r.get("mdb_worst_gyros") or [r["mdb_worst_gyro"]]
        who = f"gyro {tied[0]}" if len(tied) == 1 else f"gyros {','.join(map(str, tied))} tied"
        where = (f" at rho {r['mdb_rho']:.3g}, {r['mdb_window_s']:.3g} s window"
                 if r.get("mdb_rho") is not None else "")
        mdb = f"; MDB {r['mdb_deg_s']:.3g} deg/s ({who}{where})"
    frame = (f"; common mode in the {a['common_mode']['value']} frame" if "common_mode" in a else "")
    flick = (f"; flicker: the {a['flicker_model']['value']} model" if "flicker_model" in a else "")
    lines += ["", f"RECOMMENDED ({r['objective']} objective{frame}{flick}): {design_label(r)}; "
                  f"{r['mounting']}; {rd}",
              f"  worst case rho = {w['rho']:.4g}, {failed}: {w['rms_3axis_deg_s']:.4g} deg/s 3-axis RMS, "
              f"{w['angle_deg']:.4g} deg at the horizon; typical (design rho, intact): "
              f"{t['rms_3axis_deg_s']:.4g} deg/s, {t['angle_deg']:.4g} deg{mdb}"
              + (f"; {r['tie']}" if r.get("tie") else ""),
              "  runner-up: " + (f"{design_label(ru)}, worst case {ru['worst_case']['rms_3axis_deg_s']:.4g} deg/s, "
                                 f"{ru['worst_case']['angle_deg']:.4g} deg" if ru else "none")]
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


def _check_runs(text: str) -> int | str:
    """``--check``: a number of paired runs (1 to its cap) or ``auto`` (the check sizes itself)."""
    return "auto" if text.strip().lower() == "auto" else count("--check")(text)


def add_parser(sub) -> None:
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
    p.add_argument("--rho", type=finite_float("--rho"), metavar="R",
                   help="common correlation of the gyros' noise [-] (default 0; with --recommend "
                        "it applies to ARW and RRW)")
    p.add_argument("--recommend", action="store_true",
                   help="search scheme x N x cone angle x estimator x bandwidth with the "
                        "analytic predictor and recommend a design")
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="--recommend: the gyro noise from a model (gyroarray fit --out); a model that "
                        "names its gyros keeps each gyro's own parameters and fixes N")
    p.add_argument("--alike", action="store_true",
                   help="--model: reduce the model's gyros to one typical gyro (quadratic means) and "
                        "search every N")
    p.add_argument("--layout-from", type=Path, metavar="MEAS",
                   help="with --model: predict each estimator's fused ADEV, RMS and angle error on the "
                        "array as built (the measurement sidecar's axes, the model's per-gyro noise "
                        "and [array] covariance)")
    p.add_argument("--arw", type=float_in("--arw", MIN_ARW_DEG_RT_H, 6e6, unit="deg/√h"), metavar="DEG_RT_H",
                   help="--recommend: angle random walk [deg/rt(h)]")
    p.add_argument("--rrw", type=float_in("--rrw", 0.0, 3.6e8, unit="deg/h/√h"), metavar="DEG_H_RT_H",
                   help="--recommend: rate random walk [deg/h/rt(h)] (default 0)")
    p.add_argument("--bi", type=float_in("--bi", 0.0, 3.6e8, unit="deg/h"), metavar="DEG_H",
                   help="--recommend: bias instability [deg/h] (default 0)")
    p.add_argument("--rho-range", metavar="LO,HI",
                   help="--recommend: the correlations the gyros may have; ranked per rho, "
                        "recommended: the best worst case (a negative LO: --rho-range=-0.1,0.5)")
    p.add_argument("--rate-hz", type=float_in("--rate-hz", 1e-3, 1e6, unit="Hz"), metavar="HZ",
                   help="--recommend: sample rate (default 100)")
    p.add_argument("--horizon-s", type=finite_float("--horizon-s"), metavar="T",
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
    p.add_argument("--objective", choices=("rate", "angle"),
                   help="--recommend: rank on the 3-axis RMS rate error (rate) or the angle error at the "
                        "horizon (angle); default angle when --horizon-s is given, else rate")
    p.add_argument("--design-rho", type=float_in("--design-rho", -1.0, 1.0, lo_open=True), metavar="R",
                   help="--recommend: the ρ the estimator's weights are built for (default: chosen "
                        "min-max over --rho-range)")
    p.add_argument("--far-per-h", type=float_in("--far-per-h", 0.0, lo_open=True, unit="1/h"),
                   metavar="RATE", help="--recommend --failures: false-alarm rate of the minimum "
                                        "detectable bias (default 0.01 per hour)")
    p.add_argument("--p-md", type=float_in("--p-md", 0.0, 0.5, lo_open=True), metavar="P",
                   help="--recommend --failures: missed-detection probability of the minimum "
                        "detectable bias (default 0.001)")
    p.add_argument("--mdb-max", type=float_in("--mdb-max", 0.0, lo_open=True, unit="deg/s"),
                   metavar="DEG_S", help="--recommend --failures: exclude designs whose minimum "
                                         "detectable bias (worst gyro) is above DEG_S")
    p.add_argument("--common-mode", choices=("output", "axis"),
                   help="--recommend: the frame the gyros' correlated noise lives in: output (default; "
                        "it adds to every output with the same sign, so reversed gyros move it into the "
                        "parity space) or axis (it follows each gyro's sensing axis, so reversing buys "
                        "nothing); the decision is shown under both")
    p.add_argument("--rho-bi", type=finite_float("--rho-bi"),
                   metavar="R", help="--recommend: common correlation of the gyros' bias instability "
                                     "(flicker) in the predictor (default: the ARW correlation, --rho "
                                     "or each ρ of --rho-range)")
    p.add_argument("--temperature-swing", type=float_in("--temperature-swing", -500.0, 500.0, unit="K"),
                   metavar="C",
                   help="--recommend: the temperature's departure from the calibration temperature [K]: "
                        "the amplitude of a sinusoid with --temperature-period, else constant over the run; "
                        "temperature terms of the model (temperature_bias) then enter the error budget "
                        "(default: not stated, those terms listed as left out)")
    p.add_argument("--temperature-period", type=float_in("--temperature-period", 0.0, 1e9, lo_open=True, unit="s"),
                   metavar="S", help="--recommend: the period of the temperature swing [s] (with --temperature-swing)")
    p.add_argument("--flicker", choices=("kasdin", "circular"),
                   help="--recommend: the bias instability's (flicker) model of the ranking and the error "
                        "budget: kasdin (default; 1/f noise from switch-on, Kasdin 1995) or circular "
                        "(stationary 1/f as the simulator draws it, about half the angle at the horizon)")
    p.add_argument("--family", metavar="F,G,...",
                   help="--recommend: mounting families, a comma list of cone1, cone2, free, triads, faces "
                        "(default cone1,cone2: the cones); free/triads/faces are designed on the sphere "
                        "and listed against the GDOP floor beside the cones' ranking")
    p.add_argument("--estimators", metavar="A,B,...",
                   help="--recommend: estimators compared (default kf_array,kf_single,gls,ols,naive)")
    p.add_argument("--check", type=_check_runs, metavar="K|auto",
                   help="--recommend: simulate the recommendation, the runner-up and the mounting mirror K "
                        "times (paired) beside the prediction, and say whether K runs can resolve the "
                        "recommendation from the runner-up on the objective and how many would (K_needed: "
                        "95 %% interval, 80 %% power, the paired difference's sd from a pilot of the first "
                        "min(K, 20) runs); auto: K = K_needed, at least the 20-run pilot and at most 400 "
                        "(past 400 only the pilot is run, and the output says so)")
    p.add_argument("--seed", type=nonneg_int("--seed"), metavar="S",
                   help="--recommend --check: root seed of the paired runs")
    p.add_argument("--out", type=Path, metavar="FILE.json",
                   help="--recommend: also write the whole result (for gyroarray report --design)")
    p.add_argument("--paper-tables", action="store_true",
                   help="paper 003 Tables 1-2 beside the computed values, cell by cell")
    p.add_argument("--plot", type=Path, metavar="OUT.png",
                   help="write GDOP vs alpha and vs rho (paper 003 Figs. 8-10)")
    add_plugin(p)
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_design)

