"""Where the evaluator's work runs: one interface over a serial loop and process pools.

An :class:`Executor` maps a function over items and returns the results in the items' order::

    executor.map(fn, items) -> list      # fn and the items must pickle for a process pool
    executor.n_workers                   # how many run at once (the evaluator splits work by it)
    executor.close()                     # release the workers; the executor is not used after

``fn`` may keep state in module globals of the worker process between calls (the evaluator keeps its
scanner and reference there), so a pool's workers should live as long as the executor.

Back-ends by name in :data:`EXECUTORS` (a factory taking the number of workers): ``joblib`` (joblib's
loky process pool, created on first use and reused). A Dask back-end slots in the same way: a class whose
``map`` is ``client.gather(client.map(fn, items, pure=False))`` and whose ``n_workers`` is the cluster's
worker count, made available with ``register_executor("dask", lambda n: DaskExecutor(client, n))``;
then ``make_executor(4, "dask")``. Results do not depend on the executor (tests/test_executors.py).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from typing import Protocol, runtime_checkable

from optipose.errors import ConfigError

__all__ = ["Executor", "SerialExecutor", "JoblibExecutor", "EXECUTORS", "register_executor", "make_executor"]

log = logging.getLogger(__name__)


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
        from joblib import Parallel, delayed

        if self._pool is None:
            log.debug("starting a loky pool of %d workers", self.n_workers)
            self._pool = Parallel(n_jobs=self.n_workers, backend="loky")
        return list(self._pool(delayed(fn)(item) for item in items))

    def close(self) -> None:
        self._pool = None  # loky keeps its workers for the next pool of the same size

    def __repr__(self) -> str:
        return f"JoblibExecutor(n_jobs={self.n_workers})"


EXECUTORS: dict[str, Callable[[int], Executor]] = {"joblib": JoblibExecutor}


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
