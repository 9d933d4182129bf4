"""``optipose search``: place 1, 2, 3 sensors automatically and compare with the hand-placed layout.

:func:`search` is the Typer command (registered by :mod:`optipose.cli.app`), :func:`search_command` the
plain function behind it; imports of the library stay lazy so ``optipose --help`` is instant.
"""

from __future__ import annotations

import os
import tomllib
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

__all__ = ["search", "search_command", "verdict_headline", "stage_budget"]


@friendly_errors
def search(
    part: Part = None,
    units: Units = "auto",
    sensors: Annotated[str, typer.Option(help="Sensor counts to place, e.g. 1,2,3.")] = "1,2,3",
    budget: Annotated[
        str,
        typer.Option(
            help="quick (a first look), default (the search in the objective's cell, the paper's by default, its verdict raced on draws of the cell; in the ideal cell then checked under the band too) or thorough."
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
) -> None:
    """Place 1, 2, 3 … sensors automatically and compare with the hand layout.

    Search sensor poses with NLopt on a fast surrogate, pick and polish finalists by ICP, validate them on
    the full ICP protocol with a held-out noise seed, and print found vs. hand-placed per axis (the paper's
    Table 1 shape)."""
    search_command(
        part, units, sensors, budget, objective, seed, jobs, out, resume, config, report=not no_report, cell=cell
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
) -> Path:
    """Run the search, print found vs. hand-placed, keep everything in the result folder; returns the folder.

    With ``resume`` the part, budget, seed, objective and search settings come from that folder's config.toml.
    """
    from rich.console import Console

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
            band=not the_objective.conditions.trivial,
            cell=not the_objective.cell.ideal,
        )
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
    # a nominal search that did not check its answer under a band (quick, or `band = ""`) says so: its "better"
    # holds in the simulation's ideal cell only, which is not yet a reason to buy
    unchecked = (
        the_objective.conditions.trivial
        and the_objective.cell.ideal
        and searched.band is None
        and not searched.band_interrupted
    )
    _print_report(Console(), searched, the_part, unchecked, ideal=the_objective.cell.ideal)
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
    if searched.band_interrupted:  # the validation above is complete; only its check under the band is missing
        console.print(
            f"[yellow]interrupted[/] during the check under the band: the verdicts above hold for the nominal cell "
            f"only (results in {folder}); check them with `optipose robustness {part} --layout "
            f"{folder}/layouts/found_k{max(searched.layouts)}.toml`, or run the whole search again"
        )
        raise typer.Exit(EXIT_INTERRUPTED)
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
    from optipose.search.config import SearchConfig, search_preset, unknown_keys

    part = _needed(saved.part_source, "part" if saved.part_name is None else "source") or _needed(
        saved.part_name, "name"
    )
    cfg = _needed(saved.search, "search")  # sectioned, or flat as folders written before the sections have it
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
    from dataclasses import replace

    from optipose.model.baseline import baseline, baseline_label
    from optipose.report.views import render_layouts

    hand = baseline(part)
    named = {f"found_k{k}": lay for k, lay in layouts.items()} | (
        {baseline_label(hand): hand} if hand is not None else {}
    )
    shown = replace(part, layouts={**part.layouts, **named})
    thread = threading.Thread(target=render_layouts, args=(shown, list(named), folder / "layouts", jobs), daemon=True)
    thread.start()
    return thread


def _print_report(console, report, part, unchecked: bool = False, ideal: bool = True) -> None:
    """The verdict first, one line per k (:func:`verdict_headline`), then the details: found vs. the
    baseline per axis on the validation protocol (the records ``comparison.csv`` was written from, which
    :func:`optipose.io.load_result` reads back), the subsets each axis uses, the band, the full verdict
    lines, the surrogate's strategies and the found poses. Every table fits an 80-column terminal.
    ``unchecked``: the answer was never checked under a band (a nominal search without the check); ``ideal``:
    the search ran in the ideal cell (its verdicts say so)."""
    from optipose.verdict.compare import mdeg
    from optipose.verdict.confidence import split
    from optipose.model.baseline import baseline, baseline_label
    from optipose.report.confidence import IDEAL_CELL, mount_line

    label = baseline_label(baseline(part))
    if report.validated:
        verdicts = report.validation.verdicts()
        band = report.band.by_k() if report.band is not None else {}
        confident, fewer = split(getattr(report, "confident", {}))
        for v in confident.values() or verdicts:
            console.print(
                v.line() if confident else verdict_headline(v, label, band.get(v.k), checked=not unchecked),
                highlight=False,
            )
        for v in confident.values():
            if line := mount_line(v, report.layouts.get(v.k), baseline(part)):
                console.print(line, highlight=False)
        if fewer is not None:
            console.print(fewer.fewer_line(), highlight=False)
        if confident and ideal:
            console.print("these verdicts hold " + IDEAL_CELL, style="yellow", highlight=False)
        if confident:
            console.print(_confident_table(confident, part))
        if unchecked and not confident and any(v.no_worse for v in verdicts):
            from optipose.verdict.compare import UNCHECKED

            console.print(UNCHECKED, style="yellow", highlight=False)
        for line in report.validation.unmeasured_lines(label):
            console.print(line, style="bold red", highlight=False)
        lines = report.validation.verdict_lines(label)
        found, hand = report.validation.found, report.validation.hand
        if 1 in found and max(hand, default=0) > 1 and fewer is None:  # the headline: fewer sensors to buy
            top = hand[max(hand)]
            beats = "beats" if found[1].score < top.score else "does not beat"
            console.print(
                f"one found sensor {beats} {label} {top.name} in sum ({mdeg(found[1].score):.3f} vs "
                f"{mdeg(top.score):.3f} mdeg)",
                highlight=False,
            )
        console.print(_validation_table(report.validation, part, label))
        console.print(_subsets_table(report.validation, label))
        if any(v.ratios() for v in verdicts):
            console.print(_band_table(report.validation, part, label))
        for line in (
            lines[: len(verdicts)] if band or not confident else ()
        ):  # the validation draw's own lines, before the band's check
            console.print(line, highlight=False)
        if band:
            console.print(_band_table(report.band, part, label, "under the band"))
            for v in band.values():
                console.print(f"under the band: {v.line(label)}", highlight=False)
            nominal = {v.k: v.no_worse for v in verdicts}
            for v in band.values():
                if advice := v.band_advice(label, nominal.get(v.k, False)):
                    console.print(advice, highlight=False)
    console.print(_strategies_table(report.outcome, label))
    for k, layout in sorted(report.layouts.items()):
        console.print(f"[bold]found k={k}[/] (T_O_S, metres; X Y Z mm, roll pitch yaw deg):")
        for name, T in zip(layout.names, layout.poses):
            console.print(f"  {name}:\n" + "\n".join("    [" + "  ".join(f"{v: .5f}" for v in row) + "]" for row in T))
            console.print(f"    {_xyz_rpy(T)}", highlight=False)


def verdict_headline(verdict, label: str = "hand", band=None, checked: bool = True) -> str:
    """The verdict for one k in one short line (under 80 characters for the hand layout and names up to 6):
    buy or keep. ``band``: the same k's verdict under the band of the check after the validation; a found
    layout no worse at the preset's noise but worse somewhere in the band is not bought
    (:func:`optipose.verdict.compare.bought`). ``checked=False``: the answer was never checked under a
    band (a nominal search without the check), so a layout no worse in the ideal cell is better there, not
    yet bought. Where registrations failed on some axis of either layout: no verdict, and whose."""
    from optipose.verdict.compare import bought

    ratio, found, ref = verdict.ratio, verdict.found.name, verdict.reference.name
    mine, theirs = verdict.failed  # registrations failed on some axis: nothing to rank (Verdict.failed_line says more)
    if mine or theirs:
        who = f"found {found}" if mine else f"{label} {ref}"
        return f"k={verdict.k}: NO VERDICT: registrations of {who} failed ({', '.join(mine or theirs)})"
    if verdict.tie:
        return f"k={verdict.k}: KEEP {label} {ref}: found {found} ties it on every axis"
    if verdict.no_worse and not bought(verdict, band):
        return f"k={verdict.k}: KEEP {label} {ref}: {found} {ratio:.2f}x better, but worse under the band"
    if verdict.no_worse and not checked:
        return f"k={verdict.k}: found {found} {ratio:.2f}x better, no axis worse, in the ideal cell"
    if verdict.no_worse:
        return f"k={verdict.k}: BUY found {found}: {ratio:.2f}x better in sum than {label} {ref}, no axis worse"
    if ratio < 1:
        return f"k={verdict.k}: KEEP {label} {ref}: found {found} is {1 / ratio:.2f}x worse in sum"
    axes = ", ".join(dict.fromkeys(g.axis for g in verdict.worse))
    return f"k={verdict.k}: found {found} {ratio:.2f}x better in sum than {label} {ref}, worse on {axes}"


def _xyz_rpy(T) -> str:
    import numpy as np

    from optipose.transforms import matrix_to_rpy

    xyz, rpy = np.asarray(T)[:3, 3] * 1e3, np.rad2deg(matrix_to_rpy(np.asarray(T)[:3, :3]))
    return "XYZ " + " ".join(f"{v:.3f}" for v in xyz) + " mm, RPY " + " ".join(f"{v:.3f}" for v in rpy) + " deg"


def _compact(value: float) -> str:
    """Millidegrees in at most 6 characters: 3 significant digits."""
    return f"{value:.3g}" if value < 1e4 else f"{value:.0f}"


def _short_reason(axis) -> str:
    """Why an axis has no number, in a 6-character cell."""
    return "failed" if axis.label == "registrations failed" else "unobs."


def _short(label: str) -> str:
    """A layout's label in a table column: ``conventional`` as ``conv.``."""
    return "conv." if label == "conventional" else label


def _narrow_table(title: str, columns: list[tuple[str, str]]):
    """A rich table that keeps every row on one line of an 80-column terminal."""
    from rich import box
    from rich.table import Table

    table = Table(title=title, box=box.SIMPLE_HEAD, pad_edge=False, collapse_padding=True)
    for name, justify in columns:
        table.add_column(name, justify=justify, no_wrap=True)
    return table


def _confident_table(confident: dict, part):
    """Per k, found and the baseline: the predicted median |error| per axis in the cell with its interval (mdeg)."""
    from optipose.report.confidence import interval_cell

    v = next(iter(confident.values()))
    table = _narrow_table(
        f"{part.name}: predicted median |error| in the cell, mdeg [{100 * v.confidence:.1f} % interval]",
        [("k", "right"), ("sensors", "left"), ("roll", "right"), ("pitch", "right"), ("yaw", "right")],
    )
    for k, v in sorted(confident.items()):
        for name, axes in ((v.found_name, v.found), (v.hand_name, v.hand)):
            table.add_row(str(k), name, *(interval_cell(a.median_deg, digits=2) for a in axes))
    return table


def _validation_table(validation, part, label: str = "hand"):
    """One row per k and layout (found, baseline): median/p75 per axis and the score, in mdeg."""
    from optipose.verdict.compare import mdeg

    protocol = "full protocol" if validation.protocol == "full" else "REDUCED protocol (14 scans)"
    band = ", worst over the band" if any(c.under for c in validation.found.values()) else ""
    table = _narrow_table(
        f"{part.name}: found vs. {label}, {protocol}, held-out seed{band}; mdeg median/p75",
        [
            ("k", "right"),
            ("layout", "left"),
            ("sensors", "left"),
            ("roll", "right"),
            ("pitch", "right"),
            ("yaw", "right"),
            ("score", "right"),
        ],
    )
    for k in sorted({*validation.found, *validation.hand}):
        for name, choices in (("found", validation.found), (label, validation.hand)):
            if k in choices:
                choice = choices[k]
                cells = [
                    f"{_compact(mdeg(a.median))}/{_compact(mdeg(a.p75))}" if a.observable else _short_reason(a)
                    for a in choice.axes
                ]
                table.add_row(str(k), _short(name), choice.name, *cells, _compact(mdeg(choice.score)))
    return table


def _subsets_table(validation, label: str = "hand"):
    """The sensor subset each axis uses, per k and layout."""
    table = _narrow_table(
        "the subset each axis uses",
        [("k", "right"), ("layout", "left"), ("roll", "left"), ("pitch", "left"), ("yaw", "left")],
    )
    for k in sorted({*validation.found, *validation.hand}):
        for name, choices in (("found", validation.found), (label, validation.hand)):
            if k in choices:
                table.add_row(str(k), _short(name), *(a.label for a in choices[k].axes))
    return table


def _band_table(validation, part, label: str = "hand", title: str = "per condition"):
    """Per k and noise level of the band: baseline / found in sum, and whether found is no worse on every axis."""
    verdicts = [v for v in validation.verdicts() if v.levels()]
    table = _narrow_table(
        f"{part.name}: {label} / found {title} (* found worse on some axis)",
        [("condition", "left")] + [(f"k={v.k}", "right") for v in verdicts],
    )
    for row in zip(*(v.levels() for v in verdicts)):
        table.add_row(row[0][0], *(f"{ratio:.2f}{'' if no_worse else '*'}" for _, ratio, no_worse in row))
    return table


def _strategies_table(outcome, label: str = "hand"):
    """The surrogate's predicted score per k for greedy, joint and the baseline, and which strategy won."""
    strategies = _narrow_table(
        f"surrogate: predicted score (mdeg), greedy vs. joint vs. {label}",
        [("k", "right"), ("greedy", "right"), ("joint", "right"), (_short(label), "right"), ("winner", "right")],
    )
    for k in sorted(outcome.found):
        g, j, h = outcome.greedy.get(k), outcome.joint.get(k), outcome.hand.get(k)
        fmt = lambda f: f"{1e3 * f.stats.score:.3f}" if f is not None and f.stats else "-"  # noqa: E731
        strategies.add_row(str(k), fmt(g), fmt(j), fmt(h), outcome.found[k].strategy)
    return strategies
