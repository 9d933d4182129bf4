"""Per-axis configuration assignment: the paper's Table 1 (SPEC §5).

For a layout of n sensors every non-empty subset (2ⁿ − 1) has per-axis statistics. Within a choice C of
k sensors, each axis takes the subset of C with the lowest median (ties: lowest 75th percentile); a
subset is not eligible for an axis it cannot observe or when more than ``MAX_FAILED_FRACTION`` of its
registrations failed. The k-sensor result is the choice C with the lowest score
``Σ_axis weight · (median_weight · median + p75_weight · p75)``; an axis no subset of C can measure
costs ``UNOBSERVABLE_PENALTY`` instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
import pandas as pd

from optipose.evaluate.objective import AXES, StatisticConfig

__all__ = ["all_subsets", "subset_name", "AxisChoice", "Choice", "best_choices", "MAX_FAILED_FRACTION", "UNOBSERVABLE_PENALTY"]

MAX_FAILED_FRACTION = 0.1
UNOBSERVABLE_PENALTY = np.deg2rad(10.0)  # rad per axis: worse than any measurable error under ±2° protocols


def all_subsets(n: int) -> list[tuple[int, ...]]:
    """Every non-empty subset of range(n), by size then lexicographically: (0,), (1,), ..., (0, 1, 2)."""
    return [c for k in range(1, n + 1) for c in combinations(range(n), k)]


def subset_name(subset: tuple[int, ...], names: list[str]) -> str:
    """'S1S2S3' from sensor indices and names."""
    return "".join(names[i] for i in subset)


@dataclass(frozen=True)
class AxisChoice:
    axis: str
    subset: str  # "" when no subset of the choice can observe the axis
    median: float  # rad (NaN when unobservable)
    p75: float

    @property
    def observable(self) -> bool:
        return bool(self.subset)


@dataclass(frozen=True)
class Choice:
    """The best k sensors and, per axis, the subset of them to use."""

    k: int
    sensors: str
    axes: tuple[AxisChoice, ...]
    score: float  # rad

    def __repr__(self) -> str:
        cells = ", ".join(
            f"{a.axis}={np.rad2deg(a.median):.4f}/{np.rad2deg(a.p75):.4f} deg ({a.subset})" if a.observable else f"{a.axis}=unobservable"
            for a in self.axes
        )
        return f"Choice(k={self.k}, {self.sensors}: {cells})"


def best_choices(stats: pd.DataFrame, names: list[str], cfg: StatisticConfig, n_scans: int) -> list[Choice]:
    """The best choice for k = 1 … n sensors (Table 1), from :func:`optipose.evaluate.statistics.summarize` output."""
    by_key = {(r.subset, r.axis): r for r in stats.itertuples(index=False)}
    out = []
    for k in range(1, len(names) + 1):
        candidates = [_choose(c, names, by_key, cfg, n_scans) for c in combinations(range(len(names)), k)]
        out.append(min(candidates, key=lambda ch: ch.score))  # first of equals: lowest sensor indices
    return out


def _choose(sensors: tuple[int, ...], names, by_key, cfg: StatisticConfig, n_scans: int) -> Choice:
    subsets = [subset_name(s, names) for k in range(1, len(sensors) + 1) for s in combinations(sensors, k)]
    axes, score = [], 0.0
    for axis, weight in zip(AXES, cfg.weights):
        eligible = [by_key[(s, axis)] for s in subsets if _eligible(by_key[(s, axis)], n_scans)]
        if not eligible:
            axes.append(AxisChoice(axis, "", float("nan"), float("nan")))
            score += weight * UNOBSERVABLE_PENALTY * (cfg.median_weight + cfg.p75_weight)
            continue
        best = min(eligible, key=lambda r: (r.median, r.p75))  # stable: the smaller subset wins a full tie
        axes.append(AxisChoice(axis, best.subset, best.median, best.p75))
        score += weight * (cfg.median_weight * best.median + cfg.p75_weight * best.p75)
    return Choice(len(sensors), subset_name(sensors, names), tuple(axes), float(score))


def _eligible(row, n_scans: int) -> bool:
    return (not row.unobservable) and np.isfinite(row.median) and row.n_failed <= MAX_FAILED_FRACTION * max(n_scans, 1)
