"""Truncated bags read as far as they are readable: a ROS 1 ``.bag`` file, an mcap file (bare or
in a ROS 2 bag directory) or a ROS 2 sqlite3 bag whose end is missing — what a recorder that
loses power writes — replayed up to where the data stops, and said in one line.

:func:`truncation` says whether a path is such a bag (cheap: the file's own header and end, no
scan), :func:`open_truncated` reads it forward into a :class:`SalvageReader`, which offers what
:class:`cf_estimator.bag.reader.InputBag` uses of rosbags' ``AnyReader`` (``connections``,
``messages``, ``deserialize``, ``typestore``, ``start_time``, ``duration``) so the replay reads it
like any bag. A complete bag never comes here: it is read by rosbags, unchanged.

How each format is read forward:

* **mcap**: records with the ``mcap`` package's ``StreamReader`` (no summary or index needed);
  complete chunks split with its ``breakup_chunk`` (CRC checked); the chunk the file ends in is
  decompressed as far as its bytes go (none, zstd, lz4) and its complete records kept.
* **ROS 1** (bag format 2.0): a forward walk of the records (bag header, chunk, connection,
  message data; chunks none, bz2 or lz4 as rosbags decompresses them); the chunk the file ends in
  is kept up to its last complete record where its compression allows (none, lz4).
* **sqlite3**: rows of the ``messages`` table in insertion order until SQLite finds a page
  missing (``database disk image is malformed``).

Messages come out in log-time order, ties in file order: the order rosbags gives the complete bag,
so the first N messages of a cut bag are the first N of the whole one.
"""

from __future__ import annotations

import bz2
import sqlite3
import struct
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any

from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag1,
    ConnectionExtRosbag2,
    MessageDefinition,
    MessageDefinitionFormat,
)

from cf_estimator.bag.types import BagError, one_line, typestore

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROS1_MAGIC = b"#ROSBAG V2.0\n"
SQLITE_MAGIC = b"SQLite format 3\x00"

#: ROS 1 record op codes
_OP_MSG_DATA, _OP_BAG_HEADER, _OP_CHUNK, _OP_CONNECTION = 0x02, 0x03, 0x05, 0x07
_U32 = struct.Struct("<I")


@dataclass
class _Raw:
    """One message as read: connection id, log time [ns], serialized bytes."""

    cid: int
    log_ns: int
    data: bytes


@dataclass
class _Scan:
    """What one forward pass found."""

    conns: dict[int, Connection] = field(default_factory=dict)  #: by the file's own id
    readable_end: int = 0  #: bytes of the file read as complete records [bytes]
    reached_end: bool = False  #: the walk found the file's end in order (nothing lost)


def _ros1_truncated(path: Path) -> str | None:
    """"ros1" when ``path`` is a ROS 1 bag without a usable index (never closed, or cut before
    or inside its index), "header" when cut inside its header, else None."""
    size = path.stat().st_size
    with path.open("rb") as f:
        head = f.read(len(ROS1_MAGIC) + 4096 + 8)
        if not head or not head.startswith(ROS1_MAGIC[:min(len(head), len(ROS1_MAGIC))]):
            return None
        try:
            fields, _data, _end = _ros1_record(head, len(ROS1_MAGIC))
        except _Short:
            return "header"
        except ValueError:
            return None
        if fields.get("op") != bytes([_OP_BAG_HEADER]) or "index_pos" not in fields:
            return None
        index_pos = struct.unpack("<Q", fields["index_pos"])[0]
        if index_pos == 0 or index_pos >= size:
            return "ros1"
        f.seek(index_pos)
        tail = f.read()
    pos = 0
    while pos < len(tail):  # the index records: cut inside them is truncated too
        try:
            _f, _d, pos = _ros1_record(tail, pos)
        except _Short:
            return "ros1"
        except ValueError:
            return None
    return None


def _mcap_files(path: Path) -> list[Path]:
    if path.is_file():
        return [path] if path.suffix == ".mcap" else []
    return sorted(path.glob("*.mcap"), key=_storage_order)


def _storage_order(p: Path) -> tuple[int, str]:
    """rosbag2's split files ``name_0.mcap``, ``name_1.mcap``... in their numeric order."""
    tail = p.stem.rsplit("_", 1)[-1]
    return (int(tail) if tail.isdigit() else -1, p.name)


def _mcap_truncated(path: Path) -> str | None:
    """"mcap" when the last mcap file of ``path`` lacks its closing magic, "header" when it is
    shorter than the mcap header, else None."""
    files = _mcap_files(path)
    if not files:
        return None
    last = files[-1]
    size = last.stat().st_size
    with last.open("rb") as f:
        head = f.read(len(MCAP_MAGIC) + 9)
        if not MCAP_MAGIC.startswith(head[:len(MCAP_MAGIC)]) or not head:
            return None
        if size < len(MCAP_MAGIC) + 9:
            return "header"
        header_len = struct.unpack_from("<Q", head, len(MCAP_MAGIC) + 1)[0]
        if size < len(MCAP_MAGIC) + 9 + header_len:
            return "header"
        f.seek(max(0, size - len(MCAP_MAGIC)))
        return None if f.read() == MCAP_MAGIC else "mcap"


def _sqlite_truncated(path: Path) -> str | None:
    """"sqlite3" when a ``.db3`` file of bag directory ``path`` is shorter than its own header
    says (page size × page count), "header" when shorter than that header, else None."""
    if not path.is_dir():
        return None
    for db in sorted(path.glob("*.db3"), key=_storage_order):
        size = db.stat().st_size
        with db.open("rb") as f:
            head = f.read(100)
        if not SQLITE_MAGIC.startswith(head[:len(SQLITE_MAGIC)]):
            continue
        if len(head) < 100:
            return "header"
        page = struct.unpack_from(">H", head, 16)[0]
        page = 65536 if page == 1 else page
        pages = struct.unpack_from(">I", head, 28)[0]
        valid = head[92:96] == head[24:28] and pages > 0
        if size < page or (valid and size < page * pages) or size % page:
            return "sqlite3"
    return None


def truncation(path: Path) -> str | None:
    """The kind of truncated bag ``path`` is — ``"ros1"``, ``"mcap"``, ``"sqlite3"`` — or
    ``"header"`` when it ends inside its header (nothing readable), None when it is not a
    truncated bag (complete, or not a bag at all)."""
    try:
        if path.is_file() and path.suffix == ".bag":
            return _ros1_truncated(path)
        if path.suffix == ".mcap" or (path.is_dir() and any(path.glob("*.mcap"))):
            return _mcap_truncated(path)
        return _sqlite_truncated(path)
    except OSError:
        return None


# -- ROS 1 ------------------------------------------------------------------------------------


class _Short(Exception):
    """A record runs past the end of the bytes at hand."""


def _ros1_record(buf: bytes, pos: int) -> tuple[dict[str, bytes], bytes, int]:
    """The ROS 1 record at ``pos`` of ``buf``: header fields, data, the offset after it.
    :class:`_Short` when it runs past ``buf``, ValueError when malformed."""
    if pos + 4 > len(buf):
        raise _Short
    hlen = _U32.unpack_from(buf, pos)[0]
    hend = pos + 4 + hlen
    if hend + 4 > len(buf):
        raise _Short
    fields: dict[str, bytes] = {}
    p = pos + 4
    while p < hend:
        flen = _U32.unpack_from(buf, p)[0]
        if p + 4 + flen > hend:
            raise ValueError("header field runs past its header")
        name, sep, value = buf[p + 4:p + 4 + flen].partition(b"=")
        if not sep:
            raise ValueError("header field without '='")
        fields[name.decode("ascii", "replace")] = value
        p += 4 + flen
    dlen = _U32.unpack_from(buf, hend)[0]
    end = hend + 4 + dlen
    if end > len(buf):
        raise _Short
    return fields, buf[hend + 4:end], end


def _ros1_connection(fields: dict[str, bytes], data: bytes, owner: object) -> Connection:
    """A connection record as rosbags' ROS 1 reader makes it (type names in ROS 2 style)."""
    from rosbags.rosbag1.reader import normalize
    from rosbags.typesys.msg import normalize_msgtype

    inner, p = {}, 0
    while p + 4 <= len(data):
        flen = _U32.unpack_from(data, p)[0]
        name, _, value = data[p + 4:p + 4 + flen].partition(b"=")
        inner[name.decode("ascii", "replace")] = value.decode("utf-8", "replace")
        p += 4 + flen
    latching = inner.get("latching")
    return Connection(
        _U32.unpack(fields["conn"])[0], normalize(fields["topic"].decode()),
        normalize_msgtype(inner["type"]),
        MessageDefinition(MessageDefinitionFormat.MSG, inner.get("message_definition", "")),
        inner.get("md5sum", ""), 0,
        ConnectionExtRosbag1(inner.get("callerid"), int(latching) if latching else None), owner)


def _ros1_record_items(fields: dict[str, bytes], data: bytes, scan: _Scan, owner: object,
                       chunks: bool) -> Iterator[_Raw]:
    """What one complete record holds: a connection (kept in ``scan``), a message, or (when
    ``chunks``: a record of the file, not of a chunk) the records of a chunk."""
    op = fields.get("op", b"\x00")[0]
    if op == _OP_CONNECTION:
        c = _ros1_connection(fields, data, owner)
        scan.conns.setdefault(c.id, c)
    elif op == _OP_MSG_DATA:
        sec, nsec = struct.unpack("<II", fields["time"])
        yield _Raw(_U32.unpack(fields["conn"])[0], sec * 1_000_000_000 + nsec, data)
    elif op == _OP_CHUNK and chunks:
        yield from _ros1_chunk(fields, data, scan, owner)


def _ros1_records(buf: bytes, scan: _Scan, owner: object, base: int | None,
                  ) -> Iterator[_Raw]:
    """The connection and message records of ``buf`` (a chunk's records, or the file after its
    header when ``base`` is the offset of ``buf`` in the file); complete records only."""
    pos = 0
    while pos < len(buf):
        try:
            fields, data, end = _ros1_record(buf, pos)
        except (_Short, ValueError, struct.error):
            if base is None:
                return
            raise
        yield from _ros1_record_items(fields, data, scan, owner, chunks=base is not None)
        pos = end
        if base is not None:
            scan.readable_end = base + end


def _ros1_chunk(fields: dict[str, bytes], data: bytes, scan: _Scan, owner: object,
                partial: bool = False) -> Iterator[_Raw]:
    from lz4.frame import LZ4FrameDecompressor
    from lz4.frame import decompress as lz4_decompress

    comp = fields.get("compression", b"none").decode()
    if comp == "none":
        records = data
    elif comp == "bz2":
        records = bz2.decompress(data) if not partial else bz2.BZ2Decompressor().decompress(data)
    elif comp == "lz4":
        records = lz4_decompress(data) if not partial else LZ4FrameDecompressor().decompress(data)
    else:
        raise ValueError(f"unknown chunk compression {comp!r}")
    yield from _ros1_records(records, scan, owner, None)


def _scan_ros1(path: Path, owner: object, scan: _Scan) -> Iterator[_Raw]:
    data = path.read_bytes()
    start = len(ROS1_MAGIC)
    _f, _d, first = _ros1_record(data, start)  # the bag header (checked by truncation())
    scan.readable_end = first
    body = data[first:]
    pos = 0
    while pos < len(body):
        try:
            fields, rec, end = _ros1_record(body, pos)
        except (_Short, ValueError, struct.error):
            yield from _ros1_tail(body[pos:], scan, owner)
            return
        yield from _ros1_record_items(fields, rec, scan, owner, chunks=True)
        pos = end
        scan.readable_end = first + end
    scan.reached_end = True


def _ros1_tail(buf: bytes, scan: _Scan, owner: object) -> Iterator[_Raw]:
    """The complete records of the chunk the file ends in (none or lz4 compression)."""
    try:
        if len(buf) < 4:
            return
        hlen = _U32.unpack_from(buf, 0)[0]
        if 4 + hlen + 4 > len(buf):
            return
        fields, _d, _e = _ros1_record(buf[:4 + hlen] + b"\0\0\0\0", 0)
        if fields.get("op", b"\x00")[0] != _OP_CHUNK:
            return
        yield from _ros1_chunk(fields, buf[4 + hlen + 4:], scan, owner, partial=True)
    except Exception:  # noqa: BLE001,S110 - a tail that does not decode holds nothing usable
        return


# -- mcap -------------------------------------------------------------------------------------


def _mcap_connection(channel: Any, schema: Any, owner: object) -> Connection:
    fmt = (MessageDefinitionFormat.IDL if schema is not None and schema.encoding == "ros2idl"
           else MessageDefinitionFormat.MSG)
    msgdef = (MessageDefinition(fmt, schema.data.decode()) if schema is not None and schema.data
              else MessageDefinition(MessageDefinitionFormat.NONE, ""))
    return Connection(channel.id, channel.topic, schema.name if schema is not None else "",
                      msgdef, "", 0, ConnectionExtRosbag2(channel.message_encoding, []), owner)


def _mcap_records(records: list[Any], scan: _Scan, schemas: dict[int, Any], owner: object
                  ) -> Iterator[_Raw]:
    from mcap.records import Channel, Message, Schema

    for rec in records:
        if isinstance(rec, Schema):
            schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            scan.conns.setdefault(rec.id, _mcap_connection(rec, schemas.get(rec.schema_id),
                                                           owner))
        elif isinstance(rec, Message):
            yield _Raw(rec.channel_id, int(rec.log_time), bytes(rec.data))


def _scan_mcap_file(path: Path, owner: object, scan: _Scan, schemas: dict[int, Any]
                    ) -> Iterator[_Raw]:
    from mcap.exceptions import McapError
    from mcap.records import Chunk, DataEnd, Footer
    from mcap.stream_reader import StreamReader, breakup_chunk

    with path.open("rb") as f:
        it = iter(StreamReader(f, emit_chunks=True).records)
        end = len(MCAP_MAGIC)
        while True:
            try:
                rec = next(it)
            except StopIteration:
                scan.reached_end = True
                scan.readable_end = f.tell()
                return
            except (McapError, EOFError, ValueError, struct.error):
                break
            end = f.tell()
            scan.readable_end = end
            if isinstance(rec, Chunk):
                yield from _mcap_records(breakup_chunk(rec, validate_crc=True), scan, schemas,
                                         owner)
            elif isinstance(rec, DataEnd | Footer):
                scan.reached_end = True
                return
            else:
                yield from _mcap_records([rec], scan, schemas, owner)
        f.seek(end)
        tail = f.read()
    yield from _mcap_records(_mcap_tail(tail), scan, schemas, owner)


def _mcap_tail(buf: bytes) -> list[Any]:
    """The complete records of the chunk the file ends in, decompressed as far as it goes."""
    from mcap.exceptions import McapError
    from mcap.stream_reader import StreamReader

    try:
        if len(buf) < 9 or buf[0] != 0x06:
            return []
        p = 9 + 8 + 8 + 8 + 4
        clen = _U32.unpack_from(buf, p)[0]
        comp = buf[p + 4:p + 4 + clen].decode()
        p += 4 + clen + 8
        data = buf[p:]
        if comp == "zstd":
            import zstandard

            data = zstandard.ZstdDecompressor().decompressobj().decompress(data)
        elif comp == "lz4":
            from lz4.frame import LZ4FrameDecompressor

            data = LZ4FrameDecompressor().decompress(data)
        elif comp:
            return []
        out: list[Any] = []
        try:
            for rec in StreamReader(BytesIO(data), skip_magic=True).records:
                out.append(rec)
        except (McapError, EOFError, ValueError, struct.error):
            pass
        return out
    except Exception:  # noqa: BLE001 - a tail that does not decode holds nothing usable
        return []


def _scan_mcap(path: Path, owner: object, scan: _Scan) -> Iterator[_Raw]:
    schemas: dict[int, Any] = {}
    for f in _mcap_files(path):
        scan.reached_end = False
        yield from _scan_mcap_file(f, owner, scan, schemas)


# -- sqlite3 ----------------------------------------------------------------------------------


def _scan_sqlite(path: Path, owner: object, scan: _Scan) -> Iterator[_Raw]:
    for db_path in sorted(path.glob("*.db3"), key=_storage_order):
        db = sqlite3.connect(f"file:{db_path}?mode=ro&immutable=1", uri=True)
        try:
            # SQLite refuses a file shorter than its header's page count unless told to read
            # what is there (the connection only: the file is opened read-only)
            db.execute("PRAGMA writable_schema=ON")
            defs: dict[str, MessageDefinition] = {}
            try:
                fmt = {"ros2msg": MessageDefinitionFormat.MSG,
                       "ros2idl": MessageDefinitionFormat.IDL}
                for typ, enc, text in db.execute(
                        "SELECT topic_type, encoding, encoded_message_definition "
                        "FROM message_definitions"):
                    if enc in fmt and text:
                        defs[typ] = MessageDefinition(fmt[enc], text)
            except sqlite3.DatabaseError:
                pass
            for tid, name, typ, ser in db.execute(
                    "SELECT id, name, type, serialization_format FROM topics"):
                scan.conns.setdefault(tid, Connection(
                    tid, name, typ, defs.get(typ, MessageDefinition(
                        MessageDefinitionFormat.NONE, "")), "", 0,
                    ConnectionExtRosbag2(ser, []), owner))
            cur = db.execute(
                "SELECT rowid, topic_id, timestamp, data FROM messages NOT INDEXED")
            last = 0
            while True:
                try:
                    row = cur.fetchone()
                except sqlite3.DatabaseError:  # a page beyond the end of the file
                    return
                if row is None:
                    break
                # a page past the end reads as zeros: rows without values, rowid 0; the
                # readable part ends at the first of them
                if None in row or row[0] <= last:
                    return
                last = row[0]
                yield _Raw(int(row[1]), int(row[2]), bytes(row[3]))
        finally:
            db.close()


# -- the reader -------------------------------------------------------------------------------


_SCANNERS = {"ros1": _scan_ros1, "mcap": _scan_mcap, "sqlite3": _scan_sqlite}
KIND_NAMES = {"ros1": "ROS 1 bag", "mcap": "mcap bag", "sqlite3": "sqlite3 bag"}


class SalvageReader:
    """A truncated bag read forward: the part of rosbags' ``AnyReader`` that
    :class:`cf_estimator.bag.reader.InputBag` uses. Open with :func:`open_truncated`."""

    def __init__(self, path: Path, kind: str) -> None:
        self.path = path
        self.kind = kind
        self.is2 = kind != "ros1"
        scan = _Scan()
        counts: dict[int, int] = {}
        self.first_ns: int | None = None
        self.last_ns: int | None = None
        self.n_messages = 0
        for m in _SCANNERS[kind](path, self, scan):
            counts[m.cid] = counts.get(m.cid, 0) + 1
            self.first_ns = m.log_ns if self.first_ns is None else min(self.first_ns, m.log_ns)
            self.last_ns = m.log_ns if self.last_ns is None else max(self.last_ns, m.log_ns)
            self.n_messages += 1
        self.readable_end = scan.readable_end  #: bytes read as complete records [bytes]
        self.connections = [c._replace(msgcount=counts.get(c.id, 0))
                            for c in scan.conns.values()]
        self.typestore = _typestore_for(self.connections, self.is2)

    @property
    def start_time(self) -> int:
        """First log time [ns]."""
        return self.first_ns or 0

    @property
    def duration(self) -> int:
        """Last minus first log time plus 1 ns (rosbags' convention) [ns]."""
        return (self.last_ns - self.first_ns + 1) if self.first_ns is not None \
            and self.last_ns is not None else 0

    def messages(self, connections: Collection[Connection] = ()
                 ) -> Iterator[tuple[Connection, int, bytes]]:
        """(connection, log time [ns], raw bytes) of ``connections`` (all when empty) in
        log-time order, ties in file order — the order rosbags gives a complete bag."""
        by_id = {c.id: c for c in (connections or self.connections)}
        kept = [m for m in _SCANNERS[self.kind](self.path, self, _Scan()) if m.cid in by_id]
        kept.sort(key=lambda m: m.log_ns)  # stable
        for m in kept:
            yield by_id[m.cid], m.log_ns, m.data

    def deserialize(self, rawdata: bytes, typ: str) -> object:
        """One message decoded by rosbags (CDR for ROS 2, ROS 1 serialization for ROS 1)."""
        if self.is2:
            return self.typestore.deserialize_cdr(rawdata, typ)
        return self.typestore.deserialize_ros1(rawdata, typ)

    def close(self) -> None:
        """Nothing held open between reads."""


def _typestore_for(connections: list[Connection], is2: bool) -> Any:
    """The types as rosbags' ``AnyReader`` registers them: the bag's own definitions, or the
    Jazzy typestore when it carries none."""
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    typs: dict[str, Any] = {}
    defined = [c for c in connections if c.msgdef.format != MessageDefinitionFormat.NONE]
    for c in defined:
        if c.msgdef.format == MessageDefinitionFormat.MSG:
            typs.update(get_types_from_msg(c.msgdef.data, c.msgtype))
        else:
            sep = "=" * 80 + "\n"
            if c.msgdef.data.startswith(f"{sep}IDL: "):
                for part in c.msgdef.data.split(sep)[1:]:
                    typs.update(get_types_from_idl(part.split("\n", 1)[1]))
            else:
                typs.update(get_types_from_idl(c.msgdef.data))
    if not defined:
        typs.update(typestore().fielddefs)
    store = get_typestore(Stores.EMPTY)
    store.register(typs)
    return store


def open_truncated(path: Path, kind: str) -> tuple[SalvageReader, str]:
    """Read truncated bag ``path`` (``kind`` from :func:`truncation`) forward; the reader and
    the one-line note saying how much was read and where it stopped. :class:`BagError` when it
    ends inside its header or before its first message (nothing to replay)."""
    size = _size(path)
    name = KIND_NAMES.get(kind, "bag")
    if kind == "header":
        raise BagError(f"{path}: truncated bag: the file ends inside its header ({size} "
                       "bytes): nothing is readable")
    try:
        reader = SalvageReader(path, kind)
    except BagError:
        raise
    except Exception as exc:  # noqa: BLE001 - whatever a damaged file makes a parser raise
        raise BagError(f"{path}: truncated {name}, and not readable: {one_line(exc)}") from exc
    if reader.n_messages == 0:
        raise BagError(f"{path}: truncated {name}: the file ends before its first message "
                       f"({size} bytes): nothing to replay")
    span = reader.duration * 1e-9
    note = (f"{path.name}: truncated {name} ({size} bytes, its end missing): read "
            f"{reader.n_messages} messages up to t={span:.2f} s of the recording; the rest is "
            "lost")
    return reader, note


def _size(path: Path) -> int:
    """Bytes of a bag file, or of the storage files of a bag directory."""
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.iterdir()
               if p.suffix in (".mcap", ".db3") and p.is_file())
