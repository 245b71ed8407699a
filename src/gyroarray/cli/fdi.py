"""``gyroarray fdi`` (fault detection and isolation on a measurement) and ``gyroarray check``
(the regression thresholds), with their text.

The chain (numpy, numba) is imported inside the commands, so that building the parser
(``gyroarray --help``, every other command) does not load it.
"""

from __future__ import annotations

from pathlib import Path

from gyroarray.cli.common import add_bag_options, bag_options, EXIT_FAIL, EXIT_OK, add_force, check_plot, finite_float, measurement_inputs

__all__ = ["add_parser", "cmd_fdi", "cmd_check"]


def cmd_fdi(args):
    # deferred: the chain (numpy, numba) loads only when the command runs (a fast --help)
    from gyroarray.chain.fdi_score import analyse_measurement, format_fdi
    from gyroarray.core.measurement import read_measurement
    from gyroarray.effects.model import NoiseModel
    from gyroarray.reports.fdi_plots import plot_fdi
    check_plot(args, inputs=measurement_inputs(args))
    meas = read_measurement(args.measurement, repair=args.repair, **bag_options(args))
    model = None if args.model is None else NoiseModel.from_toml(args.model, n_gyros=meas.n_gyros)
    out, res, _ = analyse_measurement(meas, model, far_per_h=args.far_per_h)
    text = format_fdi(out, str(args.measurement))
    if args.plot is not None:
        path = plot_fdi(res, args.plot, title=f"{args.measurement}: parity statistics",
                        force=args.force)
        text += f"\nwrote {path}"
    return out, text


def cmd_check(args):
    from gyroarray.chain.check import format_check, run_check  # deferred: the chain (numpy, numba)
    result = run_check(args.thresholds, quick=not args.full)
    return result, format_check(result), (EXIT_OK if result["passed"] else EXIT_FAIL)


def add_parser(sub) -> None:
    """The ``fdi`` (fault detection) and ``check`` (regression thresholds) subcommands."""
    p = sub.add_parser("fdi", help="fault detection and isolation on a measurement (parity space)")
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    add_bag_options(p)
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="ARW/RRW/correlation of the gyros (default: estimated from the record)")
    p.add_argument("--far-per-h", type=finite_float("--far-per-h"), default=0.01, metavar="RATE",
                   help="false alarms per hour the thresholds are set for (0.01; from 1e-12 to "
                        "one per 100 samples)")
    p.add_argument("--plot", type=Path, metavar="OUT.png", help="statistics vs threshold over time")
    p.add_argument("--repair", action="store_true", help="repair short gaps and isolated NaNs")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_fdi)

    p = sub.add_parser("check", help="regression thresholds: run the threshold scenarios, exit 1 on a failure")
    p.add_argument("thresholds", type=Path, nargs="?", metavar="THRESHOLDS.toml",
                   help="default: the shipped scenarios/thresholds.toml")
    p.add_argument("--full", action="store_true",
                   help="run each scenario at its full length (slow; default: the quick version)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_check)

