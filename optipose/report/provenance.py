"""What produced a result: the command, seed, objective, versions and the config, from ``config.toml``."""

from __future__ import annotations

import shlex

from optipose.report.document import Block, Code, Heading, Table

__all__ = ["command_line", "provenance_blocks"]


def command_line(config: dict) -> str:
    """The optipose command that reproduces the result, rebuilt from its config (its ``--out`` left out)."""
    command = config.get("command", "?")
    part = config.get("part", {})
    args = ["optipose", command, part.get("source") or part.get("name", "?")]
    objective = config.get("objective", {}).get("name")
    if command == "search":
        sensors = config.get("search", {}).get("sensors")
        args += ["--budget", str(config.get("budget", "default"))]
        if sensors:
            args += ["--sensors", ",".join(str(s) for s in sensors)]
    if command == "evaluate":
        source = config.get("layout", {}).get("source", "")
        if source and not source.startswith("part:"):
            args += ["--layout", source]
    if command == "robustness":
        for source in config.get("layout_sources", []):
            args += ["--layout", source]
    if objective:
        args += ["--objective", objective]
    args += ["--seed", str(config.get("seed", 0))]
    return shlex.join(args)


def provenance_blocks(config: dict) -> list[Block]:
    """The command, the seed(s), the versions and the search settings, then the objective file as run."""
    rows = [("command", config.get("command", "")), ("part", config.get("part", {}).get("name", "")),
            ("part source", config.get("part", {}).get("source", "")), ("seed", str(config.get("seed", "")))]  # fmt: skip
    if "validation_seed" in config:
        rows.append(("validation seed (held out)", str(config["validation_seed"])))
    if "budget" in config:
        rows.append(("budget", str(config["budget"])))
    rows.append(("objective", str(config.get("objective", {}).get("name", ""))))
    rows += [(f"version: {name}", str(v)) for name, v in config.get("versions", {}).items()]
    blocks: list[Block] = [Heading("How this was made"), Code(command_line(config), "command"),
                           Table(("what", "value"), tuple(rows), numeric=(False, False))]  # fmt: skip
    if config.get("search"):
        settings = tuple((k, str(v)) for k, v in config["search"].items())
        blocks.append(Table(("search setting", "value"), settings, "search settings (SI units)", numeric=(False, False)))
    if config.get("objective_file"):
        blocks.append(Code(config["objective_file"].strip(), "objective file"))
    return blocks
