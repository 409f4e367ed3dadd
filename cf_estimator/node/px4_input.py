"""The node's PX4 input (``input_type: px4``): px4_msgs from PX4's uXRCE-DDS bridge.

Subscribes to ``<px4_topic_prefix>/sensor_combined`` (px4_msgs/SensorCombined),
``<prefix>/vehicle_magnetometer`` (VehicleMagnetometer) and, with ``px4_local_position``,
``<prefix>/vehicle_local_position`` (VehicleLocalPosition) with PX4's QoS: best effort,
transient local, keep last (a reliable subscription matches none of PX4's publishers). Each
message becomes the sensor_msgs / geometry_msgs message the pipeline takes, and goes through the
node's own callbacks: one code path for both inputs, the outputs (imu/data, imu/rpy,
/diagnostics, /tf) unchanged.

* SensorCombined → sensor_msgs/Imu: ``gyro_rad`` [rad/s], ``accelerometer_m_s2`` [m/s²] (FRD
  body), header stamp = ``timestamp`` [µs since PX4 booted] (the log's clock: the output lines up
  with PX4's own topics), frame_id ``base_link_frd``; a row whose accelerometer is invalid
  (``accelerometer_timestamp_relative`` = RELATIVE_TIMESTAMP_INVALID) is skipped.
* VehicleMagnetometer → sensor_msgs/MagneticField: ``magnetometer_ga`` [Gauss] × 1e-4 → T,
  stamped ``timestamp_sample``.
* VehicleLocalPosition → geometry_msgs/TwistStamped: (vx, vy, vz) [m/s] NED while
  ``v_xy_valid`` and ``v_z_valid``, stamped ``timestamp_sample``.

PX4 input defaults to body_frame frd, world_frame ned, velocity_frame ned (declared so:
``ros2 param get`` shows them); an override from the command line or a parameter file wins.
Only imported by :mod:`cf_estimator.node.node`; px4_msgs is imported when the node starts
with ``input_type: px4``, never otherwise.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from geometry_msgs.msg import TwistStamped
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, MagneticField

from cf_estimator.node.errors import StartError
from cf_estimator.pipeline import px4
from cf_estimator.schema import ParamSpec

SENSOR_COMBINED = "sensor_combined"
VEHICLE_MAGNETOMETER = "vehicle_magnetometer"
VEHICLE_LOCAL_POSITION = "vehicle_local_position"
#: Queue depth of the magnetometer and local position subscriptions (PX4's examples use 5).
PX4_DEPTH = 5
MISSING = ("input_type px4 needs the px4_msgs package (github.com/PX4/px4_msgs, the branch "
           "matching the autopilot): build it in your workspace (colcon build --packages-select "
           "px4_msgs) and source it, or with the PyPI wheels: python3 scripts/build_msgs.py "
           "path/to/px4_msgs")


def px4_qos(depth: int) -> QoSProfile:
    """PX4's /fmu/out QoS: best effort, transient local, keep last ``depth``."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def px4_spec(spec: ParamSpec) -> ParamSpec:
    """``spec`` with PX4's default (body_frame frd, world_frame ned, velocity_frame ned)."""
    defaults = {**px4.PX4_FILTER_DEFAULTS, **px4.PX4_PIPELINE_DEFAULTS}
    if spec.name in defaults:
        return dataclasses.replace(spec, default=defaults[spec.name])
    return spec


def topic(prefix: str, name: str) -> str:
    return f"{prefix}/{name}"


def _stamp(header: Any, t_us: int) -> None:
    sec, us = divmod(int(t_us), 1_000_000)
    header.stamp.sec, header.stamp.nanosec = sec, us * 1000


class Px4Input:
    """The PX4 subscriptions of one node and the conversions (see the module docstring)."""

    def __init__(self, node: Any, pp: Any, imu_depth: int, overrides: Any) -> None:
        try:
            from px4_msgs.msg import SensorCombined, VehicleLocalPosition, VehicleMagnetometer
        except ImportError:
            raise StartError(MISSING) from None
        self._node = node
        self._invalid = SensorCombined.RELATIVE_TIMESTAMP_INVALID
        prefix = pp.px4_topic_prefix
        self.topics = [topic(prefix, SENSOR_COMBINED), topic(prefix, VEHICLE_MAGNETOMETER)]
        self.sub_imu = node.create_subscription(
            SensorCombined, self.topics[0], self.on_sensor_combined, px4_qos(imu_depth),
            qos_overriding_options=overrides)
        self.sub_mag = node.create_subscription(
            VehicleMagnetometer, self.topics[1], self.on_magnetometer, px4_qos(PX4_DEPTH),
            qos_overriding_options=overrides)
        self.sub_vel = None
        if pp.px4_local_position:
            self.topics.append(topic(prefix, VEHICLE_LOCAL_POSITION))
            self.sub_vel = node.create_subscription(
                VehicleLocalPosition, self.topics[2], self.on_local_position,
                px4_qos(PX4_DEPTH), qos_overriding_options=overrides)

    def on_sensor_combined(self, msg: Any) -> None:
        if int(msg.accelerometer_timestamp_relative) == self._invalid:
            return  # no accelerometer sample in this row
        imu = Imu()
        _stamp(imu.header, msg.timestamp)
        imu.header.frame_id = px4.PX4_BODY_FRAME_ID
        imu.orientation_covariance[0] = -1.0  # no orientation in the input
        g, a = msg.gyro_rad, msg.accelerometer_m_s2
        v = imu.angular_velocity
        v.x, v.y, v.z = float(g[0]), float(g[1]), float(g[2])
        v = imu.linear_acceleration
        v.x, v.y, v.z = float(a[0]), float(a[1]), float(a[2])
        self._node._on_imu(imu)  # noqa: SLF001 - the node's own IMU path

    def on_magnetometer(self, msg: Any) -> None:
        mag = MagneticField()
        _stamp(mag.header, msg.timestamp_sample or msg.timestamp)
        mag.header.frame_id = px4.PX4_BODY_FRAME_ID
        f, m = msg.magnetometer_ga, mag.magnetic_field
        k = px4.GAUSS_TO_TESLA
        m.x, m.y, m.z = float(f[0]) * k, float(f[1]) * k, float(f[2]) * k
        self._node._on_mag(mag)  # noqa: SLF001

    def on_local_position(self, msg: Any) -> None:
        if not (msg.v_xy_valid and msg.v_z_valid):
            return
        vel = TwistStamped()
        _stamp(vel.header, msg.timestamp_sample or msg.timestamp)
        vel.header.frame_id = "ned"
        lin = vel.twist.linear
        lin.x, lin.y, lin.z = float(msg.vx), float(msg.vy), float(msg.vz)
        self._node._on_velocity(vel)  # noqa: SLF001
