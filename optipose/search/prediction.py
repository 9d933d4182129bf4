"""The surrogate's Table 1 as statistics: a predicted error's median and 75th percentile per axis from its noise
σ and bias δ (:func:`axis_stats`), per magnitude instance of a cell of ranges (:func:`instance_stats`), the paper's
per-axis assignment on them (:func:`best_subsets`), and the record :class:`Prediction` that
:func:`optipose.search.surrogate.predicted_stats` returns (across a cell's magnitude instances: :func:`across_instances`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

__all__ = [
    "MEDIAN_PER_SIGMA",
    "P75_PER_SIGMA",
    "Prediction",
    "axis_stats",
    "instance_stats",
    "across_instances",
    "best_subsets",
]

MEDIAN_PER_SIGMA = 0.6745  # median of |N(0, 1)|
P75_PER_SIGMA = 1.1503  # 75th percentile of |N(0, 1)|
_Z = norm.ppf((np.arange(16) + 0.5) / 16)  # 16 equal-probability stand-ins for N(0, 1)


def axis_stats(sigma: np.ndarray, delta: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Median and 75th percentile (3,) rad of |error| per axis: noise σ (3,) or per turn (turns, 3), plus
    the bias δ (turns, 3)."""
    if delta is None or not len(delta):
        return sigma * MEDIAN_PER_SIGMA, sigma * P75_PER_SIGMA
    sigma = np.broadcast_to(sigma, delta.shape)
    e = np.abs(delta[:, None, :] + sigma[:, None, :] * _Z[None, :, None]).reshape(-1, 3)
    return np.median(e, axis=0), np.percentile(e, 75, axis=0)


def instance_stats(sigma: np.ndarray, delta: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_axis_stats` of each magnitude instance: σ (instances, turns, 3); median and p75 (instances, 3)."""
    if delta is None or not len(delta):
        return sigma[:, 0] * MEDIAN_PER_SIGMA, sigma[:, 0] * P75_PER_SIGMA
    e = np.abs(delta[None, :, None, :] + sigma[:, :, None, :] * _Z[None, None, :, None]).reshape(len(sigma), -1, 3)
    return np.median(e, axis=1), np.percentile(e, 75, axis=1)


@dataclass(frozen=True)
class Prediction:
    """The surrogate's Table 1 for a layout of k sensors (:func:`predicted_stats`), the counterpart of
    :class:`optipose.evaluate.assignment.Choice` for ICP; sensors by index in the layout, axes roll, pitch, yaw.

    subsets : every non-empty subset of the k sensors (2ᵏ − 1 tuples of indices), by size then lexicographically.
    median_deg, p75_deg : (subsets, 3) degrees, each subset's predicted median and 75th percentile of |error|
        per axis, the worst over the noise levels.
    best_subset : per axis (3), the subset with the lowest median, ties by the lower p75 (the paper's assignment).
    axis_score : (3,) degrees, per axis ``median_weight · median + p75_weight · p75`` of its best subset.
    level_axis_score : (levels, 3) degrees, the same for each noise level alone, on that level's own best subsets.
    level_axis_stats : (levels, 3, 2) degrees, those subsets' median and 75th percentile per level and axis.
    score : degrees, ``Σ weights · axis_score``.
    """

    subsets: tuple[tuple[int, ...], ...]
    median_deg: np.ndarray = field(repr=False)
    p75_deg: np.ndarray = field(repr=False)
    best_subset: tuple[tuple[int, ...], ...]
    axis_score: np.ndarray
    level_axis_score: np.ndarray = field(repr=False)
    level_axis_stats: np.ndarray = field(repr=False)
    score: float


def across_instances(subsets, levels, weights, median_weight, p75_weight) -> Prediction:
    """:func:`predicted_stats` under a cell of ranges, from each level's and instance's statistics (levels,
    instances, subsets, 2, 3) rad: a statistic is the geometric mean over the instances of the worst over the
    levels; each axis's subset is chosen on those; the score is the geometric mean over the instances of each
    instance's weighted score on those subsets (what the verdict's paired ratio averages in logarithms)."""
    logs = np.log(np.maximum(np.rad2deg(levels), 1e-12))
    median, p75 = np.exp(logs.max(axis=0).mean(axis=0)).transpose(1, 0, 2)
    best = best_subsets(median, p75)
    axis = np.array([median_weight * median[s, a] + p75_weight * p75[s, a] for a, s in enumerate(best)])
    worst = np.exp(logs.max(axis=0))  # (instances, subsets, 2, 3) degrees
    per_instance = [
        sum(w * (median_weight * x[s, 0, a] + p75_weight * x[s, 1, a]) for a, (w, s) in enumerate(zip(weights, best)))
        for x in worst
    ]
    level = np.exp(logs.mean(axis=1))  # (levels, subsets, 2, 3): each level's geometric mean over the instances
    level_stats = np.array([[lv[s, :, a] for a, s in enumerate(best_subsets(lv[:, 0], lv[:, 1]))] for lv in level])
    return Prediction(
        subsets=tuple(subsets),
        median_deg=median,
        p75_deg=p75,
        best_subset=tuple(subsets[s] for s in best),
        axis_score=axis,
        level_axis_score=median_weight * level_stats[:, :, 0] + p75_weight * level_stats[:, :, 1],
        level_axis_stats=level_stats,
        score=float(np.exp(np.mean(np.log(np.maximum(per_instance, 1e-12))))),
    )


def best_subsets(median: np.ndarray, p75: np.ndarray) -> list[int]:
    """Per axis, the subset (row) with the lowest median, ties by the lower p75: the paper's assignment."""
    return [min(range(len(median)), key=lambda s: (median[s, a], p75[s, a])) for a in range(3)]
