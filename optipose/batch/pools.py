"""Where a study's trials run: one small interface over this process, joblib's process pool and Dask.

A :class:`TrialPool` runs one function call per trial and hands back whichever finishes first::

    pool.workers                       # trials at once (the study keeps that many in flight)
    pool.submit(fn, *args) -> future
    pool.wait_any(futures) -> done     # a non-empty subset of futures that have finished
    pool.result(future)                # fn's return value; raises when the worker died
    pool.close(cancel=False)           # cancel=True: stop in-flight work too (Ctrl-C)

:func:`make_pool` picks one: ``jobs == 1`` runs trials in this process, ``backend="joblib"`` in a loky
process pool (joblib's), ``backend="dask"`` on a Dask cluster — the scheduler at ``scheduler`` or a
local cluster of ``jobs`` worker processes on the loopback interface. Workers start with their thread
pools capped (:func:`optipose.batch.threads.thread_env`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Protocol

from optipose.batch.scheduler import WorkerWatch, check_scheduler
from optipose.batch.threads import Plan, plan, thread_env
from optipose.errors import ConfigError

__all__ = ["TrialPool", "SerialPool", "LokyPool", "DaskPool", "make_pool", "BACKENDS"]

log = logging.getLogger(__name__)
BACKENDS = ("joblib", "dask")
POLL_S = 2.0  # how often a Dask pool waiting for a trial counts the cluster's workers


class TrialPool(Protocol):
    workers: int
    plan: Plan

    def submit(self, fn: Callable, *args): ...

    def wait_any(self, futures) -> set: ...

    def result(self, future): ...

    def close(self, cancel: bool = False) -> None: ...


class _Done:
    """A call already made (the serial pool's future)."""

    def __init__(self, fn, args):
        self.value, self.error = None, None
        try:
            self.value = fn(*args)
        except Exception as exc:  # run_trial does not raise for a failing task; anything else is a bug to report
            self.error = exc


class SerialPool:
    """Every trial in this process, one after another (``--jobs 1``)."""

    workers = 1

    def __init__(self, trial_jobs: int | None = None):
        self.plan = plan(1, trial_jobs=trial_jobs)

    def submit(self, fn, *args):
        return _Done(fn, args)

    def wait_any(self, futures) -> set:
        return set(futures)

    def result(self, future):
        if future.error is not None:
            raise future.error
        return future.value

    def close(self, cancel: bool = False) -> None:
        pass


class LokyPool:
    """``jobs`` worker processes of joblib's loky back-end, started with capped thread pools; a pool
    whose worker died is replaced on the next submit (the study retries the trials it lost)."""

    def __init__(self, jobs: int, trial_jobs: int | None = None):
        self.workers = int(jobs)
        self.plan = plan(self.workers, trial_jobs=trial_jobs)
        self._executor = None

    def _pool(self):
        from joblib.externals.loky.process_executor import ProcessPoolExecutor

        if self._executor is None or getattr(self._executor, "_broken", False):
            log.debug("starting %d loky workers with %d thread(s) each", self.workers, self.plan.threads)
            self._executor = ProcessPoolExecutor(max_workers=self.workers, env=thread_env(self.plan.threads))
        return self._executor

    def submit(self, fn, *args):
        return self._pool().submit(fn, *args)

    def wait_any(self, futures) -> set:
        from concurrent.futures import FIRST_COMPLETED, wait

        return set(wait(list(futures), return_when=FIRST_COMPLETED).done)

    def result(self, future):
        return future.result()

    def close(self, cancel: bool = False) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=not cancel, kill_workers=cancel)
            self._executor = None


class DaskPool:
    """Trials as Dask tasks on a distributed cluster: the one at ``scheduler`` (``tcp://host:8786``), or a
    local cluster of ``jobs`` single-threaded worker processes on 127.0.0.1 when none is given. The
    address is checked first (:func:`optipose.batch.scheduler.check_scheduler`); a cluster without a
    worker is watched by a :class:`~optipose.batch.scheduler.WorkerWatch` (``no_workers``, ``after``)."""

    def __init__(
        self,
        jobs: int,
        scheduler: str | None = None,
        trial_jobs: int | None = None,
        timeout: float = 5.0,
        no_workers: str = "stop",
        after: float = 60.0,
        notify: Callable[[str], None] | None = None,
    ):
        from distributed import Client, LocalCluster

        self._cluster = None
        if scheduler:
            address = check_scheduler(scheduler)
            self._watch = WorkerWatch(address, no_workers, after, notify)
            try:
                self._client = Client(address, timeout=timeout)
            except (
                OSError,
                TimeoutError,
                TypeError,
                ValueError,
            ) as exc:  # TypeError: tls:// without Dask's TLS settings
                raise ConfigError(f"cannot reach the Dask scheduler at {address} ({_first_line(exc)})") from None
            try:
                self._wait_for_workers()
            except BaseException:
                self._client.close()
                raise
            # every worker thread runs one trial (remote workers are started with --nthreads 1: docs/batch.md, "On several machines"); as
            # many trials are kept in flight as there are worker threads now
            self.workers = sum(w["nthreads"] for w in self._client.scheduler_info()["workers"].values())
            self.plan = plan(self.workers, cores=self.workers, trial_jobs=trial_jobs)
        else:
            self.workers = int(jobs)
            self.plan = plan(self.workers, trial_jobs=trial_jobs)
            self._cluster = LocalCluster(
                n_workers=self.workers,
                threads_per_worker=1,
                processes=True,
                host="127.0.0.1",
                dashboard_address=None,
                env=thread_env(self.plan.threads),
            )
            self._client = Client(self._cluster)
            self._watch = WorkerWatch(self._client.scheduler.address, no_workers, after, notify)
        self.address = self._client.scheduler.address

    def _n_workers(self) -> int:
        return len(self._client.scheduler_info().get("workers", {}))

    def _wait_for_workers(self) -> None:
        while True:
            self._watch.check(self._n_workers())
            if self._n_workers():
                return
            time.sleep(POLL_S)

    def submit(self, fn, *args):
        return self._client.submit(fn, *args, pure=False)

    def wait_any(self, futures) -> set:
        """The futures done; every ``POLL_S`` without one, the workers are counted (NoWorkers when the
        watch says stop)."""
        from distributed import wait

        while True:
            try:
                return set(wait(list(futures), timeout=POLL_S, return_when="FIRST_COMPLETED").done)
            except TimeoutError:
                self._watch.check(self._n_workers())

    def result(self, future):
        return future.result()

    def close(self, cancel: bool = False) -> None:
        self._client.close()
        if self._cluster is not None:
            self._cluster.close()


def make_pool(
    jobs: int = 1, backend: str = "joblib", scheduler: str | None = None, trial_jobs: int | None = None, **watch
) -> TrialPool:
    """The pool for ``--jobs``, ``--backend`` and ``--scheduler`` (see the module doc); ``watch``: a Dask
    pool's ``no_workers``, ``after`` and ``notify`` (:class:`DaskPool`)."""
    if backend not in BACKENDS:
        raise ConfigError(f"unknown back-end '{backend}' (use {', '.join(BACKENDS)})")
    if scheduler and backend != "dask":
        raise ConfigError("--scheduler needs --backend dask")
    if backend == "dask":
        return DaskPool(jobs, scheduler, trial_jobs, **watch)
    return SerialPool(trial_jobs) if int(jobs) == 1 else LokyPool(jobs, trial_jobs)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
