"""``gyroarray export``: a gyro's and the accelerometer's noise model as a Kalibr, OpenVINS,
VINS-Fusion, ORB-SLAM3 or MATLAB file, with its convention in a comment header, an optional derived
inflation (simulated, or measured on a bag with a reference pose topic) and a check that re-reads the written file with its consumer's parser and compares it
with a simulation or a record (:mod:`gyroarray.chain.export`).

The chain (numpy, the simulator) is imported inside the command, so that building the parser
(``gyroarray --help``, every other command) does not load it.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from gyroarray.cli.common import EXIT_FAIL, EXIT_OK, add_force, float_in, nonneg_int, output, positive_int
from gyroarray.core.errors import InputError

__all__ = ["add_parser", "cmd_export"]

#: Formats (the keys of :data:`gyroarray.chain.export.FORMATS`, listed here so that building the
#: parser loads no numpy).
FORMAT_NAMES = ("kalibr", "openvins", "vins", "orbslam3", "matlab")

_FACTOR = float_in("--inflate", 0.0, 1e6, lo_open=True)
_OFFSET = float_in("--time-offset-s", -1e6, 1e6, unit="s")


def _axis(text: str):
    """``worst``, ``mean`` or a gyro number >= 1."""
    if text in ("worst", "mean"):
        return text
    return positive_int("--axis")(text)


def _inflate(text: str):
    """``auto``, ``measured`` or a factor > 0."""
    return text if text in ("auto", "measured") else _FACTOR(text)


def _time_offset(text: str):
    """``estimate`` or an offset [s] added to the IMU stamps."""
    return "estimate" if text == "estimate" else _OFFSET(text)


#: The options only ``--inflate measured`` reads (argparse dest, option).
_MEASURED_ONLY = (("reference", "--reference"), ("reference_topic", "--reference-topic"),
                  ("imu_topic", "--imu-topic"), ("time_offset_s", "--time-offset-s"))


def _levels(text: str) -> tuple:
    """``--inflate-levels``: increasing bin edges of the rate level [rad/s], the first >= 0; the
    last bin is open (an infinite edge is appended)."""
    try:
        edges = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--inflate-levels must be comma-separated rates [rad/s], got {text[:60]!r}") from None
    if len(edges) < 2 or not all(math.isfinite(e) for e in edges) or edges[0] < 0 or any(
            b <= a for a, b in zip(edges, edges[1:])):
        raise argparse.ArgumentTypeError(f"--inflate-levels {text[:60]}: give at least two increasing finite rates >= 0 "
                         "[rad/s] (the last bin is open above the last edge)")
    return (*edges, math.inf)


#: The options every ``--inflate measured`` reads, refused without it (argparse dest, option).
_MEASURED_TUNING = (("inflate_window", "--inflate-window"), ("inflate_levels", "--inflate-levels"),
                    ("inflate_holdout", "--inflate-holdout"))


def _check_measured(args) -> None:
    """Refuse ``--inflate measured`` without its reference, and its options without it."""
    if args.inflate != "measured":
        tuning = [opt for dest, opt in _MEASURED_TUNING if getattr(args, dest, None) is not None]
        if tuning:
            raise InputError(f"{', '.join(tuning)} {'is' if len(tuning) == 1 else 'are'} read only with "
                             "--inflate measured")
    if args.inflate == "measured":
        if args.reference is None and args.record is not None:     # the parity residual
            given = [opt for dest, opt in _MEASURED_ONLY if dest != "imu_topic"
                     and getattr(args, dest) is not None]
            if given:
                raise InputError(f"{', '.join(given)} {'is' if len(given) == 1 else 'are'} read only "
                                 "with --reference (without it, --inflate measured reads the parity "
                                 "residual of the --record array)")
            return
        for dest, opt in _MEASURED_ONLY[:2]:
            if getattr(args, dest) is None:
                raise InputError(f"--inflate measured needs {opt} (the bag with the reference pose "
                                 "topic and that topic: --reference BAG --reference-topic T), or "
                                 "--record ARRAY alone: a record of more than 3 gyros, measured "
                                 "from its parity residual")
        return
    given = [opt for dest, opt in _MEASURED_ONLY if getattr(args, dest) is not None]
    if given:
        raise InputError(f"{', '.join(given)} {'is' if len(given) == 1 else 'are'} read only with "
                         "--inflate measured (the inflation measured against a reference pose topic)")


def cmd_export(args):
    # deferred: the chain (numpy, the simulator) loads only when the command runs
    from gyroarray.chain.export import SUFFIXES, build_export, verify_file
    from gyroarray.core.outputs import write_text
    from gyroarray.effects.model import NoiseModel
    _check_measured(args)
    measured = args.inflate == "measured"
    if args.record is not None and not args.verify and not measured:
        raise InputError("--record compares the written file with a measurement: it needs --verify "
                         "(or, with --inflate measured, is the IMU record the inflation is measured on)")
    inputs = [args.model] + [p for p in (args.record, args.reference) if p is not None]
    out = output(args.out, args, "--out", inputs=inputs, suffixes=SUFFIXES[args.format])
    model = NoiseModel.from_toml(args.model)
    axis = args.gyro if args.gyro is not None else args.axis
    inflate, measured_parts = args.inflate, None
    if measured:                                   # before writing: a bad bag writes nothing
        from gyroarray.chain.export import measured_inflation  # deferred: the chain, the bag readers
        imu_record = args.record if args.record is not None else args.reference
        try:
            factor, m_summary, m_lines = measured_inflation(
                model, axis, imu_record, args.reference, args.reference_topic, imu_topic=args.imu_topic,
                time_offset_s="estimate" if args.time_offset_s is None else args.time_offset_s,
                seed=args.seed, window_s=1.0 if args.inflate_window is None else args.inflate_window,
                levels=args.inflate_levels, holdout=0.3 if args.inflate_holdout is None else args.inflate_holdout)
        except InputError as err:
            raise err if err.file is not None else err.with_file(args.model)
        inflate, measured_parts = factor, (m_summary, m_lines)
    try:
        exp = build_export(model, axis, args.format, args.rate_hz, inflate=inflate, seed=args.seed,
                           source=Path(args.model).name, topic=args.topic, measured=measured_parts)
    except InputError as err:
        raise err if err.file is not None else err.with_file(args.model)
    record = None
    if args.record is not None and args.verify:       # read before writing: a bad record writes nothing
        # deferred: the measurement readers (pandas, the bag readers) load only for --record
        from gyroarray.core.bags import is_bag
        from gyroarray.core.measurement import read_measurement
        bag_topic = args.topic if args.topic is not None else args.imu_topic
        record = read_measurement(args.record, topic=bag_topic if is_bag(args.record) else None)
    write_text(out, exp.text, force=args.force)
    summary = exp.summary
    summary["out"] = str(out)
    v = summary["values"]
    lines = [f"wrote {out} ({args.format}, {summary['axis']} of {args.model} at "
             f"{args.rate_hz:g} Hz, {summary['convention']}):"]
    if len(summary["gyros"]) > 1:
        lines.append("  every gyro (ARW deg/√h, RRW deg/h/√h): " + "; ".join(
            f"{g['gyro']}: {g['n_deg_rt_h']:.4g}, {'≤ ' if g.get('k_is_upper_bound') else ''}"
            f"{g['k_deg_h_rt_h']:.4g}" for g in summary["gyros"]))
    lines += [f"  {k} = {val:.6e}" for k, val in v.items() if not k.lower().endswith(("rate", "frequency"))]
    if summary["walk"]["upper_bound"]:
        w = summary["walk"]
        lines.append(f"  gyro walk: not resolved by the model's record (K = 0 ± {w['fit_sigma_deg_h_rt_h']:.4g} "
                     f"deg/h/√h): the file holds its 95 % upper bound {w['k_deg_h_rt_h']:.4g} deg/h/√h "
                     "(conservative; a longer still record resolves it)")
    lines.append(f"  accelerometer: {summary['accelerometer']['axis']}")
    lines += [f"  accelerometer {line}" for line in summary["accelerometer"].get("partial", {}).values()]
    if summary["accelerometer"].get("why_missing") and not summary["missing_fields"]:
        lines.append(f"  accelerometer: {summary['accelerometer']['why_missing']}")
    if "topic" in summary:
        lines.append(f"  rostopic {summary['topic']['topic']} ({summary['topic']['why']})")
    si = summary["stand_in"]
    if si["covers"]:
        lines.append(f"  stand-in random walk for {' + '.join(si['covers'])}: K_eq = "
                     f"{si['k_eq_deg_h_rt_h']:.4g} deg/h/√h, bounds their ADEV for τ >= "
                     f"{si['tau1_s']:.4g} s (within ×2 up to {si['tau2_s']:.4g} s)")
    if "inflate_measured" in summary:
        m = summary["inflate_measured"]
        nis = {c["label"]: c for c in m["nis"]}
        held = ", ".join(f"{what} values {nis[label]['mean_nis']:.3g}"
                         f" ({'inside' if nis[label]['inside'] else 'outside'} "
                         f"{nis[label]['interval'][0]:.3g}-{nis[label]['interval'][1]:.3g})"
                         for label, what in (("measured", "measured"), ("static", "static"),
                                             ("export", "exported")))
        frm = m["from"] if m.get("method") == "parity" else f"from {m['reference']} topic {m['reference_topic']}"
        lines.append(f"  inflation ×{m['factor']:.4g} measured {frm} ({m['axis']}; held-out NIS, "
                     f"1 when consistent: {held})")
        if m.get("unobserved_axes"):
            ax = ", ".join(m["unobserved_axes"])
            lines.append(f"  the reference never turns about {ax} (a planar pose, as wheel odometry gives) while the "
                         f"gyro does: on {ax} the excess is the body's motion, not the gyro's noise; a 3-D reference "
                         "(motion capture, VIO/SLAM pose) measures it")
        if m.get("method") == "parity":
            lines.append("  per motion level (density over the static one, interval): " + "; ".join(
                f"|w| {lv['lo']:g}-{lv['hi']:g} rad/s ×{lv['factor']:.3g} "
                f"[{lv['ci_rad_rt_s'][0] / m['static_n_rad_rt_s']:.3g}, "
                f"{lv['ci_rad_rt_s'][1] / m['static_n_rad_rt_s']:.3g}]"
                for lv in m["levels"] if lv["n_windows"] and lv["density_rad_rt_s"] == lv["density_rad_rt_s"]))
    elif "inflate_auto" in summary:
        a = summary["inflate_auto"]
        lines.append(f"  inflation ×{a['factor']:.4g}: {a['why']}")
        if a["not_simulated"]:
            lines.append(f"  not simulated: {', '.join(a['not_simulated'])}")
    elif summary["inflate"] != 1.0:
        lines.append(f"  inflation ×{summary['inflate']:.4g} (as asked)")
    lines += [f"warning: {w}" for w in summary["warnings"]]
    code = EXIT_OK
    if args.verify:
        ver = verify_file(exp, Path(out).read_text(encoding="utf-8"), record=record, seed=args.seed)
        summary["verify"] = ver
        rb = ver["read_back"]
        lines.append(f"  read back with {rb['parser']}: " + ("every required field, as meant" if not rb["problems"]
                                                            else f"{len(rb['problems'])} problem(s)"))
        for name, c in ver.get("coefficients", {}).items():
            lines.append(f"  round trip {name}: file {c['file']:.5g}, re-identified "
                         f"{c['reidentified']:.5g} ± {c['sigma']:.2g} (z = {c['z']:+.2f})")
        if "band" in ver:
            b = ver["band"]
            lines.append(f"  model ADEV inside the file's 95 % interval at {b['inside_fraction']:.0%} "
                         f"of {b['n_taus']} taus (worst τ = {b['worst_tau_s']:.4g} s, model/file "
                         f"{b['worst_model_over_file']:.3g}); {ver['record_s']:.0f} s simulated")
        if "record" in ver:
            rc = ver["record"]
            for note in rc["parts_notes"]:
                lines.append(f"  record: {note}")
            for c in rc["gyros"] + (rc["accelerometer"] or []):
                lines.append(f"  {c['what']}: the file's ADEV below the record's family-wise 95 % interval at "
                             f"{c['n_below']} of {c['n_taus']} τ (below the per-τ 95 % interval at "
                             f"{c['n_below_95']}), above it at {c['n_above']}")
            for nc in rc.get("accelerometer_not_checked", []):
                lines.append(f"  accelerometer field {nc['field']} NOT CHECKED against the record: {nc['why']}")
            if rc.get("drops"):
                lines.append(f"  the format drops: {rc['drops']}")
        if ver["passed"]:
            lines.append("verify: passed")
        else:
            lines += ["verify: FAILED"] + [f"  {p}" for p in ver["problems"]]
            need = ver.get("record", {}).get("inflate_needed")
            if need is not None:
                lines.append(f"  an --inflate that lifts the file to the record's ADEV at every failing "
                             f"τ: {need:.3g} (the file's numbers × {need:.3g}; conservative at the other τ), "
                             "or refit on a longer or quieter still record")
            code = EXIT_FAIL
    return summary, "\n".join(lines), code


def add_parser(sub) -> None:
    """The ``export`` subcommand."""
    p = sub.add_parser("export", help="write a gyro's noise as a Kalibr/OpenVINS/VINS/ORB-SLAM3/"
                                      "MATLAB file (--verify: round trip; exit 1 when it fails)")
    p.add_argument("model", type=Path, metavar="MODEL.toml")
    p.add_argument("--format", required=True, choices=FORMAT_NAMES,
                   help="kalibr, openvins (continuous densities), vins (discrete per sample), "
                        "orbslam3 (continuous; √rate inside), matlab (gyroparams .m)")
    p.add_argument("--rate-hz", required=True, type=float_in("--rate-hz", 1e-3, 1e6, unit="Hz"),
                   metavar="R", help="the IMU rate the tool runs at [Hz]")
    p.add_argument("--out", required=True, type=Path, metavar="FILE",
                   help="the file to write (.yaml/.yml; .m for matlab)")
    p.add_argument("--axis", type=_axis, default="worst", metavar="worst|mean|K",
                   help="which of the model's gyros the file gets: worst (default: the largest model "
                        "ADEV over tau 0.01-1000 s, as allan_variance_ros), mean (as imu_utils), or gyro K; "
                        "the header says which and lists every gyro's numbers")
    p.add_argument("--gyro", type=positive_int("--gyro"), default=None, metavar="K",
                   help="the model's gyro K (1-based): the same as --axis K")
    p.add_argument("--inflate", type=_inflate, default=1.0, metavar="auto|measured|X",
                   help="factor on the numbers, or auto: the one that makes a white + walk "
                        "filter consistent (NIS = 1) on a record simulated from the full model "
                        "(never below 1; the gyro's only), or measured: the white density in "
                        "motion over the model's, measured against --reference's pose topic "
                        "(never below 1; the gyro's only; held-out NIS in the header); without "
                        "--reference, from the parity residual of a --record of more than 3 gyros")
    p.add_argument("--reference", type=Path, default=None, metavar="BAG",
                   help="with --inflate measured: the ROS bag with the reference pose topic (also "
                        "the IMU record unless --record names one)")
    p.add_argument("--reference-topic", default=None, metavar="T",
                   help="with --inflate measured: the reference's geometry_msgs/PoseStamped or "
                        "nav_msgs/Odometry topic")
    p.add_argument("--imu-topic", default=None, metavar="T",
                   help="with --inflate measured: the IMU topic of the record (default: its one IMU topic)")
    p.add_argument("--time-offset-s", type=_time_offset, default=None, metavar="X|estimate",
                   help="with --inflate measured: offset added to the IMU stamps [s], or estimate "
                        "(default; the header states it)")
    p.add_argument("--inflate-window", type=float_in("--inflate-window", 0.0, 600.0, lo_open=True, unit="s"),
                   default=None, metavar="S",
                   help="with --inflate measured: the window the density is measured over [s] (default 1; "
                        "whole samples, at least two reference pose intervals)")
    p.add_argument("--inflate-levels", type=_levels, default=None, metavar="E0,E1,...",
                   help="with --inflate measured: bin edges of the motion level, |rate| [rad/s] (default "
                        "0,0.05,0.2,0.5,1,1.5,2.5,4; the last bin is open); each level needs 20 fitted windows")
    p.add_argument("--inflate-holdout", type=float_in("--inflate-holdout", 0.0, 0.9, lo_open=True),
                   default=None, metavar="F",
                   help="with --inflate measured: the fraction of each motion level's windows held out, the "
                        "latest ones, for the NIS check (default 0.3)")
    p.add_argument("--topic", default=None, metavar="T",
                   help="the IMU topic of Kalibr/OpenVINS files (default: the model's topic, else /imu0, "
                        "said so in the header); also the topic read from a --record bag")
    p.add_argument("--verify", action="store_true",
                   help="re-read the written file with its consumer's parser (missing or misspelled "
                        "keys, types, walks <= 0), then simulate what the tool reads from it and "
                        "re-identify ARW/RRW, or with --record compare with a measurement; exit 1 "
                        "when it fails")
    p.add_argument("--record", type=Path, default=None, metavar="MEAS",
                   help="with --verify: a measurement (CSV/Parquet with sidecar, or a ROS bag); the "
                        "file's ADEV is compared tau by tau with the record's ADEV and its 95 %% interval "
                        "over its still parts; exit 1 where the file falls below it; with --inflate "
                        "measured also the IMU record the inflation is measured on (default --reference), or, "
                        "without --reference, an array of more than 3 gyros whose parity residual "
                        "gives it")
    p.add_argument("--seed", type=nonneg_int("--seed"), default=0, help="seed of the simulations")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_export)

