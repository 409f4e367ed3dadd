"""Speed: per-sample update rate from Python (ours and peers), pipeline per-message time, the
batched filter's parameter-samples per second, and bag replay throughput against a plain rosbags
read of the same bag — all measured in one run.

Timings on a shared machine are noisy: compare the ratios within one run, not absolute numbers
across runs.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from cf_estimator.core.batch import estimate_many
from cf_estimator.core.filter import ComplementaryFilter
from cf_estimator.core.params import FilterParams


def _inputs(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    gyro = rng.normal(0.0, 0.3, (n, 3))
    acc = rng.normal(0.0, 0.3, (n, 3)) + np.array([0.0, 0.0, 9.81])
    mag = rng.normal(0.0, 0.3, (n, 3)) + np.array([0.0, 20.0, -40.0])
    return gyro, acc, mag


#: Timed runs of each estimator in :func:`per_sample_rates`, interleaved; the best is kept.
PER_SAMPLE_REPEATS = 5


def per_sample_rates(n: int = 20000, peers: tuple[str, ...] = ("vqf", "fusion", "madgwick"),
                     rate_hz: float = 200.0, repeats: int = PER_SAMPLE_REPEATS
                     ) -> dict[str, float]:
    """Samples per second of one 9-D update called from Python, per estimator.

    The same method for every estimator: ``repeats`` rounds, each running every estimator's
    loop once in turn (interleaved, so a slow spell of a shared machine hits them alike), each
    run on a freshly built estimator over the same ``n`` samples; each estimator's fastest run
    is kept (the least disturbed: noise only ever adds time). ``madgwick`` times at most 20000
    samples per run, ``complementary`` (a whole-array port) at most 5000.
    """
    gyro, acc, mag = _inputs(n)
    dt = 1.0 / rate_hz
    g_t = [tuple(r) for r in gyro.tolist()]
    a_t = [tuple(r) for r in acc.tolist()]
    m_t = [tuple(r) for r in mag.tolist()]

    def ours() -> float:
        upd = ComplementaryFilter(FilterParams()).update
        t0 = time.perf_counter()
        for i in range(n):
            upd(g_t[i], a_t[i], dt, m_t[i])
        return n / (time.perf_counter() - t0)

    runs: dict[str, Any] = {"cf_estimator": ours}
    if "vqf" in peers:
        from vqf import VQF

        def run_vqf() -> float:
            v = VQF(dt)
            t0 = time.perf_counter()
            for i in range(n):
                v.update(gyro[i], acc[i], mag[i])
                v.getQuat9D()
            return n / (time.perf_counter() - t0)

        runs["vqf"] = run_vqf
    if "fusion" in peers:  # as the bench runs it: the offset module, then the AHRS update
        from cf_estimator.bench.peers import fusion_recommended

        gd, ag = np.degrees(gyro), acc / 9.80665

        def run_fusion() -> float:
            ah, bias = fusion_recommended(rate_hz)
            t0 = time.perf_counter()
            for i in range(n):
                ah.update(bias.update(gd[i]), ag[i], mag[i])
                ah.get_quaternion()
            return n / (time.perf_counter() - t0)

        runs["fusion"] = run_fusion
    if "madgwick" in peers:  # the bench's float port of ahrs' Madgwick, gain 0.1
        from cf_estimator.bench.peers import MADGWICK_ROS_GAIN, madgwick_step

        m = min(n, 20000)
        gl, al, ml = gyro.tolist(), acc.tolist(), mag.tolist()

        def run_madgwick() -> float:
            q = (1.0, 0.0, 0.0, 0.0)
            t0 = time.perf_counter()
            for i in range(m):
                q = madgwick_step(q, gl[i], al[i], ml[i], MADGWICK_ROS_GAIN, dt)
            return m / (time.perf_counter() - t0)

        runs["madgwick"] = run_madgwick
    if "complementary" in peers:  # the port runs a whole array (one Python loop inside)
        from cf_estimator.bench.peers import run_complementary

        mc = min(n, 5000)

        def run_compl() -> float:
            t0 = time.perf_counter()
            run_complementary(gyro[:mc], acc[:mc], mag[:mc], rate_hz)
            return mc / (time.perf_counter() - t0)

        runs["complementary"] = run_compl
    out = dict.fromkeys(runs, 0.0)
    for _ in range(max(1, repeats)):
        for name, run in runs.items():
            out[name] = max(out[name], run())
    return out


def pipeline_times_us(n: int = 20000, rate_hz: float = 200.0) -> dict[str, float] | None:
    """Median and p99 [µs] of ImuPipeline.on_imu per message (None if the pipeline is missing)."""
    try:
        from cf_estimator.pipeline.pipeline import ImuPipeline
    except ImportError:
        return None
    gyro, acc, mag = _inputs(n)
    pipe = ImuPipeline()
    times = np.empty(n)
    step_ns = int(1e9 / rate_hz)
    cov = [0.0] * 9

    def vec(r):
        return SimpleNamespace(x=float(r[0]), y=float(r[1]), z=float(r[2]))

    msgs = []
    for i in range(n):
        t_ns = 10**9 + i * step_ns
        stamp = SimpleNamespace(sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        header = SimpleNamespace(stamp=stamp, frame_id="imu_link")
        msgs.append(SimpleNamespace(
            header=header, angular_velocity=vec(gyro[i]), linear_acceleration=vec(acc[i]),
            orientation=SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0),
            orientation_covariance=cov, angular_velocity_covariance=cov,
            linear_acceleration_covariance=cov))
    for i, msg in enumerate(msgs):
        t0 = time.perf_counter()
        pipe.on_imu(msg)
        times[i] = time.perf_counter() - t0
    times *= 1e6
    return {"median_us": float(np.median(times)), "p99_us": float(np.percentile(times, 99))}


def batched_rate(p: int = 256, n: int = 2000) -> float:
    """Parameter-samples per second of estimate_many with ``p`` parameter sets (9-D)."""
    gyro, acc, mag = _inputs(n)
    params = [FilterParams(k1=k) for k in np.linspace(0.2, 2.0, p)]
    t0 = time.perf_counter()
    estimate_many(params, gyro, acc, mag, rate_hz=200.0, on_candidate=lambda _p, _q: None)
    return p * n / (time.perf_counter() - t0)


def format_speed(rates: dict[str, float], pipe: dict[str, float] | None, batched: dict[int, float]
                 ) -> str:
    """The speed table."""
    from cf_estimator.core.kernel import resolve_backend

    lines = [f"cf_estimator filter backend: {resolve_backend()} (core/kernel.py)",
             "Per-sample 9-D update called from Python [samples/s], best of "
             f"{PER_SAMPLE_REPEATS} interleaved runs (ratio to imufusion)"]
    ref = rates.get("fusion")
    for k, v in rates.items():
        ratio = f"  x{v / ref:.2f}" if ref else ""
        lines.append(f"  {k:<14} {v:12,.0f}{ratio}")
    lines.append("Pipeline ImuPipeline.on_imu per message [us]: " + (
        "n/a (pipeline not available)" if pipe is None
        else f"median {pipe['median_us']:.1f}, p99 {pipe['p99_us']:.1f}"))
    for p, v in batched.items():
        lines.append(f"Batched filter, P={p}: {v:,.0f} parameter-samples/s")
    return "\n".join(lines) + "\n"


#: Bag simulated when none is given: scenario, duration [s]. 30 s of the 200 Hz flight replays
#: 6000 IMU + 3000 magnetometer messages, about the size of the AR.Drone sample bag.
DEFAULT_BAG_SCENARIO = ("flight", 30.0)


@dataclass
class BagThroughput:
    """Messages per second [1/s] over the replayed topics of one bag, best of ``repeats`` runs.

    Each figure includes opening the bag (and, for ROS 1 bags, rosbags' type generation).
    """

    bag: str  #: the input bag, or a description of the simulated one
    topics: dict[str, int]  #: messages per replayed topic (IMU, magnetometer)
    messages: dict[str, int]  #: messages handled per measurement (all equal: same connections)
    replay_per_s: float  #: replay_bag: read, deserialize, pipeline, serialize, write mcap
    read_per_s: float  #: plain AnyReader loop, raw bytes only
    read_deserialize_per_s: float  #: plain AnyReader loop + reader.deserialize
    output_bytes: int  #: size of one replay output bag [bytes] (deleted after measuring)
    repeats: int


def _read_bag(path: Path, topics: list[str], deserialize: bool) -> tuple[int, float]:
    """(messages, wall time [s]) of a plain AnyReader pass over ``topics``, open to close."""
    from rosbags.highlevel import AnyReader

    from cf_estimator.bag import io

    n = 0
    t0 = time.perf_counter()
    with AnyReader([path], default_typestore=io.typestore()) as reader:
        conns = [c for c in reader.connections if c.topic in topics]
        if deserialize:
            des = reader.deserialize
            for conn, _log_ns, raw in reader.messages(connections=conns):
                des(raw, conn.msgtype)
                n += 1
        else:
            for _ in reader.messages(connections=conns):
                n += 1
    return n, time.perf_counter() - t0


def _replay_once(bag: Path, out: Path, imu_topic: str | None, mag_topic: str | None
                 ) -> tuple[dict[str, Any], int]:
    """(summary, output size [bytes]) of one replay as ``cf-estimator replay BAG -o OUT`` runs it.

    The output bag is deleted once measured.
    """
    from cf_estimator.bag.replay import ReplayOptions, replay_bag

    opts = ReplayOptions(imu_topic=imu_topic, mag_topic=mag_topic, progress=False)
    summary = replay_bag(bag, out, options=opts).summary
    size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
    shutil.rmtree(out)
    return summary, size


def bag_throughput(bag: str | Path | None = None, repeats: int = 3, imu_topic: str | None = None,
                   mag_topic: str | None = None) -> BagThroughput:
    """Replay throughput of ``bag`` against plain rosbags reads of the same connections.

    Without ``bag`` a :data:`DEFAULT_BAG_SCENARIO` bag is simulated into a temporary directory.
    Replay outputs go to a temporary directory too; everything is removed afterwards. Topics as
    in ``cf-estimator replay`` (None = auto-detect). Raises ``cf_estimator.bag.io.BagError`` /
    ``cf_estimator.bag.replay.ReplayError`` for a bad bag or topic.
    """
    from cf_estimator.bag import io

    repeats = max(1, repeats)
    io.typestore()  # built once per process: keep it out of the first timed run
    tmp = Path(tempfile.mkdtemp(prefix="cf_estimator_bench_"))
    try:
        if bag is None:
            from cf_estimator.bag.simulate import write_scenario_bag
            from cf_estimator.scenarios import make_scenario

            name, duration = DEFAULT_BAG_SCENARIO
            sim = write_scenario_bag(make_scenario(name, duration_s=duration), tmp / name)
            path, label = sim.path, f"simulated {name}, {duration:g} s at {sim.rate_hz:g} Hz"
        else:
            path, label = Path(bag), str(bag)
        best = {"replay": 0.0, "read": 0.0, "read_deserialize": 0.0}
        counts: dict[str, int] = {}
        for i in range(repeats):
            summary, size = _replay_once(path, tmp / f"replay_{i}", imu_topic, mag_topic)
            per_topic = {summary["topics"]["imu"]: summary["messages_in"]}
            if summary["topics"]["mag"] is not None:
                per_topic[summary["topics"]["mag"]] = summary["mag_messages_in"]
            counts["replay"] = sum(per_topic.values())
            best["replay"] = max(best["replay"], counts["replay"] / summary["wall_time_s"])
            for key, deserialize in (("read", False), ("read_deserialize", True)):
                counts[key], wall = _read_bag(path, list(per_topic), deserialize)
                best[key] = max(best[key], counts[key] / wall)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return BagThroughput(label, per_topic, counts, best["replay"], best["read"],
                         best["read_deserialize"], size, repeats)


def format_bag_throughput(r: BagThroughput) -> str:
    """The bag throughput lines, each with its ratio to rosbags read + deserialize."""
    ref = r.read_deserialize_per_s
    topics = ", ".join(f"{t} {n}" for t, n in r.topics.items())
    lines = [f"Bag throughput, best of {r.repeats} [messages/s] (ratio to rosbags read + "
             "deserialize)", f"  bag: {r.bag} ({topics} messages)"]
    for name, v in (("rosbags read (raw bytes)", r.read_per_s),
                    ("rosbags read + deserialize", ref),
                    ("replay (+ pipeline, mcap output)", r.replay_per_s)):
        lines.append(f"  {name:<33} {v:10,.0f}  x{v / ref:.2f}")
    return "\n".join(lines) + "\n"
