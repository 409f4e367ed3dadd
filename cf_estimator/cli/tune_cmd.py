"""``cf-estimator tune``: search filter parameters on BROAD trial files or on a bag with a
reference orientation, with the batched filter.

Coarse-to-fine random search (:mod:`cf_estimator.bench.tuning`) over k1, k2, both clip levels
and what selects between them, the aperiodic time constant, the magnetometer gains and the
recovery trigger (``--search`` to choose; rest detection and the acceleration hold can be added),
many candidates per pass, on (optionally decimated) data; optional thesis-scenario constraint on
the peak tilt error; prints before/after and writes a ROS 2 parameter YAML that the node's
``--params-file``, ``replay --params`` and ``bench broad --params`` load unchanged.

Data: ``--data DIR`` (BROAD ``*.hdf5`` trials) or ``--bag PATH...`` (IMU, optional magnetometer
and a reference topic: :mod:`cf_estimator.bench.bagtrial` says how it is read and scored); several
bags, or directories of them, are tuned together (the mean objective over the recordings). A bag
that cannot be read is reported on one line and left out; the exit status is then 1.
``--cluster`` scores the candidates on Dask (docs/cluster.md).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cf_estimator.cli.base import EXIT_OK, EXIT_SOME_FAILED, CliError, finite_float
from cf_estimator.cli.common import (
    add_jobs_option,
    add_params_options,
    check_input_path,
    check_output_file,
    load_params,
    warn,
)

_BAG_ONLY = ("reference_topic", "imu_topic", "mag_topic", "score_after")
#: The thesis requirement: at most 90' peak tilt error under impacts, vibration and the 25 m/s
#: manoeuvre (the limit of ``bench scenarios`` and ``design --thesis``).
DEFAULT_SCENARIO_LIMIT = "90"


def _csv(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def register(subparsers: Any) -> None:
    """Add the ``tune`` sub-command."""
    from cf_estimator.bench.bagtrial import DEFAULT_REFERENCE_TOPIC, DEFAULT_SCORE_AFTER_S
    from cf_estimator.bench.tuning import DEFAULT_SEARCH, OBJECTIVES, SEARCHABLE

    p = subparsers.add_parser(
        "tune", help="search filter parameters on BROAD trials or a bag with a reference",
        description=(
            "Searches filter parameters on BROAD trial files (--data) or on a bag with a "
            "reference orientation (--bag): many candidates per pass with the batched filter. "
            "Prints the objective before and after, and writes the best set as a ROS 2 "
            "parameter YAML. Screening runs on decimated data (--decimate); the result is "
            "re-scored at full rate with --confirm."
        ),
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--data", metavar="PATH",
                     help="directory of BROAD *.hdf5 files, or one trial file")
    src.add_argument("--bag", metavar="PATH", nargs="+",
                     help="ROS 1 .bag or ROS 2 bag directory with IMU, optional magnetometer and "
                     "a reference orientation topic; several, or directories of bags (searched "
                     "recursively): one parameter set tuned over all of them")
    p.add_argument("--trials", metavar="LIST",
                   help="with --data: trials to tune on (names, prefixes, patterns)")
    b = p.add_argument_group("bag input (--bag)")
    b.add_argument("--reference-topic", metavar="TOPIC",
                   help="true orientation (sensor to world, the filter's world frame): "
                   "geometry_msgs/QuaternionStamped, PoseStamped, nav_msgs/Odometry or "
                   f"sensor_msgs/Imu orientation (default {DEFAULT_REFERENCE_TOPIC}, the truth "
                   "`cf-estimator simulate` writes)")
    b.add_argument("--imu-topic", metavar="TOPIC", help="sensor_msgs/Imu input (default: detect)")
    b.add_argument("--mag-topic", metavar="TOPIC",
                   help="sensor_msgs/MagneticField input (default: detect; 'none' = without)")
    b.add_argument("--score-after", type=finite_float, metavar="S",
                   help="score from S seconds after the first IMU sample "
                   f"(default {DEFAULT_SCORE_AFTER_S:g}: skips the start-up phase)")
    add_params_options(p, "the start point")
    p.add_argument("--objective", choices=OBJECTIVES,
                   help="total (9-D total RMSE, needs a common heading reference), inclination, "
                   "or combined = their mean (default combined; inclination for a bag without "
                   "magnetometer)")
    p.add_argument("--search", default=",".join(DEFAULT_SEARCH), metavar="LIST",
                   help="parameters to search (default %(default)s; also searchable: "
                   + ", ".join(d.name for d in SEARCHABLE if d.name not in DEFAULT_SEARCH) + ")")
    p.add_argument("--bounds", metavar="LIST",
                   help="override search boxes, e.g. saturation_limit_rad=0.005:0.03,k1=0.1:2")
    p.add_argument("--candidates", type=int, default=96, metavar="N",
                   help="candidates per pass (default %(default)s)")
    p.add_argument("--passes", type=int, default=3, metavar="N",
                   help="passes (default %(default)s)")
    p.add_argument("--decimate", type=int, default=4, metavar="K",
                   help="use every K-th sample (gyro block-averaged) while searching (default "
                   "%(default)s; 1 = full rate)")
    p.add_argument("--scenario-limit", metavar="ARCMIN", default=DEFAULT_SCENARIO_LIMIT,
                   help="reject candidates whose peak tilt error on the thesis scenarios "
                   "(impacts, vibration, 25 m/s manoeuvre) exceeds this: one number for all, "
                   "or per scenario, e.g. impacts=18,vibration=21,acceleration=90 (checks the "
                   "best 16); default %(default)s, the thesis requirement; 'none' = no "
                   "constraint (the result may break the thesis requirement)")
    p.add_argument("--confirm", action="store_true",
                   help="re-score start and best at full rate on the tuning data")
    p.add_argument("--seed", type=int, default=0,
                   help="random seed of the search (default 0; same seed, same result)")
    add_jobs_option(p)
    p.add_argument("--validate", metavar="LIST",
                   help="held-out recordings the tuned set must not lose on (comma-separated): "
                   "EuRoC/ASL flight folders or a directory of them (e.g. phantom4), BROAD trial "
                   "files or directories, bags with the reference topic; always checked too: the "
                   "built-in validation scenarios (lying still, flight, uav, started in motion, "
                   "bad start)")
    p.add_argument("--force", action="store_true",
                   help="write --out even when the tuned set loses on a validation case (a loud "
                   "warning instead of a refusal)")
    from cf_estimator.cluster import add_cluster_option

    add_cluster_option(p)
    p.add_argument("--out", metavar="YAML",
                   help="write the best parameters here, at full precision (a complete ROS 2 "
                   "parameter file)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.set_defaults(run=run)


# -- arguments ---------------------------------------------------------------------------------
def _scenario_limits(text: str) -> dict[str, float]:
    """``--scenario-limit`` → scenario → limit [arcmin]; ``none`` → {} (no constraint)."""
    names = ("impacts", "vibration", "acceleration")
    if text.strip().lower() == "none":
        return {}
    try:
        if "=" not in text:
            return dict.fromkeys(names, float(text))
        out = {}
        for item in _csv(text):
            k, _, v = item.partition("=")
            if k.strip() not in names:
                raise CliError(f"--scenario-limit: unknown scenario {k.strip()!r}; valid: "
                               f"{', '.join(names)}", 2)
            out[k.strip()] = float(v)
    except ValueError:
        raise CliError(f"--scenario-limit: not a number: {text!r}", 2) from None
    if any(not (v > 0) for v in out.values()):
        raise CliError(f"--scenario-limit: limits must be > 0 arcmin: {text!r}", 2)
    return out


def _check_args(args: Any) -> None:
    if args.candidates < 1 or args.passes < 1 or args.decimate < 1 or args.jobs < 1:
        raise CliError("--candidates, --passes, --decimate and --jobs must be >= 1", 2)
    if args.data is not None:
        given = [n for n in _BAG_ONLY if getattr(args, n) is not None]
        if given:
            raise CliError(f"--{given[0].replace('_', '-')} needs --bag (not --data)", 2)
    elif args.trials is not None:
        raise CliError("--trials needs --data (a bag is one trial)", 2)
    if args.score_after is not None and args.score_after < 0:
        raise CliError("--score-after must be >= 0", 2)


def _search_space(args: Any) -> tuple:
    from cf_estimator.bench import tuning

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
        return tuning.with_bounds(space, bounds)
    except ValueError as exc:
        raise CliError(str(exc), 2) from None


# -- data --------------------------------------------------------------------------------------
@dataclass
class _Source:
    """The tuning data: full-rate trials, a label for reports, and the --confirm printer."""

    trials: list
    label: str
    has_mag: bool
    confirm: Callable[[Any, Any], None]
    failed: int = 0  #: recordings left out (unreadable)


def _broad_source(args: Any, engine: Any) -> _Source:
    from cf_estimator.bench import broad

    check_input_path(args.data, "BROAD data")
    try:
        paths, info = broad.resolve_trials(args.data, _csv(args.trials) if args.trials else None)
    except broad.BroadDataError as exc:
        raise CliError(str(exc), 2) from None
    try:
        full = [broad.load_trial(p, info) for p in paths]
    except broad.BroadDataError as exc:
        raise CliError(str(exc)) from None

    def confirm(base: Any, best: Any) -> None:
        from cf_estimator.bench.evaluate import run_broad

        for label, p in (("before", base), ("after", best)):
            res = run_broad(paths, info, p, (), jobs=engine)
            print(f"\nfull rate, {label}:")
            print(broad.format_tables(res), end="")

    return _Source(full, f"{len(paths)} BROAD trial(s) from {args.data}", True, confirm)


@dataclass
class _BagLoad:
    """What a worker needs to read one bag into a trial (by path: shared storage)."""

    path: str
    name: str
    reference: str
    imu_topic: str | None
    mag_topic: str | None
    score_after: float
    world_frame: str = "enu"  #: the frame a PX4 log's vehicle_attitude is compared in


def _load_bag(task: _BagLoad) -> tuple[Any, str | None, int]:
    """(trial, None, 0) or (None, one-line error, exit code): a bad bag never stops the
    others."""
    from cf_estimator.bag.io import BagError
    from cf_estimator.bench import bagtrial

    try:
        trial = bagtrial.load_bag_trial(task.path, task.reference, imu_topic=task.imu_topic,
                                        mag_topic=task.mag_topic,
                                        score_after_s=task.score_after,
                                        world_frame=task.world_frame)
    except BagError as exc:
        return None, str(exc).splitlines()[0], exc.code
    except Exception as exc:  # noqa: BLE001 - anything else a broken bag raises: one line
        return None, f"{task.path}: {type(exc).__name__}: {str(exc).splitlines()[0]}", 1
    return dataclasses.replace(trial, name=task.name), None, 0


def _bag_source(args: Any, engine: Any, world_frame: str = "enu") -> _Source:
    from pathlib import Path

    from cf_estimator.bag.fleet import find_bags, output_names
    from cf_estimator.bench import bagtrial, tuning

    for b in args.bag:
        check_input_path(b, "input bag")
    bags = find_bags(args.bag)
    if not bags:
        raise CliError(f"no bags found in {', '.join(args.bag)}", 2)
    engine.check_paths([str(b.absolute()) for b in bags])
    reference = args.reference_topic or bagtrial.DEFAULT_REFERENCE_TOPIC
    score_after = bagtrial.DEFAULT_SCORE_AFTER_S if args.score_after is None else args.score_after
    loads = [_BagLoad(str(Path(b).absolute()), n, reference, args.imu_topic, args.mag_topic,
                      score_after, world_frame)
             for b, n in zip(bags, output_names(bags), strict=True)]
    loaded = engine.map(_load_bag, loads)
    trials = [t for t, _e, _c in loaded if t is not None]
    errors = [e for _t, e, _c in loaded if e is not None]
    single = len(bags) == 1 and len(args.bag) == 1
    if single and errors:  # one bag: its problem is the command's error, as before
        raise CliError(errors[0].replace(loads[0].path, args.bag[0]), loaded[0][2])
    for e in errors:
        print(f"FAILED  {e}", flush=True)
    if not trials:
        raise CliError(f"none of the {len(bags)} bag(s) could be read", 1)
    for b, t in zip([ld for (t, _e, _c), ld in zip(loaded, loads, strict=True)
                     if t is not None], trials, strict=True):
        topics = ", ".join(f"{k} {v or '(none)'}" for k, v in t.topics.items())
        shown = args.bag[0] if single else b.path
        print(f"bag {shown}: {t.describe()}; {topics}", flush=True)
    mags = {t.has_mag for t in trials}
    if len(mags) > 1:
        without = ", ".join(t.name for t in trials if not t.has_mag)
        raise CliError(f"some bags have magnetometer samples and some not ({without}): tune "
                       "them separately, or all without (--mag-topic none)", 2)

    def confirm(base: Any, best: Any) -> None:
        scores = tuning.score_candidates([base, best], trials, jobs=engine)
        print("\nfull rate [deg]:        total RMSE   inclination RMSE")
        for i, label in enumerate(("before", "after")):
            total = np.mean([scores[t.name][0][i] for t in trials])
            incl = np.mean([scores[t.name][1][i] for t in trials])
            print(f"  {label:<20} {total:10.3f}   {incl:16.3f}")

    if single:
        label = f"bag {args.bag[0]} (reference {trials[0].topics['reference']})"
    else:
        label = f"{len(trials)} bag(s) from {', '.join(args.bag)} (reference {reference})"
    src = _Source(trials, label, trials[0].has_mag, confirm)
    src.failed = len(errors)
    return src


def _objective(args: Any, source: _Source) -> str:
    if source.has_mag:
        return args.objective or "combined"
    if args.objective in ("total", "combined"):
        raise CliError(f"--objective {args.objective}: the bag has no magnetometer samples, so "
                       "heading is unobservable; use --objective inclination", 2)
    return "inclination"


def _held_out(args: Any) -> tuple[list, list]:
    """``--validate`` → (BROAD / bag trials, EuRoC flights); CliError when one is unusable."""
    from pathlib import Path

    from cf_estimator.bag.io import BagError
    from cf_estimator.bench import bagtrial, broad, euroc

    trials: list = []
    flights: list = []
    for item in _csv(args.validate or ""):
        path = check_input_path(item, "--validate recording")
        try:
            if path.is_dir() and (euroc.is_flight_dir(path) or not any(path.glob("*.hdf5"))
                                  and not (path / "metadata.yaml").exists()):
                flights += euroc.load_flights(path)
            elif path.suffix == ".hdf5" or path.is_dir() and any(path.glob("*.hdf5")):
                paths, info = broad.resolve_trials(str(path), None)
                trials += [broad.load_trial(p, info) for p in paths]
            else:
                trials.append(bagtrial.load_bag_trial(
                    path, args.reference_topic or bagtrial.DEFAULT_REFERENCE_TOPIC))
        except (euroc.EurocDataError, broad.BroadDataError) as exc:
            raise CliError(f"--validate {Path(item)}: {exc}", 2) from None
        except BagError as exc:
            raise CliError(f"--validate {Path(item)}: {exc}", 2) from None
    return trials, flights


def _validation(args: Any, base: Any, best: Any, held: tuple[list, list]) -> list:
    """Start point vs tuned set on what the search did not see; prints the table and returns
    the cases where the tuned set loses."""
    from cf_estimator.bench import tuning

    rows = tuning.validate(base, best, held[0], jobs=args.jobs, flights=held[1])
    print(f"validation (not searched on; before = the start point, LOSES = worse by more than "
          f"{(tuning.LOSS_FACTOR - 1) * 100:.0f}% + {tuning.LOSS_MARGIN_DEG:g} deg):")
    print(tuning.format_validation(rows), end="")
    return [r for r in rows if r.loses]


def _decimated(source: _Source, factor: int) -> list:
    trials = [t.decimated(factor) for t in source.trials]
    for t in trials:
        if t.n_samples < 2 or not t.movement.any():
            raise CliError(f"--decimate {factor} leaves no scored samples of {t.name}", 2)
    return trials


# -- search and report -------------------------------------------------------------------------
def _scenario_check(result: Any, base: Any, limits: dict[str, float], jobs: Any) -> Any:
    """The best of the 16 best candidates that meets every scenario limit; the start point if
    none does (and it does); CliError when not even the start point meets them."""
    from cf_estimator.bench import tuning

    top = [p for v, p in result.evaluated[:16] if np.isfinite(v)]
    peaks = tuning.scenario_peaks(top + [base], tuple(limits), jobs=jobs)
    bound = np.array(list(limits.values()))
    ok = [i for i in range(len(top)) if np.all(peaks[i] <= bound)]
    print(f"  scenario check ({', '.join(f'{k} <= {v:g}' for k, v in limits.items())} "
          f"arcmin): {len(ok)}/{len(top)} of the best candidates pass")
    for i in range(len(top)):
        print(f"    #{i:<2} peaks " + " ".join(f"{v:7.1f}" for v in peaks[i])
              + ("  ok" if i in ok else ""))
    if ok:
        return top[ok[0]]
    start_peaks = " ".join(f"{v:.1f}" for v in peaks[-1])
    if np.all(peaks[-1] <= bound):
        print(f"  no candidate meets the scenario limits; keeping the start point (peaks "
              f"{start_peaks})")
        return base
    raise CliError(f"the start point already exceeds the scenario limits (peaks {start_peaks} "
                   "arcmin): relax --scenario-limit, or --scenario-limit none")


#: Relative distance to a search bound under which a tuned value counts as "on the bound".
ON_BOUND_REL = 1e-6


def bound_notes(space: Sequence[Any], best: Any) -> dict[str, str]:
    """``name → note`` for each tuned value that ended on (within :data:`ON_BOUND_REL` of) a
    bound of its search box: the optimum may lie beyond it."""
    from cf_estimator.bench import tuning

    notes = {}
    for d in space:
        v = float(getattr(best, d.name))
        for side, b in (("lower", d.lo), ("upper", d.hi)):
            if abs(v - b) <= ON_BOUND_REL * max(abs(b), 1e-12):
                safe = tuning.SAFETY_RANGES.get(d.name)
                if safe is not None and b in safe:
                    how = f"it is also the safety bound ({safe[0]:g}:{safe[1]:g}): kept there"
                else:
                    how = f"the optimum may lie beyond it: widen it with --bounds {d.name}=LO:HI"
                notes[d.name] = f"{d.name} = {v:.6g} ended on its {side} search bound; {how}"
    return notes


def _write(path: str, best: Any, header: str, *, only: Sequence[str] | None,
           pipeline_params: Any = None, notes: dict[str, str] | None = None) -> None:
    from pathlib import Path

    from cf_estimator.bag.io import write_atomic_text
    from cf_estimator.bench.paramio import render_filter_params

    try:
        write_atomic_text(Path(path), render_filter_params(
            best, header, pipeline_params=pipeline_params, only=only, notes=notes))
    except OSError as exc:
        raise CliError(f"cannot write {path}: {exc.strerror or exc}", 2) from None
    print(f"wrote {path}")


def run(args: Any) -> int:
    """``tune``: exit 0, or 1 when bags were left out because they could not be read."""
    from cf_estimator.cluster import ClusterError, make_engine

    _check_args(args)
    check_output_file(args.out, overwrite=args.overwrite, option="--out")
    space = _search_space(args)
    limits = _scenario_limits(args.scenario_limit)
    base, base_pipeline = load_params(args.params, args.node_name)
    try:
        with make_engine(args.cluster, args.jobs) as engine:
            return _run(args, engine, space, limits, base, base_pipeline)
    except ClusterError as exc:
        raise CliError(str(exc), 2) from None


def _run(args: Any, engine: Any, space: Any, limits: dict[str, float], base: Any,
         base_pipeline: Any = None) -> int:
    from cf_estimator.bench import tuning

    source = (_bag_source(args, engine, base.world_frame) if args.bag is not None
              else _broad_source(args, engine))
    objective = _objective(args, source)
    space, dropped = tuning.for_objective(space, objective)
    if dropped:
        print(f"  objective {objective} cannot see {', '.join(dropped)} (magnetometer channel): "
              "not searched", flush=True)
    if not space:
        raise CliError(f"nothing to search for objective {objective}", 2)
    held = _held_out(args)
    trials = _decimated(source, args.decimate)
    start = time.monotonic()

    def log(line: str) -> None:
        print(f"  {line}  ({time.monotonic() - start:.0f} s)", flush=True)

    def evaluate(cands: Sequence[Any]) -> np.ndarray:
        scores = tuning.score_candidates(cands, trials, jobs=engine)
        values = tuning.objective_values(scores, objective)
        if "acceleration" in limits:  # cheap (200 Hz): screen every candidate of every pass
            peak = tuning.scenario_peaks(cands, ("acceleration",), jobs=engine)[:, 0]
            values = np.where(peak <= limits["acceleration"], values, np.inf)
        return values

    print(f"tune: {len(trials)} trial(s), objective {objective}, decimate {args.decimate}, "
          f"{args.candidates} candidates x {args.passes} passes; searching "
          + ", ".join(d.name for d in space), flush=True)
    if not limits:
        print("  no scenario limits (--scenario-limit none): the result may break the thesis "
              "requirement", flush=True)
    result = tuning.search(evaluate, base, space, candidates=args.candidates, passes=args.passes,
                           seed=args.seed, log=log)
    best = result.best  # full precision: what was scored is what is written
    if limits:
        best = _scenario_check(result, base, limits, engine)
    final = evaluate([base, best])  # inf = fails the acceleration-scenario screen
    rate = "full rate" if args.decimate == 1 else f"decimated x{args.decimate}"
    print(f"objective ({objective}, {rate}): before {final[0]:.4f}  after {final[1]:.4f}")
    print("parameters:")
    for d in space:
        print(f"  {d.name:<28} {getattr(base, d.name):>10.5g} -> {getattr(best, d.name):<10.5g}")
    if args.confirm:
        source.confirm(base, best)
    losses = _validation(args, base, best, held)
    where = "; ".join(f"{r.label} {r.metric} {r.before_deg:.2f} -> {r.after_deg:.2f} deg"
                      for r in losses[:3]) + (f"; {len(losses) - 3} more" if len(losses) > 3
                                              else "")
    if losses and args.out and not args.force:
        raise CliError(f"the tuned set is worse than the start point on {len(losses)} "
                       f"validation case(s) ({where}): {args.out} not written; check the table, "
                       "or --force to write it anyway")
    if losses:
        warn(f"THE TUNED SET IS WORSE than the start point on {len(losses)} validation "
             f"case(s): {where}" + (" (written anyway: --force)" if args.out else ""))
    if args.out:
        limit_text = (", ".join(f"{k} <= {v:g}'" for k, v in limits.items())
                      if limits else "none")
        loss_text = (f"# WARNING: worse than the start point on: {where} (--force)\n"
                     if losses else "# validation: not worse than the start point on any case\n")
        notes = bound_notes(space, best)
        for text in notes.values():
            warn(text)
        tuned = [d.name for d in space]
        what = (f"# every parameter: those of --params {args.params}, the tuned ones "
                f"({', '.join(tuned)}) replaced\n" if args.params else
                f"# only the tuned parameters ({', '.join(tuned)}); every other one stays as "
                "the node's defaults or an earlier --params-file set it\n")
        _write(args.out, best, f"# cf-estimator tune: objective {objective} on {source.label}; "
               f"before {final[0]:.4f}, after {final[1]:.4f} (decimate {args.decimate}); "
               f"scenario limits: {limit_text}\n" + loss_text + what,
               only=None if args.params else tuned,
               pipeline_params=base_pipeline if args.params else None, notes=notes)
    if source.failed:
        print(f"{source.failed} bag(s) could not be read and were left out (exit status "
              f"{EXIT_SOME_FAILED})")
    return EXIT_SOME_FAILED if source.failed else EXIT_OK
