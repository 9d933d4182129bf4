"""Where the evaluator's work runs: one interface over a serial loop and process pools.

An :class:`Executor` maps a function over items and returns the results in the items' order::

    executor.map(fn, items) -> list      # fn and the items must pickle for a process pool
    executor.n_workers                   # how many run at once (the evaluator splits work by it)
    executor.close()                     # release the workers; the executor is not used after

``fn`` may keep state in module globals of the worker process between calls (the evaluator keeps its
scanner and reference there), so a pool's workers should live as long as the executor.

Back-ends by name in :data:`EXECUTORS` (a factory taking the number of workers): ``joblib`` (joblib's
loky process pool, created on first use and reused) and ``dask`` (:class:`DaskExecutor`: a local Dask
cluster of n single-threaded worker processes, or the scheduler named by Dask's ``scheduler-address``
setting, e.g. ``DASK_SCHEDULER_ADDRESS=tcp://host:8786``, so one evaluation can run on a cluster). Another
back-end slots in with ``register_executor(name, factory)``. Results do not depend on the executor
(tests/test_executors.py).

Worker processes an executor starts get :func:`thread_env`: every thread pool a worker may open (BLAS,
OpenMP, numba, the scanner's ray threads) capped, so n workers on n cores do not run n² threads.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from typing import Protocol, runtime_checkable

from optipose.errors import ConfigError, WorkerError

__all__ = [
    "Executor",
    "SerialExecutor",
    "JoblibExecutor",
    "DaskExecutor",
    "EXECUTORS",
    "register_executor",
    "make_executor",
    "THREAD_VARIABLES",
    "thread_env",
    "stop_workers",
]

log = logging.getLogger(__name__)

THREAD_VARIABLES = (
    "OMP_NUM_THREADS",  # OpenMP: Open3D, MKL's and OpenBLAS's OpenMP builds
    "MKL_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "NUMBA_NUM_THREADS",
    "OPTIPOSE_RAY_THREADS",  # the scanner's Embree ray-casting threads (optipose.scan.raycast)
)


def thread_env(threads: int = 1) -> dict[str, str]:
    """Environment variables capping every thread pool a worker process may start at ``threads``
    (BLAS and OpenMP read them only when they load, so they are given to a process when it starts)."""
    return {name: str(max(1, int(threads))) for name in THREAD_VARIABLES}


@runtime_checkable
class Executor(Protocol):
    """Runs ``fn`` over ``items``, results in order; see the module doc."""

    n_workers: int

    def map(self, fn: Callable, items: Iterable) -> list: ...

    def close(self) -> None: ...


class SerialExecutor:
    """Everything in this process, one item after another."""

    n_workers = 1

    def map(self, fn: Callable, items: Iterable) -> list:
        return [fn(item) for item in items]

    def close(self) -> None:
        pass

    def __repr__(self) -> str:
        return "SerialExecutor()"


class JoblibExecutor:
    """``n_jobs`` worker processes of joblib's loky back-end; the pool is created on first use and reused."""

    def __init__(self, n_jobs: int):
        if int(n_jobs) < 1:
            raise ValueError(f"n_jobs must be >= 1, got {n_jobs}")
        self.n_workers = int(n_jobs)
        self._pool = None

    def map(self, fn: Callable, items: Iterable) -> list:
        """``fn`` over the items on the workers. When a worker process dies (killed, out of memory), loky
        replaces it and the map runs once more (the work is pure: the same items give the same results);
        a second death is a :class:`~optipose.errors.WorkerError`."""
        from joblib import Parallel, delayed
        from joblib.externals.loky.process_executor import BrokenProcessPool

        items = list(items)
        for attempt in (1, 2):
            if self._pool is None:
                log.debug("starting a loky pool of %d workers", self.n_workers)
                self._pool = Parallel(n_jobs=self.n_workers, backend="loky")
            try:
                return list(self._pool(delayed(fn)(item) for item in items))
            except BrokenProcessPool as exc:  # TerminatedWorkerError is one
                self._pool = None
                reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                if attempt == 2:
                    raise WorkerError(f"a worker process died twice running the same work ({reason})") from None
                log.warning("a worker process died (%s); running its %d tasks again", reason, len(items))
        raise AssertionError("unreachable")

    def close(self) -> None:
        self._pool = None  # loky keeps its workers for the next pool of the same size

    def __repr__(self) -> str:
        return f"JoblibExecutor(n_jobs={self.n_workers})"


def stop_workers() -> None:
    """Stop the loky workers this process started, at once: for a process that is about to end. At the
    interpreter's exit loky would wait for each idle worker's own teardown, a few tenths of a second of a
    command's wall (benchmarks/README.md, "bench_start.py")."""
    import sys

    module = sys.modules.get("joblib.externals.loky.reusable_executor")
    pool = getattr(module, "_executor", None)  # loky's one reusable pool; None when this process started none
    if pool is not None:
        pool.shutdown(wait=True, kill_workers=True)


class DaskExecutor:
    """Dask distributed: ``client.map`` over the cluster's workers, results gathered in order.

    client : a ``distributed.Client`` of the caller's (left open by :meth:`close`); else ``address`` (a
    scheduler, ``tcp://host:8786``), else Dask's ``scheduler-address`` setting, else a local cluster of
    ``n_workers`` single-threaded worker processes with capped thread pools (closed by :meth:`close`).
    ``n_workers`` is then the cluster's worker threads, which the evaluator splits its work by."""

    def __init__(self, n_workers: int = 2, address: str | None = None, client=None):
        import dask
        from distributed import Client, LocalCluster

        self._own, self._cluster = client is None, None
        address = address or dask.config.get("scheduler-address", None)
        if client is not None:
            self._client = client
        elif address:
            try:
                self._client = Client(address, timeout=10, set_as_default=False)
            except (OSError, TimeoutError) as exc:
                raise ConfigError(f"cannot reach the Dask scheduler at {address} ({exc})") from None
        else:
            self._cluster = LocalCluster(
                n_workers=int(n_workers),
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                env=thread_env(1),
            )
            self._client = Client(self._cluster, set_as_default=False)
        self.n_workers = max(1, sum(w["nthreads"] for w in self._client.scheduler_info()["workers"].values()))

    def map(self, fn: Callable, items: Iterable) -> list:
        """``fn`` over the items on the cluster; the scheduler re-runs the tasks of a worker that dies (Dask's
        ``distributed.scheduler.allowed-failures``, 3 by default), past that a :class:`~optipose.errors.WorkerError`."""
        from distributed import KilledWorker

        try:
            return self._client.gather(self._client.map(fn, list(items), pure=False))
        except KilledWorker as exc:
            raise WorkerError(f"Dask workers died running the same task too often ({exc})") from None

    def close(self) -> None:
        if self._own:
            self._client.close()
            if self._cluster is not None:
                self._cluster.close()

    def __repr__(self) -> str:
        return f"DaskExecutor(n_workers={self.n_workers}, scheduler={self._client.scheduler.address})"


EXECUTORS: dict[str, Callable[[int], Executor]] = {"joblib": JoblibExecutor, "dask": DaskExecutor}


def register_executor(name: str, factory: Callable[[int], Executor]) -> None:
    """Make ``factory(n_workers) -> Executor`` available to :func:`make_executor` as ``backend=name``."""
    EXECUTORS[str(name)] = factory


def make_executor(jobs: int | Executor = 1, backend: str = "joblib") -> Executor:
    """An executor for ``jobs`` workers: serial for 1, else ``EXECUTORS[backend](jobs)``; an
    :class:`Executor` given as ``jobs`` is returned as it is."""
    if isinstance(jobs, Executor):
        return jobs
    jobs = max(1, int(jobs))
    if jobs == 1:
        return SerialExecutor()
    if backend not in EXECUTORS:
        raise ConfigError(f"unknown executor '{backend}' (registered: {', '.join(EXECUTORS)})")
    return EXECUTORS[backend](jobs)
