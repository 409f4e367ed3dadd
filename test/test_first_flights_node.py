"""Issue 25, a team's first flights with the node: the live-node items, on real Jazzy rclpy.

Isolated test graphs (7), loud resets (2), frames that say what they are (3), strict parameter
files (4), the imu_filter_madgwick drop-in (5), wrong message types on the inputs (6). Each
graph is the tests' own (test/live_graph.py, test/node_harness.py).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from live_graph import (
    DEFAULT_DOMAIN_ID_GAIN,
    DEFAULT_PORT_BASE,
    DOMAIN_ID_GAIN,
    PORT_BASE,
    PROFILE,
    T0_S,
    next_domain_id,
    require,
    udp_ports_of_this_process,
)

rclpy = require("rclpy")

from node_harness import Harness  # noqa: E402,I001

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


# -- item 7: a test graph never reaches a live graph -------------------------------------------
def test_the_test_graph_is_isolated_by_its_ports(harness):
    """The test participants listen only on the profile's ports, never on the default ones
    that every other participant (any vendor, any domain id) uses: they cannot meet."""
    assert os.environ["RMW_IMPLEMENTATION"] == "rmw_fastrtps_cpp"
    assert os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(PROFILE)
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    d = harness.domain_id
    ports = udp_ports_of_this_process()
    ours = range(PORT_BASE + DOMAIN_ID_GAIN * d, PORT_BASE + DOMAIN_ID_GAIN * (d + 1))
    default = range(DEFAULT_PORT_BASE + DEFAULT_DOMAIN_ID_GAIN * d,
                    DEFAULT_PORT_BASE + DEFAULT_DOMAIN_ID_GAIN * (d + 1))
    assert any(p in ours for p in ports), ports  # the profile is in force
    assert DEFAULT_PORT_BASE - 400 not in ports, ports  # the default's domain-free port
    ephemeral = [int(x) for x in Path("/proc/sys/net/ipv4/ip_local_port_range")
                 .read_text().split()]
    if default.stop <= ephemeral[0]:  # (above it, a sending socket's port could fall there)
        assert not any(p in default for p in ports), ports
    assert max(PORT_BASE + DOMAIN_ID_GAIN * 102, PORT_BASE) < DEFAULT_PORT_BASE - 400
    assert PORT_BASE - 400 >= 1024  # no privileged port


def test_the_isolation_is_documented():
    text = (REPO / "docs" / "ros_interface.md").read_text()
    assert "fastdds_test_graph.xml" in text and "isolated by construction" in text


class _Recorder:
    """Stands in for the node's rclpy logger: keeps (level, text)."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def _add(self, level: str):
        def log(text: str, **_kwargs) -> bool:
            self.lines.append((level, text))
            return True
        return log

    def __getattr__(self, level: str):
        return self._add(level)


# -- item 2: resets are loud ------------------------------------------------------------------
def test_every_reset_and_each_new_kind_of_rejection_is_a_warn(harness, monkeypatch):
    rec = _Recorder()
    monkeypatch.setattr(harness.node, "get_logger", lambda: rec)
    assert harness.wait_connected()
    for _ in range(5):
        assert harness.publish_one(harness.imu())
    nan = harness.imu(gyro=(float("nan"), 0.0, 0.0))
    for _ in range(3):
        assert harness.publish_one(nan)
    t_back = T0_S * 10**9 + (harness.k - 300) * 10_000_000  # 3 s before the last stamp
    assert harness.publish_one(harness.imu(stamp_ns=t_back))
    assert harness.publish_one(harness.imu(stamp_ns=t_back + 10_000_000))
    assert harness.publish_one(harness.imu(stamp_ns=t_back - 4 * 10**9))  # a second reset
    warns = [t for level, t in rec.lines if level in ("warning", "warn")]
    assert sum("nonfinite_gyro" in t for t in warns) == 1, warns  # once per kind
    resets = [t for t in warns if t.startswith("filter reset (time_jump_back)")]
    assert len(resets) == 1, warns  # the second one within the rate limit: held back ...
    assert harness.pipe.counters["resets"]["time_jump_back"] == 2
    harness.node._events.period_s = 0.0  # noqa: SLF001 - ... and said with the next report
    harness.node._on_diagnostics()  # noqa: SLF001
    warns = [t for level, t in rec.lines if level in ("warning", "warn")]
    assert any("2 reset(s) time_jump_back so far" in t for t in warns), warns


# -- item 3: frames that say what they are ----------------------------------------------------
def test_node_publishes_an_frd_output_under_an_frd_frame_id():
    from rclpy.parameter import Parameter

    h = Harness(parameter_overrides=[Parameter("world_frame", value="ned"),
                                     Parameter("body_frame", value="flu"),
                                     Parameter("use_mag", value=False)])
    try:
        got = h.spin_until(lambda: len(h.received["imu"]) >= 3 and h.received["rpy"],
                           publish=lambda: h.imu_pub.publish(h.imu(frame_id="base_link")))
        assert got, "no output"
        assert h.received["imu"][-1].header.frame_id == "base_link_frd"
        assert h.received["rpy"][-1].header.frame_id == "base_link_frd"
    finally:
        h.close()


def test_node_refuses_tf_that_would_be_misread():
    from rclpy.parameter import Parameter

    from cf_estimator.node.node import CfEstimatorNode, StartError

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=next_domain_id())
    try:
        with pytest.raises(StartError, match="map_ned"):
            CfEstimatorNode(context=context, parameter_overrides=[
                Parameter("world_frame", value="ned"), Parameter("body_frame", value="flu"),
                Parameter("publish_tf", value=True), Parameter("tf_parent_frame", value="map")])
    finally:
        rclpy.shutdown(context=context)


# -- item 4: strict parameter files for flight --------------------------------------------------
@pytest.mark.parametrize(("text", "words"), [
    ("/**:\n  ros__parameters:\n    k_1: 0.5\n", "unknown parameter 'k_1' (did you mean 'k1'?)"),
    ("imu_filter:\n  ros__parameters:\n    gain: 0.1\n    world_frame: enu\n",
     "no section applies to node '/cf_estimator' (sections: imu_filter)"),
])
def test_strict_parameters_refuses_what_replay_refuses(tmp_path, text, words):
    from live_graph import node_process

    from cf_estimator.cli.base import CliError
    from cf_estimator.cli.common import load_params

    path = tmp_path / "p.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(CliError) as refused:  # what replay --params says, exit 2
        load_params(str(path))
    replay_line = str(refused.value)
    assert refused.value.code == 2 and words in replay_line
    proc = node_process(["--ros-args", "--params-file", str(path), "-p",
                         "strict_parameters:=true"], next_domain_id())
    try:
        _out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 2, err
    fatal = [line for line in err.splitlines() if "FATAL" in line]
    assert len(fatal) == 1 and replay_line in fatal[0], err


def test_strict_parameters_refuses_an_unknown_override():
    from rclpy.parameter import Parameter

    from cf_estimator.node.node import CfEstimatorNode
    from cf_estimator.schema import ParameterError

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=next_domain_id())
    try:
        with pytest.raises(ParameterError, match="'k_1' \\(did you mean 'k1'\\?\\)"):
            CfEstimatorNode(context=context, parameter_overrides=[
                Parameter("strict_parameters", value=True), Parameter("k_1", value=0.5)])
    finally:
        rclpy.shutdown(context=context)


def test_the_shipped_launch_file_is_strict_and_exposes_frames_velocity_and_params():
    text = (REPO / "launch_scripts" / "cf_estimator.launch.py").read_text()
    assert '("strict_parameters", "true"' in text
    for arg in ("velocity_topic", "world_frame", "body_frame", "params_file"):
        assert f'("{arg}",' in text


# -- item 6: a wrong message type on an input topic ------------------------------------------
def _diag_values(h) -> dict[str, str]:
    if not h.received["diag"]:
        return {}
    status = h.received["diag"][-1].status[0]
    return {kv.key: kv.value for kv in status.values} | {"_message": status.message}


def test_a_wrong_type_on_the_imu_topic_is_named_once(monkeypatch):
    from geometry_msgs.msg import Vector3Stamped
    from nav_msgs.msg import Odometry
    from rclpy.parameter import Parameter
    from rclpy.qos import qos_profile_sensor_data

    h = Harness(imu_topic="unused_imu", parameter_overrides=[
        Parameter("velocity_topic", value="vel"), Parameter("velocity_topic_type", value="twist"),
        Parameter("diagnostics_period_s", value=0.2)])
    # another participant on the same test graph (one participant cannot hold two types of
    # one topic: the node's subscription already gave imu/data_raw its type there)
    other_context = rclpy.Context()
    rclpy.init(context=other_context, domain_id=h.domain_id)
    other = rclpy.create_node("wrong_types", context=other_context)
    try:
        rec = _Recorder()
        monkeypatch.setattr(h.node, "get_logger", lambda: rec)
        other.create_publisher(Vector3Stamped, "imu/data_raw", qos_profile_sensor_data)
        other.create_publisher(Odometry, "vel", qos_profile_sensor_data)
        assert h.spin_until(lambda: {"input_type.imu", "input_type.velocity"}
                            <= set(_diag_values(h))), _diag_values(h)
        values = _diag_values(h)
        assert "geometry_msgs/msg/Vector3Stamped" in values["input_type.imu"]
        assert "sensor_msgs/msg/Imu" in values["input_type.imu"]
        assert "nav_msgs/msg/Odometry" in values["input_type.velocity"]
        assert "geometry_msgs/msg/TwistStamped" in values["input_type.velocity"]
        assert "Vector3Stamped" in values["_message"]
        n = len(h.received["diag"])
        assert h.spin_until(lambda: len(h.received["diag"]) >= n + 3)  # more reports ...
        warns = [t for level, t in rec.lines if level == "warning" and "advertised as" in t]
        assert len(warns) == 2, warns  # ... one WARN per input, not one per report
    finally:
        other.destroy_node()
        rclpy.shutdown(context=other_context)
        h.close()


# -- item 9: tf2_msgs for the wheels ------------------------------------------------------------
def test_build_tf2_msgs_into_a_prefix_leaves_the_environment_alone(tmp_path):
    import importlib.util
    import shutil
    import subprocess
    import sys

    if shutil.which("cc") is None or shutil.which("c++") is None:
        pytest.skip("no C/C++ compiler")
    if importlib.util.find_spec("rosidl_generator_py") is None:
        pytest.skip("no rosidl generators (a ROS install: apt install ros-jazzy-tf2-msgs)")
    import sysconfig

    site = Path(sysconfig.get_paths()["purelib"])
    before = (site / "tf2_msgs").exists()
    prefix = tmp_path / "tf2"
    proc = subprocess.run([sys.executable, str(REPO / "scripts" / "build_tf2_msgs.py"),
                           "--prefix", str(prefix), "--force"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    exports = dict(line.removeprefix("export ").split("=", 1)[0:2]
                   for line in proc.stdout.splitlines() if line.startswith("export "))
    assert set(exports) == {"PYTHONPATH", "LD_LIBRARY_PATH"}
    assert (site / "tf2_msgs").exists() == before  # the running environment is untouched
    env = dict(os.environ)
    for name, value in exports.items():
        env[name] = value.replace(f"${name}", os.environ.get(name, ""))
    check = ("import rclpy; from tf2_msgs.msg import TFMessage; c = rclpy.Context(); "
             f"rclpy.init(context=c, domain_id={next_domain_id()}); "
             "n = rclpy.create_node('tf2_check', context=c); "
             "n.create_publisher(TFMessage, '/tf', 10); print('published type ok')")
    run = subprocess.run([sys.executable, "-c", check], env=env, capture_output=True,
                         text=True, timeout=120)
    assert "published type ok" in run.stdout, run.stderr


def test_missing_tf2_msgs_says_how_to_build_it_for_a_shared_environment():
    import importlib.util

    from rclpy.parameter import Parameter

    from cf_estimator.node.node import CfEstimatorNode, StartError

    if importlib.util.find_spec("tf2_msgs") is not None:
        pytest.skip("tf2_msgs is importable here")
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=next_domain_id())
    try:
        with pytest.raises(StartError, match="build_tf2_msgs.py --prefix DIR"):
            CfEstimatorNode(context=context,
                            parameter_overrides=[Parameter("publish_tf", value=True)])
    finally:
        rclpy.shutdown(context=context)
