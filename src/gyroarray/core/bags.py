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
* Time: the header stamps (``header.stamp``), in the bag's order. They must
  increase strictly (a stamp repeating or going backwards is refused with the
  message index). ``time_s`` counts from the first stamp, computed from the
  integer nanoseconds (exact to the nanosecond; a Unix-epoch stamp in a
  double would keep only 0.24 µs): t0 is in the description and the notes.
  The sample rate is 1 / the median stamp step; a step longer than
  ``GAP_FACTOR`` steps is a gap (refused; ``repair`` fills gaps of up to
  ``MAX_REPAIR_SAMPLES`` samples), and a jitter above ``JITTER_TOL`` of the
  step is noted (``repair`` resamples onto the uniform step).
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

import json
import math
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
           "ORTHO_TOL"]

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
        raise _refusal(path, "cannot open this ROS2 bag (sqlite3): truncated or corrupt?", err) from None
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
        raise _refusal(path, "cannot read this ROS2 bag (sqlite3): truncated or corrupt?", err) from None
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


class _Bag:
    """An open bag: its reader, the topics and the typestore that decodes its messages."""

    def __init__(self, path: Path, info: dict | None = None):
        # deferred: rosbags (its readers and typestores) loads only when a bag is read
        from rosbags.rosbag1 import Reader as Reader1
        from rosbags.rosbag2 import Reader as Reader2
        from rosbags.typesys import Stores, get_typestore
        _guard_rosbags()
        self.path = path
        self.ros1 = path.name.lower().endswith(".bag")
        self.zstd_messages = False
        self._tmp: tempfile.TemporaryDirectory | None = None
        self.reader = None
        try:
            src = path
            if info is not None and info["compression_mode"] == "file":
                src = self._decompress_files(path, info)
            try:
                self.reader = Reader1(src) if self.ros1 else Reader2(src)
                self.reader.open()
            except InputError as err:
                raise InputError(err.message, file=err.file or str(path)) from None
            except Exception as err:  # rosbags' errors, struct/sqlite/zstd ones: a bad file
                self.reader = None
                raise _refusal(path, f"cannot open this {_kind(path)}: truncated or corrupt?",
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
        """The raw messages of ``conns`` in the bag's order: bytes (refused otherwise: an sqlite
        NULL, REAL, TEXT or INTEGER), at most :data:`MAX_MESSAGE_BYTES` (zstd messages
        decompressed in bounded pieces)."""
        for _, _, raw in self.reader.messages(connections=conns):
            if not isinstance(raw, (bytes, bytearray, memoryview)):
                raise InputError(f"the message data is {_sql_kind(raw)}, not bytes (an sqlite "
                                 "BLOB): corrupt bag?")
            if self.zstd_messages:
                raw = decompress_bounded(raw, "zstd", MAX_MESSAGE_BYTES, None, "the message")
            elif len(raw) > MAX_MESSAGE_BYTES:
                raise InputError(f"a message of {format_size(len(raw))}, more than the "
                                 f"{format_size(MAX_MESSAGE_BYTES)} a {IMU_TYPE} takes: corrupt?")
            yield bytes(raw)

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
    """One topic's samples: header stamps [ns], rates [rad/s], specific force [m/s²]."""

    def __init__(self, topic: str, stamps_ns: np.ndarray, gyro: np.ndarray, acc: np.ndarray | None,
                 frame_id: str):
        self.topic, self.stamps_ns, self.gyro, self.acc, self.frame_id = (
            topic, stamps_ns, gyro, acc, frame_id)


def _read_topic(bag: _Bag, topic: str, count: int) -> _Record:
    """Decode every message of ``topic`` (the type was checked by name), in batches."""
    path = bag.path
    check_memory(count * float(_BYTES_PER_MESSAGE), f"{count} messages of topic {topic}",
                 "split the bag (e.g. 'ros2 bag convert' or 'rosbag filter') or raise --max-memory",
                 file=str(path))
    stamps = np.empty(count, dtype=np.int64)
    values = np.empty((count, 7))           # angular velocity, linear acceleration, its cov[0]
    assert bag.reader is not None
    conns = [c for c in bag.reader.connections if c.topic == topic]
    i, batch = 0, list[bytes]()
    it = iter(bag.messages(conns))
    while True:
        try:
            item = next(it, None)
        except InputError as err:  # a message that is no bytes, a bomb: said as it is
            raise _refusal(path, err.message, topic=topic, index=i + len(batch) + 1) from None
        except Exception as err:  # a chunk or record that does not parse: truncated or corrupt
            raise _refusal(path, f"cannot read past this message of the {_kind(path)}: truncated "
                                 "or corrupt?", err, topic=topic, index=i + len(batch) + 1) from None
        if item is not None:
            if i + len(batch) >= count:
                raise _refusal(path, f"more messages than the bag's index counts ({count}): "
                                     "corrupt index?", topic=topic, index=i + len(batch) + 1)
            batch.append(item)
        if batch and (item is None or len(batch) == _BATCH):
            _decode_batch(bag, batch, i, topic, stamps, values)
            i, batch = i + len(batch), []
        if item is None:
            break
    if i < count:
        raise _refusal(path, f"the bag's index counts {count} messages but only {i} could be read: "
                             "truncated?", topic=topic, index=i + 1)
    gyro, acc = values[:, :3], values[:, 3:6]
    _check_values(path, topic, stamps, gyro)
    keep_acc = not np.any(values[:, 6] == -1.0) and np.all(np.isfinite(acc)) and acc.any()
    return _Record(topic, stamps, gyro, acc if keep_acc else None, _frame_id(bag, conns))


def _frame_id(bag: _Bag, conns) -> str:
    """The first message's header.frame_id (for the notes)."""
    for raw in bag.messages(conns):
        msg: Any = bag.decode(raw, IMU_TYPE)
        return str(msg.header.frame_id)
    return ""


def _decode_one(bag: _Bag, raw: bytes) -> tuple[int, list[float]]:
    msg: Any = bag.decode(raw, IMU_TYPE)        # a sensor_msgs/msg/Imu of the typestore
    stamp, w, a = msg.header.stamp, msg.angular_velocity, msg.linear_acceleration
    return (int(stamp.sec) * _NS_PER_S + int(stamp.nanosec),
            [w.x, w.y, w.z, a.x, a.y, a.z, float(msg.linear_acceleration_covariance[0])])


def _decode_batch(bag: _Bag, raws: list[bytes], i0: int, topic: str, stamps: np.ndarray,
                  values: np.ndarray) -> None:
    """Messages ``i0 ..`` into ``stamps`` [ns] and ``values``: by fixed offsets when every
    message of the batch has the same layout and three of them decode identically through the
    typestore, else one by one through the typestore."""
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
                           index=i0 + j + 1)
        try:
            stamps[i0 + j], values[i0 + j] = _decode_one(bag, raw)
        except Exception as err:  # bytes that are no sensor_msgs/msg/Imu: a corrupt message
            raise _refusal(bag.path, f"this message does not decode as {IMU_TYPE}: corrupt?", err,
                           topic=topic, index=i0 + j + 1) from None


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


def _check_values(path: Path, topic: str, stamps: np.ndarray, gyro: np.ndarray) -> None:
    bad = ~np.all(np.isfinite(gyro), axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise _refusal(path, f"angular_velocity is not finite ({gyro[k].tolist()}); remove or "
                             "repair that message", topic=topic, index=k + 1)
    big = np.abs(units.rad_s_to_deg_s(gyro)) > MAX_RATE_DEG_S
    if big.any():
        k = int(np.flatnonzero(big.any(axis=1))[0])
        raise _refusal(path, f"angular_velocity {gyro[k].tolist()} rad/s is beyond "
                             f"{MAX_RATE_DEG_S:g} deg/s: not a rate in rad/s (REP 103)?",
                       topic=topic, index=k + 1)
    if stamps.size < MIN_SAMPLES:
        raise _refusal(path, f"{stamps.size} message: a measurement needs at least {MIN_SAMPLES}",
                       topic=topic)
    step = np.diff(stamps)
    if np.any(step <= 0):
        k = int(np.flatnonzero(step <= 0)[0])
        how = "repeats" if step[k] == 0 else "goes backwards"
        raise _refusal(path, f"the header stamp {how} ({_stamp(stamps[k + 1])} s after "
                             f"{_stamp(stamps[k])} s); header stamps must increase (a driver that "
                             "leaves header.stamp unset, or a merged bag?)", topic=topic,
                       index=k + 2)


def _stamp(ns) -> str:
    """``1700000000.123456789`` from integer nanoseconds."""
    s, n = divmod(int(ns), _NS_PER_S)
    return f"{s}.{n:09d}"


def _uniform(path: Path, rec: _Record, t0_ns: int, repair: bool) -> tuple[np.ndarray, np.ndarray,
                                                                        np.ndarray | None, list[str]]:
    """(time_s from t0, rates, specific force, notes): gaps refused or filled, jitter noted or
    resampled (``repair``)."""
    t = (rec.stamps_ns - t0_ns) / 1e9
    step_ns = np.diff(rec.stamps_ns)
    period = float(np.median(step_ns)) / 1e9
    steps = np.diff(t)
    notes: list[str] = []
    gaps = np.flatnonzero(steps > GAP_FACTOR * period)
    for k in gaps.tolist():
        missing = int(round(steps[k] / period)) - 1
        if not repair or missing > MAX_REPAIR_SAMPLES:
            way = ("re-record, or analyse the parts either side" if repair else
                   f"rerun with --repair to fill gaps of up to {MAX_REPAIR_SAMPLES} samples by "
                   "linear interpolation")
            raise _refusal(path, f"a gap of {steps[k]:.6g} s ({max(missing, 1)} missing samples at "
                                 f"the {period:.6g} s step) before this message; {way}",
                           topic=rec.topic, index=k + 2)
    dev = np.abs(steps - period)
    worst = float(dev.max())
    if gaps.size == 0 and worst <= JITTER_TOL * period:
        return t, rec.gyro, rec.acc, notes
    what = (f"topic {rec.topic}: the stamp steps jitter by up to {worst:.3g} s "
            f"({100 * worst / period:.3g} % of the {period:.6g} s median step; rms "
            f"{float(np.sqrt(np.mean(dev ** 2))):.3g} s)")
    if not repair:
        return t, rec.gyro, rec.acc, [f"{path}: {what}; the analyses assume the uniform step "
                                      "(rerun with --repair to resample onto it)"]
    grid = np.arange(int(round(t[-1] / period)) + 1) * period
    grid = grid[grid <= t[-1]]
    gyro = np.column_stack([np.interp(grid, t, rec.gyro[:, j]) for j in range(3)])
    acc = (None if rec.acc is None else
           np.column_stack([np.interp(grid, t, rec.acc[:, j]) for j in range(3)]))
    filled = f", {gaps.size} gap(s) filled" if gaps.size else ""
    notes.append(f"{path}: repaired: {what}{filled}; resampled {t.size} messages onto {grid.size} "
                 f"samples at the median step from the first stamp, by linear interpolation in time")
    return grid, gyro, acc, notes


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


def read_bag(path, *, topic: str | None = None, extrinsics=None, repair: bool = False) -> Measurement:
    """Read the IMU topic(s) of a ROS bag as a measurement.

    Parameters
    ----------
    path : str or os.PathLike
        A ROS1 ``.bag``, a ROS2 ``.db3`` or ``.mcap`` file, or a ROS2 bag folder.
    topic : str, optional
        The ``sensor_msgs/msg/Imu`` topic (``/imu0``), or several separated by commas (an
        array). Default: the bag's one IMU topic.
    extrinsics : str or os.PathLike, optional
        Kalibr imu-chain YAML with ``imuN: T_i_b`` (4x4, body to IMU) per topic.
    repair : bool
        Fill gaps of up to ``MAX_REPAIR_SAMPLES`` samples and resample a jittering clock onto
        its median step, by linear interpolation in time (default: refuse gaps, note jitter).

    Returns
    -------
    Measurement
        ``time_s`` [s] from the first header stamp, gyro outputs [deg/s] (3 per IMU: its x, y,
        z axes), ``sample_rate_hz`` [Hz] from the median stamp step, ``acc_m_s2`` [m/s²] for a
        single IMU that publishes it; ``source`` is the bag.

    Raises
    ------
    InputError
        One line naming the bag, the topic and the message index (see the module docstring).
    """
    p = Path(path)
    bag = _Bag(p, _check_path(p))
    try:
        all_topics = bag.topics()
        chosen = _pick_topics(p, all_topics, topic)
        layout, ext_notes = _layout(p, chosen, extrinsics)     # before the (long) read
        records = [_read_topic(bag, t, all_topics[t][1]) for t in chosen]
    finally:
        bag.close()
    t0_ns = int(records[0].stamps_ns[0])
    parts, notes = [], []
    for rec in records:
        t, g, a, n = _uniform(p, rec, t0_ns, repair)
        parts.append((t, g, a))
        notes += n
    if len(records) > 1:
        time_s, rates, align_notes = _align(p, parts, chosen)
        notes += align_notes
    else:
        time_s, rates = parts[0][0], [parts[0][1]]
    acc = parts[0][2] if len(records) == 1 and extrinsics is None else None
    rate_hz = 1e9 / float(np.median(np.diff(records[0].stamps_ns)))   # exact integer steps
    frames = ", ".join(f"{r.topic} in frame {r.frame_id!r}" for r in records)
    gyros = "; ".join(f"gyros {3 * k + 1}-{3 * k + 3} are {r.topic}'s x, y, z axes"
                      for k, r in enumerate(records))
    head = [f"{p}: {_kind(p)}, {sum(r.stamps_ns.size for r in records)} {IMU_TYPE} messages "
            f"({frames}); time_s is the header stamp minus the first, t0 = {_stamp(t0_ns)} s; "
            f"sample rate {rate_hz:.6g} Hz from the median stamp step; angular_velocity [rad/s] "
            f"written in deg/s; {gyros}"]
    if acc is None and any(r.acc is not None for r in records):
        head.append(f"{p}: linear_acceleration left out (kept only for a single IMU read without "
                    "extrinsics, whose frame is the platform frame)")
    return Measurement(
        time_s=time_s, gyro_deg_s=units.rad_s_to_deg_s(np.hstack(rates)), layout=layout,
        sample_rate_hz=rate_hz, acc_m_s2=acc, source=str(p),
        description=f"{_kind(p)} {p.name}, topics {', '.join(chosen)}, header stamps from "
                    f"t0 = {_stamp(t0_ns)} s",
        notes=(*head, *ext_notes, *notes))


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

