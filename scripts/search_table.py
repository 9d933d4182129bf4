"""Print the found-vs-hand table (Markdown) of one or more search result folders, in millidegrees.

    .venv/bin/python scripts/search_table.py results/search-default-part_a results/search-default-part_b ...
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd


def cell(rows: pd.DataFrame, axis: str) -> str:
    r = rows[rows["axis"] == axis].iloc[0]
    return f"{1e3 * r['median_deg']:.3f} / {1e3 * r['p75_deg']:.3f} ({r['subset']})"


def main(folders: list[str]) -> None:
    print("| part | k | layout | roll (mdeg) | pitch (mdeg) | yaw (mdeg) | score (mdeg) | hand / found | every axis no worse |")
    print("| --- | --- | --- | --- | --- | --- | ---: | ---: | --- |")
    for folder in folders:
        c = pd.read_csv(Path(folder) / "comparison.csv")
        part = Path(folder).name.split("-")[-1]
        for k in sorted(c["k"].unique()):
            found, hand = c[(c.k == k) & (c.layout == "found")], c[(c.k == k) & (c.layout == "hand")]
            ratio = hand["score_deg"].iloc[0] / found["score_deg"].iloc[0]
            ok = all(
                (found[found.axis == a][col].iloc[0] <= hand[hand.axis == a][col].iloc[0])
                for a in ("roll", "pitch", "yaw") for col in ("median_deg", "p75_deg")
            )  # fmt: skip
            for label, rows in (("found", found), ("hand", hand)):
                extra = (f"{ratio:.2f}x", "yes" if ok else "no") if label == "found" else ("", "")
                print(f"| {part} | {k} | {label} {rows['sensors'].iloc[0]} | {cell(rows, 'roll')} | {cell(rows, 'pitch')} | "
                      f"{cell(rows, 'yaw')} | {1e3 * rows['score_deg'].iloc[0]:.3f} | {extra[0]} | {extra[1]} |")  # fmt: skip
        f1 = c[(c.k == 1) & (c.layout == "found")]["score_deg"].iloc[0]
        h3 = c[(c.k == c.k.max()) & (c.layout == "hand")]["score_deg"].iloc[0]
        print(f"<!-- {part}: found 1-sensor {f1:.5f} vs hand {c.k.max()}-sensor {h3:.5f}: "
              f"{'beats' if f1 < h3 else 'does not beat'} it -->")


if __name__ == "__main__":
    main(sys.argv[1:])
