"""Shared by the node tests: rclpy (skipped without it, unless required), isolated live graphs.

Isolated by construction: importing this module (every node test does, before rclpy starts)
makes the test process and the node processes it starts use Fast DDS (``rmw_fastrtps_cpp``)
with the profile :data:`PROFILE` (test/fastdds_test_graph.xml): RTPS port base 1500, domain
gain 50, so the test participants use ports 1100 and 1550-6599 while every participant with
the default port parameters uses 7000 and 7400 + 250 * domain upwards; discovery is limited to
this machine, and the variables that could connect a participant elsewhere (static peers, a
discovery server, a Fast DDS environment file) are removed. A test graph therefore never meets
a participant outside the tests, whatever its domain id (docs/ros_interface.md, Tests).

Every graph gets its own rclpy Context on its own ROS domain id (shuffled per test process, so
two test runs on one machine rarely meet); waits are on conditions with generous timeouts,
never fixed sleeps. ``CF_ESTIMATOR_REQUIRE_ROS=1`` (set by scripts/test.sh when rclpy is there)
turns a missing rclpy into a failure instead of a skip.
"""

from __future__ import annotations

import importlib
import os
import random
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

#: The Fast DDS profile of every test participant (see the module docstring).
PROFILE = Path(__file__).resolve().with_name("fastdds_test_graph.xml")
#: Its RTPS port parameters, and the defaults every other participant uses.
PORT_BASE, DOMAIN_ID_GAIN = 1500, 50
DEFAULT_PORT_BASE, DEFAULT_DOMAIN_ID_GAIN = 7400, 250

# Read by the middleware when a context starts (forced, not defaults: isolation must not
# depend on the caller's environment).
os.environ["RMW_IMPLEMENTATION"] = "rmw_fastrtps_cpp"
os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(PROFILE)  # Fast DDS 2.x
os.environ["FASTDDS_DEFAULT_PROFILES_FILE"] = str(PROFILE)  # its newer name
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
for _name in ("ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS", "ROS_DISCOVERY_SERVER",
              "ROS_SUPER_CLIENT", "FASTDDS_ENVIRONMENT_FILE", "RMW_FASTRTPS_USE_QOS_FROM_XML"):
    os.environ.pop(_name, None)  # each could widen discovery or replace the profile

REQUIRE_ROS = os.environ.get("CF_ESTIMATOR_REQUIRE_ROS") == "1"
REQUIRE_TF2_MSGS = os.environ.get("CF_ESTIMATOR_REQUIRE_TF2_MSGS") == "1"
G = 9.80665
T0_S = 1_700_000_000
#: Generous: a loaded 2-core machine may need seconds for DDS discovery.
TIMEOUT_S = 30.0

def _domains() -> list[int]:
    """ROS domain ids 1-101, shuffled; under pytest-xdist each worker (``gw0``, ``gw1``...)
    takes its own share, so two workers' graphs never share a domain."""
    domains = list(range(1, 102))
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    if worker.startswith("gw") and worker[2:].isdigit() and count > 1:
        domains = domains[int(worker[2:]) % count::count]
    random.Random(os.getpid() ^ time.time_ns()).shuffle(domains)
    return domains


_DOMAINS = _domains()


def require(module: str, *, required: bool = REQUIRE_ROS, hint: str = "") -> ModuleType:
    """Import ``module``; skip the test module without it unless ``required``."""
    if required:
        return importlib.import_module(module)
    return pytest.importorskip(module, reason=f"{module} not importable{hint}")


def next_domain_id() -> int:
    """A ROS domain id not used before by this test process (1-101, shuffled)."""
    domain = _DOMAINS.pop()
    _DOMAINS.insert(0, domain)
    return domain


def udp_ports_of_this_process() -> list[int]:
    """The local UDP ports of this process's sockets (Linux: /proc), sorted."""
    inodes = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            link = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if link.startswith("socket:["):
            inodes.add(link[8:-1])
    ports = []
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            cells = line.split()
            if len(cells) > 9 and cells[9] in inodes:
                ports.append(int(cells[1].rsplit(":", 1)[1], 16))
    return sorted(ports)


def wait_for(predicate: Callable[[], Any], spin: Callable[[], None], timeout: float = TIMEOUT_S,
             step: Callable[[], None] | None = None) -> bool:
    """Call ``step`` (publish...) and ``spin`` until ``predicate()`` is true or time runs out."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if step is not None:
            step()
        spin()
        if predicate():
            return True
    return False


def node_process(args: list[str], domain_id: int) -> subprocess.Popen:
    """``cf_estimator_node`` (its ``main``) in its own process on ``domain_id``."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id), PYTHONUNBUFFERED="1")
    return subprocess.Popen(
        [sys.executable, "-m", "cf_estimator.node.cf_estimator_node", *args],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def imu_message(imu_cls: type, t_ns: int, gyro=(0.0, 0.0, 0.0), accel=(0.0, 0.0, G),
                frame_id: str = "imu_link") -> Any:
    """A sensor_msgs/Imu (rclpy class ``imu_cls``) stamped ``t_ns``."""
    msg = imu_cls()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(t_ns), 10**9)
    msg.header.frame_id = frame_id
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = map(float, gyro)
    a = msg.linear_acceleration
    a.x, a.y, a.z = map(float, accel)
    msg.linear_acceleration_covariance[0] = 0.5
    return msg
