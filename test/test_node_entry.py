"""The console script's checks that need no ROS: missing rclpy, params files before rclpy starts."""

from __future__ import annotations

import subprocess
import sys

import pytest

from cf_estimator.params_file import check_params_file, params_files

WITHOUT_RCLPY = (
    "import sys; sys.modules['rclpy'] = None; "  # import rclpy now fails as on a ROS-less machine
    "from cf_estimator.node.cf_estimator_node import main; sys.exit(main(['cf_estimator_node']))"
)


def test_without_rclpy_the_node_says_how_to_get_it_in_one_line():
    proc = subprocess.run([sys.executable, "-c", WITHOUT_RCLPY], capture_output=True, text=True,
                          timeout=120)
    lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
    assert proc.returncode == 2
    assert len(lines) == 1 and "Traceback" not in lines[0], lines
    assert "rclpy" in lines[0] and "setup.bash" in lines[0] and "cf_estimator[ros]" in lines[0]


def test_params_files_are_read_from_the_ros_arguments_only():
    args = ["--params-file", "not_ros.yaml", "--ros-args", "-p", "k1:=0.5", "--params-file",
            "a.yaml", "--params-file=b.yaml", "--", "--params-file", "app.yaml",
            "--ros-args", "--params-file", "c.yaml"]
    assert params_files(args) == ["a.yaml", "b.yaml", "c.yaml"]


@pytest.mark.parametrize(("text", "words"), [
    ("/**:\n  ros__parameters:\n    k1: 0.5\n", None),
    ("/**:\n  ros__parameters:\n    k1: [0.5\n", "not valid YAML (line 4, column 1)"),
    ("just text\n", "not a ROS 2 parameter file"),
    ("", "not a ROS 2 parameter file"),
])
def test_check_params_file(tmp_path, text, words):
    path = tmp_path / "p.yaml"
    path.write_text(text, encoding="utf-8")
    problem = check_params_file(str(path))
    assert (problem is None) if words is None else (words in problem)
    if problem:
        assert "\n" not in problem and str(path) in problem


def test_check_params_file_missing(tmp_path):
    problem = check_params_file(str(tmp_path / "nope.yaml"))
    assert "cannot read" in problem and "No such file" in problem
