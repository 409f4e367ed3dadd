"""EuRoC benchmark: run our filter and the peers over flights, score the inclination.

Every algorithm is 6-D (EuRoC has no magnetometer) and returns q_world_from_sensor (world z up;
heading irrelevant). Score per flight: inclination error (:func:`cf_estimator.metrics.
inclination_error_deg`) against the slerped ground truth, RMS and max over the samples at least
``settle_s`` after the first IMU sample that have a ground truth. The mean row is the mean over
flights of each flight's RMS (and of each flight's max).

Algorithms are entries of :data:`ALGORITHMS` (name → :class:`Algorithm`); ``ours`` entries
always run with the given :class:`FilterParams`, the others are peers chosen by name. Add one
with :func:`register`.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from cf_estimator import metrics
from cf_estimator.bench.euroc import EurocDataError, Flight
from cf_estimator.bench.parallel import run_tasks
from cf_estimator.core.batch import estimate
from cf_estimator.core.params import FilterParams

#: Default settling time [s] after the first IMU sample before the scoring starts.
SETTLE_S = 10.0
SCORES = ("inclination_rms_deg", "inclination_max_deg")

Runner = Callable[[Flight, FilterParams], np.ndarray]


@dataclass(frozen=True)
class Algorithm:
    """An estimator for the benchmark.

    Attributes:
        name: column label and ``--peers`` name.
        run: f(flight, params) → q_world_from_sensor (N, 4) w x y z (NaN rows allowed before
            the estimator's initialisation; ``params`` matters only to ours).
        package: PyPI package it needs (None: part of cf_estimator).
        ours: True for our filter's variants (always run), False for peers (chosen by name).
        recorded: read from the recording, not run (the sensor's own onboard filter): only when
            named, never in ``--peers all``.
    """

    name: str
    run: Runner
    package: str | None = None
    ours: bool = False
    recorded: bool = False


def _ours_online(flight: Flight, params: FilterParams) -> np.ndarray:
    p = dataclasses.replace(params, use_mag=False)
    return estimate(flight.gyro_rad_s, flight.accel_m_s2, None, timestamps_s=flight.t_s,
                    params=p).quaternion


def _ours_offline(flight: Flight, params: FilterParams) -> np.ndarray:
    p = dataclasses.replace(params, use_mag=False)
    return estimate(flight.gyro_rad_s, flight.accel_m_s2, None, timestamps_s=flight.t_s,
                    params=p, offline=True).quaternion


def _peer(name: str) -> Runner:
    from cf_estimator.bench import peers

    def run(flight: Flight, _params: FilterParams) -> np.ndarray:
        g, a, r = flight.gyro_rad_s, flight.accel_m_s2, flight.rate_hz
        if name == "vqf":
            return peers.run_vqf(g, a, None, r)["6d"]
        if name == "vqf_offline":
            return peers.run_vqf_offline(g, a, None, r)["6d"]
        if name == "fusion":
            return peers.run_fusion(g, a, None, r)
        if name == "madgwick":
            return peers.run_madgwick(g, a, None, r)
        if name == "complementary":
            return peers.run_complementary(g, a, None, r)
        if name == "riann":
            return peers.run_riann(g, a, r)
        raise ValueError(f"no runner for peer {name!r}")

    return run


#: The recording's own onboard filter output beside ``mav0`` (the Xsens DOTs' of the phantom4
#: campaigns): stamp [ns], q_w, q_x, q_y, q_z, in the ground truth's frames.
ONBOARD_FILE = "xsens_dot_orientation.csv"
#: Longest gap [s] at either end of the recording over which its first/last sample is held.
ONBOARD_HOLD_S = 0.1


def _onboard(flight: Flight, _params: FilterParams) -> np.ndarray:
    """The sensor's own onboard filter as recorded (:data:`ONBOARD_FILE`), on the flight's IMU
    stamps (normalised linear interpolation of the quaternion, sign-aligned); NaN rows beyond
    its stamps (by more than :data:`ONBOARD_HOLD_S`) or if the recording has no such file;
    EurocDataError (one line) if the file is not such a table."""
    out = np.full((flight.t_s.size, 4), np.nan)
    path = Path(flight.path) / ONBOARD_FILE
    if not path.is_file():
        return out
    try:
        d = np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
    except ValueError as exc:
        raise EurocDataError(f"{path}: not an onboard orientation file (stamp [ns], q_w, q_x, "
                             f"q_y, q_z per row): {exc}") from None
    if d.shape[0] < 2 or d.shape[1] < 5 or not np.isfinite(d[:, :5]).all():
        raise EurocDataError(f"{path}: not an onboard orientation file (stamp [ns], q_w, q_x, "
                             "q_y, q_z per row: at least two finite rows)")
    t = (d[:, 0] - flight.t0_ns) * 1e-9
    q = d[:, 1:5].copy()
    flips = np.concatenate([[1.0], np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=1) < 0.0,
                                                        -1.0, 1.0))])
    q *= flips[:, None]
    # held over a last gap of up to ONBOARD_HOLD_S at either end (the two streams' last
    # samples differ by a few ms: a NaN there would void the whole recording's score)
    inside = (flight.t_s >= t[0] - ONBOARD_HOLD_S) & (flight.t_s <= t[-1] + ONBOARD_HOLD_S)
    qi = np.stack([np.interp(flight.t_s[inside], t, q[:, c]) for c in range(4)], axis=1)
    out[inside] = qi / np.linalg.norm(qi, axis=1, keepdims=True)
    return out


ALGORITHMS: dict[str, Algorithm] = {}


def register(algorithm: Algorithm) -> None:
    """Add (or replace) an algorithm; columns follow the registration order."""
    ALGORITHMS[algorithm.name] = algorithm


register(Algorithm("cf_estimator", _ours_online, ours=True))
register(Algorithm("cf_estimator_offline", _ours_offline, ours=True))
for _name, _package in (("vqf", "vqf"), ("vqf_offline", "vqf"), ("madgwick", None),
                        ("fusion", "imufusion"), ("complementary", None), ("riann", "riann")):
    register(Algorithm(_name, _peer(_name), _package))
register(Algorithm("onboard", _onboard, recorded=True))


def peer_names(recorded: bool = False) -> list[str]:
    """Names of the peers (non-``ours`` algorithms), in registration order; the recorded ones
    (``onboard``) only with ``recorded``."""
    return [a.name for a in ALGORITHMS.values() if not a.ours and (recorded or not a.recorded)]


def installed(algorithm: Algorithm) -> bool:
    """True if the algorithm's package imports here."""
    if algorithm.package is None:
        return True
    try:
        importlib.import_module(algorithm.package)
    except ImportError:
        return False
    return True


def select_peers(names: Sequence[str]) -> tuple[list[str], list[str]]:
    """(peers to run, peers skipped because their package is not installed), order kept;
    ValueError for an unknown name."""
    valid = peer_names(recorded=True)
    for n in names:
        if n not in valid:
            raise ValueError(f"unknown peer {n!r}; valid: {', '.join(valid)}, all, none")
    # a peer with an offline mode runs in both modes, as ours does (vqf → vqf, vqf_offline)
    names = list(dict.fromkeys(m for n in names
                               for m in ((n, f"{n}_offline") if f"{n}_offline" in valid else (n,))))
    run = [n for n in names if installed(ALGORITHMS[n])]
    return run, [n for n in names if n not in run]


# -- scoring -----------------------------------------------------------------------------------
def score_flight(flight: Flight, q_est: np.ndarray, settle_s: float = SETTLE_S
                 ) -> dict[str, float]:
    """``{inclination_rms_deg, inclination_max_deg, n_scored}`` over the samples at
    ``t ≥ settle_s`` with a ground truth (an estimate's NaN there gives NaN)."""
    err = metrics.inclination_error_deg(q_est, flight.q_ref)
    mask = (flight.t_s >= settle_s) & flight.has_reference
    rms, peak, n = metrics.rms_max(err, mask)
    return {"inclination_rms_deg": rms, "inclination_max_deg": peak, "n_scored": n}


#: Scored windows [s after the start] of a mid-air start: the first seconds, then the rest.
MIDAIR_WINDOWS = ((2.0, 12.0), (12.0, math.inf))
MIDAIR_SCORES = ("early_rms_deg", "late_rms_deg")


def score_windows(flight: Flight, q_est: np.ndarray,
                  windows: Sequence[tuple[float, float]] = MIDAIR_WINDOWS) -> dict[str, float]:
    """Inclination RMS [deg] in each window ``[t0, t1)`` of the flight's time (with a ground
    truth), keys :data:`MIDAIR_SCORES` for the two default windows."""
    err = metrics.inclination_error_deg(q_est, flight.q_ref)
    out: dict[str, float] = {}
    for key, (t0, t1) in zip(MIDAIR_SCORES, windows, strict=True):
        mask = (flight.t_s >= t0) & (flight.t_s < t1) & flight.has_reference
        out[key] = metrics.rms_max(err, mask)[0]
    return out


def _midair_worker(task: tuple) -> dict[str, dict[str, float]]:
    flight, params, peers, velocity = task
    return {a.name: score_windows(flight, a.run(flight, params))
            for a in _algorithms(peers, velocity)}


def run_midair(flights: Sequence[Flight], params: FilterParams, start_s: float,
               peers: Sequence[str] = (), jobs: int = 1, velocity: VelocityInput | None = None
               ) -> EurocResult:
    """Every flight cropped to start ``start_s`` after its first sample (:meth:`Flight.cropped`)
    and scored in :data:`MIDAIR_WINDOWS` (keys :data:`MIDAIR_SCORES`); flights too short for
    the later window are left out. ``velocity``: ours aided too (as in :func:`run_euroc`)."""
    crops = [f.cropped(start_s) for f in flights if f.t_s[-1] - start_s > MIDAIR_WINDOWS[1][0]]
    tasks = [(f, params, tuple(peers), velocity) for f in crops]
    return _collect(crops, run_tasks(_midair_worker, tasks, jobs), MIDAIR_WINDOWS[0][0])


# -- velocity aiding (issue 17) ------------------------------------------------------------
@dataclass(frozen=True)
class VelocityInput:
    """How the ground-truth velocity is given to the aided filter: resampled to ``rate_hz``
    (None: as given), white noise ``noise_m_s`` [m/s] per axis (seeded per flight name),
    delivered ``latency_s`` [s] after its stamp."""

    rate_hz: float | None = None
    noise_m_s: float = 0.0
    latency_s: float = 0.0


def degraded_velocity(flight: Flight, vin: VelocityInput) -> tuple[np.ndarray, np.ndarray]:
    """(stamps [s] (M,), velocity [m/s] (M, 3)) of a flight's ground truth, degraded by ``vin``
    (ValueError if the flight has no ground-truth velocity)."""
    import zlib

    if flight.velocity_t_s is None or flight.velocity_m_s is None:
        raise ValueError(f"{flight.name}: no ground-truth velocity")
    t, v = flight.velocity_t_s, flight.velocity_m_s
    if vin.rate_hz is not None:
        grid = np.arange(t[0], t[-1], 1.0 / vin.rate_hz)
        v = np.stack([np.interp(grid, t, v[:, i]) for i in range(3)], axis=1)
        t = grid
    if vin.noise_m_s > 0.0:
        rng = np.random.default_rng(zlib.crc32(flight.name.encode()))
        v = v + rng.normal(0.0, vin.noise_m_s, v.shape)
    return t, v


def aided_algorithms(vin: VelocityInput) -> list[Algorithm]:
    """Our filter online and offline with the (degraded) ground-truth velocity as aiding."""

    def runner(offline: bool) -> Runner:
        def run(flight: Flight, params: FilterParams) -> np.ndarray:
            p = dataclasses.replace(params, use_mag=False)
            return estimate(flight.gyro_rad_s, flight.accel_m_s2, None, timestamps_s=flight.t_s,
                            params=p, velocity=degraded_velocity(flight, vin),
                            velocity_latency_s=vin.latency_s, offline=offline).quaternion

        return run

    return [Algorithm("cf_estimator_aided", runner(False), ours=True),
            Algorithm("cf_estimator_aided_offline", runner(True), ours=True)]


def _algorithms(peers: Sequence[str], velocity: VelocityInput | None) -> list[Algorithm]:
    """Ours (and, with ``velocity``, ours aided), then the named peers."""
    algos = [a for a in ALGORITHMS.values() if a.ours]
    if velocity is not None:
        algos += aided_algorithms(velocity)
    return algos + [ALGORITHMS[n] for n in peers]


#: The gyro fault of ``bench euroc --gyro-fault``: this rate [rad/s] added to the sensor x axis
#: ...
GYRO_FAULT_RATE_RAD_S = 3.0
#: ... for this long [s]: a 0.6 rad (34°) attitude error in one step, as a gyro over-range or a
#: glitch leaves it; every sample after it is true again.
GYRO_FAULT_DURATION_S = 0.2


def gyro_fault_fits(flight: Flight, at_s: float) -> bool:
    """The flight lasts beyond a gyro fault at ``at_s`` [s since its first sample]."""
    return float(flight.t_s[-1]) > at_s + GYRO_FAULT_DURATION_S


def with_gyro_fault(flight: Flight, at_s: float) -> Flight:
    """The flight with GYRO_FAULT_RATE_RAD_S added to its gyro's x axis [rad/s, sensor frame]
    on the samples in [at_s, at_s + GYRO_FAULT_DURATION_S) [s since its first sample];
    everything else, the ground truth included, unchanged. ValueError if the flight ends
    before the fault does."""
    end = at_s + GYRO_FAULT_DURATION_S
    if not gyro_fault_fits(flight, at_s):
        raise ValueError(f"{flight.name}: ends at {float(flight.t_s[-1]):.1f} s, before a gyro "
                         f"fault at {at_s:g} s is over")
    gyro = flight.gyro_rad_s.copy()
    gyro[(flight.t_s >= at_s) & (flight.t_s < end), 0] += GYRO_FAULT_RATE_RAD_S
    return dataclasses.replace(flight, gyro_rad_s=gyro)


#: Inclination error [deg] below which a velocity-aided estimate counts as having taken hold.
HOLD_THRESHOLD_DEG = 2.0
#: The hold is judged on the error's running median over this window [s] (centred): an
#: excursion shorter than half of it does not count. On the Phantom 4 flights the reference
#: and every estimator part for tens of milliseconds in the fastest rotations (H12_imu1 at
#: 16.9 s, 235 deg/s: ours online 5.0 deg, offline 4.7, the DOT's own filter 5.9 for 70 ms)
#: — the two systems' timing, not a filter's hold; judged sample by sample, the DOT's filter,
#: converged long before each recording starts, "took hold" after a median 31.3 s
#: (horizontal) and 21.0 s (vertical), 0 s with this window (bench euroc --peers onboard).
HOLD_TRANSIENT_S = 1.0


def time_to_hold_s(flight: Flight, q_est: np.ndarray, threshold_deg: float = HOLD_THRESHOLD_DEG
                   ) -> float:
    """Time [s] from the flight's first velocity sample until the inclination error, its
    running median over :data:`HOLD_TRANSIENT_S` (the samples with a ground truth), stays below
    ``threshold_deg`` for the rest of the flight; 0 if it already is, NaN if it never settles
    (or the flight has no velocity)."""
    from scipy.ndimage import median_filter

    if flight.velocity_t_s is None or len(flight.velocity_t_s) == 0:
        return math.nan
    t0 = float(flight.velocity_t_s[0])
    rows = np.flatnonzero(flight.has_reference & (flight.t_s >= t0))
    if rows.size == 0:
        return math.nan
    err = metrics.inclination_error_deg(q_est[rows], flight.q_ref[rows])
    spacing = float(np.median(np.diff(flight.t_s[rows]))) if rows.size > 1 else 1.0
    size = max(1, int(round(HOLD_TRANSIENT_S / spacing)) | 1)
    err = median_filter(np.where(np.isnan(err), np.inf, err), size=size, mode="nearest")
    bad = np.flatnonzero(~(err < threshold_deg))
    if bad.size == 0:
        return 0.0
    if bad[-1] == rows.size - 1:
        return math.nan
    return float(flight.t_s[rows[bad[-1] + 1]]) - t0


def evaluate_flight(flight: Flight, params: FilterParams, peers: Sequence[str] = (),
                    settle_s: float = SETTLE_S, velocity: VelocityInput | None = None
                    ) -> dict[str, dict[str, float]]:
    """``{algorithm: score}`` for ours (and, with ``velocity``, ours aided) and ``peers`` on one
    flight; with ``velocity`` every algorithm also gets ``hold_s`` (:func:`time_to_hold_s`)."""
    out = {}
    for a in _algorithms(peers, velocity):
        q = a.run(flight, params)
        out[a.name] = score_flight(flight, q, settle_s)
        if velocity is not None:
            out[a.name]["hold_s"] = time_to_hold_s(flight, q)
    return out


def median_hold_s(result: EurocResult, algorithm: str) -> tuple[float, int, int]:
    """(median hold_s over the flights that settle, flights that settle, flights)."""
    vals = [per.get(algorithm, {}).get("hold_s", math.nan) for per in result.flights.values()]
    ok = [v for v in vals if math.isfinite(v)]
    return (float(np.median(ok)) if ok else math.nan), len(ok), len(vals)


@dataclass
class EurocResult:
    """Per-flight scores ``flights[flight][algorithm] = {score: value}`` plus flight facts."""

    flights: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    info: dict[str, dict] = field(default_factory=dict)
    settle_s: float = SETTLE_S

    def algorithms(self) -> list[str]:
        """Algorithm names in first-seen order."""
        return list(dict.fromkeys(a for per in self.flights.values() for a in per))

    def mean(self, algorithm: str, score: str) -> float:
        """Mean over flights of a score (NaN if any flight lacks it or is NaN)."""
        vals = [per.get(algorithm, {}).get(score, math.nan) for per in self.flights.values()]
        return float(np.mean(vals)) if vals else math.nan

    def to_json(self) -> dict:
        """``{"settle_s", "flights": {...}, "mean": {algorithm: {score: deg}}, "info": {...}}``."""
        flights = {f: {a: {k: _json(v) for k, v in s.items()} for a, s in per.items()}
                   for f, per in self.flights.items()}
        keys = list(dict.fromkeys(k for per in self.flights.values() for sc in per.values()
                                  for k in sc if k != "n_scored"))
        mean = {a: {s: _json(self.mean(a, s)) for s in keys} for a in self.algorithms()}
        return {"settle_s": self.settle_s, "flights": flights, "mean": mean, "info": self.info}


def _json(v: float) -> float | int | None:
    if isinstance(v, int):
        return v
    return None if v is None or not math.isfinite(v) else round(float(v), 6)


def flight_info(flight: Flight) -> dict:
    """Facts about a flight for reports: path, ground truth, sample counts, notes."""
    has = flight.has_reference
    return {"path": str(flight.path), "groundtruth": str(flight.groundtruth_path),
            "samples": flight.n_samples, "samples_with_groundtruth": int(has.sum()),
            "duration_s": round(float(flight.t_s[-1]), 3), "rate_hz": round(flight.rate_hz, 3),
            "notes": list(flight.notes)}


def _worker(task: tuple) -> dict[str, dict[str, float]]:
    from cf_estimator.bench.parallel import aligned

    flight, params, peers, settle_s, velocity = task
    # aligned: a cluster's copy of the arrays
    return evaluate_flight(aligned(flight), params, peers, settle_s, velocity)


def run_euroc(flights: Sequence[Flight], params: FilterParams, peers: Sequence[str] = (),
              settle_s: float = SETTLE_S, jobs: int = 1, velocity: VelocityInput | None = None
              ) -> EurocResult:
    """Evaluate every flight (one process per flight when ``jobs`` > 1), order kept."""
    tasks = [(f, params, tuple(peers), settle_s, velocity) for f in flights]
    return _collect(flights, run_tasks(_worker, tasks, jobs), settle_s)


def _collect(flights: Sequence[Flight], scores: Sequence[dict], settle_s: float) -> EurocResult:
    """One result from each flight's scores (same order) and its facts."""
    result = EurocResult(settle_s=settle_s)
    for flight, per in zip(flights, scores, strict=True):
        result.flights[flight.name] = per
        result.info[flight.name] = flight_info(flight)
    return result


def format_table(result: EurocResult, scores: tuple[str, str] = SCORES) -> str:
    """Flights × algorithms, cells ``a / b`` [deg] of the two ``scores`` (default RMS / max),
    then the mean over flights."""
    algos = result.algorithms()
    names = list(result.flights)
    w = max([len(n) for n in names] + [len("mean")])
    cw = max([len(a) for a in algos] + [13])

    def cell(rms: float, peak: float) -> str:
        if not (math.isfinite(rms) and math.isfinite(peak)):
            return f"  {'nan':>{cw}}"
        return f"  {f'{rms:.2f} / {peak:.1f}':>{cw}}"

    lines = [f"  {'flight':<{w}}" + "".join(f"  {a:>{cw}}" for a in algos)]
    for n in names:
        per = result.flights[n]
        lines.append(f"  {n:<{w}}" + "".join(
            cell(per.get(a, {}).get(scores[0], math.nan), per.get(a, {}).get(scores[1], math.nan))
            for a in algos))
    lines.append(f"  {'mean':<{w}}" + "".join(
        cell(result.mean(a, scores[0]), result.mean(a, scores[1])) for a in algos))
    return "\n".join(lines) + "\n"
