"""Tuner: vectorised scoring against per-sample loops, the search space, bag trials and
``cf-estimator tune --bag`` on a small simulated bag (CI-safe, a few seconds)."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from cf_estimator import metrics
from cf_estimator.bag import io
from cf_estimator.bag.simulate import TRUTH_TOPIC, write_scenario_bag
from cf_estimator.bench import bagtrial, tuning
from cf_estimator.bench.broad import Trial
from cf_estimator.bench.scenarios import ARCMIN_PER_RAD, run_scenarios
from cf_estimator.cli.main import main
from cf_estimator.core import quaternion as quat
from cf_estimator.core.batch import estimate
from cf_estimator.core.params import FilterParams
from cf_estimator.params_file import load_params_file
from cf_estimator.scenarios import make_scenario

RATE_HZ = 200.0


# -- per-sample references (the definitions, written out) --------------------------------------
def _err_wz(q, r):
    """w and z of the normalised q ⊗ r⁻¹, plain floats (q, r: 4 floats, r of any norm)."""
    nq = math.sqrt(sum(c * c for c in q))
    nr = math.sqrt(sum(c * c for c in r))
    a = [c / nq for c in q]
    b = [r[0] / nr, -r[1] / nr, -r[2] / nr, -r[3] / nr]
    w = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3]
    z = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]
    return w, z


def _loop_rmse_deg(q, q_ref, movement):
    """(total, inclination) RMSE [deg] sample by sample (BROAD: movement, finite rows)."""
    s_tot = s_inc = 0.0
    n = 0
    for i in range(q.shape[0]):
        if not movement[i] or not np.all(np.isfinite(q_ref[i])) or not np.all(np.isfinite(q[i])):
            continue
        w, z = _err_wz(q[i], q_ref[i])
        s_tot += (2 * math.acos(min(1.0, abs(w)))) ** 2
        s_inc += (2 * math.acos(min(1.0, math.sqrt(w * w + z * z)))) ** 2
        n += 1
    return math.degrees(math.sqrt(s_tot / n)), math.degrees(math.sqrt(s_inc / n))


def _random_quats(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _near(rng, q_ref, deg):
    """q_ref rotated by random small world-frame rotations (up to ``deg``), unnormalised."""
    axis = rng.normal(size=(q_ref.shape[0], 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    half = np.radians(rng.uniform(0, deg, q_ref.shape[0])) / 2
    dq = np.column_stack([np.cos(half), np.sin(half)[:, None] * axis])
    return quat.multiply(dq, q_ref) * rng.uniform(0.5, 2.0, (q_ref.shape[0], 1))


@pytest.fixture
def small_case():
    rng = np.random.default_rng(7)
    n = 300
    q_ref = _random_quats(rng, n)
    q_ref[[5, 40, 41]] = np.nan  # reference lost
    movement = rng.random(n) > 0.2
    est = np.stack([_near(rng, np.nan_to_num(q_ref, nan=1.0), d) for d in (2.0, 10.0, 40.0)])
    est[:, :12] = np.nan  # before initialisation
    est[2, 100:110] *= -1  # the sign of a quaternion does not matter
    trial = Trial("small", np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)), q_ref,
                  movement, RATE_HZ)
    return trial, est


def test_broad_scorer_equals_per_sample_loop(small_case):
    trial, est = small_case
    scorer = tuning.BroadScorer(trial, est.shape[0])
    for p in range(est.shape[0]):
        scorer(p, est[p])
    for p in range(est.shape[0]):
        tot, inc = _loop_rmse_deg(est[p], trial.quat_ref, trial.movement)
        assert scorer.total_deg[p] == pytest.approx(tot, rel=1e-9)
        assert scorer.inclination_deg[p] == pytest.approx(inc, rel=1e-9)
    assert scorer.total_deg[0] < scorer.total_deg[1] < scorer.total_deg[2]


def test_peak_scorer_equals_per_sample_loop(small_case):
    trial, est = small_case
    mask = np.zeros(trial.n_samples, dtype=bool)
    mask[50:200] = True
    scorer = tuning.PeakScorer(trial.quat_ref, mask, est.shape[0])
    for p in range(est.shape[0]):
        scorer(p, est[p])
    for p in range(est.shape[0]):
        peak = 0.0
        for i in np.flatnonzero(mask):
            if np.all(np.isfinite(trial.quat_ref[i])):
                w, z = _err_wz(est[p, i], trial.quat_ref[i])
                peak = max(peak, 2 * math.acos(min(1.0, math.sqrt(w * w + z * z))))
        assert scorer.peak_arcmin[p] == pytest.approx(peak * ARCMIN_PER_RAD, rel=1e-9)


def test_scorers_nan_when_nothing_is_scored(small_case):
    trial, est = small_case
    scorer = tuning.BroadScorer(dataclasses.replace(trial, movement=np.zeros(300, bool)), 1)
    scorer(0, est[0])
    assert np.isnan(scorer.total_deg[0])  # → objective inf, never "best"
    assert tuning.objective_values({"x": (scorer.total_deg, scorer.total_deg)}, "total")[0] \
        == np.inf


def test_scenario_peaks_equal_bench_scenarios():
    p = FilterParams()
    peak = tuning.scenario_peaks([p, dataclasses.replace(p, k1=1.0)], ("acceleration",))
    row = [r for r in run_scenarios(["acceleration"], p) if r["algorithm"] == "cf_estimator"][0]
    assert peak.shape == (2, 1)
    assert peak[0, 0] == pytest.approx(row["peak_arcmin"], rel=1e-9)


# -- search space ------------------------------------------------------------------------------
def test_new_dims_are_searchable_and_draws_stay_in_their_boxes():
    names = ["saturation_limit_rad", "rotation_threshold_rad_s",
             "acceleration_threshold_m_s2", "rest_window_s", "rest_gyro_threshold_rad_s"]
    space = tuning.space_from_names(names)
    assert [d.name for d in space] == names
    assert {"saturation_limit_rad", "rotation_threshold_rad_s",
            "acceleration_threshold_m_s2"} <= {d.name for d in tuning.DEFAULT_SPACE}
    res = tuning.search(lambda c: np.zeros(len(c)), FilterParams(), space, candidates=80,
                        passes=2, seed=3)
    drawn = [p for _v, p in res.evaluated]
    assert len(drawn) > 80
    for d in space:  # every draw inside its box (the start point aside)
        vals = [getattr(p, d.name) for p in drawn[1:]]
        assert min(vals) >= d.lo and max(vals) <= d.hi
    with pytest.raises(ValueError, match="cannot search 'gravity_m_s2'"):
        tuning.space_from_names(["gravity_m_s2"])


@pytest.mark.parametrize("target, rel", [
    ({"k1": 0.8, "k2": 0.004}, {"k1": 0.15, "k2": 0.3}),
    ({"acceleration_threshold_m_s2": 1.3, "rest_window_s": 1.5}, {}),
])
def test_search_finds_known_optimum(target, rel):
    """A synthetic objective (log-distance to a known point): the search must land near it."""
    space = tuning.space_from_names(list(target))

    def evaluate(cands):
        return np.array([sum((math.log(getattr(c, n)) - math.log(v)) ** 2
                             for n, v in target.items()) for c in cands])

    res = tuning.search(evaluate, FilterParams(), space, candidates=56, passes=4, seed=1)
    assert res.best_value < res.start_value
    for n, v in target.items():
        assert getattr(res.best, n) == pytest.approx(v, rel=rel.get(n, 0.15))


# -- bag trials --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def flight():
    return make_scenario("flight", duration_s=20.0, seed=3)


@pytest.fixture(scope="module")
def sim_bag(flight, tmp_path_factory):
    path = tmp_path_factory.mktemp("tune") / "flight20"
    write_scenario_bag(flight, path)
    return path


def test_load_bag_trial_from_simulated_bag(flight, sim_bag):
    tr = bagtrial.load_bag_trial(sim_bag)
    n = flight.imu.t_s.shape[0]
    assert tr.n_samples == n and tr.rate_hz == pytest.approx(RATE_HZ)
    np.testing.assert_allclose(tr.t_s, flight.imu.t_s - flight.imu.t_s[0], atol=1e-9)
    np.testing.assert_array_equal(tr.gyro_rad_s, flight.imu.gyro_rad_s)
    # magnetometer at 100 Hz: every other IMU row, in µT; NaN elsewhere
    has = np.all(np.isfinite(tr.mag_ut), axis=1)
    np.testing.assert_array_equal(np.flatnonzero(has), np.arange(0, n, 2))
    np.testing.assert_allclose(tr.mag_ut[has], flight.imu.mag_T[has] * 1e6, rtol=1e-12)
    # truth at 100 Hz: exact where stamps coincide, interpolated between
    truth = flight.truth.q_world_from_body
    np.testing.assert_allclose(tr.quat_ref[::2], truth[::2], atol=1e-12)
    err = np.degrees(metrics.tilt_error_rad(tr.quat_ref[1:-1:2], truth[1:-1:2]))
    assert np.max(err) < 0.05
    assert not tr.movement[tr.t_s < 2.0].any() and tr.movement[tr.t_s >= 2.0][:-1].all()
    d = tr.decimated(4)
    assert d.n_samples == n // 4 and d.rate_hz == pytest.approx(50.0)
    np.testing.assert_allclose(d.t_s, tr.t_s[3::4])
    np.testing.assert_allclose(d.mag_ut, tr.mag_ut[:n // 4 * 4].reshape(-1, 4, 3)[:, ::2].mean(1))


def test_score_trial_on_bag_equals_single_filter(sim_bag):
    tr = bagtrial.load_bag_trial(sim_bag).decimated(2)
    cands = [FilterParams(), FilterParams(k1=1.0, r1=0.3)]
    total, incl = tuning.score_trial(cands, tr)
    for i, p in enumerate(cands):
        q = estimate(tr.gyro_rad_s, tr.accel_m_s2, tr.mag_ut, timestamps_s=tr.t_s,
                     params=p).quaternion
        tot, inc = _loop_rmse_deg(q, tr.quat_ref, tr.movement)
        assert total[i] == pytest.approx(tot, rel=1e-9)
        assert incl[i] == pytest.approx(inc, rel=1e-9)
    assert total[0] < 3.0  # simulate's truth shares the filter's heading reference
    both = tuning.score_candidates(cands * 2, [tr], jobs=2)[tr.name]  # candidates split over jobs
    np.testing.assert_allclose(both[0], np.tile(total, 2), rtol=1e-12)


def test_filter_times_shortens_gaps():
    t = np.array([0.0, 0.01, 0.02, 3.02, 3.03])
    np.testing.assert_allclose(bagtrial.filter_times(t, 0.5), [0.0, 0.01, 0.02, 0.03, 0.04])


def _types():
    return io.typestore().types


def _write_reference_bag(path, kind, t_ref_s):
    """Level IMU at 50 Hz for 4 s, a reference of ``kind`` at ``t_ref_s`` (yaw 30°)."""
    t = _types()
    q = quat.from_euler(0.0, 0.0, math.radians(30.0))
    qmsg = io.quaternion_xyzw((q[1], q[2], q[3], q[0]))
    t0 = 1_000_000_000_000
    with io.OutputBag(path) as out:
        for k in range(200):
            ns = t0 + k * 20_000_000
            out.write("/imu", io.IMU_TYPE, ns + 1000, io.imu_message(
                *divmod(ns, 1_000_000_000), "imu", (qmsg.x, qmsg.y, qmsg.z, qmsg.w),
                [0.0] * 9, (0.0, 0.0, 0.0), None, (0.0, 0.0, 9.81), None))
        for s in t_ref_s:
            ns = t0 + int(s * 1e9)
            hdr = io.header(*divmod(ns, 1_000_000_000), "world")
            pose = t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0), orientation=qmsg)
            if kind == "pose":
                msg, typ = t[io.POSE_STAMPED_TYPE](header=hdr, pose=pose), io.POSE_STAMPED_TYPE
            else:
                cov = np.zeros(36)
                twist = t["geometry_msgs/msg/Twist"](linear=io.vector3((0, 0, 0)),
                                                     angular=io.vector3((0, 0, 0)))
                msg = t[io.ODOMETRY_TYPE](
                    header=hdr, child_frame_id="imu",
                    pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                    twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=cov))
                typ = io.ODOMETRY_TYPE
            out.write("/ref", typ, ns + 500, msg)
    return q


@pytest.mark.parametrize("kind", ["pose", "odom", "imu"])
def test_reference_message_types(tmp_path, kind):
    path = tmp_path / kind
    q = _write_reference_bag(path, "odom" if kind == "odom" else "pose", np.arange(0, 4, 0.1))
    topic = "/imu" if kind == "imu" else "/ref"  # an IMU that reports its own orientation
    tr = bagtrial.load_bag_trial(path, topic, score_after_s=1.0)
    assert tr.topics == {"imu": "/imu", "mag": None, "reference": topic}
    assert not tr.has_mag and tr.movement.sum() > 100
    np.testing.assert_allclose(tr.quat_ref[tr.movement], np.tile(q, (tr.movement.sum(), 1)),
                               atol=1e-12)


# -- CLI ---------------------------------------------------------------------------------------
def _objective_line(text):
    m = re.search(r"before (\S+)\s+after (\S+)", text)
    assert m, text
    return float(m.group(1)), float(m.group(2))


def test_cli_tune_bag_writes_loadable_yaml_not_worse(sim_bag, tmp_path, capsys):
    out = tmp_path / "tuned.yaml"
    assert main(["tune", "--bag", str(sim_bag), "--candidates", "6", "--passes", "2",
                 "--jobs", "1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "objective combined" in text and "rotation_threshold_rad_s" in text
    before, after = _objective_line(text)
    fparams, _pparams, warnings = load_params_file(out)  # the node's / replay's loader
    assert isinstance(fparams, FilterParams) and not warnings
    assert out.read_text().startswith("# cf-estimator tune: objective combined on bag ")
    # recompute the objective of the written file independently of the CLI
    trial = bagtrial.load_bag_trial(sim_bag).decimated(4)
    values = tuning.objective_values(
        tuning.score_candidates([FilterParams(), fparams], [trial]), "combined")
    assert values[0] == pytest.approx(before, abs=6e-5)
    assert values[1] == pytest.approx(after, abs=6e-5)
    assert values[1] <= values[0]


def test_cli_tune_bag_without_mag_tunes_inclination(sim_bag, tmp_path, capsys):
    assert main(["tune", "--bag", str(sim_bag), "--mag-topic", "none", "--search", "k1",
                 "--candidates", "3", "--passes", "1", "--jobs", "1"]) == 0
    assert "objective inclination" in capsys.readouterr().out
    assert main(["tune", "--bag", str(sim_bag), "--mag-topic", "none", "--objective", "total",
                 "--candidates", "3", "--passes", "1"]) == 2
    err = capsys.readouterr().err
    assert "heading is unobservable" in err and err.count("\n") == 1


@pytest.mark.parametrize("extra, code, needle", [
    (["--reference-topic", "/mocap/pose"], 2, "no topic '/mocap/pose' (--reference-topic)"),
    (["--reference-topic", "/imu/mag"], 2, "but --reference-topic needs"),
    (["--imu-topic", "/nope"], 2, "no topic '/nope' (--imu-topic)"),
    (["--trials", "01"], 2, "--trials needs --data"),
    (["--score-after", "-1"], 2, "--score-after must be >= 0"),
    (["--score-after", "30"], 1, "no IMU sample with a reference after the first 30 s"),
])
def test_cli_tune_bag_errors(sim_bag, capsys, extra, code, needle):
    assert main(["tune", "--bag", str(sim_bag), *extra]) == code
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1 and err.startswith("cf-estimator: error: ")


def test_cli_tune_bag_no_overlap_and_missing_bag(tmp_path, capsys):
    path = tmp_path / "late_ref"
    _write_reference_bag(path, "pose", np.arange(10.0, 12.0, 0.1))  # IMU covers 0..4 s
    assert main(["tune", "--bag", str(path), "--reference-topic", "/ref"]) == 1
    err = capsys.readouterr().err
    assert "does not overlap the IMU stamps" in err and err.count("\n") == 1
    assert main(["tune", "--bag", str(tmp_path / "none")]) == 2
    assert "no such file or directory" in capsys.readouterr().err


def test_cli_tune_needs_exactly_one_source(sim_bag, tmp_path, capsys):
    for argv in (["tune"], ["tune", "--bag", str(sim_bag), "--data", str(tmp_path)]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2
    capsys.readouterr()
    assert main(["tune", "--data", str(tmp_path), "--reference-topic", TRUTH_TOPIC]) == 2
    assert "--reference-topic needs --bag" in capsys.readouterr().err
