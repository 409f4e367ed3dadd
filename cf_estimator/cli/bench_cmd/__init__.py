"""``cf-estimator bench broad|euroc|scenarios|speed|cross|sustained|fleet|ablate|report``: accuracy
and speed versus the peers, the ablation of our own mechanisms, and the report (BENCHMARKS.md).

``bench broad --data DIR`` scores our filter (and ``--peers``) on BROAD trial files: per-group
tables of total/heading/inclination RMSE [deg] over the movement samples, 9-D and 6-D, and
``--json OUT`` with every trial. Metrics and frames: :mod:`cf_estimator.bench.broad`; peers:
:mod:`cf_estimator.bench.peers` (``pip install '.[bench]'``).

Each sub-command is a module of this package with ``add_parser(sub)`` and ``run(args)``;
:mod:`cf_estimator.cli.bench_cmd.common` holds what they share.
"""

from __future__ import annotations

from typing import Any

from cf_estimator.cli.bench_cmd import (
    ablate,
    broad,
    cross,
    euroc,
    fleet,
    report,
    scenarios,
    speed,
    sustained,
)


def register(subparsers: Any) -> None:
    """Add ``bench`` and its sub-commands."""
    p = subparsers.add_parser(
        "bench", help="accuracy and speed benchmarks vs peers, and ablations (bench broad, euroc, "
        "scenarios, ablate, "
        "speed, cross, sustained, fleet, report)",
        description="Benchmarks of the filter against VQF, x-io Fusion and Madgwick.",
    )
    sub = p.add_subparsers(dest="bench_command", required=True, metavar="BENCHMARK")
    broad.add_parser(sub)
    ablate.add_parser(sub)
    euroc.add_parser(sub)
    scenarios.add_parser(sub)
    speed.add_parser(sub)
    cross.add_parser(sub)
    sustained.add_parser(sub)
    fleet.add_parser(sub)
    report.add_parser(sub)
