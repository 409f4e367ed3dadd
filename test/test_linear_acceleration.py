"""Gravity-free acceleration (issue 52): the formula, its covariance, and the replay's output
topics read back from a real bag written by the replay."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_calibrate_mag import _write_bag

from cf_estimator.bag import io
from cf_estimator.bag.replay import (
    OUT_ACCEL_TOPIC,
    OUT_ACCEL_WORLD_TOPIC,
    ReplayOptions,
    replay_bag,
)
from cf_estimator.calibration.simulate import tumble
from cf_estimator.pipeline import PipelineParams
from cf_estimator.pipeline.linear_acceleration import gravity_free

G = 9.80665


def _q_xyzw(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    s = math.sin(angle / 2)
    return (a[0] * s, a[1] * s, a[2] * s, math.cos(angle / 2))


@pytest.mark.parametrize("world", ["enu", "ned"])
def test_a_tilted_sensor_accelerating_gives_the_acceleration_in_both_frames(world):
    q = _q_xyzw((1.0, 0.3, -0.2), 0.7)  # q_world_from_body
    x, y, z, w = q
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    a_world = np.array([1.5, -0.5, 2.0])
    g_w = np.array([0.0, 0.0, G if world == "ned" else -G])
    f = r.T @ (a_world - g_w)  # what the accelerometer reads
    got = gravity_free(q, f, [1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-3], [-1.0] + [0.0] * 8, G, world)
    a_b, c_b, a_w, c_w = got
    assert np.allclose(a_w, a_world, atol=1e-12)
    assert np.allclose(a_b, r.T @ a_world, atol=1e-12)
    # a tilt error of sigma 0.01 rad moves the world acceleration by about g * 0.01
    assert math.sqrt(c_w[0]) == pytest.approx(0.01 * math.hypot(*(r @ f)[[2, 1]]), rel=0.2)
    assert np.allclose(np.array(c_w).reshape(3, 3), np.array(c_w).reshape(3, 3).T)


def test_nothing_before_initialisation():
    assert gravity_free((0, 0, 0, 1), (0, 0, G), [-1.0] + [0.0] * 8, [0.0] * 9, G, "enu") is None


def test_replay_writes_both_topics_near_zero_for_a_turning_sensor_at_no_acceleration(tmp_path):
    tb = tumble(20.0, 50.0, seed=4)  # rotations only: the true linear acceleration is zero
    src = tmp_path / "in"
    _write_bag(src, tb)
    out = tmp_path / "out"
    replay_bag(src, out, pipeline_params=PipelineParams(publish_linear_acceleration=True),
               options=ReplayOptions(progress=False))
    with io.open_bag(out) as bag:
        names = {i.topic for i in bag.topics}
        assert {OUT_ACCEL_TOPIC, OUT_ACCEL_WORLD_TOPIC} <= names
        rows = {OUT_ACCEL_TOPIC: [], OUT_ACCEL_WORLD_TOPIC: []}
        frames = set()
        for m in bag.messages([OUT_ACCEL_TOPIC, OUT_ACCEL_WORLD_TOPIC]):
            lin = m.msg.accel.accel.linear
            rows[m.topic].append((lin.x, lin.y, lin.z, m.msg.accel.covariance[0]))
            frames.add((m.topic, m.msg.header.frame_id))
    assert (OUT_ACCEL_WORLD_TOPIC, "world") in frames and (OUT_ACCEL_TOPIC, "imu_link") in frames
    for topic in rows:
        a = np.array(rows[topic])[250:]  # after the start-up
        rms = float(np.sqrt(np.mean(np.sum(a[:, :3] ** 2, axis=1))))
        assert rms < 0.5, (topic, rms)  # tilt error x g, not g
        assert np.all(a[:, 3] > 0.0)  # a covariance, never zero
    default = tmp_path / "default"
    replay_bag(src, default, options=ReplayOptions(progress=False))
    with io.open_bag(default) as bag:
        assert OUT_ACCEL_TOPIC not in {i.topic for i in bag.topics}  # off by default
