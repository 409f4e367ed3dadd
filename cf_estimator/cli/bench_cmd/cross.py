"""``bench cross``: the cross-dataset table of BENCHMARKS.md."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cf_estimator.cli.base import CliError
from cf_estimator.cli.bench_cmd.common import check_outputs, families_option, write_json
from cf_estimator.cli.common import add_jobs_option, load_params, note


def add_parser(sub: Any) -> None:
    """Add ``bench cross`` to the ``bench`` sub-parsers."""
    cr = sub.add_parser(
        "cross", help="one table over every data family (EuRoC ground and mid-air starts, "
        "phantom4 vertical and horizontal, BROAD groups, thesis scenarios, compass "
        "disturbances, simulated multirotor zig-zags and figure-8s), ours beside VQF online "
        "and offline",
        description=(
            "The cross-dataset table of BENCHMARKS.md: for each family below --data (euroc/, "
            "phantom4/, phantom4_horizontal/, broad/; missing ones are left out with a note) "
            "and the simulated thesis scenarios, compass cases (a magnet on a turning "
            "sensor) and multirotor cases (zig-zags, figure-8s), our filter online and offline "
            "beside VQF online and offline. Inclination [deg]; scenarios: peak tilt error "
            "[arcmin]; compass: heading error [deg]; multirotor: also our learned bias's error "
            "[deg/s]. A default changes only when no row gets worse."
        ),
    )
    cr.add_argument("--data", default="../shared/data", metavar="DIR",
                    help="directory holding euroc/, phantom4/, phantom4_horizontal/ and broad/ "
                    "(default %(default)s)")
    cr.add_argument("--families", default=",".join(_cross_families()), metavar="LIST",
                    help="comma-separated subset of %(default)s")
    cr.add_argument("--params", metavar="YAML", help="ROS 2 parameter file for our filter "
                    "(default: the shipped defaults); the consistency rows take its covariance "
                    "floors (orientation_covariance_rad2, yaw_covariance_rad2)")
    cr.add_argument("--json", metavar="OUT", help="write the rows as JSON")
    cr.add_argument("--overwrite", action="store_true", help="replace an existing --json file")
    add_jobs_option(cr)
    cr.set_defaults(run=run)


def _cross_families() -> tuple[str, ...]:
    from cf_estimator.bench.cross import FAMILIES

    return FAMILIES


def run(args: Any) -> int:
    """``bench cross``."""
    from cf_estimator.bench import cross

    check_outputs(args, "json")
    families = families_option(args, cross.FAMILIES)
    if not Path(args.data).is_dir() and not set(families) <= set(cross.SIMULATED):
        raise CliError(f"--data: {args.data} is not a directory", 2)
    from cf_estimator.bench.consistency import Floors

    params, pipeline_params = load_params(args.params)
    result = cross.run_cross(args.data, params, families, jobs=args.jobs,
                             progress=lambda f: note(f"bench cross: {f} ..."),
                             floors=Floors.of(pipeline_params))
    print(f"Cross-dataset table ({args.data}); cf_estimator parameters: "
          f"{args.params or 'shipped defaults'}")
    for line in result.notes:
        print(f"  note: {line}")
    print()
    print(cross.format_table(result), end="")
    if args.json:
        write_json(args.json, result.to_json())
    return 0
