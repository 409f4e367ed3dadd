"""``bench fleet``: replay and tuning throughput of many bags, here and on Dask."""

from __future__ import annotations

import sys
from typing import Any

from cf_estimator.cli.base import CliError, finite_float
from cf_estimator.cli.bench_cmd.common import (
    check_outputs,
    csv_list,
    write_json,
)
from cf_estimator.cli.common import check_input_path


def add_parser(sub: Any) -> None:
    """Add ``bench fleet`` to the ``bench`` sub-parsers."""
    fl = sub.add_parser(
        "fleet", help="replay and tuning throughput of many bags: here, and on a Dask "
        "LocalCluster of 1 and 2 workers",
        description=(
            "Replays every bag of --data (default: simulated uav flights in a temporary "
            "directory) with an mcap output each, and scores --candidates parameter sets on "
            "them (one tuner pass), first in this process without Dask, then on a Dask "
            "LocalCluster of each --workers count; prints messages/s, parameter-samples/s, the "
            "speed-up and the figure per worker, and checks every result is identical to the "
            "local run. Needs pip install '.[cluster]'."
        ),
    )
    fl.add_argument("--data", metavar="DIR", help="directory of bags (default: simulated)")
    fl.add_argument("--flights", type=int, default=4, metavar="N",
                    help="simulated flights (default %(default)s)")
    fl.add_argument("--duration", type=finite_float, default=60.0, metavar="S",
                    help="seconds per simulated flight (default %(default)s, >= 40)")
    fl.add_argument("--rate", type=finite_float, default=400.0, metavar="HZ",
                    help="IMU rate of the simulated flights (default %(default)s)")
    fl.add_argument("--workers", default="1,2", metavar="LIST",
                    help="LocalCluster sizes to run, comma-separated (default %(default)s)")
    fl.add_argument("--candidates", type=int, default=16, metavar="N",
                    help="parameter sets scored per bag (default %(default)s)")
    fl.add_argument("--json", metavar="OUT", help="write every figure as JSON")
    fl.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    fl.set_defaults(run=run)


def run(args: Any) -> int:
    """``bench fleet``: exit 1 when a cluster result differs from the local one."""
    from cf_estimator.bench import fleet
    from cf_estimator.cluster import ClusterError

    check_outputs(args, "json")
    if args.data is not None:
        check_input_path(args.data, "bag directory", want_dir=True)
    try:
        workers = tuple(int(x) for x in csv_list(args.workers))
    except ValueError:
        raise CliError(f"--workers: not integers: {args.workers!r}", 2) from None
    if any(w < 1 for w in workers) or args.flights < 1 or args.candidates < 1:
        raise CliError("--workers, --flights and --candidates must be >= 1", 2)
    if args.data is None and args.duration < 40:
        raise CliError("--duration must be >= 40 s (the uav scenario)", 2)
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise CliError("bench fleet needs Dask distributed: pip install "
                       "'cf_estimator[cluster]'", 2) from None
    try:
        result = fleet.run_fleet_bench(
            args.data, flights=args.flights, duration_s=args.duration, rate_hz=args.rate,
            workers=workers, candidates=args.candidates,
            log=lambda text: print(f"bench fleet: {text}", file=sys.stderr, flush=True))
    except ClusterError as exc:
        raise CliError(str(exc), 2) from None
    except ValueError as exc:
        raise CliError(str(exc).splitlines()[0], 1) from None
    print(fleet.format_fleet_bench(result), end="")
    if args.json:
        write_json(args.json, fleet.to_json(result))
    return 0 if all(r.identical is not False for r in result.runs) else 1
