"""``bench report``: measure everything BENCHMARKS.md shows, write the results JSON and render
BENCHMARKS.md from it (``--render-only``: render the committed JSON again, no measuring)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from cf_estimator.cli.base import CliError
from cf_estimator.cli.bench_cmd.common import add_peers_option, available_peers
from cf_estimator.cli.common import add_jobs_option, load_params, note


def add_parser(sub: Any) -> None:
    """Add ``bench report`` to the ``bench`` sub-parsers."""
    from cf_estimator.bench.report import REPORT_PATH, RESULTS_PATH

    rp = sub.add_parser(
        "report", help="measure every family against every peer, write the results JSON and "
        "render BENCHMARKS.md from it (run from the repository root)",
        description=(
            "The benchmark report: the cross-dataset table (bench cross) with every peer beside "
            "ours — VQF online and offline, x-io Fusion as its README recommends, Madgwick at "
            "imu_filter_madgwick's gain, imu_complementary_filter at its ROS defaults, the "
            "Xsens DOTs' own filter on phantom4 —, a gyro fault on phantom4, and the agreement "
            "with the autopilot's attitude on the PX4 and ArduPilot logs. Writes --results "
            "(JSON, no wall-clock figure) and --report (rendered from it), replacing both. "
            "--render-only renders --results again without measuring."
        ),
    )
    rp.add_argument("--data", default="../shared/data", metavar="DIR",
                    help="directory holding euroc/, phantom4/, phantom4_horizontal/, broad/, "
                    "ulogs/, ardupilot/ (default %(default)s)")
    rp.add_argument("--results", default=str(RESULTS_PATH), metavar="JSON",
                    help="the results file written (read with --render-only) "
                    "(default %(default)s)")
    rp.add_argument("--report", default=str(REPORT_PATH), metavar="MD",
                    help="the report rendered from the results (default %(default)s)")
    rp.add_argument("--render-only", action="store_true",
                    help="render --results into --report without measuring")
    rp.add_argument("--params", metavar="YAML", help="ROS 2 parameter file for our filter "
                    "(default: the shipped defaults)")
    add_peers_option(rp)
    add_jobs_option(rp)
    rp.set_defaults(run=run)


def _parent_ok(path: Path, option: str) -> None:
    if not path.parent.is_dir():
        raise CliError(f"{option}: {path.parent} is not a directory (run from the repository "
                       f"root, or give {option})", 2)
    if path.is_dir():
        raise CliError(f"{option}: {path} is a directory", 2)


def run(args: Any) -> int:
    """``bench report``."""
    from cf_estimator.bench import report

    results_path, report_path = Path(args.results), Path(args.report)
    _parent_ok(report_path, "--report")
    if args.render_only:
        try:
            results = json.loads(results_path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise CliError(f"--results: {results_path} not found (run bench report without "
                           "--render-only to measure)", 2) from None
        except (OSError, ValueError) as exc:
            raise CliError(f"--results: cannot read {results_path}: {exc}", 2) from None
        report.write_report(results, report_path)
        print(f"rendered {report_path} from {results_path}")
        return 0
    _parent_ok(results_path, "--results")
    if not Path(args.data).is_dir():
        raise CliError(f"--data: {args.data} is not a directory", 2)
    if args.jobs < 1:
        raise CliError("--jobs must be >= 1", 2)
    wanted = available_peers(args)
    # the recorded onboard filter comes with --peers all (the report's default)
    peers = [p for p in report.REPORT_PEERS
             if p in wanted or (p == "onboard" and args.peers.strip() == "all")]
    params, _pipeline = load_params(args.params)
    results = report.measure(args.data, params, jobs=args.jobs, peers=peers,
                             params_label=args.params or "shipped defaults",
                             progress=lambda text: note(f"bench report: {text} ..."))
    report.write(results, results_path, report_path)
    print(f"wrote {results_path} and {report_path}", file=sys.stdout)
    return 0
