"""``cf-estimator bench broad|euroc|scenarios|speed|cross|sustained|fleet``: accuracy and speed
versus the peers.

``bench broad --data DIR`` scores our filter (and ``--peers``) on BROAD trial files: per-group
tables of total/heading/inclination RMSE [deg] over the movement samples, 9-D and 6-D, and
``--json OUT`` with every trial. Metrics and frames: :mod:`cf_estimator.bench.broad`; peers:
:mod:`cf_estimator.bench.peers` (``pip install '.[bench]'``).
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cf_estimator.cli.base import CliError, finite_float
from cf_estimator.cli.common import (
    add_params_options,
    check_input_path,
    check_output_file,
    load_params,
    note,
)

if TYPE_CHECKING:
    from cf_estimator.bench.speed import BagThroughput


def _csv(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def register(subparsers: Any) -> None:
    """Add ``bench`` and its sub-commands."""
    p = subparsers.add_parser(
        "bench", help="accuracy and speed benchmarks vs peers (bench broad, euroc, scenarios, "
        "speed, cross, sustained, fleet)",
        description="Benchmarks of the filter against VQF, x-io Fusion and Madgwick.",
    )
    sub = p.add_subparsers(dest="bench_command", required=True, metavar="BENCHMARK")

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
    _add_peers_option(b)
    add_params_options(b, "for our filter")
    b.add_argument("--trials", metavar="LIST", help="comma-separated trial names, prefixes "
                   "(e.g. 07) or patterns (e.g. '*magnet*'); default: all files")
    b.add_argument("--json", metavar="OUT", help="write per-trial and per-group results as JSON")
    b.add_argument("--plot", metavar="PNG", help="bar chart per trial: 9-D total and 6-D "
                   "inclination RMSE of every algorithm")
    b.add_argument("--overwrite", action="store_true",
                   help="replace existing --json/--plot files")
    b.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), metavar="N",
                   help="worker processes, one trial each (default %(default)s)")
    b.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    from cf_estimator.cluster import add_cluster_option

    add_cluster_option(b)
    b.set_defaults(run=run_broad)

    e = sub.add_parser(
        "euroc", help="inclination error on real multirotor flights (EuRoC MAV, ASL folders)",
        description=(
            "Runs our filter (6-D: EuRoC has no magnetometer) and the --peers on every EuRoC "
            "flight in --data (a flight folder holding mav0/imu0/data.csv, or any directory of "
            "them, searched recursively) and prints per flight and as the mean over flights the "
            "inclination error [deg] against the ground truth (mav0/state_groundtruth_estimate0/"
            "data.csv or groundtruth_tum.txt, slerped onto the IMU stamps): RMS / max over the "
            "samples after the first --settle seconds. Peers whose package is not installed are "
            "skipped with a note."
        ),
    )
    e.add_argument("--data", required=True, metavar="DIR",
                   help="EuRoC flight folder, or a directory of them")
    e.add_argument("--groundtruth", metavar="FILE", help="ground-truth file (ASL csv or TUM "
                   "trajectory, detected) for a single flight folder given as --data")
    e.add_argument("--settle", type=finite_float, default=10.0, metavar="S",
                   help="seconds after the first IMU sample before scoring (default %(default)s)")
    e.add_argument("--peers", default="all", metavar="LIST",
                   help="comma-separated: vqf,vqf_offline,madgwick,fusion,complementary,riann, "
                   "'all' "
                   "(default: those installed) or 'none'")
    e.add_argument("--params", metavar="YAML", help="ROS 2 parameter file for our filter "
                   "(default: the shipped defaults, FilterParams())")
    e.add_argument("--start-at", metavar="LIST",
                   help="comma-separated seconds, e.g. 20,40,60: also crop every flight to start "
                   "there (a mid-air start: node restarted in flight) and score 2-12 s and "
                   "12 s-end after that start, beside the full (ground) start")
    e.add_argument("--json", metavar="OUT", help="write per-flight scores and means as JSON")
    e.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), metavar="N",
                   help="worker processes, one flight each (default %(default)s)")
    e.add_argument("--velocity", action="store_true",
                   help="also run our filter aided by the ground truth's velocity (ASL v_RS_R "
                   "columns, else differentiated positions), degraded by the flags below: "
                   "columns cf_estimator_aided and cf_estimator_aided_offline")
    e.add_argument("--velocity-rate", type=finite_float, metavar="HZ",
                   help="resample the velocity to this rate (default: as given)")
    e.add_argument("--velocity-noise", type=finite_float, default=0.0, metavar="M_S",
                   help="white noise added per axis [m/s] (seeded per flight; default 0)")
    e.add_argument("--velocity-latency", type=finite_float, default=0.0, metavar="S",
                   help="each velocity sample reaches the filter this long after its stamp "
                   "(default 0)")
    add_cluster_option(e)
    e.set_defaults(run=run_euroc)

    s = sub.add_parser(
        "scenarios", help="peak/RMS tilt error under the thesis disturbances (simulated)",
        description=(
            "Thesis disturbances in 3-D (impacts, vibration, 25 m/s in 5 s) with realistic gyro "
            "noise and bias: peak and RMS tilt error inside each disturbance window for our "
            "filter (shipped defaults; clip off; clip and aperiodic unit off) and the peers."
        ),
    )
    _add_peers_option(s)
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
    s.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), metavar="N",
                   help="worker processes (default %(default)s)")
    s.set_defaults(run=run_scenarios)

    sp = sub.add_parser(
        "speed", help="per-sample update rate (ours vs peers), pipeline time, batched rate, "
        "bag replay throughput",
        description=(
            "In one run: samples/s of one 9-D update called from Python for our filter and each "
            "peer; ImuPipeline.on_imu median and p99 per message; the batched filter's "
            "parameter-samples per second; messages/s of `cf-estimator replay` (read, "
            "deserialize, pipeline, serialize, write an mcap bag) against a plain rosbags "
            "AnyReader read of the same topics, raw and deserialized, on --bag (default: a "
            "simulated 30 s flight in a temporary directory). Shared machines are noisy: "
            "compare ratios."
        ),
    )
    _add_peers_option(sp)
    sp.add_argument("--samples", type=int, default=20000, metavar="N",
                    help="samples per timed run (default %(default)s, >= 100)")
    sp.add_argument("--batch-sizes", default="64,256", metavar="LIST",
                    help="parameter sets per batched run, comma-separated (default %(default)s)")
    sp.add_argument("--bag", metavar="PATH", help="bag for the replay throughput (ROS 1 .bag or "
                    "ROS 2 directory; default: simulated, removed afterwards)")
    sp.add_argument("--bag-repeats", type=int, default=3, metavar="N",
                    help="replay and read passes over the bag, best kept (default %(default)s)")
    sp.add_argument("--imu-topic", metavar="TOPIC", help="IMU topic of --bag (default: detect)")
    sp.add_argument("--mag-topic", metavar="TOPIC",
                    help="magnetometer topic of --bag, or 'none' (default: detect)")
    sp.add_argument("--json", metavar="OUT", help="write every figure as JSON")
    sp.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    sp.set_defaults(run=run_speed)

    cr = sub.add_parser(
        "cross", help="one table over every data family (EuRoC ground and mid-air starts, "
        "phantom4 vertical and horizontal, BROAD groups, thesis scenarios, compass "
        "disturbances), ours beside VQF online and offline",
        description=(
            "The cross-dataset table of BENCHMARKS.md: for each family below --data (euroc/, "
            "phantom4/, phantom4_horizontal/, broad/; missing ones are left out with a note) "
            "and the simulated thesis scenarios and compass cases (a magnet on a turning "
            "sensor), our filter online and offline beside VQF online and offline. Inclination "
            "[deg]; scenarios: peak tilt error [arcmin]; compass: heading error [deg]. A "
            "default changes only when no row gets worse."
        ),
    )
    cr.add_argument("--data", default="../shared/data", metavar="DIR",
                    help="directory holding euroc/, phantom4/, phantom4_horizontal/ and broad/ "
                    "(default %(default)s)")
    cr.add_argument("--families", default=",".join(_cross_families()), metavar="LIST",
                    help="comma-separated subset of %(default)s")
    cr.add_argument("--params", metavar="YAML", help="ROS 2 parameter file for our filter "
                    "(default: the shipped defaults)")
    cr.add_argument("--json", metavar="OUT", help="write the rows as JSON")
    cr.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    cr.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), metavar="N",
                    help="worker processes (default %(default)s)")
    cr.set_defaults(run=run_cross)

    su = sub.add_parser(
        "sustained", help="what an IMU-only filter cannot know in a multirotor's sustained "
        "acceleration, from each recording's reference velocity, beside ours, ours aided, VQF",
        description=(
            "For each family below --data with a reference velocity (phantom4_horizontal, "
            "phantom4, euroc): the tilt a perfect-gyro filter averaging the accelerometer over "
            "a memory T cannot avoid, atan(|v_h(t) - v_h(t-T)|/(g T)), and the gyro drift over "
            "T with a 0.5 deg/s bias residual, beside the measured inclination error of ours "
            "online, ours velocity-aided and VQF online (RMS after 10 s, mean over recordings; "
            "cf_estimator.bench.sustained). --plot draws it (docs/img/sustained_acceleration.png)."
        ),
    )
    su.add_argument("--data", default="../shared/data", metavar="DIR",
                    help="directory holding the families (default %(default)s)")
    su.add_argument("--families", default="phantom4_horizontal,phantom4,euroc", metavar="LIST",
                    help="comma-separated family folders below --data (default %(default)s)")
    su.add_argument("--params", metavar="YAML", help="ROS 2 parameter file for our filter "
                    "(default: the shipped defaults)")
    su.add_argument("--plot", metavar="PNG", help="write the figure")
    su.add_argument("--example", metavar="NAME", help="recording (name ending) drawn over "
                    "time in the figure (default: the first family's worst for ours online)")
    su.add_argument("--overwrite", action="store_true", help="replace an existing --plot file")
    su.set_defaults(run=run_sustained)

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
    fl.set_defaults(run=run_fleet)


def _add_peers_option(parser: Any) -> None:
    """``--peers``, the same in every bench command."""
    parser.add_argument("--peers", default="all", metavar="LIST",
                        help="peers at their defaults (ROS peers: their ROS packages' defaults): "
                        "comma-separated vqf,fusion,madgwick,complementary, "
                        "'all' or 'none' (default all; peers not installed are skipped with a "
                        "note: pip install '.[bench]')")


def _load_params(path: str | None, node_name: str | None = None):
    """FilterParams from a parameter file (as the node reads it); CliError(2) when bad."""
    return load_params(path, node_name)[0]


def _check_outputs(args: Any, *names: str) -> None:
    """--json/--plot files: checked before the work starts (exist → --overwrite)."""
    for name in names:
        check_output_file(getattr(args, name, None), overwrite=args.overwrite,
                          option=f"--{name}")


def _write_json(path: str, doc: dict) -> None:
    from cf_estimator.bag.io import write_atomic_text

    try:
        write_atomic_text(Path(path), json.dumps(doc, indent=2, allow_nan=False) + "\n")
    except OSError as exc:
        raise CliError(f"cannot write {path}: {exc.strerror or exc}", 2) from None


def _available_peers(args: Any) -> list[str]:
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


def run_broad(args: Any) -> int:
    """``bench broad``."""
    from cf_estimator.bench import broad
    from cf_estimator.bench.evaluate import run_broad as evaluate_all
    from cf_estimator.schema import as_dict

    if args.jobs < 1:
        raise CliError("--jobs must be >= 1", 2)
    peers = _available_peers(args)
    check_input_path(args.data, "BROAD data")
    _check_outputs(args, "json", "plot")
    params = _load_params(args.params, args.node_name)
    try:
        paths, info = broad.resolve_trials(args.data, _csv(args.trials) if args.trials else None)
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
                                  info, params, peers, jobs=engine, progress=progress)
    except broad.BroadDataError as exc:
        raise CliError(str(exc)) from None
    except ClusterError as exc:
        raise CliError(str(exc), 2) from None
    algos = ", ".join(["cf_estimator", "cf_estimator_offline"]
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
            "cf_estimator_params": as_dict(params),
            "metrics": "BROAD: q_err = q_est * inv(q_ref); RMSE over movement samples [deg]",
        }
        _write_json(args.json, doc)
    return 0


def run_euroc(args: Any) -> int:
    """``bench euroc``."""
    from cf_estimator.bench import euroc
    from cf_estimator.bench import euroc_eval as ev
    from cf_estimator.schema import as_dict

    text = args.peers.strip()
    names = [] if text in ("", "none") else ev.peer_names() if text == "all" else _csv(text)
    try:
        peers, skipped = ev.select_peers(names)
    except ValueError as exc:
        raise CliError(str(exc), 2) from None
    for p in skipped:
        pkg = ev.ALGORITHMS[p].package
        print(f"cf-estimator: note: peer {p!r} skipped: PyPI package {pkg!r} not installed "
              "(pip install '.[bench]')", file=sys.stderr)
    if args.jobs < 1:
        raise CliError("--jobs must be >= 1", 2)
    if args.settle < 0:
        raise CliError(f"--settle must be >= 0 (got {args.settle:g})", 2)
    starts: list[float] = []
    for token in _csv(args.start_at or ""):
        try:
            value = float(token)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise CliError(f"--start-at takes seconds > 0, got {token!r}", 2)
        starts.append(value)
    params = _load_params(args.params)
    velocity = _velocity_input(args)
    try:
        if args.groundtruth:
            folders = euroc.find_flights(args.data)
            if len(folders) != 1:
                raise euroc.EurocDataError(
                    f"--groundtruth needs a single flight folder as --data ({len(folders)} found)")
            flights = [euroc.load_flight(folders[0], args.groundtruth)]
        else:
            flights = euroc.load_flights(args.data)
    except euroc.EurocDataError as exc:
        raise CliError(str(exc), 2) from None
    if velocity is not None:
        missing = [f.name for f in flights if f.velocity_t_s is None]
        if missing:
            raise CliError(f"--velocity: no ground-truth velocity for {missing[0]}", 2)
    from cf_estimator.cluster import ClusterError, make_engine

    try:  # on a cluster the flights (read here from their CSV files) travel once each
        with make_engine(args.cluster, args.jobs) as engine:
            result = ev.run_euroc(flights, params, peers, args.settle, jobs=engine,
                                  velocity=velocity)
    except ClusterError as exc:
        raise CliError(str(exc), 2) from None
    print(f"EuRoC: {len(result.flights)} flight(s) from {args.data}; 6-D inclination error "
          f"[deg] vs ground truth after the first {args.settle:g} s: RMS / max")
    print(f"cf_estimator parameters: {args.params or 'shipped defaults'}")
    if velocity is not None:
        rate = f"{velocity.rate_hz:g} Hz" if velocity.rate_hz else "rate as given"
        print(f"velocity aiding: ground-truth velocity, {rate}, noise {velocity.noise_m_s:g} "
              f"m/s, latency {velocity.latency_s:g} s")
    for name, info in result.info.items():
        for line in info["notes"]:
            print(f"  note: {name}: {line}")
    print()
    print(ev.format_table(result), end="")
    if velocity is not None:
        print()
        print(f"time from the first velocity sample until the inclination error stays below "
              f"{ev.HOLD_THRESHOLD_DEG:g} deg [s] (median over the flights that get there):")
        for algo in result.algorithms():
            med, ok, n = ev.median_hold_s(result, algo)
            text = f"{med:.1f}" if math.isfinite(med) else "never"
            print(f"  {algo:<28} {text:>6}  ({ok} of {n} flights; per flight in --json)")
    midair = {}
    for start in starts:
        mid = ev.run_midair(flights, params, start, peers, jobs=args.jobs, velocity=velocity)
        midair[f"{start:g}"] = mid
        print()
        w0, w1 = ev.MIDAIR_WINDOWS
        print(f"Mid-air start {start:g} s into each flight: inclination RMS [deg] "
              f"{w0[0]:g}-{w0[1]:g} s / {w1[0]:g} s-end after that start "
              f"({len(mid.flights)} flight(s) long enough)")
        print(ev.format_table(mid, ev.MIDAIR_SCORES), end="")
    if args.json:
        doc = result.to_json()
        doc["midair"] = {k: v.to_json() for k, v in midair.items()}
        doc["meta"] = {
            "data": str(args.data), "peers": peers, "peers_skipped": skipped,
            "params_file": args.params, "cf_estimator_params": as_dict(params),
            "velocity": None if velocity is None else dataclasses.asdict(velocity),
            "metrics": "inclination error: angle between estimated and true up in the sensor "
                       "frame [deg]; RMS and max over samples with ground truth, t >= settle_s",
        }
        _write_json(args.json, doc)
    return 0


def _velocity_input(args: Any) -> Any:
    """``bench euroc``'s velocity flags as a VelocityInput (None without --velocity)."""
    from cf_estimator.bench.euroc_eval import VelocityInput

    given = (args.velocity_rate is not None or args.velocity_noise != 0.0
             or args.velocity_latency != 0.0)
    if not args.velocity:
        if given:
            raise CliError("--velocity-rate/--velocity-noise/--velocity-latency need --velocity",
                           2)
        return None
    if args.velocity_rate is not None and not args.velocity_rate > 0.0:
        raise CliError(f"--velocity-rate must be > 0 (got {args.velocity_rate:g})", 2)
    if args.velocity_noise < 0.0 or args.velocity_latency < 0.0:
        raise CliError("--velocity-noise and --velocity-latency must be >= 0", 2)
    return VelocityInput(args.velocity_rate, args.velocity_noise, args.velocity_latency)


def run_scenarios(args: Any) -> int:
    """``bench scenarios``."""
    from cf_estimator.bench import scenarios as sc
    peers = _available_peers(args)
    _check_outputs(args, "json")
    params = _load_params(args.params, args.node_name)
    names = _csv(args.scenarios)
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

        _write_json(args.json, {"scenarios": rows, "limit_arcmin": sc.THESIS_LIMIT_ARCMIN,
                                "cf_estimator_params": as_dict(params), "peers": peers,
                                "seed": args.seed, "version": __version__,
                                "filter_backend": resolve_backend()})
    return 0


def run_speed(args: Any) -> int:
    """``bench speed``."""
    from cf_estimator.bench import speed
    peers = _available_peers(args)
    _check_outputs(args, "json")
    if args.bag is not None:
        check_input_path(args.bag, "bag")
    if args.samples < 100:
        raise CliError("--samples must be >= 100", 2)
    try:
        sizes = [int(x) for x in _csv(args.batch_sizes)]
    except ValueError:
        raise CliError(f"--batch-sizes: not integers: {args.batch_sizes!r}", 2) from None
    if args.bag_repeats < 1:
        raise CliError("--bag-repeats must be >= 1", 2)
    bag = _bag_throughput(args)  # first: a bad --bag fails before the long measurements
    rates = speed.per_sample_rates(args.samples, tuple(peers))
    pipe = speed.pipeline_times_us(args.samples)
    batched = {p: speed.batched_rate(p, args.samples) for p in sizes}
    print(speed.format_speed(rates, pipe, batched), end="")
    print(speed.format_bag_throughput(bag), end="")
    if args.json:
        batched_json = {str(k): v for k, v in batched.items()}
        from cf_estimator.core.kernel import resolve_backend

        _write_json(args.json, {"filter_backend": resolve_backend(),
                                "per_sample_hz": rates, "pipeline": pipe,
                                "batched_param_samples_per_s": batched_json,
                                "bag_throughput": dataclasses.asdict(bag)})
    return 0


def _cross_families() -> tuple[str, ...]:
    from cf_estimator.bench.cross import FAMILIES

    return FAMILIES


def run_cross(args: Any) -> int:
    """``bench cross``."""
    from cf_estimator.bench import cross

    _check_outputs(args, "json")
    families = _csv(args.families)
    bad = [f for f in families if f not in cross.FAMILIES]
    if bad or not families:
        raise CliError(f"--families: unknown {bad[0]!r}; valid: {', '.join(cross.FAMILIES)}"
                       if bad else "--families is empty", 2)
    if args.jobs < 1:
        raise CliError("--jobs must be >= 1", 2)
    if not Path(args.data).is_dir() and not set(families) <= set(cross.SIMULATED):
        raise CliError(f"--data: {args.data} is not a directory", 2)
    params = _load_params(args.params)
    result = cross.run_cross(args.data, params, families, jobs=args.jobs,
                             progress=lambda f: note(f"bench cross: {f} ..."))
    print(f"Cross-dataset table ({args.data}); cf_estimator parameters: "
          f"{args.params or 'shipped defaults'}")
    for line in result.notes:
        print(f"  note: {line}")
    print()
    print(cross.format_table(result), end="")
    if args.json:
        _write_json(args.json, result.to_json())
    return 0


def run_sustained(args: Any) -> int:
    """``bench sustained``."""
    from cf_estimator.bench import euroc, sustained
    from cf_estimator.bench.euroc_eval import ALGORITHMS, installed

    _check_outputs(args, "plot")
    families = _csv(args.families)
    if not families:
        raise CliError("--families is empty", 2)
    params = _load_params(args.params)
    with_vqf = installed(ALGORITHMS["vqf"])
    if not with_vqf:
        note("bench sustained: VQF not installed (pip install '.[bench]'): its row is left out")
    rows, loaded = [], {}
    for fam in families:
        folder = Path(args.data) / fam
        if not folder.is_dir():
            raise CliError(f"--data: {folder} is not a directory", 2)
        note(f"bench sustained: {fam} ...")
        try:
            loaded[fam] = euroc.load_flights(folder)
            rows.append(sustained.analyse(fam, loaded[fam], params, with_vqf))
        except ValueError as exc:
            raise CliError(str(exc), 1) from None
    print(f"Sustained acceleration ({args.data}); cf_estimator parameters: "
          f"{args.params or 'shipped defaults'}")
    print(sustained.format_table(rows), end="")
    if args.plot:
        flights = loaded[families[0]]
        runs = sustained.estimators(params, with_vqf)
        if args.example:
            match = [f for f in flights if f.name.endswith(args.example)]
            if not match:
                raise CliError(f"--example: no recording named {args.example!r} in "
                               f"{families[0]}", 2)
            example = match[0]
        else:
            example = max(flights, key=lambda f: sustained.score(f, runs["cf_estimator"](f)))
        sustained.plot(rows, example, {k: run(example) for k, run in runs.items()}, args.plot)
        note(f"bench sustained: figure written to {args.plot} ({example.name})")
    return 0


def run_fleet(args: Any) -> int:
    """``bench fleet``: exit 1 when a cluster result differs from the local one."""
    from cf_estimator.bench import fleet
    from cf_estimator.cluster import ClusterError

    _check_outputs(args, "json")
    if args.data is not None:
        check_input_path(args.data, "bag directory", want_dir=True)
    try:
        workers = tuple(int(x) for x in _csv(args.workers))
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
        _write_json(args.json, fleet.to_json(result))
    return 0 if all(r.identical is not False for r in result.runs) else 1


def _bag_throughput(args: Any) -> BagThroughput:
    """``speed.bag_throughput`` for ``--bag`` (None: simulated); bag errors as CliError."""
    from cf_estimator.bag.io import BagError
    from cf_estimator.bag.replay import ReplayError
    from cf_estimator.bench import speed

    try:
        return speed.bag_throughput(args.bag, args.bag_repeats, args.imu_topic, args.mag_topic)
    except BagError as exc:
        raise CliError(str(exc), exc.code) from None
    except ReplayError as exc:
        raise CliError(str(exc), 2) from None
