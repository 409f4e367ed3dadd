"""``cf-estimator simulate``: write a simulated flight (IMU, magnetometer, ground truth) as a bag.

Scenarios come from :mod:`cf_estimator.scenarios` (``--list`` shows them); the bag layout is
documented in :mod:`cf_estimator.bag.simulate` and docs/replay.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from cf_estimator.bag import io
from cf_estimator.bag.simulate import IMU_TOPIC, MAG_TOPIC, TRUTH_TOPIC, write_scenario_bag
from cf_estimator.cli.base import CliError, finite_float
from cf_estimator.scenarios import DEFAULT_DURATION_S, DEFAULT_RATE_HZ, SCENARIOS, make_scenario


def register(subparsers: Any) -> None:
    """Add the ``simulate`` sub-command to ``subparsers``."""
    p = subparsers.add_parser(
        "simulate",
        help="write a simulated IMU recording with ground truth as a ROS 2 bag",
        description=(
            f"Simulate a scenario and write a ROS 2 bag with {IMU_TOPIC} (sensor_msgs/Imu), "
            f"{MAG_TOPIC} (sensor_msgs/MagneticField, Tesla) and {TRUTH_TOPIC} "
            "(geometry_msgs/QuaternionStamped, true orientation, ENU). Reproducible with --seed."
        ),
    )
    p.add_argument("--scenario", metavar="NAME", help=f"one of: {', '.join(SCENARIOS)}")
    p.add_argument("-o", "--output", metavar="OUT", help="output ROS 2 bag directory")
    p.add_argument("--rate", type=finite_float, metavar="HZ",
                   help="IMU rate (default: the scenario's)")
    p.add_argument("--duration", type=finite_float, metavar="S",
                   help="duration (default: the scenario's)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--mag-rate", type=finite_float, default=100.0, metavar="HZ",
                   help="magnetometer rate (default 100; 0 = IMU rate)")
    p.add_argument("--truth-rate", type=finite_float, default=100.0, metavar="HZ",
                   help="ground-truth rate (default 100; 0 = IMU rate)")
    p.add_argument("--velocity-rate", type=finite_float, default=0.0, metavar="HZ",
                   help="also write a simulated GNSS velocity (geometry_msgs/TwistStamped, ENU) "
                   "on /gnss/vel at this rate (default 0 = none)")
    p.add_argument("--velocity-noise", type=finite_float, default=0.1, metavar="M_S",
                   help="its white noise per axis [m/s] (default %(default)s)")
    p.add_argument("--velocity-latency", type=finite_float, default=0.1, metavar="S",
                   help="its delay from stamp to recording [s] (default %(default)s)")
    p.add_argument("--storage", choices=sorted(io.STORAGES), default="mcap",
                   help="storage plugin (default mcap)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output bag")
    p.add_argument("--list", action="store_true", help="list the scenarios and exit")
    p.set_defaults(run=run)


def check_scenario(name: str | None) -> str:
    """The scenario name, or CliError(2) naming the valid ones."""
    if name is None:
        raise CliError(f"--scenario is required; one of: {', '.join(SCENARIOS)}", 2)
    if name not in SCENARIOS:
        raise CliError(f"unknown scenario {name!r}; valid: {', '.join(SCENARIOS)}", 2)
    return name


def run(args: argparse.Namespace) -> int:
    if args.list:
        for name, factory in SCENARIOS.items():
            doc = (factory.__doc__ or "").strip().splitlines()[0]
            print(f"{name:13s} {DEFAULT_RATE_HZ[name]:6.0f} Hz {DEFAULT_DURATION_S[name]:5.0f} s  "
                  f"{doc}")
        return 0
    name = check_scenario(args.scenario)
    if args.output is None:
        raise CliError("-o OUT is required", 2)
    for opt, value in (("--rate", args.rate), ("--duration", args.duration)):
        if value is not None and value <= 0:
            raise CliError(f"{opt} must be > 0 (got {value:g})", 2)
    for opt, value in (("--mag-rate", args.mag_rate), ("--truth-rate", args.truth_rate),
                       ("--velocity-rate", args.velocity_rate),
                       ("--velocity-noise", args.velocity_noise),
                       ("--velocity-latency", args.velocity_latency)):
        if value < 0:
            raise CliError(f"{opt} must be >= 0 (got {value:g})", 2)
    out = Path(args.output)
    try:
        io.check_output_path(out, overwrite=args.overwrite)
    except io.BagError as exc:
        raise CliError(str(exc), exc.code) from None
    try:
        scenario = make_scenario(name, rate_hz=args.rate, duration_s=args.duration, seed=args.seed)
    except ValueError as exc:
        raise CliError(str(exc), 2) from None
    velocity = None
    if args.velocity_rate > 0:
        import numpy as np

        from cf_estimator.scenarios.velocity_sensor import VelocityModel, measure_velocity

        model = VelocityModel(args.velocity_rate, args.velocity_noise, args.velocity_latency)
        velocity = measure_velocity(scenario.truth, model,
                                    np.random.default_rng([args.seed, 17]))
    progress = None
    bar = None
    if sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=scenario.imu.n_samples, unit="sample", unit_scale=True, file=sys.stderr,
                   leave=False, desc="simulate")
        progress = bar.update
    try:
        result = write_scenario_bag(
            scenario, out, storage=args.storage, overwrite=args.overwrite,
            mag_rate_hz=args.mag_rate or None, truth_rate_hz=args.truth_rate or None,
            progress=progress, velocity=velocity,
        )
    except io.BagError as exc:
        raise CliError(str(exc), exc.code) from None
    finally:
        if bar is not None:
            bar.close()
    print(f"scenario {scenario.name} (seed {scenario.seed}): {scenario.duration_s:g} s at "
          f"{scenario.rate_hz:g} Hz")
    print(f"  {scenario.description}")
    for start, end, label in scenario.disturbance_windows:
        print(f"  disturbance {label}: {start:g}-{end:.2f} s")
    counts = ", ".join(f"{t} {n}" for t, n in result.counts.items())
    print(f"wrote {result.path} ({result.storage}): {counts}")
    return 0
