#!/usr/bin/env python3
"""Build the ROS 2 message package tf2_msgs (TFMessage only) into this Python environment.

For environments whose ROS 2 Jazzy comes from the PyPI wheels (``pip install 'cf_estimator[ros]'``):
they have rclpy, geometry_msgs and the rosidl generators but no tf2_msgs, which the node's
``publish_tf`` needs. This generates the message from its definition (the same IDL as Jazzy's
tf2_msgs, so the same DDS type name and type hash: real tf2 listeners receive it) with the
wheels' rosidl generators and compiles it with the C/C++ compiler (a few seconds; the generic
build is scripts/build_msgs.py):
libraries into ``<prefix>/lib`` (on the wheels' library path), the Python package into
site-packages. On a ROS install, use ``apt install ros-jazzy-tf2-msgs`` instead (never both).

    python3 scripts/build_tf2_msgs.py            # build unless tf2_msgs already imports
    python3 scripts/build_tf2_msgs.py --force    # rebuild
    python3 scripts/build_tf2_msgs.py --prefix DIR   # into DIR, the environment untouched

``--prefix DIR`` is for a shared ROS environment that must not be modified: the libraries go to
``DIR/lib``, the Python package to ``DIR/lib/pythonX.Y/site-packages`` (pip's ``--prefix``
layout), and the script prints the two variables that make them visible::

    export PYTHONPATH=DIR/lib/pythonX.Y/site-packages:$PYTHONPATH
    export LD_LIBRARY_PATH=DIR/lib:$LD_LIBRARY_PATH

Exit codes: 0 built or already present, 2 cannot build (one line why).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import build_msgs  # noqa: E402

BuildError = build_msgs.BuildError

PACKAGE = "tf2_msgs"
#: tf2_msgs/msg/TFMessage.idl as rosidl_adapter writes it from TFMessage.msg in Jazzy.
TF_MESSAGE_IDL = """\
// generated from rosidl_adapter/resource/msg.idl.em
// with input from tf2_msgs/msg/TFMessage.msg
// generated code does not contain a copyright notice

#include "geometry_msgs/msg/TransformStamped.idl"

module tf2_msgs {
  module msg {
    struct TFMessage {
      sequence<geometry_msgs::msg::TransformStamped> transforms;
    };
  };
};
"""
#: The interface packages TFMessage uses (their libraries are linked).
DEPENDS = ("geometry_msgs", "builtin_interfaces", "std_msgs")


def build(force: bool = False, target: Path | None = None) -> str:
    """Build and install (into the running environment, or under ``target`` when given);
    returns what was done."""
    return build_msgs.build(PACKAGE, idl={"msg/TFMessage.idl": TF_MESSAGE_IDL}, deps=DEPENDS,
                            force=force, target=target)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--force", action="store_true", help="rebuild even if it imports")
    parser.add_argument("--prefix", metavar="DIR", type=Path,
                        help="install under DIR (DIR/lib, DIR/lib/pythonX.Y/site-packages) "
                        "instead of the running environment, e.g. for a shared ROS venv; "
                        "prints the PYTHONPATH and LD_LIBRARY_PATH to set")
    args = parser.parse_args(argv)
    try:
        print(build(force=args.force, target=args.prefix))
    except (BuildError, ImportError, OSError) as exc:
        print(f"build_tf2_msgs: cannot build {PACKAGE}: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
