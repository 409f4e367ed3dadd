"""A documented ``cf-estimator`` command, run once per test session and shared by every test.

The docs' quoted outputs (test/test_doc_outputs.py) and the guards that read a run's files
(test/test_cross_table.py reads ``bench cross --json``) ask here: the first asker runs the
command as a user would — in a fresh directory ``work/`` beside a link ``shared`` to
``../shared`` — and later askers get the same run (exit code, stdout, the directory with the
files it wrote). A command asked for by several test files runs once.
"""

from __future__ import annotations

import contextlib
import io
import os
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest

from cf_estimator.cli.main import main

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
#: The cross-dataset table the guards of test/test_cross_table.py run (ours and VQF only).
CROSS_COMMAND = "cf-estimator bench cross --data ../shared/data --json cross.json"


@dataclass(frozen=True)
class CliRun:
    """One finished run: exit code, what it printed on stdout, the directory it ran in."""

    rc: int
    out: str
    cwd: Path


_RUNS: dict[str, CliRun] = {}


def run_documented(command: str, tmp_path_factory: pytest.TempPathFactory) -> CliRun:
    """``command`` (``cf-estimator ...``) run once per session in a fresh ``work/`` directory."""
    if command not in _RUNS:
        argv = shlex.split(command)
        assert argv[0] == "cf-estimator", command
        base = tmp_path_factory.mktemp("documented")
        work = base / "work"
        work.mkdir()
        if SHARED.is_dir():
            (base / "shared").symlink_to(SHARED, target_is_directory=True)
        before = Path.cwd()
        buf = io.StringIO()
        os.chdir(work)
        try:
            with contextlib.redirect_stdout(buf):
                rc = main(argv[1:])
        finally:
            os.chdir(before)
        _RUNS[command] = CliRun(rc, buf.getvalue(), work)
    return _RUNS[command]
