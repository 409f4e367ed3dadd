"""Run our filter and the peers over BROAD trials and collect the metrics (one process per trial).

Algorithm names: ``cf_estimator_9d``/``cf_estimator_6d`` (our filter with the given parameters;
9-D forces ``use_mag`` on, 6-D off), ``cf_estimator_offline_9d``/``_6d`` (the same parameters
through the offline estimator, :mod:`cf_estimator.core.offline`) and ``<peer>_9d``/``<peer>_6d``
for the peers of :mod:`cf_estimator.bench.peers` at their defaults; a peer with an offline mode
(VQF) also gives ``<peer>_offline_9d``/``_6d``; with ``velocity``, ``cf_estimator_aided_9d``/``_6d``
(ours aided by the trial's optical velocity, :func:`cf_estimator.bench.broad.optical_velocity`).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cf_estimator import metrics
from cf_estimator.bench import broad
from cf_estimator.core.batch import estimate
from cf_estimator.core.params import FilterParams

OURS = "cf_estimator"
OURS_OFFLINE = "cf_estimator_offline"
OURS_AIDED = "cf_estimator_aided"
DIMS = ("9d", "6d")


def run_ours(trial: broad.Trial, params: FilterParams, dims: Sequence[str] = DIMS,
             offline: bool = False, velocity: bool = False) -> dict[str, np.ndarray]:
    """Our filter over a trial: ``{"9d": q, "6d": q}`` (q_ENU_from_sensor, NaN before init);
    ``offline``: the offline estimator; ``velocity``: aided by the trial's optical velocity
    (:func:`~cf_estimator.bench.broad.optical_velocity`, 10 Hz)."""
    aid = broad.optical_velocity(trial) if velocity else None
    out = {}
    for d in dims:
        p = dataclasses.replace(params, use_mag=(d == "9d"))
        mag = trial.mag_ut if d == "9d" else None
        out[d] = estimate(trial.gyro_rad_s, trial.accel_m_s2, mag, rate_hz=trial.rate_hz,
                          params=p, offline=offline, velocity=aid).quaternion
    return out


def evaluate_trial(path: str | os.PathLike, info: Mapping, params: FilterParams,
                   peers: Sequence[str] = (), dims: Sequence[str] = DIMS,
                   velocity: bool = False
                   ) -> tuple[str, tuple[str, ...], dict[str, dict[str, float]]]:
    """(trial name, groups, {algorithm: metrics}) for one trial file; ``velocity``: ours
    velocity-aided as well (``cf_estimator_aided``; a trial without optical positions:
    BroadDataError)."""
    from cf_estimator.bench import peers as peer_mod

    trial = broad.load_trial(path, info)
    results: dict[str, dict[str, float]] = {}

    def score(name: str, dim: str, q: np.ndarray) -> None:
        m = metrics.rmse_deg(q, trial.quat_ref, trial.movement)
        if dim == "6d":  # heading is unobservable without a magnetometer
            m = {"inclination_rmse_deg": m["inclination_rmse_deg"]}
        results[f"{name}_{dim}"] = m

    for d, q in run_ours(trial, params, dims).items():
        score(OURS, d, q)
    for d, q in run_ours(trial, params, dims, offline=True).items():
        score(OURS_OFFLINE, d, q)
    if velocity:
        if trial.position_m is None:
            raise broad.BroadDataError(f"{trial.name}: no optical positions (opt_pos) for "
                                       "--velocity")
        for d, q in run_ours(trial, params, dims, velocity=True).items():
            score(OURS_AIDED, d, q)
    runners = peer_mod.runners()
    for p in peers:
        for d, q in runners[p](trial.gyro_rad_s, trial.accel_m_s2, trial.mag_ut, trial.rate_hz,
                               tuple(dims)).items():
            score(p, d, q)
        if p == "vqf":  # the peer's own offline mode, same run
            out = peer_mod.run_vqf_offline(trial.gyro_rad_s, trial.accel_m_s2,
                                           trial.mag_ut if "9d" in dims else None,
                                           trial.rate_hz)
            for d in dims:
                if d in out:
                    score("vqf_offline", d, out[d])
    return trial.name, trial.groups, results


def _worker(args: tuple) -> tuple:
    return evaluate_trial(*args)


def run_broad(paths: Sequence[Path], info: Mapping, params: FilterParams,
              peers: Sequence[str] = (), jobs: Any = 1,
              progress: Callable[[str, int, int], None] | None = None,
              velocity: bool = False) -> broad.BenchResult:
    """Evaluate every trial (in ``jobs`` processes, or on a cluster engine: trials go to the
    workers by path); results keep the order of ``paths``; ``velocity``: see
    :func:`evaluate_trial`."""
    from cf_estimator.bench.parallel import run_tasks

    tasks = [(str(p), dict(info), params, tuple(peers), DIMS, velocity) for p in paths]
    done: dict[str, tuple] = {}
    count = [0]

    def on_done(_i: int, out: tuple) -> None:
        name, groups, res = out
        done[name] = (groups, res)
        count[0] += 1
        if progress:
            progress(name, count[0], len(tasks))

    run_tasks(_worker, tasks, jobs, on_done)
    result = broad.BenchResult()
    result.group_order = [g.get("name") for g in info.get("groups", []) if isinstance(g, Mapping)]
    for p in paths:
        groups, res = done[Path(p).stem]
        result.trials[Path(p).stem] = res
        result.groups[Path(p).stem] = groups
    return result
