"""What the ``gyroarray`` subcommands share: argument types that refuse in one line, the
options every command family takes, output-file checks and strict JSON.

Each command module (:mod:`~gyroarray.cli.design`, :mod:`~gyroarray.cli.allan`,
:mod:`~gyroarray.cli.simulate`, :mod:`~gyroarray.cli.compare`, :mod:`~gyroarray.cli.fdi`)
builds its subparsers from these; :mod:`gyroarray.cli.main` runs them. The file helpers import
:mod:`gyroarray.core.outputs` and :mod:`gyroarray.core.limits` when called: building the parser
(``import gyroarray.cli.main``, ``gyroarray --help``) needs neither.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable
from pathlib import Path
from gyroarray.core.errors import InputError

__all__ = ["EXIT_OK", "EXIT_FAIL", "EXIT_USAGE", "COUNT_CAPS", "finite_float", "float_in", "count",
           "check_count", "bounded_int", "positive_int", "nonneg_int", "json_safe", "output",
           "check_plot", "measurement_inputs", "write_json", "add_plugin", "add_force",
           "add_bag_options", "bag_options"]

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2

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


def finite_float(name: str) -> Callable[[str], float]:
    """An argparse type: a finite number, refused in one line naming the argument."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{name} must be finite, got {text!r}")
        return value
    return parse


def float_in(name: str, lo: float = -math.inf, hi: float = math.inf, *, lo_open: bool = False,
             unit: str = "") -> Callable[[str], float]:
    """An argparse type: a finite number in [lo, hi] (``(lo`` when ``lo_open``), refused in one
    line naming the argument and the range."""
    finite = finite_float(name)
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


def positive_int(name: str) -> Callable[[str], int]:
    """An argparse type: a whole number >= 1."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a whole number, got {text!r}") from None
        if value < 1:
            raise argparse.ArgumentTypeError(f"{name} must be >= 1, got {value}")
        return value
    return parse


def nonneg_int(name: str) -> Callable[[str], int]:
    """An argparse type: a whole number in [0, 2^63) (a seed)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a whole number, got {text!r}") from None
        if not 0 <= value < 2 ** 63:
            raise argparse.ArgumentTypeError(f"{name} must be in [0, 2^63), got {value}")
        return value
    return parse


def bounded_int(name: str, lo: int, hi: int) -> Callable[[str], int]:
    """An argparse type: a whole number from ``lo`` to ``hi``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} must be a whole number, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"{name} must be from {lo} to {hi}, got {value}")
        return value
    return parse


def count(name: str) -> Callable[[str], int]:
    """A whole number from 1 to the cap of ``name`` in :data:`COUNT_CAPS`, refused at parse
    time (before any file is read) with the reason and the way out."""
    cap, why = COUNT_CAPS[name]
    positive = positive_int(name)

    def parse(text: str) -> int:
        value = positive(text)
        if value > cap:
            raise argparse.ArgumentTypeError(f"{name} {value} is more than {cap}, the most "
                                             f"gyroarray runs ({why}); give {name} {cap} or less")
        return value
    return parse


def check_count(name: str, value: int, bytes_per: float, what: str) -> None:
    """Refuse a count whose memory (``value`` x ``bytes_per`` [bytes]) passes the budget,
    before the work (:func:`gyroarray.core.limits.check_memory`)."""
    from gyroarray.core.limits import check_memory  # deferred: not needed to build the parser
    check_memory(value * float(bytes_per), f"{name} {value} ({what})", f"lower {name}")


def json_safe(obj):
    """Replace non-finite floats by None so the output is strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def output(path, args, what: str, *, inputs=(), suffixes=None):
    """Check an output file the user named, before any work (:mod:`gyroarray.core.outputs`)."""
    # deferred: core.outputs (tempfile, shutil) is not needed to build the parser
    from gyroarray.core.outputs import check_output
    if path is None:
        return None
    return check_output(path, inputs=inputs, force=getattr(args, "force", False), what=what,
                        suffixes=suffixes)


def check_plot(args, *, inputs=()) -> None:
    """Check ``--plot`` (a .png, .svg or .pdf the command will write), before any work."""
    from gyroarray.core.outputs import PLOT_SUFFIXES  # deferred: not needed to build the parser
    output(args.plot, args, "--plot", inputs=inputs, suffixes=PLOT_SUFFIXES)


def measurement_inputs(args) -> list:
    """The files of a command's measurement and model arguments."""
    from gyroarray.core.outputs import measurement_files  # deferred: not needed to build the parser
    files = measurement_files(args.measurement) if getattr(args, "measurement", None) else []
    for more in getattr(args, "more", None) or ():       # fit's further records of the array
        files += measurement_files(more)
    if getattr(args, "model", None) is not None:
        files.append(args.model)
    if getattr(args, "extrinsics", None) is not None:
        files.append(args.extrinsics)
    return files


def add_bag_options(p):
    """``--topic T[,T2,...]``, ``--extrinsics FILE.yaml``, ``--stamps header|receive`` and
    ``--retime``: how a ROS bag measurement is read (:mod:`gyroarray.core.bags`); pass them on
    with :func:`bag_options`."""
    p.add_argument("--topic", metavar="T[,T2,...]",
                   help="a ROS bag's sensor_msgs/msg/Imu topic (default: its only one); several, "
                        "comma separated, make an array of 3 gyros per IMU")
    p.add_argument("--extrinsics", type=Path, metavar="FILE.yaml",
                   help="a ROS bag's IMU extrinsics, Kalibr imu-chain YAML (imu0: T_i_b: 4x4, "
                        "body to IMU); default: each IMU's axes taken as the body frame's")
    p.add_argument("--stamps", choices=("header", "receive"), default=None,
                   help="a ROS bag's time stamps: the messages' header.stamp (default) or the bag's "
                        "receive (log) times; the notes say which")
    p.add_argument("--retime", action="store_true",
                   help="a ROS bag's bunched or repeated stamps re-timed onto a uniform grid at the "
                        "mean step from the first stamp (default: refused, naming the message)")


def bag_options(args) -> dict:
    """The keyword arguments of ``read_measurement`` for the ``--topic``, ``--extrinsics``,
    ``--stamps`` and ``--retime`` the user gave (none when none: a CSV is read exactly as
    before)."""
    out = {name: getattr(args, name) for name in ("topic", "extrinsics", "stamps")
           if getattr(args, name, None) is not None}
    if getattr(args, "retime", False):
        out["retime"] = True
    return out


def write_json(path: Path, obj: dict, args) -> None:
    """The result as JSON at ``path``, atomically (checked before the work with :func:`output`)."""
    from gyroarray.core.outputs import write_text  # deferred: not needed to build the parser
    write_text(path, json.dumps(json_safe(obj), indent=1, allow_nan=False), force=args.force)


def add_plugin(p):
    """``--plugin PATH.py`` (repeatable)."""
    p.add_argument("--plugin", action="append", type=Path, metavar="PATH.py",
                   help="load the effects and estimators defined in this Python file (repeatable), "
                        "once they pass the conformance checks; the only way user code runs: "
                        "scenario, model and measurement files are never executed")


def add_force(p):
    """``--force``: replace output files that exist."""
    p.add_argument("--force", action="store_true",
                   help="replace output files that exist (never an input of the command)")


def stream_reason(args) -> str | None:
    """Why a command (``allan``, ``fuse``) streams this record (``--stream``, or its reading estimated above
    :data:`~gyroarray.core.limits.STREAM_BUDGET_BYTES` or the memory budget), or None."""
    # deferred: the measurement module (numpy, pandas) loads only when the command runs
    from gyroarray.core.bags import is_bag
    from gyroarray.core.limits import STREAM_BUDGET_BYTES, format_size, max_memory
    from gyroarray.core.measurement import read_bytes_estimate
    if is_bag(args.measurement):
        if args.stream:
            raise InputError("--stream reads a measurement file (CSV, CSV.GZ or Parquet), not a bag: "
                             "gyroarray convert BAG --out F.parquet first", file=str(args.measurement))
        return None
    if args.stream:
        return "--stream"
    need = read_bytes_estimate(args.measurement)
    budget = min(STREAM_BUDGET_BYTES, max_memory())
    if need is None or need <= budget:
        return None
    return (f"reading it whole would need about {format_size(need)}, more than the streaming "
            f"threshold of {format_size(budget)} (STREAM_BUDGET_BYTES or --max-memory, the lower)")
