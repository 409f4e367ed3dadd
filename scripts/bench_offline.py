"""Speed and memory of the offline estimator (``estimate(..., offline=True)``), one core.

    python scripts/bench_offline.py [--minutes 60] [--rate 1000]

A simulated 1 kHz recording (the ``flight`` scenario repeated to the length asked, 6-D and
9-D): samples per second of the online and offline estimate (best of --repeats) and the peak
resident memory of the offline run of the whole recording (ru_maxrss of a child process that
only builds the arrays and runs it). Not a test: the machine's load changes the figures.
"""

from __future__ import annotations

import argparse
import multiprocessing
import resource
import time

import numpy as np

from cf_estimator.core.batch import estimate
from cf_estimator.core.params import FilterParams
from cf_estimator.scenarios import make_scenario


def recording(minutes: float, rate_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(gyro, accel, mag) of ``minutes`` at ``rate_hz``: the flight scenario tiled."""
    sc = make_scenario("flight", rate_hz=rate_hz, seed=1)
    n = int(minutes * 60.0 * rate_hz)
    reps = -(-n // sc.imu.t_s.shape[0])
    tile = [np.tile(a, (reps, 1))[:n] for a in (sc.imu.gyro_rad_s, sc.imu.accel_m_s2,
                                                 sc.imu.mag_T)]
    return tile[0], tile[1], tile[2]


def rate(minutes: float, rate_hz: float, mag: bool, offline: bool, repeats: int) -> float:
    g, a, m = recording(minutes, rate_hz)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        estimate(g, a, m if mag else None, rate_hz=rate_hz, params=FilterParams(use_mag=mag),
                 offline=offline)
        best = min(best, time.perf_counter() - t0)
    return g.shape[0] / best


def _peak_child(minutes: float, rate_hz: float, mag: bool, out: multiprocessing.Queue) -> None:
    g, a, m = recording(minutes, rate_hz)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    estimate(g, a, m if mag else None, rate_hz=rate_hz, params=FilterParams(use_mag=mag),
             offline=True)
    out.put((before, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss))


def peak_memory_mb(minutes: float, rate_hz: float, mag: bool) -> tuple[float, float]:
    """(peak RSS after building the inputs, peak RSS after the offline run) [MB]."""
    q: multiprocessing.Queue = multiprocessing.Queue()
    p = multiprocessing.get_context("fork").Process(target=_peak_child,
                                                     args=(minutes, rate_hz, mag, q))
    p.start()
    before, after = q.get()
    p.join()
    return before / 1024.0, after / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0, help="recording length (default 60)")
    ap.add_argument("--rate", type=float, default=1000.0, help="sample rate [Hz] (default 1000)")
    ap.add_argument("--speed-minutes", type=float, default=5.0,
                    help="length of the timed runs (default 5)")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    for mag in (False, True):
        dim = "9-D" if mag else "6-D"
        on = rate(args.speed_minutes, args.rate, mag, False, args.repeats)
        off = rate(args.speed_minutes, args.rate, mag, True, args.repeats)
        print(f"{dim}: online {on / 1e6:.2f} M samples/s, offline {off / 1e6:.2f} M samples/s "
              f"({args.speed_minutes:g} min at {args.rate:g} Hz, best of {args.repeats})")
    for mag in (False, True):
        before, after = peak_memory_mb(args.minutes, args.rate, mag)
        print(f"{'9-D' if mag else '6-D'}: {args.minutes:g} min at {args.rate:g} Hz "
              f"({int(args.minutes * 60 * args.rate)} samples): peak RSS {after:.0f} MB "
              f"(inputs built: {before:.0f} MB)")


if __name__ == "__main__":
    main()
