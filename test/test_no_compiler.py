"""Issue 13.10: the install without a C compiler, and its switch.

``CC=/bin/false pip install .`` used to ship the compiled step anyway (setuptools reused the
``_kernel*.so`` of an earlier build in ``build/``), so the pure-Python install was never
exercised. Now an earlier binary is never reused: a failing compiler, or
``CF_ESTIMATOR_NO_EXTENSION=1``, gives a pure-Python wheel, and that wheel runs the reference.
Wheels are built from a copy of the checkout (the repository's ``build/`` is not touched).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
COPY_IGNORE = shutil.ignore_patterns(
    ".git", ".venv", "build", "dist", "install", "log", "out", "*.egg-info", "*.so",
    "__pycache__", ".pytest_cache", ".ruff_cache", ".hypothesis", ".benchmarks",
)


def _offline_build_flags() -> list[str]:
    probe = [sys.executable, "-c", "import setuptools.command.bdist_wheel"]
    return ["--no-build-isolation"] if subprocess.run(probe, capture_output=True).returncode == 0 \
        else []


def _wheel(src: Path, out: Path, **env: str) -> Path:
    out.mkdir()
    cmd = [sys.executable, "-m", "pip", "--disable-pip-version-check", "wheel", "-q", "--no-deps",
           "-w", str(out), str(src), *_offline_build_flags()]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600,
                          env={**os.environ, **env})
    assert done.returncode == 0, f"{' '.join(cmd)} failed:\n{done.stdout}\n{done.stderr}"
    (built,) = out.glob("cf_estimator-*.whl")
    return built


def _kernels(wheel: Path) -> list[str]:
    return [n for n in zipfile.ZipFile(wheel).namelist() if "/_kernel" in n]


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, Path]:
    """Wheels of one source copy: normal first (leaves build/), then CC=/bin/false, then the
    switch, each in the same tree, as a user rebuilding in a checkout would."""
    root = tmp_path_factory.mktemp("nocc")
    src = root / "src"
    shutil.copytree(REPO, src, ignore=COPY_IGNORE)
    if shutil.which(os.environ.get("CC", "cc")) is None:
        pytest.skip("no C compiler: every build is pure Python")
    return {
        "normal": _wheel(src, root / "normal"),
        "cc_false": _wheel(src, root / "cc_false", CC="/bin/false"),
        "switch": _wheel(src, root / "switch", CF_ESTIMATOR_NO_EXTENSION="1"),
        "root": root,
    }


def test_a_normal_build_carries_the_compiled_step(built):
    assert len(_kernels(built["normal"])) == 1


def test_a_failing_compiler_gives_a_pure_python_wheel(built):
    assert _kernels(built["cc_false"]) == []


def test_the_switch_gives_a_pure_python_wheel(built):
    assert _kernels(built["switch"]) == []


def test_the_pure_python_install_runs_the_reference(built):
    target = built["root"] / "site"
    with zipfile.ZipFile(built["switch"]) as zf:
        zf.extractall(target)
    code = ("import numpy as np; from cf_estimator.core.kernel import resolve_backend; "
            "from cf_estimator import estimate; "
            "r = estimate(np.zeros((50, 3)), np.tile([0, 0, 9.81], (50, 1)), rate_hz=100.0); "
            "print(resolve_backend(), np.isfinite(r.quaternion[-1]).all())")
    env = {**os.environ, "PYTHONPATH": str(target)}
    env.pop("CF_ESTIMATOR_BACKEND", None)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, env=env, cwd=built["root"])
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["python", "True"]
