"""Which magnitude of a cell of ranges rules a decision, and where (docs/method.md, "Verdicts across a cell's ranges").

In a cell of ranges each draw of the race is a cell instance with magnitudes of its own (:mod:`optipose.cell.ranges`),
so the draws' paired ratios (hand / found of the paper's score, each draw's own) spread with the magnitudes as well
as with the noise. Per range, the draws' log-ratio is fitted by least squares on the magnitude's place in its range
(its draw's quantile: the logarithm's share of the way from low to high, or the value's share of high when low is 0);
the range whose fit explains most of the draws' spread rules the decision when its line crosses a ratio of 1 inside
the range, with a slope well clear of chance (|t| >= :data:`MIN_T`, strict because every range is tried) and a share
of at least :data:`MIN_SHARE` of the spread: the found layout is better on one side of the crossing, the hand one on
the other. A decision no range rules that way holds, as far as the draws show, across the ranges.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["FIELDS", "Ruling", "ruling", "draw_ratio", "place", "line_fit"]

# a cell file's ranged field: what a verdict's line calls it, its unit, SI → that unit (optipose.verdict.words)
FIELDS = {
    "robot.path": ("robot path error", "mm", 1e3),
    "robot.path_rotation": ("robot path rotation", "deg", 180 / math.pi),
    "robot.path_correlation": ("robot path correlation length", "mm", 1e3),
    "robot.step": ("scan step error", "%", 100.0),
    "robot.orientation": ("set orientation error", "deg", 180 / math.pi),
    "calibration.sensor_translation": ("head calibration error", "mm", 1e3),
    "calibration.sensor_rotation": ("head calibration rotation", "deg", 180 / math.pi),
    "calibration.frame_translation": ("frame calibration error", "mm", 1e3),
    "calibration.frame_rotation": ("frame calibration rotation", "deg", 180 / math.pi),
    "process_scale": ("part's process scale", "x", 1.0),
}

MIN_T = 3.0  # the slope's t statistic: about 1 % false rulings over ten ranges tried on pure noise
MIN_SHARE = 0.25  # of the draws' log-ratio variance the range's line explains
MIN_DRAWS = 8  # fewer draws say nothing about a slope


@dataclass(frozen=True)
class Ruling:
    """The range that rules a decision: ``key`` (a cell file's field, ``robot.path``), the magnitude ``at`` (SI)
    where the draws' fitted ratio crosses 1, ``above`` whether the found layout is the better one above it (else
    below), and ``share``, the part of the draws' log-ratio variance the range's line explains."""

    key: str
    at: float
    above: bool
    share: float


def place(value: float, low: float, high: float) -> float:
    """A magnitude's place in its range, 0 at low and 1 at high, as its draw's quantile
    (:func:`optipose.cell.ranges.quantile` inverted)."""
    if low > 0:
        return float(np.log(value / low) / np.log(high / low))
    return float(value / high)


def draw_ratio(draw, weights, median_weight: float, p75_weight: float) -> float:
    """One draw's (:class:`optipose.verdict.confidence.PairedDraw`) hand / found ratio of the paper's score (per axis ``median_weight`` · median + ``p75_weight`` · p75
    of |error| over the draw's scans, weighted over the axes)."""

    def score(e: np.ndarray) -> float:
        stats = median_weight * np.median(e, axis=0) + p75_weight * np.percentile(e, 75, axis=0)
        return float(np.dot(weights, stats))

    return score(draw.baseline) / max(score(draw.found), 1e-300)


def line_fit(u: np.ndarray, y: np.ndarray) -> tuple[float, float, float, float]:
    """Least squares of ``y`` on ``u`` (at least three points, ``u`` not constant): slope, intercept, the share of
    y's variance the line explains, and the slope's standard error."""
    slope, intercept = np.polyfit(u, y, 1)
    fitted = intercept + slope * u
    share = 1.0 - float(np.sum((y - fitted) ** 2) / np.sum((y - y.mean()) ** 2))
    se = float(np.sqrt(np.sum((y - fitted) ** 2) / (len(y) - 2) / np.sum((u - u.mean()) ** 2)))
    return float(slope), float(intercept), share, se


def ruling(ratios, magnitudes: list[dict[str, float]], ranges) -> Ruling | None:
    """The :class:`Ruling` of the draws (``ratios``: each draw's hand / found ratio; ``magnitudes``: each draw's cell
    instance, field → SI value; ``ranges``: ``(field, low, high)`` rows), or None when no range rules them."""
    y = np.log(np.asarray(ratios, float))
    if len(y) < MIN_DRAWS or not np.all(np.isfinite(y)) or np.ptp(y) == 0:
        return None
    best = None
    for key, low, high in ranges:
        u = np.array([place(m[key], low, high) for m in magnitudes])
        if np.ptp(u) == 0:
            continue
        slope, intercept, share, se = line_fit(u, y)
        cross = -intercept / slope if slope else np.nan
        if abs(slope) < MIN_T * se or share < MIN_SHARE or not 0.0 < cross < 1.0:
            continue
        if best is None or share > best[0]:
            at = float(np.exp(np.log(low) + cross * np.log(high / low))) if low > 0 else float(cross * high)
            best = (share, Ruling(key, at, bool(slope > 0), share))
    return None if best is None else best[1]
