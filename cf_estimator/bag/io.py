"""Bag input/output over ``rosbags``: open ROS 1/ROS 2 bags, pick topics, build and write messages.

Reading: :func:`open_bag` wraps ``rosbags.highlevel.AnyReader`` (ROS 1 ``.bag`` files, ROS 2 bag
directories with sqlite3 or mcap storage) and turns every ``rosbags`` failure — missing file, not
a bag, truncated data, undecodable message — into a :class:`BagError` whose message names the file.
Messages come back in log-time order across topics, exactly as recorded.

Writing: :class:`OutputBag` writes a ROS 2 bag (Jazzy message definitions, storage mcap or
sqlite3) into a temporary sibling directory and renames it into place only when everything was
written, so a failed or interrupted run never leaves anything that looks like a complete bag.

Message construction: :func:`imu_message`, :func:`rpy_message`, :func:`diagnostics_message` and
friends build Jazzy (``Stores.ROS2_JAZZY``) message objects from plain values.
"""

from __future__ import annotations

import contextlib
import functools
import os
import shutil
import struct
import tempfile
from collections import defaultdict
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

IMU_TYPE = "sensor_msgs/msg/Imu"
MAG_TYPE = "sensor_msgs/msg/MagneticField"
VECTOR3_STAMPED_TYPE = "geometry_msgs/msg/Vector3Stamped"
QUATERNION_STAMPED_TYPE = "geometry_msgs/msg/QuaternionStamped"
POSE_STAMPED_TYPE = "geometry_msgs/msg/PoseStamped"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
TWIST_STAMPED_TYPE = "geometry_msgs/msg/TwistStamped"
VELOCITY_TYPES = (TWIST_STAMPED_TYPE, ODOMETRY_TYPE)
DIAGNOSTIC_ARRAY_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
#: Message types accepted as an orientation reference (ground truth, motion capture, odometry).
REFERENCE_TYPES = (QUATERNION_STAMPED_TYPE, POSE_STAMPED_TYPE, ODOMETRY_TYPE)

STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
#: rosbag2 metadata version written (Jazzy's rosbag2 writes and reads version 9).
ROSBAG2_VERSION = 9
#: The rosbags releases [from, to) this module is tested with (setup.py pins the same range):
#: the reader and writer use the public API, and the direct mcap path of
#: :meth:`OutputBag.write_raw` / :meth:`OutputBag.write_rows` also writes into ``McapWriter``'s
#: pending chunk (not public API), checked byte for byte against rosbags' own ``Writer.write``
#: with 0.11.0 and 0.11.9 (test/test_bulk_decode.py). Outside the range (a rosbags installed
#: past the pin) every message goes through ``Writer.write``: the same file, only slower.
ROSBAGS_TESTED = ((0, 11), (0, 12))


def rosbags_version() -> tuple[int, ...]:
    """The installed rosbags release as integers (``0.11.9`` → ``(0, 11, 9)``; () if unknown)."""
    import importlib.metadata
    import re

    try:
        text = importlib.metadata.version("rosbags")
    except importlib.metadata.PackageNotFoundError:
        return ()
    return tuple(int(x) for x in re.findall(r"\d+", text)[:3])


def direct_mcap_supported(version: tuple[int, ...] | None = None) -> bool:
    """True when the installed rosbags (or ``version``) is in :data:`ROSBAGS_TESTED`."""
    v = rosbags_version() if version is None else version
    lo, hi = ROSBAGS_TESTED
    return bool(v) and lo <= v[:2] < hi


class BagError(Exception):
    """A bag could not be read or written; the message names the file and the reason.

    ``code`` is the exit code a command line should use: 2 when the user asked for something
    that cannot be (missing path, wrong topic, existing output), 1 for bad data.
    """

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


@functools.cache
def typestore() -> Any:
    """The ROS 2 Jazzy typestore every message written by cf_estimator is defined in."""
    return get_typestore(Stores.ROS2_JAZZY)


def _short(exc: BaseException) -> str:
    """One line describing a library exception."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


# ---------------------------------------------------------------------------------------------
# reading


@dataclass(frozen=True)
class TopicInfo:
    """One topic of an input bag."""

    topic: str
    msgtype: str  #: ROS 2 style type name, e.g. ``sensor_msgs/msg/Imu``
    count: int


@dataclass(frozen=True)
class BagMessage:
    """One message of an input bag, deserialized (fields as in the ROS definition)."""

    topic: str
    msgtype: str
    log_time_ns: int  #: the time the recorder received it
    msg: Any


def _looks_like_bag(path: Path) -> str | None:
    """None when ``path`` may be a bag AnyReader can open, else why it is not."""
    if not path.exists():
        return "no such file or directory"
    if path.is_dir():
        if path.suffix == ".bag":
            return "a directory named *.bag cannot be read (rosbags takes .bag for ROS 1 files)"
        if not (path / "metadata.yaml").is_file():
            has_storage = any(path.glob("*.mcap")) or any(path.glob("*.db3"))
            return (
                "directory has no metadata.yaml (not a ROS 2 bag; reindex it with "
                "`ros2 bag reindex`)" if has_storage else "directory is not a ROS 2 bag "
                "(no metadata.yaml)"
            )
        return None
    if path.suffix != ".bag":
        return "not a ROS 1 .bag file, a ROS 2 bag directory or a PX4 .ulg log"
    return None


#: An mcap Message record's fixed part: opcode, record length, channel id, sequence, log time,
#: publish time (rosbags writes log time twice); and the size that closes a chunk (rosbags').
_MCAP_MESSAGE = struct.Struct("<BQHIQQ")
_MCAP_CHUNK_BYTES = 2**20
#: Messages decoded together by ``InputBag.messages(bulk=True)``.
_BULK_CHUNK = 8192


class InputBag:
    """An open input bag (use :func:`open_bag`); a context manager."""

    def __init__(self, path: Path, reader: AnyReader) -> None:
        self.path = path
        self._reader = reader
        counts: dict[tuple[str, str], int] = {}
        for c in reader.connections:
            counts[(c.topic, c.msgtype)] = counts.get((c.topic, c.msgtype), 0) + c.msgcount
        self.topics: list[TopicInfo] = sorted(
            (TopicInfo(t, m, n) for (t, m), n in counts.items()), key=lambda i: i.topic
        )
        self.is_ros2: bool = bool(reader.is2)

    # -- context -------------------------------------------------------------------------------
    def __enter__(self) -> InputBag:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def close(self) -> None:
        """Close the underlying reader (idempotent)."""
        with contextlib.suppress(Exception):  # closing a broken bag must not mask the error
            self._reader.close()

    # -- metadata ------------------------------------------------------------------------------
    @property
    def format(self) -> str:
        """``ros1``, ``ros2-sqlite3`` or ``ros2-mcap``."""
        if not self.is_ros2:
            return "ros1"
        suffixes = {p.suffix for p in self.path.iterdir()} if self.path.is_dir() else set()
        return "ros2-mcap" if ".mcap" in suffixes else "ros2-sqlite3"

    @property
    def start_time_ns(self) -> int:
        return int(self._reader.start_time)

    @property
    def duration_s(self) -> float:
        return float(self._reader.duration) * 1e-9 if self.topics else 0.0

    def count(self, topics: Iterable[str]) -> int:
        """Number of messages on the given topics."""
        wanted = set(topics)
        return sum(i.count for i in self.topics if i.topic in wanted)

    def msgtype_of(self, topic: str) -> str | None:
        for info in self.topics:
            if info.topic == topic:
                return info.msgtype
        return None

    def _listing(self) -> str:
        if not self.topics:
            return "the bag has no topics"
        return "topics: " + ", ".join(
            f"{i.topic} [{i.msgtype}]: {i.count} message{'' if i.count == 1 else 's'}"
            for i in self.topics)

    def select_topic(
        self, role: str, explicit: str | None, msgtypes: Sequence[str], *, required: bool,
        option: str,
    ) -> str | None:
        """The topic to use for ``role`` (e.g. "IMU").

        With ``explicit``: it must exist and have one of ``msgtypes``. Without: auto-detect by
        message type; exactly one candidate is taken, several are an error listing them, none
        is an error when ``required`` (else None). Errors are :class:`BagError`.
        """
        types = " or ".join(msgtypes)
        if explicit is not None:
            found = self.msgtype_of(explicit)
            if found is None and not explicit.startswith("/"):
                found = self.msgtype_of("/" + explicit)
                explicit = "/" + explicit if found is not None else explicit
            if found is None:
                raise BagError(
                    f"{self.path}: no topic {explicit!r} ({option}); {self._listing()}", 2
                )
            if found not in msgtypes:
                raise BagError(
                    f"{self.path}: topic {explicit!r} is {found}, but {option} needs {types}", 2
                )
            if self.count([explicit]) == 0:
                raise BagError(f"{self.path}: topic {explicit!r} has no messages")
            return explicit
        candidates = [i for i in self.topics if i.msgtype in msgtypes and i.count > 0]
        if len(candidates) == 1:
            return candidates[0].topic
        if len(candidates) > 1:
            names = ", ".join(f"{i.topic} ({i.count} msgs)" for i in candidates)
            raise BagError(
                f"{self.path}: several {role} topics ({names}); choose one with {option}", 2
            )
        if required:
            raise BagError(f"{self.path}: no {role} messages ({types}); {self._listing()}")
        return None

    # -- messages ------------------------------------------------------------------------------
    def _raw_messages(self, topics: Iterable[str]) -> Iterator[tuple] | None:
        """rosbags' (connection, log stamp, raw bytes) iterator over ``topics``, None if the
        bag has none of them."""
        wanted = set(topics)
        conns = [c for c in self._reader.connections if c.topic in wanted]
        return self._reader.messages(connections=conns) if conns else None

    def messages(self, topics: Iterable[str], *, bulk: bool = False) -> Iterator[BagMessage]:
        """Deserialized messages of ``topics`` in log-time order (as recorded, interleaved).

        ``bulk``: sensor_msgs/Imu and MagneticField are decoded a few thousand at a time with
        NumPy (:mod:`cf_estimator.bag.cdr`: light objects with the same field names and values;
        other types and unusual messages through rosbags as usual).

        Any failure of the reader (truncated chunk, corrupt record, undecodable message) is
        raised as :class:`BagError` naming the file.
        """
        it = self._raw_messages(topics)
        if it is None:
            return
        reader = self._reader

        def decode_one(conn: Any, log_ns: int, raw: bytes) -> Any:
            try:
                return reader.deserialize(raw, conn.msgtype)
            except Exception as exc:  # noqa: BLE001
                raise BagError(
                    f"{self.path}: cannot decode a {conn.msgtype} message on {conn.topic} at "
                    f"log time {log_ns} ns: {_short(exc)}"
                ) from exc

        def next_item() -> Any:
            try:
                return next(it)
            except StopIteration:
                return None
            except Exception as exc:  # noqa: BLE001 - any reader failure is a bad bag
                raise BagError(f"{self.path}: cannot read messages: {_short(exc)}") from exc

        if not bulk:
            while (item := next_item()) is not None:
                conn, log_ns, raw = item
                yield BagMessage(conn.topic, conn.msgtype, int(log_ns),
                                 decode_one(conn, log_ns, raw))
            return
        from cf_estimator.bag import cdr

        fast = (IMU_TYPE, MAG_TYPE)
        ros2 = self.is_ros2
        done = False
        while not done:
            chunk = []
            while len(chunk) < _BULK_CHUNK:
                item = next_item()
                if item is None:
                    done = True
                    break
                chunk.append(item)
            decoded: list[Any] = [None] * len(chunk)
            by_type: dict[str, list[int]] = {}
            for i, (conn, log_ns, raw) in enumerate(chunk):
                if conn.msgtype in fast:
                    by_type.setdefault(conn.msgtype, []).append(i)
                else:
                    decoded[i] = decode_one(conn, log_ns, raw)
            for msgtype, idx in by_type.items():
                items = [chunk[i] for i in idx]
                pos = {id(it[2]): it for it in items}

                def fallback(raw: bytes, mt: str, pos: dict = pos) -> Any:
                    conn, log_ns, _ = pos[id(raw)]
                    return decode_one(conn, log_ns, raw)

                for i, m in zip(idx, cdr.decode([it[2] for it in items], msgtype, ros2,
                                                fallback), strict=True):
                    decoded[i] = m
            for (conn, log_ns, _raw), msg in zip(chunk, decoded, strict=True):
                yield BagMessage(conn.topic, conn.msgtype, int(log_ns), msg)

    def chunks(self, topics: Iterable[str]) -> Iterator[MessageChunk]:
        """The messages of ``topics`` in log-time order, a few thousand at a time: Imu and
        MagneticField decoded into arrays (:class:`cf_estimator.bag.cdr.Block`), other types
        by rosbags when asked for (:meth:`MessageChunk.msg`). Failures as :meth:`messages`."""
        from cf_estimator.bag import cdr

        it = self._raw_messages(topics)
        if it is None:
            return
        ros2 = self.is_ros2
        done = False
        while not done:
            items = []
            try:
                for _ in range(_BULK_CHUNK):
                    items.append(next(it))
            except StopIteration:
                done = True
            except Exception as exc:  # noqa: BLE001 - any reader failure is a bad bag
                raise BagError(f"{self.path}: cannot read messages: {_short(exc)}") from exc
            if not items:
                return
            chunk = MessageChunk(self, items)
            for msgtype in (IMU_TYPE, MAG_TYPE):
                idx = [i for i, it_ in enumerate(items) if it_[0].msgtype == msgtype]
                if not idx:
                    continue
                block = cdr.decode_block([items[i][2] for i in idx], msgtype, ros2,
                                         chunk._decode_raw)  # noqa: SLF001
                chunk.blocks[msgtype] = block
                for k, i in enumerate(idx):
                    chunk.row[i] = k
            yield chunk

    def to_jazzy(self, msg: Any, msgtype: str) -> Any:
        """``msg`` (from this bag's typestore) as a Jazzy message object (ROS 1 ``seq`` dropped)."""
        return migrate_to_jazzy(self._reader.typestore, msgtype, msg, self._cache)

    @functools.cached_property
    def _cache(self) -> dict[str, object]:
        return {}


class MessageChunk:
    """Consecutive messages of :meth:`InputBag.chunks`: ``topic``, ``msgtype``, ``log_ns`` per
    message; ``blocks[msgtype]`` (Imu, MagneticField) with ``row[i]`` = message i's row."""

    def __init__(self, bag: InputBag, items: list[Any]) -> None:
        self._bag = bag
        self._items = items
        self.topic = [c.topic for c, _t, _r in items]
        self.msgtype = [c.msgtype for c, _t, _r in items]
        self.log_ns = [int(t) for _c, t, _r in items]
        self.blocks: dict[str, Any] = {}
        self.row = [-1] * len(items)
        self._by_raw: dict[int, int] = {}

    def __len__(self) -> int:
        return len(self._items)

    def _decode_raw(self, raw: bytes, _msgtype: str = "") -> Any:
        if not self._by_raw:
            self._by_raw = {id(r): i for i, (_c, _t, r) in enumerate(self._items)}
        return self._decode(self._by_raw[id(raw)])

    def _decode(self, i: int) -> Any:
        conn, log_ns, raw = self._items[i]
        try:
            return self._bag._reader.deserialize(raw, conn.msgtype)  # noqa: SLF001
        except Exception as exc:  # noqa: BLE001
            raise BagError(
                f"{self._bag.path}: cannot decode a {conn.msgtype} message on {conn.topic} at "
                f"log time {log_ns} ns: {_short(exc)}"
            ) from exc

    def msg(self, i: int) -> Any:
        """Message i as an object (a light view for a decoded row, else rosbags')."""
        block = self.blocks.get(self.msgtype[i])
        if block is not None:
            return block.message(self.row[i])
        return self._decode(i)


def migrate_to_jazzy(src_store: Any, msgtype: str, msg: Any, cache: dict[str, object]) -> Any:
    """Field-by-field conversion into the Jazzy class of ``msgtype`` (rosbags' own migration)."""
    from rosbags.convert.converter import migrate_message

    store = typestore()
    if msgtype not in store.fielddefs:
        raise BagError(f"message type {msgtype} is not defined in ROS 2 Jazzy")
    return migrate_message(src_store, store, msgtype, msgtype, cache, msg)


def open_bag(path: str | os.PathLike[str], *, ulog_instance: int | None = None) -> InputBag:
    """Open a ROS 1 ``.bag``, a ROS 2 bag directory or a PX4 ``.ulg`` log
    (:mod:`cf_estimator.bag.ulog`; ``ulog_instance``: the multi_id to use where a topic has
    several) — :class:`BagError` names the file."""
    p = Path(path)
    if p.suffix.lower() == ".ulg" and not p.is_dir():
        from cf_estimator.bag.ulog import open_ulog

        return open_ulog(p, ulog_instance)
    why = _looks_like_bag(p)
    if why is not None:
        raise BagError(f"{p}: {why}", 2 if not p.exists() else 1)
    try:
        reader = AnyReader([p], default_typestore=typestore())
        reader.open()
    except Exception as exc:  # noqa: BLE001 - AnyReaderError, ReaderError, sqlite, yaml, OSError...
        kind = "ROS 1 bag" if p.suffix == ".bag" else "ROS 2 bag"
        raise BagError(f"{p}: not a readable {kind}: {_short(exc)}") from exc
    return InputBag(p, reader)


# ---------------------------------------------------------------------------------------------
# message construction (Jazzy)


def _types() -> dict[str, Any]:
    return typestore().types


def stamp(sec: int, nanosec: int) -> Any:
    """builtin_interfaces/Time."""
    return _types()["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nanosec))


def stamp_from_ns(t_ns: int) -> Any:
    sec, nanosec = divmod(int(t_ns), 1_000_000_000)
    return stamp(sec, nanosec)


def header(sec: int, nanosec: int, frame_id: str) -> Any:
    """std_msgs/Header (ROS 2: no seq)."""
    return _types()["std_msgs/msg/Header"](stamp=stamp(sec, nanosec), frame_id=str(frame_id))


def vector3(v: Sequence[float]) -> Any:
    return _types()["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def quaternion_xyzw(q: Sequence[float]) -> Any:
    """geometry_msgs/Quaternion from ROS-order (x, y, z, w)."""
    return _types()["geometry_msgs/msg/Quaternion"](
        x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])
    )


def covariance9(c: Sequence[float] | None) -> np.ndarray:
    arr = np.zeros(9) if c is None else np.asarray(c, dtype=np.float64).reshape(9)
    return np.ascontiguousarray(arr, dtype=np.float64)


def imu_message(
    sec: int, nanosec: int, frame_id: str, orientation_xyzw: Sequence[float],
    orientation_covariance: Sequence[float] | None, angular_velocity: Sequence[float],
    angular_velocity_covariance: Sequence[float] | None, linear_acceleration: Sequence[float],
    linear_acceleration_covariance: Sequence[float] | None,
) -> Any:
    """sensor_msgs/Imu (Jazzy)."""
    return _types()[IMU_TYPE](
        header=header(sec, nanosec, frame_id),
        orientation=quaternion_xyzw(orientation_xyzw),
        orientation_covariance=covariance9(orientation_covariance),
        angular_velocity=vector3(angular_velocity),
        angular_velocity_covariance=covariance9(angular_velocity_covariance),
        linear_acceleration=vector3(linear_acceleration),
        linear_acceleration_covariance=covariance9(linear_acceleration_covariance),
    )


def twist_stamped_message(sec: int, nanosec: int, frame_id: str, linear: Sequence[float],
                          angular: Sequence[float] = (0.0, 0.0, 0.0)) -> Any:
    """geometry_msgs/TwistStamped (Jazzy): a velocity [m/s] (and rate [rad/s]) in frame_id."""
    t = _types()
    return t[TWIST_STAMPED_TYPE](
        header=header(sec, nanosec, frame_id),
        twist=t["geometry_msgs/msg/Twist"](linear=vector3(linear), angular=vector3(angular)))


def odometry_message(sec: int, nanosec: int, frame_id: str, child_frame_id: str,
                     orientation_xyzw: Sequence[float], position: Sequence[float],
                     linear_body: Sequence[float]) -> Any:
    """nav_msgs/Odometry (Jazzy): pose of child_frame_id in frame_id, twist in child_frame_id."""
    t = _types()
    pose = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=float(position[0]), y=float(position[1]),
                                              z=float(position[2])),
        orientation=quaternion_xyzw(orientation_xyzw))
    twist = t["geometry_msgs/msg/Twist"](linear=vector3(linear_body),
                                         angular=vector3((0.0, 0.0, 0.0)))
    return t[ODOMETRY_TYPE](
        header=header(sec, nanosec, frame_id), child_frame_id=str(child_frame_id),
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))


def imu_from_output(out: Any) -> Any:
    """sensor_msgs/Imu for ``imu/data`` from a pipeline output (every field as it computed)."""
    return imu_message(
        out.stamp_sec, out.stamp_nanosec, out.frame_id, out.orientation_xyzw,
        out.orientation_covariance, out.angular_velocity, out.angular_velocity_covariance,
        out.linear_acceleration, out.linear_acceleration_covariance,
    )


def rpy_from_output(out: Any) -> Any | None:
    """geometry_msgs/Vector3Stamped (x roll, y pitch, z yaw [rad]) or None without an attitude."""
    if out.rpy_rad is None:
        return None
    return _types()[VECTOR3_STAMPED_TYPE](
        header=header(out.stamp_sec, out.stamp_nanosec, out.frame_id), vector=vector3(out.rpy_rad)
    )


def magnetic_field_message(
    sec: int, nanosec: int, frame_id: str, field_T: Sequence[float],
    covariance: Sequence[float] | None = None,
) -> Any:
    """sensor_msgs/MagneticField [T]."""
    return _types()[MAG_TYPE](
        header=header(sec, nanosec, frame_id), magnetic_field=vector3(field_T),
        magnetic_field_covariance=covariance9(covariance),
    )


def quaternion_stamped_message(
    sec: int, nanosec: int, frame_id: str, q_wxyz: Sequence[float]
) -> Any:
    """geometry_msgs/QuaternionStamped from NumPy-order (w, x, y, z)."""
    return _types()[QUATERNION_STAMPED_TYPE](
        header=header(sec, nanosec, frame_id),
        quaternion=quaternion_xyzw((q_wxyz[1], q_wxyz[2], q_wxyz[3], q_wxyz[0])),
    )


def diagnostics_message(stamp_ns: int, reports: Sequence[Any]) -> Any:
    """diagnostic_msgs/DiagnosticArray from pipeline DiagnosticsReport objects."""
    t = _types()
    kv = t["diagnostic_msgs/msg/KeyValue"]
    status = [
        t["diagnostic_msgs/msg/DiagnosticStatus"](
            level=int(r.level), name=str(r.name), message=str(r.message),
            hardware_id=str(r.hardware_id),
            values=[kv(key=str(k), value=str(v)) for k, v in r.values],
        )
        for r in reports
    ]
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return t[DIAGNOSTIC_ARRAY_TYPE](header=header(sec, nanosec, ""), status=status)


# ---------------------------------------------------------------------------------------------
# writing


def check_output_path(path: Path, *, overwrite: bool, inputs: Sequence[Path] = ()) -> None:
    """Refuse an output that exists (without ``overwrite``), is an input, or is not a bag."""
    if path.suffix == ".bag":
        raise BagError(
            f"{path}: a ROS 2 bag is a directory; '.bag' names ROS 1 files: choose a name "
            "without the .bag suffix", 2,
        )
    resolved = path.resolve()
    for src in inputs:
        if resolved == Path(src).resolve():
            raise BagError(f"{path}: the output would overwrite the input bag", 2)
    if not (path.exists() or path.is_symlink()):
        if not path.parent.is_dir():
            raise BagError(f"{path}: parent directory {path.parent} does not exist", 2)
        if not os.access(path.parent, os.W_OK | os.X_OK):
            raise BagError(f"{path}: directory {path.parent} is not writable", 2)
        return
    if not overwrite:
        raise BagError(f"{path}: output exists (use --overwrite to replace it)", 2)
    if path.is_dir() and not (path / "metadata.yaml").is_file() and any(path.iterdir()):
        raise BagError(
            f"{path}: exists and is not a ROS 2 bag; refusing to replace it even with --overwrite",
            2,
        )


class OutputBag:
    """A ROS 2 bag being written: temporary sibling directory, renamed into place on commit.

    Use as a context manager: leaving the block normally commits; an exception aborts and
    removes everything written. Message objects are serialized with the Jazzy typestore.
    """

    def __init__(
        self, path: str | os.PathLike[str], *, storage: str = "mcap", overwrite: bool = False
    ) -> None:
        self.path = Path(path)
        if storage not in STORAGES:
            raise BagError(f"unknown storage {storage!r}; choose one of {', '.join(STORAGES)}")
        check_output_path(self.path, overwrite=overwrite)
        self.storage = storage
        self.overwrite = overwrite
        parent = self.path.parent
        self._tmpdir = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.partial-", dir=parent))
        self._bag_dir = self._tmpdir / self.path.name
        self._writer = Writer(self._bag_dir, version=ROSBAG2_VERSION,
                              storage_plugin=STORAGES[storage])
        self._connections: dict[tuple[str, str], Any] = {}
        self._store = typestore()
        self.counts: dict[str, int] = {}
        try:
            self._writer.open()
        except Exception as exc:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise BagError(f"{self.path}: cannot create the bag: {_short(exc)}") from exc
        self._open = True

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Declare a topic (Jazzy definition of ``msgtype``); idempotent."""
        key = (topic, msgtype)
        if key not in self._connections:
            self._connections[key] = self._writer.add_connection(
                topic, msgtype, typestore=self._store
            )
            self.counts.setdefault(topic, 0)

    def set_custom_data(self, key: str, value: str) -> None:
        """A ``custom_data`` entry of the bag's metadata.yaml (e.g. ``cf_estimator.mode``)."""
        self._writer.set_custom_data(key, value)

    def write(self, topic: str, msgtype: str, log_time_ns: int, msg: Any) -> None:
        """Serialize (CDR, Jazzy) and write one message at ``log_time_ns``."""
        key = (topic, msgtype)
        conn = self._connections.get(key)
        if conn is None:
            self.add_topic(topic, msgtype)
            conn = self._connections[key]
        data = self._store.serialize_cdr(msg, msgtype)
        self._writer.write(conn, int(log_time_ns), data)
        self.counts[topic] += 1

    def write_raw(self, topic: str, msgtype: str, log_time_ns: int, data: bytes) -> None:
        """Write one message already serialized (Jazzy CDR) at ``log_time_ns``.

        For mcap storage the message record goes straight into rosbags' pending chunk with the
        bookkeeping ``Writer.write`` and ``McapWriter.write`` do (the same file, byte for byte:
        tested against them); any other storage goes through ``Writer.write``.
        """
        key = (topic, msgtype)
        conn = self._connections.get(key)
        if conn is None:
            self.add_topic(topic, msgtype)
            conn = self._connections[key]
        ts = int(log_time_ns)
        st = self._mcap
        if st is None:
            self._writer.write(conn, ts, data)
        else:
            cid = conn.id
            w = self._writer
            if ts < st.message_start_time:
                st.message_start_time = ts
            if ts > st.message_end_time:
                st.message_end_time = ts
            st.channel_stats[cid] += 1
            chunk = st.chunk
            if ts < chunk.message_start_time:
                chunk.message_start_time = ts
            if ts > chunk.message_end_time:
                chunk.message_end_time = ts
            bio = chunk.bio
            chunk.msgs[cid].append((ts, bio.tell()))
            bio.write(_MCAP_MESSAGE.pack(0x05, 22 + len(data), cid, 0, ts, ts))
            bio.write(data)
            if bio.tell() > _MCAP_CHUNK_BYTES:
                _close_chunk(st)
            w.counts[cid] += 1
            if ts < w.min_timestamp:
                w.min_timestamp = ts
            if ts > w.max_timestamp:
                w.max_timestamp = ts
        self.counts[topic] += 1

    def write_rows(self, log_time_ns: np.ndarray,
                   topics: Sequence[tuple[str, str, np.ndarray]]) -> None:
        """Write n messages on each of ``topics`` (``(topic, msgtype, (n, size) uint8 CDR
        rows)``), row by row: row k of every topic at ``log_time_ns[k]``, in the order given —
        what n × :meth:`write_raw` calls write, byte for byte, with the mcap records built as
        one NumPy array and appended a chunk at a time."""
        ts = np.asarray(log_time_ns, dtype=np.int64)
        n = ts.shape[0]
        if n == 0:
            return
        st = self._mcap
        new = any((t, mt) not in self._connections for t, mt, _r in topics)
        if st is None or new:  # a new topic is declared where its first message is written
            first = n if st is None else 1
            for k in range(first):
                for topic, msgtype, rows in topics:
                    self.write_raw(topic, msgtype, int(ts[k]), rows[k].tobytes())
            if first < n:
                self.write_rows(ts[first:], [(t, mt, r[first:]) for t, mt, r in topics])
            return
        conns = [self._connections[(t, mt)] for t, mt, _r in topics]
        parts, sizes = [], []
        for conn, (_t, _m, rows) in zip(conns, topics, strict=True):
            size = rows.shape[1]
            rec = np.empty((n, 31 + size), dtype=np.uint8)
            rec[:, 0] = 0x05
            rec[:, 1:9] = np.frombuffer(struct.pack("<Q", 22 + size), dtype=np.uint8)
            rec[:, 9:11] = np.frombuffer(struct.pack("<H", conn.id), dtype=np.uint8)
            rec[:, 11:15] = 0
            stamp = ts.astype("<u8").view(np.uint8).reshape(n, 8)
            rec[:, 15:23] = stamp
            rec[:, 23:31] = stamp
            rec[:, 31:] = rows
            parts.append(rec)
            sizes.append(31 + size)
        flat = np.concatenate(parts, axis=1).reshape(-1)
        m = len(topics)
        # record r = row r // m, topic r % m: its offset in ``flat``
        prefix = np.concatenate([[0], np.cumsum(sizes[:-1])]).astype(np.int64)
        r_all = np.arange(n * m + 1, dtype=np.int64)
        starts = (r_all // m) * int(sum(sizes)) + prefix[r_all % m]
        cids = [c.id for c in conns]
        ts_list = ts.tolist()
        w = self._writer
        pos, total = 0, n * m
        while pos < total:
            chunk = st.chunk
            bio = chunk.bio
            tell = bio.tell()
            ends = tell + starts[pos + 1:] - starts[pos]  # chunk size after each record
            over = int(np.searchsorted(ends, _MCAP_CHUNK_BYTES, side="right"))
            last = min(pos + over, total - 1)  # the record after which the chunk closes
            offsets = (tell + starts[pos:last + 1] - starts[pos]).tolist()
            lo, hi = pos // m, last // m
            t_min, t_max = min(ts_list[lo:hi + 1]), max(ts_list[lo:hi + 1])
            if t_min < chunk.message_start_time:
                chunk.message_start_time = t_min
            if t_max > chunk.message_end_time:
                chunk.message_end_time = t_max
            if t_min < st.message_start_time:
                st.message_start_time = t_min
            if t_max > st.message_end_time:
                st.message_end_time = t_max
            if t_min < w.min_timestamp:
                w.min_timestamp = t_min
            if t_max > w.max_timestamp:
                w.max_timestamp = t_max
            for j in [(pos + k) % m for k in range(m)]:  # the chunk's index keeps first-seen order
                cid = cids[j]
                first = pos + ((j - pos) % m)
                count = len(range(first, last + 1, m))
                chunk.msgs[cid].extend(zip(ts_list[first // m:first // m + count],
                                           offsets[first - pos:last + 1 - pos:m],
                                           strict=True))
                st.channel_stats[cid] += count
                w.counts[cid] += count
                self.counts[topics[j][0]] += count
            bio.write(flat[starts[pos]:starts[last + 1]].tobytes())
            if bio.tell() > _MCAP_CHUNK_BYTES:
                _close_chunk(st)
            pos = last + 1

    @functools.cached_property
    def _mcap(self) -> Any:
        """rosbags' McapWriter when :meth:`write_raw` may write into it directly, else None
        (a rosbags outside :data:`ROSBAGS_TESTED`, compression, another storage)."""
        if not direct_mcap_supported():
            return None
        from rosbags.rosbag2.storage_mcap import McapWriter
        from rosbags.rosbag2.writer import CompressionMode

        st = getattr(self._writer, "storage", None)
        if type(st) is not McapWriter or self._writer.compression_mode != CompressionMode.NONE:
            return None
        if not all(hasattr(st, a) for a in ("chunk", "channel_stats", "message_start_time",
                                            "message_end_time", "close_chunk")):
            return None
        return st

    def commit(self) -> Path:
        """Finish the bag and move it to its final path (replacing an old one with overwrite)."""
        if not self._open:
            raise BagError(f"{self.path}: bag already closed")
        self._open = False
        try:
            self._writer.close()
            if self.path.exists() or self.path.is_symlink():
                if not self.overwrite:  # appeared while we were writing
                    raise BagError(f"{self.path}: output appeared meanwhile; not replacing it")
                old = self._tmpdir / (self.path.name + ".old")
                os.replace(self.path, old)
            os.replace(self._bag_dir, self.path)
        except BaseException:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            raise
        shutil.rmtree(self._tmpdir, ignore_errors=True)
        return self.path

    def abort(self) -> None:
        """Drop everything written (idempotent)."""
        if self._open:
            self._open = False
            with contextlib.suppress(Exception):
                self._writer.abort()
        shutil.rmtree(self._tmpdir, ignore_errors=True)

    def __enter__(self) -> OutputBag:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.abort()


def _close_chunk(st: Any) -> None:
    """rosbags' ``McapWriter.close_chunk`` with the message indexes packed by NumPy: the same
    records, byte for byte (tested against rosbags' writer over several chunks)."""
    from io import BytesIO

    from rosbags.rosbag2.storage_mcap import (
        PendingChunk,
        write_record,
        write_string,
        write_uint32,
        write_uint64,
    )

    chunk = st.chunk
    rec = BytesIO()
    write_uint64(rec, chunk.message_start_time)
    write_uint64(rec, chunk.message_end_time)
    write_uint64(rec, chunk.bio.tell())
    write_uint32(rec, 0)
    compressed = st.compressor(chunk.bio.getvalue())
    write_string(rec, st.compression)
    write_uint64(rec, len(compressed))
    rec.write(compressed)
    chunk_start = st.bio.tell()
    write_record(st.bio, 0x06, rec)
    chunk_end = st.bio.tell()
    offsets: list[tuple[int, int]] = []
    for cid, msgs in chunk.msgs.items():
        offsets.append((cid, st.bio.tell()))
        body = np.array(msgs, dtype="<u8").tobytes()
        st.bio.write(struct.pack("<BQHI", 0x07, 6 + len(body), cid, len(body)))
        st.bio.write(body)
    rec = BytesIO()
    write_uint64(rec, chunk.message_start_time)
    write_uint64(rec, chunk.message_end_time)
    write_uint64(rec, chunk_start)
    write_uint64(rec, chunk_end - chunk_start)
    rec.write(struct.pack("<I", len(offsets) * 10))
    for cid, offset in offsets:
        rec.write(struct.pack("<HQ", cid, offset))
    write_uint64(rec, st.bio.tell() - chunk_end)
    write_string(rec, st.compression)
    write_uint64(rec, len(compressed))
    write_uint64(rec, chunk.bio.tell())
    st.chunks.append(rec)
    st.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))


def user_file_mode() -> int:
    """The mode a new regular file gets under the user's umask (0o644 for umask 022).

    ``tempfile.mkstemp`` creates 0600 files; whatever we write through one is chmod-ed to this
    before the rename, so outputs look like any other file the user writes.
    """
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def write_atomic_text(path: Path, text: str) -> None:
    """Write a text file through a temporary sibling and rename (never half-written); the file
    gets the user's umask (:func:`user_file_mode`)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.partial-", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.chmod(tmp, user_file_mode())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
