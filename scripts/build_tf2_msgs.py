#!/usr/bin/env python3
"""Build the ROS 2 message package tf2_msgs (TFMessage only) into this Python environment.

For environments whose ROS 2 Jazzy comes from the PyPI wheels (``pip install 'cf_estimator[ros]'``):
they have rclpy, geometry_msgs and the rosidl generators but no tf2_msgs, which the node's
``publish_tf`` needs. This generates the message from its definition (the same IDL as Jazzy's
tf2_msgs, so the same DDS type name and type hash: real tf2 listeners receive it) with the
wheels' rosidl generators and compiles it with the C/C++ compiler (a few seconds):
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
import contextlib
import importlib.util
import io
import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

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
TYPESUPPORTS = ("c", "fastrtps_c", "introspection_c")


class BuildError(RuntimeError):
    """The build cannot go on (one line)."""


def _run(cmd: list[str]) -> None:
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        lines = (proc.stderr or proc.stdout).strip().splitlines()
        raise BuildError(f"{Path(cmd[0]).name} failed: {lines[-1] if lines else proc.returncode}")


def _generate(src: Path, gen: Path, share: Path) -> None:
    """rosidl: C structs, typesupports (dispatch, Fast DDS, introspection) and Python."""
    from rosidl_generator_c.cli import GenerateC
    from rosidl_generator_py.cli import GeneratePython
    from rosidl_typesupport_c.cli import GenerateCTypesupport
    from rosidl_typesupport_fastrtps_c.cli import GenerateFastRTPSCTypesupport
    from rosidl_typesupport_introspection_c.cli import GenerateIntrospectionCTypesupport

    # The generators find their templates through the ament index of this prefix.
    known = [str(share.parent), *os.environ.get("AMENT_PREFIX_PATH", "").split(":")]
    os.environ["AMENT_PREFIX_PATH"] = ":".join(p for p in dict.fromkeys(known) if p)
    files = [f"{src}:msg/TFMessage.idl"]
    for cls, sub in ((GenerateC, "c"), (GenerateCTypesupport, "ts_c"),
                     (GenerateFastRTPSCTypesupport, "ts_fastrtps_c"),
                     (GenerateIntrospectionCTypesupport, "ts_introspection_c"),
                     (GeneratePython, "py")):
        try:
            cls(cls.__name__).generate(PACKAGE, files, [str(share)], gen / sub / PACKAGE)
        except Exception as exc:  # noqa: BLE001 - the generators raise anything
            raise BuildError(f"rosidl {sub} generator: {exc}".splitlines()[0]) from None


def site_dir(prefix: Path) -> Path:
    """Where ``--prefix`` puts the Python package (pip's ``--prefix`` layout)."""
    return prefix / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"


def usage_lines(target: Path) -> str:
    """The two exports that make a ``--prefix`` build visible to Python and the loader."""
    return (f"export PYTHONPATH={site_dir(target)}:$PYTHONPATH\n"
            f"export LD_LIBRARY_PATH={target / 'lib'}:$LD_LIBRARY_PATH")


def build(force: bool = False, target: Path | None = None) -> str:
    """Build and install (into the running environment, or under ``target`` when given);
    returns what was done."""
    if target is not None:
        target = target.absolute()
        if not force and (site_dir(target) / PACKAGE / "msg").is_dir():
            return (f"{PACKAGE} already built under {target}: nothing to do (--force rebuilds)"
                    f"\n{usage_lines(target)}")
    elif not force and importlib.util.find_spec(PACKAGE) is not None:
        return f"{PACKAGE} already importable: nothing to do"
    prefix = Path(sys.prefix)
    lib, share, include = prefix / "lib", prefix / "share", prefix / "include"
    dest_lib = lib if target is None else target / "lib"
    if not (share / "geometry_msgs" / "msg" / "TransformStamped.idl").is_file():
        raise BuildError(f"no geometry_msgs interface files under {share}: install the ROS 2 "
                         "wheels first (pip install 'cf_estimator[ros]')")
    if importlib.util.find_spec("rosidl_generator_py") is None:
        raise BuildError("rosidl_generator_py is not importable (the ROS 2 wheels bring it)")
    cc, cxx = os.environ.get("CC", "cc"), os.environ.get("CXX", "c++")
    for tool in (cc, cxx):
        if shutil.which(tool) is None:
            raise BuildError(f"no compiler '{tool}' (set CC/CXX or install gcc and g++)")
    import numpy

    site = Path(sysconfig.get_paths()["purelib"]) if target is None else site_dir(target)
    with tempfile.TemporaryDirectory(prefix="tf2_msgs_build_") as tmp:
        work = Path(tmp)
        src, gen, out = work / "src", work / "gen", work / "out"
        (src / "msg").mkdir(parents=True)
        (src / "msg" / "TFMessage.idl").write_text(TF_MESSAGE_IDL, encoding="utf-8")
        noise = io.StringIO()  # the rosidl CLI's entry-point warnings (duplicate metadata)
        with contextlib.redirect_stderr(noise):
            _generate(src, gen, share)
        out.mkdir()
        incs = [f"-I{gen / d}" for d in ("c", "ts_fastrtps_c", "ts_introspection_c")]
        incs += [f"-I{d}" for d in sorted(include.iterdir()) if d.is_dir()] + [f"-I{include}"]
        incs += [f"-I{sysconfig.get_paths()['include']}", f"-I{numpy.get_include()}"]
        common = ["-shared", "-fPIC", "-O2", *incs, f"-L{out}", f"-L{lib}",
                  f"-Wl,-rpath,{lib}", *([f"-Wl,-rpath,{dest_lib}"] if target else [])]
        name = f"lib{PACKAGE}__rosidl_"
        detail = gen / "c" / PACKAGE / "msg" / "detail"
        steps = [
            (cc, sorted(detail.glob("*.c")), "generator_c",
             ["rosidl_runtime_c", "rcutils", "geometry_msgs__rosidl_generator_c",
              "builtin_interfaces__rosidl_generator_c", "std_msgs__rosidl_generator_c"]),
            (cc, sorted((gen / "ts_introspection_c").rglob("*.c")), "typesupport_introspection_c",
             [f"{PACKAGE}__rosidl_generator_c", "geometry_msgs__rosidl_typesupport_introspection_c",
              "rosidl_runtime_c"]),
            (cxx, sorted((gen / "ts_fastrtps_c").rglob("*.cpp")), "typesupport_fastrtps_c",
             [f"{PACKAGE}__rosidl_generator_c", "geometry_msgs__rosidl_typesupport_fastrtps_c",
              "geometry_msgs__rosidl_generator_c", "rosidl_typesupport_fastrtps_c",
              "rosidl_typesupport_fastrtps_cpp", "fastcdr", "rosidl_runtime_c", "rmw"]),
            (cxx, sorted((gen / "ts_c").rglob("*.cpp")), "typesupport_c",
             [f"{PACKAGE}__rosidl_generator_c", "rosidl_typesupport_c", "rosidl_runtime_c",
              "rcpputils", "rcutils"]),
            (cc, [gen / "py" / PACKAGE / "msg" / "_tf_message_s.c"], "generator_py",
             [f"{PACKAGE}__rosidl_generator_c", "geometry_msgs__rosidl_generator_py",
              "geometry_msgs__rosidl_generator_c", "rosidl_runtime_c", "rcutils"]),
        ]
        for compiler, sources, what, libs in steps:
            std = ["-std=c++17"] if compiler == cxx else []
            _run([compiler, *std, *common, *map(str, sources), *(f"-l{x}" for x in libs),
                  "-o", str(out / f"{name}{what}.so")])
        pkg = out / "py" / PACKAGE
        shutil.copytree(gen / "py" / PACKAGE / "msg", pkg / "msg",
                        ignore=shutil.ignore_patterns("*.c"))
        (pkg / "__init__.py").write_text("", encoding="utf-8")
        for ts in TYPESUPPORTS:
            ep = gen / "py" / PACKAGE / f"_{PACKAGE}_s.ep.rosidl_typesupport_{ts}.c"
            module = pkg / f"{PACKAGE}_s__rosidl_typesupport_{ts}.so"
            _run([cc, *common, str(ep), f"-l{PACKAGE}__rosidl_generator_py",
                  f"-l{PACKAGE}__rosidl_typesupport_{ts}", f"-l{PACKAGE}__rosidl_generator_c",
                  "-lrosidl_runtime_c", "-o", str(module)])
        dest_lib.mkdir(parents=True, exist_ok=True)
        site.mkdir(parents=True, exist_ok=True)
        for so in out.glob("*.so"):
            shutil.copy2(so, dest_lib / so.name)
        shutil.rmtree(site / PACKAGE, ignore_errors=True)
        shutil.copytree(pkg, site / PACKAGE)
    done = f"built {PACKAGE} (TFMessage) into {site / PACKAGE} and {dest_lib}"
    return done if target is None else f"{done}; to use it:\n{usage_lines(target)}"


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
