"""Parameter search with the batched filter: many candidates per pass over the data.

Coarse-to-fine random search in a box (log scale for gains, time constants and thresholds):

1. pass 1: ``candidates`` points drawn uniformly (in log space) in the box, plus the start point;
2. pass k > 1: the same number of points drawn around the best ``elite`` so far, with a spread
   that halves every pass (in box-normalised coordinates), plus the elite themselves.

Each pass runs all candidates through :func:`cf_estimator.core.batch.estimate_many` once per
trial; every candidate's (N, 4) estimate is scored at once, vectorised over the samples, with
:mod:`cf_estimator.metrics` (``on_candidate``: nothing per sample in Python). Trials may be
decimated for screening (:meth:`Trial.decimated`): confirm the result at full rate. The 9-D run
gives both scores: the magnetometer rotates about the world vertical only,
so the inclination of the 9-D run is the 6-D inclination. A trial is a BROAD
:class:`~cf_estimator.bench.broad.Trial` (fixed rate) or a
:class:`~cf_estimator.bench.bagtrial.BagTrial` (a recorded bag with a reference orientation,
header stamps).

Objectives (lower is better; means over trials): ``total`` (9-D total RMSE), ``inclination``
(inclination RMSE), ``combined`` (their mean). The thesis scenarios enter as a constraint: the
best candidates of the last pass are run through the scenarios and the best one whose peak tilt
error stays below the limit wins (see :func:`scenario_peaks`); the cheap acceleration scenario
(200 Hz) can also screen every pass (the CLI does so when a limit for it is given).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from cf_estimator.bench.bagtrial import BagTrial
from cf_estimator.bench.broad import Trial
from cf_estimator.bench.parallel import aligned, run_tasks, share, workers_of
from cf_estimator.core.batch import estimate_many
from cf_estimator.core.params import FilterParams
from cf_estimator.metrics import rmse_deg
from cf_estimator.schema import ParameterError

OBJECTIVES = ("total", "inclination", "combined")


@dataclass(frozen=True)
class Dim:
    """One searched parameter: a box [lo, hi], log-scaled or not; ``zero_prob``: chance that a
    first-pass draw is exactly 0 (e.g. the integral gain of the magnetometer channel)."""

    name: str
    lo: float
    hi: float
    log: bool = True
    zero_prob: float = 0.0

    def to_unit(self, v: float) -> float:
        """Value → [0, 1] box coordinate (0 maps to the lower bound)."""
        if self.log:
            v = max(v, self.lo)
            return (math.log(v) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo))
        return (v - self.lo) / (self.hi - self.lo)

    def from_unit(self, u: float) -> float:
        """[0, 1] box coordinate → value (clipped to the box)."""
        u = min(max(u, 0.0), 1.0)
        if self.log:
            v = math.exp(math.log(self.lo) + u * (math.log(self.hi) - math.log(self.lo)))
        else:
            v = self.lo + u * (self.hi - self.lo)
        return float(min(max(v, self.lo), self.hi))  # exp(log(lo)) may round below lo


#: Every searchable parameter with its box (units as in :class:`FilterParams`).
SEARCHABLE: tuple[Dim, ...] = (
    Dim("k1", 0.1, 5.0),  # below ~0.1/s a tilt error takes minutes to pull in
    Dim("k2", 1e-4, 0.1),
    Dim("saturation_limit_rad", 0.005, 1.0),
    Dim("aperiodic_time_constant_s", 0.2, 10.0, zero_prob=0.1),
    Dim("r1", 0.005, 2.0),
    Dim("r2", 1e-5, 0.05, zero_prob=0.3),
    # never 0 (= never recover), never long: recovering from a real attitude error (a bad
    # start, a hand-held launch) is a promise; 400 s left a real bag 112 deg off lying still
    Dim("recovery_trigger_s", 5.0, 30.0),
    # clip selection: the clip (saturation_limit_rad) applies only while a linear
    # acceleration is detected and the low-passed rotation rate is below the threshold
    Dim("rotation_threshold_rad_s", 0.03, 3.0),
    Dim("acceleration_threshold_m_s2", 0.05, 5.0),
    # the error path's aperiodic unit: how much of each correction it also sees
    Dim("aperiodic_prefilter", 0.01, 1.0, zero_prob=0.2),
    # stillness detection (matters only with still phases) and in-motion bias learning
    Dim("rest_gyro_threshold_rad_s", 0.002, 0.1),
    Dim("rest_window_s", 0.1, 2.0),
    Dim("bias_learning_k2", 0.002, 0.5, zero_prob=0.2),
)

#: Searched by default: the loop gains, the clip level and what selects it, the
#: aperiodic unit, the magnetometer gains and the recovery trigger. The acceleration hold and
#: the rest parameters can be chosen with ``space_from_names``.
DEFAULT_SEARCH: tuple[str, ...] = (
    "k1", "k2", "saturation_limit_rad", "aperiodic_time_constant_s", "aperiodic_prefilter",
    "r1", "r2", "recovery_trigger_s", "rotation_threshold_rad_s", "acceleration_threshold_m_s2",
)


#: The safety nets: a searched box may never leave these ranges (``--bounds`` included).
SAFETY_RANGES: dict[str, tuple[float, float]] = {
    d.name: (d.lo, d.hi) for d in SEARCHABLE
    if d.name in ("k1", "recovery_trigger_s")
}

#: Parameters of the magnetometer channel: invisible to the ``inclination`` objective.
MAG_PARAMETERS: tuple[str, ...] = ("r1", "r2")


def for_objective(space: Sequence[Dim], objective: str) -> tuple[tuple[Dim, ...], list[str]]:
    """``space`` without what ``objective`` cannot see (the magnetometer gains for
    ``inclination``) → (space, dropped names)."""
    if objective != "inclination":
        return tuple(space), []
    dropped = [d.name for d in space if d.name in MAG_PARAMETERS]
    return tuple(d for d in space if d.name not in MAG_PARAMETERS), dropped


def space_from_names(names: Sequence[str]) -> tuple[Dim, ...]:
    """The searchable boxes of ``names``, in that order (unknown names raise ValueError)."""
    by_name = {d.name: d for d in SEARCHABLE}
    bad = [n for n in names if n not in by_name]
    if bad:
        raise ValueError(f"cannot search {bad[0]!r}; searchable: {', '.join(by_name)}")
    return tuple(by_name[n] for n in names)


DEFAULT_SPACE: tuple[Dim, ...] = space_from_names(DEFAULT_SEARCH)


def with_bounds(space: Sequence[Dim], bounds: Mapping[str, tuple[float, float]]) -> tuple[Dim, ...]:
    """``space`` with some boxes replaced: ``{name: (lo, hi)}`` (names must be in ``space``)."""
    names = {d.name for d in space}
    bad = [n for n in bounds if n not in names]
    if bad:
        raise ValueError(f"bound for {bad[0]!r}, which is not searched")
    out = []
    for d in space:
        if d.name in bounds:
            lo, hi = bounds[d.name]
            if not (0 < lo < hi if d.log else lo < hi):
                raise ValueError(f"bad bounds for {d.name}: {lo:g}:{hi:g}")
            safe = SAFETY_RANGES.get(d.name)
            if safe is not None and (lo < safe[0] or hi > safe[1]):
                raise ValueError(f"bounds {d.name}={lo:g}:{hi:g} leave its safety range "
                                 f"{safe[0]:g}:{safe[1]:g} (the filter's recovery from a large "
                                 "error depends on it)")
            d = dataclasses.replace(d, lo=float(lo), hi=float(hi))
        out.append(d)
    return tuple(out)


def make_params(base: FilterParams, values: Mapping[str, float]) -> FilterParams | None:
    """``base`` with ``values``; None when the combination is invalid for the filter (e.g.
    unstable T·k2 ≥ k1)."""
    try:
        return dataclasses.replace(base, **dict(values))
    except (ParameterError, ValueError):
        return None


# -- scoring -----------------------------------------------------------------------------------
class BroadScorer:
    """``on_candidate`` callback: total / inclination RMSE [deg] of each candidate's estimate.

    BROAD definitions (:func:`cf_estimator.metrics.rmse_deg`): over the trial's ``movement``
    samples whose reference is finite, estimate rows that are NaN (before initialisation)
    ignored; NaN when nothing is scored.
    """

    def __init__(self, trial: Trial, size: int) -> None:
        self.mask = trial.movement & np.all(np.isfinite(trial.quat_ref), axis=1)
        self.q_ref = trial.quat_ref[self.mask]
        self.total_deg = np.full(size, np.nan)
        self.inclination_deg = np.full(size, np.nan)

    def __call__(self, p: int, q: np.ndarray) -> None:
        m = rmse_deg(q[self.mask], self.q_ref)
        self.total_deg[p] = m["total_rmse_deg"]
        self.inclination_deg[p] = m["inclination_rmse_deg"]


class PeakScorer:
    """``on_candidate`` callback: peak tilt error [arcmin] of each candidate over ``mask``
    against ``q_true`` (world frame), NaN when nothing is scored (see ``peak_rms_arcmin``)."""

    def __init__(self, q_true: np.ndarray, mask: np.ndarray, size: int) -> None:
        self.q_true = q_true
        self.mask = mask
        self.peak_arcmin = np.full(size, np.nan)

    def __call__(self, p: int, q: np.ndarray) -> None:
        from cf_estimator.bench.scenarios import peak_rms_arcmin

        self.peak_arcmin[p] = peak_rms_arcmin(q, self.q_true, self.mask)[0]


def _timing(trial: Trial) -> dict[str, object]:
    """``estimate_many`` timing arguments: a bag trial's stamps, else the BROAD rate."""
    if isinstance(trial, BagTrial):
        return {"timestamps_s": trial.t_s}
    return {"rate_hz": trial.rate_hz}


def score_trial(candidates: Sequence[FilterParams], trial: Trial) -> tuple[np.ndarray, np.ndarray]:
    """(total, inclination) RMSE [deg] of every candidate on one trial (9-D run)."""
    scorer = BroadScorer(trial, len(candidates))
    estimate_many([dataclasses.replace(c, use_mag=True) for c in candidates], trial.gyro_rad_s,
                  trial.accel_m_s2, trial.mag_ut, on_candidate=scorer, **_timing(trial))
    return scorer.total_deg, scorer.inclination_deg


def _score_worker(args: tuple) -> tuple[np.ndarray, np.ndarray]:
    candidates, trial = args
    return score_trial(candidates, aligned(trial))


def _chunks(n: int, parts: int) -> list[slice]:
    """``parts`` (at most ``n``) contiguous slices covering range(n)."""
    bounds = np.linspace(0, n, max(1, min(parts, n)) + 1).round().astype(int)
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _split(n_candidates: int, n_units: int, jobs: Any) -> list[slice]:
    """Candidate slices so that ``n_units`` × slices fills ``jobs`` (one slice when it does)."""
    return _chunks(n_candidates, max(1, workers_of(jobs) // max(1, n_units)))


def score_candidates(candidates: Sequence[FilterParams], trials: Sequence[Trial], jobs: Any = 1
                     ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """trial → (total, inclination) RMSE arrays [deg] over the candidates. Trials (and, with
    fewer trials than jobs, slices of the candidates) are spread over ``jobs`` processes, or
    over a cluster engine's workers (each trial's arrays sent once, then reused)."""
    cands = list(candidates)
    parts = _split(len(cands), len(trials), jobs)
    tasks = [(cands[s], share(jobs, t)) for t in trials for s in parts]
    out = run_tasks(_score_worker, tasks, jobs)
    scores = {}
    for i, t in enumerate(trials):
        mine = out[i * len(parts):(i + 1) * len(parts)]
        scores[t.name] = (np.concatenate([o[0] for o in mine]),
                          np.concatenate([o[1] for o in mine]))
    return scores


def objective_values(scores: Mapping[str, tuple[np.ndarray, np.ndarray]], objective: str
                     ) -> np.ndarray:
    """Mean over trials of the chosen objective, per candidate (NaN → +inf)."""
    if objective not in OBJECTIVES:
        raise ValueError(f"unknown objective {objective!r}; valid: {', '.join(OBJECTIVES)}")
    total = np.mean([s[0] for s in scores.values()], axis=0)
    incl = np.mean([s[1] for s in scores.values()], axis=0)
    val = {"total": total, "inclination": incl, "combined": 0.5 * (total + incl)}[objective]
    return np.where(np.isfinite(val), val, np.inf)


# -- search ------------------------------------------------------------------------------------
@dataclass
class SearchResult:
    """Outcome of :func:`search`: the best candidate and every evaluated one (value order)."""

    best: FilterParams
    best_value: float
    start_value: float
    evaluated: list[tuple[float, FilterParams]]
    history: list[str]


Evaluator = Callable[[Sequence[FilterParams]], np.ndarray]


def _draw(rng: np.random.Generator, space: Sequence[Dim], base: FilterParams, n: int,
          centers: Sequence[FilterParams] | None, spread: float) -> list[FilterParams]:
    out: list[FilterParams] = []
    tries = 0
    while len(out) < n and tries < 50 * n:
        tries += 1
        values = {}
        if centers:
            c = centers[int(rng.integers(len(centers)))]
            for d in space:
                cur = getattr(c, d.name)
                if cur == 0.0 and d.zero_prob > 0 and rng.random() < 0.5:
                    values[d.name] = 0.0
                    continue
                values[d.name] = d.from_unit(d.to_unit(cur) + spread * rng.normal())
        else:
            for d in space:
                values[d.name] = 0.0 if rng.random() < d.zero_prob else d.from_unit(rng.random())
        p = make_params(base, values)
        if p is not None:
            out.append(p)
    return out


def search(evaluate: Evaluator, base: FilterParams, space: Sequence[Dim] = DEFAULT_SPACE, *,
           candidates: int = 96, passes: int = 3, elite: int = 6, seed: int = 0,
           spread: float = 0.15, log: Callable[[str], None] | None = None) -> SearchResult:
    """Coarse-to-fine random search minimising ``evaluate(list of params) -> values``."""
    rng = np.random.default_rng(seed)
    evaluated: list[tuple[float, FilterParams]] = []
    history: list[str] = []
    start_value = float("nan")
    for k in range(passes):
        if k == 0:
            batch = [base] + _draw(rng, space, base, candidates, None, 0.0)
        else:
            centers = [p for _v, p in evaluated[:elite]]
            batch = centers + _draw(rng, space, base, candidates, centers, spread / 2 ** (k - 1))
        values = np.asarray(evaluate(batch), dtype=float)
        if k == 0:
            start_value = float(values[0])
        seen = {id(p) for _v, p in evaluated}
        evaluated.extend((float(v), p) for v, p in zip(values, batch, strict=True)
                         if id(p) not in seen)
        evaluated.sort(key=lambda vp: vp[0])
        best_v, best_p = evaluated[0]
        line = (f"pass {k + 1}/{passes}: {len(batch)} candidates, start {start_value:.4f}, "
                f"best {best_v:.4f} "
                + " ".join(f"{d.name}={getattr(best_p, d.name):.4g}" for d in space))
        history.append(line)
        if log:
            log(line)
    best_v, best_p = evaluated[0]
    return SearchResult(best_p, best_v, start_value, evaluated, history)


def round_params(params: FilterParams, space: Sequence[Dim], digits: int = 2) -> FilterParams:
    """Searched values rounded to ``digits`` significant digits (readable YAML); unchanged if
    rounding makes the set invalid."""
    values = {}
    for d in space:
        v = getattr(params, d.name)
        values[d.name] = float(f"{v:.{digits}g}") if v != 0 else 0.0
    return make_params(params, values) or params


# -- thesis scenarios as a constraint ----------------------------------------------------------
def scenario_peaks(candidates: Sequence[FilterParams], names: Sequence[str] = (
        "impacts", "vibration", "acceleration"), seed: int = 0, jobs: Any = 1) -> np.ndarray:
    """(P, S) peak tilt error [arcmin] of every candidate (6-D) on each scenario, over the
    scored windows of :func:`cf_estimator.bench.scenarios.scenario_masks` (NaN: none scored)."""
    cands = list(candidates)
    parts = _split(len(cands), len(names), jobs)
    tasks = [(cands[s], n, seed) for n in names for s in parts]
    out = run_tasks(_scenario_worker, tasks, jobs)
    cols = [np.concatenate(out[i * len(parts):(i + 1) * len(parts)]) for i in range(len(names))]
    return np.stack(cols, axis=1)


def _scenario_worker(args: tuple) -> np.ndarray:
    from cf_estimator.bench.scenarios import scenario_masks
    from cf_estimator.scenarios import make_scenario

    candidates, name, seed = args
    sc = make_scenario(name, seed=seed)
    scorer = PeakScorer(sc.truth.q_world_from_body, scenario_masks(sc), len(candidates))
    estimate_many([dataclasses.replace(c, use_mag=False) for c in candidates], sc.imu.gyro_rad_s,
                  sc.imu.accel_m_s2, None, timestamps_s=sc.imu.t_s, on_candidate=scorer)
    return scorer.peak_arcmin


# -- validation before writing -----------------------------------------------------------------
#: Built-in validation cases: (label, scenario, seed, bad start, start at [s], scored after [s]).
#: Seeds differ from ``cf-estimator simulate``'s default 0, so a simulated tuning bag is not its
#: own validation. "bad start": the first :data:`BAD_START_S` of accelerometer and magnetometer
#: turned by 120 deg about x (a hand-held or moving start, longer than the start-up phase): the
#: filter is far off when its start-up phase ends and must recover (recovery, wide clip, k1).
#: "started in motion": the recording cut so that it begins inside the disturbances (as a
#: multirotor log that starts in the air): nothing known at the start, no rest phase.
VALIDATION_CASES: tuple[tuple[str, str, int, bool, float, float], ...] = (
    ("static (lying still)", "static", 11, False, 0.0, 5.0),
    ("flight", "flight", 11, False, 0.0, 10.0),
    ("uav", "uav", 11, False, 0.0, 10.0),
    ("vibration, started in motion", "vibration", 11, False, 25.0, 10.0),
    ("static, bad start", "static", 12, True, 0.0, 30.0),
    ("flight, bad start", "flight", 12, True, 0.0, 30.0),
)
#: Length of the corrupted start of the "bad start" cases [s] (the start-up phase is 2 s).
BAD_START_S = 3.0
#: A tuned set "loses" on a case when its RMSE exceeds the start point's by this factor plus
#: :data:`LOSS_MARGIN_DEG` (noise of a few hundredths of a degree is not a loss).
LOSS_FACTOR = 1.05
LOSS_MARGIN_DEG = 0.05


@dataclass(frozen=True)
class ValidationRow:
    """One validation case: RMSE [deg] of the start point and of the tuned set."""

    label: str
    metric: str  #: "total" or "inclination"
    before_deg: float
    after_deg: float

    @property
    def loses(self) -> bool:
        """The tuned set is worse here (NaN after, finite before, counts as worse)."""
        if not math.isfinite(self.after_deg):
            return math.isfinite(self.before_deg)
        return self.after_deg > LOSS_FACTOR * self.before_deg + LOSS_MARGIN_DEG


def _bad_start(gyro: np.ndarray, acc: np.ndarray, mag: np.ndarray, t: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """The first BAD_START_S of accelerometer and magnetometer turned 120 deg about x."""
    c, s = math.cos(math.radians(120.0)), math.sin(math.radians(120.0))
    r = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    first = t < t[0] + BAD_START_S
    acc, mag = acc.copy(), mag.copy()
    acc[first] = acc[first] @ r.T
    mag[first] = mag[first] @ r.T
    return acc, mag


def _case_worker(args: tuple) -> list[tuple[str, str, float, float]]:
    from cf_estimator.metrics import rmse_deg
    from cf_estimator.scenarios import make_scenario

    (label, name, seed, bad, start_s, after_s), params, metrics = args
    sc = make_scenario(name, seed=seed)
    k = int(np.searchsorted(sc.imu.t_s, start_s))
    t, gyro = sc.imu.t_s[k:], sc.imu.gyro_rad_s[k:]
    acc, mag = sc.imu.accel_m_s2[k:], sc.imu.mag_T[k:]
    if bad:
        acc, mag = _bad_start(gyro, acc, mag, t)
    mask = t >= t[0] + after_s
    q_true = sc.truth.q_world_from_body[k:][mask]
    rows = []
    scores = []
    for p in params:
        q = estimate_many([dataclasses.replace(p, use_mag=True)], gyro, acc, mag,
                          timestamps_s=t)[0]
        scores.append(rmse_deg(q[mask], q_true))
    for metric in metrics:
        key = f"{metric}_rmse_deg"
        rows.append((label, metric, float(scores[0][key]), float(scores[1][key])))
    return rows


def _flight_worker(args: tuple) -> tuple[str, float, float]:
    from cf_estimator.bench.euroc_eval import score_flight

    flight, params = args
    out = []
    for p in params:
        q = estimate_many([dataclasses.replace(p, use_mag=False)], flight.gyro_rad_s,
                          flight.accel_m_s2, None, timestamps_s=flight.t_s)[0]
        out.append(score_flight(flight, q)["inclination_rms_deg"])
    return flight.name, float(out[0]), float(out[1])


def validate(base: FilterParams, tuned: FilterParams, held_out: Sequence[Trial] = (),
             metrics: Sequence[str] = ("total", "inclination"), jobs: int = 1,
             flights: Sequence = ()) -> list[ValidationRow]:
    """Start point vs tuned set on what the search did not see: :data:`VALIDATION_CASES`, the
    held-out trials (BROAD trials or bags with a reference, 9-D run) and held-out EuRoC-layout
    ``flights`` (:class:`cf_estimator.bench.euroc.Flight`, 6-D: inclination after 10 s)."""
    tasks = [(case, (base, tuned), tuple(metrics)) for case in VALIDATION_CASES]
    rows = [ValidationRow(*r) for out in run_tasks(_case_worker, tasks, jobs) for r in out]
    for name, before, after in run_tasks(_flight_worker, [(f, (base, tuned)) for f in flights],
                                         jobs):
        rows.append(ValidationRow(f"held-out {name}", "inclination", before, after))
    if held_out:
        scores = score_candidates([base, tuned], held_out, jobs=jobs)
        for name, (total, incl) in scores.items():
            for metric in metrics:
                v = total if metric == "total" else incl
                rows.append(ValidationRow(f"held-out {name}", metric, float(v[0]), float(v[1])))
    return rows


def format_validation(rows: Sequence[ValidationRow]) -> str:
    """The validation table (one line per case and metric; ``LOSES`` where the tuned set is
    worse)."""
    lines = [f"  {'case':<34} {'metric':<12} {'before':>8} {'after':>8}  [deg RMSE]"]
    for r in rows:
        lines.append(f"  {r.label[:34]:<34} {r.metric:<12} {r.before_deg:8.3f} "
                     f"{r.after_deg:8.3f}" + ("  LOSES" if r.loses else ""))
    return "\n".join(lines) + "\n"
