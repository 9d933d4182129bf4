"""A robustness result folder: ``config.toml``, the layouts, ``robustness.csv``, ``conditions.csv`` and,
with the bracket sensitivity, ``brackets.csv`` and ``bracket_sensors.csv``.

``conditions.csv`` holds every layout's statistics per condition, sensor subset and axis (radians), from
which any other choice can be restated.

``robustness.csv`` has one row per layout, k, condition and axis: the median and 75th percentile (degrees)
of the layout's choice of k sensors under that condition, the subset used, the choice's score, and the
hand layout's score for as many sensors under the same condition; the condition ``worst`` (or
``quantile <q>``) is the robust statistic over the band.

``brackets.csv`` (:mod:`optipose.evaluate.sensitivity`) has one row per layout, k and axis (roll, pitch,
yaw, x, y, z): the axis's subset; for rotations its median and p75 (degrees, worst over the draws) with
perfect brackets and with the brackets off by the tolerance, both zeroed; the mean signed error of an
un-zeroed cell per draw (``bias_draw<d>``), its largest magnitude (``worst_abs_bias``) and the same cell's
mean with perfect brackets (``perfect_bias``), in ``unit`` (deg for rotations, m for translations).
``bracket_sensors.csv`` has one row per layout, k and sensor: the change (degrees) of each axis's term of
the score and of the score when that sensor's bracket alone is off (worst over the draws), and its rank
(1: the bracket to make precise).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from optipose.io.folders import versions, write_config
from optipose.io.tables import robustness_frame
from optipose.model.layout import write_layout

__all__ = ["write_robustness", "write_brackets", "brackets_frame", "bracket_sensors_frame"]


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
    per_condition = [
        result.stats.assign(layout=name, condition=condition.label)
        for name, robust in results.items() for condition, result in robust.results
    ]  # fmt: skip
    pd.concat(per_condition, ignore_index=True).to_csv(folder / "conditions.csv", index=False)
    return frame


def write_brackets(folder: Path, sensitivities: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Save ``brackets.csv`` and ``bracket_sensors.csv`` into a robustness folder; returns both tables.

    sensitivities : layout name → :class:`~optipose.evaluate.sensitivity.BracketSensitivity`.
    """
    axes, sensors = brackets_frame(sensitivities), bracket_sensors_frame(sensitivities)
    axes.to_csv(Path(folder) / "brackets.csv", index=False)
    sensors.to_csv(Path(folder) / "bracket_sensors.csv", index=False)
    return axes, sensors


# The two tables below belong in io.tables with the others (kept here while that module is being edited).
def brackets_frame(sensitivities: dict) -> pd.DataFrame:
    """Per layout, k and axis: spread (rotations, degrees) and un-zeroed bias (see the module doc)."""
    rows = []
    for name, sens in sensitivities.items():
        spread = {(s.k, s.axis): s for s in sens.spread}
        for k in sorted({b.k for b in sens.bias}):
            worst = sens.worst_bias(k)
            for axis in dict.fromkeys(b.axis for b in sens.bias):
                biases = [b for b in sens.bias if b.k == k and b.axis == axis]
                scale = np.rad2deg(1.0) if axis in ("roll", "pitch", "yaw") else 1.0
                row = {"layout": name, "k": k, "axis": axis, "subset": biases[0].subset or "unobservable",
                       "unit": "deg" if scale != 1.0 else "m"}  # fmt: skip
                if (k, axis) in spread:
                    s = spread[(k, axis)]
                    row |= {"perfect_median_deg": scale * s.nominal_median, "perfect_p75_deg": scale * s.nominal_p75,
                            "mounted_median_deg": scale * s.mounted_median, "mounted_p75_deg": scale * s.mounted_p75}  # fmt: skip
                row |= {f"bias_draw{b.draw}": scale * b.bias for b in biases}
                row |= {"worst_abs_bias": scale * worst[axis], "perfect_bias": scale * biases[0].nominal}
                row |= {"tolerance_mm": 1e3 * sens.translation, "tolerance_deg": float(np.rad2deg(sens.rotation)),
                        "draws": len(sens.draws), "n_scans": sens.n_scans, "reduced_protocol": sens.reduced}  # fmt: skip
                rows.append(row)
    return pd.DataFrame(rows)


def bracket_sensors_frame(sensitivities: dict) -> pd.DataFrame:
    """Per layout, k and sensor: the change (degrees) when that sensor's bracket alone is off, and its rank."""
    rows = []
    for name, sens in sensitivities.items():
        for k in sorted({s.k for s in sens.sensors}):
            for rank, s in enumerate(sens.ranking(k), start=1):
                rows.append({"layout": name, "k": k, "sensor": s.name, "sensor_index": s.sensor, "rank": rank,
                             **{f"change_{axis}_deg": float(np.rad2deg(c)) for axis, c in zip(("roll", "pitch", "yaw"), s.change)},
                             "score_change_deg": float(np.rad2deg(s.score_change))})  # fmt: skip
    return pd.DataFrame(rows)
