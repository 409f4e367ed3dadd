"""Console script ``cf_estimator_node``: check what can be checked without ROS, then run the node.

Imports rclpy only inside :func:`main`, so a machine without ROS gets one line saying how to get
it (instead of a traceback), and a params file that is missing or not YAML is reported in one
line (the file, the line, what is wrong) before rclpy starts. Exit codes: 0 after Ctrl-C or a
shutdown, 2 when the node cannot start. The node itself: :mod:`cf_estimator.node.node`.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import yaml

PROGRAM = "cf_estimator_node"
NO_ROS = (
    "the ROS 2 Python packages are not importable ({missing}): source ROS 2 Jazzy "
    "(source /opt/ros/jazzy/setup.bash), or without a ROS install: pip install 'cf_estimator[ros]'"
)


def params_files(args: Sequence[str]) -> list[str]:
    """The ``--params-file`` paths among the ROS arguments (after ``--ros-args``, up to ``--``)."""
    files: list[str] = []
    in_ros = False
    it = iter(args)
    for arg in it:
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--":
            in_ros = False
        elif in_ros and arg == "--params-file":
            path = next(it, None)
            if path is not None:
                files.append(path)
        elif in_ros and arg.startswith("--params-file="):
            files.append(arg.partition("=")[2])
    return files


def check_params_file(path: str) -> str | None:
    """None if ``path`` is a readable YAML mapping (what rcl can load), else the problem."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        return f"{path}: cannot read the params file: {getattr(exc, 'strerror', None) or exc}"
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        return f"{path}: not valid YAML{where}: {problem}"
    if not isinstance(doc, Mapping):
        return (f"{path}: not a ROS 2 parameter file (expected '/**:' or '<node name>:' "
                "then 'ros__parameters:')")
    return None


def main(args: list[str] | None = None) -> int:
    """Run the node; ``args`` as ``sys.argv`` (program name first, then ``--ros-args ...``)."""
    argv = list(sys.argv if args is None else args)
    for path in params_files(argv[1:]):
        problem = check_params_file(path)
        if problem:
            print(f"{PROGRAM}: {problem}", file=sys.stderr)
            return 2
    try:
        from cf_estimator.node.node import run
    except ModuleNotFoundError as exc:
        if (exc.name or "").partition(".")[0] == "cf_estimator":
            raise
        print(f"{PROGRAM}: " + NO_ROS.format(missing=exc.name), file=sys.stderr)
        return 2
    try:
        return run(argv)
    except KeyboardInterrupt:  # a second Ctrl-C (launch + process group) during the clean-up
        return 0


if __name__ == "__main__":
    sys.exit(main())
