"""``optipose search``: place 1, 2, 3 sensors automatically and compare with the hand-placed layout.

:func:`search` is the Typer command (registered by :mod:`optipose.cli.app`), :func:`search_command` the
plain function behind it; imports of the library stay lazy so ``optipose --help`` is instant.
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Annotated, Optional

import typer

from optipose.cli.options import (
    EXIT_INTERRUPTED,
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
from optipose.cli.progress import make_console
from optipose.cli.report import NoReport
from optipose.errors import ConfigError, is_interrupt, read_toml

__all__ = ["search", "search_command", "stage_budget"]


@friendly_errors
def search(
    part: Part = None,
    units: Units = "auto",
    sensors: Annotated[str, typer.Option(help="Sensor counts to place, e.g. 1,2,3.")] = "1,2,3",
    budget: Annotated[
        str,
        typer.Option(
            help="quick (a first look), default (the search in the objective's cell, the paper's by default, its verdict raced on draws of the cell) or thorough."
        ),
    ] = "default",
    objective: Objective = "paper",
    cell: CellOption = None,
    seed: Seed = 0,
    jobs: Jobs = None,
    out: ResultFolder = None,
    resume: Annotated[
        Optional[Path],
        typer.Option(help="Continue the search in this result folder (same settings; PART is then not needed)."),
    ] = None,
    config: Annotated[
        Optional[Path],
        typer.Option(
            "--search-config",
            help="TOML with a search table overriding the budget (algorithms, evaluations, constraints).",
        ),
    ] = None,
    no_report: NoReport = False,
    max_time: Annotated[
        float,
        typer.Option(
            "--max-time",
            help="Seconds the whole search may take (0: no clock). Without it every stage ends by its counts and a "
            "seed gives the same answer on any machine; with it, the answer says what the clock cut.",
        ),
    ] = 0.0,
) -> None:
    """Place 1, 2, 3 … sensors automatically and compare with the hand layout.

    Search sensor poses with NLopt on a fast surrogate, pick and polish finalists by ICP, validate them on
    the full ICP protocol with a held-out noise seed, and print found vs. hand-placed per axis (the paper's
    Table 1 shape)."""
    search_command(
        part,
        units,
        sensors,
        budget,
        objective,
        seed,
        jobs,
        out,
        resume,
        config,
        report=not no_report,
        cell=cell,
        max_time=max_time,
    )


def search_command(
    part: str | None = None,
    units: str = "auto",
    sensors: str = "1,2,3",
    budget: str = "default",
    objective: str = "paper",
    seed: int = 0,
    jobs: int | None = None,
    out: Path | None = None,
    resume: Path | None = None,
    config: Path | None = None,
    report: bool = True,
    cell: str | None = None,
    max_time: float = 0.0,
) -> Path:
    """Run the search, print found vs. hand-placed, keep everything in the result folder; returns the folder.

    With ``resume`` the part, budget, seed, objective and search settings come from that folder's config.toml.
    """
    from rich.console import Console

    from optipose.cli.answer import print_answer
    from optipose.evaluate.objective import load_objective
    from optipose.io.folders import RESULTS_DIR, make_result_dir
    from optipose.model.part import load_part
    from optipose.search.budgets import config_from_budget

    console = make_console(stderr=True)
    jobs = jobs or os.cpu_count() or 1
    if part is None and resume is None:
        raise ConfigError("give a PART to search (a shipped part name or a mesh file), or --resume DIR")
    if resume:
        part, search_config, budget, seed, the_objective, saved_units = _resumed_settings(resume)
        check_output(resume, what="--resume")
        if units == "auto":  # the units the search was started with
            units = saved_units or units
    else:
        the_objective = load_objective(objective).in_cell(cell)
        search_config = config_from_budget(
            budget,
            _parse_sensors(sensors),
            _overrides(config),
            cell=not the_objective.cell.ideal,
            kinds=_checked_in(cell, the_objective.cell),
        )
    if max_time:  # the user's clock on the whole search (a resumed search takes it anew)
        search_config = replace(search_config, time_limit=max_time)
    if not resume:
        check_output(out or RESULTS_DIR, what="--out" if out else "result folder")
    the_part = load_part(part, units=units)
    folder = resume or make_result_dir(the_part.name, "search", out)

    try:
        searched = _run_with_progress(
            console, the_part, the_objective, search_config, seed, folder, budget, jobs, bool(resume)
        )
    except (KeyboardInterrupt, SystemError) as exc:
        if not is_interrupt(exc):
            raise
        console.print(
            f"[yellow]interrupted[/]: what was computed is in {folder} (history, cache, layouts found so far); "
            f"continue with `optipose search --resume {folder}`"
        )
        raise typer.Exit(EXIT_INTERRUPTED) from None
    pictures = _draw_layouts(folder, the_part, searched.layouts, jobs) if searched.validated else None
    # a search in the ideal cell says so: its "better" holds in the simulation's ideal cell only, which is not yet a
    # reason to buy (a cell with ranges, --cell cobot etc., says what a real cell does not know)
    unchecked = the_objective.cell.ideal
    print_answer(
        Console(), searched, the_part, unchecked, ideal=the_objective.cell.ideal, time_limit=search_config.time_limit
    )
    from optipose.verdict.words import cell_advice, kinds_line

    for k in sorted(searched.confident.by_k):  # each BUY raced again where the user's cell may lie
        if line := kinds_line(k, searched.kinds):
            Console().print(line, highlight=False)
    if cell is None and searched.validated and not the_objective.cell.ideal and not the_objective.cell.ranges:
        Console().print(cell_advice(the_objective.cell.name), style="yellow", highlight=False)
    ready = pictures.join if pictures is not None else None
    if searched.outcome.interrupted:
        console.print(
            f"[yellow]interrupted[/]: the best layouts so far are in {folder}/layouts; continue with "
            f"`optipose search --resume {folder}`"
        )
        raise typer.Exit(EXIT_INTERRUPTED)
    if report:
        from optipose.cli.report import write_report_after

        write_report_after(folder, console, ready)
    if ready:
        ready()
    console.print(f"results: {folder}")
    return folder


def _resumed_settings(resume: Path):
    """(part, search config, budget, seed, objective, the part's --units or None) as saved in a search result
    folder's config.toml, read once; a folder whose settings this version cannot take (an older optipose's)
    is one ConfigError."""
    saved = _resumed(resume)
    try:
        return (*_settings(saved), saved.part_units)
    except (KeyError, TypeError, ValueError, AttributeError, ConfigError) as exc:
        why = (
            f"no '{exc.args[0]}' in it"
            if isinstance(exc, KeyError)
            else (str(exc).splitlines() or [type(exc).__name__])[0]
        )
        raise ConfigError(
            f"--resume {resume}: its config.toml ({_written_by(saved)}) cannot be resumed by this "
            f"version: {why}; start a new search"
        ) from None


def _written_by(saved) -> str:
    """Which optipose wrote a result folder, as its config.toml (``saved``, a RunConfig) says."""
    return f"optipose {saved.versions.get('optipose', '?')}, result format {'none' if saved.format is None else saved.format}"


def _settings(saved):
    """The settings of a config.toml (``saved``, a RunConfig); KeyError, TypeError, ValueError or
    ConfigError where this version cannot take them."""
    from optipose.evaluate.objective import objective_from_table
    from optipose.search.config import SearchConfig, saved_table, search_preset, unknown_keys

    part = _needed(saved.part_source, "part" if saved.part_name is None else "source") or _needed(
        saved.part_name, "name"
    )
    cfg = saved_table(_needed(saved.search, "search"))  # sectioned, or flat as folders written before the sections
    unknown = unknown_keys(cfg)
    if unknown:  # a setting this version no longer has
        raise ConfigError(f"unknown search setting(s) {', '.join(unknown)}")
    _needed(cfg.get("sensors"), "sensors")
    search_config = search_preset(cfg).apply(SearchConfig())
    budget, seed = str(_needed(saved.budget, "budget")), int(_needed(saved.seed, "seed"))
    text = _needed(saved.objective_file, "objective_file")
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"its objective_file does not parse: {exc}") from None
    return part, search_config, budget, seed, objective_from_table(table, source_text=text)


def _needed(value, key: str):
    """A config value a resume cannot do without; KeyError naming its key where the file has none (the
    message then says which)."""
    if value is None:
        raise KeyError(key)
    return value


def _parse_sensors(text: str) -> tuple[int, ...]:
    """``--sensors 1,2,3`` as sorted, distinct sensor counts."""
    try:
        values = tuple(sorted({int(v) for v in text.split(",") if v.strip()}))
    except ValueError:
        raise ConfigError(f"--sensors: expected counts like 1,2,3, got '{text}'") from None
    if not values:
        raise ConfigError("--sensors: give at least one sensor count")
    return values


def _checked_in(cell: str | None, the_cell) -> tuple[str, ...]:
    """The cells a search's BUYs are raced again in (:mod:`optipose.search.kinds`): the common kinds where the user
    named no cell and the objective's is one of points; the ends of the ranges of a cell with ranges; else none."""
    from optipose.search.kinds import COMMON_KINDS

    if the_cell.ideal:
        return ()
    if the_cell.ranges:
        name = cell if cell is not None else the_cell.name
        return (f"{name}:low", f"{name}:high")
    return COMMON_KINDS if cell is None else ()


def _overrides(path: Path | None):
    """The ``[search]`` table of a ``--search-config`` TOML as a preset (``search.config.Preset``): by section
    (``[search.surrogate]`` …) or by the flat keys (``global_evals`` …), its keys checked against SearchConfig's."""
    from optipose.search.config import FLAT_KEYS, SECTIONS, search_preset, unknown_keys

    if path is None:
        return None
    if not path.is_file():
        raise ConfigError(f"search config not found: {path}")
    table = read_toml(path, "search config")[0].get("search", {})
    unknown = unknown_keys(table)
    if unknown:
        known = sorted({*FLAT_KEYS, "sensors"})
        raise ConfigError(
            f"search config {path}: unknown key(s) {', '.join(unknown)} (known: {', '.join(known)}; "
            f"or by section: {', '.join(SECTIONS)})"
        )
    try:
        return search_preset(table)
    except ConfigError as exc:
        raise ConfigError(f"search config {path}: {exc}") from None


def _resumed(resume: Path):
    """The config.toml of a search result folder as a RunConfig (refusing any other folder, and one of
    another format)."""
    from optipose.io.folders import RESULT_FORMAT, read_config

    if not resume.is_dir():
        raise ConfigError(f"--resume {resume}: not a folder (give a search's result folder)")
    if not (resume / "config.toml").is_file():
        raise ConfigError(f"--resume {resume}: no config.toml there (not a search result folder)")
    try:
        saved = read_config(resume)
    except ConfigError as exc:
        raise ConfigError(f"--resume {resume}: its config.toml is damaged ({str(exc).splitlines()[0]})") from None
    if saved.command != "search":
        raise ConfigError(f"--resume {resume}: that folder holds a '{saved.command}' result, not a search")
    written = saved.format
    if written is not None and written != RESULT_FORMAT:
        raise ConfigError(
            f"--resume {resume}: written by another optipose ({_written_by(saved)}); this version "
            f"reads result format {RESULT_FORMAT}: start a new search"
        )
    return saved


def _run_with_progress(console, part, objective, config, seed, folder, budget, jobs, resume):
    """Run the search pipeline, its progress on ``console``: per stage of the surrogate search its
    evaluations (against the stage's budget) and the best score so far, then the ICP stages by name."""
    import numpy as np

    from optipose.cli.progress import StageProgress
    from optipose.io.search import SearchFolder
    from optipose.search.pipeline import run

    with StageProgress(console, part.name, "evaluations") as progress:

        def on_eval(evaluation):
            if evaluation.stage != progress.name:
                progress.stage(evaluation.stage, stage_budget(config, evaluation.stage))
            best = f"best k={evaluation.k}: {1e3 * evaluation.best:.3f} mdeg" if np.isfinite(evaluation.best) else None
            progress.advance(detail=best)

        def on_stage(text):
            progress.stage(text, detail="")  # an ICP stage: no surrogate evaluations, no surrogate score

        return run(part, objective, config, seed, SearchFolder(folder), budget, jobs, resume, on_eval, on_stage)


def stage_budget(config, stage: str) -> int | None:
    """At most how many surrogate evaluations a stage of the search (``screen:k=2``, ``greedy:k=1`` …)
    makes, as its settings in ``config`` allow (its clock may end it sooner); None for another stage."""
    surrogate = config.surrogate
    budgets = {
        "screen": surrogate.screen_samples,
        "screen-polish": surrogate.screen_starts * surrogate.screen_evals,  # a local polish per start picked
        "greedy": surrogate.global_evals,
        "greedy-polish": surrogate.local_evals + surrogate.local_evals // 2,  # and the hand start's, when it led
        "joint": surrogate.joint_evals,  # shared between its starts
    }
    return budgets.get(stage.split(":")[0]) or None


def _draw_layouts(folder: Path, part, layouts, jobs: int):
    """``layouts/found_k*.png`` and the baseline's beside their TOML files, drawn as ``optipose show`` does by a
    thread on ``jobs`` worker processes while this one prints the answer and writes the report; returns the
    started thread (``join`` waits for the pictures)."""
    import threading

    from optipose.model.baseline import baseline, baseline_label
    from optipose.report.views import render_layouts

    baseline_layout = baseline(part)
    named = {f"found_k{k}": lay for k, lay in layouts.items()} | (
        {baseline_label(baseline_layout): baseline_layout} if baseline_layout is not None else {}
    )
    shown = replace(part, layouts={**part.layouts, **named})
    thread = threading.Thread(target=render_layouts, args=(shown, list(named), folder / "layouts", jobs), daemon=True)
    thread.start()
    return thread
