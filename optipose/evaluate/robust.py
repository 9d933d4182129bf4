"""A layout under every condition of its objective's band, and the robust statistic over them.

:func:`evaluate_robust` evaluates a layout once per :class:`~optipose.evaluate.conditions.Condition` (the
same protocol and noise seed each time: only the condition differs) and aggregates, per sensor subset and
axis, each statistic over the conditions with the objective's ``aggregate`` (the worst by default). The
robust Table 1 is the paper's assignment on those aggregated statistics: a subset is chosen for an axis
because it is good at every noise level and bracket draw, not at the nominal one alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

from optipose.evaluate.assignment import Choice, best_choices, restated, stats_by_key
from optipose.evaluate.conditions import Condition, aggregate, conditions
from optipose.evaluate.evaluator import EvaluationResult, Evaluator

__all__ = ["RobustResult", "evaluate_robust", "robust_stats"]


@dataclass
class RobustResult:
    """A layout's evaluations under each condition, and the aggregated statistics and Table 1."""

    results: list[tuple[Condition, EvaluationResult]] = field(repr=False)
    stats: pd.DataFrame = field(repr=False)
    table: list[Choice] = field(repr=False)

    @property
    def layout(self):
        return self.results[0][1].layout

    def under(self, choice: Choice) -> list[tuple[Condition, Choice]]:
        """``choice`` (its sensors and each axis's subset, as one deployed cell fixes them) under each
        condition: with the worst aggregate, the robust statistic is the largest of these."""
        return [(c, restated(choice, stats_by_key(r.stats), r.objective.statistic)) for c, r in self.results]


def evaluate_robust(part, layout, objective, seed: int = 0, jobs: int = 1, quiet: bool = False) -> RobustResult:
    """Evaluate ``layout`` under every condition of ``objective.conditions`` (see the module doc); one pool
    of workers serves every condition."""
    from optipose.evaluate.executors import make_executor

    executor, results = make_executor(jobs), []
    try:
        for condition in conditions(objective.conditions):
            with Evaluator(part, objective, seed=seed, quiet=quiet, executor=executor, condition=condition) as evaluator:
                results.append((condition, evaluator(layout)))
    finally:
        executor.close()
    stats = robust_stats([r.stats for _, r in results], objective.conditions.aggregate)
    n_scans = results[0][1].per_scan["scan"].nunique()
    return RobustResult(results, stats, best_choices(stats, layout.names, objective.statistic, n_scans))


def robust_stats(frames: list[pd.DataFrame], how: str | float = "worst") -> pd.DataFrame:
    """Per (subset, axis) the aggregate over conditions of median, p75, mean and max; a subset counts as
    failed as often as in its worst condition and unobservable when it is in any (so it is never chosen
    for an axis one condition cannot measure)."""
    if len(frames) == 1:
        return frames[0]
    keys = frames[0][["subset", "axis"]]
    if not all(f[["subset", "axis"]].equals(keys) for f in frames):
        raise ValueError("statistics of different layouts or protocols cannot be aggregated")
    out = keys.copy()
    for column in ("median", "p75", "mean", "max"):
        out[column] = aggregate([f[column].to_numpy() for f in frames], how)
    out["n_ok"] = pd.concat([f["n_ok"] for f in frames], axis=1).min(axis=1).to_numpy()
    out["n_failed"] = pd.concat([f["n_failed"] for f in frames], axis=1).max(axis=1).to_numpy()
    out["unobservable"] = pd.concat([f["unobservable"] for f in frames], axis=1).any(axis=1).to_numpy()
    return out
