"""What ``optipose search`` prints at its end: the verdict first, then found vs. the baseline per axis, the
subsets each axis uses, the surrogate's strategies and the found poses (:func:`print_answer`). The
lines are :mod:`optipose.verdict.words`'; every table fits an 80-column terminal.
"""

from __future__ import annotations

import textwrap

__all__ = ["print_answer"]


def print_answer(console, report, part, unchecked: bool = False, ideal: bool = True, time_limit: float = 0.0) -> None:
    """The verdict first, one line per k (:func:`optipose.verdict.words.verdict_headline`, or with confidence
    :func:`~optipose.verdict.words.confident_line`), then the details: found vs. the
    baseline per axis on the validation protocol (the records ``comparison.csv`` was written from, which
    :func:`optipose.io.load_result` reads back), the subsets each axis uses, the full verdict
    lines, the surrogate's strategies and the found poses. Every table fits an 80-column terminal.
    ``unchecked``: the answer holds in the ideal cell only; ``ideal``:
    the search ran in the ideal cell (its verdicts say so); ``time_limit``: the user's clock on the search (0: none),
    whose cuts the answer names."""
    from optipose.model.baseline import baseline, baseline_label
    from optipose.search.budgets import config_from_budget
    from optipose.verdict import words

    label = baseline_label(baseline(part))
    if report.validated:
        verdicts = report.validation.verdicts()
        confident = report.confident.by_k
        most = config_from_budget("thorough", tuple(report.layouts), cell=not ideal).verdict.draws
        for v in confident.values() or verdicts:
            console.print(
                words.confident_line(v) if confident else words.verdict_headline(v, label, checked=not unchecked),
                highlight=False,
            )
            if confident and (why := words.open_line(v, most)):  # wrapped by words, not where the terminal ends
                console.print(textwrap.fill(why, 80, subsequent_indent="    "), highlight=False, soft_wrap=True)
            if confident and (why := words.ruling_line(v)):
                console.print(textwrap.fill(why, 80, subsequent_indent="    "), highlight=False, soft_wrap=True)
        for v in confident.values():
            if line := words.mount_line(v, report.layouts.get(v.k), baseline(part)):
                console.print(line, highlight=False)
        if report.confident.fewer is not None:
            console.print(words.fewer_line(report.confident.fewer), highlight=False)
        if confident and ideal:
            console.print("these verdicts hold " + words.IDEAL_CELL, style="yellow", highlight=False)
        if confident:
            console.print(_confident_table(confident, part))
        if unchecked and not confident and any(v.no_worse for v in verdicts):
            console.print(words.UNCHECKED, style="yellow", highlight=False)
        for line in report.validation.unmeasured_lines(label):
            console.print(line, style="bold red", highlight=False)
        lines = report.validation.verdict_lines(label)
        found, baseline_choices = report.validation.found, report.validation.baseline
        if (
            1 in found and max(baseline_choices, default=0) > 1 and report.confident.fewer is None
        ):  # fewer sensors to buy
            console.print(
                words.one_versus_many(found[1], baseline_choices[max(baseline_choices)], label, the=False),
                highlight=False,
            )
        console.print(_validation_table(report.validation, part, label))
        console.print(_subsets_table(report.validation, label))
        for line in lines[: len(verdicts)] if not confident else ():  # the validation draw's own lines
            console.print(line, highlight=False)
    if line := words.clock_line(report.clock_cut, time_limit):
        console.print(textwrap.fill(line, 80), style="yellow", highlight=False, soft_wrap=True)
    console.print(_strategies_table(report.outcome, label))
    for k, layout in sorted(report.layouts.items()):
        console.print(f"[bold]found k={k}[/] (T_O_S, metres; X Y Z mm, roll pitch yaw deg):")
        for name, T in zip(layout.names, layout.poses):
            console.print(f"  {name}:\n" + "\n".join("    [" + "  ".join(f"{v: .5f}" for v in row) + "]" for row in T))
            console.print(f"    {words.xyz_rpy_text(T)}", highlight=False)


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
    """Per k (``confident``: k → its verdict with confidence), found and the baseline: the predicted median |error|
    per axis that one cell gives, with the interval 90 % of the cell's instances fall in (mdeg)."""
    from optipose.verdict.confidence import ONE_CELL
    from optipose.verdict.words import one_cell_cell

    table = _narrow_table(
        f"{part.name}: predicted median |error| in one cell, mdeg [{100 * ONE_CELL:.0f} % of its instances]",
        [("k", "right"), ("sensors", "left"), ("roll", "right"), ("pitch", "right"), ("yaw", "right")],
    )
    for k, v in sorted(confident.items()):
        for name, axes in ((v.found_name, v.found), (v.baseline_name, v.baseline)):
            table.add_row(str(k), name, *(one_cell_cell(a) for a in axes))
    return table


def _validation_table(validation, part, label: str = "hand"):
    """One row per k and layout (found, baseline): median/p75 per axis and the score, in mdeg."""
    from optipose.verdict.words import mdeg_compact

    protocol = "full protocol" if validation.protocol == "full" else "REDUCED protocol (14 scans)"
    table = _narrow_table(
        f"{part.name}: found vs. {label}, {protocol}, held-out seed; mdeg median/p75",
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
    for k in sorted({*validation.found, *validation.baseline}):
        for name, choices in (("found", validation.found), (label, validation.baseline)):
            if k in choices:
                choice = choices[k]
                cells = [
                    f"{mdeg_compact(a.median)}/{mdeg_compact(a.p75)}" if a.observable else _short_reason(a)
                    for a in choice.axes
                ]
                table.add_row(str(k), _short(name), choice.name, *cells, mdeg_compact(choice.score))
    return table


def _subsets_table(validation, label: str = "hand"):
    """The sensor subset each axis uses, per k and layout."""
    table = _narrow_table(
        "the subset each axis uses",
        [("k", "right"), ("layout", "left"), ("roll", "left"), ("pitch", "left"), ("yaw", "left")],
    )
    for k in sorted({*validation.found, *validation.baseline}):
        for name, choices in (("found", validation.found), (label, validation.baseline)):
            if k in choices:
                table.add_row(str(k), _short(name), *(a.label for a in choices[k].axes))
    return table


def _strategies_table(outcome, label: str = "hand"):
    """The surrogate's predicted score per k for greedy, joint and the baseline, and which strategy won."""
    strategies = _narrow_table(
        f"surrogate: predicted score (mdeg), greedy vs. joint vs. {label}",
        [("k", "right"), ("greedy", "right"), ("joint", "right"), (_short(label), "right"), ("winner", "right")],
    )
    for k in sorted(outcome.found):
        g, j, h = outcome.greedy.get(k), outcome.joint.get(k), outcome.baseline.get(k)
        fmt = lambda f: f"{1e3 * f.stats.score:.3f}" if f is not None and f.stats else "-"  # noqa: E731
        strategies.add_row(str(k), fmt(g), fmt(j), fmt(h), outcome.found[k].strategy)
    return strategies
