"""EuRoC readers, ground-truth interpolation, the inclination score and `bench euroc`.

Small EuRoC-layout folders are written by the tests; one test reads the real flights in
../shared/data/euroc when they are there.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from cf_estimator import metrics
from cf_estimator.bench import euroc
from cf_estimator.bench import euroc_eval as ev
from cf_estimator.cli.main import main
from cf_estimator.core import quaternion as quat
from cf_estimator.core.params import FilterParams
from cf_estimator.scenarios import from_body_rates

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "euroc"
T0_NS = 1403638127270096896  # an EuRoC-like absolute stamp
G = 9.80665
IMU_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
              "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
ASL_HEADER = "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], " \
             "q_RS_y [], q_RS_z [], v_RS_R_x [m s^-1]"


def _axis_angle(axis, deg):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    h = math.radians(deg) / 2
    return np.array([math.cos(h), *(math.sin(h) * axis)])


def _flight_truth(duration_s=15.0, rate=200.0, seed=0):
    """Gentle motion of a sensor mounted +x up (EuRoC-like): stamps [ns], gyro, accel, q."""
    rng = np.random.default_rng(seed)
    n = round(duration_s * rate)
    t = np.arange(n) / rate
    w = np.zeros((n, 3))
    for i in range(3):
        f, ph = rng.uniform(0.1, 0.4), rng.uniform(0, 2 * np.pi)
        w[:, i] = 0.3 * np.sin(2 * np.pi * f * t + ph) * (t > 3.0)
    q0 = _axis_angle([0, 1, 0], -90.0)  # sensor x up
    truth = from_body_rates(t, w, q0)
    acc = quat.rotate(quat.conjugate(truth.q_world_from_body), np.array([0.0, 0.0, G]))
    stamps = T0_NS + np.round(t * 1e9).astype(np.int64)
    return stamps, w, acc, truth.q_world_from_body


def _write_imu(path: Path, stamps, gyro, acc, header=IMU_HEADER, sep=","):
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [header] if header else []
    for s, g, a in zip(stamps, gyro, acc, strict=True):
        lines.append(sep.join([str(int(s))] + [repr(float(x)) for x in (*g, *a)]))
    path.write_text("\n".join(lines) + "\n")


def _write_asl_gt(path: Path, stamps, q):
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [ASL_HEADER]
    for s, qq in zip(stamps, q, strict=True):
        lines.append(",".join([str(int(s)), "1.0", "2.0", "0.5"] + [f"{x:.9f}" for x in qq]
                              + ["0.0"] * 9))
    path.write_text("\n".join(lines) + "\n")


def _write_tum_gt(path: Path, stamps, q):
    lines = ["# timestamp(s) tx ty tz qx qy qz qw"]
    for s, (w, x, y, z) in zip(stamps, q, strict=True):
        sec = f"{int(s) // 10**9}.{int(s) % 10**9:09d}"
        lines.append(f"{sec} 1.0 2.0 0.5 {x:.9f} {y:.9f} {z:.9f} {w:.9f}")
    path.write_text("\n".join(lines) + "\n")


def _write_flight(folder: Path, fmt="asl", yaw_deg=37.0, gt_slice=slice(300, -100), seed=0):
    """An EuRoC folder; the ground truth's world heading is rotated by ``yaw_deg`` (arbitrary
    heading, as in EuRoC) and covers only ``gt_slice`` of the IMU samples."""
    stamps, w, acc, q = _flight_truth(seed=seed)
    _write_imu(folder / euroc.IMU_CSV, stamps, w, acc)
    q_gt = quat.multiply(_axis_angle([0, 0, 1], yaw_deg), q)[gt_slice]
    if fmt == "asl":
        _write_asl_gt(folder / euroc.ASL_GT_CSV, stamps[gt_slice], q_gt)
    else:
        _write_tum_gt(folder / "groundtruth_tum.txt", stamps[gt_slice], q_gt)
    return stamps, q


# -- readers -----------------------------------------------------------------------------------
def test_imu_reader_headers_separators_unsorted_and_repeated(tmp_path):
    p = tmp_path / "imu.csv"
    p.write_text(
        "# a comment\n"
        "timestamp,wx,wy,wz,ax,ay,az\n"  # a header line without '#'
        "\n"
        "3000 0.3 0.0 0.0  9.0 0 0\n"  # whitespace separated
        "1000,0.1,0,0,9.1,0,0\n"
        "2000 , 0.2, 0, 0, 9.2, 0, 0\n"
        "1000,0.7,0,0,9.7,0,0\n"  # repeated stamp: the first row is kept
    )
    t, gyro, acc, notes = euroc.read_imu(p)
    assert t.tolist() == [1000, 2000, 3000]
    assert gyro[:, 0].tolist() == [0.1, 0.2, 0.3]
    assert acc[:, 0].tolist() == [9.1, 9.2, 9.0]
    assert any("sorted" in n for n in notes) and any("1 repeated" in n for n in notes)


def test_imu_reader_errors_are_one_line(tmp_path):
    with pytest.raises(euroc.EurocDataError, match="IMU csv not found"):
        euroc.read_imu(tmp_path / "missing.csv")
    p = tmp_path / "bad.csv"
    p.write_text(IMU_HEADER + "\n1000,0,0,0,9.8,0,0\n2000,0,0,x,9.8,0,0\n")
    with pytest.raises(euroc.EurocDataError, match=r"bad.csv:3: expected 7 numeric") as exc:
        euroc.read_imu(p)
    assert "\n" not in str(exc.value)
    p.write_text(IMU_HEADER + "\n1000,0,0,0,9.8,0\n")  # a short row
    with pytest.raises(euroc.EurocDataError, match="bad.csv:2"):
        euroc.read_imu(p)
    p.write_text(IMU_HEADER + "\n")
    with pytest.raises(euroc.EurocDataError, match="no data rows"):
        euroc.read_imu(p)


def test_asl_and_tum_ground_truth_give_the_same_orientation(tmp_path):
    stamps, _w, _acc, q = _flight_truth(duration_s=2.0)
    _write_asl_gt(tmp_path / "gt.csv", stamps, q)
    _write_tum_gt(tmp_path / "gt.txt", stamps, q)
    t_a, q_a, _ = euroc.read_groundtruth(tmp_path / "gt.csv")  # detected: ASL
    t_t, q_t, _ = euroc.read_groundtruth(tmp_path / "gt.txt")  # detected: TUM
    assert np.array_equal(t_a, stamps) and np.array_equal(t_t, stamps)  # exact ns from seconds
    assert np.allclose(q_a, q, atol=1e-8) and np.allclose(q_t, q, atol=1e-8)
    # without header comments the stamp magnitude decides (ns vs s)
    for name in ("gt.csv", "gt.txt"):
        body = (tmp_path / name).read_text().split("\n", 1)[1]
        (tmp_path / ("bare_" + name)).write_text(body)
    assert np.allclose(euroc.read_groundtruth(tmp_path / "bare_gt.csv")[1], q, atol=1e-8)
    assert np.allclose(euroc.read_groundtruth(tmp_path / "bare_gt.txt")[1], q, atol=1e-8)
    # the wrong explicit format: ns read as seconds do not fit, said in one line
    with pytest.raises(euroc.EurocDataError, match=r"gt.csv:2: timestamp .* out of range"):
        euroc.read_groundtruth(tmp_path / "gt.csv", "tum")


def test_ground_truth_errors(tmp_path):
    p = tmp_path / "gt.csv"
    p.write_text(ASL_HEADER + "\n1000,0,0,0,0,0,0,0,0\n")
    with pytest.raises(euroc.EurocDataError, match="zero quaternion"):
        euroc.read_groundtruth(p)
    with pytest.raises(euroc.EurocDataError, match="ground truth not found"):
        euroc.read_groundtruth(tmp_path / "none.csv")


def test_slerp_onto_imu_stamps_coverage_and_gaps():
    t_gt = np.array([0, 10, 20, 400], dtype=np.int64) * 10**7  # 0, 0.1, 0.2, 4.0 s
    q_gt = np.array([[1.0, 0, 0, 0], _axis_angle([1, 0, 0], 20.0), _axis_angle([1, 0, 0], 40.0),
                     _axis_angle([1, 0, 0], 40.0)])
    t = np.array([-5, 5, 15, 20, 100, 500, 400], dtype=np.int64) * 10**7
    out = euroc.interpolate_groundtruth(t_gt, q_gt, t, max_gap_s=0.5)
    assert np.all(np.isnan(out[[0, 4, 5]]))  # before, inside the 3.8 s gap, after
    assert np.allclose(out[1], _axis_angle([1, 0, 0], 10.0))
    assert np.allclose(out[2], _axis_angle([1, 0, 0], 30.0))
    assert np.allclose(out[3], q_gt[2]) and np.allclose(out[6], q_gt[3])  # on GT samples


def test_discovery_nested_single_and_errors(tmp_path):
    root = tmp_path / "data"
    _write_flight(root / "room1" / "A")
    _write_flight(root / "B", fmt="tum")
    (root / "empty").mkdir()
    found = euroc.find_flights(root)
    assert found == [root / "B", root / "room1" / "A"]
    names = [f.name for f in euroc.load_flights(root)]
    assert names == ["B", "room1/A"]
    assert euroc.find_flights(root / "B") == [root / "B"]  # a single flight folder
    assert euroc.load_flight(root / "B").name == "B"
    with pytest.raises(euroc.EurocDataError, match="no EuRoC flight"):
        euroc.find_flights(root / "empty")
    with pytest.raises(euroc.EurocDataError, match="data directory not found"):
        euroc.find_flights(tmp_path / "nowhere")
    with pytest.raises(euroc.EurocDataError, match="not a directory"):
        euroc.find_flights(root / "B" / euroc.IMU_CSV)
    with pytest.raises(euroc.EurocDataError, match="not an EuRoC flight folder"):
        euroc.load_flight(root / "empty")


def test_load_flight_interpolates_and_marks_uncovered_samples(tmp_path):
    stamps, q = _write_flight(tmp_path / "F", yaw_deg=0.0)
    f = euroc.load_flight(tmp_path / "F")
    assert f.n_samples == stamps.size and f.t0_ns == T0_NS
    assert f.t_s[0] == 0.0 and f.rate_hz == pytest.approx(200.0)
    has = f.has_reference
    assert has.sum() == stamps.size - 400 and not has[:300].any() and not has[-100:].any()
    assert np.allclose(f.q_ref[has], q[has], atol=1e-7)
    assert f.groundtruth_path == tmp_path / "F" / euroc.ASL_GT_CSV


def test_missing_or_foreign_ground_truth(tmp_path):
    stamps, w, acc, q = _flight_truth(duration_s=2.0)
    folder = tmp_path / "F"
    _write_imu(folder / euroc.IMU_CSV, stamps, w, acc)
    with pytest.raises(euroc.EurocDataError, match="no ground truth in"):
        euroc.load_flight(folder)
    f = euroc.load_flight(folder, require_groundtruth=False)
    assert np.all(np.isnan(f.q_ref)) and f.groundtruth_path is None
    _write_tum_gt(tmp_path / "other.txt", stamps + 10**12, q)  # another clock: no overlap
    with pytest.raises(euroc.EurocDataError, match="covers none of the IMU samples"):
        euroc.load_flight(folder, tmp_path / "other.txt")
    _write_tum_gt(tmp_path / "mine.txt", stamps, q)  # given explicitly
    assert euroc.load_flight(folder, tmp_path / "mine.txt").has_reference.all()


# -- the inclination metric and the score ------------------------------------------------------
def test_inclination_ignores_heading_and_measures_tilt():
    q_ref = quat.multiply(_axis_angle([0, 1, 0], -90.0),
                          np.tile(_axis_angle([0.3, 0.2, 1.0], 25.0), (4, 1)))
    yawed = quat.multiply(_axis_angle([0, 0, 1], 123.0), q_ref)  # world heading offset
    assert np.allclose(metrics.inclination_error_deg(yawed, q_ref), 0.0, atol=1e-5)
    tilted = quat.multiply(_axis_angle([1, 1, 0], 7.5), yawed)  # + a world-frame tilt of 7.5°
    assert np.allclose(metrics.inclination_error_deg(tilted, q_ref), 7.5, atol=1e-6)
    # = the angle between estimated and true "up" in the sensor frame
    up_est = quat.rotate(quat.conjugate(tilted), np.array([0.0, 0.0, 1.0]))
    up_ref = quat.rotate(quat.conjugate(q_ref), np.array([0.0, 0.0, 1.0]))
    angle = np.degrees(np.arccos(np.clip(np.sum(up_est * up_ref, axis=1), -1, 1)))
    assert np.allclose(angle, 7.5, atol=1e-6)


def test_rms_max_masks_and_propagates_nan():
    assert metrics.rms_max([3.0, 4.0, 100.0], [True, True, False]) == pytest.approx(
        (math.sqrt(12.5), 4.0, 2))
    rms, peak, n = metrics.rms_max([1.0, np.nan])
    assert math.isnan(rms) and math.isnan(peak) and n == 2
    assert metrics.rms_max([1.0], [False])[2] == 0


def test_score_flight_uses_settle_time_and_reference_coverage(tmp_path):
    _write_flight(tmp_path / "F", yaw_deg=50.0)
    f = euroc.load_flight(tmp_path / "F")
    tilt = _axis_angle([0, 1, 0], 2.0)
    q_est = quat.multiply(tilt, quat.multiply(_axis_angle([0, 0, 1], -50.0), f.q_ref))
    q_est[f.t_s < 5.0] = quat.multiply(_axis_angle([1, 0, 0], 30.0), q_est[f.t_s < 5.0])
    s = ev.score_flight(f, q_est, settle_s=5.0)
    assert s["inclination_rms_deg"] == pytest.approx(2.0, abs=1e-6)
    assert s["inclination_max_deg"] == pytest.approx(2.0, abs=1e-6)
    assert s["n_scored"] == int((f.has_reference & (f.t_s >= 5.0)).sum())
    assert ev.score_flight(f, q_est, settle_s=0.0)["inclination_max_deg"] > 29.0


def test_unknown_and_uninstalled_peers(monkeypatch):
    monkeypatch.setitem(ev.ALGORITHMS, "fake", ev.Algorithm("fake", ev._peer("vqf"),
                                                            "no_such_package_cf"))
    run, skipped = ev.select_peers(["fake"])
    assert run == [] and skipped == ["fake"]
    with pytest.raises(ValueError, match="unknown peer 'kalman'"):
        ev.select_peers(["kalman"])


def test_onboard_filter_is_read_from_the_recording_and_only_when_named():
    """`--peers onboard`: the sensor's own filter as recorded (phantom4's Xsens DOTs), scored
    like every column; never part of 'all'; NaN where a recording has none (EuRoC)."""
    assert "onboard" not in ev.peer_names() and "onboard" in ev.peer_names(recorded=True)
    assert ev.select_peers(["onboard"]) == (["onboard"], [])
    folder = REAL_DATA.parent / "phantom4_horizontal" / "H01_imu1"
    if not folder.is_dir():
        pytest.skip(f"phantom4 recording not available (expected in {folder})")
    flight = euroc.load_flight(folder)
    q = ev.ALGORITHMS["onboard"].run(flight, FilterParams())
    covered = np.isfinite(q).all(axis=1)
    assert covered.all()  # the last few ms beyond the file's stamps are held
    np.testing.assert_allclose(np.linalg.norm(q[covered], axis=1), 1.0, atol=1e-9)
    score = ev.score_flight(flight, q)["inclination_rms_deg"]
    assert 0.3 < score < 3.0  # the DOT's filter: about 1-1.5° against the DJI reference
    # a recording without the file: NaN rows, scored NaN (not a fake 0)
    mh = euroc.load_flight(REAL_DATA / "MH_04_difficult")
    assert np.isnan(ev.ALGORITHMS["onboard"].run(mh, FilterParams())).all()


def test_a_corrupt_onboard_file_is_one_line_and_exit_2(tmp_path, capsys):
    recording = REAL_DATA.parent / "phantom4" / "V01_imu1" / "mav0"
    if not recording.is_dir():
        pytest.skip(f"phantom4 recording not available (expected in {recording})")
    flight = tmp_path / "V01_imu1"
    flight.mkdir()
    (flight / "mav0").symlink_to(REAL_DATA.parent / "phantom4" / "V01_imu1" / "mav0")
    (flight / ev.ONBOARD_FILE).write_text("#stamp,q_w,q_x,q_y,q_z\ngarbage,x\n")
    assert main(["bench", "euroc", "--data", str(flight), "--peers", "onboard"]) == 2
    err = capsys.readouterr().err
    assert "not an onboard orientation file" in err and ev.ONBOARD_FILE in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_peer_adapters_give_up_in_the_sensor_frame():
    """vqf offline and RIANN (when installed) find a static tilt from the accelerometer."""
    n, rate = 600, 200.0
    q_true = np.tile(quat.multiply(_axis_angle([1, 2, 0], 35.0), _axis_angle([0, 1, 0], -90.0)),
                     (n, 1))
    acc = quat.rotate(quat.conjugate(q_true), np.array([0.0, 0.0, G]))
    gyro = np.zeros((n, 3))
    from cf_estimator.bench import peers

    ran = 0
    for name, run in (("vqf", lambda: peers.run_vqf_offline(gyro, acc, None, rate)["6d"]),
                      ("riann", lambda: peers.run_riann(gyro, acc, rate))):
        if not ev.installed(ev.ALGORITHMS["vqf_offline" if name == "vqf" else name]):
            continue
        q = run()
        assert q.shape == (n, 4)
        assert metrics.inclination_error_deg(q[-1], q_true[-1]) < 1.0, name
        ran += 1
    if not ran:
        pytest.skip("neither vqf nor riann installed")


# -- the CLI -----------------------------------------------------------------------------------
@pytest.fixture
def euroc_dir(tmp_path):
    d = tmp_path / "euroc"
    _write_flight(d / "MH_x", fmt="asl", seed=1)
    _write_flight(d / "V_y", fmt="tum", seed=2, yaw_deg=-100.0)
    return d


def test_cli_bench_euroc_end_to_end(euroc_dir, tmp_path, capsys):
    js = tmp_path / "out.json"
    assert main(["bench", "euroc", "--data", str(euroc_dir), "--peers", "none", "--settle",
                 "3", "--json", str(js), "--jobs", "2"]) == 0
    out = capsys.readouterr().out
    assert "EuRoC: 2 flight(s)" in out and "after the first 3 s" in out
    lines = out.splitlines()
    assert any(ln.split()[:1] == ["MH_x"] for ln in lines)
    assert any(ln.split()[:1] == ["V_y"] for ln in lines)
    assert any(ln.split()[:1] == ["mean"] for ln in lines)
    doc = json.loads(js.read_text())
    assert set(doc["flights"]) == {"MH_x", "V_y"} and doc["settle_s"] == 3.0
    for name in ("MH_x", "V_y"):
        score = doc["flights"][name]["cf_estimator"]
        assert score["inclination_rms_deg"] < 1.0  # perfect sensors, heading offset ignored
        assert score["n_scored"] == 3000 - 400 - 300  # GT coverage and t >= 3 s
    assert doc["mean"]["cf_estimator"]["inclination_rms_deg"] == pytest.approx(
        np.mean([doc["flights"][n]["cf_estimator"]["inclination_rms_deg"]
                 for n in ("MH_x", "V_y")]), abs=1e-5)
    assert doc["meta"]["peers"] == [] and doc["meta"]["cf_estimator_params"]["use_mag"] in (
        True, False)


def test_cli_bench_euroc_peers_and_explicit_groundtruth(euroc_dir, tmp_path, capsys):
    pytest.importorskip("vqf")
    stamps, q = _write_flight(tmp_path / "one", yaw_deg=10.0, gt_slice=slice(0, None))
    gt = tmp_path / "elsewhere.txt"
    _write_tum_gt(gt, stamps, q)
    (tmp_path / "one" / euroc.ASL_GT_CSV).unlink()
    js = tmp_path / "one.json"
    assert main(["bench", "euroc", "--data", str(tmp_path / "one"), "--groundtruth", str(gt),
                 "--peers", "vqf", "--json", str(js)]) == 0
    doc = json.loads(js.read_text())
    # vqf brings its offline mode along, as ours runs online and offline
    assert set(doc["flights"]["one"]) == {"cf_estimator", "cf_estimator_offline", "vqf",
                                          "vqf_offline"}
    assert doc["flights"]["one"]["vqf_offline"]["inclination_rms_deg"] < 1.0
    assert doc["flights"]["one"]["cf_estimator_offline"]["inclination_rms_deg"] < 1.0
    capsys.readouterr()


def test_gyro_fault_is_added_to_the_x_axis_in_its_window_only():
    """euroc_eval.with_gyro_fault: GYRO_FAULT_RATE_RAD_S on x over [at, at + duration), nothing
    else changed; a flight that ends before the fault is over is refused."""
    stamps, w, acc, q = _flight_truth(duration_s=5.0)
    t = (stamps - stamps[0]) * 1e-9
    f = euroc.Flight("x", t, w, acc, q, 0, Path("."))
    g = ev.with_gyro_fault(f, 2.0)
    d = g.gyro_rad_s - f.gyro_rad_s
    window = (t >= 2.0) & (t < 2.0 + ev.GYRO_FAULT_DURATION_S)
    assert window.sum() == round(ev.GYRO_FAULT_DURATION_S * 200.0)
    assert np.all(d[window, 0] == pytest.approx(ev.GYRO_FAULT_RATE_RAD_S))
    assert not d[~window].any() and not d[:, 1:].any()
    assert g.accel_m_s2 is f.accel_m_s2 and g.q_ref is f.q_ref and g.name == "x"
    with pytest.raises(ValueError, match="before a gyro fault at 4.9 s is over"):
        ev.with_gyro_fault(f, 4.9)


def test_cli_bench_euroc_gyro_fault_moves_the_scores_of_every_algorithm(euroc_dir, tmp_path,
                                                                         capsys):
    """--gyro-fault reaches the algorithms: after a 34 deg step at 5 s the score from 5 s on
    is worse than without it (perfect sensors otherwise), for ours online and offline."""
    scores = {}
    for fault in ([], ["--gyro-fault", "5"]):
        js = tmp_path / f"f{len(fault)}.json"
        assert main(["bench", "euroc", "--data", str(euroc_dir), "--peers", "none", "--settle",
                     "5", "--json", str(js), *fault]) == 0
        doc = json.loads(js.read_text())
        scores[bool(fault)] = {a: s["inclination_rms_deg"] for a, s in doc["mean"].items()}
        assert doc["meta"]["gyro_fault_at_s"] == (5.0 if fault else None)
    out = capsys.readouterr().out
    assert "gyro fault: 3 rad/s added to the sensor x axis for 0.2 s at 5 s" in out
    for algo in ("cf_estimator", "cf_estimator_offline"):
        assert scores[True][algo] > scores[False][algo] + 1.0, algo
    assert main(["bench", "euroc", "--data", str(euroc_dir), "--peers", "none",
                 "--gyro-fault", "100"]) == 2
    assert "every flight ends before the fault is over" in capsys.readouterr().err
    assert main(["bench", "euroc", "--data", str(euroc_dir), "--peers", "none",
                 "--gyro-fault", "-1"]) == 2
    assert "--gyro-fault must be >= 0 s" in capsys.readouterr().err


def test_cli_bench_euroc_errors(euroc_dir, tmp_path, capsys):
    assert main(["bench", "euroc", "--data", str(tmp_path / "none"), "--peers", "none"]) == 2
    err = capsys.readouterr().err
    assert "data directory not found" in err and err.count("\n") == 1
    assert main(["bench", "euroc", "--data", str(euroc_dir), "--peers", "kalman"]) == 2
    assert "unknown peer 'kalman'" in capsys.readouterr().err
    assert main(["bench", "euroc", "--data", str(euroc_dir), "--peers", "none",
                 "--groundtruth", str(tmp_path / "x.txt")]) == 2
    assert "needs a single flight folder" in capsys.readouterr().err
    bad = euroc_dir / "MH_x" / euroc.IMU_CSV
    bad.write_text(bad.read_text() + "12,not,a,row\n")
    assert main(["bench", "euroc", "--data", str(euroc_dir), "--peers", "none"]) == 2
    assert "data.csv:3002: expected 7 numeric columns" in capsys.readouterr().err


# -- the real flights --------------------------------------------------------------------------
@pytest.mark.skipif(not REAL_DATA.is_dir(), reason=f"EuRoC flights not present in {REAL_DATA}")
def test_real_euroc_flights_load_and_agree_at_rest():
    flights = {f.name: f for f in euroc.load_flights(REAL_DATA)}
    expected = {"MH_03_medium": 27008, "MH_04_difficult": 20320, "MH_05_difficult": 22721}
    assert {n: f.n_samples for n, f in flights.items()} == expected
    for f in flights.values():
        assert f.rate_hz == pytest.approx(200.0, rel=1e-3) and not f.notes
        has = f.has_reference
        assert has.mean() > 0.95
        # first second of ground truth, before take-off:
        # the mean accelerometer direction agrees with the ground truth's "up" within 2°
        i = np.flatnonzero(has)[:200]
        up = quat.rotate(quat.conjugate(f.q_ref[i]), np.array([0.0, 0.0, 1.0])).mean(axis=0)
        a = f.accel_m_s2[i].mean(axis=0)
        angle = math.degrees(math.acos(up @ a / np.linalg.norm(up) / np.linalg.norm(a)))
        assert angle < 2.0, f.name
        assert a[0] > 9.0  # mounted +x up


def test_ours_is_the_first_column_and_uses_6d():
    assert next(iter(ev.ALGORITHMS)) == "cf_estimator" and ev.ALGORITHMS["cf_estimator"].ours
    assert ev.peer_names() == ["vqf", "vqf_offline", "madgwick", "fusion", "complementary",
                             "riann"]
    _s, w, acc, _q = _flight_truth(duration_s=1.0)
    f = euroc.Flight("x", np.arange(200) / 200.0, w, acc, np.full((200, 4), np.nan), 0, Path("."))
    q = ev.ALGORITHMS["cf_estimator"].run(f, FilterParams(use_mag=True))  # forced to 6-D
    assert np.all(np.isfinite(q))
