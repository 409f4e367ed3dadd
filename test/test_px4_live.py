"""The node on px4_msgs in a live ROS 2 graph: real px4_msgs types over real DDS, own graph each.

PX4's uXRCE-DDS bridge publishes /fmu/out/* best effort, transient local, keep last: the
helper publishes SensorCombined / VehicleMagnetometer / VehicleLocalPosition exactly so, at
250 Hz stamps (µs since boot). px4_msgs is built from ../shared/px4_msgs by scripts/test.sh
(scripts/build_msgs.py), which sets CF_ESTIMATOR_REQUIRE_PX4_MSGS=1 so these tests cannot skip
silently there; elsewhere they skip without px4_msgs.
"""

from __future__ import annotations

import math
import os
import sys

import pytest
from live_graph import next_domain_id, require

rclpy = require("rclpy")
px4_msgs = require("px4_msgs.msg", required=os.environ.get("CF_ESTIMATOR_REQUIRE_PX4_MSGS") == "1",
                   hint=" (build it: python3 scripts/build_msgs.py ../shared/px4_msgs)")

from node_harness import Harness  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import (  # noqa: E402
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)

from cf_estimator.node.node import CfEstimatorNode, StartError  # noqa: E402
from cf_estimator.node.px4_input import MISSING  # noqa: E402

G = 9.80665
BOOT_US = 123_000_000  # PX4's clock: µs since boot
PX4_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=5,
                     reliability=ReliabilityPolicy.BEST_EFFORT,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Px4Graph:
    """The node with ``input_type: px4`` and a helper publishing PX4's topics with PX4's QoS."""

    def __init__(self, prefix: str = "/fmu/out", extra: list | None = None) -> None:
        overrides = [Parameter("input_type", value="px4")]
        if prefix != "/fmu/out":
            overrides.append(Parameter("px4_topic_prefix", value=prefix))
        self.h = Harness(parameter_overrides=overrides + (extra or []))
        helper = self.h.helper
        self.imu_pub = helper.create_publisher(px4_msgs.SensorCombined,
                                               f"{prefix}/sensor_combined", PX4_QOS)
        self.mag_pub = helper.create_publisher(px4_msgs.VehicleMagnetometer,
                                               f"{prefix}/vehicle_magnetometer", PX4_QOS)
        self.vel_pub = helper.create_publisher(px4_msgs.VehicleLocalPosition,
                                               f"{prefix}/vehicle_local_position", PX4_QOS)
        self.k = 0

    def sensor_combined(self, roll_deg: float) -> px4_msgs.SensorCombined:
        """At rest, rolled by ``roll_deg`` (FRD), the next 250 Hz stamp."""
        m = px4_msgs.SensorCombined()
        m.timestamp = BOOT_US + self.k * 4000
        self.k += 1
        r = math.radians(roll_deg)
        m.accelerometer_m_s2 = [0.0, -G * math.sin(r), -G * math.cos(r)]
        m.gyro_rad = [0.0, 0.0, 0.0]
        m.accelerometer_timestamp_relative = 0
        return m

    def connected(self) -> bool:
        return self.h.spin_until(lambda: self.imu_pub.get_subscription_count() >= 1
                                 and self.h.node._pub_imu.get_subscription_count() >= 1)  # noqa: SLF001

    def publish_one(self, msg, publisher=None, counter: str = "received_imu") -> bool:
        """Publish one message and spin until the node counted it (one in flight)."""
        before = self.h.pipe.counters[counter]
        (publisher or self.imu_pub).publish(msg)
        return self.h.spin_until(lambda: self.h.pipe.counters[counter] > before, 10.0)

    def close(self) -> None:
        self.h.close()


@pytest.fixture
def graph():
    g = Px4Graph()
    yield g
    g.close()


def test_sensor_combined_at_250_hz_with_px4_qos_reads_10_deg_roll(graph):
    g = graph
    node = g.h.node
    assert node.get_parameter("world_frame").value == "ned"  # PX4's conventions by default
    assert node.get_parameter("body_frame").value == "frd"
    sub = node._px4.sub_imu  # noqa: SLF001
    assert sub.topic_name == "/fmu/out/sensor_combined"
    assert sub.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT
    assert sub.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
    assert g.connected()
    for _ in range(300):  # 1.2 s of 250 Hz stamps
        assert g.publish_one(g.sensor_combined(10.0))
    assert g.h.spin_until(lambda: len(g.h.received["rpy"]) >= 300)
    last = g.h.received["rpy"][-1]
    assert math.degrees(last.vector.x) == pytest.approx(10.0, abs=0.2)  # +10 deg roll, FRD->NED
    assert math.degrees(last.vector.y) == pytest.approx(0.0, abs=0.2)
    out = g.h.received["imu"][-1]
    assert out.header.frame_id == "base_link_frd"
    # stamped with PX4's time since boot (the log's clock), the 300th message's
    assert out.header.stamp.sec * 10**9 + out.header.stamp.nanosec == (BOOT_US + 299 * 4000) * 1000
    assert g.h.pipe.counters["rejected"] == {} or sum(g.h.pipe.counters["rejected"].values()) == 0


def test_a_reliable_subscriber_receives_nothing_from_px4_publishers(graph):
    g = graph
    got: list = []
    g.h.helper.create_subscription(px4_msgs.SensorCombined, "/fmu/out/sensor_combined",
                                   got.append, QoSProfile(depth=10))  # reliable: PX4-incompatible
    assert g.connected()
    for _ in range(50):
        assert g.publish_one(g.sensor_combined(0.0))  # the node (best effort) receives them
    for _ in range(20):
        g.h.spin()
    assert got == []


def test_magnetometer_in_gauss_and_accel_invalid_rows(graph):
    g = graph
    assert g.h.spin_until(lambda: g.mag_pub.get_subscription_count() >= 1)
    m = px4_msgs.VehicleMagnetometer()
    m.timestamp = m.timestamp_sample = BOOT_US
    m.magnetometer_ga = [0.2, 0.0, 0.35]
    assert g.publish_one(m, g.mag_pub, "received_mag")
    bad = g.sensor_combined(0.0)
    bad.accelerometer_timestamp_relative = px4_msgs.SensorCombined.RELATIVE_TIMESTAMP_INVALID
    before = g.h.pipe.counters["received_imu"]
    g.imu_pub.publish(bad)
    assert g.connected()
    assert g.publish_one(g.sensor_combined(0.0))
    assert g.h.pipe.counters["received_imu"] == before + 1  # the invalid row was skipped


def test_prefix_for_a_second_vehicle_and_local_position_for_aiding():
    g = Px4Graph("/px4_1/fmu/out", [Parameter("px4_local_position", value=True)])
    try:
        topics = g.h.node._px4.topics  # noqa: SLF001
        assert topics == ["/px4_1/fmu/out/sensor_combined", "/px4_1/fmu/out/vehicle_magnetometer",
                          "/px4_1/fmu/out/vehicle_local_position"]
        assert g.connected()
        assert g.publish_one(g.sensor_combined(0.0))
        assert g.h.spin_until(lambda: g.vel_pub.get_subscription_count() >= 1)
        invalid = px4_msgs.VehicleLocalPosition()
        invalid.timestamp = invalid.timestamp_sample = BOOT_US
        invalid.vx, invalid.v_xy_valid, invalid.v_z_valid = 5.0, False, True
        g.vel_pub.publish(invalid)  # not valid: never reaches the aiding
        v = px4_msgs.VehicleLocalPosition()
        v.timestamp = v.timestamp_sample = BOOT_US + 4000
        v.vx, v.vy, v.vz = 1.0, 2.0, 0.0
        v.v_xy_valid = v.v_z_valid = True
        g.vel_pub.publish(v)
        pipe = g.h.pipe
        assert g.h.spin_until(lambda: pipe.velocity_aiding is not None
                              and pipe.velocity_aiding.status().received >= 1)
        for _ in range(10):
            g.h.spin()
        assert pipe.velocity_aiding.status().received == 1
    finally:
        g.close()


def test_world_frame_override_wins_over_px4_defaults():
    g = Px4Graph(extra=[Parameter("world_frame", value="enu")])
    try:
        assert g.h.node.get_parameter("world_frame").value == "enu"
        assert g.h.node.get_parameter("body_frame").value == "frd"  # the data stays FRD
        assert g.connected()
        for _ in range(100):
            assert g.publish_one(g.sensor_combined(10.0))
        assert g.h.spin_until(lambda: len(g.h.received["rpy"]) >= 100)
        # FLU -> ENU (REP-103): the same right-wing-down tilt is +10 deg roll there too
        assert math.degrees(g.h.received["rpy"][-1].vector.x) == pytest.approx(10.0, abs=0.2)
    finally:
        g.close()


def test_without_px4_msgs_the_node_says_what_to_build(monkeypatch):
    monkeypatch.setitem(sys.modules, "px4_msgs", None)
    monkeypatch.setitem(sys.modules, "px4_msgs.msg", None)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=next_domain_id())
    try:
        with pytest.raises(StartError) as exc:
            CfEstimatorNode(context=context,
                            parameter_overrides=[Parameter("input_type", value="px4")])
        assert str(exc.value) == MISSING
        assert "px4_msgs" in MISSING and "build" in MISSING and "\n" not in MISSING
    finally:
        rclpy.shutdown(context=context)
