"""The ``optipose`` Typer app: ``--verbose``, every command's registration and :func:`main`.

Each command lives in its own module (:mod:`~optipose.cli.scan`, :mod:`~optipose.cli.parts`,
:mod:`~optipose.cli.evaluate`, :mod:`~optipose.cli.search`, :mod:`~optipose.cli.robustness`,
:mod:`~optipose.cli.batch`, :mod:`~optipose.cli.report`) and shares its options through
:mod:`optipose.cli.options`; those modules never import this one. At import time they need only typer,
so ``optipose --help`` is instant; the library is imported when a command runs. Every command turns an
:class:`~optipose.errors.OptiposeError` into one line on stderr and a non-zero exit, never a traceback.
"""

from __future__ import annotations

import logging
import sys
from typing import Annotated

import typer

from optipose.cli import batch, evaluate, parts, report, robustness, scan, search

app = typer.Typer(
    name="optipose",
    help="Find where to mount 2D laser-line-triangulation sensors so a robot cell estimates a part's orientation best.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@app.callback()
def _configure_logging(
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Log what the library does.")] = False,
) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )


# The order here is the order of `optipose --help`.
app.command()(scan.scan)
app.command()(parts.parts)
app.command()(parts.show)
app.command()(parts.counts)
app.command()(evaluate.evaluate)
app.command()(search.search)
app.command()(robustness.robustness)
app.command()(batch.batch)
app.command()(batch.study)
app.command()(report.report)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
