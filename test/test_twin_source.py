"""The C twin's source against its reference's: the same named constants and parameter reads.

The C core (core/c/cf_core.h and cf_core.c; core/_kernel.c is its Python binding) repeats
core/step.py (with core/stillness.py and core/bias.py) operation for operation. Beside the
numeric comparison (test/test_kernel.py), these checks read both sources:

- every named constant the Python step uses is ``#define``-d in C with the same value, and every
  numeric ``#define`` of the C has a Python constant of that name and value (both ways; the
  header's public ones carry a ``CF_`` prefix, dropped for the comparison);
- neither step holds a bare literal beyond the algebra's 0, 1, 2, 3 (and the half angle 0.5 and
  the series' 48 in the rotation helpers): a tuning number has a name in both files;
- each constant and each parameter is read as many times in C as in Python: reading
  ``mag_saturation_limit_rad`` where ``mag_field_tolerance`` belongs changes both counts.

They need no compiler (the source is parsed), so they run on every machine.
"""

from __future__ import annotations

import ast
import collections
import re
from pathlib import Path

import pytest

from cf_estimator.core import bias, covariance, filter, ops, step, stillness

CORE = Path(step.__file__).parent
#: The C core: the header (public constants, the structs) and the step's source.
C_CORE = (CORE / "c" / "cf_core.h", CORE / "c" / "cf_core.c")
#: The header's namespace for its public names (CF_PHASE_STARTUP is step.py's PHASE_STARTUP).
C_PREFIX = "CF_"
#: The Python step: module → its functions that the C repeats (all top-level ones) ...
PY_MODULES = (step, stillness, bias)
#: ... plus the small-angle series of the exponential map, which the C inlines into expmap().
PY_EXTRA = (("ops.py", "FloatOps.sin_half_over"),)
#: The C functions that repeat them; the first four are the rotation helpers.
C_HELPERS = ("mul", "expmap", "rotate", "turn_heading")
#: The step's stages, in the order step() of step.py and step() of cf_core.c (cf_step's body,
#: also the pair's) call them: one name in both files.
STAGES = ("predict", "classify_motion", "tilt_error", "saturate", "aperiodic", "regulate",
          "recover", "heading")
C_STEP = ("rest_time_s", "bias_limit_rad_s", "toward_unit", "up", "stillness", "turn_share",
          "error_sigma", "loop_gain", "learning_gains", "step") + STAGES
#: ... and what the C computes once where the Python repeats it: the terms of a sample that the
#: stages read (once for both bias hypotheses), the gains' terms aperiodic() and regulate()
#: share; their constants and parameter reads count as those of the code they stand in for.
C_STEP += ("sample_terms", "gain_terms_of")
#: Where a C constant's Python counterpart may live (the step's modules, then the checks', then
#: the covariance model's, whose row loop the C repeats for the bulk replay).
PY_HOMES = (step, stillness, bias, ops, filter, covariance)
#: Bare numbers the algebra needs (zero, one, the 2 of rotations and sample differences, the
#: 3 axes); the rotation helpers also hold the half angle and the series' denominator.
STRUCTURAL = {0.0, 1.0, 2.0, 3.0}
HELPER_ONLY = {0.5, 48.0}
#: Reads the C has more of, for a reason of its structure: stillness() returns early while the
#: block is incomplete, repeating the at-rest line that step.py runs once for both cases.
C_EXTRA_READS = {"rest_bias_learning": 1}
#: C library macros (math.h), not constants of the step: INFINITY is Python's math.inf.
C_LIBRARY = {"NULL", "INFINITY"}
NUMBER = re.compile(r"(?<![\w.])(\d+\.?\d*(?:[eE][-+]?\d+)?)(?![\w.])")
CONST = re.compile(r"\b[A-Z][A-Z0-9_]+\b")


def _py_functions() -> list[tuple[str, ast.AST]]:
    out = []
    for module in PY_MODULES:
        tree = ast.parse(Path(module.__file__).read_text())
        out += [(f"{module.__name__}.{f.name}", f) for f in tree.body
                if isinstance(f, ast.FunctionDef)]
    for file, dotted in PY_EXTRA:
        cls_name, fn_name = dotted.split(".")
        tree = ast.parse((CORE / file).read_text())
        cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls_name)
        out += [(dotted, next(f for f in cls.body
                              if isinstance(f, ast.FunctionDef) and f.name == fn_name))]
    return out


def _c_source() -> str:
    text = "\n".join(path.read_text() for path in C_CORE)
    return re.sub(r"/\*.*?\*/", "", text, flags=re.S)


def _unprefixed(name: str) -> str:
    return name.removeprefix(C_PREFIX)


def _c_functions() -> dict[str, str]:
    src = _c_source()
    out = {}
    for name in C_HELPERS + C_STEP:
        # a definition (its header's declaration ends in ";" before any "{")
        m = re.search(rf"^(?:static )?\w+ \*?{name}\([^;{{]*?\)\n{{.*?^}}\n", src,
                      flags=re.S | re.M)
        assert m is not None, f"cf_core.c has no function {name}()"
        out[name] = m.group(0)
    return out


def _c_defines() -> dict[str, float]:
    return {_unprefixed(m.group(1)): float(m.group(2)) for m in re.finditer(
        r"^#define ([A-Z][A-Z0-9_]+) ([-+]?\d+\.?\d*(?:[eE][-+]?\d+)?)\s*$", _c_source(),
        flags=re.M)}


def _py_numbers(fn: ast.AST) -> collections.Counter:
    return collections.Counter(
        float(n.value) for n in ast.walk(fn)
        if isinstance(n, ast.Constant) and type(n.value) in (int, float))


def _c_numbers(body: str) -> collections.Counter:
    body = re.sub(r"\[\d+\]", "[]", body)  # array sizes and indices are not numbers of the step
    return collections.Counter(float(x) for x in NUMBER.findall(body))


def _py_counts() -> tuple[collections.Counter, collections.Counter]:
    names: collections.Counter = collections.Counter()
    reads: collections.Counter = collections.Counter()
    for _, fn in _py_functions():
        for n in ast.walk(fn):
            if isinstance(n, ast.Name) and CONST.fullmatch(n.id):
                names[n.id] += 1
            if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id == "p":
                reads[n.attr] += 1
    return names, reads


def _c_counts() -> tuple[collections.Counter, collections.Counter]:
    bodies = "".join(_c_functions().values())
    names = collections.Counter(_unprefixed(n) for n in CONST.findall(bodies)
                                if n not in C_LIBRARY)
    return names, collections.Counter(re.findall(r"\bp->(\w+)", bodies))


def _py_calls(fn: ast.FunctionDef) -> list[str]:
    calls = [n for n in ast.walk(fn) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)]
    return [c.func.id for c in sorted(calls, key=lambda c: (c.lineno, c.col_offset))]


def test_step_and_cf_step_call_the_same_stages_in_the_same_order():
    """One reads beside the other: each stage is a function of that name in both files."""
    tree = ast.parse(Path(step.__file__).read_text())
    py = {f.name: f for f in tree.body if isinstance(f, ast.FunctionDef)}
    assert set(STAGES) <= set(py), sorted(set(STAGES) - set(py))
    py_order = [name for name in _py_calls(py["step"]) if name in STAGES]
    c_body = _c_functions()["step"]
    c_order = [name for name in re.findall(r"\b(\w+)\(", c_body) if name in STAGES]
    assert py_order == list(STAGES)
    assert c_order == py_order


def test_every_c_constant_has_its_python_counterpart_with_the_same_value():
    defines = _c_defines()
    assert {"GYRO_LIMIT_RAD_S", "TINY", "MAG_QUICK_LIMIT_RAD", "REST_GATE_SIGMAS"} <= set(defines)
    for name, value in sorted(defines.items()):
        homes = [m for m in PY_HOMES if hasattr(m, name)]
        assert homes, f"cf_core #define {name} has no Python constant of that name"
        assert float(getattr(homes[0], name)) == value, name


def test_every_python_constant_of_the_step_is_defined_in_c_with_the_same_value():
    defines = _c_defines()
    names, _ = _py_counts()
    assert len(names) > 30
    for name in sorted(names):
        assert name in defines, f"{name} (used by the Python step) is not #define-d in cf_core"
        home = next(m for m in PY_HOMES if hasattr(m, name))
        assert float(getattr(home, name)) == defines[name], name


@pytest.mark.parametrize("side", ["python", "c"])
def test_no_bare_tuning_literal_in_either_step(side):
    if side == "python":
        found = {name: _py_numbers(fn) for name, fn in _py_functions()}
        helpers = {"cf_estimator.core.step._exp", "cf_estimator.core.step.turn_heading",
                   "FloatOps.sin_half_over"}
    else:
        found = {name: _c_numbers(body) for name, body in _c_functions().items()}
        helpers = set(C_HELPERS)
    assert helpers <= set(found), f"rotation helpers renamed: {sorted(helpers - set(found))}"
    for name, numbers in found.items():
        allowed = STRUCTURAL | (HELPER_ONLY if name in helpers else set())
        bare = sorted(set(numbers) - allowed)
        assert not bare, f"{side} {name}: bare literal(s) {bare}: name them in both files"


def test_each_constant_and_parameter_is_read_as_often_in_c_as_in_python():
    py_names, py_reads = _py_counts()
    c_names, c_reads = _c_counts()
    assert dict(c_names) == dict(py_names)
    expected = py_reads + collections.Counter(C_EXTRA_READS)
    assert dict(c_reads) == dict(expected)


def test_the_c_params_read_exactly_the_fields_the_python_step_reads():
    """cf_param_fields (what Params() copies from the view) = the Python step's p.* reads."""
    table = re.search(r"cf_param_fields\[\] = \{(.*?)\};", _c_source(), flags=re.S)
    assert table is not None
    fields = set(re.findall(r"\b[DB]F\((\w+)\)", table.group(1)))
    _, py_reads = _py_counts()
    assert fields == set(py_reads)
