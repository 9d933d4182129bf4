"""What produced a result: the command, seed, objective, versions and the config, from ``config.toml``."""

from __future__ import annotations

import shlex

from optipose.io.config import RunConfig, given
from optipose.report.document import Block, Code, Heading, Table

__all__ = ["command_line", "cell_name", "provenance_blocks"]


def command_line(config: RunConfig) -> str:
    """The optipose command that reproduces the result, rebuilt from its config (its ``--out`` left out)."""
    command = given(config.command, "?")
    args = ["optipose", command, config.part_source or given(config.part_name, "?")]
    if config.part_units:
        args += ["--units", config.part_units]
    if command == "search":
        args += ["--budget", str(given(config.budget, "default"))]
        if config.sensors:
            args += ["--sensors", ",".join(str(s) for s in config.sensors)]
    if command == "evaluate":
        source = given(config.layout_source, "")
        if source.startswith("scans:"):  # a scan folder: its manifest says the objective, layout, cell and seed
            return shlex.join([*args, "--scans", source.removeprefix("scans:")])
        if source and not source.startswith("part:"):
            args += ["--layout", source]
    if command == "robustness":
        for source in config.layout_sources:
            args += ["--layout", source]
    if config.objective_name:
        args += ["--objective", config.objective_name]
    if cell_name(config) != "ideal":
        args += ["--cell", cell_name(config)]
    args += ["--seed", str(given(config.seed, 0))]
    return shlex.join(args)


def cell_name(config: RunConfig) -> str:
    """The name of the cell the run was evaluated in (its sources are in config.toml's ``[objective.cell]``)."""
    return config.cell_name


def provenance_blocks(config: RunConfig) -> list[Block]:
    """The command, the seed(s), the versions and the search settings, then the objective file as run."""
    rows = [
        ("command", given(config.command, "")),
        ("part", given(config.part_name, "")),
        ("part source", given(config.part_source, "")),
        ("seed", str(given(config.seed, ""))),
    ]
    if config.validation_seed is not None:
        rows.append(("validation seed (held out)", str(config.validation_seed)))
    if config.budget is not None:
        rows.append(("budget", str(config.budget)))
    rows.append(("objective", str(given(config.objective_name, ""))))
    rows.append(("cell", cell_name(config)))
    rows += [(f"version: {name}", str(v)) for name, v in config.versions.items()]
    blocks: list[Block] = [
        Heading("How this was made"),
        Code(command_line(config), "command"),
        Table(("what", "value"), tuple(rows), numeric=(False, False)),
    ]
    if config.search:
        settings = tuple((k, str(v)) for k, v in config.search_settings)
        blocks.append(
            Table(("search setting", "value"), settings, "search settings (SI units)", numeric=(False, False))
        )
    if config.objective_file:
        blocks.append(Code(config.objective_file.strip(), "objective file"))
    return blocks
