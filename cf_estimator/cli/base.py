"""What every CLI module needs and that imports nothing of the CLI: the user-facing error and
the finite-number argument type (so ``main`` and ``common`` no longer import each other)."""

from __future__ import annotations

import argparse
import math

#: Exit status of every ``cf-estimator`` command (docs/replay.md, Exit status).
EXIT_OK = 0
#: Bad data: the bag (or, in a fleet, some of the bags) could not be replayed; no output for it.
EXIT_SOME_FAILED = 1
#: Usage error or refusal: bad arguments, parameter file, existing output; nothing was run.
EXIT_USAGE = 2
#: A fleet replay in which every bag failed: nothing was replayed.
EXIT_ALL_FAILED = 3


def finite_float(text: str) -> float:
    """argparse type: a finite number (rejects nan, inf and non-numbers with a usage error)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number: {text!r}")
    return value


class CliError(Exception):
    """A user-facing error: printed as ``cf-estimator: error: <message>``, exit ``code``."""

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code
