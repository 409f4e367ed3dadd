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
    assert "offline" in table.splitlines()[-1]


def test_mag_range_agrees_between_warning_and_docs():
    lo, hi = checks.MAG_PLAUSIBLE_T
    tag, text = checks.mag_units_warning(1e-3)
    assert f"{lo * 1e6:g}-{hi * 1e6:g} uT" in text and text.count("scale") <= 2  # says it once
    docs = (REPO / "docs" / "failure_modes.md").read_text()
    assert f"{lo * 1e6:g}–{hi * 1e6:g} µT" in docs


def test_readme_says_how_long_the_tests_take_and_a_quick_subset():
    readme = (REPO / "README.md").read_text()
    assert "min on a fresh 2-core machine" in readme
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
