"""Module-level guard of the tests that compare the compiled twin with the Python reference."""

from __future__ import annotations

import os

import pytest

from cf_estimator.core import kernel


def require_kernel() -> None:
    """Skip the calling test module when the compiled kernel is not built, or fail it when
    CF_ESTIMATOR_REQUIRE_KERNEL=1 (CI: the kernel must build there)."""
    if kernel.compiled_available():
        return
    if os.environ.get("CF_ESTIMATOR_REQUIRE_KERNEL") == "1":
        pytest.fail("the compiled kernel did not build (CF_ESTIMATOR_REQUIRE_KERNEL=1)",
                    pytrace=False)
    pytest.skip("compiled kernel not built (no C compiler at install time)",
                allow_module_level=True)
