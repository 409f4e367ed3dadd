"""ImuPipeline: driven by real sensor_msgs objects from the rosbags Jazzy typestore (no ROS)."""

from __future__ import annotations

import array
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from ros_test_helpers import Header, Imu, MagneticField, Quaternion, Time, Vector3

from cf_estimator.core import quaternion as quat
from cf_estimator.core.params import FilterParams
from cf_estimator.pipeline import DiagnosticsReport, ImuPipeline, PipelineOutput, PipelineParams
from cf_estimator.pipeline.diagnostics import ERROR, OK, WARN

G = 9.80665
T0_NS = 1_700_000_000 * 10**9
DT_NS = 10_000_000  # 100 Hz
#: Earth field in the sensor frame of a level sensor facing east in ENU: north = sensor +y.
MAG_T = (0.0, 20e-6, -40e-6)

#: The /diagnostics keys documented in docs/ros_interface.md (always present).
DIAGNOSTIC_KEYS = [
    "world_frame", "initialized", "phase", "imu_received", "imu_processed", "imu_rejected",
    "resets", "gaps", "period_s", "input_rate_hz", "dt_min_s", "dt_mean_s", "dt_max_s",
    "error_norm_mean_rad", "error_norm_max_rad", "clipped_fraction", "gyro_bias_x_rad_s",
    "gyro_bias_y_rad_s", "gyro_bias_z_rad_s", "at_rest", "recovery_count", "roll_rad",
    "pitch_rad", "yaw_rad", "use_mag", "heading_referenced", "mag_received", "mag_used",
    "mag_rejected", "mag_stale", "mag_invalid", "mag_dropped", "mag_disabled", "mag_age_s",
    "processing_time_mean_us", "processing_time_max_us", "stamp_age_s",
]


def stamp(t_ns: int) -> Time:
    return Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def imu_msg(t_ns, gyro=(0.0, 0.0, 0.0), accel=(0.0, 0.0, G), frame="imu_link", cov=0.01):
    """A real sensor_msgs/Imu (orientation unknown, as a raw driver publishes it)."""
    return Imu(
        header=Header(stamp=stamp(t_ns), frame_id=frame),
        orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.array([-1.0] + [0.0] * 8),
        angular_velocity=Vector3(x=float(gyro[0]), y=float(gyro[1]), z=float(gyro[2])),
        angular_velocity_covariance=np.diag([cov] * 3).ravel(),
        linear_acceleration=Vector3(x=float(accel[0]), y=float(accel[1]), z=float(accel[2])),
        linear_acceleration_covariance=np.diag([2 * cov] * 3).ravel(),
    )


def mag_msg(t_ns, field=MAG_T, frame="imu_link"):
    return MagneticField(
        header=Header(stamp=stamp(t_ns), frame_id=frame),
        magnetic_field=Vector3(x=float(field[0]), y=float(field[1]), z=float(field[2])),
        magnetic_field_covariance=np.zeros(9),
    )


def run(pipe, n, *, start_ns=T0_NS, gyro=(0.0, 0.0, 0.0), accel=(0.0, 0.0, G), mag=None,
        mag_every=1, frame="imu_link"):
    """Feed n IMU messages (and a mag sample every mag_every); return the outputs."""
    outs = []
    for i in range(n):
        t = start_ns + i * DT_NS
        if mag is not None and i % mag_every == 0:
            pipe.on_mag(mag_msg(t, mag))
        outs.append(pipe.on_imu(imu_msg(t, gyro, accel, frame)))
    return outs


def wxyz(out: PipelineOutput) -> np.ndarray:
    x, y, z, w = out.orientation_xyzw
    return np.array([w, x, y, z])


def assert_invariant(pipe):
    c = pipe.counters
    assert c["received_imu"] == c["processed"] + sum(c["rejected"].values())
    mag_accounted = (c["mag_used"] + c["mag_rejected"] + c["mag_stale"] + c["mag_invalid"]
                     + c["mag_dropped"] + c["mag_disabled"] + c["mag_pending"])
    assert c["received_mag"] == mag_accounted


# --------------------------------------------------------------------------- attitude


def test_static_level_imu_gives_zero_roll_and_pitch():
    pipe = ImuPipeline()
    outs = run(pipe, 300, mag=MAG_T)
    last = outs[-1]
    assert last.initialized
    roll, pitch, yaw = last.rpy_rad
    assert abs(roll) < 1e-6 and abs(pitch) < 1e-6
    assert yaw == pytest.approx(0.0, abs=1e-6)  # field north = sensor +y: facing east = yaw 0
    assert last.frame_id == "imu_link"
    assert (last.stamp_sec, last.stamp_nanosec) == divmod(T0_NS + 299 * DT_NS, 10**9)
    assert_invariant(pipe)


def test_upside_down_start_gives_roll_pi():
    pipe = ImuPipeline()
    outs = run(pipe, 200, accel=(0.0, 0.0, -G))
    roll, pitch, _ = outs[-1].rpy_rad
    assert abs(roll) == pytest.approx(math.pi, abs=1e-6)
    assert abs(pitch) < 1e-6
    # the first output already has it: initialisation from the first accelerometer sample
    assert abs(outs[0].rpy_rad[0]) == pytest.approx(math.pi, abs=1e-6)


def test_tilted_start_gives_the_accelerometer_roll():
    roll_true = 0.3
    accel = (0.0, G * math.sin(roll_true), G * math.cos(roll_true))
    out = run(ImuPipeline(), 50, accel=accel)[-1]
    assert out.rpy_rad[0] == pytest.approx(roll_true, abs=1e-6)


def test_ned_and_enu_outputs_differ_by_the_fixed_frame_rotation():
    tilt = (0.2, -0.1)  # roll, pitch
    q_true = quat.from_euler(tilt[0], tilt[1], 0.7)
    accel = quat.rotate(quat.conjugate(q_true), [0.0, 0.0, G])
    field = quat.rotate(quat.conjugate(q_true), [0.0, 20e-6, -40e-6])
    gyro = (0.05, -0.02, 0.1)
    enu = run(ImuPipeline(FilterParams(world_frame="enu")), 400, gyro=gyro, accel=accel,
              mag=field, mag_every=5)
    ned = run(ImuPipeline(FilterParams(world_frame="ned")), 400, gyro=gyro, accel=accel,
              mag=field, mag_every=5)
    for e, n in zip(enu[::50], ned[::50], strict=True):
        expected = quat.multiply(quat.Q_NED_FROM_ENU, wxyz(e))
        assert abs(float(np.dot(expected, wxyz(n)))) == pytest.approx(1.0, abs=1e-9)


def test_level_frd_sensor_in_ned_gives_zero_roll_and_pitch():
    """NED changes the world frame only; a body frame that is FRD (as NED users have) then reads
    level: at rest its specific force is (0, 0, -g)."""
    out = run(ImuPipeline(FilterParams(world_frame="ned", use_mag=False)), 50,
              accel=(0.0, 0.0, -G))[-1]
    assert abs(out.rpy_rad[0]) < 1e-9 and abs(out.rpy_rad[1]) < 1e-9


def test_orientation_is_ros_xyzw_order():
    out = run(ImuPipeline(), 5, accel=(0.0, 0.0, -G))[-1]
    x, y, z, w = out.orientation_xyzw
    # 180 deg about x: (x, y, z, w) = (1, 0, 0, 0) up to sign, so w is the last element
    assert abs(x) == pytest.approx(1.0) and abs(w) < 1e-9


def test_roll_and_yaw_are_continuous_with_rpy_unwrap():
    rate = 1.0  # rad/s about z
    wrapped = run(ImuPipeline(FilterParams(use_mag=False)), 800, gyro=(0, 0, rate))
    unwrapped = run(ImuPipeline(FilterParams(use_mag=False), PipelineParams(rpy_unwrap=True)),
                    800, gyro=(0, 0, rate))
    yaws = [o.rpy_rad[2] for o in unwrapped]
    assert max(abs(o.rpy_rad[2]) for o in wrapped) <= math.pi
    assert yaws[-1] == pytest.approx(rate * 799 * DT_NS * 1e-9, abs=1e-3)  # ~8 rad, no jump
    assert max(abs(b - a) for a, b in zip(yaws, yaws[1:], strict=False)) < 0.02


# --------------------------------------------------------------------------- outputs


def test_covariances_copied_and_orientation_covariance_from_parameters():
    pp = PipelineParams(orientation_covariance_rad2=0.001, yaw_covariance_rad2=0.002,
                        unreferenced_yaw_covariance_rad2=5.0)
    pipe = ImuPipeline(None, pp)
    first = pipe.on_imu(imu_msg(T0_NS))
    assert first.angular_velocity_covariance == (0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01)
    assert first.linear_acceleration_covariance == (0.02, 0, 0, 0, 0.02, 0, 0, 0, 0.02)
    assert first.angular_velocity == (0.0, 0.0, 0.0) and first.linear_acceleration == (0, 0, G)
    # no magnetometer yet: yaw unreferenced
    assert first.orientation_covariance == (0.001, 0, 0, 0, 0.001, 0, 0, 0, 5.0)
    pipe.on_mag(mag_msg(T0_NS + DT_NS))
    second = pipe.on_imu(imu_msg(T0_NS + DT_NS))
    assert second.orientation_covariance == (0.001, 0, 0, 0, 0.001, 0, 0, 0, 0.002)
    assert all(isinstance(c, float) for c in second.orientation_covariance)


def test_rclpy_like_and_duck_typed_messages_work():
    """rclpy stores covariances as NumPy/array.array; any object with the field names works."""

    def ns_imu(t_ns):
        return SimpleNamespace(
            header=SimpleNamespace(stamp=SimpleNamespace(sec=t_ns // 10**9, nanosec=t_ns % 10**9),
                                   frame_id="imu"),
            angular_velocity=SimpleNamespace(x=0.0, y=0.0, z=0.0),
            linear_acceleration=SimpleNamespace(x=0.0, y=0.0, z=G),
            angular_velocity_covariance=array.array("d", [0.0] * 9),
            linear_acceleration_covariance=[0.0] * 9,
        )

    pipe = ImuPipeline()
    outs = [pipe.on_imu(ns_imu(T0_NS + i * DT_NS)) for i in range(10)]
    assert all(o is not None and o.initialized for o in outs)


# --------------------------------------------------------------------------- magnetometer


def test_mag_dropout_keeps_output_flowing():
    pipe = ImuPipeline()
    outs = run(pipe, 100, mag=MAG_T)
    # the magnetometer stops: IMU messages keep producing outputs
    more = run(pipe, 300, start_ns=T0_NS + 100 * DT_NS)
    assert all(o is not None for o in outs + more)
    assert pipe.counters["mag_used"] == 100
    assert pipe.counters["processed"] == 400
    report = pipe.diagnostics()
    assert report.level == WARN and "no usable magnetometer sample for 3 s" in report.message
    assert_invariant(pipe)


def test_stale_mag_sample_is_not_used_and_counted():
    pipe = ImuPipeline(None, PipelineParams(mag_timeout_s=0.2))
    run(pipe, 10)
    pipe.on_mag(mag_msg(T0_NS - 10**9))  # one second older than the IMU stream
    out = pipe.on_imu(imu_msg(T0_NS + 10 * DT_NS))
    assert out is not None
    c = pipe.counters
    assert c["mag_stale"] == 1 and c["mag_used"] == 0
    assert_invariant(pipe)


def test_nan_mag_samples_are_ignored_and_counted():
    pipe = ImuPipeline()
    nan_field = (float("nan"), float("nan"), float("nan"))
    outs = run(pipe, 100, mag=nan_field)
    assert all(o is not None for o in outs)
    assert all(np.isfinite(o.orientation_xyzw).all() for o in outs)
    c = pipe.counters
    assert c["mag_invalid"] == 100 and c["mag_used"] == 0
    # one NaN component only ("not reported"): also ignored
    pipe.on_mag(mag_msg(T0_NS + 100 * DT_NS, (20e-6, float("nan"), -40e-6)))
    assert pipe.counters["mag_invalid"] == 101
    assert_invariant(pipe)


def test_mag_in_gauss_warns_once_and_heading_still_works():
    pipe = ImuPipeline()
    gauss = tuple(c * 1e4 for c in MAG_T)
    outs = run(pipe, 100, mag=gauss)
    warned = [w for o in outs for w in o.warnings]
    assert len(warned) == 1 and "Gauss" in warned[0]
    assert outs[-1].rpy_rad[2] == pytest.approx(0.0, abs=1e-6)
    assert "mag_units" in pipe.input_warnings


def test_newer_mag_sample_supersedes_the_pending_one():
    pipe = ImuPipeline()
    run(pipe, 5)
    pipe.on_mag(mag_msg(T0_NS + 5 * DT_NS))
    pipe.on_mag(mag_msg(T0_NS + 5 * DT_NS + 1000))
    pipe.on_imu(imu_msg(T0_NS + 5 * DT_NS))
    c = pipe.counters
    assert c["mag_dropped"] == 1 and c["mag_used"] == 1
    assert_invariant(pipe)


def test_mag_ignored_when_use_mag_is_false():
    pipe = ImuPipeline(FilterParams(use_mag=False))
    outs = run(pipe, 50, mag=MAG_T)
    assert pipe.counters["mag_disabled"] == 50
    assert outs[-1].orientation_covariance[8] == PipelineParams().unreferenced_yaw_covariance_rad2
    assert_invariant(pipe)


# --------------------------------------------------------------------------- time


def test_time_going_backwards_resets_and_is_counted():
    pipe = ImuPipeline()
    run(pipe, 300, gyro=(0.0, 0.0, 0.5))  # yaw turns
    assert abs(pipe.diagnostics().level) == WARN  # no mag: warn, fine
    # bag loop: stamps restart 3 s earlier
    out = pipe.on_imu(imu_msg(T0_NS))
    assert out is not None and out.initialized
    assert pipe.counters["resets"] == {"time_jump_back": 1}
    assert out.rpy_rad[2] == pytest.approx(0.0, abs=1e-9)  # re-initialised: yaw from scratch
    report = pipe.diagnostics()
    assert report.level == WARN and "filter reset" in report.message
    assert report.value("reset.time_jump_back") == "1"
    assert_invariant(pipe)


def test_time_going_backwards_without_reset_rejects_until_time_catches_up():
    pipe = ImuPipeline(None, PipelineParams(reset_on_time_jump_back=False))
    run(pipe, 100)
    assert pipe.on_imu(imu_msg(T0_NS)) is None
    assert pipe.counters["rejected"] == {"time_backwards": 1}
    assert pipe.on_imu(imu_msg(T0_NS + 100 * DT_NS)) is not None
    assert_invariant(pipe)


def test_small_backward_step_and_duplicate_stamp_are_rejected():
    pipe = ImuPipeline()
    run(pipe, 10)
    last = T0_NS + 9 * DT_NS
    assert pipe.on_imu(imu_msg(last)) is None
    assert pipe.on_imu(imu_msg(last - DT_NS // 2)) is None
    assert pipe.counters["rejected"] == {"duplicate_stamp": 1, "out_of_order": 1}
    assert pipe.counters["resets"] == {}
    assert_invariant(pipe)


def test_gap_is_not_integrated_and_long_gap_reinitialises():
    pipe = ImuPipeline(FilterParams(use_mag=False),
                       PipelineParams(max_dt_s=0.2, reset_after_gap_s=5.0))
    run(pipe, 100)
    yaw_before = pipe.on_imu(imu_msg(T0_NS + 100 * DT_NS)).rpy_rad[2]
    # 2 s gap while "turning" at 1 rad/s: integrating it would add 2 rad of yaw
    out = pipe.on_imu(imu_msg(T0_NS + 100 * DT_NS + 2 * 10**9, gyro=(0.0, 0.0, 1.0)))
    assert out is not None
    assert abs(out.rpy_rad[2] - yaw_before) == pytest.approx(0.01, abs=1e-6)  # one mean dt
    assert pipe.counters["gaps"] == 1
    report = pipe.diagnostics()
    assert report.value("dt_max_s") == "2"
    # a gap longer than reset_after_gap_s: reset, start again from this message
    out = pipe.on_imu(imu_msg(T0_NS + 100 * DT_NS + 10 * 10**9))
    assert out is not None and pipe.counters["resets"] == {"long_gap": 1}
    assert_invariant(pipe)


# --------------------------------------------------------------------------- bad data


def test_received_equals_processed_plus_rejected_over_a_mixed_stream():
    nan, inf = float("nan"), float("inf")
    pipe = ImuPipeline()
    expected = {}

    def bad(msg, reason):
        assert pipe.on_imu(msg) is None
        expected[reason] = expected.get(reason, 0) + 1

    t = T0_NS
    good = 0
    for i in range(400):
        t += DT_NS
        kind = i % 10
        if kind == 1:
            bad(imu_msg(t, gyro=(nan, 0.0, 0.0)), "nonfinite_gyro")
        elif kind == 2:
            bad(imu_msg(t, accel=(0.0, inf, G)), "nonfinite_accel")
        elif kind == 3:
            bad(imu_msg(t, accel=(0.0, 0.0, 0.0)), "zero_accel")
        elif kind == 4:
            bad(imu_msg(0), "zero_stamp")
        elif kind == 5:
            bad(SimpleNamespace(header=None), "malformed")
        elif kind == 6:
            msg = imu_msg(t)
            msg.angular_velocity_covariance = np.zeros(4)
            bad(msg, "malformed")
        else:
            if kind == 7:
                pipe.on_mag(mag_msg(t, (nan, nan, nan)))
            elif kind == 8:
                pipe.on_mag(mag_msg(t))
            assert pipe.on_imu(imu_msg(t, gyro=(0.01, 0.0, 0.0))) is not None
            good += 1
            if kind == 9:
                bad(imu_msg(t), "duplicate_stamp")
    c = pipe.counters
    assert c["received_imu"] == 400 + expected["duplicate_stamp"]
    assert c["processed"] == good
    assert c["rejected"] == expected
    assert_invariant(pipe)
    report = pipe.diagnostics()
    assert report.level == WARN and "rejected" in report.message
    for reason, count in expected.items():
        assert report.value(f"rejected.{reason}") == str(count)


def test_pipeline_never_raises_on_garbage():
    pipe = ImuPipeline()
    for garbage in (None, 42, "imu", SimpleNamespace(), object()):
        assert pipe.on_imu(garbage) is None
        assert pipe.on_mag(garbage) is None
    assert pipe.counters["rejected"] == {"malformed": 5}
    assert pipe.counters["mag_invalid"] == 5
    assert_invariant(pipe)


def test_suspicious_input_warns_once_each():
    pipe = ImuPipeline()
    outs = run(pipe, 250, gyro=(0.0, 0.0, 40.0), accel=(0.0, 0.0, 1.0), frame="/imu")
    texts = [w for o in outs if o is not None for w in o.warnings]
    tags = set(pipe.input_warnings)
    assert tags == {"IMU_frame_id_slash", "gyro_units", "accel_units"}
    assert len(texts) == 3
    assert any("deg/s" in t for t in texts) and any("units of g" in t for t in texts)
    empty = ImuPipeline()
    run(empty, 3, frame="")
    assert set(empty.input_warnings) == {"IMU_frame_id_empty"}
    removed = ImuPipeline()
    run(removed, 250, accel=(0.0, 0.1, 0.05))
    assert "accel_gravity_removed" in removed.input_warnings
    assert removed.diagnostics().level == WARN


# --------------------------------------------------------------------------- parameters


def test_apply_changes_rejects_invalid_values_and_leaves_state_untouched():
    pipe = ImuPipeline()
    run(pipe, 300, gyro=(0.0, 0.0, 0.2), mag=MAG_T, mag_every=3)
    state = pipe.filter.state_snapshot()
    fp, pp = pipe.filter_params, pipe.pipeline_params
    for changes, words in [
        ({"k1": -1.0}, "k1"),
        ({"k1": "fast"}, "k1"),
        ({"saturation_limit_rad": 0.0}, "saturation_limit_rad"),
        ({"aperiodic_time_constant_s": 500.0}, "unstable"),
        ({"k1": 0.7, "velocity_heading": "sideways"}, "velocity_heading"),
        ({"no_such_gain": 1.0}, "unknown"),
        ({"world_frame": "ned"}, "read-only"),
        ({"diagnostics_period_s": 2.0}, "read-only"),
        ({"reset_after_gap_s": 0.1}, "max_dt_s"),
    ]:
        ok, reason = pipe.apply_changes(changes)
        assert not ok and words in reason, (changes, reason)
        assert "\n" not in reason
        assert pipe.validate_changes(changes) == (False, reason)
    assert pipe.filter_params is fp and pipe.pipeline_params is pp
    after = pipe.filter.state_snapshot()
    for name in state.FIELDS:
        assert getattr(after, name) == getattr(state, name), name


def test_apply_changes_accepts_valid_values_and_keeps_the_attitude():
    pipe = ImuPipeline()
    run(pipe, 300, gyro=(0.0, 0.0, 0.2), mag=MAG_T, mag_every=3)
    before = pipe.filter.orientation_tuple()
    bias = tuple(pipe.filter.gyro_bias_rad_s)
    assert pipe.apply_changes({"k1": 0.7, "k2": 0.01, "world_frame": "enu"}) == (True, "")
    assert pipe.apply_changes({"orientation_covariance_rad2": 0.01, "rpy_unwrap": True})[0]
    assert pipe.filter_params.k1 == 0.7 and pipe.filter.params.k2 == 0.01
    assert pipe.filter.orientation_tuple() == before
    assert tuple(pipe.filter.gyro_bias_rad_s) == bias
    out = pipe.on_imu(imu_msg(T0_NS + 300 * DT_NS, gyro=(0.0, 0.0, 0.2)))
    assert out.orientation_covariance[0] == 0.01
    assert abs(float(np.dot(wxyz(out), before))) > 0.9999  # continuous: no re-initialisation


def test_use_mag_can_be_switched_off_live():
    pipe = ImuPipeline()
    run(pipe, 50, mag=MAG_T)
    assert pipe.apply_changes({"use_mag": False})[0]
    run(pipe, 50, start_ns=T0_NS + 50 * DT_NS, mag=MAG_T)
    assert pipe.counters["mag_disabled"] == 50
    assert_invariant(pipe)


# --------------------------------------------------------------------------- diagnostics


def test_diagnostics_report_contains_the_documented_keys():
    pipe = ImuPipeline()
    run(pipe, 300, mag=MAG_T)
    report = pipe.diagnostics(now_s=(T0_NS + 300 * DT_NS) * 1e-9)
    assert isinstance(report, DiagnosticsReport)
    keys = [k for k, _ in report.values]
    for key in DIAGNOSTIC_KEYS:
        assert key in keys, key
    assert all(isinstance(v, str) for _, v in report.values)
    assert report.level == OK and report.message == "running"
    assert report.hardware_id == "imu_link"
    assert float(report.value("input_rate_hz")) == pytest.approx(100.0)
    assert float(report.value("dt_mean_s")) == pytest.approx(0.01)
    assert report.value("mag_used") == "300"
    assert float(report.value("stamp_age_s")) == pytest.approx(0.01, abs=1e-6)


def test_diagnostics_levels():
    pipe = ImuPipeline()
    assert pipe.diagnostics().level == ERROR  # nothing received yet
    run(pipe, 300, mag=MAG_T)
    assert pipe.diagnostics(now_s=1.0).level == OK
    # silence: no IMU message during a whole period
    report = pipe.diagnostics(now_s=2.0)
    assert report.level == ERROR and "no IMU messages in the last 1 s" in report.message
    # every message of a period rejected
    for i in range(10):
        pipe.on_imu(imu_msg(T0_NS + (400 + i) * DT_NS, gyro=(float("nan"), 0.0, 0.0)))
    report = pipe.diagnostics(now_s=3.0)
    assert report.level == ERROR and "all 10 IMU messages rejected" in report.message
    # start-up phase is OK with its own message
    fresh = ImuPipeline()
    run(fresh, 20, mag=MAG_T)
    report = fresh.diagnostics()
    assert report.level == OK and report.message.startswith("starting up")


def test_private_state_shortcut_agrees_with_filter_status():
    """The pipeline reads per-sample flags from the filter state (speed); tie them to status()."""
    pipe = ImuPipeline()
    run(pipe, 300, mag=MAG_T)
    run(pipe, 3, start_ns=T0_NS + 300 * DT_NS, accel=(5.0, 0.0, G), mag=MAG_T)  # sudden push
    status = pipe.filter.status()
    state = pipe.filter._state  # noqa: SLF001
    assert status.clipped == bool(state.clipped) and status.clipped
    assert status.error_norm_rad == state.error_norm
    assert status.mag_status == "used" and pipe.counters["mag_used"] == 303
    assert status.heading_initialized == bool(state.heading_initialized)


def test_reset_drops_the_attitude_and_counts_the_reason():
    pipe = ImuPipeline()
    run(pipe, 10, mag=MAG_T)
    pipe.on_mag(mag_msg(T0_NS + 10 * DT_NS))
    pipe.reset("clock_jump_back")
    assert not pipe.initialized
    assert pipe.counters["resets"] == {"clock_jump_back": 1}
    assert pipe.counters["mag_dropped"] == 1
    assert pipe.on_imu(imu_msg(T0_NS)).initialized
    assert_invariant(pipe)


def test_ros_interface_doc_lists_the_diagnostic_keys():
    doc = (Path(__file__).resolve().parents[1] / "docs" / "ros_interface.md").read_text("utf-8")
    section = doc.split("## Diagnostics", 1)[1]
    missing = [k for k in DIAGNOSTIC_KEYS if f"`{k}`" not in section]
    assert not missing, missing
