#!/usr/bin/env python3
"""Fingerprints of replays, to show a restructuring changed no output bit (a script, not a test).

Replays the shared recordings (``../shared/data``: the ROS 1 bags, the PX4 ulogs, the ArduPilot
logs) and two made here — the hostile bag of ``test/test_bulk_decode.py`` and a simulated 60 s
flight with a glitching, dropping-out GNSS velocity — with several parameter sets (defaults,
``body_frame: frd`` + ``rpy_unwrap``, no magnetometer and no reset on a jump back, a magnetometer
calibration + NWU + declination, the gravity-free acceleration), read both ways (decoded rows and
message objects), velocity-aided, offline and two variants in one pass. For each: the SHA-256 of
every output topic (log times and bytes; the diagnostics without their wall-clock figures), of
the summary (without its timing) and of each series. Run it on two commits and compare:

    python3 scripts/replay_fingerprints.py before.json          # in a checkout of one commit
    python3 scripts/replay_fingerprints.py after.json           # ... and of the other
    python3 scripts/replay_fingerprints.py --compare before.json after.json

``--compare`` prints each replay that differs and what differs; exit status 1 if any does.
Takes about five minutes.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
#: filter and pipeline parameters of each variant
VARIANTS: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {
    "default": ({}, {}),
    "frd_unwrap": ({}, {"body_frame": "frd", "rpy_unwrap": True}),
    "nomag_noreset": ({"use_mag": False}, {"reset_on_time_jump_back": False}),
    "cal_nwu": ({"world_frame": "nwu"}, {
        "mag_hard_iron_t": [1e-6, -2e-6, 3e-6],
        "mag_soft_iron": [1.01, 0.0, 0.0, 0.0, 0.99, 0.0, 0.0, 0.0, 1.0],
        "magnetic_declination_rad": 0.2}),
    "accel": ({}, {"publish_linear_acceleration": True}),
}
#: the inputs every variant runs on (the others: the defaults only)
ALL_VARIANTS_ON = ("hostile", "ardrone_imu", "sample_log_small", "dronekit_log171")


def _digest(path: Path, summary: dict[str, Any], series: Any, work: Path) -> dict[str, Any]:
    from rosbags.highlevel import AnyReader

    from cf_estimator.bag.replay import OUT_DIAGNOSTICS_TOPIC

    topics: dict[str, str] = {}
    with AnyReader([path]) as reader:
        for conn in reader.connections:
            h = hashlib.sha256()
            for _c, t, raw in reader.messages(connections=[conn]):
                h.update(t.to_bytes(8, "little", signed=True))
                if conn.topic == OUT_DIAGNOSTICS_TOPIC:  # without the machine's timings
                    msg = reader.deserialize(raw, conn.msgtype)
                    st = msg.status[0]
                    h.update(repr((int(st.level), st.message, [
                        (kv.key, kv.value) for kv in st.values
                        if not kv.key.startswith("processing_time")])).encode())
                else:
                    h.update(bytes(raw))
            topics[conn.topic] = h.hexdigest()
    text = re.sub(r"'(messages_per_s|wall_s|wall_time_s|output)': [^,}]+", "",
                  repr(summary).replace(str(work), "<work>"))  # the run's own folder
    return {"topics": topics,
            "summary": hashlib.sha256(text.encode()).hexdigest(),
            "series": {k: hashlib.sha256(np.asarray(v).tobytes()).hexdigest()
                       for k, v in vars(series).items()}}


def _velocity_flight(work: Path) -> Path:
    from cf_estimator.bag.simulate import write_scenario_bag
    from cf_estimator.scenarios import make_scenario
    from cf_estimator.scenarios.velocity_sensor import (
        VelocityModel,
        measure_velocity,
        with_faults,
    )

    uav = make_scenario("uav", duration_s=60.0, seed=3)
    model = with_faults(VelocityModel(10.0, 0.1, 0.1), dropouts=[(30.0, 36.0)],
                        glitches=[(20.0, 20.35, (5.0, 0.0, 0.0))])
    path = work / "velocity_flight"
    write_scenario_bag(uav, path, velocity=measure_velocity(uav.truth, model,
                                                            np.random.default_rng(0)))
    return path


def fingerprints(work: Path) -> dict[str, Any]:
    sys.path.insert(0, str(REPO / "test"))
    from test_bulk_decode import _hostile_bag

    from cf_estimator.bag.replay import ReplayOptions, ReplayVariant, replay_variants
    from cf_estimator.bag.simulate import VELOCITY_TOPIC
    from cf_estimator.core.params import FilterParams
    from cf_estimator.pipeline.params import PipelineParams

    inputs = {p.stem: p for p in sorted((DATA / "bags").glob("*.bag"))}
    inputs.update({p.stem: p for p in sorted((DATA / "ulogs").glob("*.ulg"))})
    inputs.update({p.stem: p for p in sorted((DATA / "ardupilot").glob("*"))})
    inputs["hostile"] = _hostile_bag(work / "hostile")
    out: dict[str, Any] = {}

    def run(key: str, path: Path, variants: list[tuple[str, dict, dict]], **opts: Any) -> None:
        vs = [ReplayVariant(name, FilterParams(**fp), PipelineParams(**pp),
                            work / f"{key}_{name}".replace("/", "_")) for name, fp, pp in variants]
        for v in vs:
            shutil.rmtree(v.output_path, ignore_errors=True)
        results = replay_variants(path, vs, ReplayOptions(progress=False, overwrite=True, **opts))
        for v, r in zip(vs, results, strict=True):
            out[f"{key}/{v.name}"] = _digest(Path(v.output_path), r.summary, r.series, work)
            print(f"{key}/{v.name}", flush=True)

    for name, path in inputs.items():
        for vname, (fp, pp) in VARIANTS.items():
            if vname != "default" and name not in ALL_VARIANTS_ON:
                continue
            for mode, kw in (("rows", {}), ("objects", {"bulk_pipeline": False})):
                run(f"{name}/{vname}/{mode}", path, [("v", fp, pp)], **kw)
    flight = _velocity_flight(work)
    ref = {"reference_topic": "/ground_truth/orientation"}
    run("flight/aided6", flight, [("v", {"use_mag": False}, {})], mag_topic="none",
        velocity_topic=VELOCITY_TOPIC, **ref)
    run("flight/aided9", flight, [("v", {}, {"publish_linear_acceleration": True})],
        velocity_topic=VELOCITY_TOPIC, **ref)
    run("flight/offline", flight, [("v", {}, {})], offline=True, **ref)
    run("flight/offline_aided", flight, [("v", {}, {})], offline=True,
        velocity_topic=VELOCITY_TOPIC, **ref)
    run("flight/two", flight, [("a", {}, {}), ("b", {"k1": 0.8, "use_mag": False},
                                              {"body_frame": "frd"})], **ref)
    return out


def compare(a_path: Path, b_path: Path) -> int:
    a, b = json.loads(a_path.read_text()), json.loads(b_path.read_text())
    bad = 0
    for key in sorted(set(a) | set(b)):
        if a.get(key) == b.get(key):
            continue
        bad += 1
        if key not in a or key not in b:
            print(f"{key}: only in {'the first' if key in a else 'the second'}")
            continue
        what = [f"topic {t}" for t in sorted(set(a[key]["topics"]) | set(b[key]["topics"]))
                if a[key]["topics"].get(t) != b[key]["topics"].get(t)]
        what += ["summary"] if a[key]["summary"] != b[key]["summary"] else []
        what += [f"series {s}" for s in a[key]["series"]
                 if a[key]["series"][s] != b[key]["series"].get(s)]
        print(f"{key}: {', '.join(what)}")
    print(f"{len(set(a) | set(b))} replays, {bad} differ")
    return 1 if bad else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", type=Path, help="where to write the fingerprints")
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    args = parser.parse_args()
    if args.compare:
        return compare(*args.compare)
    if args.out is None:
        parser.error("give an output file or --compare A B")
    if not DATA.is_dir():
        parser.error(f"the shared recordings are not at {DATA}")
    with tempfile.TemporaryDirectory() as tmp:
        result = fingerprints(Path(tmp))
    args.out.write_text(json.dumps(result, indent=1, sort_keys=True))
    print(f"{len(result)} replays fingerprinted -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
