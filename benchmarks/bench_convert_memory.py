"""``gyroarray convert`` of long IMU bags: peak memory and time against the number of messages.

Issue 42, item 5: "a 24 h record at 400 Hz (35 M messages) converts in bounded memory, with a
progress bar". For each size in ``--sizes`` (default 200k and 1.6M messages, 8x apart) three
bags of one ``sensor_msgs/msg/Imu`` topic at 400 Hz are written in a temporary folder with
rosbags' own writers: a ROS1 ``.bag`` (rosbag1 Writer, ``--ros1-compression`` bz2 or lz4
chunks), a ROS2 ``.db3`` and a ROS2 ``.mcap`` (rosbag2 Writer). To write 1.6M messages in
seconds, one message is serialized by rosbags' typestore and its stamp and angular velocity
are patched in place with numpy (the offsets found by searching the serialized marker values,
so no layout is assumed); the raw messages go through the writers' ``write``.

Each bag is converted by ``gyroarray convert BAG --out OUT.parquet`` and ``--out OUT.csv.gz``,
each in a fresh process that reports its own peak RSS (``VmHWM`` of ``/proc/self/status``; not
``ru_maxrss``, which on Linux includes the forking parent's RSS) with its wall time. The table gives messages, format, output, peak RSS [MB], wall [s].

The check (bounded memory): for each bag format and output, peak RSS at the largest size is
less than ``--max-ratio`` (1.3) times the peak at the smallest, while the messages grow 8x.
Why 1.3: the fixed part of a convert process (Python, numpy, pyarrow, rosbags, mcap, tqdm
imports: ~110-150 MB) plus one chunk of STREAM_CHUNK = 16384 messages (~5 MB raw, ~10 MB of
text) does not depend on the record; a reader that kept anything per message would add at
least ~30 B/message (one int64 stamp and a pointer), i.e. >= 42 MB from 200k to 1.6M, which is
~1.3x the fixed part: a per-message structure of any practical size fails the check, the
allocator's slack (a few MB) does not. The 35 M-message case (24 h x 400 Hz = 34.56 M) is
extrapolated linearly from the two sizes: peak(35M) = peak(n2) + slope * (35M - n2), with the
slope (MB per million messages) measured between n1 and n2; its wall time likewise.

Usage: ``python benchmarks/bench_convert_memory.py [--sizes 200000,1600000]
[--ros1-compression bz2|lz4] [--formats bag,db3,mcap] [--outputs parquet,csv.gz]``
(``make bench`` runs it with the defaults through benchmarks/run.py; ``make bench
CONVERT_SIZES=...`` runs it again with other sizes). Exit status 1 when the check fails.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

IMU = "sensor_msgs/msg/Imu"
RATE_HZ = 400.0
STEP_NS = 2_500_000                      # 400 Hz
T0_NS = 1_700_000_000_123_456_789
DAY_MESSAGES = int(24 * 3600 * RATE_HZ)  # 34.56 M: 24 h at 400 Hz
MAX_RATIO = 1.3
_MARK_W = (1.2345678901234567e-3, -2.3456789012345678e-3, 3.4567890123456789e-3)
_MARK_SEC, _MARK_NSEC = 1_234_567_891, 987_654_321

# The child reports its own VmHWM (the peak RSS of its address space since exec). Not
# ru_maxrss: Linux folds the pre-exec RSS of the forked (or vforked) child, i.e. the parent's,
# into it, and the parent holds the messages it just wrote.
_CHILD = ("import re, sys\nfrom gyroarray.cli.main import main\ncode = main(sys.argv[1:])\n"
          "hwm = re.search(r'VmHWM:\\s*(\\d+) kB', open('/proc/self/status').read()).group(1)\n"
          "print('VmHWM_KB', hwm, file=sys.stderr)\nsys.exit(code)\n")


def _template(ts, ros1: bool) -> tuple[bytes, int, int, int]:
    """One serialized Imu message and the offsets of its stamp sec, nsec and angular_velocity."""
    t = ts.types
    head = {"seq": 0} if "seq" in t["std_msgs/msg/Header"].__dataclass_fields__ else {}
    header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=_MARK_SEC, nanosec=_MARK_NSEC),
                                      frame_id="imu_link", **head)
    v3 = t["geometry_msgs/msg/Vector3"]
    msg = t[IMU](header=header,
                 orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                 orientation_covariance=np.full(9, -1.0) * np.eye(3).ravel(),
                 angular_velocity=v3(x=_MARK_W[0], y=_MARK_W[1], z=_MARK_W[2]),
                 angular_velocity_covariance=np.zeros(9),
                 linear_acceleration=v3(x=0.01, y=-0.02, z=9.81),
                 linear_acceleration_covariance=np.zeros(9))
    raw = bytes(ts.serialize_ros1(msg, IMU) if ros1 else ts.serialize_cdr(msg, IMU))
    sec = raw.find(np.array([_MARK_SEC], "<u4").tobytes())
    nsec = raw.find(np.array([_MARK_NSEC], "<u4").tobytes())
    w = raw.find(np.array(_MARK_W, "<f8").tobytes())
    assert min(sec, nsec, w) >= 0 and nsec == sec + 4, (sec, nsec, w)
    return raw, sec, nsec, w


def _messages(ts, ros1: bool, n: int, seed: int) -> tuple[np.ndarray, list[bytes]]:
    """Stamps [ns] and ``n`` serialized messages of white rates (0.01 rad/s) on a bias."""
    raw, sec, nsec, w = _template(ts, ros1)
    rng = np.random.default_rng(seed)
    stamps = T0_NS + STEP_NS * np.arange(n, dtype=np.int64)
    gyro = rng.normal(0.0, 0.01, (n, 3)) + [1e-3, -2e-3, 7.3e-5]
    buf = np.tile(np.frombuffer(raw, np.uint8), (n, 1))
    buf[:, sec:sec + 4] = (stamps // 10**9).astype("<u4").view(np.uint8).reshape(n, 4)
    buf[:, nsec:nsec + 4] = (stamps % 10**9).astype("<u4").view(np.uint8).reshape(n, 4)
    buf[:, w:w + 24] = gyro.astype("<f8").view(np.uint8).reshape(n, 24)
    size = len(raw)
    flat = buf.tobytes()
    return stamps, [flat[i * size:(i + 1) * size] for i in range(n)]


def write_bag(folder: Path, kind: str, n: int, ros1_compression: str = "bz2", seed: int = 1) -> Path:
    """A bag of ``n`` Imu messages on /imu at 400 Hz: ``kind`` bag (ROS1), db3 or mcap (ROS2)."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin, Writer as Writer2
    from rosbags.typesys import Stores, get_typestore
    if kind == "bag":
        ts = get_typestore(Stores.ROS1_NOETIC)
        stamps, raws = _messages(ts, True, n, seed)
        path = folder / f"imu_{n}.bag"
        w1 = Writer1(path)
        w1.set_compression(getattr(Writer1.CompressionFormat, ros1_compression.upper()))
        with w1:
            conn = w1.add_connection("/imu", IMU, typestore=ts)
            for t, raw in zip(stamps.tolist(), raws):
                w1.write(conn, t, raw)
        return path
    ts = get_typestore(Stores.ROS2_HUMBLE)
    stamps, raws = _messages(ts, False, n, seed)
    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    folder_path = folder / f"imu_{n}_{kind}"
    with Writer2(folder_path, version=9, storage_plugin=plugin) as w2:
        conn = w2.add_connection("/imu", IMU, typestore=ts)
        for t, raw in zip(stamps.tolist(), raws):
            w2.write(conn, t, raw)
    (file,) = folder_path.glob(f"*.{kind}")
    return file


def convert(bag: Path, out: Path) -> tuple[float, float, str]:
    """(peak RSS [MB], wall [s], stderr) of ``gyroarray convert BAG --out OUT`` in a child
    (its VmHWM, read by itself at the end)."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-c", _CHILD, "convert", str(bag), "--out", str(out),
                          "--json"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    assert p.stderr is not None
    err = p.stderr.read().decode("utf-8", "replace")
    code = p.wait()
    wall = time.perf_counter() - t0
    if code != 0:
        raise RuntimeError(f"convert {bag} -> {out} exited {code}: {err.strip()[-500:]}")
    (hwm,) = [line.split()[1] for line in err.splitlines() if line.startswith("VmHWM_KB ")]
    return int(hwm) / 1024.0, wall, err


def main(sizes=(200_000, 1_600_000), ros1_compression: str = "bz2",
         formats=("bag", "db3", "mcap"), outputs=("parquet", "csv.gz"),
         max_ratio: float = MAX_RATIO) -> dict:
    sizes = sorted(int(s) for s in sizes)
    rows, verdicts = [], {}
    print(f"{'messages':>10} {'format':>6} {'output':>8} {'bag MB':>8} {'peak RSS MB':>12} "
          f"{'wall s':>8} {'write s':>8}", flush=True)
    with tempfile.TemporaryDirectory(prefix="bench_convert_memory-") as tmp:
        folder = Path(tmp)
        for n in sizes:
            for kind in formats:
                t0 = time.perf_counter()
                bag = write_bag(folder, kind, n, ros1_compression)
                write_s = time.perf_counter() - t0
                for suffix in outputs:
                    out = folder / f"out_{kind}_{n}_{suffix.replace('.', '_')}.{suffix}"
                    rss, wall, _ = convert(bag, out)
                    out.unlink()
                    out.with_name(out.name.split(".")[0] + ".toml").unlink()
                    rows.append({"messages": n, "format": kind, "output": suffix,
                                 "bag_mb": bag.stat().st_size / 1e6, "peak_rss_mb": rss,
                                 "wall_s": wall, "write_s": write_s})
                    print(f"{n:>10} {kind:>6} {suffix:>8} {bag.stat().st_size / 1e6:>8.1f} "
                          f"{rss:>12.1f} {wall:>8.1f} {write_s:>8.1f}", flush=True)
                bag.unlink()
    lo, hi = sizes[0], sizes[-1]
    ok = True
    print(f"\nbounded memory: peak RSS at {hi} / at {lo} messages ({hi / lo:g}x the messages) "
          f"< {max_ratio}; extrapolated to {DAY_MESSAGES} messages (24 h at 400 Hz):")
    for kind in formats:
        for suffix in outputs:
            a = next(r for r in rows if r["messages"] == lo and r["format"] == kind and r["output"] == suffix)
            b = next(r for r in rows if r["messages"] == hi and r["format"] == kind and r["output"] == suffix)
            ratio = b["peak_rss_mb"] / a["peak_rss_mb"]
            slope = (b["peak_rss_mb"] - a["peak_rss_mb"]) / ((hi - lo) / 1e6) if hi > lo else 0.0
            rss_day = b["peak_rss_mb"] + max(slope, 0.0) * (DAY_MESSAGES - hi) / 1e6
            wall_day = b["wall_s"] * DAY_MESSAGES / hi
            good = ratio < max_ratio
            ok &= good
            verdicts[f"{kind}->{suffix}"] = {"ratio": ratio, "mb_per_million": slope,
                                             "peak_rss_mb_24h": rss_day, "wall_s_24h": wall_day,
                                             "bounded": good}
            print(f"  {kind:>5} -> {suffix:<8} ratio {ratio:5.2f} ({'ok' if good else 'NOT BOUNDED'}), "
                  f"{slope:+7.2f} MB per million messages; 24 h: ~{rss_day:7.0f} MB peak, "
                  f"~{wall_day / 60:5.1f} min")
    return {"rows": rows, "check": verdicts, "bounded": ok, "max_ratio": max_ratio}


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="200000,1600000",
                    help="message counts, comma-separated (default 200000,1600000)")
    ap.add_argument("--ros1-compression", choices=("bz2", "lz4"), default="bz2")
    ap.add_argument("--formats", default="bag,db3,mcap")
    ap.add_argument("--outputs", default="parquet,csv.gz")
    ap.add_argument("--max-ratio", type=float, default=MAX_RATIO)
    a = ap.parse_args()
    res = main([float(s) for s in a.sizes.split(",")], a.ros1_compression,
               a.formats.split(","), a.outputs.split(","), a.max_ratio)
    sys.exit(0 if res["bounded"] else 1)
