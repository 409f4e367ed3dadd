"""PX4 ulog flight logs (``.ulg``) as replay input: the same in-memory input a bag gives.

:class:`UlogBag` is an :class:`cf_estimator.bag.reader.InputBag` (``open_bag`` returns one for a
``.ulg`` file), so ``replay``, ``tune --bag``, fleets, ``--cluster`` and the Python API read
ulogs exactly like bags. The log is read once with pyulog (a dependency of the offline tools,
never imported by the node) into arrays; they are handed out as the light message objects of
:mod:`cf_estimator.bag.cdr` (one by one) or as decoded blocks (:meth:`UlogBag.chunks`, the bulk
path), in log-time order. Topics (named as in the log):

* ``sensor_combined`` → ``sensor_msgs/msg/Imu``: ``gyro_rad`` [rad/s] and ``accelerometer_m_s2``
  [m/s²], FRD body axes, stamped with ``timestamp`` [µs since boot] (the gyro's; the
  accelerometer's is ``timestamp + accelerometer_timestamp_relative``, rows whose relative stamp
  is invalid have no accelerometer sample and are left out); no orientation (covariance[0] -1).
* ``vehicle_magnetometer`` → ``sensor_msgs/msg/MagneticField``: ``magnetometer_ga`` [Gauss] → T,
  FRD, stamped ``timestamp_sample`` (``timestamp`` in logs without it). Older logs have no such
  topic: ``sensor_combined.magnetometer_ga`` (stamp ``timestamp +
  magnetometer_timestamp_relative``, a new sample only where the relative stamp is valid and
  changes). Either less EKF2's saved bias where EKF2 subtracted it (PX4 ≤ v1.11,
  :func:`cf_estimator.pipeline.px4.saved_mag_bias`; :attr:`UlogBag.mag_bias_text` says so).
* ``vehicle_local_position`` → ``geometry_msgs/msg/TwistStamped``: (vx, vy, vz) [m/s] NED, only
  rows with ``v_xy_valid`` and ``v_z_valid``; replayed only when asked for (velocity aiding).
* ``vehicle_attitude`` → ``geometry_msgs/msg/QuaternionStamped``: PX4's own estimate, q FRD →
  NED (w, x, y, z), stamped ``timestamp_sample`` or ``timestamp``: the replay compares with it.

Header stamps are the log's time since boot (µs → ns), the "log time" of every message too.
Bad input is said, never hidden: a truncated file gives what was readable and
:attr:`UlogBag.notes` says where it ends; several instances (``multi_id``) of a topic take the
one asked for (``instance``, default the lowest) and a note names it; no ``sensor_combined``
is one :class:`BagError` line naming the topics the log has.
"""

from __future__ import annotations

import contextlib
import io as io_
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cf_estimator.bag.logbag import Stream, StreamBag
from cf_estimator.bag.types import (
    IMU_TYPE,
    MAG_TYPE,
    QUATERNION_STAMPED_TYPE,
    TWIST_STAMPED_TYPE,
    BagError,
    one_line,
)
from cf_estimator.pipeline import columns, px4

IMU_TOPIC = "sensor_combined"
MAG_TOPIC = "vehicle_magnetometer"
#: The magnetometer inside sensor_combined (older PX4 logs).
OLD_MAG_TOPIC = "sensor_combined.magnetometer_ga"
VELOCITY_TOPIC = "vehicle_local_position"
ATTITUDE_TOPIC = "vehicle_attitude"
ULOG_FORMAT = "px4-ulog"
_WANTED = (IMU_TOPIC, MAG_TOPIC, VELOCITY_TOPIC, ATTITUDE_TOPIC)


def is_ulog(path: str | os.PathLike[str]) -> bool:
    """A ``.ulg`` file name (ulogs are recognised by their suffix, as PX4 writes them)."""
    return Path(path).suffix.lower() == ".ulg"


def _cut_at(data: bytes) -> int | None:
    """The offset of a message cut by the end of the file (a truncated log), None when the
    messages end exactly at the end: pyulog stops silently at such a message. Walks the
    message headers (uint16 size, uint8 type) from the end of the 16-byte file header."""
    n = len(data)
    pos = 16
    while pos + 3 <= n:
        nxt = pos + 3 + (data[pos] | (data[pos + 1] << 8))
        if nxt > n:
            return pos
        pos = nxt
    return None if pos == n else pos


@dataclass
class _Parsed:
    """What the reader takes from a parsed log (pyulog's ULog has the same attributes)."""

    start_timestamp: int
    last_timestamp: int
    file_corruption: bool
    data_list: list[Any]
    initial_parameters: dict[str, Any]


#: Message types of a ULog file (``F``ormat, ``I``nfo, ``M``ulti info, ``P``arameter, default
#: ``Q``, flag ``B``its, ``A``dd logged, ``D``ata, ``L``ogging, tagged ``C``, ``O`` dropout,
#: ``S``ync); ``R`` (remove logged) is left to pyulog.
_KNOWN_TYPES = frozenset(b"FIMPQBADLCOS")
#: Rows gathered at once by the fast parse (bounds its index array's memory).
_GATHER_ROWS = 65536


def _fast_parse(data: bytes) -> tuple[_Parsed, int | None] | None:
    """The data messages of a ULog gathered with NumPy: pyulog's own formats and
    subscriptions (its header parse and ``_MessageAddLogged``), its ``Data`` objects, the same
    arrays as ``ULog(file)`` gives (tested), without pyulog's Python loop over every message.
    Returns (the parse, the offset of a message cut by the end of the file or None), or None
    when the file needs pyulog's own reading (appended data, corruption, removed
    subscriptions, anything unusual)."""
    from pyulog import ULog

    with contextlib.redirect_stdout(io_.StringIO()):
        head = ULog(io_.BytesIO(data), parse_header_only=True)  # type: ignore[arg-type]
    if head.file_corruption or head.has_data_appended:
        return None
    n = len(data)
    offsets: list[int] = []
    append = offsets.append
    pos, cut = 16, None
    while pos + 3 <= n:  # the message chain: uint16 size, uint8 type, payload
        nxt = pos + 3 + (data[pos] | (data[pos + 1] << 8))
        if nxt > n:
            cut = pos
            break
        append(pos)
        pos = nxt
    if cut is None and pos != n:
        cut = pos
    buf = np.frombuffer(data, dtype=np.uint8)
    off = np.asarray(offsets, dtype=np.int64)
    types = buf[off + 2]
    if not np.isin(types, np.frombuffer(bytes(_KNOWN_TYPES), dtype=np.uint8)).all():
        return None
    ends = np.append(off[1:], cut if cut is not None else n)
    size = ends - off - 3
    header = ULog._MessageHeader()  # noqa: SLF001 - pyulog's own parsing of 'A' messages
    subs: dict[int, Any] = {}
    for k in np.flatnonzero(types == ord("A")).tolist():
        o = int(off[k])
        header.initialize(data[o:o + 3])
        try:
            sub = ULog._MessageAddLogged(data[o + 3:o + 3 + int(size[k])], header,  # noqa: SLF001
                                        head.message_formats)
        except Exception:  # noqa: BLE001 - a format pyulog cannot read: let pyulog say it
            return None
        if sub.msg_id in subs:
            return None
        subs[sub.msg_id] = sub
    d_idx = np.flatnonzero(types == ord("D"))
    d_off = off[d_idx]
    ids = buf[d_off + 3].astype(np.int64) | (buf[d_off + 4].astype(np.int64) << 8)
    last = int(head.start_timestamp)
    out = []
    for msg_id in np.unique(ids).tolist():
        sub = subs.get(msg_id)
        if sub is None:
            return None
        rows = np.flatnonzero(ids == msg_id)
        item = sub.dtype.itemsize
        sz = size[d_idx[rows]] - 2
        if np.any(sz < item) or np.any(sz > sub.max_data_size):
            return None  # pyulog skips those as corrupt: its reading says so
        cols = np.arange(item, dtype=np.int64)
        parts = []
        for a in range(0, rows.shape[0], _GATHER_ROWS):
            start = d_off[rows[a:a + _GATHER_ROWS]] + 5
            parts.append(buf[start[:, None] + cols].tobytes())
        sub.buffer = b"".join(parts)
        d = ULog.Data(sub)
        if d.data["timestamp"].size:
            last = max(last, int(d.data["timestamp"].max()))
        out.append(d)
    out.sort(key=lambda ds: (ds.name, ds.multi_id))
    return _Parsed(int(head.start_timestamp), last, False, out,
                   dict(head.initial_parameters)), cut


def _mag_device_ids(chosen: dict[str, Any]) -> set[int]:
    """The device ids (non-zero) the log gives for the magnetometer read: vehicle_magnetometer's
    own ``device_id``, else the ``mag_device_id`` of sensor_selection (the magnetometer PX4
    selected) or of estimator_sensor_bias (the one EKF2 used); empty when none says."""
    for topic, name in ((MAG_TOPIC, "device_id"), ("sensor_selection", "mag_device_id"),
                        ("estimator_sensor_bias", "mag_device_id")):
        d = chosen[topic].data if topic in chosen else {}
        if name in d:
            ids = {int(i) for i in np.unique(np.asarray(d[name])).tolist() if int(i) != 0}
            if ids:
                return ids
    return set()


def _field(data: dict[str, np.ndarray], name: str, n: int) -> np.ndarray:
    """(len, n) array of ``name[0]..name[n-1]``."""
    return np.stack([np.asarray(data[f"{name}[{i}]"], dtype=float) for i in range(n)], axis=1)


def _stamp_us(data: dict[str, np.ndarray]) -> np.ndarray:
    t = data.get("timestamp_sample")
    if t is None or not np.any(t):
        t = data["timestamp"]
    return np.asarray(t, dtype=np.int64)


class UlogBag(StreamBag):
    """A PX4 ulog opened for replay (use :func:`open_ulog` or ``io.open_bag``)."""

    def __init__(self, path: Path, instance: int | None = None) -> None:  # noqa: D107
        from pyulog import ULog
        from pyulog.core import ULogException

        self.path = path
        self.is_ros2 = True
        self.imu_topic = IMU_TOPIC
        self.reference_topic = ATTITUDE_TOPIC
        self.notes: list[str] = []  #: what the reader had to say (instances, truncation, span)
        self.instances: dict[str, int] = {}  #: topic -> multi_id used
        try:
            data = path.read_bytes()  # pyulog keeps it all in memory anyway; reads are faster
        except OSError as exc:
            raise BagError(f"{path}: cannot read: {exc.strerror or exc}", 2) from None
        try:
            # every topic: the log's span (last_timestamp) counts them all, and the error
            # without sensor_combined lists them
            fast = _fast_parse(data)
            if fast is not None:
                log, cut = fast
            else:  # pyulog's own reading (appended data, corruption...)
                with contextlib.redirect_stdout(io_.StringIO()):  # pyulog prints warnings
                    log = ULog(io_.BytesIO(data))  # type: ignore[arg-type]
                cut = None if log.file_corruption else _cut_at(data)
        except ULogException as exc:
            raise BagError(f"{path}: not a readable PX4 ulog: {one_line(exc)}") from exc
        except Exception as exc:  # noqa: BLE001 - pyulog on garbage raises anything
            raise BagError(f"{path}: not a readable PX4 ulog: {one_line(exc)}") from exc
        self.log_start_us = int(log.start_timestamp)
        #: the autopilot's parameters as the log starts (name -> value; PX4's units)
        self.parameters: dict[str, Any] = dict(log.initial_parameters)
        self.log_last_us = int(log.last_timestamp)
        size = len(data)
        del data
        if cut is not None or log.file_corruption:
            where = (f"cut at byte {cut} of {size}" if cut is not None
                     else "corrupt data skipped")
            self.notes.append(
                f"{path.name}: truncated ulog ({where}): replaying what was readable, "
                f"{(self.log_last_us - self.log_start_us) * 1e-6:.1f} s of log (up to "
                f"{self.log_last_us * 1e-6:.1f} s since boot)")
        self.truncated = cut is not None or bool(log.file_corruption)
        by_name: dict[str, dict[int, Any]] = {}
        for d in log.data_list:
            by_name.setdefault(d.name, {})[int(d.multi_id)] = d
        if IMU_TOPIC not in by_name:
            listing = ", ".join(sorted(by_name)) if by_name else "none"
            raise BagError(f"{path}: no {IMU_TOPIC} in this ulog (the IMU the estimator "
                              f"needs); its topics: {listing}")
        chosen = {name: self._pick(name, inst, instance) for name, inst in by_name.items()}
        if instance is not None and not any(len(by_name.get(n, {})) > 1 for n in _WANTED):
            self.notes.append(f"--instance {instance}: no topic the replay reads has several "
                              "instances in this log (each has one)")
        self.streams: dict[str, Stream] = {}
        self._imu(chosen[IMU_TOPIC].data)
        #: EKF2's saved magnetometer bias [Gauss] when EKF2 subtracted it (px4.saved_mag_bias)
        self.mag_bias_ga: np.ndarray | None = None
        #: what was done about it (empty: no bias saved in the log)
        self.mag_bias_text = ""
        if MAG_TOPIC in chosen or "magnetometer_ga[0]" in chosen[IMU_TOPIC].data:
            ids = _mag_device_ids(chosen)
            self.mag_bias_ga, self.mag_bias_text = px4.saved_mag_bias(self.parameters, ids)
            if self.mag_bias_text and not ids:  # a bias saved, for a magnetometer not named
                self.notes.append(self.mag_bias_text)
        if MAG_TOPIC in chosen:
            self._mag(chosen[MAG_TOPIC].data)
        elif "magnetometer_ga[0]" in chosen[IMU_TOPIC].data:
            self._old_mag(chosen[IMU_TOPIC].data)
        if VELOCITY_TOPIC in chosen:
            self._velocity(chosen[VELOCITY_TOPIC].data)
        if ATTITUDE_TOPIC in chosen:
            d = chosen[ATTITUDE_TOPIC].data
            q = _field(d, "q", 4)
            ok = np.all(np.isfinite(q), axis=1) & (np.linalg.norm(q, axis=1) > 0.5)
            self.streams[ATTITUDE_TOPIC] = Stream(ATTITUDE_TOPIC, QUATERNION_STAMPED_TYPE,
                                                   _stamp_us(d)[ok] * 1000, q[ok])
        self.finish_topics()

    @property
    def format(self) -> str:
        return ULOG_FORMAT

    # -- reading the log -------------------------------------------------------------------------
    def _pick(self, name: str, inst: dict[int, Any], wanted: int | None) -> Any:
        ids = sorted(inst)
        if len(ids) == 1:
            self.instances[name] = ids[0]
            return inst[ids[0]]
        if wanted is not None and wanted not in inst:
            raise BagError(
                f"{self.path}: {name} has instances (multi_id) {', '.join(map(str, ids))}, "
                f"not {wanted} (--instance)", 2)
        use = ids[0] if wanted is None else wanted
        self.instances[name] = use
        if name in _WANTED:
            self.notes.append(
                f"{name}: {len(ids)} instances (multi_id {', '.join(map(str, ids))}) in the log, "
                f"using {use}" + ("" if wanted is not None else " (choose with --instance)"))
        return inst[use]

    def _imu(self, d: dict[str, np.ndarray]) -> None:
        t = np.asarray(d["timestamp"], dtype=np.int64)
        gyro = _field(d, "gyro_rad", 3)
        accel = _field(d, "accelerometer_m_s2", 3)
        rel = d.get("accelerometer_timestamp_relative")
        keep = np.ones(t.shape[0], dtype=bool)
        if rel is not None:
            keep = np.asarray(rel, dtype=np.int64) != px4.RELATIVE_TIMESTAMP_INVALID
            dropped = int(np.count_nonzero(~keep))
            if dropped:
                self.notes.append(f"{IMU_TOPIC}: {dropped} rows without an accelerometer "
                                  "sample (invalid accelerometer_timestamp_relative) left out")
        values = columns.imu_block(gyro[keep], accel[keep])
        self.streams[IMU_TOPIC] = Stream(IMU_TOPIC, IMU_TYPE, t[keep] * 1000, values)

    def _mag_stream(self, topic: str, t_us: np.ndarray, ga: np.ndarray) -> None:
        ok = np.all(np.isfinite(ga), axis=1)
        ga = ga[ok] if self.mag_bias_ga is None else ga[ok] - self.mag_bias_ga
        values = columns.mag_block(ga * px4.GAUSS_TO_TESLA)
        self.streams[topic] = Stream(topic, MAG_TYPE, t_us[ok] * 1000, values)

    def _mag(self, d: dict[str, np.ndarray]) -> None:
        self._mag_stream(MAG_TOPIC, _stamp_us(d), _field(d, "magnetometer_ga", 3))

    def _old_mag(self, d: dict[str, np.ndarray]) -> None:
        t = np.asarray(d["timestamp"], dtype=np.int64)
        ga = _field(d, "magnetometer_ga", 3)
        rel = d.get("magnetometer_timestamp_relative")
        if rel is None:
            keep = np.ones(t.shape[0], dtype=bool)
            t_mag = t
        else:
            rel = np.asarray(rel, dtype=np.int64)
            valid = rel != px4.RELATIVE_TIMESTAMP_INVALID
            t_mag = t + np.where(valid, rel, 0)
            # a sample is new where its own stamp changes (sensor_combined repeats the last one)
            new = np.ones(t.shape[0], dtype=bool)
            new[1:] = t_mag[1:] != t_mag[:-1]
            keep = valid & new
        keep &= np.any(ga != 0.0, axis=1)
        self._mag_stream(OLD_MAG_TOPIC, t_mag[keep], ga[keep])

    def _velocity(self, d: dict[str, np.ndarray]) -> None:
        v = np.stack([np.asarray(d[k], dtype=float) for k in ("vx", "vy", "vz")], axis=1)
        ok = np.all(np.isfinite(v), axis=1)
        for flag in ("v_xy_valid", "v_z_valid"):
            if flag in d:
                ok &= np.asarray(d[flag]) != 0
        self.streams[VELOCITY_TOPIC] = Stream(VELOCITY_TOPIC, TWIST_STAMPED_TYPE,
                                               _stamp_us(d)[ok] * 1000, v[ok])

def open_ulog(path: str | os.PathLike[str], instance: int | None = None) -> UlogBag:
    """Read a PX4 ulog for replay (:class:`cf_estimator.bag.io.BagError` names the file)."""
    p = Path(path)
    if not p.is_file():
        raise BagError(f"{p}: no such file" if not p.exists() else f"{p}: not a file", 2)
    try:
        import pyulog  # noqa: F401
    except ImportError:
        raise BagError(f"{p}: reading PX4 ulogs needs pyulog (pip install pyulog)", 2) \
            from None
    return UlogBag(p, instance)
