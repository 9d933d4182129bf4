"""The one place that turns records into tables (pandas), for the CSV files of a result folder.

Angles in tables are degrees where the column says ``_deg`` and radians where it says ``_rad``; sensors
and subsets appear by name (``S1S2``), as a user reads them.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = [
    "table1_frame",
    "comparison_frame",
    "selection_frame",
    "history_frame",
    "surrogate_frame",
    "instances_frame",
    "verdict_frame",
    "VERDICT_COLUMNS",
]


def table1_frame(choices) -> pd.DataFrame:
    """The paper's Table 1 (``table1.csv``): one row per k with each axis's subset, median and p75 (rad)."""
    rows = [
        {
            "k": c.k,
            "sensors": c.name,
            "score_rad": c.score,
            **{
                f"{a.axis}_{key}": val
                for a in c.axes
                for key, val in (("subset", a.name), ("median_rad", a.median), ("p75_rad", a.p75))
            },
        }
        for c in choices
    ]
    return pd.DataFrame(rows)


def comparison_frame(validation) -> pd.DataFrame:
    """Found vs. hand per k and axis (``comparison.csv``, degrees): the found rows in the order they were
    evaluated, then the hand rows."""
    rows = [r for k, c in validation.found.items() for r in _choice_rows("found", k, c)]
    rows += [r for k, c in validation.baseline.items() for r in _choice_rows("hand", k, c)]
    for row in rows:
        row["protocol"] = validation.protocol
    return pd.DataFrame(rows)


def _choice_rows(label: str, k: int, choice) -> list[dict]:
    return [
        {
            "k": k,
            "layout": label,
            "sensors": choice.name,
            "axis": a.axis,
            "subset": a.label,
            "median_deg": float(np.rad2deg(a.median)),
            "p75_deg": float(np.rad2deg(a.p75)),
            "score_deg": float(np.rad2deg(choice.score)),
        }
        for a in choice.axes
    ]


def selection_frame(records) -> pd.DataFrame:
    """The ICP evaluations of the selection, polish and confirmation (``selection.csv``)."""
    rows = []
    for r in records:
        row = {
            "k": r.k,
            "origin": r.origin,
            "surrogate_deg": r.surrogate,
            "protocol": r.protocol,
            "score_deg": float(np.rad2deg(r.choice.score)),
            "dominates_hand": r.dominates,
        }
        for a in r.choice.axes:
            row |= {
                f"{a.axis}_median_deg": float(np.rad2deg(a.median)),
                f"{a.axis}_p75_deg": float(np.rad2deg(a.p75)),
                f"{a.axis}_subset": a.label,
            }
        row["state"] = r.state.value
        rows.append(row)
    return pd.DataFrame(rows)


def history_frame(evaluations) -> pd.DataFrame:
    """Every surrogate evaluation of the search (``history.csv``): u as a list, value as the optimiser saw it."""
    return pd.DataFrame(
        [
            {
                "eval": e.number,
                "stage": e.stage,
                "k": e.k,
                "value": e.value,
                "feasible": e.feasible,
                "best": e.best,
                "u": list(e.u),
                "state": e.state.value,
                "constraint": e.constraint,
            }
            for e in evaluations
        ]
    )


def surrogate_frame(outcome) -> pd.DataFrame:
    """The surrogate's scores of the winner, greedy, joint and hand layouts per k (``surrogate_scores.csv``)."""
    rows = []
    for k, f in sorted(outcome.found.items()):
        for label, g in (
            ("found", f),
            ("greedy", outcome.greedy.get(k)),
            ("joint", outcome.joint.get(k)),
            ("hand", outcome.baseline.get(k)),
        ):
            if g is not None and g.stats:
                rows.append(
                    {
                        "k": k,
                        "layout": label,
                        "fidelity": "surrogate",
                        "score_deg": g.stats.score,
                        "penalised_deg": g.score,
                    }
                )
    return pd.DataFrame(rows)


def instances_frame(rows) -> pd.DataFrame:
    """A robustness check (``robustness.csv``): one row per (cell, instance, layout, k, axis) of
    :class:`~optipose.evaluate.instances.InstanceRow` s, angles in degrees; ``ratio`` (hand / layout of the score of
    the whole choice) and ``holds`` (ratio >= 1) repeated on each axis's row."""
    deg = np.rad2deg
    return pd.DataFrame(
        [
            {
                "cell": r.cell,
                "instance": r.instance,
                "seed": r.seed,
                "layout": r.layout,
                "k": r.k,
                "sensors": r.sensors,
                "axis": r.axis,
                "subset": r.subset,
                "median_deg": float(deg(r.median)),
                "p75_deg": float(deg(r.p75)),
                "hand_sensors": r.hand_sensors,
                "hand_median_deg": float(deg(r.hand_median)),
                "hand_p75_deg": float(deg(r.hand_p75)),
                "score_deg": float(deg(r.score)),
                "hand_score_deg": float(deg(r.hand_score)),
                "ratio": r.ratio,
                "holds": r.holds,
            }
            for r in rows
        ]
    )


VERDICT_COLUMNS = (
    "ratio",
    "median_ratio",
    "p75_ratio",
    "failed",
    "found_median_deg",
    "found_p75_deg",
    "hand_median_deg",
    "hand_p75_deg",
    "found_cell_median_deg",
    "hand_cell_median_deg",
)


def verdict_frame(verdicts) -> pd.DataFrame:
    """The verdicts with confidence (``verdict.csv``; a :class:`~optipose.verdict.confidence.Verdicts`, by k, then
    one found sensor against the baseline's largest choice): per k a row for the score (axis ``score``: hand / found
    in sum, found's and hand's score in the ``*_median_deg`` columns) and one per axis (hand / found of its
    share of the score, of its median and p75; ``failed``: the share of scans on which found's registration
    failed less hand's; each layout's predicted median and p75, degrees), each with its interval (``_low``,
    ``_high``); the decision and what it rests on (``failures``: the share found may fail beyond hand's) repeated on every row. A row whose
    ``hand_k`` exceeds its ``k`` compares fewer found sensors with more hand ones."""
    rows = []
    for v in verdicts.in_order():
        head = {
            "k": v.k,
            "hand_k": v.baseline_k or v.k,
            "decision": v.decision.value,
            "found": v.found_name,
            "reference": v.reference,
            "hand": v.baseline_name,
            "draws": v.n_draws,
            "scans": v.n_scans,
            "tolerance": v.tolerance,
            "failures": v.failures,
            "kept": v.kept,
            "confidence": v.confidence,
            "more_draws": v.more_draws if v.more_draws is not None else -1,
            "seconds_per_draw": v.seconds_per_draw,
            "ended": v.ended,
            # the range that rules it in a cell of ranges (optipose.verdict.ruling): its field, where, which side
            "ruling": v.ruling.key if v.ruling else "",
            "ruling_at": v.ruling.at if v.ruling else np.nan,
            "ruling_above": bool(v.ruling and v.ruling.above),
            "ruling_share": v.ruling.share if v.ruling else np.nan,
        }
        empty = {
            "median_ratio": None,
            "p75_ratio": None,
            "failed": None,
            "found_p75_deg": None,
            "hand_p75_deg": None,
            "found_cell_median_deg": None,
            "hand_cell_median_deg": None,
        }
        score = {
            "ratio": v.score,
            "found_median_deg": v.found_score_deg,
            "hand_median_deg": v.baseline_score_deg,
            **empty,
        }
        rows.append({**head, "axis": "score", **_intervals(score)})
        for ratio, found, baseline in zip(v.axes, v.found, v.baseline):
            cells = {
                "ratio": ratio.ratio,
                "median_ratio": ratio.median,
                "p75_ratio": ratio.p75,
                "failed": ratio.failed,
                "found_median_deg": found.median_deg,
                "found_p75_deg": found.p75_deg,
                "hand_median_deg": baseline.median_deg,
                "hand_p75_deg": baseline.p75_deg,
                # what one instance of the cell gives (optipose.verdict.confidence.one_cell)
                "found_cell_median_deg": found.one_cell,
                "hand_cell_median_deg": baseline.one_cell,
            }
            rows.append({**head, "axis": ratio.axis, **_intervals(cells)})
    return pd.DataFrame(rows)


def _intervals(cells: dict) -> dict:
    out = {}
    for name in VERDICT_COLUMNS:
        iv = cells[name]
        values = (np.nan, np.nan, np.nan) if iv is None else (iv.estimate, iv.low, iv.high)
        out.update({name: values[0], f"{name}_low": values[1], f"{name}_high": values[2]})
    return out
