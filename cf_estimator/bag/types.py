"""Message type names, the ROS 2 Jazzy typestore and the bag error every bag module raises."""

from __future__ import annotations

import functools
from typing import Any

from rosbags.typesys import Stores, get_typestore

IMU_TYPE = "sensor_msgs/msg/Imu"
MAG_TYPE = "sensor_msgs/msg/MagneticField"
VECTOR3_STAMPED_TYPE = "geometry_msgs/msg/Vector3Stamped"
ACCEL_WITH_COVARIANCE_STAMPED_TYPE = "geometry_msgs/msg/AccelWithCovarianceStamped"
QUATERNION_STAMPED_TYPE = "geometry_msgs/msg/QuaternionStamped"
POSE_STAMPED_TYPE = "geometry_msgs/msg/PoseStamped"
ODOMETRY_TYPE = "nav_msgs/msg/Odometry"
TWIST_STAMPED_TYPE = "geometry_msgs/msg/TwistStamped"
VELOCITY_TYPES = (TWIST_STAMPED_TYPE, ODOMETRY_TYPE)
DIAGNOSTIC_ARRAY_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
#: Message types accepted as an orientation reference (ground truth, motion capture, odometry).
REFERENCE_TYPES = (QUATERNION_STAMPED_TYPE, POSE_STAMPED_TYPE, ODOMETRY_TYPE)


class BagError(Exception):
    """A bag could not be read or written; the message names the file and the reason.

    ``code`` is the exit code a command line should use: 2 when the user asked for something
    that cannot be (missing path, wrong topic, existing output), 1 for bad data.
    """

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


@functools.cache
def typestore() -> Any:
    """The ROS 2 Jazzy typestore every message written by cf_estimator is defined in."""
    return get_typestore(Stores.ROS2_JAZZY)


def one_line(exc: BaseException) -> str:
    """One line describing a library exception."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."
