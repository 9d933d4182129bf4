"""Per-axis configuration assignment: the paper's Table 1 (docs/method.md, "The assignment: the paper's Table 1").

For a layout of n sensors every non-empty subset (2ⁿ − 1) has per-axis statistics. Within a choice C of
k sensors, each axis takes the subset of C with the lowest median (ties: lowest 75th percentile); a
subset is not eligible for an axis it cannot observe or when more than ``MAX_FAILED_FRACTION`` of its
registrations failed (the failures below that share are in its median and p75, each as a 10° error:
:mod:`optipose.evaluate.statistics`). The k-sensor result is the choice C with the lowest score
``Σ_axis weight · (median_weight · median + p75_weight · p75)``; an axis no subset of C can measure
costs ``UNOBSERVABLE_PENALTY`` instead, and says why (:attr:`AxisChoice.reason`): no subset observes it
(``unobservable``), or some would but their registrations failed too often (``registrations failed``).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
import pandas as pd

from optipose.evaluate.objective import AXES, StatisticConfig
from optipose.evaluate.statistics import FAILED_ERROR

__all__ = [
    "all_subsets",
    "subset_name",
    "AxisChoice",
    "Choice",
    "best_choices",
    "choose",
    "choice_of",
    "stats_by_key",
    "MAX_FAILED_FRACTION",
    "UNOBSERVABLE_PENALTY",
    "UNOBSERVABLE",
    "FAILED",
    "not_measured",
]

MAX_FAILED_FRACTION = 0.1
UNOBSERVABLE_PENALTY = FAILED_ERROR  # rad per axis (10°): worse than any measurable error under ±2° protocols
UNOBSERVABLE = "unobservable"  # why an axis has no subset: none of the choice's subsets can observe it
FAILED = "registrations failed"  # some could, but each failed in over MAX_FAILED_FRACTION of the scans


def not_measured(interval) -> bool:
    """A predicted error's interval (degrees) at the penalty throughout: an unobservable axis, or failed
    registrations, in every draw; no error was measured."""
    return interval.low >= np.degrees(UNOBSERVABLE_PENALTY) * (1.0 - 1e-9)


def all_subsets(n: int) -> list[tuple[int, ...]]:
    """Every non-empty subset of range(n), by size then lexicographically: (0,), (1,), ..., (0, 1, 2)."""
    return [c for k in range(1, n + 1) for c in combinations(range(n), k)]


def subset_name(subset: tuple[int, ...], names: list[str]) -> str:
    """'S1S2S3' from sensor indices and names."""
    return "".join(names[i] for i in subset)


@dataclass(frozen=True)
class AxisChoice:
    """One axis of a choice: the subset of the layout's sensors used for it and its statistics.

    subset : sensor indices in the layout, () when no subset of the choice can measure the axis.
    name : the subset for display, e.g. "S1S2" ("" when none).
    median, p75 : rad (NaN when none).
    reason : when there is no subset, why: ``UNOBSERVABLE`` or ``FAILED``; "" otherwise.
    """

    axis: str
    subset: tuple[int, ...]
    name: str
    median: float
    p75: float
    reason: str = ""

    @property
    def observable(self) -> bool:
        """Measured: some subset of the choice observes the axis and registered reliably."""
        return bool(self.subset)

    @property
    def label(self) -> str:
        """The subset's name, or why there is none (``unobservable``, ``registrations failed``)."""
        return self.name if self.subset else (self.reason or UNOBSERVABLE)


@dataclass(frozen=True)
class Choice:
    """The best k sensors and, per axis, the subset of them to use.

    sensors : the k sensor indices in the layout; name : them for display, e.g. "S1S3"; score : rad.
    """

    k: int
    sensors: tuple[int, ...]
    name: str
    axes: tuple[AxisChoice, ...]
    score: float

    @property
    def used(self) -> tuple[int, ...]:
        """The sensor indices its axes use, ascending (an axis no subset measures uses none)."""
        return tuple(sorted({i for a in self.axes for i in a.subset}))

    def __repr__(self) -> str:
        cells = ", ".join(
            f"{a.axis}={np.rad2deg(a.median):.4f}/{np.rad2deg(a.p75):.4f} deg ({a.name})"
            if a.observable
            else f"{a.axis}={a.label}"
            for a in self.axes
        )
        return f"Choice(k={self.k}, {self.name}: {cells})"


def best_choices(
    stats: pd.DataFrame, names: list[str], cfg: StatisticConfig, n_scans: int, evaluated=None
) -> list[Choice]:
    """The best choice for k = 1 … n sensors (Table 1), from :func:`optipose.evaluate.statistics.summarize` output;
    ``evaluated``: the subset names the evaluation registered (:func:`choose`; default every one)."""
    by_key = stats_by_key(stats)
    out = []
    for k in range(1, len(names) + 1):
        candidates = [choose(c, names, by_key, cfg, n_scans, evaluated) for c in combinations(range(len(names)), k)]
        out.append(min(candidates, key=lambda ch: ch.score))  # first of equals: lowest sensor indices
    return out


def stats_by_key(stats: pd.DataFrame) -> dict:
    """The rows of a statistics table by (subset name, axis)."""
    return {(r.subset, r.axis): r for r in stats.itertuples(index=False)}


def choose(
    sensors: tuple[int, ...], names: list[str], by_key: dict, cfg: StatisticConfig, n_scans: int, evaluated=None
) -> Choice:
    """The choice of exactly these ``sensors`` (indices): each axis takes its best eligible subset of them.

    by_key : :func:`stats_by_key` of the layout's statistics (a KeyError where one is missing); n_scans : scans
    per subset in the protocol; evaluated : the subset names the evaluation registered (default every one): the
    choice is among those, and each of them needs its statistics.
    """
    subsets = [s for k in range(1, len(sensors) + 1) for s in combinations(sensors, k)]
    if evaluated is not None:
        subsets = [s for s in subsets if subset_name(s, names) in evaluated]
    axes, score = [], 0.0
    for axis, weight in zip(AXES, cfg.weights):
        rows = [(s, by_key[(subset_name(s, names), axis)]) for s in subsets]
        eligible = [(s, r) for s, r in rows if _eligible(r, n_scans)]
        if not eligible:
            seen = any(not r.unobservable for _, r in rows)  # observable, but its registrations failed too often
            axes.append(AxisChoice(axis, (), "", float("nan"), float("nan"), FAILED if seen else UNOBSERVABLE))
            score += weight * UNOBSERVABLE_PENALTY * (cfg.median_weight + cfg.p75_weight)
            continue
        s, best = min(eligible, key=lambda t: (t[1].median, t[1].p75))  # stable: the smaller subset wins a full tie
        axes.append(AxisChoice(axis, tuple(s), best.subset, best.median, best.p75))
        score += weight * (cfg.median_weight * best.median + cfg.p75_weight * best.p75)
    return Choice(len(sensors), tuple(sensors), subset_name(sensors, names), tuple(axes), float(score))


def choice_of(result, sensors: tuple[int, ...]) -> Choice:
    """The choice of exactly these sensors of an evaluated layout (an ``EvaluationResult``: each axis its best
    subset of them). The sensors are a set: in any order (a found pair can sit inside the found triple in another
    order)."""
    sensors = tuple(sorted(sensors))
    by_key = stats_by_key(result.stats)
    return choose(sensors, result.layout.names, by_key, result.objective.statistic, result.n_scans)


def _eligible(row, n_scans: int) -> bool:
    return (not row.unobservable) and np.isfinite(row.median) and row.n_failed <= MAX_FAILED_FRACTION * max(n_scans, 1)
