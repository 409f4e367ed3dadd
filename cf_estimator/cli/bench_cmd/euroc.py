"""``bench euroc``: real multirotor flights (EuRoC layout: EuRoC, the Phantom 4 campaigns), ground
and mid-air starts, velocity-aided columns.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from typing import Any

from cf_estimator.cli.base import CliError, finite_float
from cf_estimator.cli.bench_cmd.common import (
    csv_list,
    load_filter_params,
    write_json,
)
from cf_estimator.cli.common import add_jobs_option


def add_parser(sub: Any) -> None:
    """Add ``bench euroc`` to the ``bench`` sub-parsers."""
    from cf_estimator.cluster import add_cluster_option

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
                   "'all' (default: those installed), 'none', and onboard (the recording's own "
                   "onboard filter, xsens_dot_orientation.csv beside mav0: only when named)")
    e.add_argument("--params", metavar="YAML", help="ROS 2 parameter file for our filter "
                   "(default: the shipped defaults, FilterParams())")
    e.add_argument("--start-at", metavar="LIST",
                   help="comma-separated seconds, e.g. 20,40,60: also crop every flight to start "
                   "there (a mid-air start: node restarted in flight) and score 2-12 s and "
                   "12 s-end after that start, beside the full (ground) start")
    e.add_argument("--gyro-fault", type=finite_float, metavar="AT_S",
                   help="a gyro fault AT_S seconds into every flight: 3 rad/s added to the "
                   "sensor x axis for 0.2 s, a 34 deg attitude error in one step (a gyro "
                   "over-range, a glitch), for every algorithm alike; flights that end before "
                   "it is over are left out. Score after it with --settle")
    e.add_argument("--json", metavar="OUT", help="write per-flight scores and means as JSON")
    add_jobs_option(e, ", one flight each")
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
    e.set_defaults(run=run)


def run(args: Any) -> int:
    """``bench euroc``."""
    from cf_estimator.bench import euroc
    from cf_estimator.bench import euroc_eval as ev
    from cf_estimator.schema import as_dict

    text = args.peers.strip()
    names = [] if text in ("", "none") else ev.peer_names() if text == "all" else csv_list(text)
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
    for token in csv_list(args.start_at or ""):
        try:
            value = float(token)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise CliError(f"--start-at takes seconds > 0, got {token!r}", 2)
        starts.append(value)
    params = load_filter_params(args.params)
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
    fault_note = None
    if args.gyro_fault is not None:
        flights, fault_note = _with_gyro_fault(flights, args.gyro_fault)
    if velocity is not None:
        missing = [f.name for f in flights if f.velocity_t_s is None]
        if missing:
            raise CliError(f"--velocity: no ground-truth velocity for {missing[0]}", 2)
    from cf_estimator.cluster import ClusterError, make_engine

    try:  # on a cluster the flights (read here from their CSV files) travel once each
        with make_engine(args.cluster, args.jobs) as engine:
            result = ev.run_euroc(flights, params, peers, args.settle, jobs=engine,
                                  velocity=velocity)
    except (ClusterError, euroc.EurocDataError) as exc:  # a recording's onboard file, say
        raise CliError(str(exc), 2) from None
    print(f"EuRoC: {len(result.flights)} flight(s) from {args.data}; 6-D inclination error "
          f"[deg] vs ground truth after the first {args.settle:g} s: RMS / max")
    print(f"cf_estimator parameters: {args.params or 'shipped defaults'}")
    if fault_note is not None:
        print(fault_note)
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
        print(f"time from the first velocity sample until the inclination error (its "
              f"{ev.HOLD_TRANSIENT_S:g} s running median) stays below {ev.HOLD_THRESHOLD_DEG:g} "
              f"deg [s] (median over the flights that get there):")
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
            "gyro_fault_at_s": args.gyro_fault,
            "metrics": "inclination error: angle between estimated and true up in the sensor "
                       "frame [deg]; RMS and max over samples with ground truth, t >= settle_s",
        }
        write_json(args.json, doc)
    return 0


def _with_gyro_fault(flights: list, at_s: float) -> tuple[list, str]:
    """``--gyro-fault``: the flights long enough, each with the fault
    (:func:`cf_estimator.bench.euroc_eval.with_gyro_fault`), and the line that says so."""
    from cf_estimator.bench import euroc_eval as ev

    if not at_s >= 0.0:
        raise CliError(f"--gyro-fault must be >= 0 s (got {at_s:g})", 2)
    long_enough = [f for f in flights if ev.gyro_fault_fits(f, at_s)]
    if not long_enough:
        raise CliError(f"--gyro-fault {at_s:g}: every flight ends before the fault is over", 2)
    note = (f"gyro fault: {ev.GYRO_FAULT_RATE_RAD_S:g} rad/s added to the sensor x axis for "
            f"{ev.GYRO_FAULT_DURATION_S:g} s at {at_s:g} s (every algorithm)")
    if len(long_enough) < len(flights):
        note += f"; {len(flights) - len(long_enough)} shorter flight(s) left out"
    return [ev.with_gyro_fault(f, at_s) for f in long_enough], note


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
