"""A robustness result folder: ``config.toml`` (the cells, instances and seeds checked in), the layouts, and
``robustness.csv``: one row per (cell, instance, layout, k, axis) of :func:`optipose.io.tables.instances_frame` —
the layout's choice of k sensors in that instance, each axis's subset and median / 75th percentile (degrees), the
hand layout's choice of as many there, the scores, hand / layout of the score (``ratio``) and whether the layout
holds (``holds``: ratio >= 1).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from optipose.files import reading
from optipose.io.config import RunConfig
from optipose.io.folders import part_table, read_config, versions, write_config, write_csv
from optipose.io.tables import instances_frame
from optipose.model.layout import write_layout

__all__ = ["write_robustness", "read_robustness"]


def write_robustness(
    folder: Path, part, objective, seed: int, layouts: dict, instances: list, rows: list, sources=()
) -> pd.DataFrame:
    """Save the folder of ``optipose robustness``; returns the table written to ``robustness.csv``.

    layouts : name → Layout, the hand layout under ``hand``; instances : the
    :class:`~optipose.evaluate.instances.Instance` s checked in; rows : their
    :class:`~optipose.evaluate.instances.InstanceRow` s."""
    folder = Path(folder)
    (folder / "layouts").mkdir(parents=True, exist_ok=True)
    for name, layout in layouts.items():
        write_layout(layout, folder / "layouts" / f"{name}.toml")
    write_config(
        folder,
        {
            "command": "robustness",
            "part": part_table(part.name, str(getattr(part, "source", "")), getattr(part, "units", "auto")),
            "seed": seed,
            "layouts": list(layouts),
            "layout_sources": list(sources),
            "instances": [{"cell": i.cell, "instance": i.label, "seed": i.seed} for i in instances],
            "objective": objective.to_dict(),
            "objective_file": objective.source_text,
            "versions": versions(),
        },
    )
    frame = instances_frame(rows)
    write_csv(frame, folder / "robustness.csv")
    return frame


def read_robustness(folder: Path, config: RunConfig | None = None):
    """The :class:`~optipose.io.results.RobustnessResult` saved by :func:`write_robustness`."""
    from optipose.io.results import RobustnessResult
    from optipose.model.layout import load_layout

    folder = Path(folder)
    config = config or read_config(folder)
    layouts = {name: load_layout(folder / "layouts" / f"{name}.toml") for name in config.layouts}
    with reading(folder / "robustness.csv"):
        rows = pd.read_csv(folder / "robustness.csv")
    return RobustnessResult(folder, config.part_name, int(config.seed), config, layouts, rows)
