"""A layout against a reference (the hand-placed one): the one place that says "no worse on every axis".

The user's question is whether to keep the sensors they have or buy the found ones. A found choice of k
sensors wins outright when every axis's median and 75th percentile is at most the reference's; how far
it misses is the summed excess. The search ranks and polishes with these, the CLI prints a
:class:`Verdict` per k, and :func:`optipose.io.load_result` gives a saved search's verdicts back;
:mod:`optipose.verdict.words` says them in lines (:func:`~optipose.verdict.words.verdict_line`).

An axis a choice does not measure (unobservable, or its registrations failed) compares as the score's
``UNOBSERVABLE_PENALTY`` (10°) on both statistics: worse than any measured error, equal to another
unmeasured one; :func:`optipose.verdict.words.unmeasured_line` says so in words, so a layout that cannot see
an axis is never read as a small error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optipose.evaluate.assignment import FAILED, UNOBSERVABLE_PENALTY, AxisChoice, Choice

__all__ = ["dominates", "excess", "rank", "weighted_excess", "AxisGap", "Verdict", "bought"]

_STATISTICS = ("median", "p75")


def _stat(axis: AxisChoice, statistic: str) -> float:
    """An axis's median or p75 (rad) as compared: ``UNOBSERVABLE_PENALTY`` where the choice does not measure it."""
    return getattr(axis, statistic) if axis.observable else UNOBSERVABLE_PENALTY


def dominates(choice: Choice, reference: Choice) -> bool:
    """Every axis's median and 75th percentile at most the reference's."""
    return all(_stat(a, s) <= _stat(b, s) for a, b in zip(choice.axes, reference.axes) for s in _STATISTICS)


def excess(choice: Choice, reference: Choice, margin: float = 1.0) -> float:
    """How far (rad, summed) the choice's per-axis medians and 75th percentiles exceed margin × the
    reference's."""
    return float(
        sum(
            max(0.0, _stat(a, s) - margin * _stat(b, s))
            for a, b in zip(choice.axes, reference.axes)
            for s in _STATISTICS
        )
    )


def rank(choice: Choice, reference: Choice | None) -> tuple[bool, float]:
    """Sort key of a choice against the reference: those no worse on every axis first, then the lower
    score (no reference: every choice counts as no worse)."""
    return (reference is not None and not dominates(choice, reference), choice.score)


def weighted_excess(values: np.ndarray, target: np.ndarray, margin: float, weights) -> float:
    """Σ weightᵢ · max(0, valueᵢ − margin · targetᵢ) over axes: the surrogate's per-axis scores (3,)
    against the reference's, in their unit."""
    return float(np.dot(weights, np.clip(np.asarray(values) - margin * np.asarray(target), 0.0, None)))


@dataclass(frozen=True)
class AxisGap:
    """An axis statistic on which the found choice is worse than the reference (rad)."""

    axis: str
    statistic: str  # median | p75
    found: float
    reference: float


@dataclass(frozen=True)
class Verdict:
    """Found vs. the reference for one k: the ratio in sum, the axes where found is worse; :func:`bought` says
    what to do."""

    k: int
    found: Choice
    reference: Choice
    layout: str = ""  # the found layout's name where several are compared (a robustness run), else ""

    @property
    def ratio(self) -> float:
        """Reference score over found score: above 1, the found choice is better in sum."""
        return float(np.rad2deg(self.reference.score)) / float(np.rad2deg(self.found.score))

    @property
    def worse(self) -> tuple[AxisGap, ...]:
        """Every axis statistic on which the found choice is worse (what :func:`dominates` tests)."""
        return tuple(
            AxisGap(f.axis, stat, _stat(f, stat), _stat(r, stat))
            for f, r in zip(self.found.axes, self.reference.axes)
            for stat in _STATISTICS
            if _stat(f, stat) > _stat(r, stat)
        )

    @property
    def no_worse(self) -> bool:
        """No axis statistic worse than the reference's: replacing the reference loses nothing."""
        return dominates(self.found, self.reference)

    @property
    def tie(self) -> bool:
        """Every axis statistic equal to the reference's: replacing it gains nothing, as
        when the choice measures every axis on hand sensors a found layout keeps in their places."""
        return self.no_worse and dominates(self.reference, self.found)

    @property
    def failed(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The axes of the found and of the reference choice whose registrations failed too often
        (``AxisChoice.reason`` ``FAILED``): there the comparison is of two unknowns, not of errors."""
        return tuple(tuple(a.axis for a in c.axes if a.reason == FAILED) for c in (self.found, self.reference))


def bought(verdict: Verdict) -> bool:
    """Whether to buy the found layout of ``verdict``: no worse than the reference on every axis and better on
    some (a tie gains nothing); never when the found choice's registrations failed on some axis."""
    return verdict.no_worse and not verdict.tie and not verdict.failed[0]
