"""Per-sample results for notebooks: ``replay --csv`` and ``EstimateResult.to_dataframe()``."""

from __future__ import annotations

import csv
import math
import sys

import numpy as np
import pytest

pytest.importorskip("pymavlink")

from cf_estimator import FilterParams, estimate  # noqa: E402
from cf_estimator.bench import dataflashwrite as dfw  # noqa: E402
from cf_estimator.cli.main import main  # noqa: E402
from cf_estimator.scenarios import make_scenario  # noqa: E402


def test_replay_csv_has_one_row_per_imu_message_with_the_reference(tmp_path, capsys):
    log = dfw.static_tilt_log(tmp_path / "still.bin", roll_deg=12.0, duration_s=6.0)
    out = tmp_path / "samples.csv"
    assert main(["replay", str(log), "--csv", str(out), "--no-progress"]) == 0
    assert f"csv     {out} (300 rows)" in capsys.readouterr().out
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 300  # 6 s at 50 Hz
    last = rows[-1]
    assert float(last["t_s"]) == pytest.approx(30.0 + 299 / 50.0)
    assert float(last["roll_deg"]) == pytest.approx(12.0, abs=0.5)
    assert last["ref_roll_deg"] == ""  # after the last ATT sample: nothing brackets it
    assert float(rows[-10]["ref_roll_deg"]) == pytest.approx(12.0, abs=1e-3)
    q = np.array([float(last[k]) for k in ("qw", "qx", "qy", "qz")])
    assert np.linalg.norm(q) == pytest.approx(1.0)
    assert float(last["tilt_var_rad2"]) > 0.0 and last["at_rest"] in ("0", "1")
    assert all(k in last for k in ("bias_x_rad_s", "yaw_var_rad2", "clipped"))


def test_csv_is_refused_for_a_fleet_in_one_line(tmp_path, capsys):
    dfw.static_tilt_log(tmp_path / "a.bin", duration_s=3.0)
    dfw.static_tilt_log(tmp_path / "b.bin", duration_s=3.0)
    code = main(["replay", str(tmp_path), "--csv", str(tmp_path / "x.csv")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--csv" in err[0]
    assert not (tmp_path / "x.csv").exists()


def test_to_dataframe_gives_the_samples_when_pandas_is_installed():
    pd = pytest.importorskip("pandas")
    sc = make_scenario("static", duration_s=5.0, seed=2)
    res = estimate(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, timestamps_s=sc.imu.t_s,
                   params=FilterParams(use_mag=False))
    df = res.to_dataframe()
    assert isinstance(df, pd.DataFrame) and len(df) == sc.imu.t_s.shape[0]
    np.testing.assert_allclose(df[["qw", "qx", "qy", "qz"]].to_numpy(), res.quaternion)
    assert math.isclose(df["cov_xx_rad2"].iloc[-1], res.orientation_covariance()[-1, 0])


def test_to_dataframe_without_pandas_names_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas -> ImportError
    sc = make_scenario("static", duration_s=2.0, seed=2)
    res = estimate(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, timestamps_s=sc.imu.t_s)
    with pytest.raises(ImportError, match="pandas"):
        res.to_dataframe()
