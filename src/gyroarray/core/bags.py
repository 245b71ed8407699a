"""ROS bags of ``sensor_msgs/msg/Imu`` as measurements (issue 33).

A robotics user records a ROS bag of IMU messages; :func:`read_bag` turns the
bag into the same :class:`~gyroarray.core.measurement.Measurement` a CSV
measurement gives (``read_measurement`` sends a bag here), through the
``rosbags`` package: pure Python, no ROS install. Readable: ROS1 ``.bag``,
ROS2 ``.db3`` (sqlite3) and ``.mcap`` files, and ROS2 bag folders (with their
``metadata.yaml``).

Reading rules
-------------
* Topics: ``topic="/imu0"`` picks one ``sensor_msgs/msg/Imu`` topic; without
  it a bag with exactly one IMU topic uses that one, and a bag with several is
  refused with their list. ``topic="/imu0,/imu1"`` makes an array.
* Time: the header stamps (``header.stamp``, default) or the bag's receive (log) times
  (``stamps="receive"``, ``--stamps receive``), in the bag's order; the notes and the
  description say which. They must increase strictly (a stamp repeating or going backwards
  is refused with the message index and ``--retime``). ``time_s`` counts from the first
  stamp, computed from the integer nanoseconds (exact to the nanosecond; a Unix-epoch stamp
  in a double would keep only 0.24 µs): t0 is in the description and the notes. The sample
  rate is 1 / the median stamp step P.
* Clock rule (:class:`_Clock`): message i's deficit D_i = (t_i − t_0)/P − i; its running
  median over 2 :data:`JITTER_WINDOW` + 1 messages is the local regular grid. The grid
  jumping up by more than ``GAP_FACTOR − 1`` steps is a gap of round(jump) dropped messages:
  refused, kept as it is (``gaps``, ``--gaps``: never filled, counted in a note) or filled
  when at most ``MAX_REPAIR_SAMPLES`` (``repair``). A stamp within :data:`JITTER_MAX_STEPS`
  (one step) of the grid is jitter: accepted, with a note when a step differs from P by more
  than ``JITTER_TOL`` (``repair`` resamples onto the uniform step). Farther, a grid jumping
  down, or a median step below half the mean step, is bunching: refused naming the message,
  unless ``retime`` (``--retime``): ``time_s[k] = k (t_last − t_first)/(n − 1)``, accepted
  while every stamp is within :data:`RETIME_MAX_SHIFT_STEPS` steps of its grid time.
* Files rosbags does not open: a ROS1-profile MCAP (``mcap convert x.bag``: schema
  ``ros1msg``, messages ``ros1``) is read with the ``mcap`` library's records and rosbags'
  ROS1 deserializer; a truncated ``.mcap`` or ``.bag`` is read up to the first record that
  does not parse (chunks decompressed bounded), with a note of the messages read, the last
  receive time and the bytes unread; holding no message it is refused with the salvage
  command (``mcap recover``, ``rosbag reindex``; a ``.db3``: sqlite3's ``.recover``).
* Streaming: :class:`BagStream` reads one topic in chunks of :data:`STREAM_CHUNK` messages
  (``gyroarray convert`` in bounded memory), with the same bits as :func:`read_bag`. A ROS1
  bag is read without rosbags' per-message index (>= 100 B a message, 3.5 GB for 24 h at
  400 Hz): its index records chunk by chunk (:func:`_ros1_chunked_reader`), in rosbags' order
  while the chunks' time ranges do not overlap (otherwise with rosbags' whole index).
* Rates: ``angular_velocity`` [rad/s] (REP 103) becomes the measurement's
  gyro columns in deg/s (``shared/spec/measurement-format.md``), one gyro per
  axis of the IMU frame: gyros 1, 2, 3 are its x, y, z unit axes.
  ``linear_acceleration`` [m/s²] of a single IMU becomes ``acc_m_s2`` unless
  the driver marks it absent (covariance[0] = -1) or leaves it all zero.
* Arrays: several topics give one gyro per axis per IMU (IMU 1's x, y, z, then
  IMU 2's ...). Stamps shared by all topics are used as they are; otherwise
  each topic is interpolated linearly in time onto the first topic's stamps
  over the common span (with a note). The axes are the rows of each IMU's
  rotation R_i_b from ``extrinsics`` (a Kalibr imu-chain YAML: ``imuN:
  T_i_b: 4x4``, the body-to-IMU transform, so gyro k of IMU i senses the body
  axis ``R_i_b[k]``; entries matched to topics by their ``rostopic`` or in
  order), or the IMU frames' axes taken as the body frame's (with a note).
* Bags are data: messages are decoded with rosbags' built-in typestores
  (ROS1 Noetic, ROS2 Humble) by their type name, never by code from the bag;
  nothing is unpickled or imported from it.
* Refusals are :class:`~gyroarray.core.errors.InputError`: one line naming the
  bag, the topic and the message index (1-based, in the bag's order on that
  topic): a wrong message type, an empty topic, stamps that repeat or go
  backwards, a non-finite rate, a truncated or corrupt file, a folder without
  ``metadata.yaml``.
* Hostile bags (``docs/bags.md``) are refused the same way, before the work: a bag file, a
  ``metadata.yaml`` or a storage file that is not a regular file (never opened blocking); a
  ``metadata.yaml`` over :data:`MAX_METADATA_BYTES` or with a field of the wrong type (the
  refusal names the field), or counts that disagree with the storage files or pass the memory
  budget; a ``.db3`` (opened read-only, immutable, every query bounded) whose tables are views,
  whose message data are no BLOBs or whose topic ids are unknown; chunks (ROS1 bz2/lz4, MCAP
  zstd/lz4) decompressed in bounded pieces, at most an eighth of the budget (an MCAP chunk at
  most its declared size); ``compression_mode: file`` decompressed into $TMPDIR within the
  budget and the free space; messages over :data:`MAX_MESSAGE_BYTES` or whose frame_id does
  not fit; extrinsics entries beyond ±:data:`MAX_TRANSLATION_M` or not a rotation.
"""

from __future__ import annotations

import io
import json
import math
import mmap
import re
import shutil
import sqlite3
import tempfile
from pathlib import Path, PurePath
from urllib.parse import quote
from typing import Any

import numpy as np

from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.layout import Layout
from gyroarray.core.limits import (MAX_RATE_DEG_S, check_disk_space, check_memory,
                                   decompress_bounded, format_size, max_memory, open_regular,
                                   read_regular)
from gyroarray.core.measurement import (GAP_FACTOR, JITTER_TOL, MAX_REPAIR_SAMPLES, MIN_SAMPLES,
                                        Measurement)

__all__ = ["BAG_SUFFIXES", "IMU_TYPE", "is_bag", "read_bag", "imu_topics", "read_extrinsics",
           "ORTHO_TOL", "STAMPS", "JITTER_MAX_STEPS", "JITTER_WINDOW", "RETIME_MAX_SHIFT_STEPS",
           "BagStream"]

#: File suffixes read as ROS bags (ROS1, ROS2 sqlite3, ROS2 MCAP).
BAG_SUFFIXES = (".bag", ".db3", ".mcap")
#: The message type read (rosbags' normalised name; ROS1's ``sensor_msgs/Imu`` too).
IMU_TYPE = "sensor_msgs/msg/Imu"
#: Largest |R Rᵀ − I| entry of an extrinsic rotation accepted [-] (Kalibr prints 1e-8 or so).
ORTHO_TOL = 1e-6
#: Largest |entry| of an extrinsic transform accepted [m for the translation]: an IMU array
#: spans metres, not kilometres.
MAX_TRANSLATION_M = 1e3
#: Bytes held per message while reading (stamp, 3 rates, 3 specific forces), for the budget.
_BYTES_PER_MESSAGE = 64
_NS_PER_S = 1_000_000_000
#: Messages decoded together (fixed offsets, checked against the typestore on three of them).
_BATCH = 65536
#: Float64 fields of sensor_msgs/msg/Imu after the header (4 + 9 + 3 + 9 + 3 + 9).
_IMU_DOUBLES = 37
#: Largest metadata.yaml read [bytes] (ros2 bag writes a few kB).
MAX_METADATA_BYTES = 4 << 20
#: Largest message read [bytes] (a sensor_msgs/msg/Imu is about 330 bytes and its frame_id).
MAX_MESSAGE_BYTES = 1 << 20
#: Largest message count of a topic [-] (beyond it a count is no count; the memory budget
#: usually refuses far fewer: :data:`_BYTES_PER_MESSAGE` each).
MAX_MESSAGE_COUNT = 1 << 40
#: Largest file a ROS2 folder in compression_mode 'file' is decompressed to [bytes] (also at
#: most the memory budget), in $TMPDIR, whose free space is checked before and while writing.
MAX_DECOMPRESSED_FILE_BYTES = 64 << 30
#: SQLite virtual-machine steps between two progress checks, and the checks a query on a .db3
#: gets: a fixed allowance plus one per 4 bytes of the file (a scan of real tables needs far
#: fewer; only a view or a recursive query could use them up, and those are refused).
_SQL_STEPS = 1000
_SQL_TICKS_FIXED = 100_000
#: Tables of a ROS2 .db3 that must be real tables (the first two must exist).
_DB3_TABLES = ("topics", "messages", "schema", "message_definitions", "metadata")
#: The time bases a bag's messages can be read on: ``header.stamp`` or the bag's receive time.
STAMPS = ("header", "receive")
#: Largest distance of a stamp from its slot on the local regular grid that is jitter [steps
#: of the median period P]: one step. Within it a late or early stamp still lies between its
#: neighbours' slots, so the message count and the uniform step agree (the AR.Drone bag's
#: 1.65-step stamp is 0.65 step late); beyond it a stamp sits in another message's slot, which
#: is bunching (refused unless --retime). Gaps are not jitter: a drop moves the grid itself.
JITTER_MAX_STEPS = 1.0
#: Half-width of the running median of the deficit D that is the local grid [messages]: a run
#: of up to this many late or early stamps is jitter; a drop (a lasting jump of D) is seen at
#: its message exactly, and clock drift (a slow ramp of D) is followed.
JITTER_WINDOW = 8
#: Largest shift of a stamp to its time on the ``--retime`` grid [steps]: bursts of up to 64
#: messages are spread; more is a drop or a rate change, which re-timing would hide.
RETIME_MAX_SHIFT_STEPS = 64.0
#: Largest mean stamp step, in median steps, of a clock with drops [-]: 2, i.e. at most as
#: many messages dropped as kept; beyond it the median step is a burst's, not the clock's.
MAX_MEAN_TO_MEDIAN_STEP = 2.0
#: Messages per chunk of a streamed read (``gyroarray convert``): 16384 messages of about
#: 330 bytes are 5.4 MB of raw messages and 0.9 MB of decoded values at a time.
STREAM_CHUNK = 16384


def is_bag(path) -> bool:
    """True when ``path`` names a ROS bag: a ``.bag``, ``.db3`` or ``.mcap`` file, or a folder
    (a ROS2 bag) not named like a measurement file and not the stem of a CSV beside it."""
    p = Path(path)
    low = p.name.lower()
    if low.endswith(BAG_SUFFIXES):
        return True
    return (p.is_dir() and not low.endswith((".csv", ".csv.gz", ".toml"))
            and not any(p.with_name(p.name + s).is_file() for s in (".csv", ".csv.gz")))


def _kind(path: Path) -> str:
    low = path.name.lower()
    if low.endswith(".bag"):
        return "ROS1 bag"
    if low.endswith(".db3"):
        return "ROS2 bag (sqlite3)"
    if low.endswith(".mcap"):
        return "ROS2 bag (MCAP)"
    return "ROS2 bag folder"


def _check_path(path: Path) -> dict | None:
    """Refuse what is no bag before rosbags sees it: missing, not a regular file (a FIFO, a
    device, a link to one: never opened blocking), a folder without a valid metadata.yaml or
    with a storage file that is not a regular file, a .db3 whose tables are not real tables.
    Returns a folder's ``rosbag2_bagfile_information`` (checked), None for a file."""
    name = str(path)
    if not path.exists() and not path.is_symlink():
        raise InputError("bag not found", file=name)
    if path.is_dir():
        if path.name.lower().endswith(BAG_SUFFIXES):
            raise InputError("a ROS bag file expected, but this is a folder", file=name)
        meta = path / "metadata.yaml"
        if not meta.exists() and not meta.is_symlink():
            raise InputError("this folder has no metadata.yaml, so it is not a ROS2 bag folder; give "
                             "the .db3 or .mcap file inside it, or restore metadata.yaml "
                             "('ros2 bag reindex')", file=name)
        info = _metadata(meta)
        for f in _storage_paths(path, info):
            open_regular(f, "ROS2 bag storage file (listed in metadata.yaml)").close()
            if info["storage_identifier"] == "sqlite3" and not info["compression_mode"] == "file":
                _check_db3(f)
        return info
    open_regular(path, "a ROS bag file").close()
    if path.name.lower().endswith(".db3"):
        _check_db3(path)
    return None


def _storage_paths(folder: Path, info: dict) -> list[Path]:
    return [folder / PurePath(x).name for x in info["relative_file_paths"]]


_META = "rosbag2_bagfile_information"


def _field(meta: Path, key: str, problem: str) -> InputError:
    return InputError(f"{_META}.{key}: {problem}", file=str(meta))


def _int(meta: Path, value, key: str, lo: int = 0, hi: int = 2**63 - 1) -> int:
    if not isinstance(value, int) or isinstance(value, bool):
        raise _field(meta, key, f"must be an integer from {lo} to {hi}, got {_shown(value)}")
    if not lo <= value <= hi:
        raise _field(meta, key, f"must be an integer from {lo} to {hi}, got {_shown(value)}")
    return value


def _str(meta: Path, value, key: str, optional: bool = False) -> str:
    if optional and value is None:
        return ""
    if not isinstance(value, str) or len(value) > 4096:
        raise _field(meta, key, f"must be a text (a string), got {_shown(value)}")
    return value


def _shown(value) -> str:
    kinds = {list: "a list", dict: "a mapping", type(None): "nothing (null)", bool: "true/false",
             str: "a text"}
    if isinstance(value, float):
        return f"{value!r} (a real number)"
    if isinstance(value, int) and not isinstance(value, bool):
        text = str(value) if abs(value) < 10**30 else f"an integer of {len(str(abs(value)))} digits"
        return text
    return kinds.get(type(value), type(value).__name__)


def _yaml(text: bytes, name: str, what: str):
    """A YAML document, safely loaded (no tags run), its syntax and nesting errors refused."""
    # deferred: ruamel.yaml (a rosbags dependency) loads only when a bag is read
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError
    too_deep = InputError(f"the {what} nests lists or mappings too deep to be read (refused; "
                          f"a real {what} nests a few levels)", file=name)
    if _flow_depth(text) > _MAX_YAML_DEPTH or _MAX_YAML_INDENT.search(text):
        raise too_deep          # before the parser, which takes seconds on thousands of levels
    try:
        return YAML(typ="safe", pure=True).load(text.decode("utf-8"))
    except UnicodeDecodeError:
        raise InputError(f"the {what} is not UTF-8 text", file=name) from None
    except RecursionError:
        raise InputError(f"the {what} nests lists or mappings too deep to be read (refused; "
                         f"a real {what} nests a few levels)", file=name) from None
    except YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        raise InputError(f"not valid YAML: {getattr(err, 'problem', None) or err}", file=name,
                         line=None if mark is None else mark.line + 1) from None
    except (ValueError, TypeError, OverflowError) as err:   # a constructor refusing a value
        raise InputError(f"not valid YAML: {' '.join(str(err).split())[:200]}", file=name) from None


#: Deepest nesting of [ ] and { } read in a YAML file (metadata.yaml, extrinsics) [-], and the
#: deepest indentation [characters] (block nesting).
_MAX_YAML_DEPTH = 64
_MAX_YAML_INDENT = re.compile(rb"^[ \t-]{512}", re.MULTILINE)
_NOT_BRACKETS = bytes(sorted(set(range(256)) - set(b"[]{}")))


def _flow_depth(text: bytes) -> int:
    """The deepest nesting of [ ] and { } in ``text`` (quotes not told apart: an upper bound;
    a closing bracket without its opening one counts as none)."""
    marks = np.frombuffer(text.translate(None, _NOT_BRACKETS), dtype=np.uint8)
    if marks.size == 0:
        return 0
    walk = np.cumsum(np.where((marks == ord("[")) | (marks == ord("{")), 1, -1))
    return int((walk - np.minimum(np.minimum.accumulate(walk), 0)).max())


def _metadata(meta: Path) -> dict:
    """The checked ``rosbag2_bagfile_information`` of a ROS2 folder's metadata.yaml: every
    field the reader uses has its type, counts are small non-negative integers."""
    name = str(meta)
    doc = _yaml(read_regular(meta, "metadata.yaml", max_bytes=MAX_METADATA_BYTES), name,
                "metadata.yaml")
    info = doc.get(_META) if isinstance(doc, dict) else None
    if not isinstance(info, dict):
        raise InputError(f"no {_META} mapping: not a ROS2 bag's metadata.yaml", file=name)
    out = dict(info)
    out["version"] = _int(meta, info.get("version"), "version", 1, 9)
    sid = _str(meta, info.get("storage_identifier"), "storage_identifier")
    if sid not in ("sqlite3", "mcap"):
        raise _field(meta, "storage_identifier", f"must be sqlite3 or mcap, got {sid[:40]!r}")
    paths = info.get("relative_file_paths")
    if not isinstance(paths, list) or not 1 <= len(paths) <= 10_000:
        raise _field(meta, "relative_file_paths", f"must be a list of 1 to 10000 file names, got "
                                                  f"{_shown(paths)}")
    for k, x in enumerate(paths):
        _str(meta, x, f"relative_file_paths[{k}]")
    mode = _str(meta, info.get("compression_mode", ""), "compression_mode", optional=True).lower()
    mode = "" if mode == "none" else mode
    fmt = _str(meta, info.get("compression_format", ""), "compression_format", optional=True)
    if mode not in ("", "file", "message"):
        raise _field(meta, "compression_mode", f"must be file, message or none, got {mode[:40]!r}")
    if mode and fmt != "zstd":
        raise _field(meta, "compression_format", f"must be zstd (the one rosbag2 writes), got "
                                                  f"{fmt[:40]!r}")
    out["compression_mode"], out["compression_format"] = mode, fmt
    topics = info.get("topics_with_message_count")
    if not isinstance(topics, list) or len(topics) > 100_000:
        raise _field(meta, "topics_with_message_count", f"must be a list of topics, got "
                                                        f"{_shown(topics)}")
    for k, entry in enumerate(topics):
        key = f"topics_with_message_count[{k}]"
        if not isinstance(entry, dict):
            raise _field(meta, key, f"must be a mapping (topic_metadata, message_count), got "
                                    f"{_shown(entry)}")
        tm = entry.get("topic_metadata")
        if not isinstance(tm, dict):
            raise _field(meta, f"{key}.topic_metadata", "must be a mapping (name, type, "
                                                        f"serialization_format), got {_shown(tm)}")
        for f in ("name", "type", "serialization_format"):
            _str(meta, tm.get(f), f"{key}.topic_metadata.{f}")
        for f in ("type_description_hash",):
            if f in tm:
                _str(meta, tm[f], f"{key}.topic_metadata.{f}", optional=True)
        if not isinstance(tm.get("offered_qos_profiles", ""), (str, list)):
            raise _field(meta, f"{key}.topic_metadata.offered_qos_profiles",
                         f"must be a text or a list, got {_shown(tm.get('offered_qos_profiles'))}")
        n = _int(meta, entry.get("message_count"), f"{key}.message_count", 0, MAX_MESSAGE_COUNT)
        check_memory(n * float(_BYTES_PER_MESSAGE), f"{_META}.{key}.message_count: {n} messages of "
                     f"topic {tm['name']}", "split the bag ('ros2 bag convert')", file=name)
    _int(meta, info.get("message_count"), "message_count", 0, MAX_MESSAGE_COUNT)
    for key, sub in (("duration", "nanoseconds"), ("starting_time", "nanoseconds_since_epoch")):
        if not isinstance(info.get(key), dict):
            raise _field(meta, key, f"must be a mapping with {sub}, got {_shown(info.get(key))}")
        _int(meta, info[key].get(sub), f"{key}.{sub}", -(2**63), 2**63 - 1)
    if not isinstance(info.get("files", []), list):
        raise _field(meta, "files", f"must be a list, got {_shown(info.get('files'))}")
    return out


def _sql_kind(value) -> str:
    return {type(None): "NULL", float: "REAL", str: "TEXT", int: "INTEGER"}.get(type(value),
                                                                                 type(value).__name__)


def _check_db3(path: Path) -> None:
    """Refuse a .db3 whose tables rosbags reads are views, virtual tables or missing, or whose
    messages name topic ids the topics table lacks; read-only, immutable, every query bounded."""
    name = str(path)
    uri = f"file:{quote(str(path.resolve()))}?mode=ro&immutable=1"
    try:
        con = sqlite3.connect(uri, uri=True, check_same_thread=False)
    except sqlite3.Error as err:
        raise _refusal(path, "cannot open this ROS2 bag (sqlite3): truncated or corrupt? "
                             f"(salvage it with {_salvage_command(path)})", err) from None
    ticks = [0, _SQL_TICKS_FIXED + path.stat().st_size // 4]

    def tick() -> int:
        ticks[0] += 1
        return int(ticks[0] > ticks[1])
    con.set_progress_handler(tick, _SQL_STEPS)
    try:
        marks = ",".join("?" * len(_DB3_TABLES))
        rows = con.execute(f"SELECT name, type, sql FROM sqlite_master WHERE name IN ({marks})",
                           _DB3_TABLES).fetchall()
        kinds = {str(n): (str(t), str(sql or "")) for n, t, sql in rows}
        for table in _DB3_TABLES:
            kind, sql = kinds.get(table, ("", ""))
            if table in ("topics", "messages") and not kind:
                raise InputError(f"the {table} table of a ROS2 bag is missing: not a rosbag2 "
                                 "sqlite3 file", file=name)
            if kind and (kind != "table" or sql.lstrip().upper().startswith("CREATE VIRTUAL")):
                what = "a virtual table" if kind == "table" else f"a {kind}"
                raise InputError(f"{table} is {what}, not a table: a ROS2 bag's {table} is a "
                                 "plain table (refused: a view or virtual table can run any "
                                 "query, even one without end)", file=name)
        bad = con.execute("SELECT messages.topic_id, count(*) FROM messages LEFT JOIN topics ON "
                          "messages.topic_id = topics.id WHERE topics.id IS NULL GROUP BY "
                          "messages.topic_id LIMIT 3").fetchall()
        if bad:
            ids = ", ".join(f"{'NULL' if i is None else i} ({n} messages)" for i, n in bad)
            raise InputError(f"messages with a topic id that the topics table does not have: "
                             f"{ids}: corrupt bag?", file=name)
    except sqlite3.Error as err:
        if ticks[0] > ticks[1]:
            raise InputError("a query on this .db3 ran past its allowance of steps: refused",
                             file=name) from None
        raise _refusal(path, "cannot read this ROS2 bag (sqlite3): truncated or corrupt? "
                             f"(salvage it with {_salvage_command(path)})", err) from None
    finally:
        con.close()


def _refusal(path: Path, what: str, err: BaseException | None = None, topic: str | None = None,
             index: int | None = None) -> InputError:
    """One-line refusal naming the bag, the topic and the message index."""
    where = "".join([f"topic {topic}, " if topic else "", f"message {index}: " if index else ""])
    why = f" ({type(err).__name__}: {' '.join(str(err).split())[:200]})" if err is not None else ""
    return InputError(f"{where}{what}{why}", file=str(path))


def _chunk_cap() -> int:
    """Largest chunk (ROS1, MCAP) decompressed [bytes]: an eighth of the memory budget."""
    return max(1 << 20, max_memory() // 8)


def _mcap_chunk(data, fmt: str, size: int) -> bytes:
    cap = _chunk_cap()
    if size > cap:
        raise InputError(f"a chunk declares {format_size(size)} uncompressed, more than the "
                         f"{format_size(cap)} gyroarray decompresses at once (an eighth of the "
                         "memory budget; raise --max-memory if it is a real bag)")
    return decompress_bounded(data, fmt, size, None,
                              f"a chunk declaring {format_size(size)} uncompressed")


def _record_size(size: int) -> None:
    """Refuse reading a record (ROS1, MCAP) that declares more than :func:`_chunk_cap` bytes:
    a sparse file of zeros would otherwise be read into memory whole."""
    cap = _chunk_cap()
    if size > cap:
        raise InputError(f"a record declares {format_size(size)}, more than the "
                         f"{format_size(cap)} gyroarray reads at once (an eighth of the memory "
                         "budget; raise --max-memory if it is a real bag)")


_GUARDED: list[bool] = []


def _guard_rosbags() -> None:
    """Give rosbags' chunk decompressors (ROS1 bz2/lz4, MCAP zstd/lz4) a bound: each chunk in
    pieces, at most :func:`_chunk_cap` (an MCAP chunk at most its declared size), so a
    compression bomb is refused instead of filling the memory; and its record reads the same
    bound (:func:`_record_size`). Same bytes for a valid bag. Once per process."""
    if _GUARDED:
        return
    # deferred: rosbags loads only when a bag is read
    from rosbags.rosbag1 import reader as ros1_reader
    from rosbags.rosbag2 import storage_mcap
    for fmt in ("bz2", "lz4"):
        if fmt in ros1_reader.decompressors:
            ros1_reader.decompressors[fmt] = (
                lambda data, fmt=fmt: decompress_bounded(data, fmt, _chunk_cap(), None, "a chunk"))  # type: ignore[misc]
    for fmt in ("zstd", "lz4"):
        if fmt in storage_mcap.DECOMPRESSORS:
            storage_mcap.DECOMPRESSORS[fmt] = lambda data, size, fmt=fmt: _mcap_chunk(data, fmt, size)  # type: ignore[misc]

    def ros1_read(src, size, read=ros1_reader.read_bytes):
        _record_size(size)
        return read(src, size)

    def mcap_read(bio, size, read=storage_mcap.read_exact):
        _record_size(size)
        return read(bio, size)
    ros1_reader.read_bytes, storage_mcap.read_exact = ros1_read, mcap_read
    _GUARDED.append(True)


# -- sources rosbags does not read: ROS1-profile MCAP, truncated MCAP and ROS1 bags -----------
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_ROS1_MAGIC = b"#ROSBAG V2.0\n"


def _mcap_profile(path: Path) -> str | None:
    """The profile an MCAP file's header record names (``ros1``, ``ros2``, ...), or None when
    the file does not start with an MCAP header."""
    with open_regular(path, "a ROS bag file") as fh:
        head = fh.read(8 + 9 + 4 + 256)
    if not head.startswith(_MCAP_MAGIC) or len(head) < 21 or head[8] != 0x01:
        return None
    n = int.from_bytes(head[17:21], "little")
    return head[21:21 + n].decode("utf-8", "replace") if len(head) >= 21 + n else None


def _ros_type(name: str) -> str:
    """``sensor_msgs/Imu`` (ROS1's name) -> ``sensor_msgs/msg/Imu`` (rosbags' normalised one)."""
    parts = name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else name


class _Conn:
    """A topic of a bag read by gyroarray itself: what rosbags' connections give."""

    def __init__(self, cid: int, topic: str, msgtype: str, encoding: str):
        self.id, self.topic, self.msgtype, self.encoding, self.msgcount = cid, topic, msgtype, encoding, 0


class _Salvage:
    """What a truncated bag lost: filled by the scan that stops at the first unreadable record."""

    def __init__(self, size: int):
        self.size, self.read_to, self.messages, self.why = size, 0, 0, ""
        self.last_ns: int | None = None

    def note(self, path: Path, command: str) -> str:
        last = "none" if self.last_ns is None else f"{_stamp(self.last_ns)} s"
        return (f"{path}: salvaged a truncated or corrupt {_kind(path)}: read {self.messages} "
                f"messages (the last received at {last}); {format_size(self.size - self.read_to)} "
                f"of {format_size(self.size)} unread from byte {self.read_to} on ({self.why}); "
                f"what they held is lost ({command} may recover more)")


def _salvage_command(path: Path) -> str:
    """The tool that rebuilds the index of a damaged bag of this kind."""
    low = path.name.lower()
    if low.endswith(".mcap"):
        return f"'mcap recover {path} -o recovered.mcap'"
    if low.endswith(".db3"):
        return f"'sqlite3 {path} .recover | sqlite3 recovered.db3'"
    if low.endswith(".bag"):
        return f"'rosbag reindex {path}' (ROS1; it keeps a .orig.bag copy)"
    return "'ros2 bag reindex'"


def _chunk_records(data: bytes) -> list:
    """The schema, channel and message records of a decompressed MCAP chunk (others skipped)."""
    # deferred: the mcap library loads only for a ROS1-profile or truncated MCAP
    from mcap.data_stream import ReadDataStream
    from mcap.opcode import Opcode
    from mcap.records import Channel, Message, Schema
    stream, out = ReadDataStream(io.BytesIO(data)), []
    while stream.count < len(data):
        opcode, length = stream.read1(), stream.read8()
        _record_size(length)
        if opcode == Opcode.CHANNEL:
            out.append(Channel.read(stream))
        elif opcode == Opcode.MESSAGE:
            out.append(Message.read(stream, length))
        elif opcode == Opcode.SCHEMA:
            out.append(Schema.read(stream))
        else:
            stream.read(length)
    return out


class _RecordSource:
    """A bag read by gyroarray itself, record by record (:class:`_McapSource`, :class:`_Ros1Salvage`):
    the subclass's ``_walk(wanted)`` yields (channel id, log time [ns], raw) in file order."""

    _conns: dict[int, _Conn]

    def _walk(self, wanted):
        raise NotImplementedError

    def messages(self, connections=()):
        """(connection, log time [ns], raw) of ``connections``' messages, in file order."""
        wanted = {c.id for c in connections} or set(self._conns)
        for cid, ts, raw in self._walk(wanted):
            yield self._conns[cid], ts, raw

    def close(self) -> None:
        pass


class _McapSource(_RecordSource):
    """The messages of an MCAP file read record by record with the ``mcap`` library's stream
    reader: a ROS1-profile MCAP (what ``mcap convert x.bag`` writes: schema encoding
    ``ros1msg``, message encoding ``ros1``), or a truncated MCAP of either profile (``salvage``:
    what is readable up to the first record that does not parse). Chunks are decompressed
    bounded (:func:`_mcap_chunk`), records are at most :func:`_chunk_cap` bytes; channels and
    message counts come from a first pass."""

    def __init__(self, path: Path, salvage: bool):
        self.path, self.salvage = path, salvage
        self.lost = _Salvage(path.stat().st_size) if salvage else None
        self._conns: dict[int, _Conn] = {}
        for _ in self._walk(None):
            pass
        self.connections = list(self._conns.values())

    def _walk(self, wanted: set | None):
        """(channel id, log time [ns], data) of every message in file order; channels and counts
        recorded on the first pass (``wanted`` None)."""
        # deferred: the mcap library loads only for a ROS1-profile or truncated MCAP
        from mcap.records import Channel, Chunk, Message, Schema
        from mcap.stream_reader import StreamReader
        first = wanted is None
        schemas: dict[int, str] = {}
        fh = open_regular(self.path, "a ROS bag file")
        try:
            reader = StreamReader(fh, emit_chunks=True, record_size_limit=_chunk_cap())
            it = iter(reader.records)
            while True:
                try:
                    rec = next(it, None)
                    if rec is None:
                        break
                    inner = [rec]
                    if isinstance(rec, Chunk):
                        data = (rec.data if rec.compression in ("", "none") else
                                _mcap_chunk(rec.data, rec.compression, rec.uncompressed_size))
                        inner = _chunk_records(data)
                except InputError:
                    raise                                     # a bomb: refused, never salvaged
                except Exception as err:  # the mcap library's errors on a cut or corrupt record
                    if not self.salvage:
                        raise
                    if first:
                        assert self.lost is not None
                        self.lost.why = f"{type(err).__name__}: {' '.join(str(err).split())[:120]}"
                    break
                for r in inner:
                    if isinstance(r, Schema):
                        schemas[r.id] = r.name
                    elif isinstance(r, Channel) and first and r.id not in self._conns:
                        self._conns[r.id] = _Conn(r.id, r.topic, _ros_type(schemas.get(r.schema_id, "")),
                                                  r.message_encoding)
                    elif isinstance(r, Message) and r.channel_id in self._conns:
                        if first:
                            self._conns[r.channel_id].msgcount += 1
                            if self.lost is not None:
                                self.lost.messages += 1
                                self.lost.last_ns = r.log_time
                        elif wanted is not None and r.channel_id in wanted:
                            yield r.channel_id, r.log_time, r.data
                if first and self.lost is not None:
                    self.lost.read_to = fh.tell()
        finally:
            fh.close()



class _Ros1Salvage(_RecordSource):
    """A ROS1 ``.bag`` whose index is gone (a cut file): its records read in file order, chunk
    by chunk (none, bz2 or lz4, each decompressed bounded to its declared size and at most
    :func:`_chunk_cap`), up to the first record that does not parse."""

    def __init__(self, path: Path):
        self.path = path
        self.lost = _Salvage(path.stat().st_size)
        self._conns: dict[int, _Conn] = {}
        for _ in self._walk(None):
            pass
        self.connections = list(self._conns.values())

    @staticmethod
    def _fields(head: bytes) -> dict[str, bytes]:
        out, pos = {}, 0
        while pos + 4 <= len(head):
            n = int.from_bytes(head[pos:pos + 4], "little")
            item = head[pos + 4:pos + 4 + n]
            if n == 0 or len(item) < n or b"=" not in item:
                raise ValueError("a header field that does not parse")
            key, _, value = item.partition(b"=")
            out[key.decode("latin-1")] = value
            pos += 4 + n
        return out

    def _records(self, data, pos: int, end: int):
        """(fields, payload, end offset) of the records in ``data[pos:end]``."""
        while pos < end:
            if pos + 4 > end:
                raise ValueError("a record header cut short")
            hlen = int.from_bytes(data[pos:pos + 4], "little")
            _record_size(hlen)
            head = bytes(data[pos + 4:pos + 4 + hlen])
            dpos = pos + 4 + hlen
            if len(head) < hlen or dpos + 4 > end:
                raise ValueError("a record header cut short")
            dlen = int.from_bytes(data[dpos:dpos + 4], "little")
            _record_size(dlen)
            if dpos + 4 + dlen > end:
                raise ValueError("a record cut short")
            yield self._fields(head), data[dpos + 4:dpos + 4 + dlen], dpos + 4 + dlen
            pos = dpos + 4 + dlen

    def _walk(self, wanted: set | None):
        first = wanted is None
        fh = open_regular(self.path, "a ROS bag file")
        try:
            size = self.lost.size
            if size < len(_ROS1_MAGIC) or fh.read(len(_ROS1_MAGIC)) != _ROS1_MAGIC:
                if first:
                    self.lost.why = "no ROS1 bag header"
                return
            data = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
            try:
                outer = self._records(data, len(_ROS1_MAGIC), size)
                while True:
                    try:
                        item = next(outer, None)
                        if item is None:
                            break
                        fields, payload, stop = item
                        op = fields.get("op", b"\x00")[:1]
                        if op == b"\x05":                              # a chunk
                            comp = fields.get("compression", b"none").decode("latin-1")
                            declared = int.from_bytes(fields.get("size", b"\0\0\0\0")[:4], "little")
                            _record_size(declared)
                            body = (bytes(payload) if comp == "none" else
                                    decompress_bounded(bytes(payload), comp, declared, None,
                                                       f"a chunk declaring {format_size(declared)}"))
                            inner = list(self._records(body, 0, len(body)))
                        else:
                            inner = [(fields, payload, stop)]
                    except InputError as err:
                        if "decompresses to more than" in err.message:
                            raise                              # a bomb: refused, never salvaged
                        if first:
                            self.lost.why = err.message[:120]
                        break
                    except Exception as err:  # a cut or corrupt record: the salvage ends here
                        if first:
                            self.lost.why = f"{type(err).__name__}: {' '.join(str(err).split())[:120]}"
                        break
                    for f, body, _ in inner:
                        op = f.get("op", b"\x00")[:1]
                        if op == b"\x07" and first:                    # a connection
                            cid = int.from_bytes(f.get("conn", b"\0\0\0\0")[:4], "little")
                            if cid not in self._conns:
                                try:
                                    info = self._fields(bytes(body))
                                except ValueError:
                                    info = {}
                                self._conns[cid] = _Conn(
                                    cid, f.get("topic", b"").decode("utf-8", "replace"),
                                    _ros_type(info.get("type", b"").decode("utf-8", "replace")), "ros1")
                        elif op == b"\x02":                            # a message
                            cid = int.from_bytes(f.get("conn", b"\0\0\0\0")[:4], "little")
                            t = f.get("time", bytes(8))
                            ns = (int.from_bytes(t[:4], "little") * _NS_PER_S
                                  + int.from_bytes(t[4:8], "little"))
                            if cid not in self._conns:
                                continue
                            if first:
                                self._conns[cid].msgcount += 1
                                self.lost.messages += 1
                                self.lost.last_ns = ns
                            elif wanted is not None and cid in wanted:
                                yield cid, ns, bytes(body)
                    if first:
                        self.lost.read_to = stop
            finally:
                data.close()
        finally:
            fh.close()



def _ros1_chunked_reader(path: Path):
    """A rosbags ROS1 reader that keeps no per-message index (for :class:`BagStream`): its
    ``open`` counts each connection's messages from the index data records and notes where
    each chunk's records lie, and ``messages`` reads one chunk at a time, its index records
    then, sorted by (time, offset) as rosbags sorts the whole bag's. That is rosbags' order
    (time, chunk position, offset) when the chunks' time ranges do not overlap in file order
    (``in_order``, checked on open; otherwise the caller reads with rosbags' own reader)."""
    # deferred: with rosbags below (the reader is built only when a ROS1 bag is streamed)
    import os
    from collections import defaultdict
    from io import BytesIO

    # deferred: rosbags loads only when a bag is read
    from rosbags.interfaces import Connection
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag1 import reader as ros1_reader

    class ChunkedReader(Reader1):
        def open(self) -> None:
            self._counts: dict[int, int] = defaultdict(int)
            #: chunk position -> [(connection id, file offset of its index entries, count)]
            self._index_at: dict[int, list[tuple[int, int, int]]] = defaultdict(list)
            super().open()
            self.indexes = {}
            self.connections = [Connection(*x[0:5], self._counts[x.id], *x[6:])
                                for x in self.connections]
            infos = sorted(getattr(self, "chunk_infos", []), key=lambda c: c.pos)
            self.in_order = all(a.end_time <= b.start_time for a, b in zip(infos, infos[1:]))
            self._chunk_order = [c.pos for c in infos]

        def read_index_data(self, pos, indexes) -> None:
            """As rosbags' (the same checks of the record's header), keeping no entry: the
            connection's count and where its entries lie."""
            assert self.bio
            start = self.bio.tell()
            size = self._index_header()
            self._counts[self._last_conn] += size // 12
            self._index_at[pos].append((self._last_conn, start + 55, size // 12))
            self.bio.seek(start + 55 + size)

        def _index_header(self) -> int:
            """The IDXDATA record header at the position (55 bytes): its data size [bytes]."""
            assert self.bio
            buf = self.bio.read(55)
            if not self.index_data_header_offsets:
                (size,) = ros1_reader.deserialize_uint32(buf, 0)
                if size != 47:
                    raise ros1_reader.ReaderError("IDXDATA header of an unexpected size")
                idx, connpos, countpos = 4, -1, -1
                while idx < size:
                    char = buf[idx + 6]
                    if char == 61:        # op=
                        idx += 8
                    elif char == 114:     # ver=
                        if buf[idx + 8] != 1:
                            raise ros1_reader.ReaderError(f"IDXDATA version {buf[idx + 8]} is not supported.")
                        idx += 12
                    elif char == 110:     # conn=
                        connpos = idx + 9
                        idx += 13
                    else:                 # count=
                        countpos = idx + 10
                        idx += 14
                self.index_data_header_offsets = (connpos, countpos)
            connpos, countpos = self.index_data_header_offsets
            (self._last_conn,) = ros1_reader.deserialize_uint32(buf, connpos)
            (count,) = ros1_reader.deserialize_uint32(buf, countpos)
            (size,) = ros1_reader.deserialize_uint32(buf, 51)
            if size != count * 12:
                raise ros1_reader.ReaderError("IDXDATA size and count disagree")
            return size

        def messages(self, connections=(), start=None, stop=None):
            self._check_open()
            assert self.bio and start is None and stop is None
            connmap = {x.id: x for x in self.connections}
            wanted = {x.id for x in (connections or self.connections)}
            for pos in self._chunk_order:
                entries = []
                for conn, at, count in self._index_at.get(pos, ()):
                    if conn not in wanted:
                        continue
                    self.bio.seek(at)
                    buf = self.bio.read(count * 12)
                    if len(buf) != count * 12:
                        raise ros1_reader.ReaderError("IDXDATA entries cut short")
                    e = np.frombuffer(buf, "<u4").reshape(count, 3).astype(np.int64)
                    entries.append(np.column_stack([e[:, 0] * _NS_PER_S + e[:, 1], e[:, 2]]))
                if not entries:
                    continue
                table = np.vstack(entries)
                table = table[np.lexsort((table[:, 1], table[:, 0]))]   # by time, then offset
                head = self.chunks[pos]
                self.bio.seek(head.datapos)
                chunk = BytesIO(head.decompressor(ros1_reader.read_bytes(self.bio, head.datasize)))
                for t, offset in table.tolist():
                    chunk.seek(offset)
                    while True:
                        header = ros1_reader.Header.read(chunk)
                        have = header.get_uint8("op")
                        if have != ros1_reader.RecordType.CONNECTION:
                            break
                        chunk.seek(ros1_reader.read_uint32(chunk), os.SEEK_CUR)
                    if have != ros1_reader.RecordType.MSGDATA:
                        raise ros1_reader.ReaderError("Expected to find message data.")
                    data = ros1_reader.read_bytes(chunk, ros1_reader.read_uint32(chunk))
                    if header.get_time("time") != t:
                        raise ros1_reader.ReaderError("a message's time is not its index entry's")
                    yield connmap[header.get_uint32("conn")], t, data
                chunk.close()

    return ChunkedReader(path)


class _Bag:
    """An open bag: its reader, the topics and the typestore that decodes its messages."""

    def __init__(self, path: Path, info: dict | None = None, stream: bool = False):
        # deferred: rosbags (its readers and typestores) loads only when a bag is read
        from rosbags.rosbag1 import Reader as Reader1
        from rosbags.rosbag2 import Reader as Reader2
        from rosbags.typesys import Stores, get_typestore
        _guard_rosbags()
        self.path = path
        self.ros1 = path.name.lower().endswith(".bag")
        self.zstd_messages = False
        self._tmp: tempfile.TemporaryDirectory | None = None
        self.reader: Any = None
        #: the note on what a salvaged (truncated) bag lost, or None
        self.salvage_note: str | None = None
        #: what kind of file this is, for the notes (a ROS1-profile MCAP says so)
        self.kind = _kind(path)
        try:
            src = path
            if info is not None and info["compression_mode"] == "file":
                src = self._decompress_files(path, info)
            mcap_file = info is None and path.name.lower().endswith(".mcap")
            if mcap_file and _mcap_profile(path) == "ros1":
                self.kind = "ROS1-profile MCAP (schema ros1msg, messages ros1)"
                self._own(path, _McapSource(path, salvage=True), None)
            else:
                try:
                    self.reader = (_ros1_chunked_reader(src) if self.ros1 and stream else
                                   Reader1(src) if self.ros1 else Reader2(src))
                    self.reader.open()
                    if not getattr(self.reader, "in_order", True):   # chunks overlap in time:
                        self.reader.close()                          # rosbags' whole index
                        self.reader = Reader1(src)
                        self.reader.open()
                except InputError as err:
                    raise InputError(err.message, file=err.file or str(path)) from None
                except Exception as err:  # rosbags' errors, struct/sqlite/zstd ones: a bad file
                    self.reader = None
                    if info is None and (mcap_file or self.ros1):     # read what is readable
                        self._own(path, _McapSource(path, salvage=True) if mcap_file
                                  else _Ros1Salvage(path), err)
                    else:
                        raise _refusal(path, f"cannot open this {_kind(path)}: truncated or "
                                             f"corrupt? (salvage it with {_salvage_command(path)})",
                                       err) from None
            storage = getattr(self.reader, "storage", None)     # ROS2 only
            if info is not None:
                assert storage is not None                      # a ROS2 folder has its storage
                if info["compression_mode"] == "message":   # decompressed here, bounded
                    storage.metadata = storage.metadata._replace(compression_mode=None)
                    self.zstd_messages = True
                self._agree(info, storage)
                for st in storage.storages:
                    _bound_sql(st)
            else:
                _bound_sql(storage)
        except BaseException:
            self.close()
            raise
        store = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        self.decode = store.deserialize_ros1 if self.ros1 else store.deserialize_cdr

    def _own(self, path: Path, source, err: BaseException | None) -> None:
        """Read with gyroarray's own record reader (:class:`_McapSource`, :class:`_Ros1Salvage`);
        a truncated file gives what it holds with a note, or, holding no message, a refusal
        naming the salvage command."""
        lost = source.lost
        truncated = lost is not None and lost.read_to < lost.size
        if truncated and lost.messages == 0:
            why = f" ({lost.why})" if err is None and lost.why else ""
            raise _refusal(path, f"cannot open this {self.kind}: truncated or corrupt? no message "
                                 f"could be salvaged ({format_size(lost.size - lost.read_to)} of "
                                 f"{format_size(lost.size)} unread{why}); rebuild it with "
                                 f"{_salvage_command(path)}", err) from None
        if truncated:
            self.salvage_note = lost.note(path, _salvage_command(path))
        self.reader = source
        self.ros1 = self.ros1 or any(c.encoding == "ros1" for c in source.connections)

    def _agree(self, info: dict, folder_reader) -> None:
        """Each topic's message_count in metadata.yaml is what the storage files hold."""
        meta = self.path / "metadata.yaml"
        held: dict[str, int] = {}
        for st in folder_reader.storages:
            for c in st.connections:
                held[c.topic] = held.get(c.topic, 0) + int(c.msgcount)
        declared: dict[str, tuple[int, int]] = {}
        for k, entry in enumerate(info["topics_with_message_count"]):
            t = entry["topic_metadata"]["name"]
            k0, n = declared.get(t, (k, 0))
            declared[t] = (k0, n + entry["message_count"])
        for t, (k, n) in declared.items():
            if n != held.get(t, 0):
                raise _field(meta, f"topics_with_message_count[{k}].message_count",
                             f"{n} messages of topic {t}, but the storage files hold "
                             f"{held.get(t, 0)}; fix it with 'ros2 bag reindex'")

    def _decompress_files(self, path: Path, info: dict) -> Path:
        """A ROS2 folder in compression_mode 'file': its storage files decompressed (bounded by
        the budget and :data:`MAX_DECOMPRESSED_FILE_BYTES`, checked against the free space of
        $TMPDIR before and while writing) into a temporary folder with a plain metadata.yaml."""
        limit = min(max_memory(), MAX_DECOMPRESSED_FILE_BYTES)
        from gyroarray.core.outputs import remove_stale_temps, temp_prefix  # deferred: a rare path
        remove_stale_temps(tempfile.gettempdir(), once=True)   # a SIGKILLed run's (its pid gone)
        self._tmp = tmp_dir = tempfile.TemporaryDirectory(prefix=temp_prefix("gyroarray-bag"))
        tmp = Path(tmp_dir.name)
        names = []
        for f in _storage_paths(path, info):
            data = read_regular(f, "compressed ROS2 storage file", max_bytes=max(1 << 20, max_memory() // 4))
            declared = _zstd_content_size(data)
            if declared is not None and declared > limit:
                raise InputError(f"declares {format_size(declared)} once decompressed, more than the "
                                 f"{format_size(limit)} gyroarray decompresses (raise --max-memory "
                                 "if it is a real bag)", file=str(f))
            check_disk_space(tmp.parent, declared or len(data), f"decompressing {f.name}",
                             file=str(f))
            free = shutil.disk_usage(tmp).free
            out = tmp / (f.name[:-5] if f.name.lower().endswith(".zstd") else f.name)
            written = [0]
            with open(out, "xb") as fh:
                def sink(piece, fh=fh, name=f.name):
                    written[0] += len(piece)
                    if written[0] + (64 << 20) > free:
                        raise InputError(f"decompressing {name} needs more than "
                                         f"{format_size(written[0])} of disk in {tmp.parent}, but only "
                                         f"{format_size(free)} was free; free some space or point "
                                         "$TMPDIR at a larger disk", file=str(f))
                    fh.write(piece)
                decompress_bounded(data, "zstd", limit, str(f), f"{f.name}", sink=sink)
            del data
            if info["storage_identifier"] == "sqlite3":
                try:
                    _check_db3(out)
                except InputError as err:
                    raise InputError(err.message, file=str(f)) from None
            names.append(out.name)
        plain = {k: info[k] for k in ("version", "storage_identifier", "duration", "starting_time",
                                      "message_count")}
        plain["relative_file_paths"] = names
        plain["compression_mode"], plain["compression_format"] = "", ""
        plain["topics_with_message_count"] = [
            {"message_count": e["message_count"],
             "topic_metadata": {"name": e["topic_metadata"]["name"],
                                "type": e["topic_metadata"]["type"],
                                "serialization_format": e["topic_metadata"]["serialization_format"],
                                "offered_qos_profiles": (
                                    e["topic_metadata"].get("offered_qos_profiles", "")
                                    if isinstance(e["topic_metadata"].get("offered_qos_profiles", ""),
                                                  str) else ""),
                                "type_description_hash": str(
                                    e["topic_metadata"].get("type_description_hash") or "")}}
            for e in info["topics_with_message_count"]]
        (tmp / "metadata.yaml").write_text(json.dumps({_META: plain}))
        return tmp

    def messages(self, conns):
        """(receive time [ns], raw message) of ``conns`` in the bag's order: bytes (refused
        otherwise: an sqlite NULL, REAL, TEXT or INTEGER), at most :data:`MAX_MESSAGE_BYTES`
        (zstd messages decompressed in bounded pieces)."""
        for _, received, raw in self.reader.messages(connections=conns):
            if not isinstance(raw, (bytes, bytearray, memoryview)):
                raise InputError(f"the message data is {_sql_kind(raw)}, not bytes (an sqlite "
                                 "BLOB): corrupt bag?")
            if self.zstd_messages:
                raw = decompress_bounded(raw, "zstd", MAX_MESSAGE_BYTES, None, "the message")
            elif len(raw) > MAX_MESSAGE_BYTES:
                raise InputError(f"a message of {format_size(len(raw))}, more than the "
                                 f"{format_size(MAX_MESSAGE_BYTES)} a {IMU_TYPE} takes: corrupt?")
            yield int(received), bytes(raw)

    def close(self) -> None:
        try:
            if self.reader is not None:
                self.reader.close()
        except Exception:  # closing a reader of a corrupt file: nothing left to report
            pass
        self.reader = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def topics(self) -> dict[str, tuple[str, int]]:
        """``{topic: (message type, message count)}``."""
        out: dict[str, tuple[str, int]] = {}
        assert self.reader is not None                  # open until close()
        for c in self.reader.connections:
            kind, n = out.get(c.topic, (c.msgtype, 0))
            out[c.topic] = (kind if kind == c.msgtype else "mixed types", n + int(c.msgcount))
        return out


def _zstd_content_size(data: bytes) -> int | None:
    """The decompressed size a zstd frame declares, or None (unknown, not zstd)."""
    try:
        try:
            from compression import zstd  # type: ignore[import-not-found]
        except ImportError:  # Python < 3.14: the backport rosbags depends on
            from backports import zstd  # type: ignore[import-not-found,no-redef,unused-ignore]
        size = zstd.get_frame_info(data[:32]).decompressed_size
    except Exception:  # not a zstd frame: decompress_bounded says so
        return None
    return size if isinstance(size, int) and size >= 0 else None


def _bound_sql(storage) -> None:
    """A progress handler on an sqlite storage's connection: no query runs without end."""
    con = getattr(storage, "dbconn", None)
    if con is None:
        return
    ticks = [0, _SQL_TICKS_FIXED + Path(storage.path).stat().st_size // 4]

    def tick() -> bool:
        ticks[0] += 1
        return ticks[0] > ticks[1]
    setter = getattr(con, "set_progress_handler", None) or getattr(con, "setprogresshandler")
    setter(tick, _SQL_STEPS)


def imu_topics(path) -> dict[str, int]:
    """The ``sensor_msgs/msg/Imu`` topics of a bag and their message counts.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.bag``, ``.db3`` or ``.mcap`` file or a ROS2 bag folder.

    Returns
    -------
    dict
        ``{topic: message count}``, in the bag's order.
    """
    p = Path(path)
    bag = _Bag(p, _check_path(p))
    try:
        return {t: n for t, (kind, n) in bag.topics().items() if kind == IMU_TYPE}
    finally:
        bag.close()


def _pick_topics(path: Path, topics: dict[str, tuple[str, int]], topic: str | None) -> list[str]:
    imu = [t for t, (kind, _) in topics.items() if kind == IMU_TYPE]
    listed = ", ".join(f"{t} ({topics[t][1]} messages)" for t in imu)
    if topic is None:
        if not imu:
            others = ", ".join(f"{t} ({k})" for t, (k, _) in topics.items()) or "none"
            raise _refusal(path, f"no {IMU_TYPE} topic in this bag (its topics: {others})")
        if len(imu) > 1:
            raise _refusal(path, f"{len(imu)} IMU topics: {listed}; pick one with --topic "
                                 f"{imu[0]}, or read them as an array with --topic {','.join(imu)}")
    chosen = imu if topic is None else [t.strip() for t in str(topic).split(",")]
    for t in chosen:
        if not t:
            raise _refusal(path, f"--topic {topic!r} has an empty topic name; give topics "
                                 "separated by commas, e.g. --topic /imu0,/imu1")
        if chosen.count(t) > 1:
            raise _refusal(path, f"--topic names {t} twice; each IMU topic once")
        if t not in topics:
            raise _refusal(path, f"no topic {t} in this bag; its IMU topics: {listed or 'none'}",
                           topic=t)
        if topics[t][0] != IMU_TYPE:
            raise _refusal(path, f"the messages are {topics[t][0]}, not {IMU_TYPE}; its IMU "
                                 f"topics: {listed or 'none'}", topic=t)
        if topics[t][1] == 0:
            raise _refusal(path, "the topic has no messages (an empty topic); record the IMU or "
                                 "pick another topic", topic=t)
    return chosen


class _Record:
    """One topic's samples: header and receive stamps [ns], rates [rad/s], specific force
    [m/s²]."""

    def __init__(self, topic: str, stamps_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray | None,
                 frame_id: str, receive_ns: np.ndarray | None = None):
        self.topic, self.stamps_ns, self.gyro, self.acc, self.frame_id = (
            topic, stamps_ns, gyro, acc, frame_id)
        self.receive_ns = stamps_ns if receive_ns is None else receive_ns


def _topic_batches(bag: _Bag, topic: str, count: int, size: int = _BATCH):
    """(header stamps [ns], receive times [ns], values) of ``topic``'s messages, ``size`` at a
    time (values: angular velocity, linear acceleration, its covariance[0]); the type was
    checked by name."""
    path = bag.path
    assert bag.reader is not None
    conns = [c for c in bag.reader.connections if c.topic == topic]
    i, batch, received = 0, list[bytes](), list[int]()
    it = iter(bag.messages(conns))
    while True:
        try:
            item = next(it, None)
        except InputError as err:  # a message that is no bytes, a bomb: said as it is
            raise _refusal(path, err.message, topic=topic, index=i + len(batch) + 1) from None
        except Exception as err:  # a chunk or record that does not parse: truncated or corrupt
            raise _refusal(path, f"cannot read past this message of the {_kind(path)}: truncated "
                                 f"or corrupt? (salvage it with {_salvage_command(path)})", err,
                           topic=topic, index=i + len(batch) + 1) from None
        if item is not None:
            if i + len(batch) >= count:
                raise _refusal(path, f"more messages than the bag's index counts ({count}): "
                                     "corrupt index?", topic=topic, index=i + len(batch) + 1)
            received.append(item[0])
            batch.append(item[1])
        if batch and (item is None or len(batch) == size):
            stamps = np.empty(len(batch), dtype=np.int64)
            values = np.empty((len(batch), 7))
            _decode_batch(bag, batch, 0, topic, stamps, values, n0=i)
            yield stamps, np.array(received, dtype=np.int64), values
            i, batch, received = i + len(batch), [], []
        if item is None:
            break
    if i < count:
        raise _refusal(path, f"the bag's index counts {count} messages but only {i} could be read: "
                             "truncated?", topic=topic, index=i + 1)


def _read_topic(bag: _Bag, topic: str, count: int) -> _Record:
    """Decode every message of ``topic`` (the type was checked by name), in batches."""
    path = bag.path
    check_memory(count * float(_BYTES_PER_MESSAGE), f"{count} messages of topic {topic}",
                 "split the bag (e.g. 'ros2 bag convert' or 'rosbag filter'), raise --max-memory, "
                 "or 'gyroarray convert' it (in bounded memory) to Parquet first", file=str(path))
    stamps = np.empty(count, dtype=np.int64)
    received = np.empty(count, dtype=np.int64)
    values = np.empty((count, 7))           # angular velocity, linear acceleration, its cov[0]
    i = 0
    for st, rc, v in _topic_batches(bag, topic, count):
        stamps[i:i + st.size], received[i:i + st.size], values[i:i + st.size] = st, rc, v
        i += st.size
    gyro, acc = values[:, :3], values[:, 3:6]
    _check_values(path, topic, 0, gyro)
    _enough(path, topic, count)
    keep_acc = not np.any(values[:, 6] == -1.0) and np.all(np.isfinite(acc)) and acc.any()
    conns = [c for c in bag.reader.connections if c.topic == topic]
    return _Record(topic, stamps, gyro, acc if keep_acc else None, _frame_id(bag, conns), received)


def _frame_id(bag: _Bag, conns) -> str:
    """The first message's header.frame_id (for the notes)."""
    for _, raw in bag.messages(conns):
        msg: Any = bag.decode(raw, IMU_TYPE)
        return str(msg.header.frame_id)
    return ""


def _decode_one(bag: _Bag, raw: bytes) -> tuple[int, list[float]]:
    msg: Any = bag.decode(raw, IMU_TYPE)        # a sensor_msgs/msg/Imu of the typestore
    stamp, w, a = msg.header.stamp, msg.angular_velocity, msg.linear_acceleration
    return (int(stamp.sec) * _NS_PER_S + int(stamp.nanosec),
            [w.x, w.y, w.z, a.x, a.y, a.z, float(msg.linear_acceleration_covariance[0])])


def _decode_batch(bag: _Bag, raws: list[bytes], i0: int, topic: str, stamps: np.ndarray,
                  values: np.ndarray, n0: int = 0) -> None:
    """Messages ``i0 ..`` into ``stamps`` [ns] and ``values``: by fixed offsets when every
    message of the batch has the same layout and three of them decode identically through the
    typestore, else one by one through the typestore. ``n0``: the messages before ``stamps[0]``
    (for the index a refusal names)."""
    fast = _fixed_layout(raws, bag.ros1)
    if fast is not None:
        n = len(raws)
        for j in sorted({0, n // 2, n - 1}):
            try:
                ns, v = _decode_one(bag, raws[j])
            except Exception:  # the one-by-one path below locates the problem
                fast = None
                break
            if ns != fast[0][j] or not np.array_equal(np.array(v), fast[1][j], equal_nan=True):
                fast = None
                break
    if fast is not None:
        stamps[i0:i0 + len(raws)], values[i0:i0 + len(raws)] = fast
        return
    for j, raw in enumerate(raws):
        length = _frame_id_overrun(raw, bag.ros1)
        if length is not None:
            raise _refusal(bag.path, f"header.frame_id declares {length} bytes, more than the "
                                     f"{len(raw)}-byte message holds: corrupt?", topic=topic,
                           index=n0 + i0 + j + 1)
        try:
            stamps[i0 + j], values[i0 + j] = _decode_one(bag, raw)
        except Exception as err:  # bytes that are no sensor_msgs/msg/Imu: a corrupt message
            raise _refusal(bag.path, f"this message does not decode as {IMU_TYPE}: corrupt?", err,
                           topic=topic, index=n0 + i0 + j + 1) from None


def _frame_id_overrun(raw: bytes, ros1: bool) -> int | None:
    """The header.frame_id length a message declares when it does not fit in the message
    (checked before the typestore sees it), else None."""
    if len(raw) < 16 or (not ros1 and raw[:2] != b"\x00\x01"):   # CDR_LE only; others: typestore
        return None
    length = int.from_bytes(raw[12:16], "little")
    return length if 16 + length + _IMU_DOUBLES * 8 > len(raw) else None


def _fixed_layout(raws: list[bytes], ros1: bool) -> tuple[np.ndarray, np.ndarray] | None:
    """(stamps [ns], values) of same-length messages with one frame_id length, read at the
    offsets of sensor_msgs/msg/Imu (ROS1 serialisation, or little-endian CDR with its 8-byte
    alignment after the 4-byte encapsulation header); None when the batch is not that regular."""
    size = len(raws[0])
    if size < 16 or any(len(r) != size for r in raws):
        return None
    buf = np.frombuffer(b"".join(raws), dtype=np.uint8).reshape(len(raws), size)
    if not ros1 and not (np.all(buf[:, 0] == 0) and np.all(buf[:, 1] == 1)):   # CDR_LE only
        return None
    lengths = buf[:, 12:16].copy().view("<u4")[:, 0]
    if np.any(lengths != lengths[0]):
        return None
    pos = 16 + int(lengths[0])
    if not ros1:
        pos = 4 + -(-(pos - 4) // 8) * 8
    if pos + _IMU_DOUBLES * 8 > size:
        return None
    sec = buf[:, 4:8].copy().view("<u4" if ros1 else "<i4")[:, 0].astype(np.int64)
    nsec = buf[:, 8:12].copy().view("<u4")[:, 0].astype(np.int64)
    doubles = buf[:, pos:pos + _IMU_DOUBLES * 8].copy().view("<f8")
    # orientation 4, its covariance 9, angular_velocity 3, covariance 9, linear_acceleration 3,
    # covariance 9
    values = np.hstack([doubles[:, 13:16], doubles[:, 25:28], doubles[:, 28:29]])
    return sec * _NS_PER_S + nsec, values


def _check_values(path: Path, topic: str, i0: int, gyro: np.ndarray) -> None:
    """Refuse a non-finite rate or one beyond :data:`MAX_RATE_DEG_S` (messages from ``i0``)."""
    bad = ~np.all(np.isfinite(gyro), axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise _refusal(path, f"angular_velocity is not finite ({gyro[k].tolist()}); remove or "
                             "repair that message", topic=topic, index=i0 + k + 1)
    big = np.abs(units.rad_s_to_deg_s(gyro)) > MAX_RATE_DEG_S
    if big.any():
        k = int(np.flatnonzero(big.any(axis=1))[0])
        raise _refusal(path, f"angular_velocity {gyro[k].tolist()} rad/s is beyond "
                             f"{MAX_RATE_DEG_S:g} deg/s: not a rate in rad/s (REP 103)?",
                       topic=topic, index=i0 + k + 1)


def _enough(path: Path, topic: str, n: int) -> None:
    if n < MIN_SAMPLES:
        raise _refusal(path, f"{n} message: a measurement needs at least {MIN_SAMPLES}",
                       topic=topic)


def _stamp(ns) -> str:
    """``1700000000.123456789`` from integer nanoseconds."""
    s, n = divmod(int(ns), _NS_PER_S)
    return f"{s}.{n:09d}"


class _Clock:
    """A topic's stamps sorted into a regular clock with dropped messages, chunk by chunk (the
    same answer read whole or streamed; the rule is in :func:`read_bag`).

    For message i (0-based) the deficit is D_i = (t_i − t_0) / P − i [steps], P the period [ns].
    A regular clock keeps D constant; a dropped message raises it by one for good; clock drift
    ramps it slowly; jitter moves single stamps. The local grid is the running median of D
    over 2 :data:`JITTER_WINDOW` + 1 messages (it follows drops and drift, not jitter): where
    it jumps up by more than ``GAP_FACTOR − 1`` steps, round(jump) messages were dropped (a
    gap); a stamp more than :data:`JITTER_MAX_STEPS` from it, or a jump down (more messages
    than the span holds), is bunched: refused, naming the message, unless re-timed."""

    def __init__(self, path: Path, topic: str, which: str, t0_ns: int, period_ns: float,
                 mode: str):
        self.path, self.topic, self.which, self.t0, self.P, self.mode = (
            path, topic, which, int(t0_ns), float(period_ns), mode)   # mode: refuse|keep|repair
        self.n = 0                                 # messages fed
        self.done = 0                              # messages whose grid is settled
        self.b0 = 0                                # global index of self.D[0]
        self.D = np.empty(0)
        self.T = np.empty(0, dtype=np.int64)
        self.last_b: float | None = None
        self.gaps: list[tuple[int, int, int]] = []     # (message after it, missing, step [ns])
        self.worst_dev = (0.0, 0)                      # |stamp - grid| [steps], message
        self.worst_step = 0.0                          # |step - (1 + missing) P| [ns]
        self.sumsq, self.nsteps = 0.0, 0

    def feed(self, stamps: np.ndarray, final: bool = False) -> None:
        """The next stamps [ns] of the topic (``final``: the last ones)."""
        stamps = np.asarray(stamps, dtype=np.int64)
        prev = self.T[-1:] if self.T.size else np.empty(0, dtype=np.int64)
        _check_increasing(self.path, self.topic, self.which, stamps, self.n, prev)
        idx = np.arange(self.n, self.n + stamps.size, dtype=np.float64)
        d = (stamps - self.t0) / self.P - idx
        self.D = np.concatenate([self.D, d])
        self.T = np.concatenate([self.T, stamps])
        self.n += stamps.size
        self._settle(final)

    def _settle(self, final: bool) -> None:
        h = JITTER_WINDOW
        end = self.n if final else self.n - h
        if end <= self.done:
            return
        lo_pad = max(0, h - (self.done - self.b0))
        hi_pad = max(0, end + h - self.n)
        x = self.D[self.done - h + lo_pad - self.b0:end + h - hi_pad - self.b0]
        x = np.concatenate([np.full(lo_pad, self.D[0]), x, np.full(hi_pad, self.D[-1])])
        grid = np.median(np.lib.stride_tricks.sliding_window_view(x, 2 * h + 1), axis=1)
        a, b = self.done - self.b0, end - self.b0
        dev = self.D[a:b] - grid
        jump = np.diff(np.concatenate([[grid[0] if self.last_b is None else self.last_b], grid]))
        if self.last_b is None:
            jump[0] = 0.0
        for k in np.flatnonzero(jump < -(GAP_FACTOR - 1.0)).tolist():
            i = self.done + k
            self._bunched(i, f"{-jump[k]:.3g} more messages than the time span holds at the "
                             f"{self.P / 1e9:.6g} s step")
        big = np.flatnonzero(np.abs(dev) > JITTER_MAX_STEPS)
        if big.size:
            k = int(big[0])
            self._bunched(self.done + k, f"the {self.which} stamp is {dev[k]:+.3g} steps from its "
                                         f"slot on the regular {self.P / 1e9:.6g} s grid, beyond the "
                                         f"{JITTER_MAX_STEPS:g}-step jitter tolerance")
        missing = np.zeros(b - a, dtype=np.int64)
        for k in np.flatnonzero(jump > GAP_FACTOR - 1.0).tolist():
            i = self.done + k
            m = max(1, int(round(jump[k])))
            missing[k] = m
            step = int(self.T[i - self.b0] - self.T[i - 1 - self.b0])
            self._gap(i, m, step)
        if dev.size:
            k = int(np.argmax(np.abs(dev)))
            if abs(dev[k]) > self.worst_dev[0]:
                self.worst_dev = (float(abs(dev[k])), self.done + k)
        lo = max(a, 1)                  # steps into messages a..b-1 (the first has none)
        if b > lo:
            steps = np.diff(self.T[lo - 1:b]).astype(np.float64) - (1 + missing[lo - a:]) * self.P
            self.worst_step = max(self.worst_step, float(np.abs(steps).max()))
            self.sumsq += float(np.sum(steps ** 2))
            self.nsteps += steps.size
        self.last_b = float(grid[-1])
        self.done = end
        keep = max(0, self.done - h - self.b0)
        self.D, self.T, self.b0 = self.D[keep:], self.T[keep:], self.b0 + keep

    def _bunched(self, i: int, what: str) -> None:
        raise _refusal(self.path, f"{what}: bunched or irregular stamps; rerun with --retime to "
                                  "re-time them onto a uniform grid at the mean step (or try "
                                  f"--stamps {'receive' if self.which == 'header' else 'header'})",
                       topic=self.topic, index=i + 1)

    def _gap(self, i: int, missing: int, step_ns: int) -> None:
        self.gaps.append((i, missing, step_ns))
        if self.mode == "keep" or (self.mode == "repair" and missing <= MAX_REPAIR_SAMPLES):
            return
        way = ("re-record, or keep it as a gap with --gaps (allan pools the contiguous parts)"
               if self.mode == "repair" else
               f"rerun with --gaps to keep it as a gap, nothing interpolated (allan pools the "
               f"contiguous parts), or --repair to fill gaps of up to {MAX_REPAIR_SAMPLES} samples "
               "by linear interpolation")
        raise _refusal(self.path, f"a gap of {step_ns / 1e9:.6g} s ({missing} missing messages at "
                                  f"the {self.P / 1e9:.6g} s step) before this message; {way}",
                       topic=self.topic, index=i + 1)

    def jittery(self) -> bool:
        """True when a step differs from its nominal (1 + missing) P by more than JITTER_TOL."""
        return self.worst_step > JITTER_TOL * self.P

    def notes(self) -> list[str]:
        """The jitter and the gaps kept, said with the rule."""
        out = []
        P = self.P / 1e9
        if self.jittery():
            rms = math.sqrt(self.sumsq / max(self.nsteps, 1)) / 1e9
            out.append(f"{self.path}: topic {self.topic}: the {self.which} stamps jitter: steps "
                       f"differ from the {P:.6g} s median step by up to {self.worst_step / 1e9:.3g} s "
                       f"({100 * self.worst_step / self.P:.3g} % of it; rms {rms:.3g} s), every stamp "
                       f"within {self.worst_dev[0]:.3g} steps of its slot on the regular grid "
                       f"(tolerance {JITTER_MAX_STEPS:g} step, the local grid the running median "
                       f"of {2 * JITTER_WINDOW + 1} messages): accepted as a regular "
                       f"{1 / P:.6g} Hz clock; the analyses assume the uniform step (--repair "
                       "resamples onto it)")
        if self.gaps and self.mode == "keep":
            missing = sum(m for _, m, _ in self.gaps)
            first = ", ".join(f"before message {i + 1} ({m})" for i, m, _ in self.gaps[:5])
            more = f", and {len(self.gaps) - 5} more" if len(self.gaps) > 5 else ""
            out.append(f"{self.path}: topic {self.topic}: {len(self.gaps)} gap(s) in time_s kept "
                       f"as they are ({missing} message(s) dropped at the {P:.6g} s step: "
                       f"{first}{more}), nothing interpolated")
        return out


def _check_increasing(path: Path, topic: str, which: str, stamps: np.ndarray, n0: int = 0,
                      prev: np.ndarray | None = None) -> None:
    """Refuse a stamp that repeats or goes backwards (messages from ``n0``; ``prev``: the
    stamp before them), naming the message and --retime."""
    prev = np.empty(0, dtype=np.int64) if prev is None else prev
    both = np.concatenate([prev, stamps])
    step = np.diff(both)
    if not np.any(step <= 0):
        return
    k = int(np.flatnonzero(step <= 0)[0])
    at = n0 + k + (0 if prev.size else 1)                   # 0-based index of the message
    before, after = int(both[k]), int(both[k + 1])
    how = "repeats" if after == before else "goes backwards"
    hint = ("header stamps must increase (a driver that leaves header.stamp unset, or a "
            "merged bag?)" if which == "header" else "receive stamps must increase")
    raise _refusal(path, f"the {which} stamp {how} ({_stamp(after)} s after {_stamp(before)} s); "
                         f"{hint}; rerun with --retime to re-time bunched or repeated stamps onto "
                         "a uniform grid" + ("" if which == "receive" else ", or try --stamps receive"),
                   topic=topic, index=at + 1)


def _check_bunching(path: Path, topic: str, which: str, stamps_ns: np.ndarray,
                    period_ns: float) -> None:
    """Refuse stamps whose median step is below 1 / :data:`MAX_MEAN_TO_MEDIAN_STEP` of their
    mean step: more than half the slots of the median-step clock would be gaps, which is
    bunching (messages stamped in bursts), not a clock with drops."""
    if stamps_ns.size < 3:
        return
    mean = (int(stamps_ns[-1]) - int(stamps_ns[0])) / (stamps_ns.size - 1)
    if mean <= MAX_MEAN_TO_MEDIAN_STEP * period_ns:
        return
    step = np.diff(stamps_ns)
    k = int(np.flatnonzero(step > GAP_FACTOR * period_ns)[0])
    raise _refusal(path, f"the {which} stamps come in bursts: the median step "
                         f"{period_ns / 1e9:.3g} s is less than 1/{MAX_MEAN_TO_MEDIAN_STEP:g} of "
                         f"the mean step {mean / 1e9:.3g} s (a burst ends here): bunched stamps; "
                         "rerun with --retime to re-time them onto a uniform grid at the mean "
                         f"step (or try --stamps {'receive' if which == 'header' else 'header'})",
                   topic=topic, index=k + 2)


def _period_ns(stamps_ns: np.ndarray) -> float:
    """The median stamp step [ns] (exact for the integer steps of an odd count)."""
    return float(np.median(np.diff(stamps_ns)))


def _retime(path: Path, topic: str, which: str, stamps_ns: np.ndarray) -> tuple[np.ndarray, float, str]:
    """(time_s, period [s], note) on the uniform grid: the rule of ``--retime``."""
    n = stamps_ns.size
    span = int(stamps_ns[-1] - stamps_ns[0])
    if span <= 0:
        raise _refusal(path, f"the {which} stamps span {span / 1e9:.6g} s over {n} messages: no "
                             "time base to re-time onto; try --stamps "
                             f"{'receive' if which == 'header' else 'header'}", topic=topic)
    period = span / (n - 1) / 1e9
    shift = ((stamps_ns - stamps_ns[0]) - np.arange(n) * (span / (n - 1))) / (span / (n - 1))
    k = int(np.argmax(np.abs(shift)))
    if abs(shift[k]) > RETIME_MAX_SHIFT_STEPS:
        raise _refusal(path, f"--retime: the {which} stamp is {shift[k]:+.3g} steps from its time on "
                             f"the uniform {period:.6g} s grid, beyond {RETIME_MAX_SHIFT_STEPS:g} steps: "
                             "dropped messages or a rate change, not bunching (cut the record "
                             "there, or read without --retime with --gaps)", topic=topic, index=k + 1)
    time_s = np.arange(n) * period
    note = (f"{path}: topic {topic}: re-timed (--retime): {n} messages put on a uniform grid from "
            f"the first {which} stamp at the mean step {period:.6g} s (span / (n - 1)); the largest "
            f"shift {abs(shift[k]):.3g} steps at message {k + 1} (at most "
            f"{RETIME_MAX_SHIFT_STEPS:g} accepted); the rule assumes no message was dropped")
    return time_s, period, note


def _uniform(path: Path, rec: _Record, t0_ns: int, repair: bool, gaps: bool = False,
             which: str = "header", retime: bool = False
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, list[str], float]:
    """(time_s from t0, rates, specific force, notes, period [s]) of one topic: gaps refused,
    kept (``gaps``) or filled (``repair``); jitter within the tolerance noted or resampled
    (``repair``); bunched stamps refused or re-timed (``retime``)."""
    stamps = rec.stamps_ns if which == "header" else rec.receive_ns
    if retime:
        t, period, note = _retime(path, rec.topic, which, stamps)
        return t, rec.gyro, rec.acc, [note], period
    period_ns = _period_ns(stamps)
    _check_increasing(path, rec.topic, which, stamps)
    _check_bunching(path, rec.topic, which, stamps, period_ns)
    clock = _Clock(path, rec.topic, which, int(stamps[0]), period_ns,
                   "keep" if gaps else "repair" if repair else "refuse")
    for a in range(0, stamps.size, _BATCH):
        clock.feed(stamps[a:a + _BATCH], final=a + _BATCH >= stamps.size)
    t = (stamps - t0_ns) / 1e9
    period = period_ns / 1e9
    notes = clock.notes()
    if not repair or not (clock.jittery() or clock.gaps):
        return t, rec.gyro, rec.acc, notes, period
    if gaps and clock.gaps:
        if not clock.jittery():
            return t, rec.gyro, rec.acc, notes, period
        raise _refusal(path, f"the stamps jitter by up to {clock.worst_step / 1e9:.3g} s and the "
                             f"record has {len(clock.gaps)} gap(s): resampling onto the uniform "
                             "step would fill them; leave out --repair to keep the stamps as they "
                             "are (the jitter is noted), or without --gaps to have short gaps "
                             "filled",
                       topic=rec.topic)
    rel = t - t[0]
    grid = np.arange(int(round(rel[-1] / period)) + 1) * period
    grid = grid[grid <= rel[-1]]
    gyro = np.column_stack([np.interp(grid, rel, rec.gyro[:, j]) for j in range(3)])
    acc = (None if rec.acc is None else
           np.column_stack([np.interp(grid, rel, rec.acc[:, j]) for j in range(3)]))
    filled = f", {len(clock.gaps)} gap(s) filled" if clock.gaps else ""
    what = (f"the {which} stamp steps jitter by up to {clock.worst_step / 1e9:.3g} s"
            if clock.jittery() else "the stamps are regular")
    notes = [f"{path}: repaired: topic {rec.topic}: {what}{filled}; resampled {t.size} messages "
             f"onto {grid.size} samples at the median step from the first stamp, by linear "
             "interpolation in time"]
    return grid + t[0], gyro, acc, notes, period


def _align(path: Path, parts: list, topics: list[str]) -> tuple[np.ndarray, list[np.ndarray], list[str]]:
    """Put every topic on the first one's stamps (common stamps as they are, else interpolated)."""
    t_ref = parts[0][0]
    if all(p[0].shape == t_ref.shape and np.array_equal(p[0], t_ref) for p in parts[1:]):
        return t_ref, [p[1] for p in parts], [f"{path}: topics {', '.join(topics)} share their "
                                              "stamps; no interpolation"]
    lo = max(float(p[0][0]) for p in parts)
    hi = min(float(p[0][-1]) for p in parts)
    keep = (t_ref >= lo) & (t_ref <= hi)
    if int(keep.sum()) < MIN_SAMPLES:
        raise _refusal(path, f"the topics {', '.join(topics)} do not overlap in time (common span "
                             f"{max(hi - lo, 0.0):.6g} s); record the IMUs together")
    t = t_ref[keep]
    rates = [parts[0][1][keep]]
    notes = []
    for (tk, gk, _), name in zip(parts[1:], topics[1:]):
        rates.append(np.column_stack([np.interp(t, tk, gk[:, j]) for j in range(3)]))
        notes.append(f"{path}: topic {name}'s stamps differ from {topics[0]}'s; its rates are "
                     f"interpolated linearly in time onto {topics[0]}'s stamps")
    if t.size < t_ref.size:
        notes.append(f"{path}: kept the common span of the topics: {t.size} of {t_ref.size} samples "
                     f"of {topics[0]}")
    return t, rates, notes


def _check_stamps_option(path: Path, stamps: str) -> str:
    if stamps not in STAMPS:
        raise InputError(f"stamps must be one of {', '.join(STAMPS)}, got {stamps!r}", file=str(path))
    return stamps


def read_bag(path, *, topic: str | None = None, extrinsics=None, repair: bool = False,
             gaps: bool = False, stamps: str = "header", retime: bool = False) -> Measurement:
    """Read the IMU topic(s) of a ROS bag as a measurement.

    Parameters
    ----------
    path : str or os.PathLike
        A ROS1 ``.bag``, a ROS2 ``.db3`` or ``.mcap`` file (a ROS1-profile MCAP too), or a
        ROS2 bag folder.
    topic : str, optional
        The ``sensor_msgs/msg/Imu`` topic (``/imu0``), or several separated by commas (an
        array). Default: the bag's one IMU topic.
    extrinsics : str or os.PathLike, optional
        Kalibr imu-chain YAML with ``imuN: T_i_b`` (4x4, body to IMU) per topic.
    repair : bool
        Fill gaps of up to ``MAX_REPAIR_SAMPLES`` samples and resample a jittering clock onto
        its median step, by linear interpolation in time (default: refuse gaps, note jitter).
    gaps : bool
        Keep dropped messages as gaps in ``time_s``, never filled, with a note counting them
        (``gyroarray allan --gaps`` pools the contiguous parts); default: refuse them.
    stamps : {"header", "receive"}
        The time base: each message's ``header.stamp`` (default) or the bag's receive (log)
        time of the message; the notes and the description say which.
    retime : bool
        Re-time bunched or repeated stamps: ``time_s[k] = k · (t_last − t_first) / (n − 1)``,
        the uniform grid from the first stamp at the mean step, accepted while every stamp is
        within :data:`RETIME_MAX_SHIFT_STEPS` steps of its grid time (default: such stamps are
        refused, naming the message).

    Returns
    -------
    Measurement
        ``time_s`` [s] from the first stamp, gyro outputs [deg/s] (3 per IMU: its x, y, z
        axes), ``sample_rate_hz`` [Hz] from the median stamp step (the mean step when
        re-timed), ``acc_m_s2`` [m/s²] for a single IMU that publishes it; ``source`` is the
        bag, ``topics`` the topics read.

    Raises
    ------
    InputError
        One line naming the bag, the topic and the message index (see the module docstring).

    Notes
    -----
    The clock rule (:class:`_Clock`): the period P is the median stamp step; message i's
    deficit D_i = (t_i − t_0)/P − i is constant on a regular clock; its running median over
    2·:data:`JITTER_WINDOW` + 1 messages is the local grid. A jump of the grid by more than
    ``GAP_FACTOR − 1`` steps is round(jump) dropped messages (a gap); a stamp within
    :data:`JITTER_MAX_STEPS` of the grid is jitter (accepted, noted when a step differs from P
    by more than ``JITTER_TOL``); farther, or a grid jumping down, is bunching (refused
    unless ``retime``). A truncated ``.mcap`` or ``.bag`` is read up to the first record that
    does not parse, with a note of what was lost; holding nothing, it is refused with the
    salvage command (``mcap recover``, ``rosbag reindex``; ``.db3``: sqlite3's ``.recover``).
    """
    p = Path(path)
    which = _check_stamps_option(p, stamps)
    bag = _Bag(p, _check_path(p))
    try:
        all_topics = bag.topics()
        chosen = _pick_topics(p, all_topics, topic)
        layout, ext_notes = _layout(p, chosen, extrinsics)     # before the (long) read
        records = [_read_topic(bag, t, all_topics[t][1]) for t in chosen]
    finally:
        bag.close()
    base = [r.stamps_ns if which == "header" else r.receive_ns for r in records]
    t0_ns = int(base[0][0])
    parts, notes, periods = [], [], []
    for rec in records:
        t, g, a, n, period = _uniform(p, rec, t0_ns, repair, gaps, which, retime)
        parts.append((t, g, a))
        periods.append(period)
        notes += n
    if len(records) > 1:
        time_s, rates, align_notes = _align(p, parts, chosen)
        notes += align_notes
    else:
        time_s, rates = parts[0][0], [parts[0][1]]
    acc = parts[0][2] if len(records) == 1 and extrinsics is None else None
    rate_hz = 1.0 / periods[0] if retime else 1e9 / _period_ns(base[0])  # exact integer steps
    kind = bag.kind
    frames = ", ".join(f"{r.topic} in frame {r.frame_id!r}" for r in records)
    gyros = "; ".join(f"gyros {3 * k + 1}-{3 * k + 3} are {r.topic}'s x, y, z axes"
                      for k, r in enumerate(records))
    source = "header stamp (header.stamp)" if which == "header" else "receive stamp (the bag's log time)"
    head = [f"{p}: {kind}, {sum(r.stamps_ns.size for r in records)} {IMU_TYPE} messages "
            f"({frames}); time_s is the {source} minus the first, t0 = {_stamp(t0_ns)} s; "
            f"sample rate {rate_hz:.6g} Hz from the {'mean' if retime else 'median'} stamp step; "
            f"angular_velocity [rad/s] written in deg/s; {gyros}"]
    if bag.salvage_note:
        head.append(bag.salvage_note)
    if acc is None and any(r.acc is not None for r in records):
        head.append(f"{p}: linear_acceleration left out (kept only for a single IMU read without "
                    "extrinsics, whose frame is the platform frame)")
    return Measurement(
        time_s=time_s, gyro_deg_s=units.rad_s_to_deg_s(np.hstack(rates)), layout=layout,
        sample_rate_hz=rate_hz, acc_m_s2=acc, source=str(p),
        description=f"{kind} {p.name}, topics {', '.join(chosen)}, {which} stamps from "
                    f"t0 = {_stamp(t0_ns)} s",
        notes=(*head, *ext_notes, *notes), topics=tuple(chosen))


class BagStream:
    """One IMU topic of a bag read in chunks of :data:`STREAM_CHUNK` messages, for a conversion
    in bounded memory (``gyroarray convert``): the same time_s and rates as :func:`read_bag`,
    bit for bit, without holding the record.

    Parameters
    ----------
    path : str or os.PathLike
        The bag (as :func:`read_bag`).
    topic : str, optional
        The one ``sensor_msgs/msg/Imu`` topic (default: the bag's only one).
    gaps : bool
        Keep dropped messages as gaps (default: refuse them, as :func:`read_bag`).
    stamps : {"header", "receive"}
        The time base.

    Notes
    -----
    Two things are decided on the first chunk, and the notes say so: the period P (the median
    step of the first chunk's stamps, where :func:`read_bag` takes the whole record's; the
    same for a record of one chunk) and whether ``linear_acceleration`` is kept (a message
    after it that marks it absent, covariance[0] = -1, is refused). Memory: one chunk of raw
    messages and its decoded values, plus the clock's window (:class:`_Clock`).
    """

    def __init__(self, path, *, topic: str | None = None, gaps: bool = False,
                 stamps: str = "header", chunk: int = STREAM_CHUNK):
        self.path = p = Path(path)
        self.which = _check_stamps_option(p, stamps)
        self.gaps, self.chunk = gaps, int(chunk)
        self._bag = _Bag(p, _check_path(p), stream=True)
        try:
            topics = self._bag.topics()
            chosen = _pick_topics(p, topics, topic)
            if len(chosen) != 1:
                raise _refusal(p, "a streamed conversion reads one IMU topic (an array is read "
                                  "whole: give one --topic, or convert each topic)")
            self.topic, self.count = chosen[0], topics[chosen[0]][1]
            self.layout, _ = _layout(p, chosen, None)
        except BaseException:
            self._bag.close()
            raise
        self.kind = self._bag.kind
        self.rate_hz: float | None = None
        self.t0_ns: int | None = None
        self.has_acc: bool | None = None
        self.frame_id = ""
        self.n = 0
        self.notes: list[str] = []

    def chunks(self):
        """(time_s [s], gyro [deg/s], specific force [m/s²] or None) of each chunk, in order;
        refusals as :func:`read_bag` (raised mid-way: the caller discards what it wrote)."""
        p, topic = self.path, self.topic
        clock: _Clock | None = None
        pending = None
        try:
            assert self._bag.reader is not None
            conns = [c for c in self._bag.reader.connections if c.topic == topic]
            self.frame_id = _frame_id(self._bag, conns)
            batches = _topic_batches(self._bag, topic, self.count, self.chunk)
            done = False
            while not done:
                item = next(batches, None)
                done = item is None
                if pending is not None:       # the previous chunk, now known whether last
                    st, rc, v = pending
                    base = st if self.which == "header" else rc
                    if clock is None:
                        _enough(p, topic, self.count)
                        self.t0_ns = int(base[0])
                        _check_increasing(p, topic, self.which, base)
                        period = _period_ns(base)
                        _check_bunching(p, topic, self.which, base, period)
                        self.rate_hz = 1e9 / period
                        clock = _Clock(p, topic, self.which, self.t0_ns, period,
                                       "keep" if self.gaps else "refuse")
                        self.has_acc = bool(not np.any(v[:, 6] == -1.0)
                                            and np.all(np.isfinite(v[:, 3:6])) and v[:, 3:6].any())
                    _check_values(p, topic, self.n, v[:, :3])
                    if self.has_acc and (np.any(v[:, 6] == -1.0) or not np.all(np.isfinite(v[:, 3:6]))):
                        k = int(np.flatnonzero((v[:, 6] == -1.0) | ~np.all(np.isfinite(v[:, 3:6]),
                                                                           axis=1))[0])
                        raise _refusal(p, "linear_acceleration is marked absent or not finite here "
                                          "but present in the first chunk; convert without it "
                                          "(read the bag whole) or cut the bag", topic=topic,
                                       index=self.n + k + 1)
                    clock.feed(base, final=done)
                    t = (base - self.t0_ns) / 1e9
                    self.n += st.size
                    yield (t, units.rad_s_to_deg_s(v[:, :3]), v[:, 3:6] if self.has_acc else None)
                pending = item
            if clock is None:
                _enough(p, topic, 0)
            assert clock is not None
            self.notes = [
                f"{p}: {self.kind}, {self.n} {IMU_TYPE} messages ({topic} in frame "
                f"{self.frame_id!r}), streamed in chunks of {self.chunk}; time_s is the {self.which} "
                f"stamp minus the first, t0 = {_stamp(self.t0_ns)} s; sample rate "
                f"{self.rate_hz:.6g} Hz from the median step of the first chunk's stamps; "
                f"angular_velocity [rad/s] written in deg/s; gyros 1-3 are {topic}'s x, y, z axes",
                *([self._bag.salvage_note] if self._bag.salvage_note else []),
                *([] if self.has_acc else [f"{p}: linear_acceleration left out (absent or zero "
                                            "in the first chunk)"]),
                *clock.notes()]
        finally:
            self.close()

    @property
    def description(self) -> str:
        return (f"{self.kind} {self.path.name}, topics {self.topic}, {self.which} stamps from "
                f"t0 = {_stamp(self.t0_ns or 0)} s")

    def close(self) -> None:
        self._bag.close()


# -- extrinsics ----------------------------------------------------------------
def read_extrinsics(path, topics: list[str]) -> dict[str, np.ndarray]:
    """The body-to-IMU transforms T_i_b (4x4) of a Kalibr imu-chain YAML, per topic.

    Parameters
    ----------
    path : str or os.PathLike
        YAML with ``imu0:``, ``imu1:`` ... entries, each with ``T_i_b`` (4 rows of 4 numbers;
        rotation orthonormal with det +1, last row 0 0 0 1, translation in metres) and
        optionally ``rostopic``.
    topics : list of str
        The topics read; an entry whose ``rostopic`` names one is that topic's, otherwise
        ``imuK`` is the K-th topic (with a note from :func:`read_bag`).

    Returns
    -------
    dict
        ``{topic: T_i_b}`` as float arrays, shape (4, 4).
    """
    name = str(path)
    doc = _yaml(read_regular(path, "extrinsics file", max_bytes=1 << 20), name, "extrinsics file")
    if not isinstance(doc, dict):
        raise InputError("expected Kalibr imu-chain YAML: imu0: {T_i_b: [[...], ...]}, imu1: ...",
                         file=name)
    keys = sorted((k for k in doc if isinstance(k, str) and k.startswith("imu")
                   and k[3:].isdigit()), key=lambda k: int(k[3:]))
    if not keys:
        raise InputError("no imu0, imu1, ... entry (Kalibr imu-chain YAML: imu0: {T_i_b: 4x4, "
                         "rostopic: /imu0})", file=name)
    by_topic = {}
    for k in keys:
        entry = doc[k]
        if not isinstance(entry, dict):
            raise InputError(f"{k} must be a mapping with T_i_b", file=name, column=k)
        if isinstance(entry.get("rostopic"), str) and entry["rostopic"] in topics:
            by_topic[entry["rostopic"]] = k
    if by_topic and len(by_topic) != len(topics):
        missing = [t for t in topics if t not in by_topic]
        raise InputError(f"no imuN entry has rostopic {', '.join(missing)}; add one per topic "
                         "read", file=name)
    if not by_topic:
        if len(keys) < len(topics):
            raise InputError(f"{len(keys)} imuN entries for {len(topics)} topics "
                             f"({', '.join(topics)}); give one per topic", file=name)
        by_topic = dict(zip(topics, keys))
    return {t: _transform(doc[k].get("T_i_b"), name, f"{k}.T_i_b") for t, k in by_topic.items()}


def _transform(value, name: str, key: str) -> np.ndarray:
    rows = value if isinstance(value, list) else None
    ok = (rows is not None and len(rows) == 4 and all(isinstance(r, list) and len(r) == 4 for r in rows)
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for r in rows for v in r))
    if not ok or rows is None:
        raise InputError("must be 4 rows of 4 numbers (the body-to-IMU transform)", file=name,
                         column=key)
    for i, r in enumerate(rows):
        for j, v in enumerate(r):
            # compared before any conversion: a 400-digit integer is no float
            if not (isinstance(v, int) or math.isfinite(v)) or not -MAX_TRANSLATION_M <= v <= MAX_TRANSLATION_M:
                where = "a rotation entry, from -1 to 1" if i < 3 and j < 3 else (
                    f"a translation [m], from -{MAX_TRANSLATION_M:g} to {MAX_TRANSLATION_M:g}"
                    if j == 3 else "0 0 0 1 (the last row)")
                shown = v if isinstance(v, float) or abs(v) < 10**20 else f"an integer of {len(str(abs(v)))} digits"
                raise InputError(f"row {i + 1}, entry {j + 1} is {shown}: must be {where}",
                                 file=name, column=key)
    T = np.array([[float(v) for v in r] for r in rows])
    R = T[:3, :3]
    err = float(np.abs(R @ R.T - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if err > ORTHO_TOL or det <= 0 or not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(f"is not a rigid transform: R must be a rotation: R·Rᵀ = I within "
                         f"{ORTHO_TOL:g}, det +1, and the last row 0 0 0 1 (got |R·Rᵀ − I| = "
                         f"{err:.3g}, det R = {det:.6g}, last row {T[3].tolist()})", file=name,
                         column=key)
    return T


def _layout(path: Path, topics: list[str], extrinsics) -> tuple[Layout, list[str]]:
    """Three gyros per topic: the rows of R_i_b (the IMU's x, y, z axes in the body frame) at
    the IMU origin -R_i_bᵀ t_i_b [m]; the identity without extrinsics (with a note)."""
    if extrinsics is None:
        note = ([f"{path}: no --extrinsics: each IMU's axes are taken as the body frame's (the "
                 "IMUs assumed aligned); give a Kalibr imu-chain YAML with T_i_b per IMU "
                 "otherwise"] if len(topics) > 1 else [])
        return Layout.from_axes(np.vstack([np.eye(3)] * len(topics)), source=str(path)), note
    T = read_extrinsics(extrinsics, topics)
    layout = Layout.from_axes(np.vstack([T[t][:3, :3] for t in topics]), source=str(extrinsics))
    origins = np.array([-T[t][:3, :3].T @ T[t][:3, 3] for t in topics])
    layout = layout.with_positions(np.repeat(origins, 3, axis=0), source=str(extrinsics))
    return layout, [f"{path}: axes and positions from T_i_b (body to IMU) in {extrinsics}"]

