"""``optipose robustness``: the hand-placed and given layouts in cell instances a search never saw.

A cell with ranges says what is not known about a user's cell (docs/cell.md); a found layout is worth buying where
it stays better than the hand one across what the ranges allow. Every layout is evaluated, as ``optipose evaluate``
does, in each instance (:mod:`optipose.evaluate.instances`): held-out draws of ``--cell``'s ranges, the ranges at
their low and at their high ends, and the same for each cell of ``--cells``. The table gives per instance and k the
hand layout's score over the layout's (the paper's score, each layout choosing its subsets per axis in that
instance) and whether the layout holds there (at least 1); the folder keeps every figure (``robustness.csv``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from optipose.cli.options import (
    CellOption,
    Jobs,
    Objective,
    Part,
    ResultFolder,
    Seed,
    Units,
    check_output,
    friendly_errors,
)
from optipose.cli.progress import make_console, status
from optipose.cli.report import NoReport
from optipose.errors import ConfigError

__all__ = ["robustness", "robustness_command"]

Layouts = Annotated[
    Optional[list[Path]],
    typer.Option(
        "--layout",
        help="A layout TOML to compare with the hand-placed one (repeatable), e.g. a search's layouts/found_k2.toml.",
    ),
]
Cells = Annotated[
    Optional[str],
    typer.Option(
        "--cells",
        help="Other cells to check in besides --cell, separated by commas (names in cells/, NAME:zeroed or "
        "TOML paths): their held-out draws and ranges' ends.",
    ),
]
Draws = Annotated[int, typer.Option("--draws", min=1, help="Held-out draws (cell instances) of each cell's ranges.")]
Ends = Annotated[
    bool,
    typer.Option("--ends/--no-ends", help="Check in each cell with ranges at its low ends and at its high ends too."),
]


@friendly_errors
def robustness(
    part: Part,
    layout: Layouts = None,
    objective: Objective = "paper",
    cell: CellOption = None,
    cells: Cells = None,
    draws: Draws = 3,
    ends: Ends = True,
    units: Units = "auto",
    out: ResultFolder = None,
    jobs: Jobs = 1,
    seed: Seed = 0,
    no_report: NoReport = False,
) -> None:
    """Check layouts against the hand one in cell instances a search never saw.

    Evaluate the hand-placed and the given layouts in held-out draws of the cell's ranges, at the ranges' ends and
    in the other cells given, and say per instance whether each layout holds (hand / found of the score >= 1)."""
    others = [c.strip() for c in (cells or "").split(",") if c.strip()]
    robustness_command(
        part, layout or [], objective, units, out, jobs or 1, seed, not no_report, cell, others, draws, ends
    )


def robustness_command(
    part: str,
    layouts: list[Path],
    objective: str = "paper",
    units: str = "auto",
    out: Path | None = None,
    jobs: int = 1,
    seed: int = 0,
    report: bool = True,
    cell: str | None = None,
    cells: list[str] = (),
    draws: int = 3,
    ends: bool = True,
) -> Path:
    """Run the evaluations, print the table and where each layout holds, save the result folder; returns it."""
    from rich.console import Console

    from optipose.evaluate.instances import check, instances
    from optipose.evaluate.objective import load_objective
    from optipose.io.folders import RESULTS_DIR, make_result_dir
    from optipose.io.robustness import read_robustness, write_robustness
    from optipose.model.baseline import baseline
    from optipose.model.collision import check_sensors_outside
    from optipose.model.layout import load_layout
    from optipose.model.part import load_part

    check_output(out or RESULTS_DIR, what="--out" if out else "result folder")
    the_part = load_part(part, units=units)
    reference = baseline(the_part)  # the hand-placed layout, else the conventional placement
    if reference is None:
        raise ConfigError(f"part '{the_part.name}' has no hand-placed layout to compare with")
    the_objective = load_objective(objective).in_cell(cell)
    names = list(dict.fromkeys([cell or the_objective.cell.name, *cells]))
    checked = instances(names, seed, draws, ends)  # a bad cell name fails here, before any work
    given = {}
    for path in layouts:
        lay = load_layout(path)
        check_sensors_outside(the_part, lay)
        given[lay.name if lay.name not in given and lay.name != "hand" else f"{lay.name}-{len(given) + 1}"] = lay
    console = make_console(stderr=True)
    rows = []
    for i, inst in enumerate(checked):
        with status(
            console,
            f"{the_part.name}: {len(given) + 1} layouts in {inst.cell}, {inst.label} ({i + 1} of {len(checked)})",
        ):
            rows += check(the_part, reference, given, the_objective, [inst], jobs)
    folder = make_result_dir(the_part.name, "robustness", out)
    write_robustness(
        folder, the_part, the_objective, seed, {"hand": reference, **given}, checked, rows, [str(p) for p in layouts]
    )
    result = read_robustness(folder)
    Console().print(_table(result, the_part.name))
    for line in _holds(result):
        Console().print(line, highlight=False)
    if report:
        from optipose.cli.report import write_report_after

        write_report_after(folder, console)
    console.print(f"results: {folder}")
    return folder


def _holds(result) -> list[str]:
    """One line per given layout and k: in how many instances it holds, and its weakest one."""
    ratios, lines = result.ratios(), []
    for r in result.holds().itertuples(index=False):
        mine = ratios[(ratios.layout == r.layout) & (ratios.k == r.k)]
        weakest = mine.loc[mine.ratio.idxmin()]
        every = f"in {'every one' if r.held == r.instances else r.held} of the {r.instances}"
        lines.append(
            f"{r.layout} k={r.k}: holds {every} cell instances checked (hand / found {weakest.ratio:.3f}x at "
            f"its weakest: {weakest.cell}, {weakest.instance})"
        )
    return lines or ["only the hand layout was given: nothing to compare (give --layout FILE)"]


def _table(result, part_name: str):
    """One row per cell instance: per given layout and k, hand / layout of the score and whether it holds."""
    from rich import box
    from rich.table import Table

    ratios = result.ratios()
    columns = list(dict.fromkeys(zip(ratios.layout, ratios.k)))
    table = Table(
        title=f"{part_name}: hand / found of the score per cell instance (>= 1: the found layout holds)",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
        collapse_padding=True,
    )
    table.add_column("cell, instance")
    for name, k in columns:
        table.add_column(f"{name} k={k}", justify="right")
    for (cell, instance), group in ratios.groupby(["cell", "instance"], sort=False):
        by = {(r.layout, r.k): r for r in group.itertuples(index=False)}
        cells = [f"{by[c].ratio:.3f}x {'holds' if by[c].holds else '[red]no[/]'}" if c in by else "-" for c in columns]
        table.add_row(f"{cell}, {instance}", *cells)
    return table
