"""Thesis disturbance scenarios: peak and RMS tilt error of our filter and the peers.

Simulated with :func:`cf_estimator.scenarios.make_scenario` (realistic MEMS noise, the thesis's
10 °/h gyro bias, hover wobble — a real tilt motion, not a perfect gyro). Every estimator runs
accelerometer + gyro only (6-D: the disturbances act on the accelerometer; tilt is what they
spoil). Tilt error = BROAD's inclination error between estimate and truth; scored from the start
of each disturbance window to ``SETTLE_S`` after its end (errors can peak after a manoeuvre).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from cf_estimator.bench.parallel import run_tasks
from cf_estimator.core.batch import estimate
from cf_estimator.core.params import FilterParams
from cf_estimator.metrics import tilt_error_rad

THESIS_LIMIT_ARCMIN = 90.0
SETTLE_S = 15.0
ARCMIN_PER_RAD = 180.0 * 60.0 / math.pi


def our_variants(params: FilterParams) -> dict[str, FilterParams]:
    """Our filter as given, with the clip off, and with clip and aperiodic unit off."""
    p = dataclasses.replace(params, use_mag=False)
    return {
        "cf_estimator": p,
        "cf_estimator_noclip": dataclasses.replace(p, use_saturation=False),
        "cf_estimator_noclip_nolag": dataclasses.replace(p, use_saturation=False,
                                                         aperiodic_time_constant_s=0.0),
    }


def scenario_masks(sc) -> np.ndarray:
    """Boolean mask of the scored samples (disturbance windows plus SETTLE_S)."""
    t = sc.truth.t_s
    mask = np.zeros(t.shape[0], dtype=bool)
    for start, end, _label in sc.disturbance_windows:
        mask |= (t >= start) & (t <= end + SETTLE_S)
    return mask


def peak_rms_arcmin(q_est: np.ndarray, q_true: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """(peak, RMS) tilt error [arcmin] over ``mask``."""
    e = tilt_error_rad(q_est, q_true)[mask] * ARCMIN_PER_RAD
    e = e[np.isfinite(e)]
    if e.size == 0:
        return float("nan"), float("nan")
    return float(np.max(e)), float(np.sqrt(np.mean(e * e)))


#: ``bench scenarios --velocity``: the simulated GNSS velocity (10 Hz, 0.1 m/s, 100 ms late).
VELOCITY_RATE_HZ, VELOCITY_NOISE_M_S, VELOCITY_LATENCY_S = 10.0, 0.1, 0.1


def _aided_rows(sc, params: FilterParams, mask: np.ndarray, seed: int) -> list[dict]:
    """Ours aided by a simulated velocity: heading offset estimated ('auto'), and with the
    heading known from the start ('filter', initial attitude = the truth's: a compass fix)."""
    from cf_estimator.scenarios.velocity_sensor import VelocityModel, measure_velocity

    model = VelocityModel(VELOCITY_RATE_HZ, VELOCITY_NOISE_M_S, VELOCITY_LATENCY_S)
    vd = measure_velocity(sc.truth, model, np.random.default_rng([seed, 17]))
    imu, q_true = sc.imu, sc.truth.q_world_from_body
    base = dataclasses.replace(params, use_mag=False)
    rows = []
    for label, p, q0 in (
        ("cf_estimator_aided", dataclasses.replace(base, velocity_heading="auto"), None),
        ("cf_estimator_aided_heading", dataclasses.replace(base, velocity_heading="filter"),
         q_true[0]),
    ):
        q = estimate(imu.gyro_rad_s, imu.accel_m_s2, None, timestamps_s=imu.t_s, params=p,
                     initial_orientation=q0, velocity=(vd.t_s, vd.v_world_m_s),
                     velocity_latency_s=VELOCITY_LATENCY_S).quaternion
        peak, rms = peak_rms_arcmin(q, q_true, mask)
        rows.append({"scenario": sc.name, "algorithm": label, "peak_arcmin": peak,
                     "rms_arcmin": rms})
    return rows


def _one(args: tuple) -> list[dict]:
    name, params, peers, seed, duration, velocity = args
    from cf_estimator.bench import peers as peer_mod
    from cf_estimator.scenarios import make_scenario

    sc = make_scenario(name, duration_s=duration, seed=seed)
    imu, q_true, mask = sc.imu, sc.truth.q_world_from_body, scenario_masks(sc)
    rows = []
    for label, p in our_variants(params).items():
        q = estimate(imu.gyro_rad_s, imu.accel_m_s2, None, timestamps_s=imu.t_s,
                     params=p).quaternion
        peak, rms = peak_rms_arcmin(q, q_true, mask)
        rows.append({"scenario": name, "algorithm": label, "peak_arcmin": peak, "rms_arcmin": rms})
    if velocity:
        rows += _aided_rows(sc, params, mask, seed)
    runners = peer_mod.runners()
    for peer in peers:
        q = runners[peer](imu.gyro_rad_s, imu.accel_m_s2, None, sc.rate_hz, ("6d",))["6d"]
        peak, rms = peak_rms_arcmin(q, q_true, mask)
        rows.append({"scenario": name, "algorithm": peer, "peak_arcmin": peak, "rms_arcmin": rms})
    return rows


def run_scenarios(names: Sequence[str], params: FilterParams, peers: Sequence[str] = (),
                  seed: int = 0, duration_s: float | None = None, jobs: int = 1,
                  velocity: bool = False) -> list[dict]:
    """Rows ``{scenario, algorithm, peak_arcmin, rms_arcmin}`` (scenario order kept); with
    ``velocity`` also ours aided by a simulated GNSS velocity (:func:`_aided_rows`)."""
    from cf_estimator.scenarios import SCENARIOS

    for n in names:
        if n not in SCENARIOS:
            raise ValueError(f"unknown scenario {n!r}; valid: {', '.join(SCENARIOS)}")
    tasks = [(n, params, tuple(peers), seed, duration_s, velocity) for n in names]
    return [r for c in run_tasks(_one, tasks, jobs) for r in c]


def format_table(rows: list[dict]) -> str:
    """One table: algorithms × scenarios, peak / RMS tilt error [arcmin], limit marked."""
    scen = list(dict.fromkeys(r["scenario"] for r in rows))
    algos = list(dict.fromkeys(r["algorithm"] for r in rows))
    cell = {(r["scenario"], r["algorithm"]): r for r in rows}
    w = max(len(a) for a in algos + ["algorithm"])
    lines = [f"Tilt error [arcmin] inside the disturbance windows (+{SETTLE_S:g} s): peak / RMS; "
             f"thesis limit {THESIS_LIMIT_ARCMIN:g}' peak (* = over)",
             f"  {'algorithm':<{w}}" + "".join(f"  {s:>20}" for s in scen)]
    for a in algos:
        cells = []
        for s in scen:
            r = cell.get((s, a))
            if r is None:
                cells.append(f"  {'-':>20}")
                continue
            flag = "*" if r["peak_arcmin"] > THESIS_LIMIT_ARCMIN else " "
            cells.append(f"  {r['peak_arcmin']:9.1f}{flag}/{r['rms_arcmin']:9.1f}")
        lines.append(f"  {a:<{w}}" + "".join(cells))
    return "\n".join(lines) + "\n"
