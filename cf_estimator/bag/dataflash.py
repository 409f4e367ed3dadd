"""ArduPilot DataFlash logs (``.bin``, any case) as replay input: the same input a ulog gives.

:class:`DataflashBag` is a :class:`cf_estimator.bag.logbag.StreamBag` (``open_bag`` returns one
for a ``.bin`` file), so ``replay`` (``--offline`` too), ``tune --bag``, fleets, ``--cluster``
and :func:`cf_estimator.bag.logarrays.log_arrays` (for ``estimate()``) read DataFlash logs like
ulogs. The log is parsed once by pymavlink's DFReader (the parser every ArduPilot tool uses; a
dependency of the offline tools, never imported by the node). Topics (named as the log's
message types):

* ``IMU`` → ``sensor_msgs/msg/Imu``: ``GyrX/Y/Z`` [rad/s], ``AccX/Y/Z`` [m/s², specific force],
  FRD body axes, stamped ``TimeUS`` [µs since boot] (``TimeMS`` in logs before 3.3). Instance 0
  by default; ``instance`` takes another (``IMU2``/``IMU3`` in older logs, the field ``I`` in
  newer ones). Where the log also has the raw ``GYR``/``ACC`` messages of that IMU (``GYRn``/
  ``ACCn`` in 3.4-3.6, ``INS_RAW_LOG_OPT``/``INS_LOG_BAT_*``) at a higher rate, those are read
  instead (gyro at its ``SampleUS`` stamps, the accelerometer interpolated onto them).
* ``MAG`` → ``sensor_msgs/msg/MagneticField``: ``MagX/Y/Z`` [milligauss] → T, FRD, samples
  with ``Health`` 0 left out. The logged field already has the autopilot's offsets
  (``OfsX/Y/Z``, its ``COMPASS_OFS_*``) and motor compensation (``MOfsX/Y/Z``) applied: it is
  read as logged (:attr:`DataflashBag.mag_text` says so).
* ``GPS`` → ``geometry_msgs/msg/TwistStamped``: the receiver's velocity, NED [m/s] (``Spd`` along
  the course ``GCrs`` [deg], ``VZ`` down), rows with a 3-D fix (``Status`` ≥ 3) only, stamped at
  boot time (``TimeUS``; ``T`` [ms] in 3.2-3.3 logs, whose ``TimeMS`` is the GPS week's); the
  first receiver (``I`` 0 or ``GPS``). Replayed only when asked for (``--velocity-topic GPS``:
  velocity aiding, docs/velocity_aiding.md), as a ulog's ``vehicle_local_position``.
* ``ATT`` → ``geometry_msgs/msg/QuaternionStamped``: the autopilot's own attitude (``Roll``,
  ``Pitch``, ``Yaw`` [deg], FRD → NED, ZYX): the replay compares with it. ``AHR2`` (the DCM
  backup), ``EKF1`` (EKF1, 3.2-3.3), ``NKF1`` (EKF2) and ``XKF1`` (EKF3; core ``C`` 0) likewise,
  compared beside it where present.

ArduPilot's attitude is the vehicle body's: the board's axes turned by the "level" trim
``AHRS_TRIM_X/Y``; the IMU and MAG are turned alike (:func:`trim_matrix`), so a level vehicle
reads level as in ATT (on the shared ArduCopter log, 1.2° of roll trim: the inclination at rest
against ATT 1.2° → 0.05°).

Bad input is said, never hidden: a truncated log gives what was readable and :attr:`notes` says
where it stopped; a log that ends upside down (a flip or a crash, the attitude through ±180°)
is scored up to :data:`CRASH_MARGIN_S` before it; Plane, Rover and Sub logs are read alike and
the vehicle is named; a log without ``MAG`` or without ``IMU`` is one line.
"""

from __future__ import annotations

import contextlib
import io as io_
import math
import os
from collections.abc import Mapping
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
from cf_estimator.core import quaternion as quat
from cf_estimator.pipeline import columns

DATAFLASH_FORMAT = "ardupilot-dataflash"
IMU_TOPIC = "IMU"
MAG_TOPIC = "MAG"
ATTITUDE_TOPIC = "ATT"
VELOCITY_TOPIC = "GPS"
#: GPS ``Status`` of a 3-D fix (AP_GPS::GPS_OK_FIX_3D); below it the velocity is not measured.
GPS_FIX_3D = 3
#: The autopilot's other attitude estimates compared beside ATT where the log has them.
ESTIMATE_TOPICS = ("AHR2", "EKF1", "NKF1", "XKF1")
#: The EKF's earth-field states (MN, ME, MD [mGauss], NED), newest EKF first: EKF3, EKF2,
#: and the 3.2-3.3 EKF's second message. atan2(ME, MN) is the declination the autopilot applies.
EARTH_FIELD_TOPICS = ("XKF2", "NKF2", "EKF2")
#: An earth-field estimate weaker than this [mGauss] horizontally has no declination (not set).
MIN_EARTH_FIELD_MGAUSS = 10.0
#: frame_id of the IMU and magnetometer messages (ArduPilot's body axes: FRD).
ARDUPILOT_BODY_FRAME_ID = "base_link_frd"
#: 1 milligauss in tesla (DataFlash MAG is in mGauss; sensor_msgs/MagneticField in T).
MILLIGAUSS_TO_TESLA = 1e-7
#: An attitude past this inclination [deg] (upside down) ends the scored flight: a flip or crash.
UPSIDE_DOWN_DEG = 90.0
#: The scored flight ends this long before the log's attitude first goes upside down [s] (the
#: tumble begins a few tenths of a second earlier).
CRASH_MARGIN_S = 1.0
#: Raw GYR/ACC are read instead of IMU when logged at least this many times faster.
RAW_RATE_FACTOR = 1.5
#: ArduPilot's level trim [rad]: its attitude (ATT...) is the vehicle body's, the board's
#: turned by roll AHRS_TRIM_X and pitch AHRS_TRIM_Y ("Level" calibration).
TRIM_PARAMS = ("AHRS_TRIM_X", "AHRS_TRIM_Y")
#: ArduPilot's declination parameters: COMPASS_DEC [rad], COMPASS_AUTODEC (1: from GPS).
DECLINATION_PARAM = "COMPASS_DEC"
AUTODEC_PARAM = "COMPASS_AUTODEC"
_VEHICLES = (("Copter", "ArduCopter"), ("Plane", "ArduPlane"), ("Rover", "Rover"),
             ("Sub", "ArduSub"), ("Tracker", "AntennaTracker"), ("Blimp", "Blimp"))


def is_dataflash(path: str | os.PathLike[str]) -> bool:
    """A ``.bin`` file name, any case (ArduPilot names its logs ``00000042.BIN``)."""
    return Path(path).suffix.lower() == ".bin"


def trim_matrix(parameters: Mapping[str, Any]) -> np.ndarray | None:
    """R_vehicle_from_board (3×3) of the log's ``AHRS_TRIM_X/Y`` [rad] (ArduPilot's
    ``_rotation_autopilot_body_to_vehicle_body``, Euler roll x, pitch y), None when the trim is
    zero, absent or not finite. Vectors measured in the board's axes times it are in the
    vehicle body's, the axes ArduPilot's ATT (and every estimate it logs) refers to."""
    try:
        tx, ty = (float(parameters[k]) for k in TRIM_PARAMS)
    except (KeyError, TypeError, ValueError):
        return None
    if not (math.isfinite(tx) and math.isfinite(ty)) or (tx == 0.0 and ty == 0.0) or \
            max(abs(tx), abs(ty)) > math.radians(45.0):
        return None
    return quat.to_matrix(quat.from_euler(tx, ty, 0.0))


def log_defaults(parameters: Mapping[str, Any]) -> tuple[dict[str, Any], str]:
    """``(defaults, note)``: the estimator parameters the log's own parameters imply —
    ``magnetic_declination_rad`` from ``COMPASS_DEC`` [rad] when it is a declination the
    autopilot used — and a note when the log does not say the declination (``COMPASS_DEC`` 0
    with ``COMPASS_AUTODEC`` 1: the autopilot looked it up from its GPS position at run time;
    empty otherwise)."""
    try:
        dec = float(parameters[DECLINATION_PARAM])
    except (KeyError, TypeError, ValueError):
        return {}, ""
    if not (math.isfinite(dec) and abs(dec) <= math.pi):
        return {}, ""
    try:
        auto = float(parameters.get(AUTODEC_PARAM, 0.0)) == 1.0
    except (TypeError, ValueError):
        auto = False
    if dec == 0.0 and auto:
        return {}, (f"{DECLINATION_PARAM} 0 with {AUTODEC_PARAM} 1: the declination the "
                    "autopilot looked up at its GPS position is not in the log; headings are "
                    "compared after removing their mean offset")
    return {"magnetic_declination_rad": dec}, ""


@dataclass
class _Rows:
    """The fields of one message type as arrays (column name -> (n,) array)."""

    columns: dict[str, np.ndarray]

    def __len__(self) -> int:
        return next(iter(self.columns.values())).shape[0] if self.columns else 0

    def stamp_us(self, prefer_sample: bool = False) -> np.ndarray:
        c = self.columns
        if prefer_sample and "SampleUS" in c:
            return c["SampleUS"].astype(np.int64)
        if "TimeUS" in c:
            return c["TimeUS"].astype(np.int64)
        if "Week" in c and "T" in c:  # 3.2-3.3 GPS: TimeMS is the GPS week's, T the boot's
            return c["T"].astype(np.int64) * 1000
        return c["TimeMS"].astype(np.int64) * 1000

    def xyz(self, prefix: str) -> np.ndarray:
        return np.stack([self.columns[f"{prefix}{a}"].astype(float) for a in "XYZ"], axis=1)

    def where(self, keep: np.ndarray) -> _Rows:
        return _Rows({k: v[keep] for k, v in self.columns.items()})


def _read(path: Path) -> tuple[dict[str, _Rows], dict[str, Any], list[str], int | None, int]:
    """(rows per message type, parameters, MSG texts, offset where a cut message starts or
    None, file size) of a DataFlash log, every type the replay may read."""
    from pymavlink import DFReader

    wanted = ["IMU", "IMU2", "IMU3", "MAG", "MAG2", "MAG3", ATTITUDE_TOPIC, *ESTIMATE_TOPICS,
              "GYR", "ACC", "GYR1", "GYR2", "GYR3", "ACC1", "ACC2", "ACC3", VELOCITY_TOPIC,
              *EARTH_FIELD_TOPICS, "MSG"]
    raw: dict[str, dict[str, list[Any]]] = {}
    texts: list[str] = []
    sink = io_.StringIO()
    with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
        reader = DFReader.DFReader_binary(str(path), zero_time_base=False)
        try:
            while (m := reader.recv_match(type=wanted)) is not None:
                kind = m.get_type()
                if kind == "MSG":
                    texts.append(str(getattr(m, "Message", "")))
                    continue
                d = m.to_dict()
                cols = raw.setdefault(kind, {k: [] for k in d if k != "mavpackettype"})
                for k, v in cols.items():
                    v.append(d.get(k, math.nan))
            left = reader.data_len - reader.offset
            cut = None
            if left >= 3 or reader.offset > reader.data_len:
                cut = reader.offset
                head = reader.data_map[max(0, cut - 3):cut]
                if len(head) == 3 and head[0] == reader.HEAD1 and head[1] == reader.HEAD2:
                    cut -= 3  # DFReader had read the cut message's header
            elif left > 0 and reader.data_map[reader.offset - 3:reader.offset - 1] == \
                    bytes((reader.HEAD1, reader.HEAD2)):
                cut = reader.offset - 3
            size = reader.data_len
            params = dict(reader.params)
        finally:
            reader.close()
    rows = {}
    for kind, cols in raw.items():
        try:
            rows[kind] = _Rows({k: np.asarray(v) for k, v in cols.items()
                                if not isinstance(v[0], str | bytes)})
        except (TypeError, ValueError):
            continue
    return rows, params, texts, cut, size


def _vehicle(texts: list[str]) -> str:
    """The firmware line of the log (``ArduCopter V3.3-dev``...), or "" when none is logged."""
    for t in texts:
        for key, name in _VEHICLES:
            if key in t and ("Ardu" in t or "APM" in t or name in t):
                return t.strip()
    return ""


def _attitude_q(rows: _Rows) -> np.ndarray:
    """(n, 4) q FRD → NED (w, x, y, z) from ``Roll``, ``Pitch``, ``Yaw`` [deg] (ZYX)."""
    c = rows.columns
    r, p, y = (np.radians(c[k].astype(float)) for k in ("Roll", "Pitch", "Yaw"))
    return quat.from_euler(r, p, y)


class DataflashBag(StreamBag):
    """An ArduPilot DataFlash log opened for replay (use :func:`open_dataflash`)."""

    def __init__(self, path: Path, instance: int | None = None) -> None:  # noqa: D107
        self.path = path
        self.is_ros2 = True
        self.imu_topic = IMU_TOPIC
        self.reference_topic = ATTITUDE_TOPIC
        self.estimate_topics = (ATTITUDE_TOPIC, *ESTIMATE_TOPICS)
        self.notes: list[str] = []  #: what the reader had to say (instance, truncation, crash)
        self.instances: dict[str, int] = {}  #: topic -> instance used
        try:
            rows, params, texts, cut, size = _read(path)
        except Exception as exc:  # noqa: BLE001 - DFReader on garbage raises anything
            raise BagError(f"{path}: not a readable ArduPilot DataFlash log: "
                              f"{one_line(exc)}") from exc
        #: the autopilot's parameters (name -> value; ArduPilot's units)
        self.parameters: dict[str, Any] = params
        self.vehicle = _vehicle(texts)  #: firmware line, e.g. "APM:Copter V3.3-dev (ae3192b8)"
        imu = self._imu_rows(rows, instance)
        if imu is None:
            kinds = ", ".join(sorted(rows)) or "none the replay reads"
            raise BagError(f"{path}: no IMU messages in this DataFlash log (the IMU the "
                              f"estimator needs); its messages: {kinds}")
        stamps = [r.stamp_us() for r in rows.values() if len(r)]
        self.log_start_us = int(min(int(s.min()) for s in stamps))
        self.log_last_us = int(max(int(s.max()) for s in stamps))
        self.truncated = cut is not None
        if cut is not None:
            self.notes.append(
                f"{path.name}: truncated DataFlash log (a message cut at byte {cut} of {size}): "
                f"replaying what was readable, {self.duration_s:.1f} s of log (up to "
                f"{self.log_last_us * 1e-6:.1f} s since boot)")
        self.streams: dict[str, Stream] = {}
        #: R_vehicle_from_board of AHRS_TRIM_X/Y applied to IMU and MAG (None: no trim)
        self.trim = trim_matrix(params)
        if self.trim is not None:
            self.notes.append(
                f"IMU and MAG turned by the log's level trim AHRS_TRIM_X/Y "
                f"({math.degrees(float(params['AHRS_TRIM_X'])):+.2f}, "
                f"{math.degrees(float(params['AHRS_TRIM_Y'])):+.2f} deg) into the vehicle "
                "body axes ATT refers to")
        self._imu(imu, rows, instance)
        self.mag_text = ""  #: what the magnetometer is (offsets applied, or no magnetometer)
        mag = self._instance_rows(rows, "MAG", instance)
        if mag is not None and len(mag):
            self._mag(mag)
        else:
            self.mag_text = "no MAG in this log: heading from the gyro alone (yaw unreferenced)"
            self.notes.append(self.mag_text)
        #: the declination the autopilot's EKF applied: (stamps [s since boot], [rad]) of its
        #: earth-field states, None when the log has none
        self.declination = _earth_field_declination(rows)
        gps = rows.get(VELOCITY_TOPIC)
        if gps is not None and len(gps):
            self._gps(gps)
        for topic in (ATTITUDE_TOPIC, *ESTIMATE_TOPICS):
            r = rows.get(topic)
            if r is None or not len(r) or not {"Roll", "Pitch", "Yaw"} <= set(r.columns):
                continue
            if "C" in r.columns:  # EKF3/EKF2 core: the first one logged (the primary)
                r = r.where(r.columns["C"] == np.min(r.columns["C"]))
            q = _attitude_q(r)
            ok = np.all(np.isfinite(q), axis=1)
            self.streams[topic] = Stream(topic, QUATERNION_STAMPED_TYPE,
                                         r.stamp_us()[ok] * 1000, q[ok], "ned")
        #: the log's time [s since boot] where its attitude first goes upside down (None: never)
        self.upside_down_s = self._upside_down(rows.get(ATTITUDE_TOPIC))
        if self.upside_down_s is not None:
            self.notes.append(
                f"ATT goes upside down at {self.upside_down_s:.1f} s since boot (a flip or a "
                f"crash): the comparison scores the flight up to {CRASH_MARGIN_S:g} s before it")
        if self.vehicle and "Copter" not in self.vehicle:
            self.notes.append(f"{self.vehicle}: read as any ArduPilot vehicle (IMU FRD, ATT "
                              "NED); sustained turns and accelerations tilt the accelerometer's "
                              "gravity, which the comparison includes")
        self.finish_topics()

    # -- reading the log -------------------------------------------------------------------------
    def _instance_rows(self, rows: dict[str, _Rows], kind: str,
                       wanted: int | None) -> _Rows | None:
        """The rows of instance ``wanted`` (None: 0) of ``kind`` (``IMU``/``MAG``): field ``I``
        in newer logs, ``IMU2``/``IMU3`` in older ones; an instance the log lacks is an error
        listing those it has."""
        base = rows.get(kind)
        have: dict[int, _Rows] = {}
        if base is not None and "I" in base.columns:
            for i in np.unique(base.columns["I"]).tolist():
                have[int(i)] = base.where(base.columns["I"] == i)
        else:
            for k, name in enumerate((kind, f"{kind}2", f"{kind}3")):
                if name in rows and len(rows[name]):
                    have[k] = rows[name]
        if not have:
            return None
        use = 0 if wanted is None else wanted
        if use not in have:
            if wanted is None:
                use = min(have)
            else:
                raise BagError(f"{self.path}: {kind} has instances "
                                  f"{', '.join(map(str, sorted(have)))}, not {wanted} "
                                  "(--instance)", 2)
        self.instances[kind] = use
        if len(have) > 1 and wanted is None and kind == IMU_TOPIC:
            self.notes.append(f"{kind}: {len(have)} instances in the log, using {use} "
                              "(choose with --instance)")
        return have[use]

    def _imu_rows(self, rows: dict[str, _Rows], instance: int | None) -> _Rows | None:
        r = self._instance_rows(rows, IMU_TOPIC, instance)
        return r if r is not None and len(r) else None

    def _raw_rows(self, rows: dict[str, _Rows], kind: str, instance: int) -> _Rows | None:
        """The raw ``GYR``/``ACC`` rows of one IMU instance (field ``I`` or ``GYRn``)."""
        base = rows.get(kind)
        if base is not None and "I" in base.columns:
            r = base.where(base.columns["I"] == instance)
        else:
            r = rows.get(f"{kind}{instance + 1}")
        return r if r is not None and len(r) > 1 else None

    def _imu(self, imu: _Rows, rows: dict[str, _Rows], instance: int | None) -> None:
        inst = self.instances.get(IMU_TOPIC, 0)
        t = imu.stamp_us()
        gyro, accel = imu.xyz("Gyr"), imu.xyz("Acc")
        g_raw, a_raw = self._raw_rows(rows, "GYR", inst), self._raw_rows(rows, "ACC", inst)
        if g_raw is not None and a_raw is not None:
            tg, ta = g_raw.stamp_us(True), a_raw.stamp_us(True)
            order_g, order_a = np.argsort(tg, kind="stable"), np.argsort(ta, kind="stable")
            tg, ta = tg[order_g], ta[order_a]
            rate = _rate_hz(t)
            if _rate_hz(tg) > RAW_RATE_FACTOR * rate and _rate_hz(ta) > RAW_RATE_FACTOR * rate:
                inside = (tg >= ta[0]) & (tg <= ta[-1])
                acc = a_raw.xyz("Acc")[order_a]
                t = tg[inside]
                gyro = g_raw.xyz("Gyr")[order_g][inside]
                accel = np.stack([np.interp(t, ta, acc[:, k]) for k in range(3)], axis=1)
                self.notes.append(f"IMU {inst}: the raw GYR/ACC ({_rate_hz(t):.0f} Hz) read "
                                  f"instead of IMU ({rate:.0f} Hz); the accelerometer "
                                  "interpolated onto the gyro's SampleUS")
        ok = np.all(np.isfinite(gyro), axis=1) & np.all(np.isfinite(accel), axis=1)
        if self.trim is not None:
            gyro, accel = gyro @ self.trim.T, accel @ self.trim.T
        values = columns.imu_block(gyro[ok], accel[ok])
        self.streams[IMU_TOPIC] = Stream(IMU_TOPIC, IMU_TYPE, t[ok] * 1000, values,
                                         ARDUPILOT_BODY_FRAME_ID)

    def _mag(self, mag: _Rows) -> None:
        c = mag.columns
        keep = np.ones(len(mag), dtype=bool)
        if "Health" in c:
            keep &= c["Health"].astype(float) != 0
        m = mag.xyz("Mag")
        keep &= np.all(np.isfinite(m), axis=1) & np.any(m != 0.0, axis=1)
        values = columns.mag_block((m[keep] if self.trim is None else m[keep] @ self.trim.T)
                                   * MILLIGAUSS_TO_TESLA)
        self.streams[MAG_TOPIC] = Stream(MAG_TOPIC, MAG_TYPE, mag.stamp_us()[keep] * 1000,
                                         values, ARDUPILOT_BODY_FRAME_ID)
        inst = self.instances.get(MAG_TOPIC, 0)
        ofs = mag.xyz("Ofs")[keep] if {"OfsX", "OfsY", "OfsZ"} <= set(c) else None
        if ofs is not None and ofs.size and np.any(ofs != 0.0):
            o = np.median(ofs, axis=0)
            self.mag_text = (f"MAG {inst} as logged: the autopilot's offsets (OfsX/Y/Z "
                             f"{o[0]:+.0f} {o[1]:+.0f} {o[2]:+.0f} mG) and motor compensation "
                             "already applied")
        else:
            self.mag_text = (f"MAG {inst} as logged: its offsets are zero (an uncalibrated "
                             "compass reads its hard-iron field as heading error)")
        if len(mag) and not keep.any():
            self.notes.append(f"MAG {inst}: no healthy sample (Health 0 or zero field)")

    def _gps(self, gps: _Rows) -> None:
        """The first receiver's 3-D-fix velocity [m/s] NED as the ``GPS`` velocity stream."""
        c = gps.columns
        if not {"Spd", "GCrs", "VZ", "Status"} <= set(c):
            return
        if "I" in c:
            gps = gps.where(c["I"] == np.min(c["I"]))
            c = gps.columns
        t_us = gps.stamp_us()
        speed, course = c["Spd"].astype(float), np.radians(c["GCrs"].astype(float))
        v = np.stack([speed * np.cos(course), speed * np.sin(course), c["VZ"].astype(float)],
                     axis=1)
        ok = (c["Status"].astype(float) >= GPS_FIX_3D) & np.all(np.isfinite(v), axis=1)
        if ok.any():
            self.streams[VELOCITY_TOPIC] = Stream(VELOCITY_TOPIC, TWIST_STAMPED_TYPE,
                                                   t_us[ok] * 1000, v[ok], "ned")

    def _upside_down(self, att: _Rows | None) -> float | None:
        if att is None or not len(att) or "Roll" not in att.columns:
            return None
        r = np.radians(att.columns["Roll"].astype(float))
        p = np.radians(att.columns["Pitch"].astype(float))
        k = np.flatnonzero(np.cos(r) * np.cos(p) < math.cos(math.radians(UPSIDE_DOWN_DEG)))
        return float(att.stamp_us()[k[0]]) * 1e-6 if k.size else None

    # -- InputBag ---------------------------------------------------------------------------------
    @property
    def format(self) -> str:
        return DATAFLASH_FORMAT

    def scored_until_s(self) -> float | None:
        """The end of the scored flight [s since boot] (before a flip or crash), None: all."""
        return None if self.upside_down_s is None else self.upside_down_s - CRASH_MARGIN_S

    def log_defaults(self) -> tuple[dict[str, Any], str]:
        """:func:`log_defaults` of this log's parameters; where the note says the declination is
        not in the parameters but the EKF's earth field is in the log, the note says that the
        comparison uses it instead."""
        defaults, note = log_defaults(self.parameters)
        if note and self.declination is not None:
            t, dec = self.declination
            note = (f"{DECLINATION_PARAM} 0 with {AUTODEC_PARAM} 1: headings are compared about "
                    "the declination the autopilot's EKF applied at each time (atan2(ME, MN) of "
                    f"its earth field: {math.degrees(dec[0]):+.1f} deg at {t[0]:.0f} s, "
                    f"{math.degrees(dec[-1]):+.1f} deg at {t[-1]:.0f} s)")
        return defaults, note

    def declination_at(self, t_s: np.ndarray) -> np.ndarray | None:
        """The declination [rad] the autopilot's EKF applied at ``t_s`` [s since boot]
        (interpolated; the first/last value outside its span), None without its earth field."""
        if self.declination is None:
            return None
        t, dec = self.declination
        return np.interp(t_s, t, np.unwrap(dec))


def _earth_field_declination(rows: dict[str, _Rows]) -> tuple[np.ndarray, np.ndarray] | None:
    """(stamps [s since boot], declination [rad]) of the newest EKF's earth field in the log
    (:data:`EARTH_FIELD_TOPICS`, the primary core ``C``), rows with a horizontal field of at
    least :data:`MIN_EARTH_FIELD_MGAUSS` only; None when there is none."""
    for topic in EARTH_FIELD_TOPICS:
        r = rows.get(topic)
        if r is None or not len(r) or not {"MN", "ME"} <= set(r.columns):
            continue
        if "C" in r.columns:
            r = r.where(r.columns["C"] == np.min(r.columns["C"]))
        mn, me = r.columns["MN"].astype(float), r.columns["ME"].astype(float)
        ok = np.isfinite(mn) & np.isfinite(me) & (np.hypot(mn, me) >= MIN_EARTH_FIELD_MGAUSS)
        if ok.any():
            return r.stamp_us()[ok] * 1e-6, np.arctan2(me[ok], mn[ok])
    return None


def _rate_hz(t_us: np.ndarray) -> float:
    """Median sample rate [Hz] of stamps [µs] (0 for fewer than two)."""
    if t_us.shape[0] < 2:
        return 0.0
    d = np.diff(t_us.astype(float))
    d = d[d > 0]
    return 1e6 / float(np.median(d)) if d.size else 0.0


def open_dataflash(path: str | os.PathLike[str], instance: int | None = None) -> DataflashBag:
    """Read an ArduPilot DataFlash log for replay (:class:`cf_estimator.bag.io.BagError` names
    the file)."""
    p = Path(path)
    if not p.is_file():
        raise BagError(f"{p}: no such file" if not p.exists() else f"{p}: not a file", 2)
    try:
        import pymavlink  # noqa: F401
    except ImportError:
        raise BagError(f"{p}: reading ArduPilot DataFlash logs needs pymavlink (pip install "
                          "pymavlink)", 2) from None
    return DataflashBag(p, instance)
