"""A recorded bag with a reference orientation as a tuning trial (``cf-estimator tune --bag``).

:func:`load_bag_trial` reads one bag (ROS 1 or ROS 2, via :mod:`cf_estimator.bag.io`) into a
:class:`BagTrial`, which the tuner scores like a BROAD :class:`~cf_estimator.bench.broad.Trial`:

* IMU samples: the IMU topic's messages in log-time order, stamped by their header; a message
  with non-finite gyro/accelerometer values, a zero accelerometer vector or a stamp that does not
  increase is dropped (the node's pipeline rejects those too). Intervals longer than
  ``max_dt_s`` are not integrated: the filter sees the median interval there, as the pipeline
  does with its recent mean interval (its reset after very long gaps is not modelled).
* Magnetometer: as the node uses it. Each sample goes to the first IMU message logged after it,
  once, if their header stamps differ by at most ``mag_timeout_s`` (a newer sample replaces an
  unused one); every other row is NaN (= no sample). Values in µT (the message's Tesla × 10⁶;
  the filter uses only directions and relative norms).
* Reference: the true orientation q_world_from_sensor from a ``QuaternionStamped``,
  ``PoseStamped``, ``Odometry`` or ``Imu`` (its ``orientation``; messages flagged unknown with
  ``orientation_covariance[0] = -1`` are skipped) topic, interpolated onto the IMU stamps
  (normalised linear interpolation between the bracketing reference samples, exact where stamps
  coincide, nothing across reference gaps over 0.5 s: :func:`cf_estimator.bag.replay.
  interpolate_quaternions`).
* Scored samples (``movement``): every IMU sample with an interpolated reference, from
  ``score_after_s`` (default 2 s = the filter's default start-up phase) after the first IMU
  sample, so the start-up transient does not dominate the objective.

Frames: the reference must be in the filter's world frame (ENU unless ``world_frame: ned``).
The BROAD inclination error ignores heading, but the total error includes it, so ``total`` and
``combined`` need a common heading reference: the filter's heading is magnetic north on ENU +y,
and so is the truth ``cf-estimator simulate`` writes. For a reference with its own heading
(motion capture, odometry) tune the ``inclination`` objective.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cf_estimator.bench.broad import Trial

#: Default reference topic: the ground truth ``cf-estimator simulate`` writes.
DEFAULT_REFERENCE_TOPIC = "/ground_truth/orientation"
DEFAULT_SCORE_AFTER_S = 2.0


@dataclass
class BagTrial(Trial):
    """A :class:`Trial` from a bag: arrays at the IMU stamps, plus the stamps themselves.

    ``t_s``: the time base the filter integrates [s from the first IMU stamp], with long gaps
    shortened (see the module docstring); ``rate_hz`` is the median rate (for display).
    """

    t_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    topics: dict[str, str | None] = field(default_factory=dict)
    dropped_imu: int = 0  #: IMU messages dropped (invalid values, stamp not increasing)

    @property
    def has_mag(self) -> bool:
        """Whether any sample carries a magnetometer reading."""
        return bool(np.any(np.all(np.isfinite(self.mag_ut), axis=1)))

    def decimated(self, factor: int) -> BagTrial:
        """As :meth:`Trial.decimated`, with the stamps taken at each block's last sample and the
        magnetometer averaged over the block's samples that have one (NaN if none)."""
        if factor <= 1:
            return self
        base = Trial.decimated(self, factor)
        n = base.n_samples * factor
        blocks = self.mag_ut[:n].reshape(-1, factor, 3)
        has = np.all(np.isfinite(blocks), axis=2, keepdims=True)
        count = has.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mag = np.where(has, blocks, 0.0).sum(axis=1) / count
        mag[count[:, 0] == 0] = np.nan
        return dataclasses.replace(
            self, gyro_rad_s=base.gyro_rad_s, accel_m_s2=base.accel_m_s2, mag_ut=mag,
            quat_ref=base.quat_ref, movement=base.movement, rate_hz=base.rate_hz,
            t_s=self.t_s[factor - 1:n:factor].copy(),
        )

    def describe(self) -> str:
        """One line: samples, span, rate, magnetometer and scored samples."""
        span = float(self.t_s[-1] - self.t_s[0]) if self.n_samples > 1 else 0.0
        n_mag = int(np.sum(np.all(np.isfinite(self.mag_ut), axis=1)))
        dropped = f" ({self.dropped_imu} dropped)" if self.dropped_imu else ""
        return (f"{self.n_samples} IMU samples{dropped} over {span:.1f} s at "
                f"{self.rate_hz:.0f} Hz, {n_mag} with a magnetometer sample, "
                f"{int(self.movement.sum())} scored")


@dataclass
class _Collected:
    """Raw series read from the bag (stamps in integer ns)."""

    imu_ns: list[int] = field(default_factory=list)
    gyro: list[tuple[float, float, float]] = field(default_factory=list)
    accel: list[tuple[float, float, float]] = field(default_factory=list)
    mag_row: list[int] = field(default_factory=list)  #: IMU row each used mag sample belongs to
    mag: list[tuple[float, float, float]] = field(default_factory=list)
    ref_ns: list[int] = field(default_factory=list)
    ref_q: list[tuple[float, float, float, float]] = field(default_factory=list)
    dropped: int = 0


def _stamp_ns(msg: Any) -> int:
    st = msg.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def _vec(v: Any) -> tuple[float, float, float]:
    return float(v.x), float(v.y), float(v.z)


def _finite(values: tuple[float, ...]) -> bool:
    return all(math.isfinite(c) for c in values)


def reference_quaternion(msgtype: str, msg: Any) -> tuple[float, float, float, float] | None:
    """Normalised (w, x, y, z) of a reference message; None when absent or invalid."""
    from cf_estimator.bag import io
    from cf_estimator.bag.metrics import reference_quaternion

    if msgtype == io.IMU_TYPE:
        if float(msg.orientation_covariance[0]) < 0.0:  # REP-145: orientation unknown
            return None
        o = msg.orientation
        q = (float(o.w), float(o.x), float(o.y), float(o.z))
    else:
        q = reference_quaternion(msgtype, msg)
    norm = math.sqrt(sum(c * c for c in q))
    if not (math.isfinite(norm) and norm > 0.5):
        return None
    return q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm


def _add_imu(c: _Collected, msg: Any) -> bool:
    """Append one IMU message; False when it is dropped."""
    t = _stamp_ns(msg)
    g, a = _vec(msg.angular_velocity), _vec(msg.linear_acceleration)
    ok = _finite(g) and _finite(a) and any(a) and (not c.imu_ns or t > c.imu_ns[-1])
    if not ok:
        c.dropped += 1
        return False
    c.imu_ns.append(t)
    c.gyro.append(g)
    c.accel.append(a)
    return True


def _collect(bag: Any, topics: dict[str, str | None], mag_timeout_s: float) -> _Collected:
    """Read the IMU, magnetometer and reference series in log-time order."""
    imu, mag, ref = topics["imu"], topics["mag"], topics["reference"]
    ref_type = bag.msgtype_of(ref)
    timeout_ns = int(round(mag_timeout_s * 1e9))
    c = _Collected()
    pending: tuple[int, tuple[float, float, float]] | None = None
    wanted = [t for t in (imu, mag, ref) if t is not None]
    for m in bag.messages(wanted, bulk=True):  # Imu/MagneticField decoded with NumPy
        if m.topic == ref:  # may also be the IMU topic (an IMU with its own orientation)
            q = reference_quaternion(ref_type, m.msg)
            if q is not None:
                c.ref_ns.append(_stamp_ns(m.msg))
                c.ref_q.append(q)
        if m.topic == mag:
            v = _vec(m.msg.magnetic_field)
            pending = (_stamp_ns(m.msg), v) if _finite(v) and any(v) else pending
        elif m.topic == imu and _add_imu(c, m.msg):
            if pending is not None and abs(c.imu_ns[-1] - pending[0]) <= timeout_ns:
                c.mag_row.append(len(c.imu_ns) - 1)
                c.mag.append(pending[1])
            pending = None
    return c


def _select_topics(bag: Any, imu_topic: str | None, mag_topic: str | None,
                   reference_topic: str) -> dict[str, str | None]:
    from cf_estimator.bag import io

    imu = bag.select_topic("IMU", imu_topic, [io.IMU_TYPE], required=True, option="--imu-topic")
    mag = None
    if mag_topic is None or mag_topic.lower() != "none":
        mag = bag.select_topic("magnetometer", mag_topic, [io.MAG_TYPE], required=False,
                               option="--mag-topic")
    ref = bag.select_topic("reference", reference_topic, (*io.REFERENCE_TYPES, io.IMU_TYPE),
                           required=True, option="--reference-topic")
    return {"imu": imu, "mag": mag, "reference": ref}


def filter_times(t_s: np.ndarray, max_dt_s: float) -> np.ndarray:
    """Stamps [s] with every interval longer than ``max_dt_s`` replaced by the median one."""
    dt = np.diff(t_s)
    if dt.size == 0:
        return t_s.copy()
    typical = float(np.median(dt))
    dt = np.where(dt > max_dt_s, min(typical, max_dt_s), dt)
    return t_s[0] + np.concatenate([[0.0], np.cumsum(dt)])


def _reference_on(c: _Collected, t0_ns: int, t_imu: np.ndarray, path: Path, topic: str
                  ) -> np.ndarray:
    """(N, 4) reference at the IMU stamps, NaN rows where it cannot be interpolated."""
    from cf_estimator.bag import io
    from cf_estimator.bag.metrics import interpolate_quaternions

    if not c.ref_ns:
        raise io.BagError(f"{path}: no valid orientation on reference topic {topic!r}")
    t_ref = (np.asarray(c.ref_ns, dtype=np.int64) - t0_ns) * 1e-9
    order = np.argsort(t_ref, kind="stable")
    t_ref, q_ref = t_ref[order], np.asarray(c.ref_q, dtype=float)[order]
    keep = np.concatenate([[True], np.diff(t_ref) > 0])  # first of equal stamps
    q, valid = interpolate_quaternions(t_ref[keep], q_ref[keep], t_imu)
    if not valid.any():
        raise io.BagError(
            f"{path}: reference {topic!r} ({t_ref[0]:.2f}..{t_ref[-1]:.2f} s) does not overlap "
            f"the IMU stamps ({t_imu[0]:.2f}..{t_imu[-1]:.2f} s, from the first IMU stamp)"
        )
    return q


def _build(c: _Collected, path: Path, topics: dict[str, str | None], score_after_s: float,
           max_dt_s: float) -> BagTrial:
    from cf_estimator.bag import io

    if len(c.imu_ns) < 2:
        raise io.BagError(f"{path}: fewer than 2 usable IMU messages on {topics['imu']!r}")
    t0 = c.imu_ns[0]
    t = (np.asarray(c.imu_ns, dtype=np.int64) - t0) * 1e-9
    q_ref = _reference_on(c, t0, t, path, str(topics["reference"]))
    movement = np.all(np.isfinite(q_ref), axis=1) & (t >= score_after_s)
    if not movement.any():
        raise io.BagError(
            f"{path}: no IMU sample with a reference after the first {score_after_s:g} s"
        )
    mag = np.full((t.shape[0], 3), np.nan)
    if c.mag_row:
        mag[np.asarray(c.mag_row)] = np.asarray(c.mag, dtype=float) * 1e6  # T → µT
    return BagTrial(
        path.name, np.asarray(c.gyro, dtype=float), np.asarray(c.accel, dtype=float), mag, q_ref,
        movement, 1.0 / float(np.median(np.diff(t))), ("bag",), path,
        t_s=filter_times(t, max_dt_s), topics=topics, dropped_imu=c.dropped,
    )


def _is_ulog(bag: Any) -> bool:
    """A flight log (PX4 ulog, ArduPilot DataFlash): its attitude is the autopilot's, FRD → NED."""
    from cf_estimator.bag.logbag import StreamBag

    return isinstance(bag, StreamBag)


def load_bag_trial(
    path: str | os.PathLike[str], reference_topic: str = DEFAULT_REFERENCE_TOPIC, *,
    imu_topic: str | None = None, mag_topic: str | None = None,
    score_after_s: float = DEFAULT_SCORE_AFTER_S, mag_timeout_s: float | None = None,
    max_dt_s: float | None = None, world_frame: str = "enu",
) -> BagTrial:
    """Read a bag into a :class:`BagTrial` (see the module docstring).

    ``imu_topic``/``mag_topic`` None = detected by type (``mag_topic`` ``"none"``: no
    magnetometer); ``mag_timeout_s``/``max_dt_s`` None = the pipeline's defaults. Raises
    :class:`cf_estimator.bag.io.BagError` (one line; ``code`` 2 for a missing or mistyped topic,
    1 for bad data such as no overlap between reference and IMU).
    """
    from cf_estimator.bag import io
    from cf_estimator.pipeline import PipelineParams

    pp = PipelineParams()
    p = Path(path)
    with io.open_bag(p) as bag:
        px4_log = _is_ulog(bag)
        if px4_log and reference_topic == DEFAULT_REFERENCE_TOPIC:
            reference_topic = bag.reference_topic  # a flight log: the autopilot's own estimate
        topics = _select_topics(bag, imu_topic, mag_topic, reference_topic)
        c = _collect(bag, topics, pp.mag_timeout_s if mag_timeout_s is None else mag_timeout_s)
        until = bag.scored_until_s() if hasattr(bag, "scored_until_s") else None
        estimates = set(getattr(bag, "estimate_topics", ())) | {getattr(bag, "reference_topic",
                                                                        None)}
    if px4_log and until is not None and c.ref_q:  # a flip or crash ends the scored flight
        keep = [i for i, t in enumerate(c.ref_ns) if t * 1e-9 <= until]
        c.ref_ns, c.ref_q = [c.ref_ns[i] for i in keep], [c.ref_q[i] for i in keep]
    if px4_log and topics["reference"] in estimates and c.ref_q:
        # FRD → NED as logged; the trial's filter sees the FRD axes as they are (body "sensor")
        from cf_estimator.pipeline import px4

        q = px4.attitude_in_output_frames(np.asarray(c.ref_q), world_frame, "frd")
        if q is None:
            raise io.BagError(f"{p}: vehicle_attitude cannot be compared in world frame "
                              f"{world_frame!r}", 2)
        c.ref_q = [tuple(r) for r in q.tolist()]
    return _build(c, p, topics, score_after_s, pp.max_dt_s if max_dt_s is None else max_dt_s)

