"""``bench broad``: BROAD trials, ours beside the peers (per-group RMSE tables, 9-D and 6-D)."""

from __future__ import annotations

import sys
import time
from pathlib import Path
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
from cf_estimator.cli.common import (
    add_jobs_option,
    add_params_options,
    check_input_path,
)


def add_parser(sub: Any) -> None:
    """Add ``bench broad`` to the ``bench`` sub-parsers."""
    b = sub.add_parser(
        "broad", help="RMSE on BROAD trial files (HDF5 layout of the BROAD benchmark)",
        description=(
            "Runs the filter (and --peers) on every BROAD trial file in --data and prints, per "
            "group (all, undisturbed, disturbed and the groups of DIR/trials.json), the mean "
            "over trials of the total/heading/inclination RMSE [deg] over the movement samples "
            "(BROAD's metrics), 9-D (with magnetometer) and 6-D (inclination only). Only files "
            "directly inside --data are read."
        ),
    )
    b.add_argument("--data", required=True, metavar="PATH",
                   help="directory of BROAD *.hdf5 files, or one trial file")
    add_peers_option(b)
    add_params_options(b, "for our filter")
    b.add_argument("--trials", metavar="LIST", help="comma-separated trial names, prefixes "
                   "(e.g. 07) or patterns (e.g. '*magnet*'); default: all files")
    b.add_argument("--velocity", action="store_true",
                   help="also ours velocity-aided (cf_estimator_aided), by a 10 Hz velocity "
                   "made of the trial's optical positions (opt_pos)")
    b.add_argument("--json", metavar="OUT", help="write per-trial and per-group results as JSON")
    b.add_argument("--plot", metavar="PNG", help="bar chart per trial: 9-D total and 6-D "
                   "inclination RMSE of every algorithm")
    b.add_argument("--overwrite", action="store_true",
                   help="replace existing --json/--plot files")
    add_jobs_option(b, ", one trial each")
    b.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    from cf_estimator.cluster import add_cluster_option

    add_cluster_option(b)
    b.set_defaults(run=run)


def run(args: Any) -> int:
    """``bench broad``."""
    from cf_estimator.bench import broad
    from cf_estimator.bench.evaluate import run_broad as evaluate_all
    from cf_estimator.schema import as_dict

    if args.jobs < 1:
        raise CliError("--jobs must be >= 1", 2)
    peers = available_peers(args)
    check_input_path(args.data, "BROAD data")
    check_outputs(args, "json", "plot")
    params = load_filter_params(args.params, args.node_name)
    try:
        trials = csv_list(args.trials) if args.trials else None
        paths, info = broad.resolve_trials(args.data, trials)
    except broad.BroadDataError as exc:
        raise CliError(str(exc), 2) from None
    start = time.monotonic()

    def progress(name: str, i: int, n: int) -> None:
        if not args.quiet:
            print(f"[{i}/{n}] {name} ({time.monotonic() - start:.0f} s)", file=sys.stderr)

    from cf_estimator.cluster import ClusterError, make_engine

    try:
        with make_engine(args.cluster, args.jobs) as engine:
            engine.check_paths([str(Path(p).absolute()) for p in paths])
            result = evaluate_all([Path(p).absolute() for p in paths] if args.cluster else paths,
                                  info, params, peers, jobs=engine, progress=progress,
                                  velocity=args.velocity)
    except broad.BroadDataError as exc:
        raise CliError(str(exc)) from None
    except ClusterError as exc:
        raise CliError(str(exc), 2) from None
    algos = ", ".join(["cf_estimator", "cf_estimator_offline"]
                      + (["cf_estimator_aided"] if args.velocity else [])
                      + [q for p in peers for q in ((p, "vqf_offline") if p == "vqf" else (p,))])
    print(f"BROAD: {len(paths)} trial(s) from {args.data}; RMSE [deg] over movement samples, "
          f"mean over trials; {algos}")
    print(f"cf_estimator parameters: {args.params or 'shipped defaults'}")
    print()
    print(broad.format_tables(result), end="")
    if args.plot:
        from cf_estimator.bench.plots import plot_broad_per_trial

        try:
            plot_broad_per_trial(result.to_json(), args.plot)
        except OSError as exc:
            raise CliError(f"cannot write {args.plot}: {exc.strerror or exc}", 2) from None
    if args.json:
        doc = result.to_json()
        doc["meta"] = {
            "data": str(args.data), "peers": peers, "params_file": args.params,
            "velocity": "optical positions, 10 Hz" if args.velocity else None,
            "cf_estimator_params": as_dict(params),
            "metrics": "BROAD: q_err = q_est * inv(q_ref); RMSE over movement samples [deg]",
        }
        write_json(args.json, doc)
    return 0
