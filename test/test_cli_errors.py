"""Bad input to ``replay``/``simulate``/``demo``: one clear line on stderr, a non-zero exit code
(2 for usage errors), and nothing left behind that looks like a complete output."""

from __future__ import annotations

import copy
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cf_estimator.bag import io
from cf_estimator.bag.replay import ReplayOptions, replay_bag
from cf_estimator.bag.simulate import write_scenario_bag
from cf_estimator.cli.main import main
from cf_estimator.scenarios import make_scenario

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def good_bag(tmp_path_factory) -> Path:
    """A small valid ROS 2 bag (static scenario, 2 s at 100 Hz)."""
    path = tmp_path_factory.mktemp("good") / "static"
    write_scenario_bag(make_scenario("static", rate_hz=100.0, duration_s=2.0), path)
    return path


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    rc = main([str(a) for a in argv])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


def assert_one_error_line(err: str, *fragments: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("cf-estimator: error: "), err
    assert "Traceback" not in err
    for f in fragments:
        assert f in lines[0], lines[0]


def assert_nothing_left(directory: Path, *expected: str) -> None:
    """Only ``expected`` names in ``directory``: no output, no temporary leftovers."""
    assert sorted(p.name for p in directory.iterdir()) == sorted(expected)


def test_missing_input_path_is_a_usage_error(tmp_path, capsys):
    rc, _, err = run_cli(capsys, "replay", tmp_path / "nope.bag", "-o", tmp_path / "out")
    assert rc == 2
    assert_one_error_line(err, "nope.bag", "no such file")
    assert_nothing_left(tmp_path)


@pytest.mark.parametrize("name", ["notabag.bag", "notes.txt"])
def test_a_file_that_is_not_a_bag(tmp_path, capsys, name):
    src = tmp_path / name
    src.write_text("hello, I am not a bag\n")
    rc, _, err = run_cli(capsys, "replay", src, "-o", tmp_path / "out")
    assert rc == 1
    assert_one_error_line(err, name)
    assert_nothing_left(tmp_path, name)


def test_a_directory_that_is_not_a_bag(tmp_path, capsys):
    (tmp_path / "folder").mkdir()
    rc, _, err = run_cli(capsys, "replay", tmp_path / "folder", "-o", tmp_path / "out")
    assert rc == 1
    assert_one_error_line(err, "folder", "not a ROS 2 bag")
    assert_nothing_left(tmp_path, "folder")


def _truncate(src: Path, dst: Path, fraction: float = 0.5) -> None:
    data = src.read_bytes()
    dst.write_bytes(data[: int(len(data) * fraction)])


def test_truncated_ros1_bag(good_bag, tmp_path, capsys):
    from rosbags.convert import convert

    full = tmp_path / "full.bag"
    convert([good_bag], full, dst_storage="sqlite3", dst_version=None, compress=None,
            compress_mode="file", default_typestore=None, typestore=None, exclude_topics=[],
            include_topics=[], exclude_msgtypes=[], include_msgtypes=[])
    _truncate(full, tmp_path / "cut.bag")
    full.unlink()
    rc, _, err = run_cli(capsys, "replay", tmp_path / "cut.bag", "-o", tmp_path / "out")
    # replayed as far as readable, said in one line (test/test_truncated_bags.py)
    assert rc == 0 and "Traceback" not in err
    assert [ln for ln in err.splitlines() if "truncated ROS 1 bag" in ln]


def test_truncated_mcap_bag(good_bag, tmp_path, capsys):
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / "metadata.yaml").write_bytes((good_bag / "metadata.yaml").read_bytes())
    _truncate(good_bag / f"{good_bag.name}.mcap", cut / f"{good_bag.name}.mcap")
    rc, _, err = run_cli(capsys, "replay", cut, "-o", tmp_path / "out")
    assert rc == 0 and "Traceback" not in err
    assert [ln for ln in err.splitlines() if "truncated mcap bag" in ln]


def test_corrupt_message_midway_leaves_no_output(good_bag, tmp_path, capsys):
    """The failure happens while writing: the partial output is removed."""
    from rosbags.convert import convert

    sq = tmp_path / "sq"
    convert([good_bag], sq, dst_storage="sqlite3", dst_version=9, compress=None,
            compress_mode="file", default_typestore=None, typestore=None, exclude_topics=[],
            include_topics=[], exclude_msgtypes=[], include_msgtypes=[])
    with sqlite3.connect(sq / "sq.db3") as db:
        imu_id = db.execute("SELECT id FROM topics WHERE name = '/imu/data_raw'").fetchone()[0]
        row = db.execute("SELECT id FROM messages WHERE topic_id = ? ORDER BY timestamp "
                         "LIMIT 1 OFFSET 150", (imu_id,)).fetchone()[0]
        db.execute("UPDATE messages SET data = X'00010000DEAD' WHERE id = ?", (row,))
    rc, _, err = run_cli(capsys, "replay", sq, "-o", tmp_path / "out", "--json",
                         tmp_path / "s.json")
    assert rc == 1
    assert_one_error_line(err, "sq", "sensor_msgs/msg/Imu", "/imu/data_raw")
    assert_nothing_left(tmp_path, "sq")


def test_bag_without_imu_messages(tmp_path, capsys):
    src = tmp_path / "magonly"
    with io.OutputBag(src) as bag:
        bag.write("/imu/mag", io.MAG_TYPE, 10**18,
                  io.magnetic_field_message(10**9, 0, "imu", (2e-5, 0.0, -4e-5)))
    rc, _, err = run_cli(capsys, "replay", src, "-o", tmp_path / "out")
    assert rc == 1
    assert_one_error_line(err, "magonly", "no IMU messages", "/imu/mag")
    assert_nothing_left(tmp_path, "magonly")


@pytest.mark.parametrize(("option", "topic", "fragment"), [
    ("--imu-topic", "/imu/mag", "is sensor_msgs/msg/MagneticField, but --imu-topic needs"),
    ("--mag-topic", "/imu/data_raw", "is sensor_msgs/msg/Imu, but --mag-topic needs"),
    ("--reference-topic", "/imu/mag", "but --reference-topic needs"),
    ("--imu-topic", "/no/such/topic", "no topic '/no/such/topic'"),
])
def test_topic_of_the_wrong_type_or_missing(good_bag, tmp_path, capsys, option, topic, fragment):
    rc, _, err = run_cli(capsys, "replay", good_bag, "-o", tmp_path / "out", option, topic)
    assert rc == 2
    assert_one_error_line(err, fragment)
    assert_nothing_left(tmp_path)


def test_several_imu_topics_list_the_candidates(tmp_path, capsys):
    src = tmp_path / "two_imus"
    with io.OutputBag(src) as bag:
        for k, topic in enumerate(("/a/imu", "/b/imu")):
            bag.write(topic, io.IMU_TYPE, 10**18 + k, io.imu_message(
                10**9, 0, "imu", (0, 0, 0, 1), None, (0, 0, 0), None, (0, 0, 9.8), None))
    rc, _, err = run_cli(capsys, "replay", src, "-o", tmp_path / "out")
    assert rc == 2
    assert_one_error_line(err, "several IMU topics", "/a/imu", "/b/imu", "--imu-topic")


def test_existing_output_without_overwrite_is_kept(good_bag, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "metadata.yaml").write_text("precious\n")
    rc, _, err = run_cli(capsys, "replay", good_bag, "-o", out)
    assert rc == 2
    assert_one_error_line(err, "out", "--overwrite")
    assert (out / "metadata.yaml").read_text() == "precious\n"
    assert_nothing_left(tmp_path, "out")


def test_existing_json_without_overwrite_writes_nothing(good_bag, tmp_path, capsys):
    (tmp_path / "s.json").write_text("{}")
    rc, _, err = run_cli(capsys, "replay", good_bag, "-o", tmp_path / "out", "--json",
                         tmp_path / "s.json")
    assert rc == 2
    assert_one_error_line(err, "s.json", "--overwrite")
    assert_nothing_left(tmp_path, "s.json")


def test_overwrite_never_replaces_a_directory_that_is_not_a_bag(good_bag, tmp_path, capsys):
    keep = tmp_path / "home"
    keep.mkdir()
    (keep / "thesis.tex").write_text("do not delete")
    rc, _, err = run_cli(capsys, "replay", good_bag, "-o", keep, "--overwrite")
    assert rc == 2
    assert_one_error_line(err, "not a ROS 2 bag")
    assert (keep / "thesis.tex").exists()


def test_output_named_like_a_ros1_bag_is_refused(good_bag, tmp_path, capsys):
    rc, _, err = run_cli(capsys, "replay", good_bag, "-o", tmp_path / "out.bag")
    assert rc == 2
    assert_one_error_line(err, "out.bag", ".bag")
    assert_nothing_left(tmp_path)


def test_bad_params_file(good_bag, tmp_path, capsys):
    params = tmp_path / "p.yaml"
    params.write_text("/**:\n  ros__parameters:\n    k1: -3.0\n")
    rc, _, err = run_cli(capsys, "replay", good_bag, "-o", tmp_path / "out", "--params", params)
    assert rc == 2
    assert_one_error_line(err, "k1")
    assert_nothing_left(tmp_path, "p.yaml")


def test_unknown_scenario(tmp_path, capsys):
    rc, _, err = run_cli(capsys, "simulate", "--scenario", "moon_landing", "-o", tmp_path / "s")
    assert rc == 2
    assert_one_error_line(err, "moon_landing", "thesis", "static")
    assert_nothing_left(tmp_path)


def test_simulate_existing_output_without_overwrite(good_bag, tmp_path, capsys):
    rc, _, err = run_cli(capsys, "simulate", "--scenario", "static", "-o", good_bag)
    assert rc == 2
    assert_one_error_line(err, "--overwrite")


def test_simulate_too_short_for_the_scenario(tmp_path, capsys):
    rc, _, err = run_cli(capsys, "simulate", "--scenario", "thesis", "--duration", "5", "-o",
                         tmp_path / "s")
    assert rc == 2
    assert_one_error_line(err, "thesis")
    assert_nothing_left(tmp_path)


def test_interrupted_replay_leaves_no_output(good_bag, tmp_path):
    from cf_estimator.pipeline import ImuPipeline

    class Interrupting(ImuPipeline):
        def process(self, events, start=0, stop=None):
            if self.counters["received_imu"] >= 100:
                raise KeyboardInterrupt
            return super().process(events, start, stop)

    with pytest.raises(KeyboardInterrupt):
        replay_bag(good_bag, tmp_path / "out", options=ReplayOptions(progress=False),
                   pipeline_factory=Interrupting)
    assert_nothing_left(tmp_path)


def test_console_entry_point_prints_one_line_and_exits_2(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run(
        [sys.executable, "-m", "cf_estimator.cli.main", "replay", str(tmp_path / "missing"),
         "-o", str(tmp_path / "out")], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 2
    assert_one_error_line(proc.stderr, "missing")
    assert proc.stdout == ""


# -- more bad bags (issue 6): empty, corrupted, unknown message types, wrong types --------------
def _replay_fails(capsys, src: Path, out_dir: Path, code: int, *fragments: str) -> str:
    rc, out, err = run_cli(capsys, "replay", src, "-o", out_dir / "out", "--json",
                           out_dir / "s.json")
    assert rc == code, err
    assert_one_error_line(err, *fragments)
    assert out == ""
    assert not (out_dir / "out").exists() and not (out_dir / "s.json").exists()
    assert not [p for p in out_dir.iterdir() if ".partial-" in p.name]
    return err


def test_empty_ros1_file(tmp_path, capsys):
    (tmp_path / "empty.bag").write_bytes(b"")
    _replay_fails(capsys, tmp_path / "empty.bag", tmp_path, 1, "empty.bag")


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_empty_ros2_bag_without_messages(tmp_path, capsys, storage):
    src = tmp_path / "nothing"
    with io.OutputBag(src, storage=storage) as bag:
        bag.add_topic("/imu/data_raw", io.IMU_TYPE)  # declared, never written
    _replay_fails(capsys, src, tmp_path, 1, "nothing", "no IMU messages")


def test_empty_storage_file(good_bag, tmp_path, capsys):
    src = tmp_path / "zero"
    src.mkdir()
    (src / "metadata.yaml").write_bytes((good_bag / "metadata.yaml").read_bytes())
    (src / f"{good_bag.name}.mcap").write_bytes(b"")
    _replay_fails(capsys, src, tmp_path, 1, "zero")


def test_corrupted_metadata(good_bag, tmp_path, capsys):
    src = tmp_path / "badmeta"
    shutil.copytree(good_bag, src)
    (src / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n  : :\n")
    _replay_fails(capsys, src, tmp_path, 1, "badmeta")


def test_corrupted_bytes_in_the_middle_of_an_mcap(good_bag, tmp_path, capsys):
    """Not truncated: a stretch of garbage in the middle (a bad disk sector). rosbags writes
    mcap chunks without CRC and its reader then skips the garbled records silently: the replay
    compares the messages read with the bag's index and fails instead of writing an output
    that looks complete with messages missing."""
    src = tmp_path / "flipped"
    shutil.copytree(good_bag, src)
    data = bytearray((src / f"{good_bag.name}.mcap").read_bytes())
    mid = len(data) // 2
    data[mid:mid + 4096] = bytes((b * 37 + 11) % 256 for b in range(4096))
    (src / f"{good_bag.name}.mcap").write_bytes(bytes(data))
    rc, out, err = run_cli(capsys, "replay", src, "-o", tmp_path / "out", "--json",
                           tmp_path / "s.json")
    assert_one_error_line(err, "flipped", "the bag is corrupt")
    assert rc == 1 and out == ""
    assert_nothing_left(tmp_path, "flipped")


def test_corrupted_bytes_in_a_ros1_bag(good_bag, tmp_path, capsys):
    from rosbags.convert import convert

    full = tmp_path / "full.bag"
    convert([good_bag], full, dst_storage="sqlite3", dst_version=None, compress=None,
            compress_mode="file", default_typestore=None, typestore=None, exclude_topics=[],
            include_topics=[], exclude_msgtypes=[], include_msgtypes=[])
    data = bytearray(full.read_bytes())
    mid = len(data) // 2
    data[mid:mid + 2048] = b"\xff" * 2048
    full.write_bytes(bytes(data))
    rc, out, err = run_cli(capsys, "replay", full, "-o", tmp_path / "out")
    assert rc == 1 and out == ""
    assert_one_error_line(err, "full.bag")
    assert_nothing_left(tmp_path, "full.bag")


CUSTOM_IMU_MSGDEF = """
std_msgs/Header header
float64[3] gyro
float64[3] accel
"""


def _bag_with_custom_type(path: Path, topic: str) -> None:
    """A ROS 2 bag whose only topic has a message type ROS 2 Jazzy does not define."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import get_types_from_msg

    store = io.typestore()
    store = copy.deepcopy(store)
    store.register(get_types_from_msg(CUSTOM_IMU_MSGDEF, "acme_msgs/msg/RawImu"))
    msg = store.types["acme_msgs/msg/RawImu"](
        header=io.header(1, 0, "imu"), gyro=np.zeros(3), accel=np.array([0.0, 0.0, 9.8]))
    with Writer(path, version=9) as w:
        conn = w.add_connection(topic, "acme_msgs/msg/RawImu", typestore=store)
        for k in range(5):
            w.write(conn, 10**18 + k, store.serialize_cdr(msg, "acme_msgs/msg/RawImu"))


def test_unknown_message_type_only(tmp_path, capsys):
    src = tmp_path / "acme"
    _bag_with_custom_type(src, "/imu/data_raw")
    _replay_fails(capsys, src, tmp_path, 1, "no IMU messages", "acme_msgs/msg/RawImu")


def test_unknown_message_type_given_as_imu_topic(tmp_path, capsys):
    src = tmp_path / "acme"
    _bag_with_custom_type(src, "/imu/data_raw")
    rc, out, err = run_cli(capsys, "replay", src, "-o", tmp_path / "out", "--imu-topic",
                           "/imu/data_raw")
    assert rc == 2 and out == ""
    assert_one_error_line(err, "acme_msgs/msg/RawImu", "--imu-topic needs sensor_msgs/msg/Imu")
    assert_nothing_left(tmp_path, "acme")


def test_usual_topic_names_with_the_wrong_types(tmp_path, capsys):
    """/imu/data_raw carries Vector3Stamped: detection goes by type, never by name."""
    src = tmp_path / "swapped"
    with io.OutputBag(src) as bag:
        for k in range(50):
            t = 10**9 + k * 10**7
            bag.write("/imu/data_raw", io.VECTOR3_STAMPED_TYPE, t,
                      io.typestore().types[io.VECTOR3_STAMPED_TYPE](
                          header=io.header(1, k * 10**7, "imu"), vector=io.vector3((0, 0, 9.8))))
    _replay_fails(capsys, src, tmp_path, 1, "no IMU messages",
                  "/imu/data_raw [geometry_msgs/msg/Vector3Stamped]")


def test_console_entry_point_on_a_corrupt_bag_prints_no_traceback(good_bag, tmp_path):
    src = tmp_path / "badmeta"
    shutil.copytree(good_bag, src)
    (src / "metadata.yaml").write_text("\x00\x01 not yaml: [")
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run(
        [sys.executable, "-m", "cf_estimator.cli.main", "replay", str(src), "-o",
         str(tmp_path / "out")], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 1
    assert_one_error_line(proc.stderr, "badmeta")
    assert proc.stdout == ""
    assert_nothing_left(tmp_path, "badmeta")
