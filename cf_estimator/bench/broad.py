"""BROAD benchmark: trial loader, error metrics and the per-trial / per-group evaluation.

BROAD (Laidig, Caruso, Cereatti, Seel, "BROAD — A Benchmark for Robust Inertial Orientation
Estimation", Data 6(7), 2021) stores one HDF5 file per trial:

- ``imu_gyr`` (N, 3) rad/s, ``imu_acc`` (N, 3) m/s², ``imu_mag`` (N, 3) µT — IMU sensor frame;
- ``opt_quat`` (N, 4) optical reference orientation, w x y z, sensor-to-earth, earth = ENU
  (NaN rows where the optical system lost the body);
- ``movement`` (N,) bool: the samples to score; attribute ``sampling_rate`` [Hz];
- ``opt_pos`` (N, 3) m: the optical body's position, earth = ENU (NaN rows as for opt_quat);
  read when present, for velocity aiding (:func:`optical_velocity`).

A ``trials.json`` next to the files (optional) lists every trial's groups.

Metrics, exactly as the benchmark's own example code (``broad_utils.py``) computes them:
q_err = q_est ⊗ q_ref⁻¹ (error in the earth frame); total 2·acos|w|, heading 2·atan|z/w|,
inclination 2·acos√(w² + z²); RMSE over the movement samples with NaN rows ignored
(``nanmean``), in degrees, per trial; group values are the mean over the group's trials.

Frames: the published HDF5 files are already "synchronized and aligned" (file attribute
``info``): the optical body frame is the IMU frame and the optical earth frame's heading is the
magnetometer's north. The benchmark's evaluation applies **no** further alignment (no heading
offset removal, no averaging): an estimator has to deliver ENU with magnetic north on +y. We do
the same, so the numbers compare with the published ones. (Measured: online VQF 9-D's mean
signed heading error over a trial is below 1°, i.e. no residual offset to remove.) Without a
magnetometer (6-D) heading is unobservable: only the inclination error is meaningful.
"""

from __future__ import annotations

import fnmatch
import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

METRICS = ("total_rmse_deg", "heading_rmse_deg", "inclination_rmse_deg")
HDF5_SUFFIXES = (".hdf5", ".h5")
TRIALS_JSON = "trials.json"


class BroadDataError(ValueError):
    """A data directory or trial file that does not follow the BROAD layout (one-line message)."""


# -- loading -----------------------------------------------------------------------------------
@dataclass
class Trial:
    """One BROAD trial in memory (arrays as stored; see the module docstring for units)."""

    name: str
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    mag_ut: np.ndarray
    quat_ref: np.ndarray
    movement: np.ndarray
    rate_hz: float
    groups: tuple[str, ...] = ()
    path: Path | None = None
    #: optical position (N, 3) [m], earth frame ENU (None: not in the file)
    position_m: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.gyro_rad_s.shape[0])

    def decimated(self, factor: int) -> Trial:
        """Every ``factor``-th sample; gyro averaged over each block (keeps the integrated angle
        to first order), accelerometer and magnetometer averaged, reference, movement and position
        taken at the block's last sample. For screening only (``factor`` 1 returns self)."""
        if factor <= 1:
            return self
        n = (self.n_samples // factor) * factor

        def block_mean(a: np.ndarray) -> np.ndarray:
            return a[:n].reshape(-1, factor, a.shape[1]).mean(axis=1)

        last = slice(factor - 1, n, factor)
        return Trial(
            self.name, block_mean(self.gyro_rad_s), block_mean(self.accel_m_s2),
            block_mean(self.mag_ut), self.quat_ref[last].copy(), self.movement[last].copy(),
            self.rate_hz / factor, self.groups, self.path,
            None if self.position_m is None else self.position_m[last].copy(),
        )


def _inside(path: Path, root: Path) -> bool:
    try:
        path.resolve().relative_to(root.resolve())
    except ValueError:
        return False
    return True


def read_trial_info(data_dir: str | os.PathLike) -> dict:
    """The directory's ``trials.json`` (``{}`` when absent); never reads outside ``data_dir``."""
    root = Path(data_dir)
    p = root / TRIALS_JSON
    if not p.is_file() or not _inside(p, root):
        return {}
    try:
        with open(p, encoding="utf-8") as fh:
            info = json.load(fh)
    except (OSError, json.JSONDecodeError) as exc:
        raise BroadDataError(f"{p}: not a readable trials.json ({exc})") from None
    return info if isinstance(info, dict) else {}


def _fallback_groups(name: str) -> tuple[str, ...]:
    """Groups for a trial missing from trials.json: all_trials + (un)disturbed from the name."""
    lowered = name.lower()
    if "undisturbed" in lowered:
        return ("all_trials", "undisturbed")
    if "disturbed" in lowered:
        return ("all_trials", "disturbed")
    return ("all_trials",)


def trial_groups(name: str, info: Mapping) -> tuple[str, ...]:
    """The groups of trial ``name`` from trials.json, else inferred from the name."""
    entry = info.get("trials", {}).get(name) if info else None
    if isinstance(entry, Mapping) and isinstance(entry.get("groups"), list):
        return tuple(str(g) for g in entry["groups"])
    return _fallback_groups(name)


def list_trials(data_dir: str | os.PathLike, select: Sequence[str] | None = None) -> list[Path]:
    """Trial files directly in ``data_dir`` (sorted), optionally filtered.

    ``select`` items match a trial name exactly, as a prefix (``07`` → ``07_undisturbed_…``) or
    as a shell pattern (``*magnet*``); an item that matches nothing raises. Files whose real
    path leaves ``data_dir`` (symlinks out of it) are ignored: nothing outside is ever read.
    """
    root = Path(data_dir)
    if not root.is_dir():
        raise BroadDataError(f"data directory not found: {root}")
    files = sorted(
        p for p in root.iterdir()
        if p.suffix.lower() in HDF5_SUFFIXES and p.is_file() and _inside(p, root)
    )
    if not files:
        raise BroadDataError(f"no BROAD trial files (*.hdf5) in {root}")
    if not select:
        return files
    chosen: list[Path] = []
    for item in select:
        hits = [p for p in files if p.stem == item or p.name == item]
        if not hits:
            hits = [p for p in files if fnmatch.fnmatch(p.stem, item) or p.stem.startswith(item)]
        if not hits:
            raise BroadDataError(f"no trial matches {item!r} in {root}")
        chosen.extend(h for h in hits if h not in chosen)
    return sorted(chosen)


def resolve_trials(data: str | os.PathLike, select: Sequence[str] | None = None
                   ) -> tuple[list[Path], dict]:
    """(trial files, trials.json) for ``--data``: a directory of trials (see
    :func:`list_trials`) or a single trial file (its directory's trials.json, if any)."""
    path = Path(data)
    if path.is_file():
        if path.suffix.lower() not in HDF5_SUFFIXES:
            raise BroadDataError(f"{path}: not a BROAD trial file (*.hdf5)")
        if select:
            raise BroadDataError("--trials selects among the files of a directory; --data "
                                 f"{path} is a single file")
        return [path], read_trial_info(path.parent)
    return list_trials(path, select), read_trial_info(path)


def load_trial(path: str | os.PathLike, info: Mapping | None = None) -> Trial:
    """Read one trial file (h5py); raises :class:`BroadDataError` for a wrong layout."""
    import h5py  # local: only the bench needs it

    p = Path(path)
    try:
        with h5py.File(p, "r") as f:
            missing = [k for k in ("imu_gyr", "imu_acc", "opt_quat", "movement") if k not in f]
            if missing:
                raise BroadDataError(f"{p.name}: missing dataset(s) {', '.join(missing)}")
            if "sampling_rate" not in f.attrs:
                raise BroadDataError(f"{p.name}: missing attribute sampling_rate")
            gyro = np.ascontiguousarray(f["imu_gyr"][()], dtype=float)
            acc = np.ascontiguousarray(f["imu_acc"][()], dtype=float)
            mag = (np.ascontiguousarray(f["imu_mag"][()], dtype=float) if "imu_mag" in f
                   else np.full_like(gyro, np.nan))
            qref = np.asarray(f["opt_quat"][()], dtype=float)
            movement = np.asarray(f["movement"][()]).reshape(-1).astype(bool)
            rate = float(np.asarray(f.attrs["sampling_rate"]).reshape(-1)[0])
            pos = np.asarray(f["opt_pos"][()], dtype=float) if "opt_pos" in f else None
    except OSError as exc:
        raise BroadDataError(f"{p.name}: not a readable HDF5 file ({exc})") from None
    n = gyro.shape[0]
    for label, arr, cols in (("imu_gyr", gyro, 3), ("imu_acc", acc, 3), ("imu_mag", mag, 3),
                             ("opt_quat", qref, 4)):
        if arr.ndim != 2 or arr.shape != (n, cols):
            raise BroadDataError(f"{p.name}: {label} has shape {arr.shape}, expected ({n}, {cols})")
    if pos is not None and pos.shape != (n, 3):
        raise BroadDataError(f"{p.name}: opt_pos has shape {pos.shape}, expected ({n}, 3)")
    if movement.shape != (n,):
        raise BroadDataError(f"{p.name}: movement has {movement.shape[0]} rows for {n} samples")
    if not (math.isfinite(rate) and rate > 0):
        raise BroadDataError(f"{p.name}: sampling_rate must be positive, got {rate!r}")
    return Trial(p.stem, gyro, acc, mag, qref, movement, rate, trial_groups(p.stem, info or {}), p,
                 pos)


def optical_velocity(trial: Trial, rate_hz: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """A velocity sensor made of the optical positions, for velocity aiding: samples at
    ``rate_hz`` [Hz], each the mean velocity over its own interval (the position difference
    across 1/rate_hz centred on its stamp, as a 10 Hz receiver reports it), world ENU [m/s],
    stamps [s] on the IMU's time base (sample i at i/rate). Intervals touching a NaN position
    give no sample. → (t_s (M,), v_m_s (M, 3)); ValueError without positions."""
    if trial.position_m is None:
        raise ValueError(f"{trial.name}: no optical positions (opt_pos)")
    if not rate_hz > 0.0:
        raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
    half = max(1, round(trial.rate_hz / rate_hz / 2.0))
    step = 2 * half
    idx = np.arange(half, trial.n_samples - half, step)
    before, after = trial.position_m[idx - half], trial.position_m[idx + half]
    ok = np.all(np.isfinite(before), axis=1) & np.all(np.isfinite(after), axis=1)
    return idx[ok] / trial.rate_hz, (after[ok] - before[ok]) * (trial.rate_hz / step)


# -- evaluation results ------------------------------------------------------------------------
@dataclass
class BenchResult:
    """Per-trial metrics ``trials[trial][algorithm] = {metric: deg}`` and each trial's groups."""

    trials: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)
    groups: dict[str, tuple[str, ...]] = field(default_factory=dict)
    group_order: list[str] = field(default_factory=list)

    def algorithms(self) -> list[str]:
        """Algorithm names in first-seen order."""
        seen: list[str] = []
        for per_algo in self.trials.values():
            for a in per_algo:
                if a not in seen:
                    seen.append(a)
        return seen

    def group_members(self) -> dict[str, list[str]]:
        """Group name → trials in it (``all`` first, then (un)disturbed, then trials.json order)."""
        names = list(self.trials)
        out: dict[str, list[str]] = {"all": names}
        for g in ("undisturbed", "disturbed"):
            members = [t for t in names if g in self.groups.get(t, ())]
            if members:
                out[g] = members
        order = list(self.group_order)
        for t in names:
            for g in self.groups.get(t, ()):
                if g not in order:
                    order.append(g)
        for g in order:
            if g in ("all_trials", "undisturbed", "disturbed") or g in out:
                continue
            members = [t for t in names if g in self.groups.get(t, ())]
            if members:
                out[g] = members
        return out

    def group_mean(self, members: Iterable[str], algorithm: str, metric: str) -> float:
        """Mean over ``members`` of a metric (NaN if any member lacks it)."""
        vals = [self.trials[t].get(algorithm, {}).get(metric, float("nan")) for t in members]
        return float(np.mean(vals)) if vals else float("nan")

    def to_json(self) -> dict:
        """``{"trials": {...}, "groups": {group: {"trials": [...], algo: {metric: mean}}}}``."""
        groups: dict[str, dict] = {}
        for g, members in self.group_members().items():
            entry: dict = {"trials": members}
            for a in self.algorithms():
                entry[a] = {m: _json_float(self.group_mean(members, a, m)) for m in METRICS
                            if all(m in self.trials[t].get(a, {}) for t in members)}
            groups[g] = entry
        trials = {t: {a: {m: _json_float(v) for m, v in mets.items()} for a, mets in per.items()}
                  for t, per in self.trials.items()}
        return {"trials": trials, "groups": groups}


def _json_float(v: float) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), 6)


def format_tables(result: BenchResult) -> str:
    """Per-group tables: 9-D total/heading/inclination and 6-D inclination RMSE [deg]."""
    algos = result.algorithms()
    bases: list[str] = []
    for a in algos:
        base = a.rsplit("_", 1)[0] if a.endswith(("_9d", "_6d")) else a
        if base not in bases:
            bases.append(base)
    cols = [("9d", "total_rmse_deg", "9D total"), ("9d", "heading_rmse_deg", "9D head."),
            ("9d", "inclination_rmse_deg", "9D incl."), ("6d", "inclination_rmse_deg", "6D incl.")]
    width = max([len(b) for b in bases] + [9])
    lines = []
    for g, members in result.group_members().items():
        lines.append(f"{g} ({len(members)} trial{'s' if len(members) != 1 else ''})")
        lines.append(f"  {'algorithm':<{width}}" + "".join(f"  {c[2]:>9}" for c in cols))
        for b in bases:
            cells = []
            for dim, metric, _ in cols:
                name = f"{b}_{dim}"
                if name not in algos:
                    cells.append(f"  {'-':>9}")
                    continue
                v = result.group_mean(members, name, metric)
                cells.append(f"  {v:9.3f}" if math.isfinite(v) else f"  {'nan':>9}")
            lines.append(f"  {b:<{width}}" + "".join(cells))
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"
