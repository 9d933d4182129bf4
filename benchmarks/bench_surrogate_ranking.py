"""How well does the surrogate rank layouts against ICP? (SPEC §6)

Draws feasible single-sensor layouts at random for a part (seeded), scores each with the surrogate
(information matrix of one reduced nominal scan) and with the objective's own ICP on the reduced protocol
(14 scans, as the search's selection stage), and prints Spearman's rank correlation between the two, the
agreement on the best layout, and the time per evaluation of each fidelity.

    .venv/bin/python benchmarks/bench_surrogate_ranking.py [--part part_b] [--layouts 16] [--seed 0]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import spearmanr

from optipose.evaluate import Evaluator
from optipose.objective import load_objective
from optipose.part import load_part
from optipose.refine import reduced_objective
from optipose.search import SearchConfig, SurrogateProblem


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="part_b")
    ap.add_argument("--layouts", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    part, objective = load_part(args.part), load_objective("paper")
    problem = SurrogateProblem(part, objective, SearchConfig())
    rng = np.random.default_rng(args.seed)
    layouts, t_sur = [], 0.0
    while len(layouts) < args.layouts:
        u = rng.random(6)
        t0 = time.perf_counter()
        value, stats = problem.evaluate(u)
        t_sur += time.perf_counter() - t0
        if stats is not None:
            layouts.append((u, value))
    t_icp, icp = 0.0, []
    with Evaluator(part, reduced_objective(objective), seed=args.seed + 1) as evaluator:
        for u, _ in layouts:
            t0 = time.perf_counter()
            result = evaluator([problem.space.to_pose(u)])
            t_icp += time.perf_counter() - t0
            icp.append(np.rad2deg(result.table[0].score))
    surrogate = np.array([v for _, v in layouts])
    icp = np.array(icp)
    rho, p = spearmanr(surrogate, icp)
    print(f"bench_surrogate_ranking: {args.part}, {len(layouts)} random feasible one-sensor layouts, seed {args.seed}")
    print(f"{'layout':>6} {'surrogate deg':>14} {'ICP (14 scans) deg':>19}")
    for i in np.argsort(icp):
        print(f"{i:>6} {surrogate[i]:>14.6f} {icp[i]:>19.6f}")
    top = int(np.argmin(icp))
    print(f"Spearman rho = {rho:.2f} (p = {p:.3g}); the surrogate's best is ICP rank "
          f"{int(np.argsort(np.argsort(icp))[np.argmin(surrogate)]) + 1} of {len(icp)}; ICP's best is surrogate rank "
          f"{int(np.argsort(np.argsort(surrogate))[top]) + 1}")  # fmt: skip
    print(f"time per layout: surrogate {1e3 * t_sur / max(1, len(layouts)):.0f} ms (incl. infeasible draws), "
          f"ICP reduced protocol {t_icp / len(layouts):.2f} s; ratio {t_icp / max(t_sur, 1e-9):.0f}x")


if __name__ == "__main__":
    main()
