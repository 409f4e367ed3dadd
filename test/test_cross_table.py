"""`cf-estimator bench cross` on the dev data: regression guards per row, and the issues' targets.

Two kinds of checks on one run of the table (test/cli_runs.py runs it once per
session; the report, BENCHMARKS.md, is the same table with every peer beside it):

**Regression guards on dev data** (``test_no_row_got_worse_beyond_its_noise``): today's run
against the committed report (``docs/results/benchmarks.json``, ``cross``: the baseline;
`cf-estimator bench report` re-sets it when a change is accepted, and BENCHMARKS.md with it). A row
that is a mean or median over recordings (flights, trials, seeds) keeps our columns' value per
recording (``members``); its guard is **paired**, recording by recording (``ablation.paired``,
the same comparison as `bench ablate`): the row got worse when the mean per-recording change
exceeds ``NOISE_SE`` paired standard errors. The spread between recordings never enters (with
it, BROAD 9-D could move 1.98° → 2.32° and pass): a family of 40 flights whose every flight got
0.02° worse got worse. A row of one value — a worst recording, a single-trial BROAD group — may
move by ``NOISE_SE`` paired standard errors of its family's mean row (``NOISE_FROM``); the
thesis scenarios (one simulated run each, nothing to pair) by a fixed 5 %
(``SIMULATED_MARGIN``), the only margin here that is not measured. A change within the committed
rounding (``ROUNDING``) is no change. An improvement passes. These guards hold today's values on
the data the team has; they are not the targets (the targets are scored on recordings we do not
have).

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
- issue 50: the slow figure-8s (1 m/s at 0.4 rad/s, near the loop's bandwidth: the proxy of
  the held-back nano-quadrotor) at most VQF online — 1.91° against 1.80° (1.29° with
  `bias_learning_k2: 0`: the in-flight learning takes the bank × the turn rate for a pitch-rate
  bias of about 0.5 °/s, and the hypotheses' evidence picks it);
- issue 50: the simulated handheld sensor (250 °/s turns, a gyro with a 1–1.5 % scale error
  and no bias; the held-back wand's and BROAD's fast rotations) below VQF online — 2.34°
  against 1.54° (peak 8.43° against 3.66°; 1.40° with `bias_learning_k2: 0`);
- issue 50: the same on every family, the simulated multirotor cases included (≤ 25 % per axis,
  mean(e²/σ²) ≤ 2): missed on the figure-8s (1 kHz and 100 Hz: 48.4 / 48.5 %, 2.19 / 2.22) and
  the slow figure-8s (68.0 %, 2.62), where the falsely learned pitch-rate bias above is taken
  for learned; zig-zags 10.3 %, 1.09, tight figure-8s 0.0 %, 0.26 (BENCHMARKS.md lists the
  missed rows under "Where we are weaker");
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

from cf_estimator.bench.ablation import NOISE_SE, paired
from cf_estimator.bench.cross import COMPASS_SEEDS, standard_error
from cf_estimator.cli.main import main

DATA = SHARED / "data"
OURS = ("cf_estimator", "cf_estimator_offline")
#: The committed report: its cross rows are the guards' baseline.
REPORT = REPO / "docs" / "results" / "benchmarks.json"
#: Rows without recordings of their own to pair → the row whose paired noise they borrow.
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
#: The thesis scenarios' margin, as a fraction of the value (one deterministic run: no noise).
SIMULATED_MARGIN = 0.05
#: The committed values' rounding (4 decimals; members 6), in the row's unit: a change within it
#: is no change.
ROUNDING = 1e-4


def _nan(v: float | None) -> float:
    return math.nan if v is None else float(v)


def _rows(doc: dict) -> dict:
    """{label: {"values", "noise", "members"}} of a cross JSON (null → NaN)."""
    rows = {}
    for r in doc["rows"]:
        rows[r["label"]] = {
            **{k: {c: _nan(v) for c, v in r[k].items()} for k in ("values", "noise")},
            "members": {c: {m: _nan(v) for m, v in ms.items()}
                        for c, ms in r.get("members", {}).items()}}
    assert len(rows) == len(doc["rows"]), "duplicate row labels"
    return rows


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    """{label: row} of the guards' run (values, noise, members; null → NaN)."""
    missing = [f for f in ("euroc", "phantom4", "phantom4_horizontal", "broad")
               if not (DATA / f).is_dir()]
    if missing:
        pytest.skip(f"{DATA} does not hold {', '.join(missing)}")
    pytest.importorskip("vqf")
    run = run_documented(CROSS_COMMAND, tmp_path_factory)
    assert run.rc == 0
    doc = json.loads((run.cwd / "cross.json").read_text())
    return _rows(doc), doc


@pytest.fixture(scope="module")
def baseline() -> dict:
    """The committed report's cross rows."""
    return _rows(json.loads(REPORT.read_text())["cross"])


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


def _paired(base: dict, now: dict, label: str, column: str):
    """The paired comparison of a row's recordings (None without two to pair)."""
    b, n = base[label]["members"].get(column, {}), now[label]["members"].get(column, {})
    p = paired(label, b, n)
    return p if p.n >= 2 else None


def worse(base: dict, now: dict, label: str, column: str) -> str | None:
    """Why ``label``'s ``column`` got worse than the baseline beyond its noise, or None."""
    before, after = base[label]["values"][column], now[label]["values"][column]
    if math.isnan(before):
        return None
    p = _paired(base, now, label, column)
    if p is not None:
        allowed = max(NOISE_SE * p.delta_se, ROUNDING)
        if p.delta_mean > allowed:
            return (f"{label} [{column}]: {p.worse} of {p.n} recordings worse, mean change "
                    f"{p.delta_mean:+.4f} > {allowed:.4f} ({NOISE_SE:g} paired standard errors)")
        return None
    m = margin(base, now, label, column)
    if not after <= before + m:
        return f"{label} [{column}]: {after:.4f} > {before:.4f} + {m:.4f}"
    return None


def margin(base: dict, now: dict, label: str, column: str) -> float:
    """How much a row of one value may get worse: the thesis's fixed share, else NOISE_SE paired
    standard errors of the row it borrows from (NOISE_FROM); at least ROUNDING."""
    if label.startswith("thesis"):
        return SIMULATED_MARGIN * base[label]["values"][column]
    p = _paired(base, now, NOISE_FROM[label], column)
    return max(NOISE_SE * p.delta_se, ROUNDING) if p is not None else math.nan


def _row(rows: dict, start: str) -> dict:
    """The values of the one row whose label starts with ``start``."""
    found = [v["values"] for k, v in rows.items() if k.startswith(start)]
    assert len(found) == 1, (start, list(rows))
    return found[0]


def guarded(rows: dict) -> list[str]:
    """The rows the regression guards hold (all but the consistency rows)."""
    return [label for label in rows if not consistency(label)]


def test_the_report_has_every_row_the_guards_hold(table, baseline):
    """The committed report (docs/results/benchmarks.json, rendered into BENCHMARKS.md) is this
    table with more columns: a row added, removed or renamed here needs ``cf-estimator bench
    report`` as well."""
    rows, _ = table
    assert list(baseline) == list(rows)


def test_every_row_has_vqf_beside(table):
    rows, doc = table
    assert doc["columns"] == ["cf_estimator", "cf_estimator_offline", "vqf", "vqf_offline"]
    for label, row in rows.items():
        assert math.isfinite(row["values"]["cf_estimator"]), label
        if ours_only(label):
            assert math.isnan(row["values"]["vqf"]), label
        else:
            assert math.isfinite(row["values"]["vqf"]), label
        if ours_only(label) or learned_bias(label):
            assert math.isnan(row["values"]["vqf_offline"]), label


def test_every_guard_pairs_recordings_or_has_a_positive_finite_margin(table, baseline):
    """A row is either paired recording by recording (at least two recordings, the same ones in
    the run and the report) or has a margin it borrows: none is held by nothing."""
    rows, _ = table
    for label in guarded(rows):
        for column in OURS:
            if math.isnan(baseline[label]["values"][column]):
                continue
            p = _paired(baseline, rows, label, column)
            if p is not None:
                assert set(baseline[label]["members"][column]) == \
                    set(rows[label]["members"][column]), (label, column)
                continue
            m = margin(baseline, rows, label, column)
            assert math.isfinite(m) and m > 0.0, (label, column, m)


def test_no_row_got_worse_beyond_its_noise(table, baseline):
    rows, _ = table
    found = [w for label in guarded(rows) for column in OURS
             if (w := worse(baseline, rows, label, column)) is not None]
    assert not found, ("worse than the committed report beyond the row's noise:\n"
                       + "\n".join(found))


def _members_row(values: list[float]) -> dict:
    return {"values": {"cf_estimator": sum(values) / len(values)}, "noise": {},
            "members": {"cf_estimator": {f"r{i}": v for i, v in enumerate(values)}}}


def test_the_guard_pairs_recordings_not_the_spread_between_them():
    """Every recording 0.02° worse fails however much the recordings differ from one another;
    a larger mean change that is only noise (half better, half worse) passes."""
    base = {"x": _members_row([0.5, 1.0, 2.0, 4.0, 8.0, 3.0])}
    shifted = {"x": _members_row([v + 0.02 for v in [0.5, 1.0, 2.0, 4.0, 8.0, 3.0]])}
    assert worse(base, shifted, "x", "cf_estimator") is not None
    noisy = {"x": _members_row([0.5 + 0.3, 1.0 - 0.3, 2.0 + 0.3, 4.0 - 0.25, 8.0 + 0.3, 3.0 - 0.3])}
    assert worse(base, noisy, "x", "cf_estimator") is None
    assert worse(base, base, "x", "cf_estimator") is None
    better = {"x": _members_row([v - 0.1 for v in [0.5, 1.0, 2.0, 4.0, 8.0, 3.0]])}
    assert worse(base, better, "x", "cf_estimator") is None


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
    learned-bias target, < 0.05 °/s, is missed: module docstring). The slow figure-8s (issue
    50's proxy of the held-back nano-quadrotor) and the handheld sensor miss it: module
    docstring."""
    rows, _ = table
    labels = [label for label in rows
              if label.startswith("simulated") and label.endswith("inclination RMS after 10 s")
              and not label.startswith(("simulated slow", "simulated handheld"))]
    assert len(labels) == 4
    for label in labels:
        assert _ours(rows, label) <= _ours(rows, label, "vqf"), label


def test_simulated_multirotor_learned_bias_at_most_vqf_online(table):
    """Issue 22's learned-bias target (< 0.05 °/s) is missed (module docstring); what the table
    holds instead: on each simulated multirotor case our learned bias is no further from the
    truth than VQF online's (zig-zags 0.50 against 0.81 °/s, figure-8s 1.56 against 2.04, tight
    figure-8s 0.25 against 1.92, slow figure-8s 0.53 against 0.60)."""
    rows, _ = table
    labels = [label for label in rows if label.startswith("simulated") and learned_bias(label)]
    assert len(labels) == 5
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
