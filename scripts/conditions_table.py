"""Found vs. hand-placed under conditions a search did not tune to (issue #13's table), Markdown.

For a search result folder, the found layouts of each k and the part's hand layout are evaluated with the
nominal objective (``paper``) on a held-out noise seed, then with each condition changed one at a time:
sensor noise 5x the preset's, 40 random orientations within +-2 deg with +-1 mm offsets, 1 mm voxels. Each
cell is hand / found in sum for that k (each axis on its own subset), and whether found is worse on some
axis (*).

    .venv/bin/python scripts/conditions_table.py results/<search folder> [--jobs 2] [--seed 11]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from optipose.verdict.compare import Verdict
from optipose.evaluate.conditions import ConditionsConfig
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective
from optipose.evaluate.robust import choice_of
from optipose.io import load_result
from optipose.model.part import load_part
from optipose.search.validate import indices_in, nested_groups


def variants():
    paper = load_objective("paper").in_cell("ideal")
    noisy = replace(paper, conditions=ConditionsConfig(noise_scales=(5.0,)))
    shaken = replace(paper, protocol=replace(paper.protocol, kind="random", count=40, range_offset=(1e-3, 1e-3, 1e-3)))
    coarse = replace(paper, registration=replace(paper.registration, voxel_size=1e-3))
    return [
        ("the nominal objective, held-out seed", paper),
        ("sensor noise 5x the preset", noisy),
        ("40 random orientations in +-2 deg, +-1 mm offsets", shaken),
        ("1 mm voxels instead of 0.5 mm", coarse),
    ]


def main() -> None:
    args = argparse.ArgumentParser()
    args.add_argument("folder")
    args.add_argument("--jobs", type=int, default=2)
    args.add_argument("--seed", type=int, default=11)
    a = args.parse_args()
    result = load_result(a.folder)
    part = load_part(result.config.part_source or result.part)
    ks = sorted(result.layouts)
    print(f"{result.part}: hand / found per k ({a.folder})\n")
    print("| condition | " + " | ".join(f"k = {k}" for k in ks) + " |")
    print("| --- |" + " ---: |" * len(ks))
    for label, objective in variants():
        from optipose.evaluate.robust import make_evaluator

        with make_evaluator(part, objective, seed=a.seed, jobs=a.jobs, quiet=True) as evaluator:
            hand = evaluator(part.layouts["hand"])
            found = {}
            for members in nested_groups(result.layouts):
                big = result.layouts[max(members)]
                evaluated = evaluator(big)
                for k in members:
                    found[k] = choice_of(evaluated, tuple(indices_in(result.layouts[k], big)))
        cells = []
        for k in ks:
            v = Verdict(k, found[k], hand.table[k - 1])
            cells.append(f"{v.ratio:.2f}{'' if v.no_worse else '*'}")
        print(f"| {label} | " + " | ".join(cells) + " |", flush=True)
    print("\n(* = found worse than hand on some axis there)")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
