"""The rclpy node, end to end: real topics, real parameter services, a real executor.

Runs on ROS 2 Jazzy's rclpy: a sourced ROS install, or the PyPI wheels that scripts/test.sh
installs. Skipped without rclpy only when the test command could not provide it. Each test uses
its own rclpy context and ROS domain (test/node_harness.py). More live-graph tests:
test/test_node_live.py.
"""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
from live_graph import require

rclpy = require("rclpy")

from node_harness import Harness  # noqa: E402,I001
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile  # noqa: E402
from rosgraph_msgs.msg import Clock as ClockMsg  # noqa: E402
from sensor_msgs.msg import MagneticField  # noqa: E402

from cf_estimator.core.params import FilterParams  # noqa: E402
from cf_estimator.pipeline import PipelineParams  # noqa: E402

T0 = 1_700_000_000
G = 9.80665


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


def test_node_publishes_imu_data_rpy_and_diagnostics(harness):
    got = harness.spin_until(
        lambda: len(harness.received["imu"]) >= 20 and harness.received["rpy"]
        and harness.received["diag"],
        publish=lambda: harness.imu_pub.publish(harness.imu()),
    )
    assert got, "no imu/data, imu/rpy or /diagnostics output"
    out = harness.received["imu"][-1]
    q = out.orientation
    assert abs(q.w) == pytest.approx(1.0, abs=1e-6)  # level, no magnetometer: identity
    assert out.orientation_covariance[0] == pytest.approx(
        PipelineParams().orientation_covariance_rad2
    )
    assert out.linear_acceleration_covariance[0] == pytest.approx(0.5)  # copied from the input
    assert out.header.frame_id == "imu_link"
    rpy = harness.received["rpy"][-1]
    assert abs(rpy.vector.x) < 1e-6 and abs(rpy.vector.y) < 1e-6
    status = harness.received["diag"][-1].status[0]
    assert "cf_estimator" in status.name
    assert status.level in (b"\x00", b"\x01")  # OK, or WARN: use_mag true but no magnetometer
    keys = {kv.key for kv in status.values}
    assert {"imu_received", "input_rate_hz", "gyro_bias_x_rad_s", "mag_used"} <= keys


def test_upside_down_imu_gives_roll_pi_on_imu_rpy(harness):
    assert harness.spin_until(
        lambda: len(harness.received["rpy"]) >= 5,
        publish=lambda: harness.imu_pub.publish(harness.imu(accel=(0.0, 0.0, -G))),
    )
    assert abs(harness.received["rpy"][-1].vector.x) == pytest.approx(math.pi, abs=1e-6)


def test_parameters_are_declared_with_descriptors(harness):
    node = harness.node
    k1 = node.describe_parameter("k1")
    assert "[1/s]" in k1.description
    assert k1.floating_point_range[0].from_value == 0.0
    assert k1.floating_point_range[0].to_value == 100.0
    assert node.describe_parameter("world_frame").read_only
    assert "enu" in node.describe_parameter("world_frame").additional_constraints
    assert node.get_parameter("mag_timeout_s").value == PipelineParams().mag_timeout_s


def test_live_parameter_change_is_applied_and_keeps_the_attitude(harness):
    assert harness.spin_until(
        lambda: len(harness.received["imu"]) >= 20,
        publish=lambda: harness.imu_pub.publish(harness.imu(gyro=(0.0, 0.0, 0.3))),
    )
    before = harness.pipe.filter.orientation_tuple()
    result = harness.node.set_parameters([Parameter("k1", value=0.7)])[0]
    assert result.successful, result.reason
    assert harness.pipe.filter_params.k1 == 0.7
    assert harness.pipe.filter.orientation_tuple() == before


def test_invalid_parameters_are_rejected_with_a_reason_through_the_service(harness):
    client = harness.helper.create_client(SetParameters, "/cf_estimator/set_parameters")
    assert client.wait_for_service(timeout_sec=10.0)
    pipe = harness.pipe
    params_before = (pipe.filter_params, pipe.pipeline_params)
    for param, words in [
        (Parameter("saturation_limit_rad", value=0.0), "saturation_limit_rad"),
        (Parameter("aperiodic_time_constant_s", value=500.0), "unstable"),
        (Parameter("k1", value=-1.0), "k1"),
        (Parameter("world_frame", value="ned"), "read-only"),
    ]:
        request = SetParameters.Request()
        request.parameters = [param.to_parameter_msg()]
        future = client.call_async(request)
        assert harness.spin_until(future.done)
        result = future.result().results[0]
        assert not result.successful and words in result.reason, result.reason
    assert (pipe.filter_params, pipe.pipeline_params) == params_before
    assert (harness.node.get_parameter("saturation_limit_rad").value
            == FilterParams().saturation_limit_rad)


def test_bad_messages_are_counted_and_the_node_lives_on(harness):
    """NaN gyro, good, NaN magnetometer, in turn; each message is published only once the node
    has counted the previous one, so no queue depth (or its parity) decides which arrive."""
    assert harness.wait_connected()
    pipe = harness.pipe
    for _ in range(5):
        assert harness.publish_one(harness.imu(gyro=(float("nan"), 0.0, 0.0)))
        assert harness.publish_one(harness.imu())
        mag = MagneticField()
        mag.header.stamp.sec = T0
        mag.magnetic_field.x = float("nan")
        before = pipe.counters["received_mag"]
        harness.mag_pub.publish(mag)
        assert harness.spin_until(lambda b=before: pipe.counters["received_mag"] > b)
    c = pipe.counters
    assert c["rejected"].get("nonfinite_gyro", 0) == 5
    assert c["mag_invalid"] == 5
    assert c["received_imu"] == c["processed"] + sum(c["rejected"].values()) == 10
    assert harness.spin_until(lambda: len(harness.received["imu"]) >= 5)  # still publishing


def test_sim_time_rewind_resets_the_filter():
    h = Harness(parameter_overrides=[Parameter("use_sim_time", value=True)])
    try:
        clock_pub = h.helper.create_publisher(ClockMsg, "/clock", QoSProfile(depth=10))
        pipe = h.pipe

        def clock(sec):
            msg = ClockMsg()
            msg.clock.sec = sec
            clock_pub.publish(msg)

        assert h.spin_until(lambda: h.node.get_clock().now().nanoseconds >= 100 * 10**9,
                            publish=lambda: clock(100))
        assert h.spin_until(lambda: pipe.counters["resets"].get("clock_jump_back", 0) >= 1,
                            publish=lambda: clock(10))
    finally:
        h.close()


def test_invalid_parameter_at_start_exits_with_one_line_error():
    proc = subprocess.run(
        [sys.executable, "-m", "cf_estimator.node.cf_estimator_node",
         "--ros-args", "-p", "saturation_limit_rad:=0.0"],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2
    assert "saturation_limit_rad" in proc.stderr + proc.stdout
    assert "Traceback" not in proc.stderr


def test_an_unexpected_exception_is_logged_once_with_its_traceback_and_counted(harness,
                                                                               monkeypatch):
    """A bug in the filter (here: a step over the rows that raises) drops the message, counts
    ``internal_error`` and logs the traceback once, not once per message; the node goes on."""
    assert harness.wait_connected()
    assert harness.publish_one(harness.imu())  # initialised
    errors: list[str] = []
    real_logger = harness.node.get_logger()

    class Logger:
        def error(self, text, **_kw):
            errors.append(text)

        def __getattr__(self, name):
            return getattr(real_logger, name)

    monkeypatch.setattr(harness.node, "get_logger", lambda: Logger())
    f = harness.pipe._filter  # noqa: SLF001

    def broken(*_a, **_k):
        raise ZeroDivisionError("a bug in the step")

    monkeypatch.setattr(f, "run_rows", broken)
    for _ in range(3):
        assert harness.publish_one(harness.imu())
    assert harness.pipe.counters["rejected"].get("internal_error") == 3
    assert len(errors) == 1
    assert "Traceback" in errors[0] and "ZeroDivisionError: a bug in the step" in errors[0]
    monkeypatch.undo()
    published = len(harness.received["imu"])
    assert harness.publish_one(harness.imu())
    assert harness.spin_until(lambda: len(harness.received["imu"]) > published)
