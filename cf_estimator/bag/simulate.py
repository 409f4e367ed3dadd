"""Scenario → ROS 2 bag: simulated ``imu/data_raw``, ``imu/mag`` and ground-truth orientation.

Topics (fully qualified, as ``ros2 bag record`` stores them for a node in the root namespace):

* ``/imu/data_raw`` — sensor_msgs/Imu at the scenario rate; orientation unknown
  (``orientation_covariance[0] = -1``), gyro/accel covariances from the sensor model's white noise.
* ``/imu/mag`` — sensor_msgs/MagneticField [T] at ``mag_rate_hz`` (default 100 Hz), the
  scenario's samples decimated on a regular grid.
* ``/ground_truth/orientation`` — geometry_msgs/QuaternionStamped, the true ``q_world_from_body``
  (ENU, frame_id ``world``) at ``truth_rate_hz`` (default 100 Hz; its stamps coincide with IMU
  stamps, so an estimate can be compared without interpolation).

Header stamps are ``start_time_ns + t``; log (receive) times are the stamp plus a small fixed
transport delay per topic (truth 50 µs, mag 100 µs, IMU 200 µs), so the recorded order is
unambiguous and identical in every storage format, and a magnetometer sample is in before the IMU
message with the same stamp (the first IMU message can fix the heading at start-up).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cf_estimator.bag import io
from cf_estimator.scenarios import Scenario
from cf_estimator.scenarios.velocity_sensor import VelocityData

IMU_TOPIC = "/imu/data_raw"
MAG_TOPIC = "/imu/mag"
TRUTH_TOPIC = "/ground_truth/orientation"
#: Simulated GNSS velocity (geometry_msgs/TwistStamped, ENU world frame), when asked for.
VELOCITY_TOPIC = "/gnss/vel"
IMU_FRAME = "imu_link"
WORLD_FRAME = "world"
#: Default first header stamp: 2024-01-01T00:00:00Z (a real-looking, non-zero time).
DEFAULT_START_TIME_NS = 1_704_067_200 * 1_000_000_000
_IMU_DELAY_NS = 200_000
_MAG_DELAY_NS = 100_000
_TRUTH_DELAY_NS = 50_000


@dataclass(frozen=True)
class SimulatedBag:
    """What :func:`write_scenario_bag` wrote."""

    path: Path
    storage: str
    counts: dict[str, int]  #: messages per topic
    duration_s: float
    rate_hz: float
    mag_rate_hz: float
    truth_rate_hz: float


def decimation_indices(t_s: np.ndarray, rate_hz: float | None) -> np.ndarray:
    """Indices of the first sample in each 1/rate_hz slot (all samples for None or ≥ the rate)."""
    n = t_s.shape[0]
    if rate_hz is None or rate_hz <= 0 or n < 2:
        return np.arange(n)
    slot = np.floor((t_s - t_s[0]) * rate_hz + 1e-6).astype(np.int64)
    _, first = np.unique(slot, return_index=True)
    return first


def _diag(variance: float) -> list[float]:
    return [variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0, variance]


def write_scenario_bag(
    scenario: Scenario, path: str | Path, *, storage: str = "mcap", overwrite: bool = False,
    mag_rate_hz: float | None = 100.0, truth_rate_hz: float | None = 100.0,
    start_time_ns: int = DEFAULT_START_TIME_NS,
    progress: Callable[[int], None] | None = None,
    velocity: VelocityData | None = None,
) -> SimulatedBag:
    """Write ``scenario`` as a ROS 2 bag at ``path`` (atomic: nothing is left on failure).

    ``mag_rate_hz``/``truth_rate_hz``: None or 0 = every IMU sample. ``progress`` is called with
    the number of IMU samples written since the last call. ``velocity``: simulated velocity
    samples (:mod:`cf_estimator.scenarios.velocity_sensor`) written on :data:`VELOCITY_TOPIC`
    stamped at their measurement time and logged at their arrival (stamp + latency).
    """
    imu = scenario.imu
    t = np.asarray(imu.t_s, dtype=float)
    n = t.shape[0]
    stamps = start_time_ns + np.round((t - t[0]) * 1e9).astype(np.int64)
    mag_rate = min(mag_rate_hz, scenario.rate_hz) if mag_rate_hz else scenario.rate_hz
    truth_rate = min(truth_rate_hz, scenario.rate_hz) if truth_rate_hz else scenario.rate_hz
    mag_mask = np.zeros(n, dtype=bool)
    mag_mask[decimation_indices(t, mag_rate)] = True
    truth_mask = np.zeros(n, dtype=bool)
    truth_mask[decimation_indices(t, truth_rate)] = True

    model = scenario.model
    gyro_var = (model.gyro_noise_density_rad_s_sqrt_hz * math.sqrt(scenario.rate_hz)) ** 2
    accel_var = (model.accel_noise_density_m_s2_sqrt_hz * math.sqrt(scenario.rate_hz)) ** 2
    gyro_cov, accel_cov = _diag(gyro_var), _diag(accel_var)
    mag_cov = _diag(model.mag_noise_std_T ** 2)
    no_orientation = [-1.0] + [0.0] * 8
    identity_xyzw = (0.0, 0.0, 0.0, 1.0)

    gyro = imu.gyro_rad_s.tolist()
    accel = imu.accel_m_s2.tolist()
    mag = imu.mag_T.tolist()
    q_truth = scenario.truth.q_world_from_body.tolist()

    with io.OutputBag(path, storage=storage, overwrite=overwrite) as out:
        out.add_topic(IMU_TOPIC, io.IMU_TYPE)
        out.add_topic(MAG_TOPIC, io.MAG_TYPE)
        out.add_topic(TRUTH_TOPIC, io.QUATERNION_STAMPED_TYPE)
        vel_rows: list[tuple[int, int, list[float]]] = []
        if velocity is not None:
            out.add_topic(VELOCITY_TOPIC, io.TWIST_STAMPED_TYPE)
            t_rel = np.asarray(velocity.t_s, dtype=float) - t[0]
            v_st = start_time_ns + np.round(t_rel * 1e9).astype(np.int64)
            v_log = start_time_ns + np.round((velocity.arrival_s - t[0]) * 1e9).astype(np.int64)
            vel_rows = [(int(a), int(b), v) for a, b, v in
                        zip(v_log.tolist(), v_st.tolist(), velocity.v_world_m_s.tolist(),
                            strict=True) if a > 0 and b > 0]
            vel_rows.sort()
        jv = 0
        out._writer.set_custom_data(  # metadata.yaml custom_data: how the bag was made
            "cf_estimator.scenario",
            json.dumps({
                "name": scenario.name, "seed": scenario.seed, "rate_hz": scenario.rate_hz,
                "duration_s": scenario.duration_s, "description": scenario.description,
                "disturbance_windows": [list(w) for w in scenario.disturbance_windows],
                "start_time_ns": int(start_time_ns),
            }),
        )
        step = max(1, n // 200)
        for k in range(n):
            ns = int(stamps[k])
            while jv < len(vel_rows) and vel_rows[jv][0] <= ns + _IMU_DELAY_NS:
                log_ns, st_ns, v = vel_rows[jv]
                vs, vn = divmod(st_ns, 1_000_000_000)
                out.write(VELOCITY_TOPIC, io.TWIST_STAMPED_TYPE, log_ns,
                          io.twist_stamped_message(vs, vn, WORLD_FRAME, v))
                jv += 1
            sec, nsec = divmod(ns, 1_000_000_000)
            if truth_mask[k]:
                out.write(TRUTH_TOPIC, io.QUATERNION_STAMPED_TYPE, ns + _TRUTH_DELAY_NS,
                          io.quaternion_stamped_message(sec, nsec, WORLD_FRAME, q_truth[k]))
            if mag_mask[k]:
                out.write(MAG_TOPIC, io.MAG_TYPE, ns + _MAG_DELAY_NS,
                          io.magnetic_field_message(sec, nsec, IMU_FRAME, mag[k], mag_cov))
            out.write(IMU_TOPIC, io.IMU_TYPE, ns + _IMU_DELAY_NS, io.imu_message(
                sec, nsec, IMU_FRAME, identity_xyzw, no_orientation, gyro[k], gyro_cov,
                accel[k], accel_cov,
            ))
            if progress is not None and (k + 1) % step == 0:
                progress(step)
        counts = dict(out.counts)
    return SimulatedBag(
        Path(path), storage, counts, scenario.duration_s, scenario.rate_hz, mag_rate, truth_rate
    )
