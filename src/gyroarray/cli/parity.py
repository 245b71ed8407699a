"""``gyroarray parity`` (parity-space self-calibration of a moving array: scale factor and axis
errors of each gyro, no reference rate needed), with its text.

The chain (numpy, scipy) is imported inside the command, so that building the parser
(``gyroarray --help``, every other command) does not load it.
"""

from __future__ import annotations

from pathlib import Path

from gyroarray.cli.common import add_bag_options, bag_options

__all__ = ["add_parser", "cmd_parity"]


def cmd_parity(args):
    # deferred: the chain (numpy, scipy) loads only when the command runs (a fast --help)
    from gyroarray.chain.parity import calibrate_record, format_parity
    from gyroarray.core.measurement import read_measurement
    from gyroarray.effects.model import NoiseModel
    meas = read_measurement(args.measurement, repair=args.repair, **bag_options(args))
    model = None if args.model is None else NoiseModel.from_toml(args.model, n_gyros=meas.n_gyros)
    cal, notes = calibrate_record(meas, model)
    out = {"calibration": None if cal is None else cal.to_json_dict(), "notes": notes}
    return out, "\n".join([format_parity(cal, str(args.measurement))] + notes)


def add_parser(sub) -> None:
    """The ``parity`` subcommand."""
    p = sub.add_parser("parity", help="scale factor and axis errors of each gyro from the parity "
                                      "of a moving array (self-calibration, no reference rate)")
    p.add_argument("measurement", type=Path, metavar="MEAS.csv")
    add_bag_options(p)
    p.add_argument("--model", type=Path, metavar="MODEL.toml",
                   help="white noise of the gyros, to weight the parity (default: each gyro's own "
                        "level, fitted on the record's still parts)")
    p.add_argument("--repair", action="store_true", help="repair short gaps and isolated NaNs")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_parity)
