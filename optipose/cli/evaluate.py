"""``optipose evaluate``: the paper's protocol on one layout, printed as the paper's Table 1.

:func:`evaluate` is the Typer command (registered by :mod:`optipose.cli.app`), :func:`evaluate_command`
the plain function behind it; imports stay lazy so ``optipose --help`` is instant.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from optipose.cli.options import (
    CellOption,
    Jobs,
    LayoutFile,
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

__all__ = ["evaluate", "evaluate_command", "table1", "register"]


@friendly_errors
def evaluate(
    part: Part,
    units: Units = "auto",
    layout: LayoutFile = None,
    out: ResultFolder = None,
    objective: Annotated[
        Optional[str],
        typer.Option(
            "--objective",
            help="Objective name in objectives/ or a TOML path; default paper (with --scans: the scans').",
        ),
    ] = None,
    cell: CellOption = None,
    jobs: Jobs = 1,
    seed: Seed = 0,
    no_report: NoReport = False,
    scans: Annotated[
        Optional[Path],
        typer.Option(
            "--scans",
            help="Evaluate this scan folder (measured, or written by `optipose scan --protocol --raw`) instead of "
            "simulating: its layout, cell and seed are the manifest's.",
        ),
    ] = None,
) -> None:
    """Table 1 of one layout: the best sensor subset per axis, by ICP.

    Scan a layout at every orientation of an objective's protocol, register every sensor subset with
    ICP, and print the best subset per axis for 1, 2, 3 … sensors (the paper's Table 1). With --scans, the
    scans are read from a scan folder (docs/scans.md) instead."""
    if scans is not None:
        for flag, value in (("--layout", layout), ("--cell", cell)):
            if value is not None:
                raise ConfigError(f"{flag} is not for --scans: the scans' manifest says it")
    evaluate_command(
        part,
        units,
        layout,
        out,
        objective or "paper",
        jobs,
        seed,
        report=not no_report,
        cell=cell,
        scans=scans,
        scans_objective=objective,
    )


def register(app: typer.Typer) -> None:
    """Add ``evaluate`` to a Typer app of the caller's (tests build one); the ``optipose`` app registers its
    commands in :mod:`optipose.cli.app`."""
    app.command()(evaluate)


def evaluate_command(
    part: str,
    units: str = "auto",
    layout: Path | None = None,
    out: Path | None = None,
    objective: str = "paper",
    jobs: int = 1,
    seed: int = 0,
    report: bool = True,
    cell: str | None = None,
    scans: Path | None = None,
    scans_objective: str | None = None,
) -> Path:
    """Run the evaluation (or, with ``scans``, read that scan folder under ``scans_objective``, default the
    manifest's), print Table 1, save the result folder; returns the folder."""
    from rich.console import Console

    from optipose.model.part import load_part
    from optipose.io import load_result
    from optipose.io.evaluation import write_evaluation
    from optipose.io.folders import RESULTS_DIR, make_result_dir

    check_output(out or RESULTS_DIR, what="--out" if out else "result folder")
    the_part = load_part(part, units=units)
    if scans is not None:
        result, layout_source = _from_scans(the_part, scans, scans_objective, jobs), f"scans:{scans}"
    else:
        result, layout_source = _simulated(the_part, layout, objective, cell, jobs, seed), str(layout or "part:hand")
    folder = make_result_dir(the_part.name, "evaluate", out)
    write_evaluation(result, folder, part_source=str(part), layout_source=layout_source, part_units=the_part.units)
    Console().print(table1(load_result(folder)))  # what the folder holds, as a report will read it
    console = make_console(stderr=True)
    n = len(result.per_scan)
    if result.n_failed:
        console.print(
            f"[yellow]{result.n_failed} of {n} registrations failed or did not converge: each a 10° error in the "
            "medians and 75th percentiles, out of the means and maxima (see per_scan.csv)[/]"
        )
    if report:
        from optipose.cli.report import write_report_after

        write_report_after(folder, console)
    console.print(f"results: {folder}")
    return folder


def _simulated(the_part, layout: Path | None, objective: str, cell: str | None, jobs: int, seed: int):
    """The evaluation of ``layout`` (default: the part's baseline) simulated in the objective's cell."""
    from optipose.evaluate.evaluator import Evaluator
    from optipose.evaluate.objective import load_objective
    from optipose.model.baseline import baseline
    from optipose.model.collision import check_sensors_outside
    from optipose.model.layout import load_layout

    if layout is not None:
        the_layout = load_layout(layout)
        check_sensors_outside(the_part, the_layout)
    elif baseline(the_part) is not None:  # the hand-placed layout, else the conventional placement
        the_layout = baseline(the_part)
    else:
        raise ConfigError(f"part '{the_part.name}' has no hand-placed layout; give one with --layout")
    the_objective = load_objective(objective).in_cell(cell)
    console = make_console(stderr=True)
    with status(
        console, f"evaluating {the_part.name} / {the_layout.name} under '{the_objective.name}' ({jobs} job(s))"
    ):
        with Evaluator(the_part, the_objective, seed=seed, jobs=jobs) as evaluator:
            return evaluator(the_layout)


def _from_scans(the_part, scans: Path, objective: str | None, jobs: int):
    """The evaluation of the scan folder ``scans`` (:func:`optipose.evaluate.recorded.evaluate_scans`)."""
    from optipose.evaluate.recorded import evaluate_scans
    from optipose.scan.folder import read_manifest

    manifest = read_manifest(scans)
    console = make_console(stderr=True)
    with status(console, f"evaluating the scans in {scans} ({len(manifest.scans)} scans, {jobs} job(s))"):
        return evaluate_scans(the_part, scans, objective, jobs=jobs)[0]


def table1(result):
    """A rich table in the shape of the paper's Table 1: rows k = 1 … n, columns roll/pitch/yaw."""
    import numpy as np
    from rich.table import Table

    n_scans = result.per_scan["scan"].nunique()
    cell = "" if result.objective.cell.ideal else f" in cell '{result.objective.cell.name}'"
    table = Table(
        title=f"{result.part}: {result.layout.name} layout, objective '{result.objective.name}'{cell}, "
        f"{n_scans} scans, seed {result.seed} — median / 75th pct, degrees (subset)"
    )
    table.add_column("sensors", justify="right")
    table.add_column("choice")
    for axis in ("roll", "pitch", "yaw"):
        table.add_column(f"{axis} [deg]", justify="right")
    for choice in result.table:
        cells = [
            f"{np.rad2deg(a.median):.5f} / {np.rad2deg(a.p75):.5f} {a.name}" if a.observable else f"[red]{a.label}[/]"
            for a in choice.axes
        ]
        table.add_row(str(choice.k), choice.name, *cells)
    return table
