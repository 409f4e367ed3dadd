#!/usr/bin/env python3
"""Replay speed of a long PX4 ulog: write a synthetic one, time ``replay`` on it.

    python scripts/bench_ulog.py [--minutes 60] [--rate 250] [--repeats 1] [--keep DIR]

The log (cf_estimator.bench.ulogwrite.static_tilt_log): sensor_combined at --rate, one
vehicle_magnetometer and vehicle_attitude at 50 Hz, --minutes long, written into a temporary
directory (or --keep DIR). Timed: the whole ``replay_bag`` as ``cf-estimator replay LOG -o OUT``
runs it — pyulog's parse, the pipeline, the comparison with vehicle_attitude, the mcap output —
best of --repeats, wall clock. Not a test: the machine's load changes the figures.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from cf_estimator.bag.replay import ReplayOptions, replay_bag
from cf_estimator.bench.ulogwrite import static_tilt_log


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--rate", type=float, default=250.0, help="IMU rate [Hz]")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--keep", type=Path, help="write the log here (kept)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_ulog_") as tmp:
        where = args.keep or Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        log = where / "synthetic.ulg"
        t0 = time.perf_counter()
        static_tilt_log(log, args.minutes * 60.0, args.rate)
        write_s = time.perf_counter() - t0
        print(f"wrote {log} ({log.stat().st_size / 1e6:.0f} MB, {args.minutes:g} min at "
              f"{args.rate:g} Hz) in {write_s:.1f} s")
        best = float("inf")
        for k in range(args.repeats):
            out = Path(tmp) / f"out{k}"
            t0, c0 = time.perf_counter(), time.process_time()
            result = replay_bag(log, out, options=ReplayOptions(progress=False))
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            best = min(best, wall)
            s = result.summary
            incl = s["reference"]["rmse_deg"]["inclination"]
            print(f"replay {k + 1}: {wall:.1f} s wall ({cpu:.1f} s CPU), {s['messages_in']} IMU + "
                  f"{s['mag_messages_in']} mag messages ({s['messages_in'] / wall:,.0f} IMU/s), "
                  f"inclination vs vehicle_attitude {incl:.3f} deg RMS")
        print(f"best {best:.1f} s for {args.minutes:g} min of {args.rate:g} Hz ulog "
              f"(target < 30 s for 60 min at 250 Hz)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
