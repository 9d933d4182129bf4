"""The live search: the one callable every NLopt run of the surrogate stages minimises.

Like optuna's ``Study`` beside its frozen trials, a :class:`SurrogateStudy` wraps a
:class:`~optipose.search.problem.SurrogateProblem` and keeps what the run has seen: every
:class:`~optipose.search.records.Evaluation` in order, the best feasible layout per k, the stage now
running, and the clock. Callbacks (``Callable[[Evaluation], None]``) follow it, e.g. a progress bar or a
flush of the history to the result folder. Time up or Ctrl-C raise :class:`Stop` out of NLopt.
"""

from __future__ import annotations

import contextlib
import time
from typing import Callable

import numpy as np

from optipose.errors import is_interrupt
from optipose.search.problem import SurrogateProblem
from optipose.search.records import EvalState, Evaluation

__all__ = ["SurrogateStudy", "Stop", "Share", "Callback"]

Callback = Callable[[Evaluation], None]


class Stop(Exception):
    """Raised inside the objective to end the whole search (time is up, or Ctrl-C)."""


class Share(Stop):
    """Raised inside the objective when a stage's share of the time budget is used up (see
    :meth:`SurrogateStudy.share`): it ends that stage, and the search goes on with the next."""


class SurrogateStudy:
    """Records and scores every layout the surrogate stages try.

    problem : what a layout scores. callbacks : called with each :class:`Evaluation` as it is recorded.
    """

    def __init__(self, problem: SurrogateProblem, callbacks: list[Callback] | tuple = ()):
        self.problem = problem
        self.history: list[Evaluation] = []
        self.callbacks = list(callbacks)
        self.interrupted = False
        self.cut: list[str] = []  # the stages a clock (the search's or a k's share of it) ended, in order
        self._best: dict[int, tuple[float, np.ndarray]] = {}
        self._deadline = np.inf
        self._share = None  # the clock's own deadline while a share of it runs
        self._stage = ""

    @property
    def stage(self) -> str:
        return self._stage

    @contextlib.contextmanager
    def stage_named(self, name: str):
        """Label the evaluations of the block with ``name`` (e.g. ``greedy:k=2``); the label stays after it."""
        self._stage = name
        yield self

    def measure_against(self, targets: dict[int, np.ndarray]) -> None:
        """From now on score layouts against these per-axis targets (k → deg): the hand layout's, once scored."""
        self.problem = self.problem.with_targets(targets)

    def start_clock(self, seconds: float) -> None:
        """From now on the search may take ``seconds``; the evaluation after that raises :class:`Stop`."""
        self._deadline = time.monotonic() + seconds

    def seconds_left(self) -> float:
        """What is left of the clock (inf before it is started)."""
        return self._deadline - time.monotonic()

    @contextlib.contextmanager
    def share(self, seconds: float):
        """Within the block the search may take ``seconds`` more (and no more than the clock's rest); the
        evaluation after that raises :class:`Share`, which ends the block's stage but not the search."""
        outer = self._deadline
        self._deadline, self._share = min(outer, time.monotonic() + seconds), outer
        try:
            yield self
        finally:
            self._deadline, self._share = outer, None

    def prefetch(self, us: np.ndarray) -> None:
        """Have the problem compute these layouts' sensors ahead, on every core, within the clock (the
        problem's ``prefetch``; nothing when it has none). Evaluating them afterwards records them as usual."""
        if not hasattr(self.problem, "prefetch"):
            return
        with self._stop_on_interrupt():
            self.problem.prefetch(us, until=self._deadline)

    @contextlib.contextmanager
    def _stop_on_interrupt(self):
        """A Ctrl-C in the block (:func:`optipose.errors.is_interrupt`) ends the search as :class:`Stop`."""
        try:
            yield
        except (KeyboardInterrupt, SystemError) as exc:
            if not is_interrupt(exc):
                raise
            self.interrupted = True
            raise Stop("interrupted") from None

    def best(self, k: int) -> tuple[float, np.ndarray] | None:
        """The best feasible value and layout of k sensors seen so far."""
        return self._best.get(k)

    def __call__(self, u: np.ndarray, grad=None) -> float:
        if time.monotonic() > self._deadline:
            stage = self._stage or "search"
            if stage not in self.cut:
                self.cut.append(stage)
            if self._share is not None and time.monotonic() <= self._share:
                raise Share("this sensor count's share of the time budget used up")
            raise Stop("time budget used up")
        with self._stop_on_interrupt():
            result = self.problem.score(np.asarray(u, dtype=float))
        k, value = len(u) // 6, result.objective
        if result.feasible and value < self._best.get(k, (np.inf,))[0]:
            self._best[k] = (value, np.array(u, dtype=float))
        record = Evaluation(
            number=len(self.history),
            stage=self._stage,
            k=k,
            u=tuple(np.round(np.asarray(u, float), 9).tolist()),
            state=result.state,
            value=value,
            best=self._best.get(k, (np.nan,))[0],
            constraint=result.constraint if result.state is EvalState.INFEASIBLE else "",
        )
        self.history.append(record)
        for callback in self.callbacks:
            callback(record)
        return float(value)
