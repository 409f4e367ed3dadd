"""Message construction: Jazzy (``Stores.ROS2_JAZZY``) message objects from plain values —
:func:`imu_message`, :func:`rpy_from_output`, :func:`diagnostics_message` and friends."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from cf_estimator.bag.types import (
    ACCEL_WITH_COVARIANCE_STAMPED_TYPE,
    DIAGNOSTIC_ARRAY_TYPE,
    IMU_TYPE,
    MAG_TYPE,
    ODOMETRY_TYPE,
    QUATERNION_STAMPED_TYPE,
    TWIST_STAMPED_TYPE,
    VECTOR3_STAMPED_TYPE,
    typestore,
)


def _types() -> dict[str, Any]:
    return typestore().types


def stamp(sec: int, nanosec: int) -> Any:
    """builtin_interfaces/Time."""
    return _types()["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nanosec))


def stamp_from_ns(t_ns: int) -> Any:
    sec, nanosec = divmod(int(t_ns), 1_000_000_000)
    return stamp(sec, nanosec)


def header(sec: int, nanosec: int, frame_id: str) -> Any:
    """std_msgs/Header (ROS 2: no seq)."""
    return _types()["std_msgs/msg/Header"](stamp=stamp(sec, nanosec), frame_id=str(frame_id))


def vector3(v: Sequence[float]) -> Any:
    return _types()["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def quaternion_xyzw(q: Sequence[float]) -> Any:
    """geometry_msgs/Quaternion from ROS-order (x, y, z, w)."""
    return _types()["geometry_msgs/msg/Quaternion"](
        x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])
    )


def covariance9(c: Sequence[float] | None) -> np.ndarray:
    arr = np.zeros(9) if c is None else np.asarray(c, dtype=np.float64).reshape(9)
    return np.ascontiguousarray(arr, dtype=np.float64)


def imu_message(
    sec: int, nanosec: int, frame_id: str, orientation_xyzw: Sequence[float],
    orientation_covariance: Sequence[float] | None, angular_velocity: Sequence[float],
    angular_velocity_covariance: Sequence[float] | None, linear_acceleration: Sequence[float],
    linear_acceleration_covariance: Sequence[float] | None,
) -> Any:
    """sensor_msgs/Imu (Jazzy)."""
    return _types()[IMU_TYPE](
        header=header(sec, nanosec, frame_id),
        orientation=quaternion_xyzw(orientation_xyzw),
        orientation_covariance=covariance9(orientation_covariance),
        angular_velocity=vector3(angular_velocity),
        angular_velocity_covariance=covariance9(angular_velocity_covariance),
        linear_acceleration=vector3(linear_acceleration),
        linear_acceleration_covariance=covariance9(linear_acceleration_covariance),
    )


def twist_stamped_message(sec: int, nanosec: int, frame_id: str, linear: Sequence[float],
                          angular: Sequence[float] = (0.0, 0.0, 0.0)) -> Any:
    """geometry_msgs/TwistStamped (Jazzy): a velocity [m/s] (and rate [rad/s]) in frame_id."""
    t = _types()
    return t[TWIST_STAMPED_TYPE](
        header=header(sec, nanosec, frame_id),
        twist=t["geometry_msgs/msg/Twist"](linear=vector3(linear), angular=vector3(angular)))


def odometry_message(sec: int, nanosec: int, frame_id: str, child_frame_id: str,
                     orientation_xyzw: Sequence[float], position: Sequence[float],
                     linear_body: Sequence[float]) -> Any:
    """nav_msgs/Odometry (Jazzy): pose of child_frame_id in frame_id, twist in child_frame_id."""
    t = _types()
    pose = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=float(position[0]), y=float(position[1]),
                                              z=float(position[2])),
        orientation=quaternion_xyzw(orientation_xyzw))
    twist = t["geometry_msgs/msg/Twist"](linear=vector3(linear_body),
                                         angular=vector3((0.0, 0.0, 0.0)))
    return t[ODOMETRY_TYPE](
        header=header(sec, nanosec, frame_id), child_frame_id=str(child_frame_id),
        pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))


def imu_from_output(out: Any) -> Any:
    """sensor_msgs/Imu for ``imu/data`` from a pipeline output (every field as it computed)."""
    return imu_message(
        out.stamp_sec, out.stamp_nanosec, out.frame_id, out.orientation_xyzw,
        out.orientation_covariance, out.angular_velocity, out.angular_velocity_covariance,
        out.linear_acceleration, out.linear_acceleration_covariance,
    )


def rpy_from_output(out: Any) -> Any | None:
    """geometry_msgs/Vector3Stamped (x roll, y pitch, z yaw [rad]) or None without an attitude."""
    if out.rpy_rad is None:
        return None
    return _types()[VECTOR3_STAMPED_TYPE](
        header=header(out.stamp_sec, out.stamp_nanosec, out.frame_id), vector=vector3(out.rpy_rad)
    )


def accel_with_covariance_message(sec: int, nanosec: int, frame_id: str,
                                  linear_m_s2: Sequence[float], cov9: Sequence[float]) -> Any:
    """geometry_msgs/AccelWithCovarianceStamped: ``linear_m_s2`` with its 3x3 covariance; the
    angular part zero, its variances -1 (not estimated)."""
    import numpy as np

    from cf_estimator.pipeline.linear_acceleration import accel_covariance6

    t = _types()
    accel = t["geometry_msgs/msg/Accel"](linear=vector3(linear_m_s2),
                                         angular=vector3((0.0, 0.0, 0.0)))
    return t[ACCEL_WITH_COVARIANCE_STAMPED_TYPE](
        header=header(sec, nanosec, frame_id),
        accel=t["geometry_msgs/msg/AccelWithCovariance"](
            accel=accel, covariance=np.array(accel_covariance6(cov9), dtype=np.float64)))


def magnetic_field_message(
    sec: int, nanosec: int, frame_id: str, field_T: Sequence[float],
    covariance: Sequence[float] | None = None,
) -> Any:
    """sensor_msgs/MagneticField [T]."""
    return _types()[MAG_TYPE](
        header=header(sec, nanosec, frame_id), magnetic_field=vector3(field_T),
        magnetic_field_covariance=covariance9(covariance),
    )


def quaternion_stamped_message(
    sec: int, nanosec: int, frame_id: str, q_wxyz: Sequence[float]
) -> Any:
    """geometry_msgs/QuaternionStamped from NumPy-order (w, x, y, z)."""
    return _types()[QUATERNION_STAMPED_TYPE](
        header=header(sec, nanosec, frame_id),
        quaternion=quaternion_xyzw((q_wxyz[1], q_wxyz[2], q_wxyz[3], q_wxyz[0])),
    )


def diagnostics_message(stamp_ns: int, reports: Sequence[Any]) -> Any:
    """diagnostic_msgs/DiagnosticArray from pipeline DiagnosticsReport objects."""
    t = _types()
    kv = t["diagnostic_msgs/msg/KeyValue"]
    status = [
        t["diagnostic_msgs/msg/DiagnosticStatus"](
            level=int(r.level), name=str(r.name), message=str(r.message),
            hardware_id=str(r.hardware_id),
            values=[kv(key=str(k), value=str(v)) for k, v in r.values],
        )
        for r in reports
    ]
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return t[DIAGNOSTIC_ARRAY_TYPE](header=header(sec, nanosec, ""), status=status)
