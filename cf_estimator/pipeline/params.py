"""Pipeline parameters: message handling around the filter (time guards, mag freshness, outputs).

One frozen dataclass, validated on construction, that is also the schema (like
:class:`cf_estimator.core.params.FilterParams`). The node declares these next to the filter's
parameters; ``read_only`` ones shape the node's wiring (publishers, timer) and need a restart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cf_estimator.core.covariance import TILT_FLOOR_RAD2, UNREFERENCED_YAW_RAD2, YAW_FLOOR_RAD2
from cf_estimator.core.magcal import check_calibration
from cf_estimator.schema import ParameterError, param, validate_fields

#: ``body_frame`` choices: the message axes as they are, or one of the two conventions.
BODY_FRAMES = ("sensor", "flu", "frd")


@dataclass(frozen=True)
class PipelineParams:
    """Parameters of :class:`cf_estimator.pipeline.ImuPipeline` (units in each description)."""

    body_frame: str = param(
        "sensor", "", "Axes convention of the IMU and magnetometer messages: 'flu' (REP-103: x "
        "forward, y left, z up; ROS drivers, MAVROS imu/data_raw) or 'frd' (x forward, y right, "
        "z down; PX4 sensor_combined, ulog). The output is then the body's orientation in the "
        "convention paired with world_frame: FLU in 'enu' (REP-103), FRD in 'ned' (PX4's roll, "
        "pitch, yaw from either source); the vectors copied to the output are converted alike. "
        "'sensor': no convention assumed, the orientation of the message axes as they are (as "
        "imu_filter_madgwick).",
        choices=BODY_FRAMES, read_only=True, group="frames",
    )
    magnetic_declination_rad: float = param(
        0.0, "rad", "Magnetic declination at the flight site, east positive (the World Magnetic "
        "Model's D; imu_filter_madgwick's declination): the published yaw refers to true north "
        "instead of magnetic north, in every world_frame.",
        minimum=-math.pi, maximum=math.pi, group="frames",
    )
    yaw_offset_rad: float = param(
        0.0, "rad", "Added to the published yaw (a rotation about the world frame's z axis, "
        "after the declination): e.g. a mounting offset of the magnetometer.",
        minimum=-math.pi, maximum=math.pi, group="frames",
    )
    output_frame_id: str = param(
        "auto", "", "header.frame_id of imu/data and imu/rpy, and the child frame of /tf. "
        "'auto': the input's frame_id, with '_frd' (or '_flu') added when body_frame makes the "
        "published body axes differ from the input's (base_link -> base_link_frd in NED, "
        "MAVROS' naming), so no reader takes an FRD orientation for a REP-103 FLU frame; any "
        "other value is used as given.",
        read_only=True, group="frames",
    )
    orientation_covariance_rad2: float = param(
        TILT_FLOOR_RAD2, "rad^2", "Floor v0 of the variance reported for roll and pitch "
        "(diagonal of orientation_covariance, rotation about the world x/y axes): what the "
        "filter cannot see (accelerometer bias, mounting). Start-up, recovery, clipped "
        "stretches, the tilt corrections the accelerometer channel made (accelerations it "
        "followed), a disagreement it keeps compensating (a bias not learned yet) and "
        "vibration add to it (docs/ros_interface.md, Covariance); the default is fitted on "
        "EuRoC's samples at rest (a MEMS IMU on a UAV and its motion-capture reference; a "
        "lab-grade IMU with an aligned reference is nearer 1e-5).",
        minimum=0.0, maximum=100.0, minimum_exclusive=True, group="output",
    )
    yaw_covariance_rad2: float = param(
        YAW_FLOOR_RAD2, "rad^2", "Floor of the variance reported for yaw while the heading is "
        "referenced by the magnetometer, about (1.0 deg)^2 (fitted on BROAD's undisturbed "
        "trials); the last measured heading error and the gyro drift since the last used "
        "sample add to it.",
        minimum=0.0, maximum=100.0, minimum_exclusive=True, group="output",
    )
    unreferenced_yaw_covariance_rad2: float = param(
        UNREFERENCED_YAW_RAD2, "rad^2", "Variance reported for yaw while no magnetometer has "
        "fixed the heading (use_mag false, or no usable sample yet): yaw is then only "
        "integrated gyro.",
        minimum=0.0, maximum=1000.0, minimum_exclusive=True, group="output",
    )
    publish_rpy: bool = param(
        True, "", "Publish roll, pitch, yaw [rad] on imu/rpy (geometry_msgs/Vector3Stamped).",
        read_only=True, group="output",
    )
    rpy_unwrap: bool = param(
        False, "", "Unwrap roll and yaw on imu/rpy so they stay continuous across +-pi "
        "(e.g. -190 deg instead of +170 deg); false: roll, yaw in (-pi, pi].",
        group="output",
    )
    publish_linear_acceleration: bool = param(
        False, "", "Publish the acceleration with gravity removed (geometry_msgs/"
        "AccelWithCovarianceStamped [m/s^2]): imu/linear_acceleration in the published body "
        "axes (frame_id as imu/data) and imu/linear_acceleration_world in the world frame "
        "(frame_id tf_parent_frame), covariance from the orientation's and the input's. "
        "Off by default: it costs the node CPU per message.",
        read_only=True, group="output",
    )
    mag_timeout_s: float = param(
        0.5, "s", "Freshness window: a magnetometer sample is used by the next IMU message only "
        "if their header stamps differ by at most this; older samples are counted stale.",
        minimum=0.0, maximum=60.0, minimum_exclusive=True, group="time",
    )
    max_dt_s: float = param(
        0.5, "s", "Longest stamp interval integrated as is. Over a longer gap the gyro rate is "
        "unknown: the message is processed with dt = the recent mean interval (the gap is not "
        "integrated) and counted as a gap.",
        minimum=0.0, maximum=60.0, minimum_exclusive=True, group="time",
    )
    reset_after_gap_s: float = param(
        5.0, "s", "A stamp gap longer than this resets the filter and re-initialises it from "
        "the message after the gap (0 = never; must be >= max_dt_s otherwise).",
        minimum=0.0, maximum=3600.0, group="time",
    )
    time_jump_back_threshold_s: float = param(
        0.5, "s", "Stamps going back by less than this are out-of-order messages (rejected); by "
        "more, time jumped back (bag loop, sim-time rewind): see reset_on_time_jump_back.",
        minimum=0.0, maximum=3600.0, minimum_exclusive=True, group="time",
    )
    reset_on_time_jump_back: bool = param(
        True, "", "On a backward time jump reset the filter and start again from the new "
        "message (false: reject messages until their stamps pass the last processed one).",
        group="time",
    )
    publish_tf: bool = param(
        False, "", "Broadcast the orientation on /tf (tf2_msgs/TFMessage, as imu_filter_madgwick "
        "does): the transform tf_parent_frame -> the IMU message's frame_id, zero translation, "
        "stamped with the IMU message. Off by default: a robot description usually owns that "
        "frame already.",
        read_only=True, group="tf",
    )
    tf_parent_frame: str = param(
        "world", "", "Parent frame of the broadcast transform: the world frame the orientation "
        "refers to (ENU or NED by world_frame).",
        group="tf",
    )
    reverse_tf: bool = param(
        False, "", "Broadcast the inverse transform instead: IMU frame -> tf_parent_frame (for a "
        "tree whose root is the robot, e.g. base_link -> imu_link already published).",
        group="tf",
    )
    velocity_topic: str = param(
        "", "", "Velocity aiding input (node): a geometry_msgs/TwistStamped (linear velocity "
        "in the world frame, axes by velocity_frame: mavros global_position/raw/gps_vel, "
        "nmea_navsat_driver vel) or nav_msgs/Odometry topic (twist in child_frame_id, rotated "
        "to the world by its own pose); empty = no velocity aiding (IMU-only).",
        read_only=True, group="velocity",
    )
    velocity_topic_type: str = param(
        "auto", "", "Message type of velocity_topic: 'auto' (from the ROS graph when the node "
        "starts, TwistStamped if not advertised yet), 'twist' or 'odometry'.",
        choices=("auto", "twist", "odometry"), read_only=True, group="velocity",
    )
    velocity_frame: str = param(
        "enu", "", "Axes of the velocity's world frame: 'enu' (REP-103, ROS drivers) or 'ned'; "
        "converted to world_frame.",
        choices=("enu", "ned"), group="velocity",
    )
    velocity_frame_id: str = param(
        "", "", "If not empty, velocity messages whose header.frame_id differs are rejected "
        "(counted velocity_rejected.frame): a velocity in some other frame.",
        group="velocity",
    )
    diagnostics_period_s: float = param(
        1.0, "s", "Period of the /diagnostics report (the node's timer; steady clock).",
        minimum=0.05, maximum=60.0, read_only=True, group="diagnostics",
    )
    input_type: str = param(
        "sensor_msgs", "", "What the node subscribes to: 'sensor_msgs' (imu/data_raw, imu/mag) "
        "or 'px4' (px4_msgs from PX4's uXRCE-DDS bridge: <px4_topic_prefix>/sensor_combined, "
        "vehicle_magnetometer, optionally vehicle_local_position, with PX4's QoS; needs the "
        "px4_msgs package). PX4 input defaults to body_frame frd, world_frame ned and "
        "velocity_frame ned (PX4's vehicle_attitude conventions) unless those are set. Offline "
        "tools read PX4 .ulg logs as PX4 input whatever this says.",
        choices=("sensor_msgs", "px4"), read_only=True, group="px4",
    )
    px4_topic_prefix: str = param(
        "/fmu/out", "", "Namespace of PX4's output topics with input_type px4, e.g. "
        "/px4_1/fmu/out for the second vehicle of a multi-vehicle setup (relative: under the "
        "node's namespace).",
        read_only=True, group="px4",
    )
    px4_local_position: bool = param(
        False, "", "With input_type px4: also subscribe to <px4_topic_prefix>/"
        "vehicle_local_position and use its velocity (vx, vy, vz NED, while v_xy_valid and "
        "v_z_valid) for the velocity aiding.",
        read_only=True, group="px4",
    )

    mag_hard_iron_t: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), "T", "Hard-iron offset h subtracted from every magnetometer sample "
        "before the filter (m = mag_soft_iron * (m_raw - h)), in the magnetometer message's own "
        "axes (before body_frame): 'cf-estimator calibrate-mag LOG' fits it. imu_filter_madgwick's "
        "mag_bias_x/y/z are taken as this when it is not set.",
        group="mag_calibration",
    )
    mag_soft_iron: tuple[float, ...] = param(
        (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0), "", "Soft-iron matrix S (3x3, row-major) "
        "applied after the hard iron is removed, same axes; identity = none. From "
        "'cf-estimator calibrate-mag' (symmetric, det 1); must be invertible and not flip the "
        "axes (det > 0).",
        group="mag_calibration",
    )
    strict_parameters: bool = param(
        False, "", "Node start-up: refuse to start (exit 2, one line, as replay --params) on any "
        "unknown or misspelt parameter and on a --params-file none of whose sections applies "
        "to this node (false: warn and run). On in the shipped launch file.",
        read_only=True, group="node",
    )

    def __post_init__(self) -> None:
        validate_fields(self)
        frame = self.output_frame_id
        if not frame or frame != frame.strip() or frame.startswith("/"):
            raise ParameterError(
                f"output_frame_id: {frame!r} is not a frame id (non-empty, no spaces around it, "
                "no leading '/'); 'auto' derives it from the input's"
            )
        frame = self.tf_parent_frame
        if not frame or frame != frame.strip() or frame.startswith("/"):
            raise ParameterError(
                f"tf_parent_frame: {frame!r} is not a frame id (non-empty, no spaces around it, "
                "no leading '/')"
            )
        prefix = self.px4_topic_prefix
        if not prefix or prefix != prefix.strip() or prefix.endswith("/") or "//" in prefix:
            raise ParameterError(
                f"px4_topic_prefix: {prefix!r} is not a topic namespace (e.g. /fmu/out or "
                "/px4_1/fmu/out: no trailing '/', no spaces)"
            )
        check_calibration(self.mag_hard_iron_t, self.mag_soft_iron)
        if 0.0 < self.reset_after_gap_s < self.max_dt_s:
            raise ParameterError(
                f"reset_after_gap_s: {self.reset_after_gap_s:g} s must be 0 (never) or at least "
                f"max_dt_s = {self.max_dt_s:g} s"
            )
