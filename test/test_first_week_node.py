"""Issue 19 on the live node: body_frame on real topics, a params file that misses the node,
and a clean stop when SIGINT reaches the whole process group (as under ``ros2 launch``)."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time

import pytest
from live_graph import imu_message, next_domain_id, require

rclpy = require("rclpy")

from node_harness import Harness  # noqa: E402,I001
from rclpy.parameter import Parameter  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402

G = 9.80665
T0_S = 1_700_000_000


def test_node_body_frame_flu_in_ned_gives_px4_angles_and_frd_vectors():
    h = Harness(parameter_overrides=[Parameter("world_frame", value="ned"),
                                     Parameter("body_frame", value="flu"),
                                     Parameter("use_mag", value=False)])
    try:
        r = math.radians(10.0)
        flu = (0.0, G * math.sin(r), G * math.cos(r))  # rolled 10 deg right, FLU axes
        got = h.spin_until(lambda: len(h.received["imu"]) >= 5 and h.received["rpy"],
                           publish=lambda: h.imu_pub.publish(h.imu(accel=flu)))
        assert got, "no output"
        out = h.received["imu"][-1]
        assert out.linear_acceleration.z == pytest.approx(-G * math.cos(r))  # FRD: z down
        assert out.linear_acceleration.y == pytest.approx(-G * math.sin(r))
        rpy = h.received["rpy"][-1].vector
        assert math.degrees(rpy.x) == pytest.approx(10.0, abs=0.01)  # not -170 deg
        assert abs(rpy.y) < 1e-6
    finally:
        h.close()


def _node(args: list[str], domain: int) -> subprocess.Popen:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "cf_estimator.node.cf_estimator_node", *args],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # its own process group, as under launch


def _read_until_started(proc: subprocess.Popen) -> list[str]:
    """stderr lines up to the node's start-up "parameters:" log line (rclpy logs to stderr)."""
    lines: list[str] = []
    for line in proc.stderr:  # type: ignore[union-attr]
        lines.append(line)
        if "parameters:" in line:
            break
    return lines


def test_params_file_for_the_executable_name_warns_loudly_and_sigint_to_group_is_clean(
        tmp_path):
    path = tmp_path / "tuned.yaml"
    path.write_text("cf_estimator_node:\n  ros__parameters:\n    k1: 0.2\n", encoding="utf-8")
    proc = _node(["--ros-args", "--params-file", str(path)], next_domain_id())
    try:
        head = _read_until_started(proc)
        assert proc.poll() is None, head + list(proc.communicate())
        pgid = os.getpgid(proc.pid)
        os.killpg(pgid, signal.SIGINT)  # launch's SIGINT ...
        time.sleep(0.05)
        if proc.poll() is None:
            os.killpg(pgid, signal.SIGINT)  # ... and the terminal's, to the whole group
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = "".join(head) + out + err
    assert proc.returncode == 0, text
    assert "Traceback" not in text and "KeyboardInterrupt" not in text
    warning = [line for line in text.splitlines() if "none of its sections" in line]
    assert len(warning) == 1, text
    assert "cf_estimator_node" in warning[0] and "defaults" in warning[0]
    assert "k1=0.35" in text  # and indeed the default gain is in force


def test_imu_message_helper_is_the_one_the_node_reads():
    msg = imu_message(Imu, T0_S * 10**9, accel=(0.0, 0.0, G))
    assert msg.linear_acceleration.z == G
