"""Issue 25, a team's first flights with the package: the replay, tune and tool side (no ROS).

Each test is one item of the issue: bad input gives one line, a non-zero exit and no output
that looks like a result (1); the fleet's exit status (10); the small agreements between docs
and behaviour (11). Bags are written here, small, with the Jazzy message classes.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest
from ros_test_helpers import TS, Imu

from cf_estimator.bag import io
from cf_estimator.bag.simulate import write_scenario_bag
from cf_estimator.cli.main import main
from cf_estimator.cli.replay_cmd import print_summary
from cf_estimator.pipeline import checks
from cf_estimator.scenarios import make_scenario

G = 9.80665
T0_NS = 1_700_000_000 * 10**9
REPO = Path(__file__).resolve().parents[1]


def _imu(t_ns: int, frame: str = "imu_link") -> object:
    h = TS.types["std_msgs/msg/Header"](
        stamp=TS.types["builtin_interfaces/msg/Time"](sec=t_ns // 10**9,
                                                     nanosec=t_ns % 10**9),
        frame_id=frame)
    v3 = TS.types["geometry_msgs/msg/Vector3"]
    import numpy as np

    return Imu(header=h, orientation=TS.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0,
                                                                                z=0.0, w=1.0),
               orientation_covariance=np.zeros(9), angular_velocity=v3(x=0.01, y=0.0, z=0.0),
               angular_velocity_covariance=np.zeros(9),
               linear_acceleration=v3(x=0.0, y=0.0, z=G),
               linear_acceleration_covariance=np.zeros(9))


def write_imu_bag(path: Path, stamps_ns: list[int]) -> Path:
    """A ROS 2 bag with one IMU message per stamp (log times increasing, 10 ms apart)."""
    with io.OutputBag(path) as bag:
        for k, t in enumerate(stamps_ns):
            bag.write("/mavros/imu/data_raw", io.IMU_TYPE, T0_NS + k * 10_000_000, _imu(t))
    return path


@pytest.fixture(scope="module")
def backwards_bag(tmp_path_factory) -> Path:
    """1000 IMU messages whose stamps run backwards, 10 ms a step (a driver's clock bug)."""
    d = tmp_path_factory.mktemp("backwards")
    return write_imu_bag(d / "backwards", [T0_NS - k * 10_000_000 for k in range(1000)])


# -- item 1: no traceback, a non-zero exit, nothing left behind ---------------------------------
def test_backward_stamps_give_one_line_exit_1_and_no_output(backwards_bag, tmp_path, capsys):
    out, js, plots = tmp_path / "out", tmp_path / "s.json", tmp_path / "plots"
    rc = main(["replay", str(backwards_bag), "-o", str(out), "--json", str(js), "--plot",
               str(plots), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1
    assert len(err) == 1 and err[0].startswith("cf-estimator: error: ")
    assert re.search(r"stamps decrease: (\d+) of 1000 rejected \(\1 out_of_order\)", err[0])
    assert not out.exists() and not js.exists()
    assert not plots.exists() or not any(plots.iterdir())
    assert not list(tmp_path.glob(".*"))  # no temporary sibling left either


def test_backward_stamps_fail_their_bag_in_a_fleet(backwards_bag, tmp_path, capsys):
    good = tmp_path / "in" / "good"
    (tmp_path / "in").mkdir()
    write_imu_bag(good, [T0_NS + k * 10_000_000 for k in range(500)])
    import shutil

    shutil.copytree(backwards_bag, tmp_path / "in" / "backwards")
    out = tmp_path / "out"
    rc = main(["replay", str(tmp_path / "in"), "-o", str(out), "--no-progress"])
    printed = capsys.readouterr().out
    assert rc == 1, printed  # some bags failed
    assert any(line.startswith("FAILED") and "stamps decrease" in line
               for line in printed.splitlines())
    assert sorted(p.name for p in out.iterdir()) == ["good"]


def test_unusable_reason_names_what_is_wrong():
    ok = {"messages_in": 100, "messages_processed": 99, "messages_rejected": {"out_of_order": 1},
          "resets": {}, "duration_s": 0.98}
    assert checks.unusable_reason(ok) is None
    assert "no IMU message usable: 5 of 5 rejected (5 nonfinite_gyro)" in checks.unusable_reason(
        {**ok, "messages_in": 5, "messages_processed": 0,
         "messages_rejected": {"nonfinite_gyro": 5}})
    assert checks.unusable_reason({**ok, "duration_s": -3.0}).startswith("stamps decrease")
    assert checks.unusable_reason({**ok, "duration_s": float("nan")}).startswith("no stamp span")
    assert checks.unusable_reason({**ok, "duration_s": None}) is not None


def test_summary_prints_with_every_figure_missing(capsys):
    """Every summary value that can be None/NaN in the JSON prints as n/a, never a traceback."""
    s = {"input": "b", "input_format": "ros2-mcap", "messages_in": 3, "mag_messages_in": 0,
         "topics": {"imu": "/imu", "mag": None}, "duration_s": None, "imu_rate_hz": None,
         "messages_processed": 3, "messages_rejected": {}, "gaps": 0, "resets": {},
         "clipped_fraction": None, "counters": {}, "final_gyro_bias_rad_s": [math.nan, 0.0, 0.0],
         "final_gyro_bias_sigma_rad_s": None, "gyro_bias_converged_after_s": None,
         "still_fraction": None, "output": None, "messages_per_s": None, "wall_time_s": None,
         "reference": {"topic": "/ref", "samples_scored": 0, "heading_alignment": "none",
                       "heading_offset_deg": None,
                       "rmse_deg": {"total": None, "inclination": None, "heading": None}},
         "velocity": {"messages_in": 2, "used": 0, "stale": 0, "rejected": {},
                      "aided_samples": 0, "heading_known": False, "heading_offset_rad": None,
                      "heading_sigma_rad": None}}
    s["topics"]["velocity"] = "/v"
    print_summary(s)
    text = capsys.readouterr().out
    assert "n/a" in text and "speed   n/a messages/s" in text


# -- item 10: exit status ---------------------------------------------------------------------
def test_fleet_exit_status_tells_some_failed_from_usage_and_all_failed(tmp_path, capsys):
    d = tmp_path / "in"
    d.mkdir()
    for name in ("a", "b"):  # two broken bags: storage without metadata.yaml
        (d / name).mkdir()
        (d / name / "x.mcap").write_bytes(b"not an mcap")
    assert main(["replay", str(d), "--json", str(tmp_path / "j.json"), "--no-progress"]) == 3
    write_imu_bag(d / "good", [T0_NS + k * 10_000_000 for k in range(300)])
    assert main(["replay", str(d), "--json", str(tmp_path / "k.json"), "--no-progress"]) == 1
    assert main(["replay", str(d / "good"), "--json", str(tmp_path / "l.json")]) == 0
    capsys.readouterr()
    docs = (REPO / "docs" / "replay.md").read_text()
    for code in ("| 0 |", "| 1 |", "| 2 |", "| 3 |"):
        assert code in docs


# -- item 11: small ---------------------------------------------------------------------------
def test_empty_imu_topic_says_0_messages(tmp_path, capsys):
    path = tmp_path / "empty"
    with io.OutputBag(path) as bag:  # the IMU topic declared, no message on it (a dead driver)
        bag.add_topic("/mavros/imu/data_raw", io.IMU_TYPE)
    assert main(["replay", str(path), "--json", str(tmp_path / "j.json")]) == 1
    err = capsys.readouterr().err
    assert "/mavros/imu/data_raw [sensor_msgs/msg/Imu]: 0 messages" in err


def test_fleet_table_says_offline(tmp_path, capsys):
    d = tmp_path / "in"
    d.mkdir()
    for i in range(2):
        write_scenario_bag(make_scenario("flight", rate_hz=50.0, duration_s=20.0, seed=i),
                           d / f"f{i}", storage="mcap")
    assert main(["replay", str(d), "--offline", "--json", str(tmp_path / "j.json"),
                 "--no-progress"]) == 0
    table = capsys.readouterr().out
    totals = [line for line in table.splitlines() if line.startswith("fleet   ")]
    assert len(totals) == 1 and "(offline: acausal estimates, --offline)" in totals[0], table


def test_mag_range_agrees_between_warning_and_docs():
    lo, hi = checks.MAG_PLAUSIBLE_T
    tag, text = checks.mag_units_warning(1e-3)
    assert f"{lo * 1e6:g}-{hi * 1e6:g} uT" in text and text.count("scale") <= 2  # says it once
    docs = (REPO / "docs" / "failure_modes.md").read_text()
    assert f"{lo * 1e6:g}–{hi * 1e6:g} µT" in docs


def test_readme_says_how_long_the_tests_take_and_a_quick_subset():
    readme = " ".join((REPO / "README.md").read_text().split())
    assert re.search(r"The whole run takes [0-9.]+(–[0-9.]+)? min on a 2-core machine", readme)
    assert "from an empty virtual environment" in readme
    assert "quick check" in readme.lower()


def test_json_summary_of_a_good_bag_is_complete(tmp_path):
    path = write_imu_bag(tmp_path / "g", [T0_NS + k * 10_000_000 for k in range(300)])
    assert main(["replay", str(path), "--json", str(tmp_path / "j.json")]) == 0
    s = json.loads((tmp_path / "j.json").read_text())
    assert checks.unusable_reason(s) is None


# -- item 2 (the helper; the node's use: test_first_flights_node.py) ---------------------------
def test_rate_limited_warnings_one_line_per_reset_and_per_new_rejection_kind():
    from cf_estimator.pipeline.log_events import RateLimitedWarnings

    w = RateLimitedWarnings(period_s=5.0)
    assert w.update({}, {"nonfinite_gyro": 1}, 0.0) == [
        "IMU message rejected: nonfinite_gyro (first of its kind; 1 so far, counted in "
        "/diagnostics)"]
    assert w.update({}, {"nonfinite_gyro": 9}, 1.0) == []  # same kind, within the period
    lines = w.update({"time_jump_back": 1}, {"nonfinite_gyro": 9, "out_of_order": 1}, 2.0)
    assert len(lines) == 2 and lines[0].startswith("filter reset (time_jump_back)")
    assert "out_of_order (first of its kind" in lines[1]
    assert w.update({"time_jump_back": 2}, {}, 3.0) == []  # held back ...
    assert w.flush(4.0) == []
    late = w.flush(7.5)  # ... and said once due, with what was held back
    assert any("8 more (9 so far)" in t for t in late)
    assert any("2 reset(s) time_jump_back so far" in t for t in late)
    # an event (an attitude error revealed while aided): one line, rate-limited alike
    ev = w.update({}, {}, 10.0, {"attitude_error": 1})
    assert len(ev) == 1 and ev[0].startswith("attitude_error: velocity-aided")
    assert "1 so far, counted in /diagnostics" in ev[0]
    assert w.update({}, {}, 11.0, {"attitude_error": 3}) == []
    assert any("(2 since the last report); 3 so far" in t for t in w.flush(15.5))


# -- items 3 and 5: frames that say what they are; nwu, true north --------------------------
def _pipe_output(world_frame: str, body_frame: str = "sensor", frame: str = "base_link",
                 n: int = 50, **pipeline: object):
    """The last output of a still, level FLU IMU (and a field pointing north-and-down, ENU
    magnetic north along y) through a fresh pipeline."""
    import numpy as np

    from cf_estimator.core.params import FilterParams
    from cf_estimator.pipeline import ImuPipeline, PipelineParams

    v3 = TS.types["geometry_msgs/msg/Vector3"]
    Header = TS.types["std_msgs/msg/Header"]
    Time = TS.types["builtin_interfaces/msg/Time"]
    Mag = TS.types["sensor_msgs/msg/MagneticField"]
    # FLU level body, x pointing magnetic north: the field is (B_n, 0, -B_d) in FLU
    mag = (20e-6, 0.0, -40e-6)
    accel = (0.0, 0.0, G)
    if body_frame == "frd":
        mag, accel = (mag[0], -mag[1], -mag[2]), (0.0, 0.0, -G)
    pipe = ImuPipeline(FilterParams(world_frame=world_frame),
                       PipelineParams(body_frame=body_frame, **pipeline))
    out = None
    for i in range(n):
        t = T0_NS + i * 10_000_000
        h = Header(stamp=Time(sec=t // 10**9, nanosec=t % 10**9), frame_id=frame)
        pipe.on_mag(Mag(header=h, magnetic_field=v3(x=mag[0], y=mag[1], z=mag[2]),
                        magnetic_field_covariance=np.zeros(9)))
        msg = _imu(t, frame)
        msg.linear_acceleration = v3(x=accel[0], y=accel[1], z=accel[2])
        msg.angular_velocity = v3(x=0.0, y=0.0, z=0.0)
        out = pipe.on_imu(msg)
    assert out is not None and out.initialized
    return out


def test_frame_ids_name_the_published_body_convention():
    assert _pipe_output("ned", "flu").frame_id == "base_link_frd"
    assert _pipe_output("enu", "frd", frame="imu_frd").frame_id == "imu_flu"
    assert _pipe_output("enu", "flu").frame_id == "base_link"  # REP-103 as it came
    assert _pipe_output("ned", "frd", frame="base_link_frd").frame_id == "base_link_frd"
    assert _pipe_output("ned", "flu", output_frame_id="fcu").frame_id == "fcu"


def test_tf_that_would_be_misread_is_refused():
    from cf_estimator.pipeline.frames import check_tf_frames

    refusal, _ = check_tf_frames("ned", "flu", "map", "auto")
    assert refusal and "map_ned" in refusal
    assert check_tf_frames("ned", "flu", "map_ned", "auto") == (None, None)
    assert check_tf_frames("enu", "flu", "map", "auto") == (None, None)
    refusal, _ = check_tf_frames("ned", "flu", "odom_ned", "base_link")
    assert refusal and "base_link_frd" in refusal
    assert check_tf_frames("nwu", "sensor", "world_nwu", "auto")[1]  # a warning


def test_nwu_is_a_world_frame_with_yaw_from_north():
    enu = _pipe_output("enu", "flu").rpy_rad
    nwu = _pipe_output("nwu", "flu").rpy_rad
    assert enu[2] == pytest.approx(math.pi / 2, abs=1e-3)  # x to magnetic north: 90 deg in ENU
    assert nwu[2] == pytest.approx(0.0, abs=1e-3)  # ... and 0 in NWU
    assert nwu[0] == pytest.approx(0.0, abs=1e-3) and nwu[1] == pytest.approx(0.0, abs=1e-3)
    frd_in_nwu = _pipe_output("nwu", "frd")  # the FRD input turned to FLU, paired with NWU
    assert frd_in_nwu.frame_id == "base_link_flu" and abs(frd_in_nwu.rpy_rad[0]) < 1e-3


def test_declination_makes_yaw_true_north_in_every_world_frame():
    d = math.radians(10.0)  # magnetic north 10 deg east of true north: true heading +10 deg
    enu = _pipe_output("enu", "flu", magnetic_declination_rad=d).rpy_rad[2]
    ned = _pipe_output("ned", "flu", magnetic_declination_rad=d).rpy_rad[2]
    nwu = _pipe_output("nwu", "flu", magnetic_declination_rad=d).rpy_rad[2]
    assert math.degrees(enu) == pytest.approx(80.0, abs=0.1)  # CCW from east
    assert math.degrees(ned) == pytest.approx(10.0, abs=0.1)  # heading, CW from north
    assert math.degrees(nwu) == pytest.approx(-10.0, abs=0.1)  # CCW from north
    off = _pipe_output("ned", "flu", magnetic_declination_rad=d,
                       yaw_offset_rad=math.radians(5.0)).rpy_rad[2]
    assert math.degrees(off) == pytest.approx(15.0, abs=0.1)


def test_nwu_and_declination_replay_as_online(tmp_path):
    """The bag replay (bulk path and offline) publishes the same world frame as the node."""
    from cf_estimator.bag.replay import ReplayOptions, replay_bag
    from cf_estimator.core.params import FilterParams
    from cf_estimator.pipeline import PipelineParams

    src = tmp_path / "f"
    write_scenario_bag(make_scenario("flight", rate_hz=50.0, duration_s=20.0, seed=4), src)
    pp = PipelineParams(magnetic_declination_rad=0.2)
    yaw = {}
    for wf in ("enu", "nwu"):
        for offline in (False, True):
            r = replay_bag(src, None, FilterParams(world_frame=wf), pp,
                           ReplayOptions(progress=False, offline=offline))
            yaw[wf, offline] = r.series.rpy_rad[-1, 2]
    for offline in (False, True):
        d = (yaw["nwu", offline] - yaw["enu", offline] + math.pi / 2 + math.pi) % (2 * math.pi)
        assert d - math.pi == pytest.approx(0.0, abs=1e-6)


# -- item 8: tune writes what it tuned --------------------------------------------------------
@pytest.fixture(scope="module")
def flight_bag(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("tune") / "flight"
    write_scenario_bag(make_scenario("flight", rate_hz=50.0, duration_s=20.0, seed=5), path)
    return path


def _tune(flight_bag: Path, out: Path, *extra: str) -> dict:
    import yaml

    rc = main(["tune", "--bag", str(flight_bag), "--search", "k1,k2", "--candidates", "4",
               "--passes", "1", "--jobs", "1", "--scenario-limit", "none", "--force",
               "--out", str(out), *extra])
    assert rc == 0
    return yaml.safe_load(out.read_text())["/**"]["ros__parameters"]


def test_tune_writes_only_the_tuned_parameters(flight_bag, tmp_path, capsys):
    doc = _tune(flight_bag, tmp_path / "t.yaml")
    assert sorted(doc) == ["k1", "k2"]  # nothing else reset to its default
    text = (tmp_path / "t.yaml").read_text()
    assert "# only the tuned parameters (k1, k2)" in text
    capsys.readouterr()


def test_tune_with_params_writes_the_merged_set_and_says_so(flight_bag, tmp_path, capsys):
    mine = tmp_path / "mine.yaml"
    mine.write_text("/**:\n  ros__parameters:\n    world_frame: ned\n    body_frame: flu\n"
                    "    velocity_topic: /mavros/global_position/raw/gps_vel\n"
                    "    publish_tf: true\n    r1: 0.2\n")
    doc = _tune(flight_bag, tmp_path / "t.yaml", "--params", str(mine))
    assert doc["world_frame"] == "ned" and doc["body_frame"] == "flu" and doc["r1"] == 0.2
    assert doc["velocity_topic"] == "/mavros/global_position/raw/gps_vel" and doc["publish_tf"]
    assert f"those of --params {mine}" in (tmp_path / "t.yaml").read_text()
    capsys.readouterr()


def test_a_tuned_value_on_a_bound_gets_a_note():
    from cf_estimator.bench import tuning
    from cf_estimator.cli.tune_cmd import bound_notes
    from cf_estimator.core.params import FilterParams
    from cf_estimator.params_file import render_params_yaml

    space = tuning.space_from_names(["k1", "k2"])
    best = FilterParams(k1=0.1, k2=0.01)  # k1 on its lower (safety) bound, k2 inside
    notes = bound_notes(space, best)
    assert list(notes) == ["k1"] and "lower search bound" in notes["k1"]
    assert "safety bound" in notes["k1"]
    space = tuning.with_bounds(space, {"k2": (0.001, 0.01)})
    assert "--bounds k2=LO:HI" in bound_notes(space, best)["k2"]
    text = render_params_yaml(best, only=["k1", "k2"], notes=notes)
    assert "# NOTE: k1 = 0.1 ended on its lower search bound" in text


def test_covariance_docs_agree_with_behaviour():
    """The first output already has an attitude: no published message carries the -1 marker,
    and the README says so instead of promising it."""
    first = _pipe_output("enu", "flu", n=1)
    assert first.orientation_covariance[0] > 0.0
    readme = (REPO / "README.md").read_text()
    assert "−1 until initialised" not in readme and "-1 until initialised" not in readme


# -- item 5: the migration doc ----------------------------------------------------------------
MADGWICK_PARAMETERS = (  # imu_filter_madgwick (imu_tools, ROS 2 Jazzy) declares these
    "gain", "zeta", "use_mag", "world_frame", "declination", "yaw_offset", "publish_tf",
    "reverse_tf", "fixed_frame", "orientation_stddev", "constant_dt", "stateless",
    "remove_gravity_vector", "publish_debug_topics", "mag_bias_x", "mag_bias_y", "mag_bias_z",
)


def test_migration_doc_maps_every_madgwick_parameter_to_ours_or_says_why_not():
    import ast

    from cf_estimator.params_file import all_specs

    ours = {s.name for s in all_specs()}
    text = (REPO / "docs" / "migrating_from_madgwick.md").read_text()
    rows = [line.split("|")[1:-1] for line in text.splitlines() if line.startswith("| `")]
    mapped = {}
    for cells in rows:
        for name in re.findall(r"`(\w+)`", cells[0]):
            mapped[name] = cells[2]
    assert set(MADGWICK_PARAMETERS) <= set(mapped), set(MADGWICK_PARAMETERS) - set(mapped)
    for name, target in mapped.items():
        names = re.findall(r"`(\w+)`", target)
        assert names or "not needed" in target or "no equivalent" in target, name
        assert all(n in ours for n in names), (name, names)
    # the launch example after the swap uses our parameter names only, and is Python
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    after = ast.parse(blocks[1])
    keys = [k.value for d in ast.walk(after) if isinstance(d, ast.Dict) for k in d.keys]
    assert keys and all(k in ours for k in keys), keys
    assert "cf_estimator_node" in blocks[1] and "/mavros/imu/data_raw" in blocks[1]


def test_velocity_aiding_gets_the_velocity_in_the_magnetic_world_of_the_core():
    """GNSS velocity is true-north; with a declination the core's world is magnetic north:
    the pipeline turns the velocity back by the declination before the aiding."""
    from cf_estimator.core.params import FilterParams
    from cf_estimator.pipeline import ImuPipeline, PipelineParams

    Twist = TS.types["geometry_msgs/msg/TwistStamped"]
    h = TS.types["std_msgs/msg/Header"](
        stamp=TS.types["builtin_interfaces/msg/Time"](sec=1_700_000_000, nanosec=0),
        frame_id="")
    v3 = TS.types["geometry_msgs/msg/Vector3"]
    msg = Twist(header=h, twist=TS.types["geometry_msgs/msg/Twist"](
        linear=v3(x=0.0, y=10.0, z=0.0), angular=v3(x=0.0, y=0.0, z=0.0)))  # 10 m/s true north
    d = math.radians(10.0)
    for wf, expected in (("enu", (-10 * math.sin(d), 10 * math.cos(d))),
                         ("ned", (10 * math.cos(d), -10 * math.sin(d)))):  # D west of it
        pipe = ImuPipeline(FilterParams(world_frame=wf),
                           PipelineParams(magnetic_declination_rad=d))
        assert pipe.on_velocity(msg) is None
        v = pipe.velocity_aiding._pending[-1][1]  # noqa: SLF001 - what the aiding was given
        assert v[:2] == pytest.approx(expected), wf


def test_a_summary_that_cannot_be_written_takes_the_output_bag_with_it(tmp_path, monkeypatch):
    from cf_estimator.cli import replay_cmd

    path = write_imu_bag(tmp_path / "g", [T0_NS + k * 10_000_000 for k in range(300)])

    def broken(target, data):
        raise ValueError("Out of range float values are not JSON compliant")

    monkeypatch.setattr(replay_cmd, "write_json", broken)
    with pytest.raises(ValueError):
        main(["replay", str(path), "-o", str(tmp_path / "out"), "--json",
              str(tmp_path / "s.json")])
    assert not (tmp_path / "out").exists()
