"""A layout against a reference (the hand-placed one): the one place that says "no worse on every axis".

The user's question is whether to keep the sensors they have or buy the found ones. A found choice of k
sensors wins outright when every axis's median and 75th percentile is at most the reference's; how far
it misses is the summed excess. Under a band of conditions (choices that carry ``under``, from
:mod:`optipose.evaluate.robust`: each noise level, its bracket draws aggregated) both tests hold level by
level: no worse on any axis at *every* level, the excess summed over them; the score compared is the
robust one. The search ranks and polishes with these, the CLI prints a
:class:`Verdict` per k, and :func:`optipose.io.load_result` gives a saved search's verdicts back.

An axis a choice does not measure (unobservable, or its registrations failed) compares as the score's
``UNOBSERVABLE_PENALTY`` (10°) on both statistics: worse than any measured error, equal to another
unmeasured one; :func:`unmeasured_line` says so in words, so a layout that cannot see an axis is never
read as a small error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optipose.evaluate.assignment import FAILED, UNOBSERVABLE, UNOBSERVABLE_PENALTY, AxisChoice, Choice

__all__ = [
    "dominates",
    "excess",
    "rank",
    "weighted_excess",
    "AxisGap",
    "Verdict",
    "bought",
    "UNCHECKED",
    "one_versus_many",
    "unmeasured_line",
    "mdeg",
]

_STATISTICS = ("median", "p75")


def _stat(axis: AxisChoice, statistic: str) -> float:
    """An axis's median or p75 (rad) as compared: ``UNOBSERVABLE_PENALTY`` where the choice does not measure it."""
    return getattr(axis, statistic) if axis.observable else UNOBSERVABLE_PENALTY


def dominates(choice: Choice, reference: Choice) -> bool:
    """Every axis's median and 75th percentile at most the reference's (at every condition of a band)."""
    return all(
        _stat(a, s) <= _stat(b, s)
        for c, r in _pairs(choice, reference)
        for a, b in zip(c.axes, r.axes)
        for s in _STATISTICS
    )


def excess(choice: Choice, reference: Choice, margin: float = 1.0) -> float:
    """How far (rad, summed) the choice's per-axis medians and 75th percentiles exceed margin × the
    reference's (summed over the conditions of a band)."""
    return float(
        sum(
            max(0.0, _stat(a, s) - margin * _stat(b, s))
            for c, r in _pairs(choice, reference)
            for a, b in zip(c.axes, r.axes)
            for s in _STATISTICS
        )
    )


def _pairs(choice: Choice, reference: Choice) -> list[tuple[Choice, Choice]]:
    """The choices to compare: condition by condition when both were evaluated under the same band."""
    if choice.under and len(choice.under) == len(reference.under):
        return [(c, r) for (_, c), (_, r) in zip(choice.under, reference.under)]
    return [(choice, reference)]


def rank(choice: Choice, reference: Choice | None) -> tuple[bool, float]:
    """Sort key of a choice against the reference: those no worse on every axis first, then the lower
    score (no reference: every choice counts as no worse)."""
    return (reference is not None and not dominates(choice, reference), choice.score)


def weighted_excess(values: np.ndarray, target: np.ndarray, margin: float, weights) -> float:
    """Σ weightᵢ · max(0, valueᵢ − margin · targetᵢ) over axes: the surrogate's per-axis scores (3,)
    against the reference's, in their unit."""
    return float(np.dot(weights, np.clip(np.asarray(values) - margin * np.asarray(target), 0.0, None)))


@dataclass(frozen=True)
class AxisGap:
    """An axis statistic on which the found choice is worse than the reference (rad)."""

    axis: str
    statistic: str  # median | p75
    found: float
    reference: float
    condition: str = ""  # under a band, the condition's label


@dataclass(frozen=True)
class Verdict:
    """Found vs. the reference for one k: the ratio in sum, the axes where found is worse, what to do."""

    k: int
    found: Choice
    reference: Choice
    layout: str = ""  # the found layout's name where several are compared (a robustness run), else ""

    @property
    def ratio(self) -> float:
        """Reference score over found score: above 1, the found choice is better in sum."""
        return float(np.rad2deg(self.reference.score)) / float(np.rad2deg(self.found.score))

    @property
    def worse(self) -> tuple[AxisGap, ...]:
        """Every axis statistic on which the found choice is worse (what :func:`dominates` tests)."""
        pairs = _pairs(self.found, self.reference)
        labels = [label for label, _ in self.found.under] if len(pairs) > 1 else [""]
        return tuple(
            AxisGap(f.axis, stat, _stat(f, stat), _stat(r, stat), label)
            for label, (c, ref) in zip(labels, pairs)
            for f, r in zip(c.axes, ref.axes)
            for stat in _STATISTICS
            if _stat(f, stat) > _stat(r, stat)
        )

    def levels(self) -> list[tuple[str, float, bool]]:
        """Under a band, per noise level: its label, reference score over found score, and whether found is
        no worse on every axis there; else []."""
        if len(self.found.under) != len(self.reference.under):
            return []
        return [
            (label, float(r.score / c.score), dominates(c, r))
            for (label, c), (_, r) in zip(self.found.under, self.reference.under)
        ]

    def band_advice(self, reference: str = "hand", nominal_no_worse: bool = False) -> str:
        """Under a band, for a found layout the nominal validation found no worse on every axis
        (``nominal_no_worse``) but the band does not: what it needs to be the better buy, in one line —

        - no worse at the lowest noise level(s) but not at some higher one: a bet on the sensor's noise on
          this part;
        - worse at the preset's noise (×1) once the brackets are off, though no worse with every bracket
          exact: its win rests on the brackets.

        "" otherwise (no band, no worse everywhere, or not no worse in the nominal cell either). The noise
        scale is read from the level's label (``evaluate.robust.by_level``: ``noise x<scale>…``)."""
        import re

        levels = [
            (float(m.group(1)), label.split(",")[0], ratio, ok, "bracket" in label)
            for label, ratio, ok in self.levels()
            if (m := re.match(r"noise x([0-9.]+)", label))
        ]
        levels.sort()
        if not nominal_no_worse or not levels or all(level[3] for level in levels):
            return ""
        head = f"k={self.k}: found {self.found.name}"
        if not levels[0][3]:
            scale, name, ratio, _, brackets = levels[0]
            if not (scale == 1.0 and brackets):
                return ""
            return (
                f"{head} is worse on some axis than {reference} {self.reference.name} at {name} ({ratio:.2f}x in sum) once the "
                f"brackets are off by the tolerance, though no worse with them exact: its win rests on brackets more precise "
                f"than the band's (optipose robustness --layout ... ranks which to make precise)"
            )
        n = next(i for i, level in enumerate(levels) if not level[3])
        held = ", ".join(f"{name} ({ratio:.2f}x better in sum)" for _, name, ratio, _, _ in levels[:n])
        lost = ", ".join(f"{name} ({ratio:.2f}x in sum)" for _, name, ratio, ok, _ in levels[n:] if not ok)
        return (
            f"{head} is no worse than {reference} {self.reference.name} on every axis at {held}, "
            f"worse on some axis at {lost}: it is the better buy only if the sensor's noise on this part, measured on the bench, "
            f"is {'no more than' if levels[n - 1][0] == 1 else f'at most {levels[n - 1][0]:g}x'} the preset's"
        )

    def ratios(self) -> list[tuple[str, float]]:
        """Under a band, (level label, reference score over found score) per noise level; else []."""
        return [(label, ratio) for label, ratio, _ in self.levels()]

    @property
    def no_worse(self) -> bool:
        """No axis statistic worse than the reference's: replacing the reference loses nothing."""
        return dominates(self.found, self.reference)

    @property
    def tie(self) -> bool:
        """Every axis statistic equal to the reference's (at every condition): replacing it gains nothing, as
        when the choice measures every axis on hand sensors a found layout keeps in their places."""
        return self.no_worse and dominates(self.reference, self.found)

    @property
    def failed(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The axes of the found and of the reference choice whose registrations failed too often
        (``AxisChoice.reason`` ``FAILED``): there the comparison is of two unknowns, not of errors."""
        return tuple(tuple(a.axis for a in c.axes if a.reason == FAILED) for c in (self.found, self.reference))

    def failed_line(self, reference: str = "hand") -> str:
        """The verdict when registrations failed on some axis of either choice ("" when none did): no
        ranking, what failed and where to look (the mesh of a part that is not a closed solid, most often)."""
        mine, theirs = self.failed
        if not mine and not theirs:
            return ""
        name, ref = self.found.name, self.reference.name
        what = [f"the registrations of found {name} failed on {', '.join(mine)}"] if mine else []
        what += [f"those of {reference} {ref} on {', '.join(theirs)}"] if theirs else []
        then = f"keep {ref} until they succeed" if mine else f"found {name} is not shown better there"
        return (
            f"k={self.k}: no verdict: {' and '.join(what)} in over a tenth of the scans (see per_scan.csv's failure "
            f"column; is the part's mesh a closed solid?): {then}"
        )

    def line(self, reference: str = "hand") -> str:
        """One line for a terminal or a report: ratio, every worse axis (mdeg), and keep or replace;
        ``reference`` names the baseline (``hand``, ``conventional``). Where registrations failed, no
        ranking: :meth:`failed_line`."""
        if failed := self.failed_line(reference):
            return failed
        ratio, name, ref = self.ratio, self.found.name, self.reference.name
        gaps = sorted(self.worse, key=lambda g: g.reference / g.found)  # the widest first
        worse = [
            f"{g.axis} {g.statistic} {_mdeg_or_none(g.found)} vs {_mdeg_or_none(g.reference)}"
            + (f" ({g.condition})" if g.condition else "")
            for g in gaps[:3]
        ]
        if len(gaps) > 3:
            worse.append(f"{len(gaps) - 3} more")
        robust = " at the worst over the band" if self.ratios() else ""
        than = f"x {'better' if ratio >= 1 else 'worse'} in sum{robust} than {reference} {ref}"
        head = f"k={self.k}: found {name} {ratio if ratio >= 1 else 1 / ratio:.2f}{than}"
        if self.tie:
            return f"k={self.k}: found {name} ties {reference} {ref} on every axis: keep {ref}"
        if worse and ratio < 1:
            return f"{head} and worse on {'; '.join(worse)} mdeg: keep {ref}"
        if worse:
            return f"{head}, but worse on {'; '.join(worse)} mdeg: keep {ref} if no axis may get worse"
        return f"{head}, no worse on any axis"


# what a nominal search's verdict says when it never checked its answer under a band (``--budget quick``)
UNCHECKED = (
    "checked in the ideal cell only (the preset's noise, every bracket exact), not under the band of a real "
    "cell: run --budget default before buying"
)


def bought(verdict: Verdict, band: Verdict | None = None) -> bool:
    """Whether to buy the found layout of ``verdict``: no worse than the reference on every axis and better on
    some (a tie gains nothing), and, when the search checked it under a band afterwards (``band``: the same
    k's verdict there), no worse at every level too; never when the found choice's registrations failed on
    some axis."""
    return verdict.no_worse and not verdict.tie and not verdict.failed[0] and (band is None or band.no_worse)


def _mdeg_or_none(rad: float) -> str:
    return "unmeasured" if rad == UNOBSERVABLE_PENALTY else f"{mdeg(rad):.3f}"


def unmeasured_line(k: int, found: Choice, reference: Choice | None = None, label: str = "hand") -> str:
    """One line when the found choice of k sensors measures some axis with none of its subsets ("" when it
    measures all three): the axes no found layout of k sensors observes, and those whose registrations
    failed too often — their error is unknown, not small — and whether the reference (``label``) does."""
    out = []
    for reason in dict.fromkeys(a.reason for a in found.axes if not a.observable):
        axes = [a.axis for a in found.axes if not a.observable and a.reason == reason]
        names = " and ".join(axes)
        theirs = [a for a in (reference.axes if reference is not None else ()) if a.axis in axes]
        also = ""
        if theirs:
            seen = [a.axis for a in theirs if a.observable]
            also = (
                f"; {label} {reference.name} does not either"
                if not seen
                else f"; {label} {reference.name} measures {' and '.join(seen)}"
            )
        if reason == UNOBSERVABLE:
            sensors = f"{k} sensor{'s' if k > 1 else ''}"
            out.append(
                f"{names} unobservable: no layout of {sensors} the search found observes {'it' if len(axes) == 1 else 'them'}{also}"
            )
        else:
            out.append(
                f"{names} not measured: the registrations of found {found.name} that observe {'it' if len(axes) == 1 else 'them'} "
                f"failed in over a tenth of the scans{also}"
            )
    return f"k={k}: " + "; ".join(out) + " (the error is unknown, not small)" if out else ""


def one_versus_many(one: Choice, many: Choice, reference: str = "hand-placed") -> str:
    """Whether one found sensor beats the reference's largest choice in sum: fewer sensors to buy."""
    beats = one.score < many.score
    return (
        f"one found sensor {'beats' if beats else 'does not beat'} the {reference} {many.name} in sum "
        f"({mdeg(one.score):.3f} vs {mdeg(many.score):.3f} mdeg)"
    )


def mdeg(rad: float) -> float:
    """Radians in millidegrees, the unit of the terminal's tables."""
    return 1e3 * float(np.rad2deg(rad))
