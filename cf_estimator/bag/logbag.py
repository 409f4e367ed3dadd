"""Flight logs read whole into arrays, handed out as an input bag: the part the PX4 ulog
reader (:mod:`cf_estimator.bag.ulog`) and the ArduPilot DataFlash reader
(:mod:`cf_estimator.bag.dataflash`) share.

A reader parses its log once into :class:`Stream` objects (one per replayable topic: stamps
[ns since boot] and values in the layout of :mod:`cf_estimator.bag.cdr`'s blocks for Imu and
MagneticField, (w, x, y, z) for QuaternionStamped, (vx, vy, vz) for TwistStamped) and
subclasses :class:`StreamBag`, which gives them out one by one (:meth:`StreamBag.messages`) or
as decoded blocks (:meth:`StreamBag.chunks`, the bulk path) in log-time order, as
:class:`cf_estimator.bag.io.InputBag` does for a bag.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cf_estimator.bag import cdr
from cf_estimator.bag.messages import (
    imu_message,
    magnetic_field_message,
    quaternion_stamped_message,
    twist_stamped_message,
)
from cf_estimator.bag.reader import BagMessage, InputBag, TopicInfo
from cf_estimator.bag.types import IMU_TYPE, MAG_TYPE, TWIST_STAMPED_TYPE
from cf_estimator.pipeline import px4

#: Events per chunk of :meth:`StreamBag.chunks` (as bags).
_CHUNK = 8192


@dataclass
class Stream:
    """One replayable topic: stamps [ns since boot] and values; ``frame``: the frame_id of its
    messages (FRD body for IMU and magnetometer, NED for velocity and attitude)."""

    topic: str
    msgtype: str
    t_ns: np.ndarray
    values: np.ndarray
    frame: str = px4.PX4_BODY_FRAME_ID


class StreamBag(InputBag):
    """An input bag over a log read at construction: ``streams`` (topic -> :class:`Stream`),
    ``topics``, ``imu_topic``, ``log_start_us``/``log_last_us`` [µs since boot] are set by the
    subclass, which also names its ``format``."""

    streams: dict[str, Stream]
    imu_topic: str
    log_start_us: int
    log_last_us: int

    def finish_topics(self) -> None:
        """``topics`` from ``streams`` (call at the end of the subclass's constructor)."""
        self.topics = sorted((TopicInfo(s.topic, s.msgtype, int(s.t_ns.shape[0]))
                              for s in self.streams.values()), key=lambda i: i.topic)

    def close(self) -> None:
        """Nothing stays open (the log was read at construction)."""

    @property
    def start_time_ns(self) -> int:
        return self.log_start_us * 1000

    @property
    def duration_s(self) -> float:
        return (self.log_last_us - self.log_start_us) * 1e-6

    def _listing(self) -> str:
        return "topics: " + ", ".join(f"{i.topic} [{i.msgtype}]" for i in self.topics)

    def imu_coverage(self) -> tuple[float, float, float]:
        """(first, last IMU stamp, log duration) [s]: how much of the log the IMU covers."""
        t = self.streams[self.imu_topic].t_ns
        if t.shape[0] == 0:
            return 0.0, 0.0, self.duration_s
        return float(t[0]) * 1e-9, float(t[-1]) * 1e-9, self.duration_s

    def _order(self, topics: Iterable[str]) -> tuple[list[Stream], np.ndarray, np.ndarray]:
        """The streams of ``topics``, and (stream index, row) of every event in time order
        (ties: the order of the streams as asked for)."""
        streams = [self.streams[t] for t in dict.fromkeys(topics) if t in self.streams]
        if not streams:
            return [], np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        t = np.concatenate([s.t_ns for s in streams])
        which = np.concatenate([np.full(s.t_ns.shape[0], k, dtype=np.int64)
                                for k, s in enumerate(streams)])
        row = np.concatenate([np.arange(s.t_ns.shape[0], dtype=np.int64) for s in streams])
        order = np.lexsort((which, t))
        return streams, which[order], row[order]

    def messages(self, topics: Iterable[str], *, bulk: bool = False) -> Iterator[BagMessage]:
        """The messages of ``topics`` one by one, log-time order (``bulk`` changes nothing)."""
        streams, which, row = self._order(topics)
        for k, r in zip(which.tolist(), row.tolist(), strict=True):
            s = streams[k]
            yield BagMessage(s.topic, s.msgtype, int(s.t_ns[r]), message(s, r))

    def chunks(self, topics: Iterable[str]) -> Iterator[StreamChunk]:
        """The messages of ``topics`` a few thousand at a time, Imu and MagneticField as decoded
        blocks (what :meth:`cf_estimator.bag.io.InputBag.chunks` gives for a bag)."""
        streams, which, row = self._order(topics)
        for a in range(0, which.shape[0], _CHUNK):
            yield StreamChunk(streams, which[a:a + _CHUNK], row[a:a + _CHUNK])

    def to_jazzy(self, msg: Any, msgtype: str) -> Any:
        """A Jazzy message object for ``--copy-inputs`` from one of this log's messages."""
        h = msg.header
        sec, ns, frame = h.stamp.sec, h.stamp.nanosec, h.frame_id
        if msgtype == IMU_TYPE:
            o, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
            return imu_message(sec, ns, frame, (o.x, o.y, o.z, o.w),
                                  msg.orientation_covariance, (w.x, w.y, w.z),
                                  msg.angular_velocity_covariance, (a.x, a.y, a.z),
                                  msg.linear_acceleration_covariance)
        if msgtype == MAG_TYPE:
            f = msg.magnetic_field
            return magnetic_field_message(sec, ns, frame, (f.x, f.y, f.z),
                                             msg.magnetic_field_covariance)
        if msgtype == TWIST_STAMPED_TYPE:
            v = msg.twist.linear
            return twist_stamped_message(sec, ns, frame, (v.x, v.y, v.z))
        q = msg.quaternion
        return quaternion_stamped_message(sec, ns, frame, (q.w, q.x, q.y, q.z))



class _Twist:
    __slots__ = ("linear", "angular")


class _TwistStampedView:
    """geometry_msgs/TwistStamped fields (velocity [m/s], NED)."""

    __slots__ = ("header", "twist")


class _QuaternionStampedView:
    """geometry_msgs/QuaternionStamped fields."""

    __slots__ = ("header", "quaternion")


def _header(t_ns: int, frame: str) -> cdr.Header:
    sec, ns = divmod(int(t_ns), 1_000_000_000)
    return cdr.Header(cdr.Stamp(sec, ns), frame)


def message(s: Stream, r: int) -> Any:
    """Row ``r`` of a stream as a light message object (sensor_msgs / geometry_msgs names)."""
    if s.msgtype in (IMU_TYPE, MAG_TYPE):
        return _block(s, np.array([r])).message(0)
    v = s.values[r].tolist()
    if s.msgtype == TWIST_STAMPED_TYPE:
        m = _TwistStampedView()
        m.header = _header(s.t_ns[r], s.frame)
        tw = _Twist()
        tw.linear, tw.angular = cdr.Vector(*v), cdr.Vector(0.0, 0.0, 0.0)
        m.twist = tw
        return m
    q = _QuaternionStampedView()
    q.header = _header(s.t_ns[r], s.frame)
    q.quaternion = cdr.Vector(v[1], v[2], v[3], v[0])
    return q


def _block(s: Stream, rows: np.ndarray) -> cdr.Block:
    """Rows of an Imu/MagneticField stream as a decoded :class:`cf_estimator.bag.cdr.Block`."""
    n = int(rows.shape[0])
    b = cdr.Block(n, s.msgtype == IMU_TYPE)
    b.values = np.ascontiguousarray(s.values[rows])
    sec, ns = np.divmod(s.t_ns[rows], 1_000_000_000)
    b.sec, b.nsec = sec.tolist(), ns.tolist()
    b.frame = [s.frame] * n
    b.plain = [True] * n
    return b


class StreamChunk:
    """Consecutive messages, as :class:`cf_estimator.bag.io.MessageChunk` has them."""

    def __init__(self, streams: Sequence[Stream], which: np.ndarray, row: np.ndarray) -> None:
        self._streams = streams
        self.topic = [streams[k].topic for k in which.tolist()]
        self.msgtype = [streams[k].msgtype for k in which.tolist()]
        t = np.empty(which.shape[0], dtype=np.int64)
        self.blocks: dict[str, cdr.Block] = {}
        self.row = [-1] * int(which.shape[0])
        self._rows = row.tolist()
        self._which = which.tolist()
        for k, s in enumerate(streams):
            idx = np.flatnonzero(which == k)
            if idx.size == 0:
                continue
            t[idx] = s.t_ns[row[idx]]
            if s.msgtype in (IMU_TYPE, MAG_TYPE):
                self.blocks[s.msgtype] = _block(s, row[idx])
                for j, i in enumerate(idx.tolist()):
                    self.row[i] = j
        self.log_ns = t.tolist()

    def __len__(self) -> int:
        return len(self.topic)

    def references(self, topic: str, ref_t: list[float], ref_q: list[Any]) -> int:
        """The QuaternionStamped messages of ``topic`` in this chunk appended as stamps [s]
        and normalised (w, x, y, z) (what the replay takes from each one); returns how many
        messages there were."""
        k = next((j for j, s in enumerate(self._streams) if s.topic == topic), None)
        if k is None:
            return 0
        s = self._streams[k]
        rows = np.asarray(self._rows)[np.asarray(self._which) == k]
        if rows.size == 0:
            return 0
        q = s.values[rows]
        q = q / np.linalg.norm(q, axis=1, keepdims=True)  # rows of norm > 0.5 (the reader's)
        sec, ns = np.divmod(s.t_ns[rows], 1_000_000_000)
        ref_t.extend((sec + ns * 1e-9).tolist())
        ref_q.extend(tuple(r) for r in q.tolist())
        return int(rows.size)

    def msg(self, i: int) -> Any:
        """Message i as a light object."""
        block = self.blocks.get(self.msgtype[i])
        if block is not None:
            return block.message(self.row[i])
        return message(self._streams[self._which[i]], self._rows[i])


