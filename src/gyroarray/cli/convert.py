"""``gyroarray convert``: a ROS bag of ``sensor_msgs/msg/Imu`` into the measurement format
(CSV + TOML sidecar, ``shared/spec/measurement-format.md``), for users who want the file.

Every command that reads a measurement reads the bag directly too (``--topic``,
``--extrinsics``); this writes what they would read (:mod:`gyroarray.core.bags`).
"""

from __future__ import annotations

from pathlib import Path

from gyroarray.cli.common import add_bag_options, add_force, bag_options, measurement_inputs, output
from gyroarray.core.errors import InputError

__all__ = ["add_parser", "cmd_convert"]

#: Suffixes of the written measurement (the spec's CSV, plain or gzip, or Parquet: the same
#: columns as float64, recommended for long records).
OUT_SUFFIXES = (".csv", ".csv.gz", ".parquet")


def _sidecar(csv_path: Path) -> Path:
    """``F.csv.gz`` / ``F.csv`` / ``F.parquet`` -> ``F.toml`` beside it."""
    name = csv_path.name
    low = name.lower()
    stem = name[:-7] if low.endswith(".csv.gz") else name[:-8] if low.endswith(".parquet") else name[:-4]
    return csv_path.with_name(stem + ".toml")


def cmd_convert(args) -> tuple[dict, str]:
    # deferred: numpy and rosbags load only when the command runs (a fast --help)
    from gyroarray.core.bags import is_bag
    from gyroarray.core.measurement import is_parquet, read_measurement, write_measurement
    to_parquet = str(args.out).lower().endswith(".parquet")
    if not is_bag(args.measurement) and not to_parquet and not is_parquet(args.measurement):
        raise InputError("convert reads a ROS bag (.bag, .db3, .mcap or a ROS2 bag folder); this "
                         "is not one (a measurement CSV is already in the format; --out F.parquet "
                         "converts it to Parquet)", file=str(args.measurement))
    inputs = measurement_inputs(args)
    out = output(args.out, args, "--out", inputs=inputs, suffixes=OUT_SUFFIXES)
    output(_sidecar(Path(args.out)), args, "--out (its sidecar)", inputs=inputs)
    meas = read_measurement(args.measurement, repair=args.repair, **bag_options(args))
    csv_path, toml_path = write_measurement(meas, out or args.out, force=args.force)
    result = {("bag" if is_bag(args.measurement) else "measurement"): str(args.measurement),
              "out": str(csv_path), "sidecar": str(toml_path),
              "n_samples": meas.n_samples, "n_gyros": meas.n_gyros,
              "sample_rate_hz": meas.sample_rate_hz, "duration_s": float(meas.time_s[-1]),
              "axes": meas.layout.axes.tolist(), "description": meas.description,
              "notes": list(meas.notes)}
    lines = [f"{args.measurement}: {meas.n_samples} samples at {meas.sample_rate_hz:.6g} Hz, "
             f"{meas.n_gyros} gyros", *[f"note: {n}" for n in meas.notes],
             f"wrote {csv_path} and {toml_path}"]
    return result, "\n".join(lines)


def add_parser(sub) -> None:
    """The ``convert`` subcommand (ROS bag to measurement files)."""
    p = sub.add_parser("convert", help="a ROS bag of sensor_msgs/msg/Imu into a measurement "
                                       "(CSV.GZ or Parquet + TOML), or a measurement CSV into Parquet")
    p.add_argument("measurement", type=Path, metavar="BAG",
                   help="a ROS1 .bag, a ROS2 .db3 or .mcap file, or a ROS2 bag folder; or a "
                        "measurement CSV/CSV.GZ (with --out F.parquet), or a Parquet measurement")
    p.add_argument("--out", type=Path, required=True, metavar="MEAS.csv.gz",
                   help="the measurement to write (.csv, .csv.gz, or .parquet: recommended for long "
                        "records, which gyroarray allan streams); its .toml sidecar beside it")
    add_bag_options(p)
    p.add_argument("--repair", action="store_true",
                   help="fill short gaps and resample a jittering clock (each listed)")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_convert)
