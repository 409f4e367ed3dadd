"""A flight log (PX4 ulog, ArduPilot DataFlash) as arrays for :func:`cf_estimator.estimate`.

    from cf_estimator import FilterParams, estimate
    from cf_estimator.bag.logarrays import log_arrays

    log = log_arrays("flight.bin")
    res = estimate(log.gyro_rad_s, log.accel_m_s2, log.mag_T, timestamps_s=log.t_s,
                   params=FilterParams(world_frame="ned"))   # FRD body -> NED, as the log

The IMU rows of the log's IMU topic (stamps [s since boot]; FRD body axes), the magnetometer
on those rows (the latest sample logged since the previous IMU row, NaN rows where none: the
``mag`` convention of ``estimate``), and the autopilot's own attitude (FRD → NED quaternions
w, x, y, z, at its own stamps) to compare with. The same reader as the replay
(:func:`cf_estimator.bag.io.open_bag`): the same notes about the log.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from cf_estimator.bag import io
from cf_estimator.pipeline import columns


@dataclass
class LogArrays:
    """A log's IMU, magnetometer and autopilot attitude as arrays (FRD body, NED world)."""

    t_s: np.ndarray  #: (N,) IMU stamps [s since boot]
    gyro_rad_s: np.ndarray  #: (N, 3) [rad/s], FRD
    accel_m_s2: np.ndarray  #: (N, 3) specific force [m/s²], FRD
    mag_T: np.ndarray  #: (N, 3) [T], FRD; NaN rows: no new magnetometer sample
    reference_t_s: np.ndarray  #: (M,) stamps of the autopilot's attitude [s since boot]
    reference_q_wxyz: np.ndarray  #: (M, 4) its q FRD → NED (w, x, y, z)
    reference_topic: str | None  #: where it comes from (vehicle_attitude, ATT), None: none
    parameters: dict = field(default_factory=dict)  #: the autopilot's parameters
    notes: list[str] = field(default_factory=list)  #: what the reader said about the log
    #: the end of the flight worth comparing [s since boot] (before a flip or crash), None: all
    scored_until_s: float | None = None


def log_arrays(path: str | os.PathLike[str], instance: int | None = None) -> LogArrays:
    """Read a PX4 ``.ulg`` or ArduPilot ``.bin`` log into :class:`LogArrays`
    (:class:`cf_estimator.bag.io.BagError` for anything else or a bad log)."""
    from cf_estimator.bag.logbag import StreamBag

    bag = io.open_bag(path, ulog_instance=instance)
    if not isinstance(bag, StreamBag):
        bag.close()
        raise io.BagError(f"{path}: not a flight log (a PX4 .ulg or ArduPilot .bin): read a "
                          "bag with replay_bag", 2)
    imu = bag.streams[bag.imu_topic]
    t_ns = imu.t_ns
    mag = np.full((t_ns.shape[0], 3), np.nan)
    mag_stream = next((s for s in bag.streams.values() if s.msgtype == io.MAG_TYPE), None)
    if mag_stream is not None and mag_stream.t_ns.shape[0] and t_ns.shape[0]:
        # each magnetometer sample on the first IMU row at or after it (a newer one replaces it)
        row = np.searchsorted(t_ns, mag_stream.t_ns, side="left")
        ok = row < t_ns.shape[0]
        mag[row[ok]] = mag_stream.values[ok, columns.MAGNETIC_FIELD]
    ref_topic = getattr(bag, "reference_topic", None)
    ref = bag.streams.get(ref_topic) if ref_topic else None
    until = bag.scored_until_s() if hasattr(bag, "scored_until_s") else None
    return LogArrays(
        t_ns * 1e-9, imu.values[:, columns.ANGULAR_VELOCITY].copy(),
        imu.values[:, columns.LINEAR_ACCELERATION].copy(), mag,
        ref.t_ns * 1e-9 if ref is not None else np.zeros(0),
        ref.values.copy() if ref is not None else np.zeros((0, 4)),
        ref_topic if ref is not None else None, dict(bag.parameters), list(bag.notes), until)
