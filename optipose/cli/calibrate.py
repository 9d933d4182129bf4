"""``optipose calibrate``: a cell's ranges narrowed to what a hand layout's measured figures show (docs/calibration.md).

:func:`calibrate` is the Typer command (registered by :mod:`optipose.cli.app`), :func:`calibrate_command` the plain
function behind it; imports stay lazy so ``optipose --help`` is instant. The measured figures come from a published
table (``--figures table.csv``) or from scans (``--scans DIR``: a result folder of ``optipose evaluate``, e.g. of
``evaluate --scans``, or a folder of the device's profiles where this version reads them). The calibrated cell file is
written whole (``--out``) even when the prior's ranges cannot produce every figure; then a warning line names them and
the exit code is :data:`EXIT_MISFIT`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from optipose.cli.options import Jobs, LayoutFile, Part, Seed, Units, check_output, friendly_errors
from optipose.errors import ConfigError

__all__ = ["calibrate", "calibrate_command", "EXIT_MISFIT"]

EXIT_MISFIT = 3  # the cell file is written, but the prior's ranges cannot produce every measured figure

Figures = Annotated[
    Optional[Path],
    typer.Option(
        "--figures", help="CSV of measured figures: part, subset, axis, median_deg, p75_deg (docs/calibration.md)."
    ),
]
Scans = Annotated[
    Optional[Path],
    typer.Option("--scans", help="A result folder of `optipose evaluate` (of scans), or a folder of raw scans."),
]
Prior = Annotated[
    Optional[str], typer.Option("--cell", help="The prior: a cell of ranges (cobot, industrial-arm, ...) or its TOML.")
]
OutCell = Annotated[Optional[Path], typer.Option("--out", help="The calibrated cell file to write (TOML).")]
ScanObjective = Annotated[
    Optional[str],
    typer.Option(
        "--objective",
        help="Objective name in objectives/ or a TOML path; default: the scans' (--scans), else paper.",
    ),
]
Draws = Annotated[int, typer.Option("--draws", min=100, help="Prior draws of the importance sampler, per round.")]
Icp = Annotated[
    int, typer.Option("--icp", min=0, help="ICP evaluations at prior instances for the emulator's correction.")
]


@friendly_errors
def calibrate(
    part: Part,
    figures: Figures = None,
    scans: Scans = None,
    cell: Prior = None,
    out: OutCell = None,
    objective: ScanObjective = None,
    layout: LayoutFile = None,
    units: Units = "auto",
    draws: Draws = 20000,
    icp: Icp = 4,
    jobs: Jobs = 1,
    seed: Seed = 0,
) -> None:
    """Calibrate a cell: narrow a preset's ranges to a hand layout's measured figures.

    Inference over the preset's ranges on the hand layout's median and 75th percentile of |error| per sensor subset
    and axis, from a published table (--figures) or scans (--scans); writes a cell file for --cell."""
    calibration = calibrate_command(part, figures, scans, cell, out, objective, layout, units, draws, icp, jobs, seed)
    if calibration.out:
        raise typer.Exit(EXIT_MISFIT)


def calibrate_command(
    part: str,
    figures: Path | None,
    scans: Path | None,
    cell: str | None,
    out: Path | None,
    objective: str | None = None,
    layout: Path | None = None,
    units: str = "auto",
    draws: int = 20000,
    icp: int = 4,
    jobs: int | None = 1,
    seed: int = 0,
):
    """Run the calibration, print its lines, write the cell file; returns the
    :class:`optipose.calibrate.calibration.Calibration`."""
    from optipose.calibrate.calibration import calibrate as run
    from optipose.calibrate.cellfile import narrowed, write_cell
    from optipose.cell.config import file_key
    from optipose.evaluate.objective import load_objective
    from optipose.model.baseline import baseline
    from optipose.model.layout import load_layout
    from optipose.model.part import load_part

    if (figures is None) == (scans is None):
        raise ConfigError("calibrate needs one of --figures table.csv or --scans DIR")
    if cell is None:
        raise ConfigError("calibrate needs --cell PRESET, the prior whose ranges it narrows (e.g. --cell cobot)")
    if out is None:
        raise ConfigError("calibrate needs --out my_cell.toml, the calibrated cell file to write")
    if out.suffix != ".toml":
        raise ConfigError(f"--out {out}: a cell file ends in .toml")
    check_output(out, file=True)
    the_part = load_part(part, units=units)
    if scans is not None:
        if layout is not None:
            raise ConfigError("--layout is the scans' own with --scans (their manifest or result folder names it)")
        summaries, the_objective, the_layout = _from_scans(the_part, scans, objective, jobs)
    else:
        from optipose.calibrate.summaries import read_figures

        summaries = read_figures(figures, the_part.name)
        the_objective = load_objective(objective or "paper")
        the_layout = load_layout(layout) if layout is not None else baseline(the_part)
        if the_layout is None:
            raise ConfigError(f"part '{the_part.name}' has no hand-placed layout; give the measured one with --layout")
    the_objective = the_objective.in_cell(cell)
    typer.echo(
        f"calibrating '{the_objective.cell.name}' on {len(summaries.figures)} figures of {the_part.name} "
        f"({summaries.origin}), {icp} ICP evaluation(s) for the emulator's correction",
        err=True,
    )
    calibration = run(the_part, the_layout, the_objective, summaries, draws=draws, icp=icp, seed=seed, jobs=jobs or 1)
    for key in calibration.keys:
        _, name, unit = file_key(key)
        prior = next((lo / unit, hi / unit) for k, lo, hi in calibration.prior.ranges if k == key)
        low, high = (v / unit for v in narrowed(calibration, key)[:2])
        now = f"{low:.3g}" if low == high else f"[{low:.3g}, {high:.3g}]"
        typer.echo(f"  {name:24s} [{prior[0]:.3g}, {prior[1]:.3g}] -> {now}")
    for key in calibration.fixed:
        typer.echo(f"  {file_key(key)[1]:24s} kept (not emulated)")
    path = write_cell(calibration, out)
    post = calibration.posterior
    typer.echo(
        f"wrote {path}: --cell {path} (effective samples {post.ess:.0f}, {calibration.seconds:.0f} s, of it ICP "
        f"{calibration.correction.seconds:.0f} s)"
    )
    if calibration.out:
        typer.echo(
            f"optipose: warning: the ranges of '{calibration.prior.name}' cannot produce {len(calibration.out)} of "
            f"{len(summaries.figures)} figures, the model is missing a source: {'; '.join(calibration.out)}",
            err=True,
        )
    return calibration


def _from_scans(part, folder: Path, objective: str | None, jobs):
    """The summaries, objective and layout of a folder: a result folder of ``optipose evaluate`` (of scans or a
    simulation), or a scan folder (``optipose scan --protocol --raw``), evaluated here by ICP first
    (:func:`optipose.evaluate.recorded.evaluate_scans`). ``objective``: the registration's, default the folder's."""
    from optipose.calibrate.summaries import from_evaluation
    from optipose.evaluate.objective import load_objective

    folder = Path(folder)
    if not folder.is_dir():
        raise ConfigError(f"--scans {folder}: not a folder")
    if (folder / "config.toml").is_file():
        from optipose.io import load_result

        result = load_result(folder)
        if not hasattr(result, "stats") or not hasattr(result, "layout"):
            raise ConfigError(f"--scans {folder}: not the result folder of an evaluation")
        if result.part != part.name:
            raise ConfigError(f"--scans {folder}: an evaluation of '{result.part}', not of '{part.name}'")
        the_objective = result.objective if objective is None else load_objective(objective)
    else:
        from optipose.evaluate.recorded import evaluate_scans

        typer.echo(f"registering the scans of {folder} ({jobs or 1} job(s))", err=True)
        result, _ = evaluate_scans(part, folder, objective, jobs=jobs or 1)
        the_objective = result.objective
    return from_evaluation(result, f"scans {folder.name}"), the_objective, result.layout
