"""The node in a live ROS 2 graph: real rclpy, real DDS (this machine only), own context each.

``main()`` with the shipped params file and with unusable ones; namespace and remaps; QoS
compatibility both ways; ``use_sim_time``; the parameter services; diagnostics keys and levels;
5 000 hostile messages over DDS; TF. The launch file itself needs ``launch`` (not on PyPI):
test/test_launch.py checks it statically.
"""

from __future__ import annotations

import math
import random
import signal
import subprocess
from pathlib import Path

import pytest
from live_graph import (
    REQUIRE_TF2_MSGS,
    T0_S,
    TIMEOUT_S,
    imu_message,
    next_domain_id,
    node_process,
    require,
    wait_for,
)

rclpy = require("rclpy")

from node_harness import Harness  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.parameter_client import AsyncParameterClient  # noqa: E402
from rclpy.qos import QoSProfile, qos_profile_sensor_data  # noqa: E402
from rosgraph_msgs.msg import Clock as ClockMsg  # noqa: E402
from sensor_msgs.msg import Imu, MagneticField  # noqa: E402

from cf_estimator.core.params import FilterParams  # noqa: E402
from cf_estimator.node.node import IMU_QUEUE_DEPTH  # noqa: E402
from cf_estimator.params_file import all_specs  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "config" / "cf_estimator.yaml"
#: Diagnostics values that are not numbers (every other value must parse as a float).
TEXT_KEYS = {"world_frame", "filter_backend", "initialized", "phase", "at_rest", "use_mag",
             "heading_referenced", "gyro_bias_converged", "heading_rate_unverified",
             "heading_recovering", "heading_source", "mag_disturbance", "mag_stopped",
             "bias_hypothesis"}


def _graph(domain_id: int):
    """A context, a helper node and an executor on ``domain_id`` (for a node in a process)."""
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node("cf_estimator_probe", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    return context, node, executor


def _close(context, node, executor) -> None:
    executor.shutdown()
    node.destroy_node()
    rclpy.shutdown(context=context)


def _stop(proc: subprocess.Popen) -> tuple[int, str, str]:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
    return proc.returncode, out, err


# -- main(): the console script ------------------------------------------------------------------
def test_main_with_the_shipped_params_file_publishes_and_stops_cleanly_on_sigint():
    domain = next_domain_id()
    proc = node_process(["--ros-args", "--params-file", str(SHIPPED)], domain)
    context, probe, executor = _graph(domain)
    try:
        got: list = []
        probe.create_subscription(Imu, "/imu/data", got.append, QoSProfile(depth=100))
        pub = probe.create_publisher(Imu, "/imu/data_raw", qos_profile_sensor_data)
        k = [0]

        def publish():
            k[0] += 1
            pub.publish(imu_message(Imu, T0_S * 10**9 + k[0] * 10_000_000))

        assert wait_for(lambda: len(got) >= 10 or proc.poll() is not None,
                        lambda: executor.spin_once(timeout_sec=0.02), 60.0, publish)
        assert proc.poll() is None, "the node exited"
        assert got[-1].orientation_covariance[0] > 0.0  # initialised output
    finally:
        _close(context, probe, executor)
        code, out, err = _stop(proc)
    assert code == 0, err
    assert "Traceback" not in err
    assert "filter step:" in out + err  # the kernel backend in the start-up log


class _SpinTornDownBySigint(SingleThreadedExecutor):
    """An executor whose spin meets what a SIGINT during a take gives: context down, rclpy error."""

    shut_down_first = True

    def spin(self) -> None:
        if self.shut_down_first:
            rclpy.shutdown()
        raise RuntimeError("Unable to convert call argument '0' to Python object")


@pytest.mark.parametrize("shut_down_first", [True, False], ids=["after-sigint", "while-running"])
def test_an_rclpy_error_during_the_sigint_shutdown_is_a_clean_stop_and_only_then(
        monkeypatch, shut_down_first):
    from cf_estimator.node import node as node_module

    monkeypatch.setenv("ROS_DOMAIN_ID", str(next_domain_id()))
    monkeypatch.setattr(_SpinTornDownBySigint, "shut_down_first", shut_down_first)
    monkeypatch.setattr(node_module, "SingleThreadedExecutor", _SpinTornDownBySigint)
    monkeypatch.setattr(node_module.signal, "signal", lambda *_: None)  # keep pytest's SIGINT
    args = ["--ros-args", "--params-file", str(SHIPPED)]
    if shut_down_first:
        assert node_module.run(args) == 0
    else:
        with pytest.raises(RuntimeError, match="Unable to convert"):
            node_module.run(args)
    assert not rclpy.ok()  # the default context is shut down either way


BAD_FILES = [
    ("syntax.yaml", "/**:\n  ros__parameters:\n    k1: [0.5\n", ["not valid YAML", "line"]),
    ("list.yaml", "- k1\n- 0.5\n", ["not a ROS 2 parameter file"]),
    ("use_mag_int.yaml", "/**:\n  ros__parameters:\n    use_mag: 1\n",
     ["use_mag", "true or false"]),
    ("k1_int.yaml", "/**:\n  ros__parameters:\n    k1: 1\n", ["k1", "decimal point"]),
    ("k1_range.yaml", "/**:\n  ros__parameters:\n    k1: -1.0\n", ["k1"]),
    ("sat.yaml", "/**:\n  ros__parameters:\n    saturation_limit_rad: 0.0\n",
     ["saturation_limit_rad"]),
    ("frame.yaml", "/**:\n  ros__parameters:\n    tf_parent_frame: ''\n", ["tf_parent_frame"]),
    (None, "", ["cannot read"]),  # a file that does not exist
]


@pytest.mark.parametrize(("name", "text", "words"), BAD_FILES,
                         ids=[n or "missing" for n, _, _ in BAD_FILES])
def test_main_refuses_an_unusable_params_file_in_one_line_with_exit_2(tmp_path, name, text,
                                                                     words):
    path = tmp_path / (name or "missing.yaml")
    if name:
        path.write_text(text, encoding="utf-8")
    proc = node_process(["--ros-args", "--params-file", str(path)], next_domain_id())
    code, out, err = _stop_after_exit(proc)
    lines = [line for line in (out + err).splitlines() if line.strip()]
    assert code == 2, out + err
    assert len(lines) == 1, lines
    assert "Traceback" not in lines[0]
    for word in words:
        assert word in lines[0], lines[0]
    if name == "use_mag_int.yaml":
        assert "decimal point" not in lines[0]  # the float hint only for float parameters


def _stop_after_exit(proc: subprocess.Popen) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:  # still running: it accepted the file
        return _stop(proc)
    return proc.returncode, out, err


# -- names, QoS, time ----------------------------------------------------------------------------
def test_namespace_and_remaps_move_every_topic():
    h = Harness(
        namespace="/uav1",
        cli_args=["--ros-args", "-r", "imu/data_raw:=/sensors/imu_raw",
                  "-r", "imu/mag:=/sensors/mag", "-r", "imu/data:=attitude/imu"],
        imu_topic="/sensors/imu_raw", mag_topic="/sensors/mag",
        out_topic="/uav1/attitude/imu", rpy_topic="/uav1/imu/rpy",
    )
    try:
        node = h.node
        subs = dict(node.get_subscriber_names_and_types_by_node("cf_estimator", "/uav1"))
        pubs = dict(node.get_publisher_names_and_types_by_node("cf_estimator", "/uav1"))
        assert {"/sensors/imu_raw", "/sensors/mag"} <= set(subs)
        assert {"/uav1/attitude/imu", "/uav1/imu/rpy", "/diagnostics"} <= set(pubs)
        assert "/imu/data_raw" not in subs and "/imu/data" not in pubs
        assert h.spin_until(lambda: len(h.received["imu"]) >= 5 and h.received["rpy"]
                            and h.received["diag"],
                            publish=lambda: h.imu_pub.publish(h.imu()))
        assert h.received["diag"][-1].status[0].name == "/uav1/cf_estimator: attitude"
    finally:
        h.close()


def test_reliable_publisher_reaches_the_best_effort_input_and_best_effort_subscriber_gets_output():
    h = Harness(input_reliable=True, output_best_effort=True)
    try:
        assert h.spin_until(lambda: len(h.received["imu"]) >= 10 and len(h.received["rpy"]) >= 10,
                            publish=lambda: h.imu_pub.publish(h.imu()))
    finally:
        h.close()


def test_imu_queue_depth_is_the_measured_default_and_a_qos_override_sets_it():
    h = Harness()
    try:
        assert h.node._sub_imu.qos_profile.depth == IMU_QUEUE_DEPTH  # noqa: SLF001
    finally:
        h.close()
    h = Harness(parameter_overrides=[
        Parameter("qos_overrides./imu/data_raw.subscription.depth", value=7)])
    try:
        assert h.node._sub_imu.qos_profile.depth == 7  # noqa: SLF001
        assert h.spin_until(lambda: len(h.received["imu"]) >= 3,
                            publish=lambda: h.imu_pub.publish(h.imu()))
    finally:
        h.close()


def test_use_sim_time_follows_clock_in_diagnostics_and_stamp_age():
    h = Harness(parameter_overrides=[Parameter("use_sim_time", value=True)])
    try:
        clock_pub = h.helper.create_publisher(ClockMsg, "/clock", QoSProfile(depth=10))
        sim_s = T0_S + 5  # the IMU stamps run from T0_S at 100 Hz

        def tick():
            msg = ClockMsg()
            msg.clock.sec = sim_s
            clock_pub.publish(msg)
            if h.k < 100:  # stamps T0_S .. T0_S + 0.99 s
                h.imu_pub.publish(h.imu())

        def stamped_diag() -> bool:
            return any(d.header.stamp.sec == sim_s for d in h.received["diag"])

        assert h.spin_until(stamped_diag, publish=tick)
        assert h.node.get_clock().now().nanoseconds == sim_s * 10**9
        values = dict((kv.key, kv.value) for kv in h.received["diag"][-1].status[0].values)
        # now (sim) - last processed stamp: 5 s minus at most 0.99 s
        assert 4.0 <= float(values["stamp_age_s"]) <= 5.0
    finally:
        h.close()


# -- parameter services --------------------------------------------------------------------------
def test_parameter_services_list_describe_get_and_set():
    h = Harness()
    try:
        client = AsyncParameterClient(h.helper, "/cf_estimator")
        assert client.wait_for_services(timeout_sec=TIMEOUT_S)

        def call(future):
            assert h.spin_until(future.done), "no reply from the parameter service"
            return future.result()

        names = set(call(client.list_parameters()).result.names)
        assert {s.name for s in all_specs()} <= names

        k1, world = call(client.describe_parameters(["k1", "world_frame"])).descriptors
        assert (k1.floating_point_range[0].from_value, k1.floating_point_range[0].to_value) == (
            0.0, 100.0)
        assert "[1/s]" in k1.description and not k1.read_only
        assert world.read_only and "enu" in world.additional_constraints

        values = call(client.get_parameters(["k1", "world_frame", "publish_tf"])).values
        assert values[0].double_value == FilterParams().k1
        assert values[1].string_value == "enu" and values[2].bool_value is False

        results = call(client.set_parameters([
            Parameter("k1", value=0.7), Parameter("k1", value=-1.0),
            Parameter("world_frame", value="ned"), Parameter("tf_parent_frame", value="/map"),
        ])).results
        assert results[0].successful
        assert not results[1].successful and "k1" in results[1].reason
        assert not results[2].successful and "read-only" in results[2].reason
        assert not results[3].successful and "tf_parent_frame" in results[3].reason
        assert h.pipe.filter_params.k1 == 0.7 and h.pipe.pipeline_params.tf_parent_frame == "world"
        assert call(client.get_parameters(["k1"])).values[0].double_value == 0.7
    finally:
        h.close()


# -- diagnostics ---------------------------------------------------------------------------------
def _status(h: Harness, after: int):
    assert h.spin_until(lambda: len(h.received["diag"]) > after)
    return h.received["diag"][-1].status[0]


def _check_values(status) -> dict[str, str]:
    values = {kv.key: kv.value for kv in status.values}
    for key, value in values.items():
        if key not in TEXT_KEYS and not key.startswith("input_warning."):
            float(value)  # every figure parses as a number ("nan" when undefined)
    return values


def test_diagnostics_levels_and_keys_with_numbers_always_numbers():
    h = Harness(parameter_overrides=[Parameter("use_mag", value=False),
                                     Parameter("diagnostics_period_s", value=0.2)])
    try:
        status = _status(h, 0)  # nothing received yet: ERROR
        assert status.level == b"\x02" and "no IMU messages received yet" in status.message
        values = _check_values(status)
        assert values["dt_max_s"] == "nan" and values["processing_time_mean_us"] == "nan"
        assert values["filter_backend"] in ("compiled", "python")
        assert h.spin_until(lambda: h.received["diag"][-1].status[0].level == b"\x00"
                            and h.pipe.counters["processed"] > 0,
                            publish=lambda: h.imu_pub.publish(h.imu()))
        status = h.received["diag"][-1].status[0]
        assert "6-D" in status.message
        values = _check_values(status)
        assert float(values["processing_time_mean_us"]) > 0.0
        n = len(h.received["diag"])  # input stops: ERROR again, figures still numbers
        assert h.spin_until(lambda: len(h.received["diag"]) > n + 1
                            and h.received["diag"][-1].status[0].level == b"\x02")
        values = _check_values(h.received["diag"][-1].status[0])
        assert values["processing_time_max_us"] == "nan" and values["dt_max_s"] == "nan"
    finally:
        h.close()
    h = Harness(parameter_overrides=[Parameter("diagnostics_period_s", value=0.2)])
    try:  # use_mag true and no magnetometer: WARN, the output flows
        assert h.spin_until(lambda: h.received["diag"]
                            and h.received["diag"][-1].status[0].level == b"\x01",
                            publish=lambda: h.imu_pub.publish(h.imu()))
        assert "no magnetometer messages" in h.received["diag"][-1].status[0].message
        assert h.received["imu"]
    finally:
        h.close()


# -- hostile input -------------------------------------------------------------------------------
def _hostile(rng: random.Random, h: Harness, t_ns: int) -> tuple[Imu, int]:
    """One random message: good, NaN/Inf, huge, zero stamp, out of order, duplicate, odd frame."""
    kind = rng.choice(["good", "good", "nan", "inf", "huge", "zero_stamp", "out_of_order",
                       "duplicate", "zero_accel", "frame"])
    t_ns += 10_000_000
    stamp, gyro = t_ns, [rng.gauss(0.0, 0.3) for _ in range(3)]
    accel = [rng.gauss(0.0, 1.0), rng.gauss(0.0, 1.0), 9.8 + rng.gauss(0.0, 1.0)]
    frame = "imu_link"
    if kind == "nan":
        gyro[rng.randrange(3)] = math.nan
    elif kind == "inf":
        accel[rng.randrange(3)] = -math.inf
    elif kind == "huge":
        (gyro if rng.random() < 0.5 else accel)[rng.randrange(3)] = 10.0 ** rng.uniform(7, 300)
    elif kind == "zero_stamp":
        stamp = 0
    elif kind == "out_of_order":
        stamp = t_ns - 50_000_000
    elif kind == "duplicate":
        stamp = t_ns - 10_000_000
    elif kind == "zero_accel":
        accel = [0.0, 0.0, 0.0]
    elif kind == "frame":
        frame = rng.choice(["", "/imu_link", "base_link", "x" * 300])
    return imu_message(Imu, stamp, gyro, accel, frame), t_ns


def test_5000_hostile_messages_over_dds_are_all_accounted_and_the_node_lives_on():
    # One batch at a time, never more than the queue holds, so every message should arrive.
    h = Harness(parameter_overrides=[Parameter("diagnostics_period_s", value=0.5)])
    try:
        assert h.wait_connected()
        rng = random.Random(11)
        pipe = h.pipe
        t_ns, sent = T0_S * 10**9, 0
        mag = MagneticField()
        for _ in range(5000 // 25):
            for _ in range(25):
                msg, t_ns = _hostile(rng, h, t_ns)
                h.imu_pub.publish(msg)
                sent += 1
            mag.header.stamp = msg.header.stamp
            mag.magnetic_field.x = rng.choice([2e-5, math.nan, 1e30, 0.0])
            h.mag_pub.publish(mag)
            h.spin_until(lambda s=sent: pipe.counters["received_imu"] >= s, timeout=10.0)
        c = pipe.counters
        assert c["received_imu"] == c["processed"] + sum(c["rejected"].values())
        assert c["received_imu"] >= 0.95 * sent  # best effort, but nothing should be lost
        assert {"nonfinite_gyro", "nonfinite_accel", "zero_stamp", "out_of_order",
                "duplicate_stamp"} <= set(c["rejected"]), c["rejected"]
        assert c["processed"] > 1000
        n_out, stamps = len(h.received["imu"]), iter(range(t_ns + 10**7, t_ns + 10**11, 10**7))
        assert h.spin_until(lambda: len(h.received["imu"]) > n_out + 10,  # still publishing
                            publish=lambda: h.imu_pub.publish(h.imu(stamp_ns=next(stamps))))
        diag = h.received["diag"][-1].status[0]
        values = _check_values(diag)
        assert int(values["imu_received"]) == int(values["imu_processed"]) + int(
            values["imu_rejected"])
    finally:
        h.close()


# -- TF ------------------------------------------------------------------------------------------
def _tf_message_class():
    return require("tf2_msgs.msg", required=REQUIRE_TF2_MSGS,
                   hint=" (ROS: apt install ros-jazzy-tf2-msgs; wheels: scripts/build_tf2_msgs.py)"
                   ).TFMessage


@pytest.mark.parametrize("reverse", [False, True], ids=["forward", "reverse_tf"])
def test_publish_tf_broadcasts_the_orientation_between_the_world_and_the_imu_frame(reverse):
    tf_message = _tf_message_class()
    h = Harness(parameter_overrides=[Parameter("publish_tf", value=True),
                                     Parameter("reverse_tf", value=reverse)])
    try:
        tfs: list = []
        h.helper.create_subscription(tf_message, "/tf", tfs.append, QoSProfile(depth=100))
        tilt = (0.0, 9.80665 * math.sin(0.3), 9.80665 * math.cos(0.3))  # roll 0.3 rad
        assert h.spin_until(lambda: len(tfs) >= 5 and len(h.received["imu"]) >= 5,
                            publish=lambda: h.imu_pub.publish(h.imu(accel=tilt)))
        t = tfs[-1].transforms[0]
        out = next(m for m in h.received["imu"] if m.header.stamp == t.header.stamp)
        q, r = out.orientation, t.transform.rotation
        sign = -1.0 if reverse else 1.0
        assert (r.x, r.y, r.z, r.w) == pytest.approx((sign * q.x, sign * q.y, sign * q.z, q.w))
        assert abs(2.0 * math.atan2(q.x, q.w)) == pytest.approx(0.3, abs=1e-3)  # roll 0.3 rad
        frames = ("imu_link", "world") if reverse else ("world", "imu_link")
        assert (t.header.frame_id, t.child_frame_id) == frames
        assert (t.transform.translation.x, t.transform.translation.y,
                t.transform.translation.z) == (0.0, 0.0, 0.0)
        # the parent frame is a live parameter
        assert h.node.set_parameters([Parameter("tf_parent_frame", value="earth")])[0].successful
        n = len(tfs)  # transforms already in flight still name "world": wait for "earth"
        assert h.spin_until(
            lambda: any("earth" in (m.transforms[0].header.frame_id, m.transforms[0].child_frame_id)
                        for m in tfs[n:]),
            publish=lambda: h.imu_pub.publish(h.imu()))
    finally:
        h.close()


def test_no_tf_publisher_by_default():
    h = Harness()
    try:
        assert h.spin_until(lambda: len(h.received["imu"]) >= 3,
                            publish=lambda: h.imu_pub.publish(h.imu()))
        pubs = dict(h.node.get_publisher_names_and_types_by_node("cf_estimator", "/"))
        assert "/tf" not in pubs and "/imu/data" in pubs
        assert h.node._pub_tf is None  # noqa: SLF001
    finally:
        h.close()

