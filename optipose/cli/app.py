"""The ``optipose`` command line.

Imports are lazy so ``optipose --help`` is instant; every command turns an :class:`OptiposeError` into
one line on stderr and a non-zero exit, never a traceback.
"""

from __future__ import annotations

import functools
import logging
import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

app = typer.Typer(
    name="optipose",
    help="Find where to mount 2D laser-line-triangulation sensors so a robot cell estimates a part's orientation best.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130

UnitsOpt = Annotated[str, typer.Option("--units", help="Mesh units: auto (diagonal > 2 means mm), m, mm or in.")]


def _fail(message: str, code: int = EXIT_USER_ERROR) -> None:
    typer.echo(f"optipose: error: {message}", err=True)
    raise typer.Exit(code)


def friendly_errors(fn):
    """Run a command; a user error or a Ctrl-C becomes one line on stderr and an exit code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from optipose.errors import OptiposeError

        try:
            return fn(*args, **kwargs)
        except OptiposeError as exc:
            _fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
        except KeyboardInterrupt:
            _fail("interrupted", EXIT_INTERRUPTED)
        except MemoryError:
            _fail("out of memory (try fewer sensors, a coarser protocol or --jobs 1)")
        except OSError as exc:  # disk full, permission denied, ...
            _fail(f"{exc.strerror or exc}: {exc.filename}" if exc.filename else str(exc))

    return wrapper


@app.callback()
def _main(
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Log what the library does.")] = False,
) -> None:
    logging.basicConfig(
        level=logging.INFO if verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )


def _parse_floats(text: str, n: int, what: str) -> list[float]:
    from optipose.errors import ConfigError

    try:
        values = [float(v) for v in text.replace(";", ",").replace(" ", ",").split(",") if v]
    except ValueError:
        raise ConfigError(f"{what}: expected {n} comma-separated numbers, got '{text}'") from None
    if len(values) != n:
        raise ConfigError(f"{what}: expected {n} numbers, got {len(values)}")
    return values


@app.command()
@friendly_errors
def scan(
    part: Annotated[str, typer.Argument(help="A shipped part name (see `optipose parts`) or a mesh file (STL, OBJ, PLY).")],
    sensor_pose: Annotated[
        Optional[list[str]],
        typer.Option("--sensor-pose", "-p", help="A 4x4 T_O_S as 16 comma-separated numbers, row-major, metres. Repeatable."),
    ] = None,
    layout: Annotated[Optional[Path], typer.Option(help="Layout TOML with [[sensors]] name/T_O_S entries.")] = None,
    material: Annotated[Optional[str], typer.Option(help="Material preset or a CSV (aoi_deg,intensity); default: the part's.")] = None,
    sensor: Annotated[Optional[str], typer.Option(help="Sensor preset or TOML file; default: the part's.")] = None,
    rpy: Annotated[str, typer.Option(help="Part orientation roll,pitch,yaw in degrees.")] = "0,0,0",
    seed: Annotated[int, typer.Option(help="Noise seed.")] = 0,
    noise: Annotated[bool, typer.Option("--noise/--no-noise", help="Sensor noise and Z quantisation.")] = True,
    out: Annotated[Optional[Path], typer.Option(help="Write the merged cloud (PLY, PCD, XYZ or NPY), metres.")] = None,
    raw: Annotated[Optional[Path], typer.Option(help="Write each sensor's raw profiles (device format) into this folder.")] = None,
    units: UnitsOpt = "auto",
) -> None:
    """Scan a part with one or more sensors and print what each sees."""
    from optipose.cli.scan import run_scan

    run_scan(part, sensor_pose, layout, material, sensor, _parse_floats(rpy, 3, "--rpy"), seed, noise, out, raw, units)


@app.command()
@friendly_errors
def parts() -> None:
    """List the shipped parts with their size, material, scanning length and layouts."""
    from optipose.cli.parts import parts_command

    parts_command()


@app.command()
@friendly_errors
def show(
    part: Annotated[str, typer.Argument(help="A shipped part name or a mesh file.")],
    out: Annotated[Optional[Path], typer.Option(help="PNG to write (default: ./<part>.png).")] = None,
    layout: Annotated[str, typer.Option(help="Which of the part's layouts to draw.")] = "hand",
    units: UnitsOpt = "auto",
) -> None:
    """Draw a part with a layout's sensors (head boxes, laser fans, scanned points) to a PNG."""
    from optipose.cli.parts import show_command

    show_command(part, out, units, layout)


@app.command()
@friendly_errors
def counts(
    part: Annotated[Optional[str], typer.Argument(help="A part (default: every shipped part).")] = None,
    layout: Annotated[str, typer.Option(help="Which of the part's layouts to scan.")] = "hand",
    markdown: Annotated[bool, typer.Option(help="Print a Markdown table (for the README).")] = False,
) -> None:
    """Point counts of a nominal scan per sensor (the paper's Figure 9 at zero offset)."""
    from optipose.cli.parts import counts_command

    counts_command(part, layout, markdown)


def _register_commands() -> None:
    """Commands defined in their own modules (each module imports only typer at import time)."""
    from optipose.cli import evaluate, search

    evaluate.register(app)
    search.register(app)


_register_commands()


def main() -> None:
    app()


if __name__ == "__main__":
    main()
