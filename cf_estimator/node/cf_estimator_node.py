"""Console script ``cf_estimator_node``: check what can be checked without ROS, then run the node.

Imports rclpy only inside :func:`main`, so a machine without ROS gets one line saying how to get
it (instead of a traceback), and a params file that is missing or not YAML is reported in one
line (the file, the line, what is wrong; :func:`cf_estimator.params_file.check_params_file`)
before rclpy starts. Exit codes: 0 after Ctrl-C or a
shutdown, 2 when the node cannot start. The node itself: :mod:`cf_estimator.node.node`.
"""

from __future__ import annotations

import sys

from cf_estimator.params_file import check_params_file, params_files

PROGRAM = "cf_estimator_node"
NO_ROS = (
    "the ROS 2 Python packages are not importable ({missing}): source ROS 2 Jazzy "
    "(source /opt/ros/jazzy/setup.bash), or without a ROS install: pip install 'cf_estimator[ros]'"
)


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
