"""How well does the surrogate rank layouts against ICP? (docs/method.md, "The surrogate")

Draws feasible layouts of ``--sensors`` sensors at random for a part (seeded), adds the part's hand-placed
sensors (each alone, or each k of them), scores each with the surrogate and with the objective's own ICP on
the reduced protocol (14 scans, as the search's selection stage; ``--protocol full``: all 77), and prints Spearman's rank correlation
with ICP for the score and per axis (each axis on its best subset), the median factor between predicted
and ICP per-axis scores, the agreement on the best layout, and the time per evaluation of each fidelity.

The surrogates compared are the noise-only information matrix of one reduced nominal scan and the same plus the
voxel-bias model (and, in a real cell, the cell term: the search's default). ``--cell`` evaluates in another cell
than the objective's. ``--icp-cache FILE`` keeps the ICP figures (.npz) so a rerun only re-scores the surrogate.

    .venv/bin/python benchmarks/bench_surrogate_ranking.py [--part part_b] [--layouts 16] [--seed 0] [--cell ideal]
"""

from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

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
    ap.add_argument("--objective", default="paper")
    ap.add_argument("--cell", default=None, help="the cell (default: the objective's)")
    ap.add_argument("--sensors", type=int, default=1, help="sensors per layout")
    ap.add_argument("--layouts", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--protocol",
        choices=("reduced", "full"),
        default="reduced",
        help="ICP on the selection's 14 scans or the full protocol",
    )
    ap.add_argument("--icp-cache", type=Path, default=None, help="keep the ICP figures here (.npz) and reuse them")
    args = ap.parse_args()

    part, objective = load_part(args.part), load_objective(args.objective).in_cell(args.cell)
    problem = SurrogateProblem(part, objective, SearchConfig())
    layouts = _layouts(problem, part, args.sensors, args.layouts, args.seed)
    n_hand = len(layouts) - args.layouts
    print(
        f"bench_surrogate_ranking: {args.part}, objective {objective.name}, {args.layouts} random feasible "
        f"{args.sensors}-sensor layouts + {n_hand} hand-placed, seed {args.seed}, cell {objective.cell.name}"
    )
    t0 = time.perf_counter()
    infos = [[problem.surrogate.info(T) for T in problem.space.to_poses(u)] for u in layouts]
    t_info = time.perf_counter() - t0
    icp, t_icp = _icp(part, objective, problem, layouts, args)
    scores = _models(part, objective, problem, layouts, infos)
    for label, (icp_score, icp_axes) in icp.items():
        print(f"-- against ICP, {label}")
        for name, stats in scores[label].items():
            _report(
                name, np.array([s.score for s in stats]), np.array([s.axis_score for s in stats]), icp_score, icp_axes
            )
    n = len(layouts)
    print(f"time per layout: surrogate scans {1e3 * t_info / n:.0f} ms, ICP {args.protocol} protocol {t_icp / n:.2f} s")


def _layouts(problem, part, k: int, n: int, seed: int) -> list[np.ndarray]:
    """``n`` random feasible k-sensor layouts (6k,), then every k of the hand-placed sensors."""
    rng, out = np.random.default_rng(seed), []
    while len(out) < n:
        u = rng.random(6 * k)
        if problem.score(u).feasible:
            out.append(u)
    hand = part.layouts["hand"].poses if "hand" in part.layouts else []
    return out + [np.concatenate([problem.space.from_pose(T) for T in c]) for c in itertools.combinations(hand, k)]


def _icp(part, objective, problem, layouts, args) -> tuple[dict, float]:
    """label → (ICP score (n,), per-axis median + p75 (n, 3)), rad → deg; and the seconds ICP took."""
    path = args.icp_cache
    if path is not None and path.is_file():
        data = np.load(path, allow_pickle=False)
        return {str(label): (data[f"score{i}"], data[f"axes{i}"]) for i, label in enumerate(data["labels"])}, float(
            data["seconds"]
        )
    reduced = objective if args.protocol == "full" else reduced_objective(objective)
    k, t0 = args.sensors, time.perf_counter()
    rows: dict = {}
    with Evaluator(part, reduced, seed=args.seed + 1, quiet=True) as evaluator:
        for u in layouts:
            _add(rows, f"cell {objective.cell.name}", evaluator(problem.space.to_poses(u)).table[k - 1])
    seconds = time.perf_counter() - t0
    out = {label: (np.rad2deg(np.array(s)), np.rad2deg(np.array(a))) for label, (s, a) in rows.items()}
    if path is not None:
        arrays = {f"score{i}": s for i, (s, _) in enumerate(out.values())} | {
            f"axes{i}": a for i, (_, a) in enumerate(out.values())
        }
        np.savez(path, labels=np.array(list(out)), seconds=seconds, **arrays)
    return out, seconds


def _add(rows: dict, label: str, choice) -> None:
    scores, axes = rows.setdefault(label, ([], []))
    scores.append(choice.score)
    axes.append([a.median + a.p75 for a in choice.axes])  # NaN where the axis is unobservable


def _models(part, objective, problem, layouts, infos) -> dict:
    plain = Surrogate(part, voxel=objective.registration.voxel_size, turns=np.zeros((0, 3)))
    noise_only = [
        predicted_stats([plain.info(T) for T in problem.space.to_poses(u)], *problem.weights) for u in layouts
    ]
    full = [predicted_stats(i, *problem.weights) for i in infos]
    return {f"cell {objective.cell.name}": {"noise only": noise_only, "the search's surrogate": full}}


def _report(name: str, score: np.ndarray, axes: np.ndarray, icp: np.ndarray, icp_axes: np.ndarray) -> None:
    ok = np.isfinite(icp_axes)
    rho = spearmanr(score, icp)[0]
    per_axis = ", ".join(
        f"{a} {spearmanr(axes[ok[:, j], j], icp_axes[ok[:, j], j])[0]:.2f}" for j, a in enumerate(AXES)
    )
    factor = ", ".join(
        f"{a} {np.exp(np.median(np.abs(np.log(axes[ok[:, j], j] / icp_axes[ok[:, j], j])))):.2f}x"
        for j, a in enumerate(AXES)
    )
    ranks = np.argsort(np.argsort(icp))
    print(
        f"  {name}: Spearman rho score {rho:.2f}; per axis {per_axis}; median factor off ICP per axis {factor}; "
        f"its best is ICP rank {int(ranks[np.argmin(score)]) + 1} of {len(icp)}"
    )


if __name__ == "__main__":
    main()
