"""Bag input/output over ``rosbags``, one import for the callers: the reader
(:mod:`cf_estimator.bag.reader`), the message builders (:mod:`cf_estimator.bag.messages`), the
writer with its mcap specifics (:mod:`cf_estimator.bag.writer`), the message type names and the
error (:mod:`cf_estimator.bag.types`) and the file helpers (:mod:`cf_estimator.bag.files`).
Each name below is defined once, in its module; this module only gathers them.
"""

from __future__ import annotations

from cf_estimator.bag.files import (
    user_file_mode,
    write_atomic_text,
)
from cf_estimator.bag.formats import open_bag
from cf_estimator.bag.messages import (
    accel_with_covariance_message,
    covariance9,
    diagnostics_message,
    header,
    imu_from_output,
    imu_message,
    magnetic_field_message,
    odometry_message,
    quaternion_stamped_message,
    quaternion_xyzw,
    rpy_from_output,
    stamp,
    stamp_from_ns,
    twist_stamped_message,
    vector3,
)
from cf_estimator.bag.reader import (
    BagMessage,
    InputBag,
    MessageChunk,
    TopicInfo,
    migrate_to_jazzy,
)
from cf_estimator.bag.types import (
    ACCEL_WITH_COVARIANCE_STAMPED_TYPE,
    DIAGNOSTIC_ARRAY_TYPE,
    IMU_TYPE,
    MAG_TYPE,
    ODOMETRY_TYPE,
    POSE_STAMPED_TYPE,
    QUATERNION_STAMPED_TYPE,
    REFERENCE_TYPES,
    TWIST_STAMPED_TYPE,
    VECTOR3_STAMPED_TYPE,
    VELOCITY_TYPES,
    BagError,
    one_line,
    typestore,
)
from cf_estimator.bag.writer import (
    ROSBAG2_VERSION,
    ROSBAGS_TESTED,
    STORAGES,
    OutputBag,
    check_output_path,
    direct_mcap_supported,
    record_rows,
    rosbags_version,
)

__all__ = [
    "ACCEL_WITH_COVARIANCE_STAMPED_TYPE",
    "accel_with_covariance_message",
    "BagError",
    "BagMessage",
    "DIAGNOSTIC_ARRAY_TYPE",
    "IMU_TYPE",
    "InputBag",
    "MAG_TYPE",
    "MessageChunk",
    "ODOMETRY_TYPE",
    "OutputBag",
    "POSE_STAMPED_TYPE",
    "QUATERNION_STAMPED_TYPE",
    "REFERENCE_TYPES",
    "ROSBAG2_VERSION",
    "ROSBAGS_TESTED",
    "STORAGES",
    "TWIST_STAMPED_TYPE",
    "TopicInfo",
    "VECTOR3_STAMPED_TYPE",
    "VELOCITY_TYPES",
    "check_output_path",
    "covariance9",
    "diagnostics_message",
    "direct_mcap_supported",
    "header",
    "imu_from_output",
    "imu_message",
    "magnetic_field_message",
    "migrate_to_jazzy",
    "odometry_message",
    "one_line",
    "open_bag",
    "quaternion_stamped_message",
    "quaternion_xyzw",
    "record_rows",
    "rosbags_version",
    "rpy_from_output",
    "stamp",
    "stamp_from_ns",
    "twist_stamped_message",
    "typestore",
    "user_file_mode",
    "vector3",
    "write_atomic_text",
]
