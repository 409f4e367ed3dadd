"""Cross-dataset table: every family of the dev data in one table, ours beside VQF.

One row per family and window, four columns: our filter online and offline, VQF online and
offline (its own offline mode). Rows (inclination [deg] unless marked):

- EuRoC MH, ground start: RMS after the first 10 s, mean over flights;
- EuRoC MH, mid-air starts (each flight cropped to start 20, 40, 60 s in): RMS 2-12 s and
  12 s-end after that start;
- phantom4 (vertical zig-zags) and phantom4_horizontal (horizontal zig-zags, sustained
  acceleration): RMS after the first 10 s, mean and worst recording;
- BROAD: 6-D inclination RMSE and 9-D total RMSE per trial group;
- thesis scenarios (simulated, 6-D): peak tilt error [arcmin] in the disturbance windows;
- covariance consistency (issue 27), per data family, our online filter only: the share of
  samples whose error is beyond 2σ [%] and mean(e²/σ²) [1], σ the reported orientation
  covariance (tilt: √(cov[0] + cov[4]), 6-D; heading: √cov[8], BROAD 9-D), after 10 s
  (:mod:`cf_estimator.bench.consistency`; a consistent Gaussian: tilt 1.8 %, heading 4.6 %,
  mean 1), and for the tilt the share beyond twice its per-axis σ (13.5 %: issue 27's 14 %);
- compass (simulated, 9-D): a magnet of 0.3, 0.5 and 1x the Earth field fixed to a turning
  sensor for 60 s (:mod:`cf_estimator.scenarios.compass`, a calibrated magnetometer's
  residue): heading error [deg] while it is on, peak and RMS, mean over COMPASS_SEEDS;
- multirotor (simulated, 6-D, :mod:`cf_estimator.scenarios`): the sustained-acceleration
  cases of issue 22, in the air from the first sample — horizontal zig-zags like the Phantom's
  (``zigzag``, 120 Hz, the DOTs' bias size) and figure-8s on a de-biased gyro (``circles``, at
  1 kHz and at 100 Hz, 3 m/s at 0.6 rad/s; and tight ones at 1 kHz, 1 m/s at 1.5 rad/s, a
  nano-quadrotor's: VQF won them, as on the real nano-quadrotor of issue 22, until the bias was
  learned through the aperiodic unit's own lag, step.learning_input; and slow ones at 1 kHz,
  1 m/s at 0.4 rad/s, near the loop's bandwidth, where the in-flight learning takes the bank
  for a pitch-rate bias and VQF wins, as on the held-back nano-quadrotor of issue 50): inclination
  RMS and peak after 10 s [deg], and the learned gyro bias's error at the end |b − b_true|
  [deg/s] (ours and VQF's, online columns), mean over MULTIROTOR_SEEDS;
- aided (6-D, velocity aiding, :mod:`cf_estimator.core.velocity`): ours aided online and
  offline in our two columns (VQF takes no velocity: '-'): phantom4 and phantom4_horizontal with
  their RTK velocity as given, EuRoC with its ground truth's velocity degraded to GNSS quality
  (10 Hz, 0.1 m/s, 100 ms late, as ``bench euroc --velocity-rate 10 --velocity-noise 0.1
  --velocity-latency 0.1``) from the ground and from the mid-air starts
  (12 s-end), and the median time from the first velocity sample until the inclination error
  stays below 2° (:func:`~cf_estimator.bench.euroc_eval.time_to_hold_s`), the thesis
  acceleration manoeuvre with a simulated GNSS velocity (peak [arcmin]), and BROAD's 18 trials
  aided by a 10 Hz velocity made of their optical positions
  (:func:`~cf_estimator.bench.broad.optical_velocity`; handheld motion up to 8 g, 9-D total
  and 6-D inclination, online only: the one aided family with a compass).

Families whose data directory is missing are left out (a note says so). A default changes only
when no row gets worse beyond its noise (docs/decisions/0002-ablation-held-out-by-family.md):
the rows that are means over recordings keep our columns' per-recording values
(``Row.members``, in the JSON), which test/test_cross_table.py pairs with the committed
report's, recording by recording.

``peers`` (``bench report``; ``bench cross`` itself prints our two columns and VQF's) adds
columns for the other peers of :mod:`cf_estimator.bench.peers` — x-io Fusion, Madgwick,
imu_complementary_filter — at the settings their authors give, on every row a peer can run
(not the aided and consistency rows, nor the learned-bias rows: ours and VQF's only), and
``onboard`` (the Xsens DOTs' own filter, recorded) on the phantom4 rows.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from cf_estimator.core.params import FilterParams

if TYPE_CHECKING:
    from cf_estimator.bench.consistency import Floors
    from cf_estimator.bench.euroc_eval import VelocityInput

COLUMNS = ("cf_estimator", "cf_estimator_offline", "vqf", "vqf_offline")
#: Our columns (online, offline): the ones whose rows keep their per-recording values (Row.members).
OURS = COLUMNS[:2]
FAMILIES = ("euroc", "phantom4", "phantom4_horizontal", "broad", "scenarios", "compass",
            "multirotor", "handheld", "aided")
#: Simulated families (no data directory needed).
SIMULATED = ("scenarios", "compass", "multirotor", "handheld")
#: The aided rows' recorded families (data directories) and the label of each.
AIDED_FAMILIES = (("phantom4_horizontal", "phantom4 horizontal"), ("phantom4", "phantom4"),
                  ("euroc", "EuRoC MH"))
COMPASS_FRACTIONS = (0.3, 0.5, 1.0)
COMPASS_SEEDS = (0, 1, 2, 3)
MIDAIR_STARTS_S = (20.0, 40.0, 60.0)
#: The simulated multirotor cases: (label, scenario name, rate [Hz] or None for its own, the
#: scenario's keyword arguments).
MULTIROTOR_CASES: tuple[tuple[str, str, float | None, dict[str, float]], ...] = (
    ("zig-zags 4 m/s², 120 Hz", "zigzag", None, {}),
    ("figure-8s 1.8 m/s², 1 kHz", "circles", None, {}),
    ("figure-8s 1.8 m/s², 100 Hz", "circles", 100.0, {}),
    ("tight figure-8s 1.5 m/s², 1 kHz", "circles", None,
     {"speed_m_s": 1.0, "turn_rate_rad_s": 1.5}),
    # turns near the loop's bandwidth (k1 0.35 1/s): the bank × the turn rate reads as a
    # pitch-rate bias, the held-back nano-quadrotor's loss (issue 50; decision 0010)
    ("slow figure-8s 0.4 m/s², 1 kHz", "circles", None,
     {"speed_m_s": 1.0, "turn_rate_rad_s": 0.4}),
)
MULTIROTOR_SEEDS = (0, 1, 2)
SCENARIOS = ("impacts", "vibration", "acceleration")


def _euroc_gnss() -> VelocityInput:
    """EuRoC's ground-truth velocity degraded to GNSS quality (the aided rows)."""
    from cf_estimator.bench.euroc_eval import VelocityInput

    return VelocityInput(rate_hz=10.0, noise_m_s=0.1, latency_s=0.1)


@dataclass
class Row:
    """One row: ``values[column]`` in ``unit`` (NaN: not run / not applicable).

    ``noise[column]``: the standard error of the row's mean over its recordings (sample standard
    deviation / √n, in ``unit``; NaN for a single recording or a maximum): the spread between
    recordings, for the reader. ``members[column]``: our columns' value per recording (flight,
    trial, seed) of a row that is a mean or median over recordings: what a regression guard
    pairs, recording by recording, against the committed report (test/test_cross_table.py).
    """

    family: str
    label: str
    unit: str
    values: dict[str, float] = field(default_factory=dict)
    noise: dict[str, float] = field(default_factory=dict)
    members: dict[str, dict[str, float]] = field(default_factory=dict)


def standard_error(values: Iterable[float]) -> float:
    """Sample standard deviation / √n of ``values`` (NaN below two values or with a NaN)."""
    vals = [float(v) for v in values]
    if len(vals) < 2 or not all(math.isfinite(v) for v in vals):
        return math.nan
    return statistics.stdev(vals) / math.sqrt(len(vals))


def _runnable(peers: Sequence[str]) -> list[str]:
    """The peers among ``peers`` that run on arrays (:func:`cf_estimator.bench.peers.runners`):
    not a peer's offline mode (run beside its online one) nor a recorded filter."""
    from cf_estimator.bench.peers import PEERS

    return [p for p in peers if p in PEERS]


@dataclass
class CrossResult:
    """The rows in table order, the columns (ours, VQF's, then any other peers asked for), and
    notes (families left out, peers missing)."""

    rows: list[Row] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    columns: list[str] = field(default_factory=lambda: list(COLUMNS))

    def to_json(self) -> dict:
        """``{"columns", "rows": [{family, label, unit, values, noise[, members]}], "notes"}``
        (NaN → null; values and noise to 4 decimals, members to 6)."""
        def clean(v: float, digits: int = 4) -> float | None:
            return None if not math.isfinite(v) else round(float(v), digits)

        cols = self.columns
        rows = []
        for r in self.rows:
            row: dict[str, Any] = {
                "family": r.family, "label": r.label, "unit": r.unit,
                "values": {c: clean(r.values.get(c, math.nan)) for c in cols},
                "noise": {c: clean(r.noise.get(c, math.nan)) for c in cols}}
            if r.members:
                row["members"] = {c: {k: clean(v, 6) for k, v in m.items()}
                                  for c, m in r.members.items()}
            rows.append(row)
        return {"columns": list(cols), "notes": list(self.notes), "rows": rows}


class _Flights:
    """Each EuRoC-layout folder's flights, loaded once per table (its plain and aided rows
    read the same recordings)."""

    def __init__(self) -> None:
        self._loaded: dict[Path, list[Any]] = {}

    def __call__(self, folder: Path) -> list[Any]:
        from cf_estimator.bench import euroc

        if folder not in self._loaded:
            self._loaded[folder] = euroc.load_flights(folder)
        return self._loaded[folder]


def _euroc_rows(flights: list[Any], params: FilterParams, peers: Sequence[str], jobs: int,
                family: str, label: str, midair: bool,
                columns: Sequence[str] = COLUMNS) -> list[Row]:
    from cf_estimator.bench import euroc_eval as ev

    res = ev.run_euroc(flights, params, peers, ev.SETTLE_S, jobs=jobs)
    start = ", ground start" if midair else ""

    def noise(found: ev.EurocResult, c: str, score: str) -> float:
        return standard_error([per.get(c, {}).get(score, math.nan)
                               for per in found.flights.values()])

    mean = Row(family, f"{label}{start}, after 10 s: mean", "deg",
               {c: res.mean(c, "inclination_rms_deg") for c in columns},
               {c: noise(res, c, "inclination_rms_deg") for c in columns},
               _flight_members(res, "inclination_rms_deg"))
    rows = [mean]
    if not midair:
        rows.append(Row(family, f"{label}, after 10 s: worst recording", "deg",
                        {c: max(per.get(c, {}).get("inclination_rms_deg", math.nan)
                                for per in res.flights.values()) for c in columns}))
        return rows
    for start in MIDAIR_STARTS_S:
        mid = ev.run_midair(flights, params, start, peers, jobs=jobs)
        for key, window in zip(ev.MIDAIR_SCORES, ("2-12 s", "12 s-end"), strict=True):
            rows.append(Row(family, f"{label}, mid-air start {start:g} s: {window}", "deg",
                            {c: mid.mean(c, key) for c in columns},
                            {c: noise(mid, c, key) for c in columns},
                            _flight_members(mid, key)))
    return rows


def _flight_members(found: Any, score: str, columns: Mapping[str, str] | None = None
                    ) -> dict[str, dict[str, float]]:
    """Row.members of an EuRoC-layout result: our columns' ``score`` per flight
    (``columns``: column → the algorithm that fills it, ours online and offline by default)."""
    columns = columns or {c: c for c in OURS}
    return {c: {f: per.get(a, {}).get(score, math.nan) for f, per in found.flights.items()}
            for c, a in columns.items()}


def _broad_rows(root: Path, params: FilterParams, peers: Sequence[str], jobs: int,
                columns: Sequence[str] = COLUMNS) -> list[Row]:
    from cf_estimator.bench import broad
    from cf_estimator.bench.evaluate import run_broad

    paths = broad.list_trials(root)
    res = run_broad(paths, broad.read_trial_info(root), params, peers, jobs)
    rows = []

    def noise(members: Sequence[str], algorithm: str, metric: str) -> float:
        return standard_error([res.trials[t].get(algorithm, {}).get(metric, math.nan)
                               for t in members])

    for group, members in res.group_members().items():
        rows.append(Row("broad", f"BROAD {group} ({len(members)}): 6-D inclination", "deg",
                        {c: res.group_mean(members, f"{c}_6d", "inclination_rmse_deg")
                         for c in columns},
                        {c: noise(members, f"{c}_6d", "inclination_rmse_deg") for c in columns},
                        {c: {t: res.trials[t].get(f"{c}_6d", {}).get("inclination_rmse_deg",
                                                                      math.nan)
                             for t in members} for c in OURS}))
    for group, members in res.group_members().items():
        rows.append(Row("broad", f"BROAD {group} ({len(members)}): 9-D total", "deg",
                        {c: res.group_mean(members, f"{c}_9d", "total_rmse_deg")
                         for c in columns},
                        {c: noise(members, f"{c}_9d", "total_rmse_deg") for c in columns},
                        {c: {t: res.trials[t].get(f"{c}_9d", {}).get("total_rmse_deg", math.nan)
                             for t in members} for c in OURS}))
    return rows


def _compass_case(args: tuple[float, int, FilterParams, tuple[str, ...], Floors]
                  ) -> tuple[float, dict[str, tuple]]:
    """(fraction, {column: (peak, rms)}) of the heading error while the magnet is on."""
    import numpy as np

    from cf_estimator.bench import peers as peer_mod
    from cf_estimator.core.batch import estimate
    from cf_estimator.scenarios.compass import heading_error_deg, magnet_on_turning_sensor

    fraction, seed, params, peers, floors = args
    params = dataclasses.replace(params, use_mag=True)
    c = magnet_on_turning_sensor(seed, fraction)
    qs = {}
    var = None
    for col, offline in (("cf_estimator", False), ("cf_estimator_offline", True)):
        r = estimate(c.gyro_rad_s, c.accel_m_s2, c.mag_T, rate_hz=c.rate_hz, params=params,
                     offline=offline)
        qs[col] = r.quaternion
        if not offline:  # the reported heading variance, for the consistency rows
            var = floors.covariance(r)[:, 8][c.magnet_on]
    if "vqf" in peers:
        qs["vqf"] = peer_mod.run_vqf(c.gyro_rad_s, c.accel_m_s2, c.mag_T, c.rate_hz)["9d"]
        qs["vqf_offline"] = peer_mod.run_vqf_offline(c.gyro_rad_s, c.accel_m_s2, c.mag_T,
                                                     c.rate_hz)["9d"]
    runners = peer_mod.runners()
    for p in _runnable(peers):
        if p != "vqf":
            qs[p] = runners[p](c.gyro_rad_s, c.accel_m_s2, c.mag_T, c.rate_hz, ("9d",))["9d"]
    out = {}
    for col, q in qs.items():
        e = heading_error_deg(q, c.q_true)[c.magnet_on]
        out[col] = (float(np.max(e)), float(np.sqrt(np.mean(e * e))))
        if col == "cf_estimator":
            out["_consistency"] = (np.radians(e), var)
    return fraction, out


def _compass_rows(params: FilterParams, peers: Sequence[str], jobs: int,
                  floors: Floors, columns: Sequence[str] = COLUMNS) -> list[Row]:
    import numpy as np

    from cf_estimator.bench.parallel import run_tasks

    work = [(f, s, params, tuple(peers), floors) for f in COMPASS_FRACTIONS
            for s in COMPASS_SEEDS]
    found = run_tasks(_compass_case, work, jobs)
    rows = []
    for fraction in COMPASS_FRACTIONS:
        runs = [out for f, out in found if f == fraction]
        for i, what in enumerate(("peak", "RMS")):
            cols = [c for c in columns if all(c in r for r in runs)]
            rows.append(Row("compass", f"magnet {fraction:g}x on a turning sensor: heading {what}",
                            "deg", {c: sum(r[c][i] for r in runs) / len(runs) for c in cols},
                            {c: standard_error([r[c][i] for r in runs]) for c in cols},
                            {c: {f"seed {s}": r[c][i]
                                 for s, r in zip(COMPASS_SEEDS, runs, strict=True)}
                             for c in OURS}))
    from cf_estimator.bench.consistency import consistency

    for fraction in COMPASS_FRACTIONS:  # the reported heading sigma while the magnet is on
        parts = [out["_consistency"] for f, out in found if f == fraction]
        k = consistency(np.concatenate([p[0] for p in parts]),
                        np.concatenate([p[1] for p in parts]))
        label = f"magnet {fraction:g}x on a turning sensor: heading"
        rows.append(Row("compass", f"{label} beyond 2σ (consistent 4.6 %)", "%",
                        {"cf_estimator": k["beyond_2sigma_pct"]}))
        rows.append(Row("compass", f"{label} mean(e²/σ²) (consistent 1)", "1",
                        {"cf_estimator": k["mean_ratio"]}))
    return rows


def _simulated_6d(g: Any, a: Any, t: Any, rate_hz: float, truth: Any, params: FilterParams,
                  peers: Sequence[str]) -> tuple[dict[str, tuple[float, ...]], Any, Any, Any]:
    """Ours online and offline and the peers, 6-D, on one simulated recording (gyro [rad/s],
    accelerometer [m/s²], stamps [s], the truth q_world(ENU)_from_sensor): ({column: (RMS,
    peak) [deg] after SETTLE_S}, our online result, VQF online's output or None, the mask of
    the scored samples)."""
    import numpy as np

    from cf_estimator.bench import peers as peer_mod
    from cf_estimator.bench.euroc_eval import SETTLE_S
    from cf_estimator.core.batch import estimate
    from cf_estimator.metrics import tilt_error_rad

    p6 = dataclasses.replace(params, use_mag=False)
    runs = {col: estimate(g, a, None, timestamps_s=t, params=p6, offline=off)
            for col, off in (("cf_estimator", False), ("cf_estimator_offline", True))}
    qs = {col: r.quaternion for col, r in runs.items()}
    vqf = None
    if "vqf" in peers:
        vqf = peer_mod.run_vqf(g, a, None, rate_hz)
        qs["vqf"] = vqf["6d"]
        qs["vqf_offline"] = peer_mod.run_vqf_offline(g, a, None, rate_hz)["6d"]
    runners = peer_mod.runners()
    for p in _runnable(peers):
        if p != "vqf":
            qs[p] = runners[p](g, a, None, rate_hz, ("6d",))["6d"]
    after = t >= SETTLE_S
    out: dict[str, tuple[float, ...]] = {}
    for col, q in qs.items():
        e = np.degrees(tilt_error_rad(q, truth))[after]
        out[col] = (float(np.sqrt(np.mean(e * e))), float(np.max(e)))
    return out, runs["cf_estimator"], vqf, after


def _seed_rows(family: str, label: str, whats: Sequence[tuple[str, str]], runs: Sequence[dict],
               seeds: Sequence[int], columns: Sequence[str]) -> list[Row]:
    """One row per (what, unit) of ``whats``: element i of each seed's tuple per column, mean
    over the seeds, its standard error, and our columns' per-seed values (the paired guards)."""
    rows = []
    n = len(seeds)
    for i, (what, unit) in enumerate(whats):
        cols = [c for c in columns if all(len(r.get(c, ())) > i for r in runs)]
        rows.append(Row(family, f"simulated {label}: {what}", unit,
                        {c: sum(r[c][i] for r in runs) / n for c in cols},
                        {c: standard_error([r[c][i] for r in runs]) for c in cols},
                        {c: {f"seed {s}": r[c][i] for s, r in zip(seeds, runs, strict=True)}
                         for c in OURS if c in cols}))
    return rows


#: The inclination rows of a simulated recording: (what, unit) of :func:`_simulated_6d`'s pair.
INCLINATION_ROWS = (("inclination RMS after 10 s", "deg"), ("inclination peak after 10 s", "deg"))


def _multirotor_case(args: tuple[str, float | None, dict[str, float], int, FilterParams,
                                  tuple[str, ...], Floors]) -> dict[str, tuple]:
    """{column: (RMS, peak) [deg] after 10 s}; ours and VQF online also the learned-bias error
    at the end [deg/s] as a third element; ``_consistency``: ours online's tilt error [rad] and
    its reported variance [rad²] after 10 s (the consistency rows)."""
    import numpy as np

    from cf_estimator.metrics import tilt_error_rad
    from cf_estimator.scenarios import make_scenario

    name, rate, kwargs, seed, params, peers, floors = args
    sc = make_scenario(name, rate_hz=rate, seed=seed, **kwargs)
    truth = sc.truth.q_world_from_body
    out, ours, vqf, after = _simulated_6d(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, sc.imu.t_s,
                                          sc.rate_hz, truth, params, peers)
    bias = {"cf_estimator": ours.gyro_bias_rad_s[-1]}
    if vqf is not None:
        bias["vqf"] = vqf["bias"][-1]
    for col, b in bias.items():
        b_err = b - sc.gyro_bias_true_rad_s[-1]
        out[col] += (float(np.degrees(np.linalg.norm(b_err))),)
    cov = floors.covariance(ours)
    result: dict[str, tuple] = dict(out)
    result["_consistency"] = (tilt_error_rad(ours.quaternion, truth)[after],
                              (cov[:, 0] + cov[:, 4])[after])
    return result


def _multirotor_rows(params: FilterParams, peers: Sequence[str], jobs: int, floors: Floors,
                     columns: Sequence[str] = COLUMNS) -> list[Row]:
    import numpy as np

    from cf_estimator.bench.consistency import CONSISTENT_BEYOND, consistency
    from cf_estimator.bench.parallel import run_tasks

    work = [(name, rate, kwargs, seed, params, tuple(peers), floors)
            for _, name, rate, kwargs in MULTIROTOR_CASES for seed in MULTIROTOR_SEEDS]
    found = run_tasks(_multirotor_case, work, jobs)
    rows = []
    n = len(MULTIROTOR_SEEDS)
    whats = (*INCLINATION_ROWS, ("learned-bias error at the end", "deg/s"))
    for k, (label, *_) in enumerate(MULTIROTOR_CASES):
        rows += _seed_rows("multirotor", label, whats, found[k * n:(k + 1) * n],
                           MULTIROTOR_SEEDS, columns)
    for k, (label, *_) in enumerate(MULTIROTOR_CASES):  # the reported tilt σ, ours online
        parts = [r["_consistency"] for r in found[k * n:(k + 1) * n]]
        c = consistency(np.concatenate([p[0] for p in parts]),
                        np.concatenate([p[1] for p in parts]))
        head = f"simulated {label}: tilt"
        rows.append(Row("multirotor", f"{head} beyond 2σ (consistent {CONSISTENT_BEYOND['tilt']})",
                        "%", {"cf_estimator": c["beyond_2sigma_pct"]}))
        rows.append(Row("multirotor", f"{head}, per axis: beyond 2σ (consistent "
                        f"{CONSISTENT_BEYOND['tilt per axis']})", "%",
                        {"cf_estimator": c["beyond_2sigma_axis_pct"]}))
        rows.append(Row("multirotor", f"{head} mean(e²/σ²) (consistent 1)", "1",
                        {"cf_estimator": c["mean_ratio"]}))
    return rows


def _handheld_case(args: tuple[int, FilterParams, tuple[str, ...]]
                   ) -> dict[str, tuple[float, ...]]:
    """{column: (RMS, peak) [deg] after 10 s} of one simulated handheld recording
    (:func:`cf_estimator.bench.ablation.handheld_case`), 6-D."""
    import numpy as np

    from cf_estimator.bench.ablation import handheld_case

    seed, params, peers = args
    t, g, a, truth = handheld_case(seed)
    return _simulated_6d(g, a, t, float(1.0 / np.median(np.diff(t))), truth, params, peers)[0]


def _handheld_rows(params: FilterParams, peers: Sequence[str], jobs: int,
                   columns: Sequence[str] = COLUMNS) -> list[Row]:
    from cf_estimator.bench.ablation import HANDHELD_SEEDS
    from cf_estimator.bench.parallel import run_tasks

    runs = run_tasks(_handheld_case, [(seed, params, tuple(peers)) for seed in HANDHELD_SEEDS],
                     jobs)
    return _seed_rows("handheld", "handheld, 250 °/s turns", INCLINATION_ROWS, runs,
                      HANDHELD_SEEDS, columns)


def _aided_rows(root: Path, params: FilterParams, jobs: int, loaded: _Flights
                ) -> tuple[list[Row], list[str]]:
    """The velocity-aided rows (module docstring) and notes for missing data directories."""
    from cf_estimator.bench import euroc_eval as ev
    from cf_estimator.bench.scenarios import run_scenarios

    base = dataclasses.replace(params, use_mag=False)
    rows, notes = [], []
    aided = {"cf_estimator": "cf_estimator_aided",
             "cf_estimator_offline": "cf_estimator_aided_offline"}
    for family, label in AIDED_FAMILIES:
        folder = root / family
        if not folder.is_dir():
            notes.append(f"aided: {folder} not found, its rows left out")
            continue
        flights = loaded(folder)
        vin = _euroc_gnss() if family == "euroc" else ev.VelocityInput()
        res = ev.run_euroc(flights, base, (), ev.SETTLE_S, jobs=jobs, velocity=vin)
        start = ", ground start" if family == "euroc" else ""

        def noise(found: ev.EurocResult, a: str, score: str) -> float:
            return standard_error([per.get(a, {}).get(score, math.nan)
                                   for per in found.flights.values()])

        rows.append(Row("aided", f"{label}{start}, aided, after 10 s: mean", "deg",
                        {c: res.mean(a, "inclination_rms_deg") for c, a in aided.items()},
                        {c: noise(res, a, "inclination_rms_deg") for c, a in aided.items()},
                        _flight_members(res, "inclination_rms_deg", aided)))
        holds = {a: [per.get(a, {}).get("hold_s", math.nan) for per in res.flights.values()]
                 for a in aided.values()}
        rows.append(Row("aided", f"{label}{start}, aided: median time to < 2 deg", "s",
                        {c: ev.median_hold_s(res, a)[0] for c, a in aided.items()},
                        {c: standard_error([h for h in holds[a] if math.isfinite(h)])
                         for c, a in aided.items()},
                        _flight_members(res, "hold_s", aided)))
        if family != "euroc":
            continue
        for at in MIDAIR_STARTS_S:
            mid = ev.run_midair(flights, base, at, (), jobs=jobs, velocity=vin)
            key = ev.MIDAIR_SCORES[1]
            rows.append(Row("aided", f"{label}, aided, mid-air start {at:g} s: 12 s-end", "deg",
                            {c: mid.mean(a, key) for c, a in aided.items()},
                            {c: noise(mid, a, key) for c, a in aided.items()},
                            _flight_members(mid, key, aided)))
    found = run_scenarios(["acceleration"], base, (), jobs=jobs, velocity=True)
    peak = {r["algorithm"]: r["peak_arcmin"] for r in found}
    rows.append(Row("aided", "thesis acceleration, aided: peak (limit 90')", "arcmin",
                    {"cf_estimator": peak.get("cf_estimator_aided", math.nan)}))
    folder = root / "broad"
    if not folder.is_dir():
        notes.append(f"aided: {folder} not found, its rows left out")
        return rows, notes
    from cf_estimator.bench import broad
    from cf_estimator.bench.parallel import run_tasks

    trials = broad.list_trials(folder)
    scores = run_tasks(_broad_aided, [(p, params) for p in trials], jobs)
    for i, what in enumerate(("9-D total", "6-D inclination")):
        values = [s[i] for s in scores]
        rows.append(Row("aided", f"BROAD all ({len(values)}), aided by its optical positions: "
                        f"{what}", "deg", {"cf_estimator": sum(values) / len(values)},
                        {"cf_estimator": standard_error(values)},
                        {"cf_estimator": {p.stem: v for p, v in zip(trials, values,
                                                                    strict=True)}}))
    return rows, notes


def _broad_aided(args: tuple[Path, FilterParams]) -> tuple[float, float]:
    """One BROAD trial aided by its optical velocity: (9-D total, 6-D inclination) RMSE [deg]
    over its movement samples."""
    from cf_estimator import metrics
    from cf_estimator.bench import broad
    from cf_estimator.bench.evaluate import run_ours

    path, params = args
    trial = broad.load_trial(path)
    q = run_ours(trial, params, velocity=True)
    return (metrics.rmse_deg(q["9d"], trial.quat_ref, trial.movement)["total_rmse_deg"],
            metrics.rmse_deg(q["6d"], trial.quat_ref, trial.movement)["inclination_rmse_deg"])


def _scenario_rows(params: FilterParams, peers: Sequence[str], jobs: int,
                   columns: Sequence[str] = COLUMNS) -> list[Row]:
    from cf_estimator.bench.scenarios import run_scenarios

    found = run_scenarios(SCENARIOS, params, _runnable(peers), jobs=jobs)
    rows = []
    for name in SCENARIOS:
        values = {r["algorithm"]: r["peak_arcmin"] for r in found
                  if r["scenario"] == name and r["algorithm"] in columns}
        rows.append(Row("scenarios", f"thesis {name}: peak (limit 90')", "arcmin", values))
    return rows


def _consistency_rows(folder: Path, family: str, label: str, params: FilterParams,
                      jobs: int, floors: Floors) -> list[Row]:
    from cf_estimator.bench.consistency import (
        CONSISTENT_BEYOND,
        HEADING_POOLS,
        family_consistency,
    )

    found = family_consistency(folder, family, params, jobs, floors)
    rows = []
    for what, head in (("tilt", f"{label}: tilt"), ("heading", f"{label} 9-D: heading"),
                       *((key, f"BROAD {name} ({found.get(key, {}).get('trials', 0):.0f}) "
                               "9-D: heading") for key, name, _groups in HEADING_POOLS)):
        if what not in found:
            continue
        c = found[what]
        beyond = CONSISTENT_BEYOND["tilt" if what == "tilt" else "heading"]
        rows.append(Row(family, f"{head} beyond 2σ (consistent {beyond})", "%",
                        {"cf_estimator": c["beyond_2sigma_pct"]}))
        if what == "tilt":  # 2-D: also beyond twice one axis's σ (issue 27's 14 %)
            rows.append(Row(family, f"{head}, per axis: beyond 2σ (consistent "
                            f"{CONSISTENT_BEYOND['tilt per axis']})", "%",
                            {"cf_estimator": c["beyond_2sigma_axis_pct"]}))
        rows.append(Row(family, f"{head} mean(e²/σ²) (consistent 1)", "1",
                        {"cf_estimator": c["mean_ratio"]}))
    return rows


def run_cross(data: str | Path, params: FilterParams, families: Sequence[str] = FAMILIES,
              jobs: int = 1, progress: Callable[[str], None] | None = None,
              floors: Floors | None = None, peers: Sequence[str] = ()) -> CrossResult:
    """The table over the families below ``data`` (``euroc/``, ``phantom4/``, ``broad/``);
    ``floors``: the covariance model's, for the consistency rows (default: the shipped
    ones); ``peers``: more columns beside VQF's (module docstring: ``fusion``, ``madgwick``,
    ``complementary``, ``onboard``; those not installed are left out with a note)."""
    from cf_estimator.bench.consistency import Floors
    from cf_estimator.bench.euroc_eval import select_peers

    floors = floors if floors is not None else Floors()

    root = Path(data)
    result = CrossResult()
    extra = [p for p in dict.fromkeys(peers) if p not in ("vqf", "vqf_offline")]
    peers, missing = select_peers(["vqf"])  # vqf and vqf_offline, if installed
    if missing:
        result.notes.append("VQF not installed (pip install vqf): its columns are empty")
    if extra:
        more, gone = select_peers(extra)
        if gone:
            result.notes.append(f"peers not installed, their columns left out: {', '.join(gone)}")
        result.columns += more
        peers = peers + more
    cols = result.columns
    runs_on_arrays = [p for p in peers if p != "onboard"]
    loaded = _Flights()
    for family in families:
        if progress:
            progress(family)
        if family == "scenarios":
            result.rows += _scenario_rows(params, runs_on_arrays, jobs, cols)
            continue
        if family == "compass":
            result.rows += _compass_rows(params, runs_on_arrays, jobs, floors, cols)
            continue
        if family == "multirotor":
            result.rows += _multirotor_rows(params, runs_on_arrays, jobs, floors, cols)
            continue
        if family == "handheld":
            result.rows += _handheld_rows(params, runs_on_arrays, jobs, cols)
            continue
        if family == "aided":
            rows, notes = _aided_rows(root, params, jobs, loaded)
            result.rows += rows
            result.notes += notes
            continue
        folder = root / family
        if not folder.is_dir():
            result.notes.append(f"{family}: {folder} not found, left out")
            continue
        if family == "euroc":
            result.rows += _euroc_rows(loaded(folder), params, runs_on_arrays, jobs, "euroc",
                                       "EuRoC MH", midair=True, columns=cols)
            result.rows += _consistency_rows(folder, family, "EuRoC MH", params, jobs, floors)
        elif family in ("phantom4", "phantom4_horizontal"):
            label = "phantom4" if family == "phantom4" else "phantom4 horizontal"
            result.rows += _euroc_rows(loaded(folder), params, peers, jobs, family, label,
                                       midair=False, columns=cols)
            result.rows += _consistency_rows(folder, family, label, params, jobs, floors)
        elif family == "broad":
            # BROAD's evaluation runs VQF's offline mode with VQF itself
            result.rows += _broad_rows(folder, params, _runnable(peers), jobs, cols)
            result.rows += _consistency_rows(folder, family, "BROAD all", params, jobs,
                                             floors)
        else:
            raise ValueError(f"unknown family {family!r}; valid: {', '.join(FAMILIES)}")
    return result


def format_table(result: CrossResult) -> str:
    """Rows × the columns, two decimals (arcmin, s and % one), '-' where not applicable."""
    w = max([len(r.label) for r in result.rows] + [6])
    cols = result.columns
    cw = max(len(c) for c in cols)
    lines = [f"  {'row':<{w}}  {'unit':<6}" + "".join(f"  {c:>{cw}}" for c in cols)]
    for r in result.rows:
        cells = []
        for c in cols:
            v = r.values.get(c, math.nan)
            text = "-" if not math.isfinite(v) else (f"{v:.1f}" if r.unit in ("arcmin", "s", "%")
                                                     else f"{v:.2f}")
            cells.append(f"  {text:>{cw}}")
        lines.append(f"  {r.label:<{w}}  {r.unit:<6}" + "".join(cells))
    return "\n".join(lines) + "\n"
