"""Choices back from the tables that wrote them: a layout's choice of k sensors from its rows of
``comparison.csv`` or ``robustness.csv``, and one axis's choice from a table's cells (degrees back to
radians). The search's reader (:mod:`optipose.io.load`) and the robustness reader
(:mod:`optipose.io.robustness`) both restate choices through here.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from optipose.errors import ConfigError
from optipose.evaluate.assignment import FAILED, UNOBSERVABLE, AxisChoice, Choice
from optipose.evaluate.objective import AXES

__all__ = ["choices_from_comparison", "axis_choice", "sensor_indices"]


def choices_from_comparison(rows: pd.DataFrame, names: list[str]) -> dict[int, Choice]:
    """k → Choice from ``comparison.csv`` rows of one layout (degrees back to radians), in file order; a folder
    validated under the retired band of conditions (a ``condition`` column): its robust choice (``band`` rows)."""
    if "condition" in rows:
        rows = rows[rows.condition == "band"]
    return {k: _choice(group, k, names) for k, group in rows.groupby("k", sort=False)}


def _choice(group: pd.DataFrame, k, names: list[str]) -> Choice:
    by_axis = {r.axis: r for r in group.itertuples(index=False)}
    axes = []
    for axis in AXES:
        r = by_axis[axis]
        axes.append(axis_choice(axis, r.subset, r.median_deg, r.p75_deg, names))
    first = group.iloc[0]
    sensors = str(first["sensors"])
    return Choice(int(k), sensor_indices(sensors, names), sensors, tuple(axes), float(np.deg2rad(first["score_deg"])))


def sensor_indices(name: str, names: list[str]) -> tuple[int, ...]:
    """Sensor indices of a subset name such as ``S1S3`` (the layout's names, longest first)."""
    if not name:
        return ()
    pattern = "|".join(re.escape(n) for n in sorted(names, key=len, reverse=True))
    tokens = re.findall(pattern, name) if pattern else []
    if "".join(tokens) != name:
        raise ConfigError(f"subset '{name}' does not name sensors of the layout ({', '.join(names)})")
    return tuple(sorted(names.index(t) for t in tokens))


def axis_choice(axis: str, subset, median_deg: float, p75_deg: float, names: list[str]) -> AxisChoice:
    """An axis of a choice from a table's cells: its subset's name or, where there is none, the reason
    written instead (``unobservable``, ``registrations failed``; an empty cell: unobservable)."""
    text = str(subset)
    median, p75 = np.deg2rad(_number(median_deg)), np.deg2rad(_number(p75_deg))
    if text in ("", "nan", UNOBSERVABLE, FAILED):
        return AxisChoice(axis, (), "", median, p75, FAILED if text == FAILED else UNOBSERVABLE)
    return AxisChoice(axis, sensor_indices(text, names), text, median, p75)


def _number(cell) -> float:
    """A table's numeric cell as a float: an empty one (an axis with no subset, read without NA
    conversion) is NaN."""
    return np.nan if str(cell).strip() in ("", "nan") else float(cell)
