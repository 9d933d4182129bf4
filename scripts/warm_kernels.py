"""Compile the compiled kernels (numba) once, at set-up: each is cached beside its module on first use, and a
fresh clone's first command would otherwise spend some 6 s compiling them (benchmarks/README.md, "bench_start.py").

    .venv/bin/python scripts/warm_kernels.py

A search on part B in the paper's cell, shrunk to a few poses and two scans, uses every kernel a search does.
"""

from __future__ import annotations

import numpy as np

from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective
from optipose.model.baseline import baseline
from optipose.model.part import load_part
from optipose.search.budgets import config_from_budget
from optipose.search.objectives import stage_objective
from optipose.search.problem import SurrogateProblem


def main() -> None:
    part, paper = load_part("part_b"), load_objective("paper")
    problem = SurrogateProblem(part, paper, config_from_budget("quick", (1,), cell=True))
    for u in np.random.default_rng(0).random((8, 6)):
        problem.sensor(u)
    with Evaluator(part, stage_objective(paper, "validation", "reduced"), seed=0, quiet=True, scans=2) as evaluator:
        evaluator(baseline(part))


if __name__ == "__main__":
    main()
