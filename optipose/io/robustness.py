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

import pandas as pd

from optipose.files import reading
from optipose.io.choices import choices_from_comparison
from optipose.io.config import RunConfig
from optipose.io.folders import part_table, read_config, versions, write_config, write_csv
from optipose.io.tables import bracket_sensors_frame, brackets_frame, robustness_frame
from optipose.model.layout import write_layout

__all__ = ["write_robustness", "write_brackets", "brackets_frame", "bracket_sensors_frame", "read_robustness"]


def write_robustness(
    folder: Path, part, objective, seed: int, results: dict, baseline: str = "hand", sources=()
) -> pd.DataFrame:
    """Save the folder of ``optipose robustness``; returns the table written to ``robustness.csv``.

    results : layout name → :class:`~optipose.evaluate.robust.RobustResult`, the baseline's under the name ``baseline``.
    """
    folder = Path(folder)
    (folder / "layouts").mkdir(parents=True, exist_ok=True)
    for name, result in results.items():
        write_layout(result.layout, folder / "layouts" / f"{name}.toml")
    write_config(
        folder,
        {
            "command": "robustness",
            "part": part_table(part.name, str(getattr(part, "source", "")), getattr(part, "units", "auto")),
            "seed": seed,
            "layouts": list(results),
            "layout_sources": list(sources),
            "objective": objective.to_dict(),
            "objective_file": objective.source_text,
            "versions": versions(),
        },
    )
    frame = robustness_frame(results, baseline, objective.conditions.aggregate)
    write_csv(frame, folder / "robustness.csv")
    per_condition = [
        result.stats.assign(layout=name, condition=condition.label)
        for name, robust in results.items()
        for condition, result in robust.results
    ]
    write_csv(pd.concat(per_condition, ignore_index=True), folder / "conditions.csv")
    return frame


def write_brackets(folder: Path, sensitivities: dict) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Save ``brackets.csv`` and ``bracket_sensors.csv`` into a robustness folder; returns both tables.

    sensitivities : layout name → :class:`~optipose.evaluate.sensitivity.BracketSensitivity`.
    """
    axes, sensors = brackets_frame(sensitivities), bracket_sensors_frame(sensitivities)
    write_csv(axes, Path(folder) / "brackets.csv")
    write_csv(sensors, Path(folder) / "bracket_sensors.csv")
    return axes, sensors


def read_robustness(folder: Path, config: RunConfig | None = None):
    """The :class:`~optipose.io.results.RobustnessResult` saved by :func:`write_robustness` (and
    :func:`write_brackets`)."""
    from optipose.io.results import RobustnessResult
    from optipose.model.layout import load_layout

    folder = Path(folder)
    config = config or read_config(folder)
    layouts = {name: load_layout(folder / "layouts" / f"{name}.toml") for name in config.layouts}
    with reading(folder / "robustness.csv") as path:
        rows = pd.read_csv(path)
        robust = [c for c in dict.fromkeys(rows["condition"]) if c == "worst" or str(c).startswith("quantile")]
        rows = rows.assign(condition=rows["condition"].replace({robust[0]: "band"})) if robust else rows
        choices = {}
        for name, group in rows.groupby("layout", sort=False):
            for k, choice in choices_from_comparison(group, layouts[name].names).items():
                choices[(str(name), int(k))] = choice
    extra = {n: _optional_csv(folder / f"{n}.csv") for n in ("brackets", "bracket_sensors")}
    return RobustnessResult(folder, config.part_name, int(config.seed), config, layouts, choices, **extra)


def _optional_csv(path: Path):
    if not path.is_file():
        return None
    with reading(path):
        return pd.read_csv(path)
