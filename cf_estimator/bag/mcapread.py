"""ROS 2 mcap storage read a chunk at a time with NumPy: the messages rosbags' reader yields, in
its order, without a Python object per message.

rosbags' ``McapReader.messages`` decompresses each chunk, walks its records one by one in Python
and merges the chunks with ``heapq.merge``; at a few hundred thousand messages that walk is most
of a replay's reading time. Here each chunk is decompressed once (rosbags' own ``decompress``:
the same checks), the message records are located from the chunk's message index and checked
to tile the chunk exactly (every record a Message record, each starting where the previous one
ends — what the sequential walk would find), and their channel ids, log times and payload
offsets are read as arrays. A chunk that does not tile (other records inside it, an index that
disagrees with the records) is walked record by record in Python, as rosbags walks it.

What comes out is what ``AnyReader.messages(connections=...)`` yields, in the same order, for
the same bag: the chunks and channels rosbags would read (its connection matching, its chunk
selection by the index's channel counts, its per-chunk time window), each chunk's messages in a
stable sort by log time, chunks merged by (log time, chunk offset). Tested message for message
against rosbags (test/test_mcap_read.py).

Used only where that equality is known to hold: one bag, rosbags' ``McapReader`` over a single
indexed ``.mcap`` file without per-message or per-file compression, and a rosbags release in
:data:`cf_estimator.bag.writer.ROSBAGS_TESTED` (the reader's index objects are not public API).
Everything else — ROS 1 bags, sqlite3, unindexed or multi-file mcap — reads through rosbags.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

#: mcap record opcodes
_MESSAGE, _MESSAGE_INDEX = 0x05, 0x07
_U64 = struct.Struct("<Q")
_HIQQ = struct.Struct("<HIQQ")
_MAX_SEEK = 2**63 - 1


@dataclass
class _Chunk:
    """One decompressed chunk's messages on the wanted channels, sorted by log time (stable)."""

    offset: int  #: the chunk record's file offset (rosbags' tie-break between chunks)
    buf: np.ndarray  #: the decompressed records, uint8
    log: np.ndarray  #: int64 log time per message
    conn: np.ndarray  #: index into McapSource.connections per message
    start: np.ndarray  #: int64 payload offset in ``buf``
    length: np.ndarray  #: int64 payload length


class RawBatch:
    """Consecutive messages of :meth:`McapSource.batches`: ``log_ns`` (int64) and ``conn``
    (index into :attr:`McapSource.connections`) per message, payloads in the chunk buffers."""

    def __init__(self, bufs: list[np.ndarray], src: np.ndarray, log_ns: np.ndarray,
                 conn: np.ndarray, start: np.ndarray, length: np.ndarray) -> None:
        self._bufs = bufs
        self._src = src
        self.log_ns = log_ns
        self.conn = conn
        self._start = start
        self._length = length

    def __len__(self) -> int:
        return int(self.log_ns.shape[0])

    def raw(self, i: int) -> bytes:
        """Message i's serialized bytes."""
        s = int(self._start[i])
        return self._bufs[int(self._src[i])][s:s + int(self._length[i])].tobytes()

    def rows(self, sel: np.ndarray) -> np.ndarray | None:
        """(len(sel), L) uint8: the payloads of messages ``sel`` when all have one length L,
        else None."""
        lens = self._length[sel]
        n = int(sel.shape[0])
        if n == 0:
            return np.zeros((0, 0), dtype=np.uint8)
        size = int(lens[0])
        if size == 0 or not bool(np.all(lens == size)):
            return None
        starts, srcs = self._start[sel], self._src[sel]
        first = int(srcs[0])
        if bool(np.all(srcs == first)):
            return sliding_window_view(self._bufs[first], size)[starts]
        out = np.empty((n, size), dtype=np.uint8)
        for s in np.unique(srcs).tolist():
            m = srcs == s
            out[m] = sliding_window_view(self._bufs[s], size)[starts[m]]
        return out


def source_for(reader: Any, connections: Sequence[Any]) -> McapSource | None:
    """A :class:`McapSource` for ``reader.messages(connections=connections)`` when this module
    reads that bag as rosbags does, else None (read through rosbags)."""
    from cf_estimator.bag.writer import direct_mcap_supported

    if not direct_mcap_supported() or not connections:
        return None
    try:
        from rosbags.rosbag2.reader import DirectoryReader, Reader
        from rosbags.rosbag2.storage_mcap import McapReader
    except ImportError:  # pragma: no cover - a rosbags outside the tested range
        return None
    readers = getattr(reader, "readers", None)
    if not getattr(reader, "is2", False) or not readers or len(readers) != 1:
        return None
    if type(readers[0]) is not Reader:
        return None
    r2 = readers[0].storage  # a bag directory: rosbags' DirectoryReader owns the connections
    if type(r2) is not DirectoryReader or getattr(r2.metadata, "compression_mode", None):
        return None  # per-message or per-file compression: rosbags
    storages = getattr(r2, "storages", None)
    if not storages or len(storages) != 1 or type(storages[0]) is not McapReader:
        return None
    storage = storages[0]
    if not storage.chunks or storage.bio is None:
        return None  # unindexed: rosbags scans the file
    # DirectoryReader.messages' matching of the storage's channels to the requested connections
    conns = [c for c in connections if c.owner is r2]
    if len(conns) != len(connections):
        return None
    channel_map: dict[int, int] = {}
    targets: list[Any] = []
    for x in storage.connections:
        y = next((y for y in conns if y.topic == x.topic and y.msgtype == x.msgtype
                  and y.ext == x.ext and (not x.digest or not y.digest or y.digest == x.digest)),
                 None)
        if y is not None:
            if y not in targets:
                targets.append(y)
            channel_map[x.id] = targets.index(y)
    return McapSource(storage, channel_map, targets)


class McapSource:
    """The messages of some channels of one indexed mcap file, in rosbags' order."""

    def __init__(self, storage: Any, channel_map: dict[int, int], targets: list[Any]) -> None:
        self._storage = storage
        self._channel_map = channel_map  #: mcap channel id -> index into connections
        self.connections = targets  #: the AnyReader connections messages are yielded as
        size = max(channel_map, default=0) + 1
        self._lookup = np.full(max(size, 65536), -1, dtype=np.intp)
        for cid, k in channel_map.items():
            self._lookup[cid] = k

    def batches(self, size: int) -> Iterator[RawBatch]:
        """The messages in batches of about ``size`` (all when fewer are left). Raises rosbags'
        ``ReaderError`` (or another exception) on a damaged file, as its reader would."""
        wanted = self._channel_map
        chunks = [c for c in self._storage.chunks
                  if any(c.channel_count.get(cid, 0) for cid in wanted)]
        # load in order of start time: a chunk's messages all lie in [start, end] (rosbags'
        # window), so every message before the next chunk's start is final
        chunks.sort(key=lambda c: (c.message_start_time, c.chunk_start_offset))
        pending: list[_Chunk] = []
        out: list[tuple[_Chunk, np.ndarray]] = []  # (chunk, its messages to emit), in order
        n_out = 0
        for j, info in enumerate(chunks):
            loaded = self._load(info)
            if loaded.log.shape[0]:
                pending.append(loaded)
            frontier = chunks[j + 1].message_start_time if j + 1 < len(chunks) else None
            ready, pending = _split(pending, frontier)
            for item in ready:
                out.append(item)
                n_out += int(item[1].shape[0])
            while n_out >= size:
                batch, out, n_out = _take(out, size)
                yield batch
        while n_out > 0:
            batch, out, n_out = _take(out, size)
            yield batch

    def _load(self, info: Any) -> _Chunk:
        from rosbags.rosbag2.storage_mcap import decompress, read_exact

        bio = self._storage.bio
        bio.seek(info.chunk_start_offset + 9 + 24)
        crc = struct.unpack("<I", read_exact(bio, 4))[0]
        bio.seek(info.chunk_start_offset + 9 + 40 + len(info.compression))
        data = decompress(read_exact(bio, info.compressed_size), info.compression,
                          info.uncompressed_size, crc)
        buf = np.frombuffer(data, dtype=np.uint8)
        start_t, stop_t = info.message_start_time, info.message_end_time + 1
        found = self._from_index(info, buf)
        if found is None:
            cid, log, dstart, dlen = _walk(data)
        else:
            cid, log, dstart, dlen = found
        conn = self._lookup[cid] if cid.size else np.zeros(0, dtype=np.intp)
        keep = (conn >= 0) & (log >= start_t) & (log < stop_t)
        if not bool(np.all(keep)):
            conn, log, dstart, dlen = conn[keep], log[keep], dstart[keep], dlen[keep]
        if log.shape[0] > 1 and not bool(np.all(log[1:] >= log[:-1])):
            order = np.argsort(log, kind="stable")
            conn, log, dstart, dlen = conn[order], log[order], dstart[order], dlen[order]
        return _Chunk(info.chunk_start_offset, buf, log, conn, dstart, dlen)

    def _from_index(self, info: Any, buf: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """The chunk's Message records located from its message index, when they tile the
        chunk exactly (else None: walk it)."""
        bio = self._storage.bio
        length = info.message_index_length
        if length <= 0 or not info.message_index_offsets:
            return None
        bio.seek(info.chunk_start_offset + info.chunk_length)
        index = bio.read(length)
        if len(index) != length:
            return None
        parts = []
        pos = 0
        while pos < length:
            if pos + 9 > length or index[pos] != _MESSAGE_INDEX:
                return None
            rec_len = _U64.unpack_from(index, pos + 1)[0]
            body = pos + 9
            if rec_len < 6 or body + rec_len > length:
                return None
            n_bytes = struct.unpack_from("<I", index, body + 2)[0]
            if n_bytes % 16 or 6 + n_bytes > rec_len:
                return None
            pairs = np.frombuffer(index, dtype="<u8", count=n_bytes // 8, offset=body + 6)
            parts.append(pairs[1::2])
            pos = body + rec_len
        size = buf.shape[0]
        listed = np.sort(np.concatenate(parts)) if parts else None  # uint64
        if listed is None or listed.shape[0] == 0 or int(listed[0]) != 0 or \
                int(listed[-1]) + 31 > size:
            return None
        offs = listed.astype(np.int64)
        if not bool(np.all(buf[offs] == _MESSAGE)):
            return None
        lens = _gather(buf, offs + 1, 8, "<u8").astype(np.int64)
        ends = offs + 9 + lens
        if (lens < 22).any() or ends[-1] != size or not bool(np.all(ends[:-1] == offs[1:])):
            return None
        cid = _gather(buf, offs + 9, 2, "<u2").astype(np.intp)
        log = _gather(buf, offs + 15, 8, "<u8").astype(np.int64)
        return cid, log, offs + 31, lens - 22


def _gather(buf: np.ndarray, at: np.ndarray, width: int, dtype: str) -> np.ndarray:
    """The little-endian integers of ``width`` bytes at offsets ``at`` of ``buf``."""
    return np.ascontiguousarray(sliding_window_view(buf, width)[at]).view(dtype).reshape(-1)


def _walk(data: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every Message record of a decompressed chunk, record by record (rosbags' msgsrc walk:
    other records skipped, a record running past the chunk an error)."""
    from rosbags.rosbag2.errors import ReaderError

    cids, logs, starts, lens = [], [], [], []
    pos, size = 0, len(data)
    while pos < size:
        op = data[pos]
        if pos + 9 > size:
            raise ReaderError(f"Truncated record at offset {pos + 1}.")
        n = _U64.unpack_from(data, pos + 1)[0]
        body = pos + 9
        # rosbags skips another record by seeking (past the end: the walk stops there) and
        # reads a Message record (running past the end: an error)
        if op == _MESSAGE:
            if body + n > size:
                raise ReaderError(f"Truncated record at offset {body}: expected {n} bytes.")
            if n < 22:
                raise ReaderError(f"Invalid message record length {n}.")
            cid, _seq, log, _pub = _HIQQ.unpack_from(data, body)
            cids.append(cid)
            logs.append(log)
            starts.append(body + 22)
            lens.append(n - 22)
        elif body + n > _MAX_SEEK:  # rosbags' seek past it overflows
            raise ReaderError(f"Invalid record length {n} at offset {body}.")
        pos = body + n
    return (np.asarray(cids, dtype=np.intp), np.asarray(logs, dtype=np.uint64).astype(np.int64),
            np.asarray(starts, dtype=np.int64), np.asarray(lens, dtype=np.int64))


def _split(pending: list[_Chunk], frontier: int | None
           ) -> tuple[list[tuple[_Chunk, np.ndarray]], list[_Chunk]]:
    """The pending messages logged before ``frontier`` (all when None) in rosbags' order —
    by log time, then chunk offset, then position in the chunk — and the chunks still holding
    later ones (their emitted messages dropped)."""
    if not pending:
        return [], []
    if len(pending) == 1:  # the usual case: chunks follow each other in time
        c = pending[0]
        n = int(c.log.shape[0])
        k = n if frontier is None else int(np.searchsorted(c.log, frontier, side="left"))
        return ([(c, np.arange(k))] if k else []), ([_tail(c, k)] if k < n else [])
    # overlapping chunks: a merged order over all of them
    logs = np.concatenate([c.log for c in pending])
    which = np.concatenate([np.full(c.log.shape[0], i, dtype=np.intp)
                            for i, c in enumerate(pending)])
    pos = np.concatenate([np.arange(c.log.shape[0]) for c in pending])
    offsets = np.asarray([c.offset for c in pending], dtype=np.int64)[which]
    order = np.lexsort((pos, offsets, logs))
    logs, which, pos = logs[order], which[order], pos[order]
    k = logs.shape[0] if frontier is None else int(np.searchsorted(logs, frontier, "left"))
    ready: list[tuple[_Chunk, np.ndarray]] = []
    # runs of consecutive messages from one chunk, in the merged order
    if k:
        w = which[:k]
        cuts = np.flatnonzero(np.diff(w)) + 1
        for a, b in zip([0, *cuts.tolist()], [*cuts.tolist(), k], strict=True):
            ready.append((pending[int(w[a])], pos[a:b]))
    rest = []
    for i, c in enumerate(pending):
        left = np.sort(pos[k:][which[k:] == i])
        if left.shape[0]:
            rest.append(_select(c, left))
    return ready, rest


def _tail(c: _Chunk, k: int) -> _Chunk:
    return _Chunk(c.offset, c.buf, c.log[k:], c.conn[k:], c.start[k:], c.length[k:])


def _select(c: _Chunk, idx: np.ndarray) -> _Chunk:
    return _Chunk(c.offset, c.buf, c.log[idx], c.conn[idx], c.start[idx], c.length[idx])


def _take(out: list[tuple[_Chunk, np.ndarray]], size: int
          ) -> tuple[RawBatch, list[tuple[_Chunk, np.ndarray]], int]:
    """The first ``size`` messages of ``out`` as a batch, the rest, and how many are left."""
    parts: list[tuple[_Chunk, np.ndarray]] = []
    need = size
    rest = list(out)
    while rest and need > 0:
        c, idx = rest[0]
        if idx.shape[0] <= need:
            parts.append((c, idx))
            need -= idx.shape[0]
            rest.pop(0)
        else:
            parts.append((c, idx[:need]))
            rest[0] = (c, idx[need:])
            need = 0
    bufs: list[np.ndarray] = []
    ids: dict[int, int] = {}
    src, log, conn, start, length = [], [], [], [], []
    for c, idx in parts:
        b = ids.setdefault(id(c.buf), len(bufs))
        if b == len(bufs):
            bufs.append(c.buf)
        src.append(np.full(idx.shape[0], b, dtype=np.intp))
        log.append(c.log[idx])
        conn.append(c.conn[idx])
        start.append(c.start[idx])
        length.append(c.length[idx])
    left = sum(int(idx.shape[0]) for _c, idx in rest)
    batch = RawBatch(bufs, np.concatenate(src), np.concatenate(log), np.concatenate(conn),
                     np.concatenate(start), np.concatenate(length))
    return batch, rest, left
