"""Parameter search with the batched filter: many candidates per pass over the data.

Coarse-to-fine random search in a box (log scale for gains, time constants and thresholds):

1. pass 1: ``candidates`` points drawn uniformly (in log space) in the box, plus the start point;
2. pass k > 1: the same number of points drawn around the best ``elite`` so far, with a spread
   that halves every pass (in box-normalised coordinates), plus the elite themselves.

Each pass runs all candidates through :func:`cf_estimator.core.batch.estimate_many` once per
trial; every candidate's (N, 4) estimate is scored at once, vectorised over the samples, with
:mod:`cf_estimator.metrics` (``on_candidate``: nothing per sample in Python). Trials may be
decimated for screening (:meth:`Trial.decimated`): confirm the result at full rate. The 9-D run
gives both scores: in ``mag_mode: yaw`` the magnetometer rotates about the world vertical only,
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
    Dim("k1", 0.05, 5.0),
    Dim("k2", 1e-4, 0.1),
    Dim("saturation_limit_rad", 0.005, 1.0),
    Dim("aperiodic_time_constant_s", 0.2, 10.0, zero_prob=0.1),
    Dim("r1", 0.005, 2.0),
    Dim("r2", 1e-5, 0.05, zero_prob=0.3),
    # never 0 (= never recover): recovering from a real attitude error is a promise
    Dim("recovery_trigger_s", 10.0, 600.0),
    # clip selection: the tight clip (saturation_limit_rad) applies only while a linear
    # acceleration is detected and the low-passed rotation rate is below the threshold
    Dim("wide_saturation_limit_rad", 0.03, 10.0),  # 10 rad = effectively no clip
    Dim("rotation_threshold_rad_s", 0.03, 3.0),
    Dim("acceleration_threshold_m_s2", 0.05, 5.0),
    Dim("acceleration_hold_s", 0.1, 10.0),
    # the error path's aperiodic unit: how much of each correction it also sees
    Dim("aperiodic_prefilter", 0.01, 1.0, zero_prob=0.2),
    # stillness detection (matters only with still phases) and in-motion bias learning
    Dim("rest_gyro_threshold_rad_s", 0.002, 0.1),
    Dim("rest_time_s", 0.3, 10.0),
    Dim("rest_window_s", 0.1, 2.0),
    Dim("bias_learning_k2", 0.002, 0.5, zero_prob=0.2),
)

#: Searched by default: the loop gains, both clip levels and what selects between them, the
#: aperiodic unit, the magnetometer gains and the recovery trigger. The acceleration hold and
#: the rest parameters can be chosen with ``space_from_names``.
DEFAULT_SEARCH: tuple[str, ...] = (
    "k1", "k2", "saturation_limit_rad", "aperiodic_time_constant_s", "aperiodic_prefilter",
    "r1", "r2", "recovery_trigger_s", "wide_saturation_limit_rad", "rotation_threshold_rad_s",
    "acceleration_threshold_m_s2",
)


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
            d = dataclasses.replace(d, lo=float(lo), hi=float(hi))
        out.append(d)
    return tuple(out)


def make_params(base: FilterParams, values: Mapping[str, float]) -> FilterParams | None:
    """``base`` with ``values``; None when the combination is invalid for the filter (e.g.
    unstable T·k2 ≥ k1) or pointless for the search: a wide clip level below the tight one
    (``wide_saturation_limit_rad`` < ``saturation_limit_rad`` inverts the clip selection)."""
    try:
        p = dataclasses.replace(base, **dict(values))
    except (ParameterError, ValueError):
        return None
    if p.wide_saturation_limit_rad < p.saturation_limit_rad and (
            "wide_saturation_limit_rad" in values or "saturation_limit_rad" in values):
        return None
    return p


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
