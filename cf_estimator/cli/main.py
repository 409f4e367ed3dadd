"""``cf-estimator`` command line: one sub-command per module ``cf_estimator.cli.<name>_cmd``.

Each command module provides ``register(subparsers)``, which adds its parser and sets
``run=<callable(args) -> int>``. Errors meant for the user are raised as :class:`CliError`
and printed as one line on stderr; argparse usage errors exit with 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings
from collections.abc import Sequence
from typing import Any

from cf_estimator.cli.base import CliError, finite_float

__all__ = ["COMMANDS", "CliError", "build_parser", "finite_float", "main"]

#: Sub-command modules, in the order ``--help`` lists them.
COMMANDS: tuple[str, ...] = ("design", "bench", "tune", "demo", "simulate", "replay",
                             "calibrate_mag")


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
        try:
            module = importlib.import_module(f"cf_estimator.cli.{name}_cmd")
        except ModuleNotFoundError as exc:  # e.g. a colcon workspace without the pip packages
            _register_missing(sub, name, exc)
            continue
        module.register(sub)
    return parser


#: Import name → what to install (pip / apt on ROS 2 Jazzy) for the messages of missing modules.
_INSTALL_HINTS: dict[str, str] = {
    "scipy": "pip install scipy (or apt install python3-scipy)",
    "rosbags": "pip install rosbags",
    "matplotlib": "pip install matplotlib (or apt install python3-matplotlib)",
    "h5py": "pip install h5py (or apt install python3-h5py)",
    "yaml": "pip install pyyaml (or apt install python3-yaml)",
    "numpy": "pip install numpy (or apt install python3-numpy)",
}


def missing_module_text(command: str, exc: ModuleNotFoundError) -> str:
    """One line: which Python package ``command`` needs and how to install it."""
    top = (exc.name or str(exc)).split(".")[0]
    how = _INSTALL_HINTS.get(top, f"pip install {top}")
    return (f"'cf-estimator {command}' needs the Python package {top!r}, which is not "
            f"installed: {how} (all that the CLI uses: pip install numpy scipy rosbags "
            "matplotlib h5py tqdm pyyaml)")


def _register_missing(sub: Any, name: str, exc: ModuleNotFoundError) -> None:
    """A sub-command whose module cannot be imported: listed, and a one-line error when run."""
    command = name.replace("_", "-")
    text = missing_module_text(command, exc)
    sub.add_parser(command, help=f"(unavailable: needs {(exc.name or '?').split('.')[0]})",
                   description=text)
    _MISSING[command] = text


#: Sub-commands whose module could not be imported → their one-line error (see main()).
_MISSING: dict[str, str] = {}


_SHOWN: set[str] = set()


def _one_line_warning(message: Warning | str, category: type[Warning], filename: str,
                      lineno: int, file: Any = None, line: str | None = None) -> None:
    """Python warnings (e.g. a peer's, or estimate()'s unit checks) as one line each, once per
    text: ``cf-estimator: warning: <text>`` instead of the file, line and source line."""
    text = str(message).splitlines()[0] if str(message) else category.__name__
    if text in _SHOWN:
        return
    _SHOWN.add(text)
    print(f"cf-estimator: warning: {text}", file=sys.stderr if file is None else file)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cf-estimator`` console script; returns the exit code."""
    warnings.showwarning = _one_line_warning  # bench workers (fork) inherit it
    parser = build_parser()
    words = list(sys.argv[1:] if argv is None else argv)
    command = next((w for w in words if not w.startswith("-")), None)
    if command in _MISSING and not {"-h", "--help", "--version"} & set(words):
        print(f"cf-estimator: error: {_MISSING[command]}", file=sys.stderr)
        return 2
    args = parser.parse_args(words)
    try:
        return int(args.run(args) or 0)
    except CliError as exc:
        print(f"cf-estimator: error: {exc}", file=sys.stderr)
        return exc.code
    except ModuleNotFoundError as exc:  # a package imported when the command runs
        print(f"cf-estimator: error: {missing_module_text(args.command, exc)}", file=sys.stderr)
        return 2
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
