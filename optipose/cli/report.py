"""``optipose report RESULT_DIR``: a self-contained ``report.html`` and a ``report.md`` for a result folder.

:func:`report` is the Typer command, :func:`report_command` the plain function; :func:`write_report_after`
is what ``search``, ``evaluate`` and ``robustness`` call at their end (unless ``--no-report``): a report
that fails is a warning there, never a lost result.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from optipose.cli.options import check_output, friendly_errors
from optipose.cli.progress import make_console, status
from optipose.errors import ConfigError

__all__ = ["report", "report_command", "write_report_after", "NoReport"]

NoReport = Annotated[
    bool, typer.Option("--no-report", help="Do not write report.html and report.md into the result folder.")
]


@friendly_errors
def report(
    result_dir: Annotated[
        Path,
        typer.Argument(
            metavar="RESULT_DIR",
            help="A result folder of optipose search, evaluate or robustness, or a study folder of optipose batch.",
        ),
    ],
    views: Annotated[
        bool, typer.Option("--views/--no-views", help="Draw the 3D views (they scan each layout once).")
    ] = True,
) -> None:
    """Write report.html and report.md into a result folder.

    report.html is self-contained (it opens offline): the verdict first, Table 1, error box plots, point
    counts, 3D views, robustness, the search, the poses to paste. A study folder gets its study report."""
    report_command(result_dir, views)


def report_command(result_dir: Path, views: bool = True) -> Path:
    """Write the report; returns the path of report.html."""
    from optipose.report.build import write_report

    if not Path(result_dir).is_dir():
        raise ConfigError(f"{result_dir}: no such result folder")
    check_output(Path(result_dir), what="report into")
    console = make_console(stderr=True)
    if (Path(result_dir) / "index.parquet").is_file():  # a batch study: its table of trials, linking their reports
        from optipose.batch.summary import read_study_index
        from optipose.cli.batch import write_study_report

        html, md = write_study_report(Path(result_dir), read_study_index(result_dir))
        console.print(f"study report: {html} (and {md.name})")
        return html
    with status(console, f"writing the report of {result_dir}"):
        html, md = write_report(result_dir, views=views)
    console.print(f"report: {html} (and {md.name})")
    return html


def write_report_after(folder: Path, console, ready=None) -> None:
    """The report at the end of a command; a failure is one warning line, the result folder stays. ``ready()``:
    waits for the layouts' pictures being drawn beside it (:func:`optipose.report.build.write_report`)."""
    import logging

    from optipose.report.build import write_report

    try:
        with status(console, "writing report.html"):
            html, _ = write_report(folder, ready=ready)
        console.print(f"report: {html}")
    except Exception as exc:  # a report must never cost the results
        logging.getLogger(__name__).debug("report failed", exc_info=True)
        console.print(f"[yellow]warning[/]: no report ({type(exc).__name__}: {exc}); try `optipose report {folder}`")
