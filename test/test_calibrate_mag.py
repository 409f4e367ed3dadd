"""Magnetometer calibration (issue 52): the fit on simulated sensors with a known calibration,
the real CLI on real bags written by rosbags and on the shared logs, and the calibration applied
before the filter by the pipeline (node and replay), the replay's bulk path and ``estimate``."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DATA_ROOT

from cf_estimator import estimate
from cf_estimator.bag import io
from cf_estimator.bag.replay import ReplayOptions, replay_bag
from cf_estimator.calibration import magfit
from cf_estimator.calibration.autopilot import px4_calibration
from cf_estimator.calibration.simulate import FIELD_ENU_T, tumble
from cf_estimator.cli.main import main
from cf_estimator.core import quaternion as quat
from cf_estimator.params_file import load_params_file
from cf_estimator.pipeline import ImuPipeline, PipelineParams
from cf_estimator.schema import ParameterError

FIELD_T = float(np.linalg.norm(FIELD_ENU_T))
#: A soft iron and hard iron of the size real drones show (hard iron ~ the Earth's field).
SOFT_A = np.array([[1.08, 0.05, -0.03], [0.05, 0.93, 0.04], [-0.03, 0.04, 1.03]])
HARD_T = np.array([25e-6, -40e-6, 15e-6])
ULOG_SMALL = DATA_ROOT / "ulogs" / "sample_log_small.ulg"


def _det1_inverse(a: np.ndarray) -> np.ndarray:
    s = np.linalg.inv(a)
    return s / np.cbrt(np.linalg.det(s))


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b, 2) / np.linalg.norm(b, 2))


def _write_bag(path, tb) -> None:
    """A real ROS 2 bag (rosbags, mcap): IMU and magnetometer of the simulated recording."""
    t0 = 1_700_000_000_000_000_000
    with io.OutputBag(path, storage="mcap") as out:
        out.add_topic("/imu/data_raw", io.IMU_TYPE)
        out.add_topic("/imu/mag", io.MAG_TYPE)
        for k in range(tb.t_s.shape[0]):
            ns = t0 + int(round(tb.t_s[k] * 1e9))
            sec, nsec = divmod(ns, 1_000_000_000)
            out.write("/imu/mag", io.MAG_TYPE, ns, io.magnetic_field_message(
                sec, nsec, "imu_link", tb.mag_raw_t[k].tolist(), [0.0] * 9))
            out.write("/imu/data_raw", io.IMU_TYPE, ns + 1000, io.imu_message(
                sec, nsec, "imu_link", (0.0, 0.0, 0.0, 1.0), [-1.0] + [0.0] * 8,
                tb.gyro_rad_s[k].tolist(), [0.0] * 9, tb.accel_m_s2[k].tolist(), [0.0] * 9))


@pytest.fixture(scope="module")
def full_tumble():
    """Two minutes of a sensor tumbled through every orientation (about 75 % of the sphere)."""
    return tumble(120.0, 50.0, seed=0, hard_iron_t=HARD_T, soft_iron=SOFT_A)


@pytest.fixture(scope="module")
def full_bag(full_tumble, tmp_path_factory):
    path = tmp_path_factory.mktemp("cal") / "tumble"
    _write_bag(path, full_tumble)
    return path


# -- the fit ---------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_recovers_a_known_calibration_within_two_percent(seed):
    tb = tumble(120.0, 50.0, seed=seed, hard_iron_t=HARD_T, soft_iron=SOFT_A)
    cal = magfit.fit(tb.mag_raw_t)
    assert cal.coverage >= magfit.ELLIPSOID_MIN_COVERAGE
    assert cal.model == "ellipsoid"
    assert np.linalg.norm(cal.hard_iron - HARD_T) / FIELD_T < 0.02
    assert _rel(cal.soft_iron, _det1_inverse(SOFT_A)) < 0.02
    # corrected samples are the true field up to the scale the data cannot tell
    corrected = cal.apply(tb.mag_raw_t)
    scale = np.cbrt(np.linalg.det(SOFT_A))
    err = np.linalg.norm(corrected - scale * tb.mag_true_t, axis=1) / FIELD_T
    assert np.sqrt(np.mean(err**2)) < 0.02


def test_fit_refuses_a_flight_that_turns_through_little_of_the_sphere():
    tb = tumble(120.0, 50.0, seed=0, max_tilt_rad=0.3, hard_iron_t=HARD_T, soft_iron=SOFT_A)
    with pytest.raises(magfit.CalibrationError, match="of the sphere") as exc:
        magfit.fit(tb.mag_raw_t)
    assert "\n" not in str(exc.value)
    covered = float(str(exc.value).split("through ")[1].split("%")[0]) / 100
    assert covered < magfit.ELLIPSOID_MIN_COVERAGE


def test_hard_iron_only_needs_less_coverage_and_keeps_the_soft_iron_identity():
    tb = tumble(60.0, 50.0, seed=1, hard_iron_t=HARD_T)  # no soft iron
    cal = magfit.fit(tb.mag_raw_t, hard_iron_only=True)
    assert cal.model == "sphere"
    assert np.array_equal(cal.soft_iron, np.eye(3))
    assert np.linalg.norm(cal.hard_iron - HARD_T) / FIELD_T < 0.02


def test_fit_refuses_normalised_samples_and_a_magnet_that_moves_with_the_sensor():
    tb = tumble(120.0, 50.0, seed=0)
    unit = tb.mag_true_t / np.linalg.norm(tb.mag_true_t, axis=1)[:, None] * 1e-4
    with pytest.raises(magfit.CalibrationError, match="normalises"):
        magfit.fit(unit)
    disturbed = tb.mag_raw_t.copy()
    disturbed[len(disturbed) // 2:] += np.array([0.0, 0.0, 30e-6])  # a magnet added mid-way
    with pytest.raises(magfit.CalibrationError):
        magfit.fit(disturbed)


# -- the command as a user runs it ---------------------------------------------------------------
def test_cli_writes_parameters_the_node_file_reader_accepts(full_bag, tmp_path, capsys):
    out = tmp_path / "mag.yaml"
    rc = main(["calibrate-mag", str(full_bag), "-o", str(out)])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    assert "coverage" in printed.out and "residual" in printed.out
    fp, pp, _ = load_params_file(out)
    assert np.linalg.norm(np.array(pp.mag_hard_iron_t) - HARD_T) / FIELD_T < 0.02
    soft = np.array(pp.mag_soft_iron).reshape(3, 3)
    assert _rel(soft, _det1_inverse(SOFT_A)) < 0.02
    # nothing else is set: the file follows the node's own with --params-file
    text = out.read_text()
    assert "mag_hard_iron_t:" in text and "k1:" not in text


def test_cli_refuses_a_flight_in_one_line_and_writes_nothing(tmp_path, capsys):
    tb = tumble(60.0, 50.0, seed=2, max_tilt_rad=0.3, hard_iron_t=HARD_T)
    bag = tmp_path / "flight"
    _write_bag(bag, tb)
    out = tmp_path / "mag.yaml"
    rc = main(["calibrate-mag", str(bag), "-o", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1
    assert len(err) == 1 and err[0].startswith("cf-estimator: error: ") and "sphere" in err[0]
    assert not out.exists()


# -- applied before the filter ------------------------------------------------------------------
def _heading_rms_deg(q_est: np.ndarray, q_true: np.ndarray, skip: int) -> float:
    e = quat.multiply(q_est[skip:], quat.conjugate(q_true[skip:]))
    heading = 2.0 * np.arctan(np.abs(e[:, 3] / e[:, 0]))
    return float(np.degrees(np.sqrt(np.nanmean(heading**2))))


def test_estimate_applies_the_calibration_before_the_filter(full_tumble):
    tb = full_tumble
    cal = magfit.fit(tb.mag_raw_t)
    kw = dict(timestamps_s=tb.t_s)
    raw = estimate(tb.gyro_rad_s, tb.accel_m_s2, tb.mag_raw_t, **kw)
    fixed = estimate(tb.gyro_rad_s, tb.accel_m_s2, tb.mag_raw_t, **kw,
                     mag_hard_iron_t=cal.hard_iron.tolist(),
                     mag_soft_iron=cal.soft_iron.ravel().tolist())
    truth = estimate(tb.gyro_rad_s, tb.accel_m_s2, tb.mag_true_t, **kw)
    skip = 500
    err_raw = _heading_rms_deg(raw.quaternion, tb.q_world_from_sensor, skip)
    err_fixed = _heading_rms_deg(fixed.quaternion, tb.q_world_from_sensor, skip)
    err_true = _heading_rms_deg(truth.quaternion, tb.q_world_from_sensor, skip)
    assert err_fixed < err_true + 0.5 < err_raw
    with pytest.raises(ParameterError, match="mag_soft_iron"):
        estimate(tb.gyro_rad_s, tb.accel_m_s2, tb.mag_raw_t, **kw, mag_soft_iron=[0.0] * 9)


def test_pipeline_on_mag_passes_the_corrected_field():
    msg = io.magnetic_field_message(1, 0, "imu", [30e-6, -20e-6, 10e-6], [0.0] * 9)
    pp = PipelineParams(mag_hard_iron_t=(10e-6, 0.0, -5e-6),
                        mag_soft_iron=(1.1, 0.0, 0.0, 0.0, 0.9, 0.0, 0.0, 0.0, 1.0))
    pipe = ImuPipeline(pipeline_params=pp)
    pipe.on_mag(msg)
    _, mx, my, mz = pipe.mag_input.pending
    assert (mx, my, mz) == pytest.approx((1.1 * 20e-6, 0.9 * -20e-6, 15e-6), rel=1e-12)


def test_replay_bulk_and_per_message_apply_it_alike(full_bag, full_tumble):
    cal = magfit.fit(full_tumble.mag_raw_t)
    pp = PipelineParams(mag_hard_iron_t=tuple(cal.hard_iron.tolist()),
                        mag_soft_iron=tuple(cal.soft_iron.ravel().tolist()))
    runs = [replay_bag(full_bag, None, pipeline_params=p,
                       options=ReplayOptions(progress=False, bulk_pipeline=bulk)).series
            for p, bulk in ((pp, True), (pp, False), (PipelineParams(), True))]
    assert np.array_equal(runs[0].q_wxyz, runs[1].q_wxyz, equal_nan=True)
    n = min(len(runs[0].q_wxyz), len(full_tumble.q_world_from_sensor))
    errs = [_heading_rms_deg(r.q_wxyz[:n], full_tumble.q_world_from_sensor[:n], 500)
            for r in (runs[0], runs[2])]
    assert errs[0] < 0.5 * errs[1]


# -- the shared real logs -----------------------------------------------------------------------
def _need(path):
    if not path.exists():
        pytest.skip(f"shared data missing: {path}")


def test_cli_on_a_real_px4_log_names_the_autopilots_calibration_and_refuses(capsys):
    _need(ULOG_SMALL)
    rc = main(["calibrate-mag", str(ULOG_SMALL)])
    printed = capsys.readouterr()
    assert rc == 1
    assert "CAL_MAG1 (device 592905, prime)" in printed.out
    err = printed.err.strip().splitlines()
    assert len(err) == 1 and "hardly turned" in err[0]


def test_cli_on_a_real_bag_with_a_normalised_field_says_so(capsys):
    bag = DATA_ROOT / "bags" / "sparkfun_razor.bag"
    _need(bag)
    rc = main(["calibrate-mag", str(bag)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and "normalises" in err[0]


def test_recovers_the_px4_logs_own_calibration_from_a_tumble():
    """The CAL_MAG1 this real CubeOrange log carries, as the distortion of a simulated tumble:
    the fit recovers PX4's offsets within 2 % of the field and its scale matrix within 2 %."""
    _need(ULOG_SMALL)
    from pyulog import ULog

    auto = px4_calibration(ULog(str(ULOG_SMALL)).initial_parameters)
    assert auto is not None
    a = np.linalg.inv(auto.soft_iron)  # PX4: m = S (raw - off) -> raw = S^-1 m + off
    tb = tumble(120.0, 50.0, seed=0, hard_iron_t=auto.hard_iron_t, soft_iron=a)
    cal = magfit.fit(tb.mag_raw_t)
    assert np.linalg.norm(cal.hard_iron - auto.hard_iron_t) / FIELD_T < 0.02
    assert _rel(cal.soft_iron, auto.soft_iron_det1) < 0.02
