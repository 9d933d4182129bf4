"""One trial, as a worker runs it: the task, its result folder written whole or not at all.

:func:`run_trial` is what every back-end ships to its workers (it and its arguments pickle). It writes
the task's result folder under ``<study>/trials/.tmp-<key>-<random>/`` and renames it to
``<study>/trials/<key>/`` only when the task has finished, with ``trial.toml`` (parameters, timings,
worker) inside: a folder named after a trial is a complete trial, whatever happened to the client. A
task that raises gives a failed record (its error in one line) and leaves no folder; the worker goes
on with the next trial.

Results land on the file system the workers write to: a study on several machines needs its folder
on a file system they share with the client (docs/batch.md, "On several machines").
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import time
import traceback
import uuid
from dataclasses import replace
from datetime import datetime, timezone
from pathlib import Path

from optipose.batch.records import TrialRecord, TrialState
from optipose.batch.spec import TrialSpec
from optipose.batch.threads import Plan, cap_threads
from optipose.errors import ConfigError, interrupted, is_interrupt
from optipose.files import write_text

__all__ = ["run_trial", "TRIAL_FILE", "TMP_PREFIX", "now", "TASK_RUNNERS"]

log = logging.getLogger(__name__)
TRIAL_FILE = "trial.toml"
TMP_PREFIX = ".tmp-"


def now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def run_trial(trial: TrialSpec, study_dir: str, plan: Plan) -> TrialRecord:
    """Run ``trial``'s task into ``<study_dir>/trials/<key>/``; a record complete (without results: the
    client reads them back from the folder) or failed. Never raises for a failing task."""
    cap_threads(plan.threads)
    trials = Path(study_dir) / "trials"
    final = trials / trial.key
    tmp = trials / f"{TMP_PREFIX}{trial.key}-{uuid.uuid4().hex[:8]}"
    started, t0, c0 = now(), time.perf_counter(), time.process_time()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    record = TrialRecord(trial, TrialState.RUNNING, started=started, worker=worker)
    try:
        tmp.mkdir(parents=True)
        TASK_RUNNERS[trial.task](trial, tmp, plan.trial_jobs)
        if interrupted():  # a Ctrl-C that something in the task caught and went past: its result is not sure
            raise KeyboardInterrupt
        seconds = time.perf_counter() - t0
        done = TrialRecord(
            trial,
            TrialState.COMPLETE,
            started=started,
            finished=now(),
            seconds=seconds,
            cpu_seconds=time.process_time() - c0,
            worker=worker,
            folder=f"trials/{trial.key}",
        )
        _write_trial_file(tmp, done, plan)
        if final.exists():  # a folder that lost its trial.toml: never a complete trial
            shutil.rmtree(final)
        os.rename(tmp, final)
        return done
    except Exception as exc:  # a failing trial is recorded and the study goes on
        shutil.rmtree(tmp, ignore_errors=True)
        if (
            is_interrupt(exc) or interrupted()
        ):  # Ctrl-C while compiled code ran (numba raises it as a SystemError): the study stops
            raise KeyboardInterrupt from exc
        log.debug("trial %s failed:\n%s", trial.key, traceback.format_exc())
        return replace(
            record.failed(error_line(exc), now()),
            seconds=time.perf_counter() - t0,
            cpu_seconds=time.process_time() - c0,
        )
    except BaseException:  # Ctrl-C in a serial study: nothing half-written stays behind
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def error_line(exc: BaseException) -> str:
    """``Type: first line of the message`` (the index holds one line per failed trial)."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


def _write_trial_file(folder: Path, record: TrialRecord, plan: Plan) -> None:
    import tomli_w

    table = {
        "trial": record.trial.params(),
        "key": record.key,
        "started": record.started,
        "finished": record.finished,
        "seconds": record.seconds,
        "cpu_seconds": record.cpu_seconds,
        "worker": record.worker,
        "plan": plan.__dict__,
    }
    write_text(folder / TRIAL_FILE, tomli_w.dumps(table))


def _hand(part):
    if "hand" not in part.layouts:
        raise ConfigError(f"part '{part.name}' has no hand-placed layout to evaluate")
    return part.layouts["hand"]


def _check_k(trial: TrialSpec, layout) -> None:
    if trial.sensors > len(layout):
        raise ConfigError(f"k = {trial.sensors}, but the hand-placed layout has {len(layout)} sensors")


def _evaluate(trial: TrialSpec, folder: Path, jobs: int) -> None:
    from optipose.evaluate.evaluator import Evaluator
    from optipose.evaluate.objective import load_objective
    from optipose.io.evaluation import write_evaluation
    from optipose.model.part import load_part

    part = load_part(trial.part)
    layout = _hand(part)
    _check_k(trial, layout)
    with Evaluator(part, load_objective(trial.objective), seed=trial.seed, jobs=jobs, quiet=True) as evaluator:
        result = evaluator(layout)
    write_evaluation(result, folder, part_source=trial.part, layout_source="part:hand")


def _search(trial: TrialSpec, folder: Path, jobs: int) -> None:
    from optipose.evaluate.objective import load_objective
    from optipose.io.search import SearchFolder
    from optipose.model.part import load_part
    from optipose.search.budgets import config_from_budget
    from optipose.search.pipeline import run

    part = load_part(trial.part)
    objective = load_objective(trial.objective)
    config = config_from_budget(trial.budget, (trial.sensors,), cell=not objective.cell.ideal)
    report = run(part, objective, config, trial.seed, SearchFolder(folder), trial.budget, jobs)
    if report.outcome.interrupted:  # the search kept a Ctrl-C to itself: the study stops
        raise KeyboardInterrupt
    if not report.validated:
        raise RuntimeError("the search ended before its validation")


TASK_RUNNERS = {"search": _search, "evaluate": _evaluate}
