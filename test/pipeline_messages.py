"""Plain message objects for pipeline tests without ROS (the fields the pipeline reads)."""

from __future__ import annotations

from types import SimpleNamespace as NS

#: ENU field [T] at the test site, seen by a level sensor pointing north-east-ish
FIELD_T = (5e-6, 20e-6, -45e-6)


def _header(t_ns: int, frame: str = "imu_link") -> NS:
    return NS(stamp=NS(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000), frame_id=frame)


def imu_msg(t_ns: int) -> NS:
    """A level, still IMU."""
    return NS(header=_header(t_ns), angular_velocity=NS(x=0.0, y=0.0, z=0.0),
              linear_acceleration=NS(x=0.0, y=0.0, z=9.80665),
              angular_velocity_covariance=[0.0] * 9, linear_acceleration_covariance=[0.0] * 9)


def mag_msg(t_ns: int) -> NS:
    return NS(header=_header(t_ns), magnetic_field=NS(x=FIELD_T[0], y=FIELD_T[1], z=FIELD_T[2]))
