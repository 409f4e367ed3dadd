"""Issue 19, "a UAV team's first week": what a new UAV user hit, each pinned by a test.

Layering of the CLI and the bench, lazy sub-command imports, the body-frame option (FLU/FRD),
a covariance from the filter's state, the node's warning for a params file that misses it,
tune's safety (bounded search, held-out validation, --force), the ROS peers at their ROS
defaults, the filter at 10-50 Hz, and the papercuts of the first week.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from cf_estimator.cli.main import build_parser

REPO = Path(__file__).resolve().parents[1]
PKG = REPO / "cf_estimator"


def _imported_modules(path: Path) -> set[str]:
    """Every module a source file imports (top level and inside functions)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module:
            out.add(node.module)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


# -- item 9: layering --------------------------------------------------------------------------
def test_bench_never_imports_the_cli() -> None:
    offenders = {p.name: sorted(m for m in _imported_modules(p) if m.startswith("cf_estimator.cli"))
                 for p in (PKG / "bench").glob("*.py")}
    assert {k: v for k, v in offenders.items() if v} == {}


def test_cli_common_and_main_do_not_import_each_other() -> None:
    common = _imported_modules(PKG / "cli" / "common.py")
    main = _imported_modules(PKG / "cli" / "main.py") - {"cf_estimator.cli.main"}  # -m re-entry
    assert "cf_estimator.cli.main" not in common
    assert "cf_estimator.cli.common" in main  # the one direction left: main uses common
    assert "cf_estimator.cli.base" in common


def test_grid_bad_params_file_is_one_line(tmp_path) -> None:
    bad = tmp_path / "p.yaml"
    bad.write_text("cf_estimator:\n  ros__parameters:\n    k1: fast\n")
    r = subprocess.run([sys.executable, "-m", "cf_estimator.bench.grid", "--data", str(tmp_path),
                        "--set", "k1=1", "--params", str(bad)], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("grid: ") and "k1" in r.stderr
    assert "Traceback" not in r.stderr


# -- item 8: lazy imports, help ----------------------------------------------------------------
_BLOCKED = "import sys; sys.modules['scipy'] = None; sys.modules['rosbags'] = None; "


def _cli_without_scipy_rosbags(*argv: str) -> subprocess.CompletedProcess:
    code = _BLOCKED + "from cf_estimator.cli.main import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True)


def test_version_works_without_scipy_and_rosbags() -> None:
    r = _cli_without_scipy_rosbags("--version")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("cf-estimator ") and r.stderr == ""


def test_missing_package_is_one_line_naming_what_to_install() -> None:
    for argv, pkg in ((("design", "--k1", "1"), "scipy"), (("replay", "in"), "rosbags")):
        r = _cli_without_scipy_rosbags(*argv)
        assert r.returncode == 2
        lines = r.stderr.strip().splitlines()
        assert "Traceback" not in r.stderr
        assert lines[-1].startswith("cf-estimator: error: ") and f"pip install {pkg}" in lines[-1]


def test_top_level_help_lists_bench_euroc() -> None:
    assert "euroc" in build_parser().format_help()
