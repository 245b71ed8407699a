"""``gyroarray convert``: a ROS bag of ``sensor_msgs/msg/Imu`` into the measurement format
(CSV + TOML sidecar, ``shared/spec/measurement-format.md``), for users who want the file.

Every command that reads a measurement reads the bag directly too (``--topic``,
``--extrinsics``, ``--stamps``, ``--retime``); this writes what they would read
(:mod:`gyroarray.core.bags`).

One topic is converted in bounded memory: the bag is read in chunks of
:data:`~gyroarray.core.bags.STREAM_CHUNK` messages (:class:`~gyroarray.core.bags.BagStream`)
and each chunk is appended to the output (CSV, CSV.GZ, or Parquet row groups of
:data:`PARQUET_STREAM_ROWS` rows) in a hidden temporary file that gets its name only when the
whole bag was read (a refusal half-way leaves nothing). A progress bar (tqdm) goes to stderr
when stderr is a terminal, or with ``--progress``. An array of topics, ``--repair`` and
``--retime`` need the whole record and read it whole (within the memory budget).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from gyroarray.cli.common import add_bag_options, add_force, bag_options, measurement_inputs, output
from gyroarray.core.errors import InputError

__all__ = ["add_parser", "cmd_convert"]

#: Suffixes of the written measurement (the spec's CSV, plain or gzip, or Parquet: the same
#: columns as float64, recommended for long records).
OUT_SUFFIXES = (".csv", ".csv.gz", ".parquet")
#: Rows per Parquet row group of a streamed conversion [-]: 131072 rows of 7 float64 columns
#: are 7.3 MB held before each group is written.
PARQUET_STREAM_ROWS = 1 << 17


def _sidecar(csv_path: Path) -> Path:
    """``F.csv.gz`` / ``F.csv`` / ``F.parquet`` -> ``F.toml`` beside it."""
    name = csv_path.name
    low = name.lower()
    stem = name[:-7] if low.endswith(".csv.gz") else name[:-8] if low.endswith(".parquet") else name[:-4]
    return csv_path.with_name(stem + ".toml")


def _streams(args, opts: dict) -> bool:
    """True when the bag is converted in chunks: one topic, no --repair, --retime or
    --extrinsics (those need the whole record)."""
    topic = opts.get("topic")
    return (not args.repair and not opts.get("retime") and opts.get("extrinsics") is None
            and (topic is None or "," not in str(topic)))


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
    opts = bag_options(args)
    if is_bag(args.measurement) and _streams(args, opts):
        return _convert_streamed(args, Path(out or args.out), opts)
    meas = read_measurement(args.measurement, repair=args.repair, gaps=args.gaps, **opts)
    csv_path, toml_path = write_measurement(meas, out or args.out, force=args.force)
    result = {("bag" if is_bag(args.measurement) else "measurement"): str(args.measurement),
              "out": str(csv_path), "sidecar": str(toml_path),
              "n_samples": meas.n_samples, "n_gyros": meas.n_gyros,
              "sample_rate_hz": meas.sample_rate_hz, "duration_s": float(meas.time_s[-1]),
              "axes": meas.layout.axes.tolist(), "description": meas.description,
              "topics": list(meas.topics), "streamed": False, "notes": list(meas.notes)}
    lines = [f"{args.measurement}: {meas.n_samples} samples at {meas.sample_rate_hz:.6g} Hz, "
             f"{meas.n_gyros} gyros", *[f"note: {n}" for n in meas.notes],
             f"wrote {csv_path} and {toml_path}"]
    return result, "\n".join(lines)


class _ChunkWriter:
    """Appends chunks of rows (time_s, gyro1..3, [acc_x..z]) to an open binary file as the
    measurement writer would write them whole: the same header and shortest round-trip
    decimals for CSV (gzip without a name or time), float64 columns (zstd) for Parquet."""

    def __init__(self, fh, low: str):
        self.fh, self.low = fh, low
        self.names: list[str] | None = None
        self._gz: Any = None
        self._pq: Any = None
        self._held: list = []
        self._rows = 0

    def write(self, t, gyro, acc) -> None:
        # deferred: numpy with the command
        import numpy as np
        block = np.column_stack([t, gyro] + ([] if acc is None else [acc]))
        if self.names is None:
            self._start(acc is not None)
        if self.low.endswith(".parquet"):
            self._held.append(block)
            self._rows += block.shape[0]
            if self._rows >= PARQUET_STREAM_ROWS:
                self._flush_parquet()
            return
        row = ",".join(["%r"] * block.shape[1])
        text = "".join(map(lambda r: row % tuple(r) + "\n", block.tolist())).encode("ascii")
        (self._gz or self.fh).write(text)

    def _start(self, with_acc: bool) -> None:
        # deferred: the measurement module (numpy, pandas) loads only when the command runs
        from gyroarray import __version__
        from gyroarray.core import measurement as ms
        self.names = [ms._TIME, "gyro1", "gyro2", "gyro3", *(ms._ACC_NAMES if with_acc else ())]
        if self.low.endswith(".parquet"):
            return
        head = f"# written by gyroarray {__version__}\n{','.join(self.names)}\n".encode("ascii")
        if self.low.endswith(".gz"):
            import gzip  # deferred: only for a .csv.gz
            self._gz = gzip.GzipFile(filename="", mode="wb", fileobj=self.fh, compresslevel=6, mtime=0)
        (self._gz or self.fh).write(head)

    def _flush_parquet(self) -> None:
        # deferred: numpy and pyarrow load only for a Parquet output
        import numpy as np
        import pyarrow as pa
        import pyarrow.parquet as pq
        if not self._held:
            return
        block = np.vstack(self._held)
        table = pa.table({c: np.ascontiguousarray(block[:, j]) for j, c in enumerate(self.names or ())})
        if self._pq is None:
            self._pq = pq.ParquetWriter(self.fh, table.schema, compression="zstd")
        self._pq.write_table(table, row_group_size=block.shape[0])
        self._held, self._rows = [], 0

    def close(self) -> None:
        if self._pq is not None or self._held:
            self._flush_parquet()
            if self._pq is not None:
                self._pq.close()
        if self._gz is not None:
            self._gz.close()


def _convert_streamed(args, out: Path, opts: dict) -> tuple[dict, str]:
    """Convert one topic chunk by chunk (bounded memory), with a progress bar."""
    # deferred: numpy, rosbags, tqdm and the writers load only when the command runs
    import numpy as np
    import tomli_w
    from tqdm import tqdm
    from gyroarray.core import measurement as ms
    from gyroarray.core.bags import BagStream
    from gyroarray.core.outputs import open_staged, write_many
    stream = BagStream(args.measurement, topic=opts.get("topic"), gaps=args.gaps,
                       stamps=opts.get("stamps", "header"))
    toml_path = _sidecar(out)
    show = bool(args.progress) or (hasattr(sys.stderr, "isatty") and sys.stderr.isatty())
    bar = tqdm(total=stream.count, unit="msg", unit_scale=True, desc=f"convert {stream.topic}",
               file=sys.stderr, disable=not show, leave=False, mininterval=0.5)
    fh, staged = open_staged(out)
    n, last = 0, 0.0
    try:
        with fh:
            writer = _ChunkWriter(fh, out.name.lower())
            for t, gyro, acc in stream.chunks():
                writer.write(t, gyro, acc)
                n, last = n + t.size, float(t[-1])
                bar.update(t.size)
            writer.close()
    except BaseException:
        staged.discard()
        raise
    finally:
        bar.close()
        stream.close()
    rate = float(stream.rate_hz or 1.0)
    stub = ms.Measurement(time_s=np.array([0.0, 1.0]), gyro_deg_s=np.zeros((2, 3)),
                          layout=stream.layout, sample_rate_hz=rate,
                          description=stream.description, topics=(stream.topic,))
    sidecar = tomli_w.dumps(ms._sidecar_dict(stub)).encode("utf-8")
    write_many([(out, staged), (toml_path, sidecar)], force=args.force)
    notes = list(stream.notes)
    result = {"bag": str(args.measurement), "out": str(out), "sidecar": str(toml_path),
              "n_samples": n, "n_gyros": 3, "sample_rate_hz": rate, "duration_s": last,
              "axes": stream.layout.axes.tolist(), "description": stream.description,
              "topics": [stream.topic], "streamed": True, "notes": notes}
    lines = [f"{args.measurement}: {n} samples at {rate:.6g} Hz, 3 gyros (streamed)",
             *[f"note: {x}" for x in notes], f"wrote {out} and {toml_path}"]
    return result, "\n".join(lines)


def add_parser(sub) -> None:
    """The ``convert`` subcommand (ROS bag to measurement files)."""
    p = sub.add_parser("convert", help="a ROS bag of sensor_msgs/msg/Imu into a measurement "
                                       "(CSV.GZ or Parquet + TOML), or a measurement CSV into Parquet")
    p.add_argument("measurement", type=Path, metavar="BAG",
                   help="a ROS1 .bag, a ROS2 .db3 or .mcap file (a ROS1-profile MCAP too), or a "
                        "ROS2 bag folder; or a measurement CSV/CSV.GZ (with --out F.parquet), or a "
                        "Parquet measurement")
    p.add_argument("--out", type=Path, required=True, metavar="MEAS.csv.gz",
                   help="the measurement to write (.csv, .csv.gz, or .parquet: recommended for long "
                        "records, which gyroarray allan streams); its .toml sidecar beside it")
    add_bag_options(p)
    p.add_argument("--repair", action="store_true",
                   help="fill short gaps and resample a jittering clock (each listed; reads the "
                        "record whole)")
    p.add_argument("--gaps", action="store_true",
                   help="keep dropped messages as gaps in time_s, nothing interpolated (counted in "
                        "the notes; allan --gaps pools the contiguous parts)")
    p.add_argument("--progress", action="store_true",
                   help="show a progress bar on stderr (default: only when stderr is a terminal)")
    add_force(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_convert)
