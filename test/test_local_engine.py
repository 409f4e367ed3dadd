"""LocalEngine's process pool: safe to start from a process that holds threads.

The suite's node tests leave native DDS threads in the pytest process; a pool forked from it
once deadlocked a worker (a lock held by a thread that does not exist in the child). Here a
thread holds a lock the worker function needs while the pool starts: a forked worker inherits
the lock held and waits for ever; a worker from the fork server imports the module afresh.
"""

from __future__ import annotations

import os
import threading

import pytest

from cf_estimator.cluster import LocalEngine

_LOCK = threading.Lock()


def _needs_the_lock(x: int) -> tuple[int, int, str | None]:
    with _LOCK:
        return x * x, os.getpid(), os.environ.get("CF_ESTIMATOR_TEST_MARK")


@pytest.mark.timeout(120)
def test_pool_started_while_a_thread_holds_a_lock_does_not_deadlock(monkeypatch):
    monkeypatch.setenv("CF_ESTIMATOR_TEST_MARK", "first")
    held, release = threading.Event(), threading.Event()

    def holder() -> None:
        with _LOCK:
            held.set()
            release.wait(100)

    t = threading.Thread(target=holder, daemon=True)
    t.start()
    held.wait(10)
    try:
        seen: list[int] = []
        out = LocalEngine(2).map(_needs_the_lock, range(6), on_done=lambda i, r: seen.append(i))
    finally:
        release.set()
        t.join(10)
    assert [r[0] for r in out] == [x * x for x in range(6)]  # in task order
    assert sorted(seen) == list(range(6))
    assert all(pid != os.getpid() for _, pid, _ in out)  # really other processes
    assert {mark for *_, mark in out} == {"first"}


def test_workers_see_the_callers_environment_at_each_map(monkeypatch):
    """The fork server keeps the environment of its start; the caller's CF_ESTIMATOR_* at
    map time is what a worker runs with (e.g. CF_ESTIMATOR_BACKEND)."""
    engine = LocalEngine(2)
    monkeypatch.setenv("CF_ESTIMATOR_TEST_MARK", "one")
    assert {r[2] for r in engine.map(_needs_the_lock, range(4))} == {"one"}
    monkeypatch.setenv("CF_ESTIMATOR_TEST_MARK", "two")
    assert {r[2] for r in engine.map(_needs_the_lock, range(4))} == {"two"}
    monkeypatch.delenv("CF_ESTIMATOR_TEST_MARK")
    assert {r[2] for r in engine.map(_needs_the_lock, range(4))} == {None}
