"""The verdict first: per k, found vs. the baseline (hand-placed, or the conventional placement) in sum and
per axis, whether one found sensor beats the baseline's three, and the paper's Table 1 side by side.

Reads :class:`~optipose.verdict.compare.Verdict` and :class:`~optipose.evaluate.assignment.Choice`
records only; the lines are :mod:`optipose.verdict.words`', the ones the terminal prints.
"""

from __future__ import annotations

from optipose.report.document import Block, Heading, Paragraph, Table
from optipose.verdict.compare import Verdict, bought
from optipose.verdict.words import UNCHECKED, mdeg_text, one_versus_many, unmeasured_line, verdict_line

__all__ = ["verdict_css", "verdict_blocks", "verdict_table", "table1_rows", "table1_side_by_side", "table1_alone"]

_AXES = ("roll", "pitch", "yaw")


def verdict_css(verdict: Verdict) -> str:
    """good: no worse on any axis; mixed: better in sum but worse somewhere; bad: worse in sum."""
    if verdict.no_worse:
        return "verdict good"
    return "verdict mixed" if verdict.ratio >= 1 else "verdict bad"


def verdict_blocks(
    verdicts: list[Verdict], found: dict, reference: dict, label: str, unchecked: bool = False
) -> list[Block]:
    """An axis a found layout does not measure, one line per k; one coloured line per k (the terminal's), then
    the headline: one found sensor vs. the baseline's largest.

    found, reference : k → Choice; label : ``hand`` or ``conventional``; unchecked : the search ran in the ideal
    cell (a layout no worse there is not yet one to buy).
    """
    blocks: list[Block] = [Heading("Verdict")]
    unmeasured = (unmeasured_line(k, choice, reference.get(k), label) for k, choice in found.items())
    blocks += [Paragraph(text, "verdict bad") for text in unmeasured if text]  # an axis no found layout measures, first
    if not verdicts:
        blocks.append(
            Paragraph(
                f"no verdict: nothing to compare the found layouts with ({label} layout missing)", "verdict mixed"
            )
        )
        return blocks
    blocks.append(verdict_table(verdicts, label, unchecked))
    if unchecked and any(v.no_worse for v in verdicts):
        blocks.append(Paragraph(UNCHECKED[0].upper() + UNCHECKED[1:] + ".", "verdict mixed"))
    for v in verdicts:
        refused = v.no_worse and not bought(v)  # a tie, or failed registrations
        blocks.append(Paragraph(verdict_line(v, label), "verdict mixed" if refused else verdict_css(v)))
    top = max(reference, default=0)
    if 1 in found and top > 1:
        beats = found[1].score < reference[top].score
        text = one_versus_many(found[1], reference[top], "hand-placed" if label == "hand" else label)
        blocks.append(
            Paragraph(
                ("Fewer sensors to buy: " if beats else "Fewer sensors to buy? No: ") + text,
                "verdict good" if beats else "verdict bad",
            )
        )
    return blocks


def verdict_table(verdicts: list[Verdict], label: str, unchecked: bool = False) -> Table:
    """Per k: found and baseline sensors, baseline / found in sum, per axis whether found is no worse
    (median and p75), and what to do (``unchecked``: the search ran in the ideal cell)."""
    rows = []
    buy = "better in the ideal cell; check it in a real cell before buying" if unchecked else "buy the found sensors"
    for v in verdicts:
        gaps = {g.axis for g in v.worse}
        decision = (
            buy
            if v.no_worse
            else (f"keep {label}" if v.ratio < 1 else f"better in sum; keep {label} if no axis may get worse")
        )
        if v.tie:
            decision = f"keep {label}: the found choice ties it"
        rows.append(
            (
                str(v.k),
                v.found.name,
                v.reference.name,
                f"{v.ratio:.2f}x",
                *("worse" if a in gaps else "no worse" for a in _AXES),
                decision,
            )
        )
    return Table(
        ("k", "found", label, f"{label} / found in sum", *_AXES, "what to do"),
        tuple(rows),
        f"found vs. {label} per k: above 1x the found choice is better in sum; per axis, no worse on median and "
        "75th percentile",
        numeric=(True, False, False, True, False, False, False, False),
    )


def _cell(axis) -> str:
    if not axis.observable:
        return axis.label
    return f"{mdeg_text(axis.median)} / {mdeg_text(axis.p75)} ({axis.name})"


def table1_rows(label: str, choice) -> tuple[str, ...]:
    """A Table 1 row: k, layout, sensors, per axis median / p75 mdeg (subset), score mdeg."""
    return (str(choice.k), label, choice.name, *(_cell(a) for a in choice.axes), mdeg_text(choice.score))


def table1_side_by_side(found: dict, reference: dict, label: str, caption: str) -> Table:
    """The paper's Table 1 shape with found and baseline rows per k."""
    rows = []
    for k in sorted({*found, *reference}):
        for name, choices in (("found", found), (label, reference)):
            if k in choices:
                rows.append(table1_rows(name, choices[k]))
    return Table(
        ("k", "layout", "sensors", *(f"{a} (mdeg)" for a in _AXES), "score (mdeg)"),
        tuple(rows),
        caption,
        numeric=(True, False, False, True, True, True, True),
    )


def table1_alone(choices: list, label: str, caption: str) -> Table:
    """Table 1 of one layout (an evaluation): one row per k."""
    rows = tuple(table1_rows(label, c) for c in choices)
    return Table(
        ("k", "layout", "sensors", *(f"{a} (mdeg)" for a in _AXES), "score (mdeg)"),
        rows,
        caption,
        numeric=(True, False, False, True, True, True, True),
    )
