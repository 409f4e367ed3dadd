"""Soak benchmark: hours of simulated static IMU data through :class:`ImuPipeline`.

    python3 -m cf_estimator.bench.soak [--duration-s 3600] [--rate-hz 1000] [--json FILE]

A sensor lies still at a fixed tilted attitude (roll 10 deg, pitch -5 deg, yaw 30 deg, ENU) with
a constant gyro bias, white noise on gyro, accelerometer and magnetometer, IMU at ``--rate-hz``
and magnetometer at 100 Hz, stamps in integer nanoseconds, diagnostics every second of stamp
time (as the node's timer would). One hour at 1 kHz is 3.6 M IMU messages.

Messages are lightweight stand-ins with the sensor_msgs field names (``__slots__`` classes,
covariances as ``array.array('d')`` like rclpy's): the pipeline reads messages by duck typing,
and building rosbags message objects per message would cost more than the pipeline itself.

Reported (table on stdout, ``--json`` for the figures):

* memory: the number of live Python memory blocks (``sys.getallocatedblocks()``) and the
  resident set size at the end of each tenth; growth = last tenth minus first tenth. And
  ``tracemalloc`` over two windows of ``--trace-n`` messages, the first and the last of the run:
  its peak, and the bytes still held at the end of each window that were allocated inside it
  (a leak shows there). Tracing costs ~20x per message here, so it is not kept on for the whole
  hour; the traced messages are left out of the timing figures (``--trace-n 0``: no tracing);
* time: median, p99 and max ``on_imu`` time per tenth of the run (``perf_counter`` around each
  call, into a preallocated buffer: measuring allocates nothing);
* accuracy: max tilt and total attitude error per tenth and over the run (after the first
  ``--settle-s`` = 10 s), max |gyro-bias error|, and every message accounted for.
"""

from __future__ import annotations

import argparse
import array
import json
import math
import random
import resource
import sys
import time
import tracemalloc
from collections.abc import Sequence
from typing import Any

from cf_estimator.pipeline import ImuPipeline

G = 9.80665
T0_NS = 1_700_000_000 * 1_000_000_000
MAG_ENU_T = (0.0, 25e-6, -43e-6)
SEGMENTS = 10


class _Stamp:
    __slots__ = ("sec", "nanosec")

    def __init__(self, t_ns: int) -> None:
        self.sec, self.nanosec = divmod(t_ns, 1_000_000_000)


class _Header:
    __slots__ = ("stamp", "frame_id")

    def __init__(self, t_ns: int, frame_id: str) -> None:
        self.stamp = _Stamp(t_ns)
        self.frame_id = frame_id


class _Vector3:
    __slots__ = ("x", "y", "z")

    def __init__(self, x: float, y: float, z: float) -> None:
        self.x, self.y, self.z = x, y, z


class ImuStandIn:
    """sensor_msgs/Imu field names (orientation unused by the pipeline, left out)."""

    __slots__ = ("header", "angular_velocity", "angular_velocity_covariance",
                 "linear_acceleration", "linear_acceleration_covariance")

    def __init__(self, t_ns: int, gyro: Sequence[float], accel: Sequence[float],
                 cov: array.array) -> None:
        self.header = _Header(t_ns, "imu_link")
        self.angular_velocity = _Vector3(*gyro)
        self.angular_velocity_covariance = cov
        self.linear_acceleration = _Vector3(*accel)
        self.linear_acceleration_covariance = cov


class MagStandIn:
    """sensor_msgs/MagneticField field names."""

    __slots__ = ("header", "magnetic_field")

    def __init__(self, t_ns: int, field: Sequence[float]) -> None:
        self.header = _Header(t_ns, "imu_link")
        self.magnetic_field = _Vector3(*field)


def _quat_from_euler(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)


def _to_sensor(q: Sequence[float], v: Sequence[float]) -> tuple[float, float, float]:
    """R(q)ᵀ·v for q = q_world_from_sensor (w, x, y, z)."""
    w, x, y, z = q
    r = ((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
         (2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
         (2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)))
    return tuple(sum(r[i][j] * v[i] for i in range(3)) for j in range(3))  # type: ignore


def _percentile(sorted_values: Sequence[float], p: float) -> float:
    k = min(len(sorted_values) - 1, max(0, int(round(p * (len(sorted_values) - 1)))))
    return sorted_values[k]


def _rss_bytes() -> int:
    try:
        with open("/proc/self/statm", encoding="ascii") as fh:
            return int(fh.read().split()[1]) * resource.getpagesize()
    except OSError:  # not Linux: the high-water mark instead
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def run_soak(duration_s: float, rate_hz: float, *, seed: int = 1, trace_n: int = 20_000,
             settle_s: float = 10.0, progress: bool = True) -> dict[str, Any]:
    """Run the soak; returns the figures (see the module docstring)."""
    n = int(round(duration_s * rate_hz))
    if n < SEGMENTS:
        raise ValueError("too short: need at least 10 messages")
    trace_n = max(0, min(trace_n, n // SEGMENTS // 2))
    dt_ns = int(round(1e9 / rate_hz))
    mag_every = max(1, int(round(rate_hz / 100.0)))
    diag_every = max(1, int(round(rate_hz)))
    rng = random.Random(seed)
    gauss = rng.gauss
    q_true = _quat_from_euler(math.radians(10.0), math.radians(-5.0), math.radians(30.0))
    up = _to_sensor(q_true, (0.0, 0.0, 1.0))
    f_true = tuple(G * c for c in up)
    m_true = _to_sensor(q_true, MAG_ENU_T)
    bias = (0.01, -0.005, 0.003)
    sg, sa, sm = 0.005, 0.05, 0.5e-6
    cov = array.array("d", [sg * sg, 0, 0, 0, sg * sg, 0, 0, 0, sg * sg])
    tw, tx, ty, tz = q_true

    pipe = ImuPipeline()
    seg_len = n // SEGMENTS
    times = array.array("d", bytes(8 * (seg_len + SEGMENTS)))  # preallocated: no growth
    segments: list[dict[str, Any]] = []
    max_tilt = max_total = 0.0
    seg_tilt = seg_total = 0.0
    settle_n = int(settle_s * rate_hz)
    n_out = 0
    windows: list[dict[str, int]] = []
    traced = False
    clock = time.perf_counter
    wall0 = clock()
    k = 0  # index within the segment
    for i in range(n):
        if trace_n and (i == 0 or i == n - trace_n):
            tracemalloc.start()
            traced = True
        t_ns = T0_NS + i * dt_ns
        if i % mag_every == 0:
            pipe.on_mag(MagStandIn(t_ns, (m_true[0] + gauss(0, sm), m_true[1] + gauss(0, sm),
                                          m_true[2] + gauss(0, sm))))
        msg = ImuStandIn(
            t_ns,
            (bias[0] + gauss(0, sg), bias[1] + gauss(0, sg), bias[2] + gauss(0, sg)),
            (f_true[0] + gauss(0, sa), f_true[1] + gauss(0, sa), f_true[2] + gauss(0, sa)),
            cov,
        )
        t0 = clock()
        out = pipe.on_imu(msg)
        if not traced:
            times[k] = clock() - t0
            k += 1
        if out is not None:
            n_out += 1
            if i >= settle_n:
                x, y, z, w = out.orientation_xyzw
                vx, vy, vz = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
                c = vx * up[0] + vy * up[1] + vz * up[2]
                tilt = math.degrees(math.acos(c if c < 1.0 else 1.0))
                d = abs(w * tw + x * tx + y * ty + z * tz)
                total = math.degrees(2.0 * math.acos(d if d < 1.0 else 1.0))
                if tilt > seg_tilt:
                    seg_tilt = tilt
                if total > seg_total:
                    seg_total = total
        if (i + 1) % diag_every == 0:
            pipe.diagnostics(now_s=t_ns * 1e-9)
        if traced and (i == trace_n - 1 or i == n - 1):
            held, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            traced = False
            windows.append({"first_message": i + 1 - trace_n, "messages": trace_n,
                            "held_bytes": held, "peak_bytes": peak})
        last_of_segment = (i + 1) % seg_len == 0 and len(segments) < SEGMENTS - 1
        if last_of_segment or i == n - 1:
            blocks, rss = sys.getallocatedblocks(), _rss_bytes()  # before sorting (a list)
            seg = sorted(times[:k]) or [math.nan]
            segments.append({
                "segment": len(segments) + 1,
                "messages": (i + 1) - sum(x["messages"] for x in segments),
                "timed": k,
                "median_us": 1e6 * _percentile(seg, 0.5),
                "p99_us": 1e6 * _percentile(seg, 0.99),
                "max_us": 1e6 * seg[-1],
                "allocated_blocks": blocks,
                "rss_bytes": rss,
                "max_tilt_error_deg": seg_tilt,
                "max_total_error_deg": seg_total,
                "wall_s": clock() - wall0,
            })
            del seg  # a list of every timing: measured memory must not include it
            max_tilt, max_total = max(max_tilt, seg_tilt), max(max_total, seg_total)
            seg_tilt = seg_total = 0.0
            k = 0
            if progress:
                s = segments[-1]
                print(f"  segment {s['segment']:2d}/{SEGMENTS}: median {s['median_us']:.1f} us, "
                      f"blocks {s['allocated_blocks']}, tilt max "
                      f"{s['max_tilt_error_deg']:.3f} deg ({s['wall_s']:.0f} s)",
                      file=sys.stderr, flush=True)
    wall = clock() - wall0
    c = pipe.counters
    bias_est = [float(b) for b in pipe.filter.gyro_bias_rad_s]
    return {
        "duration_s": duration_s,
        "rate_hz": rate_hz,
        "messages": n,
        "mag_messages": c["received_mag"],
        "processed": c["processed"],
        "outputs": n_out,
        "rejected": sum(c["rejected"].values()),
        "resets": sum(c["resets"].values()),
        "gaps": c["gaps"],
        "tracemalloc_windows": windows,
        "tracemalloc_peak_bytes": max((w["peak_bytes"] for w in windows), default=0),
        "blocks_growth": segments[-1]["allocated_blocks"] - segments[0]["allocated_blocks"],
        "rss_growth_bytes": segments[-1]["rss_bytes"] - segments[0]["rss_bytes"],
        "max_rss_kib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
        "max_static_error_deg": max_tilt,
        "max_total_error_deg": max_total,
        "settle_s": settle_s,
        "gyro_bias_error_rad_s": max(abs(b - t) for b, t in zip(bias_est, bias, strict=True)),
        "phase": pipe.filter.status().phase,
        "wall_time_s": wall,
        "segments": segments,
    }


def print_report(r: dict[str, Any], file: Any = sys.stdout) -> None:
    print(f"soak: {r['messages']} IMU messages ({r['duration_s']:g} s at {r['rate_hz']:g} Hz), "
          f"{r['mag_messages']} mag; processed {r['processed']}, rejected {r['rejected']}, "
          f"resets {r['resets']}, gaps {r['gaps']}; wall {r['wall_time_s']:.0f} s", file=file)
    print(f"memory: live blocks first->last tenth {r['blocks_growth']:+d}, RSS "
          f"{r['rss_growth_bytes'] / 1024:+.0f} KiB; max RSS {r['max_rss_kib'] / 1024:.0f} MiB",
          file=file)
    for w in r["tracemalloc_windows"]:
        print(f"tracemalloc: messages {w['first_message']}..{w['first_message'] + w['messages']}"
              f": peak {w['peak_bytes'] / 1e3:.1f} kB, still held at the end "
              f"{w['held_bytes'] / 1e3:.1f} kB", file=file)
    print(f"error: max tilt {r['max_static_error_deg']:.4f} deg, max total "
          f"{r['max_total_error_deg']:.4f} deg (after {r['settle_s']:g} s); gyro-bias error "
          f"{r['gyro_bias_error_rad_s']:.2e} rad/s; phase {r['phase']}", file=file)
    print("segment  messages  median_us  p99_us   max_us  live_blocks  rss_MiB  tilt_max_deg",
          file=file)
    for s in r["segments"]:
        print(f"{s['segment']:7d}  {s['messages']:8d}  {s['median_us']:9.1f}  {s['p99_us']:6.1f}"
              f"  {s['max_us']:7.0f}  {s['allocated_blocks']:11d}  "
              f"{s['rss_bytes'] / 2**20:7.1f}  {s['max_tilt_error_deg']:12.4f}", file=file)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python3 -m cf_estimator.bench.soak",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--duration-s", type=float, default=3600.0)
    ap.add_argument("--rate-hz", type=float, default=1000.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--settle-s", type=float, default=10.0)
    ap.add_argument("--trace-n", type=int, default=20_000,
                    help="messages traced by tracemalloc at the start and at the end (0: none)")
    ap.add_argument("--json", help="write the figures to this file")
    ap.add_argument("--quiet", action="store_true", help="no per-segment progress on stderr")
    args = ap.parse_args(argv)
    if args.duration_s <= 0 or args.rate_hz <= 0:
        ap.error("--duration-s and --rate-hz must be positive")
    report = run_soak(args.duration_s, args.rate_hz, seed=args.seed, trace_n=args.trace_n,
                      settle_s=min(args.settle_s, args.duration_s / 2),
                      progress=not args.quiet)
    print_report(report)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=2)
    ok = report["rejected"] == 0 and report["processed"] == report["messages"]
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
