#!/usr/bin/env python3
"""Reproducer (core, 10 Hz): one 1 rad/s gyro sample (5.7 deg tilt error) then one 144 m/s^2
accelerometer sample; 10 s of clean still data later the tilt error is still 2.8 deg (at 100 Hz
the same sequence recovers). From test/test_fuzz.py::test_tilt_recovers_within_10_s_of_good_data."""
import math

import numpy as np

from cf_estimator import FilterParams
from cf_estimator.core.filter import ComplementaryFilter

G = 9.80665
for rate in (10.0, 100.0):
    dt = 1.0 / rate
    f = ComplementaryFilter(FilterParams(use_mag=False))
    rng = np.random.default_rng(0)
    for _ in range(int(3.0 * rate)):
        f.update(tuple(rng.normal(0, 0.003, 3)), tuple([0, 0, G] + rng.normal(0, 0.03, 3)), dt)
    for _ in range(3):
        f.update((0.0, 0.0, 0.0), (0.0, 0.0, G), dt)
    f.update((0.0, 1.0, 0.0), (0.0, 0.0, G), dt)      # one bad gyro sample
    f.update((0.0, 0.0, 0.0), (0.0, 0.0, 144.0), dt)  # one accelerometer spike
    for k in range(int(10.0 * rate)):
        q = f.update(tuple(rng.normal(0, 0.003, 3)), tuple([0, 0, G] + rng.normal(0, 0.03, 3)), dt)
        if (k + 1) % int(2 * rate) == 0:
            w, x, y, z = q
            tilt = math.degrees(2 * math.asin(min(1.0, math.hypot(x, y))))
            s = f.status()
            print(f"{rate:5.0f} Hz t+{(k + 1) / rate:4.1f} s: tilt {tilt:5.2f} deg, "
                  f"clipped {s.clipped}, phase {s.phase}")
