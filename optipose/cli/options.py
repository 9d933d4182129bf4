"""What every command shares: errors turned into exit codes, number parsing, and the option types.

Each option or argument that more than one command takes is declared here once, as an ``Annotated``
type, so its flag, help and checks read the same everywhere. Only typer and :mod:`optipose.errors`
(which imports nothing) are imported, so ``optipose --help`` stays instant.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Annotated, NoReturn, Optional

import typer

from optipose.errors import ConfigError, OptiposeError

__all__ = [
    "EXIT_USER_ERROR",
    "EXIT_INTERRUPTED",
    "fail",
    "friendly_errors",
    "parse_floats",
    "check_output",
    "Part",
    "Units",
    "LayoutFile",
    "Objective",
    "Seed",
    "Jobs",
    "ResultFolder",
]

EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a Ctrl-C


def fail(message: str, code: int = EXIT_USER_ERROR) -> NoReturn:
    """Print ``optipose: error: <message>`` on stderr and exit with ``code``."""
    typer.echo(f"optipose: error: {message}", err=True)
    raise typer.Exit(code)


def friendly_errors(fn):
    """Run a command; a user error or a Ctrl-C becomes one line on stderr and an exit code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except OptiposeError as exc:
            fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
        except KeyboardInterrupt:
            fail("interrupted", EXIT_INTERRUPTED)
        except MemoryError:
            fail("out of memory (try fewer sensors, a coarser protocol or --jobs 1)")
        except OSError as exc:  # disk full, permission denied, ...
            fail(f"{exc.strerror or exc}: {exc.filename}" if exc.filename else str(exc))

    return wrapper


def parse_floats(text: str, n: int, what: str) -> list[float]:
    """``n`` numbers from text separated by commas, semicolons or spaces; ``what`` names the option."""
    try:
        values = [float(v) for v in text.replace(";", ",").replace(" ", ",").split(",") if v]
    except ValueError:
        raise ConfigError(f"{what}: expected {n} comma-separated numbers, got '{text}'") from None
    if len(values) != n:
        raise ConfigError(f"{what}: expected {n} numbers, got {len(values)}")
    return values


def check_output(path: Path | None, file: bool = False, what: str = "--out") -> None:
    """Refuse an output that cannot be written before the work, not after it: ``path`` a folder (or, with
    ``file``, a file whose folder is checked). A probe file is written and removed in the folder, or in
    its nearest existing parent when the command will create it (nothing is created here). A permission
    test would not do: root passes every one, and a read-only file system stops root too."""
    import tempfile

    if path is None:
        return
    path = Path(path)
    folder = path.parent if file else path
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ConfigError(f"{what} {path}: {existing} is a file, not a folder")
    try:
        fd, probe = tempfile.mkstemp(dir=existing, prefix=".optipose-probe-")
    except OSError as exc:
        raise ConfigError(f"{what} {path}: cannot write in {existing} ({exc.strerror or exc})") from None
    import os

    os.close(fd)
    os.unlink(probe)


# -- options and arguments shared by several commands ----------------------------------------------------
# Optional so a command may give PART a default (search with --resume, counts over every part); without
# a default it is required.
Part = Annotated[
    Optional[str],
    typer.Argument(
        metavar="PART", help="A shipped part name (see `optipose parts`), a part TOML or a mesh file (STL, OBJ, PLY)."
    ),
]
Units = Annotated[
    str,
    typer.Option(
        "--units", help="Mesh units: auto (diagonal > 20 means mm, 2-20 is refused as mm-or-inches), m, mm or in."
    ),
]
LayoutFile = Annotated[
    Optional[Path],
    typer.Option("--layout", help="Layout TOML, a name and T_O_S per sensor; default: the part's hand-placed one."),
]
Objective = Annotated[str, typer.Option("--objective", help="Objective name in objectives/ or a TOML path.")]
CellOption = Annotated[
    Optional[str],
    typer.Option(
        "--cell",
        help="The cell the layouts are evaluated in: a name in cells/ (`optipose cells` lists them), NAME:zeroed for it zeroed on a master part, or a TOML path; default: the objective's.",
    ),
]
Seed = Annotated[
    int,
    typer.Option(
        "--seed", help="Seed of the sensor noise and random protocols; a search validates with a seed derived from it."
    ),
]
Jobs = Annotated[
    Optional[int],
    typer.Option("--jobs", min=1, help="Worker processes for ICP (search's default: one per core)."),
]
ResultFolder = Annotated[
    Optional[Path],
    typer.Option(
        "--out", help="Result folder (default: results/<part>-<command>-<timestamp>/, linked as results/latest)."
    ),
]
