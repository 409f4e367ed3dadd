#!/usr/bin/env python3
"""Load benchmark of cf_estimator_node on the real ROS 2 runtime (a script, not a test).

A publisher sends 1 kHz sensor_msgs/Imu and 100 Hz MagneticField (sensor-data QoS, stamps =
the wall clock at publishing); the target — ``cf_estimator_node`` or a bare rclpy echo node that
republishes each Imu as it is — sends imu/data; a subscriber records each output's arrival time.
Each role runs in its own process, on its own ROS domain per trial, DDS discovery on this
machine only. Echo and node trials alternate in the same run (``--rounds``), with the same input
queue depth, so they see the same machine load.

Reported per target: delivered fraction (outputs received / inputs published after the
warm-up), end-to-end latency = arrival (wall clock) - header stamp [ms] p50/p90/p99/max, and for
the node its own processing time per message from /diagnostics (median of the per-period means
``processing_time_mean_us``), and the target process's CPU time (a share of one core, and per IMU
message) and resident memory over the measured span, read from /proc. Then the ratios against
the echo node and the issue's targets: fraction >= echo's - 1 point, p99 <= 1.5 x echo's,
processing median <= 50 us, CPU per message <= 1.5 x echo's.

    python3 scripts/bench_node_load.py                       # 2 rounds of 20 s per target
    python3 scripts/bench_node_load.py --rate 250            # a 250 Hz IMU
    python3 scripts/bench_node_load.py --depth 5 --rounds 1  # the sensor-data default depth
    python3 scripts/bench_node_load.py --velocity-rate 10    # the velocity-aided node

``--velocity-rate HZ`` adds a geometry_msgs/TwistStamped on /gnss/vel (a steady 5 m/s cruise,
stamped 100 ms before it is sent, as GNSS arrives late) and runs the node with
``velocity_topic: /gnss/vel``, ``velocity_heading: filter`` (aided from the first window: the
aided per-sample path is what is measured); the echo node does not subscribe to it.
The machine's other load counts: run it on an idle machine for figures that mean something.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

IMU_RATE_HZ = 1000.0  #: default IMU rate (--rate); the magnetometer at a tenth of it
MAG_EVERY = 10
#: How often the target process's CPU time and memory are read from /proc [s].
SAMPLE_S = 0.25
WARMUP_S = 1.0
IN_TOPIC, MAG_TOPIC, OUT_TOPIC = "/imu/data_raw", "/imu/mag", "/imu/data"
VEL_TOPIC = "/gnss/vel"
VEL_LATENCY_NS = 100_000_000
DISCOVERY_TIMEOUT_S = 60.0


def _env(domain: int) -> dict[str, str]:
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1",
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


# -- roles (each in its own process) -------------------------------------------------------------
def role_publisher(duration_s: float, out: Path, velocity_rate_hz: float = 0.0,
                   node_target: bool = False, rate_hz: float = IMU_RATE_HZ) -> int:
    """Wait until the target and the subscriber are matched, publish for WARMUP_S + duration_s;
    write the measured stamps [ns] (after the warm-up) and the wall-clock span they cover to
    ``out``."""
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu, MagneticField

    rclpy.init()
    node = rclpy.create_node("load_publisher")
    imu_pub = node.create_publisher(Imu, IN_TOPIC, qos_profile_sensor_data)
    mag_pub = node.create_publisher(MagneticField, MAG_TOPIC, qos_profile_sensor_data)
    vel_pub = vel = None
    if velocity_rate_hz > 0:
        from geometry_msgs.msg import TwistStamped

        vel_pub = node.create_publisher(TwistStamped, VEL_TOPIC, qos_profile_sensor_data)
        vel = TwistStamped()
        vel.header.frame_id = "map"
        vel.twist.linear.x = 5.0
    end = time.monotonic() + DISCOVERY_TIMEOUT_S
    while not (imu_pub.get_subscription_count() >= 1 and mag_pub.get_subscription_count() >= 1
               and node.count_publishers(OUT_TOPIC) >= 1
               and node.count_subscribers(OUT_TOPIC) >= 1
               and (vel_pub is None or not node_target or vel_pub.get_subscription_count() >= 1)):
        if time.monotonic() > end:
            print("publisher: the target or the subscriber never appeared", file=sys.stderr)
            return 2
        rclpy.spin_once(node, timeout_sec=0.05)
    imu, mag = Imu(), MagneticField()
    imu.header.frame_id = mag.header.frame_id = "imu_link"
    imu.linear_acceleration.z = 9.80665
    imu.angular_velocity.z = 0.01
    mag.magnetic_field.y, mag.magnetic_field.z = 2.2e-5, -4.2e-5
    n_imu = int((WARMUP_S + duration_s) * rate_hz)
    n_warm = int(WARMUP_S * rate_hz)
    every_mag = MAG_EVERY
    every_vel = max(1, int(rate_hz / velocity_rate_hz)) if velocity_rate_hz > 0 else 0
    period = 1.0 / rate_hz
    stamps: list[int] = []
    t0 = time.perf_counter()
    for i in range(n_imu):
        delay = t0 + i * period - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        now = time.time_ns()
        imu.header.stamp.sec, imu.header.stamp.nanosec = divmod(now, 10**9)
        imu_pub.publish(imu)
        if i % every_mag == 0:
            mag.header.stamp = imu.header.stamp
            mag_pub.publish(mag)
        if vel_pub is not None and i % every_vel == 0:
            vel.header.stamp.sec, vel.header.stamp.nanosec = divmod(now - VEL_LATENCY_NS, 10**9)
            vel_pub.publish(vel)
        if i >= n_warm:
            stamps.append(now)
    out.write_text(json.dumps({"stamps": stamps, "elapsed_s": time.perf_counter() - t0,
                               "measured_from_ns": stamps[0] if stamps else 0,
                               "measured_to_ns": time.time_ns()}), encoding="utf-8")
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


def role_subscriber(out: Path) -> int:
    """Record (stamp, arrival) of every imu/data and the node's processing time until SIGINT."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import Imu

    rclpy.init()
    node = rclpy.create_node("load_subscriber")
    arrivals: list[tuple[int, int]] = []
    proc_us: list[float] = []
    aided: list[int] = []

    def on_imu(msg: Imu) -> None:
        arrivals.append((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, time.time_ns()))

    def on_diag(msg: DiagnosticArray) -> None:
        for status in msg.status:
            for kv in status.values:
                if kv.key == "processing_time_mean_us":
                    proc_us.append(float(kv.value))
                elif kv.key == "velocity_aided_samples":
                    aided.append(int(kv.value))

    node.create_subscription(Imu, OUT_TOPIC, on_imu, QoSProfile(depth=1000))
    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, QoSProfile(depth=100))
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        rclpy.spin(node)
    out.write_text(json.dumps({"arrivals": arrivals, "proc_us": proc_us, "aided": aided}),
                   encoding="utf-8")
    rclpy.try_shutdown()
    return 0


def role_echo(depth: int) -> int:
    """The baseline: republish every Imu unchanged (same QoS as the node: sensor data in,
    reliable depth 10 out); magnetometer messages are received and dropped."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.qos import QoSProfile, qos_profile_sensor_data
    from sensor_msgs.msg import Imu, MagneticField

    rclpy.init()
    node = rclpy.create_node("echo")
    pub = node.create_publisher(Imu, OUT_TOPIC, QoSProfile(depth=10))
    qos = QoSProfile(depth=depth, reliability=qos_profile_sensor_data.reliability)
    node.create_subscription(Imu, IN_TOPIC, pub.publish, qos)
    node.create_subscription(MagneticField, MAG_TOPIC, lambda msg: None, qos_profile_sensor_data)
    with contextlib.suppress(KeyboardInterrupt, ExternalShutdownException):
        rclpy.spin(node)
    rclpy.try_shutdown()
    return 0


# -- orchestration -------------------------------------------------------------------------------
def _python_role(role: str, *args: str) -> list[str]:
    return [sys.executable, str(Path(__file__).resolve()), "--role", role, *args]


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def _proc_sample(pid: int) -> tuple[int, float, float] | None:
    """(wall clock [ns], CPU time user + system [s], resident memory [MB]) of a process from
    /proc (Linux), or None when it cannot be read."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        rss_kb = next(int(line.split()[1]) for line in
                      Path(f"/proc/{pid}/status").read_text().splitlines()
                      if line.startswith("VmRSS:"))
    except (OSError, StopIteration, IndexError, ValueError):
        return None
    ticks = os.sysconf("SC_CLK_TCK")
    return time.time_ns(), (int(fields[11]) + int(fields[12])) / ticks, rss_kb / 1024.0


def _sample_while(pid: int, running: Any, into: list[tuple[int, float, float]]) -> None:
    while running():
        got = _proc_sample(pid)
        if got is not None:
            into.append(got)
        time.sleep(SAMPLE_S)


def _cpu_between(samples: list[tuple[int, float, float]], t0_ns: int, t1_ns: int
                 ) -> tuple[float, float]:
    """(CPU seconds the process used between two wall-clock times, its largest resident memory
    [MB] then): the samples nearest inside the span."""
    inside = [s for s in samples if t0_ns <= s[0] <= t1_ns]
    if len(inside) < 2:
        return float("nan"), float("nan")
    (ta, ca, _), (tb, cb, _) = inside[0], inside[-1]
    span = (t1_ns - t0_ns) / (tb - ta) if tb > ta else float("nan")
    return (cb - ca) * span, max(s[2] for s in inside)


def trial(target: str, depth: int, duration_s: float, domain: int, tmp: Path,
          velocity_rate_hz: float = 0.0, rate_hz: float = IMU_RATE_HZ) -> dict[str, Any]:
    """One run of publisher → target → subscriber; the figures of :func:`summarize`."""
    env = _env(domain)
    pub_file, sub_file = tmp / f"{target}_{domain}_pub.json", tmp / f"{target}_{domain}_sub.json"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    sub = subprocess.Popen(_python_role("subscriber", "--out", str(sub_file)), env=env, **quiet)
    if target == "node":
        cmd = [sys.executable, "-m", "cf_estimator.node.cf_estimator_node", "--ros-args",
               "-p", f"qos_overrides.{IN_TOPIC}.subscription.depth:={depth}"]
        if velocity_rate_hz > 0:
            cmd += ["-p", f"velocity_topic:={VEL_TOPIC}", "-p", "velocity_heading:=filter"]
    else:
        cmd = _python_role("echo", "--depth", str(depth))
    tgt = subprocess.Popen(cmd, env=env, **quiet)
    pub = subprocess.Popen(
        _python_role("publisher", "--duration", str(duration_s), "--out", str(pub_file),
                     "--velocity-rate", str(velocity_rate_hz), "--target", target,
                     "--rate", str(rate_hz)), env=env)
    samples: list[tuple[int, float, float]] = []
    sampler = threading.Thread(target=_sample_while,
                               args=(tgt.pid, lambda: pub.poll() is None, samples), daemon=True)
    sampler.start()
    try:
        code = pub.wait(timeout=DISCOVERY_TIMEOUT_S + duration_s + 60)
        sampler.join()
        time.sleep(1.0)  # the last messages in flight
    finally:
        _stop(tgt)
        _stop(sub)
        _stop(pub)
    if code != 0:
        raise RuntimeError(f"{target}: publisher exit code {code}")
    pub_data = json.loads(pub_file.read_text())
    row = summarize(pub_data, json.loads(sub_file.read_text()))
    cpu_s, rss_mb = _cpu_between(samples, pub_data["measured_from_ns"], pub_data["measured_to_ns"])
    span_s = (pub_data["measured_to_ns"] - pub_data["measured_from_ns"]) * 1e-9
    row["cpu_pct"] = 100.0 * cpu_s / span_s if span_s > 0 else float("nan")
    row["cpu_us_per_msg"] = 1e6 * cpu_s / row["published"] if row["published"] else float("nan")
    row["rss_mb"] = rss_mb
    return row


def _percentile(sorted_values: list[float], p: float) -> float:
    if not sorted_values:
        return float("nan")
    k = min(len(sorted_values) - 1, max(0, round(p / 100.0 * (len(sorted_values) - 1))))
    return sorted_values[k]


def summarize(pub: dict[str, Any], sub: dict[str, Any]) -> dict[str, Any]:
    sent = set(pub["stamps"])
    latency_ms = sorted((arrival - stamp) * 1e-6 for stamp, arrival in sub["arrivals"]
                        if stamp in sent)
    proc = [x for x in sub["proc_us"] if x == x]  # NaN: a period without messages
    return {
        "published": len(sent),
        "delivered": len(latency_ms),
        "fraction": len(latency_ms) / len(sent) if sent else float("nan"),
        "p50_ms": _percentile(latency_ms, 50), "p90_ms": _percentile(latency_ms, 90),
        "p99_ms": _percentile(latency_ms, 99),
        "max_ms": latency_ms[-1] if latency_ms else float("nan"),
        "proc_median_us": statistics.median(proc) if proc else float("nan"),
        "publish_rate_hz": len(sent) / max(pub["elapsed_s"] - WARMUP_S, 1e-9),
        "aided_samples": max(sub.get("aided") or [0]),
    }


def _pooled(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Trials of one target together: sums for counts, medians of the per-trial figures."""
    out = {"published": sum(r["published"] for r in rows),
           "delivered": sum(r["delivered"] for r in rows)}
    out["fraction"] = out["delivered"] / out["published"]
    for key in ("p50_ms", "p90_ms", "p99_ms", "max_ms", "proc_median_us", "publish_rate_hz",
                "cpu_pct", "cpu_us_per_msg", "rss_mb"):
        out[key] = statistics.median(r[key] for r in rows)
    out["aided_samples"] = sum(r.get("aided_samples", 0) for r in rows)
    return out


def _row(name: str, r: dict[str, Any]) -> str:
    return (f"{name:<22} {r['published']:>9} {r['delivered']:>9} {100 * r['fraction']:>8.2f}% "
            f"{r['p50_ms']:>7.3f} {r['p90_ms']:>7.3f} {r['p99_ms']:>7.3f} {r['max_ms']:>8.2f} "
            f"{r['proc_median_us']:>9.1f} {r['cpu_pct']:>6.1f}% {r['cpu_us_per_msg']:>8.1f} "
            f"{r['rss_mb']:>7.1f}")


def orchestrate(rounds: int, duration_s: float, depth: int, velocity_rate_hz: float = 0.0,
                rate_hz: float = IMU_RATE_HZ) -> int:
    from cf_estimator.core.kernel import resolve_backend

    domains = random.Random(os.getpid()).sample(range(1, 102), 2 * rounds)
    results: dict[str, list[dict[str, Any]]] = {"echo": [], "node": []}
    print(f"load: {rate_hz:.0f} Hz Imu + {rate_hz / MAG_EVERY:.0f} Hz MagneticField for "
          f"{duration_s:g} s (+{WARMUP_S:g} s warm-up) per trial, {rounds} round(s), input queue "
          f"depth {depth} for both, {os.cpu_count()} CPUs, load average "
          f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}, filter step {resolve_backend()}"
          + (f"; + {velocity_rate_hz:g} Hz TwistStamped on {VEL_TOPIC} (node velocity-aided)"
             if velocity_rate_hz > 0 else ""))
    header = (f"{'trial':<22} {'published':>9} {'delivered':>9} {'fraction':>9} {'p50 ms':>7} "
              f"{'p90 ms':>7} {'p99 ms':>7} {'max ms':>8} {'proc µs':>9} {'CPU':>7} "
              f"{'µs/msg':>8} {'RSS MB':>7}")
    print(header)
    with tempfile.TemporaryDirectory(prefix="cf_node_load_") as tmp:
        for r in range(rounds):
            for target in ("echo", "node"):
                row = trial(target, depth, duration_s, domains.pop(), Path(tmp),
                            velocity_rate_hz, rate_hz)
                results[target].append(row)
                print(_row(f"{target} round {r + 1}", row), flush=True)
    echo, node = _pooled(results["echo"]), _pooled(results["node"])
    print("-" * len(header))
    print(_row("echo (all rounds)", echo))
    print(_row("node (all rounds)", node))
    d_points = 100 * (node["fraction"] - echo["fraction"])
    p99_ratio = node["p99_ms"] / echo["p99_ms"]
    p50_ratio = node["p50_ms"] / echo["p50_ms"]
    print(f"node vs echo: delivered {d_points:+.2f} points, p50 x{p50_ratio:.2f}, "
          f"p99 x{p99_ratio:.2f}; node processing median {node['proc_median_us']:.1f} µs/message; "
          f"publisher kept {echo['publish_rate_hz']:.0f} / {node['publish_rate_hz']:.0f} Hz")
    cpu_ratio = node["cpu_us_per_msg"] / echo["cpu_us_per_msg"]
    rss_ratio = node["rss_mb"] / echo["rss_mb"]
    print(f"node vs echo: CPU {node['cpu_pct']:.1f} % vs {echo['cpu_pct']:.1f} % of a core "
          f"({node['cpu_us_per_msg']:.1f} vs {echo['cpu_us_per_msg']:.1f} µs per IMU message, "
          f"x{cpu_ratio:.2f}); memory {node['rss_mb']:.0f} vs {echo['rss_mb']:.0f} MB "
          f"(x{rss_ratio:.2f})")
    if velocity_rate_hz > 0:
        print(f"node velocity-aided IMU samples (all rounds, from /diagnostics): "
              f"{node['aided_samples']}")
    checks = [(d_points >= -1.0, "delivered >= echo - 1 point"),
              (p99_ratio <= 1.5, "p99 <= 1.5 x echo"),
              (node["proc_median_us"] <= 50.0, "processing median <= 50 µs"),
              (cpu_ratio <= 1.5, "CPU per message <= 1.5 x echo")]
    print("targets: " + "; ".join(f"{text}: {'met' if ok else 'NOT met'}" for ok, text in checks))
    return 0


def main(argv: list[str] | None = None) -> int:
    from cf_estimator.node.node import IMU_QUEUE_DEPTH

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=2, help="echo+node trial pairs (2)")
    parser.add_argument("--duration", type=float, default=20.0, help="seconds per trial (20)")
    parser.add_argument("--depth", type=int, default=IMU_QUEUE_DEPTH,
                        help=f"input queue depth of both targets ({IMU_QUEUE_DEPTH})")
    parser.add_argument("--rate", type=float, default=IMU_RATE_HZ, metavar="HZ",
                        help=f"IMU rate (default {IMU_RATE_HZ:g}; the magnetometer at a tenth)")
    parser.add_argument("--velocity-rate", type=float, default=0.0, metavar="HZ",
                        help="also publish a TwistStamped velocity at this rate; the node is "
                        "velocity-aided (default 0: none)")
    parser.add_argument("--role", choices=("publisher", "subscriber", "echo"),
                        help=argparse.SUPPRESS)
    parser.add_argument("--target", default="node", help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.role == "publisher":
        return role_publisher(args.duration, args.out, args.velocity_rate,
                              args.target == "node", args.rate)
    if args.role == "subscriber":
        return role_subscriber(args.out)
    if args.role == "echo":
        return role_echo(args.depth)
    if args.rounds < 1 or args.duration <= 0 or args.depth < 1:
        parser.error("--rounds, --duration and --depth must be positive")
    if args.velocity_rate < 0:
        parser.error("--velocity-rate must be >= 0")
    if not args.rate > 0:
        parser.error("--rate must be > 0")
    return orchestrate(args.rounds, args.duration, args.depth, args.velocity_rate, args.rate)


if __name__ == "__main__":
    sys.exit(main())
