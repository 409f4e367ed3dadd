"""Ablation held out family by family: paired per-recording deltas of a variant against a base.

Every recording of the dev data is scored with our filter online (the base parameters, then each
variant's), and each variant is compared with the base *recording by recording* on each family:
the mean paired delta (variant − base; positive = the variant is worse), its paired standard
error, and a sign test (how many recordings got better / worse). The spread between recordings
never enters: a family of 40 flights whose every flight moves by 0.02° is a real change.

Families (the score of one recording; lower is better):

- ``euroc``: EuRoC MH, ground start, inclination RMS after 10 s [deg];
- ``euroc_midair``: the same flights cropped to start 20 / 40 / 60 s in, RMS 12 s-end [deg];
- ``phantom4``, ``phantom4_horizontal``: inclination RMS after 10 s [deg], per recording;
- ``broad_<group>``: BROAD 6-D inclination RMSE per trial [deg], one family per trial group
  (a trial is in several groups); ``broad9d``: the 9-D total RMSE per trial [deg];
- ``autopilot``: the PX4 ulogs (``ulogs/``) and ArduPilot logs (``ardupilot/``), 6-D, against
  the autopilot's own attitude (vehicle_attitude, ATT) at its stamps, inclination RMS from
  AUTOPILOT_SETTLE_S after the first IMU sample to the end worth scoring (before a crash)
  [deg];
- ``multirotor``: the simulated in-air multirotor cases (zig-zags with the Phantom DOTs' bias,
  and with a de-biased gyro; figure-8s, tight and slow figure-8s on a de-biased gyro), inclination
  RMS after 10 s [deg], one recording per case and seed;
- ``handheld``: a simulated handheld sensor (:func:`handheld_case`): a rotation of up to
  250 °/s about a random axis every 8 s, a slow wobble, world-frame hand accelerations of
  about 1 m/s², a gyro without bias but with a 1-1.5 % scale error; inclination RMS after
  10 s [deg], one recording per seed (the held-back wand's and BROAD's fast rotations);
- ``thesis``: the thesis's impacts, vibration and acceleration, peak tilt [arcmin];
- ``compass``: a magnet of 0.3 / 0.5 / 1x the field on a turning sensor, heading RMS [deg].

Leave one family out (:func:`verdict`): for each family F, the variant is *chosen* on the other
families (their standardised deltas summed: negative = the variant wins there) and *checked* on
F. A mechanism (the base) stays against its ablation (the variant) when, chosen without any
family, it still helps or is neutral there; a variant that wins where chosen and does not lose
beyond 2 paired standard errors on any held-out family replaces the base.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cf_estimator.core.params import FilterParams

#: Recording families, in report order (``broad_<group>`` families are added per group found).
FAMILIES = ("euroc", "euroc_midair", "phantom4", "phantom4_horizontal", "broad", "broad9d",
            "autopilot", "multirotor", "handheld", "thesis", "compass")
MIDAIR_STARTS_S = (20.0, 40.0, 60.0)
#: (label, scenario, rate [Hz] or None, options): the simulated multirotor recordings.
MULTIROTOR_CASES: tuple[tuple[str, str, float | None, dict[str, Any]], ...] = (
    ("zigzag", "zigzag", None, {}),
    ("zigzag_debiased", "zigzag", None, {"gyro_bias_rad_s": (0.0, 0.0, 0.0)}),
    ("figure8", "circles", 200.0, {}),
    ("figure8_tight", "circles", 200.0, {"speed_m_s": 1.0, "turn_rate_rad_s": 1.5}),
    ("figure8_slow", "circles", 200.0, {"speed_m_s": 1.0, "turn_rate_rad_s": 0.4}),
)
MULTIROTOR_SEEDS = (0, 1, 2)
THESIS_CASES = ("impacts", "vibration", "acceleration")
HANDHELD_SEEDS = (0, 1, 2, 3, 4)
#: Start of the autopilot logs' scoring after their first IMU sample [s]: the shared ulogs are
#: 6-10 s long (the filter's start-up phase is 2 s).
AUTOPILOT_SETTLE_S = 2.0
COMPASS_FRACTIONS = (0.3, 0.5, 1.0)
#: The families the leave-one-family-out verdict holds out (BROAD by its two disjoint groups and
#: 9-D; the other BROAD groups overlap these and are reported only).
VERDICT_FAMILIES = ("euroc", "euroc_midair", "phantom4", "phantom4_horizontal",
                    "broad_undisturbed", "broad_disturbed", "broad9d", "autopilot", "multirotor",
                    "handheld", "thesis", "compass")
#: A delta beyond this many paired standard errors is a change, not noise.
NOISE_SE = 2.0
#: Requirements a family's every recording must meet (the thesis's ±90' under impacts,
#: vibration and acceleration): a variant that breaks one where the base met it is worse,
#: however few the recordings.
LIMITS = {"thesis": 90.0}

Scores = dict[str, dict[str, float]]  # family -> recording id -> score


# -- one recording, one score -----------------------------------------------------------------
def _flight_task(args: tuple) -> list[tuple[str, str, float]]:
    from cf_estimator.bench import euroc
    from cf_estimator.bench import euroc_eval as ev
    from cf_estimator.core.batch import estimate

    family, path, params = args
    flight = euroc.load_flight(path)
    p = dataclasses.replace(params, use_mag=False)
    out = []
    q = estimate(flight.gyro_rad_s, flight.accel_m_s2, None, timestamps_s=flight.t_s,
                 params=p).quaternion
    out.append((family, flight.name, ev.score_flight(flight, q)["inclination_rms_deg"]))
    if family == "euroc":
        for start in MIDAIR_STARTS_S:  # the flights bench cross crops (ev.run_midair)
            if flight.t_s[-1] - start <= ev.MIDAIR_WINDOWS[1][0]:
                continue
            crop = flight.cropped(start)
            q = estimate(crop.gyro_rad_s, crop.accel_m_s2, None, timestamps_s=crop.t_s,
                         params=p).quaternion
            out.append(("euroc_midair", f"{flight.name}@{start:g}",
                        ev.score_windows(crop, q)["late_rms_deg"]))
    return out


def _broad_task(args: tuple) -> list[tuple[str, str, float]]:
    from cf_estimator import metrics
    from cf_estimator.bench import broad
    from cf_estimator.bench.evaluate import run_ours

    path, info, params = args
    trial = broad.load_trial(path, info)
    qs = run_ours(trial, params)
    m6 = metrics.rmse_deg(qs["6d"], trial.quat_ref, trial.movement)["inclination_rmse_deg"]
    m9 = metrics.rmse_deg(qs["9d"], trial.quat_ref, trial.movement)["total_rmse_deg"]
    out = [("broad9d", trial.name, m9)]
    out += [(f"broad_{g}", trial.name, m6) for g in broad.trial_groups(trial.name, info)]
    return out


def _autopilot_task(args: tuple) -> list[tuple[str, str, float]]:
    from cf_estimator.bag.io import BagError
    from cf_estimator.bag.logarrays import log_arrays
    from cf_estimator.core.batch import estimate
    from cf_estimator.metrics import inclination_error_deg

    path, params = args
    try:
        log = log_arrays(path)
    except BagError:
        return []
    if log.reference_topic is None or log.t_s.shape[0] < 2:
        return []
    p = dataclasses.replace(params, use_mag=False, world_frame="ned")
    with warnings.catch_warnings():  # a crash's spin past the gyro's range is part of the log
        warnings.simplefilter("ignore")
        q = estimate(log.gyro_rad_s, log.accel_m_s2, None, timestamps_s=log.t_s,
                     params=p).quaternion
    # our estimate at each of the autopilot's stamps: the last IMU row at or before it
    row = np.searchsorted(log.t_s, log.reference_t_s, side="right") - 1
    until = math.inf if log.scored_until_s is None else log.scored_until_s
    keep = ((row >= 0) & (log.reference_t_s >= log.t_s[0] + AUTOPILOT_SETTLE_S)
            & (log.reference_t_s <= until))
    if not np.any(keep):
        return []
    e = inclination_error_deg(q[row[keep]], log.reference_q_wxyz[keep])
    e = e[np.isfinite(e)]
    return [("autopilot", Path(path).name, float(np.sqrt(np.mean(e * e))))] if e.size else []


def _multirotor_task(args: tuple) -> list[tuple[str, str, float]]:
    from cf_estimator.bench.euroc_eval import SETTLE_S
    from cf_estimator.core.batch import estimate
    from cf_estimator.metrics import tilt_error_rad
    from cf_estimator.scenarios import make_scenario

    label, name, rate, options, seed, params = args
    sc = make_scenario(name, rate_hz=rate, seed=seed, **options)
    imu = sc.imu
    q = estimate(imu.gyro_rad_s, imu.accel_m_s2, None, timestamps_s=imu.t_s,
                 params=dataclasses.replace(params, use_mag=False)).quaternion
    e = np.degrees(tilt_error_rad(q, sc.truth.q_world_from_body))[imu.t_s >= SETTLE_S]
    return [("multirotor", f"{label}/{seed}", float(np.sqrt(np.mean(e * e))))]


def handheld_case(seed: int, rate_hz: float = 200.0, duration_s: float = 90.0
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A handheld sensor: (t [s], gyro [rad/s], accel [m/s²], q_world(ENU)_from_sensor truth).

    Every 8 s from 4 s, a 1.5 s rotation of peak 250 °/s (half a sine) about a random body
    axis; a slow wobble of 0.2 rad/s per axis; hand accelerations (sums of sines, about
    1 m/s² per horizontal axis, 0.7 m/s² vertical, world frame); a gyro with a scale error of
    +1.5 / −1.5 / +1 % and 0.003 rad/s noise, no bias; accelerometer noise 0.05 m/s²."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    t = np.arange(int(duration_s * rate_hz)) * dt
    w = 0.2 * np.stack([np.sin(0.7 * t), np.sin(0.5 * t + 1.0), np.sin(0.3 * t + 2.0)], 1)
    for k in range(int(duration_s // 8)):
        t0 = 4.0 + 8.0 * k
        axis = rng.normal(size=3)
        on = (t >= t0) & (t < t0 + 1.5)
        w[on] += np.outer(np.sin(np.pi * (t[on] - t0) / 1.5) * np.radians(250.0),
                          axis / np.linalg.norm(axis))
    steps = Rotation.from_rotvec(w[:-1] * dt)
    q = [Rotation.identity()]
    for r in steps:
        q.append(q[-1] * r)
    world_from_sensor = Rotation.concatenate(q)
    a_world = np.stack([np.sin(1.3 * t) + 0.5 * np.sin(3.1 * t),
                        np.cos(1.1 * t) + 0.5 * np.sin(2.3 * t), 0.7 * np.sin(1.7 * t)], 1)
    accel = world_from_sensor.inv().apply(a_world + np.array([0.0, 0.0, 9.80665]))
    accel += rng.normal(scale=0.05, size=accel.shape)
    gyro = w * np.array([1.015, 0.985, 1.01]) + rng.normal(scale=0.003, size=w.shape)
    return t, gyro, accel, world_from_sensor.as_quat()[:, [3, 0, 1, 2]]


def _handheld_task(args: tuple) -> list[tuple[str, str, float]]:
    from cf_estimator.bench.euroc_eval import SETTLE_S
    from cf_estimator.core.batch import estimate
    from cf_estimator.metrics import inclination_error_deg

    seed, params = args
    t, gyro, accel, q_true = handheld_case(seed)
    q = estimate(gyro, accel, None, timestamps_s=t,
                 params=dataclasses.replace(params, use_mag=False)).quaternion
    e = inclination_error_deg(q, q_true)[t >= SETTLE_S]
    return [("handheld", str(seed), float(np.sqrt(np.mean(e * e))))]


def _thesis_task(args: tuple) -> list[tuple[str, str, float]]:
    from cf_estimator.bench.scenarios import peak_rms_arcmin, scenario_masks
    from cf_estimator.core.batch import estimate
    from cf_estimator.scenarios import make_scenario

    name, params = args
    sc = make_scenario(name, seed=0)
    imu = sc.imu
    q = estimate(imu.gyro_rad_s, imu.accel_m_s2, None, timestamps_s=imu.t_s,
                 params=dataclasses.replace(params, use_mag=False)).quaternion
    return [("thesis", name, peak_rms_arcmin(q, sc.truth.q_world_from_body,
                                             scenario_masks(sc))[0])]


def _compass_task(args: tuple) -> list[tuple[str, str, float]]:
    from cf_estimator.core.batch import estimate
    from cf_estimator.scenarios.compass import heading_error_deg, magnet_on_turning_sensor

    fraction, seed, params = args
    c = magnet_on_turning_sensor(seed, fraction)
    q = estimate(c.gyro_rad_s, c.accel_m_s2, c.mag_T, rate_hz=c.rate_hz,
                 params=dataclasses.replace(params, use_mag=True)).quaternion
    e = heading_error_deg(q, c.q_true)[c.magnet_on]
    return [("compass", f"{fraction:g}x/{seed}", float(np.sqrt(np.mean(e * e))))]


def _run(task: tuple) -> list[tuple[str, str, float]]:
    kind, args = task
    return _WORKERS[kind](args)


_WORKERS: dict[str, Callable[[tuple], list[tuple[str, str, float]]]] = {
    "flight": _flight_task, "broad": _broad_task, "autopilot": _autopilot_task,
    "multirotor": _multirotor_task,
    "handheld": _handheld_task, "thesis": _thesis_task, "compass": _compass_task,
}


def tasks_for(data: str | Path, params: FilterParams, families: Sequence[str] = FAMILIES
              ) -> list[tuple[str, tuple]]:
    """The work for one parameter set: (worker kind, arguments) per recording; recorded
    families whose folder is missing under ``data`` are left out."""
    from cf_estimator.bench import broad, euroc

    root = Path(data)
    want = set(families)
    tasks: list[tuple[str, tuple]] = []
    for fam in ("euroc", "phantom4", "phantom4_horizontal"):
        if (fam in want or (fam == "euroc" and "euroc_midair" in want)) and (root / fam).is_dir():
            tasks += [("flight", (fam, str(p), params)) for p in euroc.find_flights(root / fam)]
    if want & {"broad", "broad9d"} and (root / "broad").is_dir():
        info = broad.read_trial_info(root / "broad")
        tasks += [("broad", (str(p), info, params)) for p in broad.list_trials(root / "broad")]
    if "autopilot" in want:
        logs = [p for sub in ("ulogs", "ardupilot") if (root / sub).is_dir()
                for p in sorted((root / sub).iterdir()) if p.suffix.lower() in (".ulg", ".bin")]
        tasks += [("autopilot", (str(p), params)) for p in logs]
    if "multirotor" in want:
        tasks += [("multirotor", (label, name, rate, opts, seed, params))
                  for label, name, rate, opts in MULTIROTOR_CASES for seed in MULTIROTOR_SEEDS]
    if "handheld" in want:
        tasks += [("handheld", (seed, params)) for seed in HANDHELD_SEEDS]
    if "thesis" in want:
        tasks += [("thesis", (name, params)) for name in THESIS_CASES]
    if "compass" in want:
        tasks += [("compass", (f, seed, params)) for f in COMPASS_FRACTIONS for seed in (0, 1)]
    return tasks


def score_all(data: str | Path, params: FilterParams, families: Sequence[str] = FAMILIES,
              jobs: int = 2) -> Scores:
    """Score every recording of ``families`` with ``params`` (ours online)."""
    from cf_estimator.bench.parallel import run_tasks

    scores: Scores = {}
    want = set(families)
    for chunk in run_tasks(_run, tasks_for(data, params, families), jobs):
        for family, rec, value in chunk:
            if family in want or (family.startswith("broad_") and "broad" in want):
                scores.setdefault(family, {})[rec] = float(value)
    return scores


# -- paired comparison ------------------------------------------------------------------------
@dataclass(frozen=True)
class Paired:
    """One family's paired comparison of a variant against the base."""

    family: str
    n: int
    base_mean: float
    delta_mean: float  # variant − base, mean over recordings (positive: variant worse)
    delta_se: float  # paired standard error of delta_mean
    better: int  # recordings where the variant is lower by more than 1e-9
    worse: int
    sign_p: float  # two-sided sign test p-value
    broken: int = 0  # recordings beyond the family's limit (LIMITS) only with the variant

    @property
    def z(self) -> float:
        """delta_mean in paired standard errors (0 when there is no spread)."""
        if self.delta_se > 0.0:
            return self.delta_mean / self.delta_se
        return 0.0 if self.delta_mean == 0.0 else math.copysign(math.inf, self.delta_mean)

    @property
    def change(self) -> str:
        """'worse', 'better' or 'same' (beyond NOISE_SE paired standard errors; worse too when
        the variant breaks the family's limit on a recording)."""
        if self.z > NOISE_SE or self.broken:
            return "worse"
        if self.z < -NOISE_SE:
            return "better"
        return "same"


def sign_test_p(better: int, worse: int) -> float:
    """Two-sided exact sign test p-value for ``better`` vs ``worse`` (ties dropped)."""
    n = better + worse
    if n == 0:
        return 1.0
    k = min(better, worse)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2.0 ** n
    return min(1.0, 2.0 * tail)


def paired(family: str, base: Mapping[str, float], variant: Mapping[str, float]) -> Paired:
    """The paired comparison over the recordings both have a finite score for."""
    keys = [k for k in base if k in variant and math.isfinite(base[k])
            and math.isfinite(variant[k])]
    d = np.array([variant[k] - base[k] for k in keys])
    n = len(keys)
    se = float(np.std(d, ddof=1) / math.sqrt(n)) if n > 1 else 0.0
    better, worse = int(np.sum(d < -1e-9)), int(np.sum(d > 1e-9))
    limit = LIMITS.get(family, math.inf)
    broken = sum(1 for k in keys if variant[k] > limit >= base[k])
    return Paired(family, n, float(np.mean([base[k] for k in keys])) if n else math.nan,
                  float(np.mean(d)) if n else math.nan, se, better, worse,
                  sign_test_p(better, worse), broken)


def compare(base: Scores, variant: Scores) -> list[Paired]:
    """Paired comparisons for every family both score sets have."""
    return [paired(f, base[f], variant[f]) for f in ordered(base) if f in variant]


def ordered(scores: Iterable[str]) -> list[str]:
    """Families in report order (the BROAD groups after 'broad', in name order)."""
    names = list(scores)
    rank = {f: i for i, f in enumerate(FAMILIES)}
    return sorted(names, key=lambda f: (rank.get("broad" if f.startswith("broad_") else f,
                                                 len(FAMILIES)), f))


def verdict(rows: Sequence[Paired]) -> tuple[str, list[str]]:
    """Leave one family out over :data:`VERDICT_FAMILIES` → (choice, losers).

    For each family F the variant is chosen or not on the other families (their paired
    z-scores summed: negative = the variant wins there) and checked on F. 'variant' when it
    is chosen without every family and no held-out family loses beyond the noise; 'variant
    (neutral: fewer knobs)' when no family changes beyond the noise at all; otherwise 'base',
    with the families on which the variant, chosen without them, loses. Families of one
    recording (no paired noise) do not vote."""
    z = {r.family: 10.0 if r.broken else max(-10.0, min(10.0, r.z)) for r in rows
         if r.n > 1 and r.family in VERDICT_FAMILIES}
    if not any(abs(v) > NOISE_SE for v in z.values()):
        return "variant (neutral: fewer knobs)", []
    losers, always_chosen = [], True
    for fam in z:
        chosen = sum(v for f, v in z.items() if f != fam) < 0.0
        always_chosen = always_chosen and chosen
        if chosen and z[fam] > NOISE_SE:
            losers.append(fam)
    if always_chosen and not losers:
        return "variant", []
    return "base", losers


def format_comparison(name: str, rows: Sequence[Paired], unit_of: Callable[[str], str]) -> str:
    """One variant's table: per family n, base mean, mean delta ± paired SE, better/worse."""
    lines = [f"{name}", f"  {'family':32s} {'n':>3s} {'base':>8s} {'delta':>9s} {'± SE':>8s} "
                        f"{'better/worse':>12s} {'sign p':>7s}  change"]
    for r in rows:
        lines.append(f"  {r.family:32s} {r.n:3d} {r.base_mean:8.3f} {r.delta_mean:+9.3f} "
                     f"{r.delta_se:8.3f} {r.better:5d}/{r.worse:<6d} {r.sign_p:7.3f}  "
                     f"{r.change} [{unit_of(r.family)}]")
    choice, losers = verdict(rows)
    lines.append(f"  leave-one-family-out: {choice}"
                 + (f" (chosen without them, the variant loses on {', '.join(losers)})"
                    if losers else ""))
    return "\n".join(lines)


def unit_of(family: str) -> str:
    """The score's unit of a family."""
    return {"thesis": "arcmin"}.get(family, "deg")


def parse_override(text: str) -> tuple[str, Any]:
    """``name=value`` → (name, value) with the FilterParams field's type."""
    name, _, raw = text.partition("=")
    fields = {f.name: f for f in dataclasses.fields(FilterParams)}
    if name not in fields or not raw:
        raise ValueError(f"not a filter parameter override NAME=VALUE: {text!r}")
    kind = type(getattr(FilterParams(), name))
    if kind is bool:
        if raw.lower() not in ("true", "false", "1", "0"):
            raise ValueError(f"{name} takes true or false, not {raw!r}")
        return name, raw.lower() in ("true", "1")
    return name, kind(raw)
