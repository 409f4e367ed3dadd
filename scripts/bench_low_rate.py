#!/usr/bin/env python3
"""Low-rate input (issue 19, item 7): the filter at 10-50 Hz, as a MAVROS stream delivers it.

1. A still sensor with a gyro bias (simulated ``static`` scenario, 60 s) at 10, 20, 50 and
   200 Hz: share of samples detected at rest, when rest is first detected, the learned bias's
   error [deg/s] and whether it converged. At 10 Hz the 0.5 s stillness block holds 5 samples.
2. EuRoC (../shared/data/euroc, 200 Hz) brought to 10 and 50 Hz two ways: every k-th sample
   ("pick": what a low-rate MAVLink stream of a snapshot gives) and block-averaged ("avg": what
   an autopilot that averages or integrates over the interval gives); 6-D inclination RMS [deg]
   after 10 s (the ``bench euroc`` score), shipped defaults.

    python3 scripts/bench_low_rate.py [--data ../shared/data/euroc]

Prints a table (deterministic: same data, same figures).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

from cf_estimator import FilterParams, estimate
from cf_estimator.bench import euroc
from cf_estimator.bench.euroc_eval import score_flight
from cf_estimator.scenarios import make_scenario

RATES_HZ = (10.0, 20.0, 50.0, 200.0)


def still_rows() -> list[str]:
    """One line per rate: rest detection and bias learning on a still sensor."""
    rows = []
    for rate in RATES_HZ:
        sc = make_scenario("static", rate_hz=rate, duration_s=60.0, seed=1)
        r = estimate(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, None, timestamps_s=sc.imu.t_s,
                     params=FilterParams(use_mag=False))
        err = np.degrees(np.linalg.norm(r.gyro_bias_rad_s[-1] - sc.imu.gyro_bias_rad_s[-1]))
        first = sc.imu.t_s[np.argmax(r.at_rest)] if r.at_rest.any() else float("nan")
        rows.append(f"  {rate:5.0f} Hz {int(round(rate * 0.5)):14d} {r.at_rest.mean():8.2f}"
                    f" {first:15.1f} {err:19.3f}  {bool(r.gyro_bias_converged[-1])}")
    return rows


def reduced(f: euroc.Flight, k: int, average: bool) -> euroc.Flight:
    """Every k-th sample (the block's last), gyro and accelerometer picked or block-averaged."""
    n = (f.n_samples // k) * k
    sl = slice(k - 1, n, k)
    gyro, acc = f.gyro_rad_s[sl], f.accel_m_s2[sl]
    if average:
        gyro = f.gyro_rad_s[:n].reshape(-1, k, 3).mean(axis=1)
        acc = f.accel_m_s2[:n].reshape(-1, k, 3).mean(axis=1)
    return dataclasses.replace(f, t_s=f.t_s[sl], gyro_rad_s=gyro, accel_m_s2=acc,
                               q_ref=f.q_ref[sl])


def euroc_score(f: euroc.Flight) -> float:
    """6-D inclination RMS [deg] after 10 s, shipped defaults."""
    q = estimate(f.gyro_rad_s, f.accel_m_s2, None, timestamps_s=f.t_s,
                 params=FilterParams(use_mag=False)).quaternion
    return float(score_flight(f, q)["inclination_rms_deg"])


def main(argv: list[str] | None = None) -> int:
    """Print both tables."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[1].parent / "shared"
                                          / "data" / "euroc"), metavar="DIR")
    args = ap.parse_args(argv)
    print("still sensor, gyro bias, 60 s (simulated):")
    print("     rate  samples/block  at rest  first rest [s]  bias error [deg/s]  converged")
    print("\n".join(still_rows()))
    try:
        flights = euroc.load_flights(args.data)
    except euroc.EurocDataError as exc:
        print(f"bench_low_rate: {exc}", file=sys.stderr)
        return 2
    print(f"\nEuRoC ({args.data}), 6-D inclination RMS [deg] after 10 s:")
    print(f"  {'flight':<18} {'200 Hz':>7} {'50 pick':>9} {'50 avg':>9} {'10 pick':>9}"
          f" {'10 avg':>9}")
    cols = []
    for f in flights:
        row = [euroc_score(f)] + [euroc_score(reduced(f, k, avg)) for k in (4, 20)
                                  for avg in (False, True)]
        cols.append(row)
        print(f"  {f.name:<18} " + " ".join(f"{v:7.2f}" for v in row[:1])
              + " ".join(f"{v:9.2f}" for v in row[1:]))
    mean = np.mean(cols, axis=0)
    print(f"  {'mean':<18} " + " ".join(f"{v:7.2f}" for v in mean[:1])
          + " ".join(f"{v:9.2f}" for v in mean[1:]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
