"""`cf-estimator bench cross`: the cross-dataset table of BENCHMARKS.md, run as a user runs it.

The shipped defaults must hold the dev-data targets of issue 16 in every family at once; these
assertions are the guard a default change has to pass (a change that wins one family and
loses another fails here).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from cf_estimator.cli.main import main

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    if not all((DATA / f).is_dir() for f in ("euroc", "phantom4", "broad")):
        pytest.skip(f"{DATA} does not hold euroc/, phantom4/ and broad/")
    pytest.importorskip("vqf")
    out = tmp_path_factory.mktemp("cross") / "cross.json"
    assert main(["bench", "cross", "--data", str(DATA), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    return {r["label"]: r["values"] for r in doc["rows"]}, doc


def _row(rows: dict, start: str) -> dict:
    found = [v for k, v in rows.items() if k.startswith(start)]
    assert len(found) == 1, (start, list(rows))
    return found[0]


def test_every_family_has_its_rows_with_vqf_beside(table):
    rows, doc = table
    assert doc["columns"] == ["cf_estimator", "cf_estimator_offline", "vqf", "vqf_offline"]
    for start in ("EuRoC MH, ground start", "EuRoC MH, mid-air start 20 s: 2-12 s",
                  "EuRoC MH, mid-air start 60 s: 12 s-end", "phantom4, after 10 s: mean",
                  "BROAD all (18): 6-D", "BROAD all (18): 9-D", "thesis impacts"):
        v = _row(rows, start)
        assert math.isfinite(v["cf_estimator"]) and math.isfinite(v["vqf"]), start


def test_euroc_ground_and_mid_air_targets(table):
    rows, _ = table
    assert _row(rows, "EuRoC MH, ground start")["cf_estimator"] <= 1.7
    for s in (20, 40, 60):
        late = _row(rows, f"EuRoC MH, mid-air start {s} s: 12 s-end")
        early = _row(rows, f"EuRoC MH, mid-air start {s} s: 2-12 s")
        assert late["cf_estimator"] <= 2.5 and late["cf_estimator"] < late["vqf"], s
        assert early["cf_estimator"] < early["vqf"], s


def test_phantom4_targets(table):
    rows, _ = table
    mean = _row(rows, "phantom4, after 10 s: mean")
    assert mean["cf_estimator"] <= 2.5 and mean["cf_estimator"] < mean["vqf"]
    assert _row(rows, "phantom4, after 10 s: worst")["cf_estimator"] < 6.0


def test_broad_and_thesis_rows(table):
    rows, _ = table
    assert _row(rows, "BROAD all (18): 9-D total")["cf_estimator"] <= 2.0
    for label, v in rows.items():
        if label.startswith("BROAD") and "6-D" in label:  # no group 10 % behind VQF online
            assert v["cf_estimator"] <= 1.10 * v["vqf"], label
        if label.startswith("thesis"):
            assert v["cf_estimator"] < 90.0 and v["cf_estimator"] < v["vqf"], label


def test_covariance_consistency_rows(table):
    """Issue 27: the reported orientation covariance against the real errors (σ² = cov[0] +
    cov[4] for the tilt, cov[8] for the heading). Fitted on phantom4 (vertical) only; mean(e²/σ²)
    in [0.5, 2] on every family it can be held on, the beyond-2σ share within the issue's
    25 %. BROAD's lab-grade IMU and optical reference have errors below the fitted floor: its
    tilt is conservative (reported, not asserted in range) but never overconfident."""
    rows, _ = table
    for label in ("EuRoC MH: tilt", "phantom4: tilt", "phantom4 horizontal: tilt",
                  "BROAD all 9-D: heading"):
        ratio = _row(rows, f"{label} mean(e²/σ²)")["cf_estimator"]
        beyond = _row(rows, f"{label} beyond 2σ")["cf_estimator"]
        assert 0.5 <= ratio <= 2.0, (label, ratio)
        assert beyond <= 25.0, (label, beyond)
    assert _row(rows, "BROAD all: tilt mean(e²/σ²)")["cf_estimator"] <= 2.0
    for f in ("0.3", "0.5", "1"):  # the compass: conservative while a magnet is on
        assert _row(rows, f"magnet {f}x on a turning sensor: heading mean")["cf_estimator"] <= 2.0


def test_unknown_family_is_refused_in_one_line(capsys):
    assert main(["bench", "cross", "--families", "euroc,mars"]) == 2
    assert "unknown 'mars'" in capsys.readouterr().err
