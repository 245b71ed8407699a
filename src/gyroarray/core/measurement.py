"""Measurement files: one recorded (or simulated) run of a gyro array.

A measurement is a CSV of samples plus a TOML sidecar with the same stem
(``shared/spec/measurement-format.md`` is the contract)::

    run42.csv      (or run42.csv.gz)   time_s, gyro1..gyroN, [ref_x, ref_y, ref_z], [temp_c],
                                       [acc_x, acc_y, acc_z]
    run42.toml                         sample_rate_hz, description, [topics], [layout], [site],
                                       [units]

:func:`read_measurement` turns such a pair into a :class:`Measurement`, the
one in-memory type used everywhere; :func:`write_measurement` writes one back
so that reading it again reproduces every value exactly.

Reading rules (where the spec leaves a choice, the choice made here)
--------------------------------------------------------------------
* Paths: the CSV (``run42.csv`` or ``run42.csv.gz``), the sidecar
  (``run42.toml``) or the bare stem (``run42``) are accepted; for the last
  two exactly one of ``run42.csv`` / ``run42.csv.gz`` must exist.
* Text: UTF-8 (a leading byte-order mark is skipped, with a note); lines end
  in ``\\n`` or ``\\r\\n``, a bare ``\\r`` is refused. ``.gz`` files are
  decompressed first and line numbers count lines of the decompressed text.
* Lines whose first character is ``#`` are comments, anywhere in the file;
  empty lines are skipped too (with a note). Every other line is the header
  (the first one) or one sample. Line numbers in messages are 1-based and
  count every line of the file, comments and header included.
* Cells: standard CSV quoting is understood; spaces around a number are
  tolerated; an empty cell or ``nan`` is a *missing value* (see repair);
  ``inf``, numbers that overflow a double and anything else that is not a
  decimal number are refused. Every row must have as many fields as the
  header. Extra columns are ignored (with a note) but still counted.
* Samples: at least :data:`MIN_SAMPLES`; ``time_s`` strictly increasing.
  The nominal period is the median step of ``time_s``; a step longer than
  :data:`GAP_FACTOR` periods is a gap of ``round(step / period) - 1``
  missing samples.
* Repair (``repair=True``): gaps of 1..:data:`MAX_REPAIR_SAMPLES` missing
  samples get rows inserted at evenly spaced times, and runs of at most
  :data:`MAX_REPAIR_SAMPLES` missing values in a data column (not touching
  the first or last sample) are filled, both by linear interpolation in
  time; each repair is reported in :attr:`Measurement.notes`. Without
  ``repair`` both are refused; longer gaps or runs, missing values at the
  start or end, and missing times are refused either way.
* ``acc_x``, ``acc_y``, ``acc_z`` (specific force at the platform origin,
  platform frame, m/s²) come as a set of three or not at all, like
  ``ref_*``; their cells follow the same rules as every other column.
* Sidecar: ``sample_rate_hz`` (> 0) and ``[layout]`` are required;
  ``layout.axes`` wins over ``scheme``/``n_gyros``/``alpha_deg`` (with a
  note). Optional ``layout.positions_m``: one [x, y, z] row per gyro,
  finite, metres (within ``layout.MAX_POSITION_M`` of the origin). Optional ``[site]`` needs ``latitude_deg`` in [-90, 90] and
  ``heading_deg``. Optional ``[units]`` declares non-default units (keys
  ``time``, ``gyro``, ``ref``, ``temp``, ``acc``, see :data:`ACCEPTED_UNITS`);
  values are converted to the canonical file units (s, deg/s, degC, m/s²)
  with a note.
  Optional ``topics``: the ROS bag topics the record was converted from (``gyroarray
  convert`` writes them), an array of non-empty strings, at most one per gyro.
  Unknown top-level keys are noted; unknown keys inside ``[layout]``,
  ``[site]`` and ``[units]`` are refused, since every key there changes how
  the samples are interpreted (a misspelt ``gyro`` unit must not pass).
* Every problem is an :class:`~gyroarray.core.errors.InputError` naming the file,
  the line and/or column (a CSV column name, a 1-based character column or a
  TOML key) and what is wrong. Nothing is ever written by the reader.

Speed: the well-formed case is parsed by pandas' C reader (exact
round-trip float parsing) after the line structure (comments, blank lines,
field counts) has been checked with numpy: about 0.5-1 s for 1e6 rows × 7
columns, gzip included. When pandas refuses a cell, the rows are parsed
again in chunks and only the refused chunk goes through the exact
:mod:`csv` path that locates the problem. Files with quote characters in
the data take the :mod:`csv` path throughout (about 10 s per 7e6 cells).
At most ``_MAX_NOTES`` repairs of each kind are listed in ``notes``, then
counted.
"""

from __future__ import annotations

import csv
import gzip
import io
import math
import os
import re
import warnings
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Callable, Iterator, Mapping

import numpy as np
import pandas as pd
import tomli_w

from gyroarray import __version__
from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.layout import MAX_GYROS, UNIT_NORM_TOL, Layout, check_positions
from gyroarray.core.limits import (MAX_LINE_BYTES, MAX_RATE_DEG_S, check_memory, format_size, gunzip_bounded,
                              max_memory, open_regular, read_line_bounded, read_regular)
from gyroarray.core.outputs import measurement_files, same_path, write_bytes
from gyroarray.core.tomlio import (TomlDoc, finite_number, is_number, load_toml, short_repr, toml_number,
                                   toml_table, toml_type, utf8_text)

__all__ = [
    "Measurement",
    "Site",
    "read_measurement",
    "constant_gyros",
    "without_gyros",
    "relative_time_s",
    "MIN_SPREAD_DEG_S",
    "write_measurement",
    "MIN_SAMPLES",
    "MAX_REPAIR_SAMPLES",
    "GAP_FACTOR",
    "MAX_CONE_GYROS",
    "RATE_NOTE_TOL",
    "ACCEPTED_UNITS",
    "PARQUET_SUFFIX",
    "PARQUET_ROW_GROUP",
    "is_parquet",
    "parquet_bytes",
    "RecordHead",
    "record_head",
    "iter_record",
    "read_bytes_estimate",
    "parquet_batches",
    "read_window",
    "MAX_COLUMNS",
    "MAX_EXTRA_COLUMNS",
    "MAX_HEADER_BYTES",
    "MAX_PARQUET_FOOTER_BYTES",
]

#: Fewest samples a measurement may have (a time step needs two).
MIN_SAMPLES = 2
#: Longest gap [samples] or run of missing values [samples] that ``repair``
#: fills; longer ones are refused even with ``repair=True``.
MAX_REPAIR_SAMPLES = 5
#: Largest ``n_gyros`` of a conical layout in a sidecar (a sanity bound).
MAX_CONE_GYROS = 1024
#: A time step longer than this many nominal periods [-] is a gap.
GAP_FACTOR = 1.5
#: Relative disagreement [-] between ``sample_rate_hz`` and the rate given by
#: ``time_s`` above which a note is added (``time_s`` is the truth).
RATE_NOTE_TOL = 0.01
#: Milliseconds per second, for ``[units] time = "ms"``.
MS_PER_S = 1000.0

_TIME, _REF_NAMES, _TEMP = "time_s", ("ref_x", "ref_y", "ref_z"), "temp_c"
_ACC_NAMES = ("acc_x", "acc_y", "acc_z")
_GYRO_RE = re.compile(r"gyro(\d+)", re.ASCII)
_NUMBER_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_NAN_WORDS = frozenset({"nan", "+nan", "-nan"})
_INF_WORDS = frozenset({"inf", "+inf", "-inf", "infinity", "+infinity", "-infinity"})
#: Cells pandas may turn into NaN on the fast path (the slow path knows more
#: spellings; both agree on what is missing).
_PANDAS_NA = ["", "nan", "NaN", "NAN"]
_GZIP_MAGIC = b"\x1f\x8b"
_BOM = b"\xef\xbb\xbf"
_CSV_CHUNK_ROWS = 65536
_LOCATE_CHUNK_ROWS = 16384
_MAX_NOTES = 10          # per kind of repair; the rest are counted
#: Extra columns (beyond the spec's) a measurement may have [-]: allowed, and ignored with a note.
MAX_EXTRA_COLUMNS = 256
#: Most columns a measurement may have [-]: ``time_s``, at most ``layout.MAX_GYROS`` gyros, the
#: spec's seven optional columns (``ref_x..z``, ``acc_x..z``, ``temp_c``) and at most
#: :data:`MAX_EXTRA_COLUMNS` extra ones. A CSV header or a Parquet schema with more is refused
#: before its names are matched or any sample is read (a Parquet file of 20,000 columns took
#: 267 s of CPU before its refusal).
MAX_COLUMNS = 1 + MAX_GYROS + 7 + MAX_EXTRA_COLUMNS
#: Longest line read before the samples [bytes]: the header and the comment or blank lines
#: before it (:func:`gyroarray.core.limits.read_line_bounded`); :data:`_MAX_HEAD_BYTES` in all.
MAX_HEADER_BYTES = MAX_LINE_BYTES
_MAX_HEAD_BYTES = 16 * MAX_HEADER_BYTES
# pandas >= 3.1 parses floats exactly by default and deprecates the option.
_EXACT_FLOATS = ({} if tuple(int(p) for p in pd.__version__.split(".")[:2]) >= (3, 1)
                 else {"float_precision": "round_trip"})


def _ms_to_s(x):
    """Time [ms] -> [s]."""
    return x / MS_PER_S


def _deg_h_to_deg_s(x):
    """Rate [deg/h] -> [deg/s]."""
    return x / units.S_PER_H


_RATE_UNITS = MappingProxyType(
    {"deg/s": None, "rad/s": units.rad_s_to_deg_s, "deg/h": _deg_h_to_deg_s})
#: Units a sidecar's ``[units]`` table may declare, per key, each with its
#: converter to the canonical file unit (None: already canonical). Read-only.
ACCEPTED_UNITS: Mapping[str, Mapping[str, Callable | None]] = MappingProxyType({
    "time": MappingProxyType({"s": None, "ms": _ms_to_s}),
    "gyro": _RATE_UNITS,
    "ref": _RATE_UNITS,
    "temp": MappingProxyType({"degC": None, "C": None, "°C": None}),
    "acc": MappingProxyType({"m/s2": None, "m/s^2": None, "m/s²": None, "g": units.g_to_m_s2}),
})
_CANONICAL_UNIT = {"time": "s", "gyro": "deg/s", "ref": "deg/s", "temp": "degC", "acc": "m/s2"}


# =========================================================================
# The in-memory types
# =========================================================================
@dataclass(frozen=True)
class Site:
    """Where the rate table stands.

    Parameters
    ----------
    latitude_rad : float
        Geodetic latitude [rad], in [-π/2, π/2].
    heading_rad : float
        Heading of the platform x axis from true north at t = 0, turning
        about up [rad].
    """

    latitude_rad: float
    heading_rad: float

    def __post_init__(self):
        lat, heading = float(self.latitude_rad), float(self.heading_rad)
        if not (math.isfinite(heading) and abs(lat) <= math.pi / 2):
            raise ValueError(f"invalid site: latitude {lat!r} rad, heading {heading!r} rad")
        object.__setattr__(self, "latitude_rad", lat)
        object.__setattr__(self, "heading_rad", heading)


@dataclass(frozen=True, eq=False)
class Measurement:
    """One run of a gyro array, in the units of the measurement file.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Sample times [s], strictly increasing.
    gyro_deg_s : ndarray, shape (n, N)
        Output of each gyro along its sensitive axis [deg/s]; column k-1 is
        gyro k, in the order of ``layout.axes``.
    layout : Layout
        Sensitive axes of the N gyros.
    sample_rate_hz : float
        Nominal sample rate [Hz] from the sidecar (``time_s`` is the truth).
    ref_deg_s : ndarray, shape (n, 3), optional
        Reference angular rate of the platform in the body frame, relative
        to the Earth [deg/s]; None when the file has no ``ref_*`` columns.
    temp_c : ndarray, shape (n,), optional
        Temperature at the array [°C]; None when absent.
    site : Site, optional
        Where the table stands; None when the sidecar has no ``[site]``.
    description : str
        Free text from the sidecar.
    source : str, optional
        Path of the CSV as the user named it; None for data not read from a
        file.
    notes : tuple of str
        What the reader noticed and reported (ignored columns and keys, unit
        conversions, repairs, sample-rate disagreement).
    acc_m_s2 : ndarray, shape (n, 3), optional
        Specific force at the platform origin, platform frame [m/s²]
        (``acc_x``, ``acc_y``, ``acc_z``; +g0 on z at rest, level, z up);
        None when the file has no ``acc_*`` columns.
    topics : tuple of str
        The ROS bag topics the record came from (``("/imu0",)``), in the order of the gyros:
        read from a bag, or from a converted record's sidecar (``topics``); ``()`` when unknown.

    Notes
    -----
    All arrays are float64 copies, stored read-only, all finite. Shapes,
    finiteness, strictly increasing time and unit layout axes are checked on
    construction; a violation is a programming error (``ValueError``), since
    user files are checked by :func:`read_measurement` first.
    """

    time_s: np.ndarray
    gyro_deg_s: np.ndarray
    layout: Layout
    sample_rate_hz: float
    ref_deg_s: np.ndarray | None = None
    temp_c: np.ndarray | None = None
    site: Site | None = None
    description: str = ""
    source: str | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)
    acc_m_s2: np.ndarray | None = None
    topics: tuple[str, ...] = ()

    def __post_init__(self):
        time = _frozen_array(self.time_s, "time_s", ndim=1)
        n = time.shape[0]
        if n < MIN_SAMPLES or not np.all(np.diff(time) > 0):
            raise ValueError(f"time_s needs >= {MIN_SAMPLES} strictly increasing samples")
        if not isinstance(self.layout, Layout):
            raise ValueError(f"layout must be a Layout, got {type(self.layout).__name__}")
        norms = np.linalg.norm(self.layout.axes, axis=1)
        if np.any(np.abs(norms - 1.0) > UNIT_NORM_TOL):
            raise ValueError("layout axes must be unit vectors")
        object.__setattr__(self, "time_s", time)
        object.__setattr__(self, "gyro_deg_s", _frozen_array(
            self.gyro_deg_s, "gyro_deg_s", ndim=2, shape=(n, self.layout.n_gyros)))
        if self.ref_deg_s is not None:
            object.__setattr__(self, "ref_deg_s", _frozen_array(
                self.ref_deg_s, "ref_deg_s", ndim=2, shape=(n, 3)))
        if self.temp_c is not None:
            object.__setattr__(self, "temp_c", _frozen_array(
                self.temp_c, "temp_c", ndim=1, shape=(n,)))
        if self.acc_m_s2 is not None:
            object.__setattr__(self, "acc_m_s2", _frozen_array(
                self.acc_m_s2, "acc_m_s2", ndim=2, shape=(n, 3)))
        rate = float(self.sample_rate_hz)
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"sample_rate_hz must be finite and > 0, got {rate!r}")
        object.__setattr__(self, "sample_rate_hz", rate)
        if self.site is not None and not isinstance(self.site, Site):
            raise ValueError(f"site must be a Site or None, got {type(self.site).__name__}")
        if not isinstance(self.description, str):
            raise ValueError("description must be a str")
        object.__setattr__(self, "source", None if self.source is None else str(self.source))
        object.__setattr__(self, "notes", tuple(str(s) for s in self.notes))
        object.__setattr__(self, "topics", tuple(str(t) for t in self.topics))

    # -- SI views -----------------------------------------------------------
    @property
    def gyro_rad_s(self) -> np.ndarray:
        """Gyro outputs [rad/s], shape (n, N) (a new array on each access)."""
        return units.deg_s_to_rad_s(self.gyro_deg_s)

    @property
    def ref_rad_s(self) -> np.ndarray | None:
        """Reference rate [rad/s], shape (n, 3), or None without reference."""
        return None if self.ref_deg_s is None else units.deg_s_to_rad_s(self.ref_deg_s)

    @property
    def dt_s(self) -> float:
        """Sample period [s]: the median step of ``time_s``.

        When the median agrees with the sidecar's nominal period
        1/``sample_rate_hz`` to 1e-6 relative, the nominal value is returned,
        free of the rounding of the printed times (0.0100 − 0.0000 style
        differences are not exactly 0.01 in binary); time_s stays the truth
        whenever the two disagree.
        """
        median = float(np.median(np.diff(self.time_s)))
        nominal = 1.0 / self.sample_rate_hz
        return nominal if abs(median - nominal) <= 1e-6 * nominal else median

    @property
    def n_samples(self) -> int:
        """Number of samples n."""
        return int(self.time_s.shape[0])

    @property
    def n_gyros(self) -> int:
        """Number of gyros N."""
        return int(self.gyro_deg_s.shape[1])

    @property
    def has_reference(self) -> bool:
        """True when the table's reference rate ``ref_deg_s`` is present."""
        return self.ref_deg_s is not None

    @property
    def has_acc(self) -> bool:
        """True when the specific force at the origin ``acc_m_s2`` is present."""
        return self.acc_m_s2 is not None

    def __repr__(self) -> str:
        return (f"Measurement(n_samples={self.n_samples}, n_gyros={self.n_gyros}, "
                f"sample_rate_hz={self.sample_rate_hz!r}, layout={self.layout!r}, "
                f"has_reference={self.has_reference}, source={self.source!r})")


def _frozen_array(x, name: str, *, ndim: int, shape: tuple | None = None) -> np.ndarray:
    """A read-only finite float64 copy of ``x``, checked against ndim/shape."""
    a = np.array(x, dtype=np.float64, copy=True, order="C")
    if a.ndim != ndim or (shape is not None and a.shape != shape):
        raise ValueError(f"{name} must have shape {shape or ('?',) * ndim}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains a non-finite value")
    a.setflags(write=False)
    return a


# =========================================================================
# Reading
# =========================================================================
def read_measurement(path, *, repair: bool = False, topic: str | None = None,
                     extrinsics=None, gaps: bool = False, stamps: str | None = None,
                     retime: bool = False) -> Measurement:
    """Read a measurement (CSV + TOML sidecar, or a ROS bag) and check it.

    Parameters
    ----------
    path : str or os.PathLike
        The CSV (``run42.csv`` / ``run42.csv.gz``), its sidecar
        (``run42.toml``) or the stem (``run42``); or a ROS bag of
        ``sensor_msgs/msg/Imu`` (``.bag``, ``.db3``, ``.mcap`` or a ROS2 bag
        folder), read by :func:`gyroarray.core.bags.read_bag`.
    repair : bool
        Fill short gaps and short runs of missing values by linear
        interpolation in time, and report each repair in ``notes``
        (default: refuse them).
    topic : str, optional
        A bag's IMU topic(s), comma separated (bags only).
    extrinsics : str or os.PathLike, optional
        Kalibr imu-chain YAML of a bag's IMUs (bags only).
    gaps : bool
        Keep gaps in ``time_s`` (dropped samples, steps longer than :data:`GAP_FACTOR`
        periods) as they are, nothing interpolated, with a note counting them (default:
        refuse them, or fill short ones with ``repair``). For analyses that pool the
        contiguous parts (``gyroarray allan --gaps``); CSVs, Parquet and bags (a bag's dropped
        messages, :func:`gyroarray.core.bags.read_bag`).
    stamps : {"header", "receive"}, optional
        A bag's time stamps: the messages' ``header.stamp`` (default) or the bag's receive
        (log) times (bags only).
    retime : bool
        Re-time a bag's bunched or repeated stamps onto a uniform grid (bags only; the rule in
        :func:`gyroarray.core.bags.read_bag`).

    Returns
    -------
    Measurement
        Values in the file's canonical units (s, deg/s, degC).

    Raises
    ------
    InputError
        For anything wrong with the files, naming the file, the line and/or
        column and the problem (see the module docstring for the rules).
    """
    # deferred: core.bags imports this module (Measurement), so it cannot be imported at the top
    from gyroarray.core.bags import is_bag, read_bag
    if is_bag(path):
        return read_bag(path, topic=topic, extrinsics=extrinsics, repair=repair, gaps=gaps,
                        stamps=stamps or "header", retime=retime)
    for option, value in (("--topic", topic), ("--extrinsics", extrinsics), ("--stamps", stamps),
                          ("--retime", retime or None)):
        if value is not None:
            raise InputError(f"{option} is for ROS bags (.bag, .db3, .mcap or a ROS2 bag folder); "
                             "this is a measurement CSV: leave it out", file=str(path))
    csv_path, toml_path = _measurement_paths(path)
    csv_name = str(csv_path)
    side = _read_sidecar(toml_path)
    if is_parquet(csv_path):
        return _read_parquet_measurement(csv_path, side, repair, gaps)
    _check_csv_head(csv_path, csv_name)               # the header's length, before the file is read
    data, notes = _read_csv_bytes(csv_path)
    cols, table, line_notes = _parse_csv(data, csv_name)
    _check_gyro_count(cols, side, csv_name, table.header_line)
    values, repair_notes = _checked_values(table, cols, csv_name, repair,
                                           _nominal_period(side, cols), side.units, keep_gaps=gaps)
    values, unit_notes = _to_canonical(values, cols, side.units, side.name, csv_name)
    rate_note = _rate_note(values[:, 0], side)
    all_notes = (*notes, *line_notes, *side.notes, *unit_notes, *repair_notes, *rate_note)
    return _build(values, cols, side, csv_name, all_notes)


#: A gyro whose output spans less than this [deg/s] is constant: no gyro
#: resolves 3.6e-9 deg/h, so such a column is a dead, stuck or zeroed channel
#: (also one of subnormal numbers).
MIN_SPREAD_DEG_S = 1e-12


def constant_gyros(m: Measurement) -> list[int]:
    """The gyros (1-based) whose output is constant (dead or stuck).

    A column is constant when its spread (max − min) is below
    :data:`MIN_SPREAD_DEG_S`. Such a gyro carries no noise to analyse: the
    analyses report it and go on with the others.
    """
    spread = np.ptp(m.gyro_deg_s, axis=0)
    return [k + 1 for k in np.flatnonzero(spread < MIN_SPREAD_DEG_S).tolist()]


def constant_note(gyros: list[int], m: Measurement) -> str:
    """``gyro 2 is constant (dead or stuck?): ...`` for the notes and refusals."""
    values = ", ".join(f"{float(m.gyro_deg_s[0, k - 1]):.6g} deg/s" for k in gyros)
    which = (f"gyro {gyros[0]} is" if len(gyros) == 1 else
             "gyros " + ", ".join(map(str, gyros)) + " are")
    return f"{which} constant (dead or stuck?) at {values}"


def without_gyros(m: Measurement, gyros: list[int], note: str = "") -> Measurement:
    """The measurement without the given gyros (1-based), the note added.

    The remaining gyros keep their order and are numbered 1..N' in the
    result (the note should say how the numbers map).
    """
    keep = [k for k in range(m.n_gyros) if k + 1 not in set(gyros)]
    if not keep:
        raise InputError("no gyro left to analyse", file=m.source)
    layout = Layout.from_axes(m.layout.axes[keep], source=m.source)
    # one topic per gyro follows its gyro; fewer topics (one IMU topic for a triad) stay whole
    topics = tuple(m.topics[k] for k in keep) if len(m.topics) == m.n_gyros else m.topics
    return Measurement(time_s=m.time_s, gyro_deg_s=m.gyro_deg_s[:, keep], layout=layout,
                       sample_rate_hz=m.sample_rate_hz, ref_deg_s=m.ref_deg_s, temp_c=m.temp_c,
                       site=m.site, description=m.description, source=m.source,
                       notes=(*m.notes, *([note] if note else [])), acc_m_s2=m.acc_m_s2,
                       topics=topics)


def relative_time_s(m: Measurement) -> np.ndarray:
    """``time_s − time_s[0]`` [s]: the clock every analysis works on.

    Unix-epoch stamps (1.7e9 s) resolve only 2.4e-7 s in a double; a clock
    built at the epoch (``t0 + k·dt``) is not uniform to the analyses'
    tolerance, while the differences to the first stamp are exact.
    """
    return m.time_s - m.time_s[0]


# -- paths ------------------------------------------------------------------
def _measurement_paths(path) -> tuple[Path, Path]:
    """(CSV path, sidecar path) for a CSV, sidecar or stem path."""
    p = Path(path)
    low = p.name.lower()
    if low.endswith(".csv") or low.endswith(".csv.gz") or low.endswith(PARQUET_SUFFIX):
        if not p.is_file():
            raise InputError("measurement file not found" if not p.exists()
                             else "not a regular file", file=str(p))
        return p, _sidecar_of(p)
    stem = p.with_name(p.name[:-5]) if low.endswith(".toml") else p
    found = [c for c in (stem.with_name(stem.name + ".csv"),
                         stem.with_name(stem.name + ".csv.gz"),
                         stem.with_name(stem.name + PARQUET_SUFFIX)) if c.is_file()]
    if len(found) != 1:
        what = "no measurement CSV" if not found else "two measurement CSVs"
        raise InputError(f"{what} for this stem: looked for {stem.name}.csv and "
                         f"{stem.name}.csv.gz (and {stem.name}{PARQUET_SUFFIX}; give the CSV "
                         "path)", file=str(path))
    return found[0], _sidecar_of(found[0])


def _sidecar_of(csv_path: Path) -> Path:
    """``<stem>.toml`` beside a ``<stem>.csv`` or ``<stem>.csv.gz``."""
    name = csv_path.name
    low = name.lower()
    stem = (name[:-7] if low.endswith(".csv.gz") else
            name[:-len(PARQUET_SUFFIX)] if low.endswith(PARQUET_SUFFIX) else name[:-4])
    return csv_path.with_name(stem + ".toml")


def _read_bytes(path: Path, what: str) -> bytes:
    """A regular file's bytes (FIFOs, devices and folders refused), within the memory budget."""
    return read_regular(path, what)


# -- the sidecar ------------------------------------------------------------
@dataclass(frozen=True)
class _Sidecar:
    name: str
    sample_rate_hz: float
    description: str
    layout: Layout
    site: Site | None
    units: dict
    notes: tuple[str, ...]
    topics: tuple[str, ...] = ()


#: Longest topic name a sidecar's ``topics`` may hold [characters] (a sanity bound: ROS names are
#: short; a longer string is not a topic).
MAX_TOPIC_CHARS = 1024


def _parse_topics(doc: TomlDoc, n_gyros: int) -> tuple[str, ...]:
    """The sidecar's ``topics`` (the bag topics a converted record came from), checked: an array of
    at most ``n_gyros`` non-empty strings of at most :data:`MAX_TOPIC_CHARS` characters, without
    control characters; ``()`` when the key is absent."""
    if "topics" not in doc.data:
        return ()
    topics = doc.data["topics"]
    if not isinstance(topics, list):
        raise doc.error(f"topics must be an array of strings (the ROS bag topics, e.g. [\"/imu0\"]), "
                        f"got {toml_type(topics)}", "topics")
    if len(topics) > n_gyros:
        raise doc.error(f"topics names {len(topics)} topics for {n_gyros} gyro(s); each topic gives at "
                        "least one gyro", "topics")
    for k, t in enumerate(topics):
        key = f"topics[{k}]"
        if not isinstance(t, str):
            raise doc.error(f"{key} must be a string (a ROS topic name), got {toml_type(t)}", key)
        if not t or len(t) > MAX_TOPIC_CHARS or any(ord(c) < 32 or ord(c) == 127 for c in t):
            raise doc.error(f"{key} must be a non-empty topic name of at most {MAX_TOPIC_CHARS} "
                            f"characters without control characters, got {short_repr(t)}", key)
    return tuple(topics)


def _load_toml(path: Path, what: str = "sidecar") -> TomlDoc:
    if what == "sidecar" and not path.exists() and not path.is_symlink():
        raise InputError("missing sidecar: every measurement CSV needs a .toml with the "
                         "same stem beside it (sample_rate_hz, [layout])", file=str(path))
    return load_toml(path, what)


def _read_sidecar(path: Path) -> _Sidecar:
    doc = _load_toml(path)
    d = doc.data
    known = {"sample_rate_hz", "description", "layout", "site", "units", "fused", "topics"}   # fused: gyroarray fuse's provenance
    unknown = sorted(set(d) - known)
    notes = [f"{doc.name}: ignored unknown key(s) {', '.join(unknown)}"] if unknown else []
    if "sample_rate_hz" not in d:
        raise doc.error("sample_rate_hz is missing (the nominal sample rate [Hz] is "
                        "required)", "sample_rate_hz")
    rate = toml_number(doc, d["sample_rate_hz"], "sample_rate_hz")
    if rate <= 0:
        raise doc.error(f"sample_rate_hz must be > 0, got {rate!r}", "sample_rate_hz")
    description = d.get("description", "")
    if not isinstance(description, str):
        raise doc.error(f"description must be a string, got {toml_type(description)}",
                        "description")
    layout, layout_notes = parse_layout(doc)
    return _Sidecar(name=doc.name, sample_rate_hz=rate, description=description,
                    layout=layout, site=parse_site(doc), units=_parse_units(doc),
                    notes=tuple(notes + layout_notes), topics=_parse_topics(doc, layout.n_gyros))


_CONE_KEYS = ("scheme", "n_gyros", "alpha_deg")


def parse_layout(doc: TomlDoc) -> tuple[Layout, list[str]]:
    t = toml_table(doc, "layout", {"axes", "positions_m", *_CONE_KEYS})
    if t is None:
        raise doc.error("[layout] is missing (give axes, or scheme, n_gyros and alpha_deg)",
                        "layout")
    if "axes" in t:
        ignored = [k for k in _CONE_KEYS if k in t]
        notes = ([f"{doc.name}: layout.axes given, so {', '.join(ignored)} ignored "
                  "(explicit axes win)"] if ignored else [])
        return _with_positions(doc, t, _axes_layout(doc, t["axes"])), notes
    missing = [k for k in _CONE_KEYS if k not in t]
    if missing:
        raise doc.error("layout is incomplete: give axes, or all of scheme, n_gyros and "
                        f"alpha_deg (missing: {', '.join(missing)})", "layout")
    return _with_positions(doc, t, _cone_layout(doc, t)), []


def _with_positions(doc: TomlDoc, t: dict, layout: Layout) -> Layout:
    """``layout`` with ``layout.positions_m`` when the table has it (checked)."""
    if "positions_m" not in t:
        return layout
    rows = t["positions_m"]
    key = "layout.positions_m"
    if not (isinstance(rows, list) and all(
            isinstance(r, list) and len(r) == 3 and all(is_number(x) for x in r) for r in rows)):
        raise doc.error("layout.positions_m must be an array of [x, y, z] rows of numbers "
                        f"(metres, one per gyro), got {short_repr(rows)}", key)
    values = [[finite_number(x) for x in r] for r in rows]
    if any(x is None for r in values for x in r):
        raise doc.error(f"layout.positions_m must hold finite numbers, got {short_repr(rows)}", key)
    try:
        return layout.with_positions(check_positions(values, layout.n_gyros))
    except InputError as e:
        raise doc.error(e.message, key) from None


def _axes_layout(doc: TomlDoc, axes) -> Layout:
    key = "layout.axes"
    rows_ok = isinstance(axes, list) and len(axes) > 0 and all(
        isinstance(r, list) and len(r) == 3 and all(is_number(x) for x in r) for r in axes)
    if not rows_ok:
        raise doc.error("layout.axes must be an array of [x, y, z] rows of numbers, "
                        f"got {short_repr(axes)}", key)
    rows = [[finite_number(x) for x in r] for r in axes]
    if any(x is None for r in rows for x in r):
        raise doc.error(f"layout.axes must hold finite numbers, got {short_repr(axes)}", key)
    try:
        return Layout.from_axes(rows, source=doc.name)
    except InputError as e:
        raise doc.error(e.message, key) from None


def _cone_layout(doc: TomlDoc, t: dict) -> Layout:
    scheme, n = t["scheme"], t["n_gyros"]
    if not (isinstance(scheme, int) and not isinstance(scheme, bool) and scheme in (1, 2)):
        raise doc.error(f"layout.scheme must be 1 or 2, got {toml_type(scheme)}",
                        "layout.scheme")
    if not (isinstance(n, int) and not isinstance(n, bool) and 3 <= n <= MAX_CONE_GYROS):
        raise doc.error(f"layout.n_gyros must be an integer from 3 to {MAX_CONE_GYROS}, "
                        f"got {toml_type(n)}", "layout.n_gyros")
    alpha = toml_number(doc, t["alpha_deg"], "layout.alpha_deg")
    if not 0.0 <= alpha <= 180.0:
        raise doc.error(f"layout.alpha_deg must be in [0, 180] deg, got {alpha!r}",
                        "layout.alpha_deg")
    return Layout.conical(scheme, n, units.deg_to_rad(alpha))


def parse_site(doc: TomlDoc) -> Site | None:
    t = toml_table(doc, "site", {"latitude_deg", "heading_deg"})
    if t is None:
        return None
    for key in ("latitude_deg", "heading_deg"):
        if key not in t:
            raise doc.error(f"site.{key} is missing ([site] needs latitude_deg and "
                            "heading_deg)", "site")
    lat = toml_number(doc, t["latitude_deg"], "site.latitude_deg")
    heading = toml_number(doc, t["heading_deg"], "site.heading_deg")
    if not -90.0 <= lat <= 90.0:
        raise doc.error(f"site.latitude_deg must be in [-90, 90] deg, got {lat!r}",
                        "site.latitude_deg")
    return Site(units.deg_to_rad(lat), units.deg_to_rad(heading))


def _parse_units(doc: TomlDoc) -> dict:
    t = toml_table(doc, "units", set(ACCEPTED_UNITS))
    if t is None:
        return {}
    for key, unit in t.items():
        accepted = ACCEPTED_UNITS[key]
        if not isinstance(unit, str) or unit not in accepted:
            raise doc.error(f"unknown unit {short_repr(unit)} for units.{key} (accepted: "
                            f"{', '.join(repr(u) for u in accepted)})", f"units.{key}")
    return dict(t)


# -- the CSV: bytes and lines -----------------------------------------------
def _read_csv_bytes(path: Path) -> tuple[bytes, list[str]]:
    """The CSV's bytes (decompressed), checked to be UTF-8; and notes."""
    name = str(path)
    raw = _read_bytes(path, "measurement file")
    if name.lower().endswith(".gz"):
        raw = gunzip_bounded(raw, max_memory() // _READ_BYTES_FACTOR, name, cost=_read_cost,
                             max_cost=max_memory())
    elif raw.startswith(_GZIP_MAGIC):
        raise InputError("file is gzip-compressed but its name does not end in .gz",
                         file=name)
    _check_read_memory(raw, name)
    notes = []
    if raw.startswith(_BOM):
        raw = raw[len(_BOM):]
        notes.append(f"{name}: skipped the UTF-8 byte-order mark")
    if not raw.isascii():
        utf8_text(raw, name)
    if b"\r" in raw and raw.count(b"\r") != raw.count(b"\r\n"):
        lone = re.search(rb"\r(?!\n)", raw)
        assert lone is not None                                # more \r than \r\n
        pos = lone.start()
        raise InputError("carriage return (\\r) inside a line: lines must end in \\n or "
                         "\\r\\n", file=name, line=raw.count(b"\n", 0, pos) + 1)
    return raw, notes


#: The decompressed text may take at most this share of the memory budget [-]
#: (the reader holds the text, its line index and the parsed table at once).
_READ_BYTES_FACTOR = 8
#: Peak memory of the reader per byte of text, per line and per comma [bytes]
#: (measured with tracemalloc: 323 MB for 1e6 rows x 5 columns = 106 MB of
#: text, 250 MB for 5e6 blank lines; rounded up).
_MEM_PER_BYTE, _MEM_PER_LINE, _MEM_PER_CELL = 2, 50, 16


def _read_cost(data: bytes) -> int:
    """Estimated peak memory [bytes] of parsing ``data`` (a piece of the CSV text)."""
    return (_MEM_PER_BYTE * len(data) + _MEM_PER_LINE * data.count(b"\n")
            + _MEM_PER_CELL * data.count(b","))


def _check_read_memory(data: bytes, name: str) -> None:
    """Refuse, before the text is indexed, a file whose reading would exceed the budget."""
    lines = data.count(b"\n") + 1
    need = _read_cost(data)
    check_memory(need, f"reading {lines} lines ({format_size(len(data))} of text)",
                 "split the record or keep only the columns needed (gyroarray allan streams a "
                 "record this long: --stream)", file=name)


@dataclass(frozen=True)
class _Lines:
    """Physical lines of the CSV: byte bounds, and which ones hold data."""

    data: bytes
    starts: np.ndarray      # first byte of each line
    ends: np.ndarray        # end of each line's content (before \r\n / \n)
    stops: np.ndarray       # first byte after each line's terminator
    header: int             # index of the header line
    rows: np.ndarray        # indices of the data lines, in order

    def text(self, i: int) -> str:
        return self.data[self.starts[i]:self.ends[i]].decode("utf-8")


def _scan_lines(data: bytes, name: str) -> tuple[_Lines, list[str]]:
    """Find comment, blank, header and data lines (numpy, no Python loop)."""
    if not data:
        raise InputError("empty file", file=name)
    buf = np.frombuffer(data, dtype=np.uint8)
    nl = np.flatnonzero(buf == ord("\n"))
    starts = np.concatenate(([0], nl + 1))
    stops = np.concatenate((nl + 1, [len(data)]))
    if starts[-1] == len(data):           # the text ends with a newline
        starts, stops = starts[:-1], stops[:-1]
    ends = stops - (buf[stops - 1] == ord("\n"))
    ends = ends - ((ends > starts) & (buf[np.maximum(ends - 1, 0)] == ord("\r")))
    blank = ends == starts
    comment = ~blank & (buf[starts] == ord("#"))
    kept = np.flatnonzero(~(blank | comment))
    if kept.size == 0:
        raise InputError("empty file: no header line (only comments or blank lines)",
                         file=name)
    lines = _Lines(data, starts, ends, stops, int(kept[0]), kept[1:])
    n_blank = int(blank.sum())
    notes = ([f"{name}: skipped {n_blank} blank line(s) (first at line "
              f"{int(np.flatnonzero(blank)[0]) + 1})"] if n_blank else [])
    return lines, notes


# -- the CSV: header --------------------------------------------------------
@dataclass(frozen=True)
class _Columns:
    """The header, and where the columns this module reads are."""

    n_fields: int
    positions: tuple[int, ...]   # file positions: time, gyro1..N, [ref x y z], [acc x y z], [temp]
    names: tuple[str, ...]       # their names, same order
    n_gyros: int
    has_ref: bool
    has_temp: bool
    has_acc: bool = False


def _parse_header(text: str, name: str, line: int) -> tuple[_Columns, list[str]]:
    def error(message, column=None):
        return InputError(message, file=name, line=line, column=column)

    try:
        fields = [f.strip() for f in next(csv.reader([text]))]
    except (csv.Error, StopIteration) as e:
        raise error(f"malformed header: {e}") from None
    return _header_columns(fields, text, name, error)


def _header_columns(fields: list[str], text: str, name: str, error) -> tuple[_Columns, list[str]]:
    """The columns of a header's field names (CSV header or Parquet schema); ``error(message,
    column)`` builds the located refusal."""
    if len(fields) > MAX_COLUMNS:
        raise error(f"{len(fields)} columns, more than the {MAX_COLUMNS} a measurement may have "
                    f"(time_s, at most {MAX_GYROS} gyros, ref_x..z, acc_x..z, temp_c and at most "
                    f"{MAX_EXTRA_COLUMNS} extra columns): not a measurement file")
    where: dict[str, int] = {}
    for k, f in enumerate(fields, 1):
        if not f:
            raise error(f"header field {k} is empty (every column needs a name)", k)
        if f in where:
            raise error(f"duplicate column name {f!r} (columns {where[f]} and {k})", f)
        where[f] = k
    if _TIME not in where:
        raise error(f"required column {_TIME} is missing (header: {short_repr(text, 60)})")
    n_gyros = _gyro_count(fields, error)
    refs = [r for r in _REF_NAMES if r in where]
    if refs and len(refs) != 3:
        raise error(f"ref_x, ref_y and ref_z must be given together; found only "
                    f"{', '.join(refs)}", refs[0])
    accs = [a for a in _ACC_NAMES if a in where]
    if accs and len(accs) != 3:
        missing = [a for a in _ACC_NAMES if a not in where]
        raise error(f"acc_x, acc_y and acc_z must be given together; found only "
                    f"{', '.join(accs)} ({', '.join(missing)} missing)", accs[0])
    names = (_TIME, *(f"gyro{k}" for k in range(1, n_gyros + 1)), *refs, *accs,
             *([_TEMP] if _TEMP in where else []))
    used = set(names)
    extras = [f for f in fields if f not in used]
    notes = ([f"{name}: ignored extra column(s) {', '.join(extras)}"] if extras else [])
    cols = _Columns(n_fields=len(fields), positions=tuple(where[c] - 1 for c in names),
                    names=names, n_gyros=n_gyros, has_ref=bool(refs),
                    has_temp=_TEMP in where, has_acc=bool(accs))
    return cols, notes


def _gyro_count(fields: list[str], error) -> int:
    """N, checking that the gyro columns are exactly gyro1..gyroN."""
    found = [f for f in fields if _GYRO_RE.fullmatch(f)]
    if not found:
        raise error("no gyro columns (gyro1, gyro2, ... required)")
    expected = [f"gyro{k}" for k in range(1, len(found) + 1)]
    if set(found) != set(expected):
        wanted, have = set(expected), set(found)
        wrong = next(f for f in found if f not in wanted)
        missing = next(f for f in expected if f not in have)
        raise error(f"gyro columns must be numbered gyro1..gyro{len(found)} "
                    f"consecutively: found {', '.join(found)} ({wrong} is out of "
                    f"sequence, {missing} is missing)", wrong)
    return len(found)


# -- the CSV: cells ---------------------------------------------------------
@dataclass(frozen=True)
class _Table:
    """The used columns as floats (NaN for missing cells), with line numbers."""

    values: np.ndarray            # (n, k) in the file's units
    lines: np.ndarray             # (n,) 1-based file line of each row
    header_line: int
    token: Callable[[int, int], str]   # text of cell (row, j) for NaN/inf cells


class _CellError(ValueError):
    """A cell that is not a number (message without location)."""


def _cell_value(token: str) -> float:
    """The float in a cell; NaN if missing; _CellError if not a number."""
    s = token.strip()
    if _NUMBER_RE.fullmatch(s):
        x = float(s)
        if math.isinf(x):
            raise _CellError(f"value {short_repr(token)} overflows to infinity")
        return x
    if not s or s.lower() in _NAN_WORDS:
        return math.nan
    if s.lower() in _INF_WORDS:
        raise _CellError(f"infinite value {short_repr(token)}")
    raise _CellError(f"non-numeric value {short_repr(token)}")


def _missing_kind(token: str) -> str:
    if token == _NULL:
        return "null value"
    return "empty cell" if not token.strip() else f"NaN value {short_repr(token)}"


def _parse_csv(data: bytes, name: str) -> tuple[_Columns, _Table, list[str]]:
    lines, notes = _scan_lines(data, name)
    header_line = lines.header + 1
    cols, header_notes = _parse_header(lines.text(lines.header), name, header_line)
    if lines.rows.size == 0:
        raise InputError("no data rows after the header", file=name, line=header_line)
    quoted = lines.data.find(b'"', int(lines.starts[lines.rows[0]])) != -1
    table = _parse_slow(lines, cols, name) if quoted else _parse_fast(lines, cols, name)
    return cols, table, notes + header_notes


def _body_bytes(lines: _Lines, rows: np.ndarray) -> bytes:
    """The given data lines as one byte string (lines between them left out)."""
    breaks = np.flatnonzero(np.diff(rows) != 1)
    firsts = np.concatenate(([rows[0]], rows[breaks + 1]))
    lasts = np.concatenate((rows[breaks], [rows[-1]]))
    # every piece but the last ends with its line's newline
    return b"".join(lines.data[lines.starts[a]:lines.stops[b]] for a, b in zip(firsts, lasts))


def _check_field_counts(lines: _Lines, cols: _Columns, name: str) -> None:
    """Every data line has as many fields as the header (no quotes here)."""
    buf = np.frombuffer(lines.data, dtype=np.uint8)
    commas_before_stop = np.searchsorted(np.flatnonzero(buf == ord(",")), lines.stops)
    per_line = np.diff(commas_before_stop, prepend=0)
    rows = lines.rows
    counts = per_line[rows] + 1
    bad = np.flatnonzero(counts != cols.n_fields)
    if bad.size:
        i = int(bad[0])
        raise _field_count_error(int(counts[i]), cols.n_fields, name, int(rows[i]) + 1)


def _field_count_error(got: int, expected: int, name: str, line: int) -> InputError:
    return InputError(f"wrong number of fields: {got}, the header has {expected}",
                      file=name, line=line)


def _pandas_values(body: bytes, cols: _Columns, n_rows: int) -> np.ndarray:
    """The used columns of a quote-free body as float64 (pandas C parser).

    Raises ValueError when pandas refuses a cell or finds another row count.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        df = pd.read_csv(io.BytesIO(body), header=None, names=range(cols.n_fields),
                         usecols=list(cols.positions), dtype=np.float64, engine="c",
                         index_col=False, keep_default_na=False, na_values=_PANDAS_NA,
                         skip_blank_lines=False, **_EXACT_FLOATS)
    if len(df) != n_rows:
        raise ValueError("row count differs")
    return df.loc[:, list(cols.positions)].to_numpy(dtype=np.float64)


def _parse_fast(lines: _Lines, cols: _Columns, name: str) -> _Table:
    """pandas' C parser on a quote-free body, the slow path only where it fails.

    When pandas refuses the body, it is parsed again in chunks of
    ``_LOCATE_CHUNK_ROWS`` rows, and only the chunks pandas refuses go
    through the exact slow path (which raises the located error, or accepts
    spellings pandas does not know, such as ``-nan``).
    """
    _check_field_counts(lines, cols, name)
    rows = lines.rows
    try:
        values = _pandas_values(_body_bytes(lines, rows), cols, rows.size)
    except (ValueError, OverflowError):
        step = _LOCATE_CHUNK_ROWS
        values = np.concatenate([_chunk_values(lines, rows[a:a + step], cols, name)
                                 for a in range(0, rows.size, step)])

    def token(row: int, j: int) -> str:
        return lines.text(int(rows[row])).split(",")[cols.positions[j]]

    return _Table(values, rows + 1, lines.header + 1, token)


def _chunk_values(lines: _Lines, rows: np.ndarray, cols: _Columns, name: str) -> np.ndarray:
    try:
        return _pandas_values(_body_bytes(lines, rows), cols, rows.size)
    except (ValueError, OverflowError):
        return _parse_slow(lines, cols, name, rows).values


def _parse_slow(lines: _Lines, cols: _Columns, name: str, rows=None) -> _Table:
    """Exact cell-by-cell parse with :mod:`csv`; raises at the first bad cell.

    ``rows`` (indices of physical lines) defaults to every data line; about
    5-10 µs per cell, so used only for quoted files and to locate errors.
    """
    rows = lines.rows if rows is None else rows
    file_lines = rows + 1
    reader = csv.reader(lines.text(int(i)) for i in rows)
    values: list = []
    rec_lines: list[int] = []
    missing: dict[tuple[int, int], str] = {}
    while True:
        first = reader.line_num
        try:
            fields = next(reader)
        except StopIteration:
            break
        except csv.Error as e:
            raise InputError(f"malformed CSV row: {e}", file=name,
                             line=int(file_lines[min(first, len(file_lines) - 1)])) from None
        line = int(file_lines[first])
        if len(fields) != cols.n_fields:
            raise _field_count_error(len(fields), cols.n_fields, name, line)
        values.append(_row_values(fields, cols, name, line, len(values), missing))
        rec_lines.append(line)
    array = np.array(values, dtype=np.float64).reshape(len(values), len(cols.positions))
    return _Table(array, np.array(rec_lines, dtype=np.int64), lines.header + 1,
                  lambda row, j: missing[(row, j)])


def _row_values(fields, cols: _Columns, name: str, line: int, row: int,
                missing: dict) -> list[float]:
    out = []
    for j, pos in enumerate(cols.positions):
        try:
            x = _cell_value(fields[pos])
        except _CellError as e:
            raise InputError(f"{e} in column {cols.names[j]}", file=name, line=line,
                             column=cols.names[j]) from None
        if x != x:
            missing[(row, j)] = fields[pos]
        out.append(x)
    return out


# -- checks and repairs -----------------------------------------------------
def _check_gyro_count(cols: _Columns, side: _Sidecar, name: str, line: int | None) -> None:
    if cols.n_gyros != side.layout.n_gyros:
        raise InputError(
            f"gyro count does not match the layout: {cols.n_gyros} gyro column(s) "
            f"(gyro1..gyro{cols.n_gyros}) but the layout in {side.name} has "
            f"{side.layout.n_gyros} axes", file=name, line=line)


def _checked_values(table: _Table, cols: _Columns, name: str, repair: bool,
                    nominal_s: float | None = None, declared: dict | None = None,
                    keep_gaps: bool = False) -> tuple[np.ndarray, list[str]]:
    """Check cells, time and gaps; repair or refuse; values in file units.

    With ``repair``, in this order: exact duplicate rows are dropped, short
    gaps and runs of missing values are filled, and a jittering clock is
    resampled onto the nominal grid (each step listed in the notes). With
    ``keep_gaps`` gaps in the time stamps are kept as they are (counted in a note).
    """
    _check_infinite(table, cols, name)
    _check_physical(table, cols, declared or {}, name)
    if len(table.values) < MIN_SAMPLES:
        raise InputError(f"too few samples: {len(table.values)}, at least {MIN_SAMPLES} needed",
                         file=name, line=int(table.lines[-1]))
    dup_notes: list[str] = []
    if repair:
        table, dup_notes = _drop_duplicate_rows(table, name)
        if len(table.values) < MIN_SAMPLES:
            raise InputError(f"too few samples after dropping exact duplicate rows: "
                             f"{len(table.values)}, at least {MIN_SAMPLES} needed", file=name,
                             line=int(table.lines[-1]))
    _check_time(table, name)
    _check_time_steps(table, name)
    values, lines = table.values, table.lines
    gaps: list[tuple[int, int]]
    if keep_gaps:
        gaps, gap_notes = [], _kept_gaps(values[:, 0], name)
    else:
        gaps, gap_notes = _find_gaps(values[:, 0], lines, name, repair)
    runs, run_notes = _find_missing_runs(table, cols, name, repair)
    if gaps or runs:
        values = _fill_runs(values.copy(), runs)
    values, stamp_notes = _stamps_checked(values, cols, nominal_s, name, declared or {},
                                          repair and not keep_gaps)
    if gaps or runs:
        values = _insert_gap_rows(values, gaps)
        _check_repaired(values, cols, name)
    values, jitter_notes = _jitter(values, nominal_s, name, repair, keep_gaps=keep_gaps)
    return values, dup_notes + run_notes + gap_notes + stamp_notes + jitter_notes


#: With ``repair``, replace a reference derived over stamps that lie by the one re-derived on
#: the uniform grid (:func:`gyroarray.core.stamps.corrected_reference`). The corrected MPU
#: reference shows the encoder's own 2nd harmonic above its floor, which the cross-spectral scale
#: factor now leaves out (analysis/transfer.py reads only lines the gyro shows, GYRO_LINE_Z):
#: gyro 3 then reads 5949 +- 54 ppm (the fundamental's whole-cycle DFT: +6037); before that
#: change the same reference gave +32 %. The note names the bias either way.
CORRECT_LYING_REFERENCE = True


def _stamps_checked(values: np.ndarray, cols: _Columns, nominal_s: float | None, name: str,
                    declared: dict, correct: bool) -> tuple[np.ndarray, list[str]]:
    """A reference derived over stamps that lie: name it and its bias; correct it (``correct``).

    Only for a jittering clock (a step off the nominal period by more than
    :data:`JITTER_TOL`) with ``ref_*`` columns: :func:`gyroarray.core.stamps.stamps_lie`
    undoes numpy.gradient over the stamps and asks whether the angle's increments follow
    the stamps' steps. When they do not, the samples are uniform and the stamps lie: with
    ``correct`` (and :data:`CORRECT_LYING_REFERENCE`) the reference columns are replaced at
    the rows by :func:`gyroarray.core.stamps.corrected_reference` (the angle recovered and
    differentiated on the uniform grid the stamps span); the rows are then re-timed as any
    jittering clock's. Returns (values, notes); values in file units.
    """
    if not cols.has_ref or nominal_s is None or len(values) < MIN_SAMPLES:
        return values, []
    t = values[:, 0]
    steps = np.diff(t)
    period = float(np.median(steps))
    if abs(period / nominal_s - 1.0) <= RATE_NOTE_TOL:
        period = nominal_s
    one = steps <= GAP_FACTOR * period
    if not one.any() or float(np.max(np.abs(steps[one] - period))) <= JITTER_TOL * period:
        return values, []
    # deferred: scipy is loaded only when a jittering clock has a reference
    from gyroarray.core.stamps import corrected_reference, stamps_lie

    g = _column_groups(cols)
    ref = values[:, g["ref"]]
    verdict = stamps_lie(t, values[:, g["gyro"]], ref, period)
    if not verdict.lie:
        return values, []
    corr = corrected_reference(t, ref, period)
    convert = ACCEPTED_UNITS["ref"][declared.get("ref", "deg/s")]
    to_deg_s = (lambda x: x) if convert is None else convert
    rms, worst, mean = (float(v) for v in to_deg_s(np.array([corr.bias_rms, corr.bias_max,
                                                              corr.bias_mean])))
    moved = np.sqrt(np.mean((ref - corr.ref_at_rows) ** 2, axis=0)) > 0
    ref_names = ", ".join(n for n, b in zip(cols.names[g["ref"]], moved) if b) or "ref"
    time_unit = "ms" if declared.get("time") == "ms" else "s"
    what = (f"{name}: the reference ({ref_names}) is biased by its stamps: it was derived by "
            f"numpy.gradient over time stamps whose jitter is an error of the stamps, not of the "
            f"sampling ({verdict.reason}); the bias is rms {rms:.3g} deg/s, max {worst:.3g} deg/s, "
            f"mean {mean:+.3g} deg/s, {corr.scale_ppm:+.0f} ppm in scale (a scale factor fitted "
            f"against it reads {corr.scale_ppm:.0f} ppm low); the samples are uniform at "
            f"{corr.period_s:.7g} {time_unit} (the stamp span over {verdict.n_slots} intervals)")
    if not correct:
        return values, [what + "; rerun with --repair to replace it by the reference re-derived "
                        "on that grid from the angle recovered by undoing numpy.gradient"]
    if not CORRECT_LYING_REFERENCE:
        return values, [what + "; kept as recorded (the correction waits on the cross-spectral "
                        "scale factor's use of only the lines the gyro shows, issue 44 item 1)"]
    out = values.copy()
    out[:, g["ref"]] = corr.ref_at_rows
    return out, [what + "; repaired: replaced by the reference re-derived by numpy.gradient on "
                 "that grid of the angle recovered by undoing numpy.gradient over the stamps"]


def _nominal_period(side: "_Sidecar", cols: _Columns) -> float:
    """The sidecar's nominal sample period in the time column's unit."""
    period = 1.0 / side.sample_rate_hz
    return period * MS_PER_S if side.units.get("time") == "ms" else period


def _check_physical(table: _Table, cols: _Columns, declared: dict, name: str) -> None:
    """Refuse a gyro or reference rate beyond :data:`MAX_RATE_DEG_S` (a unit or logging error)."""
    groups = _column_groups(cols)
    for key in ("gyro", "ref"):
        if key not in groups:
            continue
        block = table.values[:, groups[key]]
        convert = ACCEPTED_UNITS[key][declared.get(key, "deg/s")]
        with np.errstate(invalid="ignore", over="ignore"):
            mag = np.abs(block if convert is None else convert(block))
            bad = mag > MAX_RATE_DEG_S
        if bad.any():
            row = int(np.flatnonzero(bad.any(axis=1))[0])
            j = int(np.flatnonzero(bad[row])[0])
            col = cols.names[groups[key].start + j]
            raise InputError(f"{col} = {_fmt(table.values[row, groups[key].start + j])} is beyond "
                             f"the {MAX_RATE_DEG_S:g} deg/s any gyro or rate table can see "
                             "(a unit or logging error?)", file=name, line=int(table.lines[row]),
                             column=col)


#: Shortest time step accepted [s]: a clock faster than 1 GHz is not a gyro's.
MIN_TIME_STEP_S = 1e-9
#: Largest |step - nominal period| / nominal period accepted as the same clock
#: without a note [-] (printing the times to a few digits stays far below it).
JITTER_TOL = 1e-3


def _check_time_steps(table: _Table, name: str) -> None:
    """Refuse time steps below :data:`MIN_TIME_STEP_S` (subnormal or nanosecond steps)."""
    t = table.values[:, 0]
    step = np.diff(t)
    tiny = np.flatnonzero(step < MIN_TIME_STEP_S)
    if tiny.size:
        i = int(tiny[0])
        raise InputError(f"time step of {_fmt(step[i])} s between line {table.lines[i]} and line "
                         f"{table.lines[i + 1]} is shorter than {MIN_TIME_STEP_S:g} s (a sample "
                         "rate above 1 GHz): not a gyro's clock (a unit error?)", file=name,
                         line=int(table.lines[i + 1]), column=_TIME)


def _drop_duplicate_rows(table: _Table, name: str) -> tuple[_Table, list[str]]:
    """Drop rows that repeat the previous row exactly (``repair``); refuse conflicting ones.

    Two rows with the same time stamp and different values are refused,
    naming both lines: nothing tells which of them is right.
    """
    v = table.values
    same_t = v[1:, 0] == v[:-1, 0]
    if not same_t.any():
        return table, []
    same_row = same_t & np.all((v[1:] == v[:-1]) | (np.isnan(v[1:]) & np.isnan(v[:-1])), axis=1)
    conflict = np.flatnonzero(same_t & ~same_row)
    if conflict.size:
        i = int(conflict[0])
        raise InputError(f"conflicting duplicate rows: line {table.lines[i]} and line "
                         f"{table.lines[i + 1]} both have time_s = {_fmt(v[i, 0])} s but different "
                         "values; --repair drops exact duplicates only (it cannot tell which row "
                         "is right)", file=name, line=int(table.lines[i + 1]), column=_TIME)
    keep = np.concatenate(([True], ~same_row))
    kept = np.flatnonzero(keep)
    dropped = table.lines[1:][same_row]
    notes = [f"{name}: repaired: dropped line {int(line)}, an exact duplicate of the row before it"
             for line in dropped]
    token = table.token
    return (_Table(v[kept], table.lines[kept], table.header_line,
                   lambda row, j: token(int(kept[row]), j)),
            _summarised(notes, "exact duplicate rows dropped"))


def _jitter(values: np.ndarray, nominal_s: float | None, name: str,
            repair: bool, keep_gaps: bool = False) -> tuple[np.ndarray, list[str]]:
    """Resample a jittering clock onto the nominal grid (``repair``), or note the jitter.

    The period is the median step, or the sidecar's nominal period when the
    two agree to 1 %. With ``repair`` every column is linearly interpolated
    in time onto ``t0 + k * period``, k = 0 .. round((t_end - t0) / period).
    With ``keep_gaps`` the gaps' steps are not jitter (and a jittering clock with
    gaps is not resampled: that would fill them).
    """
    t = values[:, 0]
    period = float(np.median(np.diff(t)))
    if nominal_s is not None and abs(period / nominal_s - 1.0) <= RATE_NOTE_TOL:
        period = nominal_s
    steps = np.diff(t)
    gap = steps > GAP_FACTOR * float(np.median(steps)) if keep_gaps else np.zeros(steps.size, bool)
    dev = np.abs(steps[~gap] - period)
    worst = float(dev.max()) if dev.size else 0.0
    if worst <= JITTER_TOL * period:
        return values, []
    if repair and gap.any():
        raise InputError(f"the time steps jitter by up to {worst:.3g} s and the record has "
                         f"{int(gap.sum())} gap(s): resampling onto the nominal grid would fill them; "
                         "leave out --repair to keep the stamps as they are (the jitter is noted), "
                         "or without --gaps to have short gaps filled", file=name, column=_TIME)
    what = (f"the time steps jitter by up to {worst:.3g} s ({100 * worst / period:.3g} % of the "
            f"{period:.6g} s step; rms {float(np.sqrt(np.mean(dev ** 2))):.3g} s)")
    if not repair:
        return values, [f"{name}: {what}; the analyses assume the uniform step (rerun with --repair "
                        "to resample onto the nominal grid by linear interpolation)"]
    rel = t - t[0]
    with np.errstate(all="ignore"):
        n_steps = float(rel[-1]) / period
    if not (math.isfinite(n_steps) and n_steps <= 2 * len(t) + 10):
        raise InputError(f"cannot resample onto a {period:.6g} s grid: the record spans "
                         f"{_fmt(rel[-1])} s", file=name, column=_TIME)
    k = int(round(n_steps))
    grid = np.arange(k + 1) * period
    grid = grid[grid <= rel[-1]]
    out = np.empty((grid.size, values.shape[1]))
    out[:, 0] = t[0] + grid
    for j in range(1, values.shape[1]):
        out[:, j] = np.interp(grid, rel, values[:, j])
    if not np.all(np.diff(out[:, 0]) > 0):
        raise InputError("cannot resample: the nominal grid is not representable at these time "
                         "stamps (subtract the first stamp from time_s)", file=name, column=_TIME)
    return out, [f"{name}: repaired: {what}; resampled {len(t)} samples onto {grid.size} at the "
                 f"nominal {period:.6g} s step from the first stamp, by linear interpolation in time"]


def _check_infinite(table: _Table, cols: _Columns, name: str) -> None:
    inf = np.isinf(table.values)
    if inf.any():
        row = int(np.flatnonzero(inf.any(axis=1))[0])
        j = int(np.flatnonzero(inf[row])[0])
        token = table.token(row, j)
        try:
            _cell_value(token)
            problem = f"infinite value {short_repr(token)}"   # pandas knows more spellings
        except _CellError as e:
            problem = str(e)
        raise InputError(f"{problem} in column {cols.names[j]}", file=name,
                         line=int(table.lines[row]), column=cols.names[j])


def _check_time(table: _Table, name: str) -> None:
    t, lines = table.values[:, 0], table.lines
    nan = np.flatnonzero(np.isnan(t))
    if nan.size:
        i = int(nan[0])
        raise InputError(f"{_missing_kind(table.token(i, 0))} in column {_TIME}: sample "
                         "times cannot be missing or repaired", file=name,
                         line=int(lines[i]), column=_TIME)
    bad = np.flatnonzero(~(np.diff(t) > 0))
    if bad.size:
        i = int(bad[0])
        hint = ("; if the rows repeat exactly, --repair drops the duplicates"
                if t[i + 1] == t[i] else "")
        raise InputError(f"time_s is not strictly increasing: {_fmt(t[i + 1])} s at line "
                         f"{lines[i + 1]} follows {_fmt(t[i])} s at line {lines[i]}{hint}",
                         file=name, line=int(lines[i + 1]), column=_TIME)


def _fmt(x) -> str:
    return repr(float(x))


def _find_gaps(t: np.ndarray, lines: np.ndarray, name: str,
               repair: bool) -> tuple[list[tuple[int, int]], list[str]]:
    """Gaps as (row before the gap, missing samples); refuse unless repairable."""
    step = np.diff(t)
    period = float(np.median(step))
    where = np.flatnonzero(step > GAP_FACTOR * period)
    with np.errstate(over="ignore"):
        missing = np.rint(np.minimum(step[where] / period, 1e15)).astype(np.int64) - 1
    gaps, notes = [], []
    for i, m in zip(where.tolist(), missing.tolist()):
        span = (f"between line {lines[i]} (t = {_fmt(t[i])} s) and line {lines[i + 1]} "
                f"(t = {_fmt(t[i + 1])} s)")
        if m > MAX_REPAIR_SAMPLES or not repair:
            fix = (f"gaps longer than {MAX_REPAIR_SAMPLES} samples cannot be repaired"
                   if m > MAX_REPAIR_SAMPLES else
                   "rerun with --repair (repair=True in Python) to fill it by linear interpolation")
            fix += ("; gyroarray allan --gaps (gaps=True in Python) keeps the gaps and pools the "
                    "contiguous parts, nothing interpolated")
            raise InputError(f"gap of {m} missing sample(s) {span} (nominal period "
                             f"{period:.6g} s); {fix}", file=name,
                             line=int(lines[i + 1]), column=_TIME)
        gaps.append((i, m))
        notes.append(f"{name}: repaired a gap: inserted {m} sample(s) {span}, values "
                     "linearly interpolated in time")
    return gaps, _summarised(notes, "gaps repaired")


def _kept_gaps(t: np.ndarray, name: str) -> list[str]:
    """The note on gaps kept as they are (``gaps=True``): how many, how many samples missing."""
    step = np.diff(t)
    period = float(np.median(step))
    where = np.flatnonzero(step > GAP_FACTOR * period)
    if not where.size:
        return []
    with np.errstate(over="ignore"):
        missing = int(np.sum(np.rint(np.minimum(step[where] / period, 1e15)) - 1))
    return [f"{name}: {where.size} gap(s) in time_s kept as they are ({missing} sample(s) missing at "
            f"the {period:.6g} s step), nothing interpolated"]


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges where ``mask`` is True."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def _find_missing_runs(table: _Table, cols: _Columns, name: str,
                       repair: bool) -> tuple[list[tuple[int, int, int]], list[str]]:
    """Runs (start, stop, column) of missing data values; refuse unless repairable."""
    nan = np.isnan(table.values[:, 1:])
    if not nan.any():
        return [], []
    runs = sorted((a, b, j + 1) for j in np.flatnonzero(nan.any(axis=0)).tolist()
                  for a, b in true_runs(nan[:, j]))
    n, lines, notes = len(table.values), table.lines, []
    for a, b, j in runs:
        col = cols.names[j]
        where = (f"line {lines[a]}" if b - a == 1 else f"lines {lines[a]}-{lines[b - 1]}")
        kind = _missing_kind(table.token(a, j))
        what = f"{kind}, {where}"
        if a == 0 or b == n:
            problem = (f"missing value(s) at the {'start' if a == 0 else 'end'} of column "
                       f"{col} ({what}) cannot be interpolated")
        elif b - a > MAX_REPAIR_SAMPLES:
            problem = (f"run of {b - a} missing values in column {col} ({what}) is longer "
                       f"than {MAX_REPAIR_SAMPLES} samples and cannot be repaired")
        elif not repair:
            problem = (f"{kind} in column {col} ({b - a} missing value(s), {where}); rerun "
                       "with --repair (repair=True in Python) to fill by linear interpolation")
        else:
            notes.append(f"{name}: repaired {b - a} missing value(s) in column {col} at "
                         f"{where} by linear interpolation in time")
            continue
        raise InputError(problem, file=name, line=int(lines[a]), column=col)
    return runs, _summarised(notes, "runs of missing values repaired")


def _summarised(notes: list[str], what: str) -> list[str]:
    """At most ``_MAX_NOTES`` notes of one kind, then a count of the rest."""
    if len(notes) <= _MAX_NOTES:
        return notes
    return notes[:_MAX_NOTES] + [f"... and {len(notes) - _MAX_NOTES} more {what}"]


def _fill_runs(values: np.ndarray, runs) -> np.ndarray:
    t = values[:, 0]
    for j in sorted({j for _, _, j in runs}):
        bad = np.isnan(values[:, j])
        values[bad, j] = np.interp(t[bad], t[~bad], values[~bad, j])
    return values


def _insert_gap_rows(values: np.ndarray, gaps) -> np.ndarray:
    if not gaps:
        return values
    t = values[:, 0]
    new_t = np.concatenate([t[i] + (t[i + 1] - t[i]) * np.arange(1, m + 1) / (m + 1)
                            for i, m in gaps])
    at = np.concatenate([np.full(m, i + 1) for i, m in gaps])
    rows = np.column_stack([new_t] + [np.interp(new_t, t, values[:, j])
                                      for j in range(1, values.shape[1])])
    return np.insert(values, at, rows, axis=0)


def _check_repaired(values: np.ndarray, cols: _Columns, name: str) -> None:
    if not np.all(np.diff(values[:, 0]) > 0):
        raise InputError("cannot repair: the inserted sample times are not representable "
                         "between their neighbours", file=name, column=_TIME)
    bad = np.flatnonzero(~np.isfinite(values).all(axis=0))
    if bad.size:
        raise InputError("cannot repair: interpolation overflows (values too large)",
                         file=name, column=cols.names[int(bad[0])])


def _column_groups(cols: _Columns) -> dict[str, slice]:
    n = cols.n_gyros
    groups = {"time": slice(0, 1), "gyro": slice(1, 1 + n)}
    j = 1 + n
    if cols.has_ref:
        groups["ref"] = slice(j, j + 3)
        j += 3
    if cols.has_acc:
        groups["acc"] = slice(j, j + 3)
        j += 3
    if cols.has_temp:
        groups["temp"] = slice(j, j + 1)
    return groups


def _to_canonical(values: np.ndarray, cols: _Columns, declared: dict, toml_name: str,
                  name: str) -> tuple[np.ndarray, list[str]]:
    """Convert columns declared in ``[units]`` to s, deg/s and degC."""
    groups = _column_groups(cols)
    todo = [(key, unit) for key, unit in declared.items()
            if key in groups and ACCEPTED_UNITS[key][unit] is not None]
    if not todo:
        return values, []
    values, notes = values.copy(), []
    for key, unit in todo:
        convert = ACCEPTED_UNITS[key][unit]
        assert convert is not None                             # todo keeps the converted units
        with np.errstate(over="ignore", under="ignore"):
            values[:, groups[key]] = convert(values[:, groups[key]])
        notes.append(f"{toml_name}: converted {key} from {unit} to {_CANONICAL_UNIT[key]} "
                     "([units] table)")
        bad = ~np.isfinite(values[:, groups[key]])
        if bad.any():
            raise InputError(f"a {key} value overflows when converted from {unit}",
                             file=name, column=cols.names[groups[key].start])
    if not np.all(np.diff(values[:, 0]) > 0):
        raise InputError("time_s is not strictly increasing after converting its unit",
                         file=name, column=_TIME)
    return values, notes


def _build(values: np.ndarray, cols: _Columns, side: _Sidecar, name: str,
           notes) -> Measurement:
    g = _column_groups(cols)
    return Measurement(
        time_s=values[:, 0], gyro_deg_s=values[:, g["gyro"]], layout=side.layout,
        sample_rate_hz=side.sample_rate_hz,
        ref_deg_s=values[:, g["ref"]] if "ref" in g else None,
        temp_c=values[:, g["temp"].start] if "temp" in g else None,
        site=side.site, description=side.description, source=name, notes=notes,
        acc_m_s2=values[:, g["acc"]] if "acc" in g else None, topics=side.topics)


def _rate_note(time_s: np.ndarray, side: _Sidecar) -> list[str]:
    """A note when sample_rate_hz and the median step of time_s disagree."""
    with np.errstate(divide="ignore", over="ignore"):
        rate = 1.0 / float(np.median(np.diff(time_s)))
    if abs(rate / side.sample_rate_hz - 1.0) <= RATE_NOTE_TOL:
        return []
    return [f"{side.name}: sample_rate_hz = {_fmt(side.sample_rate_hz)} but the median "
            f"step of time_s gives {rate:.6g} Hz; time_s is used"]


# =========================================================================
# Parquet, and reading a record in chunks (records longer than memory)
# =========================================================================
#: Suffix of a Parquet measurement: the CSV's columns (``time_s``, ``gyro1..N``, optional
#: ``ref_*``, ``acc_*``, ``temp_c``) and units, numeric (float or integer) columns, the same
#: ``<stem>.toml`` sidecar beside it. The recommended format for long records: read in row
#: groups without parsing text, and streamed by ``gyroarray allan``.
PARQUET_SUFFIX = ".parquet"
#: Rows per row group of the Parquet files gyroarray writes (a streamed reader holds about one
#: row group of the columns it reads at a time).
PARQUET_ROW_GROUP = 1 << 20
#: Peak memory of reading a Parquet measurement whole, per value [bytes]: the arrow buffers,
#: the float64 table and the checks' copies (rounded up from tracemalloc).
_PARQUET_BYTES_PER_VALUE = 40
_NULL = "null"


def is_parquet(path) -> bool:
    """True when ``path`` names a Parquet measurement (ends in :data:`PARQUET_SUFFIX`)."""
    return Path(path).name.lower().endswith(PARQUET_SUFFIX)


#: Largest Parquet footer (the file's metadata) read [bytes]; at most a sixty-fourth of the
#: memory budget, at least 1 MiB (:func:`_footer_cap`). pyarrow holds about 18 times a footer
#: while parsing it; a measurement's footer takes about 200 bytes per column and row group
#: (2 MB for 10 columns in 1000 row groups of 2**20 rows).
MAX_PARQUET_FOOTER_BYTES = 64 << 20
#: Most rows per byte of a row group's ``time_s`` column as encoded, before compression [-]:
#: time is strictly increasing, so its values are distinct; a float takes at least 4 bytes in
#: every encoding (its dictionary page too) and pyarrow's DELTA_BINARY_PACKED of evenly spaced
#: integers 42 rows per byte (measured); 1024 leaves a margin of 24 for other writers.
_MAX_ROWS_PER_TIME_BYTE = 1024
#: Largest column chunk (one row group, decoded) searched for the first cell that is not a number
#: [bytes], at most a sixteenth of the budget (at least 1 MiB); a larger non-numeric column is
#: refused from its type alone (a 600 MiB text cell in a 21 kB file was decoded whole: 2.76 GB).
_LOCATE_MAX_BYTES = 16 << 20
_PARQUET_MAGIC = b"PAR1"
_PARQUET_ERRORS: tuple = (OSError, ValueError, MemoryError)   # with pyarrow.ArrowException


def _footer_cap() -> int:
    """The largest Parquet footer read now [bytes] (:data:`MAX_PARQUET_FOOTER_BYTES`)."""
    return max(1 << 20, min(MAX_PARQUET_FOOTER_BYTES, max_memory() // 64))


def _arrow_errors() -> tuple:
    # not deferred: pandas (imported above) loads pyarrow; the import names it here
    import pyarrow as pa
    return (pa.ArrowException, *_PARQUET_ERRORS)


def _said(e: BaseException) -> str:
    """An exception in one short line (its type and message)."""
    return f"{type(e).__name__}: {' '.join(str(e).split())[:160]}"


def _parquet_file(path: Path, name: str):
    """The open ``pyarrow.parquet.ParquetFile``, refused in one line when it is not Parquet.

    Before pyarrow reads the footer, its length (the 4 bytes before the closing ``PAR1``) is
    checked against the file and :func:`_footer_cap`; before the schema's names are matched,
    its column count against :data:`MAX_COLUMNS`. No sample is read.
    """
    # deferred: pyarrow.parquet (with ssl) loads only for a Parquet file; pyarrow itself comes with pandas
    import pyarrow.parquet as pq
    with open_regular(path, "measurement file") as fh:      # no FIFO, device or folder
        size = os.fstat(fh.fileno()).st_size
        head = fh.read(4)
        fh.seek(max(size - 8, 0))
        tail = fh.read(8)
    if size < 12 or head != _PARQUET_MAGIC or tail[4:] not in (_PARQUET_MAGIC, b"PARE"):
        raise InputError(f"not a readable Parquet file: {format_size(size)} that do not start and "
                         "end with PAR1 (Parquet's magic bytes)", file=name)
    if tail[4:] == b"PARE":
        raise InputError("an encrypted Parquet file (its footer is encrypted): gyroarray reads "
                         "plain Parquet", file=name)
    footer = int.from_bytes(tail[:4], "little")
    if footer > size - 12:
        raise InputError(f"not a readable Parquet file: its footer says it is {footer} bytes, "
                         f"more than the file's {size} bytes hold", file=name)
    cap = _footer_cap()
    if footer > cap:
        raise InputError(f"Parquet footer (the file's metadata) of {format_size(footer)}, more than "
                         f"the {format_size(cap)} gyroarray reads (a measurement's footer takes about "
                         "200 bytes per column and row group): too many columns or row groups for a "
                         "measurement (raise --max-memory if it is a real record)", file=name)
    try:
        pf = pq.ParquetFile(path)
        n_columns = pf.metadata.num_columns
        if n_columns <= MAX_COLUMNS:
            pf.schema_arrow                                # the arrow schema, parsed once here
    except _arrow_errors() as e:
        raise InputError(f"not a readable Parquet file: {_said(e)}", file=name) from None
    if n_columns > MAX_COLUMNS:
        raise InputError(f"{n_columns} columns, more than the {MAX_COLUMNS} a measurement may have "
                         f"(time_s, at most {MAX_GYROS} gyros, ref_x..z, acc_x..z, temp_c and at "
                         f"most {MAX_EXTRA_COLUMNS} extra columns): not a measurement file "
                         "(nothing read beyond its footer)", file=name)
    return pf


@dataclass(frozen=True)
class _ParquetPlan:
    """What a Parquet file's footer says of the columns read, checked against itself and the
    file's size (:func:`_parquet_plan`)."""

    rows: int                        # data rows
    group_rows: tuple[int, ...]      # rows of each row group
    group_bytes: int                 # the largest row group's columns read: stored + decoded pages
    column_bytes: Mapping            # column -> its largest chunk, stored + decoded [bytes]


def _parquet_plan(pf, names, name: str) -> _ParquetPlan:
    """The rows and sizes of the columns ``names`` of an open Parquet file, from its footer.

    Refused (one line naming the file, the row group and the column) before any data is read: a
    negative row count, row groups whose rows do not add up to the file's, a column chunk whose
    value count is not its row group's rows, a chunk outside the file's data, more rows than a
    row group's ``time_s`` can hold (:data:`_MAX_ROWS_PER_TIME_BYTE`).
    """
    meta = pf.metadata
    forged = "a corrupt or forged Parquet footer"
    data_end = os.stat(name).st_size - 8 - meta.serialized_size
    leaf: dict[str, int] = {}
    for j in range(meta.num_columns):
        leaf.setdefault(meta.schema.column(j).path, j)
    used = [(c, leaf[c]) for c in names if c in leaf]     # a nested column: its type refuses it
    groups, total, biggest = [], 0, 0
    col_bytes = dict.fromkeys((c for c, _ in used), 0)
    n_groups = meta.num_row_groups
    for i in range(n_groups):
        rg = meta.row_group(i)
        n = int(rg.num_rows)
        where = f"row group {i + 1} of {n_groups}"
        if n < 0:
            raise InputError(f"{where}: the footer says {n} rows (a count of rows is never "
                             f"negative): {forged}", file=name)
        group = 0
        for c, j in used:
            cc = rg.column(j)
            values = int(cc.num_values)
            if values != n:
                raise InputError(f"{where}: the footer says {n} rows, and column {c}'s data holds "
                                 f"{values} values: {forged}", file=name, column=c)
            dictionary = cc.dictionary_page_offset if cc.has_dictionary_page else None
            first = int(cc.data_page_offset if dictionary is None else min(dictionary, cc.data_page_offset))
            stored, decoded = int(cc.total_compressed_size), int(cc.total_uncompressed_size)
            if first < 4 or stored < 0 or decoded < 0 or first + stored > data_end:
                raise InputError(f"{where}: column {c}'s data (bytes {first} to {first + stored}) "
                                 f"lies outside the file's data (bytes 4 to {data_end}): a corrupt "
                                 "or truncated Parquet file", file=name, column=c)
            if c == _TIME and n > _MAX_ROWS_PER_TIME_BYTE * max(decoded, 1):
                raise InputError(f"{where}: the footer says {n} rows, but its time_s data "
                                 f"({format_size(decoded)} decoded) holds at most "
                                 f"{_MAX_ROWS_PER_TIME_BYTE * max(decoded, 1)} rows (time is strictly "
                                 f"increasing, and no encoding stores distinct values denser than "
                                 f"{_MAX_ROWS_PER_TIME_BYTE} per byte): {forged}", file=name,
                                 column=c)
            group += stored + decoded
            col_bytes[c] = max(col_bytes[c], stored + decoded)
        groups.append(n)
        total += n
        biggest = max(biggest, group)
    if total != int(meta.num_rows):
        raise InputError(f"the footer says {meta.num_rows} rows, its row groups hold {total}: "
                         f"{forged}", file=name)
    return _ParquetPlan(rows=total, group_rows=tuple(groups), group_bytes=biggest,
                        column_bytes=MappingProxyType(col_bytes))


def _parquet_columns(pf, name: str) -> tuple[_Columns, list[str], _ParquetPlan]:
    """The measurement columns of a Parquet schema, each checked to hold numbers; and the
    footer's plan of them (:func:`_parquet_plan`). A column that is not numeric is searched for
    its first cell that is not a number only when its chunks are small
    (:data:`_LOCATE_MAX_BYTES`); else it is refused from its type, nothing read."""
    # not deferred: pandas (imported above) loads pyarrow; the import names it here
    import pyarrow as pa
    schema = pf.schema_arrow
    fields = [str(f) for f in schema.names]

    def error(message, column=None):
        return InputError(message, file=name, column=column)

    cols, notes = _header_columns(fields, ", ".join(fields), name, error)
    plan = _parquet_plan(pf, cols.names, name)
    locate = max(1 << 20, min(_LOCATE_MAX_BYTES, max_memory() // 16))
    for c in cols.names:
        t = schema.field(c).type
        if not (pa.types.is_floating(t) or pa.types.is_integer(t) or pa.types.is_decimal(t)):
            size = plan.column_bytes.get(c)
            if size is None or size > locate:
                what = "a nested column" if size is None else f"{format_size(size)} in a row group"
                raise InputError(f"column {c} holds {t} values, not numbers ({what}, not read): "
                                 "write it as float64", file=name, column=c)
            raise _parquet_type_error(pf, c, t, name)
    return cols, notes, plan


def _parquet_type_error(pf, column: str, dtype, name: str) -> InputError:
    """The refusal of a column that does not hold numbers, naming its first non-numeric cell."""
    row, shown = None, None
    start = 0
    for batch in parquet_batches(pf, [column], _LOCATE_CHUNK_ROWS, name):
        for i, v in enumerate(batch.column(0).to_pylist()):
            if v is None:
                continue
            if isinstance(v, str):
                try:
                    _cell_value(v)
                except _CellError:
                    pass
                else:
                    if row is None:
                        row, shown = start + i + 1, v      # a number written as text
                    continue
            return InputError(f"non-numeric value {short_repr(v)} in column {column} (a "
                              f"{dtype} column; measurement columns hold numbers)",
                              file=name, row=start + i + 1, column=column)
        start += batch.num_rows
    where = f" (row {row} holds {short_repr(shown)})" if row is not None else ""
    return InputError(f"column {column} holds {dtype} values, not numbers{where}: write it as "
                      "float64", file=name, row=row, column=column)


def parquet_batches(pf, columns: list[str], batch_size: int, name: str | None = None):
    """The record batches of ``columns`` of an open ``ParquetFile``, one row group at a time.

    ``ParquetFile.iter_batches`` over the whole file reads ahead (pyarrow 26 held the whole
    file's columns decoded by the end: 4 GB for 1e8 rows x 5 columns); one row group at a
    time, without threads, it holds at most one row group.

    A row group whose data holds other rows than its footer says is refused when it ends, and
    pyarrow's errors on corrupt data are said in one line (:class:`InputError` naming ``name``).
    """
    meta = pf.metadata
    for rg in range(meta.num_row_groups):
        want, got = int(meta.row_group(rg).num_rows), 0
        try:
            for batch in pf.iter_batches(batch_size=batch_size, row_groups=[rg], columns=columns,
                                         use_threads=False):
                got += batch.num_rows
                yield batch
        except _arrow_errors() as e:
            raise InputError(f"row group {rg + 1} of {meta.num_row_groups} cannot be read "
                             f"({_said(e)}): a corrupt Parquet file", file=name) from None
        if got != want:
            raise InputError(f"row group {rg + 1} of {meta.num_row_groups}: the footer says {want} "
                             f"rows, the data holds {got}: a corrupt or forged Parquet footer",
                             file=name)


def _parquet_values(columns, names) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """The named arrow columns as one float64 array (n, k), nulls as NaN; and the null masks."""
    # not deferred: pandas (imported above) loads pyarrow; the import names it here
    import pyarrow as pa
    import pyarrow.compute as pc
    out, nulls = [], {}
    for j, c in enumerate(names):
        col = columns(c)
        if col.null_count:
            nulls[j] = np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool)
        v = pc.cast(col, pa.float64(), safe=False).to_numpy(zero_copy_only=False)
        out.append(np.asarray(v, dtype=np.float64))
    return np.column_stack(out) if out else np.empty((0, 0)), nulls


_LINE_WORD = re.compile(r"\bline(s?) (\d+)")


def _as_rows(err: InputError) -> InputError:
    """A refusal located by data row (Parquet, streamed CSV): ``line N`` said as ``row N``."""
    return InputError(_LINE_WORD.sub(r"row\1 \2", err.message), file=err.file,
                      row=err.line if err.row is None else err.row, column=err.column)


def _parquet_table(values: np.ndarray, nulls: dict, first_row: int) -> _Table:
    """A :class:`_Table` of Parquet rows (``lines`` hold 1-based data rows)."""
    def token(row: int, j: int) -> str:
        return _NULL if j in nulls and nulls[j][row] else repr(float(values[row, j]))
    return _Table(values, np.arange(first_row, first_row + len(values)), 0, token)


def _parquet_read_bytes(plan: _ParquetPlan, k: int) -> float:
    """Peak memory [bytes] of reading ``k`` columns of a Parquet file whole:
    :data:`_PARQUET_BYTES_PER_VALUE` per value (an honest row group's pages, 16 bytes a value,
    included), and what the footer says the largest row group's pages take beyond that."""
    pages = max(0.0, plan.group_bytes - 16.0 * max(plan.group_rows, default=0) * k)
    return float(plan.rows) * k * _PARQUET_BYTES_PER_VALUE + pages


def _parquet_group_bytes(plan: _ParquetPlan, k: int) -> int:
    """What a streamed reader holds of a Parquet file [bytes]: its largest row group of ``k``
    columns, decoded with its pages (16 bytes a value), or what the footer says its pages take
    when that is more."""
    return int(max(16 * max(plan.group_rows, default=0) * k, plan.group_bytes))


def _read_parquet_measurement(path: Path, side: _Sidecar, repair: bool, gaps: bool) -> Measurement:
    """:func:`read_measurement` of a Parquet file (same checks and notes as the CSV, by row)."""
    name = str(path)
    pf = _parquet_file(path, name)
    cols, col_notes, plan = _parquet_columns(pf, name)
    _check_gyro_count(cols, side, name, None)
    n = plan.rows
    if n == 0:
        raise InputError("no data rows (the Parquet file has columns but no samples)", file=name)
    check_memory(_parquet_read_bytes(plan, len(cols.names)),
                 f"reading {n} rows x {len(cols.names)} columns",
                 "gyroarray allan streams a record this long (--stream); cut the record for the "
                 "other commands", file=name)
    try:
        table = pf.read(columns=list(cols.names))
    except _arrow_errors() as e:
        raise InputError(f"the Parquet data cannot be read ({_said(e)}): a corrupt file",
                         file=name) from None
    if table.num_rows != n:
        raise InputError(f"the footer says {n} rows, the data holds {table.num_rows}: a corrupt or "
                         "forged Parquet footer", file=name)
    values, nulls = _parquet_values(table.column, cols.names)
    del table
    try:
        values, repair_notes = _checked_values(_parquet_table(values, nulls, 1), cols, name, repair,
                                               _nominal_period(side, cols), side.units,
                                               **({"keep_gaps": True} if gaps else {}))
    except InputError as err:
        raise _as_rows(err) from None
    values, unit_notes = _to_canonical(values, cols, side.units, side.name, name)
    all_notes = (*col_notes, *side.notes, *unit_notes, *repair_notes,
                 *_rate_note(values[:, 0], side))
    return _build(values, cols, side, name, all_notes)


@dataclass(frozen=True)
class RecordHead:
    """What is known of a measurement before its samples are read (for reading in chunks).

    Parameters
    ----------
    source : str
        The data file (CSV, CSV.GZ or Parquet) as named.
    layout : Layout
        Sensitive axes of the N gyros (from the sidecar).
    sample_rate_hz : float
        Nominal sample rate [Hz] from the sidecar.
    names : tuple of str
        The columns read, in the order of each chunk's columns: ``time_s``, ``gyro1..N``, then
        ``ref_x..z``, ``acc_x..z``, ``temp_c`` where present.
    n_rows : int or None
        Data rows (Parquet: from its metadata); None for a CSV (not known before reading).
    text_bytes : int
        Estimated size of the CSV text [bytes] (decompressed for .gz); 0 for Parquet.
    notes : tuple of str
        The sidecar's and the header's notes.
    """

    source: str
    layout: Layout
    sample_rate_hz: float
    names: tuple[str, ...]
    n_rows: int | None
    text_bytes: int
    notes: tuple[str, ...]
    units: Mapping = field(default_factory=dict, repr=False)
    columns: _Columns | None = field(default=None, repr=False)
    #: The sidecar's site (None when it has none).
    site: Site | None = field(default=None, repr=False)
    #: The sidecar's description.
    description: str = field(default="", repr=False)
    #: What a chunked reader holds of a Parquet file beyond its chunks [bytes]: its largest row
    #: group read, decoded with its pages, from the footer (0 for a CSV, read in chunks).
    group_bytes: int = field(default=0, repr=False)

    @property
    def n_gyros(self) -> int:
        """Number of gyros N."""
        return self.layout.n_gyros

    @property
    def has_reference(self) -> bool:
        """True when the record has ``ref_x``, ``ref_y``, ``ref_z``."""
        return "ref_x" in self.names

    def in_memory_bytes(self) -> float:
        """Estimated peak memory [bytes] of :func:`read_measurement` on this record."""
        if self.n_rows is not None:
            return float(self.n_rows) * len(self.names) * _PARQUET_BYTES_PER_VALUE
        return float(self.text_bytes) * (_MEM_PER_BYTE + _MEM_PER_CELL / 8 + _MEM_PER_LINE / 64)


def read_bytes_estimate(path) -> float | None:
    """Estimated peak memory [bytes] of :func:`read_measurement` on ``path``, from the file's
    size (CSV: its text, .gz: :data:`_GZ_TEXT_RATIO` times the compressed size) or a Parquet
    file's row count; None when the path does not resolve to a measurement file (the reader
    then says why). Reads no sample.
    """
    try:
        data_path, _ = _measurement_paths(path)
        if is_parquet(data_path):
            meta = _parquet_file(data_path, str(data_path)).metadata   # the footer checked first
            return float(meta.num_rows) * meta.num_columns * _PARQUET_BYTES_PER_VALUE
        size = data_path.stat().st_size
    except (InputError, OSError, ValueError):   # a bad file (arrow's errors are these): the reader says why
        return None
    text = size * (_GZ_TEXT_RATIO if data_path.name.lower().endswith(".gz") else 1.0)
    return text * (_MEM_PER_BYTE + _MEM_PER_CELL / 8 + _MEM_PER_LINE / 64)


def record_head(path) -> RecordHead:
    """The sidecar and the header (or Parquet schema) of a measurement, checked; no samples read.

    Parameters
    ----------
    path : str or os.PathLike
        The CSV, CSV.GZ or Parquet file, its sidecar or the stem (as :func:`read_measurement`).

    Returns
    -------
    RecordHead

    Raises
    ------
    InputError
        Anything wrong with the sidecar or the header, as :func:`read_measurement` says it.
    """
    data_path, toml_path = _measurement_paths(path)
    name = str(data_path)
    side = _read_sidecar(toml_path)
    if is_parquet(data_path):
        pf = _parquet_file(data_path, name)
        cols, notes, plan = _parquet_columns(pf, name)
        n_rows, text_bytes = plan.rows, 0
        _check_gyro_count(cols, side, name, None)
        biggest = max(plan.group_rows, default=0)
        group_bytes = _parquet_group_bytes(plan, len(cols.names))
        check_memory(group_bytes,                       # decoded float64 + its compressed pages
                     f"reading a row group of {biggest} rows x {len(cols.names)} columns",
                     f"rewrite the file with smaller row groups (at most {PARQUET_ROW_GROUP} rows, "
                     "what gyroarray convert writes)", file=name)
    else:
        header, line, text_bytes = _csv_header_line(data_path, name)
        cols, notes = _parse_header(header, name, line)
        _check_gyro_count(cols, side, name, line)
        n_rows, group_bytes = None, 0
    return RecordHead(source=name, layout=side.layout, sample_rate_hz=side.sample_rate_hz,
                      names=cols.names, n_rows=n_rows, text_bytes=text_bytes,
                      notes=(*side.notes, *notes), units=MappingProxyType(dict(side.units)),
                      columns=cols, site=side.site, description=side.description,
                      group_bytes=group_bytes)


def read_window(head: RecordHead, n_rows: int, chunk_rows: int) -> Measurement:
    """The first ``n_rows`` samples of a record as a :class:`Measurement`, read in chunks of
    ``chunk_rows`` rows (:func:`iter_record`, every chunk read checked) and never beyond them.

    Parameters
    ----------
    head : RecordHead
        From :func:`record_head`.
    n_rows : int
        Samples of the window (from the first one; fewer when the record is shorter).
    chunk_rows : int
        Rows per chunk read.

    Returns
    -------
    Measurement
        Its notes are the sidecar's and the header's (nothing repaired).
    """
    parts, got = [], 0
    for chunk in iter_record(head, chunk_rows):
        take = min(chunk.shape[0], int(n_rows) - got)
        parts.append(chunk[:take])
        got += take
        if got >= n_rows:
            break
    values = np.vstack(parts)
    cols = head.columns
    assert cols is not None
    side = _Sidecar(name=head.source, sample_rate_hz=head.sample_rate_hz, description=head.description,
                    layout=head.layout, site=head.site, units=dict(head.units), notes=())
    return _build(values, cols, side, head.source, tuple(head.notes))


def _csv_header_line(path: Path, name: str) -> tuple[str, int, int]:
    """(header text, its 1-based line, estimated text size [bytes]) of a CSV or CSV.GZ, every
    line up to the header read with a bounded length (:func:`_head_line`)."""
    gz = name.lower().endswith(".gz")
    with open_regular(path, "measurement file") as fh:
        total = os.fstat(fh.fileno()).st_size
        try:
            found = _head_line(gzip.GzipFile(fileobj=fh, mode="rb") if gz else fh, name)
            text = None if found is None else found[0].decode("utf-8")
        except (OSError, EOFError, zlib.error, UnicodeDecodeError) as e:
            raise InputError(f"cannot read the header: {e}", file=name) from None
    if found is None or text is None:
        raise InputError("empty file: no header line (only comments or blank lines)", file=name)
    return text, found[1], int(total * (_GZ_TEXT_RATIO if gz else 1))


def _head_line(fh, name: str) -> tuple[bytes, int] | None:
    """(the header line's bytes, without its end and a byte-order mark; its 1-based line) of a
    CSV's binary text stream, or None when the text ends before a header.

    Each line up to the header is read with at most :data:`MAX_HEADER_BYTES` (a sparse file of
    zeros, or a gzip of one, is refused after 1 MiB instead of being held whole: it reached
    4.5 GB), the comment and blank lines before the header :data:`_MAX_HEAD_BYTES` and
    :data:`_MAX_HEAD_LINES` in all.
    """
    spent = 0
    for i in range(1, _MAX_HEAD_LINES + 1):
        raw, whole = read_line_bounded(fh, MAX_HEADER_BYTES)
        body = raw[len(_BOM):] if i == 1 and raw.startswith(_BOM) else raw
        if not whole:
            what = "a comment line" if body.startswith(b"#") else "the header line"
            raise InputError(f"{what} is longer than {format_size(MAX_HEADER_BYTES)} (no end of "
                             f"line in its first {MAX_HEADER_BYTES + 1} bytes): not a CSV of samples "
                             f"(a header of {MAX_COLUMNS} columns is far shorter)", file=name, line=i)
        if not raw:
            return None
        body = body.rstrip(b"\r\n")
        if body and not body.startswith(b"#"):
            return body, i
        spent += len(raw)
        if spent > _MAX_HEAD_BYTES:
            raise InputError(f"no header line in the first {format_size(spent)} of text ({i} comment "
                             "or blank lines): not a CSV of samples", file=name, line=i)
    return None


def _check_csv_head(path: Path, name: str) -> None:
    """Refuse, before a CSV (or CSV.GZ) is read whole, a header or a line before it longer than
    :data:`MAX_HEADER_BYTES` (:func:`_head_line`: only the lines up to the header are read).
    Anything else (not gzip, no header, not UTF-8) is left to the reader, which says it."""
    gz = name.lower().endswith(".gz")
    with open_regular(path, "measurement file") as fh:
        if not gz and fh.peek(2)[:2] == _GZIP_MAGIC:
            return
        try:
            _head_line(gzip.GzipFile(fileobj=fh, mode="rb") if gz else fh, name)
        except (OSError, EOFError, zlib.error):
            return


#: Decompressed / compressed size of a measurement CSV.GZ assumed when deciding to stream [-]
#: (printed doubles compress about 2.2-2.6x with gzip -6).
_GZ_TEXT_RATIO = 2.5
_MAX_HEAD_LINES = 100_000


def iter_record(head: RecordHead, chunk_rows: int, *, check: bool = True) -> Iterator[np.ndarray]:
    """The samples of a measurement in chunks of at most ``chunk_rows`` rows, checked.

    Parameters
    ----------
    head : RecordHead
        From :func:`record_head`.
    chunk_rows : int
        Rows per chunk (>= 2).
    check : bool
        Check every chunk (default). False skips the checks (only the unit conversion is
        done): for a second pass over a file a first pass has checked.

    Yields
    ------
    ndarray, shape (k, len(head.names))
        The columns of ``head.names`` in canonical units (s, deg/s, degC, m/s²).

    Raises
    ------
    InputError
        The checks of :func:`read_measurement` without repair, said by data row (1-based, the
        header not counted): a non-numeric, missing or infinite value, a rate beyond any gyro,
        time not strictly increasing (across chunks too), a gap. Nothing is repaired.

    Notes
    -----
    Parquet is read with ``ParquetFile.iter_batches``, a CSV with pandas' chunked C reader
    (comment lines skipped). The last row of each chunk is checked again with the next one, so
    steps and gaps across chunks are found.
    """
    cols = head.columns
    assert cols is not None
    name = head.source
    nominal = (1.0 / head.sample_rate_hz) * (MS_PER_S if head.units.get("time") == "ms" else 1.0)
    prev = None
    row = 1
    for raw, nulls in _raw_chunks(head, max(2, int(chunk_rows))):
        if not check:
            yield _to_canonical(raw, cols, dict(head.units), name, name)[0]
            continue
        values = raw if prev is None else np.vstack([prev, raw])
        if prev is not None:
            nulls = {j: np.concatenate(([False], m)) for j, m in nulls.items()}
        first = row - (0 if prev is None else 1)
        if len(values) >= MIN_SAMPLES or prev is None:
            try:
                checked, _ = _checked_values(_parquet_table(values, nulls, first), cols, name,
                                             False, nominal, dict(head.units))
            except InputError as err:
                raise _as_rows(err) from None
            checked, _ = _to_canonical(checked, cols, dict(head.units), name, name)
            yield checked if prev is None else checked[1:]
        row += len(raw)
        prev = raw[-1:]


def _raw_chunks(head: RecordHead, chunk_rows: int):
    """(values in file units with NaN for missing, null masks) per chunk."""
    cols = head.columns
    assert cols is not None
    names = list(cols.names)
    if is_parquet(head.source):
        pf = _parquet_file(Path(head.source), head.source)
        for batch in parquet_batches(pf, names, chunk_rows, head.source):
            yield _parquet_values(batch.column, names)
        return
    raw = open_regular(Path(head.source), "measurement file")
    total = os.fstat(raw.fileno()).st_size
    text = gzip.GzipFile(fileobj=raw, mode="rb") if head.source.lower().endswith(".gz") else raw
    guarded = io.BufferedReader(_TextGuard(text, head.source, total))
    with warnings.catch_warnings(), raw, guarded:
        warnings.simplefilter("ignore")
        reader = pd.read_csv(guarded, comment="#", skip_blank_lines=True, header=0,
                             usecols=names, chunksize=chunk_rows, engine="c",
                             keep_default_na=False, na_values=_PANDAS_NA, **_EXACT_FLOATS)
        row = 1
        with reader:
            chunks = iter(reader)
            while True:
                try:
                    df = next(chunks)
                except StopIteration:
                    break
                except InputError:
                    raise
                except (pd.errors.ParserError, ValueError, OSError, EOFError, zlib.error) as e:
                    raise InputError(f"malformed CSV (read in chunks of {chunk_rows} rows, after "
                                     f"data row {row - 1}): {e}", file=head.source) from None
                yield _numeric_chunk(df, names, head.source, row), {}
                row += len(df)


#: Longest line a streamed CSV may have [bytes]: a measurement row is under 1 KiB; a longer run
#: without a newline is not a CSV of samples, and the chunked reader would have to hold it.
MAX_STREAM_LINE_BYTES = MAX_LINE_BYTES


class _TextGuard(io.RawIOBase):
    """The bytes of a CSV as read, refusing a NUL byte or a line beyond
    :data:`MAX_STREAM_LINE_BYTES` (the chunked reader's memory stays bounded)."""

    def __init__(self, fh, name: str, total: int):
        self._fh, self._name, self._total = fh, name, total
        self._run = 0               # bytes since the last newline
        self._pos = 0

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        data = self._fh.read(min(len(b), 1 << 16))
        if data:
            nul = data.find(b"\x00")
            if nul >= 0:
                raise InputError(f"NUL byte at byte {self._pos + nul} of the text "
                                 f"(the file is {format_size(self._total)}): not a text CSV of samples",
                                 file=self._name)
            first, last = data.find(b"\n"), data.rfind(b"\n")
            longest = self._run + (len(data) if first < 0 else first)
            self._run = len(data) if last < 0 else len(data) - last - 1
            if first < 0:
                self._run = longest
            if longest > MAX_STREAM_LINE_BYTES:
                raise InputError(f"a line longer than {format_size(MAX_STREAM_LINE_BYTES)} near byte "
                                 f"{self._pos} of the text (the file is {format_size(self._total)}): "
                                 "not a CSV of samples", file=self._name)
            b[:len(data)] = data
            self._pos += len(data)
        return len(data)


def _numeric_chunk(df, names: list[str], name: str, first_row: int) -> np.ndarray:
    """A pandas chunk's columns as float64, refusing (by data row) a cell that is not a number."""
    out = []
    for c in names:
        col = df[c]
        if col.dtype.kind not in "fiu":
            num = pd.to_numeric(col, errors="coerce")
            bad = np.flatnonzero(num.isna().to_numpy() & col.notna().to_numpy())
            if bad.size:
                i = int(bad[0])
                token = str(col.iloc[i])
                try:
                    _cell_value(token)
                except _CellError as e:
                    raise InputError(f"{e} in column {c}", file=name, row=first_row + i,
                                     column=c) from None
            col = num
        out.append(col.to_numpy(dtype=np.float64))
    return np.column_stack(out)


def parquet_bytes(m: Measurement) -> bytes:
    """The Parquet file of a measurement: the CSV's columns as float64, zstd, row groups of
    :data:`PARQUET_ROW_GROUP` rows (what ``write_measurement(m, "F.parquet")`` writes)."""
    # deferred: pyarrow.parquet (with ssl) loads only for a Parquet file written; pyarrow itself comes with pandas
    import pyarrow as pa
    import pyarrow.parquet as pq
    names, blocks = _csv_columns(m)
    table = pa.table({c: np.ascontiguousarray(b[:, j])
                      for c, (b, j) in zip(names, ((b, j) for b in blocks
                                                   for j in range(b.shape[1])))})
    sink = io.BytesIO()
    pq.write_table(table, sink, compression="zstd", row_group_size=PARQUET_ROW_GROUP)
    return sink.getvalue()


# =========================================================================
# Writing
# =========================================================================
def write_measurement(m: Measurement, path, *, force: bool = True) -> tuple[Path, Path]:
    """Write a measurement as CSV (gzip if ``path`` ends in .gz) + TOML sidecar.

    Parameters
    ----------
    m : Measurement
        What to write. Values go out in the canonical file units (s, deg/s,
        degC) with the shortest decimal that reads back as the same double,
        so ``read_measurement(write_measurement(m, p)[0])`` reproduces every
        array exactly. ``notes`` and ``source`` are not written.
    path : str or os.PathLike
        Output CSV, ending in ``.csv`` or ``.csv.gz``, or Parquet (``.parquet``: the same
        columns as float64, :func:`parquet_bytes`; recommended for long records); the sidecar
        is ``<stem>.toml`` beside it.
    force : bool
        Replace existing files (atomically, never through a symlink; see
        :mod:`gyroarray.core.outputs`); False refuses an existing file.

    Returns
    -------
    csv_path, toml_path : Path
        The two files written.

    Raises
    ------
    InputError
        If ``path`` does not end in .csv/.csv.gz, if either output file is
        the file ``m`` was read from (or its sidecar): nothing the user gave
        is ever overwritten; or if a file cannot be written.

    Notes
    -----
    A conical layout is written as ``scheme``/``n_gyros``/``alpha_deg`` when
    that reproduces its axes exactly, otherwise as explicit ``axes``. Degrees
    (``alpha_deg`` and the site) are chosen so that converting them back
    gives the stored radians exactly whenever such a decimal exists.
    """
    csv_path = Path(path)
    low = csv_path.name.lower()
    if not (low.endswith(".csv") or low.endswith(".csv.gz") or low.endswith(PARQUET_SUFFIX)):
        raise InputError(f"output must end in .csv or .csv.gz (or {PARQUET_SUFFIX})", file=str(path))
    toml_path = _sidecar_of(csv_path)
    _refuse_overwriting_source(m, (csv_path, toml_path))
    if low.endswith(PARQUET_SUFFIX):
        text = parquet_bytes(m)
    else:
        text = _csv_text(m).encode("utf-8")
    if low.endswith(".gz"):
        text = gzip.compress(text, compresslevel=6, mtime=0)
    sidecar = tomli_w.dumps(_sidecar_dict(m)).encode("utf-8")
    for target, content in ((csv_path, text), (toml_path, sidecar)):
        write_bytes(target, content, force=force)
    return csv_path, toml_path


def _refuse_overwriting_source(m: Measurement, targets) -> None:
    if m.source is None or not Path(m.source).name:        # no file behind it ("" or a folder)
        return
    for target in targets:
        if any(same_path(target, p) for p in measurement_files(m.source)):
            raise InputError("refusing to overwrite the measurement's own source file "
                             f"({m.source} or its sidecar); choose another path",
                             file=str(target))


def _csv_text(m: Measurement) -> str:
    names, blocks = _csv_columns(m)
    table = np.hstack(blocks)
    row_format = ",".join(["%r"] * table.shape[1])   # %r of a float: shortest round trip
    out = [f"# written by gyroarray {__version__}", ",".join(names)]
    for start in range(0, len(table), _CSV_CHUNK_ROWS):
        rows = table[start:start + _CSV_CHUNK_ROWS].tolist()
        out.extend(map(row_format.__mod__, map(tuple, rows)))
    return "\n".join(out) + "\n"


def _csv_columns(m: Measurement) -> tuple[list[str], list[np.ndarray]]:
    """The written columns' names and their (n, k) blocks, in the file's order."""
    names = [_TIME, *(f"gyro{k}" for k in range(1, m.n_gyros + 1))]
    blocks = [m.time_s[:, None], m.gyro_deg_s]
    if m.ref_deg_s is not None:
        names += _REF_NAMES
        blocks.append(m.ref_deg_s)
    if m.temp_c is not None:
        names.append(_TEMP)
        blocks.append(m.temp_c[:, None])
    if m.acc_m_s2 is not None:
        names += _ACC_NAMES
        blocks.append(m.acc_m_s2)
    return names, blocks


def _exact_deg(rad: float) -> float:
    """The shortest decimal degrees d near ``rad`` with ``deg_to_rad(d) == rad``.

    ``rad_to_deg(deg_to_rad(15.1881))`` is 15.188099999999999 (about 7 % of
    decimals come back one ulp off); both convert to the same radians, and
    the sidecar should show what the user wrote. The few neighbours of
    ``rad_to_deg(rad)`` are tried; without an exact one, that value is used.
    """
    d0 = float(units.rad_to_deg(rad))
    candidates = [d0]
    for direction in (math.inf, -math.inf):
        d = d0
        for _ in range(4):
            d = math.nextafter(d, direction)
            candidates.append(d)
    exact = [d for d in candidates if units.deg_to_rad(d) == rad]
    return min(exact, key=lambda d: len(repr(d))) if exact else d0


def _layout_table(layout: Layout) -> dict:
    """``scheme``/``n_gyros``/``alpha_deg`` if they rebuild the axes exactly, else axes."""
    if (layout.scheme in (1, 2) and layout.alpha_rad is not None
            and 3 <= layout.n_gyros <= MAX_CONE_GYROS):
        alpha_deg = _exact_deg(layout.alpha_rad)
        again = Layout.conical(layout.scheme, layout.n_gyros, units.deg_to_rad(alpha_deg))
        if 0.0 <= alpha_deg <= 180.0 and np.array_equal(again.axes, layout.axes):
            return {"scheme": int(layout.scheme), "n_gyros": layout.n_gyros,
                    "alpha_deg": alpha_deg, **_positions_entry(layout)}
    return {"axes": layout.axes.tolist(), **_positions_entry(layout)}


def _positions_entry(layout: Layout) -> dict:
    """``{"positions_m": rows}`` when the layout has positions, else empty."""
    return {} if layout.positions_m is None else {"positions_m": layout.positions_m.tolist()}


def _sidecar_dict(m: Measurement) -> dict:
    doc = {"sample_rate_hz": m.sample_rate_hz, "description": m.description,
           **({"topics": list(m.topics)} if m.topics else {}),
           "layout": _layout_table(m.layout)}
    if m.site is not None:
        doc["site"] = {"latitude_deg": _exact_deg(m.site.latitude_rad),
                       "heading_deg": _exact_deg(m.site.heading_rad)}
    return doc
