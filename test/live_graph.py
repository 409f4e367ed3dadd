"""Shared by the node tests: rclpy (skipped without it, unless required), isolated live graphs.

Every graph gets its own rclpy Context on its own ROS domain id (shuffled per test process, so
two test runs on one machine rarely meet) with discovery limited to this machine; waits are on
conditions with generous timeouts, never fixed sleeps. ``CF_ESTIMATOR_REQUIRE_ROS=1`` (set by
scripts/test.sh when rclpy is there) turns a missing rclpy into a failure instead of a skip.
"""

from __future__ import annotations

import importlib
import os
import random
import subprocess
import sys
import time
from collections.abc import Callable
from types import ModuleType
from typing import Any

import pytest

# Read by the middleware when a context starts: DDS discovery stays on this machine.
os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
os.environ.pop("ROS_LOCALHOST_ONLY", None)  # deprecated in Jazzy: it would override the range

REQUIRE_ROS = os.environ.get("CF_ESTIMATOR_REQUIRE_ROS") == "1"
REQUIRE_TF2_MSGS = os.environ.get("CF_ESTIMATOR_REQUIRE_TF2_MSGS") == "1"
G = 9.80665
T0_S = 1_700_000_000
#: Generous: a loaded 2-core machine may need seconds for DDS discovery.
TIMEOUT_S = 30.0

_DOMAINS = list(range(1, 102))
random.Random(os.getpid() ^ time.time_ns()).shuffle(_DOMAINS)


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
