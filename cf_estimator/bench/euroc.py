"""EuRoC MAV dataset (ASL folder layout): flight discovery, IMU and ground-truth readers.

Burri et al., "The EuRoC micro aerial vehicle datasets", IJRR 35(10), 2016. One flight is a
folder holding ``mav0/imu0/data.csv``:

- IMU csv: ``timestamp [ns], w_RS_S_x/y/z [rad/s], a_RS_S_x/y/z [m/s²]`` in the IMU sensor
  frame S (on the EuRoC hexacopter mounted with +x up: at rest a_x ≈ +9.8 m/s²).
- ground truth, first found of: ``mav0/state_groundtruth_estimate0/data.csv`` (ASL:
  ``t [ns], p_RS_R xyz [m], q_RS w x y z, v, b_w, b_a``) or a TUM trajectory file next to
  ``mav0/`` (:data:`TUM_NAMES`: ``t [s] tx ty tz qx qy qz qw``); or a file given explicitly.
  q_RS rotates vectors from S to the world frame R (z up, heading set by the motion-capture
  system, i.e. arbitrary): the same convention as our ``q_world_from_sensor`` up to a heading,
  so only the inclination is comparable. The b_w/b_a columns are never read.

Readers accept ``#`` comment lines, one header line without ``#``, comma and/or whitespace
separators, unsorted rows (sorted, stable) and repeated timestamps (the first row kept). The
ground truth is interpolated onto the IMU stamps (slerp); IMU samples outside its coverage, or
inside a gap longer than ``max_gap_s``, get NaN reference rows (not scored). Every problem is a
:class:`EurocDataError` with a one-line message naming the file (and line).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

IMU_CSV = Path("mav0", "imu0", "data.csv")
ASL_GT_CSV = Path("mav0", "state_groundtruth_estimate0", "data.csv")
#: TUM trajectory files looked for next to ``mav0/``, in this order (after the ASL csv).
TUM_NAMES = ("groundtruth_tum.txt", "groundtruth.tum", "data.tum")
GT_FORMATS = ("asl", "tum")
#: Longest ground-truth gap [s] bridged by interpolation (EuRoC's ground truth runs at 200 Hz).
MAX_GAP_S = 0.1


def _tokens(line: str) -> list[str]:
    """A text table line's fields: separated by commas and/or whitespace."""
    return line.replace(",", " ").split()


class EurocDataError(ValueError):
    """A folder or file that does not follow the EuRoC/TUM layout (one-line message)."""


@dataclass(frozen=True, eq=False)
class Flight:
    """One EuRoC flight on the IMU's time base.

    Attributes:
        name: flight name (folder name, or its path relative to the searched directory).
        t_s: IMU sample times (N,) [s] since the first IMU sample, strictly increasing.
        gyro_rad_s: angular rate (N, 3) [rad/s], sensor frame.
        accel_m_s2: specific force (N, 3) [m/s²], sensor frame.
        q_ref: ground truth q_world_from_sensor (N, 4) w, x, y, z (world z up, heading
            arbitrary), slerped onto ``t_s``; NaN rows where there is no ground truth.
        t0_ns: the first IMU stamp [ns] (``t_s`` is relative to it).
        path: the flight folder.
        groundtruth_path: the ground-truth file read (None if none).
        notes: what the readers repaired (unsorted rows, repeated stamps), for reports.
    """

    name: str
    t_s: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    q_ref: np.ndarray
    t0_ns: int
    path: Path
    groundtruth_path: Path | None = None
    notes: tuple[str, ...] = ()
    #: ground-truth velocity stamps (M,) [s] on ``t_s``'s time base (None: no ground truth)
    velocity_t_s: np.ndarray | None = None
    #: ground-truth velocity (M, 3) [m/s] in the ground truth's world frame (z up): the ASL
    #: v_RS_R columns, or differentiated positions (TUM files, ASL files without v)
    velocity_m_s: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        """Number of IMU samples N."""
        return int(self.t_s.shape[0])

    @property
    def rate_hz(self) -> float:
        """Nominal IMU rate [Hz]: 1 / median sample interval."""
        return float(1.0 / np.median(np.diff(self.t_s)))

    @property
    def has_reference(self) -> np.ndarray:
        """(N,) bool: samples with a ground-truth orientation."""
        return np.all(np.isfinite(self.q_ref), axis=1)

    def cropped(self, start_s: float) -> Flight:
        """The flight from ``start_s`` [s] after its first sample on (a mid-air start: the node
        restarted in flight, a bag that begins in the air), times re-based to 0 there; named
        ``<name>@<start_s>s``. ValueError if fewer than two samples are left."""
        i = int(np.searchsorted(self.t_s, start_s))
        if self.n_samples - i < 2:
            raise ValueError(f"{self.name}: nothing left after {start_s:g} s "
                             f"(the flight lasts {float(self.t_s[-1]):.1f} s)")
        t0 = float(self.t_s[i])
        vt = vel = None
        if self.velocity_t_s is not None and self.velocity_m_s is not None:
            keep = self.velocity_t_s >= t0  # the velocity from the new start on, re-based too
            vt, vel = self.velocity_t_s[keep] - t0, self.velocity_m_s[keep]
        return Flight(f"{self.name}@{start_s:g}s", self.t_s[i:] - t0, self.gyro_rad_s[i:],
                      self.accel_m_s2[i:], self.q_ref[i:], self.t0_ns + int(round(t0 * 1e9)),
                      self.path, self.groundtruth_path, self.notes, vt, vel)


# -- text tables -------------------------------------------------------------------------------
def _stamp_ns(token: str, unit_s: bool) -> int:
    """A timestamp token as integer nanoseconds (exact for decimal seconds)."""
    if not unit_s:
        try:
            return int(token)
        except ValueError:
            pass
    value = Decimal(token)  # InvalidOperation for non-numbers
    if not value.is_finite():
        raise InvalidOperation
    ns = int(value * 1_000_000_000 if unit_s else value)
    if not -(2**63) <= ns < 2**63:
        raise OverflowError
    return ns


def read_table(path: str | os.PathLike, min_cols: int, time_in_s: bool, what: str
               ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Rows of a numeric text table: (stamps [ns] int64 (M,), values (M, min_cols − 1), notes).

    The first column is the timestamp (ns integers, or seconds if ``time_in_s``); the next
    ``min_cols − 1`` columns are read (more are ignored). Rows come back sorted by stamp with
    repeated stamps dropped (first row kept); ``notes`` says when that happened.
    """
    p = Path(path)
    try:
        with open(p, encoding="utf-8", errors="replace") as fh:
            lines = fh.readlines()
    except FileNotFoundError:
        raise EurocDataError(f"{what} not found: {p}") from None
    except OSError as exc:
        raise EurocDataError(f"cannot read {what} {p}: {exc.strerror or exc}") from None
    stamps: list[int] = []
    rows: list[list[float]] = []
    header_allowed = True
    for lineno, line in enumerate(lines, 1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        tokens = _tokens(text)
        try:
            if len(tokens) < min_cols:
                raise ValueError
            stamp = _stamp_ns(tokens[0], time_in_s)
            values = list(map(float, tokens[1:min_cols]))
        except (ValueError, InvalidOperation):
            if header_allowed and not any(_is_number(t) for t in tokens[:1]):
                header_allowed = False  # one header line without '#' (e.g. "timestamp,...")
                continue
            raise EurocDataError(
                f"{p}:{lineno}: expected {min_cols} numeric columns in a {what}, got "
                f"{text[:60]!r}") from None
        except OverflowError:
            unit = "s" if time_in_s else "ns"
            raise EurocDataError(f"{p}:{lineno}: timestamp {tokens[0]} [{unit}] out of range "
                                 f"for a {what} (wrong format?)") from None
        header_allowed = False
        stamps.append(stamp)
        rows.append(values)
    if not stamps:
        raise EurocDataError(f"{what} {p} holds no data rows")
    t = np.array(stamps, dtype=np.int64)
    v = np.array(rows, dtype=float)
    if not np.all(np.isfinite(v)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(v), axis=1))[0])
        raise EurocDataError(f"{p}: non-finite value in data row {bad + 1}")
    notes: list[str] = []
    order = np.argsort(t, kind="stable")
    if np.any(order != np.arange(t.size)):
        notes.append(f"{p.name}: rows not in time order, sorted")
        t, v = t[order], v[order]
    keep = np.concatenate(([True], np.diff(t) > 0))
    if not np.all(keep):
        notes.append(f"{p.name}: {int((~keep).sum())} repeated timestamp(s), first row kept")
        t, v = t[keep], v[keep]
    return t, v, notes


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


# -- readers -----------------------------------------------------------------------------------
def read_imu(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """An EuRoC IMU csv: (stamps [ns] (N,), gyro [rad/s] (N, 3), accel [m/s²] (N, 3), notes)."""
    t, v, notes = read_table(path, 7, time_in_s=False, what="IMU csv")
    if t.size < 2:
        raise EurocDataError(f"IMU csv {path} needs at least 2 samples")
    return t, v[:, 0:3], v[:, 3:6], notes


def _detect_format(path: Path) -> str:
    """'asl' or 'tum' from the header comment, else from the first stamp's magnitude."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            head = [next(fh, "") for _ in range(20)]
    except FileNotFoundError:
        raise EurocDataError(f"ground truth not found: {path}") from None
    except OSError as exc:
        raise EurocDataError(f"cannot read ground truth {path}: {exc.strerror or exc}") from None
    text = "".join(head).lower()
    if "q_rs_w" in text or "p_rs_r" in text:
        return "asl"
    if re.search(r"\bqx\b", text):
        return "tum"
    for line in head:
        tokens = _tokens(line)
        if tokens and not line.lstrip().startswith("#") and _is_number(tokens[0]):
            # ASL stamps are nanoseconds (~1e18 for EuRoC); TUM stamps are seconds
            return "asl" if float(tokens[0]) > 1e12 else "tum"
    raise EurocDataError(f"ground truth {path}: cannot tell ASL from TUM format (no data rows)")


def read_groundtruth(path: str | os.PathLike, fmt: str | None = None
                     ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """A ground-truth file: (stamps [ns] (M,), q_world_from_sensor (M, 4) w x y z, notes).

    ``fmt``: ``"asl"`` (EuRoC state_groundtruth_estimate0 csv, ns, quaternion w x y z in
    columns 5–8) or ``"tum"`` (``t[s] tx ty tz qx qy qz qw``); None detects it. Quaternions
    are normalised and made sign-continuous; a zero-norm one is an error.
    """
    p = Path(path)
    if fmt is None:
        fmt = _detect_format(p)
    if fmt not in GT_FORMATS:
        raise ValueError(f"unknown ground-truth format {fmt!r}; valid: {', '.join(GT_FORMATS)}")
    t, v, notes = read_table(p, 8, time_in_s=(fmt == "tum"), what=f"{fmt.upper()} ground truth")
    q = v[:, 3:7] if fmt == "asl" else v[:, [6, 3, 4, 5]]
    norm = np.linalg.norm(q, axis=1)
    if np.any(norm < 1e-6):
        row = int(np.flatnonzero(norm < 1e-6)[0]) + 1
        raise EurocDataError(f"{p}: zero quaternion in data row {row}")
    q = q / norm[:, None]
    flips = np.concatenate(([False], np.einsum("ij,ij->i", q[1:], q[:-1]) < 0))
    sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
    return t, q * sign[:, None], notes


def read_groundtruth_velocity(path: str | os.PathLike, fmt: str | None = None
                              ) -> tuple[np.ndarray, np.ndarray, str]:
    """World-frame velocity of a ground-truth file: (stamps [ns] (M,), v [m/s] (M, 3), source).

    ASL files with finite ``v_RS_R`` columns (8–10): those (source ``"v_RS_R"``); otherwise
    (TUM, or no velocity columns) the positions differentiated, central differences at the
    stamps (source ``"positions"``).
    """
    p = Path(path)
    if fmt is None:
        fmt = _detect_format(p)
    if fmt == "asl":
        try:
            t, v, _ = read_table(p, 11, time_in_s=False, what="ASL ground truth")
            return t, v[:, 7:10], "v_RS_R"
        except EurocDataError:
            pass  # no (finite) velocity columns: differentiate the positions
    t, v, _ = read_table(p, 4, time_in_s=(fmt == "tum"), what=f"{fmt.upper()} ground truth")
    if t.size < 2:
        raise EurocDataError(f"ground truth {p}: too few rows to differentiate positions")
    ts = (t - t[0]) * 1e-9
    return t, np.gradient(v[:, 0:3], ts, axis=0), "positions"


def interpolate_groundtruth(t_gt_ns: np.ndarray, q_gt: np.ndarray, t_ns: np.ndarray,
                            max_gap_s: float = MAX_GAP_S) -> np.ndarray:
    """Slerp ground truth (stamps [ns] (M,), w x y z (M, 4)) onto stamps ``t_ns`` (N,) [ns].

    Returns (N, 4) w x y z; NaN rows outside [t_gt[0], t_gt[-1]] and inside ground-truth gaps
    longer than ``max_gap_s`` [s].
    """
    from scipy.spatial.transform import Rotation, Slerp

    out = np.full((t_ns.shape[0], 4), np.nan)
    if t_gt_ns.size < 2:
        return out
    base = t_gt_ns[0]
    tg = (t_gt_ns - base) * 1e-9
    tq = (np.asarray(t_ns, dtype=np.int64) - base) * 1e-9
    inside = (tq >= tg[0]) & (tq <= tg[-1])
    k = np.searchsorted(tg, tq, side="left")
    j = np.clip(k, 1, tg.size - 1)
    exact = tg[np.minimum(k, tg.size - 1)] == tq
    inside &= ((tg[j] - tg[j - 1]) <= max_gap_s) | exact
    if not np.any(inside):
        return out
    slerp = Slerp(tg, Rotation.from_quat(q_gt, scalar_first=True))
    q = slerp(tq[inside]).as_quat(scalar_first=True)
    out[inside] = q
    return out


# -- discovery and loading ---------------------------------------------------------------------
def is_flight_dir(path: str | os.PathLike) -> bool:
    """True if ``path`` holds ``mav0/imu0/data.csv``."""
    return (Path(path) / IMU_CSV).is_file()


def find_flights(data: str | os.PathLike) -> list[Path]:
    """Flight folders: ``data`` itself if it is one, else every folder below it holding
    ``mav0/imu0/data.csv`` (recursively, sorted; symlinked folders are not followed)."""
    root = Path(data)
    if not root.exists():
        raise EurocDataError(f"data directory not found: {root}")
    if not root.is_dir():
        raise EurocDataError(f"not a directory: {root} (give an EuRoC flight folder or a "
                             "directory of them)")
    if is_flight_dir(root):
        return [root]
    found: list[Path] = []
    for dirpath, dirnames, _files in os.walk(root):
        here = Path(dirpath)
        if is_flight_dir(here):
            found.append(here)
            dirnames[:] = []  # a flight's own folders hold no further flights
            continue
        dirnames[:] = sorted(d for d in dirnames if d != "mav0")
    if not found:
        raise EurocDataError(f"no EuRoC flight (a folder with {IMU_CSV.as_posix()}) in {root}")
    return sorted(found)


def find_groundtruth(folder: str | os.PathLike) -> tuple[Path, str] | None:
    """(file, format) of a flight's ground truth: the ASL csv, else a TUM file; None if none."""
    f = Path(folder)
    if (f / ASL_GT_CSV).is_file():
        return f / ASL_GT_CSV, "asl"
    for name in TUM_NAMES:
        if (f / name).is_file():
            return f / name, "tum"
    return None


def flight_name(folder: Path, root: Path | None = None) -> str:
    """The folder's name, or its path relative to ``root`` when it lies below it."""
    if root is not None and folder != root:
        try:
            return folder.relative_to(root).as_posix()
        except ValueError:
            pass
    return folder.resolve().name if folder.name in ("", ".", "..") else folder.name


def load_flight(path: str | os.PathLike, groundtruth: str | os.PathLike | None = None,
                gt_format: str | None = None, require_groundtruth: bool = True,
                max_gap_s: float = MAX_GAP_S, name: str | None = None) -> Flight:
    """Read one flight folder; ground truth from ``groundtruth`` (a file) or found in the folder.

    ``require_groundtruth=False`` gives all-NaN ``q_ref`` when the folder has none; with True
    (default) a missing ground truth, or one that covers no IMU sample, raises.
    """
    folder = Path(path)
    if not is_flight_dir(folder):
        raise EurocDataError(f"not an EuRoC flight folder (no {IMU_CSV.as_posix()}): {folder}")
    t_ns, gyro, acc, notes = read_imu(folder / IMU_CSV)
    gt = (Path(groundtruth), gt_format) if groundtruth is not None else find_groundtruth(folder)
    q_ref = np.full((t_ns.shape[0], 4), np.nan)
    gt_path = None
    vel_t = vel = None
    if gt is None:
        if require_groundtruth:
            raise EurocDataError(
                f"no ground truth in {folder} (expected {ASL_GT_CSV.as_posix()} or "
                f"{' / '.join(TUM_NAMES)})")
    else:
        gt_path = gt[0]
        t_gt, q_gt, gt_notes = read_groundtruth(gt_path, gt[1])
        notes += gt_notes
        q_ref = interpolate_groundtruth(t_gt, q_gt, t_ns, max_gap_s)
        t_vel, vel, _source = read_groundtruth_velocity(gt_path, gt[1] or _detect_format(gt_path))
        vel_t = (t_vel - t_ns[0]) * 1e-9
        if require_groundtruth and not np.any(np.isfinite(q_ref[:, 0])):
            raise EurocDataError(f"ground truth {gt_path} covers none of the IMU samples "
                                 "(different clocks or units?)")
    t_s = (t_ns - t_ns[0]) * 1e-9
    return Flight(name or flight_name(folder), t_s, gyro, acc, q_ref, int(t_ns[0]), folder,
                  gt_path, tuple(notes), vel_t, vel)


def load_flights(data: str | os.PathLike, **kwargs) -> list[Flight]:
    """Every flight below ``data`` (see :func:`find_flights`), named relative to it."""
    root = Path(data)
    return [load_flight(f, name=flight_name(f, root), **kwargs) for f in find_flights(root)]
