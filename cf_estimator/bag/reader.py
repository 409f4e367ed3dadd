"""Reading bags over ``rosbags``: :class:`InputBag` wraps ``rosbags.highlevel.AnyReader`` (ROS 1
``.bag`` files, ROS 2 bag directories with sqlite3 or mcap storage) and turns every ``rosbags``
failure — truncated data, undecodable message — into a :class:`~cf_estimator.bag.types.BagError`
whose message names the file. Messages come back in log-time order across topics, as recorded.
:func:`cf_estimator.bag.formats.open_bag` picks the reader of a path (this one, the ulog and
DataFlash readers, the truncated-bag salvage), which build on the types here.
"""

from __future__ import annotations

import contextlib
import functools
import os
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader

from cf_estimator.bag.types import IMU_TYPE, MAG_TYPE, BagError, one_line, typestore


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
        #: the bag's end is missing: read as far as readable (:mod:`cf_estimator.bag.salvage`)
        self.truncated = False
        self.notes: list[str] = []  #: what the reader had to say (one line each)

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
        suffixes = ({p.suffix for p in self.path.iterdir()} if self.path.is_dir()
                    else {self.path.suffix})
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
                    f"log time {log_ns} ns: {one_line(exc)}"
                ) from exc

        def next_item() -> Any:
            try:
                return next(it)
            except StopIteration:
                return None
            except Exception as exc:  # noqa: BLE001 - any reader failure is a bad bag
                raise BagError(f"{self.path}: cannot read messages: {one_line(exc)}") from exc

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

        fast = self._mcap_source(topics)
        if fast is not None:
            yield from self._fast_chunks(fast)
            return
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
                raise BagError(f"{self.path}: cannot read messages: {one_line(exc)}") from exc
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

    def _mcap_source(self, topics: Iterable[str]) -> Any:
        """:mod:`cf_estimator.bag.mcapread` over ``topics`` where it reads this bag as rosbags
        does (one indexed mcap file; ``CF_ESTIMATOR_MCAP_READER=rosbags`` turns it off), else
        None."""
        if os.environ.get("CF_ESTIMATOR_MCAP_READER", "") == "rosbags" or not self.is_ros2:
            return None
        from cf_estimator.bag import mcapread

        wanted = set(topics)
        conns = [c for c in self._reader.connections if c.topic in wanted]
        try:
            return mcapread.source_for(self._reader, conns)
        except Exception:  # noqa: BLE001 - anything unexpected: rosbags reads it
            return None

    def _fast_chunks(self, source: Any) -> Iterator[FastChunk]:
        """:meth:`chunks` from an :class:`cf_estimator.bag.mcapread.McapSource`."""
        it = source.batches(_BULK_CHUNK)
        while True:
            try:
                batch = next(it)
            except StopIteration:
                return
            except Exception as exc:  # noqa: BLE001 - any reader failure is a bad bag
                raise BagError(f"{self.path}: cannot read messages: {one_line(exc)}") from exc
            yield FastChunk(self, source.connections, batch)

    def to_jazzy(self, msg: Any, msgtype: str) -> Any:
        """``msg`` (from this bag's typestore) as a Jazzy message object (ROS 1 ``seq`` dropped)."""
        return migrate_to_jazzy(self._reader.typestore, msgtype, msg, self._cache)

    @functools.cached_property
    def _cache(self) -> dict[str, object]:
        return {}


def _deserialize(bag: InputBag, conn: Any, raw: Any, log_ns: int) -> Any:
    """One raw message of ``bag`` decoded by rosbags; a message that does not decode is a
    :class:`BagError` naming the bag, the type, the topic and the log time."""
    try:
        return bag._reader.deserialize(raw, conn.msgtype)  # noqa: SLF001
    except Exception as exc:  # noqa: BLE001
        raise BagError(
            f"{bag.path}: cannot decode a {conn.msgtype} message on {conn.topic} at "
            f"log time {log_ns} ns: {one_line(exc)}"
        ) from exc


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
        return _deserialize(self._bag, conn, raw, log_ns)

    def msg(self, i: int) -> Any:
        """Message i as an object (a light view for a decoded row, else rosbags')."""
        block = self.blocks.get(self.msgtype[i])
        if block is not None:
            return block.message(self.row[i])
        return self._decode(i)


class FastChunk:
    """:class:`MessageChunk` over a batch of :mod:`cf_estimator.bag.mcapread` (arrays, no
    object per message): the same ``topic``, ``msgtype``, ``log_ns``, ``row``, ``blocks`` and
    :meth:`msg`, and :meth:`kinds`."""

    def __init__(self, bag: InputBag, connections: Sequence[Any], batch: Any) -> None:
        from cf_estimator.bag import cdr

        self._bag = bag
        self._conns = connections
        self._batch = batch
        self.log_ns = batch.log_ns.tolist()
        self.blocks: dict[str, Any] = {}
        conn = batch.conn
        n = len(batch)
        row = np.full(n, -1, dtype=np.int64)
        ros2 = bag.is_ros2
        for msgtype in (IMU_TYPE, MAG_TYPE):
            ks = [k for k, c in enumerate(connections) if c.msgtype == msgtype]
            if not ks:
                continue
            sel = np.flatnonzero(conn == ks[0]) if len(ks) == 1 else \
                np.flatnonzero(np.isin(conn, ks))
            if sel.size == 0:
                continue
            rows = batch.rows(sel)
            block = cdr.decode_rows(rows, msgtype, ros2) if rows is not None else None
            if block is None:
                idx = sel.tolist()
                raws = [batch.raw(i) for i in idx]
                by_raw = {id(r): i for r, i in zip(raws, idx, strict=True)}
                block = cdr.decode_block(raws, msgtype, ros2,
                                         lambda raw, _mt, m=by_raw: self._decode(m[id(raw)]))
            self.blocks[msgtype] = block
            row[sel] = np.arange(sel.size)
        self.row = row.tolist()
        self.row_array = row  #: ``row`` as an int64 array
        self.log_ns_array = batch.log_ns  #: ``log_ns`` as an int64 array

    def __len__(self) -> int:
        return len(self._batch)

    @functools.cached_property
    def topic(self) -> list[str]:
        names = [c.topic for c in self._conns]
        return [names[k] for k in self._batch.conn.tolist()]

    @functools.cached_property
    def msgtype(self) -> list[str]:
        types = [c.msgtype for c in self._conns]
        return [types[k] for k in self._batch.conn.tolist()]

    def kind_array(self, table: dict[str, int], default: int) -> np.ndarray:
        """Per message: ``table[topic]`` (``default`` for a topic not in it), an int8 array."""
        lut = np.asarray([table.get(c.topic, default) for c in self._conns], dtype=np.int8)
        return lut[self._batch.conn]

    def _decode(self, i: int) -> Any:
        conn = self._conns[int(self._batch.conn[i])]
        return _deserialize(self._bag, conn, self._batch.raw(i), self.log_ns[i])

    def msg(self, i: int) -> Any:
        """Message i as an object (a light view for a decoded row, else rosbags')."""
        conn = self._conns[int(self._batch.conn[i])]
        block = self.blocks.get(conn.msgtype)
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
