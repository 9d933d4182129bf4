"""A layout under every condition of its objective's band, and the robust statistic over them.

:func:`evaluate_robust` evaluates a layout once per :class:`~optipose.evaluate.conditions.Condition` (the
same protocol and noise seed each time: only the condition differs) and aggregates, per sensor subset and
axis, each statistic over the conditions with the objective's ``aggregate`` (the worst by default). The
robust Table 1 is the paper's assignment on those aggregated statistics: a subset is chosen for an axis
because it is good at every noise level and bracket draw, not at the nominal one alone. Layouts are
compared (:mod:`optipose.verdict.compare`) at each noise level, over its bracket draws (:func:`by_level`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import pandas as pd

from optipose.evaluate.assignment import Choice, best_choices, choose, restated, stats_by_key
from optipose.evaluate.conditions import Condition, aggregate, conditions
from optipose.evaluate.evaluator import EvaluationResult, Evaluator, EvaluatorWrapper
from optipose.errors import ConfigError
from optipose.evaluate.objective import Objective, load_objective

__all__ = [
    "RobustResult",
    "RobustEvaluator",
    "make_evaluator",
    "evaluate_robust",
    "robust_result",
    "by_level",
    "choice_of",
    "robust_stats",
]


@dataclass
class RobustResult:
    """A layout's evaluations under each condition, and the aggregated statistics and Table 1 (each choice
    carries itself restated at every noise level of the band, the bracket draws aggregated, ``Choice.under``)."""

    results: list[tuple[Condition, EvaluationResult]] = field(repr=False)
    stats: pd.DataFrame = field(repr=False)
    table: list[Choice] = field(repr=False)

    @property
    def layout(self):
        return self.results[0][1].layout

    @property
    def n_scans(self) -> int:
        return self.results[0][1].n_scans

    @property
    def timings(self) -> dict:
        return {key: sum(r.timings.get(key, 0.0) for _, r in self.results) for key in ("scan", "register", "wall")}

    def under(self, choice: Choice) -> list[tuple[Condition, Choice]]:
        """``choice`` (its sensors and each axis's subset, as one deployed cell fixes them) under each
        condition: with the worst aggregate, the robust statistic is the largest of these."""
        return [(c, restated(choice, stats_by_key(r.stats), r.objective.statistic)) for c, r in self.results]


class RobustEvaluator(EvaluatorWrapper):
    """An :class:`Evaluator` that scores a layout under every condition of its objective's band: the same
    protocol and noise seed each time, one set of workers (and their scanners and reference) for all.
    ``RobustEvaluator(part, objective)(layout) -> RobustResult``; the arguments are the Evaluator's."""

    def __init__(self, part, objective, seed: int = 0, jobs: int = 1, quiet: bool = False, executor=None):
        self.evaluator = Evaluator(part, objective, seed=seed, jobs=jobs, quiet=quiet, executor=executor)
        self.objective, self.seed = self.evaluator.objective, self.evaluator.seed
        self.conditions = conditions(self.objective.conditions)

    def __call__(self, layout) -> RobustResult:
        return robust_result(list(zip(self.conditions, self.evaluator.under(layout, self.conditions))), self.objective)


def make_evaluator(part, objective, seed: int = 0, jobs: int = 1, quiet: bool = False, executor=None, scans: int = 0):
    """The evaluator an objective asks for: a plain :class:`Evaluator` when its band is trivial (one
    condition, the nominal one), else a :class:`RobustEvaluator`. Both give results with ``table``,
    ``stats``, ``layout`` and ``n_scans``. ``scans``: this many of the protocol's scans, drawn by the seed (0:
    all; a plain evaluator only)."""
    objective = objective if isinstance(objective, Objective) else load_objective(objective)
    if objective.conditions.trivial:
        return Evaluator(part, objective, seed=seed, jobs=jobs, quiet=quiet, executor=executor, scans=scans)
    if scans:
        raise ConfigError("a share of the scans is evaluated in one condition only, not under a band")
    return RobustEvaluator(part, objective, seed=seed, jobs=jobs, quiet=quiet, executor=executor)


def evaluate_robust(part, layout, objective, seed: int = 0, jobs: int = 1, quiet: bool = False) -> RobustResult:
    """Evaluate ``layout`` under every condition of ``objective.conditions`` (see the module doc)."""
    with RobustEvaluator(part, objective, seed=seed, jobs=jobs, quiet=quiet) as evaluator:
        return evaluator(layout)


def robust_result(results: list[tuple[Condition, EvaluationResult]], objective) -> RobustResult:
    """The evaluations of one layout under each condition, aggregated; every choice of the robust Table 1
    restated at each noise level of the band (``Choice.under``, see :func:`by_level`)."""
    stats = robust_stats([r.stats for _, r in results], objective.conditions.aggregate)
    first = results[0][1]
    table = best_choices(stats, first.layout.names, objective.statistic, first.n_scans)
    levels = _levels_by_key(results, objective)
    return RobustResult(results, stats, [_restated_by_level(ch, levels, objective) for ch in table])


def by_level(results: list[tuple[Condition, EvaluationResult]], how) -> list[tuple[str, pd.DataFrame]]:
    """(label, statistics) per noise level: each statistic aggregated (``how``) over the level's bracket draws.

    A layout is compared with another at each noise level, not at each bracket draw: a draw is one sample of
    errors within the tolerance, drawn per sensor index, so draw d turns the hand layout's S3 and a found
    layout's F1 by different errors, and no draw is a condition both share. What both share is the
    tolerance; over the draws, the worst (or a quantile) of each statistic is what the tolerance can do.
    """
    levels = list(dict.fromkeys(c.noise_scale for c, _ in results))
    out = []
    for level in levels:
        group = [(c, r) for c, r in results if c.noise_scale == level]
        draws = [c.draw for c, _ in group if c.draw is not None]
        agg = "worst" if how == "worst" else f"quantile {how:g}"
        label = f"noise x{level:g}" + (
            f", {agg} of {len(draws)} bracket draws"
            if len(draws) > 1
            else (f", bracket draw {draws[0]}" if draws else "")
        )
        out.append((label, robust_stats([r.stats for _, r in group], how)))
    return out


def _levels_by_key(results, objective) -> list[tuple[str, dict]]:
    """:func:`by_level`'s statistics, each as :func:`stats_by_key` gives them."""
    return [(label, stats_by_key(stats)) for label, stats in by_level(results, objective.conditions.aggregate)]


def _restated_by_level(choice: Choice, levels: list[tuple[str, dict]], objective) -> Choice:
    return replace(
        choice, under=tuple((label, restated(choice, by_key, objective.statistic)) for label, by_key in levels)
    )


def choice_of(result, sensors: tuple[int, ...]) -> Choice:
    """The choice of exactly these sensors of an evaluated layout (each axis its best subset of them), from
    an :class:`EvaluationResult` or a :class:`RobustResult` (then restated at each noise level). The sensors
    are a set: in any order (a found pair can sit inside the found triple in another order)."""
    sensors = tuple(sorted(sensors))
    if isinstance(result, EvaluationResult):
        return choose(
            sensors, result.layout.names, stats_by_key(result.stats), result.objective.statistic, result.n_scans
        )
    objective = result.results[0][1].objective
    choice = choose(sensors, result.layout.names, stats_by_key(result.stats), objective.statistic, result.n_scans)
    return _restated_by_level(choice, _levels_by_key(result.results, objective), objective)


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
