"""The node under test and a helper node on one executor, in their own context and ROS domain.

Import only after :func:`live_graph.require` found rclpy (this module imports it).
"""

from __future__ import annotations

from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
from live_graph import T0_S, TIMEOUT_S, imu_message, next_domain_id, wait_for
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Imu, MagneticField

from cf_estimator.node.node import CfEstimatorNode


class Harness:
    """``CfEstimatorNode(**node_kwargs)``, a helper node publishing ``imu_topic``/``mag_topic``
    and recording ``out_topic``, ``rpy_topic`` and /diagnostics, one single-threaded executor."""

    def __init__(
        self,
        *,
        imu_topic: str = "imu/data_raw",
        mag_topic: str = "imu/mag",
        out_topic: str = "imu/data",
        rpy_topic: str = "imu/rpy",
        input_reliable: bool = False,
        output_best_effort: bool = False,
        **node_kwargs: Any,
    ) -> None:
        self.domain_id = next_domain_id()
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=self.domain_id)
        self.node = CfEstimatorNode(context=self.context, **node_kwargs)
        self.helper = rclpy.create_node("cf_estimator_test_helper", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.executor.add_node(self.helper)
        in_qos = QoSProfile(depth=100) if input_reliable else qos_profile_sensor_data
        self.imu_pub = self.helper.create_publisher(Imu, imu_topic, in_qos)
        self.mag_pub = self.helper.create_publisher(MagneticField, mag_topic, in_qos)
        out_qos = QoSProfile(depth=1000)
        if output_best_effort:
            out_qos.reliability = ReliabilityPolicy.BEST_EFFORT
        self.received: dict[str, list] = {"imu": [], "rpy": [], "diag": []}
        self.helper.create_subscription(Imu, out_topic, self.received["imu"].append, out_qos)
        self.helper.create_subscription(
            Vector3Stamped, rpy_topic, self.received["rpy"].append, out_qos
        )
        self.helper.create_subscription(
            DiagnosticArray, "/diagnostics", self.received["diag"].append, QoSProfile(depth=100)
        )
        self.k = 0

    @property
    def pipe(self) -> Any:
        """The node's pipeline (counters, parameters in force)."""
        return self.node._pipe  # noqa: SLF001 - the tests read it, never drive it

    def imu(self, accel=(0.0, 0.0, 9.80665), gyro=(0.0, 0.0, 0.0), stamp_ns: int | None = None,
            frame_id: str = "imu_link") -> Imu:
        """The next IMU message (100 Hz stamps unless ``stamp_ns``)."""
        t = stamp_ns if stamp_ns is not None else T0_S * 10**9 + self.k * 10_000_000
        self.k += 1
        return imu_message(Imu, t, gyro, accel, frame_id)

    def spin(self) -> None:
        self.executor.spin_once(timeout_sec=0.02)

    def spin_until(self, predicate, timeout: float = TIMEOUT_S, publish=None) -> bool:
        return wait_for(predicate, self.spin, timeout, publish)

    def wait_connected(self) -> bool:
        """The node's IMU subscription and the helper's output subscription are matched."""
        return self.spin_until(lambda: self.imu_pub.get_subscription_count() >= 1
                               and self.node._pub_imu.get_subscription_count() >= 1)  # noqa: SLF001

    def publish_one(self, msg: Imu, timeout: float = 5.0) -> bool:
        """Publish one IMU message and spin until the node counted it (one message in flight:
        no queue can overflow, whatever its depth)."""
        before = self.pipe.counters["received_imu"]
        self.imu_pub.publish(msg)
        return self.spin_until(lambda: self.pipe.counters["received_imu"] > before, timeout)

    def close(self) -> None:
        self.executor.shutdown()
        self.helper.destroy_node()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)
