"""Robustness: each given layout against the hand one in every cell instance checked (held-out draws of a cell's
ranges, the ranges' ends, other presets), from the record :class:`~optipose.io.results.RobustnessResult`."""

from __future__ import annotations

import numpy as np

from optipose.report import figures
from optipose.report.document import Block, Figure, Heading, Paragraph, Table

__all__ = ["holds_blocks", "instance_blocks"]


def holds_blocks(result, label: str) -> list[Block]:
    """One line per given layout and k: in how many instances it holds (hand / layout of the score at least 1),
    and its weakest instance."""
    ratios = result.ratios()
    out = []
    for r in result.holds().itertuples(index=False):
        if r.layout == "hand":
            continue
        mine = ratios[(ratios.layout == r.layout) & (ratios.k == r.k)]
        weakest = mine.loc[mine.ratio.idxmin()]
        held = r.held == r.instances
        every = f"in {'every one' if held else r.held} of the {r.instances}"
        out.append(
            Paragraph(
                f"{r.layout} k={r.k}: holds {every} cell instances checked; {label} / found "
                f"{weakest.ratio:.3f}x at its weakest ({weakest.cell}, {weakest.instance})",
                "verdict good" if held else "verdict bad",
            )
        )
    return out


def instance_blocks(result, label: str) -> list[Block]:
    """Per given layout and k: a table of every instance (the layout's and the hand layout's score, the ratio,
    whether it holds) and a bar chart of the same."""
    rows, ratios = result.rows, result.ratios()
    blocks: list[Block] = []
    for (name, k), group in ratios.groupby(["layout", "k"], sort=False):
        if name == "hand":
            continue
        lines, bars = [], []
        for g in group.itertuples(index=False):
            mine = rows[(rows.layout == name) & (rows.k == k) & (rows.cell == g.cell) & (rows.instance == g.instance)]
            score, hand = float(mine.score_deg.iloc[0]), float(mine.hand_score_deg.iloc[0])
            lines.append(
                (
                    f"{g.cell}, {g.instance}",
                    f"{g.sensors}: {1e3 * score:.1f}",
                    f"{g.hand_sensors}: {1e3 * hand:.1f}",
                    f"{g.ratio:.3f}x",
                    "yes" if g.holds else "no",
                )
            )
            bars.append((f"{g.cell}, {g.instance}", float(np.deg2rad(score)), float(np.deg2rad(hand))))
        slug = "".join(c if c.isalnum() else "_" for c in str(name))
        blocks += [
            Heading(f"{name} (k={k}) in every cell instance", 3),
            Table(
                ("cell, instance", "found (mdeg)", f"{label} (mdeg)", f"{label} / found", "holds"),
                tuple(lines),
                f"{name} vs. {label}: the paper's score (sum of per-axis median and p75), each layout choosing its "
                "subsets per axis in that instance",
                numeric=(False, True, True, True, False),
            ),
            Figure(
                figures.condition_bars(bars, label, f"{name} (k={k}) vs. {label} per cell instance"),
                f"instances_{slug}_k{k}.png",
                f"{name}: score in every cell instance, found vs. {label}",
            ),
        ]
    return blocks
