"""A replay's per-sample results as CSV (``cf-estimator replay --csv PATH``): what a notebook
reads with ``pandas.read_csv`` without reading the output bag back.

One row per processed IMU message, in order: ``t_s`` (header stamp [s], the input's clock: a
flight log's time since boot), the published quaternion ``qw qx qy qz`` (q_world_from_body in
the output frames), ``roll_deg pitch_deg yaw_deg`` (ZYX), the reported variances
``tilt_var_rad2`` (orientation_covariance[0] + [4]) and ``yaw_var_rad2`` ([8]), the gyro-bias
estimate ``bias_x/y/z_rad_s`` (sensor frame, held between its samples at ≤ 50 Hz), the flags
``clipped`` and ``at_rest`` (0/1), and, where the replay had a reference, the reference's
``ref_qw ref_qx ref_qy ref_qz ref_roll_deg ref_pitch_deg ref_yaw_deg`` interpolated onto the
row's stamp (empty where none brackets it). Empty cells: no value (before initialisation).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cf_estimator.bag.files import write_atomic_text
from cf_estimator.bag.metrics import interpolate_quaternions
from cf_estimator.core import quaternion as quat


def series_columns(series: Any) -> dict[str, np.ndarray]:
    """The CSV's columns (name -> (N,) array) of a :class:`cf_estimator.bag.replay.ReplaySeries`."""
    t = series.t_s
    n = t.shape[0]
    cols: dict[str, np.ndarray] = {"t_s": t}
    q = series.q_wxyz.reshape(-1, 4)
    for k, name in enumerate(("qw", "qx", "qy", "qz")):
        cols[name] = q[:, k]
    rpy = np.degrees(series.rpy_rad.reshape(-1, 3))
    for k, name in enumerate(("roll_deg", "pitch_deg", "yaw_deg")):
        cols[name] = rpy[:, k]
    cols["tilt_var_rad2"] = series.tilt_var_rad2 if series.tilt_var_rad2.shape[0] == n \
        else np.full(n, np.nan)
    cols["yaw_var_rad2"] = series.yaw_var_rad2 if series.yaw_var_rad2.shape[0] == n \
        else np.full(n, np.nan)
    bias = np.full((n, 3), np.nan)
    if series.bias_t_s.shape[0]:
        k = np.searchsorted(series.bias_t_s, t, side="right") - 1  # the latest sample
        ok = k >= 0
        bias[ok] = series.gyro_bias_rad_s[k[ok]]
    for k, name in enumerate(("bias_x_rad_s", "bias_y_rad_s", "bias_z_rad_s")):
        cols[name] = bias[:, k]
    cols["clipped"] = series.clipped.astype(int)
    cols["at_rest"] = series.at_rest.astype(int)
    if series.ref_t_s.shape[0] >= 1:
        rq, valid = interpolate_quaternions(series.ref_t_s, series.ref_q_wxyz, t)
        rq = np.where(valid[:, None], rq, np.nan)
        for k, name in enumerate(("ref_qw", "ref_qx", "ref_qy", "ref_qz")):
            cols[name] = rq[:, k]
        rr = np.degrees(quat.to_euler(rq))
        for k, name in enumerate(("ref_roll_deg", "ref_pitch_deg", "ref_yaw_deg")):
            cols[name] = rr[:, k]
    return cols


def _cell(x: float) -> str:
    return "" if not np.isfinite(x) else repr(float(x)) if x != int(x) or abs(x) > 1e15 \
        else str(int(x))


def write_csv(path: str | Path, series: Any) -> int:
    """Write the CSV (atomically, the user's umask); returns the number of rows."""
    cols = series_columns(series)
    names = list(cols)
    data = np.column_stack([np.asarray(cols[k], dtype=float) for k in names])
    lines = [",".join(names)]
    lines.extend(",".join(_cell(x) for x in row) for row in data.tolist())
    write_atomic_text(Path(path), "\n".join(lines) + "\n")
    return int(data.shape[0])
