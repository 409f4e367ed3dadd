"""``bench sustained``: what an IMU-only filter cannot know in a multirotor's sustained
acceleration.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cf_estimator.cli.base import CliError
from cf_estimator.cli.bench_cmd.common import (
    check_outputs,
    csv_list,
    load_filter_params,
)
from cf_estimator.cli.common import note


def add_parser(sub: Any) -> None:
    """Add ``bench sustained`` to the ``bench`` sub-parsers."""
    su = sub.add_parser(
        "sustained", help="what an IMU-only filter cannot know in a multirotor's sustained "
        "acceleration, from each recording's reference velocity, beside ours, ours aided, VQF",
        description=(
            "For each family below --data with a reference velocity (phantom4_horizontal, "
            "phantom4, euroc): the tilt a perfect-gyro filter averaging the accelerometer over "
            "a memory T cannot avoid, atan(|v_h(t) - v_h(t-T)|/(g T)), and the gyro drift over "
            "T with a 0.5 deg/s bias residual, beside the measured inclination error of ours "
            "online, ours velocity-aided and VQF online (RMS after 10 s, mean over recordings; "
            "cf_estimator.bench.sustained), and the rotor drag the accelerometer reads across "
            "the thrust axis (K of f = -K*v, and how well it shows the velocity). --plot draws "
            "it (docs/img/sustained_acceleration.png)."
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
    su.set_defaults(run=run)


def run(args: Any) -> int:
    """``bench sustained``."""
    from cf_estimator.bench import euroc, sustained
    from cf_estimator.bench.euroc_eval import ALGORITHMS, installed

    check_outputs(args, "plot")
    families = csv_list(args.families)
    if not families:
        raise CliError("--families is empty", 2)
    params = load_filter_params(args.params)
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
