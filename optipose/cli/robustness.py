"""``optipose robustness``: the hand-placed and given layouts side by side under every condition of a band.

Each layout is evaluated under every condition of the objective's ``[conditions]`` (default objective:
``robust``: noise at 1, 3 and 5 times the preset's, brackets off by up to 0.2 mm and 0.1°); per layout and
condition the table shows its robust choice of all its sensors (at most as many as the hand layout has)
against the hand layout's robust choice of as many, each axis on a fixed subset, and
a verdict on the robust statistic (the worst over the conditions) says whether to keep the hand sensors.

When the band has a mounting tolerance (``--brackets``, the default then), each layout's bracket
sensitivity follows (:mod:`optipose.evaluate.sensitivity`, on the reduced protocol at the preset's noise):
how far each axis spreads with the brackets off, the bias an un-zeroed cell sees, and which sensor's
bracket to make precise.
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
Brackets = Annotated[
    Optional[bool],
    typer.Option(
        "--brackets/--no-brackets",
        help="Each layout's bracket sensitivity (reduced protocol, noise x1): spread, "
        "un-zeroed bias, the sensor to mount precisely. Default: on when the objective has a mounting tolerance.",
    ),
]


@friendly_errors
def robustness(
    part: Part,
    layout: Layouts = None,
    objective: Objective = "robust",
    cell: CellOption = None,
    units: Units = "auto",
    out: ResultFolder = None,
    jobs: Jobs = 1,
    seed: Seed = 0,
    brackets: Brackets = None,
    no_report: NoReport = False,
) -> None:
    """Compare layouts with the hand one under a band of conditions.

    Evaluate the hand-placed and the given layouts under every condition of the objective's band (noise
    levels, bracket tolerances) and say, per layout, whether it stays no worse than the hand one."""
    robustness_command(
        part, layout or [], objective, units, out, jobs or 1, seed, brackets, report=not no_report, cell=cell
    )


def robustness_command(
    part: str,
    layouts: list[Path],
    objective: str = "robust",
    units: str = "auto",
    out: Path | None = None,
    jobs: int = 1,
    seed: int = 0,
    brackets: bool | None = None,
    report: bool = True,
    cell: str | None = None,
) -> Path:
    """Run the evaluations, print the table and the verdicts, save the result folder; returns the folder."""
    from rich.console import Console

    from optipose.evaluate.objective import load_objective
    from optipose.evaluate.robust import evaluate_robust
    from optipose.io.folders import RESULTS_DIR, make_result_dir
    from optipose.io.robustness import write_robustness
    from optipose.model.collision import check_sensors_outside
    from optipose.model.layout import load_layout
    from optipose.model.baseline import baseline
    from optipose.model.part import load_part

    check_output(out or RESULTS_DIR, what="--out" if out else "result folder")
    the_part = load_part(part, units=units)
    reference = baseline(the_part)  # the hand-placed layout, else the conventional placement
    if reference is None:
        raise ConfigError(f"part '{the_part.name}' has no hand-placed layout to compare with")
    the_objective = load_objective(objective).in_cell(cell)
    if brackets is None:
        brackets = the_objective.conditions.mounted
    elif brackets and not the_objective.conditions.mounted:
        raise ConfigError(
            f"--brackets: objective '{the_objective.name}' has no mounting tolerance (mounting_translation_mm, "
            "mounting_rotation_deg in [conditions])"
        )
    given = [load_layout(p) for p in layouts]
    for lay in given:
        check_sensors_outside(the_part, lay)
    console = make_console(stderr=True)
    results = {}
    for i, lay in enumerate([reference, *given]):
        name = (
            "hand" if i == 0 else (lay.name if lay.name not in results else f"{lay.name}-{len(results)}")
        )  # two files of one name
        with status(console, f"{the_part.name}: {name} under {len(_conditions(the_objective))} conditions"):
            results[name] = evaluate_robust(the_part, lay, the_objective, seed=seed, jobs=jobs, quiet=True)
    folder = make_result_dir(the_part.name, "robustness", out)
    rows = write_robustness(
        folder, the_part, the_objective, seed, results, baseline="hand", sources=[str(p) for p in layouts]
    )
    Console().print(_table(rows, the_part.name))
    for line in _verdicts(results):
        Console().print(line)
    if brackets:
        _brackets(the_part, the_objective, seed, jobs, results, folder, console)
    if report:
        from optipose.cli.report import write_report_after

        write_report_after(folder, console)
    console.print(f"results: {folder}")
    return folder


def _brackets(part, objective, seed: int, jobs: int, results: dict, folder: Path, console) -> None:
    """Each layout's bracket sensitivity (its robust choice per k), printed and saved beside the rest."""
    from rich.console import Console

    from optipose.evaluate.sensitivity import BracketEvaluator
    from optipose.io.robustness import write_brackets

    found = {}
    with BracketEvaluator(part, objective, seed=seed, jobs=jobs) as evaluator:
        for name, result in results.items():
            n = len(result.layout)
            with status(
                console,
                f"{part.name}: {name}'s brackets ({1 + objective.conditions.mounting_draws * (3 + n)} evaluations)",
            ):
                found[name] = evaluator(result.layout, result.table)
    write_brackets(folder, found)
    for renderable in _bracket_tables(found, part.name):
        Console().print(renderable)


def _conditions(objective):
    from optipose.evaluate.conditions import conditions

    return conditions(objective.conditions)


def _verdicts(results: dict) -> list[str]:
    """Per given layout, the verdict on the robust statistic against the hand layout's choice of as many sensors."""
    from optipose.model.baseline import baseline_label
    from optipose.verdict.compare import Verdict
    from optipose.verdict.words import verdict_line

    baseline, lines = results["hand"], []
    label = baseline_label(baseline.layout)  # "conventional" for a part without a hand-placed layout
    for name, result in results.items():
        if name == "hand":
            continue
        k = min(len(result.layout), len(baseline.table))
        line = verdict_line(Verdict(k, result.table[k - 1], baseline.table[k - 1]), label)
        lines.append(f"{name} (worst over the band): {line}")
    return lines


def _table(rows, part_name: str):
    """One row per layout and condition: per axis median/p75 (mdeg), the score, and hand / this; narrow
    enough for an 80-column terminal (conditions as ``x3 m1``: noise times 3, mounting draw 1)."""
    from rich import box
    from rich.table import Table

    table = Table(
        title=f"{part_name}: under every condition, mdeg median/p75 (x: noise scale, m: bracket draw)",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
        collapse_padding=True,
    )
    for col in ("layout", "cond.", "roll", "pitch", "yaw", "score", "hand/it"):
        table.add_column(col, justify="left" if col in ("layout", "cond.") else "right", no_wrap=True)
    for (layout, k, condition), group in rows.groupby(["layout", "k", "condition"], sort=False):
        cells = {r.axis: f"{1e3 * r.median_deg:.2f}/{1e3 * r.p75_deg:.2f}" for r in group.itertuples()}
        first = group.iloc[0]
        ratio = "" if layout == "hand" else f"{first['hand_score_deg'] / first['score_deg']:.2f}x"
        short = condition.replace("noise x", "x").replace(", mounting draw ", " m")
        name = f"{layout} k{k}" if layout == "hand" else layout
        table.add_row(
            name, short, cells["roll"], cells["pitch"], cells["yaw"], f"{1e3 * first['score_deg']:.2f}", ratio
        )
    return table


def _bracket_tables(found: dict, part_name: str) -> list:
    """Per layout (its choice of all its sensors): each axis's spread with perfect and off brackets (mdeg
    median/p75, zeroed) and the mean error of an un-zeroed cell per draw and its worst magnitude (mdeg; µm
    for x, y, z), narrow enough for an 80-column terminal; then each
    sensor's score change with its bracket alone off, and per layout the bracket to make precise."""
    import numpy as np
    from rich import box
    from rich.table import Table

    first = next(iter(found.values()))
    protocol = f"{'reduced protocol, ' if first.reduced else ''}{first.n_scans} scans"
    axes = Table(
        title=f"{part_name}: brackets off by ±{1e3 * first.translation:g} mm, ±{np.rad2deg(first.rotation):g}° "
        f"({len(first.draws)} draw{'s' if len(first.draws) > 1 else ''}, noise x1, {protocol}); mdeg, µm for x y z",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
        collapse_padding=True,
    )
    for col in ("layout", "axis", "subset", "perfect", "off", "bias per draw", "worst"):
        axes.add_column(col, justify="left" if col in ("layout", "axis", "subset") else "right", no_wrap=True)
    sensors = Table(
        title="one bracket off at a time: change of each axis's median+p75 and of the score, mdeg (worst draw)",
        box=box.SIMPLE_HEAD,
        pad_edge=False,
        collapse_padding=True,
    )
    for col in ("layout", "sensor", "roll", "pitch", "yaw", "score", "rank"):
        sensors.add_column(col, justify="left" if col in ("layout", "sensor") else "right", no_wrap=True)
    lines = []
    for name, sens in found.items():
        k = len(sens.names)
        label = f"{name} k{k}" if name == "hand" else name
        for i, row in enumerate(_axis_rows(sens, k)):
            axes.add_row(label if i == 0 else "", *row)
        ranking = sens.ranking(k)
        for rank, s in enumerate(ranking, start=1):
            sensors.add_row(
                label if rank == 1 else "",
                s.name,
                *(_mdeg(c, signed=True) for c in s.change),
                _mdeg(s.score_change, signed=True),
                str(rank),
            )
        best = ranking[0]
        lines.append(
            f"{label}: make {best.name}'s bracket precise (score {_mdeg(best.score_change, signed=True)} mdeg with it alone off)"
        )
    return [axes, sensors, *lines]


def _axis_rows(sens, k: int) -> list[tuple[str, ...]]:
    """The cells of the axes table for the choice of k sensors: rotations in mdeg, translations in µm."""
    worst = sens.worst_bias(k)
    spread = {s.axis: s for s in sens.spread if s.k == k}
    rows = []
    for axis in dict.fromkeys(b.axis for b in sens.bias):
        biases = [b for b in sens.bias if b.k == k and b.axis == axis]
        rotation = axis in spread
        value = _mdeg if rotation else (lambda v, signed=False: f"{1e6 * v:+.1f}" if signed else f"{1e6 * v:.1f}")
        if rotation:
            s = spread[axis]
            perfect, off = (
                f"{_mdeg(s.nominal_median)}/{_mdeg(s.nominal_p75)}",
                f"{_mdeg(s.mounted_median)}/{_mdeg(s.mounted_p75)}",
            )
        else:
            perfect = off = ""
        rows.append(
            (
                axis,
                biases[0].subset or "-",
                perfect,
                off,
                " ".join(value(b.bias, signed=True) for b in biases),
                value(worst[axis]),
            )
        )
    return rows


def _mdeg(rad: float, signed: bool = False) -> str:
    """A rotation's cell: millidegrees to two places, ``n/a`` where not finite."""
    from optipose.verdict.words import mdeg_text

    return mdeg_text(rad, 2, signed, missing="n/a")
