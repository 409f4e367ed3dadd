"""Read message-like objects with the sensor_msgs field names (rclpy and rosbags alike).

Duck typing only: an rclpy ``sensor_msgs.msg.Imu``, a rosbags Jazzy-typestore ``Imu`` or any
object with the same attribute names works. Covariances may be ``array.array`` (rclpy), NumPy
arrays (rosbags) or plain sequences. ROS quaternions are ``(x, y, z, w)``; the core's are
``(w, x, y, z)``: the conversion happens here and in the pipeline's output, nowhere else.
Every reader raises ``AttributeError``/``TypeError``/``ValueError`` on a malformed message; the
pipeline counts those as rejected (``malformed``).
"""

from __future__ import annotations

from typing import Any

Vec3 = tuple[float, float, float]
Cov9 = tuple[float, float, float, float, float, float, float, float, float]

#: sensor_msgs convention: a covariance whose element 0 is -1 means "not provided".
UNKNOWN_COVARIANCE: Cov9 = (-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


def stamp_of(msg: Any) -> tuple[int, int]:
    """``(sec, nanosec)`` of ``msg.header.stamp``."""
    st = msg.header.stamp
    return int(st.sec), int(st.nanosec)


def stamp_ns(msg: Any) -> int:
    """``msg.header.stamp`` in integer nanoseconds (exact; dt is computed from these)."""
    st = msg.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def frame_id_of(msg: Any) -> str:
    """``msg.header.frame_id`` as a string."""
    return str(msg.header.frame_id)


def vector3(v: Any) -> Vec3:
    """``(x, y, z)`` floats of a geometry_msgs/Vector3-like object."""
    return float(v.x), float(v.y), float(v.z)


def quaternion_xyzw(q: Any) -> tuple[float, float, float, float]:
    """``(x, y, z, w)`` floats of a geometry_msgs/Quaternion-like object (ROS order)."""
    return float(q.x), float(q.y), float(q.z), float(q.w)


def covariance9(c: Any) -> Cov9:
    """A 9-element covariance as a tuple of floats (array.array, NumPy array or sequence)."""
    tolist = getattr(c, "tolist", None)
    out = tuple(tolist()) if tolist is not None else tuple(float(x) for x in c)
    if len(out) != 9:
        raise ValueError(f"covariance must have 9 elements, got {len(out)}")
    return out  # type: ignore[return-value]


def imu_gyro_rad_s(msg: Any) -> Vec3:
    """``angular_velocity`` [rad/s] of a sensor_msgs/Imu-like message."""
    return vector3(msg.angular_velocity)


def imu_accel_m_s2(msg: Any) -> Vec3:
    """``linear_acceleration`` [m/s^2] of a sensor_msgs/Imu-like message."""
    return vector3(msg.linear_acceleration)


def mag_field(msg: Any) -> Vec3:
    """``magnetic_field`` of a sensor_msgs/MagneticField-like message (Tesla by convention;
    components may be NaN, meaning "not reported")."""
    return vector3(msg.magnetic_field)
