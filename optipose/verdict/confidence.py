"""A verdict with confidence (issue #33): a found layout against the hand one on the same draws, with intervals.

Both layouts are evaluated on the same draws (common random numbers: one seed gives both the same part
instance, calibration, robot paths and scan noise; docs/cell.md). A :class:`PairedDraw` holds, per layout,
each axis's per-scan |error| of the subset its :class:`Choice` uses (a failed registration ``FAILED_ERROR``,
an axis it does not measure ``UNOBSERVABLE_PENALTY``). The statistic is the objective's (docs/method.md, "The score"): per axis the
median and 75th percentile over a draw's scans, averaged over draws (the expected error in the cell), and
the score Σ weight · (median_weight · median + p75_weight · p75).

The intervals come from a bootstrap over scans nested in one over draws, both paired: a replicate resamples
the draws (with replacement) and, inside each, the scan indices, the same for both layouts. Resampling at
both levels would count the scans' noise twice (the draws' spread already holds it), so each draw's
statistics are shrunk towards their mean until their spread is the cells' alone (Davison & Hinkley 1997,
§3.8). A percentile bootstrap over a handful of draws is too narrow (it knows no Student t), so each
interval's deviations from the estimate (in logs) are then scaled to the variance of a mean of D draws — the
draws' spread over D, or the scans' own where that is larger — times Student's quantile over the normal
one, on D − 1 degrees of freedom where the cells vary (the draws' spread exceeds the scans'), else on all
the scans' (one draw: the scans' alone). An interval wider than 95 % (a racing look's) is read off the
replicates at 95 % and widened by the normal quantiles' ratio: the replicates' far tails are too thin to
read. Intervals are two-sided at ``confidence``: of the ratio hand / found (above 1: found is better) of
the score, of each axis's test (the hand layout's score over that score with the axis's share, weight ·
(median + p75), the found layout's: an axis is worse by more than the tolerance when found's error on it
alone adds more than the tolerance to the hand layout's total; docs/method.md, "The verdict with
confidence") and of each axis's median and p75. The quantiles do not see a registration that fails in fewer than
a quarter of a draw's scans, so each axis also has the share of scans on which found's registration failed less
hand's (:func:`optipose.verdict.bootstrap.failed_shares`: a Student interval over the draws, at least the scans' own spread), which may exceed 0 by
at most ``Rules.failures`` (one scan in a hundred): a failed registration is a part scanned again or set aside. The
decision:

- KEEP: the score's interval lies below 1 (hand is better), or some axis's test lies below 1 / (1 + tolerance),
  or found fails some axis more often than hand by more than ``failures``;
- BUY: the score's interval lies above 1, no axis's test reaches below 1 / (1 + tolerance) and no axis's failed
  share reaches above ``failures``;
- TIE: the score's and every axis's test's intervals lie within [1 / (1 + tolerance), 1 + tolerance], and no
  failed share reaches above ``failures`` (found failing less is no reason to move a bracket on its own);
- KEEP too when none of these holds but the score's interval lies below 1 + tolerance: found can gain no more
  than a TIE allows, so no draw can make it a BUY (a futility stop; its risk is one side of the interval, as a
  KEEP's);
- UNDECIDED: none of these, with how many more draws would settle it (the interval's width ∝ 1/√draws).

Each test reads one side of a two-sided interval, so at 95 % a BUY or a KEEP is one-sided at 97.5 %.
:mod:`optipose.verdict.racing` adds draws until the decision is not UNDECIDED or a budget ends. The same
draws and :class:`Rules` give the same verdict. The bootstrap is :mod:`optipose.verdict.bootstrap`'s; a search's
verdicts together are one :class:`Verdicts`; their lines are :mod:`optipose.verdict.words`'.

What one cell gives (:func:`one_cell`): each draw is one instance of the cell (its part as made, its calibration, in a
cell of ranges its magnitudes), and a user's cell is one instance, not their average; so beside the interval of the
expected median, each axis's median carries the interval that one new instance's falls in (90 %, from the draws'
spread: :data:`ONE_CELL`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Sequence

import numpy as np
from scipy.stats import t as stats_t

from optipose.evaluate.assignment import UNOBSERVABLE_PENALTY, Choice, not_measured
from optipose.evaluate.objective import AXES, StatisticConfig
from optipose.evaluate.statistics import FAILED_ERROR
from optipose.verdict.bootstrap import (
    draw_statistics,
    failed_shares,
    log_interval,
    log_quantities,
    nested_replicates,
    widening,
)

from optipose.verdict.rules import Rules
from optipose.verdict.ruling import Ruling

__all__ = [
    "Decision",
    "PairedDraw",
    "Interval",
    "AxisError",
    "AxisRatio",
    "ConfidentVerdict",
    "Verdicts",
    "scan_errors",
    "paired_draw",
    "paired_draws",
    "compare_draws",
    "one_cell",
    "ONE_CELL",
    "NOT_GIVEN",
    "raced_in",
    "borne_out",
    "at_ends",
]


class Decision(StrEnum):
    """What a verdict with confidence says: buy the found layout, keep the baseline, a tie (keep it: nothing to
    gain), or not yet settled. Its value is the word the terminal, the report and ``verdict.csv`` write."""

    BUY = "BUY"
    KEEP = "KEEP"
    TIE = "TIE"
    UNDECIDED = "UNDECIDED"


@dataclass(frozen=True, eq=False)
class PairedDraw:
    """One draw (a seed) of both layouts: (n_scans, 3) |error| rad per scan and axis, the rows the same scans
    (compared by identity: its fields are arrays)."""

    seed: int
    found: np.ndarray
    baseline: np.ndarray

    def __post_init__(self):
        if self.found.shape != self.baseline.shape or self.found.ndim != 2 or self.found.shape[1] != len(AXES):
            raise ValueError(
                f"a paired draw needs two (n_scans, 3) arrays, got {self.found.shape} and {self.baseline.shape}"
            )


def scan_errors(result, choice: Choice) -> np.ndarray:
    """(n_scans, 3) rad: per scan (in scan order) and axis the |error| of the subset ``choice`` uses for the
    axis in ``result`` (an :class:`~optipose.evaluate.evaluator.EvaluationResult`); a failed registration
    counts ``FAILED_ERROR``, an axis the choice does not measure ``UNOBSERVABLE_PENALTY``."""
    per_scan = result.per_scan
    scans = np.sort(per_scan["scan"].unique())
    out = np.full((len(scans), len(AXES)), UNOBSERVABLE_PENALTY)
    for j, axis in enumerate(choice.axes):
        if not axis.observable:
            continue
        rows = per_scan[per_scan["subset"] == axis.name].sort_values("scan")
        if not np.array_equal(rows["scan"].to_numpy(), scans):
            raise ValueError(f"subset {axis.name} lacks some scans of the evaluation")
        ok = rows["ok"].to_numpy(bool)
        out[:, j] = np.where(ok, np.abs(rows[f"err_{axis.axis}"].to_numpy(float)), FAILED_ERROR)
    return out


def paired_draw(found, found_choice: Choice, baseline, baseline_choice: Choice) -> PairedDraw:
    """The paired draw of two evaluations on the same seed (common random numbers); a ValueError if they
    were not (another seed, other scans)."""
    if found.seed != baseline.seed or found.n_scans != baseline.n_scans:
        raise ValueError(
            f"not a paired draw: seed {found.seed} ({found.n_scans} scans) vs {baseline.seed} ({baseline.n_scans} scans)"
        )
    return PairedDraw(int(found.seed), scan_errors(found, found_choice), scan_errors(baseline, baseline_choice))


def paired_draws(
    found: Sequence, found_choice: Choice, baseline: Sequence, baseline_choice: Choice
) -> list[PairedDraw]:
    """The paired draws of two lists of evaluations, matched by seed (in the found list's order)."""
    by_seed = {r.seed: r for r in baseline}
    missing = [r.seed for r in found if r.seed not in by_seed]
    if missing:
        raise ValueError(f"no hand evaluation on seed(s) {missing}")
    return [paired_draw(r, found_choice, by_seed[r.seed], baseline_choice) for r in found]


@dataclass(frozen=True)
class Interval:
    """A point estimate and its two-sided interval."""

    estimate: float
    low: float
    high: float

    def within(self, low: float, high: float) -> bool:
        return low <= self.low and self.high <= high


NOT_GIVEN = Interval(float("nan"), float("nan"), float("nan"))
ONE_CELL = 0.90  # the share of a cell's instances :func:`one_cell`'s interval holds


def one_cell(values_deg, share: float = ONE_CELL) -> Interval:
    """What one instance of the cell gives, from the draws' values (degrees, one per draw, each an instance): the
    geometric mean, and the log-normal prediction interval of one new instance, mean ± t(n − 1) · sd · √(1 + 1/n)
    of the logs at ``share``. :data:`NOT_GIVEN` from fewer than two draws, or where a draw's value is a penalty
    (an axis not measured, or registrations that failed on half its scans)."""
    x = np.asarray(values_deg, float)
    if len(x) < 2 or not np.all(np.isfinite(x)) or np.any(x <= 0) or np.any(x >= np.degrees(FAILED_ERROR)):
        return NOT_GIVEN
    logs = np.log(x)
    half = stats_t.ppf((1.0 + share) / 2.0, len(x) - 1) * logs.std(ddof=1) * math.sqrt(1.0 + 1.0 / len(x))
    mean = float(logs.mean())
    return Interval(math.exp(mean), math.exp(mean - half), math.exp(mean + half))


@dataclass(frozen=True)
class AxisError:
    """A layout's predicted error on one axis in the cell (degrees): the median and p75 over a draw's scans,
    expected over draws, with intervals; and ``one_cell``, the median one instance of the cell gives, with the
    interval of :func:`one_cell` (:data:`NOT_GIVEN` where unknown)."""

    axis: str
    median_deg: Interval
    p75_deg: Interval
    one_cell: Interval = NOT_GIVEN


@dataclass(frozen=True)
class AxisRatio:
    """One axis: its test ``ratio`` (the hand layout's score over that score with this axis's share the
    found layout's), hand / found of its median and of its p75, and ``failed``: the share of scans on which
    the found layout's registration for the axis failed, less the hand one's (a difference, not a ratio)."""

    axis: str
    ratio: Interval
    median: Interval
    p75: Interval
    failed: Interval = Interval(0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ConfidentVerdict:
    """Found vs. hand for one k, with confidence. ``found_name`` and ``baseline_name`` name the choices as
    their layouts name sensors (e.g. "F1F3", "S1S2"); ``reference`` says what the hand side is ("hand",
    "conventional"). ``more_draws``: under UNDECIDED, the draws to add that would settle it at the present
    estimates (None when no number would); ``seconds_per_draw`` (NaN unknown) turns it into minutes; ``ended``:
    what ended the race of an UNDECIDED one. Its lines
    are :mod:`optipose.verdict.words`' (:func:`~optipose.verdict.words.confident_line`)."""

    k: int
    decision: Decision
    found_name: str
    baseline_name: str
    score: Interval  # hand / found
    axes: tuple[AxisRatio, ...]
    found: tuple[AxisError, ...]
    baseline: tuple[AxisError, ...]
    found_score_deg: Interval
    baseline_score_deg: Interval
    n_draws: int
    n_scans: int  # the scans of every draw together
    tolerance: float
    confidence: float
    more_draws: int | None = None
    seconds_per_draw: float = float("nan")
    reference: str = "hand"
    baseline_k: int = 0  # the hand choice's size when it differs from k (fewer found sensors against more hand ones)
    failures: float = (
        0.01  # the share of an axis's scans found may fail on beyond hand's (Rules.failures); NaN: not applied
    )
    kept: bool = (
        False  # the found side is the baseline's own choice, the search's answer where it beat the found layout
    )
    # how a race left it UNDECIDED: "draws" (its budget's draws ran out), "clock" (a user's clock ended it), "ends" (a
    # BUY across a cell's ranges not shown at their ends) or "kinds" (a BUY in a cell the user did not name, not shown
    # in every common kind: both optipose.search.kinds), "" (decided, or not raced)
    ended: str = ""
    ruling: Ruling | None = None  # in a cell of ranges: the range whose magnitude decides which layout is better

    @property
    def more_minutes(self) -> float:
        """Minutes the ``more_draws`` would take (NaN when unknown)."""
        return float("nan") if self.more_draws is None else self.more_draws * self.seconds_per_draw / 60.0

    @property
    def unmeasured(self) -> list[str]:
        """The axes neither layout measures in any draw (unobservable, or failed: the penalty throughout)."""
        return [
            f.axis
            for f, h in zip(self.found, self.baseline)
            if not_measured(f.median_deg) and not_measured(h.median_deg)
        ]


@dataclass(frozen=True)
class Verdicts:
    """A search's verdicts with confidence: ``by_k``, k → found vs. the baseline's choice of as many sensors (k
    ascending), and ``fewer``: one found sensor against the baseline's largest choice, on the same draws (None
    without it)."""

    by_k: dict[int, ConfidentVerdict] = field(default_factory=dict)
    fewer: ConfidentVerdict | None = None

    def __post_init__(self):
        object.__setattr__(self, "by_k", dict(sorted(self.by_k.items())))

    def in_order(self) -> tuple[ConfidentVerdict, ...]:
        """Every verdict: by k, then ``fewer`` (the rows of ``verdict.csv``)."""
        return (*self.by_k.values(), *([self.fewer] if self.fewer is not None else []))


def raced_in(k: int, kinds: dict[str, Verdicts]) -> dict[str, ConfidentVerdict]:
    """Cell → k's verdict there, of the cells a search's BUYs were raced again in (``kinds``: cell → their
    :class:`Verdicts`, :mod:`optipose.search.kinds`) that raced k; empty where none did."""
    return {name: v.by_k[k] for name, v in kinds.items() if k in v.by_k}


def borne_out(k: int, kinds: dict[str, Verdicts]) -> bool:
    """Whether k's BUY was a BUY again in every cell it was raced again in (:func:`raced_in`; True where none raced
    it): what keeps a search's BUY one (:func:`optipose.search.kinds.qualified`) and its line's colour."""
    return all(v.decision == Decision.BUY for v in raced_in(k, kinds).values())


def at_ends(names) -> bool:
    """Whether the cells a search's BUYs were raced again in are the ends of a cell's ranges (``NAME:low``,
    ``NAME:high``), not other kinds of cell."""
    names = list(names)
    return bool(names) and all(str(name).endswith((":low", ":high")) for name in names)


def compare_draws(
    draws: Sequence[PairedDraw],
    rules: Rules = Rules(),
    *,
    k: int = 0,
    found_name: str = "found",
    baseline_name: str = "hand",
    reference: str = "hand",
    seconds_per_draw: float = float("nan"),
    baseline_k: int = 0,
    kept: bool = False,
) -> ConfidentVerdict:
    """The verdict on paired draws (one per seed, each the same scans for both layouts)."""
    if not draws:
        raise ValueError("a verdict needs at least one paired draw")
    n_scans = [len(d.found) for d in draws]
    per_draw = [
        draw_statistics(d, rules.replicates, np.random.default_rng([rules.seed, i])) for i, d in enumerate(draws)
    ]
    mean, boot = nested_replicates(per_draw, rules)
    point, samples = log_quantities(mean, rules.statistic), log_quantities(boot, rules.statistic)
    widen = widening(per_draw, samples, rules, n_scans)
    c = rules.confidence
    iv = [Interval(*log_interval(point[i], samples[:, i], widen[i], c)) for i in range(10)]
    degrees = lambda v: np.rad2deg(np.exp(v))  # noqa: E731
    iv += [Interval(*log_interval(point[i], samples[:, i], widen[i], c, degrees)) for i in range(10, 24)]
    failed = [Interval(*f) for f in failed_shares(draws, c)]
    axes = tuple(AxisRatio(axis, iv[1 + j], iv[4 + j], iv[7 + j], failed[j]) for j, axis in enumerate(AXES))
    cells = {  # each draw's median per axis, degrees: what one instance gives
        side: np.degrees([np.median(getattr(d, side), axis=0) for d in draws]) for side in ("found", "baseline")
    }
    found = tuple(
        AxisError(axis, iv[10 + j], iv[13 + j], one_cell(cells["found"][:, j])) for j, axis in enumerate(AXES)
    )
    baseline = tuple(
        AxisError(axis, iv[16 + j], iv[19 + j], one_cell(cells["baseline"][:, j])) for j, axis in enumerate(AXES)
    )
    # one found sensor against more hand ones asks whether it matches them, not whether it is worth buying
    futility = baseline_k in (0, k)
    decision, more = _decide(iv[0], axes, rules.tolerance, rules.failures, len(draws), futility)
    return ConfidentVerdict(
        k=k,
        decision=decision,
        found_name=found_name,
        baseline_name=baseline_name,
        score=iv[0],
        axes=axes,
        found=found,
        baseline=baseline,
        found_score_deg=iv[22],
        baseline_score_deg=iv[23],
        n_draws=len(draws),
        n_scans=sum(n_scans),
        tolerance=rules.tolerance,
        confidence=c,
        more_draws=more,
        seconds_per_draw=seconds_per_draw,
        reference=reference,
        baseline_k=baseline_k,
        failures=rules.failures,
        kept=kept,
    )


def _decide(
    score: Interval, axes: tuple[AxisRatio, ...], tolerance: float, failures: float, n: int, futility: bool = True
) -> tuple[Decision, int | None]:
    """The decision from the intervals (module docstring) and, when UNDECIDED, the draws to add; ``futility``:
    a score that cannot gain more than the tolerance is a KEEP (not where fewer sensors are to match more)."""
    floor, ceiling = 1.0 / (1.0 + tolerance), 1.0 + tolerance
    if score.high < 1.0 or any(a.ratio.high < floor or a.failed.low > failures for a in axes):
        return Decision.KEEP, None
    if score.low > 1.0 and all(a.ratio.low >= floor and a.failed.high <= failures for a in axes):
        return Decision.BUY, None
    if score.within(floor, ceiling) and all(a.ratio.within(floor, ceiling) and a.failed.high <= failures for a in axes):
        return Decision.TIE, None
    if futility and score.high < ceiling:  # found gains less than a TIE allows, and may be worse: nothing to buy
        return Decision.KEEP, None
    return Decision.UNDECIDED, _more_draws(score, axes, math.log(ceiling), failures, n, futility)


def _needed(interval: Interval, bound: float, above: bool, n: int, log: bool = True) -> float:
    """Draws at which the interval's side towards ``bound`` (a log ratio; with ``log`` False, the interval's own
    unit) clears it at the same estimate, the width ∝ 1/√draws; inf when the estimate itself is on the wrong side."""
    at = (lambda v: math.log(max(v, 1e-300))) if log else float
    m = at(interval.estimate)
    half = abs(m - at(interval.low if above else interval.high))
    gap = (m - bound) if above else (bound - m)
    if (
        not log and gap == 0 and half == 0
    ):  # a failed share exactly at its bound, no spread: met already (its test is <=)
        return float(n)
    if gap <= 0:
        return math.inf
    return n * (half / gap) ** 2 if half > 0 else float(n)


def _more_draws(
    score: Interval, axes: tuple[AxisRatio, ...], tol: float, failures: float, n: int, futility: bool = True
) -> int | None:
    """The fewest draws to add for some decision to be reached at the present estimates (None: none would)."""
    ratios, failed = [a.ratio for a in axes], [a.failed for a in axes]
    buy = max(
        [_needed(score, 0.0, True, n)]
        + [_needed(a, -tol, True, n) for a in ratios]
        + [_needed(f, failures, False, n, log=False) for f in failed]
    )
    keep = min(
        [_needed(score, 0.0, False, n)]
        + [_needed(score, tol, False, n) if futility else math.inf]
        + [_needed(a, -tol, False, n) for a in ratios]
        + [_needed(f, failures, True, n, log=False) for f in failed]
    )
    tie = max(
        [max(_needed(i, -tol, True, n), _needed(i, tol, False, n)) for i in [score, *ratios]]
        + [_needed(f, failures, False, n, log=False) for f in failed]
    )
    best = min(buy, keep, tie)
    return None if not math.isfinite(best) else max(1, math.ceil(best) - n)
