"""How good can one sensor be on a part? Score N scrambled-Sobol single-sensor poses on the surrogate
(the search's pose space and constraints) and compare the best with the best hand-placed sensor.

    .venv/bin/python scripts/single_sensor_screen.py part_c --samples 65536
    .venv/bin/python scripts/single_sensor_screen.py part_c --samples 16384 --icp 40

Prints how many poses were feasible, the hand sensor's predicted per-axis scores (median + 75th percentile,
mdeg), the best poses' scores and their ratio to the hand sensor's, and how many are predicted no worse than
the hand sensor on every axis. The surrogate is the search's cheap fidelity, so this bounds what the search
can be led to, not what ICP will measure.

``--icp N`` asks ICP too: the N best distinct poses (more than 0.1 apart in some [0, 1] unit, ranked by the
sum plus 20 x every axis's predicted excess over the hand sensor's), each first polished on that score
(``--polish`` BOBYQA evaluations), run the objective's 14-scan reduced protocol with the search's selection
seed; the ``--confirm`` best there run the full protocol with the selection seed and with the held-out
validation seed of ``--seed``, beside the hand sensor. It prints how many are no worse than the best hand
sensor on every axis, and the ratio hand / this on the held-out seed.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import qmc

from optipose.evaluate.objective import load_objective
from optipose.model.part import load_part
from optipose.search.config import SearchConfig
from optipose.search.problem import SurrogateProblem
from optipose.search.surrogate import SensorInfo, predicted_stats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("part")
    ap.add_argument("--samples", type=int, default=65536, help="Sobol points (a power of 2)")
    ap.add_argument("--objective", default="paper")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--show", type=int, default=5)
    ap.add_argument(
        "--icp", type=int, default=0, help="ICP on this many of the best distinct poses (0: surrogate only)"
    )
    ap.add_argument("--polish", type=int, default=30, help="surrogate polish evaluations per pose before ICP")
    ap.add_argument("--confirm", type=int, default=6, help="of those, how many run the full protocol")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()

    part, objective = load_part(args.part), load_objective(args.objective)
    problem = SurrogateProblem(part, objective, SearchConfig())
    weights = problem.weights
    hand = {
        s.name: predicted_stats([problem.surrogate.info(np.asarray(s.T_O_S))], *weights)
        for s in part.layouts["hand"].sensors
    }
    name, best_hand = min(hand.items(), key=lambda kv: kv[1].score)
    target = best_hand.axis_score
    print(
        f"{part.name}: best hand sensor {name}, predicted roll / pitch / yaw {np.round(1e3 * target, 3)} mdeg, sum {1e3 * best_hand.score:.3f}"
    )

    t0 = time.monotonic()
    points = qmc.Sobol(6, scramble=True, seed=args.seed).random(args.samples)
    scored = []
    for u in points:
        info = problem.sensor(u)
        if isinstance(info, SensorInfo):
            stats = predicted_stats([info], *weights)
            scored.append((stats.score, stats.axis_score, u, stats))
    print(f"{len(scored)} of {args.samples} poses feasible, {time.monotonic() - t0:.0f} s")
    scored.sort(key=lambda t: t[0])
    for score, axes, u, _ in scored[: args.show]:
        pose = problem.space.describe(problem.space.to_pose(u))
        print(
            f"  sum {1e3 * score:.3f} mdeg (hand / this {best_hand.score / score:.2f}), this / hand per axis {np.round(axes / target, 2)}: {pose}"
        )
    dominating = [t for t in scored if np.all(t[1] <= target)]
    twice = [t for t in dominating if t[0] <= best_hand.score / 2]
    print(f"no worse than {name} on every axis: {len(dominating)}; of those, at least 2x better in sum: {len(twice)}")
    if dominating:
        print(f"  best of those: hand / this {best_hand.score / dominating[0][0]:.2f} in sum")
    if args.icp > 0:
        icp_check(part, objective, problem, scored, target, args)


def icp_check(part, objective, problem, scored, target, args) -> None:
    """The ``--icp`` stage (module doc)."""
    from dataclasses import replace

    from optipose.evaluate.evaluator import Evaluator
    from optipose.verdict.compare import dominates, rank
    from optipose.evaluate.objective import reduced_objective
    from optipose.search.driver import apart, local_best
    from optipose.search.study import SurrogateStudy
    from optipose.seeds import selection_seed, validation_seed

    # rank and polish on the search's own score with its per-axis penalty at margin 1 and weight 20
    config = replace(problem.config, hand_margin=1.0, hand_weight=20.0)
    problem = SurrogateProblem(
        part, objective, config, problem.surrogate, cache=dict(problem.cache), targets={1: target}
    )
    key = lambda t: t[0] + problem.shortfall(1, t[3])  # noqa: E731
    starts: list[np.ndarray] = []
    for t in sorted(scored, key=key):
        if len(starts) >= args.icp:
            break
        if apart(t[2], starts, 0.1):
            starts.append(t[2])
    poses: list[np.ndarray] = []
    for j, u0 in enumerate(starts):
        row = local_best(SurrogateStudy(problem), "LN_BOBYQA", u0, args.polish, args.seed + j)
        u = np.asarray(row.u) if row is not None else u0
        if apart(u, poses, 0.02):
            poses.append(u)
    fmt = lambda c: " ".join(f"{a.axis} {1e3 * np.rad2deg(a.median):.3f}/{1e3 * np.rad2deg(a.p75):.3f}" for a in c.axes)  # noqa: E731
    hand = part.layouts["hand"]
    with (
        Evaluator(
            part, reduced_objective(objective), seed=selection_seed(args.seed), jobs=args.jobs, quiet=True
        ) as reduced,
        Evaluator(part, objective, seed=selection_seed(args.seed), jobs=args.jobs, quiet=True) as full,
        Evaluator(part, objective, seed=validation_seed(args.seed), jobs=args.jobs, quiet=True) as held_out,
    ):
        bar, bar_held = full(hand).table[0], held_out(hand).table[0]
        print(
            f"ICP, best hand sensor: full protocol {bar.name} {fmt(bar)} mdeg; held-out seed {bar_held.name} {fmt(bar_held)} mdeg, sum {1e3 * np.rad2deg(bar_held.score):.3f}"
        )
        ranked = []
        for u in poses:
            choice = reduced(problem.space.to_poses(u)).table[0]
            ranked.append((rank(choice, bar), u))
        ranked.sort(key=lambda t: t[0])
        print(
            f"{len(poses)} distinct poses on the reduced protocol: {sum(not t[0][0] for t in ranked)} no worse than {bar.name} on every axis"
        )
        wins = 0
        for _, u in ranked[: args.confirm]:
            poses_u = problem.space.to_poses(u)
            a, b = full(poses_u).table[0], held_out(poses_u).table[0]
            wins += dominates(b, bar_held) and b.score <= bar_held.score / 2
            print(
                f"  full: {'no worse' if dominates(a, bar) else 'worse somewhere'} | held-out: hand / this {bar_held.score / b.score:.2f}, "
                f"{'no worse on every axis' if dominates(b, bar_held) else 'worse on some axis'}: {fmt(b)} | {problem.space.describe(poses_u[0])}"
            )
        print(
            f"held-out: {wins} of {min(args.confirm, len(ranked))} no worse on every axis and at least 2x better in sum"
        )


if __name__ == "__main__":
    main()
