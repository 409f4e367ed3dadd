"""``bench fleet``: replay and tuning throughput of a directory of flights, here and on Dask.

The fleet is a directory of bags (``--data``) or simulated ``uav`` flights written to a
temporary directory. Each configuration — this process (no Dask), a LocalCluster with 1 worker,
one with 2 workers (``--workers``) — runs the same two jobs:

* **replay**: every bag through :func:`cf_estimator.bag.fleet.replay_fleet` with an mcap output
  each; throughput in input messages per second of wall time;
* **tune**: one pass of the tuner's scoring (:func:`cf_estimator.bench.tuning.score_candidates`,
  ``--candidates`` parameter sets, the bags read as tuning trials); throughput in
  parameter-samples per second (candidates × IMU samples / wall time).

Timings start once the cluster is up (its start-up is reported apart) and include everything a
command pays after it: on a cluster, sending tasks and trials and gathering the results. Every
result is compared with the local run: replay summaries and output messages, tuning scores, bit
for bit.
"""

from __future__ import annotations

import hashlib
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: The default simulated fleet: ``flights`` × ``uav`` scenario of ``duration_s`` at ``rate_hz``.
DEFAULT_FLIGHTS = 4
DEFAULT_DURATION_S = 60.0
DEFAULT_RATE_HZ = 400.0


@dataclass
class FleetRun:
    """One configuration's figures."""

    engine: str
    workers: int  #: 0 = this process, no Dask
    startup_s: float  #: starting the cluster and sending the tuning trials to it
    replay_s: float
    replay_messages: int
    tune_s: float
    param_samples: int
    identical: bool | None = None  #: None for the local reference run

    @property
    def replay_per_s(self) -> float:
        return self.replay_messages / self.replay_s if self.replay_s > 0 else 0.0

    @property
    def param_samples_per_s(self) -> float:
        return self.param_samples / self.tune_s if self.tune_s > 0 else 0.0


@dataclass
class FleetBench:
    fleet: str
    bags: int
    imu_messages: int
    candidates: int
    runs: list[FleetRun] = field(default_factory=list)


def simulate_fleet(directory: Path, flights: int, duration_s: float, rate_hz: float) -> Path:
    """``flights`` simulated ``uav`` bags (seeds 0..flights-1) in ``directory``."""
    from cf_estimator.bag.simulate import write_scenario_bag
    from cf_estimator.scenarios import make_scenario

    directory.mkdir(parents=True, exist_ok=True)
    for i in range(flights):
        sc = make_scenario("uav", rate_hz=rate_hz, duration_s=duration_s, seed=i)
        write_scenario_bag(sc, directory / f"uav_{i:02d}")
    return directory


def _digest(summaries: list[dict[str, Any]], outputs: Path) -> str:
    """A hash of every bag's summary (without timings and paths) and output IMU/RPY messages."""
    from rosbags.highlevel import AnyReader

    from cf_estimator.bag.fleet import comparable
    from cf_estimator.bag.replay import OUT_IMU_TOPIC, OUT_RPY_TOPIC

    h = hashlib.sha256()
    for s in summaries:
        c = comparable(s)
        c.pop("output", None)
        h.update(repr(sorted(c.items())).encode())
        with AnyReader([outputs / s["name"]]) as reader:
            conns = [x for x in reader.connections if x.topic in (OUT_IMU_TOPIC, OUT_RPY_TOPIC)]
            for conn, t, raw in reader.messages(connections=conns):
                h.update(conn.topic.encode() + t.to_bytes(8, "little") + bytes(raw))
    return h.hexdigest()


def _scores_digest(scores: dict[str, Any]) -> str:
    h = hashlib.sha256()
    for name in sorted(scores):
        for arr in scores[name]:
            h.update(name.encode() + arr.tobytes())
    return h.hexdigest()


def run_fleet_bench(data: str | Path | None = None, *, flights: int = DEFAULT_FLIGHTS,
                    duration_s: float = DEFAULT_DURATION_S, rate_hz: float = DEFAULT_RATE_HZ,
                    workers: tuple[int, ...] = (1, 2), candidates: int = 16,
                    decimate: int = 1, log: Any = None) -> FleetBench:
    """Replay and tune the fleet here, then on LocalClusters of ``workers`` processes."""
    from cf_estimator.bag import fleet as bag_fleet
    from cf_estimator.bag.replay import ReplayOptions
    from cf_estimator.bench import bagtrial, tuning
    from cf_estimator.cluster import DaskEngine, LocalEngine
    from cf_estimator.core.params import FilterParams
    from cf_estimator.pipeline import PipelineParams

    tmp = Path(tempfile.mkdtemp(prefix="cf_estimator_fleet_"))
    try:
        if data is None:
            if log:
                log(f"simulating {flights} uav flight(s) of {duration_s:g} s at {rate_hz:g} Hz")
            root = simulate_fleet(tmp / "fleet", flights, duration_s, rate_hz)
            label = f"{flights} simulated uav flights, {duration_s:g} s at {rate_hz:g} Hz"
        else:
            root, label = Path(data), str(data)
        bags = bag_fleet.find_bags([root])
        if not bags:
            raise ValueError(f"no bags found in {root}")
        opts = ReplayOptions(progress=False, reference_topic=None)
        trials = [bagtrial.load_bag_trial(b).decimated(decimate) for b in bags]
        names = bag_fleet.output_names(bags)
        trials = [_named(t, n) for t, n in zip(trials, names, strict=True)]
        base = FilterParams()
        cands = [base] + [_vary(base, i) for i in range(1, candidates)]
        samples = sum(t.n_samples for t in trials) * len(cands)
        result = FleetBench(label, len(bags), sum(t.n_samples for t in trials) * decimate,
                            len(cands))
        ref_replay = ref_scores = None
        for n in (0, *workers):
            t0 = time.perf_counter()
            engine = LocalEngine(1) if n == 0 else DaskEngine(f"local:{n}")
            try:
                for t in trials:  # the tuner sends each trial once, before its first pass
                    engine.share(t)
                startup = time.perf_counter() - t0
                out = tmp / f"out_{n}"
                tasks = bag_fleet.make_tasks(bags, str(out), None, FilterParams(),
                                             PipelineParams(), opts)
                t0 = time.perf_counter()
                rep = bag_fleet.replay_fleet(tasks, engine, progress=False)
                replay_s = time.perf_counter() - t0
                if rep["failures"]:
                    raise ValueError(rep["failures"][0]["error"])
                t0 = time.perf_counter()
                scores = tuning.score_candidates(cands, trials, jobs=engine)
                tune_s = time.perf_counter() - t0
            finally:
                engine.close()
            digest = (_digest(rep["bags"], out), _scores_digest(scores))
            shutil.rmtree(out, ignore_errors=True)
            if n == 0:
                ref_replay, ref_scores = digest
                identical = None
            else:
                identical = digest == (ref_replay, ref_scores)
            name = f"LocalCluster, {n} worker{'s' if n > 1 else ''}" if n else "no Dask"
            run = FleetRun(name, n, startup,
                           replay_s, rep["fleet"]["messages"], tune_s, samples, identical)
            result.runs.append(run)
            if log:
                log(f"{run.engine}: replay {run.replay_s:.2f} s, tune {run.tune_s:.2f} s")
        return result
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _named(trial: Any, name: str) -> Any:
    import dataclasses

    return dataclasses.replace(trial, name=name)


def _vary(base: Any, i: int) -> Any:
    """Candidate ``i``: the gains scaled on a fixed grid (deterministic, all valid)."""
    import dataclasses

    f = 0.5 + 0.1 * (i % 10)
    return dataclasses.replace(base, k1=base.k1 * f, k2=base.k2 * f)


def format_fleet_bench(r: FleetBench) -> str:
    """The table: per configuration, replay and tune throughput, speed-up, per worker."""
    ref = r.runs[0]
    lines = [
        f"Fleet: {r.fleet}: {r.bags} bag(s), {r.imu_messages} IMU messages; tune: "
        f"{r.candidates} candidates x every trial",
        f"  {'engine':<24} {'start s':>7} {'replay msg/s':>13} {'x':>5} {'per worker':>11} "
        f"{'tune p-samples/s':>17} {'x':>5} {'per worker':>11}  identical",
    ]
    for run in r.runs:
        k = max(1, run.workers)
        sr = run.replay_per_s / ref.replay_per_s if ref.replay_per_s else 0.0
        st = run.param_samples_per_s / ref.param_samples_per_s if ref.param_samples_per_s else 0.0
        same = "reference" if run.identical is None else ("yes" if run.identical else "NO")
        lines.append(
            f"  {run.engine:<24} {run.startup_s:7.2f} {run.replay_per_s:13,.0f} "
            f"{sr:5.2f} {run.replay_per_s / k:11,.0f} {run.param_samples_per_s:17,.0f} "
            f"{st:5.2f} {run.param_samples_per_s / k:11,.0f}  {same}")
    lines.append("  x: speed-up over no Dask; per worker: throughput / workers, the figure that "
                 "carries to a bigger cluster")
    lines.append("  start s: starting the cluster and sending the tuning trials (not in the "
                 "throughputs); replay: a task per bag, so at most one worker per bag")
    return "\n".join(lines) + "\n"


def to_json(r: FleetBench) -> dict[str, Any]:
    return {
        "fleet": r.fleet, "bags": r.bags, "imu_messages": r.imu_messages,
        "candidates": r.candidates,
        "runs": [{"engine": x.engine, "workers": x.workers, "startup_s": x.startup_s,
                  "replay_s": x.replay_s, "replay_messages": x.replay_messages,
                  "replay_messages_per_s": x.replay_per_s, "tune_s": x.tune_s,
                  "param_samples": x.param_samples,
                  "param_samples_per_s": x.param_samples_per_s, "identical": x.identical}
                 for x in r.runs],
    }
