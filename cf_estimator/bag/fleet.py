"""Replay many recordings: find the bags, replay each (here or on a Dask cluster), summarise.

Each bag is one independent task (:func:`replay_task`): it reads its input by path, writes its
own output bag and plots, and returns its JSON summary, or a one-line failure (corrupt,
truncated, no IMU topic...) without stopping the others. :func:`replay_fleet` runs the tasks on
a :class:`cf_estimator.cluster.Engine` with one progress bar over the whole fleet.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cf_estimator.bag import io
from cf_estimator.bag.replay import ReplayError, ReplayOptions, replay_bag
from cf_estimator.core.params import FilterParams
from cf_estimator.pipeline import PipelineParams

#: Files a fleet directory is searched for (any case): ROS 1 bags, PX4 ulogs,
#: ArduPilot DataFlash logs. (".bag" stays lower case: rosbags reads ROS 1 by that suffix.)
LOG_SUFFIXES = (".bag", ".ulg", ".bin")
#: Summary keys that depend on the machine, not on the data (left out of comparisons).
TIMING_KEYS = ("wall_time_s", "messages_per_s")


def _is_ros2_dir(p: Path) -> bool:
    return p.is_dir() and (p / "metadata.yaml").is_file()


def _storage_dir(p: Path) -> bool:
    """A directory holding bag storage files but no metadata (a broken ROS 2 bag)."""
    return p.is_dir() and (any(p.glob("*.mcap")) or any(p.glob("*.db3")))


def find_bags(inputs: Sequence[str | os.PathLike[str]]) -> list[Path]:
    """The bags named by ``inputs``: ROS 1 ``.bag`` files and ROS 2 bag directories as given,
    and those found (recursively, sorted, hidden entries skipped) in other directories.

    A directory with ``.mcap``/``.db3`` files but no ``metadata.yaml`` is listed too, so its
    replay fails with the reason instead of being skipped silently.
    """
    found: list[Path] = []
    for item in inputs:
        p = Path(item)
        if not p.is_dir() or _is_ros2_dir(p):
            found.append(p)
            continue
        here_found: list[Path] = []
        for root, dirs, files in os.walk(p):
            dirs[:] = sorted(d for d in dirs if not d.startswith("."))
            here = Path(root)
            if here != p and (_is_ros2_dir(here) or _storage_dir(here)):
                here_found.append(here)
                dirs[:] = []
                continue
            here_found.extend(here / f for f in files
                              if f.lower().endswith(LOG_SUFFIXES) and not f.startswith("."))
            if here == p and _storage_dir(here):
                here_found.append(here)
        found.extend(sorted(here_found, key=lambda b: b.relative_to(p).as_posix()))
    return list(dict.fromkeys(found))


def output_names(bags: Sequence[Path]) -> list[str]:
    """One unique output name per bag: its name without ``.bag``; on a clash, its path
    below the common directory with ``/`` as ``_``."""
    stems = [b.name[:-4] if b.name.lower().endswith(LOG_SUFFIXES) else b.name for b in bags]
    if len(set(stems)) == len(stems):
        return stems
    absolute = [b.resolve() for b in bags]
    root = Path(os.path.commonpath([str(a.parent) for a in absolute]))
    names = []
    for a in absolute:
        rel = a.relative_to(root).as_posix()
        names.append((rel[:-4] if rel.lower().endswith(LOG_SUFFIXES) else rel).replace("/", "_"))
    return names


@dataclass
class ReplayTask:
    """One bag of a fleet: what a worker needs (all picklable, paths absolute)."""

    bag: str
    name: str
    output: str | None
    plot_dir: str | None
    filter_params: FilterParams
    pipeline_params: PipelineParams
    options: ReplayOptions


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def replay_task(task: ReplayTask) -> dict[str, Any]:
    """Replay one bag; ``{"status": "ok", "summary": ...}`` or ``{"status": "failed",
    "input": ..., "error": one line}`` (never raises for a bad bag)."""
    try:
        if task.output is not None:  # the fleet's output directory, on the worker's side
            Path(task.output).parent.mkdir(parents=True, exist_ok=True)
        result = replay_bag(task.bag, task.output, task.filter_params, task.pipeline_params,
                            task.options)
        summary = result.summary
        summary["name"] = task.name
        if task.plot_dir is not None:
            from cf_estimator.bag.plots import plot_replay

            paths = plot_replay(result, task.plot_dir, title=Path(task.bag).name)
            summary["plots"] = [str(p) for p in paths]
        return {"status": "ok", "name": task.name, "summary": summary}
    except (io.BagError, ReplayError) as exc:
        error = _one_line(exc)
    except Exception as exc:  # noqa: BLE001 - a bag that breaks anything else is still one line
        error = f"{task.bag}: {type(exc).__name__}: {_one_line(exc)}"
    if not error.startswith(task.bag):
        error = f"{task.bag}: {error}"
    return {"status": "failed", "name": task.name, "input": task.bag, "error": error}


def count_task(path: str) -> int:
    """Messages on the IMU, magnetometer and reference types of a bag (0 if unreadable): the
    progress bar's share of that bag."""
    types = {io.IMU_TYPE, io.MAG_TYPE, *io.REFERENCE_TYPES}
    try:
        with io.open_bag(path) as bag:
            return sum(i.count for i in bag.topics if i.msgtype in types)
    except Exception:  # noqa: BLE001 - its replay reports why
        return 0


class FleetProgress:
    """One tqdm bar over every bag's messages, with bags done/failed as its postfix."""

    def __init__(self, totals: Sequence[int], enabled: bool | None) -> None:
        if enabled is None:
            enabled = sys.stderr.isatty()
        self.totals = list(totals)
        self.shown = [0] * len(self.totals)
        self.done = self.failed = 0
        self._bar = None
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(total=sum(self.totals), unit="msg", unit_scale=True,
                             desc=f"fleet ({len(self.totals)} bags)", file=sys.stderr,
                             leave=False, dynamic_ncols=True)
            self._postfix()

    def _postfix(self) -> None:
        if self._bar is not None:
            self._bar.set_postfix_str(f"bags {self.done}/{len(self.totals)}, failed "
                                      f"{self.failed}", refresh=False)

    def messages(self, i: int, n: int) -> None:
        """``n`` more messages of bag ``i`` read (no further than its count)."""
        n = max(0, min(n, self.totals[i] - self.shown[i]))
        self.shown[i] += n
        if self._bar is not None and n:
            self._bar.update(n)

    def finished(self, i: int, ok: bool) -> None:
        self.messages(i, self.totals[i])
        self.done += 1
        self.failed += 0 if ok else 1
        self._postfix()
        if self._bar is not None:
            self._bar.refresh()

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def make_tasks(bags: Sequence[Path], output_dir: str | None, plot_dir: str | None,
               filter_params: FilterParams, pipeline_params: PipelineParams,
               options: ReplayOptions) -> list[ReplayTask]:
    """One task per bag; outputs ``OUT/<name>`` and plots ``PLOTS/<name>/`` (absolute paths,
    so a worker with another working directory writes the same place)."""
    names = output_names(bags)
    opts = dataclasses.replace(options, progress=False, on_messages=None)
    return [
        ReplayTask(
            bag=str(Path(b).absolute()), name=n,
            output=str(Path(output_dir, n).absolute()) if output_dir is not None else None,
            plot_dir=str(Path(plot_dir, n).absolute()) if plot_dir is not None else None,
            filter_params=filter_params, pipeline_params=pipeline_params, options=opts,
        )
        for b, n in zip(bags, names, strict=True)
    ]


def replay_fleet(tasks: Sequence[ReplayTask], engine: Any | None = None,
                 progress: bool | None = None) -> dict[str, Any]:
    """Replay every task on ``engine`` (default: serially here); the fleet summary.

    Returns ``{"fleet": totals, "bags": [summary of each replayed bag], "failures": [...]}``
    in task order. Serially in this process the bar advances message by message; on an engine
    with workers it advances as each bag finishes.
    """
    from cf_estimator.cluster import LocalEngine

    engine = engine or LocalEngine(1)
    t0 = time.perf_counter()
    totals = engine.map(count_task, [t.bag for t in tasks])
    bar = FleetProgress(totals, progress)
    run_tasks: Sequence[ReplayTask] = tasks
    if isinstance(engine, LocalEngine) and engine.workers <= 1:
        current = {"i": 0}

        def on_messages(n: int) -> None:
            bar.messages(current["i"], n)

        run_tasks = [dataclasses.replace(
            t, options=dataclasses.replace(t.options, on_messages=on_messages)) for t in tasks]
        results: list[dict[str, Any]] = []
        try:
            for i, t in enumerate(run_tasks):
                current["i"] = i
                r = replay_task(t)
                results.append(r)
                bar.finished(i, r["status"] == "ok")
        finally:
            bar.close()
    else:
        try:
            results = engine.map(replay_task, run_tasks,
                                 on_done=lambda i, r: bar.finished(i, r["status"] == "ok"))
        finally:
            bar.close()
    wall = time.perf_counter() - t0
    ok = [r["summary"] for r in results if r["status"] == "ok"]
    failures = [{"name": r["name"], "input": r["input"], "error": r["error"]}
                for r in results if r["status"] != "ok"]
    messages = sum(s["messages_in"] + s["mag_messages_in"] + s["reference_messages_in"]
                   for s in ok)
    return {
        "fleet": {
            "bags": len(tasks), "replayed": len(ok), "failed": len(failures),
            "messages": messages, "imu_messages": sum(s["messages_in"] for s in ok),
            "engine": getattr(engine, "description", "this process"),
            "wall_time_s": wall, "messages_per_s": messages / wall if wall > 0 else None,
        },
        "bags": ok,
        "failures": failures,
    }


def comparable(summary: dict[str, Any]) -> dict[str, Any]:
    """A bag's summary without the machine-dependent figures (:data:`TIMING_KEYS`)."""
    return {k: v for k, v in summary.items() if k not in TIMING_KEYS}


def _shown(path: str | None) -> str:
    """A path as the table shows it: relative to the working directory when below it."""
    if not path:
        return "-"
    rel = os.path.relpath(path)
    return path if rel.startswith("..") else rel


def _num(value: Any, spec: str) -> str:
    """A table figure: ``value`` with ``spec``, ``n/a`` when None/NaN (never a traceback)."""
    if value is None or (isinstance(value, float) and value != value):
        return "n/a"
    return format(value, spec)


def format_table(fleet: dict[str, Any]) -> str:
    """The console table: one line per bag (figures or the failure), then the totals."""
    rows = [("bag", "format", "IMU msgs", "stamps s", "rejected", "resets", "bias",
             "RMSE tot/incl deg", "output")]
    by_name: dict[str, Any] = {s["name"]: ("ok", s) for s in fleet["bags"]}
    by_name.update({f["name"]: ("failed", f) for f in fleet["failures"]})
    order = [s["name"] for s in fleet["bags"]] + [f["name"] for f in fleet["failures"]]
    lines = []
    for name in order:
        kind, s = by_name[name]
        if kind == "failed":
            lines.append(f"FAILED  {s['error'].replace(s['input'], _shown(s['input']))}")
            continue
        rmse = s.get("rmse_deg")
        rmse_text = (f"{_num(rmse.get('total'), '.2f')}/{_num(rmse.get('inclination'), '.2f')}"
                     if rmse else "-")
        rows.append((
            name, s["input_format"], str(s["messages_in"]), _num(s.get("duration_s"), ".1f"),
            str(sum((s.get("messages_rejected") or {}).values())),
            str(sum((s.get("resets") or {}).values())),
            "converged" if s.get("gyro_bias_converged") else "no",
            rmse_text, _shown(s.get("output")),
        ))
    widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]))]
    table = ["  ".join(v.ljust(w) if c in (0, 1, 6, 8) else v.rjust(w)
                       for c, (v, w) in enumerate(zip(r, widths, strict=True))).rstrip()
             for r in rows]
    f = fleet["fleet"]
    rate = f["messages_per_s"]
    table.extend(lines)
    modes = sorted({s.get("mode", "online") for s in fleet["bags"]})
    mode = (" (offline: acausal estimates, --offline)" if modes == ["offline"]
            else f" (modes: {', '.join(modes)})" if len(modes) > 1 else "")
    table.append(f"fleet   {f['replayed']} of {f['bags']} bag(s) replayed{mode}, {f['failed']} "
                 f"failed; {f['messages']} messages in {_num(f.get('wall_time_s'), '.2f')} s"
                 + (f" ({rate / 1e3:.1f} k messages/s)" if rate else "") + f" on {f['engine']}")
    return "\n".join(table) + "\n"
