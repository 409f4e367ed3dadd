"""Suite-wide hooks: a test skipped for missing shared data fails in CI, and says so once here.

The accuracy guards read recordings from ``../shared/data`` (beside the checkout, never copied).
A user's clone without it skips them, and the run ends with one line naming the directory.
With ``CF_ESTIMATOR_REQUIRE_DATA=1`` (set by ``.ci/run``) each such skip is a failure instead:
CI cannot go green because the data was not mounted.

A skip is a missing-data skip when its reason names the shared directory (every such skip in
this suite gives the path it looked for).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

#: Where the shared recordings are looked for: ``$CF_ESTIMATOR_DATA_ROOT`` when set (CI's
#: second pass points it at an empty directory to run the suite as a plain clone does), else
#: ``../shared/data`` beside the checkout.
DATA_ROOT_ENV = "CF_ESTIMATOR_DATA_ROOT"
DATA_ROOT = (Path(os.environ[DATA_ROOT_ENV]).resolve() if os.environ.get(DATA_ROOT_ENV)
             else Path(__file__).resolve().parents[1].parent / "shared" / "data")
REQUIRE_DATA_ENV = "CF_ESTIMATOR_REQUIRE_DATA"
_SHARED = re.compile(r"(^|[\s/\\])shared([/\\]|\s|$)")
_data_skips: list[str] = []


def require_data() -> bool:
    """True when missing shared data must fail the run (CI)."""
    return os.environ.get(REQUIRE_DATA_ENV, "").strip() == "1"


def is_missing_data(reason: str) -> bool:
    """A skip reason that names the shared data directory (``.../shared/...``)."""
    return bool(_SHARED.search(reason)) or str(DATA_ROOT) in reason


def _skip_reason(report: pytest.TestReport) -> str | None:
    if report.skipped and isinstance(report.longrepr, tuple) and len(report.longrepr) == 3:
        return str(report.longrepr[2])
    return None


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    outcome = yield
    report = outcome.get_result()
    reason = _skip_reason(report)
    if reason is not None and is_missing_data(reason) and require_data():
        report.outcome = "failed"
        report.longrepr = f"{REQUIRE_DATA_ENV}=1, but the shared data is missing: {reason}"


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    reason = _skip_reason(report)
    if reason is not None and is_missing_data(reason):
        _data_skips.append(report.nodeid)


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    if _data_skips:
        terminalreporter.write_line(
            f"cf_estimator: {len(_data_skips)} test(s) skipped: the shared data is not in "
            f"{DATA_ROOT} (or only in part); the accuracy guards on recordings did not run "
            f"({REQUIRE_DATA_ENV}=1, as CI sets it, makes this a failure)", yellow=True)
