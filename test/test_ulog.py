"""PX4 ulog input: reading, replay beside the autopilot's estimate, PX4 conventions, bad input.

Real logs from ../shared/data/ulogs (read in place, never copied into the repo; skipped when
absent): sample_px4_events.ulg (SITL, 31 s, vehicle_magnetometer, local position),
sample_appended_multiple.ulg (a real board, magnetometer inside sensor_combined, appended data),
sample_log_small.ulg (a 20-minute log whose sensor_combined covers 6.5 s). Synthetic logs
(cf_estimator.bench.ulogwrite) for what the real ones lack: several instances, no IMU, a known
attitude. Expected values are read from the logs with pyulog here, independently of the reader.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from ros_test_helpers import read_topics

pyulog = pytest.importorskip("pyulog")

from cf_estimator import metrics  # noqa: E402
from cf_estimator.bag import io, ulog  # noqa: E402
from cf_estimator.bag.fleet import find_bags  # noqa: E402
from cf_estimator.bag.replay import OUT_IMU_TOPIC, ReplayOptions, replay_bag  # noqa: E402
from cf_estimator.bench import ulogwrite  # noqa: E402
from cf_estimator.cli.main import main  # noqa: E402
from cf_estimator.core.params import FilterParams  # noqa: E402
from cf_estimator.pipeline import px4  # noqa: E402
from cf_estimator.pipeline.params import PipelineParams  # noqa: E402

ULOGS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ulogs"
SITL = ULOGS / "sample_px4_events.ulg"
BOARD = ULOGS / "sample_appended_multiple.ulg"
SHORT_IMU = ULOGS / "sample_log_small.ulg"
OPTS = ReplayOptions(progress=False)


def _require(path: Path) -> Path:
    if not path.is_file():
        pytest.skip(f"PX4 log {path} not available (expected in ../shared/data/ulogs)")
    return path


def _topic(path: Path, name: str) -> dict[str, np.ndarray]:
    return next(d for d in pyulog.ULog(str(path), [name]).data_list if d.name == name).data


def _attitude(path: Path) -> tuple[np.ndarray, np.ndarray]:
    d = _topic(path, "vehicle_attitude")
    t = d.get("timestamp_sample", d["timestamp"]).astype(np.int64) * 1000
    return t, np.stack([d[f"q[{i}]"] for i in range(4)], axis=1).astype(float)


def _output_q(out_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    msgs = read_topics(out_dir)[OUT_IMU_TOPIC]
    t = np.array([m.msg.header.stamp.sec * 10**9 + m.msg.header.stamp.nanosec for m in msgs])
    o = [m.msg.orientation for m in msgs]
    return t, np.array([[q.w, q.x, q.y, q.z] for q in o])


def _inclination_vs_log(out_dir: Path, log: Path) -> float:
    """Inclination RMS [deg] of the output bag's orientation against the log's
    vehicle_attitude, matched by stamp (nearest output at or before each attitude sample)."""
    t_out, q_out = _output_q(out_dir)
    t_att, q_att = _attitude(log)
    inside = (t_att >= t_out[0]) & (t_att <= t_out[-1])
    i = np.searchsorted(t_out, t_att[inside], side="right") - 1
    _tot, _head, incl = metrics.error_angles(metrics.error_quaternion(q_out[i], q_att[inside]))
    return float(np.degrees(np.sqrt(np.mean(incl ** 2))))


@pytest.fixture(scope="module")
def sitl(tmp_path_factory):
    d = tmp_path_factory.mktemp("sitl")
    result = replay_bag(_require(SITL), d / "out", options=OPTS)
    return {"dir": d, "result": result}


# -- reading ---------------------------------------------------------------------------------
def test_sitl_log_reads_as_a_bag_with_px4_units_and_stamps():
    with io.open_bag(_require(SITL)) as bag:
        assert bag.format == "px4-ulog"
        topics = {i.topic: (i.msgtype, i.count) for i in bag.topics}
        sc = _topic(SITL, "sensor_combined")
        assert topics["sensor_combined"] == (io.IMU_TYPE, len(sc["timestamp"]))
        assert topics["vehicle_magnetometer"][0] == io.MAG_TYPE
        first = next(bag.messages(["sensor_combined"]))
        assert first.log_time_ns == int(sc["timestamp"][0]) * 1000  # µs since boot -> ns
        st = first.msg.header.stamp
        assert st.sec * 10**9 + st.nanosec == int(sc["timestamp"][0]) * 1000
        assert first.msg.angular_velocity.y == pytest.approx(float(sc["gyro_rad[1]"][0]))
        assert first.msg.linear_acceleration.z == pytest.approx(
            float(sc["accelerometer_m_s2[2]"][0]))
        mag = next(bag.messages(["vehicle_magnetometer"])).msg.magnetic_field
        vm = _topic(SITL, "vehicle_magnetometer")
        assert mag.x == pytest.approx(float(vm["magnetometer_ga[0]"][0]) * 1e-4)  # Gauss -> T


def test_velocity_only_where_px4_says_it_is_valid():
    d = _topic(_require(SITL), "vehicle_local_position")
    valid = (d["v_xy_valid"] != 0) & (d["v_z_valid"] != 0)
    assert 0 < valid.sum() < len(valid)  # the log has both: the test can fail
    with io.open_bag(SITL) as bag:
        vel = [m.msg for m in bag.messages(["vehicle_local_position"])]
    assert len(vel) == int(valid.sum())
    assert vel[0].twist.linear.x == pytest.approx(float(d["vx"][valid][0]))
    assert vel[0].twist.linear.z == pytest.approx(float(d["vz"][valid][0]))


def test_old_log_takes_the_magnetometer_from_sensor_combined():
    with io.open_bag(_require(BOARD)) as bag:
        topics = {i.topic: i.count for i in bag.topics}
        assert "vehicle_magnetometer" not in topics
        n_mag, n_imu = topics[ulog.OLD_MAG_TOPIC], topics["sensor_combined"]
        assert 0 < n_mag < n_imu  # new samples only, not one per IMU row
        m = next(bag.messages([ulog.OLD_MAG_TOPIC])).msg.magnetic_field
        assert 1e-5 < math.hypot(m.x, m.y, m.z) < 1e-3  # tesla, not gauss


def test_chunks_and_messages_give_the_same_stream():
    with io.open_bag(_require(SITL)) as bag:
        topics = [i.topic for i in bag.topics]
        one = [(m.topic, m.log_time_ns) for m in bag.messages(topics)]
        many = [(t, ns) for c in bag.chunks(topics) for t, ns in zip(c.topic, c.log_ns,
                                                                      strict=True)]
    assert one == many
    assert [ns for _t, ns in one] == sorted(ns for _t, ns in one)


# -- replay beside the autopilot ---------------------------------------------------------------
def test_replay_output_is_frd_to_ned_on_the_log_clock_and_agrees_with_vehicle_attitude(sitl):
    s = sitl["result"].summary
    assert s["input_format"] == "px4-ulog"
    assert s["px4"]["output_frames"] == "frd body -> ned world"
    assert s["parameters"]["filter"]["world_frame"] == "ned"
    assert s["parameters"]["pipeline"]["body_frame"] == "frd"
    ref = s["reference"]
    assert ref["kind"] == "autopilot" and "not ground truth" in ref["label"]
    assert ref["topic"] == "vehicle_attitude"
    for k in ("roll", "pitch", "yaw"):
        assert k in ref["rpy_rmse_deg"] and k in ref["rpy_max_deg"]
    assert ref["rmse_deg"]["inclination"] <= 0.3
    # read back independently: the output bag's orientation, matched by stamp
    assert _inclination_vs_log(sitl["dir"] / "out", SITL) <= 0.3
    t_out, _q = _output_q(sitl["dir"] / "out")
    sc = _topic(SITL, "sensor_combined")
    assert t_out[0] == int(sc["timestamp"][0]) * 1000


@pytest.mark.parametrize("log", [BOARD, SHORT_IMU], ids=["board", "short_imu"])
def test_real_logs_agree_with_the_autopilot_in_inclination(log, tmp_path):
    result = replay_bag(_require(log), tmp_path / "out", options=OPTS)
    assert result.summary["reference"]["rmse_deg"]["inclination"] <= 0.3
    assert _inclination_vs_log(tmp_path / "out", log) <= 0.3


def test_declination_comes_from_the_log_and_turns_the_yaw_onto_the_autopilots(sitl, tmp_path):
    """PX4's NED is true north: the replay takes EKF2_MAG_DECL from the log (SITL: 3.32 deg, the
    simulated field's own declination) unless the user set it; the yaw then agrees with
    vehicle_attitude to a fraction of a degree, and not without it."""
    decl = float(pyulog.ULog(str(SITL), parse_header_only=True).initial_parameters[
        "EKF2_MAG_DECL"])
    s = sitl["result"].summary
    assert s["parameters"]["pipeline"]["magnetic_declination_rad"] == pytest.approx(
        math.radians(decl))
    assert any(c.startswith("magnetic_declination_rad=") for c in s["px4"]["conventions_applied"])
    assert s["reference"]["rpy_rmse_deg"]["yaw"] < 1.0
    opts = ReplayOptions(progress=False, explicit_params=frozenset({"magnetic_declination_rad"}))
    magnetic = replay_bag(SITL, tmp_path / "magnetic", options=opts).summary
    assert magnetic["parameters"]["pipeline"]["magnetic_declination_rad"] == 0.0
    assert magnetic["reference"]["rpy_rmse_deg"]["yaw"] > decl - 1.0
    assert magnetic["reference"]["rmse_deg"]["inclination"] == pytest.approx(
        s["reference"]["rmse_deg"]["inclination"], abs=1e-6)


@pytest.mark.parametrize(("value", "expect"), [
    (3.5, math.radians(3.5)), (-12.0, math.radians(-12.0)), (float("nan"), None), (200.0, None),
    ("x", None)])
def test_log_declination_is_taken_only_when_it_is_a_declination(value, expect):
    got = px4.log_defaults({"EKF2_MAG_DECL": value})
    assert got == ({} if expect is None else {"magnetic_declination_rad": pytest.approx(expect)})
    assert px4.log_defaults({}) == {}
    fp, pp, changed = px4.apply_px4_conventions(FilterParams(), PipelineParams(), (),
                                                {"EKF2_MAG_DECL": value})
    assert pp.magnetic_declination_rad == pytest.approx(expect if expect is not None else 0.0)
    kept = px4.apply_px4_conventions(FilterParams(), PipelineParams(magnetic_declination_rad=0.1),
                                     {"magnetic_declination_rad"}, {"EKF2_MAG_DECL": 3.5})[1]
    assert kept.magnetic_declination_rad == 0.1


def test_world_frame_set_by_the_user_is_kept_and_the_comparison_follows(sitl, tmp_path):
    fp = FilterParams(world_frame="enu")
    opts = ReplayOptions(progress=False, explicit_params=frozenset({"world_frame"}))
    enu = replay_bag(SITL, tmp_path / "enu", fp, options=opts)
    s = enu.summary
    assert s["parameters"]["filter"]["world_frame"] == "enu"
    assert s["px4"]["output_frames"] == "flu body -> enu world"
    ned_incl = sitl["result"].summary["reference"]["rmse_deg"]["inclination"]
    assert s["reference"]["rmse_deg"]["inclination"] == pytest.approx(ned_incl, abs=0.02)
    # the same attitude, expressed FLU -> ENU
    _t, q_ned = _output_q(sitl["dir"] / "out")
    _t, q_enu = _output_q(tmp_path / "enu")
    expect = px4.attitude_in_output_frames(q_ned, "enu", "flu")
    err = metrics.error_angles(metrics.error_quaternion(q_enu[-500:], expect[-500:]))[0]
    assert np.degrees(np.max(err)) < 0.5


def test_a_known_attitude_reads_back(tmp_path):
    log = ulogwrite.static_tilt_log(tmp_path / "tilt.ulg", 20.0, roll_deg=10.0)
    result = replay_bag(log, None, options=OPTS)
    rpy = np.degrees(result.series.rpy_rad[-100:])
    assert np.allclose(rpy[:, 0], 10.0, atol=0.3)  # roll +10 deg, FRD -> NED as PX4 states it
    assert np.allclose(rpy[:, 1], 0.0, atol=0.3)


MAG_OFFSET_GA = (0.0, 0.06, 0.0)  # a hard-iron offset across a 0.2 G horizontal field: 16.7 deg


def _saved_bias(device_id: int) -> dict[str, float | int]:
    return {"EKF2_MAGBIAS_X": MAG_OFFSET_GA[0], "EKF2_MAGBIAS_Y": MAG_OFFSET_GA[1],
            "EKF2_MAGBIAS_Z": MAG_OFFSET_GA[2], "EKF2_MAGBIAS_ID": device_id}


@pytest.mark.parametrize(("saved_for", "subtracted"), [(1000, True), (1001, False)])
def test_ekf2s_saved_magnetometer_bias_is_subtracted_where_ekf2_subtracted_it(
        tmp_path, saved_for, subtracted):
    """PX4 <= 1.11 subtracts EKF2_MAGBIAS_X/Y/Z from the magnetometer whose device id is
    EKF2_MAGBIAS_ID: the replay does the same, so a log whose magnetometer carries that offset
    gives the true heading (the synthetic vehicle faces north), and a bias saved for another
    device is left alone (the heading then shows the offset's 16.7 deg)."""
    log = ulogwrite.static_tilt_log(tmp_path / "bias.ulg", 20.0, mag_offset_ga=MAG_OFFSET_GA,
                                    parameters=_saved_bias(saved_for))
    result = replay_bag(log, None, options=OPTS)
    yaw = np.degrees(result.series.rpy_rad[-100:, 2])
    px4_summary = result.summary["px4"]
    applied = [c for c in px4_summary["conventions_applied"] if "EKF2_MAGBIAS" in c]
    assert "device 1000" in px4_summary["magnetometer_bias"] or not subtracted
    if subtracted:
        assert np.allclose(yaw, 0.0, atol=1.0)
        assert applied and "subtracted" in applied[0]
    else:
        assert np.all(np.abs(yaw) > 10.0)
        assert not applied
        assert "not subtracted: the magnetometer is device 1000" in px4_summary[
            "magnetometer_bias"]


@pytest.mark.parametrize(("params", "ids", "expect"), [
    (_saved_bias(7), {7}, "subtracted"),
    (_saved_bias(7), set(), "does not say which magnetometer"),
    (_saved_bias(7), {7, 8}, "device 7, 8"),
    ({**_saved_bias(7), "EKF2_MAGBIAS_Y": 0.0}, {7}, ""),  # all zero: nothing saved
    ({**_saved_bias(7), "EKF2_MAGBIAS_Y": float("nan")}, {7}, ""),
    ({**_saved_bias(7), "EKF2_MAGBIAS_Y": 3.0}, {7}, ""),  # 3 G is not a bias
    ({"EKF2_MAGBIAS_Y": 0.06}, {7}, ""),  # no device id saved
])
def test_saved_magnetometer_bias_only_when_it_is_one_and_ekf2_used_it(params, ids, expect):
    bias, text = px4.saved_mag_bias(params, ids)
    assert (bias is not None) == (expect == "subtracted")
    if bias is not None:
        assert np.allclose(bias, MAG_OFFSET_GA)
    assert (expect in text) if expect else text == ""


def test_real_log_with_a_saved_magnetometer_bias_reads_as_ekf2s(monkeypatch):
    """sample_log_small.ulg (PX4 1.10) saved a bias for the magnetometer EKF2 used: subtracted,
    the heading moves 4 deg towards the autopilot's (13.9 -> 9.8 deg RMS; what is left is the
    autopilot's own heading, which does not follow its magnetometer in this excerpt)."""
    params = pyulog.ULog(str(_require(SHORT_IMU)), parse_header_only=True).initial_parameters
    assert np.allclose(ulog.open_ulog(SHORT_IMU).mag_bias_ga,
                       [params[k] for k in px4.PX4_MAG_BIAS_PARAMS])
    with_bias = replay_bag(SHORT_IMU, None, options=OPTS).summary["reference"]["rpy_rmse_deg"]
    monkeypatch.setattr(px4, "saved_mag_bias", lambda _params, _ids: (None, ""))
    without = replay_bag(SHORT_IMU, None, options=OPTS).summary["reference"]["rpy_rmse_deg"]
    assert with_bias["yaw"] < without["yaw"] - 3.0
    assert with_bias["roll"] == pytest.approx(without["roll"], abs=0.05)


# -- bad input -----------------------------------------------------------------------------------
def test_truncated_log_replays_what_is_readable_and_says_how_much(tmp_path):
    data = _require(SITL).read_bytes()
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(data[: len(data) // 2 + 7])
    result = replay_bag(cut, None, options=OPTS)
    full = len(_topic(SITL, "sensor_combined")["timestamp"])
    assert 0 < result.summary["messages_in"] < full
    notes = [w for w in result.summary["warnings"] if "truncated" in w]
    assert len(notes) == 1 and "s of log" in notes[0] and "\n" not in notes[0]


def test_log_without_sensor_combined_is_one_line_naming_its_topics(tmp_path, capsys):
    log = ulogwrite.static_tilt_log(tmp_path / "noimu.ulg", 3.0, with_imu=False)
    with pytest.raises(io.BagError) as exc:
        io.open_bag(log)
    text = str(exc.value)
    assert "no sensor_combined" in text and "vehicle_attitude" in text
    assert "vehicle_magnetometer" in text and "\n" not in text
    assert main(["replay", str(log), "--json", str(tmp_path / "s.json")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no sensor_combined" in err[0]


def test_imu_covering_a_fraction_of_the_log_is_said_once_and_not_plotted_long(tmp_path):
    result = replay_bag(_require(SHORT_IMU), None, options=OPTS)
    lines = [w for w in result.summary["warnings"] if "covers only" in w]
    assert len(lines) == 1 and "6.5 s" in lines[0]
    # the comparison and its series stay within the IMU's span (plots: seconds, not minutes)
    ref_t = result.series.ref_t_s
    assert ref_t.size > 0 and ref_t[-1] - ref_t[0] < 8.0
    assert result.series.t_s[-1] - result.series.t_s[0] < 8.0


def test_several_instances_pick_one_say_which_and_instance_chooses(tmp_path, capsys):
    log = ulogwrite.static_tilt_log(tmp_path / "two.ulg", 5.0, mag_instances=2)
    with io.open_bag(log) as bag:
        assert bag.instances["vehicle_magnetometer"] == 0
        assert any("2 instances" in n and "--instance" in n for n in bag.notes)
        m0 = np.linalg.norm(bag.streams["vehicle_magnetometer"].values[:, :3], axis=1).mean()
    with io.open_bag(log, ulog_instance=1) as bag:
        assert bag.instances["vehicle_magnetometer"] == 1
        m1 = np.linalg.norm(bag.streams["vehicle_magnetometer"].values[:, :3], axis=1).mean()
    assert m1 / m0 == pytest.approx(1.05, rel=0.01)  # the second instance reads 5 % high
    assert main(["replay", str(log), "--instance", "3", "--json", str(tmp_path / "s.json")]) == 2
    assert "not 3 (--instance)" in capsys.readouterr().err


def test_a_file_that_is_not_a_ulog_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"not a ulog at all")
    assert main(["replay", str(bad), "--json", str(tmp_path / "s.json")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a readable PX4 ulog" in err[0]


# -- every offline command -----------------------------------------------------------------------
def test_cli_replay_prints_the_autopilot_comparison_and_writes_json(tmp_path, capsys):
    out = tmp_path / "s.json"
    assert main(["replay", str(_require(SITL)), "--json", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    line = next(x for x in text.splitlines() if x.startswith("autopilot"))
    assert "not ground truth" in line and "inclination" in line and "roll" in line
    s = json.loads(out.read_text())
    assert s["reference"]["kind"] == "autopilot"


def test_fleet_directory_mixing_bags_and_ulogs_finds_both(tmp_path):
    (tmp_path / "a.ulg").symlink_to(_require(SITL))
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.bag").write_bytes(b"")
    found = {p.name for p in find_bags([tmp_path])}
    assert found == {"a.ulg", "b.bag"}


def test_tune_reads_a_ulog_with_vehicle_attitude_as_reference():
    from cf_estimator.bench.bagtrial import load_bag_trial

    trial = load_bag_trial(_require(SITL))
    assert trial.topics["reference"] == "vehicle_attitude"
    assert trial.topics["imu"] == "sensor_combined"
    # the reference is in the trial's frames (FRD sensor axes, ENU world): gravity agrees
    ok = np.all(np.isfinite(trial.quat_ref), axis=1)
    q = trial.quat_ref[ok][0]
    a0 = trial.accel_m_s2[ok][0]
    acc = a0 / np.linalg.norm(a0)
    w, x, y, z = q
    up_in_body = np.array([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])
    assert np.dot(up_in_body, acc) > 0.99  # at rest the accelerometer points up


def test_bulk_and_message_by_message_replays_agree(sitl):
    one = replay_bag(SITL, None, options=ReplayOptions(progress=False, bulk_decode=False))
    bulk = sitl["result"].summary["reference"]
    ref = one.summary["reference"]
    assert ref["samples_scored"] == bulk["samples_scored"]
    assert ref["rmse_deg"] == pytest.approx(bulk["rmse_deg"])


def test_reference_topic_none_leaves_the_autopilot_out():
    result = replay_bag(_require(SITL), None,
                        options=ReplayOptions(progress=False, reference_topic="none"))
    assert "reference" not in result.summary
    assert result.summary["px4"]["output_frames"] == "frd body -> ned world"


def test_copy_inputs_writes_the_log_topics_as_ros_messages(tmp_path):
    log = ulogwrite.static_tilt_log(tmp_path / "t.ulg", 3.0)
    replay_bag(log, tmp_path / "out", options=ReplayOptions(progress=False, copy_inputs=True))
    topics = read_topics(tmp_path / "out")
    assert {"sensor_combined", "vehicle_magnetometer", OUT_IMU_TOPIC} <= set(topics)
    imu = topics["sensor_combined"][0].msg
    assert imu.header.frame_id == "base_link_frd"
    assert imu.linear_acceleration.z == pytest.approx(-9.80665 * math.cos(math.radians(10)),
                                                      abs=0.1)


@pytest.mark.parametrize("name", ["sample_px4_events.ulg", "sample_log_small.ulg"])
def test_fast_parse_gives_what_pyulog_gives(name):
    import contextlib
    import io as io_

    data = _require(ULOGS / name).read_bytes()
    parsed = ulog._fast_parse(data)
    assert parsed is not None
    fast, cut = parsed
    assert cut is None
    with contextlib.redirect_stdout(io_.StringIO()):
        ref = pyulog.ULog(io_.BytesIO(data))
    assert (fast.start_timestamp, fast.last_timestamp) == (ref.start_timestamp,
                                                           ref.last_timestamp)
    assert [(d.name, d.multi_id) for d in fast.data_list] == \
        [(d.name, d.multi_id) for d in ref.data_list]
    for a, b in zip(fast.data_list, ref.data_list, strict=True):
        assert a.data.keys() == b.data.keys()
        for k in a.data:
            assert np.array_equal(a.data[k], b.data[k], equal_nan=True), (a.name, k)


def test_appended_data_is_left_to_pyulog():
    assert ulog._fast_parse(_require(BOARD).read_bytes()) is None


@pytest.mark.parametrize("world", ["ned", "enu", "nwu"])
def test_vehicle_attitude_in_the_output_frames_rotates_vectors_alike(world):
    from cf_estimator.core import quaternion as quat

    rng = np.random.default_rng(3)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    v_frd = rng.normal(size=(20, 3))
    v_ned = quat.rotate(q, v_frd)
    body = px4.output_body("frd", world)
    v_body = v_frd if body == "frd" else v_frd * [1, -1, -1]
    expect = {"ned": v_ned, "enu": v_ned[:, [1, 0, 2]] * [1, 1, -1],
              "nwu": v_ned * [1, -1, -1]}[world]
    got = quat.rotate(px4.attitude_in_output_frames(q, world, body), v_body)
    assert np.allclose(got, expect)
