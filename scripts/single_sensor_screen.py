"""How good can one sensor be on a part? Score N scrambled-Sobol single-sensor poses on the surrogate
(the search's pose space and constraints) and compare the best with the best hand-placed sensor.

    .venv/bin/python scripts/single_sensor_screen.py part_c --samples 65536

Prints how many poses were feasible, the hand sensor's predicted per-axis scores (median + 75th percentile,
mdeg), the best poses' scores and their ratio to the hand sensor's, and how many are predicted no worse than
the hand sensor on every axis. The surrogate is the search's cheap fidelity, so this bounds what the search
can be led to, not what ICP will measure.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import qmc

from optipose.objective import load_objective
from optipose.part import load_part
from optipose.search import SearchConfig, SurrogateProblem
from optipose.surrogate import SensorInfo, predicted_stats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part")
    ap.add_argument("--samples", type=int, default=65536, help="Sobol points (a power of 2)")
    ap.add_argument("--objective", default="paper")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--show", type=int, default=5)
    args = ap.parse_args()

    part, objective = load_part(args.part), load_objective(args.objective)
    problem = SurrogateProblem(part, objective, SearchConfig())
    weights = problem._weights
    hand = {s.name: predicted_stats([problem.surrogate.info(np.asarray(s.T_O_S))], *weights) for s in part.layouts["hand"].sensors}
    name, best_hand = min(hand.items(), key=lambda kv: kv[1]["score"])
    target = best_hand["axis_score"]
    print(f"{part.name}: best hand sensor {name}, predicted roll / pitch / yaw {np.round(1e3 * target, 3)} mdeg, sum {1e3 * best_hand['score']:.3f}")

    t0 = time.monotonic()
    points = qmc.Sobol(6, scramble=True, seed=args.seed).random(args.samples)
    scored = []
    for u in points:
        info = problem.sensor(u)
        if isinstance(info, SensorInfo):
            stats = predicted_stats([info], *weights)
            scored.append((stats["score"], stats["axis_score"], u))
    print(f"{len(scored)} of {args.samples} poses feasible, {time.monotonic() - t0:.0f} s")
    scored.sort(key=lambda t: t[0])
    for score, axes, u in scored[: args.show]:
        pose = problem.space.describe(problem.space.to_pose(u))
        print(f"  sum {1e3 * score:.3f} mdeg (hand / this {best_hand['score'] / score:.2f}), this / hand per axis {np.round(axes / target, 2)}: {pose}")
    dominating = [t for t in scored if np.all(t[1] <= target)]
    twice = [t for t in dominating if t[0] <= best_hand["score"] / 2]
    print(f"no worse than {name} on every axis: {len(dominating)}; of those, at least 2x better in sum: {len(twice)}")
    if dominating:
        print(f"  best of those: hand / this {best_hand['score'] / dominating[0][0]:.2f} in sum")


if __name__ == "__main__":
    main()
