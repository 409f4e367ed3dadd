"""What every CLI module needs and that imports nothing of the CLI: the user-facing error and
the finite-number argument type (so ``main`` and ``common`` no longer import each other)."""

from __future__ import annotations

import argparse
import math


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
