"""Process pool or cluster for the benchmarks and the tuner: one call, serial when one job is
enough. ``jobs`` is a process count or a :class:`cf_estimator.cluster.Engine` (``--cluster``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


def workers_of(jobs: Any) -> int:
    """How many tasks run at once: ``jobs`` itself, or the engine's worker count."""
    return int(getattr(jobs, "workers", jobs))


def run_tasks(worker: Callable[[Any], Any], tasks: list, jobs: Any,
              on_done: Callable[[int, Any], None] | None = None) -> list:
    """``[worker(t) for t in tasks]``, in task order; in a process pool when ``jobs`` > 1
    (fork on POSIX: workers inherit the loaded data), on the engine when ``jobs`` is one."""
    from cf_estimator.cluster import Engine, LocalEngine

    engine = jobs if isinstance(jobs, Engine) else LocalEngine(int(jobs))
    return engine.map(worker, tasks, on_done)


def share(jobs: Any, obj: Any) -> Any:
    """``obj`` as tasks on ``jobs`` should reference it: itself locally; on a cluster, a handle
    to one copy kept in the workers' memory (sent once, reused by every task and pass)."""
    fn = getattr(jobs, "share", None)
    return fn(obj) if fn is not None else obj


def aligned(obj: Any) -> Any:
    """``obj`` (a dataclass) with every unaligned NumPy array field copied to aligned memory.

    Arrays a cluster worker receives can sit unaligned in the message buffer; the compiled
    filter step takes only aligned native float64 buffers (PEP 3118 format ``d``). Locally
    nothing is copied; the values are the same bits either way.
    """
    import dataclasses

    import numpy as np

    if not dataclasses.is_dataclass(obj) or isinstance(obj, type):
        return obj
    fixed = {f.name: np.array(v, copy=True) for f in dataclasses.fields(obj)
             if isinstance(v := getattr(obj, f.name), np.ndarray) and not v.flags.aligned}
    return dataclasses.replace(obj, **fixed) if fixed else obj
