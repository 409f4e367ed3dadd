"""Parameter search with the batched filter: many candidates per pass over the data.

Coarse-to-fine random search in a box (log scale for gains and time constants):

1. pass 1: ``candidates`` points drawn uniformly (in log space) in the box, plus the start point;
2. pass k > 1: the same number of points drawn around the best ``elite`` so far, with a spread
   that halves every pass (in box-normalised coordinates), plus the elite themselves.

Each pass runs all candidates together through :func:`cf_estimator.core.batch.estimate_many`
(one :class:`~cf_estimator.core.batched.BatchedFilter` per trial; the cost per step hardly grows
with the number of candidates) and accumulates the BROAD errors on the fly (nothing stored).
Trials may be decimated for screening (:meth:`Trial.decimated`): confirm the result at full
rate. The 9-D run gives both scores: in ``mag_mode: yaw`` the magnetometer rotates about the
world vertical only, so the inclination of the 9-D run is the 6-D inclination.

Objectives (lower is better; means over trials): ``total`` (9-D total RMSE), ``inclination``
(inclination RMSE), ``combined`` (their mean). The thesis scenarios enter as a constraint: the
best candidates of the last pass are run through the scenarios and the best one whose peak tilt
error stays below the limit wins (see :func:`scenario_peaks`); the cheap acceleration scenario
(200 Hz) can also screen every pass (the CLI does so when a limit for it is given).
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from cf_estimator.bench.broad import Trial
from cf_estimator.core.batch import estimate_many
from cf_estimator.core.params import FilterParams
from cf_estimator.metrics import error_angles
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
            return float(math.exp(math.log(self.lo) + u * (math.log(self.hi) - math.log(self.lo))))
        return float(self.lo + u * (self.hi - self.lo))


DEFAULT_SPACE: tuple[Dim, ...] = (
    Dim("k1", 0.05, 5.0),
    Dim("k2", 1e-4, 0.1),
    Dim("saturation_limit_rad", 0.005, 1.0),
    Dim("aperiodic_time_constant_s", 0.2, 10.0, zero_prob=0.1),
    Dim("r1", 0.005, 2.0),
    Dim("r2", 1e-5, 0.05, zero_prob=0.3),
    Dim("recovery_trigger_s", 10.0, 600.0, zero_prob=0.3),
)


def space_from_names(names: Sequence[str]) -> tuple[Dim, ...]:
    """The default box restricted to ``names`` (unknown names raise ValueError)."""
    by_name = {d.name: d for d in DEFAULT_SPACE}
    bad = [n for n in names if n not in by_name]
    if bad:
        raise ValueError(f"cannot search {bad[0]!r}; searchable: {', '.join(by_name)}")
    return tuple(by_name[n] for n in names)


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
    """``base`` with ``values``; None when the combination is invalid (e.g. unstable T·k2 ≥ k1)."""
    try:
        return dataclasses.replace(base, **dict(values))
    except (ParameterError, ValueError):
        return None


# -- scoring -----------------------------------------------------------------------------------
class _Accumulator:
    """Running sums of squared total / inclination error over the scored samples, per candidate."""

    def __init__(self, trial: Trial, size: int):
        self.qref_inv = trial.quat_ref * np.array([1.0, -1.0, -1.0, -1.0])
        norms = np.linalg.norm(trial.quat_ref, axis=1)
        self.score = trial.movement & np.isfinite(norms)
        safe = np.where(np.isfinite(norms) & (norms > 0), norms, 1.0)
        self.qref_inv = self.qref_inv / safe[:, None]
        self.sum_total = np.zeros(size)
        self.sum_incl = np.zeros(size)
        self.count = np.zeros(size)

    def __call__(self, i: int, q: np.ndarray) -> None:
        if not self.score[i]:
            return
        r = self.qref_inv[i]
        w = q[:, 0] * r[0] - q[:, 1] * r[1] - q[:, 2] * r[2] - q[:, 3] * r[3]
        z = q[:, 0] * r[3] + q[:, 1] * r[2] - q[:, 2] * r[1] + q[:, 3] * r[0]
        qe = np.zeros_like(q)
        qe[:, 0], qe[:, 3] = w, z
        norm = np.sqrt(np.sum(q * q, axis=1))
        qe[:, 0] /= norm
        qe[:, 3] /= norm
        total, _h, incl = error_angles(qe)
        ok = np.isfinite(total)
        self.sum_total[ok] += total[ok] ** 2
        self.sum_incl[ok] += incl[ok] ** 2
        self.count[ok] += 1

    def rmse_deg(self) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.maximum(self.count, 1)
            return (np.degrees(np.sqrt(self.sum_total / c)), np.degrees(np.sqrt(self.sum_incl / c)))


def score_trial(candidates: Sequence[FilterParams], trial: Trial) -> tuple[np.ndarray, np.ndarray]:
    """(total, inclination) RMSE [deg] of every candidate on one trial (9-D run)."""
    acc = _Accumulator(trial, len(candidates))
    estimate_many([dataclasses.replace(c, use_mag=True) for c in candidates], trial.gyro_rad_s,
                  trial.accel_m_s2, trial.mag_ut, rate_hz=trial.rate_hz, on_sample=acc, store=False)
    return acc.rmse_deg()


def _score_worker(args: tuple) -> tuple[str, np.ndarray, np.ndarray]:
    candidates, trial = args
    total, incl = score_trial(candidates, trial)
    return trial.name, total, incl


def score_candidates(candidates: Sequence[FilterParams], trials: Sequence[Trial], jobs: int = 1
                     ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """trial → (total, inclination) RMSE arrays over the candidates; trials spread over jobs."""
    tasks = [(list(candidates), t) for t in trials]
    if jobs <= 1 or len(tasks) <= 1:
        out = [_score_worker(t) for t in tasks]
    else:
        ctx = multiprocessing.get_context("fork" if os.name == "posix" else "spawn")
        with ctx.Pool(min(jobs, len(tasks))) as pool:
            out = pool.map(_score_worker, tasks, chunksize=1)
    return {name: (tot, inc) for name, tot, inc in out}


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
        "impacts", "vibration", "acceleration"), seed: int = 0, jobs: int = 1) -> np.ndarray:
    """(P, S) peak tilt error [arcmin] of every candidate (6-D) on each scenario."""
    tasks = [(list(candidates), n, seed) for n in names]
    if jobs <= 1 or len(tasks) <= 1:
        cols = [_scenario_worker(t) for t in tasks]
    else:
        ctx = multiprocessing.get_context("fork" if os.name == "posix" else "spawn")
        with ctx.Pool(min(jobs, len(tasks))) as pool:
            cols = pool.map(_scenario_worker, tasks, chunksize=1)
    return np.stack(cols, axis=1)


def _scenario_worker(args: tuple) -> np.ndarray:
    from cf_estimator.bench.scenarios import ARCMIN_PER_RAD, scenario_masks
    from cf_estimator.metrics import tilt_error_rad
    from cf_estimator.scenarios import make_scenario

    candidates, name, seed = args
    sc = make_scenario(name, seed=seed)
    mask = scenario_masks(sc)
    q_true = sc.truth.q_world_from_body
    peak = np.zeros(len(candidates))

    def on_sample(i: int, q: np.ndarray) -> None:
        if mask[i]:
            e = tilt_error_rad(q, q_true[i]) * ARCMIN_PER_RAD
            np.fmax(peak, e, out=peak)

    estimate_many([dataclasses.replace(c, use_mag=False) for c in candidates], sc.imu.gyro_rad_s,
                  sc.imu.accel_m_s2, None, timestamps_s=sc.imu.t_s, on_sample=on_sample,
                  store=False)
    return peak
