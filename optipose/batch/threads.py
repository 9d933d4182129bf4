"""How a study shares the cores: the one place that decides a trial's own jobs and its threads.

A study runs ``workers`` trials at once. Each trial may itself scan with threads (Embree ray casting,
``OPTIPOSE_RAY_THREADS``), run compiled kernels (numba), BLAS (numpy, scipy), OpenMP (Open3D) and an
evaluator process pool (its ``jobs``). Left alone, every one of them takes every core, and ``workers``
trials on C cores run ``workers × C`` threads of each kind. :func:`plan` splits the cores instead:
each trial gets ``cores // workers`` (at least 1) for its threads and its evaluator's jobs.

The caps reach a worker in two ways: as environment variables given to its process when it starts
(:func:`optipose.parallel.executors.thread_env`; BLAS and OpenMP read them only when they load), and in
the trial itself (:func:`cap_threads`: the ray threads and numba, which read theirs at use).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from optipose.parallel.executors import THREAD_VARIABLES, thread_env

__all__ = ["Plan", "plan", "usable_cores", "thread_env", "cap_threads", "current_caps", "THREAD_VARIABLES"]


@dataclass(frozen=True)
class Plan:
    """workers : trials at once; trial_jobs : each trial's evaluator processes; threads : each trial's
    threads of every kind (see the module doc)."""

    workers: int
    trial_jobs: int
    threads: int


def usable_cores() -> int:
    """The cores this process may run on (its affinity, which a batch system sets), at least 1."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return max(1, os.cpu_count() or 1)


def plan(workers: int, cores: int | None = None, trial_jobs: int | None = None) -> Plan:
    """Split ``cores`` (default: this machine's) between ``workers`` trials at once. ``trial_jobs``
    overrides each trial's share (the benchmark pins it to 1 to measure the back-ends alone).

    On a remote Dask cluster the client does not know the workers' cores: it passes ``cores=workers``
    (each worker thread one core, as ``dask worker --nthreads 1`` starts them)."""
    workers = max(1, int(workers))
    share = max(1, (cores or usable_cores()) // workers)
    if trial_jobs is not None:
        share = max(1, int(trial_jobs))
    return Plan(workers, share, share)


def current_caps() -> dict[str, str | None]:
    """This process's thread caps (what a worker started with; tests ask its workers)."""
    return {name: os.environ.get(name) for name in THREAD_VARIABLES}


def cap_threads(threads: int) -> None:
    """Cap this process's thread pools that read their size at use (run at the start of each trial)."""
    os.environ.update(thread_env(threads))
    try:
        import numba

        numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    except (ImportError, ValueError):  # no numba, or its pool was sized smaller when it loaded
        pass
