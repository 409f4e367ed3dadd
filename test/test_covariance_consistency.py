"""Issue 27: an orientation covariance an EKF can trust (cf_estimator/core/covariance.py).

One model for the node's pipeline (per message), the bag replay's bulk path (test_bulk_decode
checks it against the per-message one bit for bit) and ``estimate()``: here the per-message
pipeline and ``estimate()`` agree on real recordings, 6-D and 9-D; the reported σ is consistent
with the real errors on the calibration family and on a family it was not fitted on; it grows
with sustained acceleration and shrinks with velocity aiding and at rest.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from ros_test_helpers import Header, Imu, MagneticField, Quaternion, Time, Vector3

from cf_estimator import metrics
from cf_estimator.bench.consistency import (
    Floors,
    consistency,
    family_consistency,
    flight_samples,
)
from cf_estimator.core.batch import estimate
from cf_estimator.core.bias import BIAS_RANDOM_WALK_RAD_S_SQRT_S
from cf_estimator.core.covariance import (
    CORRECTION_WINDOW_S,
    TILT_FLOOR_RAD2,
    OrientationCovariance,
    gyro_drift_var,
)
from cf_estimator.core.params import FilterParams
from cf_estimator.pipeline import ImuPipeline, PipelineParams

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
T0_NS = 1_700_000_000 * 10**9


def _need(*families: str) -> None:
    missing = [f for f in families if not (DATA / f).is_dir()]
    if missing:
        pytest.skip(f"{DATA} does not hold {', '.join(missing)}")


def _header(t_ns: int) -> Header:
    return Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="imu")


def _per_message(t_s: np.ndarray, gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray | None,
                 fp: FilterParams) -> np.ndarray:
    """(N, 9) orientation_covariance of the node's pipeline, one message at a time (a
    magnetometer message at each IMU stamp, just before it)."""
    pipe = ImuPipeline(fp, PipelineParams())
    out = np.full((len(t_s), 9), np.nan)
    for k, t in enumerate(t_s.tolist()):
        t_ns = T0_NS + int(round(t * 1e9))
        if mag is not None:
            m = mag[k]
            field = Vector3(x=float(m[0]), y=float(m[1]), z=float(m[2]))
            pipe.on_mag(MagneticField(header=_header(t_ns), magnetic_field=field,
                                      magnetic_field_covariance=np.zeros(9)))
        g, a = gyro[k], acc[k]
        o = pipe.on_imu(Imu(
            header=_header(t_ns), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=np.array([-1.0] + [0.0] * 8),
            angular_velocity=Vector3(x=float(g[0]), y=float(g[1]), z=float(g[2])),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2])),
            linear_acceleration_covariance=np.zeros(9)))
        if o is not None and o.initialized:
            out[k] = o.orientation_covariance
    return out


def _stamps(t_s: np.ndarray) -> np.ndarray:
    """The stamps as the pipeline sees them (whole nanoseconds), in seconds."""
    return np.round(np.asarray(t_s) * 1e9) * 1e-9


def test_estimate_reports_the_pipelines_covariance_per_message_6d() -> None:
    _need("phantom4_horizontal")
    from cf_estimator.bench import euroc

    f = euroc.load_flight(DATA / "phantom4_horizontal" / "H01_imu1")
    n = int(np.searchsorted(f.t_s, 15.0))
    t, g, a = _stamps(f.t_s[:n]), f.gyro_rad_s[:n], f.accel_m_s2[:n]
    fp = FilterParams(use_mag=False)
    node = _per_message(t, g, a, None, fp)
    r = estimate(g, a, None, timestamps_s=t, params=fp)
    api = r.orientation_covariance()
    assert np.all(np.isfinite(node)) and np.all(np.isfinite(api))
    np.testing.assert_allclose(api, node, rtol=1e-6, atol=1e-12)
    # the flight accelerates: the tilt sigma is far above the floor somewhere, and it is the
    # square root of the reported variance (elements 0 + 4)
    assert np.max(r.tilt_sigma_rad) > 3.0 * math.sqrt(2.0 * TILT_FLOOR_RAD2)
    np.testing.assert_allclose(r.tilt_sigma_rad ** 2, node[:, 0] + node[:, 4], rtol=1e-6)
    np.testing.assert_allclose(r.heading_sigma_rad ** 2,
                               PipelineParams().unreferenced_yaw_covariance_rad2, rtol=1e-12)


def test_estimate_reports_the_pipelines_covariance_per_message_9d() -> None:
    _need("broad")
    from cf_estimator.bench import broad

    info = broad.read_trial_info(DATA / "broad")
    path = broad.list_trials(DATA / "broad", ["29_disturbed_stationary_magnet_B"])[0]
    tr = broad.load_trial(path, info)
    n = int(40.0 * tr.rate_hz)
    t = _stamps(np.arange(n) / tr.rate_hz)
    g, a, m = tr.gyro_rad_s[:n], tr.accel_m_s2[:n], tr.mag_ut[:n] * 1e-6  # µT -> T (the node's)
    fp = FilterParams(use_mag=True)
    node = _per_message(t, g, a, m, fp)
    r = estimate(g, a, m, timestamps_s=t, params=fp)
    np.testing.assert_allclose(r.orientation_covariance(), node, rtol=1e-6, atol=1e-12)
    # referenced heading: below the unreferenced variance; it grows while the magnet is on
    yaw = node[:, 8]
    assert np.median(yaw) < PipelineParams().unreferenced_yaw_covariance_rad2
    assert np.max(r.heading_sigma_rad) > 2.0 * np.min(r.heading_sigma_rad)


def test_the_tilt_floor_is_the_fit_at_rest() -> None:
    """The floor stands for what the filter cannot see (accelerometer bias, mounting): the tilt
    error left when nothing moves. TILT_FLOOR_RAD2 is the maximum-likelihood floor of EuRoC's
    samples at rest (bench.consistency.fit_tilt_floor, the model's other terms included): a
    filter change that moves the error at rest makes it stale, and this test says so."""
    _need("euroc")
    from cf_estimator.bench import euroc
    from cf_estimator.bench.consistency import fit_tilt_floor, rest_samples

    found = [rest_samples(p, FilterParams()) for p in euroc.find_flights(DATA / "euroc")]
    e = np.concatenate([f[0] for f in found])
    assert np.isfinite(e).sum() > 3000  # the three flights rest before take-off
    fit = fit_tilt_floor(e, np.concatenate([f[1] for f in found]))
    assert fit == pytest.approx(TILT_FLOOR_RAD2, rel=0.05), fit
    # the fit finds a floor it is given: errors drawn with per-axis variance 3e-5 + var
    rng = np.random.default_rng(3)
    var = rng.uniform(0.0, 1e-4, 200_000)
    s = np.sqrt(3e-5 + var)
    drawn = np.hypot(rng.normal(0.0, s), rng.normal(0.0, s))
    assert fit_tilt_floor(drawn, var) == pytest.approx(3e-5, rel=0.03)


def test_consistent_on_the_phantom_campaigns_it_was_not_fitted_on() -> None:
    """The tilt floor was fitted at rest on EuRoC; both Phantom campaigns are checks, in flight
    from an in-air start (the horizontal one with sustained horizontal acceleration, errors 3–8
    deg). There the floor alone gave mean(e²/σ²) ≈ 19 (issue 27's "2-5x too small"), the
    disagreement's own mean square as the acceleration term 0.14 (the swing the loop did not
    follow), the correction the loop made 0.55 with 4.6 % beyond twice the per-axis σ (the
    corrections that compensated a bias not learned yet, after the in-air start, counted as
    tilt error); with those counted as the disagreement they leave, 0.88 and 12.4 % (consistent:
    1 and 13.5 %); the vertical campaign 1.18 and 18.4 %."""
    _need("phantom4", "phantom4_horizontal")
    fp = FilterParams()
    vertical = family_consistency(DATA / "phantom4", "phantom4", fp)["tilt"]
    horizontal = family_consistency(DATA / "phantom4_horizontal", "phantom4_horizontal",
                                    fp)["tilt"]
    for c in (vertical, horizontal):
        assert 0.5 <= c["mean_ratio"] <= 2.0, c
        assert 5.0 <= c["beyond_2sigma_axis_pct"] <= 25.0, c
    # the sigma follows the error: the horizontal campaign's median sigma is above the vertical
    # one's by about the ratio of their RMS errors
    sigmas = horizontal["median_sigma_deg"] / vertical["median_sigma_deg"]
    errors = horizontal["rms_deg"] / vertical["rms_deg"]
    assert sigmas > 1.3 and errors / 1.5 < sigmas < 1.5 * errors, (sigmas, errors)


def test_velocity_aiding_shrinks_the_tilt_sigma_without_overconfidence() -> None:
    _need("phantom4_horizontal")
    from cf_estimator.bench import euroc

    fp = FilterParams(use_mag=False)
    sig: dict[bool, np.ndarray] = {}
    for name in ("H02_imu1", "H10_imu2"):
        f = euroc.load_flight(DATA / "phantom4_horizontal" / name)
        keep = f.t_s >= 10.0
        for aided in (False, True):
            vel = (f.velocity_t_s, f.velocity_m_s) if aided else None
            r = estimate(f.gyro_rad_s, f.accel_m_s2, None, timestamps_s=f.t_s, params=fp,
                         velocity=vel)
            e = metrics.tilt_error_rad(r.quaternion, f.q_ref)[keep]
            s2 = r.tilt_sigma_rad[keep] ** 2
            sig[aided] = np.concatenate([sig.get(aided, np.zeros(0)), np.sqrt(s2)])
            c = consistency(e, s2)
            assert c["mean_ratio"] <= 2.0, (name, aided, c)  # never overconfident
    assert np.median(sig[True]) < 0.6 * np.median(sig[False])


def _still(n: int, noise_m_s2: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    acc = np.tile([0.0, 0.0, 9.80665], (n, 1)) + rng.normal(0.0, noise_m_s2, (n, 3))
    return rng.normal(0.0, 0.002, (n, 3)), acc


def test_vibration_grows_the_tilt_variance_and_keeps_it_an_upper_bound() -> None:
    n = 6000  # 60 s at 100 Hz, a level sensor on a vibrating mount
    fp = FilterParams(use_mag=False)
    level = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    reported, actual = [], []
    for noise in (0.3, 3.0):
        g, a = _still(n, noise)
        r = estimate(g, a, None, rate_hz=100.0, params=fp)
        late = slice(2000, None)
        reported.append(float(np.mean(r.tilt_sigma_rad[late] ** 2)))
        actual.append(float(np.mean(metrics.tilt_error_rad(r.quaternion, level)[late] ** 2)))
    # vibration is reported: ten times the noise, a hundred times its power, and the variance
    # above the floor grows by more than 20 times
    floor = 2.0 * TILT_FLOOR_RAD2
    assert reported[1] - floor > 20.0 * (reported[0] - floor) > 0.0
    for rep, act in zip(reported, actual, strict=True):
        assert act <= rep <= 10.0 * max(act, 2.0 * TILT_FLOOR_RAD2), (rep, act)


def test_rest_brings_the_tilt_variance_back_to_the_floor() -> None:
    n = 1000
    fp = FilterParams(use_mag=False)
    q0 = (math.cos(0.1), math.sin(0.1), 0.0, 0.0)  # 11.5 deg off, on a still, level sensor
    r = estimate(np.zeros((n, 3)), np.tile([0.0, 0.0, 9.80665], (n, 1)), None, rate_hz=100.0,
                 params=fp, initial_orientation=q0)
    c = r.orientation_covariance()
    assert c[20, 0] > 10.0 * TILT_FLOOR_RAD2  # pulled in at start: the error is reported
    assert c[-1, 0] < 1.2 * TILT_FLOOR_RAD2  # 10 s of rest later: the floor
    assert c[-1, 0] >= TILT_FLOOR_RAD2


def test_model_terms_have_their_documented_sizes() -> None:
    """The formula of the module docstring, term by term (per axis = S/2)."""
    m = OrientationCovariance(1e-4, 4e-4, 10.0, 0.1, k1=0.35, gravity_m_s2=9.8)
    # a steady horizontal disagreement of 0.1 rad, (0.06, 0.08): no acceleration the loop
    # follows (that disagreement dies away as the loop catches up) but a rate it compensates
    # through its proportional path, a bias not learned yet: the tilt error it leaves is the
    # disagreement itself, L = 0.1², not the correction it keeps making (k1·0.1·10 s = 0.35 rad
    # once the window is full, which the model reported before)
    for _ in range(20000):
        c = m.step(0.01, False, 0.001, 2, 0.1, 0.06, 0.08, 0.0, False, 0.0, False, None)
    assert c[0] == pytest.approx(1e-4 + 0.5 * 0.1**2, rel=1e-3)
    # an acceleration the loop follows at its running gain k (loop_k1, lowered by a velocity
    # swing): the disagreement jumps to A and dies away as exp(−k·t) while the tilt takes on
    # the acceleration; the correction made for the disagreement's transient part, A·k·t·e^(−k·t)
    # in the continuous limit, and the steady part the same (M lags: it is c's mean square over
    # 1/k): S = M + L peaks at 1.3–1.4·(A/e)² about 1/k in — less than the A² the tilt is off
    # by at the end of a leg held that long (a vehicle whose velocity is bounded holds no leg
    # much longer; docs/decisions/0007-covariance.md), gone once it is over
    for k in (0.35, 0.175):
        m.reset()
        s2 = []
        for i in range(3000):
            lx = 0.1 * math.exp(-k * i * 0.01)
            s2.append(2.0 * (m.step(0.01, False, 0.001, 2, 0.1, lx, 0.0, 0.0, False, 0.0, False,
                                    None, k)[0] - 1e-4))
        peak = int(np.argmax(s2))
        assert 0.9 / k < peak * 0.01 < 1.2 / k, (k, peak)
        assert 1.2 * (0.1 / math.e) ** 2 < s2[peak] < 1.5 * (0.1 / math.e) ** 2, (k, s2[peak])
        assert s2[-1] < 0.1 * s2[peak]
    # a zig-zag: the disagreement swings +-0.3 rad every 2 s; the corrections cancel, and the
    # variance stays far below the swing's own mean square (0.09) that the first model
    # reported: the loop's tilt error swings by k1·0.3·2 s / 2 ≈ 0.1 rad
    m.reset()
    ms = []
    for k in range(20000):
        lx = 0.3 if (k // 200) % 2 == 0 else -0.3
        ms.append(m.step(0.01, False, 0.001, 2, 0.3, lx, 0.0, 0.0, False, 0.0, False, None)[0])
    assert 1e-4 + 0.5 * 0.05**2 < max(ms[10000:]) < 1e-4 + 0.5 * 0.15**2
    assert c[8] == 10.0  # heading not referenced
    # vibration: noise_a2 = 6 sigma_a^2 (sample-to-sample differences, three axes)
    m.reset()
    c = m.step(0.01, False, 0.001, 2, 0.0, 0.0, 0.0, 6.0 * 2.0**2, False, 0.0, False, None)
    assert c[0] == pytest.approx(1e-4 + 0.5 * (2.0 / 9.8) ** 2 * 0.01 * 0.35, rel=1e-12)
    # a clip of 2 s: the bias error's σ known at its start times the gyro-only time, and the
    # random walk since, integrated (q·t³/3)
    q = BIAS_RANDOM_WALK_RAD_S_SQRT_S**2
    m.reset()
    for _ in range(200):
        c = m.step(0.01, True, 0.01, 2, 0.0, 0.0, 0.0, 0.0, True, 0.0, False, 5.0)
    assert c[0] == pytest.approx(1e-4 + (0.01**2 - 2.0 * q) * 2.0**2 + q * 2.0**3 / 3.0,
                                 rel=1e-9)
    # 5 s without a field
    assert c[8] == pytest.approx(4e-4 + (0.01**2 - 5.0 * q) * 5.0**2 + q * 5.0**3 / 3.0,
                                 rel=1e-12)
    # a bias error that is the walk alone: a third of (σ_b·t)², which counted the walk's
    # latest part for the whole time
    t = 60.0
    assert gyro_drift_var(math.sqrt(q * t), t) == pytest.approx(q * t**3 / 3.0, rel=1e-12)
    assert gyro_drift_var(0.01, 0.0) == 0.0


def test_a_disturbed_field_leaves_the_heading_error_measured_before_it() -> None:
    """A magnet appears: the first samples pass the channel's tests (their innovation is the
    magnet's, 0.9 rad) and then the field is rejected. While rejected and seen to move with the
    body (the filter reports no innovation for it), the heading's variance is the error the
    channel measured before — the running mean of the innovations over its memory, which the
    few disturbed samples barely move —, not the last disturbed innovation held for as long as
    the magnet stays (BROAD's attached-magnet trials reported 41° for a heading 2° off); a
    rejected field not seen to move with the body may be right and the heading wrong: its
    innovation counts when larger."""
    assert OrientationCovariance(1e-4, 4e-4, 10.0, 0.1, r1=0.5).yaw_memory_s == 2.0
    m = OrientationCovariance(1e-4, 4e-4, 10.0, 0.1, k1=0.35, r1=0.07)
    assert m.yaw_memory_s == CORRECTION_WINDOW_S  # 1/r1 = 14 s, at most the window
    rng = np.random.default_rng(0)
    dt = 0.01
    for _ in range(3000):  # 30 s of a clean field: the heading 0.02 rad off, noise 0.04 rad
        m.step(dt, False, 1e-4, 2, 0.0, 0.0, 0.0, 0.0, True, 0.02 + rng.normal(0.0, 0.04),
               True, 0.0)
    for _ in range(5):  # the magnet's first samples, used
        c = m.step(dt, False, 1e-4, 2, 0.0, 0.0, 0.0, 0.0, True, 0.9, True, 0.0)
    assert c[8] == pytest.approx(4e-4 + 0.9**2, rel=1e-9)  # while used: the innovation
    ages = np.arange(1, 1001) * dt
    yaw = [m.step(dt, False, 1e-4, 2, 0.0, 0.0, 0.0, 0.0, True, 0.0, False, a,
                  mag_rejected=True)[8] for a in ages]
    held = math.sqrt(yaw[0] - 4e-4)  # the running mean: 0.02 plus 5 samples' share of 0.9
    assert held == pytest.approx(0.02 + 5 * dt / CORRECTION_WINDOW_S * 0.9, abs=0.005)
    # then the gyro drift grows it
    assert yaw[-1] == pytest.approx(4e-4 + held**2 + gyro_drift_var(1e-4, 10.0), rel=1e-9)
    # a rejected field that keeps to the world (a compass wrong at power-on, a field that
    # jumped on a still sensor): its own innovation, when larger than the mean
    c = m.step(dt, False, 1e-4, 2, 0.0, 0.0, 0.0, 0.0, True, 2.0, False, 10.01,
               mag_rejected=True)
    assert c[8] == pytest.approx(4e-4 + 2.0**2 + gyro_drift_var(1e-4, 10.01), rel=1e-9)
    c = m.step(dt, False, 1e-4, 2, 0.0, 0.0, 0.0, 0.0, True, 0.001, False, 10.02,
               mag_rejected=True)
    assert c[8] == pytest.approx(4e-4 + held**2 + gyro_drift_var(1e-4, 10.02), rel=1e-9)


def test_replay_summary_scores_the_covariance_against_the_ground_truth(tmp_path) -> None:
    import json

    from cf_estimator.cli.main import main

    bag, out, js = tmp_path / "flight", tmp_path / "out", tmp_path / "flight.json"
    assert main(["simulate", "--scenario", "flight", "--duration", "30", "-o", str(bag)]) == 0
    assert main(["replay", str(bag), "-o", str(out), "--reference-topic",
                 "/ground_truth/orientation", "--json", str(js)]) == 0
    doc = json.loads(js.read_text())
    summary = doc[0] if isinstance(doc, list) else doc
    cov = summary["reference"]["covariance"]
    for name in ("tilt", "heading"):  # 9-D: the magnetometer references the heading
        c = cov[name]
        assert c["samples"] > 1000, (name, c)
        assert 0.0 <= c["beyond_2sigma_pct"] <= 100.0 and c["mean_ratio"] > 0.0, (name, c)
        # beyond twice the per-axis σ, the smaller radius: never fewer samples
        assert c["beyond_2sigma_pct"] <= c["beyond_2sigma_axis_pct"] <= 100.0, (name, c)


def test_a_consistent_2d_gaussian_gives_the_documented_shares() -> None:
    """The two shares' meanings (bench/consistency.py): a tilt error whose two axes are
    N(0, s²) each, reported as σ² = 2s² (cov[0] + cov[4]): mean(e²/σ²) 1, e⁻⁴ ≈ 1.8 % beyond 2σ
    and e⁻² ≈ 13.5 % beyond twice the per-axis σ (issue 27's 14 %); an overconfident σ (half
    the variance) moves all three up."""
    rng = np.random.default_rng(7)
    s = np.radians(rng.uniform(0.5, 3.0, 400_000))  # per-axis σ [rad], varying per sample
    e = np.hypot(rng.normal(0.0, s), rng.normal(0.0, s))
    c = consistency(e, 2.0 * s * s)
    assert c["mean_ratio"] == pytest.approx(1.0, abs=0.01)
    assert c["beyond_2sigma_pct"] == pytest.approx(100.0 * math.exp(-4.0), abs=0.1)
    assert c["beyond_2sigma_axis_pct"] == pytest.approx(100.0 * math.exp(-2.0), abs=0.2)
    over = consistency(e, s * s)
    assert over["mean_ratio"] == pytest.approx(2.0, abs=0.02)
    assert over["beyond_2sigma_pct"] == pytest.approx(100.0 * math.exp(-2.0), abs=0.2)
    assert over["beyond_2sigma_axis_pct"] == pytest.approx(100.0 * math.exp(-1.0), abs=0.3)
    assert math.isnan(consistency(e[:0], s[:0])["beyond_2sigma_axis_pct"])


def test_the_consistency_figures_take_the_node_s_floors() -> None:
    """`bench cross --params` judges the covariance a node with that file would publish: its
    floors reach the model (the tilt variance cov[0] + cov[4] moves by twice the per-axis floor's
    change, sample for sample), and a parameter file's floors become the figures' (Floors.of)."""
    _need("phantom4")
    path = next(p for p in sorted((DATA / "phantom4").iterdir()) if p.is_dir())
    fp = FilterParams()
    e0, v0 = flight_samples(path, fp)
    e1, v1 = flight_samples(path, fp, Floors(tilt0_rad2=TILT_FLOOR_RAD2 + 1e-4))
    np.testing.assert_array_equal(e0, e1)  # the estimate does not depend on the floors
    np.testing.assert_allclose(v1 - v0, 2e-4, rtol=1e-9, atol=1e-15)
    assert consistency(e1, v1)["mean_ratio"] < consistency(e0, v0)["mean_ratio"]
    pp = PipelineParams(orientation_covariance_rad2=2e-4, yaw_covariance_rad2=5e-4)
    assert Floors.of(pp) == Floors(2e-4, 5e-4, pp.unreferenced_yaw_covariance_rad2)
    assert Floors() == Floors.of(PipelineParams())  # the shipped floors are the node's defaults


def test_bench_cross_params_file_sets_the_floors(tmp_path, monkeypatch, capsys) -> None:
    """The CLI hands the parameter file's covariance floors to the table (and the filter's
    parameters beside them): the consistency rows judge what that node would publish."""
    from cf_estimator.bench import cross
    from cf_estimator.cli.main import main

    seen = {}

    def fake_run_cross(data, params, families, jobs=1, progress=None, floors=None):
        seen.update(params=params, floors=floors, families=families)
        return cross.CrossResult()

    monkeypatch.setattr(cross, "run_cross", fake_run_cross)
    yaml = tmp_path / "p.yaml"
    yaml.write_text("cf_estimator:\n  ros__parameters:\n    yaw_covariance_rad2: 0.0002\n"
                    "    k1: 0.3\n", encoding="utf-8")
    assert main(["bench", "cross", "--families", "compass", "--params", str(yaml)]) == 0
    assert seen["floors"] == Floors(yaw0_rad2=2e-4)
    assert seen["params"].k1 == 0.3 and list(seen["families"]) == ["compass"]
    capsys.readouterr()
