"""Writing ROS 2 bags: :class:`OutputBag` writes Jazzy messages (storage mcap or sqlite3) into a
temporary sibling directory and renames it into place only when everything was written, so a
failed or interrupted run never leaves anything that looks like a complete bag. The mcap
specifics (the direct path into rosbags' pending chunk, gated by :data:`ROSBAGS_TESTED`) live
here too."""

from __future__ import annotations

import contextlib
import functools
import os
import shutil
import struct
import tempfile
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer

from cf_estimator.bag.types import BagError, one_line, typestore

STORAGES = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
#: rosbag2 metadata version written (Jazzy's rosbag2 writes and reads version 9).
ROSBAG2_VERSION = 9
#: The rosbags releases [from, to) this module is tested with (setup.py pins the same range):
#: the reader and writer use the public API, and the direct mcap path of
#: :meth:`OutputBag.write_raw` / :meth:`OutputBag.write_rows` also writes into ``McapWriter``'s
#: pending chunk (not public API), checked byte for byte against rosbags' own ``Writer.write``
#: with 0.11.0 and 0.11.9 (test/test_bulk_decode.py). Outside the range (a rosbags installed
#: past the pin) every message goes through ``Writer.write``: the same file, only slower.
#: The same range gates :mod:`cf_estimator.bag.mcapread` (it reads ``McapReader``'s chunk index
#: and matches channels as ``DirectoryReader`` does; outside it the replay reads through
#: ``AnyReader.messages``).
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


#: An mcap Message record's fixed part: opcode, record length, channel id, sequence, log time,
#: publish time (rosbags writes log time twice); and the size that closes a chunk (rosbags').
_MCAP_MESSAGE = struct.Struct("<BQHIQQ")
_MCAP_CHUNK_BYTES = 2**20


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
            raise BagError(f"{self.path}: cannot create the bag: {one_line(exc)}") from exc
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
        if self._mcap is not None:  # the direct path owns the pending chunk (see commit)
            self.write_raw(topic, msgtype, log_time_ns, bytes(data))
            return
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
        one NumPy array and appended a chunk at a time (:meth:`write_records`)."""
        n = len(log_time_ns)
        rec, payloads = record_rows(n, [rows.shape[1] for _t, _m, rows in topics])
        for view, (_t, _m, rows) in zip(payloads, topics, strict=True):
            view[...] = rows
        self.write_records(log_time_ns, [(t, mt, rows.shape[1]) for t, mt, rows in topics],
                           rec)

    def write_records(self, log_time_ns: np.ndarray, topics: Sequence[tuple[str, str, int]],
                      rec: np.ndarray) -> None:
        """:meth:`write_rows` of messages already encoded in place: ``rec`` from
        :func:`record_rows` with ``topics`` (``(topic, msgtype, payload size)``) in the order
        of its sizes and every payload filled (the record headers are filled here)."""
        ts = np.asarray(log_time_ns, dtype=np.int64)
        n = ts.shape[0]
        if n == 0:
            return
        sizes = [31 + size for _t, _m, size in topics]
        st = self._mcap
        new = any((t, mt) not in self._connections for t, mt, _s in topics)
        if st is None or new:  # a new topic is declared where its first message is written
            first = n if st is None else 1
            starts = np.cumsum([0] + sizes)
            for k in range(first):
                for (topic, msgtype, _s), lo, hi in zip(topics, starts[:-1], starts[1:],
                                                        strict=True):
                    self.write_raw(topic, msgtype, int(ts[k]), rec[k, lo + 31:hi].tobytes())
            if first < n:
                self.write_records(ts[first:], topics, rec[first:])
            return
        conns = [self._connections[(t, mt)] for t, mt, _s in topics]
        # row k: the k-th record of every topic, side by side: the headers filled in place
        stamp = ts.astype("<u8").view(np.uint8).reshape(n, 8)
        off = 0
        for conn, size in zip(conns, sizes, strict=True):
            # opcode, record length, channel id, sequence 0; log and publish time
            rec[:, off:off + 15] = np.frombuffer(
                _MCAP_MESSAGE.pack(0x05, size - 9, conn.id, 0, 0, 0)[:15], dtype=np.uint8)
            rec[:, off + 15:off + 23] = stamp
            rec[:, off + 23:off + 31] = stamp
            off += size
        flat = rec.reshape(-1)
        view = memoryview(flat)
        m = len(topics)
        cids = [c.id for c in conns]
        ts_u8 = ts.astype("<u8")
        w = self._writer
        row_bytes = int(sum(sizes))
        tell = st.chunk.bio.tell()
        if tell + n * row_bytes <= _MCAP_CHUNK_BYTES:
            # the usual case: every record goes into the pending chunk, which stays open (the
            # loop below in one pass, without its search for the record that closes it)
            chunk = st.chunk
            _note_times(st, w, int(ts.min()), int(ts.max()))
            row_at = tell + np.arange(n, dtype=np.int64) * row_bytes
            off = 0
            for j, cid in enumerate(cids):
                pairs = np.empty((n, 2), dtype="<u8")
                pairs[:, 0] = ts_u8
                pairs[:, 1] = row_at + off
                off += sizes[j]
                chunk.msgs[cid].append(pairs)
                st.channel_stats[cid] += n
                w.counts[cid] += n
                self.counts[topics[j][0]] += n
            chunk.bio.write(view)
            return
        # record r = row r // m, topic r % m: its offset in ``flat``
        prefix = np.concatenate([[0], np.cumsum(sizes[:-1])]).astype(np.int64)
        r_all = np.arange(n * m + 1, dtype=np.int64)
        starts = (r_all // m) * row_bytes + prefix[r_all % m]
        pos, total = 0, n * m
        while pos < total:
            chunk = st.chunk
            bio = chunk.bio
            tell = bio.tell()
            ends = tell + starts[pos + 1:] - starts[pos]  # chunk size after each record
            over = int(np.searchsorted(ends, _MCAP_CHUNK_BYTES, side="right"))
            last = min(pos + over, total - 1)  # the record after which the chunk closes
            offsets_arr = tell + starts[pos:last + 1] - starts[pos]
            lo, hi = pos // m, last // m
            _note_times(st, w, int(ts[lo:hi + 1].min()), int(ts[lo:hi + 1].max()))
            for j in [(pos + k) % m for k in range(m)]:  # the chunk's index keeps first-seen order
                cid = cids[j]
                first = pos + ((j - pos) % m)
                count = len(range(first, last + 1, m))
                # the (log time, offset) pairs of the chunk's message index as one array
                # (_close_chunk writes them; the pending chunk never reaches rosbags' own
                # close_chunk: commit closes it first)
                pairs = np.empty((count, 2), dtype="<u8")
                pairs[:, 0] = ts_u8[first // m:first // m + count]
                pairs[:, 1] = offsets_arr[first - pos:last + 1 - pos:m]
                chunk.msgs[cid].append(pairs)
                st.channel_stats[cid] += count
                w.counts[cid] += count
                self.counts[topics[j][0]] += count
            bio.write(view[int(starts[pos]):int(starts[last + 1])])
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
            st = self._mcap
            if st is not None and st.chunk.bio.tell():
                _close_chunk(st)  # what Writer.close would do with its own close_chunk
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


def _index_pairs(msgs: list[Any]) -> np.ndarray:
    """(n, 2) uint64 (log time, offset) of a channel's messages in a pending chunk: tuples
    (:meth:`OutputBag.write_raw`) and (k, 2) arrays (:meth:`OutputBag.write_rows`), in order."""
    parts: list[np.ndarray] = []
    run: list[tuple[int, int]] = []
    for m in msgs:
        if type(m) is tuple:
            run.append(m)
            continue
        if run:
            parts.append(np.array(run, dtype="<u8").reshape(-1, 2))
            run = []
        parts.append(m)
    if run or not parts:
        parts.append(np.array(run, dtype="<u8").reshape(-1, 2))
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def _note_times(st: Any, w: Any, t_min: int, t_max: int) -> None:
    """The log-time range of records written into the pending chunk: the chunk's, the
    storage's and the writer's."""
    chunk = st.chunk
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


def record_rows(n: int, sizes: Sequence[int]) -> tuple[np.ndarray, list[np.ndarray]]:
    """An (n, Σ(31 + size)) uint8 array for :meth:`OutputBag.write_records` (row k: the mcap
    message records of message k of each topic, side by side) and the (n, size) payload view of
    each topic in it, to encode the messages into."""
    rec = np.empty((n, sum(31 + s for s in sizes)), dtype=np.uint8)
    views, off = [], 0
    for size in sizes:
        views.append(rec[:, off + 31:off + 31 + size])
        off += 31 + size
    return rec, views


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
    chunk_start = st.bio.tell()
    if st.compression == "":  # the records as they are: written from the buffer, not copied
        with chunk.bio.getbuffer() as records:
            n_compressed = len(records)
            write_string(rec, st.compression)
            write_uint64(rec, n_compressed)
            st.bio.write(b"\x06")  # write_record's opcode and length, then the record
            write_uint64(st.bio, rec.tell() + n_compressed)
            st.bio.write(rec.getbuffer())
            st.bio.write(records)
    else:
        compressed = st.compressor(chunk.bio.getvalue())
        n_compressed = len(compressed)
        write_string(rec, st.compression)
        write_uint64(rec, n_compressed)
        rec.write(compressed)
        write_record(st.bio, 0x06, rec)
    chunk_end = st.bio.tell()
    offsets: list[tuple[int, int]] = []
    for cid, msgs in chunk.msgs.items():
        offsets.append((cid, st.bio.tell()))
        body = _index_pairs(msgs).tobytes()
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
    write_uint64(rec, n_compressed)
    write_uint64(rec, chunk.bio.tell())
    st.chunks.append(rec)
    st.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))
