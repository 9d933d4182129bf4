"""Robustness: found vs. the baseline at every condition of the band (noise levels, bracket draws), and
the spread a mounting tolerance adds per sensor and axis."""

from __future__ import annotations

import numpy as np

from optipose.report import figures
from optipose.report.document import Block, Figure, Heading, Paragraph, Table
from optipose.verdict.words import mdeg_text

__all__ = ["band_blocks", "bracket_blocks"]


def band_blocks(name: str, verdict, label: str) -> list[Block]:
    """Per condition of the band: found and baseline score, the ratio, and whether found is no worse on
    every axis there; a bar chart of the same. ``verdict`` carries the choices per condition."""
    found, reference = verdict.found, verdict.reference
    if not found.under or len(found.under) != len(reference.under):
        return []
    from optipose.verdict.compare import dominates

    rows, bars = [], []
    for (condition, f), (_, r) in zip(found.under, reference.under):
        ok = dominates(f, r)
        rows.append(
            (
                condition,
                mdeg_text(f.score),
                mdeg_text(r.score),
                f"{r.score / f.score:.2f}x",
                "yes"
                if ok
                else "no: " + ", ".join(a.axis for a, b in zip(f.axes, r.axes) if a.median > b.median or a.p75 > b.p75),
            )
        )
        bars.append((condition, f.score, r.score))
    rows.append(
        (
            "robust (over the band)",
            mdeg_text(found.score),
            mdeg_text(reference.score),
            f"{verdict.ratio:.2f}x",
            "yes" if verdict.no_worse else "no",
        )
    )
    slug = "".join(c if c.isalnum() else "_" for c in name)
    return [
        Heading(f"{name} (k={verdict.k}) at every condition of the band", 3),
        Table(
            ("condition", "found (mdeg)", f"{label} (mdeg)", f"{label} / found", "found no worse on every axis"),
            tuple(rows),
            f"{name} vs. {label} {reference.name}: score per condition (sum of per-axis median and p75)",
            numeric=(False, True, True, True, False),
        ),
        Figure(
            figures.condition_bars(
                bars, f"{label} {reference.name}", f"{name} {found.name} vs. {label} {reference.name}"
            ),
            f"band_{slug}_k{verdict.k}.png",
            f"{name}: score at every condition of the band, found vs. {label}",
        ),
    ]


def bracket_blocks(brackets, bracket_sensors, label: str) -> list[Block]:
    """The mounting-tolerance spread per layout and axis (perfect vs. brackets off, zeroed; the un-zeroed
    bias), and per sensor the change when its bracket alone is off (the bracket to make precise)."""
    if brackets is None or not len(brackets):
        return []
    # each layout with all its sensors, as the terminal shows it (the CSV files hold every k)
    brackets = brackets[brackets["k"] == brackets.groupby("layout")["k"].transform("max")]
    if bracket_sensors is not None and len(bracket_sensors):
        bracket_sensors = bracket_sensors[
            bracket_sensors["k"] == bracket_sensors.groupby("layout")["k"].transform("max")
        ]
    first = brackets.iloc[0]
    blocks: list[Block] = [
        Heading("Brackets: what a mounting tolerance does", 3),
        Paragraph(
            f"brackets off by ±{first['tolerance_mm']:g} mm and ±{first['tolerance_deg']:g}° ({int(first['draws'])} draw(s), "
            f"{int(first['n_scans'])} scans{', reduced protocol' if bool(first['reduced_protocol']) else ''}), the cell zeroed on a master part",
            "note",
        ),
    ]
    rows = []
    for r in brackets.to_dict("records"):
        rotation = r["unit"] == "deg"
        fmt = (lambda v: f"{1e3 * v:.3f}") if rotation else (lambda v: f"{1e6 * v:.1f}")  # mdeg or µm
        spread = [
            f"{fmt(r[c])}" if rotation and np.isfinite(r.get(c, np.nan)) else ""
            for c in ("perfect_median_deg", "perfect_p75_deg", "mounted_median_deg", "mounted_p75_deg")
        ]
        layout = label if r["layout"] == "hand" else r["layout"]
        rows.append(
            (
                layout,
                str(r["k"]),
                r["axis"],
                r["subset"],
                *spread,
                fmt(r["worst_abs_bias"]),
                "mdeg" if rotation else "µm",
            )
        )
    blocks.append(
        Table(
            (
                "layout",
                "k",
                "axis",
                "subset",
                "perfect median",
                "perfect p75",
                "off median",
                "off p75",
                "un-zeroed bias",
                "unit",
            ),
            tuple(rows),
            "per axis: error with perfect and with off brackets (zeroed), and the worst mean error of an un-zeroed cell",
            numeric=(False, True, False, False, True, True, True, True, True, False),
        )
    )
    if bracket_sensors is not None and len(bracket_sensors):
        srows = tuple(
            (
                label if r["layout"] == "hand" else r["layout"],
                str(r["k"]),
                r["sensor"],
                *(f"{1e3 * r[f'change_{a}_deg']:+.3f}" for a in ("roll", "pitch", "yaw")),
                f"{1e3 * r['score_change_deg']:+.3f}",
                str(r["rank"]),
            )
            for r in bracket_sensors.to_dict("records")
        )
        blocks.append(
            Table(
                ("layout", "k", "sensor", "roll (mdeg)", "pitch (mdeg)", "yaw (mdeg)", "score (mdeg)", "rank"),
                srows,
                "one bracket off at a time: change of each axis's median+p75 and of the score (worst draw); rank 1 is the bracket to make precise",
                numeric=(False, True, False, True, True, True, True, True),
            )
        )
    return blocks
