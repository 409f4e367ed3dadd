"""What every ``cf-estimator bench`` sub-command shares: ``--peers``, the parameter file, the
output checks, JSON writing, comma lists."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from cf_estimator.cli.base import CliError
from cf_estimator.cli.common import (
    check_output_file,
    load_params,
    note,
)


def csv_list(text: str) -> list[str]:
    """The non-empty, stripped items of a comma-separated option."""
    return [t.strip() for t in text.split(",") if t.strip()]


def families_option(args: Any, valid: tuple[str, ...]) -> list[str]:
    """``--families`` as a list, each one of ``valid``, and ``--jobs`` ≥ 1 (CliError(2) if not)."""
    families = csv_list(args.families)
    bad = [f for f in families if f not in valid]
    if bad or not families:
        raise CliError(f"--families: unknown {bad[0]!r}; valid: {', '.join(valid)}"
                       if bad else "--families is empty", 2)
    if args.jobs < 1:
        raise CliError("--jobs must be >= 1", 2)
    return families


def add_peers_option(parser: Any) -> None:
    """``--peers``, the same in every bench command."""
    parser.add_argument("--peers", default="all", metavar="LIST",
                        help="peers at their defaults (ROS peers: their ROS packages' defaults): "
                        "comma-separated vqf,fusion,madgwick,complementary, "
                        "'all' or 'none' (default all; peers not installed are skipped with a "
                        "note: pip install '.[bench]')")


def load_filter_params(path: str | None, node_name: str | None = None):
    """FilterParams from a parameter file (as the node reads it); CliError(2) when bad."""
    return load_params(path, node_name)[0]


def check_outputs(args: Any, *names: str) -> None:
    """--json/--plot files: checked before the work starts (exist → --overwrite)."""
    for name in names:
        check_output_file(getattr(args, name, None), overwrite=args.overwrite,
                          option=f"--{name}")


def write_json(path: str, doc: dict) -> None:
    from cf_estimator.bag.io import write_atomic_text

    try:
        write_atomic_text(Path(path), json.dumps(doc, indent=2, allow_nan=False) + "\n")
    except OSError as exc:
        raise CliError(f"cannot write {path}: {exc.strerror or exc}", 2) from None


def available_peers(args: Any) -> list[str]:
    """The installed peers among ``--peers`` (one rule for every bench command): unknown
    names are CliError(2); peers whose package is missing are skipped with one note."""
    from cf_estimator.bench.peers import missing_note, parse_peers, split_available

    try:
        wanted = parse_peers(args.peers)
    except ValueError as exc:
        raise CliError(str(exc), 2) from None
    have, missing = split_available(wanted)
    if missing:
        note(missing_note(missing))
    return have
