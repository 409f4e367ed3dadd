"""Process pool for the benchmarks and the tuner: one call, serial when one job is enough."""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable
from typing import Any


def run_tasks(worker: Callable[[Any], Any], tasks: list, jobs: int) -> list:
    """``[worker(t) for t in tasks]``, in task order; in a process pool when ``jobs`` > 1
    (fork on POSIX: workers inherit the loaded data)."""
    if jobs <= 1 or len(tasks) <= 1:
        return [worker(t) for t in tasks]
    ctx = multiprocessing.get_context("fork" if os.name == "posix" else "spawn")
    with ctx.Pool(min(jobs, len(tasks))) as pool:
        return pool.map(worker, tasks, chunksize=1)
