"""The ``optipose`` Typer app: ``--verbose``, ``--version``, every command's registration and :func:`main`.

Each command lives in its own module (:mod:`~optipose.cli.scan`, :mod:`~optipose.cli.parts`,
:mod:`~optipose.cli.evaluate`, :mod:`~optipose.cli.search`, :mod:`~optipose.cli.calibrate`, :mod:`~optipose.cli.robustness`,
:mod:`~optipose.cli.batch`, :mod:`~optipose.cli.report`) and shares its options through
:mod:`optipose.cli.options`; those modules never import this one. At import time they need only typer,
so ``optipose --help`` is instant; the library is imported when a command runs. Every command turns an
:class:`~optipose.errors.OptiposeError` into one line on stderr and a non-zero exit, never a traceback, and
:func:`main` does the same for what click finds wrong with the command line (an unknown option, a bad or
missing value). The help is click's plain one, each text re-wrapped to the terminal (see ``app``).
"""

from __future__ import annotations

import logging
import sys
from typing import Annotated, Optional

import typer

from optipose.cli import batch, calibrate, cells, evaluate, parts, report, robustness, scan, search
from optipose.cli.options import EXIT_INTERRUPTED, EXIT_USER_ERROR

# rich_markup_mode=None: click's plain help, which re-wraps every paragraph to the terminal and never cuts
# a word or a default, and in which the brackets of "[grid]" or "[[trials]]" stay text instead of markup
app = typer.Typer(
    name="optipose",
    help="Find where to mount 2D laser-line-triangulation sensors so a robot cell estimates a part's orientation best.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _print_version(value: bool) -> None:
    if value:
        typer.echo(f"optipose {version()}")
        raise typer.Exit()


def version() -> str:
    """The installed optipose's version (its package metadata), else the source tree's."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return installed("optipose")
    except PackageNotFoundError:  # run from a source tree that was never installed
        import optipose

        return getattr(optipose, "__version__", "unknown")


@app.callback()
def _configure_logging(
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Log what the library does.")] = False,
    _version: Annotated[
        Optional[bool],
        typer.Option("--version", callback=_print_version, is_eager=True, help="Print optipose's version and exit."),
    ] = None,
) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )


def _register(command) -> None:
    """Add a command; its docstring's first paragraph, on one line, is its entry in `optipose --help`
    (click would otherwise cut it to the width left beside the command names, with "...")."""
    summary = " ".join((command.__doc__ or "").split("\n\n")[0].split())
    app.command(short_help=summary)(command)


# The order here is the order of `optipose --help`.
for _command in (
    scan.scan,
    parts.parts,
    parts.show,
    parts.counts,
    cells.cells,
    evaluate.evaluate,
    search.search,
    calibrate.calibrate,
    robustness.robustness,
    batch.batch,
    batch.study,
    report.report,
):
    _register(_command)


def main(args: list[str] | None = None) -> None:
    """Run the command line; a usage error (an unknown option, a bad or missing value) is one line
    ``optipose: error: ...`` on stderr and exit code 2, as every error a command finds itself."""
    from optipose.heap import keep_freed_memory

    keep_freed_memory()  # before any work: this process's arrays and its workers' (optipose/heap.py)
    errors = _click_exceptions()
    try:
        code = app(args, prog_name="optipose", standalone_mode=False)
    except getattr(errors, "NoArgsIsHelpError", ()) as exc:  # `optipose` alone: its help, as typer prints it
        typer.echo(exc.ctx.get_help())
        code = EXIT_USER_ERROR
    except errors.UsageError as exc:  # BadParameter, MissingParameter, NoSuchOption, ...
        typer.echo(f"optipose: error: {usage_message(exc)}", err=True)
        code = EXIT_USER_ERROR
    except typer.Abort:  # end of input or a Ctrl-C while the command line is read
        typer.echo("optipose: error: interrupted", err=True)
        code = EXIT_INTERRUPTED
    # standalone_mode=False: click returns an Exit's code (typer.Exit, --help, --version) and a command's
    # return value otherwise (None: success)
    sys.exit(code if isinstance(code, int) else 0)


def _click_exceptions():
    """The module of the click exceptions typer raises: newer typers carry their own copy of click."""
    try:
        from typer._click import exceptions
    except ImportError:  # a typer that uses click itself
        from click import exceptions
    return exceptions


def usage_message(exc) -> str:
    """A click usage error in one line, pointing to the help of the command it is about."""
    message = " ".join(exc.format_message().split()).rstrip(".")
    return f"{message} (see `{exc.ctx.command_path} --help`)" if exc.ctx is not None else message


if __name__ == "__main__":
    main()
