"""A robustness result folder: ``config.toml``, the layouts, and ``robustness.csv``.

``robustness.csv`` has one row per layout, k, condition and axis: the median and 75th percentile (degrees)
of the layout's choice of k sensors under that condition, the subset used, the choice's score, and the
hand layout's score for as many sensors under the same condition; the condition ``worst`` (or
``quantile <q>``) is the robust statistic over the band.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from optipose.io.folders import versions, write_config
from optipose.model.layout import write_layout

__all__ = ["write_robustness", "robustness_frame"]


def write_robustness(folder: Path, part, objective, seed: int, results: dict, hand: str = "hand", sources=()) -> pd.DataFrame:
    """Save the folder of ``optipose robustness``; returns the table written to ``robustness.csv``.

    results : layout name → :class:`~optipose.evaluate.robust.RobustResult`, the hand layout's under ``hand``.
    """
    folder = Path(folder)
    (folder / "layouts").mkdir(parents=True, exist_ok=True)
    for name, result in results.items():
        write_layout(result.layout, folder / "layouts" / f"{name}.toml")
    write_config(folder, {
        "command": "robustness", "part": {"name": part.name, "source": str(getattr(part, "source", ""))},
        "seed": seed, "layouts": list(results), "layout_sources": list(sources),
        "objective": objective.to_dict(), "objective_file": objective.source_text, "versions": versions(),
    })  # fmt: skip
    frame = robustness_frame(results, hand, objective.conditions.aggregate)
    frame.to_csv(folder / "robustness.csv", index=False)
    return frame


def robustness_frame(results: dict, hand: str = "hand", aggregate="worst") -> pd.DataFrame:
    """The rows of ``robustness.csv`` (see the module doc), hand layout first."""
    robust_label = "worst" if aggregate == "worst" else f"quantile {aggregate:g}"
    hand_result = results[hand]
    n_hand = len(hand_result.table)
    given = {name: min(len(r.layout), n_hand) for name, r in results.items() if name != hand}
    # the hand layout's best k for every k a given layout is compared at (every k when none is given)
    jobs = [(hand, k) for k in sorted(set(given.values()) or range(1, n_hand + 1))] + list(given.items())
    rows = []
    for name, k in jobs:
        result = results[name]
        choice, reference = result.table[k - 1], hand_result.table[k - 1]
        for (condition, c), (_, h) in zip(result.under(choice), hand_result.under(reference)):
            rows += _rows(name, k, condition.label, c, h.score)
        rows += _rows(name, k, robust_label, choice, reference.score)
    return pd.DataFrame(rows)


def _rows(layout: str, k: int, condition: str, choice, hand_score: float) -> list[dict]:
    return [
        {"layout": layout, "k": k, "condition": condition, "sensors": choice.name, "axis": a.axis,
         "subset": a.name or "unobservable", "median_deg": float(np.rad2deg(a.median)), "p75_deg": float(np.rad2deg(a.p75)),
         "score_deg": float(np.rad2deg(choice.score)), "hand_score_deg": float(np.rad2deg(hand_score))}
        for a in choice.axes
    ]  # fmt: skip
