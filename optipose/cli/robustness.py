"""``optipose robustness``: the hand-placed and given layouts side by side under every condition of a band.

Each layout is evaluated under every condition of the objective's ``[conditions]`` (default objective:
``robust``: noise at 1, 3 and 5 times the preset's, brackets off by up to 0.2 mm and 0.1°); per layout and
condition the table shows its robust choice of all its sensors (at most as many as the hand layout has)
against the hand layout's robust choice of as many, each axis on a fixed subset, and
a verdict on the robust statistic (the worst over the conditions) says whether to keep the hand sensors.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from optipose.cli.options import Jobs, Objective, Part, ResultFolder, Seed, Units, friendly_errors
from optipose.errors import ConfigError

__all__ = ["robustness", "robustness_command"]

Layouts = Annotated[
    Optional[list[Path]],
    typer.Option("--layout", help="A layout TOML to compare with the hand-placed one (repeatable), e.g. a search's layouts/found_k2.toml."),
]


@friendly_errors
def robustness(
    part: Part,
    layout: Layouts = None,
    objective: Objective = "robust",
    units: Units = "auto",
    out: ResultFolder = None,
    jobs: Jobs = 1,
    seed: Seed = 0,
) -> None:
    """Evaluate the hand-placed and the given layouts under every condition of the objective's band (noise
    levels, bracket tolerances) and say, per layout, whether it stays no worse than the hand one."""
    robustness_command(part, layout or [], objective, units, out, jobs or 1, seed)


def robustness_command(part: str, layouts: list[Path], objective: str = "robust", units: str = "auto",
                       out: Path | None = None, jobs: int = 1, seed: int = 0) -> Path:  # fmt: skip
    """Run the evaluations, print the table and the verdicts, save the result folder; returns the folder."""
    from rich.console import Console

    from optipose.evaluate.objective import load_objective
    from optipose.evaluate.robust import evaluate_robust
    from optipose.io.folders import make_result_dir
    from optipose.io.robustness import write_robustness
    from optipose.model.layout import load_layout
    from optipose.model.part import load_part

    the_part = load_part(part, units=units)
    if "hand" not in the_part.layouts:
        raise ConfigError(f"part '{the_part.name}' has no hand-placed layout to compare with")
    the_objective = load_objective(objective)
    given = [load_layout(p) for p in layouts]
    console = Console(stderr=True)
    results = {}
    for lay in [the_part.layouts["hand"], *given]:
        name = lay.name if lay.name not in results else f"{lay.name}-{len(results)}"  # two files of one name
        with console.status(f"{the_part.name}: {name} under {len(_conditions(the_objective))} conditions"):
            results[name] = evaluate_robust(the_part, lay, the_objective, seed=seed, jobs=jobs, quiet=True)
    folder = make_result_dir(the_part.name, "robustness", out)
    rows = write_robustness(folder, the_part, the_objective, seed, results, hand="hand", sources=[str(p) for p in layouts])
    Console().print(_table(rows, the_part.name))
    for line in _verdicts(results):
        Console().print(line)
    console.print(f"results: {folder}")
    return folder


def _conditions(objective):
    from optipose.evaluate.conditions import conditions

    return conditions(objective.conditions)


def _verdicts(results: dict) -> list[str]:
    """Per given layout, the verdict on the robust statistic against the hand layout's choice of as many sensors."""
    from optipose.evaluate.compare import Verdict

    hand, lines = results["hand"], []
    for name, result in results.items():
        if name == "hand":
            continue
        k = min(len(result.layout), len(hand.table))
        line = Verdict(k, result.table[k - 1], hand.table[k - 1]).line()
        lines.append(f"{name} (worst over the band): {line}")
    return lines


def _table(rows, part_name: str):
    """One row per layout and condition: per axis median/p75 (mdeg), the score, and hand / this; narrow
    enough for an 80-column terminal (conditions as ``x3 m1``: noise times 3, mounting draw 1)."""
    from rich import box
    from rich.table import Table

    table = Table(title=f"{part_name}: under every condition, mdeg median/p75 (x: noise scale, m: bracket draw)",
                  box=box.SIMPLE_HEAD, pad_edge=False, collapse_padding=True)  # fmt: skip
    for col in ("layout", "cond.", "roll", "pitch", "yaw", "score", "hand/it"):
        table.add_column(col, justify="left" if col in ("layout", "cond.") else "right", no_wrap=True)
    for (layout, k, condition), group in rows.groupby(["layout", "k", "condition"], sort=False):
        cells = {r.axis: f"{1e3 * r.median_deg:.2f}/{1e3 * r.p75_deg:.2f}" for r in group.itertuples()}
        first = group.iloc[0]
        ratio = "" if layout == "hand" else f"{first['hand_score_deg'] / first['score_deg']:.2f}x"
        short = condition.replace("noise x", "x").replace(", mounting draw ", " m")
        name = f"{layout} k{k}" if layout == "hand" else layout
        table.add_row(name, short, cells["roll"], cells["pitch"], cells["yaw"], f"{1e3 * first['score_deg']:.2f}", ratio)
    return table
