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
hand's (:func:`_failed`: a Student interval over the draws, at least the scans' own spread), which may exceed 0 by
at most ``Rules.failures`` (one scan in a hundred): a failed registration is a part scanned again or set aside. The
decision:

- KEEP: the score's interval lies below 1 (hand is better), or some axis's test lies below 1 / (1 + tolerance),
  or found fails some axis more often than hand by more than ``failures``;
- BUY: the score's interval lies above 1, no axis's test reaches below 1 / (1 + tolerance) and no axis's failed
  share reaches above ``failures``;
- TIE: the score's and every axis's test's intervals lie within [1 / (1 + tolerance), 1 + tolerance], and no
  failed share reaches above ``failures`` (found failing less is no reason to move a bracket on its own);
- UNDECIDED: none of these, with how many more draws would settle it (the interval's width ∝ 1/√draws).

Each test reads one side of a two-sided interval, so at 95 % a BUY or a KEEP is one-sided at 97.5 %.
:mod:`optipose.verdict.racing` adds draws until the decision is not UNDECIDED or a budget ends. The same
draws and :class:`Rules` give the same verdict.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.stats import norm as stats_norm
from scipy.stats import t as stats_t

from optipose.evaluate.assignment import UNOBSERVABLE_PENALTY, Choice, not_measured
from optipose.evaluate.objective import AXES, StatisticConfig
from optipose.evaluate.statistics import FAILED_ERROR
from optipose.verdict.rules import Rules

__all__ = [
    "BUY",
    "KEEP",
    "TIE",
    "UNDECIDED",
    "DECISIONS",
    "PairedDraw",
    "Interval",
    "AxisError",
    "AxisRatio",
    "ConfidentVerdict",
    "scan_errors",
    "paired_draw",
    "paired_draws",
    "compare_draws",
    "FEWER",
    "split",
]

BUY, KEEP, TIE, UNDECIDED = "BUY", "KEEP", "TIE", "UNDECIDED"
FEWER = "fewer"  # the key, among a search's verdicts by k, of one found sensor against the baseline's largest choice
DECISIONS = (BUY, KEEP, TIE, UNDECIDED)
_QUANTILES = (0.5, 0.75)  # median and p75, np.median's and np.percentile(75)'s linear interpolation
_READ = 0.95  # the widest interval read off the bootstrap replicates; a wider one is scaled from it (_interval)
_LOG_BOUND = 600.0  # an interval's sides in logs at most this far out: exp stays finite, in degrees too


@dataclass(frozen=True, eq=False)
class PairedDraw:
    """One draw (a seed) of both layouts: (n_scans, 3) |error| rad per scan and axis, the rows the same scans
    (compared by identity: its fields are arrays)."""

    seed: int
    found: np.ndarray
    hand: np.ndarray

    def __post_init__(self):
        if self.found.shape != self.hand.shape or self.found.ndim != 2 or self.found.shape[1] != len(AXES):
            raise ValueError(
                f"a paired draw needs two (n_scans, 3) arrays, got {self.found.shape} and {self.hand.shape}"
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


def paired_draw(found, found_choice: Choice, hand, hand_choice: Choice) -> PairedDraw:
    """The paired draw of two evaluations on the same seed (common random numbers); a ValueError if they
    were not (another seed, other scans)."""
    if found.seed != hand.seed or found.n_scans != hand.n_scans:
        raise ValueError(
            f"not a paired draw: seed {found.seed} ({found.n_scans} scans) vs {hand.seed} ({hand.n_scans} scans)"
        )
    return PairedDraw(int(found.seed), scan_errors(found, found_choice), scan_errors(hand, hand_choice))


def paired_draws(found: Sequence, found_choice: Choice, hand: Sequence, hand_choice: Choice) -> list[PairedDraw]:
    """The paired draws of two lists of evaluations, matched by seed (in the found list's order)."""
    by_seed = {r.seed: r for r in hand}
    missing = [r.seed for r in found if r.seed not in by_seed]
    if missing:
        raise ValueError(f"no hand evaluation on seed(s) {missing}")
    return [paired_draw(r, found_choice, by_seed[r.seed], hand_choice) for r in found]


@dataclass(frozen=True)
class Interval:
    """A point estimate and its two-sided interval."""

    estimate: float
    low: float
    high: float

    def within(self, low: float, high: float) -> bool:
        return low <= self.low and self.high <= high


@dataclass(frozen=True)
class AxisError:
    """A layout's predicted error on one axis in the cell (degrees): the median and p75 over a draw's scans,
    expected over draws, with intervals."""

    axis: str
    median_deg: Interval
    p75_deg: Interval


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
    """Found vs. hand for one k, with confidence. ``found_name`` and ``hand_name`` name the choices as
    their layouts name sensors (e.g. "F1F3", "S1S2"); ``reference`` says what the hand side is ("hand",
    "conventional"). ``more_draws``: under UNDECIDED, the draws to add that would settle it at the present
    estimates (None when no number would); ``seconds_per_draw`` (NaN unknown) turns it into minutes."""

    k: int
    decision: str
    found_name: str
    hand_name: str
    score: Interval  # hand / found
    axes: tuple[AxisRatio, ...]
    found: tuple[AxisError, ...]
    hand: tuple[AxisError, ...]
    found_score_deg: Interval
    hand_score_deg: Interval
    n_draws: int
    n_scans: int  # the scans of every draw together
    tolerance: float
    confidence: float
    more_draws: int | None = None
    seconds_per_draw: float = float("nan")
    reference: str = "hand"
    hand_k: int = 0  # the hand choice's size when it differs from k (fewer found sensors against more hand ones)
    failures: float = (
        0.01  # the share of an axis's scans found may fail on beyond hand's (Rules.failures); NaN: not applied
    )
    kept: bool = (
        False  # the found side is the baseline's own choice, the search's answer where it beat the found layout
    )

    @property
    def more_minutes(self) -> float:
        """Minutes the ``more_draws`` would take (NaN when unknown)."""
        return float("nan") if self.more_draws is None else self.more_draws * self.seconds_per_draw / 60.0

    def line(self) -> str:
        """One line of at most 80 columns: the decision, hand / found in sum with its interval, the draws (and
        under UNDECIDED how many more would settle it), e.g.
        ``k=2: BUY F1F3 1.42x [1.21, 1.66] better than hand S1S2 (12 draws)``."""
        s, ref = self.score, f"{self.reference} {self.hand_name}"
        ratio = f"{s.estimate:.2f}x [{s.low:.2f}, {s.high:.2f}]"
        head = f"k={self.k}: {self.decision}"
        if len(self.unmeasured) == len(self.found):  # equal because neither measures anything: say that
            text = f"k={self.k}: nothing measured: {self.found_name} and {ref} see no {'/'.join(self.unmeasured)}"
            return text if len(text) <= 80 else f"k={self.k}: nothing measured: {self.found_name} and {ref} see no axis"
        tail = f"{self.n_draws} draw{'s' if self.n_draws != 1 else ''}"
        if self.decision == UNDECIDED and self.more_draws is not None:
            minutes = self.more_minutes
            took = (
                (f", {minutes:.0f} min" if minutes >= 1 else f", {60 * minutes:.0f} s")
                if math.isfinite(minutes)
                else ""
            )
            tail += f"; +{self.more_draws}{took}"
        if self.decision == KEEP:
            worse = [a.axis for a in self.axes if a.ratio.high < 1.0 / (1.0 + self.tolerance)]
            fails = [a for a in self.axes if a.failed.low > self.failures]
            why = (f", worse on {'/'.join(worse)}" if worse else "") + "".join(
                f", fails {100 * a.failed.estimate:.1f} % more {a.axis}" for a in fails[:1]
            )
            # the reasons before the ratio where both do not fit
            texts = [
                f"{head} {ref}; {self.found_name} {ratio}{why}",
                f"{head} {ref}; {self.found_name}{why}",
                f"{head} {ref}{why}",
            ]
            text = next(
                (t for t in texts if len(f"{t} ({tail})") <= 80), next((t for t in texts if len(t) <= 80), texts[-1])
            )
        elif self.decision == BUY:
            text = f"{head} {self.found_name} {ratio} better than {ref}"
        elif self.decision == TIE and self.kept:
            text = f"{head} keep {ref}: no found layout beat it"  # the search answered with the baseline's own choice
        elif self.decision == TIE:
            text = f"{head} {self.found_name} {ratio} vs {ref}: keep {self.hand_name}"
        else:
            text = f"{head} {self.found_name} {ratio} vs {ref}"
        # undecided: the axis whose interval straddles the tolerance, where it fits
        open_ = [a for a in self.axes if a.ratio.low < 1.0 / (1.0 + self.tolerance) <= a.ratio.high]
        axis = "".join(f"; {a.axis} {a.ratio.estimate:.2f}x [{a.ratio.low:.2f}, {a.ratio.high:.2f}]" for a in open_[:1])
        failing = [
            a for a in self.axes if a.failed.low <= self.failures < a.failed.high
        ]  # found may fail more than allowed
        fails = "".join(f"; {a.axis} fails {100 * a.failed.estimate:+.1f} %" for a in failing[:1])
        axis = (axis or fails) if self.decision == UNDECIDED else ""
        # the failed share is in no table: it goes before the draws to add where both do not fit
        order = (f"{text}{axis}", f"{text} ({tail})") if axis == fails else (f"{text} ({tail})", f"{text}{axis}")
        fits = [line for line in (f"{text}{axis} ({tail})", *order) if len(line) <= 80]
        return fits[0] if fits else text[:80]

    @property
    def unmeasured(self) -> list[str]:
        """The axes neither layout measures in any draw (unobservable, or failed: the penalty throughout)."""
        return [
            f.axis for f, h in zip(self.found, self.hand) if not_measured(f.median_deg) and not_measured(h.median_deg)
        ]

    def fewer_line(self) -> str:
        """The comparison of fewer found sensors with more hand ones (``hand_k`` > k) in one line of at most 80
        columns, e.g. ``fewer sensors: found F1 alone matches hand S1S2S3 within 10 % (1.02x [0.95, 1.08])``
        (shorter where the names are long: ``fewer: F1 alone matches conventional S1S2S3 within 10 % …``)."""
        s = self.score
        ratio, ref = f"{s.estimate:.2f}x [{s.low:.2f}, {s.high:.2f}]", f"{self.reference} {self.hand_name}"
        template = (
            "nothing measured by {who} or {ref}"
            if len(self.unmeasured) == len(self.found)
            else {
                BUY: "{who} is better than {ref}: {ratio}",
                KEEP: "{who} does not match {ref} ({ratio})",
                TIE: "{who} matches {ref} within " + f"{100 * self.tolerance:.0f}" + " % ({ratio})",
            }.get(self.decision, "{who} vs {ref}: {ratio}, not settled")
        )
        found = "" if self.kept else "found "  # the search answered with one of the baseline's own
        lines = [
            f"{head}: " + template.format(who=who, ref=ref, ratio=ratio)
            for head, who in (
                ("fewer sensors", f"{found}{self.found_name} alone"),
                ("fewer sensors", f"{self.found_name} alone"),
                ("fewer", f"{self.found_name} alone"),
            )
        ]
        return next((line for line in lines if len(line) <= 80), lines[-1][:80])

    def axis_lines(self) -> list[str]:
        """Per axis, found's and hand's predicted median / p75 (mdeg) with intervals, each ≤ 80 columns."""
        out = []
        for f, h in zip(self.found, self.hand):
            cells = [
                f"{_mdeg(i.estimate)} [{_mdeg(i.low)}, {_mdeg(i.high)}]"
                for i in (f.median_deg, h.median_deg, f.p75_deg, h.p75_deg)
            ]
            out.append(f"  {f.axis:5} median found {cells[0]} hand {cells[1]} mdeg")
            out.append(f"  {'':5} p75    found {cells[2]} hand {cells[3]} mdeg")
        return out


def split(verdicts: dict) -> tuple[dict, "ConfidentVerdict | None"]:
    """A search's verdicts as (k → verdict, k ascending) and the :data:`FEWER` one (None without it)."""
    return {k: verdicts[k] for k in sorted(k for k in verdicts if k != FEWER)}, verdicts.get(FEWER)


def _mdeg(deg: float) -> str:
    return f"{1e3 * deg:.3g}"


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


def _draw_stats(draw: PairedDraw, replicates: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One draw's statistics (2 quantiles, 2 layouts, 3 axes) and (replicates, 2, 2, 3) of its scans
    resampled, the same scan indices for both layouts."""
    x = np.concatenate([draw.found, draw.hand], axis=1).T  # (6, n)
    observed = _quantiles(np.sort(x, axis=1)).reshape(2, 2, 3)
    index = rng.integers(0, x.shape[1], (replicates, x.shape[1]))
    boot = np.sort(x[:, index], axis=2)  # (6, replicates, n)
    return observed, np.moveaxis(_quantiles(boot), 2, 0).reshape(replicates, 2, 2, 3)


def _replicates(per_draw: list, rules: Rules) -> tuple[np.ndarray, np.ndarray]:
    """The observed statistics averaged over draws (2, 2, 3) and (replicates, 2, 2, 3) of the nested
    bootstrap: draws resampled, each one's statistics shrunk to the cells' spread plus its scans' resampling."""
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


def _quantities(stats: np.ndarray, statistic: StatisticConfig) -> np.ndarray:
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


def _widening(per_draw: list, boot: np.ndarray, rules: Rules, n_scans: list[int]) -> np.ndarray:
    """(24,) the factor each quantity's bootstrap deviations are scaled by: to the variance of a mean of D
    draws (the draws' spread over D, at least the scans' own) and the Student quantile of its degrees of
    freedom over the normal one. With one draw, the scans' variance alone."""
    d = len(per_draw)
    per = np.stack([_quantities(s, rules.statistic) for s, _ in per_draw])  # (D, 24)
    within = np.stack([_quantities(b, rules.statistic).var(axis=0) for _, b in per_draw]).mean(axis=0)
    between = per.var(axis=0, ddof=1) if d > 1 else within
    # the draws' spread, an estimate on D − 1 degrees of freedom, where it exceeds the scans' own (the cells
    # vary); else the scans' variance, known from every scan of every draw
    df = np.where(between > within, max(d - 1, 1), max(sum(n - 1 for n in n_scans), 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        tail = (1.0 + rules.confidence) / 2.0
        student = stats_t.ppf(tail, df) / stats_norm.ppf(tail)
        scale = np.sqrt(np.maximum(between, within) / d / boot.var(axis=0))
    return np.where(np.isfinite(scale), student * scale, 1.0)


def _interval(point: float, samples: np.ndarray, widen: float, confidence: float, unit=np.exp) -> Interval:
    """The percentile interval of log ``samples`` about log ``point``, its deviations scaled by ``widen``.
    Beyond :data:`_READ` the replicates' own tails are too thin to read (a racing look at 99.9 % would take
    the one or two most extreme of 2000), so the interval is read at :data:`_READ` and its deviations scaled
    by the normal quantiles' ratio: the skew of the 95 % interval, the width of the one asked for."""
    read = min(confidence, _READ)
    tail = 100.0 * (1.0 - read) / 2.0
    reach = stats_norm.ppf((1.0 + confidence) / 2.0) / stats_norm.ppf((1.0 + read) / 2.0)
    low, high = point + widen * reach * (np.percentile(samples, [tail, 100.0 - tail]) - point)
    low, high = np.clip(
        [low, high], -_LOG_BOUND, _LOG_BOUND
    )  # an unbounded side stays a finite number, not an overflow
    return Interval(float(unit(point)), float(unit(low)), float(unit(high)))


def compare_draws(
    draws: Sequence[PairedDraw],
    rules: Rules = Rules(),
    *,
    k: int = 0,
    found_name: str = "found",
    hand_name: str = "hand",
    reference: str = "hand",
    seconds_per_draw: float = float("nan"),
    hand_k: int = 0,
    kept: bool = False,
) -> ConfidentVerdict:
    """The verdict on paired draws (one per seed, each the same scans for both layouts)."""
    if not draws:
        raise ValueError("a verdict needs at least one paired draw")
    n_scans = [len(d.found) for d in draws]
    per_draw = [_draw_stats(d, rules.replicates, np.random.default_rng([rules.seed, i])) for i, d in enumerate(draws)]
    mean, boot = _replicates(per_draw, rules)
    point, samples = _quantities(mean, rules.statistic), _quantities(boot, rules.statistic)
    widen = _widening(per_draw, samples, rules, n_scans)
    c = rules.confidence
    iv = [_interval(point[i], samples[:, i], widen[i], c) for i in range(10)]
    iv += [_interval(point[i], samples[:, i], widen[i], c, lambda v: np.rad2deg(np.exp(v))) for i in range(10, 24)]
    failed = _failed(draws, c)
    axes = tuple(AxisRatio(axis, iv[1 + j], iv[4 + j], iv[7 + j], failed[j]) for j, axis in enumerate(AXES))
    found = tuple(AxisError(axis, iv[10 + j], iv[13 + j]) for j, axis in enumerate(AXES))
    hand = tuple(AxisError(axis, iv[16 + j], iv[19 + j]) for j, axis in enumerate(AXES))
    decision, more = _decide(iv[0], axes, rules.tolerance, rules.failures, len(draws))
    return ConfidentVerdict(
        k=k,
        decision=decision,
        found_name=found_name,
        hand_name=hand_name,
        score=iv[0],
        axes=axes,
        found=found,
        hand=hand,
        found_score_deg=iv[22],
        hand_score_deg=iv[23],
        n_draws=len(draws),
        n_scans=sum(n_scans),
        tolerance=rules.tolerance,
        confidence=c,
        more_draws=more,
        seconds_per_draw=seconds_per_draw,
        reference=reference,
        hand_k=hand_k,
        failures=rules.failures,
        kept=kept,
    )


def _failed(draws: Sequence[PairedDraw], confidence: float) -> list[Interval]:
    """Per axis, the share of scans on which found's registration failed (its error the penalty: a failed
    registration, or an axis its choice does not measure) less hand's, averaged over draws, with a two-sided
    Student interval at ``confidence``: the draws' spread on D − 1 degrees of freedom where it exceeds the
    scans' own (the paired per-scan differences' variance over a draw's scans), else the scans' on all of theirs.
    Exactly [0, 0] where neither layout fails, or both fail on the same scans."""
    diff = [
        (d.found >= FAILED_ERROR).astype(float) - (d.hand >= FAILED_ERROR) for d in draws
    ]  # (n, 3) each, in {-1, 0, 1}
    per = np.stack([x.mean(axis=0) for x in diff])  # (D, 3)
    within = np.mean([x.var(axis=0, ddof=1) / len(x) if len(x) > 1 else np.zeros(len(AXES)) for x in diff], axis=0)
    between = per.var(axis=0, ddof=1) if len(draws) > 1 else within
    df = np.where(between > within, max(len(draws) - 1, 1), max(sum(len(x) - 1 for x in diff), 1))
    half = stats_t.ppf((1.0 + confidence) / 2.0, df) * np.sqrt(np.maximum(between, within) / len(draws))
    mean = per.mean(axis=0)
    return [Interval(float(m), float(max(-1.0, m - h)), float(min(1.0, m + h))) for m, h in zip(mean, half)]


def _decide(
    score: Interval, axes: tuple[AxisRatio, ...], tolerance: float, failures: float, n: int
) -> tuple[str, int | None]:
    """The decision from the intervals (module docstring) and, when UNDECIDED, the draws to add."""
    floor, ceiling = 1.0 / (1.0 + tolerance), 1.0 + tolerance
    if score.high < 1.0 or any(a.ratio.high < floor or a.failed.low > failures for a in axes):
        return KEEP, None
    if score.low > 1.0 and all(a.ratio.low >= floor and a.failed.high <= failures for a in axes):
        return BUY, None
    if score.within(floor, ceiling) and all(a.ratio.within(floor, ceiling) and a.failed.high <= failures for a in axes):
        return TIE, None
    return UNDECIDED, _more_draws(score, axes, math.log(ceiling), failures, n)


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


def _more_draws(score: Interval, axes: tuple[AxisRatio, ...], tol: float, failures: float, n: int) -> int | None:
    """The fewest draws to add for some decision to be reached at the present estimates (None: none would)."""
    ratios, failed = [a.ratio for a in axes], [a.failed for a in axes]
    buy = max(
        [_needed(score, 0.0, True, n)]
        + [_needed(a, -tol, True, n) for a in ratios]
        + [_needed(f, failures, False, n, log=False) for f in failed]
    )
    keep = min(
        [_needed(score, 0.0, False, n)]
        + [_needed(a, -tol, False, n) for a in ratios]
        + [_needed(f, failures, True, n, log=False) for f in failed]
    )
    tie = max(
        [max(_needed(i, -tol, True, n), _needed(i, tol, False, n)) for i in [score, *ratios]]
        + [_needed(f, failures, False, n, log=False) for f in failed]
    )
    best = min(buy, keep, tie)
    return None if not math.isfinite(best) else max(1, math.ceil(best) - n)
