"""An evaluation's result folder: per-scan errors, point counts, statistics, Table 1 and the config."""

from __future__ import annotations

from pathlib import Path

from optipose.files import atomic_path, reading
from optipose.io.config import RunConfig
from optipose.io.folders import part_table, read_config, versions, write_config, write_csv
from optipose.io.tables import table1_frame

__all__ = ["write_evaluation", "read_evaluation"]


def write_evaluation(
    result, folder: Path, part_source: str = "", layout_source: str = "", part_units: str = "auto"
) -> Path:
    """Save an :class:`optipose.evaluate.evaluator.EvaluationResult`: per-scan errors (CSV and Parquet),
    point counts, statistics, Table 1 and, last, the config (a folder without ``config.toml`` is one whose
    writing was cut short). Each file is written whole or not at all. Returns the folder."""
    folder = Path(folder)
    write_csv(result.per_scan, folder / "per_scan.csv")
    with atomic_path(folder / "per_scan.parquet") as tmp:
        result.per_scan.to_parquet(tmp, index=False)
    write_csv(result.points, folder / "points.csv")
    write_csv(result.stats, folder / "stats.csv")
    write_csv(table1_frame(result.table), folder / "table1.csv")
    write_config(
        folder,
        {
            "command": "evaluate",
            "part": part_table(result.part, part_source, part_units),
            "layout": {"name": result.layout.name, "source": layout_source, **result.layout.to_table()},
            "seed": result.seed,
            "objective": result.objective.to_dict(),
            "objective_file": result.objective.source_text,
            "timings_s": result.timings,
            "failed_registrations": result.n_failed,
            "versions": versions(),
        },
    )
    return folder


def read_evaluation(folder: Path, config: RunConfig | None = None):
    """The :class:`~optipose.evaluate.evaluator.EvaluationResult` saved in ``folder`` by
    :func:`write_evaluation`: the tables as written, Table 1 recomputed from the statistics (CSV floats
    round-trip exactly, so it is the table that was saved)."""
    import pandas as pd

    from optipose.evaluate.assignment import best_choices
    from optipose.evaluate.evaluator import EvaluationResult
    from optipose.evaluate.objective import objective_from_dict
    from optipose.model.layout import layout_from_table

    folder = Path(folder)
    config = config or read_config(folder)
    objective = objective_from_dict(config.objective, source_text=config.objective_file or "")
    layout = layout_from_table(config.layout, name=config.layout_name, where=f"{folder}/config.toml")
    with reading(folder / "per_scan.parquet") as path:
        per_scan = pd.read_parquet(path)
        n_scans = per_scan["scan"].nunique()
        evaluated = set(per_scan["subset"])  # a verdict's draw registers some subsets only
    with reading(folder / "stats.csv") as path:
        stats = pd.read_csv(path)
        table = best_choices(stats, layout.names, objective.statistic, n_scans, evaluated)
    with reading(folder / "points.csv") as path:
        points = pd.read_csv(path)
    timings = {k: float(v) for k, v in config.timings.items()}
    return EvaluationResult(
        config.part_name, layout, objective, int(config.seed), per_scan, points, stats, table, timings
    )
