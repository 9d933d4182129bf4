"""A trial's frozen record and its state, as the study index holds them (one row per trial).

Like optuna's ``FrozenTrial`` / ``TrialState``: the live study (:mod:`optipose.batch.study`) makes a new
record at every change of state and never edits one; :meth:`TrialRecord.row` is the index's row.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace

from optipose.batch.spec import TrialSpec

__all__ = ["TrialState", "TrialRecord"]


class TrialState(str, enum.Enum):
    PENDING = "pending"
    RUNNING = "running"
    COMPLETE = "complete"
    FAILED = "failed"


@dataclass(frozen=True)
class TrialRecord:
    """One trial: its parameters, state, error (failed only), timings and per-axis results.

    started, finished : UTC times, ISO 8601 (empty while unknown); seconds : wall time in the worker;
    cpu_seconds : CPU time of the worker process over the trial (all its threads; not its child processes);
    worker : ``host:pid`` that ran it; folder : its result folder relative to the study folder (complete
    only); results : the per-axis columns of :func:`optipose.batch.results.trial_results`.
    """

    trial: TrialSpec
    state: TrialState = TrialState.PENDING
    error: str = ""
    started: str = ""
    finished: str = ""
    seconds: float = float("nan")
    cpu_seconds: float = float("nan")
    worker: str = ""
    folder: str = ""
    results: dict = field(default_factory=dict, compare=False)

    @property
    def key(self) -> str:
        return self.trial.key

    def running(self, started: str) -> "TrialRecord":
        return replace(self, state=TrialState.RUNNING, error="", started=started, finished="", results={})

    def failed(self, error: str, finished: str) -> "TrialRecord":
        return replace(self, state=TrialState.FAILED, error=error, finished=finished, folder="", results={})

    def row(self) -> dict:
        """The index's row: key, parameters, state and timings, then the results' columns."""
        return {
            "key": self.key,
            **self.trial.params(),
            "state": self.state.value,
            "error": self.error,
            "started": self.started,
            "finished": self.finished,
            "seconds": self.seconds,
            "cpu_seconds": self.cpu_seconds,
            "worker": self.worker,
            "folder": self.folder,
            **self.results,
        }
