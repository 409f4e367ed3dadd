"""What imu_filter_madgwick users write (issue 52): live integers for float parameters, live
misspelt and madgwick names, madgwick's parameter files and mag_bias_*, a magnetometer that
stops; and the node's gravity-free acceleration topics. The node runs in its own context and
ROS domain (test/node_harness.py)."""

from __future__ import annotations

import pytest
from live_graph import require

rclpy = require("rclpy")

from geometry_msgs.msg import AccelWithCovarianceStamped  # noqa: E402,I001
from node_harness import Harness  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402

from cf_estimator.params_file import load_params_file  # noqa: E402
from cf_estimator.pipeline import ImuPipeline  # noqa: E402
from cf_estimator.schema import ParameterError  # noqa: E402
from pipeline_messages import imu_msg, mag_msg  # noqa: E402


def _set(h: Harness, param: Parameter):
    client = h.helper.create_client(SetParameters, "/cf_estimator/set_parameters")
    assert client.wait_for_service(timeout_sec=10.0)
    request = SetParameters.Request()
    request.parameters = [param.to_parameter_msg()]
    future = client.call_async(request)
    assert h.spin_until(future.done)
    return future.result().results[0]


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def test_ros2_param_set_an_integer_for_a_float_is_accepted_as_that_float(harness):
    result = _set(harness, Parameter("k1", value=1))
    assert result.successful, result.reason
    assert harness.node.get_parameter("k1").value == 1.0
    assert isinstance(harness.node.get_parameter("k1").value, float)
    assert harness.pipe.filter_params.k1 == 1.0
    result = _set(harness, Parameter("mag_hard_iron_t", value=[0, 0, 0]))
    assert result.successful, result.reason
    result = _set(harness, Parameter("k1", value=2**60))  # not exact as a double: refused
    assert not result.successful
    assert harness.pipe.filter_params.k1 == 1.0


def test_a_live_misspelt_or_madgwick_name_gets_ours(harness):
    result = _set(harness, Parameter("k_1", value=0.5))
    assert not result.successful and "did you mean 'k1'" in result.reason, result.reason
    result = _set(harness, Parameter("gain", value=0.1))
    assert not result.successful and "ours is 'k1'" in result.reason, result.reason


def test_madgwick_mag_bias_overrides_are_the_hard_iron():
    h = Harness(parameter_overrides=[Parameter("mag_bias_x", value=1e-5),
                                     Parameter("mag_bias_z", value=-2e-6)])
    try:
        assert h.pipe.pipeline_params.mag_hard_iron_t == (1e-5, 0.0, -2e-6)
    finally:
        h.close()


def test_node_publishes_gravity_free_acceleration_when_asked():
    h = Harness(parameter_overrides=[Parameter("publish_linear_acceleration", value=True)])
    try:
        got = {"body": [], "world": []}
        h.helper.create_subscription(AccelWithCovarianceStamped, "imu/linear_acceleration",
                                     got["body"].append, QoSProfile(depth=100))
        h.helper.create_subscription(AccelWithCovarianceStamped,
                                     "imu/linear_acceleration_world", got["world"].append,
                                     QoSProfile(depth=100))
        assert h.wait_connected()
        assert h.spin_until(lambda: h.node._pub_accel.get_subscription_count() >= 1)  # noqa: SLF001
        for _ in range(30):
            assert h.publish_one(h.imu(accel=(0.0, 0.0, 9.80665 + 1.0)))  # 1 m/s^2 up
        assert h.spin_until(lambda: len(got["body"]) >= 20 and len(got["world"]) >= 20)
        body, world = got["body"][-1], got["world"][-1]
        assert world.header.frame_id == "world" and body.header.frame_id == "imu_link"
        assert world.accel.accel.linear.z == pytest.approx(1.0, abs=1e-6)
        assert body.accel.accel.linear.z == pytest.approx(1.0, abs=1e-6)
        assert world.accel.covariance[0] > 0.0 and world.accel.covariance[21] == -1.0
    finally:
        h.close()


# -- without a ROS graph --------------------------------------------------------------------------
def test_a_madgwick_file_gets_a_hint_naming_ours(tmp_path):
    f = tmp_path / "madgwick.yaml"
    f.write_text("imu_filter:\n  ros__parameters:\n    gain: 0.1\n")
    with pytest.raises(ParameterError, match="imu_filter_madgwick's node.*gain -> k1"):
        load_params_file(f)
    g = tmp_path / "names.yaml"
    g.write_text("/**:\n  ros__parameters:\n    zeta: 0.01\n")
    with pytest.raises(ParameterError, match="'zeta' \\(imu_filter_madgwick's name; ours is 'k2'"):
        load_params_file(g)
    b = tmp_path / "bias.yaml"
    b.write_text("/**:\n  ros__parameters:\n    mag_bias_x: 1.0e-5\n    mag_bias_y: -3.0e-6\n")
    _, pp, warnings = load_params_file(b)
    assert pp.mag_hard_iron_t == (1e-5, -3e-6, 0.0)
    assert any("mag_hard_iron_t" in w for w in warnings)


def test_a_magnetometer_that_stops_is_diagnosed_as_stopped_not_as_a_magnet():
    pipe = ImuPipeline()
    t = 0
    for k in range(300):  # 3 s with the compass at 100 Hz
        t = 1_000_000_000 + k * 10_000_000
        pipe.on_mag(mag_msg(t))
        pipe.on_imu(imu_msg(t))
    report = pipe.diagnostics()
    assert "stopped" not in report.message
    for k in range(300, 600):  # the compass stops, the IMU goes on
        pipe.on_imu(imu_msg(1_000_000_000 + k * 10_000_000))
    report = pipe.diagnostics()
    assert "magnetometer stopped" in report.message, report.message
    assert "moves with the sensor" not in report.message
    assert ("mag_stopped", "true") in report.values
