"""A calibration run: a prior cell's ranges, a hand layout's measured figures, and the posterior (docs/calibration.md).

:func:`calibrate` builds the emulator of the hand layout in the prior cell, evaluates the layout by ICP at ``icp``
cell instances of the prior (their seeds are their magnitude draws, :meth:`optipose.cell.config.Cell.instance`) to fit
the emulator's correction to ICP, samples the posterior (:mod:`optipose.calibrate.posterior`) and says which figures
the ranges cannot produce. Its record :class:`Calibration` is what the cell file (:mod:`optipose.calibrate.cellfile`)
and the command's lines are written from.
"""

from __future__ import annotations

import itertools
import logging
import time
from dataclasses import dataclass

import numpy as np

from optipose.calibrate.emulator import Emulator, field_value
from optipose.calibrate.posterior import Correction, Posterior, fit_correction, misfit, sample
from optipose.calibrate.summaries import AXES, STATS, Summaries
from optipose.errors import ConfigError

__all__ = ["Calibration", "IcpRuns", "calibrate", "figure_logs", "icp_runs"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Calibration:
    """A calibration's answer.

    prior : the prior :class:`~optipose.cell.config.Cell`; summaries : the measured figures; keys : the ranges it
    calibrated (in the emulator's order), fixed : the ranges it kept (not emulated); posterior, correction : the
    sample and the ICP correction; out : the figures (labels with what was measured and what the ranges reach) the
    ranges cannot produce, empty when they can; predicted : (figures, 3) degrees, the posterior's 5 %, 50 % and 95 %
    of each figure (corrected to ICP); seconds : the run's wall time.
    """

    prior: object
    summaries: Summaries
    keys: tuple[str, ...]
    fixed: tuple[str, ...]
    posterior: Posterior
    correction: Correction
    out: tuple[str, ...]
    predicted: np.ndarray
    seconds: float


def figure_logs(summaries: Summaries, stats: dict[str, np.ndarray]) -> np.ndarray:
    """(n, figures) the logs of the emulated (or evaluated) figures from per-subset statistics (n, 2, 3) rad."""
    cols = [
        np.log(np.maximum(stats[f.subset][:, STATS.index(f.stat), AXES.index(f.axis)], 1e-12))
        for f in summaries.figures
    ]
    return np.column_stack(cols)


@dataclass(frozen=True)
class IcpRuns:
    """The layout evaluated by ICP at prior instances, beside the emulator at their magnitudes: per subset name,
    (m, 2, 3) rad median and p75 per axis, ``emulated`` and ``evaluated``; ``seeds`` the instances, ``seconds`` the
    evaluations' wall time. One set serves every calibration of the same layout, objective and prior."""

    seeds: tuple[int, ...]
    emulated: dict
    evaluated: dict
    seconds: float


def icp_runs(part, layout, objective, emulator: Emulator, icp: int, seed: int = 0, jobs: int = 1) -> IcpRuns:
    """:class:`IcpRuns` at the prior's instances of seeds ``seed`` … ``seed + icp − 1`` (each its own magnitudes)."""
    from optipose.evaluate.evaluator import Evaluator

    start = time.perf_counter()
    seeds = tuple(seed + i for i in range(icp))
    emulated = {sub: [] for sub in emulator.labels}
    evaluated = {sub: [] for sub in emulator.labels}
    for s in seeds:
        instance = objective.cell.instance(s)
        values = np.array([[field_value(instance, k) for k in emulator.keys]])
        for sub, stats in emulator.stats(values).items():
            emulated[sub].append(stats[0])
        with Evaluator(part, objective, seed=s, jobs=jobs, quiet=True) as evaluator:
            result = evaluator(layout)
        for sub in emulator.labels:
            evaluated[sub].append([[_stat(result.stats, sub, axis, stat) for axis in AXES] for stat in STATS])
        log.info("ICP at prior instance %d: %.1f s", s, time.perf_counter() - start)
    shape = (len(seeds), 2, 3)
    return IcpRuns(
        seeds,
        {k: np.reshape(v, shape) for k, v in emulated.items()},
        {k: np.reshape(v, shape) for k, v in evaluated.items()},
        time.perf_counter() - start,
    )


def calibrate(
    part,
    layout,
    objective,
    summaries: Summaries,
    draws: int = 20000,
    icp: int = 4,
    seed: int = 0,
    jobs: int = 1,
    emulator: Emulator | None = None,
    runs: IcpRuns | None = None,
) -> Calibration:
    """Calibrate ``objective.cell`` (a cell of ranges, the prior) to ``summaries`` of ``layout`` on ``part``.

    draws : prior draws of the importance sampler (per round); icp : ICP evaluations of the layout at prior
    instances (seeds ``seed`` … ``seed + icp − 1``) for the emulator's correction (0: none, a default spread).
    emulator, runs : the layout's emulator and ICP runs in this prior, when a caller already has them (a study of
    several calibrations of one layout); ``runs`` replaces ``icp``.
    """
    start = time.perf_counter()
    prior = objective.cell
    if not prior.ranges:
        raise ConfigError(f"cell '{prior.name}' has no range to calibrate (a prior is a cell of ranges: cobot, ...)")
    emulator = emulator or Emulator(part, layout, objective)
    unknown = sorted({f.subset for f in summaries.figures} - set(emulator.labels))
    if unknown:
        raise ConfigError(
            f"{summaries.origin}: subset {', '.join(unknown)} is not one of the layout's that sees the part "
            f"({', '.join(emulator.labels)})"
        )
    subsets = sorted({f.subset for f in summaries.figures})
    ranges = [r for r in prior.ranges if r[0] in emulator.keys]
    runs = runs or icp_runs(part, layout, objective, emulator, icp, seed, jobs)
    correction = _correction(summaries, runs)
    cov = summaries.noise() + correction.cov

    def simulate(values: np.ndarray) -> np.ndarray:
        return figure_logs(summaries, emulator.stats(values, subsets)) + correction.log_ratio

    observed = summaries.logs
    posterior, first = sample(simulate, ranges, observed, cov, draws, seed)
    out = tuple(_out_line(summaries, i, first) for i in misfit(first, observed, cov, posterior))
    predicted = _predicted(simulate, posterior)
    log.info("calibrated on %d figures: ESS %.0f in %d rounds", len(observed), posterior.ess, posterior.rounds)
    return Calibration(
        prior,
        summaries,
        emulator.keys,
        emulator.fixed,
        posterior,
        correction,
        out,
        predicted,
        time.perf_counter() - start,
    )


def _correction(summaries: Summaries, runs: IcpRuns) -> Correction:
    """The emulator's correction to ICP for the summaries' figures, from the ICP runs."""
    figures = summaries.figures
    pairs = list(itertools.combinations(range(len(figures)), 2))
    related = [
        [(i, j) for i, j in pairs if (figures[i].subset, figures[i].axis) == (figures[j].subset, figures[j].axis)],
        [(i, j) for i, j in pairs if figures[i].axis == figures[j].axis and figures[i].subset != figures[j].subset],
    ]
    subsets = {f.subset for f in figures}
    shape = (len(runs.seeds), len(figures))
    emulated = figure_logs(summaries, {s: runs.emulated[s] for s in subsets}) if runs.seeds else np.zeros(shape)
    evaluated = figure_logs(summaries, {s: runs.evaluated[s] for s in subsets}) if runs.seeds else np.zeros(shape)
    return fit_correction(emulated, evaluated, related, runs.seeds, runs.seconds)


def _stat(stats, subset: str, axis: str, stat: str) -> float:
    row = stats[(stats["subset"] == subset) & (stats["axis"] == axis)]
    return float(row[stat].iloc[0]) if len(row) else float("nan")


def _predicted(simulate, posterior: Posterior) -> np.ndarray:
    """(figures, 3) degrees: each figure's weighted 5, 50 and 95 % over the posterior's settings."""
    from optipose.calibrate.posterior import weighted_quantiles

    keep = posterior.weights > 1e-8 * posterior.weights.max()
    logs = simulate(posterior.values[keep])
    w = posterior.weights[keep]
    return np.rad2deg(np.exp([weighted_quantiles(logs[:, j], w, [0.05, 0.5, 0.95]) for j in range(logs.shape[1])]))


def _out_line(summaries: Summaries, i: int, first: np.ndarray) -> str:
    f = summaries.figures[i]
    lo, hi = np.rad2deg(np.exp([first[:, i].min(), first[:, i].max()]))
    return f"{summaries.part} {f.label} {np.rad2deg(f.value):.3g}° (the ranges give {lo:.3g}–{hi:.3g}°)"
