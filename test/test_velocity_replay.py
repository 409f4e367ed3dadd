"""Velocity aiding through the pipeline and the bag replay: real rosbags messages (issue 17)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from cf_estimator.bag import io
from cf_estimator.bag.replay import ReplayOptions, ReplayVariant, replay_bag, replay_variants
from cf_estimator.bag.simulate import VELOCITY_TOPIC, write_scenario_bag
from cf_estimator.cli.main import main
from cf_estimator.core import quaternion as quat
from cf_estimator.core.params import FilterParams
from cf_estimator.pipeline import ImuPipeline, PipelineParams
from cf_estimator.pipeline.velocity_input import velocity_from_message
from cf_estimator.scenarios import make_scenario
from cf_estimator.scenarios.velocity_sensor import VelocityModel, measure_velocity, with_faults

P6 = FilterParams(use_mag=False)
T0_NS = 1_704_067_200 * 10**9


@pytest.fixture(scope="module")
def uav():
    return make_scenario("uav", duration_s=60.0, seed=3)


@pytest.fixture(scope="module")
def faulty_bag(uav, tmp_path_factory):
    """The flight with a 10 Hz GNSS velocity that glitches by 5 m/s and drops out for 6 s."""
    model = with_faults(VelocityModel(10.0, 0.1, 0.1), dropouts=[(30.0, 36.0)],
                        glitches=[(20.0, 20.35, (5.0, 0.0, 0.0))])
    vd = measure_velocity(uav.truth, model, np.random.default_rng(0))
    path = tmp_path_factory.mktemp("vel") / "flight"
    write_scenario_bag(uav, path, velocity=vd)
    return path


def test_replay_aided_and_unaided_side_by_side(faulty_bag):
    opts = ReplayOptions(mag_topic="none", reference_topic="/ground_truth/orientation",
                         velocity_topic=VELOCITY_TOPIC, progress=False)
    aided, = replay_variants(faulty_bag, [ReplayVariant("aided", P6)], opts)
    opts.velocity_topic = None
    unaided, = replay_variants(faulty_bag, [ReplayVariant("unaided", P6)], opts)
    va = aided.summary["velocity"]
    assert aided.summary["topics"]["velocity"] == VELOCITY_TOPIC
    assert "velocity" not in unaided.summary
    assert va["rejected"].get("jump", 0) >= 3  # the 5 m/s glitch
    assert va["used"] > 400 and va["heading_known"]
    assert va["unaided_stale_samples"] > 0  # the dropout
    assert va["aided_axes_at_end"] == "xy" and 0.5 < va["aided_fraction"] < 1.0
    # vertical-only until the heading offset is known, horizontal after it
    assert 0.3 < va["aided_horizontal_fraction"] < va["aided_fraction"]
    assert va["time_to_aid_s"] is not None and va["time_to_aid_s"] > 0.0
    # aiding came back after the 30-36 s dropout: the stretch at the end began after 36 s
    assert 0.0 < va["aided_for_s_at_end"] < 60.0 - 36.0
    inc_a = aided.summary["reference"]["rmse_deg"]["inclination"]
    inc_u = unaided.summary["reference"]["rmse_deg"]["inclination"]
    assert inc_a < 0.5 * inc_u


def test_replay_cli_velocity_topic_json_and_errors(faulty_bag, tmp_path, capsys):
    params = tmp_path / "p.yaml"
    params.write_text("/**:\n  ros__parameters:\n    use_mag: false\n")
    out = tmp_path / "s.json"
    assert main(["replay", str(faulty_bag), "--mag-topic", "none", "--velocity-topic",
                 VELOCITY_TOPIC, "--params", str(params), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    line = next(ln for ln in text.splitlines() if ln.startswith("velocity "))
    assert f"on {VELOCITY_TOPIC}: used" in line and "jump" in line and "heading offset" in line
    doc = json.loads(out.read_text())
    assert doc["velocity"]["aided_samples"] > 0
    # a topic of the wrong type: one-line error, exit 2
    assert main(["replay", str(faulty_bag), "--velocity-topic", "/imu/mag", "--json",
                 str(tmp_path / "t.json")]) == 2
    err = capsys.readouterr().err
    assert "--velocity-topic needs geometry_msgs/msg/TwistStamped or nav_msgs/msg/Odometry" in err
    assert len(err.strip().splitlines()) == 1


def test_offline_replay_uses_the_aided_specific_force(faulty_bag):
    opts = ReplayOptions(mag_topic="none", reference_topic="/ground_truth/orientation",
                         velocity_topic=VELOCITY_TOPIC, progress=False, offline=True)
    r = replay_bag(faulty_bag, None, P6, None, opts)
    opts.velocity_topic = None
    r0 = replay_bag(faulty_bag, None, P6, None, opts)
    assert (r.summary["reference"]["rmse_deg"]["inclination"]
            < 0.7 * r0.summary["reference"]["rmse_deg"]["inclination"])


def test_offline_replay_runs_each_row_as_the_aiding_ran_it():
    """The offline replay's recorder notes per row whether the velocity aiding had the row
    aided (set_aided) and said the vehicle moves (interrupt_rest); the offline passes get those
    flags (offline.ROW_AIDED / ROW_MOVING), as estimate(offline=True) gives them: a slow steady
    turn in motion is not learned as bias offline either."""
    from cf_estimator.bag.replay import _offline_orientations, _RecordingFilter
    from cf_estimator.core.filter import EXTRA_COLUMNS
    from cf_estimator.core.offline import ROW_AIDED, ROW_MOVING, smooth_segment

    rec = _RecordingFilter(P6)
    rec.initialize((1.0, 0.0, 0.0, 0.0))
    t = np.arange(0.0, 8.0, 0.01)
    g = (0.0, 0.0, math.radians(0.3))
    for k in range(t.size):
        rec.set_aided(k % 400 >= 200)
        rec.interrupt_rest()
        rec.update(g, (0.0, 0.0, P6.gravity_m_s2), 0.01)
    flags = np.asarray(rec.flags)
    aided = np.arange(t.size) % 400 >= 200
    assert (flags == np.where(aided, ROW_AIDED, 0) | ROW_MOVING).all()
    q, segments = _offline_orientations(t, rec, P6, 0.5)
    assert segments == 1
    rows = np.asarray(rec.rows)
    q_plain = np.full((t.size, 4), np.nan)
    smooth_segment(np.ascontiguousarray(rows[:, :3]), np.ascontiguousarray(rows[:, 3:6]), None,
                   t, P6, q_plain, np.zeros((t.size, EXTRA_COLUMNS)))
    # unflagged, the passes take the turn for bias at rest and hold the heading still; flagged,
    # the heading turns with the gyro (0.3 deg/s over the 7 s from 1 s on)
    yaw = np.degrees(2.0 * np.arctan2(q[:, 3], q[:, 0]))
    yaw_plain = np.degrees(2.0 * np.arctan2(q_plain[:, 3], q_plain[:, 0]))
    assert abs(yaw[-1] - yaw[100]) > 1.8 > 1.0 > abs(yaw_plain[-1] - yaw_plain[100])


# -- messages --------------------------------------------------------------------------------
def test_twist_and_odometry_messages_give_the_same_world_velocity():
    q = quat.from_euler(0.1, -0.2, 1.0)
    v_world = np.array([1.0, -2.0, 0.5])
    vb = quat.rotate(quat.conjugate(q), v_world)
    tw = io.twist_stamped_message(5, 0, "map", v_world)
    od = io.odometry_message(5, 0, "odom", "base_link", (q[1], q[2], q[3], q[0]), (0, 0, 0), vb)
    t1, v1 = velocity_from_message(tw, "enu", "enu")
    t2, v2 = velocity_from_message(od, "enu", "enu")
    assert t1 == t2 == 5 * 10**9
    assert np.allclose(v1, v_world) and np.allclose(v2, v_world)
    _, vn = velocity_from_message(tw, "enu", "ned")  # ENU -> NED
    assert np.allclose(vn, (-2.0, 1.0, -0.5))


def test_bad_velocity_messages_are_reasons_not_exceptions():
    assert velocity_from_message(io.twist_stamped_message(0, 0, "map", (1, 0, 0)), "enu",
                                 "enu") == "stamp"
    assert velocity_from_message(io.twist_stamped_message(1, 0, "map", (math.nan, 0, 0)), "enu",
                                 "enu") == "nonfinite"
    assert velocity_from_message(io.twist_stamped_message(1, 0, "gps", (1, 0, 0)), "enu", "enu",
                                 "map") == "frame"
    zero_q = io.odometry_message(1, 0, "odom", "base", (0, 0, 0, 0), (0, 0, 0), (1, 0, 0))
    assert velocity_from_message(zero_q, "enu", "enu") == "frame"
    assert velocity_from_message(io.magnetic_field_message(1, 0, "imu", (1e-5, 0, 0)), "enu",
                                 "enu") == "malformed"
    assert velocity_from_message(object(), "enu", "enu") == "malformed"


def _aided_stream(imu, vd, gyro=None, frame=lambda j: "map"):
    """(k, IMU message k) of ``imu`` in time order (``gyro`` in place of its own when given),
    each after the (None, velocity message) of ``vd`` that arrived by then (TwistStamped,
    frame id ``frame(j)`` for the j-th)."""
    jv = 0
    for k in range(imu.n_samples):
        t = float(imu.t_s[k])
        while jv < len(vd.t_s) and vd.arrival_s[jv] <= t:
            st = divmod(T0_NS + round(float(vd.t_s[jv]) * 1e9), 10**9)
            yield None, io.twist_stamped_message(*st, frame(jv), vd.v_world_m_s[jv])
            jv += 1
        st = divmod(T0_NS + round(t * 1e9), 10**9)
        g = imu.gyro_rad_s[k] if gyro is None else gyro[k]
        yield k, io.imu_message(*st, "imu", (0, 0, 0, 1), None, g, None, imu.accel_m_s2[k],
                                None)


def test_pipeline_counts_velocity_and_reports_it_in_diagnostics(uav):
    vd = measure_velocity(uav.truth, VelocityModel(10.0, 0.1, 0.1), np.random.default_rng(0))
    pipe = ImuPipeline(P6, PipelineParams(velocity_frame_id="map"))
    imu = uav.imu
    jv = 0
    moving_seen: list[bool] = []
    for k, msg in _aided_stream(imu, vd, frame=lambda j: "gps" if j == 7 else "map"):
        if k is None:
            pipe.on_velocity(msg)
            jv += 1
            continue
        pipe.on_imu(msg)
        if k % 200 == 0:
            moving_seen.append(pipe.velocity_aiding is not None and pipe.velocity_aiding.moving_now)
    values = dict(pipe.diagnostics().values)
    assert values["velocity_rejected.frame"] == "1"
    assert values["velocity_aiding"] == "aided"
    assert values["velocity_heading_known"] == "true"
    assert int(values["velocity_received"]) == jv
    # which axes are aided, for how long, and how long aiding took to begin
    st = pipe.velocity_aiding.status()
    assert values["velocity_aided_axes"] == "xy"
    assert 0 < int(values["velocity_aided_horizontal_samples"]) < int(
        values["velocity_aided_samples"])
    first_v = st.first_velocity_t_s - T0_NS * 1e-9  # pipeline stamps are the header's
    assert np.min(np.abs(vd.t_s - first_v)) < 1e-6 and first_v < 1.0
    to_aid = float(values["velocity_time_to_aid_s"])
    assert to_aid == pytest.approx(st.first_aided_t_s - st.first_velocity_t_s, rel=1e-5)
    assert 0.0 < to_aid < 30.0  # it does begin, and not at the first velocity sample
    # one aided stretch since it began (no dropout in this stream): it lasted to the end
    assert float(values["velocity_aided_for_s"]) == pytest.approx(
        float(imu.t_s[-1]) + T0_NS * 1e-9 - st.first_aided_t_s, abs=1e-3)
    # moving (not at rest, whatever the stillness blocks say) while the flight is under way;
    # at the end the vehicle hovers below 5 sigma of the velocity noise
    assert sum(moving_seen) > 0.5 * len(moving_seen)
    slow = np.linalg.norm(vd.v_world_m_s[-5:], axis=1).max() < 5.0 * P6.velocity_noise_m_s
    assert values["velocity_moving"] == str(not slow).lower()
    # no gyro fault in this flight: never taken for an attitude error (the key is there)
    assert values["velocity_attitude_errors"] == "0"
    # a reset (time jump back) resets the aiding as well
    pipe.on_imu(io.imu_message(1, 0, "imu", (0, 0, 0, 1), None, (0, 0, 0), None, (0, 0, 9.8),
                               None))
    assert pipe.velocity_aiding.status().age_s == math.inf


def test_pipeline_counts_an_attitude_error_revealed_while_aided_and_says_it(uav):
    """A gyro fault (3 rad/s on x for 0.2 s at 40 s) in an aided flight through the pipeline:
    counted as an event (event_counts, event_total), in the diagnostics
    (velocity_attitude_errors) and in the node's log line (RateLimitedWarnings)."""
    from cf_estimator.pipeline.log_events import RateLimitedWarnings

    vd = measure_velocity(uav.truth, VelocityModel(10.0, 0.1, 0.1), np.random.default_rng(0))
    pipe = ImuPipeline(P6, PipelineParams())
    imu = uav.imu
    gyro = imu.gyro_rad_s.copy()
    gyro[(imu.t_s >= 40.0) & (imu.t_s < 40.2), 0] += 3.0
    totals = []
    for k, msg in _aided_stream(imu, vd, gyro):
        if k is None:
            pipe.on_velocity(msg)
        else:
            pipe.on_imu(msg)
            totals.append(pipe.event_total)
    n = pipe.event_counts.get("attitude_error", 0)
    assert n >= 1 and pipe.event_total == n
    first = int(np.argmax(np.array(totals) > 0))
    assert 40.0 <= imu.t_s[first] < 42.0  # taken hold of within 2 s of the fault, not before
    values = dict(pipe.diagnostics().values)
    assert values["velocity_attitude_errors"] == str(n)
    lines = RateLimitedWarnings().update(pipe.reset_counts, pipe.rejected_counts, 0.0,
                                         pipe.event_counts)
    assert len(lines) == 1 and lines[0].startswith("attitude_error: velocity-aided")
    assert f"{n} so far" in lines[0]


def test_pipeline_without_velocity_messages_matches_the_filter_bit_for_bit(uav):
    """No velocity topic: the pipeline never creates the aiding (bit-equal by construction)."""
    pipe = ImuPipeline(P6)
    imu = uav.imu
    for k in range(500):
        st = divmod(T0_NS + round(float(imu.t_s[k]) * 1e9), 10**9)
        pipe.on_imu(io.imu_message(*st, "imu", (0, 0, 0, 1), None, imu.gyro_rad_s[k], None,
                                   imu.accel_m_s2[k], None))
    assert pipe.velocity_aiding is None
    assert not any(k.startswith("velocity") for k, _ in pipe.diagnostics().values)


def test_pipeline_with_stale_velocity_messages_is_bit_equal_to_no_velocity(uav):
    """Velocity messages that arrive 5 s after their stamps (velocity_timeout_s 1.5 s): each is
    counted stale and the outputs are those of a pipeline that never saw a velocity."""
    vd = measure_velocity(uav.truth, VelocityModel(10.0, 0.1, 5.0), np.random.default_rng(0))
    aided, plain = ImuPipeline(P6), ImuPipeline(P6)
    jv = 0
    for k, msg in _aided_stream(uav.imu, vd):
        if k is None:
            aided.on_velocity(msg)
            jv += 1
            continue
        a, b = aided.on_imu(msg), plain.on_imu(msg)
        assert a.orientation_xyzw == b.orientation_xyzw
        assert a.orientation_covariance == b.orientation_covariance
    status = aided.velocity_aiding.status()
    assert jv > 400 and status.rejected["too_old"] == jv and status.aided_samples == 0
    assert dict(aided.diagnostics().values)["velocity_stale"] == str(jv)
