"""What the scans gave: per-axis error for every sensor subset (the paper's Figures 5–7) and the points
per scan and sensor (Figure 9), from an :class:`~optipose.evaluate.evaluator.EvaluationResult`."""

from __future__ import annotations

from optipose.report import figures
from optipose.report.document import Block, Figure, Heading, Paragraph, Table

__all__ = ["scan_blocks"]


def scan_blocks(result, label: str, slug: str, note: str = "") -> list[Block]:
    """Box plots of |error| per subset and axis, the points per scan and sensor, and a small points table.

    result : EvaluationResult; label : what to call the layout (``found k=3``, ``hand``); slug : file names.
    """
    n_scans = result.per_scan["scan"].nunique()
    blocks: list[Block] = [Heading(f"Errors and points: {label}", 3)]
    if note:
        blocks.append(Paragraph(note, "note"))
    blocks.append(
        Figure(
            figures.subset_boxplots(result.per_scan, f"{label}: |error| per sensor subset over {n_scans} scans"),
            f"{slug}_errors.png",
            f"{label}: per-axis |error| (mdeg) of every sensor subset, {n_scans} scans "
            "(box: quartiles, line: median; the paper's Figures 5-7)",
        )
    )
    blocks.append(
        Figure(
            figures.point_counts(result.points, f"{label}: points per scan and sensor"),
            f"{slug}_points.png",
            f"{label}: points per scan and sensor after down-sampling (the paper's Figure 9)",
        )
    )
    summary = result.points.groupby("sensor", sort=False).agg(
        raw_min=("n_points", "min"),
        raw_median=("n_points", "median"),
        down_min=("n_points_down", "min"),
        down_median=("n_points_down", "median"),
        down_max=("n_points_down", "max"),
    )
    rows = tuple((str(name), *(f"{v:.0f}" for v in row)) for name, row in summary.iterrows())
    blocks.append(
        Table(
            ("sensor", "raw min", "raw median", "down-sampled min", "down-sampled median", "down-sampled max"),
            rows,
            f"{label}: points per scan (raw profiles and after voxel down-sampling)",
        )
    )
    return blocks
