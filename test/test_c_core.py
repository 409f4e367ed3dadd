"""The standalone C core (cf_estimator/core/c): plain C99 with no Python, its own C tests.

The core is what a C/C++ ROS node or a flight controller compiles; core/_kernel.c only binds it
to Python (test_kernel.py and test_bulk_twins.py compare that binding with the Python
reference). Here the core stands alone: it includes nothing of Python, compiles as strict C99,
its header compiles as C++ and links from C++, and test/c/test_cf_core.c (the core's behaviour:
a still sensor's bias learned, a rotation integrated, an invalid sample skipped, a refused one
leaving the state as it was, the batch run equal to the per-sample one) passes. Its defaults and
named constants are those of the Python reference. Built with the system compiler ($CC, cc,
gcc) in a temporary directory; skipped, with the reason, when there is none.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from cf_estimator.core import bias, covariance, filter, ops, step, stillness
from cf_estimator.core.filter import step_params
from cf_estimator.core.params import FilterParams

REPO = Path(__file__).resolve().parents[1]
CORE_DIR = REPO / "cf_estimator" / "core" / "c"
HEADER = CORE_DIR / "cf_core.h"
SOURCE = CORE_DIR / "cf_core.c"
C_TESTS = REPO / "test" / "c" / "test_cf_core.c"
CPP_USER = REPO / "test" / "c" / "cpp_user.cpp"
#: What the core may include: itself and the C standard library (no Python.h, no allocator).
ALLOWED_INCLUDES = {"cf_core.h", "math.h", "string.h", "stddef.h"}
#: Strict C99, every warning an error; no fused multiply-adds (the bits of the Python).
C_FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2", "-ffp-contract=off"]
#: Where the step's named constants live in Python (as test_twin_source.PY_HOMES).
PY_HOMES = (step, stillness, bias, ops, filter, covariance)


def _compiler(*names: str) -> str | None:
    for name in names:
        if name and shutil.which(name):
            return name
    return None


def _cc() -> str:
    cc = _compiler(os.environ.get("CC", ""), "cc", "gcc", "clang")
    if cc is None:
        pytest.skip("no C compiler (cc, gcc, clang, $CC): the C core's own tests need one")
    return cc


def _run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300, **kw)


@pytest.fixture(scope="module")
def c_tests(tmp_path_factory) -> Path:
    """test/c/test_cf_core.c linked with cf_core.c alone (strict C99, -Werror)."""
    out = tmp_path_factory.mktemp("c_core") / "test_cf_core"
    done = _run([_cc(), *C_FLAGS, "-I", str(CORE_DIR), str(C_TESTS), str(SOURCE), "-lm", "-o",
                 str(out)])
    assert done.returncode == 0, f"the C tests do not build:\n{done.stderr}"
    return out


def _pairs(text: str) -> dict[str, float]:
    return {name: float(value) for name, value in (line.split() for line in text.splitlines())}


def test_the_core_includes_nothing_of_python():
    for path in (HEADER, SOURCE):
        included = set(re.findall(r'^\s*#\s*include\s*[<"]([^>"]+)[>"]', path.read_text(), re.M))
        assert included <= ALLOWED_INCLUDES, f"{path.name} includes {included - ALLOWED_INCLUDES}"
        assert not re.search(r"\b(Py[A-Z_]\w*|malloc|calloc|realloc|free)\b",
                             re.sub(r"/\*.*?\*/", "", path.read_text(), flags=re.S)), path.name


def test_the_core_compiles_alone_as_strict_c99(tmp_path):
    done = _run([_cc(), *C_FLAGS, "-c", str(SOURCE), "-o", str(tmp_path / "cf_core.o")])
    assert done.returncode == 0, done.stderr


def test_the_c_tests_of_the_core_pass(c_tests):
    done = _run([str(c_tests)])
    assert re.search(r"^\d+ passed, 0 failed$", done.stdout, re.M), done.stdout + done.stderr
    assert done.returncode == 0, done.stdout


def test_the_c_defaults_are_filter_params_defaults(c_tests):
    """cf_params_default() = step_params(FilterParams()): every field the step reads."""
    c = _pairs(_run([str(c_tests), "--defaults"]).stdout)
    view = step_params(FilterParams())
    assert c.pop("ned") == float(view.world_frame == "ned")
    assert c, "cf_param_fields is empty"
    for name, value in c.items():
        assert float(getattr(view, name)) == value, name


def test_the_c_named_constants_are_the_python_steps(c_tests):
    c = _pairs(_run([str(c_tests), "--constants"]).stdout)
    assert {"REST_NOISE_SIGMAS", "MAG_REFERENCE_SAMPLES", "EXTRA_COLUMNS",
            "EVIDENCE_RATIO"} <= set(c)
    for name, value in c.items():
        home = next((m for m in PY_HOMES if hasattr(m, name)), None)
        assert home is not None, f"cf_constants {name} has no Python constant of that name"
        assert float(getattr(home, name)) == value, name


def test_the_header_compiles_as_cpp():
    cxx = _compiler(os.environ.get("CXX", ""), "c++", "g++", "clang++")
    if cxx is None:
        pytest.skip("no C++ compiler (c++, g++, clang++, $CXX)")
    done = _run([cxx, "-x", "c++", "-std=c++11", "-fsyntax-only", "-Wall", "-Wextra", "-Werror",
                 "-pedantic", str(HEADER)])
    assert done.returncode == 0, done.stderr


def test_a_cpp_program_links_the_c_core(tmp_path):
    """The header's extern "C": a C++ user (a ROS 2 node) calls the core compiled as C."""
    cxx = _compiler(os.environ.get("CXX", ""), "c++", "g++", "clang++")
    if cxx is None:
        pytest.skip("no C++ compiler (c++, g++, clang++, $CXX)")
    obj = tmp_path / "cf_core.o"
    done = _run([_cc(), *C_FLAGS, "-c", str(SOURCE), "-o", str(obj)])
    assert done.returncode == 0, done.stderr
    exe = tmp_path / "cpp_user"
    done = _run([cxx, "-std=c++11", "-Wall", "-Wextra", "-Werror", "-I", str(CORE_DIR),
                 str(CPP_USER), str(obj), "-lm", "-o", str(exe)])
    assert done.returncode == 0, done.stderr
    done = _run([str(exe)])
    assert done.returncode == 0, done.stdout + done.stderr
    w, x, y, z = (float(v) for v in done.stdout.split())
    assert abs(w - 0.8775825618903728) < 1e-9 and abs(z - 0.479425538604203) < 1e-9  # yaw 1 rad
