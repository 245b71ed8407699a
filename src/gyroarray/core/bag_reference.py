"""A reference attitude from a ROS bag: a pose or odometry topic (issue 42, item 6).

A bag recorded with motion capture or a VIO/SLAM odometry output holds, beside the IMU, the
attitude of the body over time. :func:`read_reference` reads one such topic,
``geometry_msgs/PoseStamped`` or ``nav_msgs/Odometry`` (ROS1 names as ROS2's, normalised by
rosbags), from a ROS1 ``.bag``, a ROS2 bag folder or a ``.db3``/``.mcap`` file, with
rosbags' ``AnyReader`` (pure Python, no ROS install; messages decoded by their type name with
the built-in typestores, nothing from the bag executed).

Reading rules
-------------
* Time: the header stamps (``header.stamp``) in integer nanoseconds; ``time_s`` counts from
  the first one, ``t0_ns``. Stamps must increase strictly (a repeated or backward stamp is
  refused with the message index, 1-based on that topic).
* Attitude: ``pose.orientation`` (``pose.pose.orientation`` for Odometry), the rotation of the
  body (child) frame into the parent frame, stored as ``quat_wxyz`` normalised and made
  sign-continuous (q and −q are one rotation). A non-finite quaternion or one whose norm is
  off 1 by more than :data:`QUAT_NORM_TOL` is refused with the message index.
* Rate: the body-frame angular rate from consecutive orientations,
  ω_k = Log(R_kᵀ R_{k+1}) / (t_{k+1} − t_k) [rad/s], stamped at the midpoint
  (``rate_time_s``); for Odometry whose ``twist.twist.angular`` is not all zero that twist
  (REP 105: in the child frame, the body frame) is used instead, at the message stamps. The
  notes say which.
* Refusals are :class:`~gyroarray.core.errors.InputError` naming the file and the topic: a
  topic the bag does not have or of another type (with the pose/odometry topics it has, and
  all topics), an empty topic, fewer than :data:`MIN_POSES` messages, a file that cannot be
  opened.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gyroarray.core.errors import InputError

__all__ = ["POSE_TYPE", "ODOMETRY_TYPE", "REFERENCE_TYPES", "MIN_POSES", "QUAT_NORM_TOL",
           "Reference", "read_reference", "reference_topics", "first_stamp_ns"]

#: Message types read as a reference (rosbags' normalised names; ROS1's too).
POSE_TYPE = "geometry_msgs/msg/PoseStamped"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
REFERENCE_TYPES = (POSE_TYPE, ODOMETRY_TYPE)
#: Fewest messages a reference needs [-] (two to form a rate; a few more to be a record).
MIN_POSES = 3
#: Largest |‖q‖ − 1| accepted [-]; inside it the quaternion is normalised.
QUAT_NORM_TOL = 1e-3
_NS_PER_S = 1_000_000_000


@dataclass(frozen=True)
class Reference:
    """The attitude of the body over time, from a pose or odometry topic.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Header stamps from ``t0_ns`` [s], strictly increasing.
    quat_wxyz : ndarray, shape (n, 4)
        Unit quaternions (w, x, y, z) [-] of the body-to-parent rotation, sign-continuous.
    rate_time_s : ndarray, shape (m,)
        Times of ``rate_rad_s`` from ``t0_ns`` [s] (pose midpoints, or the stamps for a twist).
    rate_rad_s : ndarray, shape (m, 3)
        Body-frame angular rate [rad/s].
    t0_ns : int
        The first header stamp [ns since the epoch of the bag's clock].
    topic : str
        The topic read.
    msgtype : str
        Its message type (:data:`POSE_TYPE` or :data:`ODOMETRY_TYPE`).
    rate_source : str
        ``"orientation differences"`` or ``"odometry twist"``.
    frame_id : str
        The first message's header.frame_id (parent frame).
    source : str, optional
        The bag as the user named it; None for a reference not read from a file.
    notes : tuple of str
        What the reader did and assumed.
    """

    time_s: np.ndarray
    quat_wxyz: np.ndarray
    rate_time_s: np.ndarray
    rate_rad_s: np.ndarray
    t0_ns: int = 0
    topic: str = ""
    msgtype: str = POSE_TYPE
    rate_source: str = "orientation differences"
    frame_id: str = ""
    source: str | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self):
        t = np.array(self.time_s, dtype=np.float64)
        q = np.array(self.quat_wxyz, dtype=np.float64)
        if t.ndim != 1 or t.size < 2 or not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
            raise ValueError("time_s needs >= 2 finite, strictly increasing stamps")
        if q.shape != (t.size, 4) or not np.all(np.isfinite(q)):
            raise ValueError(f"quat_wxyz must be finite with shape ({t.size}, 4), got {q.shape}")
        rt = np.array(self.rate_time_s, dtype=np.float64)
        rr = np.array(self.rate_rad_s, dtype=np.float64)
        if rt.ndim != 1 or rr.shape != (rt.size, 3):
            raise ValueError("rate_rad_s must have shape (len(rate_time_s), 3)")
        for name, a in (("time_s", t), ("quat_wxyz", q), ("rate_time_s", rt), ("rate_rad_s", rr)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "t0_ns", int(self.t0_ns))
        object.__setattr__(self, "notes", tuple(str(s) for s in self.notes))

    @classmethod
    def from_quaternions(cls, time_s, quat_wxyz, **kw) -> "Reference":
        """A reference from stamps [s] and quaternions (w, x, y, z) [-], its rate derived from
        consecutive orientations (normalised and made sign-continuous here)."""
        q = _continuous(np.asarray(quat_wxyz, dtype=np.float64))
        t = np.asarray(time_s, dtype=np.float64)
        rt, rr = orientation_rate(t, q)
        return cls(time_s=t, quat_wxyz=q, rate_time_s=rt, rate_rad_s=rr, **kw)

    @property
    def n_poses(self) -> int:
        """Number of poses n."""
        return int(self.time_s.size)


def _continuous(q: np.ndarray) -> np.ndarray:
    """Unit quaternions, each flipped to the hemisphere of the one before (q ≡ −q)."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    flip = np.sign(np.einsum("ij,ij->i", q[1:], q[:-1]))
    flip[flip == 0] = 1.0
    sign = np.concatenate([[1.0], np.cumprod(flip)])
    return q * sign[:, None]


def orientation_rate(time_s: np.ndarray, quat_wxyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body-frame rate from consecutive orientations: Log(R_kᵀ R_{k+1}) / Δt [rad/s], at the
    midpoints of the stamps [s]."""
    from scipy.spatial.transform import Rotation     # deferred: scipy is heavy
    r = Rotation.from_quat(np.asarray(quat_wxyz)[:, [1, 2, 3, 0]])
    rel = (r[:-1].inv() * r[1:]).as_rotvec()
    dt = np.diff(time_s)
    return 0.5 * (time_s[:-1] + time_s[1:]), rel / dt[:, None]


def _open(path: Path):
    # deferred: rosbags loads only when a bag is read
    from rosbags.highlevel import AnyReader
    if not path.exists():
        raise InputError("no such bag (file or ROS2 bag folder)", file=str(path))
    try:
        reader = AnyReader([path])
        reader.open()
    except Exception as err:  # rosbags' errors, struct/sqlite ones: not a bag, or a broken one
        raise InputError(f"cannot open this bag: truncated or corrupt, or not a ROS bag? "
                         f"({type(err).__name__}: {err})", file=str(path)) from None
    return reader


def _topics(reader) -> dict[str, tuple[str, int]]:
    out: dict[str, tuple[str, int]] = {}
    for c in reader.connections:
        kind, n = out.get(c.topic, (c.msgtype, 0))
        out[c.topic] = (kind if kind == c.msgtype else "mixed types", n + int(c.msgcount))
    return out


def reference_topics(path) -> dict[str, tuple[str, int]]:
    """The pose and odometry topics of a bag: ``{topic: (message type, message count)}``."""
    p = Path(path)
    reader = _open(p)
    try:
        return {t: v for t, v in _topics(reader).items() if v[0] in REFERENCE_TYPES}
    finally:
        reader.close()


def first_stamp_ns(path, topic: str) -> int:
    """The header stamp [ns] of the first message of ``topic`` (any type with a header), in the
    bag's order: the t0 a measurement read from the bag counts its ``time_s`` from."""
    p = Path(path)
    reader = _open(p)
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise InputError(f"no topic {topic} in this bag (its topics: "
                             f"{', '.join(sorted(_topics(reader))) or 'none'})", file=str(p))
        for conn, _, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            return int(msg.header.stamp.sec) * _NS_PER_S + int(msg.header.stamp.nanosec)
        raise InputError(f"topic {topic} has no messages", file=str(p))
    finally:
        reader.close()


def _refuse_topic(path: Path, topics: dict[str, tuple[str, int]], topic: str, why: str):
    ref = [f"{t} ({k}, {n} messages)" for t, (k, n) in topics.items() if k in REFERENCE_TYPES]
    every = [f"{t} ({k})" for t, (k, _) in topics.items()]
    return InputError(f"topic {topic}: {why}; its pose/odometry topics: "
                      f"{', '.join(ref) or 'none'}; all its topics: {', '.join(every) or 'none'}",
                      file=str(path))


def read_reference(path, topic: str) -> Reference:
    """Read a ``geometry_msgs/PoseStamped`` or ``nav_msgs/Odometry`` topic as a reference.

    Parameters
    ----------
    path : str or os.PathLike
        A ROS1 ``.bag``, a ROS2 bag folder, or a ROS2 ``.db3``/``.mcap`` file.
    topic : str
        The pose or odometry topic (e.g. ``/vicon/body/pose``, ``/odom``).

    Returns
    -------
    Reference
        Stamps [s] from the first (``t0_ns``), unit quaternions (w, x, y, z) [-], the
        body-frame rate [rad/s] and notes (module docstring).

    Raises
    ------
    InputError
        Naming the file and the topic, with the pose/odometry topics the bag has and all its
        topics, for an unknown topic, a topic of another type, an empty one; with the message
        index for stamps that do not increase or a bad quaternion.
    """
    p = Path(path)
    reader = _open(p)
    try:
        topics = _topics(reader)
        if topic not in topics:
            raise _refuse_topic(p, topics, topic, "no such topic in this bag")
        kind, count = topics[topic]
        if kind not in REFERENCE_TYPES:
            raise _refuse_topic(p, topics, topic, f"the messages are {kind}, not "
                                                  f"{' or '.join(REFERENCE_TYPES)}")
        if count < MIN_POSES:
            raise _refuse_topic(p, topics, topic, f"{count} messages, fewer than the "
                                                  f"{MIN_POSES} a reference needs")
        conns = [c for c in reader.connections if c.topic == topic]
        stamps, quats, twists, frame = [], [], [], ""
        for i, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
            try:
                msg: Any = reader.deserialize(raw, conn.msgtype)
            except Exception as err:  # a message that does not decode: corrupt
                raise InputError(f"topic {topic}, message {i + 1}: cannot decode it as "
                                 f"{kind}: corrupt? ({type(err).__name__})", file=str(p)) from None
            if i == 0:
                frame = str(msg.header.frame_id)
            stamps.append(int(msg.header.stamp.sec) * _NS_PER_S + int(msg.header.stamp.nanosec))
            o = msg.pose.orientation if kind == POSE_TYPE else msg.pose.pose.orientation
            quats.append((o.w, o.x, o.y, o.z))
            if kind == ODOMETRY_TYPE:
                a = msg.twist.twist.angular
                twists.append((a.x, a.y, a.z))
    finally:
        reader.close()
    return _build(p, topic, kind, frame, np.array(stamps, dtype=np.int64),
                  np.array(quats, dtype=np.float64),
                  np.array(twists, dtype=np.float64) if twists else None)


def _build(p: Path, topic: str, kind: str, frame: str, stamps: np.ndarray, q: np.ndarray,
           twist: np.ndarray | None) -> Reference:
    steps = np.diff(stamps)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        what = "repeats" if steps[bad[0]] == 0 else "goes backwards"
        raise InputError(f"topic {topic}, message {i + 1}: the header stamp {what} "
                         f"({stamps[i - 1]} then {stamps[i]} ns); a reference needs strictly "
                         "increasing stamps", file=str(p))
    norm = np.linalg.norm(q, axis=1)
    bad = np.flatnonzero(~np.isfinite(norm) | (np.abs(norm - 1.0) > QUAT_NORM_TOL))
    if bad.size:
        raise InputError(f"topic {topic}, message {int(bad[0]) + 1}: the orientation quaternion "
                         f"has norm {norm[bad[0]]:.6g}, not 1 (within {QUAT_NORM_TOL}): no attitude",
                         file=str(p))
    t0 = int(stamps[0])
    t = (stamps - t0) / 1e9
    q = _continuous(q)
    notes = [f"{p}: topic {topic} ({kind}), {t.size} messages, parent frame {frame!r}; time_s "
             f"is the header stamp minus the first, t0 = {t0 / 1e9:.9f} s; the attitude is the "
             "body (child) frame's, taken to be the IMU frame"]
    if twist is not None and np.all(np.isfinite(twist)) and np.any(twist != 0.0):
        rt, rr, source = t, twist, "odometry twist"
        notes.append(f"{p}: rate from twist.twist.angular (body frame, REP 105)")
    else:
        rt, rr = orientation_rate(t, q)
        source = "orientation differences"
        notes.append(f"{p}: rate from consecutive orientations, Log(R_kᵀ R_k+1)/Δt, body frame, "
                     "at the stamps' midpoints")
    return Reference(time_s=t, quat_wxyz=q, rate_time_s=rt, rate_rad_s=rr, t0_ns=t0, topic=topic,
                     msgtype=kind, rate_source=source, frame_id=frame, source=str(p),
                     notes=tuple(notes))
