"""Fault injection on the real recordings (../shared/data/bags), replayed through the pipeline.

Each bag is read once with rosbags (ROS 1 files read in place, never copied into the repo) and
replayed message by message, in recorded order, through a fresh :class:`ImuPipeline`: once clean,
and once per fault:

=================  ==========================================  ================================
fault              what is done to the message stream           how it must be counted
=================  ==========================================  ================================
drop 10 %          each message (IMU and mag) of the faulted    invisible to the pipeline (no
                   stretch dropped with probability 0.1         rejection): received = sent
duplicate 1 %      1 % of the messages sent twice in a row      ``rejected.duplicate_stamp`` per
                                                                IMU copy, ``mag_dropped`` per mag
swap 1 %           1 % of the IMU messages swapped with the     ``rejected.out_of_order`` per
                   next one (also over the whole bag)           swap (the late one is refused)
NaN bursts         bursts of 10 messages: gyro NaN, accel NaN,  ``rejected.nonfinite_gyro`` /
                   both, and magnetometer NaN                   ``nonfinite_accel``; mag_invalid
5 s gap            every message of 5 s removed                 ``reset.long_gap`` = 1
loop               the bag played twice back to back, as        ``reset.time_jump_back`` = 1
                   ``ros2 bag play --loop`` does (stamps jump
                   back by the bag's length)
=================  ==========================================  ================================

Invariants: every output finite and unit-norm; every IMU message sent is processed or rejected
with the right reason, in ``counters`` and in ``diagnostics()``; the tilt (the world vertical
seen in the sensor frame) stays within 2 deg of the clean replay outside the faulted stretches.

**Faulted stretches** (where the tilt comparison is skipped): the fault itself plus a settling
window of ``SETTLE_S`` = 15 s after it (``SETTLE_RESET_S`` = 35 s after the 5 s gap, see below). Why
15 s: a fault that loses samples (drop, swap, NaN, gap) loses gyro information, so the faulted
estimate deviates from the clean one during fast motion (the AR.Drone turns at up to 23 rad/s: one
lost sample is up to ~25 deg). Nothing in the faulted run is then wrong, it just has less
information; the deviation is removed by the accelerometer channel, i.e. as fast as the filter
corrects any attitude error: within ~3 s at rest (rest detection after two still blocks, 1.5 s with
the first, then the start-up gain), at the clipped rate ``k1*saturation_limit_rad`` ~ 0.3 deg/s in
motion until the ``recovery_trigger_s`` = 10 s recovery mode takes over: 10 s + a few seconds of
convergence. The 5 s gap resets the filter (gap > ``reset_after_gap_s``) and re-initialises it from
the single accelerometer sample after the gap, then runs the 2 s start-up phase (high gain, no
clip): during a manoeuvre the estimate follows the linear accelerations, and the error left is
removed at the clipped rate: measured up to 33 s on the AR.Drone (a gap at 54 s), hence 35 s. Faults
are placed at fixed fractions of each bag (chosen before looking at the results, not tuned);
measured settling times at other positions are in docs/failure_modes.md. Duplicates and the loop
lose no information: their tilt must match the clean replay everywhere (duplicates: bit for bit).
"""

from __future__ import annotations

import copy
import math
import random
import subprocess
import sys
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cf_estimator.bag import io
from cf_estimator.pipeline import ImuPipeline

REPO = Path(__file__).resolve().parents[1]
BAGS = REPO.parent / "shared" / "data" / "bags"
BAG_NAMES = ["ardrone_imu.bag", "sparkfun_razor.bag"]
SETTLE_S = 15.0
#: after a reset (the 5 s gap) the filter restarts from one accelerometer sample and runs its
#: 2 s start-up phase at high gain: during a manoeuvre that follows linear accelerations, and
#: what is left is corrected at the clipped rate in motion (measured: up to 33 s on the AR.Drone)
SETTLE_RESET_S = 35.0
TILT_TOLERANCE_DEG = 2.0
#: where faults start, as a fraction of each bag's IMU stamp span (fixed beforehand)
FAULT_AT = {"ardrone_imu.bag": (0.25, 0.5), "sparkfun_razor.bag": (0.25,)}
FAULT_LENGTH_S = 5.0

Event = tuple[bool, object]  # (is_imu, message)


def _require(path: Path) -> Path:
    if not path.is_file():
        pytest.skip(f"real recording {path} not available (expected in ../shared/data/bags)")
    return path


def stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def load_events(path: Path) -> list[Event]:
    """IMU and magnetometer messages of a bag in recorded (log-time) order."""
    with io.open_bag(path) as bag:
        imu = bag.select_topic("IMU", None, [io.IMU_TYPE], required=True, option="--imu-topic")
        mag = bag.select_topic("mag", None, [io.MAG_TYPE], required=False, option="--mag-topic")
        topics = [t for t in (imu, mag) if t is not None]
        return [(m.topic == imu, m.msg) for m in bag.messages(topics)]


class Run:
    """One replay: outputs (world vertical in the sensor frame per stamp) and the pipeline."""

    def __init__(self, events: list[Event]) -> None:
        self.pipe = ImuPipeline()
        self.up: dict[int, np.ndarray] = {}
        self.q: dict[int, tuple[float, ...]] = {}
        self.sent_imu = 0
        self.up_by_pass: list[dict[int, np.ndarray]] = [{}]
        #: stamps [s] where the filter's still phase began (it then trusts the accelerometer
        #: with the start-up gain: two runs whose 0.5 s stillness blocks start at different
        #: samples, e.g. after a reset, enter it up to a block apart)
        self.rest_onsets: list[float] = []
        was_rest = False
        last = None
        for is_imu, msg in events:
            if not is_imu:
                self.pipe.on_mag(msg)
                continue
            self.sent_imu += 1
            t = stamp_ns(msg)
            if last is not None and t < last - 10**9:  # a loop: a new pass begins
                self.up_by_pass.append({})
            last = t
            out = self.pipe.on_imu(msg)
            if out is None:
                continue
            q = out.orientation_xyzw
            assert all(math.isfinite(c) for c in q)
            assert abs(math.sqrt(sum(c * c for c in q)) - 1.0) < 1e-9
            assert all(math.isfinite(c) for c in out.rpy_rad)
            x, y, z, w = q
            up = np.array([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])
            self.up[t] = up
            self.q[t] = q
            rest = self.pipe.filter.status().at_rest
            if rest and not was_rest:
                self.rest_onsets.append(t * 1e-9)
            was_rest = rest
            self.up_by_pass[-1][t] = up
        c = self.pipe.counters
        assert c["received_imu"] == self.sent_imu
        assert c["received_imu"] == c["processed"] + sum(c["rejected"].values())
        assert c["received_mag"] == (c["mag_used"] + c["mag_rejected"] + c["mag_stale"]
                                     + c["mag_invalid"] + c["mag_dropped"] + c["mag_disabled"]
                                     + c["mag_pending"])


#: After a rest onset in either run, the runs may differ this long [s]: one block (0.5 s) of
#: onset offset, then the start-up gain (5 1/s) removes the difference.
REST_ONSET_SETTLE_S = 1.5


def rest_onset_stretches(*runs: Run) -> list[tuple[float, float]]:
    """[onset, onset + REST_ONSET_SETTLE_S] for every rest onset of the runs."""
    return [(t, t + REST_ONSET_SETTLE_S) for r in runs for t in r.rest_onsets]


def tilt_deviation(clean: dict[int, np.ndarray], faulted: dict[int, np.ndarray],
                   excluded: list[tuple[float, float]]) -> tuple[int, float]:
    """(samples compared, max angle [deg]) between the two tilts at common stamps outside
    the excluded [start, end] stretches (seconds)."""
    worst, n = 0.0, 0
    for t, u in faulted.items():
        v = clean.get(t)
        if v is None or any(a <= t * 1e-9 <= b for a, b in excluded):
            continue
        n += 1
        worst = max(worst, math.degrees(math.acos(max(-1.0, min(1.0, float(u @ v))))))
    return n, worst


def with_vectors(msg, gyro=None, accel=None, field=None):
    """A copy of a bag message with some vectors replaced (e.g. by NaN)."""
    new = copy.deepcopy(msg)
    for attr, value in (("angular_velocity", gyro), ("linear_acceleration", accel),
                        ("magnetic_field", field)):
        if value is not None:
            vec = getattr(new, attr)
            vec.x, vec.y, vec.z = value
    return new


# -- faults: (events, stretches) -> faulted events, expected counter deltas ----------------------
def fault_drop(events, a, b, rng):
    out = [e for e in events if not (a <= stamp_ns(e[1]) * 1e-9 <= b and rng.random() < 0.1)]
    return out, {}


def fault_swap(events, a, b, rng, rate: float = 0.01):
    """Each IMU message in [a, b] swapped with the next IMU message with probability ``rate``."""
    out = list(events)
    imu_idx = [i for i, (is_imu, _) in enumerate(out) if is_imu]
    swaps = 0
    k = 0
    while k < len(imu_idx) - 1:
        i, j = imu_idx[k], imu_idx[k + 1]
        t_i, t_j = stamp_ns(out[i][1]), stamp_ns(out[j][1])
        # neighbours less than time_jump_back_threshold_s apart (else it is a time jump)
        if a <= t_i * 1e-9 <= b and rng.random() < rate and 0 < t_j - t_i < 500_000_000:
            out[i], out[j] = out[j], out[i]
            swaps += 1
            k += 2
        else:
            k += 1
    return out, {"rejected.out_of_order": swaps}


def fault_duplicate(events, a, b, rng):
    out, n_imu, n_mag = [], 0, 0
    for e in events:
        out.append(e)
        if rng.random() < 0.01:
            out.append(e)
            n_imu += e[0]
            n_mag += not e[0]
    return out, {"rejected.duplicate_stamp": n_imu, "mag_dropped+": n_mag}


def fault_nan(events, a, b, rng):
    """Bursts of 10 messages in [a, b]: gyro NaN, then accel NaN, then both, mag NaN."""
    out, counts, burst, kind = [], {"nonfinite_gyro": 0, "nonfinite_accel": 0, "mag": 0}, 0, 0
    nan3 = (math.nan, math.nan, math.nan)
    for is_imu, msg in events:
        inside = a <= stamp_ns(msg) * 1e-9 <= b
        if inside and burst == 0 and is_imu and rng.random() < 0.05:
            burst, kind = 10, (kind + 1) % 3
        if burst and inside:
            if is_imu:
                burst -= 1
                g = (math.nan, 0.0, 0.0) if kind in (0, 2) else None
                acc = (0.0, math.inf, math.nan) if kind in (1, 2) else None
                msg = with_vectors(msg, gyro=g, accel=acc)
                counts["nonfinite_gyro" if g else "nonfinite_accel"] += 1
            else:
                msg = with_vectors(msg, field=nan3)
                counts["mag"] += 1
        out.append((is_imu, msg))
    return out, {"rejected.nonfinite_gyro": counts["nonfinite_gyro"],
                 "rejected.nonfinite_accel": counts["nonfinite_accel"],
                 "mag_invalid+": counts["mag"]}


def fault_gap(events, a, b, rng):
    out = [e for e in events if not (a <= stamp_ns(e[1]) * 1e-9 <= a + 5.0)]
    return out, {"reset.long_gap": 1}


FAULTS: dict[str, Callable] = {
    "drop_10pc": fault_drop, "swap_1pc": fault_swap, "nan_bursts": fault_nan,
    "gap_5s": fault_gap,
}


@pytest.fixture(scope="module", params=BAG_NAMES)
def bag(request):
    path = _require(BAGS / request.param)
    events = load_events(path)
    clean = Run(events)
    stamps = [stamp_ns(m) * 1e-9 for is_imu, m in events if is_imu]
    return {"name": request.param, "events": events, "clean": clean,
            "t0": stamps[0], "t1": stamps[-1]}


def _diag(pipe: ImuPipeline) -> dict[str, str]:
    return dict(pipe.diagnostics().values)


def _check_counts(clean: Run, run: Run, expected: dict[str, int]) -> None:
    d_clean, d_run = _diag(clean.pipe), _diag(run.pipe)
    c_clean, c_run = clean.pipe.counters, run.pipe.counters
    for key, n in expected.items():
        if key.endswith("+"):  # a magnetometer counter, relative to the clean replay
            name = key[:-1]
            assert c_run[name] - c_clean[name] == n, (name, c_run[name], c_clean[name])
        else:  # a /diagnostics key
            assert d_run.get(key, "0") == str(n), (key, d_run.get(key), n)
    rejected = {k for k in d_run if k.startswith("rejected.")}
    assert rejected <= {k for k in expected if k.startswith("rejected.")} | {
        k for k in d_clean if k.startswith("rejected.")}
    resets = {k for k in d_run if k.startswith("reset.")}
    assert resets == {k for k in expected if k.startswith("reset.")}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_faulted_replay_stays_finite_counted_and_close_to_clean(bag, fault):
    rng = random.Random(zlib.crc32(fault.encode()))  # stable across runs (hash() is salted)
    span = bag["t1"] - bag["t0"]
    events, stretches, expected = bag["events"], [], {}
    positions = FAULT_AT[bag["name"]][:1] if fault == "gap_5s" else FAULT_AT[bag["name"]]
    for frac in positions:
        a = bag["t0"] + frac * span
        b = a + FAULT_LENGTH_S
        events, exp = FAULTS[fault](events, a, b, rng)
        for k, v in exp.items():
            expected[k] = expected.get(k, 0) + v
        stretches.append((a, b + (SETTLE_RESET_S if fault == "gap_5s" else SETTLE_S)))
    run = Run(events)
    _check_counts(bag["clean"], run, expected)
    n, worst = tilt_deviation(bag["clean"].up, run.up,
                              stretches + rest_onset_stretches(bag["clean"], run))
    assert n > 0.1 * len(bag["clean"].up), "nothing left to compare"
    assert worst < TILT_TOLERANCE_DEG, f"{fault}: tilt {worst:.2f} deg off the clean replay"


#: Whole-bag swaps: the worst tilt deviation from the clean replay at any stamp, measured
#: (ardrone 3.8 deg, sparkfun 12.3 deg) with margin. Each swap loses one sample, and with 1 % of
#: all messages swapped no stamp is outside a faulted stretch: this is a regression bound only.
SWAP_EVERYWHERE_BOUND_DEG = {"ardrone_imu.bag": 6.0, "sparkfun_razor.bag": 18.0}


def test_swaps_all_over_the_bag_are_each_counted(bag):
    events, expected = fault_swap(bag["events"], -math.inf, math.inf, random.Random(11))
    assert expected["rejected.out_of_order"] > 5
    run = Run(events)
    _check_counts(bag["clean"], run, expected)
    _, worst = tilt_deviation(bag["clean"].up, run.up, [])
    assert worst < SWAP_EVERYWHERE_BOUND_DEG[bag["name"]]


def test_gap_in_the_middle_of_the_ardrone_flight():
    # A reset in the flight part (5 s gap at 46 s): the restart's start-up phase runs during the
    # flight. Before the error was made linear in the acceleration (a/‖g‖, not a/|a|) the tilt
    # stayed 2-10 deg off the clean replay until the recording ended; now it re-converges.
    events = load_events(_require(BAGS / "ardrone_imu.bag"))
    clean = Run(events)
    stamps = [stamp_ns(m) * 1e-9 for is_imu, m in events if is_imu]
    a = stamps[0] + 0.5 * (stamps[-1] - stamps[0])
    faulted, expected = fault_gap(events, a, a + 5.0, None)
    run = Run(faulted)
    assert run.pipe.counters["resets"] == {"long_gap": 1}
    _, worst = tilt_deviation(clean.up, run.up, [(a, a + 5.0 + SETTLE_RESET_S)]
                              + rest_onset_stretches(clean, run))
    assert worst < TILT_TOLERANCE_DEG


def test_duplicates_change_nothing_but_the_counters(bag):
    events, expected = fault_duplicate(bag["events"], 0.0, 0.0, random.Random(3))
    assert expected["rejected.duplicate_stamp"] > 10
    run = Run(events)
    _check_counts(bag["clean"], run, expected)
    assert run.q == bag["clean"].q  # bit for bit: a duplicate carries no information


def test_bag_played_twice_like_ros2_bag_play_loop(bag):
    """Stamps jump back by the bag's length: one reset, then the second pass equals the first."""
    events = bag["events"] + bag["events"]
    run = Run(events)
    clean = bag["clean"]
    c = run.pipe.counters
    assert c["resets"] == {"time_jump_back": 1}
    assert c["processed"] == 2 * clean.pipe.counters["processed"]
    assert _diag(run.pipe)["reset.time_jump_back"] == "1"
    assert len(run.up_by_pass) == 2
    n, worst = tilt_deviation(clean.up, run.up_by_pass[1], [])
    assert n == len(clean.up)
    assert worst < TILT_TOLERANCE_DEG


def test_soak_script_smoke(tmp_path):
    """A few thousand messages through the soak benchmark (the full run is an hour of data)."""
    proc = subprocess.run(
        [sys.executable, "-m", "cf_estimator.bench.soak", "--duration-s", "4",
         "--rate-hz", "1000", "--json", str(tmp_path / "soak.json")],
        capture_output=True, text=True, timeout=300, cwd=REPO,
    )
    assert proc.returncode == 0, proc.stderr
    import json

    report = json.loads((tmp_path / "soak.json").read_text())
    assert report["messages"] == 4000
    assert report["rejected"] == 0
    assert report["max_static_error_deg"] < 1.0
    assert report["tracemalloc_peak_bytes"] > 0
    assert len(report["segments"]) == 10
