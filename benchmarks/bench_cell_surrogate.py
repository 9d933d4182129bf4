"""How well does the surrogate rank layouts under a real cell? (docs/method.md, "The surrogate under the cell")

Per part, ``--layouts`` random feasible three-sensor layouts (seeded draws of the search space, kept when the
surrogate problem finds them feasible) and the hand layout. Each is evaluated once by ICP under the cell on
the reduced protocol (14 scans, as the search's selection stage) with one fixed seed, so every layout sees
the same cell instance (the part as made, the calibration) and the same per-scan draws: common random
numbers. ICP's Table 1 gives each layout's best choice of k = 1, 2 and 3 of its sensors; the surrogate's
counterpart is the best-scoring k-subset of the same three sensors, so one ICP evaluation ranks all three k.

The surrogates compared: the nominal one (sensor noise and voxel bias: what the search scores with today,
blind to the cell), and the same with the cell's terms (:mod:`optipose.search.cell_terms`), all of them and
each source alone; in a cell of ranges (``--cell cobot``) the cell's terms across the ranges (the search's) and at
the ranges' middles. Printed: Spearman ρ of each against ICP under the cell, per part and k, and per axis.
With ``--icp-seeds 1,2`` ICP runs under each seed's cell instance: the later seeds' ICP is ranked against
the first (how much one instance alone moves the ranking), and every surrogate also against the geometric
mean of ICP's scores over the seeds. ICP results are cached per layout and seed in ``--cache`` (npz), so a
rerun only re-scores the surrogates.

    nice .venv/bin/python benchmarks/bench_cell_surrogate.py --parts part_a,part_b,part_c --layouts 50 --icp-seeds 1,2 --jobs 2
    nice .venv/bin/python benchmarks/bench_cell_surrogate.py --icp-only ...   # fill the ICP cache only
"""

from __future__ import annotations

import argparse
import itertools
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.stats import spearmanr

from optipose.cell.robot import CalibrationErrors, RobotErrors
from optipose.cell.scans import CellSetup
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective, reduced_objective
from optipose.model.material import MaterialEffects
from optipose.model.part import load_part
from optipose.search.config import SearchConfig
from optipose.search.problem import SurrogateProblem
from optipose.search.surrogate import Surrogate, predicted_stats, protocol_turns

AXES = ("roll", "pitch", "yaw")
SENSORS = 3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default="part_a,part_b,part_c")
    ap.add_argument(
        "--layouts", type=int, default=50, help="random feasible layouts per part (the hand layout is added)"
    )
    ap.add_argument("--cell", default="ur10e")
    ap.add_argument("--seed", type=int, default=0, help="the layouts' draws; ICP runs with seed + 1")
    ap.add_argument(
        "--icp-seeds",
        default="",
        help="ICP seeds, comma-separated (default: seed + 1); the first is the one ranked "
        "against, the others (other cell instances) are ranked against it as a ceiling",
    )
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/optipose-bench-cellsurr"))
    ap.add_argument("--icp-only", action="store_true", help="fill the ICP cache, score no surrogate")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    objective = load_objective("paper").in_cell(args.cell)
    for name in args.parts.split(","):
        part = load_part(name)
        problem = SurrogateProblem(part, load_objective("paper").in_cell("ideal"), SearchConfig())
        layouts = _layouts(problem, part, args.layouts, args.seed)
        seeds = [int(x) for x in args.icp_seeds.split(",")] if args.icp_seeds else [args.seed + 1]
        print(
            f"bench_cell_surrogate: {name}, cell {args.cell}, {args.layouts} random feasible {SENSORS}-sensor layouts + the hand "
            f"layout, layouts seed {args.seed}, ICP seed(s) {', '.join(map(str, seeds))} (reduced protocol)",
            flush=True,
        )
        icp = [_icp(part, objective, problem, layouts, args, s) for s in seeds]
        if not args.icp_only:
            _rank(part, objective, problem, layouts, icp, seeds)


def _layouts(problem, part, n: int, seed: int) -> list[np.ndarray]:
    """``n`` random feasible three-sensor layouts (18,), then the hand layout (the conventional placement for a
    part without one)."""
    from optipose.model.baseline import baseline

    rng, out = np.random.default_rng(seed), []
    while len(out) < n:
        u = rng.random(6 * SENSORS)
        if problem.score(u).feasible:
            out.append(u)
    hand = baseline(part).poses[:SENSORS]
    return out + [np.concatenate([problem.space.from_pose(T) for T in hand])]


def _icp(part, objective, problem, layouts, args, seed: int) -> dict:
    """Per layout, ICP's best-choice score (k,) and per-axis median + p75 (k, 3), deg; cached per layout."""
    reduced = reduced_objective(objective)
    scores, axes, todo = [], [], []
    stem = f"{part.name}-{args.cell}-seed{args.seed}" + ("" if seed == args.seed + 1 else f"-icp{seed}")
    files = [args.cache / f"{stem}-{i:03d}.npz" for i in range(len(layouts) - 1)] + [args.cache / f"{stem}-hand.npz"]
    todo = [i for i, f in enumerate(files) if not f.is_file()]
    if todo:
        t0 = time.perf_counter()
        with Evaluator(part, reduced, seed=seed, jobs=args.jobs, quiet=True) as evaluator:
            for n, i in enumerate(todo):
                table = evaluator(problem.space.to_poses(layouts[i])).table
                np.savez(
                    files[i],
                    u=layouts[i],
                    score=np.rad2deg([c.score for c in table]),
                    axes=np.rad2deg([[a.median + a.p75 for a in c.axes] for c in table]),
                )
                if n % 10 == 9:
                    print(
                        f"  ICP {n + 1} of {len(todo)}, {(time.perf_counter() - t0) / (n + 1):.1f} s per layout",
                        flush=True,
                    )
    for i, f in enumerate(files):
        data = np.load(f)
        if not np.allclose(data["u"], layouts[i]):
            raise SystemExit(f"{f}: another layout than this run's draw; remove the cache")
        scores.append(data["score"])
        axes.append(data["axes"])
    return {"score": np.array(scores), "axes": np.array(axes)}


def _models(part, objective, problem) -> dict:
    """The surrogates compared: name → Surrogate (None: the problem's own, the nominal surrogate)."""
    setup = CellSetup.of(objective.cell, part)
    cell, none = (
        setup.cell,
        CellSetup(
            replace(
                setup.cell,
                robot=RobotErrors(),
                calibration=CalibrationErrors(),
                as_made=False,
                material=False,
                ranges=(),
            ),
            setup.process.scaled(0.0),
            MaterialEffects(),
        ),
    )
    alone = {
        "calibration alone": replace(none, cell=replace(none.cell, calibration=cell.calibration)),
        "robot alone": replace(none, cell=replace(none.cell, robot=cell.robot)),
        "part as made alone": replace(none, process=setup.process),
        "material alone": replace(none, effects=setup.effects),
    }
    make = lambda s: Surrogate(part, voxel=objective.registration.voxel_size, turns=protocol_turns(objective), cell=s)
    middle = {"the cell's terms at the middles": make(setup.middle())} if setup.cell.ranges else {}
    return (
        {"nominal (today)": problem.surrogate, "with the cell's terms": make(setup)}
        | middle
        | {k: make(s) for k, s in alone.items()}
    )


def _rank(part, objective, problem, layouts, icp: list[dict], seeds: list[int]) -> None:
    """Spearman ρ of each surrogate against ICP under the first seed's cell instance (and of ICP under the
    other seeds' instances: how far one instance alone moves the ranking), then, with several seeds, against
    the geometric mean of ICP's scores over them."""
    rows = {f"ICP, seed {s}": (v["score"], v["axes"], np.nan) for s, v in zip(seeds[1:], icp[1:])}
    for name, surrogate in _models(part, objective, problem).items():
        t0 = time.perf_counter()
        infos = [[surrogate.info(T) for T in problem.space.to_poses(u)] for u in layouts]
        t_info = time.perf_counter() - t0
        score, axes = _predicted(infos, problem.weights)
        rows[name] = (score, axes, t_info / len(layouts))
    targets = {f"ICP under the cell, seed {seeds[0]}": icp[0]}
    if len(icp) > 1:
        mean = {key: np.exp(np.mean([np.log(v[key]) for v in icp], axis=0)) for key in ("score", "axes")}
        targets[f"the geometric mean of ICP under the cell over seeds {', '.join(map(str, seeds))}"] = mean
    for label, target in targets.items():
        for k in range(SENSORS):
            print(f"-- k = {k + 1}: Spearman rho against {label} ({len(layouts)} layouts)")
            for name, (score, axes, t) in rows.items():
                if name.startswith("ICP") and label != next(iter(targets)):
                    continue
                _line(name, score[:, k], axes[:, k], target["score"][:, k], target["axes"][:, k], t)


def _line(name: str, score, axes, icp_score, icp_axes, t: float) -> None:
    ok = np.isfinite(icp_axes) & np.isfinite(axes)
    per_axis = " / ".join(f"{spearmanr(axes[ok[:, a], a], icp_axes[ok[:, a], a])[0]:.2f}" for a in range(3))
    factor = np.exp(np.median(np.log(score / icp_score)))
    print(
        f"  {name:26s} score {spearmanr(score, icp_score)[0]:5.2f}; roll / pitch / yaw {per_axis}; median factor predicted / ICP "
        f"{factor:.2f}" + ("" if np.isnan(t) else f"; surrogate {1e3 * t:.0f} ms per layout"),
        flush=True,
    )


def _predicted(infos, weights) -> tuple[np.ndarray, np.ndarray]:
    """Per layout, the surrogate's best-choice score (k,) and its per-axis median + p75 (k, 3), deg: for each
    k the k-subset of the layout's sensors with the lowest score, as ICP's Table 1 chooses."""
    scores, axes = [], []
    for layout in infos:
        s_row, a_row = [], []
        for k in range(1, SENSORS + 1):
            preds = [
                predicted_stats([layout[i] for i in c], *weights) for c in itertools.combinations(range(SENSORS), k)
            ]
            best = min(preds, key=lambda p: p.score)
            s_row.append(best.score)
            a_row.append(best.axis_score)
        scores.append(s_row)
        axes.append(a_row)
    return np.array(scores), np.array(axes)


if __name__ == "__main__":
    main()
