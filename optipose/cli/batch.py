"""``optipose batch STUDY.toml`` and ``optipose study STUDY_DIR``: run a study of many trials, and show one.

:func:`batch` and :func:`study` are the Typer commands (registered by :mod:`optipose.cli.app`),
:func:`batch_command` and :func:`study_command` the plain functions behind them; imports of the library
stay lazy so ``optipose --help`` is instant. Everything that can be wrong with the input (the study
file, its parts and objectives, the back-end, the scheduler) is checked before the study folder is made.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from optipose.cli.options import EXIT_INTERRUPTED, check_output, fail, friendly_errors
from optipose.cli.progress import make_console
from optipose.errors import ConfigError

__all__ = ["batch", "batch_command", "study", "study_command"]

StudyFile = Annotated[
    Path, typer.Argument(metavar="STUDY_FILE", help="The study file (TOML: a [grid] and/or [[trials]]; see studies/).")
]
StudyDir = Annotated[Path, typer.Argument(metavar="FOLDER", help="A study folder written by `optipose batch`.")]


@friendly_errors
def batch(
    study_file: StudyFile,
    out: Annotated[Optional[Path], typer.Option("--out", help="Study folder (default: results/<study name>/).")] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="Continue the study in its folder: complete trials are kept, the rest run.")
    ] = False,
    jobs: Annotated[
        int, typer.Option("--jobs", min=1, help="Trials at once: worker processes (joblib), or local Dask workers.")
    ] = 1,
    backend: Annotated[
        str, typer.Option("--backend", help="joblib (a process pool on this machine) or dask.")
    ] = "joblib",
    scheduler: Annotated[
        Optional[str],
        typer.Option(
            "--scheduler", help="A Dask scheduler, tcp://HOST:8786 (default: a local cluster of --jobs workers)."
        ),
    ] = None,
    trial_jobs: Annotated[
        Optional[int],
        typer.Option(
            "--trial-jobs",
            min=1,
            help="Each trial's own processes and threads (default: the cores split between the workers).",
        ),
    ] = None,
    no_workers: Annotated[
        str,
        typer.Option(
            "--no-workers",
            help="When a Dask cluster has had no worker for a while: stop (finished trials kept) or wait.",
        ),
    ] = "stop",
    no_workers_after: Annotated[
        float,
        typer.Option(
            "--no-workers-after", min=1, help="Seconds without a Dask worker before the study stops or waits."
        ),
    ] = 60.0,
    summary: Annotated[
        bool, typer.Option("--summary", help="Only print the table of the study in --out (or results/<name>/).")
    ] = False,
    no_report: Annotated[
        bool, typer.Option("--no-report", help="Do not write the study report (study.html, study.md).")
    ] = False,
) -> None:
    """Run a study of many trials, each into its own result folder.

    Every trial of the study (parts × tasks × objectives × sensor counts × budgets × seeds) runs into its
    own result folder; an index lists all of them (index.parquet, index.csv), and the study report
    (study.html, study.md) shows them."""
    if summary:
        from optipose.batch.spec import load_study_spec

        study_command(out or Path("results") / load_study_spec(study_file).name, report=not no_report)
        return
    batch_command(
        study_file,
        out,
        resume,
        jobs,
        backend,
        scheduler,
        trial_jobs,
        report=not no_report,
        no_workers=no_workers,
        no_workers_after=no_workers_after,
    )


@friendly_errors
def study(folder: StudyDir) -> None:
    """Print a study's table and write its report.

    Per part and setting, its trials over seeds: complete and failed, the score and each axis in mdeg;
    the same table and one row per trial are written to study.html and study.md."""
    study_command(folder)


def batch_command(
    study_file: Path,
    out: Path | None = None,
    resume: bool = False,
    jobs: int = 1,
    backend: str = "joblib",
    scheduler: str | None = None,
    trial_jobs: int | None = None,
    report: bool = True,
    no_workers: str = "stop",
    no_workers_after: float = 60.0,
) -> Path:
    """Run the study with a progress bar; print its table; returns the study folder. A Dask cluster
    without workers for ``no_workers_after`` seconds stops the study (``no_workers="stop"``: one line,
    exit 2, the finished trials kept) or is waited for (``"wait"``: one line)."""
    from optipose.batch.pools import make_pool
    from optipose.batch.scheduler import NoWorkers, WorkerWatch
    from optipose.errors import note_interrupts
    from optipose.batch.spec import load_study_spec
    from optipose.batch.study import prepare_folder

    WorkerWatch("", no_workers, no_workers_after)  # its options checked before anything starts
    spec = load_study_spec(study_file)
    folder = Path(out) if out else Path("results") / spec.name
    check_output(folder)
    prepare_folder(folder, resume)
    console = make_console(stderr=True)

    def notify(line: str) -> None:
        console.print(f"optipose: warning: {line}", markup=False, highlight=False)

    note_interrupts()  # a Ctrl-C stops the study even where a trial's code catches it (optipose.errors)
    pool = make_pool(jobs, backend, scheduler, trial_jobs, no_workers=no_workers, after=no_workers_after, notify=notify)
    resume_hint = f"`optipose batch {study_file} --out {folder} --resume`"
    try:
        index = _run_with_progress(
            console, spec, folder, pool, resume, {"backend": backend, "scheduler": scheduler or ""}
        )
    except KeyboardInterrupt:
        console.print(f"[yellow]interrupted[/]: finished trials are in {folder}; continue with {resume_hint}")
        raise typer.Exit(EXIT_INTERRUPTED) from None
    except NoWorkers as exc:
        fail(f"{exc}; finished trials are in {folder}: continue with {resume_hint}")
    finally:
        pool.close()
    study_command(folder, report)
    from optipose.batch.records import TrialState

    n_failed = index.count(TrialState.FAILED)
    if n_failed:
        console.print(
            f"[yellow]{n_failed} trial(s) failed[/] (their errors are in {folder}/index.csv); "
            f"`--resume` runs them again"
        )
    console.print(f"results: {folder}")
    return folder


def _run_with_progress(console, spec, folder: Path, pool, resume: bool, config: dict):
    """Run the study, its trials counted on ``console``: those already complete (``resume``) and each that
    ends, out of all of the study's, with how many failed; one line per trial when not on a terminal."""
    from optipose.batch.records import TrialState
    from optipose.batch.study import run_study
    from optipose.cli.progress import StageProgress

    # every trial of the study counts once: the kept ones now, the others as they end
    kept = _complete_trials(folder, spec) if resume else 0
    with StageProgress(console, spec.name, "trials", each=True) as progress:
        progress.stage(f"{pool.workers} worker(s)", len(spec.trials), detail="0 failed")
        if kept:
            progress.advance(kept, detail=f"{kept} kept")
        failed = 0

        def on_record(record):
            nonlocal failed
            failed += record.state == TrialState.FAILED
            progress.advance(detail=f"{failed} failed, last {record.key} {record.state.value}")

        return run_study(spec, folder, pool, resume, on_record, config)


def _complete_trials(folder: Path, spec) -> int:
    """How many of the study's trials ``--resume`` keeps: those whose folder a complete run left (as
    :meth:`optipose.batch.index.StudyIndex.open` decides)."""
    from optipose.batch.trial import TRIAL_FILE

    return sum((Path(folder) / "trials" / t.key / TRIAL_FILE).is_file() for t in spec.trials)


def study_command(folder: Path, report: bool = True) -> None:
    """Print the table per part and setting of a study folder, and (``report``) write its study report."""
    from rich.console import Console

    from optipose.batch.summary import read_study_index, summary_frame

    if not Path(folder).is_dir():
        raise ConfigError(f"study folder not found: {folder}")
    index = read_study_index(folder)
    Console().print(_summary_table(summary_frame(index), Path(folder).name))
    if report:
        html, _ = write_study_report(folder, index)
        make_console(stderr=True).print(f"study report: {html}")


def write_study_report(folder: Path, index) -> tuple[Path, Path]:
    """``study.html`` and ``study.md`` in the study folder: the table per part and setting this command
    prints, then one sortable row per trial, each with all of its columns and a link to its
    ``report.html`` where it has one (``optipose report <trial folder>`` writes it)."""
    from optipose.batch.summary import summary_frame
    from optipose.report.study import study_report, summary_table

    rows = index.drop(columns=[c for c in ("folder",) if c in index]).to_dict("records")
    folders = [Path(folder) / f if isinstance(f, str) and f else None for f in index.get("folder", [None] * len(index))]
    return study_report(
        rows, folders, folder, title=f"study {Path(folder).name}", summary=summary_table(summary_frame(index))
    )


def _summary_table(frame, name: str):
    """The study's table per part and setting (:func:`optipose.report.study.summary_table`, which the
    study report shows too) as a rich table of an 80-column terminal; failures (``2F``) in red."""
    from rich import box
    from rich.table import Table
    from rich.text import Text

    from optipose.report.study import summary_table

    block = summary_table(frame)
    table = Table(
        title=f"study {name}: mdeg, median over seeds", box=box.SIMPLE_HEAD, pad_edge=False, collapse_padding=True
    )
    for column, numeric in zip(block.header, block.numeric):
        # in a narrow terminal the names wrap, so that the numbers need not be cut
        table.add_column(column, justify="right" if numeric else "left", no_wrap=numeric, overflow="fold")
    for row in block.rows:
        cells = [Text(cell) for cell in row]  # Text, not markup: a part's name may hold brackets
        for cell in cells:
            cell.highlight_regex(r"\d+F$", "red")
        table.add_row(*cells)
    return table
