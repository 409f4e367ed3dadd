"""Which implementation runs the filter step: the compiled twin or the Python reference.

:mod:`cf_estimator.core.step` is the reference: the equations, readable, run with floats or
NumPy arrays. ``c/cf_core.c`` (the standalone C core; ``_kernel.c`` binds it to Python)
repeats them operation for operation in C (built by ``pip install``
/ ``colcon build`` when a C compiler is present; tested to agree to 1e-12). Without it
everything works the same, only slower. ``CF_ESTIMATOR_BACKEND=python`` forces the reference.
"""

from __future__ import annotations

import os
from types import ModuleType

try:
    from cf_estimator.core import _kernel as compiled_kernel
except ImportError:  # no C compiler at install time: the Python reference runs everything
    compiled_kernel: ModuleType | None = None  # type: ignore[no-redef]

BACKENDS = ("compiled", "python")
BACKEND_ENV = "CF_ESTIMATOR_BACKEND"


def compiled_available() -> bool:
    """True when the compiled step kernel was built and imports."""
    return compiled_kernel is not None


def resolve_backend(backend: str | None = None) -> str:
    """'compiled' or 'python': ``backend`` if given, else $CF_ESTIMATOR_BACKEND, else the
    compiled kernel when it is available. Asking for 'compiled' without it raises RuntimeError."""
    choice = backend or os.environ.get(BACKEND_ENV) or (
        "compiled" if compiled_available() else "python")
    if choice not in BACKENDS:
        raise ValueError(f"unknown filter backend {choice!r}; valid: {', '.join(BACKENDS)}")
    if choice == "compiled" and not compiled_available():
        raise RuntimeError("the compiled filter kernel is not built (reinstall with a C compiler "
                           "present) — set CF_ESTIMATOR_BACKEND=python to run the reference")
    return choice
