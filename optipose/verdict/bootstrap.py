"""The verdict's bootstrap: intervals from paired draws, nested over draws and the scans inside each.

A replicate resamples the draws (with replacement) and, inside each, the scan indices, the same for both layouts;
each draw's statistics are shrunk towards their mean until their spread is the cells' alone (Davison & Hinkley
1997, §3.8), and each interval's deviations from the estimate (in logs) are scaled to the variance of a mean of D
draws times Student's quantile over the normal one (:func:`widening`). The share of scans on which found's
registration failed less hand's has its own Student interval (:func:`failed_shares`). What the intervals decide is
:func:`optipose.verdict.confidence.compare_draws`'s (its module docstring says how).

The arrays are indexed (…, 2 quantiles: median and p75, 2 layouts: found and hand, 3 axes), in rad.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.stats import norm as stats_norm
from scipy.stats import t as stats_t

from optipose.evaluate.objective import AXES, StatisticConfig
from optipose.evaluate.statistics import FAILED_ERROR

__all__ = [
    "READ",
    "LOG_BOUND",
    "draw_statistics",
    "nested_replicates",
    "log_quantities",
    "widening",
    "log_interval",
    "failed_shares",
]

_QUANTILES = (0.5, 0.75)  # median and p75, np.median's and np.percentile(75)'s linear interpolation
READ = 0.95  # the widest interval read off the bootstrap replicates; a wider one is scaled from it (log_interval)
LOG_BOUND = 600.0  # an interval's sides in logs at most this far out: exp stays finite, in degrees too


def _quantiles(x: np.ndarray) -> np.ndarray:
    """(2, …) the median and p75 over the last axis of an array sorted along it (np.quantile's linear rule)."""
    n = x.shape[-1]
    out = []
    for q in _QUANTILES:
        pos = q * (n - 1)
        lo = int(np.floor(pos))
        hi = min(lo + 1, n - 1)
        out.append(x[..., lo] + (pos - lo) * (x[..., hi] - x[..., lo]))
    return np.stack(out)


def draw_statistics(draw, replicates: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One draw's statistics (2 quantiles, 2 layouts, 3 axes) and (replicates, 2, 2, 3) of its scans
    resampled, the same scan indices for both layouts."""
    x = np.concatenate([draw.found, draw.baseline], axis=1).T  # (6, n)
    observed = _quantiles(np.sort(x, axis=1)).reshape(2, 2, 3)
    index = rng.integers(0, x.shape[1], (replicates, x.shape[1]))
    boot = np.sort(x[:, index], axis=2)  # (6, replicates, n)
    return observed, np.moveaxis(_quantiles(boot), 2, 0).reshape(replicates, 2, 2, 3)


def nested_replicates(per_draw: list, rules) -> tuple[np.ndarray, np.ndarray]:
    """The observed statistics averaged over draws (2, 2, 3) and (replicates, 2, 2, 3) of the nested
    bootstrap: draws resampled, each one's statistics shrunk to the cells' spread plus its scans' resampling.
    ``per_draw``: each draw's :func:`draw_statistics`; ``rules``: a :class:`~optipose.verdict.confidence.Rules`
    (its replicates and seed)."""
    stats = np.stack([s for s, _ in per_draw])  # (D, 2, 2, 3)
    deviations = np.stack([b - s for s, b in per_draw])  # (D, R, 2, 2, 3)
    mean, n = stats.mean(axis=0), len(per_draw)
    shrink = np.zeros_like(mean)
    if n > 1:
        between = stats.var(axis=0, ddof=1)
        within = deviations.var(axis=1).mean(axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            shrink = np.where(between > 0, np.sqrt(np.clip(between - within, 0.0, None) / between), 0.0)
    rng = np.random.default_rng([rules.seed, 0x0B007])
    picks = rng.integers(0, n, (rules.replicates, n))
    columns = rng.integers(0, rules.replicates, (rules.replicates, n))
    values = mean + shrink * (stats[picks] - mean) + deviations[picks, columns]  # (R, D, 2, 2, 3)
    return mean, values.mean(axis=1)


def log_quantities(stats: np.ndarray, statistic: StatisticConfig) -> np.ndarray:
    """(…, 24) logs of what the verdict reports, from (…, 2 quantiles, 2 layouts, 3 axes) in rad: hand / found
    of the score, each axis's test (the hand layout's score over that score with the axis's share, weight ·
    (median + p75), the found layout's), hand / found of each median and p75 (10); found's median and p75 per
    axis, hand's (12); found's and hand's score (2)."""
    share = np.asarray(statistic.weights, float) * (
        statistic.median_weight * stats[..., 0, :, :] + statistic.p75_weight * stats[..., 1, :, :]
    )
    score = share.sum(axis=-1, keepdims=True)  # (…, 2 layouts, 1)
    swapped = score[..., 1, :] - share[..., 1, :] + share[..., 0, :]  # (…, 3)
    log = np.log(np.maximum(np.concatenate([score, stats[..., 0, :, :], stats[..., 1, :, :]], axis=-1), 1e-300))
    f, h = log[..., 0, :], log[..., 1, :]  # (…, 7): score, medians, p75s
    tests = h[..., :1] - np.log(np.maximum(swapped, 1e-300))
    return np.concatenate(
        [h[..., :1] - f[..., :1], tests, h[..., 1:] - f[..., 1:], f[..., 1:], h[..., 1:], f[..., :1], h[..., :1]],
        axis=-1,
    )


def widening(per_draw: list, boot: np.ndarray, rules, n_scans: list[int]) -> np.ndarray:
    """(24,) the factor each quantity's bootstrap deviations are scaled by: to the variance of a mean of D
    draws (the draws' spread over D, at least the scans' own) and the Student quantile of its degrees of
    freedom over the normal one. With one draw, the scans' variance alone. ``rules``: its statistic and
    confidence."""
    d = len(per_draw)
    per = np.stack([log_quantities(s, rules.statistic) for s, _ in per_draw])  # (D, 24)
    within = np.stack([log_quantities(b, rules.statistic).var(axis=0) for _, b in per_draw]).mean(axis=0)
    between = per.var(axis=0, ddof=1) if d > 1 else within
    # the draws' spread, an estimate on D − 1 degrees of freedom, where it exceeds the scans' own (the cells
    # vary); else the scans' variance, known from every scan of every draw
    df = np.where(between > within, max(d - 1, 1), max(sum(n - 1 for n in n_scans), 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        tail = (1.0 + rules.confidence) / 2.0
        student = stats_t.ppf(tail, df) / stats_norm.ppf(tail)
        scale = np.sqrt(np.maximum(between, within) / d / boot.var(axis=0))
    return np.where(np.isfinite(scale), student * scale, 1.0)


def log_interval(
    point: float, samples: np.ndarray, widen: float, confidence: float, unit=np.exp
) -> tuple[float, float, float]:
    """The percentile interval of log ``samples`` about log ``point``, its deviations scaled by ``widen``.
    Beyond :data:`READ` the replicates' own tails are too thin to read (a racing look at 99.9 % would take
    the one or two most extreme of 2000), so the interval is read at :data:`READ` and its deviations scaled
    by the normal quantiles' ratio: the skew of the 95 % interval, the width of the one asked for. Returns
    (estimate, low, high), each through ``unit``."""
    read = min(confidence, READ)
    tail = 100.0 * (1.0 - read) / 2.0
    reach = stats_norm.ppf((1.0 + confidence) / 2.0) / stats_norm.ppf((1.0 + read) / 2.0)
    low, high = point + widen * reach * (np.percentile(samples, [tail, 100.0 - tail]) - point)
    low, high = np.clip([low, high], -LOG_BOUND, LOG_BOUND)  # an unbounded side stays a finite number, not an overflow
    return float(unit(point)), float(unit(low)), float(unit(high))


def failed_shares(draws: Sequence, confidence: float) -> list[tuple[float, float, float]]:
    """Per axis, the share of scans on which found's registration failed (its error the penalty: a failed
    registration, or an axis its choice does not measure) less hand's, averaged over draws, with a two-sided
    Student interval at ``confidence``: the draws' spread on D − 1 degrees of freedom where it exceeds the
    scans' own (the paired per-scan differences' variance over a draw's scans), else the scans' on all of theirs.
    Exactly [0, 0] where neither layout fails, or both fail on the same scans. Returns (estimate, low, high)
    per axis; ``draws``: :class:`~optipose.verdict.confidence.PairedDraw` records."""
    diff = [
        (d.found >= FAILED_ERROR).astype(float) - (d.baseline >= FAILED_ERROR) for d in draws
    ]  # (n, 3) each, in {-1, 0, 1}
    per = np.stack([x.mean(axis=0) for x in diff])  # (D, 3)
    within = np.mean([x.var(axis=0, ddof=1) / len(x) if len(x) > 1 else np.zeros(len(AXES)) for x in diff], axis=0)
    between = per.var(axis=0, ddof=1) if len(draws) > 1 else within
    df = np.where(between > within, max(len(draws) - 1, 1), max(sum(len(x) - 1 for x in diff), 1))
    half = stats_t.ppf((1.0 + confidence) / 2.0, df) * np.sqrt(np.maximum(between, within) / len(draws))
    mean = per.mean(axis=0)
    return [(float(m), float(max(-1.0, m - h)), float(min(1.0, m + h))) for m, h in zip(mean, half)]
