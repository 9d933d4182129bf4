"""Commands about parts: ``optipose parts``, ``optipose show PART``, ``optipose counts [PART]``.

Each command is a Typer function (registered by :mod:`optipose.cli.app`) over a plain ``*_command``
function that scripts and tests call directly. Imports are lazy so the CLI's ``--help`` stays instant.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from optipose.cli.options import Part, Units, check_output, friendly_errors
from optipose.errors import ConfigError

__all__ = ["parts", "show", "counts", "parts_command", "show_command", "counts_command", "counts_table", "console"]


@friendly_errors
def parts() -> None:
    """List the shipped parts: size, material, scanning length, layouts."""
    parts_command()


@friendly_errors
def show(
    part: Part,
    out: Annotated[Optional[Path], typer.Option(help="PNG to write (default: ./<part>.png).")] = None,
    layout: Annotated[str, typer.Option(help="Which of the part's layouts to draw, or a layout TOML.")] = "hand",
    units: Units = "auto",
) -> None:
    """Draw a part with a layout's sensors to a PNG.

    The picture shows the part, each sensor's head box and laser fan, and the points of a nominal scan."""
    show_command(part, out, units, layout)


@friendly_errors
def counts(
    part: Part = None,
    layout: Annotated[str, typer.Option(help="Which of the part's layouts to scan.")] = "hand",
    markdown: Annotated[bool, typer.Option(help="Print a Markdown table (for the docs).")] = False,
) -> None:
    """Point counts of a nominal scan, per sensor.

    For PART, or for every shipped part without one (the paper's Figure 9 at zero offset)."""
    counts_command(part, layout, markdown)


def parts_command() -> None:
    """List the shipped parts: size, material, scanning length, layouts and their sensor counts."""
    from rich import box
    from rich.table import Table

    from optipose.model.part import list_parts, load_part

    table = Table(title="Shipped parts (parts/)", box=box.SIMPLE_HEAD, pad_edge=False)
    for column in ("part", "L x W x H mm", "material", "scan mm", "layouts", "keep-outs"):
        table.add_column(column, no_wrap=True)
    for name in list_parts():
        part = load_part(name)
        size = " x ".join(f"{v:.4g}" for v in part.size * 1e3)
        layouts = ", ".join(f"{k}:{len(v)}" for k, v in part.layouts.items()) or "-"
        keepouts = ", ".join(k.name for k in part.keepouts) or "-"
        scan = f"{part.motion.length * 1e3:g}/{part.motion.step * 1e3:g}"
        table.add_row(name, size, part.material, scan, layouts, keepouts)
    table.caption = "scan: length/step; layouts: name:sensors; the part travels along +x"
    console().print(table)


def show_command(part: str, out: Path | None = None, units: str = "auto", layout: str = "hand") -> Path:
    """Save a PNG of the part, its sensors' heads, laser fans and nominal scan points; return its path.

    out : the PNG to write; default ``<part name>.png`` in the current folder.
    """
    from optipose.model.part import load_part
    from optipose.report.views import render_part

    check_output(out, file=True)
    loaded = load_part(part, units)
    if layout.endswith(".toml"):  # a layout file, e.g. results/<run>/layouts/found_k2.toml
        from dataclasses import replace

        from optipose.model.layout import load_layout

        extra = load_layout(layout)
        loaded = replace(loaded, layouts={**loaded.layouts, extra.name: extra})
        layout = extra.name
    elif layout == "hand" and layout not in loaded.layouts:
        layout = None  # a bare mesh: draw the part alone
    elif layout not in loaded.layouts:
        raise ConfigError(
            f"part '{loaded.name}' has no layout '{layout}' (it has: {', '.join(loaded.layouts) or 'none'}; or give a .toml file)"
        )
    path = render_part(loaded, out or Path(f"{loaded.name}.png"), layout)
    console().print(f"wrote {path}")
    return path


def counts_table(parts: list[str], layout: str = "hand") -> list[dict]:
    """Nominal-scan point counts per sensor: rows {part, sensor, points, profiles, per_profile}."""
    from optipose.model.part import load_part
    from optipose.scan.scanner import nominal_scans

    rows = []
    for name in parts:
        part = load_part(name)
        if layout not in part.layouts:
            continue
        for sensor, scan in nominal_scans(part, layout).items():
            n_prof = part.motion.n_profiles
            rows.append(
                {
                    "part": part.name,
                    "sensor": sensor,
                    "points": len(scan),
                    "profiles": n_prof,
                    "per_profile": len(scan) / n_prof,
                }
            )
    return rows


def counts_command(part: str | None = None, layout: str = "hand", markdown: bool = False) -> list[dict]:
    """Print nominal-scan point counts per sensor for one part (or every shipped part when None)."""
    from rich.table import Table

    from optipose.model.part import list_parts

    rows = counts_table([part] if part else list_parts(), layout)
    if markdown:  # for the docs' tables (docs/parts.md)
        print("| part | sensor | points | profiles | points per profile |")
        print("| --- | --- | ---: | ---: | ---: |")
        for r in rows:
            print(f"| {r['part']} | {r['sensor']} | {r['points']} | {r['profiles']} | {r['per_profile']:.0f} |")
        return rows
    table = Table(title=f"Nominal-scan point counts, layout '{layout}'")
    for column in ("part", "sensor", "points", "profiles", "points / profile"):
        table.add_column(column, justify="left" if column in ("part", "sensor") else "right")
    for r in rows:
        table.add_row(r["part"], r["sensor"], f"{r['points']:,}", str(r["profiles"]), f"{r['per_profile']:.0f}")
    console().print(table)
    return rows


def console(width: int = 100):
    """A rich console; ``width`` columns when the output is not a terminal, so piped tables do not wrap."""
    import sys

    from rich.console import Console

    return Console(width=None if sys.stdout.isatty() else width)
