"""The rclpy node class: a thin adapter around :class:`cf_estimator.pipeline.ImuPipeline`.

With :mod:`cf_estimator.node.cf_estimator_node` (the console script, which imports this module
only once it knows rclpy is there) the only code of the package that imports rclpy. It converts
messages and wires callbacks; every decision (validation, time guards, magnetometer freshness,
covariances, diagnostics) is the pipeline's, so the bag replay behaves exactly like this node.

Topics (relative: a namespace or a remap moves them): ``imu/data_raw`` (sensor_msgs/Imu) and
``imu/mag`` (sensor_msgs/MagneticField) in, sensor-data QoS (best effort; the IMU queue
:data:`IMU_QUEUE_DEPTH` deep); ``imu/data`` (the input Imu with orientation and
orientation_covariance filled), ``imu/rpy`` (geometry_msgs/Vector3Stamped, roll/pitch/yaw in
rad) and ``/diagnostics`` out, reliable; ``/tf`` (tf2_msgs/TFMessage) when ``publish_tf``.
QoS overrides are accepted for the four relative topics
(``qos_overrides./<resolved topic>.<publisher|subscription>.<policy>``).
Run it single-threaded (``rclpy.spin``, as ``main`` does): callbacks are not locked.
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped, Vector3Stamped
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.clock import Clock, ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterNotDeclaredException,
)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import Imu, MagneticField

from cf_estimator.node.errors import StartError
from cf_estimator.params_file import (
    MAG_BIAS_ALIASES,
    ROS_STANDARD_PARAMETERS,
    ROS_STANDARD_PREFIXES,
    all_specs,
    build_params,
    check_names,
    describe_unknown,
    hard_iron_from_aliases,
    unapplied_file_warning,
    unknown_names,
)
from cf_estimator.pipeline import ImuPipeline
from cf_estimator.pipeline.checks import RESET_CLOCK_JUMP, input_type_problem
from cf_estimator.pipeline.diagnostics import LEVEL_NAMES
from cf_estimator.pipeline.frames import check_tf_frames
from cf_estimator.pipeline.linear_acceleration import accel_covariance6
from cf_estimator.pipeline.log_events import RateLimitedWarnings
from cf_estimator.schema import ParameterError, ParamSpec, as_dict

NODE_NAME = "cf_estimator"
IMU_IN = "imu/data_raw"
MAG_IN = "imu/mag"
IMU_OUT = "imu/data"
RPY_OUT = "imu/rpy"
ACCEL_OUT = "imu/linear_acceleration"
ACCEL_WORLD_OUT = "imu/linear_acceleration_world"
DIAGNOSTICS_OUT = "/diagnostics"
TF_OUT = "/tf"
#: Depth of the reliable publishers' history.
PUBLISHER_DEPTH = 10
#: Depth of the IMU subscription's queue (best effort, keep last). Chosen by measurement
#: (scripts/bench_node_load.py, 1 kHz IMU on a loaded 2-core machine: see docs/ros_interface.md):
#: deep enough to ride out a few tens of ms without the executor, and it costs no latency while
#: the node keeps up. Override: ``qos_overrides./imu/data_raw.subscription.depth``.
IMU_QUEUE_DEPTH = 50
#: Depth of /tf's history (tf2_ros' TransformBroadcaster uses 100).
TF_DEPTH = 100
#: Seconds between repeats of the same warning in the log.
LOG_THROTTLE_S = 5.0


def descriptor_for(spec: ParamSpec) -> ParameterDescriptor:
    """The ROS parameter descriptor of one schema entry (description, unit, range, read-only).

    rclpy's ranges are inclusive: an exclusive bound is stated in ``additional_constraints``
    and enforced by the node's on-set callback (the schema check).
    """
    d = ParameterDescriptor()
    d.name = spec.name
    d.description = (f"[{spec.unit}] " if spec.unit else "") + spec.description
    d.read_only = spec.read_only
    constraints = []
    if spec.choices:
        constraints.append("one of: " + ", ".join(spec.choices))
    bounded = spec.minimum is not None or spec.maximum is not None
    if bounded:
        lo = spec.minimum if spec.minimum is not None else -sys.float_info.max
        hi = spec.maximum if spec.maximum is not None else sys.float_info.max
        if spec.kind == "float":
            d.floating_point_range = [
                FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)
            ]
        elif spec.kind == "int":
            d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=1)]
        if spec.minimum_exclusive or spec.maximum_exclusive:
            constraints.append(f"range {spec.range_text()}")
    d.additional_constraints = "; ".join(constraints)
    return d


def _type_hint(spec: ParamSpec, text: str) -> str:
    """What to write for ``spec`` after rclpy refused a value of the wrong type."""
    if spec.kind == "float" and "'INTEGER'" in text:
        return " (float parameters need a decimal point in YAML, e.g. 1.0 not 1)"
    return {
        "bool": " (write true or false)",
        "int": " (write an integer)",
        "float": " (write a number with a decimal point, e.g. 1.0)",
        "str": " (write a string)",
    }[spec.kind]


class UnknownParameter(ParameterNotDeclaredException):
    """A live set of a parameter the node does not have: the parameter service answers with
    this one line (the nearest name, or ours for an imu_filter_madgwick name)."""

    def __init__(self, names: list[str]) -> None:
        super().__init__(names)
        self.text = f"unknown parameter {describe_unknown(names)}"

    def __str__(self) -> str:
        return self.text


def exact_float(value: Any) -> float | None:
    """``value`` as a float when it is an integer that a double holds exactly, else None."""
    if isinstance(value, bool) or not isinstance(value, int) or abs(value) > 2**53:
        return None
    return float(value)


def _sensor_qos(depth: int = qos_profile_sensor_data.depth) -> QoSProfile:
    """A fresh sensor-data profile (QoS overrides modify the profile they get)."""
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=depth,
        reliability=qos_profile_sensor_data.reliability,
        durability=qos_profile_sensor_data.durability,
    )


class CfEstimatorNode(Node):
    """Attitude estimation node (see the module docstring)."""

    def __init__(self, node_name: str = NODE_NAME, *, params_files: Sequence[str] = (),
                 **kwargs: Any) -> None:
        """``params_files``: the ``--params-file`` paths of the command line (``run`` passes
        them): each one none of whose sections is for this node gets a start-up warning."""
        super().__init__(node_name, **kwargs)
        log = self.get_logger()
        self._names = {s.name for s in all_specs()}
        values = self._declare_all()
        filter_params, pipeline_params = build_params(values)  # ParameterError: main() reports
        unknown = unknown_names(getattr(self, "_parameter_overrides", {}))  # this node's overrides
        if pipeline_params.strict_parameters:  # flight: refuse, with replay --params' lines
            for path in params_files:
                check_names(path, self.get_fully_qualified_name())  # ParameterError: main()
            if unknown:
                raise ParameterError(f"unknown parameter {describe_unknown(unknown)} "
                                     "(strict_parameters)")
        elif unknown:  # once, at start-up: a misspelt key would otherwise be silently ignored
            log.warning(f"unknown parameter(s), ignored: {describe_unknown(unknown)}")
        ns = self.get_namespace().rstrip("/")
        px4_in = pipeline_params.input_type == "px4"
        imu_in = (f"{pipeline_params.px4_topic_prefix}/sensor_combined" if px4_in else IMU_IN)
        self._pipe = ImuPipeline(
            filter_params, pipeline_params, diagnostics_name=f"{ns}/{self.get_name()}: attitude",
            imu_topic=self.resolve_topic_name(imu_in),
        )
        self._last_level: int | None = None
        self._type_problems: dict[str, str] = {}  # input role -> the line warned
        self._velocity_count = 0
        self._events = RateLimitedWarnings(LOG_THROTTLE_S)
        self._resets_logged = 0
        self._events_logged = 0
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._converts_axes = self._pipe.converts_axes

        overrides = QoSOverridingOptions.with_default_policies()
        reliable = QoSProfile(depth=PUBLISHER_DEPTH)
        self._pub_imu = self.create_publisher(
            Imu, IMU_OUT, reliable, qos_overriding_options=overrides
        )
        self._pub_rpy = None
        if pipeline_params.publish_rpy:
            self._pub_rpy = self.create_publisher(
                Vector3Stamped, RPY_OUT, QoSProfile(depth=PUBLISHER_DEPTH),
                qos_overriding_options=overrides,
            )
        #: imu/rpy's message, filled and published per IMU message (publish serializes it at
        #: once: one object, not a new one each time, as /tf's)
        self._rpy_msg = Vector3Stamped()
        self._pub_diag = self.create_publisher(
            DiagnosticArray, DIAGNOSTICS_OUT, QoSProfile(depth=PUBLISHER_DEPTH)
        )
        self._pub_accel = self._pub_accel_world = None
        if pipeline_params.publish_linear_acceleration:
            from geometry_msgs.msg import AccelWithCovarianceStamped

            self._accel_type = AccelWithCovarianceStamped
            self._pub_accel = self.create_publisher(
                AccelWithCovarianceStamped, ACCEL_OUT, QoSProfile(depth=PUBLISHER_DEPTH),
                qos_overriding_options=overrides)
            self._pub_accel_world = self.create_publisher(
                AccelWithCovarianceStamped, ACCEL_WORLD_OUT, QoSProfile(depth=PUBLISHER_DEPTH),
                qos_overriding_options=overrides)
        self._pub_tf = None
        if pipeline_params.publish_tf:
            refusal, tf_warning = check_tf_frames(
                filter_params.world_frame, pipeline_params.body_frame,
                pipeline_params.tf_parent_frame, pipeline_params.output_frame_id)
            if refusal:  # a transform every ROS consumer would misread: not published
                raise StartError(refusal)
            if tf_warning:
                log.warning(tf_warning)
            try:
                from tf2_msgs.msg import TFMessage
            except ImportError:
                raise StartError(
                    "publish_tf needs the tf2_msgs package (ROS: apt install ros-jazzy-tf2-msgs; "
                    "PyPI wheels: python3 scripts/build_tf2_msgs.py into this environment, or "
                    "python3 scripts/build_tf2_msgs.py --prefix DIR for a shared one that must "
                    "stay unmodified, then the PYTHONPATH and LD_LIBRARY_PATH it prints)"
                ) from None
            self._pub_tf = self.create_publisher(TFMessage, TF_OUT, QoSProfile(depth=TF_DEPTH))
            self._tf_msg = TFMessage(transforms=[TransformStamped()])
        self._px4 = None
        if px4_in:  # px4_msgs from PX4's bridge, PX4's QoS (node/px4_input.py)
            from cf_estimator.node.px4_input import Px4Input

            self._px4 = Px4Input(self, pipeline_params, IMU_QUEUE_DEPTH, overrides)
        else:
            self._sub_imu = self.create_subscription(
                Imu, IMU_IN, self._on_imu, _sensor_qos(IMU_QUEUE_DEPTH),
                qos_overriding_options=overrides,
            )
            self._sub_mag = self.create_subscription(
                MagneticField, MAG_IN, self._on_mag, _sensor_qos(),
                qos_overriding_options=overrides,
            )
        self._sub_vel = None
        if pipeline_params.velocity_topic:
            vel_type = self._velocity_type(pipeline_params)
            self._sub_vel = self.create_subscription(
                vel_type, pipeline_params.velocity_topic, self._on_velocity, _sensor_qos(),
                qos_overriding_options=overrides,
            )
        # Diagnostics on the steady clock: they keep coming when sim time stalls.
        self._timer = self.create_timer(
            pipeline_params.diagnostics_period_s, self._on_diagnostics,
            clock=Clock(clock_type=ClockType.STEADY_TIME),
        )
        # Any backward jump of the node clock is reported; the callback applies the threshold.
        self._jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=None, min_backward=Duration(nanoseconds=-1),
                          on_clock_change=False),
            post_callback=self._on_time_jump,
        )
        self.add_pre_set_parameters_callback(self._convert_parameters)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self._post_set = hasattr(self, "add_post_set_parameters_callback")
        if self._post_set:
            self.add_post_set_parameters_callback(self._apply_parameters)

        ins = self._px4.topics if self._px4 else [IMU_IN, MAG_IN]
        topics = {
            "in": [self.resolve_topic_name(t) for t in ins]
            + ([f"{self.resolve_topic_name(pipeline_params.velocity_topic)} (velocity aiding, "
                f"{self._sub_vel.msg_type.__name__})"] if self._sub_vel else []),
            "out": [self.resolve_topic_name(IMU_OUT)]
            + ([self.resolve_topic_name(RPY_OUT)] if self._pub_rpy else [])
            + ([self.resolve_topic_name(ACCEL_OUT), self.resolve_topic_name(ACCEL_WORLD_OUT)]
               if self._pub_accel else [])
            + [DIAGNOSTICS_OUT]
            + ([TF_OUT] if self._pub_tf else []),
        }
        backend = self._pipe.filter.backend
        log.info(
            f"subscribed ({'PX4 QoS: best effort, transient local' if px4_in else 'sensor-data'}"
            f" QoS) to {', '.join(topics['in'])}; publishing "
            f"{', '.join(topics['out'])}; world frame {filter_params.world_frame}, body frame "
            f"{pipeline_params.body_frame}; filter step: "
            + ("compiled kernel" if backend == "compiled"
               else "Python reference (no compiled kernel: slower)")
        )
        self.warn_unapplied_params_files(params_files)
        effective = {**as_dict(filter_params), **as_dict(pipeline_params)}
        log.info("parameters: " + ", ".join(f"{k}={v}" for k, v in effective.items()))

    def warn_unapplied_params_files(self, paths: Sequence[str]) -> list[str]:
        """Warn (once, at start-up) for every ``--params-file`` none of whose sections is for
        this node: rclpy ignores such a file silently. Returns the warnings."""
        texts = [t for t in (unapplied_file_warning(p, self.get_fully_qualified_name())
                             for p in paths) if t]
        for text in texts:
            self.get_logger().warning(text)
        return texts

    def _declare_all(self) -> dict[str, Any]:
        """Declare every schema parameter; input_type first: PX4 input declares body_frame,
        world_frame and velocity_frame with PX4's defaults (overrides still win)."""
        specs = {s.name: s for s in all_specs()}
        overrides = getattr(self, "_parameter_overrides", {})
        alias = hard_iron_from_aliases(
            {k: p.value for k, p in overrides.items()
             if k in MAG_BIAS_ALIASES or k == "mag_hard_iron_t"})
        if alias is not None:  # imu_filter_madgwick's mag_bias_x/y/z: the hard iron's default
            import dataclasses

            specs["mag_hard_iron_t"] = dataclasses.replace(specs["mag_hard_iron_t"],
                                                           default=alias)
            self.get_logger().info(f"imu_filter_madgwick's mag_bias_x/y/z taken as "
                                   f"mag_hard_iron_t {list(alias)} [T]")
        values = {"input_type": self._declare(specs["input_type"])}
        px4_in = values["input_type"] == "px4"
        if px4_in:
            from cf_estimator.node.px4_input import px4_spec
        for name, spec in specs.items():
            if name not in values:
                values[name] = self._declare(px4_spec(spec) if px4_in else spec)
        return values

    def _declare(self, spec: ParamSpec) -> Any:
        """Declare one schema parameter; a value of the wrong type → ParameterError, one line."""
        try:
            return self.declare_parameter(spec.name, spec.default, descriptor_for(spec)).value
        except InvalidParameterTypeException as exc:
            text = str(exc).splitlines()[0]
            raise ParameterError(f"{text}{_type_hint(spec, text)}") from None

    # -- messages ---------------------------------------------------------------------------
    def _log_events(self, flush: bool = False) -> None:
        """One WARN per reset, per event and per new kind of rejection, rate-limited per reason
        (:class:`cf_estimator.pipeline.log_events.RateLimitedWarnings`, steady clock)."""
        now_s = self._steady.now().nanoseconds * 1e-9
        pipe = self._pipe
        lines = (self._events.flush(now_s) if flush else
                 self._events.update(pipe.reset_counts, pipe.rejected_counts, now_s,
                                     pipe.event_counts))
        self._resets_logged = pipe.reset_total
        self._events_logged = pipe.event_total
        for text in lines:
            self.get_logger().warning(text)

    def _on_imu(self, msg: Imu) -> None:
        out = self._pipe.on_imu(msg)
        log = self.get_logger()
        if (out is None or self._pipe.reset_total != self._resets_logged
                or self._pipe.event_total != self._events_logged):
            self._log_events()
        if out is None:
            bug = self._pipe.take_internal_error()
            if bug is not None:
                log.error("internal error (a bug, please report it): the message was dropped, "
                          f"the node goes on; counted as internal_error\n{bug}")
            return
        for text in out.warnings:
            log.warning(text)
        try:
            # imu/data is the input message itself: header, vectors and covariances as received.
            q = msg.orientation
            q.x, q.y, q.z, q.w = out.orientation_xyzw
            if out.frame_id != msg.header.frame_id:  # output_frame_id: the body published
                msg.header.frame_id = out.frame_id
            msg.orientation_covariance = out.orientation_covariance
            if self._converts_axes:  # body_frame: the vectors in the output's convention too
                v = msg.angular_velocity
                v.x, v.y, v.z = out.angular_velocity
                v = msg.linear_acceleration
                v.x, v.y, v.z = out.linear_acceleration
                msg.angular_velocity_covariance = out.angular_velocity_covariance
                msg.linear_acceleration_covariance = out.linear_acceleration_covariance
            self._pub_imu.publish(msg)
            if self._pub_rpy is not None and out.rpy_rad is not None:
                rpy = self._rpy_msg
                rpy.header = msg.header
                rpy.vector.x, rpy.vector.y, rpy.vector.z = out.rpy_rad
                self._pub_rpy.publish(rpy)
            if self._pub_accel is not None and out.gravity_free is not None:
                self._publish_accel(msg, out.gravity_free)
            if self._pub_tf is not None:
                self._publish_tf(msg)
        except Exception as exc:  # noqa: BLE001 - never die on one message
            log.error(f"cannot publish the output: {exc}", throttle_duration_sec=LOG_THROTTLE_S)

    def _publish_accel(self, msg: Imu, gravity_free: Any) -> None:
        """imu/linear_acceleration (body axes, imu/data's frame id) and
        imu/linear_acceleration_world (frame id tf_parent_frame): gravity removed."""
        a_b, c_b, a_w, c_w = gravity_free
        for pub, frame, a, c in ((self._pub_accel, msg.header.frame_id, a_b, c_b),
                                 (self._pub_accel_world,
                                  self._pipe.pipeline_params.tf_parent_frame, a_w, c_w)):
            m = self._accel_type()
            m.header.stamp = msg.header.stamp
            m.header.frame_id = frame
            lin = m.accel.accel.linear
            lin.x, lin.y, lin.z = a
            m.accel.covariance = accel_covariance6(c)
            pub.publish(m)

    def _publish_tf(self, msg: Imu) -> None:
        """/tf: tf_parent_frame → the IMU frame (or the reverse), rotation = the orientation."""
        child = msg.header.frame_id.lstrip("/")
        if not child:  # no frame to attach (the pipeline warns about the empty frame_id once)
            return
        pp = self._pipe.pipeline_params
        t = self._tf_msg.transforms[0]
        t.header.stamp = msg.header.stamp
        q = msg.orientation  # q_world_from_sensor: world = parent, sensor = child
        r = t.transform.rotation
        if pp.reverse_tf:  # parent = sensor, child = world: the inverse rotation
            t.header.frame_id, t.child_frame_id = child, pp.tf_parent_frame
            r.x, r.y, r.z, r.w = -q.x, -q.y, -q.z, q.w
        else:
            t.header.frame_id, t.child_frame_id = pp.tf_parent_frame, child
            r.x, r.y, r.z, r.w = q.x, q.y, q.z, q.w
        self._pub_tf.publish(self._tf_msg)

    def _on_mag(self, msg: MagneticField) -> None:
        self._pipe.on_mag(msg)

    def _velocity_type(self, pp: Any) -> Any:
        """TwistStamped or Odometry for velocity_topic: by velocity_topic_type, or ('auto') by
        the type advertised on the graph now (TwistStamped when nobody advertises it yet)."""
        kind = pp.velocity_topic_type
        if kind == "auto":
            name = self.resolve_topic_name(pp.velocity_topic)
            types = dict(self.get_topic_names_and_types()).get(name, [])
            kind = "odometry" if "nav_msgs/msg/Odometry" in types else "twist"
        if kind == "odometry":
            try:
                from nav_msgs.msg import Odometry
            except ImportError:
                raise StartError(
                    "velocity_topic_type odometry needs the nav_msgs package (ROS: apt install "
                    "ros-jazzy-nav-msgs; PyPI wheels: pip install ros-jazzy-nav-msgs)"
                ) from None
            return Odometry
        from geometry_msgs.msg import TwistStamped

        return TwistStamped

    def _on_velocity(self, msg: Any) -> None:
        self._velocity_count += 1
        reason = self._pipe.on_velocity(msg)
        if reason is not None and reason != "too_old":
            self.get_logger().warning(
                f"velocity message rejected: {reason} (counted in /diagnostics)",
                throttle_duration_sec=LOG_THROTTLE_S,
            )

    def _on_diagnostics(self) -> None:
        try:
            self._publish_diagnostics()
        except Exception as exc:  # noqa: BLE001 - a diagnostics bug must not stop the node
            self.get_logger().error(
                f"diagnostics failed: {exc}", throttle_duration_sec=LOG_THROTTLE_S
            )

    def _input_type_problems(self) -> dict[str, str]:
        """``role → one line`` for each input topic that has received nothing and that the
        graph advertises only with another type (WARN once per topic and type)."""
        c = self._pipe.counters
        waiting = [(role, sub) for role, sub, n in (
            ("IMU", self._sub_imu, c["received_imu"]),
            ("magnetometer", self._sub_mag, c["received_mag"]),
            ("velocity", self._sub_vel, self._velocity_count)) if sub is not None and n == 0]
        if not waiting:
            self._type_problems = {}
            return {}
        problems = {}
        for role, sub in waiting:
            cls = sub.msg_type
            expected = f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"
            # the publishers' types (the topic's own list holds this node's subscription too)
            advertised = sorted({i.topic_type for i in
                                 self.get_publishers_info_by_topic(sub.topic_name)})
            text = input_type_problem(role, sub.topic_name, expected, advertised)
            if text:
                problems[role] = text
                if self._type_problems.get(role) != text:
                    self.get_logger().warning(text)
        self._type_problems = problems
        return problems

    def _publish_diagnostics(self) -> None:
        now = self.get_clock().now()
        report = self._pipe.diagnostics(now.nanoseconds * 1e-9)
        problems = self._input_type_problems()
        status = DiagnosticStatus()
        level = max(report.level, 1) if problems and report.level < 2 else report.level
        status.level = bytes([level])  # 'byte' field: bytes of length 1 in rclpy
        status.name = report.name
        status.message = report.message + "".join(f"; {t}" for t in problems.values())
        status.hardware_id = report.hardware_id
        status.values = [KeyValue(key=k, value=v) for k, v in report.values] + [
            KeyValue(key=f"input_type.{role.lower()}", value=text)
            for role, text in problems.items()]
        array = DiagnosticArray()
        array.header.stamp = now.to_msg()
        array.status = [status]
        self._pub_diag.publish(array)
        self._log_events(flush=True)  # what the rate limit held back, now due
        if report.level != self._last_level:
            text = f"status {LEVEL_NAMES.get(report.level, report.level)}: {report.message}"
            if report.level == 0:
                self.get_logger().info(text)
            else:
                self.get_logger().warning(text)
            self._last_level = report.level

    def _on_time_jump(self, jump: Any) -> None:
        back_s = -jump.delta.nanoseconds * 1e-9
        if back_s >= self._pipe.pipeline_params.time_jump_back_threshold_s:
            self._pipe.reset(RESET_CLOCK_JUMP)
            self.get_logger().warning(f"clock jumped back by {back_s:.3f} s: filter reset")
            # said just now: mark it reported (its line would repeat it)
            self._events.update(self._pipe.reset_counts, {},
                                self._steady.now().nanoseconds * 1e-9)
            self._resets_logged = self._pipe.reset_total

    # -- parameters -------------------------------------------------------------------------------
    def _convert_parameters(self, params: list[Any]) -> list[Any]:
        """Before rclpy checks types: an integer for a float parameter (``ros2 param set …
        k1 1``) becomes that float where it is exact, integers for a double array alike; a
        name the node does not have is refused with the nearest one (as at start-up)."""
        from rclpy.parameter import Parameter

        specs = {s.name: s for s in all_specs()}
        out = []
        unknown = []
        for p in params:
            spec = specs.get(p.name)
            if spec is None:
                if (not self.has_parameter(p.name) and p.name not in ROS_STANDARD_PARAMETERS
                        and not p.name.startswith(ROS_STANDARD_PREFIXES)):
                    unknown.append(p.name)
                out.append(p)
                continue
            if spec.kind == "float" and p.type_ == Parameter.Type.INTEGER:
                value = exact_float(p.value)
                if value is not None:
                    p = Parameter(p.name, Parameter.Type.DOUBLE, value)
            elif spec.kind == "float_list" and p.type_ == Parameter.Type.INTEGER_ARRAY:
                values = [exact_float(v) for v in p.value]
                if all(v is not None for v in values):
                    p = Parameter(p.name, Parameter.Type.DOUBLE_ARRAY, values)
            out.append(p)
        if unknown and not self._allow_undeclared_parameters:
            raise UnknownParameter(unknown)
        return out

    def _changes(self, params: list[Any]) -> dict[str, Any]:
        return {p.name: p.value for p in params if p.name in self._names}

    def _validate_parameters(self, params: list[Any]) -> SetParametersResult:
        changes = self._changes(params)
        if not changes:  # use_sim_time, qos_overrides...: not ours to judge
            return SetParametersResult(successful=True)
        ok, reason = self._pipe.validate_changes(changes)
        if ok and self._pub_tf is not None and "tf_parent_frame" in changes:
            pp, fp = self._pipe.pipeline_params, self._pipe.filter_params
            refusal, _ = check_tf_frames(fp.world_frame, pp.body_frame,
                                         str(changes["tf_parent_frame"]), pp.output_frame_id)
            if refusal:  # the start-up refusal holds at run time too
                ok, reason = False, refusal
        if ok and not self._post_set:  # rclpy without post-set callbacks: apply now
            self._apply_parameters(params)
        return SetParametersResult(successful=ok, reason=reason)

    def _apply_parameters(self, params: list[Any]) -> None:
        changes = self._changes(params)
        if not changes:
            return
        ok, reason = self._pipe.apply_changes(changes)
        log = self.get_logger()
        if ok:
            log.info("parameters changed: " + ", ".join(f"{k}={v}" for k, v in changes.items()))
        else:  # validated a moment ago: only a concurrent change could get here
            log.error(f"parameter change not applied: {reason}")


def run(args: list[str]) -> int:
    """Start rclpy with ``args`` (``--ros-args ...``), spin the node until shutdown.

    Returns the exit code: 0 after Ctrl-C / shutdown, 2 when the node cannot start (rclpy
    refuses the arguments or a params file, or a parameter is invalid): one line, no traceback.
    """
    try:
        rclpy.init(args=args)
    except Exception as exc:  # noqa: BLE001 - rclpy raises its C layer's RCLError here
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        print(f"{NODE_NAME}: cannot start: {text}", file=sys.stderr)
        return 2
    from cf_estimator.params_file import params_files

    node = None
    code = 0
    # the executor exists before the node logs that it started: a SIGINT right after that log
    # (launch, a test) must not land inside the executor's construction (rclpy then prints a
    # traceback from SingleThreadedExecutor.__del__ at exit)
    executor = SingleThreadedExecutor()
    try:
        node = CfEstimatorNode(params_files=params_files(args))
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (
        ParameterError, InvalidParameterValueException, InvalidParameterTypeException, StartError
    ) as exc:
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        kind = "cannot start" if isinstance(exc, StartError) else "invalid parameter"
        get_logger(NODE_NAME).fatal(f"{kind}: {text}")
        code = 2
    except RuntimeError:
        # a SIGINT shuts the context down while the executor may be inside a take on a
        # subscription being torn down (rclpy: "Unable to convert call argument"): that is the
        # requested stop, not a failure. With the context still up it is a real error.
        if rclpy.ok():
            raise
    finally:
        # `ros2 launch` signals the node and Ctrl-C the whole process group: a second SIGINT
        # must not interrupt the clean-up (a traceback from destroy_node, "exit code -2")
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            executor.shutdown()
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        except KeyboardInterrupt:
            pass
    return code
