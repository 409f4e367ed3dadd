"""ArduPilot DataFlash logs (.bin) as replay input: the shared real logs (pymavlink reads them)
and logs written here with bench/dataflashwrite.py (known attitude, trim, crash, truncation).

The real logs live in ../shared/data/ardupilot (never copied): tests needing them skip naming
that directory.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pymavlink")

from conftest import DATA_ROOT  # noqa: E402

from cf_estimator import FilterParams, estimate  # noqa: E402
from cf_estimator.bag import dataflash  # noqa: E402
from cf_estimator.bag.fleet import find_bags  # noqa: E402
from cf_estimator.bag.logarrays import log_arrays  # noqa: E402
from cf_estimator.bag.replay import replay_bag  # noqa: E402
from cf_estimator.bench import dataflashwrite as dfw  # noqa: E402
from cf_estimator.cli.main import main  # noqa: E402

ARDUPILOT = DATA_ROOT / "ardupilot"
COPTER = ARDUPILOT / "dronekit_log171.bin"
PLANE = ARDUPILOT / "pymavlink_test.BIN"


def _need(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"shared data missing: {path}")
    return path


def test_a_still_tilted_vehicle_reads_back_in_ardupilots_conventions(tmp_path):
    p = dfw.static_tilt_log(tmp_path / "still.bin", roll_deg=10.0)
    res = replay_bag(p, None)
    s = res.summary
    assert s["input_format"] == dataflash.DATAFLASH_FORMAT
    assert s["ardupilot"]["output_frames"] == "frd body -> ned world"
    roll, pitch, _yaw = np.degrees(res.series.rpy_rad[-1])
    assert abs(roll - 10.0) < 0.5 and abs(pitch) < 0.5  # FRD roll right-side down, as ATT
    ref = s["reference"]
    assert ref["kind"] == "autopilot" and ref["topic"] == "ATT"
    assert "autopilot's estimate (ATT" in ref["label"]
    assert ref["rmse_deg"]["inclination"] < 0.5
    assert res.series.t_s[0] == pytest.approx(30.0)  # stamps: the log's time since boot


def test_level_trim_turns_the_imu_into_the_vehicle_axes_att_refers_to(tmp_path):
    trim_deg = 3.0
    # the board sits rolled 10 deg; the autopilot, trimmed by 3 deg, says the vehicle is at 7
    p = dfw.static_tilt_log(tmp_path / "trim.bin", roll_deg=10.0,
                            parameters={"AHRS_TRIM_X": math.radians(trim_deg),
                                        "AHRS_TRIM_Y": 0.0})
    raw = dfw.static_tilt_log(tmp_path / "raw.bin", roll_deg=10.0)
    bag = dataflash.open_dataflash(p)
    assert bag.trim is not None
    assert any("AHRS_TRIM_X/Y (+3.00, +0.00 deg)" in n for n in bag.notes)
    a = log_arrays(p)
    b = log_arrays(raw)
    roll_trimmed = math.degrees(math.atan2(-a.accel_m_s2[:, 1].mean(), -a.accel_m_s2[:, 2].mean()))
    roll_raw = math.degrees(math.atan2(-b.accel_m_s2[:, 1].mean(), -b.accel_m_s2[:, 2].mean()))
    assert roll_raw == pytest.approx(10.0, abs=0.2)
    assert roll_trimmed == pytest.approx(10.0 - trim_deg, abs=0.2)


def test_a_log_that_ends_upside_down_is_scored_before_the_crash(tmp_path):
    n = 1000
    t = 10_000_000 + np.arange(n) * 20_000
    rng = np.random.default_rng(3)
    gyro = rng.normal(0, 0.002, (n, 3))
    accel = np.tile([0.0, 0.0, -9.80665], (n, 1)) + rng.normal(0, 0.05, (n, 3))
    att_t = t[::5]
    rpy = np.zeros((att_t.shape[0], 3))
    rpy[-20:, 0] = 179.0  # the last 0.4 s upside down: the autopilot's view of a flip
    p = dfw.write_dataflash(tmp_path / "crash.bin", [dfw.imu_message(t, gyro, accel),
                                                     dfw.att_message(att_t, rpy)])
    res = replay_bag(p, None)
    x = res.summary["ardupilot"]
    assert x["upside_down_s"] == pytest.approx(att_t[-20] * 1e-6)
    assert x["scored_until_s"] == pytest.approx(att_t[-20] * 1e-6 - dataflash.CRASH_MARGIN_S)
    # the level flight before it agrees; the crash itself is not scored
    assert res.summary["reference"]["max_deg"]["inclination"] < 1.0
    assert any("upside down" in w for w in res.summary["warnings"])


def test_plane_firmware_and_a_log_without_mag_are_said_in_one_line(tmp_path):
    p = dfw.static_tilt_log(tmp_path / "plane.bin", with_mag=False,
                            firmware="ArduPlane V4.0.0 (synthetic)")
    res = replay_bag(p, None)
    w = res.summary["warnings"]
    assert any(x.startswith("ArduPlane V4.0.0") for x in w)
    assert any(x.startswith("no MAG in this log") for x in w)
    assert res.summary["topics"]["mag"] is None
    assert res.summary["reference"]["heading_alignment"] == "first"


def test_a_truncated_log_replays_what_is_readable_and_says_where_it_stopped(tmp_path):
    p = dfw.static_tilt_log(tmp_path / "full.bin", duration_s=10.0)
    data = p.read_bytes()
    cut = tmp_path / "cut.bin"
    cut.write_bytes(data[: len(data) * 2 // 3 + 7])  # in the middle of a message
    bag = dataflash.open_dataflash(cut)
    assert bag.truncated
    note = next(n for n in bag.notes if "truncated DataFlash log" in n)
    assert "replaying what was readable" in note
    full = dataflash.open_dataflash(p)
    assert not full.truncated
    assert 0 < bag.streams["IMU"].t_ns.shape[0] < full.streams["IMU"].t_ns.shape[0]
    assert main(["replay", str(cut), "--json", str(tmp_path / "s.json"), "--no-progress"]) == 0


def test_imu_instance_option_and_an_instance_the_log_lacks(tmp_path, capsys):
    n = 200
    t = 1_000_000 + np.arange(n) * 20_000
    g = np.zeros((n, 3))
    a = np.tile([0.0, 0.0, -9.80665], (n, 1))
    a2 = np.tile([0.0, -9.80665 * math.sin(0.2), -9.80665 * math.cos(0.2)], (n, 1))
    p = dfw.write_dataflash(tmp_path / "two.bin", [dfw.imu_message(t, g, a),
                                                   dfw.imu_message(t, g, a2, name="IMU2")])
    first = dataflash.open_dataflash(p)
    assert first.instances["IMU"] == 0
    assert any("2 instances" in x and "--instance" in x for x in first.notes)
    second = dataflash.open_dataflash(p, instance=1)
    assert second.streams["IMU"].values[0, 26] == pytest.approx(a2[0, 1], rel=1e-6)
    code = main(["replay", str(p), "--instance", "4", "--json", str(tmp_path / "x.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "instances 0, 1, not 4" in err[0]


def test_a_file_that_is_not_a_dataflash_log_is_one_line(tmp_path, capsys):
    bad = tmp_path / "junk.BIN"
    bad.write_bytes(b"not a log at all" * 10)
    code = main(["replay", str(bad), "--json", str(tmp_path / "x.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and len(err) == 1 and "junk.BIN" in err[0]
    assert "Traceback" not in err[0]


def test_a_fleet_directory_finds_bin_logs_in_any_case(tmp_path):
    dfw.static_tilt_log(tmp_path / "a.bin", duration_s=4.0)
    dfw.static_tilt_log(tmp_path / "00000002.BIN", duration_s=4.0)
    found = find_bags([tmp_path])
    assert sorted(p.name for p in found) == ["00000002.BIN", "a.bin"]


def test_log_arrays_feed_estimate_in_ned(tmp_path):
    p = dfw.static_tilt_log(tmp_path / "est.bin", roll_deg=-20.0)
    log = log_arrays(p)
    assert log.reference_topic == "ATT" and log.reference_q_wxyz.shape[1] == 4
    assert np.isfinite(log.mag_T).all(axis=1).sum() > 0
    res = estimate(log.gyro_rad_s, log.accel_m_s2, log.mag_T, timestamps_s=log.t_s,
                   params=FilterParams(world_frame="ned"))
    assert math.degrees(res.euler_rad()[-1][0]) == pytest.approx(-20.0, abs=0.5)


def test_real_copter_flight_replays_and_agrees_with_att_before_the_flip(tmp_path):
    log = _need(COPTER)
    out = tmp_path / "s.json"
    assert main(["replay", str(log), "--json", str(out), "--no-progress"]) == 0
    s = json.loads(out.read_text())
    x = s["ardupilot"]
    assert "Copter" in x["vehicle"]
    assert x["scored_until_s"] is not None and x["scored_until_s"] < 239.0
    assert "offsets" in x["magnetometer"]
    ref = s["reference"]
    assert ref["topic"] == "ATT" and ref["kind"] == "autopilot"
    # measured 2.85 deg (docs/decisions/ardupilot-dataflash.md); a guard, not the figure
    assert ref["rmse_deg"]["inclination"] < 3.5
    assert set(x["estimates"]) >= {"AHR2", "EKF1"}
    # COMPASS_DEC 0 under COMPASS_AUTODEC: the EKF's earth field (EKF2 MN/ME) says the
    # declination, 0 on the ground and 13 deg once learned in flight
    assert x["heading_alignment"] == "none"
    assert ref["rmse_deg"]["heading"] < 6.0  # measured 5.3 (7.3 about the mean offset)


def test_real_plane_test_log_is_read_as_truncated_with_its_declination():
    bag = dataflash.open_dataflash(_need(PLANE))
    assert bag.truncated  # pymavlink's test file is the first 64 KiB of a log
    assert "Plane" in bag.vehicle
    d, note = bag.log_defaults()
    assert note == "" and d["magnetic_declination_rad"] == pytest.approx(
        bag.parameters["COMPASS_DEC"])
    assert set(bag.streams) >= {"IMU", "MAG", "ATT", "AHR2", "NKF1"}


def test_tune_reads_a_dataflash_log_with_att_as_reference(tmp_path):
    from cf_estimator.bench.bagtrial import load_bag_trial

    p = dfw.static_tilt_log(tmp_path / "tune.bin", roll_deg=5.0, duration_s=10.0)
    trial = load_bag_trial(p, world_frame="ned")
    assert trial.topics["reference"] == "ATT"
    q = trial.quat_ref[np.all(np.isfinite(trial.quat_ref), axis=1)]
    assert q.shape[0] > 0
    roll = 2 * math.degrees(math.atan2(q[0, 1], q[0, 0]))
    assert roll == pytest.approx(5.0, abs=0.01)


def test_gps_velocity_is_a_ned_stream_of_3d_fixes_only(tmp_path):
    t = 30_000_000 + np.arange(50) * 200_000  # 5 Hz, as ArduPilot logs GPS
    v = np.tile([3.0, -4.0, 0.5], (50, 1))  # north, west, down [m/s]
    status = np.where(np.arange(50) < 10, 1, 3)  # no fix for the first 2 s
    p = dfw.write_dataflash(tmp_path / "gps.bin", [
        dfw.imu_message(t, np.zeros((50, 3)), np.tile([0.0, 0.0, -9.80665], (50, 1))),
        dfw.gps_message(t, v, status)])
    bag = dataflash.open_dataflash(p)
    s = bag.streams[dataflash.VELOCITY_TOPIC]
    assert s.msgtype == "geometry_msgs/msg/TwistStamped"
    assert s.t_ns.shape[0] == 40 and s.t_ns[0] == t[10] * 1000  # 3-D fixes only
    np.testing.assert_allclose(s.values, v[10:], atol=1e-5)  # Spd along GCrs, VZ down: NED


def test_real_copter_flight_aided_by_its_gps_agrees_better_with_att(tmp_path):
    log = _need(COPTER)
    scores = {}
    for name, extra in (("imu", []), ("gps", ["--velocity-topic", "GPS"])):
        out = tmp_path / f"{name}.json"
        assert main(["replay", str(log), "--json", str(out), "--no-progress", *extra]) == 0
        scores[name] = json.loads(out.read_text())
    vel = scores["gps"]["velocity"]
    assert scores["gps"]["topics"]["velocity"] == "GPS"
    assert vel["used"] > 900  # of 1038 3-D fixes at 5 Hz
    # its 3.3 GPS stamps are boot time (T), not the GPS week's TimeMS: else nothing is used
    incl = {k: s["reference"]["rmse_deg"]["inclination"] for k, s in scores.items()}
    # measured 2.85 -> 1.66 deg: the flight's sustained accelerations, known from the GPS
    assert incl["gps"] < incl["imu"] - 0.8, incl


def test_headings_are_compared_about_the_declination_the_ekf_applied_at_each_time(tmp_path):
    """The autopilot's EKF learns the declination in flight (COMPASS_AUTODEC): its ATT heading
    is magnetic + atan2(ME, MN) of its earth field at that time, which the comparison uses."""
    n, rate = 1500, 50.0  # 30 s still, heading magnetic north
    t = 30_000_000 + np.round(np.arange(n) / rate * 1e6).astype(np.int64)
    gyro, accel = np.zeros((n, 3)), np.tile([0.0, 0.0, -9.80665], (n, 1))
    mag = np.tile([200.0, 0.0, 400.0], (n // 5, 1))  # mG, FRD = NED when level, north
    k = t[::5]  # 10 Hz; ATT compared from 1 s on (the heading is the compass's by then)
    dec = np.where(np.arange(k.shape[0]) < k.shape[0] // 2, 0.0, 10.0)  # learned halfway [deg]
    ekf = dfw.Message("XKF2", "QBffff", ("TimeUS", "C", "MN", "ME", "MD", "MX"),
                      [(int(tt), 0, 200.0 * math.cos(math.radians(d)),
                        200.0 * math.sin(math.radians(d)), 400.0, 0.0)
                       for tt, d in zip(k, dec, strict=True)])
    p = dfw.write_dataflash(tmp_path / "dec.bin", [
        dfw.imu_message(t, gyro, accel), dfw.mag_message(k, mag),
        dfw.att_message(k[10:], np.stack([0 * dec, 0 * dec, dec], axis=1)[10:]), ekf],
        parameters={"COMPASS_DEC": 0.0, "COMPASS_AUTODEC": 1.0})
    s = replay_bag(p, None).summary
    assert s["reference"]["heading_alignment"] == "none"
    assert s["reference"]["rmse_deg"]["heading"] < 0.5  # about the mean offset: 5 deg
    assert any("the declination the autopilot's EKF applied" in w for w in s["warnings"])
