"""Real bags as they come (issue 42, item 5): dropped messages kept as gaps, jittered stamps
accepted within the stated tolerance, bunched or repeated stamps refused or re-timed, header
or receive stamps, ROS1-profile MCAP, truncated bags salvaged (or refused with the salvage
command), and a bounded-memory streamed convert.

No robot_localization bag is in tests/data, so real-like records are written here: a ROS1
.bag by rosbags (bz2 chunks), and ROS2 copies by other writers than rosbags: MCAP by
``mcap-ros2-support`` (zstd, lz4, none) and .db3 in rosbag2's schemas v1, v3 and v4 by plain
sqlite3 with CDR from mcap-ros2-support's serializer."""

from __future__ import annotations

import json
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.writer import Writer as Ros2McapWriter
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_typestore

from gyroarray.core import units
from gyroarray.core.bags import BagStream, JITTER_MAX_STEPS
from gyroarray.core.errors import InputError
from gyroarray.core.measurement import read_measurement
from tests.hostile import assert_contract, run_cli
from tests.test_bags import IMU, imu_message, write_bag

#: sensor_msgs/msg/Imu as rosbag2 stores it (ros2msg, the dependencies after '=' lines).
IMU_ROS2_MSGDEF = """std_msgs/Header header
geometry_msgs/Quaternion orientation
float64[9] orientation_covariance
geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance
geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Quaternion
float64 x
float64 y
float64 z
float64 w
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
"""
T0_NS = 1_400_000_000_987_654_321          # an epoch stamp whose ns a double would lose
STEP_NS = 10_000_000                       # 100 Hz (the Husky's IMU)


def husky_record(seed: int = 1, n: int = 3000):
    """A resting IMU at 100 Hz as real bags hold it: header stamps with ±0.3 ms jitter, one
    stamp 0.65 step late (the AR.Drone bag's 1.65-step step at message 5), 3 messages
    dropped after message 1000 and 40 after message 2000 (of the kept ones); receive stamps
    1-3 ms after the header ones. Returns (header [ns], receive [ns], gyro [rad/s], acc)."""
    rng = np.random.default_rng(seed)
    k = np.arange(n + 43, dtype=np.int64)
    header = T0_NS + k * STEP_NS + rng.integers(-300_000, 300_000, k.size)
    header[4] = T0_NS + 3 * STEP_NS + 165 * STEP_NS // 100      # 1.65 steps after message 4
    keep = np.r_[0:1000, 1003:2003, 2043:n + 43]
    header = header[keep]
    receive = header + rng.integers(1_000_000, 3_000_000, header.size)
    gyro = rng.normal(0.0, 0.002, (header.size, 3)) + [1e-3, -2e-3, 7.3e-5]
    acc = rng.normal(0.0, 0.02, (header.size, 3)) + [0.0, 0.0, 9.81]
    return header, receive, gyro, acc


def ros2_dict(stamp_ns: int, w, a, frame: str = "imu_link") -> dict:
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    return {"header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            "orientation_covariance": [-1.0] + [0.0] * 8,
            "angular_velocity": {"x": float(w[0]), "y": float(w[1]), "z": float(w[2])},
            "angular_velocity_covariance": [0.0] * 9,
            "linear_acceleration": {"x": float(a[0]), "y": float(a[1]), "z": float(a[2])},
            "linear_acceleration_covariance": [0.0] * 9}


def write_ros1(path: Path, rec, topic: str = "/imu/data") -> Path:
    """rosbags' ROS1 writer, bz2 chunks, receive stamps as the record times."""
    header, receive, gyro, acc = rec
    ts = get_typestore(Stores.ROS1_NOETIC)
    w = Writer1(path)
    w.set_compression(Writer1.CompressionFormat.BZ2)
    with w:
        conn = w.add_connection(topic, IMU, typestore=ts)
        for i in range(header.size):
            w.write(conn, int(receive[i]), ts.serialize_ros1(imu_message(ts, header[i], gyro[i], acc[i]), IMU))
    return path


def write_mcap_ros2(path: Path, rec, compression=CompressionType.ZSTD, topic: str = "/imu/data",
                    chunk_size: int = 1 << 20) -> Path:
    """mcap-ros2-support's writer (its own CDR serializer), receive stamps as log times."""
    header, receive, gyro, acc = rec
    with open(path, "wb") as fh:
        w = Ros2McapWriter(fh, compression=compression, chunk_size=chunk_size)
        schema = w.register_msgdef(IMU, IMU_ROS2_MSGDEF)
        for i in range(header.size):
            w.write_message(topic, schema, ros2_dict(header[i], gyro[i], acc[i]),
                            log_time=int(receive[i]), publish_time=int(receive[i]))
        w.finish()
    return path


def write_db3(path: Path, rec, version: int, topic: str = "/imu/data") -> Path:
    """A rosbag2 sqlite3 file in schema ``version`` (1: no schema table, 3: qos profiles,
    4: message definitions), CDR from mcap-ros2-support's serializer, by plain sqlite3."""
    header, receive, gyro, acc = rec
    encode = serialize_dynamic(IMU, IMU_ROS2_MSGDEF)[IMU]
    con = sqlite3.connect(path)
    cols = "id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, serialization_format TEXT NOT NULL"
    if version >= 3:
        cols += ", offered_qos_profiles TEXT NOT NULL"
    if version >= 4:
        cols += ", type_description_hash TEXT NOT NULL"
    con.execute(f"CREATE TABLE topics({cols})")
    con.execute("CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, "
                "timestamp INTEGER NOT NULL, data BLOB NOT NULL)")
    if version >= 3:
        con.execute("CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL)")
        con.execute("INSERT INTO schema VALUES (?, 'humble')", (version,))
    if version >= 4:
        con.execute("CREATE TABLE message_definitions(id INTEGER PRIMARY KEY, topic_type TEXT NOT "
                    "NULL, encoding TEXT NOT NULL, encoded_message_definition TEXT NOT NULL, "
                    "type_description_hash TEXT NOT NULL)")
        con.execute("INSERT INTO message_definitions VALUES (1, ?, 'ros2msg', ?, '')",
                    (IMU, IMU_ROS2_MSGDEF))
    values = [1, topic, IMU, "cdr"] + ([""] if version >= 3 else []) + ([""] if version >= 4 else [])
    con.execute(f"INSERT INTO topics VALUES ({','.join('?' * len(values))})", values)
    con.executemany("INSERT INTO messages(topic_id, timestamp, data) VALUES (1, ?, ?)",
                    [(int(receive[i]), encode(ros2_dict(header[i], gyro[i], acc[i])))
                     for i in range(header.size)])
    con.commit()
    con.close()
    return path


def refused(argv, *fragments) -> str:
    o = run_cli(argv)
    assert_contract(o, str(argv[1]))
    assert o.code == 2, o.out
    for f in fragments:
        assert f in o.err, (f, o.err)
    return o.err


# -- the same record in every format: bit-identical, gaps and jitter included ----------------
REAL_LIKE = ["bag_bz2", "mcap_zstd", "mcap_lz4", "mcap_none", "db3_v1", "db3_v3", "db3_v4"]


def real_like(tmp_path: Path, kind: str, rec) -> Path:
    if kind == "bag_bz2":
        return write_ros1(tmp_path / "husky.bag", rec)
    if kind.startswith("mcap"):
        comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                "none": CompressionType.NONE}[kind.split("_")[1]]
        return write_mcap_ros2(tmp_path / "husky.mcap", rec, comp)
    return write_db3(tmp_path / "husky.db3", rec, int(kind[-1]))


@pytest.mark.parametrize("kind", REAL_LIKE)
def test_real_like_bag_with_gaps_and_jitter(tmp_path, kind):
    rec = husky_record()
    header, receive, gyro, acc = rec
    bag = real_like(tmp_path, kind, rec)
    m = read_measurement(bag, gaps=True)
    # time_s: exact integer ns from the first stamp, then one correctly rounded division
    assert np.array_equal(m.time_s, (header - header[0]) / 1e9)
    assert np.array_equal(m.gyro_deg_s, units.rad_s_to_deg_s(gyro))
    assert np.array_equal(m.acc_m_s2, acc)
    want = 1e9 / float(np.median(np.diff(header)))
    assert abs(m.sample_rate_hz - want) <= np.spacing(want)          # within 1 ulp
    assert m.topics == ("/imu/data",)
    gap = [n for n in m.notes if "gap(s) in time_s kept" in n]
    assert len(gap) == 1 and "2 gap(s)" in gap[0] and "43 message(s) dropped" in gap[0]
    assert "before message 1001 (3)" in gap[0] and "before message 2001 (40)" in gap[0]
    # the 1.65-step stamp and the ±0.3 ms jitter: accepted with the tolerance said
    jit = [n for n in m.notes if "jitter" in n]
    assert len(jit) == 1 and f"tolerance {JITTER_MAX_STEPS:g} step" in jit[0]
    # without --gaps: refused at the first message after the drop, naming both ways out
    with pytest.raises(InputError, match=r"message 1001: a gap .*3 missing messages.*--gaps.*--repair"):
        read_measurement(bag)
    # receive stamps: the bag's log times
    r = read_measurement(bag, gaps=True, stamps="receive")
    assert np.array_equal(r.time_s, (receive - receive[0]) / 1e9)
    assert "receive stamps" in r.description and "receive stamp" in r.notes[0]


def test_every_writer_gives_the_same_bits(tmp_path):
    rec = husky_record(2)
    got = []
    for kind in REAL_LIKE:
        folder = tmp_path / kind
        folder.mkdir()
        got.append(read_measurement(real_like(folder, kind, rec), gaps=True))
    for m in got[1:]:
        assert np.array_equal(m.time_s, got[0].time_s)
        assert np.array_equal(m.gyro_deg_s, got[0].gyro_deg_s)
        assert m.sample_rate_hz == got[0].sample_rate_hz


def test_allan_gaps_on_a_bag_equals_the_csv(tmp_path):
    """The same samples as a CSV and as a bag give the same pooled ADEV with --gaps."""
    rec = husky_record(3)
    bag = write_mcap_ros2(tmp_path / "g.mcap", rec)
    csv = tmp_path / "g.csv"
    o = run_cli(["convert", bag, "--gaps", "--out", csv, "--json"])
    assert_contract(o)
    assert o.code == 0 and o.json["streamed"] and o.json["topics"] == ["/imu/data"]
    back = read_measurement(csv, gaps=True)
    assert np.array_equal(back.time_s, (rec[0] - rec[0][0]) / 1e9)
    a = run_cli(["allan", bag, "--gaps", "--json"])
    b = run_cli(["allan", csv, "--gaps", "--json"])
    assert a.code == 0 and b.code == 0, (a.err, b.err)
    for g in ("1", "2", "3"):
        assert a.json["gyros"][g]["adev_deg_h"] == b.json["gyros"][g]["adev_deg_h"]
    refused(["allan", bag], "message 1001", "--gaps")
    refused(["convert", bag, "--out", tmp_path / "x.csv"], "message 1001", "--gaps")
    assert not (tmp_path / "x.csv").exists()
    # --repair fills only gaps of up to 5 samples: the 40-message gap is refused, naming --gaps
    refused(["convert", bag, "--repair", "--out", tmp_path / "y.csv"], "message 2001", "--gaps")


def test_a_single_drop_is_still_a_gap_and_a_late_stamp_is_not(tmp_path):
    n = 400
    stamps = T0_NS + STEP_NS * np.arange(n, dtype=np.int64)
    late = stamps.copy()
    late[4] = stamps[3] + 165 * STEP_NS // 100                      # 1.65 steps, then 0.35
    g = np.zeros((n, 3)) + 1e-3
    a = np.zeros((n, 3))
    m = read_measurement(write_mcap_ros2(tmp_path / "late.mcap", (late, late, g, a)))
    assert np.array_equal(m.time_s, (late - late[0]) / 1e9)
    assert any("jitter" in x and "0.65 steps" in x for x in m.notes)
    keep = np.r_[0:4, 5:n]                                           # message 5 dropped
    drop = write_mcap_ros2(tmp_path / "drop.mcap", (stamps[keep], stamps[keep], g[keep], a[keep]))
    with pytest.raises(InputError, match="message 5: a gap of 0.02 s .1 missing"):
        read_measurement(drop)


def bunched(n: int = 600, burst: int = 5, repeat: bool = False):
    """Stamps in bursts of ``burst`` messages (a driver stamping at delivery): 1 µs apart, or
    repeating exactly."""
    i = np.arange(n, dtype=np.int64)
    within = 0 if repeat else 1000
    return T0_NS + (i // burst) * burst * STEP_NS + (i % burst) * within


@pytest.mark.parametrize("repeat", [False, True], ids=["bunched", "repeated"])
def test_bunched_stamps_refused_then_retimed(tmp_path, repeat):
    st = bunched(repeat=repeat)
    rng = np.random.default_rng(4)
    g = rng.normal(0, 0.01, (st.size, 3))
    bag = write_mcap_ros2(tmp_path / "b.mcap", (st, st, g, np.zeros((st.size, 3))))
    err = refused(["allan", bag], "topic /imu/data", "message ", "--retime")
    assert ("repeats" in err) == repeat
    m = read_measurement(bag, retime=True)
    # the rule: the uniform grid from the first stamp at the mean step (span / (n - 1))
    period = (int(st[-1]) - int(st[0])) / (st.size - 1) / 1e9
    assert np.array_equal(m.time_s, np.arange(st.size) * period)
    assert m.sample_rate_hz == 1.0 / period
    assert np.array_equal(m.gyro_deg_s, units.rad_s_to_deg_s(g))
    assert any("re-timed (--retime)" in x for x in m.notes)
    o = run_cli(["allan", bag, "--retime", "--json"])
    assert_contract(o)
    assert o.code == 0


def test_retime_refuses_a_drop_it_would_hide(tmp_path):
    n = 1000
    # 200 dropped mid-way: the mean-step grid is ~100 steps off there (more than 64)
    st = T0_NS + STEP_NS * np.r_[0:500, 700:n + 200].astype(np.int64)
    g = np.zeros((n, 3))
    bag = write_mcap_ros2(tmp_path / "d.mcap", (st, st, g, g))
    with pytest.raises(InputError, match="--retime: .* steps from its time on the uniform"):
        read_measurement(bag, retime=True)


def test_stamps_option_and_retime_are_for_bags(tmp_path):
    from tests.hostile import SIDECAR_3, write_measurement
    csv = write_measurement(tmp_path, "plain", np.arange(50) / 50.0,
                            np.random.default_rng(13).normal(size=(50, 3)), SIDECAR_3)
    with pytest.raises(InputError, match="--stamps is for ROS bags"):
        read_measurement(csv, stamps="receive")
    with pytest.raises(InputError, match="--retime is for ROS bags"):
        read_measurement(csv, retime=True)


# -- ROS1-profile MCAP (what `mcap convert x.bag` writes) ------------------------------------
def write_mcap_ros1(path: Path, rec, topic: str = "/imu0") -> Path:
    header, receive, gyro, acc = rec
    ts = get_typestore(Stores.ROS1_NOETIC)
    msgdef, _ = ts.generate_msgdef(IMU, ros_version=1)
    with open(path, "wb") as fh:
        w = McapWriter(fh, compression=CompressionType.ZSTD, chunk_size=1 << 16)
        w.start(profile="ros1", library="test")
        sid = w.register_schema(name="sensor_msgs/Imu", encoding="ros1msg", data=msgdef.encode())
        cid = w.register_channel(topic=topic, message_encoding="ros1", schema_id=sid)
        for i in range(header.size):
            w.add_message(cid, log_time=int(receive[i]), publish_time=int(receive[i]),
                          data=ts.serialize_ros1(imu_message(ts, header[i], gyro[i], acc[i]), IMU))
        w.finish()
    return path


def test_ros1_profile_mcap_reads_bit_identical(tmp_path):
    rec = husky_record(5, n=2500)
    header, receive, gyro, acc = rec
    bag = write_mcap_ros1(tmp_path / "ros1.mcap", rec)
    m = read_measurement(bag, gaps=True)
    assert np.array_equal(m.time_s, (header - header[0]) / 1e9)
    assert np.array_equal(m.gyro_deg_s, units.rad_s_to_deg_s(gyro))
    assert np.array_equal(m.acc_m_s2, acc)
    assert "ROS1-profile MCAP" in m.notes[0] and m.topics == ("/imu0",)
    # the same bits as the ROS1 .bag rosbags writes of the same record
    same = read_measurement(write_ros1(tmp_path / "ros1.bag", rec, "/imu0"), gaps=True)
    assert np.array_equal(same.time_s, m.time_s) and np.array_equal(same.gyro_deg_s, m.gyro_deg_s)
    out = tmp_path / "ros1.parquet"
    o = run_cli(["convert", bag, "--gaps", "--out", out, "--json"])
    assert_contract(o)
    assert o.code == 0
    back = read_measurement(out, gaps=True)
    assert np.array_equal(back.time_s, m.time_s) and np.array_equal(back.gyro_deg_s, m.gyro_deg_s)


# -- truncated bags: salvaged with a note, or refused with the salvage command ---------------
def test_truncated_mcap_is_salvaged(tmp_path):
    n = 20000
    rng = np.random.default_rng(6)
    st = T0_NS + STEP_NS * np.arange(n, dtype=np.int64) + rng.integers(0, 20_000, n)
    g = rng.normal(0, 0.01, (n, 3))
    full = write_mcap_ros2(tmp_path / "full.mcap", (st, st, g, g), chunk_size=1 << 18)
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) // 2])
    # what the cut keeps, from the full file's own chunk index: every chunk ending before it
    from mcap.reader import make_reader
    with open(full, "rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    whole = [c for c in chunks if c.chunk_start_offset + c.chunk_length <= len(data) // 2]
    assert 1 <= len(whole) < len(chunks)
    kept = int(np.sum(st <= max(c.message_end_time for c in whole)))
    m = read_measurement(cut)
    assert m.n_samples == kept
    assert np.array_equal(m.time_s, (st[:kept] - st[0]) / 1e9)
    assert np.array_equal(m.gyro_deg_s, units.rad_s_to_deg_s(g[:kept]))
    note = [x for x in m.notes if "salvaged" in x]
    assert len(note) == 1 and f"read {kept} messages" in note[0] and "mcap recover" in note[0]
    assert f"the last received at {st[kept - 1] // 10**9}." in note[0]


def test_truncated_ros1_bag_is_salvaged_chunk_by_chunk(tmp_path):
    rec = husky_record(7, n=20000)
    header, _, gyro, _ = rec
    full = write_ros1(tmp_path / "full.bag", rec)
    data = full.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[:len(data) // 2])
    m = read_measurement(cut, gaps=True)
    k = m.n_samples
    assert 1000 < k < header.size
    assert np.array_equal(m.time_s, (header[:k] - header[0]) / 1e9)
    assert np.array_equal(m.gyro_deg_s, units.rad_s_to_deg_s(gyro[:k]))
    assert any("salvaged" in x and f"read {k} messages" in x and "rosbag reindex" in x for x in m.notes)


@pytest.mark.parametrize("kind,command", [("mcap", "mcap recover"), ("db3", ".recover"),
                                          ("bag", "rosbag reindex")])
def test_nothing_to_salvage_names_the_command(tmp_path, kind, command):
    """rosbags' MCAP writer puts a small bag in one chunk, so half of it holds no message."""
    from tests.test_bags import record
    bag = write_bag(tmp_path, "one", kind, {"/imu0": record(8)})
    cut = tmp_path / f"cut.{kind}"
    cut.write_bytes(bag.read_bytes()[:bag.stat().st_size // 2])
    refused(["allan", cut], "truncated or corrupt", command)


# -- streamed convert: chunk by chunk, the bits of the whole read -----------------------------
def test_stream_chunks_equal_the_whole_read(tmp_path):
    rec = husky_record(9)
    bag = write_ros1(tmp_path / "s.bag", rec)
    whole = read_measurement(bag, gaps=True)
    s = BagStream(bag, gaps=True, chunk=700)             # chunk edges near the gaps too
    parts = list(s.chunks())
    assert len(parts) == -(-whole.n_samples // 700)
    assert np.array_equal(np.concatenate([p[0] for p in parts]), whole.time_s)
    assert np.array_equal(np.vstack([p[1] for p in parts]), whole.gyro_deg_s)
    assert np.array_equal(np.vstack([p[2] for p in parts]), whole.acc_m_s2)
    # the same gaps found (the period is the first chunk's median step here, the whole
    # record's there, so the step printed differs in its last digits)
    def where(notes):
        return [n.split("step: ")[1] for n in notes if "gap(s) in time_s kept" in n]
    assert where(s.notes) == where(whole.notes) == [
        "before message 1001 (3), before message 2001 (40)), nothing interpolated"]
    assert any("median step of the first chunk" in n for n in s.notes)


def test_progress_bar_on_request(tmp_path):
    bag = write_mcap_ros2(tmp_path / "p.mcap", husky_record(10, n=2500))
    o = run_cli(["convert", bag, "--gaps", "--progress", "--out", tmp_path / "p.csv.gz"])
    assert o.code == 0 and "msg" in o.err and "convert /imu/data" in o.err
    quiet = run_cli(["convert", bag, "--gaps", "--out", tmp_path / "q.csv.gz"])
    assert quiet.code == 0 and quiet.err == ""           # stderr no terminal: no bar


def fast_mcap(path: Path, n: int) -> tuple[np.ndarray, np.ndarray]:
    """An MCAP of ``n`` messages at 400 Hz, written fast: one CDR message by mcap-ros2-support,
    its stamp and rates patched in place with numpy, raw messages through the mcap writer."""
    encode = serialize_dynamic(IMU, IMU_ROS2_MSGDEF)[IMU]
    template = encode(ros2_dict(T0_NS, [0.0, 0.0, 0.0], [0.0, 0.0, 9.81]))
    size = len(template)
    # CDR: 4-byte encapsulation, sec (i32), nanosec (u32), frame_id (u32 length + text + NUL),
    # then 8-aligned doubles: orientation 4, covariance 9, angular_velocity 3
    flen = int.from_bytes(template[12:16], "little")
    pos = 4 + -(-(16 + flen - 4) // 8) * 8 + 13 * 8
    rng = np.random.default_rng(11)
    stamps = T0_NS + 2_500_000 * np.arange(n, dtype=np.int64)
    gyro = rng.normal(0.0, 0.01, (n, 3))
    buf = np.tile(np.frombuffer(template, np.uint8), (n, 1))
    buf[:, 4:8] = (stamps // 10**9).astype("<i4").view(np.uint8).reshape(n, 4)
    buf[:, 8:12] = (stamps % 10**9).astype("<u4").view(np.uint8).reshape(n, 4)
    buf[:, pos:pos + 24] = gyro.astype("<f8").view(np.uint8).reshape(n, 24)
    raw = buf.tobytes()
    with open(path, "wb") as fh:
        w = McapWriter(fh, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(name=IMU, encoding="ros2msg", data=IMU_ROS2_MSGDEF.encode())
        cid = w.register_channel(topic="/imu", message_encoding="cdr", schema_id=sid)
        for i in range(n):
            t = int(stamps[i])
            w.add_message(cid, log_time=t, publish_time=t, data=raw[i * size:(i + 1) * size])
        w.finish()
    return stamps, gyro


CHILD = r"""
import json, resource, sys
import numpy, pyarrow, rosbags.rosbag2, rosbags.typesys, tqdm, mcap  # the imports, before
from gyroarray.cli.main import main
import gyroarray.cli.convert, gyroarray.core.bags, gyroarray.core.measurement
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
code = main(sys.argv[1:])
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"code": code, "before_kib": before, "after_kib": after}))
"""


@pytest.mark.slow
def test_convert_of_a_million_messages_in_bounded_memory(tmp_path):
    """1e6 messages (42 min at 400 Hz). Read whole, the record alone is >= 150 MB: read_bag's
    stamps, receive times and 7 values (72 B/message) plus the Measurement's time, rates and
    specific force (56 B) and the deg/s conversion (24 B); the CSV text is another ~130 MB.
    Streamed, a chunk is 16384 raw messages of 284 B (4.7 MB, held twice while decoded and
    joined), its values as Python floats and its text (~10 MB) and the MCAP reader's 1 MiB
    chunk, about 25 MB: the bound of 60 MB on the peak RSS growth leaves room for the
    allocator's slack and is 40 % of the whole read's lower bound (measured when this test
    was written: 32 MB streamed, 434 MB for read_measurement + write_measurement of the same
    bag). The bound does not grow with the record: the clock keeps 2·JITTER_WINDOW stamps."""
    n = 1_000_000
    bag = tmp_path / "long.mcap"
    stamps, gyro = fast_mcap(bag, n)
    out = tmp_path / "long.csv.gz"
    run = subprocess.run([sys.executable, "-c", CHILD, "convert", str(bag), "--out", str(out),
                          "--json"], capture_output=True, text=True, timeout=600,
                         env={**__import__("os").environ, "OPENBLAS_NUM_THREADS": "1"})
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["code"] == 0, run.stderr
    growth_mb = (got["after_kib"] - got["before_kib"]) / 1024
    assert growth_mb < 60, growth_mb
    back = read_measurement(out)
    assert back.n_samples == n
    assert np.array_equal(back.time_s, (stamps - stamps[0]) / 1e9)
    assert np.array_equal(back.gyro_deg_s, units.rad_s_to_deg_s(gyro))
