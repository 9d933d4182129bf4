"""Print the found-vs-hand table (Markdown) of one or more search result folders, in millidegrees.

.venv/bin/python scripts/search_table.py results/search-default-part_a results/search-default-part_b ...
"""

from __future__ import annotations

import sys

from optipose.io import load_result
from optipose.verdict.words import mdeg_text


def cells(choice) -> str:
    return " | ".join(f"{mdeg_text(a.median)} / {mdeg_text(a.p75)} ({a.label})" for a in choice.axes)


def main(folders: list[str]) -> None:
    print(
        "| part | k | layout | roll (mdeg) | pitch (mdeg) | yaw (mdeg) | score (mdeg) | hand / found | every axis no worse |"
    )
    print("| --- | --- | --- | --- | --- | --- | ---: | ---: | --- |")
    for folder in folders:
        result = load_result(folder)
        for v in result.verdicts():
            print(
                f"| {result.part} | {v.k} | found {v.found.name} | {cells(v.found)} | {mdeg_text(v.found.score)} | "
                f"{v.ratio:.2f}x | {'yes' if v.no_worse else 'no'} |"
            )
            print(
                f"| {result.part} | {v.k} | hand {v.reference.name} | {cells(v.reference)} | {mdeg_text(v.reference.score)} |  |  |"
            )
        lines = result.verdict_lines()
        if lines and lines[-1].startswith("one found sensor"):
            print(f"<!-- {result.part}: {lines[-1]} -->")


if __name__ == "__main__":
    main(sys.argv[1:])
