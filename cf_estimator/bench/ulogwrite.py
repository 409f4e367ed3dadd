"""Write synthetic PX4 ulog files (ULog version 1): for the ulog tests and the replay benchmark.

The file is what PX4's logger writes, reduced to what a reader needs: the 16-byte header, the
flag bits, one format ("F") and one subscription ("A") per topic instance, and data ("D")
messages in time order. Topics and fields are PX4's (``sensor_combined``: gyro_rad,
accelerometer_m_s2, FRD, ``timestamp`` µs since boot, accelerometer_timestamp_relative;
``vehicle_magnetometer``: magnetometer_ga [Gauss]; ``vehicle_attitude``: q FRD → NED, w x y z).

:func:`static_tilt_log` writes a vehicle standing still rolled by ``roll_deg`` (gravity and a
north-pointing field in the body, a little white noise): its ``vehicle_attitude`` is the truth.
"""

from __future__ import annotations

import math
import os
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

_MAGIC = b"ULog\x01\x12\x35"
_TYPES = {"uint64_t": "<u8", "int32_t": "<i4", "float": "<f4", "uint8_t": "u1", "bool": "u1",
          "uint32_t": "<u4", "int8_t": "i1"}


@dataclass
class Topic:
    """One logged topic instance: ``fields`` are (type, name, count) in order (the first must
    be ``uint64_t timestamp``); ``data`` maps a field name to an (n,) or (n, count) array."""

    name: str
    fields: Sequence[tuple[str, str, int]]
    data: dict[str, np.ndarray]
    multi_id: int = 0
    msg_id: int = field(default=-1)

    def dtype(self) -> np.dtype:
        """The logged bytes: every field but the trailing padding (PX4's logger leaves it
        out; the format still names it)."""
        fields = list(self.fields)
        while fields and fields[-1][1].startswith("_padding"):
            fields.pop()
        return np.dtype([(n, _TYPES[t], (c,)) if c > 1 else (n, _TYPES[t])
                         for t, n, c in fields])

    def format_text(self) -> str:
        parts = [f"{t}[{c}] {n}" if c > 1 else f"{t} {n}" for t, n, c in self.fields]
        return f"{self.name}:" + "".join(p + ";" for p in parts)


def _message(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def _parameter(name: str, value: float | int) -> bytes:
    """A "P" message: the parameter's value at the log's start (PX4's float or int32_t)."""
    if isinstance(value, int):
        key, raw = f"int32_t {name}".encode(), struct.pack("<i", value)
    else:
        key, raw = f"float {name}".encode(), struct.pack("<f", value)
    return _message(b"P", bytes([len(key)]) + key + raw)


def write_ulog(path: str | os.PathLike[str], topics: Sequence[Topic], start_us: int = 0,
               parameters: Mapping[str, float | int] | None = None) -> Path:
    """Write ``topics`` into a ulog at ``path`` (data interleaved by timestamp), with the
    autopilot's ``parameters`` (name -> value; int → int32_t, float → float) at its start."""
    out = Path(path)
    chunks = [_MAGIC + b"\x01" + struct.pack("<Q", start_us),
              _message(b"B", bytes(16) + bytes(24))]
    formats: dict[str, str] = {}
    for t in topics:
        formats.setdefault(t.name, t.format_text())
    for text in formats.values():
        chunks.append(_message(b"F", text.encode()))
    key = b"char[4] ver_sw"
    chunks.append(_message(b"I", bytes([len(key)]) + key + b"synt"))
    chunks += [_parameter(k, v) for k, v in (parameters or {}).items()]
    rows, stamps, ids = [], [], []
    for i, t in enumerate(topics):
        t.msg_id = i
        chunks.append(_message(b"A", struct.pack("<BH", t.multi_id, i) + t.name.encode()))
        dt = t.dtype()
        n = len(t.data["timestamp"])
        rec = np.zeros(n, dtype=np.dtype([("size", "<u2"), ("type", "u1"), ("id", "<u2"),
                                          ("body", dt)]))
        rec["size"] = 2 + dt.itemsize
        rec["type"] = ord("D")
        rec["id"] = i
        for name in dt.names:
            if name in t.data:
                rec["body"][name] = t.data[name]
        rows.append(rec.view(np.uint8).reshape(n, -1))
        stamps.append(np.asarray(t.data["timestamp"], dtype=np.int64))
        ids.append(np.full(n, i))
    order = np.lexsort((np.concatenate(ids), np.concatenate(stamps)))
    which = np.concatenate(ids)[order]
    row = np.concatenate([np.arange(len(s)) for s in stamps])[order]
    body = b"".join(rows[k][r].tobytes() for k, r in zip(which.tolist(), row.tolist(),
                                                          strict=True))
    out.write_bytes(b"".join(chunks) + body)
    return out


SENSOR_COMBINED_FIELDS = (
    ("uint64_t", "timestamp", 1), ("float", "gyro_rad", 3), ("uint32_t", "gyro_integral_dt", 1),
    ("int32_t", "accelerometer_timestamp_relative", 1), ("float", "accelerometer_m_s2", 3),
    ("uint32_t", "accelerometer_integral_dt", 1), ("uint8_t", "accelerometer_clipping", 1),
    ("uint8_t", "_padding0", 3),
)
MAG_FIELDS = (("uint64_t", "timestamp", 1), ("uint64_t", "timestamp_sample", 1),
              ("uint32_t", "device_id", 1), ("float", "magnetometer_ga", 3),
              ("uint8_t", "calibration_count", 1), ("uint8_t", "_padding0", 3))
ATTITUDE_FIELDS = (("uint64_t", "timestamp", 1), ("uint64_t", "timestamp_sample", 1),
                   ("float", "q", 4), ("float", "delta_q_reset", 4),
                   ("uint8_t", "quat_reset_counter", 1), ("uint8_t", "_padding0", 7))


def static_tilt_log(path: str | os.PathLike[str], duration_s: float = 60.0,
                    rate_hz: float = 250.0, roll_deg: float = 10.0, *, mag_hz: float = 50.0,
                    with_imu: bool = True, mag_instances: int = 1, imu_from_s: float = 0.0,
                    imu_until_s: float | None = None, seed: int = 0,
                    boot_us: int = 5_000_000, mag_offset_ga: Sequence[float] = (0.0, 0.0, 0.0),
                    parameters: Mapping[str, float | int] | None = None) -> Path:
    """A vehicle at rest rolled by ``roll_deg`` (FRD, NED): sensor_combined at ``rate_hz``
    (from ``imu_from_s`` to ``imu_until_s`` only, the rest of the log without IMU),
    vehicle_magnetometer (``mag_instances`` instances, device ids 1000, 1001, …, the second
    reading a little off; each reads ``mag_offset_ga`` [Gauss, FRD] on top of the field: a
    hard-iron bias), vehicle_attitude at 50 Hz (the truth) over the whole ``duration_s``;
    ``parameters`` as the autopilot's (:func:`write_ulog`)."""
    rng = np.random.default_rng(seed)
    r = math.radians(roll_deg)
    g = 9.80665
    # specific force at rest, FRD, rolled by r about x: -g along the body's "up" = (0, sin, -cos)
    accel = np.array([0.0, -g * math.sin(r), -g * math.cos(r)])
    # a field pointing north and 60 deg down (0.2 G horizontal), in the rolled body
    f_ned = np.array([0.2, 0.0, 0.2 * math.tan(math.radians(60.0))])
    c, s = math.cos(r), math.sin(r)
    f_body = np.array([f_ned[0], c * f_ned[1] + s * f_ned[2], -s * f_ned[1] + c * f_ned[2]])
    topics: list[Topic] = []
    until = duration_s if imu_until_s is None else imu_until_s
    if with_imu:
        t = boot_us + np.arange(int(imu_from_s * 1e6), int(until * 1e6), int(1e6 / rate_hz),
                                dtype=np.int64)
        n = t.shape[0]
        topics.append(Topic("sensor_combined", SENSOR_COMBINED_FIELDS, {
            "timestamp": t, "gyro_rad": rng.normal(0.0, 0.002, (n, 3)),
            "accelerometer_timestamp_relative": np.zeros(n, dtype=np.int32),
            "accelerometer_m_s2": accel + rng.normal(0.0, 0.02, (n, 3)),
            "gyro_integral_dt": np.full(n, int(1e6 / rate_hz)),
        }))
    tm = boot_us + np.arange(0, int(duration_s * 1e6), int(1e6 / mag_hz), dtype=np.int64)
    for k in range(mag_instances):
        m = tm.shape[0]
        topics.append(Topic("vehicle_magnetometer", MAG_FIELDS, {
            "timestamp": tm + 100, "timestamp_sample": tm, "device_id": np.full(m, 1000 + k),
            "magnetometer_ga": f_body * (1.0 + 0.05 * k) + np.asarray(mag_offset_ga)
            + rng.normal(0.0, 0.002, (m, 3)),
        }, multi_id=k))
    ta = boot_us + np.arange(0, int(duration_s * 1e6), 20_000, dtype=np.int64)
    q = np.array([math.cos(r / 2), math.sin(r / 2), 0.0, 0.0])
    topics.append(Topic("vehicle_attitude", ATTITUDE_FIELDS, {
        "timestamp": ta, "timestamp_sample": ta, "q": np.tile(q, (ta.shape[0], 1))}))
    return write_ulog(path, topics, start_us=boot_us, parameters=parameters)
