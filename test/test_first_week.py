"""Issue 19, "a UAV team's first week": what a new UAV user hit, each pinned by a test.

Layering of the CLI and the bench, lazy sub-command imports, the body-frame option (FLU/FRD),
a covariance from the filter's state, the node's warning for a params file that misses it,
tune's safety (bounded search, held-out validation, --force), the ROS peers at their ROS
defaults, the filter at 10-50 Hz, and the papercuts of the first week.
"""

from __future__ import annotations

import ast
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from ros_test_helpers import Header, Imu, MagneticField, Quaternion, Time, Vector3

from cf_estimator.cli.main import build_parser
from cf_estimator.cli.main import main as cli_main
from cf_estimator.core import quaternion as quat
from cf_estimator.core.params import FilterParams
from cf_estimator.pipeline import ImuPipeline, PipelineParams

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "cf_estimator"


def _imported_modules(path: Path) -> set[str]:
    """Every module a source file imports (top level and inside functions)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


# -- item 9: layering --------------------------------------------------------------------------
def test_bench_never_imports_the_cli() -> None:
    offenders = {p.name: sorted(m for m in _imported_modules(p) if m.startswith("cf_estimator.cli"))
                 for p in (PKG / "bench").glob("*.py")}
    assert {k: v for k, v in offenders.items() if v} == {}


def test_cli_common_and_main_do_not_import_each_other() -> None:
    common = _imported_modules(PKG / "cli" / "common.py")
    main = _imported_modules(PKG / "cli" / "main.py") - {"cf_estimator.cli.main"}  # -m re-entry
    assert "cf_estimator.cli.main" not in common
    assert "cf_estimator.cli.common" in main  # the one direction left: main uses common
    assert "cf_estimator.cli.base" in common


def test_grid_bad_params_file_is_one_line(tmp_path) -> None:
    bad = tmp_path / "p.yaml"
    bad.write_text("cf_estimator:\n  ros__parameters:\n    k1: fast\n")
    r = subprocess.run([sys.executable, "-m", "cf_estimator.bench.grid", "--data", str(tmp_path),
                        "--set", "k1=1", "--params", str(bad)], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("grid: ") and "k1" in r.stderr
    assert "Traceback" not in r.stderr


# -- item 8: lazy imports, help ----------------------------------------------------------------
_BLOCKED = "import sys; sys.modules['scipy'] = None; sys.modules['rosbags'] = None; "


def _cli_without_scipy_rosbags(*argv: str) -> subprocess.CompletedProcess:
    code = _BLOCKED + "from cf_estimator.cli.main import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True)


def test_version_works_without_scipy_and_rosbags() -> None:
    r = _cli_without_scipy_rosbags("--version")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("cf-estimator ") and r.stderr == ""


def test_missing_package_is_one_line_naming_what_to_install() -> None:
    # design's formulas need no scipy; its thesis check (the exact transition, expm) does
    for argv, pkg in ((("design", "--thesis"), "scipy"), (("replay", "in"), "rosbags")):
        r = _cli_without_scipy_rosbags(*argv)
        assert r.returncode == 2
        lines = r.stderr.strip().splitlines()
        assert "Traceback" not in r.stderr
        assert lines[-1].startswith("cf-estimator: error: ") and f"pip install {pkg}" in lines[-1]


def test_top_level_help_lists_bench_euroc() -> None:
    assert "euroc" in build_parser().format_help()


# -- item 3: body frame (FLU / FRD) -------------------------------------------------------------
G = 9.80665
T0_NS = 1_700_000_000 * 10**9
#: Earth field in NED (north, east, down) [T], dip 60 deg.
MAG_NED_T = (20e-6, 0.0, 34.6e-6)


def _frd_to_flu(v) -> tuple[float, float, float]:
    return (float(v[0]), -float(v[1]), -float(v[2]))


def _frd_sample(roll_deg: float, pitch_deg: float, yaw_deg: float):
    """Specific force [m/s^2] and field [T] in FRD of a still body at PX4's Euler angles."""
    q_ned_from_frd = quat.from_euler(*np.radians([roll_deg, pitch_deg, yaw_deg]))
    q_inv = quat.conjugate(q_ned_from_frd)
    accel = quat.rotate(q_inv, [0.0, 0.0, -G])  # specific force at rest: up = -z in NED
    mag = quat.rotate(q_inv, MAG_NED_T)
    return tuple(accel), tuple(mag)


def _run_pipeline(world_frame: str, body_frame: str, accel, mag=None, gyro=(0.01, 0.02, 0.03),
                  n: int = 200):
    pipe = ImuPipeline(FilterParams(world_frame=world_frame, use_mag=mag is not None),
                       PipelineParams(body_frame=body_frame))
    cov = np.array([0.1, 0.01, 0.02, 0.01, 0.2, 0.03, 0.02, 0.03, 0.3])
    out = None
    for i in range(n):
        t = T0_NS + i * 10_000_000
        header = Header(stamp=Time(sec=t // 10**9, nanosec=t % 10**9), frame_id="imu_link")
        if mag is not None:
            pipe.on_mag(MagneticField(header=header, magnetic_field=Vector3(
                x=mag[0], y=mag[1], z=mag[2]), magnetic_field_covariance=np.zeros(9)))
        out = pipe.on_imu(Imu(
            header=header, orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.array([-1.0] + [0.0] * 8),
            angular_velocity=Vector3(x=gyro[0], y=gyro[1], z=gyro[2]),
            angular_velocity_covariance=cov,
            linear_acceleration=Vector3(x=accel[0], y=accel[1], z=accel[2]),
            linear_acceleration_covariance=cov))
        gyro = (0.0, 0.0, 0.0)  # one turning sample first, then still
    return out


def test_ned_with_flu_input_and_body_frame_flu_gives_px4_roll_pitch_yaw() -> None:
    accel_frd, mag_frd = _frd_sample(10.0, 5.0, 30.0)
    accel_flu, mag_flu = _frd_to_flu(accel_frd), _frd_to_flu(mag_frd)
    for body, accel, mag in (("flu", accel_flu, mag_flu), ("frd", accel_frd, mag_frd)):
        rpy = [math.degrees(a) for a in _run_pipeline("ned", body, accel, mag).rpy_rad]
        assert rpy == [pytest_approx(10.0), pytest_approx(5.0), pytest_approx(30.0)], body
    # the message axes as they are (imu_filter_madgwick's answer): FLU data in NED is upside down
    roll = math.degrees(_run_pipeline("ned", "sensor", accel_flu).rpy_rad[0])
    assert abs(roll) == pytest_approx(170.0)


def test_enu_with_frd_input_gives_rep103_angles() -> None:
    accel_frd, _ = _frd_sample(10.0, 5.0, 0.0)
    roll, pitch, _ = (math.degrees(a) for a in _run_pipeline("enu", "frd", accel_frd).rpy_rad)
    # REP-103 (FLU in ENU): right side down is +roll as in PX4, nose up is -pitch
    assert (roll, pitch) == (pytest_approx(10.0), pytest_approx(-5.0))


def test_body_frame_converts_the_copied_vectors_and_their_covariances() -> None:
    out = _run_pipeline("ned", "flu", (0.0, 0.0, G), n=1, gyro=(0.1, 0.2, 0.3))
    assert out.linear_acceleration == (0.0, 0.0, -G)  # FLU up -> FRD: -z
    assert out.angular_velocity == (0.1, -0.2, -0.3)
    # D C D, D = diag(1, -1, -1): xy and xz terms change sign, yz does not
    assert out.angular_velocity_covariance == (0.1, -0.01, -0.02, -0.01, 0.2, 0.03, -0.02, 0.03,
                                               0.3)
    same = _run_pipeline("ned", "frd", (0.0, 0.0, -G), n=1, gyro=(0.1, 0.2, 0.3))
    assert same.angular_velocity == (0.1, 0.2, 0.3)  # already FRD: untouched


def pytest_approx(v: float):
    """Angles [deg] within 0.05 deg."""
    return pytest.approx(v, abs=0.05)


# -- item 5: covariance from the filter's state ------------------------------------------------
def _still_pipeline_run(mag_of_time, seconds: float, pipe=None, t0_s: float = 0.0):
    """A level, still sensor at 100 Hz; ``mag_of_time(t)`` the field in the sensor frame (or
    None: no sample). Returns the pipeline and [(t, yaw [rad], yaw sigma [rad], tilt var)]."""
    pipe = pipe or ImuPipeline()
    rows = []
    for i in range(int(seconds * 100)):
        t = t0_s + i * 0.01
        t_ns = T0_NS + int(round(t * 1e9))
        header = Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="imu")
        m = mag_of_time(t)
        if m is not None:
            pipe.on_mag(MagneticField(header=header, magnetic_field=Vector3(
                x=m[0], y=m[1], z=m[2]), magnetic_field_covariance=np.zeros(9)))
        out = pipe.on_imu(Imu(
            header=header, orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.zeros(9), angular_velocity=Vector3(x=0.0, y=0.0, z=0.0),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=Vector3(x=0.0, y=0.0, z=G),
            linear_acceleration_covariance=np.zeros(9)))
        c = out.orientation_covariance
        rows.append((t, out.rpy_rad[2], math.sqrt(c[8]), c[0]))
    return pipe, rows


def _field(heading_deg: float):
    """Earth field [T] in the sensor frame of a level sensor whose ENU yaw is heading_deg."""
    a = math.radians(heading_deg)
    north_in_sensor = (math.sin(a), math.cos(a))  # world +y seen from a sensor at yaw a
    return (20e-6 * north_in_sensor[0], 20e-6 * north_in_sensor[1], -40e-6)


def test_yaw_covariance_reports_a_large_heading_error_and_shrinks_with_it() -> None:
    # heading fixed at 0 for 5 s, then the field says the sensor faces 120 deg: a 120 deg error
    _pipe, rows = _still_pipeline_run(lambda t: _field(0.0 if t < 5.0 else 120.0), 60.0)
    before = [r for r in rows if 4.0 < r[0] < 5.0]
    assert max(r[2] for r in before) < math.radians(4.0)  # referenced and right: about 1 deg
    after = [r for r in rows if r[0] > 5.2]
    for t, yaw, sigma, _ in after[::100]:
        err = abs(math.remainder(yaw - math.radians(120.0), 2 * math.pi))
        # the reported sigma follows the true heading error (not a constant floor)
        assert sigma >= 0.8 * err, (t, math.degrees(err), math.degrees(sigma))
        assert sigma <= err + math.radians(10.0), (t, math.degrees(err), math.degrees(sigma))
    assert after[0][2] > math.radians(100.0)
    assert after[-1][2] < after[0][2]


def test_yaw_covariance_grows_during_a_magnetometer_dropout_and_tilt_stays_small() -> None:
    pipe, rows = _still_pipeline_run(lambda t: _field(0.0), 10.0)
    _, gap = _still_pipeline_run(lambda t: None, 30.0, pipe, t0_s=10.0)
    sig = [r[2] for r in gap]
    assert sig[-1] > sig[0] > 0.0  # sigma_b * t since the last used sample (small at rest)
    assert gap[-1][3] < 2 * PipelineParams().orientation_covariance_rad2  # tilt: still known


def test_unreferenced_yaw_covariance_without_magnetometer() -> None:
    _pipe, rows = _still_pipeline_run(lambda t: None, 1.0)
    assert rows[-1][2] ** 2 == pytest.approx(PipelineParams().unreferenced_yaw_covariance_rad2)


# -- item 1: tune safety -----------------------------------------------------------------------
@pytest.fixture(scope="module")
def flight60(tmp_path_factory) -> Path:
    """The issue's bag: `cf-estimator simulate --scenario flight --duration 60 -o flight60`."""
    path = tmp_path_factory.mktemp("fw_tune") / "flight60"
    assert cli_main(["simulate", "--scenario", "flight", "--duration", "60", "-o",
                     str(path)]) == 0
    return path


def test_search_boxes_keep_the_safety_nets() -> None:
    from cf_estimator.bench import tuning

    boxes = {d.name: (d.lo, d.hi) for d in tuning.SEARCHABLE}
    assert boxes["recovery_trigger_s"][1] <= 30.0 and boxes["recovery_trigger_s"][0] > 0.0
    assert boxes["k1"][0] >= 0.1
    with pytest.raises(ValueError, match="safety range"):
        tuning.with_bounds(tuning.DEFAULT_SPACE, {"recovery_trigger_s": (10.0, 400.0)})


def test_tune_refuses_to_write_a_set_that_loses_on_validation(flight60, tmp_path, capsys):
    """The simulated flight alone tunes to a slow loop (k1 0.13, T 8 s) that loses on real
    phantom4 recordings it never saw (and on one built-in case): refused."""
    phantom4 = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "phantom4"
    if not phantom4.is_dir():
        pytest.skip(f"{phantom4} not present")
    out = tmp_path / "tuned.yaml"
    argv = ["tune", "--bag", str(flight60), "--candidates", "48", "--passes", "2",
            "--validate", str(phantom4), "--out", str(out)]
    assert cli_main(argv) == 1
    cap = capsys.readouterr()
    assert "validation (not searched on" in cap.out and "LOSES" in cap.out
    assert "held-out V" in cap.out
    last = cap.err.strip().splitlines()[-1]
    assert last.startswith("cf-estimator: error: the tuned set is worse than the start point")
    assert "--force" in last and not out.exists()
    # every searched value inside the safety nets
    for name, lo, hi in (("recovery_trigger_s", 5.0, 30.0), ("k1", 0.1, 5.0)):
        line = next(x for x in cap.out.splitlines() if x.strip().startswith(name + " "))
        assert lo <= float(line.split("->")[1]) <= hi, line
    # --force: written, with the warning in the file and on stderr
    assert cli_main([*argv, "--force"]) == 0
    cap = capsys.readouterr()
    assert "THE TUNED SET IS WORSE" in cap.err
    assert "# WARNING: worse than the start point on:" in out.read_text()


def test_tune_inclination_objective_does_not_search_the_magnetometer_gains(flight60, capsys):
    assert cli_main(["tune", "--bag", str(flight60), "--objective", "inclination",
                     "--candidates", "3", "--passes", "1", "--scenario-limit", "none"]) == 0
    text = capsys.readouterr().out
    searching = next(line for line in text.splitlines() if line.startswith("tune: "))
    assert "k1" in searching and "r1" not in searching and "r2" not in searching
    assert "cannot see r1, r2" in text


def test_tune_validate_reads_held_out_euroc_flights(flight60, capsys):
    euroc = REPO.parent / "shared" / "data" / "euroc" / "MH_04_difficult"
    if not euroc.is_dir():
        pytest.skip(f"EuRoC data not present in {euroc}")
    assert cli_main(["tune", "--bag", str(flight60), "--search", "k1", "--candidates", "2",
                     "--passes", "1", "--scenario-limit", "none", "--validate",
                     str(euroc)]) == 0
    text = capsys.readouterr().out
    assert "held-out MH_04_difficult" in text


# -- item 6: the ROS peers at their ROS defaults -----------------------------------------------
def _still(roll_deg: float, pitch_deg: float, yaw_deg: float, n: int, gyro=(0.0, 0.0, 0.0),
           lateral_m_s2: float = 0.0):
    """n samples of a still sensor at ENU Euler angles (+ a constant world-x acceleration)."""
    q = quat.from_euler(*np.radians([roll_deg, pitch_deg, yaw_deg]))
    qi = quat.conjugate(q)
    acc = quat.rotate(qi, [lateral_m_s2, 0.0, G])
    mag = quat.rotate(qi, [0.0, 20.0, -40.0])  # uT, north = +y, dip down
    return (np.tile(gyro, (n, 1)), np.tile(acc, (n, 1)), np.tile(mag, (n, 1)), q)


def test_complementary_port_finds_a_still_attitude_in_enu() -> None:
    from cf_estimator.bench.peers import run_complementary

    g, a, m, q = _still(20.0, -10.0, 30.0, 500)
    out = run_complementary(g, a, m, 100.0)
    assert np.degrees(quat.angle_between(out[-1], q)) < 0.01
    assert np.degrees(quat.angle_between(out[0], q)) < 0.01  # initialised from the first sample


def test_complementary_port_learns_the_gyro_bias_at_rest() -> None:
    from cf_estimator.bench.peers import run_complementary

    g, a, _m, q = _still(0.0, 0.0, 0.0, 6000, gyro=(0.0, 0.0, 0.02))  # 60 s at 100 Hz, 6-D
    def yaw_drift(out):  # 6-D: the start heading is arbitrary, the change is not
        return abs(math.remainder(quat.to_euler(out[-1])[2] - quat.to_euler(out[0])[2],
                                  2 * math.pi))

    drift_on = yaw_drift(run_complementary(g, a, None, 100.0))
    drift_off = yaw_drift(run_complementary(g, a, None, 100.0, do_bias_estimation=False))
    assert math.degrees(drift_off) == pytest.approx(0.02 * 60.0 * 180.0 / math.pi, rel=0.01)
    assert math.degrees(drift_on) < 0.05 * math.degrees(drift_off)  # bias_alpha 0.01: learned


def test_complementary_port_adaptive_gain_ignores_large_linear_acceleration() -> None:
    from cf_estimator.bench.peers import run_complementary

    g, a, _m, q = _still(0.0, 0.0, 0.0, 3000, lateral_m_s2=8.0)  # |a| 1.29 g: factor 0
    a[0] = (0.0, 0.0, G)  # level at the start
    def tilt(out):  # angle between estimated and true "up" in the sensor frame (6-D)
        up = [quat.rotate(quat.conjugate(x), [0.0, 0.0, 1.0]) for x in (out[-1], q)]
        return math.acos(min(1.0, float(np.dot(up[0], up[1]))))

    tilt_on = tilt(run_complementary(g, a, None, 100.0))
    tilt_off = tilt(run_complementary(g, a, None, 100.0, do_adaptive_gain=False))
    assert math.degrees(tilt_on) < 0.01
    assert math.degrees(tilt_off) > 20.0  # pulled toward atan(8 / 9.8) = 39 deg


def test_madgwick_peer_runs_at_imu_filter_madgwick_gain() -> None:
    """The port steps as ahrs' Madgwick at gain 0.1 does (and not as at ahrs' own 0.033)."""
    pytest.importorskip("ahrs")
    from ahrs.filters import Madgwick

    from cf_estimator.bench import peers

    assert peers.MADGWICK_ROS_GAIN == 0.1 and peers.MADGWICK_ROS_ZETA == 0.0
    g, a, m, _q = _still(20.0, -10.0, 30.0, 200, gyro=(0.01, -0.02, 0.03))
    # noise keeps the gradient away from zero: its normalisation would amplify rounding
    a = a + np.random.default_rng(1).normal(0.0, 0.5, a.shape)
    out = peers.run_madgwick(g, a, m, 100.0)
    for gain, equal in ((0.1, True), (0.033, False)):
        ref = Madgwick(frequency=100.0, gain=gain)
        ref.gain = gain
        q = peers.initial_nwu(a[0], m[0])
        for i in range(1, len(g)):
            q = ref.updateMARG(q, g[i], a[i], m[i])
        ahrs_last = quat.multiply(peers.Q_ENU_FROM_NWU, q)
        assert (float(np.max(np.abs(out[-1] - ahrs_last))) < 1e-9) is equal


# -- item 7: low-rate streams (10-50 Hz) -------------------------------------------------------
def _load_low_rate_script():
    import importlib.util

    spec = importlib.util.spec_from_file_location("bench_low_rate",
                                                  REPO / "scripts" / "bench_low_rate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


@pytest.mark.parametrize("rate_hz", [10.0, 20.0, 50.0])
def test_rest_detection_and_bias_learning_work_with_five_samples_per_block(rate_hz) -> None:
    from cf_estimator import estimate
    from cf_estimator.scenarios import make_scenario

    sc = make_scenario("static", rate_hz=rate_hz, duration_s=60.0, seed=1)
    r = estimate(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, None, timestamps_s=sc.imu.t_s,
                 params=FilterParams(use_mag=False))
    assert r.at_rest.mean() > 0.9  # the 0.5 s block holds 5 samples at 10 Hz
    assert sc.imu.t_s[np.argmax(r.at_rest)] < 3.0
    true_bias = sc.imu.gyro_bias_rad_s[-1]
    assert np.degrees(np.linalg.norm(true_bias)) > 0.05  # there is a bias to learn
    assert np.degrees(np.linalg.norm(r.gyro_bias_rad_s[-1] - true_bias)) < 0.05
    assert bool(r.gyro_bias_converged[-1])


def test_euroc_at_10_hz_block_averaged_stays_near_full_rate() -> None:
    data = REPO.parent / "shared" / "data" / "euroc"
    if not data.is_dir():
        pytest.skip(f"EuRoC data not present in {data}")
    from cf_estimator.bench import euroc

    bench = _load_low_rate_script()
    flights = euroc.load_flights(data)
    full = np.mean([bench.euroc_score(f) for f in flights])
    avg10 = np.mean([bench.euroc_score(bench.reduced(f, 20, True)) for f in flights])
    pick10 = np.mean([bench.euroc_score(bench.reduced(f, 20, False)) for f in flights])
    assert avg10 < full + 0.2  # 10 Hz averaged: within 0.2 deg of 200 Hz
    assert pick10 > avg10 + 1.0  # picking samples aliases the vibration: the docs' advice


# -- item 8: papercuts -------------------------------------------------------------------------
def _imu(t_ns: int, accel, gyro=(0.0, 0.0, 0.0)) -> Imu:
    header = Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="imu")
    return Imu(header=header, orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
               orientation_covariance=np.zeros(9),
               angular_velocity=Vector3(x=gyro[0], y=gyro[1], z=gyro[2]),
               angular_velocity_covariance=np.zeros(9),
               linear_acceleration=Vector3(x=float(accel[0]), y=float(accel[1]),
                                           z=float(accel[2])),
               linear_acceleration_covariance=np.zeros(9))


def test_accel_scale_check_is_blind_to_heavy_vibration() -> None:
    rng = np.random.default_rng(0)
    vib = rng.normal(0.0, 5.0, (300, 3))  # phantom4-like: 5 m/s^2 per axis
    assert np.mean(np.linalg.norm(vib + [0.0, 0.0, G], axis=1)) > 12.0  # mean |a| far from g
    pipe = ImuPipeline()
    for i, v in enumerate(vib):
        pipe.on_imu(_imu(T0_NS + i * 5_000_000, (v[0], v[1], G + v[2])))
    assert not any(t.startswith("accel") for t in pipe.input_warnings)
    # a real scale error still warns: the same vibration on a 1.5x accelerometer
    pipe = ImuPipeline()
    for i, v in enumerate(vib):
        pipe.on_imu(_imu(T0_NS + i * 5_000_000, 1.5 * np.array([v[0], v[1], G + v[2]])))
    assert "accel_norm" in pipe.input_warnings


def test_estimate_unit_check_is_blind_to_heavy_vibration() -> None:
    import warnings

    from cf_estimator import estimate
    from cf_estimator.core.input_checks import InputUnitsWarning

    rng = np.random.default_rng(0)
    acc = rng.normal(0.0, 5.0, (400, 3)) + [0.0, 0.0, G]
    with warnings.catch_warnings():
        warnings.simplefilter("error", InputUnitsWarning)
        estimate(np.zeros((400, 3)), acc, None, rate_hz=200.0)  # no warning raised


def test_gauss_magnetometer_warns_once_with_the_fix_and_diagnostics_stay_ok() -> None:
    pipe = ImuPipeline()
    for i in range(300):
        t = T0_NS + i * 10_000_000
        header = Header(stamp=Time(sec=t // 10**9, nanosec=t % 10**9), frame_id="imu")
        pipe.on_mag(MagneticField(header=header, magnetic_field=Vector3(x=0.0, y=0.2, z=-0.4),
                                  magnetic_field_covariance=np.zeros(9)))  # Gauss
        out = pipe.on_imu(_imu(t, (0.0, 0.0, G)))
    text = pipe.input_warnings["mag_units"]
    assert "Gauss" in text and "1e-4" in text
    report = pipe.diagnostics()
    assert report.level == 0, report.message
    assert ("input_warning.mag_units", text) in report.values
    assert out.warnings == []  # said once, not per message


def test_no_imu_error_names_the_topic_waited_on() -> None:
    pipe = ImuPipeline(imu_topic="/mavros/imu/data_raw")
    report = pipe.diagnostics(now_s=1.0)
    assert report.level == 2 and "no IMU messages received yet on /mavros/imu/data_raw" in (
        report.message)


def test_reference_plot_legend_says_the_alignment_the_console_says() -> None:
    from cf_estimator.bag.plots import alignment_label

    assert alignment_label("none") == ""
    assert alignment_label("first") == " (heading-aligned: first)"


def _euroc_folder(root: Path, accel_scale: float) -> Path:
    """A 30 s still EuRoC-layout flight at 100 Hz (ASL csv), accelerometer x ``accel_scale``."""
    imu = root / "mav0" / "imu0"
    gt = root / "mav0" / "state_groundtruth_estimate0"
    imu.mkdir(parents=True)
    gt.mkdir(parents=True)
    t = 10**18 + np.arange(3000) * 10_000_000
    rows = [f"{k},0.0,0.0,0.0,0.0,0.0,{G * accel_scale}" for k in t]
    (imu / "data.csv").write_text("#timestamp [ns],w_x,w_y,w_z,a_x,a_y,a_z\n" + "\n".join(rows)
                                  + "\n")
    rows = [f"{k},0,0,0,1,0,0,0,0,0,0,0,0,0,0,0,0" for k in t[::10]]
    (gt / "data.csv").write_text("#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z,v_x,v_y,v_z,"
                                 "b_w_x,b_w_y,b_w_z,b_a_x,b_a_y,b_a_z\n" + "\n".join(rows) + "\n")
    return root


def test_bench_prints_python_warnings_as_one_line(tmp_path) -> None:
    folder = _euroc_folder(tmp_path / "g_units", 1.0 / G)  # accelerometer in g
    code = ("import sys; from cf_estimator.cli.main import main; "
            "sys.exit(main(sys.argv[1:]))")
    r = subprocess.run([sys.executable, "-c", code, "bench", "euroc", "--data", str(folder),
                        "--peers", "none", "--jobs", "1"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert lines and all(x.startswith("cf-estimator: ") for x in lines), r.stderr
    assert any("looks like units of g" in x for x in lines)
    assert "InputUnitsWarning" not in r.stderr and ".py:" not in r.stderr
