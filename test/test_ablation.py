"""bench ablate: the paired comparison, the sign test, the leave-one-family-out verdict, the CLI."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from cf_estimator.bench import ablation


def test_sign_test_matches_the_binomial_tails():
    assert ablation.sign_test_p(0, 0) == 1.0
    assert ablation.sign_test_p(5, 5) == 1.0
    # 0 of 8 better: both tails of Binomial(8, 1/2) at 0 -> 2/256
    assert ablation.sign_test_p(0, 8) == pytest.approx(2.0 / 256.0)
    assert ablation.sign_test_p(8, 0) == ablation.sign_test_p(0, 8)


def test_a_small_shift_on_every_recording_is_a_change_however_wide_the_spread():
    base = {f"r{i}": float(i) for i in range(20)}  # recordings 0-19 deg apart
    variant = {k: v + 0.02 + 0.001 * (i % 3) for i, (k, v) in enumerate(base.items())}
    row = ablation.paired("phantom4", base, variant)
    assert row.n == 20 and row.worse == 20 and row.better == 0
    assert row.delta_mean == pytest.approx(0.021, abs=1e-3)
    assert row.change == "worse"
    assert row.sign_p < 1e-4


def test_a_delta_within_its_paired_noise_is_no_change():
    base = {f"r{i}": 1.0 for i in range(10)}
    variant = {k: 1.0 + (0.1 if i % 2 else -0.1) for i, k in enumerate(base)}
    row = ablation.paired("euroc", base, variant)
    assert row.change == "same" and row.better == 5 and row.worse == 5


def test_recordings_missing_or_not_finite_in_either_run_are_left_out_of_the_pairs():
    row = ablation.paired("euroc", {"a": 1.0, "b": 2.0, "c": math.nan},
                          {"a": 1.5, "c": 3.0, "d": 0.0})
    assert row.n == 1 and row.delta_mean == pytest.approx(0.5)


def test_breaking_the_thesis_limit_is_worse_even_on_three_recordings():
    base = {"impacts": 20.0, "vibration": 16.0, "acceleration": 55.0}
    variant = {"impacts": 1000.0, "vibration": 21.0, "acceleration": 1500.0}
    row = ablation.paired("thesis", base, variant)
    assert row.broken == 2 and row.change == "worse"
    assert ablation.verdict([row])[0] == "base"


def _row(family, z, n=10):
    return ablation.Paired(family, n, 1.0, z * 0.01, 0.01, 0, 0, 1.0)


def test_leave_one_family_out_keeps_the_base_where_the_held_out_family_loses():
    # the variant wins on four families; chosen without phantom4 it loses there
    rows = [_row("euroc", -3), _row("broad_undisturbed", -3), _row("broad_disturbed", -3),
            _row("multirotor", -3), _row("phantom4", 5)]
    choice, losers = ablation.verdict(rows)
    assert choice == "base" and losers == ["phantom4"]


def test_leave_one_family_out_takes_a_variant_that_wins_and_loses_nowhere():
    rows = [_row("euroc", -3), _row("phantom4", -1), _row("broad_undisturbed", 0.5)]
    assert ablation.verdict(rows) == ("variant", [])
    neutral = [_row("euroc", 0.0), _row("phantom4", 1.0)]
    assert ablation.verdict(neutral)[0].startswith("variant (neutral")


def test_overlapping_broad_groups_and_single_recordings_do_not_vote():
    rows = [_row("broad_rotation", 9), _row("broad_combined", 9, n=1), _row("euroc", -3),
            _row("phantom4", -3)]
    assert ablation.verdict(rows) == ("variant", [])


def test_a_variant_the_other_families_never_choose_is_not_taken_for_its_one_win():
    # better on one family, worse beyond the noise on two: without any family held out the
    # rest do not choose it, so no family is a 'loser' - and the base must still stay
    rows = [_row("handheld", -4), _row("phantom4", 5), _row("phantom4_horizontal", 5),
            _row("euroc", 0.0)]
    assert ablation.verdict(rows)[0] == "base"


def test_overrides_take_the_parameter_types():
    assert ablation.parse_override("use_saturation=false") == ("use_saturation", False)
    assert ablation.parse_override("k1=0.5") == ("k1", 0.5)
    with pytest.raises(ValueError, match="not a filter parameter"):
        ablation.parse_override("no_such=1")
    with pytest.raises(ValueError, match="true or false"):
        ablation.parse_override("use_mag=maybe")


def test_the_cli_scores_the_simulated_families_and_writes_paired_json(tmp_path):
    out = tmp_path / "ablate.json"
    run = subprocess.run(
        [sys.executable, "-m", "cf_estimator.cli.main", "bench", "ablate", "--data", str(tmp_path),
         "--families", "thesis", "--variant", "noclip:use_saturation=false", "--jobs", "1",
         "--json", str(out)], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert "leave-one-family-out: base" in run.stdout  # the clip is what the thesis needs
    found = json.loads(out.read_text())
    assert set(found["base"]["thesis"]) == set(ablation.THESIS_CASES)
    fam = found["variants"]["noclip"]["families"][0]
    assert fam["family"] == "thesis" and fam["broken"] >= 1


def test_the_cli_refuses_a_variant_of_an_unknown_parameter(tmp_path):
    run = subprocess.run(
        [sys.executable, "-m", "cf_estimator.cli.main", "bench", "ablate", "--data", str(tmp_path),
         "--families", "thesis", "--variant", "x:nope=1"], capture_output=True, text=True,
        timeout=120)
    assert run.returncode == 2 and "not a filter parameter" in run.stderr
    assert "Traceback" not in run.stderr


def test_the_autopilot_family_scores_a_real_log_against_its_own_attitude():
    from conftest import DATA_ROOT

    from cf_estimator.core.params import FilterParams

    log = DATA_ROOT / "ardupilot" / "dronekit_log171.bin"
    if not log.is_file():
        pytest.skip(f"ArduPilot log {log} not available (expected in ../shared/data/ardupilot)")
    (row,) = ablation._autopilot_task((str(log), FilterParams()))
    assert row[0] == "autopilot" and row[1] == log.name
    # the shipped defaults follow ArduPilot's own ATT within a few degrees up to the flip; a
    # wrong frame (ENU against NED) or the crash's spin scored would be tens of degrees
    assert 0.5 < row[2] < 5.0
