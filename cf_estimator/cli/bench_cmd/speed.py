"""``bench speed``: per-sample update rate, pipeline time, batched rate, bag replay throughput."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

from cf_estimator.cli.base import CliError
from cf_estimator.cli.bench_cmd.common import (
    add_peers_option,
    available_peers,
    check_outputs,
    csv_list,
    write_json,
)
from cf_estimator.cli.common import check_input_path

if TYPE_CHECKING:
    from cf_estimator.bench.speed import BagThroughput


def add_parser(sub: Any) -> None:
    """Add ``bench speed`` to the ``bench`` sub-parsers."""
    sp = sub.add_parser(
        "speed", help="per-sample update rate (ours vs peers), pipeline time, batched rate, "
        "bag replay throughput",
        description=(
            "In one run: samples/s of one 9-D update called from Python for our filter and each "
            "peer (the best of interleaved runs, the same for all); ImuPipeline.on_imu median "
            "and p99 per message; the batched filter's parameter-samples per second; "
            "messages/s of `cf-estimator replay` (read, deserialize, pipeline, serialize, "
            "write an mcap bag) against a plain rosbags "
            "AnyReader read of the same topics, raw and deserialized, on --bag (default: a "
            "simulated 30 s flight in a temporary directory). Shared machines are noisy: "
            "compare ratios."
        ),
    )
    add_peers_option(sp)
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
    sp.set_defaults(run=run)


def run(args: Any) -> int:
    """``bench speed``."""
    from cf_estimator.bench import speed
    peers = available_peers(args)
    check_outputs(args, "json")
    if args.bag is not None:
        check_input_path(args.bag, "bag")
    if args.samples < 100:
        raise CliError("--samples must be >= 100", 2)
    try:
        sizes = [int(x) for x in csv_list(args.batch_sizes)]
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

        write_json(args.json, {"filter_backend": resolve_backend(),
                                "per_sample_hz": rates, "pipeline": pipe,
                                "batched_param_samples_per_s": batched_json,
                                "bag_throughput": dataclasses.asdict(bag)})
    return 0


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
