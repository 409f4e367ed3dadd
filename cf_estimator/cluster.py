"""Where independent work runs: this process, a local process pool, or a Dask cluster.

An :class:`Engine` maps a module-level function over picklable tasks and returns the results
in task order (``on_done(i, result)`` is called as each one finishes, for progress bars).
:func:`make_engine` turns the CLI's ``--cluster`` / ``--jobs`` into one:

* no ``--cluster``: :class:`LocalEngine` (serial, or a pool of ``jobs`` processes started by
  a fork server) — nothing of Dask is imported;
* ``--cluster local:N``: a Dask ``LocalCluster`` of N single-threaded worker processes on the
  loopback interface, shut down when the command ends;
* ``--cluster tcp://host:8786``: a running Dask scheduler (``dask scheduler`` / ``dask worker``).

What travels to a Dask worker is the task (parameters, a recording's *path*, options) and the
result (summaries, score arrays); recordings are read by the workers from shared storage, never
shipped. :meth:`DaskEngine.check_paths` refuses, in one line, a path a worker cannot read.
A worker must run the same cf_estimator version with the same filter-step backend as the client:
checked at connection (:meth:`DaskEngine.check_workers`), so results are those of a local run.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
from collections.abc import Callable, Sequence
from typing import Any

#: Seconds to wait for a scheduler (and its workers) before giving up with one line.
CONNECT_TIMEOUT_S = 20.0


class ClusterError(Exception):
    """A user-facing cluster failure (bad --cluster, unreachable scheduler, unreadable path)."""


class Engine:
    """Runs ``fn(task)`` for every task; results in task order."""

    #: how many tasks can run at once (splits work, e.g. candidate slices in the tuner)
    workers: int = 1
    description: str = "this process"

    def map(self, fn: Callable[[Any], Any], tasks: Sequence[Any],
            on_done: Callable[[int, Any], None] | None = None) -> list[Any]:
        raise NotImplementedError

    def check_paths(self, paths: Sequence[str], *, writable: Sequence[str] = ()) -> None:
        """Every worker can read ``paths`` and write into the directories ``writable``."""

    def share(self, obj: Any) -> Any:
        """A handle tasks can carry instead of ``obj`` (here: ``obj`` itself)."""
        return obj

    def close(self) -> None:
        """Release workers (idempotent)."""

    def __enter__(self) -> Engine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


#: Environment variables a local worker takes from the caller at each task (a fork server's
#: workers otherwise keep the environment of the moment the server started).
_WORKER_ENV_PREFIX = "CF_ESTIMATOR_"


def _caller_env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k.startswith(_WORKER_ENV_PREFIX)}


def _indexed(args: tuple[Callable[[Any], Any], int, Any, dict[str, str]]) -> tuple[int, Any]:
    fn, i, task, env = args
    for k in [k for k in os.environ if k.startswith(_WORKER_ENV_PREFIX) and k not in env]:
        del os.environ[k]
    os.environ.update(env)
    return i, fn(task)


def _pool_context() -> multiprocessing.context.BaseContext:
    """A fork server on POSIX, else spawn.

    Never a plain fork: the caller may hold native threads (a ROS 2 node's DDS threads, Dask,
    BLAS) and a child forked while one of them holds a lock waits on it for ever. The fork
    server is a fresh single-threaded interpreter started once per process; the workers it
    forks import what a task needs (the same as spawn, without an interpreter start per
    worker).
    """
    if "forkserver" in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("forkserver")
    return multiprocessing.get_context("spawn")


class LocalEngine(Engine):
    """Serial in this process (``jobs`` ≤ 1), else a pool of ``jobs`` worker processes.

    ``fn`` must be a module-level function and the tasks picklable (as for Dask); a worker
    sees the caller's ``CF_ESTIMATOR_*`` environment variables as they are at :meth:`map`. As
    with spawn, a script that uses a pool from the library (``jobs`` > 1) guards its entry
    point with ``if __name__ == "__main__":`` (the workers import the main module).
    """

    def __init__(self, jobs: int = 1) -> None:
        self.workers = max(1, int(jobs))
        self.description = ("this process" if self.workers == 1
                            else f"{self.workers} local processes")

    def map(self, fn: Callable[[Any], Any], tasks: Sequence[Any],
            on_done: Callable[[int, Any], None] | None = None) -> list[Any]:
        tasks = list(tasks)
        out: list[Any] = [None] * len(tasks)
        if self.workers <= 1 or len(tasks) <= 1:
            for i, t in enumerate(tasks):
                out[i] = fn(t)
                if on_done:
                    on_done(i, out[i])
            return out
        env = _caller_env()
        with _pool_context().Pool(min(self.workers, len(tasks))) as pool:
            for i, r in pool.imap_unordered(_indexed,
                                            [(fn, i, t, env) for i, t in enumerate(tasks)]):
                out[i] = r
                if on_done:
                    on_done(i, r)
        return out


def _worker_identity() -> dict[str, str]:
    """What a worker runs (compared with the client's at connection)."""
    from cf_estimator import __version__
    from cf_estimator.core.kernel import resolve_backend

    try:
        backend = resolve_backend()
    except (RuntimeError, ValueError) as exc:
        backend = f"unavailable: {exc}"
    return {"version": __version__, "backend": backend}


def _unreadable(paths: Sequence[str], writable: Sequence[str]) -> list[str]:
    """The paths this process cannot read (or, for ``writable``, write into)."""
    bad = [p for p in paths if not (os.path.exists(p) and os.access(p, os.R_OK))]
    for d in writable:
        probe = d
        while probe and not os.path.exists(probe):  # an output dir not created yet: its parent
            parent = os.path.dirname(probe.rstrip("/"))
            if parent == probe:
                break
            probe = parent
        if not (os.path.isdir(probe) and os.access(probe, os.W_OK | os.X_OK)):
            bad.append(f"{d} (not writable)")
    return bad


class DaskEngine(Engine):
    """Tasks on a Dask distributed cluster (``client.map``; results gathered in order)."""

    def __init__(self, address: str) -> None:
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise ClusterError("--cluster needs Dask distributed: pip install "
                               "'cf_estimator[cluster]' (or 'dask[distributed]')") from None
        self._cluster = None
        self.client = None
        self._shared: dict[int, tuple[Any, Any]] = {}
        try:
            if address.startswith("local:"):
                n = _count(address[len("local:"):])
                self._cluster = LocalCluster(
                    n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                    dashboard_address="127.0.0.1:0", silence_logs=50,  # loopback, any port
                )
                self.client = Client(self._cluster, timeout=CONNECT_TIMEOUT_S)
                self.description = f"Dask LocalCluster, {n} worker process(es)"
            else:
                if "://" not in address:
                    address = f"tcp://{address}"
                self.client = Client(address, timeout=CONNECT_TIMEOUT_S)
                self.client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
                self.description = f"Dask scheduler {address}"
        except ClusterError:
            self.close()
            raise
        except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, CommClosedError...
            self.close()
            text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ClusterError(f"--cluster {address}: cannot start or reach the cluster: "
                               f"{text}") from None
        self.workers = max(1, sum(int(n) for n in self.client.nthreads().values()))
        self.description += f" ({self.workers} thread(s) in all)"
        self.check_workers()

    def check_workers(self) -> None:
        """Every worker runs this cf_estimator version with this filter backend."""
        mine = _worker_identity()
        try:
            theirs = self.client.run(_worker_identity)
        except Exception as exc:  # noqa: BLE001 - e.g. cf_estimator not installed there
            raise ClusterError(f"cannot run cf_estimator on the workers ({type(exc).__name__}: "
                               f"{exc}); install it there (same version)") from None
        for worker, ident in sorted(theirs.items()):
            if ident != mine:
                self.close()
                raise ClusterError(
                    f"worker {worker} runs cf_estimator {ident['version']} (filter step "
                    f"{ident['backend']}), this client {mine['version']} ({mine['backend']}): "
                    "install the same version everywhere so results match a local run")

    def check_paths(self, paths: Sequence[str], *, writable: Sequence[str] = ()) -> None:
        absolute = [os.path.abspath(p) for p in paths]
        outs = [os.path.abspath(d) for d in writable]
        answers = self.client.run(_unreadable, absolute, outs)
        for worker, bad in sorted(answers.items()):
            if bad:
                more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
                raise ClusterError(
                    f"worker {worker} cannot read {bad[0]}{more}: recordings and outputs go to "
                    "the workers by path, so they must be on storage every worker mounts at "
                    "the same path")

    def share(self, obj: Any) -> Any:
        """``obj`` scattered once to the workers (a future that tasks carry; kept, per object,
        for the engine's lifetime, so the tuner's passes reuse it)."""
        key = id(obj)
        if key not in self._shared:
            self._shared[key] = (obj, self.client.scatter(obj, hash=False))
        return self._shared[key][1]

    def map(self, fn: Callable[[Any], Any], tasks: Sequence[Any],
            on_done: Callable[[int, Any], None] | None = None) -> list[Any]:
        from distributed import as_completed

        tasks = list(tasks)
        if not tasks:
            return []
        futures = self.client.map(fn, tasks, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        out: list[Any] = [None] * len(tasks)
        try:
            for fut in as_completed(futures):
                i = index[fut.key]
                out[i] = fut.result()  # a task's exception is raised here, as locally
                if on_done:
                    on_done(i, out[i])
        finally:
            for f in futures:
                f.release()
        return out

    def close(self) -> None:
        client, cluster = getattr(self, "client", None), self._cluster
        self.client, self._cluster = None, None
        self._shared = {}
        # closing must not mask the real error
        if client is not None:
            with contextlib.suppress(Exception):
                client.close()
        if cluster is not None:
            with contextlib.suppress(Exception):
                cluster.close()


def _count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise ClusterError(f"--cluster local:{text}: N must be a whole number >= 1 "
                           "(worker processes)")
    return n


def make_engine(cluster: str | None, jobs: int = 1) -> Engine:
    """The engine for ``--cluster`` (None: local, ``jobs`` processes; Dask is not imported)."""
    if cluster is None:
        return LocalEngine(jobs)
    cluster = cluster.strip()
    if not cluster:
        raise ClusterError("--cluster: empty address; give tcp://HOST:PORT or local:N")
    if cluster.startswith("local:"):
        _count(cluster[len("local:"):])
    return DaskEngine(cluster)


def add_cluster_option(parser: Any) -> None:
    """``--cluster ADDRESS|local:N`` (shared by replay, tune and bench)."""
    parser.add_argument(
        "--cluster", metavar="ADDRESS",
        help="run the work on Dask: tcp://HOST:8786 (a running `dask scheduler`) or local:N "
        "(a LocalCluster of N worker processes); recordings go to the workers by path, so they "
        "must be on shared storage (docs/cluster.md). Default: this machine, without Dask")
