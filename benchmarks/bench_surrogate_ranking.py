"""How well does the surrogate rank layouts against ICP? (SPEC §6)

Draws feasible single-sensor layouts at random for a part (seeded), adds the part's hand-placed sensors,
scores each with two surrogates, the noise-only information matrix of one reduced nominal scan and the
same plus the voxel-bias model (the search's default), and with the objective's own ICP on the reduced
protocol (14 scans, as the search's selection stage). Prints Spearman's rank correlation with ICP for the
score and per axis, the median factor between predicted and ICP per-axis scores, the agreement on the best
layout, and the time per evaluation of each fidelity.

    .venv/bin/python benchmarks/bench_surrogate_ranking.py [--part part_b] [--layouts 16] [--seed 0] [--noise-scale 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import spearmanr

from optipose.evaluate.conditions import Condition
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective, reduced_objective
from optipose.model.part import load_part
from optipose.search.config import SearchConfig
from optipose.search.problem import SurrogateProblem
from optipose.search.surrogate import Surrogate, predicted_stats

AXES = ("roll", "pitch", "yaw")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="part_b")
    ap.add_argument("--layouts", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise-scale", type=float, default=1.0, help="the sensor noise sigma times this, in ICP and the surrogate")
    args = ap.parse_args()
    scales = (args.noise_scale,)

    part, objective = load_part(args.part), load_objective("paper")
    problem = SurrogateProblem(part, objective, SearchConfig())
    rng = np.random.default_rng(args.seed)
    layouts = []
    while len(layouts) < args.layouts:
        u = rng.random(6)
        score = problem.score(u)
        if score.feasible:
            layouts.append((u, score.value))
    hand = part.layouts["hand"].poses if "hand" in part.layouts else []
    layouts += [(problem.space.from_pose(T), problem.score(problem.space.from_pose(T), constrained=False).value) for T in hand]
    n_hand = len(hand)
    t0 = time.perf_counter()
    bias_stats = [predicted_stats([problem.surrogate.info(problem.space.to_pose(u))], *problem.weights, noise_scales=scales) for u, _ in layouts]
    t_bias = time.perf_counter() - t0
    layouts = [(u, s["score"]) for (u, _), s in zip(layouts, bias_stats)]
    t_icp, icp, icp_axes = 0.0, [], []
    with Evaluator(part, reduced_objective(objective), seed=args.seed + 1, condition=Condition(args.noise_scale)) as evaluator:
        for u, _ in layouts:
            t0 = time.perf_counter()
            result = evaluator([problem.space.to_pose(u)])
            t_icp += time.perf_counter() - t0
            icp.append(np.rad2deg(result.table[0].score))
            row = result.stats[result.stats["subset"] == result.layout.names[0]].set_index("axis")
            icp_axes.append([np.rad2deg(row.loc[a, "median"] + row.loc[a, "p75"]) for a in AXES])
    # the same layouts on the noise-only surrogate (no voxel-bias turns), timed the same way
    plain = Surrogate(part, voxel=objective.registration.voxel_size, turns=np.zeros((0, 3)))
    weights = (tuple(objective.statistic.weights), objective.statistic.median_weight, objective.statistic.p75_weight)
    t0 = time.perf_counter()
    noise_only = [predicted_stats([plain.info(problem.space.to_pose(u))], *weights, noise_scales=scales) for u, _ in layouts]
    t_plain = time.perf_counter() - t0
    models = {
        "noise only": (np.array([s["score"] for s in noise_only]), np.array([s["axis_score"] for s in noise_only])),
        "noise + voxel bias": (np.array([v for _, v in layouts]), np.array([s["axis_score"] for s in bias_stats])),
    }
    icp, icp_axes = np.array(icp), np.array(icp_axes)
    print(f"bench_surrogate_ranking: {args.part}, {len(layouts) - n_hand} random feasible one-sensor layouts "
          f"+ {n_hand} hand-placed sensors, seed {args.seed}, noise x{args.noise_scale:g}")
    print(f"{'layout':>6} {'noise only':>11} {'with bias':>11} {'ICP (14 scans)':>15}   (scores in mdeg)")
    for i in np.argsort(icp):
        label = f"hand{i - len(layouts) + n_hand + 1}" if i >= len(layouts) - n_hand else str(i)
        print(f"{label:>6} {1e3 * models['noise only'][0][i]:>11.3f} {1e3 * models['noise + voxel bias'][0][i]:>11.3f} {1e3 * icp[i]:>15.3f}")
    for name, (score, axes) in models.items():
        rho = spearmanr(score, icp)[0]
        per_axis = ", ".join(f"{a} {spearmanr(axes[:, j], icp_axes[:, j])[0]:.2f}" for j, a in enumerate(AXES))
        factor = ", ".join(f"{a} {np.exp(np.median(np.abs(np.log(axes[:, j] / icp_axes[:, j])))):.2f}x" for j, a in enumerate(AXES))
        ranks = np.argsort(np.argsort(icp))
        print(f"{name}: Spearman rho score {rho:.2f}; per axis {per_axis}; median factor off ICP per axis {factor}; "
              f"its best is ICP rank {int(ranks[np.argmin(score)]) + 1} of {len(icp)}")
    n = len(layouts)
    print(f"time per layout: noise-only surrogate {1e3 * t_plain / n:.0f} ms, with bias {1e3 * t_bias / n:.0f} ms, "
          f"ICP reduced protocol {t_icp / n:.2f} s ({t_icp / max(t_bias, 1e-9):.0f}x the surrogate with bias)")


if __name__ == "__main__":
    main()
