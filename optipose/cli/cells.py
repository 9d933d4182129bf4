"""``optipose cells``: the shipped cells, one line each (docs/cell.md).

A Typer function (registered by :mod:`optipose.cli.app`) over :func:`cells_command`, which scripts and tests call
directly; the library is imported when the command runs, so the CLI's ``--help`` stays instant.
"""

from __future__ import annotations

from optipose.cli.options import friendly_errors

__all__ = ["cells", "cells_command", "cells_table"]


@friendly_errors
def cells() -> None:
    """List the shipped cells: whether their magnitudes are ranges, whether they are zeroed, what they are."""
    cells_command()


def cells_table() -> list[dict]:
    """One row per shipped cell: ``{cell, ranges, zeroed, description}`` (``ranges``: how many magnitudes are
    ranges; ``zeroed``: whether the file zeroes the cell on a master part)."""
    from optipose.cell.config import CELLS_DIR, cell_names, load_cell

    rows = []
    for name in cell_names():
        cell = load_cell(CELLS_DIR / f"{name}.toml")  # the file, as shipped (``ideal`` by name is the built-in one)
        rows.append(
            {
                "cell": name,
                "ranges": len(cell.ranges),
                "zeroed": cell.calibration.zeroed,
                "description": cell.description,
            }
        )
    return rows


def cells_command() -> list[dict]:
    """Print the shipped cells (``cells/``), one line each; return their rows (:func:`cells_table`)."""
    from rich import box
    from rich.table import Table

    from optipose.cli.parts import console

    table = Table(title="Shipped cells (cells/)", box=box.SIMPLE_HEAD, pad_edge=False)
    for column in ("cell", "ranges", "zeroed", "description"):
        table.add_column(column, no_wrap=True)
    rows = cells_table()
    for row in rows:
        ranges = f"{row['ranges']} ranges" if row["ranges"] else "points"
        table.add_row(row["cell"], ranges, "zeroed" if row["zeroed"] else "not zeroed", row["description"])
    table.caption = "--cell NAME:zeroed: the cell zeroed on a master part; a range is drawn per run seed (docs/cell.md)"
    console(width=200).print(table)  # one line a cell
    return rows
