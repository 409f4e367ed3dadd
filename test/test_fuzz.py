"""Property-based fuzzing of :class:`cf_estimator.pipeline.ImuPipeline` (hypothesis).

Generated message streams (real ``sensor_msgs`` objects from the rosbags Jazzy typestore) with
NaN/Inf/huge gyro, accelerometer and magnetometer components, zero-norm accelerometers, zero,
duplicate, out-of-order and backwards stamps, gaps from milliseconds to minutes, magnetometers
absent, stale, NaN or at another rate, empty and odd frame ids, malformed messages. For every
stream:

* no exception, ever (``on_imu``, ``on_mag``, ``diagnostics``), and never ``internal_error``;
* every output quaternion is finite and unit-norm (rpy and covariance finite too);
* ``received = processed + rejected``; every rejection has the reason an independent model of
  docs/failure_modes.md predicts (the model also predicts gaps, resets and the magnetometer
  bookkeeping: ``mag_received = used + rejected + stale + invalid + dropped + disabled + pending``);
* after the bad data stop, the tilt is back within 1 deg of the truth within 10 s of good data
  (truth: a random fixed tilt, turning slowly about the world vertical, with gyro bias and noise).

Parameters (``cf_estimator.params_file.all_specs()``): random valid and invalid values through the
live-update path (``validate_changes``/``apply_changes``); invalid ones are refused with a reason
and change nothing; valid ones take effect at the next sample without resetting the attitude.

Profiles: ``ci`` (default; derandomized, no example database: the same 10 000 cases every run,
about 2-3 minutes) and ``long`` (``HYPOTHESIS_PROFILE=long``: 10x the examples, random seeds,
for on-demand runs). ``HYPOTHESIS_PROFILE=ci`` is implied when the variable is unset.
"""

from __future__ import annotations

import copy
import math
import os
import random
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st
from ros_test_helpers import Header, Imu, MagneticField, Quaternion, Time, Vector3

from cf_estimator.core.params import FilterParams
from cf_estimator.params_file import all_specs, build_params
from cf_estimator.pipeline import ImuPipeline, PipelineParams, checks
from cf_estimator.schema import ParamSpec

# -- profiles ----------------------------------------------------------------------------------
_HEALTH = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much]
settings.register_profile(
    "ci", derandomize=True, deadline=None, database=None, print_blob=True,
    suppress_health_check=_HEALTH,
)
settings.register_profile(
    "long", derandomize=False, deadline=None, print_blob=True, suppress_health_check=_HEALTH,
)
PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "ci")
_SCALE = {"ci": 1, "long": 10}.get(PROFILE, 1)

#: Examples per property in the ci profile (sum >= 10 000; see the module docstring).
EXAMPLES = {
    "streams": 4000,
    "recovery": 600,
    "params_invalid": 2400,
    "params_valid": 2800,
    "read_only": 200,  # a small space: hypothesis stops when it has tried every value
}
CI_TOTAL = sum(EXAMPLES.values())


def profile(name: str) -> settings:
    """The settings of one property: the selected profile, scaled example count."""
    return settings(settings.get_profile(PROFILE), max_examples=EXAMPLES[name] * _SCALE)


# -- real messages (rosbags Jazzy typestore) ----------------------------------------------------

G = 9.80665
T0_NS = 1_700_000_000 * 10**9
MAG_ENU_T = (0.0, 25e-6, -43e-6)  # Earth field in ENU (north, down-pointing), Tesla
_COV = np.diag([1e-4, 1e-4, 1e-4]).ravel()
_UNKNOWN = np.array([-1.0] + [0.0] * 8)
_IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)


def _stamp(t_ns: int) -> Time:
    return Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def imu_msg(t_ns: int, gyro, accel, frame: str = "imu_link", cov=_COV) -> Imu:
    return Imu(
        header=Header(stamp=_stamp(t_ns), frame_id=frame),
        orientation=_IDENTITY,
        orientation_covariance=_UNKNOWN,
        angular_velocity=Vector3(x=gyro[0], y=gyro[1], z=gyro[2]),
        angular_velocity_covariance=cov,
        linear_acceleration=Vector3(x=accel[0], y=accel[1], z=accel[2]),
        linear_acceleration_covariance=cov,
    )


def mag_msg(t_ns: int, field, frame: str = "imu_link") -> MagneticField:
    return MagneticField(
        header=Header(stamp=_stamp(t_ns), frame_id=frame),
        magnetic_field=Vector3(x=field[0], y=field[1], z=field[2]),
        magnetic_field_covariance=np.zeros(9),
    )


def malformed_imu(kind: int, t_ns: int) -> Any:
    """IMU messages a reader cannot use (missing fields, wrong types, wrong covariance size)."""
    good = imu_msg(t_ns, (0.0, 0.0, 0.0), (0.0, 0.0, G))
    if kind == 0:
        good.angular_velocity_covariance = np.zeros(8)
    elif kind == 1:
        good.angular_velocity = None
    elif kind == 2:
        good.linear_acceleration = Vector3(x=None, y=0.0, z=G)  # type: ignore[arg-type]
    elif kind == 3:
        good.header = Header(stamp=Time(sec="soon", nanosec=0), frame_id="imu")  # type: ignore
    elif kind == 4:
        return SimpleNamespace(header=good.header)  # no vectors at all
    else:
        return None
    return good


# -- quaternion helpers (w, x, y, z) -------------------------------------------------------------
def qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def rotate_inv(q, v):
    """R(q)ᵀ·v: a world vector seen in the sensor frame."""
    w, x, y, z = q
    return qmul(qmul((w, -x, -y, -z), (0.0, *v)), q)[1:]


def up_in_sensor(q):
    """Third row of R(q): the world vertical in the sensor frame."""
    w, x, y, z = q
    return (2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y))


def angle_deg(u, v) -> float:
    nu = math.sqrt(sum(c * c for c in u))
    nv = math.sqrt(sum(c * c for c in v))
    c = sum(a * b for a, b in zip(u, v, strict=True)) / (nu * nv)
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def check_output(out, frame) -> None:
    """Every published output: finite unit quaternion, finite rpy/covariance, frame kept."""
    q = out.orientation_xyzw
    assert all(math.isfinite(c) for c in q), q
    assert abs(math.sqrt(sum(c * c for c in q)) - 1.0) < 1e-9, q
    assert out.initialized and out.rpy_rad is not None
    assert all(math.isfinite(c) for c in out.rpy_rad), out.rpy_rad
    assert all(math.isfinite(c) for c in out.orientation_covariance)
    assert out.orientation_covariance[0] > 0.0
    assert out.frame_id == frame


# -- an independent model of the guards (docs/failure_modes.md) ---------------------------------
@dataclass
class Model:
    """What the pipeline must do with each message, from the documented rules only."""

    pp: PipelineParams
    use_mag: bool = True
    last_ns: int | None = None
    pending_mag_ns: int | None = None
    received: int = 0
    processed: int = 0
    gaps: int = 0

    def __post_init__(self) -> None:
        self.rejected: dict[str, int] = {}
        self.resets: dict[str, int] = {}
        self.mag = dict(invalid=0, stale=0, dropped=0, disabled=0, consumed=0, received=0)

    def _reset(self, reason: str) -> None:
        self.resets[reason] = self.resets.get(reason, 0) + 1
        self.last_ns = None
        if self.pending_mag_ns is not None:
            self.mag["dropped"] += 1
            self.pending_mag_ns = None

    def imu(self, t_ns: int | None, gyro, accel) -> str | None:
        """The rejection reason, or None when the message must be processed."""
        self.received += 1
        reason = self._classify(t_ns, gyro, accel)
        if reason is not None:
            self.rejected[reason] = self.rejected.get(reason, 0) + 1
            return reason
        assert t_ns is not None
        pending, self.pending_mag_ns = self.pending_mag_ns, None
        if pending is not None:
            if not self.use_mag:
                self.mag["disabled"] += 1
            elif abs(t_ns - pending) <= round(self.pp.mag_timeout_s * 1e9):
                self.mag["consumed"] += 1
            else:
                self.mag["stale"] += 1
        self.last_ns = t_ns
        self.processed += 1
        return None

    def _classify(self, t_ns, gyro, accel) -> str | None:
        if t_ns is None:
            return checks.MALFORMED
        if t_ns == 0:
            return checks.ZERO_STAMP
        if not all(math.isfinite(c) for c in gyro):
            return checks.NONFINITE_GYRO
        if not all(math.isfinite(c) for c in accel):
            return checks.NONFINITE_ACCEL
        a2 = sum(c * c for c in accel)
        if a2 == 0.0:
            return checks.ZERO_ACCEL
        if sum(c * c for c in gyro) > checks.GYRO_MAX_RAD_S**2:
            return checks.IMPLAUSIBLE_GYRO
        if a2 > checks.ACCEL_MAX_M_S2**2:
            return checks.IMPLAUSIBLE_ACCEL
        if self.last_ns is None:
            return None
        d = t_ns - self.last_ns
        pp = self.pp
        if d == 0:
            return checks.DUPLICATE_STAMP
        if d < 0:
            if -d < round(pp.time_jump_back_threshold_s * 1e9):
                return checks.OUT_OF_ORDER
            if not pp.reset_on_time_jump_back:
                return checks.TIME_BACKWARDS
            self._reset(checks.RESET_TIME_JUMP_BACK)
        elif pp.reset_after_gap_s and d > round(pp.reset_after_gap_s * 1e9):
            self._reset(checks.RESET_LONG_GAP)
        elif d > round(pp.max_dt_s * 1e9):
            self.gaps += 1
        return None

    def on_mag(self, t_ns: int | None, field) -> None:
        self.mag["received"] += 1
        if t_ns is None:
            self.mag["invalid"] += 1
            return
        if not self.use_mag:
            self.mag["disabled"] += 1
            return
        n2 = sum(c * c for c in field)
        if t_ns == 0 or not math.isfinite(n2) or n2 == 0.0:
            self.mag["invalid"] += 1
            return
        if self.pending_mag_ns is not None:
            self.mag["dropped"] += 1
        self.pending_mag_ns = t_ns

    def check(self, pipe: ImuPipeline) -> None:
        c = pipe.counters
        assert c["received_imu"] == self.received
        assert c["processed"] == self.processed
        assert c["rejected"] == self.rejected
        assert c["received_imu"] == c["processed"] + sum(c["rejected"].values())
        assert c["resets"] == self.resets
        assert c["gaps"] == self.gaps
        m = self.mag
        assert c["received_mag"] == m["received"]
        assert (c["mag_invalid"], c["mag_stale"], c["mag_dropped"], c["mag_disabled"]) == (
            m["invalid"], m["stale"], m["dropped"], m["disabled"])
        assert c["mag_used"] + c["mag_rejected"] == m["consumed"]
        assert c["mag_pending"] == (self.pending_mag_ns is not None)
        assert c["received_mag"] == (c["mag_used"] + c["mag_rejected"] + c["mag_stale"]
                                     + c["mag_invalid"] + c["mag_dropped"] + c["mag_disabled"]
                                     + c["mag_pending"])


# -- strategies ----------------------------------------------------------------------------------
FINITE_GOOD = st.floats(-20.0, 20.0, allow_nan=False)
#: beyond any sensor: NaN, +-Inf, huge (up to float max: overflow when squared)
BAD_COMPONENT = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 1.3e156, 1e200, 3.4e38]),
    st.floats(1e4, 1e308).flatmap(lambda v: st.sampled_from([v, -v])),
)
#: extreme but possible: violent motion, a shock
LARGE_PLAUSIBLE = st.floats(-500.0, 500.0, allow_nan=False)
TINY = st.sampled_from([5e-324, 1e-160, -1e-170, 1e-300])


@st.composite
def vec3(draw, bad_prob: bool = True):
    kind = draw(st.sampled_from(["good", "good", "bad", "large", "zero", "tiny"]))
    if kind == "good":
        return tuple(draw(FINITE_GOOD) for _ in range(3))
    if kind == "large":
        return tuple(draw(LARGE_PLAUSIBLE) for _ in range(3))
    if kind == "zero":
        return (0.0, 0.0, 0.0)
    if kind == "tiny":
        return (draw(TINY), 0.0, draw(st.sampled_from([0.0, -0.0, 1e-200])))
    v = [draw(FINITE_GOOD) for _ in range(3)]
    for i in draw(st.sets(st.integers(0, 2), min_size=1)):
        v[i] = draw(BAD_COMPONENT)
    return tuple(v)


FRAMES = st.sampled_from(["imu_link", "", "/imu", "imu link", "ünï/cödé", "x" * 300, "imu\x00"])

#: how the next IMU stamp relates to the stream: ms steps, gaps up to minutes, zero,
#: duplicates, small and large steps back (relative to the last *processed* stamp)
STAMP = st.one_of(
    st.tuples(st.just("step"), st.integers(1_000_000, 50_000_000)),
    st.tuples(st.just("step"), st.integers(1, 999_999)),
    st.tuples(st.just("gap"), st.sampled_from([500_000_001, 5_000_000_001, 60 * 10**9,
                                               300 * 10**9])),
    st.tuples(st.just("gap"), st.integers(50_000_000, 600 * 10**9)),
    st.tuples(st.just("zero"), st.just(0)),
    st.tuples(st.just("dup"), st.just(0)),
    st.tuples(st.just("back"), st.integers(1, 499_999_999)),
    st.tuples(st.just("back"), st.sampled_from([500_000_000, 500_000_001, 93 * 10**9])),
    st.tuples(st.just("back"), st.integers(500_000_000, 86_400 * 10**9)),
)

IMU_EVENT = st.tuples(st.just("imu"), STAMP, vec3(), vec3(), FRAMES,
                      st.one_of(st.none(), st.none(), st.none(), st.integers(0, 5)))
MAG_EVENT = st.tuples(
    st.just("mag"),
    st.sampled_from(["same", "same", "stale", "future", "zero", "malformed"]),
    st.integers(0, 120 * 10**9),
    st.one_of(st.just(MAG_ENU_T), st.just((25.0, 0.0, -43.0)), vec3()),
    FRAMES,
)
PIPELINE_PARAMS = st.builds(
    lambda mdt, gap, jb, rj, mt: PipelineParams(
        max_dt_s=mdt, reset_after_gap_s=0.0 if gap is None else max(gap, mdt),
        time_jump_back_threshold_s=jb, reset_on_time_jump_back=rj, mag_timeout_s=mt),
    st.sampled_from([0.5, 0.05, 2.0]), st.sampled_from([5.0, None, 0.5, 120.0]),
    st.sampled_from([0.5, 0.001, 30.0]), st.booleans(), st.sampled_from([0.5, 0.01, 10.0]),
)


def _resolve_stamp(spec, model: Model, last_emitted: int) -> int:
    kind, value = spec
    ref = model.last_ns if model.last_ns is not None else last_emitted
    if kind == "step" or kind == "gap":
        return last_emitted + value
    if kind == "zero":
        return 0
    if kind == "dup":
        return ref
    return max(1, ref - value)  # back


# -- 1. arbitrary streams: no exception, finite unit outputs, every message accounted for ------
@profile("streams")
@given(
    events=st.lists(st.one_of(IMU_EVENT, IMU_EVENT, IMU_EVENT, MAG_EVENT), max_size=24),
    pp=st.one_of(st.just(PipelineParams()), PIPELINE_PARAMS),
    use_mag=st.booleans(), ned=st.booleans(),
)
def test_any_stream_is_accounted_for_and_outputs_stay_unit(events, pp, use_mag, ned):
    fp = FilterParams(use_mag=use_mag, world_frame="ned" if ned else "enu")
    pipe = ImuPipeline(fp, pp)
    model = Model(pp, use_mag=use_mag)
    last_emitted = T0_NS
    for ev in events:
        if ev[0] == "imu":
            _, stamp_spec, gyro, accel, frame, malformed = ev
            t_ns = _resolve_stamp(stamp_spec, model, last_emitted)
            if t_ns > 0:
                last_emitted = t_ns
            if malformed is not None:
                msg = malformed_imu(malformed, t_ns)
                expected = model.imu(None, gyro, accel)
            else:
                msg = imu_msg(t_ns, gyro, accel, frame)
                expected = model.imu(t_ns, gyro, accel)
            out = pipe.on_imu(msg)
            if expected is None:
                assert out is not None, pipe.last_reject_reason
                check_output(out, frame)
            else:
                assert out is None
                assert pipe.last_reject_reason == expected
        else:
            _, when, offset, field, frame = ev
            t_ns = {"same": last_emitted, "stale": last_emitted - offset,
                    "future": last_emitted + offset, "zero": 0,
                    "malformed": last_emitted}[when]
            t_ns = max(t_ns, 1) if when != "zero" else 0
            if when == "malformed":
                msg = mag_msg(t_ns, field, frame)
                msg.magnetic_field = None
                model.on_mag(None, field)
            else:
                msg = mag_msg(t_ns, field, frame)
                model.on_mag(t_ns, field)
            pipe.on_mag(msg)
        model.check(pipe)
    assert checks.INTERNAL_ERROR not in pipe.counters["rejected"]
    report = pipe.diagnostics(now_s=last_emitted * 1e-9)
    assert report.value("imu_received") == str(model.received)
    assert report.value("imu_processed") == str(model.processed)
    assert report.value("imu_rejected") == str(sum(model.rejected.values()))
    for reason, n in model.rejected.items():
        assert report.value(f"rejected.{reason}") == str(n)
    assert all(isinstance(v, str) for _, v in report.values)


# -- 2. recovery: after the bad data stop, tilt back within 1 deg of the truth in 10 s ----------
@dataclass(frozen=True)
class Truth:
    """A fixed tilt turning at a constant rate about the world vertical (ENU), gyro bias, noise.

    q(t) = Rz(rate·t)·q0: the specific force and the body rate are constant in the sensor frame,
    the tilt (world vertical in the sensor frame) never changes.
    """

    q0: tuple[float, float, float, float]
    yaw_rate: float
    bias: tuple[float, float, float]
    seed: int

    def sensors(self):
        up = rotate_inv(self.q0, (0.0, 0.0, 1.0))
        gyro = tuple(self.yaw_rate * u + b for u, b in zip(up, self.bias, strict=True))
        accel = tuple(G * u for u in up)
        mag = rotate_inv(self.q0, MAG_ENU_T)  # yaw is not checked: mag is only exercised
        return up, gyro, accel, mag


@st.composite
def truths(draw) -> Truth:
    v = [draw(st.floats(-1.0, 1.0)) for _ in range(4)]
    n = math.sqrt(sum(c * c for c in v))
    assume(n > 0.1)
    q0 = tuple(c / n for c in v)
    rate = draw(st.sampled_from([0.0, 0.02, -0.05]))  # rad/s: slow enough to count as "rest"
    bias = tuple(draw(st.sampled_from([0.0, 0.01, -0.02])) for _ in range(3))
    return Truth(q0, rate, bias, draw(st.integers(0, 2**16)))  # type: ignore[arg-type]


BAD_KIND = st.sampled_from([
    "gyro_bad", "accel_bad", "accel_zero", "both_bad", "violent", "accel_wrong", "mag_bad",
    "stamp_zero", "dup", "out_of_order", "back", "gap", "malformed", "frame", "no_mag",
])


@profile("recovery")
@given(
    truth=truths(),
    rate_hz=st.sampled_from([25.0, 10.0, 50.0]),
    good_before_s=st.sampled_from([0.5, 3.0, 0.0, 8.0]),
    bad=st.lists(st.tuples(BAD_KIND, vec3(), st.integers(1, 2**31)), min_size=1, max_size=60),
    mag_every=st.sampled_from([1, 0, 3, 7]),
    frame=FRAMES,
)
def test_tilt_recovers_within_10_s_of_good_data(truth, rate_hz, good_before_s, bad, mag_every,
                                                frame):
    pipe = ImuPipeline()
    up, gyro, accel, mag = truth.sensors()
    rng = random.Random(truth.seed)
    dt_ns = int(1e9 / rate_hz)
    t = T0_NS
    i = 0

    def good(t_ns: int) -> Any:
        nonlocal i
        i += 1
        if mag_every and i % mag_every == 0:
            pipe.on_mag(mag_msg(t_ns, mag, frame))
        g = tuple(c + rng.gauss(0.0, 0.003) for c in gyro)
        a = tuple(c + rng.gauss(0.0, 0.03) for c in accel)
        out = pipe.on_imu(imu_msg(t_ns, g, a, frame))
        if out is not None:
            check_output(out, frame)
        return out

    for _ in range(int(good_before_s * rate_hz)):
        good(t)
        t += dt_ns
    for kind, v, k in bad:
        if kind in ("gyro_bad", "both_bad", "violent"):
            # violent: up to +-500 rad/s per axis, inside GYRO_MAX_RAD_S: integrated as data
            g = v if kind != "violent" else tuple(((k >> s) % 2001 - 1000) * 0.5
                                                  for s in (0, 11, 22))
            a = v if kind == "both_bad" else accel
            out = pipe.on_imu(imu_msg(t, g, a, frame))
        elif kind in ("accel_bad", "accel_zero", "accel_wrong"):
            a = {"accel_bad": v, "accel_zero": (0.0, 0.0, 0.0),
                 "accel_wrong": tuple(c * (k % 40) for c in v)}[kind]
            out = pipe.on_imu(imu_msg(t, gyro, a, frame))
        elif kind == "mag_bad":
            pipe.on_mag(mag_msg(t - (k % 3) * 10**9, v, frame))
            out = good(t)
        elif kind == "stamp_zero":
            out = pipe.on_imu(imu_msg(0, gyro, accel, frame))
        elif kind == "dup":
            out = pipe.on_imu(imu_msg(t - dt_ns, gyro, accel, frame))
        elif kind == "out_of_order":
            out = pipe.on_imu(imu_msg(t - dt_ns - k % (dt_ns * 3), v, v, frame))
        elif kind == "back":  # a bag loop: time restarts earlier (then runs on from there)
            t -= 10**9 * (1 + k % 120)
            out = pipe.on_imu(imu_msg(t, v, accel, frame))
        elif kind == "gap":  # milliseconds to minutes without messages
            t += [dt_ns * 2, 10**9 // 2 + 1, 3 * 10**9, 6 * 10**9, 200 * 10**9][k % 5] + k % 997
            out = good(t)
        elif kind == "malformed":
            out = pipe.on_imu(malformed_imu(k % 6, t))
        elif kind == "frame":
            out = pipe.on_imu(imu_msg(t, gyro, accel, ["", "/odd", "é" * 40][k % 3]))
        else:  # no_mag: a stretch of good IMU data without magnetometer
            for _ in range(1 + k % 50):
                out = pipe.on_imu(imu_msg(t, gyro, accel, frame))
                t += dt_ns
        if out is not None:
            assert all(math.isfinite(c) for c in out.orientation_xyzw)
        t += dt_ns
    # good data: 10 s to recover, then every output must be within 1 deg of the true tilt
    n_recover = int(round(10.0 * rate_hz))
    worst = 0.0
    for j in range(n_recover + int(0.5 * rate_hz) + 1):
        out = good(t)
        t += dt_ns
        if j >= n_recover:
            assert out is not None
            x, y, z, w = out.orientation_xyzw
            worst = max(worst, angle_deg(up_in_sensor((w, x, y, z)), up))
    assert worst < 1.0, f"tilt error {worst:.2f} deg after 10 s of good data"
    c = pipe.counters
    assert c["received_imu"] == c["processed"] + sum(c["rejected"].values())
    assert checks.INTERNAL_ERROR not in c["rejected"]


# -- 3. parameters: schema + live updates -----------------------------------------------------
SPECS = {s.name: s for s in all_specs()}
WRITABLE = [s for s in all_specs() if not s.read_only]
READ_ONLY = [s for s in all_specs() if s.read_only]


def valid_value(spec: ParamSpec) -> st.SearchStrategy:
    if spec.kind == "bool":
        return st.booleans()
    if spec.choices:
        return st.sampled_from(list(spec.choices) + [c.upper() for c in spec.choices])
    if spec.kind == "str":  # a free string (tf_parent_frame): a frame id
        return st.sampled_from(["world", "map", "earth_ned", "uav1/world"])
    if spec.kind == "float_list":  # the magnetometer calibration: a hard iron [T] up to twice
        # the Earth's field, a soft iron within 20 % of the identity (det > 0); ints allowed
        n, scale = (3, 1e-4) if spec.name == "mag_hard_iron_t" else (9, 0.2)
        base = spec.default
        return st.lists(st.floats(-scale, scale), min_size=n, max_size=n).map(
            lambda d, base=base: [b + x for b, x in zip(base, d, strict=True)]) | st.just(
            [int(b) for b in base])
    lo, hi = spec.minimum, spec.maximum
    assert lo is not None and hi is not None
    return st.one_of(
        st.floats(lo, hi, exclude_min=spec.minimum_exclusive, exclude_max=spec.maximum_exclusive),
        st.sampled_from([spec.default, hi] if not spec.maximum_exclusive else [spec.default]),
        st.integers(math.ceil(lo) + (1 if spec.minimum_exclusive and lo == math.ceil(lo) else 0),
                    math.floor(hi)),
    )


def invalid_value(spec: ParamSpec) -> st.SearchStrategy:
    wrong_type = st.sampled_from(["1.0", None, [1.0], {"v": 1}, b"x"])
    if spec.kind == "bool":
        return st.one_of(wrong_type, st.sampled_from([0, 1, 1.0, "true"]))
    if spec.choices:
        return st.one_of(st.sampled_from([None, 1, True, "", "north", "ENUx"]))
    if spec.kind == "str":
        return st.sampled_from([None, 1, True, "", " world", "/world"])
    if spec.kind == "float_list":  # wrong length, non-finite or non-number elements
        n = len(spec.default)
        return st.sampled_from([None, 1.0, "0 0 0", [0.0] * (n - 1), [0.0] * (n + 1),
                                [math.nan] * n, [math.inf] + [0.0] * (n - 1), [True] * n,
                                ["1.0"] * n])
    lo, hi = spec.minimum, spec.maximum
    assert lo is not None and hi is not None
    out = [st.floats(max_value=lo, exclude_max=not spec.minimum_exclusive, allow_nan=False),
           st.floats(min_value=hi, exclude_min=not spec.maximum_exclusive, allow_nan=False),
           st.sampled_from([math.nan, math.inf, -math.inf, True, False]), wrong_type]
    return st.one_of(out)


def _invalid_for_spec(spec: ParamSpec, value: Any) -> bool:
    try:
        spec.check(value)
    except ValueError:
        return True
    return False


@st.composite
def change_sets(draw, valid: bool) -> dict[str, Any]:
    """1-4 writable parameters with valid values (``valid``) or at least one invalid one."""
    k = draw(st.integers(1, 4))
    names = draw(st.permutations([s.name for s in WRITABLE]))[:k]
    changes = {n: draw(valid_value(SPECS[n])) for n in names}
    if not valid:
        how = draw(st.sampled_from(["value", "value", "unknown", "read_only"]))
        if how == "unknown":
            changes[draw(st.sampled_from(["k4", "K1", "imu_topic", "", "k1 "]))] = 1.0
        elif how == "read_only":
            spec = draw(st.sampled_from(READ_ONLY))
            other = {"bool": lambda d: not d,
                     # a choice other than the default; a free string (velocity_topic): another
                     "str": lambda d, c=spec.choices: (next(x for x in c if x != d) if c
                                                       else d + "_other" if d else "other"),
                     "float": lambda d: 2.0 * d}[spec.kind](spec.default)
            changes[spec.name] = other
        else:
            name = draw(st.sampled_from(names))
            value = draw(invalid_value(SPECS[name]).filter(
                lambda v, spec=SPECS[name]: _invalid_for_spec(spec, v)))
            changes[name] = value
    return changes


def _merged(pipe: ImuPipeline, changes: dict[str, Any]) -> dict[str, Any]:
    cur = {s.name: getattr(pipe.filter_params, s.name) for s in all_specs()
           if hasattr(pipe.filter_params, s.name)}
    cur |= {s.name: getattr(pipe.pipeline_params, s.name) for s in all_specs()
            if hasattr(pipe.pipeline_params, s.name)}
    return cur | changes


def _state(pipe: ImuPipeline) -> dict[str, Any]:
    s = pipe.filter.state_snapshot()
    return {name: getattr(s, name) for name in s.FIELDS}


_BASE: dict[tuple[int, int], tuple[ImuPipeline, int, random.Random]] = {}


def _running_pipeline(seed: int, n: int = 60) -> tuple[ImuPipeline, int, random.Random]:
    """A copy of a pipeline n samples into a tilted, turning, magnetometer-referenced stream
    (100 Hz, accelerometer noise); built once per (seed, n)."""
    key = (seed % 16, n)
    if key not in _BASE:
        _BASE[key] = _build_running_pipeline(*key)
    return copy.deepcopy(_BASE[key])


def _build_running_pipeline(seed: int, n: int) -> tuple[ImuPipeline, int, random.Random]:
    rng = random.Random(seed)
    pipe = ImuPipeline()
    q0 = (0.9, 0.3, -0.2, 0.25)
    nq = math.sqrt(sum(c * c for c in q0))
    q0 = tuple(c / nq for c in q0)
    t = T0_NS
    for _ in range(n):
        g = (rng.gauss(0.05, 0.02), rng.gauss(-0.03, 0.02), rng.gauss(0.2, 0.02))
        a = tuple(c + rng.gauss(0.0, 0.5) for c in rotate_inv(q0, (0.0, 0.0, G)))
        pipe.on_mag(mag_msg(t, rotate_inv(q0, MAG_ENU_T)))
        assert pipe.on_imu(imu_msg(t, g, a)) is not None
        t += 10_000_000
    return pipe, t, rng


@profile("params_invalid")
@given(changes=change_sets(valid=False), seed=st.integers(0, 15))
def test_invalid_parameter_changes_are_refused_and_change_nothing(changes, seed):
    pipe, t, rng = _running_pipeline(seed, n=20)
    read_only = any(n in SPECS and SPECS[n].read_only for n in changes)
    schema_reason = None
    try:  # the schema refuses the merged set too (except a read-only change: valid at start-up)
        build_params(_merged(pipe, changes))
    except ValueError as exc:
        schema_reason = str(exc)
    assert read_only or schema_reason is not None
    twin = copy.deepcopy(pipe)
    state, fp, pp, counters = _state(pipe), pipe.filter_params, pipe.pipeline_params, pipe.counters
    ok, reason = pipe.validate_changes(changes)
    assert not ok and reason and "\n" not in reason
    ok2, reason2 = pipe.apply_changes(changes)
    assert (ok2, reason2) == (False, reason)
    if read_only:
        assert "read-only at run time" in reason or schema_reason == reason
    elif "unknown parameter" not in reason:
        assert reason == schema_reason  # the same one-line reason as the schema gives
    assert pipe.filter_params is fp and pipe.pipeline_params is pp
    assert _state(pipe) == state and pipe.counters == counters
    # and the next sample is processed exactly as if nothing had been tried
    msg = imu_msg(t, (0.01, 0.02, 0.2), (0.3, 1.0, 9.7))
    a, b = pipe.on_imu(msg), twin.on_imu(msg)
    assert a is not None and b is not None
    assert a.orientation_xyzw == b.orientation_xyzw
    assert a.orientation_covariance == b.orientation_covariance


@profile("params_valid")
# a large k1 whose running gain differs from it (the covariance's k1: loop_k1)
@example(changes={"k1": 100.0, "k2": 0.0, "max_dt_s": 1.0}, seed=0, next_dt_ns=700_000_000)
@given(changes=change_sets(valid=True), seed=st.integers(0, 15),
       next_dt_ns=st.sampled_from([10_000_000, 10_000_000, 40_000_000, 700_000_000]))
def test_valid_parameter_changes_apply_at_the_next_sample_without_reset(changes, seed,
                                                                        next_dt_ns):
    pipe, t, rng = _running_pipeline(seed, n=20)
    try:
        fp_new, pp_new = build_params(_merged(pipe, changes))
    except ValueError as exc:  # valid one by one, but a cross-parameter rule fails
        ok, reason = pipe.apply_changes(changes)
        assert not ok and reason == str(exc)
        return
    state = _state(pipe)
    assert pipe.validate_changes(changes) == (True, "")
    assert _state(pipe) == state  # validating changes nothing
    assert pipe.apply_changes(changes) == (True, "")
    assert pipe.filter_params == fp_new and pipe.pipeline_params == pp_new
    assert _state(pipe) == state  # attitude, bias, phase, everything kept
    assert pipe.initialized and not pipe.counters["resets"]
    # the next sample runs with the new values: the filter step equals a filter built with them
    # from the same state, and the time guards use the new thresholds
    model = Model(pp_new, use_mag=fp_new.use_mag, last_ns=t - 10_000_000)
    t_next = t - 10_000_000 + next_dt_ns
    gyro, accel = (0.02, -0.01, 0.25), (0.4, -0.8, 9.6)
    expected = model.imu(t_next, gyro, accel)
    ref = copy.deepcopy(pipe.filter)  # the same state: both bias hypotheses, the published one
    ref.set_params(fp_new)
    before_gaps = pipe.counters["gaps"]
    out = pipe.on_imu(imu_msg(t_next, gyro, accel))
    assert expected is None and out is not None
    check_output(out, pipe.output_frame_id("imu_link"))  # output_frame_id: 'auto' here
    if model.resets:
        assert pipe.counters["resets"] == model.resets
        return
    assert pipe.counters["gaps"] - before_gaps == model.gaps
    dt = next_dt_ns * 1e-9 if not model.gaps else None
    if dt is not None:
        # the published frame: the core's, turned by declination and yaw offset (frames.py)
        w, x, y, z = pipe.output_frame.apply_array(
            np.array([ref.update(gyro, accel, dt, None)]))[0].tolist()
        assert out.orientation_xyzw == (x, y, z, w)
    # the covariance model (docs/ros_interface.md, core/covariance.py) with the new floors and
    # gains: tilt = floor + the error norm squared while settling + half the mean square of the
    # accelerometer channel's correction, the square of the disagreement's steady part (the
    # model's state) and the vibration term (+ the clipped drift while clipped)
    cov = out.orientation_covariance
    status = pipe.filter.status()
    settling = status.phase in ("startup", "recovering")
    floor = pp_new.orientation_covariance_rad2
    model = pipe.covariance_model  # the mean square it holds after this step
    assert model.tilt0 == floor and model.k1 == fp_new.k1 and model.r1 == fp_new.r1
    tilt = floor + (status.error_norm_rad**2 if settling else 0.0)
    if dt is not None:
        noise = pipe.filter._state.noise_a2 / (6.0 * fp_new.gravity_m_s2**2) * dt  # noqa: SLF001
        steady = model._sx * model._sx + model._sy * model._sy  # noqa: SLF001
        # the loop's running gain (bias.loop_gain: below a large configured k1 in a swing)
        loop_k1 = pipe.filter._state.loop_k1  # noqa: SLF001
        k1 = loop_k1 if loop_k1 > 0.0 else fp_new.k1
        tilt += 0.5 * (model._ms + steady + noise * k1)  # noqa: SLF001
    tilt = min(tilt, max(math.pi**2, floor))
    assert cov[0] == cov[4]
    if status.clipped or dt is None:
        assert cov[0] >= min(floor, math.pi**2) * (1.0 - 1e-12)
    else:
        assert cov[0] == pytest.approx(tilt, rel=1e-12, abs=0.0)
    if status.heading_initialized:
        assert cov[8] >= pp_new.yaw_covariance_rad2
    else:
        assert cov[8] == pp_new.unreferenced_yaw_covariance_rad2


@profile("read_only")
@given(spec=st.sampled_from(READ_ONLY), data=st.data())
def test_read_only_parameters_refuse_a_different_value_and_accept_the_same(spec, data):
    """world_frame, publish_rpy, diagnostics_period_s: fixed at start-up.

    The pipeline refuses any different value ("read-only at run time"), accepts its current
    value as a no-op (rclpy itself refuses every set of a read-only parameter in the node).
    publish_rpy and diagnostics_period_s are not used by the pipeline at all (they wire the
    node's publisher and timer); world_frame selects the output frame.
    """
    pipe, t, _ = _running_pipeline(0, n=10)
    in_filter = hasattr(pipe.filter_params, spec.name)

    def value_in_force() -> Any:
        return getattr(pipe.filter_params if in_filter else pipe.pipeline_params, spec.name)

    current = value_in_force()
    value = data.draw(valid_value(spec))
    state = _state(pipe)
    ok, reason = pipe.apply_changes({spec.name: value})
    same = spec.check(value) == current
    assert ok == same
    if not same:
        assert reason == f"{spec.name} is read-only at run time (restart the node to change it)"
    assert value_in_force() == current
    assert _state(pipe) == state


def test_ci_profile_runs_at_least_10000_cases():
    assert CI_TOTAL >= 10_000


# -- regressions found by the fuzzing ------------------------------------------------------------
@pytest.mark.parametrize(("gyro", "accel", "reason"), [
    ((1.3e156, 0.0, 0.0), (0.0, 0.0, G), "implausible_gyro"),  # overflowed in the filter
    ((1e10, 0.0, 0.0), (0.0, 0.0, G), "implausible_gyro"),  # tilt took > 10 s to recover
    ((0.0, 0.0, 0.0), (1e100, 0.0, 0.0), "implausible_accel"),  # rest detector blocked minutes
    ((0.0, 0.0, 0.0), (1e200, 0.0, 1.0), "implausible_accel"),  # was "nonfinite_accel"
    ((1e308, 1e308, 0.0), (0.0, 0.0, G), "implausible_gyro"),  # was "nonfinite_gyro"
])
def test_absurd_magnitudes_are_rejected_not_integrated(gyro, accel, reason):
    pipe = ImuPipeline()
    t = T0_NS
    for _ in range(300):
        assert pipe.on_imu(imu_msg(t, (0.0, 0.0, 0.0), (0.0, 0.0, G))) is not None
        t += 10_000_000
    state = _state(pipe)
    assert pipe.on_imu(imu_msg(t, gyro, accel)) is None
    assert pipe.last_reject_reason == reason
    assert _state(pipe) == state
    out = pipe.on_imu(imu_msg(t + 10_000_000, (0.0, 0.0, 0.0), (0.0, 0.0, G)))
    assert out is not None and abs(out.orientation_xyzw[3]) > 0.99999
    assert pipe.counters["rejected"] == {reason: 1}


def test_a_sub_nanosecond_reset_after_gap_still_resets():
    pipe = ImuPipeline(pipeline_params=PipelineParams(max_dt_s=1e-12, reset_after_gap_s=1e-12))
    pipe.on_imu(imu_msg(T0_NS, (0.0, 0.0, 0.0), (0.0, 0.0, G)))
    pipe.on_imu(imu_msg(T0_NS + 10_000_000, (0.0, 0.0, 0.0), (0.0, 0.0, G)))
    assert pipe.counters["resets"] == {"long_gap": 1}  # was: 0 (rounded to 0 ns = "never")
