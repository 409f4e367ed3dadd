"""Write ArduPilot DataFlash logs (``.bin``): for the DataFlash tests and the low-rate benchmark.

The file is what ArduPilot's logger writes, reduced to what a reader needs: a ``FMT`` message
per message type (type id, length, name, struct format, column names), then the messages in
time order (``0xA3 0x95`` + type id + the packed fields). pymavlink's DFReader reads it as it
reads an autopilot's log. Formats use ArduPilot's format characters (``Q`` uint64, ``f``
float, ``I`` uint32, ``B`` uint8, ``N`` char[16], ``Z`` char[64], ``h`` int16...).

:func:`static_tilt_log` writes a vehicle standing still rolled by ``roll_deg`` (IMU, MAG in
milligauss, ATT in degrees): its ``ATT`` is the truth.
"""

from __future__ import annotations

import math
import os
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

_HEAD = b"\xa3\x95"
_FMT_ID = 0x80
#: ArduPilot format characters -> struct codes (the subset the writer needs).
_STRUCT = {"Q": "Q", "q": "q", "f": "f", "I": "I", "i": "i", "B": "B", "b": "b", "H": "H",
           "h": "h", "n": "4s", "N": "16s", "Z": "64s", "d": "d"}


@dataclass
class Message:
    """One message type: ``name`` (≤ 4 characters), ArduPilot ``format`` and ``columns``;
    ``rows``: one tuple of values per message, in column order."""

    name: str
    format: str
    columns: Sequence[str]
    rows: Sequence[Sequence[object]]

    def struct(self) -> struct.Struct:
        return struct.Struct("<" + "".join(_STRUCT[c] for c in self.format))


def _fmt_message(type_id: int, m: Message) -> bytes:
    length = 3 + m.struct().size
    body = struct.pack("<BB4s16s64s", type_id, length, m.name.encode(), m.format.encode(),
                       ",".join(m.columns).encode())
    return _HEAD + bytes([_FMT_ID]) + body


def write_dataflash(path: str | os.PathLike[str], messages: Sequence[Message],
                    parameters: Mapping[str, float] | None = None,
                    firmware: str = "ArduCopter V3.6.0 (synthetic)") -> Path:
    """Write ``messages`` into a DataFlash log at ``path``, interleaved by their first column
    (``TimeUS``), after the ``parameters`` (PARM) and the firmware line (MSG) at time 0."""
    params = Message("PARM", "QNf", ("TimeUS", "Name", "Value"),
                     [(0, k.encode(), float(v)) for k, v in (parameters or {}).items()])
    msg = Message("MSG", "QZ", ("TimeUS", "Message"), [(0, firmware.encode())])
    all_msgs = [params, msg, *messages]
    out = [_fmt_message(_FMT_ID, Message("FMT", "BBnNZ",
                                         ("Type", "Length", "Name", "Format", "Columns"), []))]
    events: list[tuple[int, int, bytes]] = []
    for k, m in enumerate(all_msgs):
        type_id = 0x81 + k
        out.append(_fmt_message(type_id, m))
        s = m.struct()
        for row in m.rows:
            events.append((int(row[0]), k, _HEAD + bytes([type_id]) + s.pack(*row)))
    events.sort(key=lambda e: (e[0], e[1]))
    p = Path(path)
    p.write_bytes(b"".join(out) + b"".join(e[2] for e in events))
    return p


IMU_FORMAT = ("IMU", "QffffffIIf",
              ("TimeUS", "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ", "EG", "EA", "T"))
MAG_FORMAT = ("MAG", "QhhhhhhhhhB", ("TimeUS", "MagX", "MagY", "MagZ", "OfsX", "OfsY", "OfsZ",
                                      "MOfsX", "MOfsY", "MOfsZ", "Health"))
ATT_FORMAT = ("ATT", "Qffffff", ("TimeUS", "DesRoll", "Roll", "DesPitch", "Pitch", "DesYaw",
                                  "Yaw"))

GPS_FORMAT = ("GPS", "QBBffffB", ("TimeUS", "I", "Status", "Spd", "GCrs", "VZ", "HDop",
                                   "NSats"))


def imu_message(t_us: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
                name: str = "IMU") -> Message:
    """IMU rows: stamps [µs], gyro [rad/s] and accelerometer [m/s²] (FRD)."""
    rows = [(int(t), *map(float, g), *map(float, a), 0, 0, 25.0)
            for t, g, a in zip(t_us, gyro, accel, strict=True)]
    return Message(name, IMU_FORMAT[1], IMU_FORMAT[2], rows)


def mag_message(t_us: np.ndarray, mag_mga: np.ndarray, offsets_mga: Sequence[int] = (0, 0, 0),
                health: int = 1) -> Message:
    """MAG rows: stamps [µs], field [milligauss] (FRD, offsets applied), the offsets logged."""
    rows = [(int(t), *(int(round(c)) for c in m), *map(int, offsets_mga), 0, 0, 0, health)
            for t, m in zip(t_us, mag_mga, strict=True)]
    return Message("MAG", MAG_FORMAT[1], MAG_FORMAT[2], rows)


def gps_message(t_us: np.ndarray, v_ned_m_s: np.ndarray, status: int | Sequence[int] = 3,
                instance: int = 0) -> Message:
    """GPS rows (ArduPilot ≥ 3.4 layout): stamps [µs since boot], a velocity NED [m/s] as
    ground speed, course [deg] and VZ (down), fix ``status`` (3: 3-D) per row or for all."""
    st = np.broadcast_to(np.asarray(status), (len(t_us),))
    rows = [(int(t), instance, int(k), float(math.hypot(v[0], v[1])),
             math.degrees(math.atan2(v[1], v[0])) % 360.0, float(v[2]), 0.8, 12)
            for t, v, k in zip(t_us, v_ned_m_s, st, strict=True)]
    return Message("GPS", GPS_FORMAT[1], GPS_FORMAT[2], rows)


def att_message(t_us: np.ndarray, rpy_deg: np.ndarray) -> Message:
    """ATT rows: stamps [µs], roll, pitch, yaw [deg] (FRD → NED, yaw 0-360)."""
    rows = [(int(t), 0.0, float(r), 0.0, float(p), 0.0, float(y) % 360.0)
            for t, (r, p, y) in zip(t_us, rpy_deg, strict=True)]
    return Message("ATT", ATT_FORMAT[1], ATT_FORMAT[2], rows)


def static_tilt_log(path: str | os.PathLike[str], roll_deg: float = 10.0,
                    duration_s: float = 20.0, rate_hz: float = 50.0, seed: int = 0,
                    with_mag: bool = True, boot_us: int = 30_000_000,
                    parameters: Mapping[str, float] | None = None,
                    firmware: str = "ArduCopter V3.6.0 (synthetic)") -> Path:
    """A vehicle standing still rolled by ``roll_deg`` (FRD body, NED world, heading north):
    gravity and a field of 200 mG north / 400 mG down in the body, white noise; ATT at 10 Hz
    says the truth."""
    rng = np.random.default_rng(seed)
    n = int(duration_s * rate_hz)
    t = boot_us + np.round(np.arange(n) / rate_hz * 1e6).astype(np.int64)
    r = math.radians(roll_deg)
    # specific force of a still body: -g expressed in FRD, i.e. up; NED down = +z
    f_body = np.array([0.0, -9.80665 * math.sin(r), -9.80665 * math.cos(r)])
    b_ned = np.array([200.0, 0.0, 400.0])
    b_body = np.array([b_ned[0], b_ned[1] * math.cos(r) + b_ned[2] * math.sin(r),
                       -b_ned[1] * math.sin(r) + b_ned[2] * math.cos(r)])
    gyro = rng.normal(0.0, 0.002, (n, 3))
    accel = f_body + rng.normal(0.0, 0.05, (n, 3))
    msgs = [imu_message(t, gyro, accel)]
    k = max(1, int(rate_hz // 10))
    att_t = t[::k]
    msgs.append(att_message(att_t, np.tile([roll_deg, 0.0, 0.0], (att_t.shape[0], 1))))
    if with_mag:
        mt = t[::k]
        msgs.append(mag_message(mt, b_body + rng.normal(0.0, 2.0, (mt.shape[0], 3))))
    return write_dataflash(path, msgs, parameters, firmware)
