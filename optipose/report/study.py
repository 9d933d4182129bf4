"""A study's report: one row per trial, sortable by any column, each linking to the trial's own report.

:func:`study_report` takes plain rows (a trial's parameters and results as a dict, e.g. one row of a
study index) and the trial folders, so it does not depend on how a batch runs its trials; the batch
command (issue #15) calls it with its index rows once its trials are done.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from optipose.files import write_text
from optipose.report.document import Heading, Paragraph, Table, render_html, render_markdown

__all__ = ["study_report", "study_table"]


def study_table(rows: list[dict], folders: list[str | Path | None], out_dir: Path) -> Table:
    """A sortable table: columns in the order keys first appear; a ``report`` column linking to each
    trial's ``report.html`` (relative to ``out_dir``) when the trial has one."""
    columns = list(dict.fromkeys(key for row in rows for key in row))
    numeric = tuple(all(_is_number(r.get(c)) for r in rows if r.get(c) not in (None, "")) and any(r.get(c) not in (None, "") for r in rows)
                    for c in columns)  # fmt: skip
    cells, links = [], {}
    for i, (row, folder) in enumerate(zip(rows, folders)):
        cells.append(tuple(_format(row.get(c)) for c in columns) + ("report" if folder else "",))
        if folder and (Path(folder) / "report.html").is_file():
            links[(i, len(columns))] = os.path.relpath(Path(folder) / "report.html", out_dir)
        elif folder:
            cells[-1] = cells[-1][:-1] + ("no report",)
    return Table((*columns, "report"), tuple(cells), f"{len(rows)} trials; click a column to sort", sortable=True,
                 links=links, numeric=(*numeric, False))  # fmt: skip


def study_report(rows: list[dict], folders: list[str | Path | None], out: str | Path, title: str = "study") -> tuple[Path, Path]:
    """Write ``study.html`` (self-contained, sortable) and ``study.md`` into ``out``; returns both paths.

    rows : one dict per trial (its parameters, state and results; values are shown as they are, floats
    to 4 significant digits); folders : each trial's result folder (None for a trial without one).
    """
    if len(rows) != len(folders):
        raise ValueError(f"{len(rows)} rows but {len(folders)} folders")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    states = [str(r.get("state", "")) for r in rows]
    summary = ", ".join(f"{states.count(s)} {s}" for s in dict.fromkeys(states) if s) or f"{len(rows)} trials"
    blocks = [Heading("Trials"), Paragraph(summary), study_table(rows, folders, out)]
    html, md = out / "study.html", out / "study.md"
    write_text(html, render_html(title, blocks))
    write_text(md, render_markdown(title, blocks, "."))
    return html, md


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _format(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.4g}"
    return str(value)
