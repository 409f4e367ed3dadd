"""Bag replay on synthetic bags: simulate → (ROS 1 / sqlite3 / mcap) → replay → compare.

The synthetic recording is the ``flight`` scenario at 200 Hz for 20 s (4000 IMU, 2000
magnetometer, 2000 ground-truth messages), written with rosbags and converted with rosbags.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from ros_test_helpers import read_topics
from rosbags.convert import convert

from cf_estimator.bag import io
from cf_estimator.bag.metrics import error_angles, error_statistics
from cf_estimator.bag.replay import (
    OUT_DIAGNOSTICS_TOPIC,
    OUT_IMU_TOPIC,
    OUT_RPY_TOPIC,
    ReplayOptions,
    replay_bag,
)
from cf_estimator.bag.simulate import IMU_TOPIC, MAG_TOPIC, TRUTH_TOPIC, write_scenario_bag
from cf_estimator.cli.main import main
from cf_estimator.core import quaternion as quat
from cf_estimator.pipeline import ImuPipeline
from cf_estimator.scenarios import make_scenario

RATE_HZ = 200.0
DURATION_S = 20.0
SEED = 3
#: The first seconds hold the start-up phase and the heading fix by the first magnetometer
#: sample (the first IMU message arrives before it): bounds are checked after it.
SETTLED_S = 2.0


def _convert(src: Path, dst: Path, storage: str) -> None:
    convert(
        [src], dst, dst_storage=storage, dst_version=None if dst.suffix == ".bag" else 9,
        compress=None, compress_mode="file", default_typestore=None, typestore=None,
        exclude_topics=[], include_topics=[], exclude_msgtypes=[], include_msgtypes=[],
    )


@pytest.fixture(scope="module")
def scenario():
    return make_scenario("flight", rate_hz=RATE_HZ, duration_s=DURATION_S, seed=SEED)


@pytest.fixture(scope="module")
def bags(tmp_path_factory, scenario):
    """The same recording as ROS 2 mcap, ROS 2 sqlite3 and ROS 1."""
    d = tmp_path_factory.mktemp("synthetic")
    paths = {"mcap": d / "flight_mcap", "sqlite3": d / "flight_sqlite3", "ros1": d / "flight.bag"}
    write_scenario_bag(scenario, paths["mcap"], storage="mcap")
    _convert(paths["mcap"], paths["sqlite3"], "sqlite3")
    _convert(paths["mcap"], paths["ros1"], "sqlite3")
    return paths


@pytest.fixture(scope="module")
def replayed(bags, tmp_path_factory):
    """Each input format replayed once, plus the mcap input a second time."""
    d = tmp_path_factory.mktemp("replayed")
    opts = ReplayOptions(reference_topic=TRUTH_TOPIC, progress=False)
    out = {}
    for key, src in bags.items():
        out[key] = replay_bag(src, d / f"out_{key}", options=opts)
    out["mcap_again"] = replay_bag(bags["mcap"], d / "out_mcap_again", options=opts)
    return out


def raw_messages(path: Path, topic: str) -> list[tuple[int, bytes]]:
    """(log time, serialized bytes) of a topic: for bit-exact comparisons."""
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [(t, bytes(raw)) for _, t, raw in reader.messages(connections=conns)]


def diagnostics_values(path: Path) -> list[tuple[int, int, str, list[tuple[str, str]]]]:
    """Diagnostics without the wall-clock processing-time figures (they measure this machine)."""
    rows = []
    for m in read_topics(path)[OUT_DIAGNOSTICS_TOPIC]:
        st = m.msg.status[0]
        values = [(kv.key, kv.value) for kv in st.values
                  if not kv.key.startswith("processing_time")]
        rows.append((m.log_time_ns, int(st.level), st.message, values))
    return rows


# -- simulate ------------------------------------------------------------------------------------


def test_simulated_bag_has_raw_imu_mag_in_tesla_and_truth(bags, scenario):
    topics = read_topics(bags["mcap"])
    n = scenario.imu.n_samples
    assert len(topics[IMU_TOPIC]) == n
    assert len(topics[MAG_TOPIC]) == int(DURATION_S * 100)  # decimated to 100 Hz
    assert len(topics[TRUTH_TOPIC]) == int(DURATION_S * 100)
    first = topics[IMU_TOPIC][0].msg
    assert first.orientation_covariance[0] == -1.0  # no orientation in raw data
    assert first.header.frame_id == "imu_link"
    np.testing.assert_allclose(
        [first.angular_velocity.x, first.angular_velocity.y, first.angular_velocity.z],
        scenario.imu.gyro_rad_s[0])
    field = np.array([[m.msg.magnetic_field.x, m.msg.magnetic_field.y, m.msg.magnetic_field.z]
                      for m in topics[MAG_TOPIC]])
    assert 40e-6 < np.median(np.linalg.norm(field, axis=1)) < 60e-6  # Tesla
    q = topics[TRUTH_TOPIC][10].msg.quaternion
    t = topics[TRUTH_TOPIC][10].msg.header.stamp
    k = int(round((t.sec + t.nanosec * 1e-9 - topics[IMU_TOPIC][0].msg.header.stamp.sec
                   - topics[IMU_TOPIC][0].msg.header.stamp.nanosec * 1e-9) * RATE_HZ))
    np.testing.assert_allclose([q.w, q.x, q.y, q.z], scenario.truth.q_world_from_body[k])


def test_simulate_is_reproducible_from_the_seed(tmp_path, scenario):
    short = make_scenario("static", rate_hz=100.0, duration_s=2.0, seed=7)
    write_scenario_bag(short, tmp_path / "a")
    write_scenario_bag(make_scenario("static", rate_hz=100.0, duration_s=2.0, seed=7),
                       tmp_path / "b")
    assert raw_messages(tmp_path / "a", IMU_TOPIC) == raw_messages(tmp_path / "b", IMU_TOPIC)


# -- accuracy against the ground truth -----------------------------------------------------------


def test_replay_follows_ground_truth_within_bounds(replayed):
    result = replayed["mcap"]
    scored = result.scored
    settled = scored["t_s"] - scored["t_s"][0] >= SETTLED_S
    incl = np.degrees(scored["inclination"][settled])
    head = np.degrees(scored["heading"][settled])
    # Stated bounds for a MEMS-grade simulated UAV flight (tilts 10-30 deg, turns, 0.1 deg/s bias):
    assert np.sqrt(np.mean(incl**2)) < 1.0 and incl.max() < 2.0
    assert np.sqrt(np.mean(head**2)) < 2.0 and head.max() < 5.0
    rmse = result.summary["rmse_deg"]
    assert set(rmse) == {"total", "inclination", "heading"}
    assert rmse["inclination"] < 1.0 and rmse["total"] < 2.0


def test_every_input_gives_one_output_with_its_stamp_and_log_time(bags, replayed):
    inputs = read_topics(bags["mcap"])[IMU_TOPIC]
    outputs = read_topics(Path(replayed["mcap"].output))
    assert replayed["mcap"].summary["messages_processed"] == len(inputs)
    for topic in (OUT_IMU_TOPIC, OUT_RPY_TOPIC):
        got = outputs[topic]
        assert len(got) == len(inputs)
        for i in (0, 1, len(inputs) // 2, len(inputs) - 1):
            assert got[i].log_time_ns == inputs[i].log_time_ns
            assert got[i].msg.header.stamp.sec == inputs[i].msg.header.stamp.sec
            assert got[i].msg.header.stamp.nanosec == inputs[i].msg.header.stamp.nanosec
            assert got[i].msg.header.frame_id == inputs[i].msg.header.frame_id


def test_diagnostics_are_published_once_per_second_of_bag_time(replayed):
    diags = read_topics(Path(replayed["mcap"].output))[OUT_DIAGNOSTICS_TOPIC]
    stamps = np.array([m.msg.header.stamp.sec + m.msg.header.stamp.nanosec * 1e-9
                       for m in diags])
    assert len(diags) == int(DURATION_S) - 1  # ticks at 1, 2, ... 19 s after the first message
    np.testing.assert_allclose(np.diff(stamps), 1.0, atol=1e-9)
    assert all(m.log_time_ns == m.msg.header.stamp.sec * 10**9 + m.msg.header.stamp.nanosec
               for m in diags)
    assert diags[-1].msg.status[0].level == 0  # OK on a clean simulated flight


# -- determinism across formats and runs -------------------------------------------------------


@pytest.mark.parametrize("other", ["sqlite3", "ros1", "mcap_again"])
def test_ros1_sqlite3_mcap_inputs_and_repeated_runs_give_identical_outputs(replayed, other):
    a, b = Path(replayed["mcap"].output), Path(replayed[other].output)
    for topic in (OUT_IMU_TOPIC, OUT_RPY_TOPIC):
        assert raw_messages(a, topic) == raw_messages(b, topic)
    assert diagnostics_values(a) == diagnostics_values(b)
    sa, sb = replayed["mcap"].summary, replayed[other].summary
    for key in ("messages_in", "messages_processed", "messages_rejected", "clipped_fraction",
                "final_gyro_bias_rad_s", "rmse_deg"):
        assert sa[key] == sb[key]


# -- equivalence with the pipeline -------------------------------------------------------------


def test_replay_writes_exactly_what_a_fresh_pipeline_produces(bags, replayed):
    pipe = ImuPipeline()
    expected = []
    with io.open_bag(bags["ros1"]) as bag:
        for m in bag.messages([IMU_TOPIC, MAG_TOPIC]):
            if m.topic == MAG_TOPIC:
                pipe.on_mag(m.msg)
            else:
                out = pipe.on_imu(m.msg)
                if out is not None:
                    expected.append(out)
    written = read_topics(Path(replayed["ros1"].output))
    imu, rpy = written[OUT_IMU_TOPIC], written[OUT_RPY_TOPIC]
    assert len(imu) == len(expected) == len(rpy)
    for out, got, got_rpy in zip(expected, imu, rpy, strict=True):
        g = got.msg
        assert (g.header.stamp.sec, g.header.stamp.nanosec) == (out.stamp_sec, out.stamp_nanosec)
        assert g.header.frame_id == out.frame_id
        o = g.orientation
        assert (o.x, o.y, o.z, o.w) == tuple(out.orientation_xyzw)
        assert tuple(g.orientation_covariance) == tuple(out.orientation_covariance)
        av, la = g.angular_velocity, g.linear_acceleration
        assert (av.x, av.y, av.z) == tuple(out.angular_velocity)
        assert (la.x, la.y, la.z) == tuple(out.linear_acceleration)
        assert tuple(g.angular_velocity_covariance) == tuple(out.angular_velocity_covariance)
        assert tuple(g.linear_acceleration_covariance) == tuple(
            out.linear_acceleration_covariance)
        v = got_rpy.msg.vector
        assert (v.x, v.y, v.z) == tuple(out.rpy_rad)
    assert replayed["ros1"].summary["counters"] == {
        k: v for k, v in pipe.counters.items()
    }


# -- options, summary, plots -------------------------------------------------------------------


def test_copy_inputs_writes_the_input_topics_as_jazzy_messages(bags, tmp_path):
    out = tmp_path / "with_inputs"
    replay_bag(bags["ros1"], out, options=ReplayOptions(
        copy_inputs=True, reference_topic=TRUTH_TOPIC, progress=False))
    written = read_topics(out)
    source = read_topics(bags["mcap"])
    for topic in (IMU_TOPIC, MAG_TOPIC, TRUTH_TOPIC):
        assert len(written[topic]) == len(source[topic])
    # ROS 1 headers (seq) became ROS 2 headers, the values survived
    assert not hasattr(written[IMU_TOPIC][5].msg.header, "seq")
    assert raw_messages(out, IMU_TOPIC) == raw_messages(bags["mcap"], IMU_TOPIC)


def test_cli_replay_writes_bag_json_and_plots(bags, tmp_path, capsys):
    out, js, plots = tmp_path / "out", tmp_path / "summary.json", tmp_path / "plots"
    rc = main(["replay", str(bags["sqlite3"]), "-o", str(out), "--storage", "sqlite3",
               "--reference-topic", TRUTH_TOPIC, "--json", str(js), "--plot", str(plots)])
    assert rc == 0
    captured = capsys.readouterr()
    assert "\r" not in captured.err  # no progress bar: stderr is not a terminal
    assert list(out.glob("*.db3"))
    s = json.loads(js.read_text())
    for key in ("messages_in", "messages_processed", "messages_rejected", "duration_s",
                "imu_rate_hz", "clipped_fraction", "final_gyro_bias_rad_s", "rmse_deg"):
        assert key in s
    assert s["messages_in"] == s["messages_processed"] == int(RATE_HZ * DURATION_S)
    assert s["imu_rate_hz"] == pytest.approx(RATE_HZ, rel=1e-6)
    assert s["duration_s"] == pytest.approx(DURATION_S - 1 / RATE_HZ, abs=1e-6)
    assert 0.0 <= s["clipped_fraction"] <= 1.0 and len(s["final_gyro_bias_rad_s"]) == 3
    assert set(s["rmse_deg"]) == {"total", "inclination", "heading"}
    assert sorted(p.name for p in plots.iterdir()) == [
        "attitude.png", "bias.png", "clipping.png", "error.png"]
    assert "error   vs /ground_truth/orientation" in captured.out


def test_cli_json_to_stdout_is_pure_json(bags, capsys):
    rc = main(["replay", str(bags["mcap"]), "--json", "-", "--mag-topic", "none"])
    assert rc == 0
    s = json.loads(capsys.readouterr().out)
    assert s["output"] is None and s["topics"]["mag"] is None
    assert s["counters"]["received_mag"] == 0


def test_overwrite_replaces_an_existing_output(bags, tmp_path):
    out = tmp_path / "out"
    opts = ReplayOptions(progress=False)
    replay_bag(bags["mcap"], out, options=opts)
    first = raw_messages(out, OUT_IMU_TOPIC)
    replay_bag(bags["mcap"], out, options=ReplayOptions(overwrite=True, progress=False))
    assert raw_messages(out, OUT_IMU_TOPIC) == first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporary leftovers


# -- error statistics ------------------------------------------------------------------------


def test_error_angles_split_tilt_and_heading():
    ref = quat.from_euler(np.array([0.1]), np.array([-0.2]), np.array([1.0]))
    tilt = quat.multiply(quat.exp(np.array([[0.02, 0.0, 0.0]])), ref)  # earth-frame tilt
    yaw = quat.multiply(quat.exp(np.array([[0.0, 0.0, 0.05]])), ref)  # earth-frame heading
    e_tilt, e_yaw = error_angles(tilt, ref), error_angles(yaw, ref)
    assert e_tilt["inclination"][0] == pytest.approx(0.02)
    assert e_tilt["heading"][0] == pytest.approx(0.0, abs=1e-12)
    assert e_yaw["heading"][0] == pytest.approx(0.05)
    assert e_yaw["inclination"][0] == pytest.approx(0.0, abs=1e-7)
    assert e_yaw["total"][0] == pytest.approx(0.05)


def test_heading_alignment_removes_a_constant_heading_offset():
    t = np.arange(200) * 0.01
    ref = quat.from_euler(0.2 * np.sin(t), 0.1 * np.cos(t), 0.5 * t)
    offset = quat.exp(np.array([0.0, 0.0, 0.7]))  # the estimate's world is yawed by 0.7 rad
    est = quat.multiply(np.broadcast_to(offset, ref.shape), ref)
    none, _ = error_statistics(t, est, t, ref, "none")
    first, _ = error_statistics(t, est, t, ref, "first")
    mean, _ = error_statistics(t, est, t, ref, "mean")
    assert none["rmse_deg"]["heading"] == pytest.approx(math.degrees(0.7))
    assert none["rmse_deg"]["inclination"] == pytest.approx(0.0, abs=1e-6)
    for stats in (first, mean):
        assert stats["heading_offset_deg"] == pytest.approx(math.degrees(0.7))
        assert stats["rmse_deg"]["total"] == pytest.approx(0.0, abs=1e-5)


def test_reference_is_scored_at_its_own_stamps_by_interpolation():
    t_est = np.arange(0.0, 1.0, 0.01)
    est = quat.from_euler(np.zeros_like(t_est), np.zeros_like(t_est), t_est)
    t_ref = np.array([0.005, 0.5, 2.0])  # the last one is outside the estimate: not scored
    ref = quat.from_euler(np.zeros(3), np.zeros(3), t_ref)
    stats, scored = error_statistics(t_est, est, t_ref, ref, "none")
    assert stats["samples_scored"] == 2
    assert stats["max_deg"]["total"] < 1e-3


# -- demo ----------------------------------------------------------------------------------------


def test_demo_prints_the_table_and_writes_its_files(tmp_path, capsys, monkeypatch):
    from cf_estimator.cli import demo_cmd

    # The real demo simulates 110 s at 500 Hz (the thesis scenario's minimum); the plumbing is
    # tested on a short flight without disturbances to keep the test fast.
    def short_flight(name, rate_hz=None, duration_s=None, seed=0):
        assert name == "thesis"
        return make_scenario("flight", rate_hz=100.0, duration_s=20.0, seed=seed)

    monkeypatch.setattr(demo_cmd, "make_scenario", short_flight)
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "thesis limit 90'" in text
    assert "shipped parameters" in text and "clip and aperiodic unit off" in text
    for name in ("thesis_flight", "demo_errors.png", "demo_summary.json"):
        assert (out / name).exists() and str(out / name) in text
    s = json.loads((out / "demo_summary.json").read_text())
    assert set(s["errors"]) == {"shipped", "no_clip"}
    assert s["errors"]["shipped"]["roll"]["peak_arcmin"] > 0


# -- offline ---------------------------------------------------------------------------------------


def test_replay_offline_json_metadata_and_accuracy(bags, replayed, tmp_path, capsys):
    import yaml

    out, js = tmp_path / "out_offline", tmp_path / "offline.json"
    assert main(["replay", str(bags["mcap"]), "-o", str(out), "--offline", "--json", str(js),
                 "--reference-topic", TRUTH_TOPIC, "--no-progress"]) == 0
    assert "mode    offline" in capsys.readouterr().out
    s = json.loads(js.read_text())
    assert s["mode"] == "offline" and s["offline"]["segments"] == 1
    meta = yaml.safe_load((out / "metadata.yaml").read_text())
    assert meta["rosbag2_bagfile_information"]["custom_data"]["cf_estimator.mode"] == "offline"
    online = replayed["mcap"].summary
    assert online["mode"] == "online"
    # same topics and counts as the online replay; the estimate is at least as good
    assert s["outputs_written"] == online["outputs_written"]
    assert s["rmse_deg"]["inclination"] <= online["rmse_deg"]["inclination"]
    imu = read_topics(out)["/imu/data"]
    stamps = [m.msg.header.stamp.sec * 10**9 + m.msg.header.stamp.nanosec for m in imu]
    assert stamps == sorted(stamps) and len(stamps) == online["messages_processed"]


def test_replay_offline_splits_at_resets(tmp_path):
    sc = make_scenario("flight", rate_hz=RATE_HZ, duration_s=DURATION_S, seed=SEED)
    src = tmp_path / "gap_mcap"
    write_scenario_bag(sc, src, storage="mcap")
    # the same recording with a 10 s stamp gap in the middle: the pipeline resets there
    from rosbags.highlevel import AnyReader

    gapped = tmp_path / "gapped"
    with AnyReader([src]) as reader, io.OutputBag(gapped) as bag:
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if t > reader.start_time + 10 * 10**9:  # every topic, stamps and log times
                msg.header.stamp.sec += 10
                t += 10 * 10**9
            bag.write(conn.topic, conn.msgtype, t, msg)
    r = replay_bag(gapped, None, options=ReplayOptions(offline=True, progress=False))
    assert r.summary["resets"] and r.summary["offline"]["segments"] == 2
    assert np.all(np.isfinite(r.series.q_wxyz))


def test_the_error_plot_draws_the_published_tilt_sigma(tmp_path, monkeypatch):
    """Issue 27 in the replay's plots: with a ground-truth reference, error.png draws the
    published covariance's tilt σ, √(cov[0] + cov[4]), beside the inclination error, sample for
    sample the series' own variance; an offline replay does not (its error is the offline
    pass's, the σ the online filter's)."""
    from cf_estimator.bag import plots
    from cf_estimator.cli.main import main

    bag = tmp_path / "flight"
    assert main(["simulate", "--scenario", "flight", "--duration", "20", "-o", str(bag)]) == 0
    drawn: dict[str, dict[str, np.ndarray]] = {}

    def keep(fig, path):
        drawn[path.name] = {ln.get_label(): ln.get_ydata() for ln in fig.axes[0].get_lines()}
        plots._pyplot().close(fig)
        return path

    monkeypatch.setattr(plots, "_save", keep)
    label = "reported tilt σ, √(cov[0]+cov[4])"
    for offline in (False, True):
        drawn.clear()
        r = replay_bag(bag, None, options=ReplayOptions(
            reference_topic="/ground_truth/orientation", offline=offline, progress=False))
        plots.plot_replay(r, tmp_path / "plots")
        lines = drawn["error.png"]
        assert "inclination" in lines
        if offline:
            assert label not in lines
            continue
        np.testing.assert_allclose(lines[label], np.degrees(np.sqrt(r.series.tilt_var_rad2)))
        assert np.nanmin(lines[label]) > 0.0


def test_replay_offline_plots_the_online_filter_beside_the_offline_estimate(bags, replayed,
                                                                            tmp_path):
    from cf_estimator.bag.plots import plot_replay

    r = replay_bag(bags["mcap"], None, options=ReplayOptions(offline=True, progress=False))
    s, online = r.series, replayed["mcap"].series
    assert s.online_rpy_rad.shape == s.rpy_rad.shape == online.rpy_rad.shape
    # the online column is what the online replay printed; the offline one differs from it
    np.testing.assert_allclose(s.online_rpy_rad, online.rpy_rad, atol=1e-12, equal_nan=True)
    assert np.nanmax(np.abs(s.rpy_rad - online.rpy_rad)) > 1e-4
    assert online.online_rpy_rad.shape[0] == 0  # an online replay has no second series
    paths = plot_replay(r, tmp_path / "plots")
    assert (tmp_path / "plots" / "attitude.png") in paths
