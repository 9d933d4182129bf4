"""A batch study as it runs: trials handed to a pool, each finished trial recorded the moment it ends.

:func:`run_study` keeps ``pool.workers`` trials in flight; a trial is ``running`` in the index while a
worker has it, then ``complete`` (its results read back from its folder) or ``failed`` (its error), and
the study goes on. A worker that dies costs its trial one retry; a second death marks it failed. On
Ctrl-C the trials in flight go back to ``pending`` and the index is written before the interrupt goes
on, so the folder stays consistent and ``--resume`` runs exactly what is missing; so too when a Dask
cluster has had no worker for longer than the user allows (:class:`optipose.batch.scheduler.NoWorkers`).
A study that ends removes the temporary folders its dead workers left.

The study folder::

    study.toml            the study file as given
    config.toml           command "batch", the back-end, the plan of cores, versions
    index.parquet         one row per trial (index.csv beside it): records.TrialRecord.row()
    trials/<key>/         each complete trial's result folder (+ trial.toml)
"""

from __future__ import annotations

import logging
import shutil
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from optipose.batch.index import INDEX_FILE, StudyIndex
from optipose.batch.records import TrialRecord, TrialState
from optipose.batch.results import trial_results
from optipose.batch.spec import StudySpec
from optipose.batch.trial import TMP_PREFIX, error_line, now, run_trial
from optipose.errors import ConfigError, WorkerError, interrupted
from optipose.files import write_text

__all__ = ["run_study", "prepare_folder", "remove_leftovers", "MAX_RETRIES"]

log = logging.getLogger(__name__)
MAX_RETRIES = 1  # re-runs of a trial whose worker died


def prepare_folder(folder: Path, resume: bool) -> None:
    """Refuse to start a new study over an old one (and to resume where there is none)."""
    has_index = (Path(folder) / INDEX_FILE).is_file()
    if has_index and not resume:
        raise ConfigError(f"{folder} holds a study already: continue it with --resume, or give another --out")
    if resume and not has_index and Path(folder).exists() and any(Path(folder).iterdir()):
        raise ConfigError(f"--resume {folder}: not an optipose study folder (no {INDEX_FILE})")


def run_study(
    spec: StudySpec,
    folder: Path,
    pool,
    resume: bool = False,
    on_record: Callable[[TrialRecord], None] | None = None,
    config: dict | None = None,
) -> StudyIndex:
    """Run every trial of ``spec`` that is not complete in ``folder`` on ``pool``; returns the index.

    on_record(record) is called for every trial that ends (complete or failed)."""
    folder = Path(folder)
    prepare_folder(folder, resume)
    (folder / "trials").mkdir(parents=True, exist_ok=True)
    _write_header(folder, spec, pool, config or {})
    index = StudyIndex.open(folder, spec.trials, resume)
    index.write()
    todo = [t for t in spec.trials if index[t.key].state != TrialState.COMPLETE]
    log.info("%s: %d of %d trials to run on %d worker(s)", spec.name, len(todo), len(spec.trials), pool.workers)
    queue, in_flight, retries = list(reversed(todo)), {}, {}
    try:
        _fill(queue, in_flight, index, pool, folder)
        while in_flight:
            for future in pool.wait_any(in_flight):
                trial = in_flight.pop(future)
                record = _finished(pool, future, index[trial.key], folder, retries)
                if record is None:  # its worker died: once more
                    queue.append(trial)
                    index.set(TrialRecord(trial))
                else:
                    index.set(record)
                    if on_record:
                        on_record(record)
                index.write()
                if interrupted():  # a Ctrl-C a trial caught and went past (optipose.errors.note_interrupts)
                    raise KeyboardInterrupt
            _fill(queue, in_flight, index, pool, folder)
    except (KeyboardInterrupt, WorkerError):  # Ctrl-C, or a cluster without workers the user would not wait for
        for record in list(index.records.values()):  # in flight, or handed to a serial pool when it came
            if record.state == TrialState.RUNNING:
                index.set(TrialRecord(record.trial))
        index.write()
        pool.close(cancel=True)
        raise
    remove_leftovers(folder)
    return index


def remove_leftovers(folder: Path) -> None:
    """The temporary folders of trials whose worker died (``trials/.tmp-*``): once no trial is in flight,
    nothing will rename them, and the trial ran again elsewhere."""
    for tmp in (Path(folder) / "trials").glob(f"{TMP_PREFIX}*"):
        shutil.rmtree(tmp, ignore_errors=True)


def _fill(queue: list, in_flight: dict, index: StudyIndex, pool, folder: Path) -> None:
    """Hand trials to the pool until it has ``workers`` of them; each is ``running`` in the index first."""
    while queue and len(in_flight) < pool.workers:
        trial = queue.pop()
        index.set(index[trial.key].running(now()))
        index.write()
        in_flight[pool.submit(run_trial, trial, str(folder), pool.plan)] = trial


def _finished(pool, future, running: TrialRecord, folder: Path, retries: dict) -> TrialRecord | None:
    """The record of a trial that ended: complete with its results, failed, or None to run it again."""
    try:
        record = pool.result(future)
    except Exception as exc:  # the worker died (or the pool broke) under this trial
        n = retries.get(running.key, 0)
        if n < MAX_RETRIES:
            retries[running.key] = n + 1
            log.warning("trial %s: its worker died (%s); running it again", running.key, error_line(exc))
            return None
        return running.failed(f"worker died: {error_line(exc)}", now())
    if record.state != TrialState.COMPLETE:
        return record
    try:
        return replace(record, results=trial_results(folder / record.folder, record.trial))
    except Exception as exc:  # e.g. the workers wrote to a file system the client does not see
        return record.failed(f"its folder cannot be read back here: {error_line(exc)}", now())


def _write_header(folder: Path, spec: StudySpec, pool, config: dict) -> None:
    """``study.toml`` (the file as given) and ``config.toml`` (how it ran), replaced on every (re)start."""
    from optipose.io.folders import versions, write_config

    if spec.text:
        write_text(folder / "study.toml", spec.text)
    write_config(
        folder,
        {
            "command": "batch",
            "study": {
                "name": spec.name,
                "source": spec.source,
                "description": spec.description,
                "trials": len(spec.trials),
            },
            "pool": {"kind": type(pool).__name__, "workers": pool.workers, "address": getattr(pool, "address", None)},
            "plan": pool.plan.__dict__,
            **config,
            "versions": versions(),
        },
    )
