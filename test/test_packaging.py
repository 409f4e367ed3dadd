"""Packaging: package.xml, the wheel's files, console scripts, and the node's ROS dependencies.

The wheel and the editable install are built from a copy of the checkout in a temporary
directory, so the tests neither write ``build/`` or ``*.egg-info`` into the repository nor see
stale files from an earlier build.
"""

from __future__ import annotations

import ast
import functools
import re
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import venv
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "cf_estimator"

#: ROS / rosdep key for every third-party top-level module the node may import (directly or
#: through the pipeline and core). A new third-party import needs a row here and an exec_depend.
ROSDEP_KEY = {
    "rclpy": "rclpy",
    "rcl_interfaces": "rcl_interfaces",
    "builtin_interfaces": "builtin_interfaces",
    "sensor_msgs": "sensor_msgs",
    "geometry_msgs": "geometry_msgs",
    "std_msgs": "std_msgs",
    "diagnostic_msgs": "diagnostic_msgs",
    "tf2_msgs": "tf2_msgs",
    "nav_msgs": "nav_msgs",
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "yaml": "python3-yaml",
}

#: Imported by the node only when asked for and never released to rosdep: PX4 teams build
#: px4_msgs from source in their workspace (input_type px4; a one-line error names it otherwise),
#: so it is no exec_depend (rosdep could not resolve it for everyone else).
SOURCE_BUILT_OPTIONAL = {"px4_msgs"}

REQUIRED_EXEC_DEPENDS = {
    "rclpy",
    "sensor_msgs",
    "geometry_msgs",
    "std_msgs",
    "diagnostic_msgs",
    "python3-numpy",
    "python3-yaml",
    "launch",
    "launch_ros",
}

COPY_IGNORE = shutil.ignore_patterns(
    ".git", ".venv", "build", "dist", "install", "log", "out", "*.egg-info",
    "__pycache__", ".pytest_cache", ".ruff_cache", ".hypothesis", ".benchmarks",
)  # fmt: skip


def _manifest() -> ET.Element:
    return ET.parse(REPO / "package.xml").getroot()


def _exec_depends() -> set[str]:
    root = _manifest()
    names = {e.text.strip() for e in root.findall("exec_depend")}
    return names | {e.text.strip() for e in root.findall("depend")}


# --------------------------------------------------------------------------- package.xml


def test_package_xml_is_format_3_ament_python_named_cf_estimator():
    root = _manifest()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == PACKAGE
    assert re.fullmatch(r"\d+\.\d+\.\d+", root.findtext("version"))
    assert root.findtext("license") == "Apache-2.0"
    maintainer = root.find("maintainer")
    assert maintainer is not None and maintainer.get("email") and maintainer.text.strip()
    assert root.findtext("export/build_type") == "ament_python"


def test_package_xml_lists_the_node_and_launch_runtime_dependencies():
    missing = REQUIRED_EXEC_DEPENDS - _exec_depends()
    assert not missing, f"package.xml lacks <exec_depend> for {sorted(missing)}"


def _module_file(name: str) -> Path | None:
    base = REPO.joinpath(*name.split("."))
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _imported_names(path: Path, module: str) -> set[str]:
    """Absolute dotted names imported by one module (relative imports resolved)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = package.split(".")
                anchor = ".".join(parts[: len(parts) - node.level + 1])
                base = f"{anchor}.{node.module}" if node.module else anchor
            else:
                base = node.module
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)  # maybe submodules
    return names


def _third_party_imports_of_node() -> dict[str, set[str]]:
    """Third-party top-level module -> internal modules importing it, over the import closure
    of every module in ``cf_estimator/node/`` (parent packages' ``__init__`` included)."""
    todo = [
        ".".join(p.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__")
        for p in sorted((REPO / PACKAGE / "node").rglob("*.py"))
    ]
    seen: set[str] = set()
    found: dict[str, set[str]] = {}
    while todo:
        module = todo.pop()
        if module in seen:
            continue
        seen.add(module)
        path = _module_file(module)
        if path is None:
            continue
        for name in _imported_names(path, module):
            top = name.partition(".")[0]
            if top == PACKAGE:
                parts = name.split(".")
                todo.extend(".".join(parts[:i]) for i in range(1, len(parts) + 1))
            elif top not in sys.stdlib_module_names and top != "__future__":
                found.setdefault(top, set()).add(module)
    return found


def test_every_third_party_import_of_the_node_is_an_exec_depend():
    declared = _exec_depends()
    problems = []
    for top, users in sorted(_third_party_imports_of_node().items()):
        if top in SOURCE_BUILT_OPTIONAL:
            continue
        key = ROSDEP_KEY.get(top)
        if key is None:
            problems.append(f"{top} (imported by {sorted(users)}): no rosdep key known")
        elif key not in declared:
            problems.append(f"{top} (imported by {sorted(users)}): add <exec_depend>{key}")
    assert not problems, "node runtime imports not covered by package.xml:\n" + "\n".join(problems)


def test_import_scan_resolves_relative_and_submodule_imports(tmp_path):
    source = tmp_path / "m.py"
    source.write_text("from . import a\nfrom ..core import b\nimport numpy.linalg\n")
    names = _imported_names(source, "cf_estimator.node.m")
    assert {"cf_estimator.node.a", "cf_estimator.core.b", "numpy.linalg"} <= names


# --------------------------------------------------------------------------- build & install


@pytest.fixture(scope="module")
def source_copy(tmp_path_factory) -> Path:
    dst = tmp_path_factory.mktemp("src") / PACKAGE
    shutil.copytree(REPO, dst, ignore=COPY_IGNORE)
    return dst


@functools.cache
def _can_build_offline() -> bool:
    """This interpreter's setuptools builds wheels by itself (>= 70.1 has bdist_wheel built in), so
    pip may skip downloading the build requirements. Older ones need ``wheel``, whose recent
    releases no longer work with them: build in pip's isolated environment then."""
    probe = [sys.executable, "-c", "import setuptools.command.bdist_wheel"]
    return subprocess.run(probe, capture_output=True).returncode == 0


def _pip(*args: str) -> None:
    isolation = ["--no-build-isolation"] if _can_build_offline() else []
    cmd = [sys.executable, "-m", "pip", "--disable-pip-version-check", *args, *isolation]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{' '.join(cmd)} failed:\n{done.stdout}\n{done.stderr}"


@pytest.fixture(scope="module")
def wheel(source_copy, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    _pip("wheel", "-q", "--no-deps", "-w", str(out), str(source_copy))
    (built,) = out.glob(f"{PACKAGE}-*.whl")
    return built


def _files(root: Path, pattern: str) -> list[Path]:
    return sorted(p.relative_to(root) for p in root.glob(pattern) if p.is_file())


def test_wheel_installs_package_xml_marker_launch_and_config_under_share(wheel, source_copy):
    names = set(zipfile.ZipFile(wheel).namelist())
    data = "-".join(wheel.name.split("-")[:2]) + ".data/data/"
    launch = _files(source_copy, "launch_scripts/*.launch.py")
    config = _files(source_copy, "config/*.yaml")
    expected = {
        f"share/ament_index/resource_index/packages/{PACKAGE}",
        f"share/{PACKAGE}/package.xml",
        *(f"share/{PACKAGE}/launch/{p.name}" for p in launch),
        *(f"share/{PACKAGE}/config/{p.name}" for p in config),
    }
    missing = sorted(e for e in expected if data + e not in names)
    assert not missing, f"{wheel.name} lacks data files {missing}"


def test_wheel_contains_every_module_of_the_package(wheel, source_copy):
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = [p.as_posix() for p in _files(source_copy, f"{PACKAGE}/**/*.py")]
    assert modules, "no modules found in the repository"
    missing = [m for m in modules if m not in names]
    assert not missing, f"{wheel.name} lacks modules {missing}"


def test_wheel_carries_the_compiled_step_when_a_compiler_is_present(wheel):
    """The C twin of the step is built into the wheel (optional: skipped without a compiler,
    unless CF_ESTIMATOR_REQUIRE_KERNEL=1, which scripts/test.sh sets when cc exists)."""
    import os

    names = zipfile.ZipFile(wheel).namelist()
    built = [n for n in names if re.fullmatch(rf"{PACKAGE}/core/_kernel\..*\.(so|pyd)", n)]
    if not built and os.environ.get("CF_ESTIMATOR_REQUIRE_KERNEL") != "1":
        pytest.skip("no C compiler: the wheel is pure Python (the reference step runs)")
    assert len(built) == 1, f"{wheel.name}: compiled kernel missing ({names[:5]}...)"
    assert "py3-none-any" not in wheel.name  # a platform wheel, since it carries binary code


def test_wheel_declares_both_console_scripts_and_the_package_xml_version(wheel):
    with zipfile.ZipFile(wheel) as zf:
        (entry_points,) = [n for n in zf.namelist() if n.endswith(".dist-info/entry_points.txt")]
        text = zf.read(entry_points).decode()
    assert re.search(r"^cf-estimator = cf_estimator\.cli\.main:main$", text, re.M)
    assert re.search(
        r"^cf_estimator_node = cf_estimator\.node\.cf_estimator_node:main$", text, re.M
    )
    assert wheel.name.startswith(f"{PACKAGE}-{_manifest().findtext('version')}-")


def test_pip_builds_through_pep517_so_colcon_script_dir_stays_colcon_only():
    # setup.cfg sends scripts to lib/cf_estimator for `ros2 run`; only colcon may see that.
    # The [build-system] table keeps pip off the legacy `setup.py develop` path that reads it.
    cfg = (REPO / "setup.cfg").read_text()
    assert re.search(r"^\[develop\]\s*\nscript_dir\s*=\s*\$base/lib/cf_estimator$", cfg, re.M)
    assert re.search(r"^\[install\]\s*\ninstall_scripts\s*=\s*\$base/lib/cf_estimator$", cfg, re.M)
    build_system = tomllib.loads((REPO / "pyproject.toml").read_text())["build-system"]
    assert build_system["build-backend"] == "setuptools.build_meta"


def test_editable_pip_install_puts_cf_estimator_on_the_env_path(source_copy, tmp_path):
    env = tmp_path / "venv"
    venv.EnvBuilder(with_pip=False).create(env)
    python = env / "bin" / "python"
    # The new env sees this interpreter's packages (pip, setuptools, wheel), so pip takes the
    # same build path there as `pip install -e .` takes here.
    site = subprocess.check_output(
        [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], text=True
    )
    Path(site.strip(), "_parent_env.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _pip("--python", str(python), "install", "-q", "--no-deps", "-e", str(source_copy))
    for script in ("cf-estimator", "cf_estimator_node"):
        assert (env / "bin" / script).is_file(), f"{script} not in {env / 'bin'}"
    assert not (env / "lib" / PACKAGE).exists(), "pip used setup.cfg's colcon script dir"
