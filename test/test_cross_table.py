"""`cf-estimator bench cross` on the dev data: regression guards per row, and the issues' targets.

Two kinds of checks on one run of the table (test/cli_runs.py runs it once per
session; the report, BENCHMARKS.md, is the same table with every peer beside it):

**Regression guards on dev data** (``test_no_row_got_worse_beyond_its_noise``): every row of our
two columns (online, offline) stays at most one noise margin above its value when the guard was
last set (``BASELINE``). The margin is the row's noise from ``bench cross`` itself
(``Row.noise``: the standard error of the row's mean over its recordings, flights, trials or
seeds) — how far a change that is neutral on average moves the row. A row without a spread of
its own borrows its family's: a worst recording or a single-trial BROAD group takes the noise of
the family's mean over all its recordings (``NOISE_FROM``); the thesis scenarios (one simulated
run each, nothing to spread over) get a fixed 5 % (``SIMULATED_MARGIN``), the only margin here
that is not measured. These guards hold today's values on the data the team has; they are not
the targets (the targets are scored on recordings we do not have). An improvement passes;
re-set ``BASELINE`` from the printed table when a change is accepted, and regenerate the report
(``cf-estimator bench report``: docs/results/benchmarks.json and BENCHMARKS.md).

The aided rows (issue 23: velocity aiding, ours only — VQF takes no velocity, its columns are
'-') are guarded alike; their "median time to < 2 deg" rows take as noise the standard error of
the per-flight times over the flights that settle, at least ``HOLD_MARGIN_FLOOR_S`` (one
velocity sample at 10 Hz: a median of identical times has no spread to measure).

**Targets that are met today** (issues 16, 22, 23; the rows the table prints), one test each
below.
The targets **missed** on the dev data are deliberately not asserted (a test would fail, or a
looser bound would pretend); they stay open:

- issue 16/22: BROAD 6-D inclination ≤ 0.68° — 0.686° (VQF online 0.689°);
- issue 22: phantom4 horizontal ≤ 3.0° — 3.15° (below VQF online's 4.05° and no recording
  above 6°: asserted);
- issue 22: the simulated multirotor cases (rows "simulated ..."): learned-bias error < 0.05 °/s
  on each — zig-zags 0.50 °/s (the vertical component a level 6-D flight cannot observe),
  figure-8s 1.56 °/s (1 kHz and 100 Hz; about the pitch axis: the turn's bank, fixed on the
  body for each loop, which the turning body makes look like a pitch-rate bias; not the rotor
  drag, decision 0005), tight figure-8s 0.25 °/s; their inclination RMS at
  most VQF online's is met on all four (asserted; decision 0005), and so is a
  learned bias no further off than VQF online's (asserted: VQF 0.81 / 2.04 / 2.04 / 1.92 °/s);
- issue 27: the tilt's share beyond 2σ within 5–25 % on every family, read against the σ
  whose consistent mean(e²/σ²) is 1 (σ² = cov[0] + cov[4]; a consistent Gaussian: 1.8 %, below
  the issue's 5 %): EuRoC 0.0 %, phantom4 5.9 %, horizontal 2.0 %, BROAD 2.5 %. Read as the
  issue's "a consistent 2-D Gaussian: 14 %" defines it, beyond twice the per-axis σ (rows "per
  axis"; consistent 13.5 %), it is met on all four (asserted: EuRoC 15.3 %, phantom4 18.4 %,
  horizontal 12.4 %, BROAD 7.9 %; bench/consistency.py);
- issue 23: thesis acceleration aided ≤ 15' — 42.9' on the table's seed (seeds 0-2: 42.9 /
  35.5 / 18.7'; 25.5 / 23.1 / 31.5' before the in-motion alignment: traded, decision 0006;
  32.5 / 34.9 / 31.3' with the heading known from the start).

Targets of those issues that this table does not print (so not checked here): the
compass 90° off at power-on, each magnet *trial* within VQF + 1° (the table has group means,
checked here as a necessary condition; per trial: test_compass_disturbance.py), BROAD peaks
against every peer other than VQF, the per-sample speed; issue 23's node load with velocity.
"""

from __future__ import annotations

import json
import math

import pytest
from cli_runs import CROSS_COMMAND, REPO, SHARED, run_documented

from cf_estimator.bench.cross import COMPASS_SEEDS, standard_error
from cf_estimator.cli.main import main

DATA = SHARED / "data"
OURS = ("cf_estimator", "cf_estimator_offline")
#: Rows without a spread of their own → the row whose noise they borrow (the family's mean).
NOISE_FROM = {
    "phantom4, after 10 s: worst recording": "phantom4, after 10 s: mean",
    "phantom4 horizontal, after 10 s: worst recording": "phantom4 horizontal, after 10 s: mean",
    "BROAD combined (1): 6-D inclination": "BROAD all (18): 6-D inclination",
    "BROAD tapping (1): 6-D inclination": "BROAD all (18): 6-D inclination",
    "BROAD vibration (1): 6-D inclination": "BROAD all (18): 6-D inclination",
    "BROAD combined (1): 9-D total": "BROAD all (18): 9-D total",
    "BROAD tapping (1): 9-D total": "BROAD all (18): 9-D total",
    "BROAD vibration (1): 9-D total": "BROAD all (18): 9-D total",
}
#: The smallest margin of a "median time to < 2 deg" row [s] (one velocity sample at 10 Hz).
HOLD_MARGIN_FLOOR_S = 0.1
#: The thesis scenarios' margin, as a fraction of the value (one deterministic run: no noise).
SIMULATED_MARGIN = 0.05
#: Our (online, offline) value of each row when the guards were last set (issue 26, on the
#: tree with issues 22-25 merged; re-set with issue 22's loop lag and gate, then with the
#: running mean in start-up and the turn share, with a velocity that says moving, and
#: with the loop's drift from the bias estimate's error, bias.error_sigma, and with the turn held
#: over the loop's memory, step.py turn_hold; the compass rows re-set when the simulated
#: magnetometer gained a calibrated sensor's residue, scenarios.compass.MAG_RESIDUE;
#: `cf-estimator bench cross --json`, 4 decimals).
BASELINE: dict[str, tuple[float, float | None]] = {
    "EuRoC MH, ground start, after 10 s: mean": (1.2633, 0.8537),
    "EuRoC MH, mid-air start 20 s: 2-12 s": (2.6307, 0.7289),
    "EuRoC MH, mid-air start 20 s: 12 s-end": (1.4448, 0.8829),
    "EuRoC MH, mid-air start 40 s: 2-12 s": (4.7453, 1.3688),
    "EuRoC MH, mid-air start 40 s: 12 s-end": (1.7882, 0.8337),
    "EuRoC MH, mid-air start 60 s: 2-12 s": (3.8292, 0.5890),
    "EuRoC MH, mid-air start 60 s: 12 s-end": (1.7842, 0.9434),
    "phantom4, after 10 s: mean": (1.6254, 1.3124),
    "phantom4, after 10 s: worst recording": (2.1653, 3.3518),
    "phantom4 horizontal, after 10 s: mean": (3.1509, 1.5396),
    "phantom4 horizontal, after 10 s: worst recording": (5.2574, 4.0796),
    "BROAD all (18): 6-D inclination": (0.6863, 0.5406),
    "BROAD undisturbed (11): 6-D inclination": (0.6432, 0.5152),
    "BROAD disturbed (7): 6-D inclination": (0.7541, 0.5806),
    "BROAD rotation (5): 6-D inclination": (0.6174, 0.5759),
    "BROAD translation (5): 6-D inclination": (0.4201, 0.3607),
    "BROAD combined (1): 6-D inclination": (1.8873, 0.9838),
    "BROAD slow (6): 6-D inclination": (0.3706, 0.3097),
    "BROAD fast (5): 6-D inclination": (0.9703, 0.7618),
    "BROAD no_breaks (7): 6-D inclination": (0.6932, 0.5236),
    "BROAD with_breaks (4): 6-D inclination": (0.5556, 0.5004),
    "BROAD tapping (1): 6-D inclination": (0.6169, 0.5568),
    "BROAD vibration (1): 6-D inclination": (0.3462, 0.3237),
    "BROAD stationary_magnet (2): 6-D inclination": (1.1451, 0.8580),
    "BROAD attached_magnet (3): 6-D inclination": (0.6752, 0.4892),
    "BROAD all (18): 9-D total": (1.9820, 1.8949),
    "BROAD undisturbed (11): 9-D total": (1.5056, 1.4527),
    "BROAD disturbed (7): 9-D total": (2.7307, 2.5899),
    "BROAD rotation (5): 9-D total": (1.3761, 1.3611),
    "BROAD translation (5): 9-D total": (1.2490, 1.2312),
    "BROAD combined (1): 9-D total": (3.4361, 3.0181),
    "BROAD slow (6): 9-D total": (1.2376, 1.2144),
    "BROAD fast (5): 9-D total": (1.8272, 1.7387),
    "BROAD no_breaks (7): 9-D total": (1.8558, 1.7846),
    "BROAD with_breaks (4): 9-D total": (0.8927, 0.8720),
    "BROAD tapping (1): 9-D total": (1.3813, 1.3469),
    "BROAD vibration (1): 9-D total": (6.7872, 6.6983),
    "BROAD stationary_magnet (2): 9-D total": (1.8290, 1.6393),
    "BROAD attached_magnet (3): 9-D total": (2.4294, 2.2684),
    "thesis impacts: peak (limit 90')": (20.4124, None),
    "thesis vibration: peak (limit 90')": (15.8781, None),
    "thesis acceleration: peak (limit 90')": (55.2172, None),
    "magnet 0.3x on a turning sensor: heading peak": (2.3606, 2.2517),
    "magnet 0.3x on a turning sensor: heading RMS": (1.3492, 1.2434),
    "magnet 0.5x on a turning sensor: heading peak": (2.1531, 2.0262),
    "magnet 0.5x on a turning sensor: heading RMS": (1.2891, 1.1738),
    "magnet 1x on a turning sensor: heading peak": (2.1531, 2.0147),
    "magnet 1x on a turning sensor: heading RMS": (1.2891, 1.1635),
    "simulated zig-zags 4 m/s², 120 Hz: inclination RMS after 10 s": (3.8876, 1.3944),
    "simulated zig-zags 4 m/s², 120 Hz: inclination peak after 10 s": (12.1291, 3.2743),
    "simulated zig-zags 4 m/s², 120 Hz: learned-bias error at the end": (0.5023, None),
    "simulated figure-8s 1.8 m/s², 1 kHz: inclination RMS after 10 s": (3.5883, 3.4407),
    "simulated figure-8s 1.8 m/s², 1 kHz: inclination peak after 10 s": (5.0755, 5.4864),
    "simulated figure-8s 1.8 m/s², 1 kHz: learned-bias error at the end": (1.5576, None),
    "simulated figure-8s 1.8 m/s², 100 Hz: inclination RMS after 10 s": (3.5941, 3.4390),
    "simulated figure-8s 1.8 m/s², 100 Hz: inclination peak after 10 s": (5.1407, 5.4852),
    "simulated figure-8s 1.8 m/s², 100 Hz: learned-bias error at the end": (1.5585, None),
    "simulated tight figure-8s 1.5 m/s², 1 kHz: inclination RMS after 10 s": (0.7533, 0.4599),
    "simulated tight figure-8s 1.5 m/s², 1 kHz: inclination peak after 10 s": (1.1387, 0.9782),
    "simulated tight figure-8s 1.5 m/s², 1 kHz: learned-bias error at the end": (0.2522, None),
    "phantom4 horizontal, aided, after 10 s: mean": (0.8621, 0.7165),
    "phantom4 horizontal, aided: median time to < 2 deg": (4.3317, 5.9721),
    "phantom4, aided, after 10 s: mean": (0.7001, 0.6406),
    "phantom4, aided: median time to < 2 deg": (4.1773, 3.7020),
    "EuRoC MH, ground start, aided, after 10 s: mean": (0.9561, 0.8048),
    "EuRoC MH, ground start, aided: median time to < 2 deg": (0.0000, 0.0000),
    "EuRoC MH, aided, mid-air start 20 s: 12 s-end": (0.8591, 0.7232),
    "EuRoC MH, aided, mid-air start 40 s: 12 s-end": (0.8663, 0.7598),
    "EuRoC MH, aided, mid-air start 60 s: 12 s-end": (0.8567, 0.7637),
    "thesis acceleration, aided: peak (limit 90')": (42.9004, None),
    "BROAD all (18), aided by its optical positions: 9-D total": (1.9776, None),
    "BROAD all (18), aided by its optical positions: 6-D inclination": (0.7031, None),
}


def _nan(v: float | None) -> float:
    return math.nan if v is None else float(v)


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    """{label: row} of the guards' run (values and noise; null → NaN)."""
    missing = [f for f in ("euroc", "phantom4", "phantom4_horizontal", "broad")
               if not (DATA / f).is_dir()]
    if missing:
        pytest.skip(f"{DATA} does not hold {', '.join(missing)}")
    pytest.importorskip("vqf")
    run = run_documented(CROSS_COMMAND, tmp_path_factory)
    assert run.rc == 0
    doc = json.loads((run.cwd / "cross.json").read_text())
    rows = {r["label"]: {k: {c: _nan(v) for c, v in r[k].items()} for k in ("values", "noise")}
            for r in doc["rows"]}
    assert len(rows) == len(doc["rows"]), "duplicate row labels"
    return rows, doc


def margin(rows: dict, label: str, column: str) -> float:
    """How much worse than BASELINE the row may get: its noise, or its family's (see above)."""
    if label.startswith("thesis"):
        return SIMULATED_MARGIN * BASELINE[label][0]
    noise = rows[NOISE_FROM.get(label, label)]["noise"][column]
    if label.endswith("median time to < 2 deg"):
        return max(noise, HOLD_MARGIN_FLOOR_S) if math.isfinite(noise) else HOLD_MARGIN_FLOOR_S
    return noise


def aided(label: str) -> bool:
    """A velocity-aided row (ours only: VQF takes no velocity)."""
    return ", aided" in label


def consistency(label: str) -> bool:
    """A covariance consistency row (ours only; issue 27): held by its own target test, not by
    a baseline (closer to consistent is better, in either direction)."""
    return "beyond 2σ" in label or "mean(e²/σ²)" in label


def learned_bias(label: str) -> bool:
    """A learned gyro bias's error (ours and VQF online; no offline column)."""
    return label.endswith("learned-bias error at the end")


def ours_only(label: str) -> bool:
    """A row only our filter has: aided, covariance consistency."""
    return aided(label) or consistency(label)


def _row(rows: dict, start: str) -> dict:
    """The values of the one row whose label starts with ``start``."""
    found = [v["values"] for k, v in rows.items() if k.startswith(start)]
    assert len(found) == 1, (start, list(rows))
    return found[0]


def test_the_report_has_every_row_the_guards_hold(table):
    """The committed report (docs/results/benchmarks.json, rendered into BENCHMARKS.md) is this
    table with more columns: a row added, removed or renamed here needs ``cf-estimator bench
    report`` as well."""
    rows, _ = table
    report = json.loads((REPO / "docs" / "results" / "benchmarks.json").read_text())
    assert [r["label"] for r in report["cross"]["rows"]] == list(rows)


def test_every_row_has_a_baseline_and_vqf_beside(table):
    rows, doc = table
    assert doc["columns"] == ["cf_estimator", "cf_estimator_offline", "vqf", "vqf_offline"]
    guarded = [label for label in rows if not consistency(label)]
    assert guarded == list(BASELINE), "a row was added, removed or renamed: set BASELINE"
    for label, row in rows.items():
        assert math.isfinite(row["values"]["cf_estimator"]), label
        if ours_only(label):
            assert math.isnan(row["values"]["vqf"]), label
        else:
            assert math.isfinite(row["values"]["vqf"]), label
        if ours_only(label) or learned_bias(label):
            assert math.isnan(row["values"]["vqf_offline"]), label


def test_every_guard_has_a_positive_finite_margin(table):
    rows, _ = table
    for label, (_, offline) in BASELINE.items():
        for column in OURS if offline is not None else OURS[:1]:
            m = margin(rows, label, column)
            assert math.isfinite(m) and m > 0.0, (label, column, m)


def test_no_row_got_worse_beyond_its_noise(table):
    rows, _ = table
    worse = []
    for label, base in BASELINE.items():
        for column, before in zip(OURS, base, strict=True):
            if before is None:
                continue
            now, m = rows[label]["values"][column], margin(rows, label, column)
            if not now <= before + m:
                worse.append(f"{label} [{column}]: {now:.4f} > {before:.4f} + noise {m:.4f}")
    assert not worse, "worse than the baseline beyond the row's noise:\n" + "\n".join(worse)


def test_standard_error_is_the_sample_deviation_over_root_n():
    assert standard_error([1.0, 2.0, 3.0]) == pytest.approx(1.0 / math.sqrt(3.0))
    assert math.isnan(standard_error([1.0]))  # one recording: no spread to measure
    assert math.isnan(standard_error([1.0, math.nan]))


# --- issue 16 / 22 targets met on the dev data -------------------------------------------------

def _ours(rows: dict, label: str, column: str = "cf_estimator") -> float:
    return rows[label]["values"][column]


def test_target_euroc_ground_start_at_most_1_7_deg(table):
    rows, _ = table
    assert _ours(rows, "EuRoC MH, ground start, after 10 s: mean") <= 1.7


@pytest.mark.parametrize("start", [20, 40, 60])
def test_target_euroc_mid_air_late_at_most_2_5_deg_and_both_windows_below_vqf(table, start):
    rows, _ = table
    late = f"EuRoC MH, mid-air start {start} s: 12 s-end"
    early = f"EuRoC MH, mid-air start {start} s: 2-12 s"
    assert _ours(rows, late) <= 2.5
    assert _ours(rows, late) < _ours(rows, late, "vqf")
    assert _ours(rows, early) < _ours(rows, early, "vqf")


@pytest.mark.parametrize("start", [20, 40, 60])
def test_target_euroc_mid_air_early_at_most_5_deg(table, start):
    rows, _ = table
    assert _ours(rows, f"EuRoC MH, mid-air start {start} s: 2-12 s") <= 5.0


def test_target_phantom4_vertical_at_most_2_deg_below_vqf_no_recording_above_6(table):
    rows, _ = table
    mean = "phantom4, after 10 s: mean"
    assert _ours(rows, mean) <= 2.0  # issue 22 (issue 16: 2.5)
    assert _ours(rows, mean) < _ours(rows, mean, "vqf")
    assert _ours(rows, "phantom4, after 10 s: worst recording") <= 6.0


def test_target_phantom4_horizontal_below_vqf_online_no_recording_above_6(table):
    """Issue 22's target but its ≤ 3.0° (missed: module docstring)."""
    rows, _ = table
    mean = "phantom4 horizontal, after 10 s: mean"
    assert _ours(rows, mean) < _ours(rows, mean, "vqf")
    assert _ours(rows, "phantom4 horizontal, after 10 s: worst recording") <= 6.0


def test_target_simulated_multirotor_cases_at_most_vqf_online(table):
    """Issue 22's RMS target on the simulated multirotor cases (zig-zags 3.89° against 5.11°,
    figure-8s 3.59° against 5.01° since the loop gain follows the velocity swing, tight
    figure-8s 0.75° against 1.10° since the bias is learned through the unit's own R̄; their
    learned-bias target, < 0.05 °/s, is missed: module docstring)."""
    rows, _ = table
    labels = [label for label in rows
              if label.startswith("simulated") and label.endswith("inclination RMS after 10 s")]
    assert len(labels) == 4
    for label in labels:
        assert _ours(rows, label) <= _ours(rows, label, "vqf"), label


def test_simulated_multirotor_learned_bias_at_most_vqf_online(table):
    """Issue 22's learned-bias target (< 0.05 °/s) is missed (module docstring); what the table
    holds instead: on each simulated multirotor case our learned bias is no further from the
    truth than VQF online's (zig-zags 0.50 against 0.81 °/s, figure-8s 1.56 against 2.04, tight
    figure-8s 0.25 against 1.92)."""
    rows, _ = table
    labels = [label for label in rows if label.startswith("simulated") and learned_bias(label)]
    assert len(labels) == 4
    for label in labels:
        assert _ours(rows, label) <= _ours(rows, label, "vqf"), label


def test_target_broad_9d_at_most_2_deg(table):
    rows, _ = table
    assert _ours(rows, "BROAD all (18): 9-D total") <= 2.0


def test_target_no_broad_group_more_than_10_percent_behind_vqf_online(table):
    rows, _ = table
    groups = [k for k in rows if k.startswith("BROAD") and not consistency(k)
              and "aided" not in k]  # VQF takes no velocity
    assert len(groups) == 28
    behind = {k: _ours(rows, k) / _ours(rows, k, "vqf") for k in groups}
    assert max(behind.values()) <= 1.10, behind


def test_target_broad_magnet_groups_within_vqf_online_plus_1_deg(table):
    """Issue 22 asks it per magnet trial; the table's group means are a necessary condition."""
    rows, _ = table
    for group in ("stationary_magnet (2)", "attached_magnet (3)"):
        label = f"BROAD {group}: 9-D total"
        assert _ours(rows, label) <= _ours(rows, label, "vqf") + 1.0, label


def test_target_thesis_peaks_below_90_arcmin_and_below_vqf(table):
    rows, _ = table
    for name in ("impacts", "vibration", "acceleration"):
        label = f"thesis {name}: peak (limit 90')"
        assert _ours(rows, label) < 90.0 and _ours(rows, label) < _ours(rows, label, "vqf")


@pytest.mark.parametrize("fraction", ["0.3", "0.5", "1"])
def test_target_magnet_on_a_turning_sensor_heading_below_5_deg_on_every_seed(table, fraction):
    """Issue 22: < 5° throughout, on each seed. The row is the mean of the seeds' peaks, with its
    standard error; Samuelson's inequality bounds every seed's peak by mean + (n − 1)·SE."""
    rows, _ = table
    row = rows[f"magnet {fraction}x on a turning sensor: heading peak"]
    n = len(COMPASS_SEEDS)
    for column in OURS:
        bound = row["values"][column] + (n - 1) * row["noise"][column]
        assert bound < 5.0, (column, bound)


def test_covariance_consistency_rows(table):
    """Issue 27: the reported orientation covariance against the real errors (σ² = cov[0] +
    cov[4] for the tilt, cov[8] for the heading). Tilt floor fitted at rest on EuRoC only;
    mean(e²/σ²) in [0.5, 2] on every recorded family (EuRoC, phantom4 and its horizontal
    campaign — 0.88 since a disagreement the loop keeps compensating counts as itself (0.57
    before) —, BROAD tilt since the
    acceleration term is the correction the loop made, BROAD heading: all trials, the
    undisturbed ones — the yaw floor's fit family, 0.54 since the floor is 3e-4 (0.46 at
    4e-4) — and the magnet trials, 0.57 (0.26 while the last disturbed innovation was held as
    the heading's error, 0.497 at the floor 4e-4)), the beyond-2σ share within the issue's
    25 %. The simulated compass cases too, while a magnet is on (0.90 since their magnetometer
    has a calibrated sensor's residue, scenarios.compass.MAG_RESIDUE; 0.22 with a perfect
    one, against the yaw floor fitted on a real sensor; 0.11 while the disturbed innovation
    was reported). The tilt's
    share beyond twice its per-axis σ (the issue's 14 % reading) within the issue's 5–25 % on
    every family (since the disagreement a loop keeps compensating counts as itself, not as the
    corrections it makes, and the floor is the fit at rest: EuRoC 26.4 → 15.3 %, horizontal 4.6
    → 12.4 %), and at least the share beyond 2σ of the whole (twice the per-axis σ is the
    smaller radius)."""
    rows, _ = table
    for label in ("EuRoC MH: tilt", "phantom4: tilt", "phantom4 horizontal: tilt",
                  "BROAD all: tilt", "BROAD all 9-D: heading",
                  "BROAD undisturbed (11) 9-D: heading", "BROAD magnet (5) 9-D: heading"):
        ratio = _row(rows, f"{label} mean(e²/σ²)")["cf_estimator"]
        beyond = _row(rows, f"{label} beyond 2σ")["cf_estimator"]
        assert 0.5 <= ratio <= 2.0, (label, ratio)
        assert beyond <= 25.0, (label, beyond)
    for label in ("EuRoC MH: tilt", "phantom4: tilt", "phantom4 horizontal: tilt",
                  "BROAD all: tilt"):
        axis = _row(rows, f"{label}, per axis: beyond 2σ")["cf_estimator"]
        assert axis >= _row(rows, f"{label} beyond 2σ")["cf_estimator"], label
        assert 5.0 <= axis <= 25.0, (label, axis)
    for f in ("0.3", "0.5", "1"):  # the compass, while a magnet is on
        ratio = _row(rows, f"magnet {f}x on a turning sensor: heading mean")["cf_estimator"]
        assert 0.5 <= ratio <= 2.0, (f, ratio)


def test_unknown_family_is_refused_in_one_line(capsys):
    assert main(["bench", "cross", "--families", "euroc,mars"]) == 2
    assert "unknown 'mars'" in capsys.readouterr().err


# --- issue 23 targets met on the dev data (velocity aiding) ------------------------------------

def test_target_aided_euroc_ground_start_at_most_1_deg_and_at_once(table):
    rows, _ = table
    assert _ours(rows, "EuRoC MH, ground start, aided, after 10 s: mean") <= 1.0
    assert _ours(rows, "EuRoC MH, ground start, aided: median time to < 2 deg") <= 5.0


def test_target_aided_median_time_to_hold_at_most_5_s_on_the_phantom_flights(table):
    """Issue 23: the median time from the first velocity sample until the inclination error
    stays below 2° (its running median over euroc_eval.HOLD_TRANSIENT_S) ≤ 5 s."""
    rows, _ = table
    for family in ("phantom4", "phantom4 horizontal"):
        assert _ours(rows, f"{family}, aided: median time to < 2 deg") <= 5.0, family


def test_aided_broad_is_no_worse_than_unaided(table):
    """BROAD's handheld trials aided by their optical positions (up to 8 g): the aiding may not
    help a hand's short accelerations, but it must not hurt — with the attitude-error check on
    the aperiodic unit's per-sample state the shakes passed for gyro faults (4.51° against
    0.69°; BENCHMARKS.md "After a gyro fault")."""
    rows, _ = table
    assert (_ours(rows, "BROAD all (18), aided by its optical positions: 9-D total")
            <= _ours(rows, "BROAD all (18): 9-D total") + 0.1)
    assert (_ours(rows, "BROAD all (18), aided by its optical positions: 6-D inclination")
            <= _ours(rows, "BROAD all (18): 6-D inclination") + 0.1)


def test_target_aided_euroc_mid_air_at_most_1_2_deg_at_every_start(table):
    rows, _ = table
    for at in (20, 40, 60):
        assert _ours(rows, f"EuRoC MH, aided, mid-air start {at} s: 12 s-end") <= 1.2, at


def test_target_aided_phantom4_vertical_at_most_1_5_deg(table):
    rows, _ = table
    assert _ours(rows, "phantom4, aided, after 10 s: mean") <= 1.5


def test_target_aided_phantom4_horizontal_at_most_1_2_deg(table):
    """Issue 23: ≤ 1.2° online (goal 1.0°, below the DOT's own filter's 1.54°)."""
    rows, _ = table
    assert _ours(rows, "phantom4 horizontal, aided, after 10 s: mean") <= 1.0


def test_aided_beats_unaided_on_every_recorded_family(table):
    """Velocity aiding is worth having wherever the vehicle accelerates: each family's aided
    mean below its unaided one, online and offline."""
    rows, _ = table
    for unaided, with_v in (("EuRoC MH, ground start, after 10 s: mean",
                             "EuRoC MH, ground start, aided, after 10 s: mean"),
                            ("phantom4, after 10 s: mean", "phantom4, aided, after 10 s: mean"),
                            ("phantom4 horizontal, after 10 s: mean",
                             "phantom4 horizontal, aided, after 10 s: mean")):
        for column in OURS:
            assert _ours(rows, with_v, column) < _ours(rows, unaided, column), (with_v, column)
        assert _ours(rows, with_v) < _ours(rows, unaided, "vqf"), with_v
