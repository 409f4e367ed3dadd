"""Speed: per-sample update rate from Python (ours and peers), pipeline per-message time, and the
batched filter's parameter-samples per second — all measured in one run on the same inputs.

Timings on a shared machine are noisy: compare the ratios within one run, not absolute numbers
across runs.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

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


def per_sample_rates(n: int = 20000, peers: tuple[str, ...] = ("vqf", "fusion", "madgwick"),
                     rate_hz: float = 200.0) -> dict[str, float]:
    """Samples per second of one 9-D update called from Python, per estimator."""
    gyro, acc, mag = _inputs(n)
    dt = 1.0 / rate_hz
    out: dict[str, float] = {}
    g_t = [tuple(r) for r in gyro.tolist()]
    a_t = [tuple(r) for r in acc.tolist()]
    m_t = [tuple(r) for r in mag.tolist()]
    f = ComplementaryFilter(FilterParams())
    upd = f.update
    t0 = time.perf_counter()
    for i in range(n):
        upd(g_t[i], a_t[i], dt, m_t[i])
    out["cf_estimator"] = n / (time.perf_counter() - t0)
    if "vqf" in peers:
        from vqf import VQF

        v = VQF(dt)
        t0 = time.perf_counter()
        for i in range(n):
            v.update(gyro[i], acc[i], mag[i])
            v.getQuat9D()
        out["vqf"] = n / (time.perf_counter() - t0)
    if "fusion" in peers:
        import imufusion

        ah = imufusion.Ahrs()
        ah.set_sample_period(dt)
        gd, ag = np.degrees(gyro), acc / 9.80665
        t0 = time.perf_counter()
        for i in range(n):
            ah.update(gd[i], ag[i], mag[i])
            ah.get_quaternion()
        out["fusion"] = n / (time.perf_counter() - t0)
    if "madgwick" in peers:
        from ahrs.filters import Madgwick

        mw = Madgwick(frequency=rate_hz, gain=0.041)
        q = np.array([1.0, 0.0, 0.0, 0.0])
        m = min(n, 5000)  # pure Python: fewer samples are enough
        t0 = time.perf_counter()
        for i in range(m):
            q = mw.updateMARG(q, gyro[i], acc[i], mag[i])
        out["madgwick"] = m / (time.perf_counter() - t0)
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
    estimate_many(params, gyro, acc, mag, rate_hz=200.0, store=False)
    return p * n / (time.perf_counter() - t0)


def format_speed(rates: dict[str, float], pipe: dict[str, float] | None, batched: dict[int, float]
                 ) -> str:
    """The speed table."""
    lines = ["Per-sample 9-D update called from Python [samples/s] (ratio to imufusion)"]
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
