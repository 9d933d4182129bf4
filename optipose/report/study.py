"""A study's report: its table per part and setting first, then one short row per trial, sortable, each
unfolding to all of its columns and linking the trial's own report.

:func:`study_report` takes plain rows (a trial's parameters and results as a dict, e.g. one row of a
study index) and the trial folders, so it does not depend on how a batch runs its trials;
:func:`summary_table` is the table per part and setting that ``optipose study`` prints too (from
:func:`optipose.batch.summary.summary_frame`). Angles are in millidegrees, as in the terminal: a column
``<name>_deg`` is shown x1000 as ``<name>_mdeg``. The short table keeps to a handful of columns so it fits a
1,280-pixel-wide window; a study index has some 26, which are all in each trial's details.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

from optipose.files import write_text
from optipose.report.document import Block, Details, Heading, Paragraph, Table, render_html, render_markdown
from optipose.verdict.words import mdeg_column

__all__ = ["study_report", "study_table", "summary_table", "trial_details", "TRIAL_COLUMNS"]

# (header, column of a study index) of the short table, in this order; a trial's other columns are in its details
TRIAL_COLUMNS = (
    ("trial", "key"),
    ("part", "part"),
    ("task", "task"),
    ("k", "sensors"),
    ("seed", "seed"),
    ("state", "state"),
    ("score", "score_deg"),
    ("roll", "roll_median_deg"),
    ("pitch", "pitch_median_deg"),
    ("yaw", "yaw_median_deg"),
    ("hand/found", "ratio"),
    ("s", "seconds"),
)
_TEXT = {"key", "part", "task", "state"}  # left-aligned, sorted as text


def study_table(rows: list[dict], folders: list[str | Path | None], out_dir: Path) -> Table:
    """One short sortable row per trial: the :data:`TRIAL_COLUMNS` the rows have (every column for rows
    without a ``key``), angles in mdeg; the trial's name links to its details (:func:`trial_details`, all of
    its columns) and a ``report`` column to its ``report.html`` (relative to ``out_dir``) when it has one."""
    # rows of a study index (they have a key, which each trial's details are found by) are folded to the
    # short columns; other rows are shown whole
    shown = [(h, c) for h, c in TRIAL_COLUMNS if any(c in r for r in rows)]
    folded = any("key" in r for r in rows) and len(shown) < len(_columns(rows))
    if not folded:
        shown = [(mdeg_column(c), c) for c in _columns(rows)]
    cells, links = [], {}
    for i, (row, folder) in enumerate(zip(rows, folders)):
        cells.append(tuple(_cell(row, c) for _, c in shown) + (_report_cell(folder),))
        if folded and "key" in row:
            links[(i, 0)] = f"#{_anchor(row['key'])}"
        if cells[-1][-1] == "report":
            links[(i, len(shown))] = os.path.relpath(Path(folder) / "report.html", out_dir)
    numeric = tuple(c not in _TEXT and _numeric(rows, c) for _, c in shown)
    caption = f"{len(rows)} trials; click a column to sort" + (", a trial to see all of its columns" if folded else "")
    angles = [h for h, c in shown if c.endswith("_deg")]
    if angles:
        caption += f"; {', '.join(angles)} in mdeg" + (" (each axis: its median)" if len(angles) > 1 else "")
    return Table(
        (*(h for h, _ in shown), "report"),
        tuple(cells),
        caption,
        sortable=True,
        links=links,
        numeric=(*numeric, False),
        anchor="trials",
    )


def trial_details(rows: list[dict]) -> list[Details]:
    """Per trial, every column it has (angles in mdeg), folded under its name, state and score."""
    out = []
    for row in rows:
        fields = tuple((mdeg_column(c), _value(c, row.get(c))) for c in _columns(rows))
        score = _value("score_deg", row.get("score_deg"))
        head = ", ".join(
            p
            for p in (str(row.get("state", "")), f"score {score} mdeg" if score else "", str(row.get("error") or ""))
            if p
        )
        out.append(Details(f"{row.get('key', '')}: {head}", (_side_by_side(fields, 3),), _anchor(row.get("key", ""))))
    return out


def _side_by_side(fields: tuple[tuple[str, str], ...], n: int) -> Table:
    """(name, value) pairs in ``n`` pairs of columns, filled down each pair first: a trial's some 26
    columns in a block a few rows high."""
    per = -(-len(fields) // n)
    columns = [fields[i * per : (i + 1) * per] for i in range(n)]
    rows = tuple(tuple(x for col in columns for x in (col[r] if r < len(col) else ("", ""))) for r in range(per))
    return Table(("column", "value") * n, rows, numeric=(False,) * 2 * n)


def summary_table(frame) -> Table:
    """The table ``optipose study`` prints (a :func:`optipose.batch.summary.summary_frame`): per part and
    setting, trials complete of all (and failed, ``F``), score median and worst and each axis's median in
    mdeg over the seeds; for searches hand over found and how many found layouts were no worse on every
    axis."""
    searches = "ratio_median" in frame
    header = (
        "part",
        "task",
        "k",
        "ok/n",
        "score",
        "worst",
        "roll",
        "pitch",
        "yaw",
        *(("hand/f", "no worse") if searches else ()),
    )
    rows = []
    for r in frame.to_dict("records"):
        task = (
            r["task"]
            + (f" {r['budget']}" if r["budget"] else "")
            + ("" if r["objective"] == "paper" else f" {r['objective']}")
        )
        cells = [
            r["part"],
            task,
            str(r["sensors"]),
            f"{r['complete']}/{r['trials']}" + (f" {r['failed']}F" if r["failed"] else ""),
            *(
                _two_decimals(r[c])
                for c in (
                    "score_median_deg",
                    "score_worst_deg",
                    "roll_median_deg",
                    "pitch_median_deg",
                    "yaw_median_deg",
                )
            ),
        ]
        if searches:
            ratio = r.get("ratio_median")
            no_worse = r.get("no_worse")  # NaN on the rows of other tasks in a study of several
            cells += [
                "-" if ratio is None or math.isnan(ratio) else f"{ratio:.2f}",
                no_worse if isinstance(no_worse, str) else "-",
            ]
        rows.append(tuple(cells))
    return Table(
        header,
        tuple(rows),
        "mdeg, the median over seeds (worst: the largest score); ok/n: trials complete of all, F: failed",
        numeric=tuple(h not in ("part", "task") for h in header),
    )


def study_report(
    rows: list[dict],
    folders: list[str | Path | None],
    out: str | Path,
    title: str = "study",
    summary: Table | None = None,
) -> tuple[Path, Path]:
    """Write ``study.html`` (self-contained, sortable) and ``study.md`` into ``out``; returns both paths.

    rows : one dict per trial (its parameters, state and results; floats shown to 4 significant digits,
    ``*_deg`` columns in mdeg); folders : each trial's result folder (None for a trial without one);
    summary : the table per part and setting (:func:`summary_table`), shown first.
    """
    if len(rows) != len(folders):
        raise ValueError(f"{len(rows)} rows but {len(folders)} folders")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    states = [str(r.get("state", "")) for r in rows]
    counts = ", ".join(f"{states.count(s)} {s}" for s in dict.fromkeys(states) if s)
    blocks: list[Block] = [Paragraph(f"{len(rows)} trials" + (f": {counts}" if counts else ""))]
    if summary is not None:
        blocks += [Heading("Per part and setting"), summary]
    table = study_table(rows, folders, out)
    blocks += [Heading("Trials"), table]
    if any(table.links.get((i, 0)) for i in range(len(rows))):  # some columns are folded: each trial's details
        blocks += [Heading("Each trial", 3), *trial_details(rows)]
    html, md = out / "study.html", out / "study.md"
    write_text(html, render_html(title, blocks))
    write_text(md, render_markdown(title, blocks, "."))
    return html, md


def _columns(rows: list[dict]) -> list[str]:
    """Every column of the rows, in the order they first appear."""
    return list(dict.fromkeys(key for row in rows for key in row))


def _cell(row: dict, column: str) -> str:
    value = row.get(column)
    if column == "part" and isinstance(value, str) and ("/" in value or Path(value).suffix):
        return Path(value).stem  # a mesh file's path: its name, as the terminal shows it
    if column == "task" and row.get("budget"):
        return f"{value} {row['budget']}"
    if column == "seconds":
        return "" if not _is_number(value) or math.isnan(value) else f"{value:.0f}"
    return _value(column, value, digits=3)


def _report_cell(folder) -> str:
    if not folder:
        return ""
    return "report" if (Path(folder) / "report.html").is_file() else "no report"


def _value(column: str, value, digits: int = 4) -> str:
    """A cell: empty for none, ``<name>_deg`` in mdeg, floats to ``digits`` significant digits."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if column.endswith("_deg") and _is_number(value):
        value = 1e3 * value
        return f"{value:.0f}" if abs(value) >= 10**digits else f"{value:.{digits}g}"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def _two_decimals(value) -> str:
    """Degrees as mdeg with two decimals (the terminal's summary), ``-`` for none."""
    return "-" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{1e3 * value:.2f}"


def _anchor(key) -> str:
    return "trial-" + re.sub(r"[^A-Za-z0-9_.-]+", "-", str(key))


def _numeric(rows: list[dict], column: str) -> bool:
    values = [r.get(column) for r in rows if r.get(column) not in (None, "")]
    return bool(values) and all(_is_number(v) for v in values)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
