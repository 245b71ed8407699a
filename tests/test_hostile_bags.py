"""Hostile ROS bags (the bag readers guarded like the CSV reader): every file of the campaign
ends in a one-line refusal (exit 2) naming the file and what is wrong, or a right answer;
never a hang, an internal error or more memory than ``--max-memory``. The hostile files are
small on disk (sparse files, compression bombs of zeros)."""

from __future__ import annotations

import bz2
import os
import shutil
import sqlite3
from pathlib import Path

import lz4.frame
import numpy as np
import pytest
import yaml
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import Writer as Writer2
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.typesys import Stores, get_typestore

try:
    from compression import zstd
except ImportError:  # Python < 3.14: rosbags' own dependency
    from backports import zstd

from tests.hostile import assert_contract, run_cli
from tests.test_bags import IMU, STEP_NS, T0_NS, imu_message, kalibr_yaml, record, write_bag

BUDGET = "200M"          # the --max-memory of the bomb cases: far below what they expand to
BOMB = 400 << 20         # what each bomb expands to [bytes]: twice the budget


def refused(argv, *fragments, timeout: float = 60.0) -> str:
    """Exit 2 with one line naming argv[1] (or the first fragment) and every fragment."""
    o = run_cli([str(a) for a in argv], timeout=timeout)
    assert_contract(o)
    assert o.code == 2, (o.code, o.out[:300])
    for f in fragments:
        assert f in o.err, (f, o.err)
    return o.err


def allan(bag, *more):
    return ["allan", bag, "--json", *more]


def zeros_frames(compress, total: int, piece: int = 64 << 20) -> bytes:
    """``total`` zero bytes as concatenated frames of ``piece`` zeros (one compressed once)."""
    frame = compress(b"\0" * piece)
    return frame * max(1, total // piece)


# -- sqlite3 (.db3): views, types, ids --------------------------------------------------------
ENDLESS = "WITH RECURSIVE c(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM c) SELECT max(x) FROM c"


def db3(tmp_path, name="v") -> Path:
    return write_bag(tmp_path, name, "db3", {"/imu0": record(1)})


def loose_messages(bag: Path) -> sqlite3.Connection:
    """The bag's messages table without its NOT NULL constraints (any value can be put in)."""
    con = sqlite3.connect(bag)
    con.executescript("CREATE TABLE m2(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp "
                      "INTEGER, data BLOB); INSERT INTO m2 SELECT id, topic_id, timestamp, data "
                      "FROM messages; DROP TABLE messages; ALTER TABLE m2 RENAME TO messages;")
    return con


@pytest.mark.parametrize("table", ["message_definitions", "schema", "messages", "topics"])
def test_db3_table_that_is_an_endless_view(tmp_path, table):
    bag = db3(tmp_path)
    con = sqlite3.connect(bag)
    con.execute(f"ALTER TABLE {table} RENAME TO real_{table}")
    con.execute(f"CREATE VIEW {table} AS SELECT * FROM real_{table} WHERE ({ENDLESS}) > 0")
    con.commit()
    con.close()
    before = bag.read_bytes()
    refused(allan(bag), str(bag), table, "not a table", timeout=20)
    refused(["convert", bag, "--out", tmp_path / "x.csv.gz"], str(bag), table, timeout=20)
    refused(allan(bag.parent), str(bag), table, timeout=20)           # the folder too
    assert bag.read_bytes() == before and not (tmp_path / "x.csv.gz").exists()


@pytest.mark.parametrize("value,kind", [("NULL", "NULL"), ("1.5", "REAL"), ("'text'", "TEXT"),
                                        ("42", "INTEGER")])
def test_db3_message_data_not_a_blob(tmp_path, value, kind):
    bag = db3(tmp_path)
    con = loose_messages(bag)
    con.execute(f"UPDATE messages SET data = {value} WHERE id = 5")
    con.commit()
    con.close()
    refused(allan(bag), str(bag), "topic /imu0", "message 5", kind)


def test_db3_messages_of_unknown_topic_ids(tmp_path):
    bag = db3(tmp_path)
    con = loose_messages(bag)
    con.execute("UPDATE messages SET topic_id = 99 WHERE id IN (7, 8)")
    con.execute("UPDATE messages SET topic_id = NULL WHERE id = 9")
    con.commit()
    con.close()
    refused(allan(bag), str(bag), "topic id", "99")


# -- non-regular files: FIFOs, devices, links to /dev/zero ------------------------------------
@pytest.mark.parametrize("kind", ["db3", "mcap"])
@pytest.mark.parametrize("how", ["fifo", "dev_zero"])
def test_non_regular_file_in_a_bag_folder(tmp_path, kind, how):
    bag = write_bag(tmp_path, "run", kind, {"/imu0": record(2)})
    bag.unlink()
    if how == "fifo":
        os.mkfifo(bag)
    else:
        os.symlink("/dev/zero", bag)
    what = "FIFO" if how == "fifo" else "character device"
    refused(allan(bag.parent), str(bag), what, timeout=20)
    refused(allan(bag), str(bag), timeout=20)
    refused(["convert", bag.parent, "--out", tmp_path / "x.csv.gz"], what, timeout=20)


@pytest.mark.parametrize("how", ["fifo", "dev_zero"])
def test_metadata_yaml_not_a_regular_file(tmp_path, how):
    bag = write_bag(tmp_path, "run", "mcap", {"/imu0": record(2)})
    meta = bag.parent / "metadata.yaml"
    meta.unlink()
    os.mkfifo(meta) if how == "fifo" else os.symlink("/dev/zero", meta)
    refused(allan(bag.parent), "metadata.yaml", timeout=20)


@pytest.mark.parametrize("how", ["fifo", "dev_zero"])
def test_fuse_with_a_bag_sidecar_that_is_no_file(tmp_path, how):
    rng = np.random.default_rng(3)
    n = 2000
    stamps = T0_NS + STEP_NS * np.arange(n, dtype=np.int64)
    bag = write_bag(tmp_path, "f", "mcap", {"/imu0": (stamps, rng.normal(0, 0.01, (n, 3)),
                                                      np.zeros((n, 3)))})
    side = bag.with_name(bag.name + ".toml")
    os.mkfifo(side) if how == "fifo" else os.symlink("/dev/zero", side)
    o = run_cli(["fuse", bag, "--estimator", "naive", "--out", tmp_path / "fused.csv", "--json"],
                timeout=60)
    assert_contract(o)
    if o.code == 0:
        assert (tmp_path / "fused.csv").is_file()


# -- memory: compression bombs, sparse metadata, huge declared lengths ------------------------
def ros1_bomb(tmp_path, fmt) -> Path:
    """A ROS1 bag whose one chunk decompresses to its messages and then BOMB zero bytes."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / "bomb.bag"
    stamps, gyro, acc = record(4)
    w = Writer1(path)
    w.set_compression(fmt)
    if fmt == Writer1.CompressionFormat.BZ2:
        tail = zeros_frames(lambda b: bz2.compress(b, 9), BOMB, 16 << 20)
        w.compressor = lambda x: bz2.compress(x, 9) + tail
    else:
        tail = zeros_frames(lz4.frame.compress, BOMB)
        w.compressor = lambda x: lz4.frame.compress(x) + tail
    with w:
        conn = w.add_connection("/imu0", IMU, typestore=ts)
        for i in range(len(stamps)):
            w.write(conn, T0_NS + i * STEP_NS,
                    ts.serialize_ros1(imu_message(ts, stamps[i], gyro[i], acc[i]), IMU))
    return path


@pytest.mark.parametrize("fmt", ["BZ2", "LZ4"])
def test_ros1_chunk_bomb(tmp_path, fmt):
    bag = ros1_bomb(tmp_path, getattr(Writer1.CompressionFormat, fmt))
    assert bag.stat().st_size < 2 << 20
    refused(allan(bag, "--max-memory", BUDGET), str(bag), "chunk", "decompresses to more than")


def test_ros1_record_declaring_more_than_the_budget(tmp_path):
    """A chunk whose stored data is 40 MiB (a sparse file could declare far more) is not read
    into memory under a 200 MiB budget (at most an eighth of it at once)."""
    ts = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / "long.bag"
    stamps, gyro, acc = record(14)
    w = Writer1(path)
    w.set_compression(Writer1.CompressionFormat.BZ2)
    w.compressor = lambda x: bz2.compress(x, 9) + bytes(40 << 20)
    with w:
        conn = w.add_connection("/imu0", IMU, typestore=ts)
        for i in range(len(stamps)):
            w.write(conn, T0_NS + i * STEP_NS,
                    ts.serialize_ros1(imu_message(ts, stamps[i], gyro[i], acc[i]), IMU))
    refused(allan(path, "--max-memory", BUDGET), str(path), "a record declares 40 MiB")


def mcap_bomb(tmp_path, fmt: str, bomb: int = BOMB) -> Path:
    """An MCAP whose chunk decompresses to its records and then ``bomb`` zero bytes."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    folder = tmp_path / f"bomb_{fmt}"
    stamps, gyro, acc = record(5)
    comp = zstd.compress if fmt == "zstd" else lz4.frame.compress
    tail = zeros_frames(comp, bomb) if bomb else b""
    w = Writer2(folder, version=9, storage_plugin=StoragePlugin.MCAP)
    w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with w:
        w.storage.compression = fmt
        w.storage.compressor = lambda x: comp(x) + tail
        conn = w.add_connection("/imu0", IMU, typestore=ts)
        for i in range(len(stamps)):
            w.write(conn, T0_NS + i * STEP_NS,
                    ts.serialize_cdr(imu_message(ts, stamps[i], gyro[i], acc[i]), IMU))
    (file,) = folder.glob("*.mcap")
    return file


@pytest.mark.parametrize("fmt", ["zstd", "lz4"])
def test_mcap_chunk_bomb(tmp_path, fmt):
    bag = mcap_bomb(tmp_path, fmt)
    assert bag.stat().st_size < 4 << 20
    refused(allan(bag, "--max-memory", BUDGET), str(bag), "chunk", "decompresses to more than")
    refused(allan(bag.parent, "--max-memory", BUDGET), str(bag.parent), "chunk")


def test_mcap_chunk_declaring_more_than_the_budget(tmp_path):
    bag = mcap_bomb(tmp_path, "zstd", bomb=0)
    from rosbags.rosbag2 import storage_mcap
    reader = storage_mcap.McapReader(bag)
    reader.open()
    (chunk,) = reader.chunks
    reader.close()
    # the chunk record and its index in the summary: uncompressed_size (u64) -> 3 GiB
    size = chunk.uncompressed_size.to_bytes(8, "little")
    data = bag.read_bytes()
    assert data.count(size) == 2 and chunk.compressed_size != chunk.uncompressed_size
    bag.write_bytes(data.replace(size, (3 << 30).to_bytes(8, "little")))
    refused(allan(bag, "--max-memory", BUDGET), str(bag), "chunk", "3 GiB")


def test_sparse_metadata_yaml(tmp_path):
    bag = write_bag(tmp_path, "run", "mcap", {"/imu0": record(7)})
    meta = bag.parent / "metadata.yaml"
    with open(meta, "r+b") as f:
        f.truncate(2 << 30)                                    # 2 GiB, sparse
    refused(allan(bag.parent, "--max-memory", BUDGET), "metadata.yaml", "more than")


def raw_bag(tmp_path, kind: str, raws: list[bytes]) -> Path:
    """A bag with ``raws`` as the messages of the IMU topic /imu0."""
    if kind == "bag":
        ts = get_typestore(Stores.ROS1_NOETIC)
        path = tmp_path / "raw.bag"
        with Writer1(path) as w:
            conn = w.add_connection("/imu0", IMU, typestore=ts)
            for i, raw in enumerate(raws):
                w.write(conn, T0_NS + i * STEP_NS, raw)
        return path
    ts = get_typestore(Stores.ROS2_HUMBLE)
    folder = tmp_path / f"raw_{kind}"
    with Writer2(folder, version=9, storage_plugin=StoragePlugin.MCAP if kind == "mcap"
                 else StoragePlugin.SQLITE3) as w:
        conn = w.add_connection("/imu0", IMU, typestore=ts)
        for i, raw in enumerate(raws):
            w.write(conn, T0_NS + i * STEP_NS, raw)
    (file,) = folder.glob(f"*.{kind}")
    return file


@pytest.mark.parametrize("kind", ["bag", "db3", "mcap"])
def test_message_declaring_a_huge_frame_id(tmp_path, kind):
    ts = get_typestore(Stores.ROS1_NOETIC if kind == "bag" else Stores.ROS2_HUMBLE)
    ser = ts.serialize_ros1 if kind == "bag" else ts.serialize_cdr
    stamps, gyro, acc = record(8)
    raws = [bytes(ser(imu_message(ts, stamps[i], gyro[i], acc[i]), IMU)) for i in range(len(stamps))]
    bad = bytearray(raws[9])
    bad[12:16] = (1 << 30).to_bytes(4, "little")            # header.frame_id: 1 GiB declared
    raws[9] = bytes(bad)
    bag = raw_bag(tmp_path, kind, raws)
    refused(allan(bag, "--max-memory", BUDGET), str(bag), "message 10", "frame_id")


def file_compressed_folder(tmp_path, extra: int = 0) -> Path:
    """A ROS2 folder in compression_mode 'file' whose .db3.zstd holds the bag and ``extra``
    zero bytes after it (sqlite reads the pages its header counts)."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    folder = tmp_path / "filemode"
    stamps, gyro, acc = record(9)
    w = Writer2(folder, version=9, storage_plugin=StoragePlugin.SQLITE3)
    w.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
    with w:
        conn = w.add_connection("/imu0", IMU, typestore=ts)
        for i in range(len(stamps)):
            w.write(conn, T0_NS + i * STEP_NS,
                    ts.serialize_cdr(imu_message(ts, stamps[i], gyro[i], acc[i]), IMU))
    (file,) = folder.glob("*.zstd")
    if extra:
        file.write_bytes(zstd.compress(zstd.decompress(file.read_bytes()))
                         + zeros_frames(zstd.compress, extra))
    return folder


def test_message_compressed_folder_reads_and_its_bomb_is_refused(tmp_path):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    folder = tmp_path / "msgmode"
    stamps, gyro, acc = record(12)
    w = Writer2(folder, version=9, storage_plugin=StoragePlugin.SQLITE3)
    w.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    with w:
        conn = w.add_connection("/imu0", IMU, typestore=ts)
        for i in range(len(stamps)):
            w.write(conn, T0_NS + i * STEP_NS,
                    ts.serialize_cdr(imu_message(ts, stamps[i], gyro[i], acc[i]), IMU))
    o = run_cli(allan(folder))
    assert_contract(o)
    assert o.code == 0 and set(o.json["gyros"]) == {"1", "2", "3"}
    (bag,) = folder.glob("*.db3")
    con = sqlite3.connect(bag)
    con.execute("UPDATE messages SET data = ? WHERE id = 3", (zstd.compress(b"\0" * (8 << 20)),))
    con.commit()
    con.close()
    refused(allan(folder), str(folder), "message 3", "decompresses to more than 1 MiB")


def test_file_compressed_folder_reads(tmp_path):
    folder = file_compressed_folder(tmp_path)
    o = run_cli(allan(folder))
    assert_contract(o)
    assert o.code == 0 and set(o.json["gyros"]) == {"1", "2", "3"}


def test_file_compressed_folder_bomb(tmp_path, monkeypatch):
    import tempfile
    folder = file_compressed_folder(tmp_path, extra=BOMB)
    assert sum(f.stat().st_size for f in folder.iterdir()) < 1 << 20
    tmp = tmp_path / "tmpdir"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))          # $TMPDIR, as tempfile reads it
    refused(allan(folder, "--max-memory", "64M"), str(folder), "decompresses to more than 64 MiB")
    assert not any(tmp.iterdir())                               # nothing left behind


def test_file_compressed_folder_without_the_disk_space(tmp_path, monkeypatch):
    folder = file_compressed_folder(tmp_path)
    real = shutil.disk_usage

    def full(path):
        u = real(path)
        return type(u)(u.total, u.total - 1000, 1000)
    monkeypatch.setattr(shutil, "disk_usage", full)
    refused(allan(folder), str(folder), "free")


# -- metadata.yaml: counts and types ----------------------------------------------------------
def edited_metadata(tmp_path, edit) -> Path:
    bag = write_bag(tmp_path, "run", "db3", {"/imu0": record(10)})
    meta = bag.parent / "metadata.yaml"
    doc = yaml.safe_load(meta.read_text())
    edit(doc["rosbag2_bagfile_information"])
    meta.write_text(yaml.safe_dump(doc))
    return bag.parent


def set_count(value):
    def edit(info):
        info["topics_with_message_count"][0]["message_count"] = value
    return edit


@pytest.mark.parametrize("value", [10**8, 1e8, [1, 2], float("nan"), -5, "many", True, 399],
                         ids=["1e8", "1e8_float", "list", "nan", "negative", "text", "bool",
                              "disagrees"])
def test_metadata_message_counts(tmp_path, value):
    folder = edited_metadata(tmp_path, set_count(value))
    refused(allan(folder, "--max-memory", BUDGET), "metadata.yaml",
            "topics_with_message_count[0].message_count")


@pytest.mark.parametrize("field,value", [
    ("topics_with_message_count[0].topic_metadata.name", ["/imu0", "/x"]),
    ("topics_with_message_count[0].topic_metadata.type", {"a": 1}),
    ("topics_with_message_count[0].topic_metadata", "imu"),
    ("topics_with_message_count", {"a": 1}),
    ("relative_file_paths", "run_0.db3"),
    ("storage_identifier", 7),
    ("version", "nine"),
    ("message_count", -1),
    ("duration", 5),
    ("compression_mode", ["file"]),
])
def test_metadata_field_types(tmp_path, field, value):
    def edit(info):
        parts = field.replace("[0]", ".0").split(".")
        node = info
        for p in parts[:-1]:
            node = node[int(p)] if p.isdigit() else node[p]
        node[int(parts[-1]) if parts[-1].isdigit() else parts[-1]] = value
    folder = edited_metadata(tmp_path, edit)
    refused(allan(folder), "metadata.yaml", f"rosbag2_bagfile_information.{field}")


# -- --extrinsics ------------------------------------------------------------------------------
def pair(tmp_path) -> Path:
    r = record(11)
    return write_bag(tmp_path, "pair", "mcap", {"/imu0": r, "/imu1": r})


@pytest.mark.parametrize("case", ["huge_int", "det_minus_one", "not_orthonormal", "nan",
                                  "huge_translation"])
def test_extrinsics_not_a_rotation(tmp_path, case):
    bag = pair(tmp_path)
    T = np.eye(4).tolist()
    if case == "huge_int":
        text = kalibr_yaml(tmp_path / "e.yaml", {"/imu0": np.eye(4), "/imu1": np.eye(4)}).read_text()
        text = text.replace("1.0", str(10**400), 1)
        (tmp_path / "e.yaml").write_text(text)
    else:
        M = np.array(T)
        if case == "det_minus_one":
            M[2, 2] = -1.0
        elif case == "not_orthonormal":
            M[0, 1] = 1e-3
        elif case == "nan":
            M[1, 1] = np.nan
        else:
            M[0, 3] = 1e30
        kalibr_yaml(tmp_path / "e.yaml", {"/imu0": np.eye(4), "/imu1": M})
        text = (tmp_path / "e.yaml").read_text().replace("nan", ".nan")   # YAML's NaN
        (tmp_path / "e.yaml").write_text(text)
    err = refused(["convert", bag, "--topic", "/imu0,/imu1", "--extrinsics", tmp_path / "e.yaml",
                   "--out", tmp_path / "o.csv"], "e.yaml", "T_i_b")
    if case in ("det_minus_one", "not_orthonormal"):
        assert "R·Rᵀ = I within 1e-06, det +1" in err, err
    if case == "nan":
        assert "row 2, entry 2 is nan" in err, err


def test_extrinsics_nested_deep(tmp_path):
    bag = pair(tmp_path)
    (tmp_path / "deep.yaml").write_text("imu0:\n  T_i_b: " + "[" * 3000 + "]" * 3000 + "\n")
    refused(["convert", bag, "--topic", "/imu0,/imu1", "--extrinsics", tmp_path / "deep.yaml",
             "--out", tmp_path / "o.csv"], "deep.yaml")
    (tmp_path / "fifo.yaml").unlink(missing_ok=True)
    os.mkfifo(tmp_path / "fifo.yaml")
    refused(["convert", bag, "--topic", "/imu0,/imu1", "--extrinsics", tmp_path / "fifo.yaml",
             "--out", tmp_path / "o.csv"], "fifo.yaml", "FIFO", timeout=20)


CHILD = """
import json, resource, sys
from gyroarray.cli.main import main
rss = []
codes = []
for argv in json.loads(sys.argv[1]):
    codes.append(main(argv))
    rss.append(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
print(json.dumps({"codes": codes, "rss": rss}))
"""


@pytest.mark.slow
def test_bombs_stay_under_the_budget_in_a_child(tmp_path):
    """The bombs read in a fresh process after a plain bag: refused, and its peak RSS grows by
    less than a third of the 200 MiB budget past the plain bag's (the interpreter, numpy, scipy
    and rosbags), where each bomb expands to 400 MiB."""
    import json
    import subprocess
    import sys
    plain = write_bag(tmp_path, "plain", "mcap", {"/imu0": record(13)})
    bags = [ros1_bomb(tmp_path, Writer1.CompressionFormat.BZ2), mcap_bomb(tmp_path, "zstd"),
            mcap_bomb(tmp_path, "lz4"), file_compressed_folder(tmp_path, extra=BOMB)]
    argv = [["allan", str(b), "--json", "--max-memory", BUDGET] for b in [plain, *bags]]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    res = subprocess.run([sys.executable, "-c", CHILD, json.dumps(argv)], capture_output=True,
                         text=True, timeout=120, env=env, cwd=Path(__file__).parent.parent)
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert got["codes"] == [0, 2, 2, 2, 2], res.stderr
    assert res.stderr.count("decompresses to more than") == 4, res.stderr
    grown = got["rss"][-1] - got["rss"][0]
    assert grown < 64 << 20, (grown / 2**20, got["rss"])
