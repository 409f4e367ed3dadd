"""``cf-estimator tune``: search filter parameters on BROAD trial files with the batched filter.

Coarse-to-fine random search (:mod:`cf_estimator.bench.tuning`) over k1, k2, the clip, the
aperiodic time constant and the magnetometer gains (``--search`` to choose), many candidates per
pass, on (optionally decimated) trials; optional thesis-scenario constraint on the peak tilt
error; prints before/after and writes a ROS 2 parameter YAML that ``--params-file`` and
``bench broad --params`` load unchanged.
"""

from __future__ import annotations

import os
import time
from typing import Any

import numpy as np

from cf_estimator.cli.main import CliError


def _csv(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def register(subparsers: Any) -> None:
    """Add the ``tune`` sub-command."""
    from cf_estimator.bench.tuning import DEFAULT_SPACE, OBJECTIVES

    p = subparsers.add_parser(
        "tune", help="search filter parameters on BROAD trials (batched filter)",
        description=(
            "Searches filter parameters on BROAD trial files (many candidates per pass with the "
            "batched filter), prints the objective before and after, and writes the best set as "
            "a ROS 2 parameter YAML. Screening runs on decimated data (--decimate); the result "
            "is re-scored at full rate with --confirm."
        ),
    )
    p.add_argument("--data", required=True, metavar="DIR", help="directory of BROAD *.hdf5 files")
    p.add_argument("--trials", metavar="LIST", help="trials to tune on (names, prefixes, patterns)")
    p.add_argument("--params", metavar="YAML", help="start point (default: shipped defaults)")
    p.add_argument("--objective", choices=OBJECTIVES, default="combined",
                   help="total (9-D total RMSE), inclination, or combined = their mean "
                   "(default %(default)s)")
    p.add_argument("--search", default=",".join(d.name for d in DEFAULT_SPACE), metavar="LIST",
                   help="parameters to search (default %(default)s)")
    p.add_argument("--bounds", metavar="LIST",
                   help="override search boxes, e.g. saturation_limit_rad=0.005:0.03,k1=0.1:2")
    p.add_argument("--candidates", type=int, default=96, metavar="N",
                   help="candidates per pass (default %(default)s)")
    p.add_argument("--passes", type=int, default=3, metavar="N",
                   help="passes (default %(default)s)")
    p.add_argument("--decimate", type=int, default=4, metavar="K",
                   help="use every K-th sample (gyro block-averaged) while searching (default "
                   "%(default)s; 1 = full rate)")
    p.add_argument("--scenario-limit", metavar="ARCMIN",
                   help="reject candidates whose peak tilt error on the thesis scenarios exceeds "
                   "this: one number for all, or per scenario, e.g. "
                   "impacts=18,vibration=21,acceleration=90 (checks the best 16)")
    p.add_argument("--confirm", action="store_true",
                   help="re-score start and best at full rate on the tuning trials")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), metavar="N")
    p.add_argument("--out", metavar="YAML", help="write the best parameters here")
    p.set_defaults(run=run)


def _scenario_limits(text: str) -> dict[str, float]:
    names = ("impacts", "vibration", "acceleration")
    try:
        if "=" not in text:
            return dict.fromkeys(names, float(text))
        out = {}
        for item in _csv(text):
            k, _, v = item.partition("=")
            out[k.strip()] = float(v)
    except ValueError:
        raise CliError(f"--scenario-limit: not a number: {text!r}", 2) from None
    return out


def run(args: Any) -> int:
    """``tune``."""
    from cf_estimator.bench import broad, tuning
    from cf_estimator.bench.paramio import render_filter_params
    from cf_estimator.cli.bench_cmd import _load_params

    if args.candidates < 1 or args.passes < 1 or args.decimate < 1 or args.jobs < 1:
        raise CliError("--candidates, --passes, --decimate and --jobs must be >= 1", 2)
    try:
        space = tuning.space_from_names(_csv(args.search))
        bounds = {}
        for item in _csv(args.bounds or ""):
            name, _, rng = item.partition("=")
            lo, _, hi = rng.partition(":")
            try:
                bounds[name.strip()] = (float(lo), float(hi))
            except ValueError:
                raise ValueError(f"--bounds: expected NAME=LO:HI, got {item!r}") from None
        space = tuning.with_bounds(space, bounds)
    except ValueError as exc:
        raise CliError(str(exc), 2) from None
    base = _load_params(args.params)
    try:
        paths = broad.list_trials(args.data, _csv(args.trials) if args.trials else None)
        info = broad.read_trial_info(args.data)
        full = [broad.load_trial(p, info) for p in paths]
    except broad.BroadDataError as exc:
        raise CliError(str(exc)) from None
    trials = [t.decimated(args.decimate) for t in full]
    start = time.monotonic()

    def log(line: str) -> None:
        print(f"  {line}  ({time.monotonic() - start:.0f} s)", flush=True)

    limits = _scenario_limits(args.scenario_limit) if args.scenario_limit is not None else {}

    def evaluate(cands):
        scores = tuning.score_candidates(cands, trials, jobs=args.jobs)
        values = tuning.objective_values(scores, args.objective)
        if "acceleration" in limits:  # cheap (200 Hz): screen every candidate of every pass
            peak = tuning.scenario_peaks(cands, ("acceleration",))[:, 0]
            values = np.where(peak <= limits["acceleration"], values, np.inf)
        return values

    print(f"tune: {len(trials)} trial(s), objective {args.objective}, decimate {args.decimate}, "
          f"{args.candidates} candidates x {args.passes} passes; searching "
          + ", ".join(d.name for d in space), flush=True)
    result = tuning.search(evaluate, base, space, candidates=args.candidates, passes=args.passes,
                           seed=args.seed, log=log)
    best = tuning.round_params(result.best, space)
    if limits:
        top = [tuning.round_params(p, space) for _v, p in result.evaluated[:16]]
        peaks = tuning.scenario_peaks(top, tuple(limits), jobs=args.jobs)
        ok = [i for i in range(len(top)) if np.all(peaks[i] <= np.array(list(limits.values())))]
        print(f"  scenario check ({', '.join(f'{k} <= {v:g}' for k, v in limits.items())} "
              f"arcmin): {len(ok)}/{len(top)} of the best candidates pass")
        for i in range(len(top)):
            print(f"    #{i:<2} peaks " + " ".join(f"{v:7.1f}" for v in peaks[i])
                  + ("  ok" if i in ok else ""))
        if not ok:
            raise CliError("no candidate meets --scenario-limit; widen the search or relax it")
        best = top[ok[0]]
    final = evaluate([base, best])  # inf = fails the acceleration-scenario screen
    print(f"objective ({args.objective}, decimated data): before {final[0]:.4f}  after "
          f"{final[1]:.4f}")
    print("parameters:")
    for d in space:
        print(f"  {d.name:<28} {getattr(base, d.name):>10.5g} -> {getattr(best, d.name):<10.5g}")
    if args.confirm:
        from cf_estimator.bench.evaluate import run_broad

        for label, p in (("before", base), ("after", best)):
            res = run_broad(paths, info, p, (), jobs=args.jobs)
            print(f"\nfull rate, {label}:")
            print(broad.format_tables(res), end="")
    if args.out:
        header = (f"# cf-estimator tune: objective {args.objective} on {len(paths)} BROAD trial(s) "
                  f"from {args.data}; before {final[0]:.4f}, after {final[1]:.4f} (decimate "
                  f"{args.decimate})\n")
        try:
            with open(args.out, "w", encoding="utf-8") as fh:
                fh.write(render_filter_params(best, header))
        except OSError as exc:
            raise CliError(f"cannot write {args.out}: {exc.strerror or exc}") from None
        print(f"wrote {args.out}")
    return 0
