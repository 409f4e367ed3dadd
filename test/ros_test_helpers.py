"""Shared by the tests: real ROS 2 Jazzy message classes (rosbags) and a whole-bag reader.

The typestore is the one cf_estimator writes with (:func:`cf_estimator.bag.io.typestore`).
"""

from __future__ import annotations

from pathlib import Path

from cf_estimator.bag import io

TS = io.typestore()
Time = TS.types["builtin_interfaces/msg/Time"]
Header = TS.types["std_msgs/msg/Header"]
Vector3 = TS.types["geometry_msgs/msg/Vector3"]
Quaternion = TS.types["geometry_msgs/msg/Quaternion"]
Imu = TS.types["sensor_msgs/msg/Imu"]
MagneticField = TS.types["sensor_msgs/msg/MagneticField"]


def read_topics(path: Path) -> dict[str, list[io.BagMessage]]:
    """Every message of a bag by topic, in log order (small test bags: all in memory)."""
    out: dict[str, list[io.BagMessage]] = {}
    with io.open_bag(path) as bag:
        for m in bag.messages([t.topic for t in bag.topics]):
            out.setdefault(m.topic, []).append(m)
    return out
