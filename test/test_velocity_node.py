"""Velocity aiding in the live node: TwistStamped and Odometry over real DDS (issue 17)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from live_graph import require

rclpy = require("rclpy")

from geometry_msgs.msg import TwistStamped  # noqa: E402,I001
from node_harness import Harness  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402

from cf_estimator.core import quaternion as quat  # noqa: E402
from cf_estimator.metrics import tilt_error_rad  # noqa: E402
from cf_estimator.scenarios import make_scenario  # noqa: E402
from cf_estimator.scenarios.velocity_sensor import VelocityModel, measure_velocity  # noqa: E402

T0_NS = 1_700_000_000 * 10**9


@pytest.fixture(scope="module")
def flight():
    """40 s of the multirotor flight at 200 Hz and a 10 Hz, 0.1 m/s, 100 ms GNSS velocity."""
    sc = make_scenario("uav", duration_s=40.0, seed=3)
    vd = measure_velocity(sc.truth, VelocityModel(10.0, 0.1, 0.1), np.random.default_rng(0))
    return sc, vd


def _stamp(msg, t_s: float) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(T0_NS + round(t_s * 1e9), 10**9)


def _play(h: Harness, sc, vd, make_velocity) -> list:
    """Publish IMU and velocity messages in arrival order (velocity at stamp + latency), one in
    flight at a time; returns the node's orientations (w, x, y, z) per IMU message."""
    vel_pub = h.helper.create_publisher(type(make_velocity(0)), "gnss/vel",
                                        qos_profile_sensor_data)
    assert h.spin_until(lambda: vel_pub.get_subscription_count() >= 1
                        and h.imu_pub.get_subscription_count() >= 1)
    assert h.wait_connected()
    imu = sc.imu
    jv = 0
    for k in range(imu.n_samples):
        t = float(imu.t_s[k])
        while jv < len(vd.t_s) and vd.arrival_s[jv] <= t:
            before = h.pipe.velocity_aiding.status().received if h.pipe.velocity_aiding else 0
            vel_pub.publish(make_velocity(jv))
            assert h.spin_until(lambda b=before: h.pipe.velocity_aiding is not None
                                and h.pipe.velocity_aiding.status().received > b, 5.0)
            jv += 1
        msg = h.imu(accel=tuple(imu.accel_m_s2[k]), gyro=tuple(imu.gyro_rad_s[k]),
                    stamp_ns=T0_NS + round(t * 1e9))
        assert h.publish_one(msg)
    assert h.spin_until(lambda: len(h.received["imu"]) >= imu.n_samples - 5)
    return h.received["imu"]


def _tilt_rms_deg(sc, outs) -> float:
    stamps = np.array([o.header.stamp.sec + o.header.stamp.nanosec * 1e-9 for o in outs])
    q = np.array([(o.orientation.w, o.orientation.x, o.orientation.y, o.orientation.z)
                  for o in outs])
    k = np.clip(np.searchsorted(sc.imu.t_s, stamps - T0_NS * 1e-9 - 1e-6), 0, sc.imu.n_samples - 1)
    e = np.degrees(tilt_error_rad(q, sc.truth.q_world_from_body[k]))
    return float(np.sqrt(np.mean(e[sc.imu.t_s[k] >= 10.0] ** 2)))


def test_node_aided_by_twist_stamped_velocity(flight):
    sc, vd = flight

    def twist(j: int) -> TwistStamped:
        m = TwistStamped()
        _stamp(m, float(vd.t_s[j]))
        m.header.frame_id = "map"
        m.twist.linear.x, m.twist.linear.y, m.twist.linear.z = map(float, vd.v_world_m_s[j])
        return m

    h = Harness(parameter_overrides=[Parameter("velocity_topic", value="gnss/vel"),
                                     Parameter("use_mag", value=False)])
    try:
        assert h.node._sub_vel.msg_type is TwistStamped  # noqa: SLF001 - auto: not advertised
        outs = _play(h, sc, vd, twist)
        st = h.pipe.velocity_aiding.status()
        assert st.used > 0.9 * len(vd.t_s)
        assert st.aided_samples > 0.5 * sc.imu.n_samples
        assert st.heading_known
        report = h.pipe.diagnostics()
        values = dict(report.values)
        assert values["velocity_aiding"] == "aided"
        assert int(values["velocity_used"]) == st.used
        assert math.isfinite(float(values["velocity_heading_offset_rad"]))
        aided_rms = _tilt_rms_deg(sc, outs)
    finally:
        h.close()
    # the same flight without velocity, through the node too
    h = Harness(parameter_overrides=[Parameter("use_mag", value=False)])
    try:
        assert h.node._sub_vel is None  # noqa: SLF001
        assert h.wait_connected()
        for k in range(sc.imu.n_samples):
            assert h.publish_one(h.imu(accel=tuple(sc.imu.accel_m_s2[k]),
                                       gyro=tuple(sc.imu.gyro_rad_s[k]),
                                       stamp_ns=T0_NS + round(float(sc.imu.t_s[k]) * 1e9)))
        assert h.spin_until(lambda: len(h.received["imu"]) >= sc.imu.n_samples - 5)
        unaided_rms = _tilt_rms_deg(sc, h.received["imu"])
    finally:
        h.close()
    assert aided_rms < 0.6 * unaided_rms


def test_node_aided_by_odometry_with_body_frame_twist_and_a_wrong_frame_rejected(flight):
    from nav_msgs.msg import Odometry

    sc, vd = flight

    def odom(j: int) -> Odometry:
        m = Odometry()
        _stamp(m, float(vd.t_s[j]))
        m.header.frame_id = "odom" if j % 50 else "elsewhere"  # every 50th: the wrong frame
        m.child_frame_id = "base_link"
        t = float(vd.t_s[j])
        k = int(np.searchsorted(sc.truth.t_s, t))
        q = sc.truth.q_world_from_body[min(k, sc.truth.n_samples - 1)]
        o = m.pose.pose.orientation
        o.w, o.x, o.y, o.z = map(float, q)
        vb = quat.rotate(quat.conjugate(q), vd.v_world_m_s[j])  # twist in the body frame
        m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.linear.z = map(float, vb)
        return m

    h = Harness(parameter_overrides=[Parameter("velocity_topic", value="gnss/vel"),
                                     Parameter("velocity_topic_type", value="odometry"),
                                     Parameter("velocity_frame_id", value="odom"),
                                     Parameter("use_mag", value=False)])
    try:
        assert h.node._sub_vel.msg_type is Odometry  # noqa: SLF001
        _play(h, sc, vd, odom)
        st = h.pipe.velocity_aiding.status()
        assert st.rejected["frame"] == len(range(0, len(vd.t_s), 50))
        assert st.used > 0.9 * len(vd.t_s)
        assert st.heading_known and st.aided_samples > 0.5 * sc.imu.n_samples
    finally:
        h.close()
