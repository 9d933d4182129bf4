"""Progress of long work that runs in stages: a rich bar on a terminal, plain whole lines otherwise.

A search runs stage after stage (``screen:k=1``, ``greedy:k=1``, … then its ICP stages), each with its own
number of evaluations; a study runs its trials. :class:`StageProgress` shows the stage now running with
that stage's own count: against its total when the total is known beforehand (an upper bound, such as a
stage's evaluation budget, which the clock may cut short), as a bare count otherwise, never as ``N/M``
with N past M. When its console is not a terminal (a pipe, a log file, a CI job) there is no live bar,
whose last frame would be cut to the console's width: it prints one whole line when a stage starts, one
when it ends, and one every ``every`` seconds in between, also while a stage counts nothing (the search's
ICP stages), so that a log shows the work is still going (:func:`plain_line`).
"""

from __future__ import annotations

import threading
import time
from typing import Callable

__all__ = ["StageProgress", "status", "make_console", "plain_line", "count_text"]


def count_text(done: int, total: int | None, unit: str) -> str:
    """``1200/4096 evaluations`` against a known total, ``1200 evaluations`` without one or once past it;
    empty before anything is counted in a stage without a total."""
    if total is not None and done <= total:
        return f"{done}/{total} {unit}"
    return f"{done} {unit}" if done else ""


def plain_line(title: str, stage: str, count: str = "", detail: str = "", seconds: float | None = None) -> str:
    """One whole log line: ``part_b: screen:k=2 1200/4096 evaluations, best k=2 0.780 mdeg, 41 s``."""
    head = " ".join(p for p in (f"{title}: {stage}" if stage else title, count) if p)
    return ", ".join(p for p in (head, detail, f"{seconds:.0f} s" if seconds is not None else "") if p)


class StageProgress:
    """Shows work in stages on ``console`` (a context manager).

    title : what runs (a part's name, a study's); unit : what a stage counts (evaluations, trials);
    every : seconds between two progress lines when the console is not a terminal; each : a line for each
    unit done too (a study's trials, which are few and slow); clock : for tests.
    """

    def __init__(
        self,
        console,
        title: str,
        unit: str,
        every: float = 10.0,
        each: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.console, self.title, self.unit, self.every, self.each, self.clock = (
            console,
            title,
            unit,
            every,
            each,
            clock,
        )
        self.live = console.is_terminal
        self.name, self.total, self.done, self.detail = "", None, 0, ""
        self._started = self._printed = clock()
        self._bar = self._task = None
        self._lock = threading.RLock()  # the plain lines come from the work's thread and from the heartbeat
        self._stop = threading.Event()
        self._heartbeat = None

    def __enter__(self) -> StageProgress:
        if self.live:
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            columns = [
                TextColumn("{task.description}"),
                BarColumn(),
                TextColumn("{task.fields[count]}"),
                TextColumn("{task.fields[detail]}"),
                TimeElapsedColumn(),
            ]
            self._bar = Progress(*columns, console=self.console)
            self._bar.__enter__()
            self._task = self._bar.add_task(self.title, total=None, count="", detail="")
        else:
            self._heartbeat = threading.Thread(target=self._beat, name="progress-lines", daemon=True)
            self._heartbeat.start()
        return self

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)
            return
        self._stop.set()
        self._heartbeat.join()
        if exc[0] is None:
            with self._lock:
                self._end_stage()

    def _beat(self) -> None:
        """A line every ``every`` seconds in which nothing else printed one (a stage without units to count)."""
        while not self._stop.wait(max(self.every, 0.1)):
            with self._lock:
                if self.name and self.clock() - self._printed >= self.every:
                    self._line(count=self._count())

    def stage(self, name: str, total: int | None = None, detail: str | None = None) -> None:
        """A new stage begins: ``total`` of its units at most (None: not known beforehand, or it counts none)."""
        with self._lock:
            self._end_stage()
            self.name, self.total, self.done = name, total, 0
            self.detail = self.detail if detail is None else detail
            if self._bar is not None:
                self._bar.reset(
                    self._task,
                    completed=0,
                    description=f"{self.title}: {name}",
                    count=self._count(),
                    detail=self.detail,
                )
                self._set_total(total)
            else:
                self._line(count=self._count() if total else "")

    def advance(self, n: int = 1, detail: str | None = None) -> None:
        """``n`` more units of the stage done; ``detail`` (e.g. the best score so far) replaces the last."""
        with self._lock:
            self.done += n
            if detail is not None:
                self.detail = detail
            if self.total is not None and self.done > self.total:  # past its bound: a count, no longer a fraction
                self.total = None
                if self._bar is not None:
                    self._set_total(None)
            if self._bar is not None:
                self._bar.update(self._task, completed=self.done, count=self._count(), detail=self.detail)
            elif self.each or self.clock() - self._printed >= self.every:
                self._line(count=self._count())

    def _set_total(self, total: int | None) -> None:
        """The bar's total; None makes it indeterminate (rich's update and reset read None as "unchanged")."""
        for task in self._bar.tasks:
            if task.id == self._task:
                task.total = total

    def _count(self) -> str:
        return count_text(self.done, self.total, self.unit)

    def _end_stage(self) -> None:
        """The plain line that closes a stage which counted something."""
        if self._bar is None and self.name and self.done:
            self._line(count=f"done, {self.done} {self.unit}")

    def _line(self, count: str) -> None:
        now = self.clock()
        line = plain_line(self.title, self.name, count, self.detail, now - self._started)
        # soft_wrap: the line stays whole whatever the console's width; markup off: a stage's [..] stays text
        self.console.print(line, soft_wrap=True, markup=False, highlight=False)
        self._printed = now


class status:  # noqa: N801 - used as `with status(console, text):`, like rich's console.status
    """``console.status(text)`` on a terminal (a spinner); elsewhere, where a spinner shows nothing, a
    plain line when the work starts and one with its seconds when it ends."""

    def __init__(self, console, text: str, clock: Callable[[], float] = time.monotonic):
        self.console, self.text, self.clock = console, text, clock
        self._spinner = console.status(text) if console.is_terminal else None

    def __enter__(self) -> status:
        if self._spinner is not None:
            self._spinner.__enter__()
        else:
            self._started = self.clock()
            self.console.print(self.text, soft_wrap=True, markup=False, highlight=False)
        return self

    def __exit__(self, *exc) -> None:
        if self._spinner is not None:
            self._spinner.__exit__(*exc)
        elif exc[0] is None:
            line = plain_line(self.text, "", "done", "", self.clock() - self._started)
            self.console.print(line, soft_wrap=True, markup=False, highlight=False)


def make_console(stderr: bool = False):
    """A rich console; when it is not a terminal its long lines stay whole (no wrapping at 80 columns in
    a pipe or a log), while its tables keep the width they would have there."""
    from rich.console import Console

    console = Console(stderr=stderr)
    console.soft_wrap = not console.is_terminal
    return console
