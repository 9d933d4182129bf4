"""The verdict with confidence (issue #33): one table and one picture, the first thing a purchaser reads.

Per k: the decision (BUY, KEEP, TIE, UNDECIDED), the found choice and the baseline's, baseline / found in sum
with its interval, and each layout's predicted median |error| per axis in the cell with its interval; the
picture draws the same medians per axis. Reads :class:`~optipose.verdict.confidence.ConfidentVerdict`
records only; the lines are the ones the terminal prints (:meth:`ConfidentVerdict.line`).
"""

from __future__ import annotations

from optipose.evaluate.assignment import not_measured
from optipose.verdict.confidence import BUY, KEEP, TIE, split
from optipose.report.document import Block, Figure, Paragraph, Table
from optipose.report.figures import verdict_intervals

__all__ = ["confident_blocks", "confident_css", "interval_cell", "mount_line", "IDEAL_CELL"]

IDEAL_CELL = (
    "in the ideal cell (the CAD part, an exact robot and calibration): run without --cell ideal, or "
    "with a cell file of yours, for the errors of a real cell before buying"
)

_CSS = {BUY: "verdict good", KEEP: "verdict bad", TIE: "verdict info"}


def confident_css(decision: str) -> str:
    """good: buy; bad: keep the baseline; info: a tie; mixed: undecided."""
    return _CSS.get(decision, "verdict mixed")


def interval_cell(interval, scale: float = 1e3, digits: int = 3) -> str:
    """``0.203 [0.151, 0.262]``: an estimate and its interval (scale 1e3: degrees shown in mdeg; ``digits``
    significant ones)."""
    if not_measured(interval):
        return "not measured"
    # rounded to ``digits`` significant ones but written out (110, not 1.1e+02: a column of mdeg reads at a glance)
    e, lo, hi = (f"{float(f'{scale * x:.{digits}g}'):g}" for x in (interval.estimate, interval.low, interval.high))
    return f"{e} [{lo}, {hi}]" if digits > 2 else f"{e} [{lo}-{hi}]"


def mount_line(verdict, found, hand) -> str:
    """What a BUY asks of the cell, in one line: the found sensors its choice uses that are new (their poses
    follow in the layouts), the baseline's it keeps in their brackets and those it frees, e.g.
    ``k=2: mount F1 (new), keep S2; S1 freed``; "" for another decision. ``found``, ``hand``: the
    :class:`~optipose.model.layout.Layout` of the found k sensors and the baseline's."""
    from optipose.model.layout import kept_sensors

    if verdict.decision != BUY or found is None or hand is None:
        return ""
    used = [n for n in found.names if n in verdict.found_name]
    kept = kept_sensors(found, hand)
    new = [n for n in used if n not in kept]
    keep = [kept[n] for n in used if n in kept]
    freed = [n for n in hand.names if n in verdict.hand_name and n not in keep]
    parts = ([f"mount {', '.join(new)} (new)"] if new else []) + ([f"keep {', '.join(keep)}"] if keep else [])
    return f"k={verdict.k}: " + ", ".join(parts) + (f"; {', '.join(freed)} freed" if freed else "")


def confident_blocks(verdicts: dict, cell: str = "ideal", layouts: dict | None = None, hand=None) -> list[Block]:
    """The verdict's lines, what a BUY mounts and keeps (:func:`mount_line`), its table and its picture (empty
    without verdicts). ``cell``: the cell's name, which the caption says the errors are predicted in;
    ``layouts``: k → the found layout, ``hand``: the baseline's."""
    by_k, fewer = split(verdicts)
    if not by_k:
        return []
    ordered = list(by_k.values())
    label = ordered[0].reference
    blocks: list[Block] = [Paragraph(v.line(), confident_css(v.decision)) for v in ordered]
    blocks += [
        Paragraph(line, "verdict good") for v in ordered if (line := mount_line(v, (layouts or {}).get(v.k), hand))
    ]
    if cell == "ideal":
        blocks.append(Paragraph("These verdicts hold " + IDEAL_CELL + ".", "verdict mixed"))
    if fewer is not None:
        blocks.append(Paragraph(fewer.fewer_line(), confident_css(fewer.decision)))
    rows = []
    for v in ordered:
        rows.append(
            (
                f"k={v.k}",
                v.decision,
                "found " + v.found_name,
                f"{v.score.estimate:.2f}x [{v.score.low:.2f}, {v.score.high:.2f}]",
                *(interval_cell(a.median_deg) for a in v.found),
                str(v.n_draws),
            )
        )
        rows.append(("", "", f"{label} {v.hand_name}", "", *(interval_cell(a.median_deg) for a in v.hand), ""))
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
    blocks.append(
        Figure(
            verdict_intervals(ordered),
            "verdict_intervals.png",
            f"Found (blue) and {label} (orange): predicted median |error| per axis and k, with intervals.",
        )
    )
    return blocks
