"""Bulk decoding of ``sensor_msgs/Imu`` and ``MagneticField``, and fast encoding of the outputs.

Decoding: a message's bytes are a header (stamp, ``frame_id``) followed by a fixed block of
float64 — 37 for an Imu (orientation 4, its covariance 9, angular velocity 3, covariance 9,
linear acceleration 3, covariance 9), 12 for a MagneticField (field 3, covariance 9). Messages
whose ``frame_id`` has the same length share one layout: they are stacked into a 2-D byte array
and read with NumPy views, all at once. Both serializations rosbags hands out are handled:
ROS 2 CDR little-endian (4-byte encapsulation header, string length counting its NUL, doubles
aligned to 8) and ROS 1 (``seq`` first, no NUL, no alignment). Anything else — big-endian CDR,
a length that does not match the layout, a ``frame_id`` that is not UTF-8 — is left to rosbags'
own deserializer, so unusual messages decode exactly as before.

The decoded messages are light objects with the sensor_msgs field names (what the pipeline
reads), holding the same values as rosbags' message objects: the pipeline's results are the
same, bit for bit.

Encoding: :func:`imu_cdr` / :func:`vector3_stamped_cdr` build the Jazzy CDR bytes of the
replay's ``/imu/data`` and ``/imu/rpy`` outputs with one ``struct`` call each — the bytes rosbags'
``serialize_cdr`` gives for the same message object (tested).
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from cf_estimator.bag.types import IMU_TYPE
from cf_estimator.pipeline import columns as col
from cf_estimator.pipeline.columns import IMU_DOUBLES, MAG_DOUBLES

_CDR_LE = b"\x00\x01\x00\x00"
_ZERO9 = np.zeros(9)


class Stamp:
    __slots__ = ("sec", "nanosec")

    def __init__(self, sec: int, nanosec: int) -> None:
        self.sec, self.nanosec = sec, nanosec


class Header:
    __slots__ = ("stamp", "frame_id")

    def __init__(self, stamp: Stamp, frame_id: str) -> None:
        self.stamp, self.frame_id = stamp, frame_id


class Vector:
    """geometry_msgs Vector3 / Quaternion fields (``w`` only for a quaternion)."""

    __slots__ = ("x", "y", "z", "w")

    def __init__(self, x: float, y: float, z: float, w: float = 0.0) -> None:
        self.x, self.y, self.z, self.w = x, y, z, w


class ImuView:
    """A decoded sensor_msgs/Imu: the fields the pipeline and the replay read [SI units]."""

    __slots__ = ("header", "orientation", "orientation_covariance", "angular_velocity",
                 "angular_velocity_covariance", "linear_acceleration",
                 "linear_acceleration_covariance")


class MagView:
    """A decoded sensor_msgs/MagneticField [T]."""

    __slots__ = ("header", "magnetic_field", "magnetic_field_covariance")


def _layout(raw: bytes, ros2: bool) -> tuple[int, int] | None:
    """(end of the frame id bytes, offset of the first float64) or None when unusual; the
    frame id starts at byte 16 in both serializations."""
    if len(raw) < 16 or (ros2 and raw[:4] != _CDR_LE):
        return None
    n = int.from_bytes(raw[12:16], "little")  # ROS 2: includes the NUL
    if not ros2:
        return 16 + n, 16 + n
    if n < 1:
        return None
    end = 16 + n
    return end - 1, end + (-(end - 4) % 8)  # doubles aligned to 8 after the encapsulation


class Block:
    """Messages of one type decoded into arrays (row k = message k of the raws given).

    ``plain[k]``: row k was decoded from the plain layout (``values``, ``sec``, ``nsec``,
    ``frame`` hold it); otherwise ``objects[k]`` is rosbags' message. :meth:`message` gives
    either as an object with the sensor_msgs field names.
    """

    def __init__(self, n: int, imu: bool) -> None:
        self.imu = imu
        self.n = n
        d = IMU_DOUBLES if imu else MAG_DOUBLES
        self.values = np.zeros((n, d))
        self._sec: list[int] | None = [0] * n
        self._nsec: list[int] | None = [0] * n
        self.frame: list[str | None] = [None] * n
        self.plain: list[bool] = [False] * n
        self.objects: list[Any] = [None] * n
        self._arrays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def sec(self) -> list[int]:
        """Header stamp seconds per row (a list; made from :meth:`arrays` when first asked
        after the bulk decoder, which keeps them as arrays)."""
        if self._sec is None:
            self._sec = self.arrays()[0].tolist()
        return self._sec

    @sec.setter
    def sec(self, values: list[int]) -> None:
        self._lists()
        self._sec, self._arrays = values, None

    def _lists(self) -> None:
        """Both stamp lists made (before the arrays they may come from are dropped)."""
        if self._sec is None or self._nsec is None:
            sec, nsec, _plain = self.arrays()
            self._sec, self._nsec = sec.tolist(), nsec.tolist()

    @property
    def nsec(self) -> list[int]:
        """Header stamp nanoseconds per row (as :attr:`sec`)."""
        if self._nsec is None:
            self._nsec = self.arrays()[1].tolist()
        return self._nsec

    @nsec.setter
    def nsec(self, values: list[int]) -> None:
        self._lists()
        self._nsec, self._arrays = values, None

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``sec``, ``nsec`` (int64) and ``plain`` (bool) as arrays, made once: call it when
        the block is filled (the bulk decoder gives them as it decodes)."""
        if self._arrays is None:
            self._arrays = (np.asarray(self.sec, dtype=np.int64),
                            np.asarray(self.nsec, dtype=np.int64),
                            np.asarray(self.plain, dtype=bool))
        return self._arrays

    def message(self, k: int) -> Any:
        """Message k as an object (a light view, or rosbags' message for an unusual one)."""
        if not self.plain[k]:
            return self.objects[k]
        v = self.values[k].tolist()
        header = Header(Stamp(self.sec[k], self.nsec[k]), self.frame[k] or "")
        if self.imu:
            m = ImuView()
            m.header = header
            m.orientation = Vector(*v[col.ORIENTATION])
            m.orientation_covariance = self.values[k, col.ORIENTATION_COVARIANCE]
            m.angular_velocity = Vector(*v[col.ANGULAR_VELOCITY])
            m.angular_velocity_covariance = self.values[k, col.ANGULAR_VELOCITY_COVARIANCE]
            m.linear_acceleration = Vector(*v[col.LINEAR_ACCELERATION])
            m.linear_acceleration_covariance = self.values[k, col.LINEAR_ACCELERATION_COVARIANCE]
            return m
        m = MagView()
        m.header = header
        m.magnetic_field = Vector(*v[col.MAGNETIC_FIELD])
        m.magnetic_field_covariance = self.values[k, col.MAGNETIC_FIELD_COVARIANCE]
        return m


def decode_block(raws: Sequence[bytes], msgtype: str, ros2: bool,
                 fallback: Callable[[bytes, str], Any]) -> Block:
    """Decode ``raws`` (one type) into a :class:`Block`: NumPy views where the layout is the
    plain one, ``fallback(raw, msgtype)`` (rosbags' deserializer) for the others."""
    imu = msgtype == IMU_TYPE
    n_doubles = IMU_DOUBLES if imu else MAG_DOUBLES
    block = Block(len(raws), imu)
    if _decode_uniform(block, raws, ros2, n_doubles):
        return block
    groups: dict[tuple[int, int, int], list[int]] = {}
    for i, raw in enumerate(raws):
        lay = _layout(raw, ros2)
        if lay is None or len(raw) != lay[1] + 8 * n_doubles:
            block.objects[i] = fallback(raw, msgtype)
            continue
        groups.setdefault((len(raw), *lay), []).append(i)
    for (size, frame_end, body), idx in groups.items():
        buf = np.frombuffer(b"".join(raws[i] for i in idx), dtype=np.uint8).reshape(-1, size)
        stamps = np.ascontiguousarray(buf[:, 4:12]).view("<u4").reshape(-1, 2)
        # ROS 2 builtin_interfaces/Time.sec is int32; ROS 1 time.secs is uint32
        secs = np.ascontiguousarray(stamps[:, 0]).view("<i4") if ros2 else stamps[:, 0]
        values = np.ascontiguousarray(buf[:, body:]).view("<f8").astype(np.float64)
        frames = buf[:, 16:frame_end]
        # one frame id string per distinct byte pattern (usually one for the whole bag)
        if frames.shape[1] == 0:
            uniq, inverse = np.zeros((1, 0), dtype=np.uint8), np.zeros(len(idx), dtype=int)
        elif bool(np.all(frames == frames[0])):
            uniq, inverse = frames[:1], np.zeros(len(idx), dtype=int)
        else:
            uniq, inverse = np.unique(frames, axis=0, return_inverse=True)
        texts = [_utf8(bytes(u)) for u in uniq]  # None: not UTF-8, left to rosbags
        nul_ok = (buf[:, frame_end] == 0).tolist() if ros2 else [True] * len(idx)
        inverse = inverse.reshape(-1).tolist()
        sec_list, nsec_list = secs.tolist(), stamps[:, 1].tolist()
        rows = np.asarray(idx)
        block.values[rows] = values
        for k, i in enumerate(idx):
            frame = texts[inverse[k]]
            if frame is None or not nul_ok[k]:  # the NUL terminator must be there too
                block.objects[i] = fallback(raws[i], msgtype)
                continue
            block.sec[i] = sec_list[k]
            block.nsec[i] = nsec_list[k]
            block.frame[i] = frame
            block.plain[i] = True
    return block


def decode_rows(rows: np.ndarray, msgtype: str, ros2: bool) -> Block | None:
    """The messages given as the rows of an (n, size) uint8 array (one serialized message per
    row, all of one length) as a :class:`Block`, when every one has the plain layout and one
    frame id (what :func:`decode_block` gives them); None otherwise (use decode_block)."""
    imu = msgtype == IMU_TYPE
    block = Block(int(rows.shape[0]), imu)
    if rows.shape[0] and _decode_uniform_rows(block, rows, ros2,
                                              IMU_DOUBLES if imu else MAG_DOUBLES):
        return block
    return None


def _decode_uniform(block: Block, raws: Sequence[bytes], ros2: bool, n_doubles: int) -> bool:
    """The common case at NumPy speed: every message has the plain layout, one size and one
    frame id. False (nothing written) when that is not so."""
    n = len(raws)
    if n == 0:
        return False
    size = len(raws[0])
    buf = np.frombuffer(b"".join(raws), dtype=np.uint8)
    if buf.shape[0] != n * size:
        return False  # sizes differ
    return _decode_uniform_rows(block, buf.reshape(n, size), ros2, n_doubles)


def _decode_uniform_rows(block: Block, buf: np.ndarray, ros2: bool, n_doubles: int) -> bool:
    """:func:`_decode_uniform` of messages stacked as the rows of ``buf`` (n, size)."""
    n, size = buf.shape
    lay = _layout(buf[0].tobytes(), ros2)
    if lay is None or size != lay[1] + 8 * n_doubles:
        return False
    frame_end, body = lay
    # same header prefix after the stamp (encapsulation, frame id length, frame id, its NUL)
    ref = buf[0]
    if not (bool(np.all(buf[:, 12:body] == ref[12:body])) and (
            not ros2 or bool(np.all(buf[:, 0:4] == ref[0:4])))):
        return False
    if ros2 and ref[frame_end] != 0:
        return False
    frame = _utf8(bytes(ref[16:frame_end]))
    if frame is None:
        return False
    stamps = np.ascontiguousarray(buf[:, 4:12]).view("<u4").reshape(n, 2)
    secs = np.ascontiguousarray(stamps[:, 0]).view("<i4") if ros2 else stamps[:, 0]
    block.values = np.ascontiguousarray(buf[:, body:]).view("<f8").astype(np.float64,
                                                                          copy=False)
    block.frame = [frame] * n
    block.plain = [True] * n
    # the stamps as arrays; the lists of Block.sec/nsec are made from them when asked
    block._arrays = (secs.astype(np.int64), stamps[:, 1].astype(np.int64),
                     np.ones(n, dtype=bool))
    block._sec = block._nsec = None
    return True


def decode(raws: Sequence[bytes], msgtype: str, ros2: bool,
           fallback: Callable[[bytes, str], Any]) -> list[Any]:
    """Decode every message of ``raws`` (one type) into objects: light views where the layout
    is the plain one, ``fallback(raw, msgtype)`` (rosbags' deserializer) for the others."""
    block = decode_block(raws, msgtype, ros2, fallback)
    return [block.message(k) for k in range(block.n)]


def _utf8(b: bytes) -> str | None:
    try:
        return b.decode("utf-8")
    except UnicodeDecodeError:
        return None


# -- encoding --------------------------------------------------------------------------------
_structs: dict[tuple[str, int], struct.Struct] = {}


def _header_struct(kind: str, frame: bytes, n_doubles: int) -> struct.Struct:
    key = (kind, len(frame))
    s = _structs.get(key)
    if s is None:
        end = 16 + len(frame) + 1
        pad = -(end - 4) % 8
        s = struct.Struct(f"<4siII{len(frame) + 1}s{pad}x{n_doubles}d")
        _structs[key] = s
    return s


def _cov(c: Any) -> tuple[float, ...]:
    if type(c) is tuple and len(c) == 9:  # the pipeline's covariances: tuples of floats
        return c
    if c is None:
        return (0.0,) * 9
    t = tuple(float(x) for x in c)
    if len(t) != 9:
        raise ValueError("a covariance has 9 elements")
    return t


def imu_cdr(out: Any) -> bytes:
    """The Jazzy CDR bytes of :func:`cf_estimator.bag.io.imu_from_output` for ``out``."""
    return imu_cdr_fields(out.stamp_sec, out.stamp_nanosec, out.frame_id, out.orientation_xyzw,
                          out.orientation_covariance, out.angular_velocity,
                          out.angular_velocity_covariance, out.linear_acceleration,
                          out.linear_acceleration_covariance)


def imu_cdr_fields(sec: int, nanosec: int, frame_id: str, xyzw: Sequence[float],
                   orientation_cov: Any, g: Sequence[float], g_cov: Any, a: Sequence[float],
                   a_cov: Any) -> bytes:
    """The Jazzy CDR bytes of a sensor_msgs/Imu from its fields (quaternion in ROS order)."""
    frame = str(frame_id).encode("utf-8")
    s = _header_struct("imu", frame, IMU_DOUBLES)
    ox, oy, oz, ow = xyzw
    return s.pack(_CDR_LE, int(sec), int(nanosec), len(frame) + 1, frame,
                  float(ox), float(oy), float(oz), float(ow), *_cov(orientation_cov),
                  float(g[0]), float(g[1]), float(g[2]), *_cov(g_cov),
                  float(a[0]), float(a[1]), float(a[2]), *_cov(a_cov))


def vector3_stamped_cdr(sec: int, nanosec: int, frame_id: str, v: Sequence[float]) -> bytes:
    """The Jazzy CDR bytes of a geometry_msgs/Vector3Stamped."""
    frame = str(frame_id).encode("utf-8")
    s = _header_struct("v3", frame, 3)
    return s.pack(_CDR_LE, int(sec), int(nanosec), len(frame) + 1, frame,
                  float(v[0]), float(v[1]), float(v[2]))


# -- bulk encoding -----------------------------------------------------------------------------
def _header_size(frame: bytes) -> int:
    end = 16 + len(frame) + 1
    return end + (-(end - 4) % 8)


def imu_cdr_size(frame_id: str) -> int:
    """Bytes of one :func:`imu_cdr_rows` row with this frame id."""
    return _header_size(str(frame_id).encode("utf-8")) + 8 * IMU_DOUBLES


def vector3_stamped_size(frame_id: str) -> int:
    """Bytes of one :func:`vector3_stamped_rows` row with this frame id."""
    return _header_size(str(frame_id).encode("utf-8")) + 8 * 3


def _header_rows(sec: np.ndarray, nsec: np.ndarray, frame: bytes, n_doubles: int,
                 out: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """(n, whole message) uint8 (``out`` if given) with the header filled in (encapsulation,
    stamp, frame id with NUL, padding to 8) and the ``n_doubles`` after it left to the caller,
    and the header's size."""
    n = sec.shape[0]
    size = _header_size(frame)
    if out is None:
        out = np.empty((n, size + 8 * n_doubles), dtype=np.uint8)
    elif out.shape != (n, size + 8 * n_doubles) or out.dtype != np.uint8:
        raise ValueError(f"out must be uint8 of shape {(n, size + 8 * n_doubles)}")
    head = out[:, :size]
    head[:] = _header_template(frame)  # all but the stamp, then the stamp
    head[:, 4:8] = sec.astype("<i4").view(np.uint8).reshape(n, 4)
    head[:, 8:12] = nsec.astype("<u4").view(np.uint8).reshape(n, 4)
    return out, size


@functools.lru_cache(maxsize=64)
def _header_template(frame: bytes) -> np.ndarray:
    """A header's bytes with a zero stamp: encapsulation, stamp, frame id length, frame id,
    NUL, padding to 8."""
    head = np.zeros(_header_size(frame), dtype=np.uint8)
    head[0:4] = np.frombuffer(_CDR_LE, dtype=np.uint8)
    head[12:16] = np.frombuffer(struct.pack("<I", len(frame) + 1), dtype=np.uint8)
    head[16:16 + len(frame)] = np.frombuffer(frame, dtype=np.uint8)
    head.flags.writeable = False
    return head


def imu_cdr_rows(sec: np.ndarray, nsec: np.ndarray, frame_id: str, q_xyzw: np.ndarray,
                 orientation_cov: Sequence[float], gyro: np.ndarray, gyro_cov: Sequence[float],
                 accel: np.ndarray, accel_cov: Sequence[float],
                 out: np.ndarray | None = None) -> np.ndarray:
    """(n, size) uint8: row k = :func:`imu_cdr_fields` of message k (one frame id for all);
    written into ``out`` when given (e.g. a payload view of ``writer.record_rows``)."""
    frame = str(frame_id).encode("utf-8")
    rows, head = _header_rows(sec, nsec, frame, IMU_DOUBLES, out)
    body = rows[:, head:].view("<f8")  # (n, IMU_DOUBLES), in place
    body[:, col.ORIENTATION] = q_xyzw
    body[:, col.ORIENTATION_COVARIANCE] = np.asarray(orientation_cov, dtype=np.float64)
    body[:, col.ANGULAR_VELOCITY] = gyro
    body[:, col.ANGULAR_VELOCITY_COVARIANCE] = np.asarray(gyro_cov, dtype=np.float64)
    body[:, col.LINEAR_ACCELERATION] = accel
    body[:, col.LINEAR_ACCELERATION_COVARIANCE] = np.asarray(accel_cov, dtype=np.float64)
    return rows


def vector3_stamped_rows(sec: np.ndarray, nsec: np.ndarray, frame_id: str, v: np.ndarray,
                         out: np.ndarray | None = None) -> np.ndarray:
    """(n, size) uint8: row k = :func:`vector3_stamped_cdr` of message k (into ``out`` when
    given)."""
    frame = str(frame_id).encode("utf-8")
    rows, head = _header_rows(sec, nsec, frame, 3, out)
    rows[:, head:].view("<f8")[:] = v
    return rows


_PAD4 = (b"", b"\x00", b"\x00\x00", b"\x00\x00\x00")
#: the length-prefixed, NUL-ended bytes of the strings seen (diagnostics repeat their keys and
#: most values from report to report), bounded
_STRINGS: dict[str, bytes] = {}
_STRINGS_MAX = 4096


def _encoded(text: str) -> bytes:
    """``text`` as a CDR string: length with the NUL, UTF-8 bytes, NUL (kept in _STRINGS)."""
    b = text.encode("utf-8")
    enc = struct.pack("<I", len(b) + 1) + b + b"\x00"
    if len(_STRINGS) < _STRINGS_MAX:
        _STRINGS[text] = enc
    return enc


def _cdr_string(out: bytearray, text: str) -> None:
    """A CDR string at the end of ``out`` (aligned to 4 from the encapsulation's end)."""
    out += _PAD4[-(len(out) - 4) % 4]
    out += _STRINGS.get(text) or _encoded(text)


def diagnostic_array_cdr(stamp_ns: int, reports: Sequence[Any]) -> bytes:
    """The Jazzy CDR bytes of :func:`cf_estimator.bag.messages.diagnostics_message` for the
    same arguments (what rosbags' ``serialize_cdr`` gives it: tested)."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    out = bytearray(_CDR_LE)
    out += struct.pack("<iI", sec, nanosec)
    _cdr_string(out, "")  # frame_id
    out += b"\x00" * (-(len(out) - 4) % 4)
    out += struct.pack("<I", len(reports))
    for r in reports:
        out += struct.pack("<B", int(r.level))
        for text in (str(r.name), str(r.message), str(r.hardware_id)):
            _cdr_string(out, text)
        values = list(r.values)
        out += b"\x00" * (-(len(out) - 4) % 4)
        out += struct.pack("<I", len(values))
        strings, pad = _STRINGS, _PAD4
        for k, v in values:  # _cdr_string of the key and the value, inlined
            for text in (str(k), str(v)):
                out += pad[-(len(out) - 4) % 4]
                out += strings.get(text) or _encoded(text)
    return bytes(out)
