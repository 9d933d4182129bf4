"""Where "no worse than the hand layout on every axis at every noise level" can be had, by the surrogate.

For k = 1 the found sensor must beat the hand layout's best single sensor on each axis's median and 75th
percentile at every noise level of the band (12 numbers for ``objectives/robust.toml``). This script asks the
surrogate (``search.surrogate``, the band's noise levels and the bracket term) how many feasible poses of a
space-filling sample of the search space, each then moved by a local search (and one from each hand sensor) that maximises its smallest
ratio hand / pose over the 12 statistics, do that, and how much better in sum at the preset's noise the
best of those is. For k = 2 and 3 the same with k - 1 of the hand sensors kept in their places and the
sample's pose added (the search's hand-anchored candidates): a kept sensor gives the axes it measures the
hand layout's own numbers, so a tie there is exact.

    .venv/bin/python benchmarks/bench_frontier.py [--part part_b] [--objective robust] [--samples 1024] [--starts 8]
        [--icp N [--icp-k 1,2,3] [--icp-kept S2,S1S3]]

``--icp N`` then measures what the surrogate only predicts: for each k and kept set, the N distinct poses the
surrogate ranks best — those it predicts no worse first, by their sum at the preset's noise (the poses that could
make "no worse and 2x better"), then the rest by their smallest ratio — and the hand layout are evaluated by ICP
under every condition of the band on the full protocol with another noise seed (``--seed`` + 1), and each is
compared with the hand layout's best k-choice per noise level, as the search's validation compares (each
statistic the worst over the level's bracket draws). For k >= 2 the pose takes the lowest free place of the hand
layout (the other places keep their hand sensors, each with its index's noise draws and bracket errors), and
the choice of the kept sensors and the pose is compared. ``--icp-k`` limits the ICP to some k, ``--icp-kept``
to kept sets by name (``S2,S1S3``).

The surrogate's ranking agrees with ICP only to Spearman ρ ≈ 0.7–0.9 (docs/method.md, 'How well the surrogate ranks layouts'), so a
count here is the surrogate's view, not ICP's; a zero says the surrogate sees no such pose in the sample.
Each axis takes its best subset at each noise level separately (the verdict fixes one subset per axis on the
worst over the band), so the counts are, if anything, generous.
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np

from optipose.evaluate.objective import load_objective
from optipose.model.baseline import baseline
from optipose.model.part import load_part
from optipose.search.budgets import config_from_budget
from optipose.search.driver import optimize
from optipose.search.problem import SurrogateProblem
from optipose.search.surrogate import SensorInfo, predicted_stats


def level_stats(infos, objective) -> np.ndarray:
    """Per noise level, per axis, the predicted median and p75 (deg) of the axis's best subset at that level:
    (levels, 3, 2), as the search's max-min candidates see them (``level_axis_stats``)."""
    band = objective.conditions
    mounting = (band.mounting_translation, band.mounting_rotation) if band.mounted else None
    return predicted_stats(infos, noise_scales=band.noise_scales, mounting=mounting).level_axis_stats


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="part_b", help="a part, or several separated by commas")
    ap.add_argument("--objective", default="robust")
    ap.add_argument("--samples", type=int, default=1024)
    ap.add_argument("--starts", type=int, default=8, help="poses moved by the local search, the best of the sample")
    ap.add_argument("--evals", type=int, default=60, help="surrogate evaluations of each local search")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--icp",
        type=int,
        default=0,
        help="evaluate this many of the best poses of each k and kept set by ICP under the band",
    )
    ap.add_argument("--icp-k", default="1,2,3", help="the k to evaluate by ICP")
    ap.add_argument("--icp-kept", default="", help="only these kept sets by ICP, e.g. S2,S1S3 (default: all)")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    from scipy.stats import qmc

    objective = load_objective(args.objective)
    print(
        f"bench_frontier: objective {objective.name}, {args.samples} Sobol poses + {args.starts} local searches of "
        f"{args.evals}, seed {args.seed}; ratios hand / layout (> 1: better)"
    )
    print(
        f"{'part':8} {'k':>2} {'kept':>8} {'feasible':>8} {'no worse':>8} {'best min ratio':>14} {'its x1 sum':>10} {'best x1 sum':>11}"
    )
    for name in args.part.split(","):
        t0 = time.perf_counter()
        part = load_part(name)
        problem = SurrogateProblem(
            part, objective, config_from_budget("default", (1, 2, 3), band=not objective.conditions.trivial)
        )
        hand = baseline(part)
        hand_u = [problem.space.from_pose(T) for T in hand.poses]
        hand_info = [problem.info(u) for u in hand_u]
        points = qmc.Sobol(6, scramble=True, seed=args.seed).random(args.samples)
        problem.prefetch(points)
        for k in range(1, len(hand.poses) + 1):
            ref = min(
                itertools.combinations(range(len(hand_info)), k),
                key=lambda c: level_stats([hand_info[i] for i in c], objective).max(axis=0).sum(),
            )
            target = level_stats([hand_info[i] for i in ref], objective)
            for kept in itertools.combinations(range(len(hand_info)), k - 1):
                base = [hand_info[i] for i in kept]

                def ratios(u6):
                    info = problem.sensor(u6)
                    if not isinstance(info, SensorInfo):
                        return None
                    stats = level_stats(base + [info], objective)
                    return float(np.min(target / stats)), float(target[0].sum() / stats[0].sum())

                scored = [(r, u) for u in points if (r := ratios(u)) is not None]
                order = sorted(range(len(scored)), key=lambda i: -scored[i][0][0])[: args.starts]
                starts = [scored[i][1] for i in order] + [
                    np.clip(u, 0.0, 1.0) for u in hand_u
                ]  # and from each hand sensor
                for j, start in enumerate(starts):  # move the best few to maximise the smallest ratio
                    seen = []

                    def fn(u, grad=None):
                        r = ratios(np.asarray(u, dtype=float))
                        if r is not None:
                            seen.append((r, np.array(u, dtype=float)))
                        return -r[0] if r is not None else 1.0

                    optimize(fn, "LN_BOBYQA", start, args.evals, args.seed + j)
                    scored += seen
                mins = np.array([r[0] for r, _ in scored])
                sums = np.array([r[1] for r, _ in scored])
                top = int(np.argmax(mins))
                ok = mins >= 1.0
                kept_names = "".join(hand.names[i] for i in kept) or "-"
                print(
                    f"{name:8} {k:>2} {kept_names:>8} {len(scored):>8} {int(ok.sum()):>8} {mins[top]:>14.2f} "
                    f"{sums[top]:>10.2f} {sums[ok].max() if ok.any() else float('nan'):>11.2f}"
                )
                wanted = not args.icp_kept or kept_names in args.icp_kept.split(",")
                if args.icp and str(k) in args.icp_k.split(",") and wanted:
                    icp_check(part, objective, problem, hand, kept, k, scored, args)
        print(
            f"{name:8} hand's best by the surrogate: "
            + ", ".join(
                f"k={k} {''.join(hand.names[i] for i in min(itertools.combinations(range(len(hand_info)), k), key=lambda c: level_stats([hand_info[i] for i in c], objective).max(axis=0).sum()))}"
                for k in range(1, len(hand.poses) + 1)
            )
            + f"; {time.perf_counter() - t0:.0f} s"
        )
    print(
        "no worse: poses (of those feasible) predicted no worse on every statistic at every level; best min ratio: the"
    )
    print(
        "largest smallest ratio over the 12 statistics; its x1 sum: that layout's sum ratio at the preset's noise; best x1"
    )
    print("sum: the largest sum ratio at the preset's noise among the no-worse ones")


def icp_check(part, objective, problem, hand, kept: tuple[int, ...], k: int, scored, args) -> None:
    """The ``--icp`` best poses of this k and kept set by the surrogate (see the module doc), and the hand
    layout, by ICP under the band (full protocol, seed + 1): per pose and noise level, hand / layout in sum
    and whether it is no worse on every statistic; then how many statistics it loses, and by how much at most."""
    from optipose.verdict.compare import Verdict
    from optipose.evaluate.robust import choice_of, make_evaluator
    from optipose.model.layout import Layout, SensorPose

    picks: list[tuple[tuple[float, float], np.ndarray]] = []
    for r, u in sorted(scored, key=lambda t: (-min(t[0][0], 1.0), -t[0][1] if t[0][0] >= 1.0 else -t[0][0])):
        if all(np.abs(u - p).max() > 0.02 for _, p in picks):  # distinct poses, not one basin's neighbours
            picks.append((r, u))
        if len(picks) == args.icp:
            break
    free = min(i for i in range(len(hand.poses)) if i not in kept)
    t0 = time.perf_counter()
    with make_evaluator(part, objective, seed=args.seed + 1, jobs=args.jobs, quiet=True) as evaluator:
        reference = next(c for c in evaluator(hand).table if c.k == k)
        print(
            f"  ICP under the band, seed {args.seed + 1}, full protocol: the hand layout's best choice of {k}: {reference.name}"
            + (f"; the pose in place {free + 1}" if k > 1 else "")
        )
        for j, (predicted, u) in enumerate(picks):
            if k == 1:
                layout, sensors = Layout((SensorPose("F1", problem.space.to_pose(u)),), name=f"frontier{j}"), (0,)
            else:
                poses = list(hand.sensors)
                poses[free] = SensorPose("F", problem.space.to_pose(u))
                layout, sensors = Layout(tuple(poses), name=f"frontier{j}"), tuple(sorted((*kept, free)))
            result = evaluator(layout)
            v = Verdict(k, choice_of(result, sensors), reference)
            gaps = v.worse
            levels = "  ".join(
                f"{label.split(',')[0]} {ratio:.2f}{'' if ok else '*'}" for label, ratio, ok in v.levels()
            )
            worst = max((g.found / g.reference for g in gaps), default=float("nan"))
            print(
                f"  pose {j}: surrogate smallest ratio {predicted[0]:.2f}, x1 sum {predicted[1]:.2f}; ICP hand / layout {levels}; "
                f"worse on {len(gaps)} of {6 * len(v.levels())} statistics (at most {worst:.2f}x)"
            )
    print(f"  ({time.perf_counter() - t0:.0f} s; * = worse on some statistic at that level)")


if __name__ == "__main__":
    main()
