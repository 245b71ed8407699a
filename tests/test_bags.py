"""ROS bags in (issue 33, item 1): bags written here with rosbags' own writers (ROS1 .bag, ROS2
.db3 and .mcap) from numpy records read back to bit-identical stamps and rates; arrays of
several IMU topics with Kalibr extrinsics; one-line refusals naming the bag, the topic and the
message index."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
from rosbags.typesys import Stores, get_typestore

from gyroarray.core import units
from gyroarray.core.errors import InputError
from gyroarray.core.measurement import read_measurement
from tests.hostile import SIDECAR_3, assert_contract, run_cli, write_measurement

IMU = "sensor_msgs/msg/Imu"
T0_NS = 1_700_000_000_123_456_789        # a Unix-epoch stamp: a double would lose its ns
STEP_NS = 5_000_000                      # 200 Hz
N = 400


def record(seed: int, n: int = N, t0_ns: int = T0_NS, step_ns: int = STEP_NS):
    """(stamps [ns], rates [rad/s], specific force [m/s²]) of a resting IMU."""
    rng = np.random.default_rng(seed)
    stamps = t0_ns + step_ns * np.arange(n, dtype=np.int64) + rng.integers(0, 20_000, n)
    gyro = rng.normal(0.0, 0.01, (n, 3)) + [1e-3, -2e-3, 7.3e-5]
    acc = rng.normal(0.0, 0.02, (n, 3)) + [0.0, 0.0, 9.81]
    return stamps, gyro, acc


def imu_message(ts, stamp_ns: int, w, a, frame: str = "imu_link"):
    t = ts.types
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    stamp = t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
    head = ({"seq": 0} if "seq" in t["std_msgs/msg/Header"].__dataclass_fields__ else {})
    header = t["std_msgs/msg/Header"](stamp=stamp, frame_id=frame, **head)
    v3 = t["geometry_msgs/msg/Vector3"]
    return t[IMU](header=header,
                  orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                  orientation_covariance=np.full(9, -1.0) * np.eye(3).ravel(),
                  angular_velocity=v3(x=float(w[0]), y=float(w[1]), z=float(w[2])),
                  angular_velocity_covariance=np.zeros(9),
                  linear_acceleration=v3(x=float(a[0]), y=float(a[1]), z=float(a[2])),
                  linear_acceleration_covariance=np.zeros(9))


def write_bag(folder: Path, name: str, kind: str, topics: dict, others: dict | None = None,
              frames=("imu_link",), garbage=()) -> Path:
    """A bag of ``{topic: (stamps, gyro, acc)}`` IMU records (and ``{topic: msgtype}`` topics
    without messages); message i has frame_id ``frames[i % len(frames)]``, and the messages
    whose index is in ``garbage`` are junk bytes. Returns the .bag, .db3 or .mcap file."""
    others = others or {}

    def data(ts, serialize, stamp, w, a, i):
        if i in garbage:
            return b"\x00\x01\x00\x00" + b"\xff" * 9
        return serialize(imu_message(ts, stamp, w, a, frames[i % len(frames)]), IMU)
    if kind == "bag":
        ts = get_typestore(Stores.ROS1_NOETIC)
        path = folder / f"{name}.bag"
        with Writer1(path) as w:
            conns = {t: w.add_connection(t, IMU, typestore=ts) for t in topics}
            for t, typ in others.items():
                w.add_connection(t, typ, typestore=ts)
            for k, (t, (st, g, a)) in enumerate(topics.items()):
                for i in range(len(st)):
                    w.write(conns[t], T0_NS + i * STEP_NS + k,
                            data(ts, ts.serialize_ros1, st[i], g[i], a[i], i))
        return path
    ts = get_typestore(Stores.ROS2_HUMBLE)
    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    folder_path = folder / name
    with Writer2(folder_path, version=9, storage_plugin=plugin) as w:
        conns = {t: w.add_connection(t, IMU, typestore=ts) for t in topics}
        for t, typ in others.items():
            w.add_connection(t, typ, typestore=ts)
        for k, (t, (st, g, a)) in enumerate(topics.items()):
            for i in range(len(st)):
                w.write(conns[t], T0_NS + i * STEP_NS + k,
                        data(ts, ts.serialize_cdr, st[i], g[i], a[i], i))
    (file,) = folder_path.glob(f"*.{kind}")
    return file


@pytest.mark.parametrize("frames", [("imu_link",), ("imu", "imu_link_with_a_longer_name")],
                         ids=["one_layout", "frame_ids_of_two_lengths"])
@pytest.mark.parametrize("kind", ["bag", "db3", "mcap"])
def test_bag_reads_back_bit_identical(tmp_path, kind, frames):
    stamps, gyro, acc = record(1)
    path = write_bag(tmp_path, "one", kind, {"/imu0": (stamps, gyro, acc)}, frames=frames)
    m = read_measurement(path)
    assert m.source == str(path) and m.n_gyros == 3 and m.n_samples == N
    # stamps: exact integer ns from the first, then one correctly rounded division
    assert np.array_equal(m.time_s, (stamps - stamps[0]) / 1e9)
    # the spec's unit is deg/s: the same conversion in numpy, bit for bit
    assert np.array_equal(m.gyro_deg_s, units.rad_s_to_deg_s(gyro))
    assert np.array_equal(m.acc_m_s2, acc)
    assert np.array_equal(m.layout.axes, np.eye(3))
    assert m.sample_rate_hz == 1e9 / float(np.median(np.diff(stamps)))
    assert f"t0 = {stamps[0] // 10**9}.{stamps[0] % 10**9:09d} s" in m.description
    assert any("jitter" in n for n in m.notes)          # the 0-20 µs stamp noise is noted


def test_ros2_folder_reads_like_its_file(tmp_path):
    stamps, gyro, acc = record(2)
    path = write_bag(tmp_path, "run", "mcap", {"/imu": (stamps, gyro, acc)})
    a, b = read_measurement(path), read_measurement(path.parent)
    assert np.array_equal(a.time_s, b.time_s) and np.array_equal(a.gyro_deg_s, b.gyro_deg_s)


def test_allan_reads_an_mcap(tmp_path):
    path = write_bag(tmp_path, "imu", "mcap", {"/imu0": record(3, n=2000)[:2] + (record(3)[2][:1].repeat(2000, 0),)})
    o = run_cli(["allan", path, "--json"])
    assert_contract(o)
    assert o.code == 0 and set(o.json["gyros"]) == {"1", "2", "3"}
    assert any("/imu0" in n for n in o.json["notes"])


def test_convert_writes_what_the_reader_reads(tmp_path):
    stamps, gyro, acc = record(4)
    path = write_bag(tmp_path, "conv", "bag", {"/imu0": (stamps, gyro, acc)})
    out = tmp_path / "meas.csv.gz"
    o = run_cli(["convert", path, "--topic", "/imu0", "--out", out, "--json"])
    assert_contract(o)
    assert o.code == 0 and o.json["n_gyros"] == 3 and Path(o.json["sidecar"]).is_file()
    m, back = read_measurement(path), read_measurement(out)
    assert np.array_equal(back.time_s, m.time_s) and np.array_equal(back.gyro_deg_s, m.gyro_deg_s)
    assert np.array_equal(back.acc_m_s2, m.acc_m_s2)
    assert np.array_equal(back.layout.axes, m.layout.axes)
    again = run_cli(["convert", path, "--out", out])           # exists: refused without --force
    assert_contract(again, str(out))
    assert again.code == 2


def rotation(axis, angle):
    """Rodrigues' rotation matrix."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def kalibr_yaml(path: Path, transforms: dict) -> Path:
    lines = []
    for k, (topic, T) in enumerate(transforms.items()):
        rows = "\n".join(f"  - [{', '.join(repr(float(v)) for v in row)}]" for row in T)
        lines.append(f"imu{k}:\n  T_i_b:\n{rows}\n  rostopic: {topic}\n  update_rate: 200.0")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_two_topics_make_a_six_gyro_array_with_extrinsics(tmp_path):
    rng = np.random.default_rng(5)
    stamps = T0_NS + STEP_NS * np.arange(N, dtype=np.int64)
    omega_b = rng.normal(0.0, 0.05, (N, 3))                 # the body rate both IMUs sense
    R1 = rotation([1.0, 2.0, -0.5], 0.7)                     # R_i_b of imu1: body to IMU
    t1 = np.array([0.05, -0.02, 0.01])
    acc = np.zeros((N, 3))
    bag = write_bag(tmp_path, "pair", "db3", {"/imu0": (stamps, omega_b, acc),
                                               "/imu1": (stamps, omega_b @ R1.T, acc)})
    T1 = np.eye(4)
    T1[:3, :3], T1[:3, 3] = R1, t1
    # listed in the other order: entries are matched by their rostopic
    ext = kalibr_yaml(tmp_path / "imu_chain.yaml", {"/imu1": T1, "/imu0": np.eye(4)})
    m = read_measurement(bag, topic="/imu0,/imu1", extrinsics=ext)
    assert m.n_gyros == 6 and m.acc_m_s2 is None
    assert np.allclose(m.layout.axes[:3], np.eye(3), atol=1e-15)
    assert np.allclose(m.layout.axes[3:], R1, atol=1e-12)
    assert np.allclose(m.layout.positions_m[3:], -R1.T @ t1, atol=1e-12)
    # every gyro reads its body axis: gyro = H omega_b
    assert np.allclose(m.gyro_deg_s, units.rad_s_to_deg_s(omega_b @ m.layout.axes.T), atol=1e-12)
    # the same through the CLI, to a file
    out = tmp_path / "pair.csv"
    o = run_cli(["convert", bag, "--topic", "/imu0,/imu1", "--extrinsics", ext, "--out", out, "--json"])
    assert_contract(o)
    assert o.code == 0 and read_measurement(out).n_gyros == 6
    # without extrinsics: the IMU axes taken as the body's, with a note
    plain = read_measurement(bag, topic="/imu0,/imu1")
    assert np.array_equal(plain.layout.axes, np.vstack([np.eye(3)] * 2))
    assert any("no --extrinsics" in n for n in plain.notes)


def test_unaligned_topics_are_interpolated_with_a_note(tmp_path):
    s0, g0, a0 = record(6)
    s1 = s0 + 1_000_000                                          # 1 ms later
    g1 = np.random.default_rng(7).normal(0, 0.01, (N, 3))
    bag = write_bag(tmp_path, "skew", "mcap", {"/a": (s0, g0, a0), "/b": (s1, g1, a0)})
    m = read_measurement(bag, topic="/a,/b")
    t0 = (s0 - s0[0]) / 1e9
    keep = t0 >= (s1[0] - s0[0]) / 1e9
    assert np.array_equal(m.time_s, t0[keep])
    want = np.interp(m.time_s, (s1 - s0[0]) / 1e9, g1[:, 2])
    assert np.array_equal(m.gyro_deg_s[:, 5], units.rad_s_to_deg_s(want))
    assert any("interpolated" in n for n in m.notes)


# -- refusals: exit 2, one line naming the bag, the topic and the message index -------------
def refused(argv, *fragments):
    o = run_cli(argv)
    assert_contract(o, str(argv[1]))
    assert o.code == 2, o.out
    for f in fragments:
        assert f in o.err, (f, o.err)
    return o.err


def test_several_topics_are_listed_not_guessed(tmp_path):
    r = record(8)
    bag = write_bag(tmp_path, "two", "mcap", {"/imu0": r, "/imu1": r})
    refused(["allan", bag], "/imu0 (400 messages)", "/imu1", "--topic /imu0,/imu1")


def test_wrong_type_and_empty_topic(tmp_path):
    bag = write_bag(tmp_path, "mixed", "bag", {"/imu0": record(9)},
                    others={"/chatter": "std_msgs/msg/String", "/imu_empty": IMU})
    out = tmp_path / "x.csv"
    refused(["convert", bag, "--topic", "/chatter", "--out", out], "topic /chatter",
            "std_msgs/msg/String, not sensor_msgs/msg/Imu")
    refused(["convert", bag, "--topic", "/imu_empty", "--out", out], "topic /imu_empty",
            "no messages")
    refused(["convert", bag, "--topic", "/nope", "--out", out], "no topic /nope")
    assert not out.exists()


@pytest.mark.parametrize("kind", ["bag", "mcap"])
def test_stamps_going_backwards(tmp_path, kind):
    stamps, gyro, acc = record(10)
    stamps[100] = stamps[98]
    bag = write_bag(tmp_path, "back", kind, {"/imu0": (stamps, gyro, acc)})
    refused(["allan", bag], "topic /imu0", "message 101", "goes backwards")
    stamps[100] = stamps[99]
    bag = write_bag(tmp_path, "same", kind, {"/imu0": (stamps, gyro, acc)})
    refused(["allan", bag], "message 101", "repeats")


def test_a_gap_is_refused_and_repaired(tmp_path):
    stamps, gyro, acc = record(11)
    keep = np.r_[0:200, 203:N]                                   # 3 messages dropped
    bag = write_bag(tmp_path, "gap", "mcap", {"/imu0": (stamps[keep], gyro[keep], acc[keep])})
    refused(["allan", bag], "topic /imu0", "message 201", "--repair")
    m = read_measurement(bag, repair=True)
    assert m.n_samples in (N - 1, N) and any("repaired" in n for n in m.notes)
    assert np.allclose(np.diff(m.time_s), 1.0 / m.sample_rate_hz, rtol=1e-9)


@pytest.mark.parametrize("kind", ["bag", "db3", "mcap"])
def test_truncated_file(tmp_path, kind):
    bag = write_bag(tmp_path, "full", kind, {"/imu0": record(12)})
    cut = tmp_path / f"cut.{kind}"
    cut.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    refused(["allan", cut], "truncated or corrupt")


def test_folder_without_metadata_and_options_on_a_csv(tmp_path):
    folder = tmp_path / "bagdir"
    folder.mkdir()
    refused(["allan", folder], "no metadata.yaml")
    csv = write_measurement(tmp_path, "plain", np.arange(50) / 50.0,
                            np.random.default_rng(13).normal(size=(50, 3)), SIDECAR_3)
    with pytest.raises(InputError, match="--topic is for ROS bags"):
        read_measurement(csv, topic="/imu0")
    assert read_measurement(csv).n_gyros == 3                    # a CSV reads as before


def test_bad_extrinsics(tmp_path):
    r = record(14)
    bag = write_bag(tmp_path, "pair", "mcap", {"/imu0": r, "/imu1": r})
    T = np.eye(4)
    T[0, 0] = 2.0                                                  # not a rotation
    ext = kalibr_yaml(tmp_path / "bad.yaml", {"/imu0": np.eye(4), "/imu1": T})
    with pytest.raises(InputError, match="not a rigid transform") as err:
        read_measurement(bag, topic="/imu0,/imu1", extrinsics=ext)
    assert "bad.yaml" in str(err.value) and "imu1.T_i_b" in str(err.value)
    (tmp_path / "junk.yaml").write_text("imu0: [unclosed\n")
    o = run_cli(["convert", bag, "--topic", "/imu0,/imu1", "--extrinsics", tmp_path / "junk.yaml",
                 "--out", tmp_path / "o.csv"])
    assert_contract(o, "junk.yaml")
    assert o.code == 2


@pytest.mark.parametrize("kind", ["bag", "mcap"])
def test_a_corrupt_message_is_located(tmp_path, kind):
    bag = write_bag(tmp_path, "junk", kind, {"/imu0": record(15)}, garbage={57})
    refused(["allan", bag], "topic /imu0", "message 58", "does not decode as sensor_msgs/msg/Imu")
