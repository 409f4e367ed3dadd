"""What every ``cf-estimator`` command shares: the parameter-file options and the checks of
input and output paths, so the same mistake gives the same one-line error and exit code in
every command.

Exit codes: 2 for what the user asked for and cannot be (a missing input, an output that
exists without ``--overwrite`` or cannot be written, a bad parameter file), 1 for bad data.
Output paths are checked before any work starts, so a long run never ends in a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from cf_estimator.cli.base import CliError
from cf_estimator.core.params import FilterParams
from cf_estimator.pipeline.params import PipelineParams
from cf_estimator.schema import ParameterError


def warn(text: str) -> None:
    """One warning line on stderr."""
    print(f"cf-estimator: warning: {text}", file=sys.stderr)


def note(text: str) -> None:
    """One informational line on stderr."""
    print(f"cf-estimator: note: {text}", file=sys.stderr)


# -- parameter files ---------------------------------------------------------------------------
def add_params_options(parser: Any, what: str = "the node's parameter file") -> None:
    """``--params YAML`` and ``--node-name NAME`` (which sections of the file apply)."""
    from cf_estimator.params_file import DEFAULT_NODE_NAME

    parser.add_argument("--params", metavar="YAML",
                        help=f"ROS 2 parameter file ({what}; default: the shipped parameters); "
                        "unknown keys are refused")
    parser.add_argument("--node-name", default=DEFAULT_NODE_NAME, metavar="NAME",
                        help="apply the sections of --params that the node of this name reads "
                        "(the node's rule: '/**', the name, wildcards; others are ignored with "
                        "a warning); e.g. cf_estimator or /robot/cf_estimator (default "
                        "%(default)s)")


def add_jobs_option(parser: Any, unit: str = "") -> None:
    """``--jobs N``: worker processes, at most 2 by default (the machine's cores otherwise);
    ``unit`` says what one worker takes (", one flight each")."""
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), metavar="N",
                        help=f"worker processes{unit} (default %(default)s)")


def load_params(
    path: str | None, node_name: str | None = None
) -> tuple[FilterParams, PipelineParams]:
    """Parameters from a ROS 2 parameter file as the node reads it (defaults without one).

    Warnings (sections for other nodes) go to stderr; any problem is CliError(2) naming the file.
    """
    from cf_estimator.params_file import DEFAULT_NODE_NAME, load_params_file

    if path is None:
        return FilterParams(), PipelineParams()
    check_input_path(path, "parameter file", want_file=True)
    try:
        fp, pp, warnings = load_params_file(path, node_name or DEFAULT_NODE_NAME)
    except ParameterError as exc:
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CliError(text if text.startswith(str(path)) else f"{path}: {text}", 2) from None
    for text in warnings:
        warn(text)
    return fp, pp


# -- inputs ------------------------------------------------------------------------------------
def check_input_path(path: str | os.PathLike[str], what: str, *, want_file: bool = False,
                     want_dir: bool = False) -> Path:
    """A missing input is CliError(2) in every command: ``PATH: no such file or directory``."""
    p = Path(path)
    if not p.exists():
        raise CliError(f"{p}: no such file or directory ({what})", 2)
    if want_file and not p.is_file():
        raise CliError(f"{p}: {what} is not a file", 2)
    if want_dir and not p.is_dir():
        raise CliError(f"{p}: {what} is not a directory", 2)
    return p


# -- outputs -----------------------------------------------------------------------------------
def _writable_parent(path: Path, option: str) -> None:
    parent = path.parent if str(path.parent) else Path(".")
    existing = parent
    while not existing.exists():  # the first existing ancestor decides (mkdir -p)
        if existing == existing.parent:
            break
        existing = existing.parent
    if existing.exists() and not existing.is_dir():
        raise CliError(f"{option} {path}: {existing} is a file, not a directory", 2)
    if not os.access(existing, os.W_OK | os.X_OK):
        raise CliError(f"{option} {path}: directory {existing} is not writable", 2)


def check_output_file(target: str | None, *, overwrite: bool, option: str,
                      create_parents: bool = False) -> None:
    """A file the command will write: must not exist without ``overwrite``, must not be a
    directory, and its directory must exist (or be creatable) and be writable. ``-`` is stdout."""
    if target is None or target == "-":
        return
    path = Path(target)
    if path.is_dir():
        raise CliError(f"{option} {path}: is a directory", 2)
    if path.exists() and not overwrite:
        raise CliError(f"{option} {path}: exists (use --overwrite to replace it)", 2)
    if not create_parents and not path.parent.is_dir():
        raise CliError(f"{option} {path}: directory {path.parent} does not exist", 2)
    _writable_parent(path, option)


def check_output_dir(target: str | None, *, overwrite: bool | None, option: str) -> None:
    """A directory the command will write files into (created if missing).

    An existing directory needs ``overwrite`` (None: the command replaces its own files in it
    anyway, e.g. the demo); an existing file, a parent that is a file, or an unwritable
    location is refused.
    """
    if target is None:
        return
    path = Path(target)
    if path.exists():
        if not path.is_dir():
            raise CliError(f"{option} {path}: exists and is not a directory", 2)
        if overwrite is False:
            raise CliError(f"{option} {path}: directory exists (use --overwrite to write "
                           "into it)", 2)
        if not os.access(path, os.W_OK | os.X_OK):
            raise CliError(f"{option} {path}: directory is not writable", 2)
        return
    _writable_parent(path, option)


def version_text() -> str:
    """``cf-estimator <version> (filter step: <backend>)`` for ``--version``."""
    from cf_estimator import __version__
    from cf_estimator.core.kernel import resolve_backend

    try:
        backend = resolve_backend()
    except (RuntimeError, ValueError) as exc:
        backend = f"unavailable: {exc}"
    return f"cf-estimator {__version__} (filter step: {backend})"


class VersionAction(argparse.Action):
    """``--version``: print :func:`version_text` and exit 0 (imports only when asked)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS,
                 **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser: Any, namespace: Any, values: Any, option_string: Any = None
                 ) -> None:
        print(version_text())
        parser.exit()
