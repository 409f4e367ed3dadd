#!/usr/bin/env python3
"""Build a ROS 2 message package into this Python environment, without colcon.

For environments whose ROS 2 Jazzy comes from the PyPI wheels (``pip install 'cf_estimator[ros]'``):
they have rclpy, the common interface packages and the rosidl generators, but not every message
package. This generates a package's messages from their definitions (``.msg`` through
rosidl_adapter, or ``.idl`` as given: the same IDL as a colcon build, so the same DDS type names
and hashes) with the wheels' generators and compiles them with the C/C++ compiler: libraries
into ``<prefix>/lib`` (on the wheels' library path), the Python package into site-packages.
On a ROS install, build the package with colcon or apt-install it instead (never both).

    python3 scripts/build_msgs.py ../shared/px4_msgs          # a package directory (msg/*.msg)
    python3 scripts/build_msgs.py ../shared/px4_msgs --force  # rebuild
``scripts/build_tf2_msgs.py`` builds tf2_msgs (TFMessage) through :func:`build`.
Exit codes: 0 built or already present, 2 cannot build (one line why).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path

TYPESUPPORTS = ("c", "fastrtps_c", "introspection_c")


class BuildError(RuntimeError):
    """The build cannot go on (one line)."""


def _run(cmd: list[str]) -> None:
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        lines = (proc.stderr or proc.stdout).strip().splitlines()
        raise BuildError(f"{Path(cmd[0]).name} failed: {lines[-1] if lines else proc.returncode}")


def _snake(name: str) -> str:
    """rosidl's file stem of a message name: ``SensorCombined`` -> ``sensor_combined``."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", "_", name).lower()


def _generate(package: str, src: Path, idls: Sequence[str], gen: Path, share: Path) -> None:
    """rosidl: C structs, typesupports (dispatch, Fast DDS, introspection) and Python."""
    from rosidl_generator_c.cli import GenerateC
    from rosidl_generator_py.cli import GeneratePython
    from rosidl_typesupport_c.cli import GenerateCTypesupport
    from rosidl_typesupport_fastrtps_c.cli import GenerateFastRTPSCTypesupport
    from rosidl_typesupport_introspection_c.cli import GenerateIntrospectionCTypesupport

    # The generators find their templates through the ament index of this prefix.
    known = [str(share.parent), *os.environ.get("AMENT_PREFIX_PATH", "").split(":")]
    os.environ["AMENT_PREFIX_PATH"] = ":".join(p for p in dict.fromkeys(known) if p)
    files = [f"{src}:{rel}" for rel in idls]
    for cls, sub in ((GenerateC, "c"), (GenerateCTypesupport, "ts_c"),
                     (GenerateFastRTPSCTypesupport, "ts_fastrtps_c"),
                     (GenerateIntrospectionCTypesupport, "ts_introspection_c"),
                     (GeneratePython, "py")):
        try:
            cls(cls.__name__).generate(package, files, [str(share)], gen / sub / package)
        except Exception as exc:  # noqa: BLE001 - the generators raise anything
            raise BuildError(f"rosidl {sub} generator: {exc}".splitlines()[0]) from None


def _msg_to_idl(package_dir: Path, package: str, dest: Path) -> list[str]:
    """``msg/*.msg`` of a package directory as ``msg/*.idl`` under ``dest`` (rosidl_adapter)."""
    from rosidl_adapter.msg import convert_msg_to_idl

    msgs = sorted((package_dir / "msg").glob("*.msg"))
    if not msgs:
        raise BuildError(f"{package_dir}: no msg/*.msg files")
    out = dest / "msg"
    out.mkdir(parents=True, exist_ok=True)
    for m in msgs:
        try:
            convert_msg_to_idl(package_dir, package, m.relative_to(package_dir), out)
        except Exception as exc:  # noqa: BLE001
            raise BuildError(f"rosidl_adapter on {m.name}: {exc}".splitlines()[0]) from None
    return [f"msg/{m.stem}.idl" for m in msgs]


def site_dir(prefix: Path) -> Path:
    """Where ``--prefix`` puts the Python package (pip's ``--prefix`` layout)."""
    return prefix / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}" / "site-packages"


def usage_lines(target: Path) -> str:
    """The two exports that make a ``--prefix`` build visible to Python and the loader."""
    return (f"export PYTHONPATH={site_dir(target)}:$PYTHONPATH\n"
            f"export LD_LIBRARY_PATH={target / 'lib'}:$LD_LIBRARY_PATH")


def build(package: str, *, idl: Mapping[str, str] | None = None,
          package_dir: Path | None = None, deps: Sequence[str] = (),
          force: bool = False, target: Path | None = None) -> str:
    """Build and install ``package``; returns what was done.

    Messages from ``idl`` (``{"msg/X.idl": text}``) or from ``package_dir``'s ``msg/*.msg``;
    ``deps``: the interface packages its messages use (their libraries are linked).
    ``target``: install under this prefix (``lib``, ``lib/pythonX.Y/site-packages``) instead
    of the running environment (a shared ROS environment stays untouched); the result then
    says the PYTHONPATH and LD_LIBRARY_PATH to set.
    """
    if target is not None:
        target = target.absolute()
        if not force and (site_dir(target) / package / "msg").is_dir():
            return (f"{package} already built under {target}: nothing to do (--force rebuilds)"
                    f"\n{usage_lines(target)}")
    elif not force and importlib.util.find_spec(package) is not None:
        return f"{package} already importable: nothing to do"
    prefix = Path(sys.prefix)
    lib, share, include = prefix / "lib", prefix / "share", prefix / "include"
    dest_lib = lib if target is None else target / "lib"
    if not (share / "builtin_interfaces").is_dir():
        raise BuildError(f"no ROS 2 interface files under {share}: install the ROS 2 wheels "
                         "first (pip install 'cf_estimator[ros]')")
    for dep in deps:
        if not (share / dep).is_dir():
            raise BuildError(f"no {dep} interface files under {share}")
    if importlib.util.find_spec("rosidl_generator_py") is None:
        raise BuildError("rosidl_generator_py is not importable (the ROS 2 wheels bring it)")
    cc, cxx = os.environ.get("CC", "cc"), os.environ.get("CXX", "c++")
    for tool in (cc, cxx):
        if shutil.which(tool) is None:
            raise BuildError(f"no compiler '{tool}' (set CC/CXX or install gcc and g++)")
    import numpy

    def dep_libs(kind: str) -> list[str]:
        """``<dep>__rosidl_<kind>`` of every dependency that has that library."""
        names = [f"{d}__rosidl_{kind}" for d in deps]
        return [n for n in names if (lib / f"lib{n}.so").is_file()]

    site = Path(sysconfig.get_paths()["purelib"]) if target is None else site_dir(target)
    with tempfile.TemporaryDirectory(prefix=f"{package}_build_") as tmp:
        work = Path(tmp)
        src, gen, out = work / "src", work / "gen", work / "out"
        if idl is not None:
            for rel, text in idl.items():
                (src / rel).parent.mkdir(parents=True, exist_ok=True)
                (src / rel).write_text(text, encoding="utf-8")
            idls = sorted(idl)
        elif package_dir is not None:
            with contextlib.redirect_stdout(io.StringIO()):  # the adapter's progress lines
                idls = _msg_to_idl(package_dir, package, src)
        else:
            raise BuildError("nothing to build: give idl or package_dir")
        noise = io.StringIO()  # the rosidl CLI's entry-point warnings (duplicate metadata)
        with contextlib.redirect_stderr(noise), contextlib.redirect_stdout(noise):
            _generate(package, src, idls, gen, share)
        out.mkdir()
        incs = [f"-I{gen / d}" for d in ("c", "ts_fastrtps_c", "ts_introspection_c")]
        incs += [f"-I{d}" for d in sorted(include.iterdir()) if d.is_dir()] + [f"-I{include}"]
        incs += [f"-I{sysconfig.get_paths()['include']}", f"-I{numpy.get_include()}"]
        common = ["-shared", "-fPIC", "-O2", *incs, f"-L{out}", f"-L{lib}",
                  f"-Wl,-rpath,{lib}", *([f"-Wl,-rpath,{dest_lib}"] if target else [])]
        name = f"lib{package}__rosidl_"
        detail = gen / "c" / package / "msg" / "detail"
        gen_c = dep_libs("generator_c")
        steps = [
            (cc, sorted(detail.glob("*.c")), "generator_c",
             ["rosidl_runtime_c", "rcutils", *gen_c]),
            (cc, sorted((gen / "ts_introspection_c").rglob("*.c")), "typesupport_introspection_c",
             [f"{package}__rosidl_generator_c", *dep_libs("typesupport_introspection_c"),
              "rosidl_typesupport_introspection_c", "rosidl_runtime_c"]),
            (cxx, sorted((gen / "ts_fastrtps_c").rglob("*.cpp")), "typesupport_fastrtps_c",
             [f"{package}__rosidl_generator_c", *dep_libs("typesupport_fastrtps_c"), *gen_c,
              "rosidl_typesupport_fastrtps_c", "rosidl_typesupport_fastrtps_cpp", "fastcdr",
              "rosidl_runtime_c", "rmw"]),
            (cxx, sorted((gen / "ts_c").rglob("*.cpp")), "typesupport_c",
             [f"{package}__rosidl_generator_c", "rosidl_typesupport_c", "rosidl_runtime_c",
              "rcpputils", "rcutils"]),
            (cc, sorted((gen / "py" / package / "msg").glob("*_s.c")), "generator_py",
             [f"{package}__rosidl_generator_c", *dep_libs("generator_py"), *gen_c,
              "rosidl_runtime_c", "rcutils"]),
        ]
        for compiler, sources, what, libs in steps:
            if not sources:
                raise BuildError(f"rosidl generated no sources for {what}")
            std = ["-std=c++17"] if compiler == cxx else []
            _run([compiler, *std, *common, *map(str, sources), *(f"-l{x}" for x in libs),
                  "-o", str(out / f"{name}{what}.so")])
        pkg = out / "py" / package
        shutil.copytree(gen / "py" / package / "msg", pkg / "msg",
                        ignore=shutil.ignore_patterns("*.c"))
        (pkg / "__init__.py").write_text("", encoding="utf-8")
        for ts in TYPESUPPORTS:
            ep = gen / "py" / package / f"_{package}_s.ep.rosidl_typesupport_{ts}.c"
            module = pkg / f"{package}_s__rosidl_typesupport_{ts}.so"
            _run([cc, *common, str(ep), f"-l{package}__rosidl_generator_py",
                  f"-l{package}__rosidl_typesupport_{ts}", f"-l{package}__rosidl_generator_c",
                  "-lrosidl_runtime_c", "-o", str(module)])
        dest_lib.mkdir(parents=True, exist_ok=True)
        site.mkdir(parents=True, exist_ok=True)
        for so in out.glob("*.so"):
            shutil.copy2(so, dest_lib / so.name)
        shutil.rmtree(site / package, ignore_errors=True)
        shutil.copytree(pkg, site / package)
    what = ", ".join(Path(i).stem for i in idls)
    done = f"built {package} ({what}) into {site / package} and {dest_lib}"
    return done if target is None else f"{done}; to use it:\n{usage_lines(target)}"


def package_name(package_dir: Path) -> str:
    """The ``<name>`` of a package directory's package.xml."""
    try:
        return ET.parse(package_dir / "package.xml").getroot().findtext("name") or ""
    except (OSError, ET.ParseError) as exc:
        raise BuildError(f"{package_dir}: no readable package.xml ({exc})") from None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("package_dir", type=Path, help="package directory (package.xml, msg/)")
    parser.add_argument("--depends", nargs="*", default=[], metavar="PKG",
                        help="interface packages its messages use (e.g. std_msgs)")
    parser.add_argument("--force", action="store_true", help="rebuild even if it imports")
    parser.add_argument("--prefix", metavar="DIR", type=Path,
                        help="install under DIR (DIR/lib, DIR/lib/pythonX.Y/site-packages) "
                        "instead of the running environment; prints the exports to set")
    args = parser.parse_args(argv)
    name = args.package_dir.name
    try:
        name = package_name(args.package_dir) or name
        print(build(name, package_dir=args.package_dir.resolve(), deps=args.depends,
                    force=args.force, target=args.prefix))
    except (BuildError, ImportError, OSError) as exc:
        print(f"build_msgs: cannot build {name}: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
