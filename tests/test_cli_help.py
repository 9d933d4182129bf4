"""How the command line presents itself: help that reads whole at 80 columns, ``--version``, one-line
usage errors, and progress that is plain whole lines when the output is not a terminal."""

from __future__ import annotations

import io
import os
import re
import subprocess
import sys
from importlib.metadata import version

import pytest
from rich.console import Console

from cli_checks import assert_one_line_error, run

COMMANDS = [
    "scan",
    "parts",
    "show",
    "counts",
    "cells",
    "evaluate",
    "search",
    "calibrate",
    "robustness",
    "batch",
    "study",
    "report",
]


def _help(*command: str, columns: int = 80) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": str(columns)}
    return subprocess.run(
        [sys.executable, "-m", "optipose", *command, "--help"], capture_output=True, text=True, timeout=60, env=env
    )


def _declared(command: str | None) -> list[str]:
    """Every help text the code declares for the top level (None) or a command: its own, and its options'."""
    import typer

    from optipose.cli.app import app

    group = typer.main.get_command(app)
    if command is None:
        return [group.help, *(c.short_help for c in group.commands.values()), *(p.help for p in group.params)]
    cmd = group.commands[command]
    return [cmd.help.partition("\f")[0], *(p.help for p in cmd.params if getattr(p, "help", None))]


def _words(text: str) -> str:
    return " ".join(text.replace("│", " ").split())


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_help_at_80_columns_shows_every_help_text_whole(command):
    shown = _help(*([command] if command else []))
    assert shown.returncode == 0, shown.stderr
    lines = shown.stdout.splitlines()
    assert max(len(line) for line in lines) <= 80
    text = _words(shown.stdout)
    for declared in _declared(command):
        assert _words(declared) in text, declared  # no word dropped, cut or split by a hard line break


def test_help_keeps_brackets_and_shows_defaults_whole():
    batch = _words(_help("batch").stdout)
    assert "(TOML: a [grid] and/or [[trials]]; see studies/)" in batch
    search = _words(_help("search").stdout)
    assert "results/<part>-<command>-<timestamp>/" in search and "[default: default]" in search
    assert not re.search(r"~\s*\d|\d\s*(s|min)\b", search)  # no measured timings in the help: they live in docs


def test_version():
    shown = run("--version")
    assert shown.returncode == 0 and shown.stdout == f"optipose {version('optipose')}\n"


def test_no_arguments_shows_the_help():
    shown = run()
    assert shown.returncode == 2 and shown.stdout.startswith("Usage: optipose [OPTIONS] COMMAND")


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["search", "part_b", "--jobs", "0"], "--jobs"),
        (["evaluate", "part_b", "--jobs", "0"], "--jobs"),
        (["batch", "study.toml", "--jobs", "0"], "--jobs"),
        (["robustness", "part_b", "--jobs", "two"], "--jobs"),
        (["search", "part_b", "--seed", "1.5"], "--seed"),
        (["search", "part_b", "--frobnicate"], "--frobnicate"),
        (["scan"], "PART"),
        (["batch"], "STUDY_FILE"),
        (["evaluate", "part_b", "--units"], "--units"),
        (["parts", "extra"], "extra"),
        (["no-such-command"], "no-such-command"),
    ],
)
def test_a_usage_error_is_one_line_and_exit_2(args, fragment):
    result = run(*args)
    assert_one_line_error(result, fragment)
    assert "╭" not in result.stderr and "Usage:" not in result.stderr and result.stdout == ""


# --- progress ----------------------------------------------------------------------------------------------
def _plain_console() -> tuple[Console, io.StringIO]:
    out = io.StringIO()
    return Console(file=out, width=40), out  # a file, not a terminal; narrower than any line below


def test_progress_off_a_terminal_is_whole_lines_per_stage_and_every_few_seconds():
    from optipose.cli.progress import StageProgress, plain_line

    assert (
        plain_line("part_b", "screen:k=2", "1200/4096 evaluations", "best k=2: 0.780 mdeg", 41.2)
        == "part_b: screen:k=2 1200/4096 evaluations, best k=2: 0.780 mdeg, 41 s"
    )
    console, out = _plain_console()
    now = [0.0]
    with StageProgress(console, "part_b", "evaluations", every=10.0, clock=lambda: now[0]) as progress:
        progress.stage("searching on the surrogate")
        progress.stage("screen:k=1", 1024)
        for i in range(1024):
            now[0] += 1 / 32  # exact in binary: the lines fall on whole seconds
            progress.advance(detail=f"best k=1: {1 + 1 / (i + 1):.3f} mdeg")
        progress.stage("greedy:k=1", 70)
        for _ in range(75):  # past its bound (a stage may exceed what it was told): a count, not 75/70
            now[0] += 1 / 4
            progress.advance()
        progress.stage("validating on the full protocol (held-out noise seed)", detail="")
    lines = out.getvalue().splitlines()
    assert lines == [
        "part_b: searching on the surrogate, 0 s",
        "part_b: screen:k=1 0/1024 evaluations, 0 s",
        "part_b: screen:k=1 320/1024 evaluations, best k=1: 1.003 mdeg, 10 s",
        "part_b: screen:k=1 640/1024 evaluations, best k=1: 1.002 mdeg, 20 s",
        "part_b: screen:k=1 960/1024 evaluations, best k=1: 1.001 mdeg, 30 s",
        "part_b: screen:k=1 done, 1024 evaluations, best k=1: 1.001 mdeg, 32 s",
        "part_b: greedy:k=1 0/70 evaluations, best k=1: 1.001 mdeg, 32 s",
        "part_b: greedy:k=1 40/70 evaluations, best k=1: 1.001 mdeg, 42 s",
        "part_b: greedy:k=1 done, 75 evaluations, best k=1: 1.001 mdeg, 51 s",
        "part_b: validating on the full protocol (held-out noise seed), 51 s",
    ]


def test_progress_on_a_terminal_never_shows_a_count_past_its_total():
    from optipose.cli.progress import StageProgress, count_text

    assert (
        count_text(70, 70, "evaluations") == "70/70 evaluations"
        and count_text(71, 70, "evaluations") == "71 evaluations"
    )
    console = Console(file=io.StringIO(), force_terminal=True, width=80)
    with StageProgress(console, "part_b", "evaluations") as progress:
        progress.stage("greedy:k=1", 3)
        progress.advance(3)
        task = progress._bar.tasks[0]
        assert (task.completed, task.total, task.fields["count"]) == (3, 3, "3/3 evaluations")
        progress.advance()
        assert (task.completed, task.total, task.fields["count"]) == (4, None, "4 evaluations")
        progress.stage("joint:k=2", 10)
        assert (task.completed, task.total, task.fields["count"]) == (0, 10, "0/10 evaluations")


def test_a_spinner_off_a_terminal_is_a_line_at_its_start_and_end():
    from optipose.cli.progress import status

    console, out = _plain_console()
    now = [5.0]
    with status(console, "part_b: hand under 4 conditions, a text wider than the console", clock=lambda: now[0]):
        now[0] += 12.4
    assert out.getvalue().splitlines() == [
        "part_b: hand under 4 conditions, a text wider than the console",
        "part_b: hand under 4 conditions, a text wider than the console done, 12 s",
    ]


def test_each_search_stage_budget_bounds_its_evaluations():
    from optipose.cli.search import stage_budget
    from optipose.search.budgets import config_from_budget

    quick = config_from_budget("quick", (1, 2, 3))
    assert stage_budget(quick, "screen:k=2") == quick.surrogate.screen_samples == 1024
    assert stage_budget(quick, "greedy:k=3") == quick.surrogate.global_evals
    assert stage_budget(quick, "screen-polish:k=1") == quick.surrogate.screen_starts * quick.surrogate.screen_evals
    assert stage_budget(quick, "selecting finalists") is None


def test_progress_off_a_terminal_says_a_stage_without_counts_still_runs():
    import time

    from optipose.cli.progress import StageProgress

    console, out = _plain_console()
    with StageProgress(console, "part_b", "evaluations", every=0.2) as progress:
        progress.stage("validating on the full protocol (held-out noise seed)", detail="")
        time.sleep(1.0)  # an ICP stage: nothing is counted, the heartbeat prints
    lines = out.getvalue().splitlines()
    assert len(lines) >= 3 and all(
        line.startswith("part_b: validating on the full protocol (held-out noise seed), ") for line in lines
    )
