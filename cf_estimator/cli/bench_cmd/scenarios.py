"""``bench scenarios``: the thesis's simulated disturbances (peak and RMS tilt error), ours beside
the peers.
"""

from __future__ import annotations

from typing import Any

from cf_estimator.cli.base import CliError
from cf_estimator.cli.bench_cmd.common import (
    add_peers_option,
    available_peers,
    check_outputs,
    csv_list,
    load_filter_params,
    write_json,
)
from cf_estimator.cli.common import add_jobs_option, add_params_options


def add_parser(sub: Any) -> None:
    """Add ``bench scenarios`` to the ``bench`` sub-parsers."""
    s = sub.add_parser(
        "scenarios", help="peak/RMS tilt error under the thesis disturbances (simulated)",
        description=(
            "Thesis disturbances in 3-D (impacts, vibration, 25 m/s in 5 s) with realistic gyro "
            "noise and bias: peak and RMS tilt error inside each disturbance window for our "
            "filter (shipped defaults; clip off; clip and aperiodic unit off) and the peers."
        ),
    )
    add_peers_option(s)
    add_params_options(s, "for our filter")
    s.add_argument("--scenarios", default="impacts,vibration,acceleration", metavar="LIST",
                   help="comma-separated thesis scenarios (default %(default)s)")
    s.add_argument("--seed", type=int, default=0,
                   help="simulation seed of the sensor noise and disturbances (default 0)")
    s.add_argument("--duration", type=float, metavar="S",
                   help="scenario duration [s] (default: each scenario's own)")
    s.add_argument("--velocity", action="store_true",
                   help="also ours aided by a simulated GNSS velocity (10 Hz, 0.1 m/s, 100 ms "
                   "late): heading offset estimated (cf_estimator_aided) and known from the "
                   "start (cf_estimator_aided_heading)")
    s.add_argument("--json", metavar="OUT", help="write the table's rows as JSON")
    s.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    add_jobs_option(s)
    s.set_defaults(run=run)


def run(args: Any) -> int:
    """``bench scenarios``."""
    from cf_estimator.bench import scenarios as sc
    peers = available_peers(args)
    check_outputs(args, "json")
    params = load_filter_params(args.params, args.node_name)
    names = csv_list(args.scenarios)
    try:
        rows = sc.run_scenarios(names, params, peers, seed=args.seed, duration_s=args.duration,
                                jobs=args.jobs, velocity=args.velocity)
    except ValueError as exc:
        raise CliError(str(exc), 2) from None
    print(sc.format_table(rows), end="")
    if args.json:
        from cf_estimator import __version__
        from cf_estimator.core.kernel import resolve_backend
        from cf_estimator.schema import as_dict

        write_json(args.json, {"scenarios": rows, "limit_arcmin": sc.THESIS_LIMIT_ARCMIN,
                                "cf_estimator_params": as_dict(params), "peers": peers,
                                "seed": args.seed, "version": __version__,
                                "filter_backend": resolve_backend()})
    return 0
