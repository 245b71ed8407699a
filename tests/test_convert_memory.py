"""A long bag converts in bounded memory (issue 42, item 5): the streamed reader of a ROS1 bag
keeps no per-message index and holds one chunk at a time, with the bits of the whole read.

rosbags' own ROS1 reader builds, on open, one ``IndexData`` (a 3-tuple: 64 B, its time int
32 B, offset int 28 B, list slots 16 B) per message: >= 100 B/message, 3.5 GB for a 24 h
record at 400 Hz (35 M messages). :class:`~gyroarray.core.bags.BagStream` reads the index
records chunk by chunk instead (benchmarks/bench_convert_memory.py measures the process's peak
RSS at 200k and 1.6M messages for ROS1, db3 and MCAP)."""

from __future__ import annotations

import tracemalloc

import numpy as np
from rosbags.rosbag1 import Reader as Reader1
from rosbags.rosbag1 import Writer as Writer1
from rosbags.typesys import Stores, get_typestore

from gyroarray.core import units
from gyroarray.core.bags import BagStream
from gyroarray.core.measurement import read_measurement
from tests.test_bags import IMU, T0_NS, imu_message, record

N = 8000                 # messages: 20 s at 400 Hz
STEP_NS = 2_500_000      # 400 Hz
CHUNK_BYTES = 64 << 10   # the writer's chunk threshold [bytes]: ~200 messages of 327 B a chunk
STREAM = 256             # messages per streamed chunk


def write_ros1(path, n: int = N, compression: str = "lz4"):
    """A ROS1 bag of ``n`` Imu messages on /imu at 400 Hz in chunks of ~64 KiB."""
    stamps, gyro, acc = record(5, n=n, step_ns=STEP_NS)
    ts = get_typestore(Stores.ROS1_NOETIC)
    w = Writer1(path)
    w.set_compression(getattr(Writer1.CompressionFormat, compression.upper()))
    w.chunk_threshold = CHUNK_BYTES
    with w:
        conn = w.add_connection("/imu", IMU, typestore=ts)
        for i in range(n):
            w.write(conn, T0_NS + i * STEP_NS, ts.serialize_ros1(imu_message(ts, stamps[i], gyro[i], acc[i]), IMU))
    return stamps, gyro, acc


def _peak(fn) -> float:
    """Peak of the Python allocations [bytes] while ``fn()`` runs (tracemalloc)."""
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_streamed_ros1_reader_holds_one_chunk_not_an_index(tmp_path):
    bag = tmp_path / "long.bag"
    stamps, gyro, acc = write_ros1(bag)

    # rosbags' reader on open: >= 100 B per message (the module docstring), 0.8 MB here
    def whole_index():
        r = Reader1(bag)
        r.open()
        r.close()
    indexed = _peak(whole_index)
    assert indexed > 100 * N, indexed

    # the streamed read, open and every chunk, of this bag and of one of 300 messages (its
    # chunks as full: one bag chunk of 64 KiB, one streamed chunk of 256 messages): the fixed
    # costs (a typestore, the decoders) are the same, what grows with the record is the chunk
    # table (40 entries) and the clock's window (<= 2 x 1024 int64, 16 kB). A bound of 0.3 MB
    # on the growth from 300 to 8000 messages is crossed by any per-message structure of
    # >= 39 B (rosbags' index: >= 100 B, 0.77 MB for the 7700 messages more)
    short = tmp_path / "short.bag"
    write_ros1(short, n=300)

    def streamed(path, parts):
        s = BagStream(path, chunk=STREAM)
        for t, g, a in s.chunks():
            parts.append((t[-1], g[-1].copy()))         # kept: one row a chunk, not the chunk
        return parts
    streamed(short, [])                                 # warm: lazy imports
    parts: list = []
    base = _peak(lambda: streamed(short, []))
    held = _peak(lambda: streamed(bag, parts))
    assert held - base < 0.3e6, (held, base)
    assert len(parts) == -(-N // STREAM)


def test_streamed_ros1_equals_the_whole_read_bz2(tmp_path):
    """The chunked reader's order and bits are rosbags' (the streamed-equals-whole rule)."""
    bag = tmp_path / "b.bag"
    stamps, gyro, acc = write_ros1(bag, n=3000, compression="bz2")
    whole = read_measurement(bag)
    s = BagStream(bag, chunk=700)
    parts = list(s.chunks())
    assert np.array_equal(np.concatenate([p[0] for p in parts]), whole.time_s)
    assert np.array_equal(np.concatenate([p[0] for p in parts]), (stamps - stamps[0]) / 1e9)
    assert np.array_equal(np.vstack([p[1] for p in parts]), units.rad_s_to_deg_s(gyro))
    assert np.array_equal(np.vstack([p[2] for p in parts]), whole.acc_m_s2)
    assert s.count == 3000


def test_chunks_overlapping_in_time_are_read_with_rosbags_whole_index(tmp_path):
    """A bag whose chunks' time ranges overlap (a message logged late, in a later chunk): file
    order is not rosbags' time order, so the streamed reader falls back to rosbags' index and
    yields the messages in time order as the whole read does."""
    from gyroarray.core.bags import _Bag
    bag = tmp_path / "late.bag"
    ts = get_typestore(Stores.ROS1_NOETIC)
    stamps, gyro, acc = record(6, n=400, step_ns=STEP_NS)
    order = list(range(400))
    order[50], order[350] = order[350], order[50]       # 350 written early, 50 late: overlap
    w = Writer1(bag)
    w.chunk_threshold = 4 << 10                         # ~12 messages a chunk
    with w:
        conn = w.add_connection("/imu", IMU, typestore=ts)
        for i in order:
            w.write(conn, T0_NS + i * STEP_NS, ts.serialize_ros1(imu_message(ts, stamps[i], gyro[i], acc[i]), IMU))
    b = _Bag(bag, None, stream=True)
    try:
        assert not hasattr(b.reader, "in_order")        # rosbags' own reader
        times = [t for t, _ in b.messages(list(b.reader.connections))]
    finally:
        b.close()
    assert times == [T0_NS + i * STEP_NS for i in range(400)]
