"""Fuzzing the readers of the newer formats: ROS bags (ROS1, ROS2 ``.db3`` and ``.mcap``), their
``metadata.yaml``, and Parquet measurements (issue 40).

Strategies start from a small valid file of each kind and damage it the way a careless
recorder or a hostile user could: bytes flipped or cut anywhere, a ``.db3`` whose rows hold
NULL, REAL or TEXT data or unknown topic ids, whose tables are views, a ``metadata.yaml``
whose counts are huge, negative, NaN, text or lists, whose topics are lists, whose
compression mode is ``file``; Parquet files of many or few columns, of every Arrow type, with
extreme values, tiny or empty row groups, hostile column names, or a damaged footer.

The property is the CLI's contract (:func:`hostile.assert_contract`): exit 0 with finite
numbers, or exit 2 with one line naming the file; never exit 1, never a traceback, never a
hang. The process's address space is capped (``tests/test_fuzz_args._AddressSpaceCap``) with
``--max-memory 1G``, so a reader that ignores the budget dies with a ``MemoryError`` (an
internal error) instead of taking the machine; no input file is modified.

``make test`` runs a small derandomized sample; ``make fuzz`` runs ``GYROARRAY_FUZZ_EXAMPLES``
(3 % of them each test) with random seeds.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hostile import assert_contract, finite_numbers, run_cli
from tests.test_bags import record, write_bag
from tests.test_fuzz_args import _AddressSpaceCap, _fingerprint

LONG = int(os.environ.get("GYROARRAY_FUZZ_EXAMPLES", "0"))
FUZZ = settings(max_examples=max(LONG * 3 // 100, 1) if LONG else 8, deadline=None,
                derandomize=not LONG, database=None, suppress_health_check=list(HealthCheck))

#: the budget every call gets
BUDGET = "1G"
#: hostile values of a count or size field of metadata.yaml
COUNTS = [0, -1, -(2**63), 1, 49, 51, 10**8, 2**63, 10**400, 1e300, float("nan"), float("inf"),
          "fifty", "", None, True, [50], {"n": 50}]
#: hostile Parquet values (as float64 or cast to the drawn type)
VALUES = [0.0, -0.0, 5e-324, 1e-310, 1e-3, 1.0, 1e5, 1e200, 1e308, float("nan"), float("inf"),
          -float("inf")]


@pytest.fixture(scope="module")
def valid(tmp_path_factory):
    """One small valid file of each kind (50 messages of one IMU topic, a 4-gyro Parquet)."""
    folder = tmp_path_factory.mktemp("readers")
    files = {kind: write_bag(folder, f"ok_{kind}", kind, {"/imu": record(3, n=50)})
             for kind in ("bag", "db3", "mcap")}
    rng = np.random.default_rng(40)
    t = np.arange(500) / 100.0
    table = pa.table({"time_s": t, **{f"gyro{k}": rng.normal(0.0, 0.01, 500) for k in range(1, 5)}})
    files["parquet"] = folder / "ok.parquet"
    pq.write_table(table, files["parquet"])
    (folder / "ok.toml").write_text(
        "sample_rate_hz = 100.0\n[layout]\nscheme = 1\nn_gyros = 4\nalpha_deg = 54.7356\n")
    return files


def _copy(src: Path, dest: Path) -> Path:
    """A copy of a valid file (or of a ROS2 bag's whole folder); returns the file to read."""
    if src.suffix in (".db3", ".mcap"):
        shutil.copytree(src.parent, dest / src.parent.name)
        return dest / src.parent.name / src.name
    if src.suffix == ".parquet":
        shutil.copy(src.with_suffix(".toml"), dest / src.with_suffix(".toml").name)
    shutil.copy(src, dest / src.name)
    return dest / src.name


@st.composite
def byte_damage(draw, data: bytes) -> bytes:
    """``data`` with a few bytes flipped, a piece cut out or the tail cut off."""
    kind = draw(st.sampled_from(["flip", "cut", "truncate", "zero_run"]))
    n = len(data)
    i = draw(st.integers(0, n - 1))
    if kind == "flip":
        out = bytearray(data)
        for j in draw(st.lists(st.integers(0, n - 1), min_size=1, max_size=8)) + [i]:
            out[j] ^= draw(st.sampled_from([0x01, 0x80, 0xFF, 0x7F]))
        return bytes(out)
    if kind == "cut":
        return data[:i] + data[i + draw(st.integers(1, 64)):]
    if kind == "zero_run":
        k = draw(st.integers(1, 256))
        return data[:i] + b"\x00" * k + data[i + k:]
    return data[:i]


def _damage_db3(draw, db3: Path) -> None:
    """One hostile edit of a rosbag2 sqlite database, in place (the fuzz copy)."""
    what = draw(st.sampled_from(["null", "real", "text", "topic_id", "view", "drop", "huge_id",
                                 "timestamp"]))
    con = sqlite3.connect(db3)
    try:
        rows = draw(st.sampled_from(["id = 1", "id % 7 = 0", "1 = 1"]))
        if what in ("null", "real", "text"):
            value = {"null": "NULL", "real": "3.5", "text": "'abc'"}[what]
            if what == "null":                 # past the NOT NULL of rosbag2's schema
                con.executescript(
                    "CREATE TABLE m2(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, "
                    "data BLOB); INSERT INTO m2 SELECT * FROM messages; DROP TABLE messages; "
                    "ALTER TABLE m2 RENAME TO messages;")
            con.execute(f"UPDATE messages SET data = {value} WHERE {rows}")
        elif what == "topic_id":
            con.execute(f"UPDATE messages SET topic_id = {draw(st.sampled_from([-1, 2, 2**62]))} "
                        f"WHERE {rows}")
        elif what == "huge_id":
            con.execute(f"UPDATE messages SET id = id + {2**62} WHERE {rows}")
        elif what == "timestamp":
            value = draw(st.sampled_from(["-1", str(2**63 - 1), "NULL", "'x'"]))
            if value == "NULL":
                value = "-5"                     # NOT NULL in rosbag2's schema
            con.execute(f"UPDATE messages SET timestamp = {value} WHERE {rows}")
        else:
            table = draw(st.sampled_from(["messages", "topics", "schema", "message_definitions"]))
            exists = con.execute("SELECT count(*) FROM sqlite_master WHERE name = ?",
                                 (table,)).fetchone()[0]
            if exists:
                con.execute(f"ALTER TABLE {table} RENAME TO {table}_gone")
                if what == "view":                       # an endless recursive CTE behind it
                    con.execute(f"CREATE VIEW {table} AS WITH RECURSIVE c(x) AS "
                                f"(SELECT 1 UNION ALL SELECT x + 1 FROM c) "
                                f"SELECT * FROM {table}_gone, c")
        con.commit()
    finally:
        con.close()


def _damage_metadata(draw, folder: Path) -> None:
    """One hostile field of a ROS2 bag's metadata.yaml (or a broken YAML text), in place."""
    path = folder / "metadata.yaml"
    if draw(st.booleans()) and draw(st.booleans()):
        path.write_bytes(draw(byte_damage(path.read_bytes())))
        return
    meta = yaml.safe_load(path.read_text())
    info = meta["rosbag2_bagfile_information"]
    field = draw(st.sampled_from(["message_count", "topic_count", "file_count", "topic",
                                  "compression", "version", "paths", "starting_time", "files"]))
    value = draw(st.sampled_from(COUNTS))
    if field == "message_count":
        info["message_count"] = value
    elif field == "topic_count":
        info["topics_with_message_count"][0]["message_count"] = value
    elif field == "file_count" and info.get("files"):
        info["files"][0]["message_count"] = value
    elif field == "topic":
        info["topics_with_message_count"][0]["topic_metadata"]["name"] = draw(
            st.sampled_from([["/imu"], None, 5, "", "/other", "/imu\n/x"]))
    elif field == "compression":
        info["compression_mode"] = draw(st.sampled_from(["file", "message", "FILE", 3]))
        info["compression_format"] = draw(st.sampled_from(["zstd", "lz4", "bz2", "", None]))
    elif field == "version":
        info["version"] = value
    elif field == "paths":
        info["relative_file_paths"] = draw(st.sampled_from(
            [["../../etc/passwd"], ["/dev/zero"], [], ["missing.db3"], "x.db3", [5]]))
    elif field == "starting_time":
        info["starting_time"] = {"nanoseconds_since_epoch": value}
    else:
        info["files"] = value
    text = yaml.safe_dump(meta, allow_unicode=True) if _dumpable(meta) else "{"
    path.write_text(text)


def _dumpable(meta) -> bool:
    try:
        yaml.safe_dump(meta)
        return True
    except (yaml.YAMLError, OverflowError, ValueError):
        return False


@st.composite
def damaged_bags(draw, valid: dict, folder: Path) -> Path:
    kind = draw(st.sampled_from(["bag", "db3", "mcap"]))
    path = _copy(valid[kind], folder)
    how = draw(st.sampled_from(["bytes", "metadata", "db3"] if kind == "db3" else
                               ["bytes", "metadata"] if kind == "mcap" else ["bytes"]))
    if how == "bytes":
        path.write_bytes(draw(byte_damage(path.read_bytes())))
    elif how == "metadata":
        _damage_metadata(draw, path.parent)
    else:
        _damage_db3(draw, path)
    return path


def _arrow_column(draw, n: int, rng: np.random.Generator):
    """One column of ``n`` values of a drawn Arrow type, extreme values mixed in."""
    kind = draw(st.sampled_from(["float64", "float32", "int64", "int8", "uint64", "bool", "string",
                                 "null", "binary", "list", "timestamp"]))
    x = rng.normal(0.0, 0.01, n)
    if n and draw(st.booleans()):
        x[draw(st.integers(0, n - 1))] = draw(st.sampled_from(VALUES))
    if kind in ("float64", "float32"):
        return pa.array(x, type=getattr(pa, kind)())
    if kind in ("int64", "int8", "uint64"):
        return pa.array(np.clip(np.nan_to_num(x * 1000), -100, 100).astype(kind), type=getattr(pa, kind)())
    if kind == "bool":
        return pa.array(x > 0)
    if kind == "string":
        return pa.array([repr(v) for v in x])
    if kind == "binary":
        return pa.array([b"\x00" * 3] * n, type=pa.binary())
    if kind == "list":
        return pa.array([[v] for v in x])
    if kind == "timestamp":
        return pa.array(np.arange(n, dtype="int64"), type=pa.timestamp("ns"))
    return pa.nulls(n)


@st.composite
def hostile_parquets(draw, valid: dict, folder: Path) -> Path:
    """A Parquet measurement (with the valid one's sidecar) of drawn shape, types and values,
    or the valid one with damaged bytes."""
    path = folder / "m.parquet"
    shutil.copy(valid["parquet"].with_suffix(".toml"), folder / "m.toml")
    if draw(st.booleans()) and draw(st.booleans()):
        path.write_bytes(draw(byte_damage(valid["parquet"].read_bytes())))
        return path
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.sampled_from([0, 1, 2, 3, 17, 500, 3000]))
    n_cols = draw(st.sampled_from([0, 1, 2, 4, 5, 9, 300]))
    names = ["time_s"] + [f"gyro{k}" for k in range(1, n_cols)]
    if draw(st.booleans()):
        i = draw(st.integers(0, len(names) - 1))
        names[i] = draw(st.sampled_from(["", "time_s", "gyro1", "x" * 2000, "gyro\n2", "acc_x",
                                         "gyro99999999999999999999"]))
    step = draw(st.sampled_from([0.01, 0.0, -0.01, 5e-324, 1e300]))
    cols = [pa.array(np.arange(n) * step)] if n_cols else []
    cols += [_arrow_column(draw, n, rng) for _ in range(max(n_cols - 1, 0))]
    table = pa.Table.from_arrays(cols, names=names[:len(cols)]) if cols else pa.table({})
    pq.write_table(table, path, row_group_size=draw(st.sampled_from([1, 7, 1 << 20])))
    return path


def _contract(argv, given) -> None:
    before = _fingerprint(given)
    with _AddressSpaceCap():
        o = run_cli(argv + ["--max-memory", BUDGET, "--json"], timeout=300)
    assert _fingerprint(given) == before, ("an input was modified", argv)
    assert_contract(o)
    if o.code == 0:
        assert finite_numbers(o.json), argv


def _given(path: Path) -> list:
    return sorted(path.parent.iterdir()) if path.suffix in (".db3", ".mcap") else \
        [path, path.with_suffix(".toml")]


def test_damaged_bags_keep_the_contract(valid, tmp_path_factory):
    @FUZZ
    @given(data=st.data())
    def one(data):
        folder = tmp_path_factory.mktemp("bag")
        path = data.draw(damaged_bags(valid, folder))
        command = data.draw(st.sampled_from(["allan", "convert"]))
        target = path.parent if path.suffix in (".db3", ".mcap") and data.draw(st.booleans()) else path
        argv = [command, str(target)] + (["--out", str(folder / "out.csv.gz")] if command == "convert" else [])
        _contract(argv, _given(path))
        shutil.rmtree(folder, ignore_errors=True)
    one()


def test_hostile_parquet_keeps_the_contract(valid, tmp_path_factory):
    @FUZZ
    @given(data=st.data())
    def one(data):
        folder = tmp_path_factory.mktemp("pq")
        path = data.draw(hostile_parquets(valid, folder))
        command = data.draw(st.sampled_from(["allan", "fuse", "allan --stream", "fuse --stream"]))
        argv = command.split() + [str(path)]
        if command.startswith("fuse"):
            argv += ["--estimator", "ols", "--out", str(folder / "fused.csv.gz")]
        _contract(argv, [path, path.with_suffix(".toml")])
        shutil.rmtree(folder, ignore_errors=True)
    one()
