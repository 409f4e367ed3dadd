"""The column layout of decoded message blocks, named once.

A block holds one row per message: the float64 fields of ``sensor_msgs/Imu`` (37) or
``sensor_msgs/MagneticField`` (12) in the message's own field order. The bag readers fill
blocks in this layout (``bag/cdr.py`` from CDR bytes, ``bag/ulog.py`` and ``bag/dataflash.py``
from autopilot logs); the pipeline (``pipeline/process.py``) reads them. Both name the
columns from here: no layer reads another's column numbers.
"""

from __future__ import annotations

import numpy as np

#: sensor_msgs/Imu: orientation (x, y, z, w) and its covariance, angular velocity [rad/s] and
#: its covariance, linear acceleration [m/s²] and its covariance (row-major 3×3 each)
IMU_DOUBLES = 37
ORIENTATION = slice(0, 4)
ORIENTATION_W = 3
ORIENTATION_COVARIANCE = slice(4, 13)
ANGULAR_VELOCITY = slice(13, 16)
ANGULAR_VELOCITY_COVARIANCE = slice(16, 25)
LINEAR_ACCELERATION = slice(25, 28)
LINEAR_ACCELERATION_COVARIANCE = slice(28, 37)

#: sensor_msgs/MagneticField: the field [T] and its covariance
MAG_DOUBLES = 12
MAGNETIC_FIELD = slice(0, 3)
MAGNETIC_FIELD_COVARIANCE = slice(3, 12)


def imu_block(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray) -> np.ndarray:
    """(n, IMU_DOUBLES) rows of IMU messages with only rates and accelerations (an autopilot
    log's): orientation (0, 0, 0, 1) marked unknown (covariance[0] = −1, REP-145), the other
    covariances 0."""
    values = np.zeros((gyro_rad_s.shape[0], IMU_DOUBLES))
    values[:, ORIENTATION_W] = 1.0
    values[:, ORIENTATION_COVARIANCE.start] = -1.0
    values[:, ANGULAR_VELOCITY] = gyro_rad_s
    values[:, LINEAR_ACCELERATION] = accel_m_s2
    return values


def mag_block(field_t: np.ndarray) -> np.ndarray:
    """(n, MAG_DOUBLES) rows of magnetometer messages: the field [T], covariances 0."""
    values = np.zeros((field_t.shape[0], MAG_DOUBLES))
    values[:, MAGNETIC_FIELD] = field_t
    return values
