"""``cf-estimator`` command line: one sub-command per module ``cf_estimator.cli.<name>_cmd``.

Each command module provides ``register(subparsers)``, which adds its parser and sets
``run=<callable(args) -> int>``. Errors meant for the user are raised as :class:`CliError`
and printed as one line on stderr; argparse usage errors exit with 2.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import sys
from collections.abc import Sequence

#: Sub-command modules, in the order ``--help`` lists them.
COMMANDS: tuple[str, ...] = ("design", "bench", "tune", "demo", "simulate", "replay")


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


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every sub-command registered."""
    parser = argparse.ArgumentParser(
        prog="cf-estimator",
        description="Complementary-filter attitude estimation: design, simulate, replay, tune.",
    )
    from cf_estimator.cli.common import VersionAction

    parser.add_argument("--version", action=VersionAction,
                        help="print the package version and the filter-step backend, and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"cf_estimator.cli.{name}_cmd").register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cf-estimator`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except CliError as exc:
        print(f"cf-estimator: error: {exc}", file=sys.stderr)
        return exc.code
    except KeyboardInterrupt:
        print("cf-estimator: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `cf-estimator replay … --json - | head`: not an error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # Python would complain again at exit otherwise
        return 1


if __name__ == "__main__":  # pragma: no cover
    # under ``python -m`` this file is also imported as cf_estimator.cli.main; use that copy so
    # the CliError the commands raise is the one main() catches
    from cf_estimator.cli.main import main as _main

    sys.exit(_main())
