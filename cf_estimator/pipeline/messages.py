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


def stamp_of(msg: Any) -> tuple[int, int]:
    """``(sec, nanosec)`` of ``msg.header.stamp``."""
    st = msg.header.stamp
    return int(st.sec), int(st.nanosec)


def stamp_ns(msg: Any) -> int:
    """``msg.header.stamp`` in integer nanoseconds (exact; dt is computed from these)."""
    st = msg.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


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
