"""How well does the surrogate rank layouts against ICP? (docs/method.md, "The surrogate")

Draws feasible layouts of ``--sensors`` sensors at random for a part (seeded), adds the part's hand-placed
sensors (each alone, or each k of them), scores each with the surrogate and with the objective's own ICP on
the reduced protocol (14 scans, as the search's selection stage; ``--protocol full``: all 77), and prints Spearman's rank correlation
with ICP for the score and per axis (each axis on its best subset), the median factor between predicted
and ICP per-axis scores, the agreement on the best layout, and the time per evaluation of each fidelity.

With the nominal objective (``--objective paper``) the surrogates compared are the noise-only information
matrix of one reduced nominal scan and the same plus the voxel-bias model (the search's default), at
``--noise-scale``. With a band (``--objective robust``) ICP runs under every condition of the band
(``optipose.evaluate.robust.RobustEvaluator``; ``--draws`` overrides its bracket draws) and the surrogate
(voxel bias, the band's noise levels) is compared with and without the bracket mounting term, on the robust
score and at each noise level alone, and with and without the noise bias term (what the noise does to
equal-weight voxel centroids, a bias growing as σ²; ``--no-mounting`` drops the band's bracket tolerance to
see that term alone). ``--icp-cache FILE`` keeps the ICP figures (.npz) so a rerun only
re-scores the surrogate.

    .venv/bin/python benchmarks/bench_surrogate_ranking.py [--part part_b] [--layouts 16] [--seed 0] [--noise-scale 5]
    .venv/bin/python benchmarks/bench_surrogate_ranking.py --objective robust --sensors 2 --layouts 12 --draws 1
    .venv/bin/python benchmarks/bench_surrogate_ranking.py --objective robust --no-mounting --layouts 12
"""

from __future__ import annotations

import argparse
import itertools
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from optipose.evaluate.conditions import Condition
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective, reduced_objective
from optipose.evaluate.robust import RobustEvaluator, robust_result
from optipose.model.part import load_part
from optipose.search.config import SearchConfig
from optipose.search.problem import SurrogateProblem
from optipose.search.surrogate import Surrogate, predicted_stats

AXES = ("roll", "pitch", "yaw")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="part_b")
    ap.add_argument("--objective", default="paper", help="paper (nominal) or an objective with a band, e.g. robust")
    ap.add_argument("--sensors", type=int, default=1, help="sensors per layout")
    ap.add_argument("--layouts", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--noise-scale", type=float, default=1.0, help="nominal objective: the sensor noise sigma times this"
    )
    ap.add_argument("--draws", type=int, default=None, help="band objective: bracket draws per noise level")
    ap.add_argument(
        "--protocol",
        choices=("reduced", "full"),
        default="reduced",
        help="ICP on the selection's 14 scans or the full protocol",
    )
    ap.add_argument("--no-mounting", action="store_true", help="band objective: brackets exact (the noise band alone)")
    ap.add_argument("--icp-cache", type=Path, default=None, help="keep the ICP figures here (.npz) and reuse them")
    args = ap.parse_args()

    part, objective = load_part(args.part), load_objective(args.objective)
    if args.draws is not None:
        objective = replace(objective, conditions=replace(objective.conditions, mounting_draws=args.draws))
    if args.no_mounting:
        objective = replace(
            objective, conditions=replace(objective.conditions, mounting_translation=0.0, mounting_rotation=0.0)
        )
    band = not objective.conditions.trivial
    problem = SurrogateProblem(part, objective, SearchConfig())
    layouts = _layouts(problem, part, args.sensors, args.layouts, args.seed)
    n_hand = len(layouts) - args.layouts
    print(
        f"bench_surrogate_ranking: {args.part}, objective {objective.name}, {args.layouts} random feasible "
        f"{args.sensors}-sensor layouts + {n_hand} hand-placed, seed {args.seed}"
        + ("" if band else f", noise x{args.noise_scale:g}")
    )
    t0 = time.perf_counter()
    infos = [[problem.surrogate.info(T) for T in problem.space.to_poses(u)] for u in layouts]
    t_info = time.perf_counter() - t0
    icp, t_icp = _icp(part, objective, problem, layouts, args, band)
    scores = (
        _band_models(part, objective, problem, layouts, infos)
        if band
        else _nominal_models(part, objective, problem, layouts, infos, args.noise_scale)
    )
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


def _icp(part, objective, problem, layouts, args, band: bool) -> tuple[dict, float]:
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
    if band:
        with RobustEvaluator(part, reduced, seed=args.seed + 1, quiet=True) as evaluator:
            for u in layouts:
                result = evaluator(problem.space.to_poses(u))
                _add(rows, "the robust score (worst over the band)", result.table[k - 1])
                for scale in objective.conditions.noise_scales:
                    at = robust_result([(c, r) for c, r in result.results if c.noise_scale == scale], reduced)
                    _add(rows, f"noise x{scale:g} (worst over its draws)", at.table[k - 1])
    else:
        with Evaluator(
            part, reduced, seed=args.seed + 1, condition=Condition(args.noise_scale), quiet=True
        ) as evaluator:
            for u in layouts:
                _add(rows, f"noise x{args.noise_scale:g}", evaluator(problem.space.to_poses(u)).table[k - 1])
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


def _nominal_models(part, objective, problem, layouts, infos, scale: float) -> dict:
    plain = Surrogate(part, voxel=objective.registration.voxel_size, turns=np.zeros((0, 3)))
    noise_only = [
        predicted_stats([plain.info(T) for T in problem.space.to_poses(u)], *problem.weights, noise_scales=(scale,))
        for u in layouts
    ]
    bias = [predicted_stats(i, *problem.weights, noise_scales=(scale,)) for i in infos]
    return {f"noise x{scale:g}": {"noise only": noise_only, "noise + voxel bias": bias}}


def _band_models(part, objective, problem, layouts, infos) -> dict:
    """Per ICP label, the surrogate without either band term, with the noise bias term, and with it and the
    mounting term (when the band has a tolerance), at the same noise levels."""
    scales, mounting = problem.band["noise_scales"], problem.band["mounting"]
    bare = Surrogate(part, voxel=objective.registration.voxel_size, turns=problem.surrogate.turns)  # no noise bias term
    bare_infos = [[bare.info(T) for T in problem.space.to_poses(u)] for u in layouts]
    models = [("voxel bias alone", bare_infos, None), ("with the noise bias term", infos, None)]
    models += [("with the noise bias and the mounting term", infos, mounting)] if mounting else []
    out = {}
    for label, levels in [
        ("the robust score (worst over the band)", scales),
        *[(f"noise x{s:g} (worst over its draws)", (s,)) for s in scales],
    ]:
        out[label] = {
            name: [predicted_stats(i, *problem.weights, noise_scales=tuple(levels), mounting=m) for i in model_infos]
            for name, model_infos, m in models
        }
    t0 = time.perf_counter()
    for i in infos:
        predicted_stats(i, *problem.weights, noise_scales=scales, mounting=mounting)
    print(f"predicted_stats with the mounting term: {1e3 * (time.perf_counter() - t0) / len(infos):.1f} ms per layout")
    return out


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
