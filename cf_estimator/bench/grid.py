"""Grid check of parameter changes on BROAD, with a split of the trials into two halves.

The shipped defaults were checked with it: a change is kept only if it helps on both halves
(tuned on one half, it must also help on the other — it generalises), not only on all 18.

    python -m cf_estimator.bench.grid --data ../shared/data/broad \\
        --set rest_window_s=0.5,1 --set rest_gyro_threshold_rad_s=0.005,0.01,0.02

Prints, per grid point (all combinations of the ``--set`` values applied to ``--params`` or the
defaults), the mean inclination and 9-D total RMSE [deg] over all trials and over each half
(``--split``: the trials of half A; the rest are half B), sorted by ``--sort``.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import os
import sys
from collections.abc import Mapping, Sequence

import numpy as np

from cf_estimator.bench import broad, tuning
from cf_estimator.core.params import FilterParams
from cf_estimator.schema import ParameterError

#: Half A of the shipped 18 BROAD trials (every other trial by number); B = the others.
DEFAULT_SPLIT = ("02", "05", "09", "11", "15", "21", "27", "30", "34")


def grid_points(base: FilterParams, values: Mapping[str, Sequence[float]]) -> list[FilterParams]:
    """Every combination of ``values`` applied to ``base`` (invalid combinations dropped)."""
    names = list(values)
    points = []
    for combo in itertools.product(*values.values()):
        p = tuning.make_params(base, dict(zip(names, combo, strict=True)))
        if p is not None:
            points.append(p)
    return points


def half_means(scores: Mapping[str, tuple[np.ndarray, np.ndarray]], split: Sequence[str]
               ) -> dict[str, dict[str, np.ndarray]]:
    """{'all'|'A'|'B': {'total': (P,), 'inclination': (P,)}} mean RMSE [deg] per candidate.

    A trial is in half A when its name starts with one of ``split``.
    """
    groups = {"all": list(scores), "A": [n for n in scores if n.startswith(tuple(split))]}
    groups["B"] = [n for n in scores if n not in groups["A"]]
    out = {}
    for g, names in groups.items():
        if names:
            out[g] = {"total": np.mean([scores[n][0] for n in names], axis=0),
                      "inclination": np.mean([scores[n][1] for n in names], axis=0)}
    return out


def format_grid(points: Sequence[FilterParams], names: Sequence[str],
                means: Mapping[str, Mapping[str, np.ndarray]], sort: str) -> str:
    """One line per grid point, best ``sort`` (inclination|total over all trials) first."""
    order = np.argsort(means["all"][sort])
    halves = [g for g in ("all", "A", "B") if g in means]
    head = "  ".join(f"{k:>5} {g:<3}" for k in ("incl.", "total") for g in halves)
    lines = [f"{head}  parameters"]
    for i in order:
        vals = "  ".join(f"{means[g][k][i]:9.4f}" for k in ("inclination", "total")
                         for g in halves)
        lines.append(f"{vals}  " + " ".join(f"{n}={getattr(points[i], n):g}" for n in names))
    return "\n".join(lines) + "\n"


def _parse_set(text: str) -> tuple[str, list[float]]:
    name, _, vals = text.partition("=")
    if name not in {f.name for f in dataclasses.fields(FilterParams)} or not vals:
        raise argparse.ArgumentTypeError(f"expected PARAM=V1,V2,... with a filter parameter, "
                                         f"got {text!r}")
    try:
        return name, [float(v) for v in vals.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not numbers: {vals!r}") from None


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: see the module docstring."""
    ap = argparse.ArgumentParser(prog="python -m cf_estimator.bench.grid",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, metavar="DIR")
    ap.add_argument("--set", type=_parse_set, action="append", required=True,
                    metavar="PARAM=V1,V2", help="values of one parameter (repeatable)")
    ap.add_argument("--params", metavar="YAML", help="base parameters (default: defaults)")
    ap.add_argument("--split", default=",".join(DEFAULT_SPLIT), metavar="LIST",
                    help="trial-name prefixes of half A (default %(default)s)")
    ap.add_argument("--sort", choices=("inclination", "total"), default="inclination")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    args = ap.parse_args(argv)
    from cf_estimator.params_file import load_params_file  # pipeline-level: lazily

    try:
        base = FilterParams()
        if args.params is not None:
            base, _pp, warnings = load_params_file(args.params)
            for text in warnings:
                print(f"grid: warning: {text}", file=sys.stderr)
        info = broad.read_trial_info(args.data)
        trials = [broad.load_trial(p, info) for p in broad.list_trials(args.data, None)]
    except (OSError, ParameterError, broad.BroadDataError) as exc:  # one line, as the CLI's
        text = getattr(exc, "strerror", None) or str(exc).splitlines()[0]
        print(f"grid: {text}", file=sys.stderr)
        return 1 if isinstance(exc, broad.BroadDataError) else 2
    values = dict(args.set)
    points = grid_points(base, values)
    if not points:
        ap.error("no valid parameter combination in the grid")
    scores = tuning.score_candidates(points, trials, jobs=args.jobs)
    means = half_means(scores, [s.strip() for s in args.split.split(",") if s.strip()])
    print(f"{len(points)} grid point(s) on {len(trials)} trial(s); RMSE [deg], mean over trials")
    print(format_grid(points, list(values), means, args.sort), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
