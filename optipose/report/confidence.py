"""The verdict with confidence (issue #33): two tables and one picture, the first thing a purchaser reads.

Per k: the decision (BUY, KEEP, TIE, UNDECIDED), the found choice and the baseline's, baseline / found in sum
with its interval, and each layout's predicted median |error| per axis in the cell with its interval; then what one
cell gives (the interval of one instance's median, :func:`~optipose.verdict.confidence.one_cell`); the picture draws
the expected medians per axis. Reads :class:`~optipose.verdict.confidence.ConfidentVerdict`
records only; the lines and cells are :mod:`optipose.verdict.words`', the ones the terminal prints.
"""

from __future__ import annotations

import math

from optipose.report.document import Block, Figure, Paragraph, Table
from optipose.report.figures import verdict_intervals
from optipose.verdict.confidence import ONE_CELL, Decision, Verdicts, borne_out
from optipose.verdict.words import (
    IDEAL_CELL,
    confident_line,
    fewer_line,
    interval_cell,
    kinds_line,
    mount_line,
    one_cell_cell,
    open_line,
    ruling_line,
    ratio_cell,
)

__all__ = ["confident_blocks", "confident_css"]

_CSS = {Decision.BUY: "verdict good", Decision.KEEP: "verdict bad", Decision.TIE: "verdict info"}


def confident_css(decision: Decision) -> str:
    """good: buy; bad: keep the baseline; info: a tie; mixed: undecided."""
    return _CSS.get(decision, "verdict mixed")


def confident_blocks(
    verdicts: Verdicts, cell: str = "ideal", layouts: dict | None = None, baseline=None, kinds: dict | None = None
) -> list[Block]:
    """The verdict's lines, what a BUY mounts and keeps (:func:`mount_line`), its table and its picture (empty
    without verdicts). ``cell``: the cell's name, which the caption says the errors are predicted in;
    ``layouts``: k → the found layout, ``baseline``: the baseline's; ``kinds``: cell → the BUYs raced again in
    that common kind of cell (:func:`kinds_line`)."""
    if not verdicts.by_k:
        return []
    ordered = list(verdicts.by_k.values())
    label = ordered[0].reference
    blocks: list[Block] = [Paragraph(confident_line(v), confident_css(v.decision)) for v in ordered]
    blocks += [Paragraph(line.strip(), "verdict info") for v in ordered if (line := open_line(v))]
    blocks += [Paragraph(line.strip(), "verdict info") for v in ordered if (line := ruling_line(v))]
    for v in ordered:  # a BUY raced again in the common kinds of cell: good where it holds in every one
        if line := kinds_line(v.k, kinds or {}):
            blocks.append(Paragraph(line.strip(), "verdict good" if borne_out(v.k, kinds) else "verdict mixed"))
    blocks += [
        Paragraph(line, "verdict good") for v in ordered if (line := mount_line(v, (layouts or {}).get(v.k), baseline))
    ]
    if cell == "ideal":
        blocks.append(Paragraph("These verdicts hold " + IDEAL_CELL + ".", "verdict mixed"))
    if verdicts.fewer is not None:
        blocks.append(Paragraph(fewer_line(verdicts.fewer), confident_css(verdicts.fewer.decision)))
    rows = []
    for v in ordered:
        rows.append(
            (
                f"k={v.k}",
                str(v.decision),
                "found " + v.found_name,
                ratio_cell(v.score),
                *(interval_cell(a.median_deg) for a in v.found),
                str(v.n_draws),
            )
        )
        rows.append(("", "", f"{label} {v.baseline_name}", "", *(interval_cell(a.median_deg) for a in v.baseline), ""))
    v = ordered[0]  # its failures NaN: a verdict from before the failures' rule, whose caption leaves it out
    caption = (
        f"Predicted median |error| per axis in the {cell} cell (mdeg), each with its {100 * v.confidence:.1f} % interval "
        f"from paired draws of the cell and a bootstrap over scans; {label} / found in sum; BUY needs the interval of "
        f"the sum above 1, no axis of the found layout adding more than {100 * v.tolerance:.0f} % to the {label} layout's total"
        + (
            f" and none failing its registration on more than {100 * v.failures:g} % of the scans beyond the {label} layout's."
            if v.failures == v.failures
            else "."
        )
    )
    blocks.append(
        Table(
            ("k", "verdict", "layout", f"{label} / found", "roll", "pitch", "yaw", "draws"),
            tuple(rows),
            caption,
            anchor="confident-verdict",
        )
    )
    if any(math.isfinite(a.one_cell.low) for v in ordered for a in (*v.found, *v.baseline)):
        rows = []  # a folder from before the one-cell interval has none to show
        for v in ordered:
            rows.append((f"k={v.k}", f"found {v.found_name}", *(one_cell_cell(a) for a in v.found)))
            rows.append(("", f"{label} {v.baseline_name}", *(one_cell_cell(a) for a in v.baseline)))
        caption = (
            f"What one {cell} cell gives: the median |error| per axis (mdeg) of one instance of the cell (its part as "
            "made, its calibration and, in a cell of ranges, its magnitudes), and the interval "
            f"{100 * ONE_CELL:.0f} % of the instances fall in, from the spread of the draws (each draw one instance); "
            "yours is one of them. The table above gives the median expected over instances, with its interval."
        )
        blocks.append(Table(("k", "layout", "roll", "pitch", "yaw"), tuple(rows), caption, anchor="one-cell"))
    blocks.append(
        Figure(
            verdict_intervals(ordered),
            "verdict_intervals.png",
            f"Found (blue) and {label} (orange): predicted median |error| per axis and k, with intervals.",
        )
    )
    return blocks
