"""What a sensor pose costs the surrogate in a real cell, and what two savings buy (issue #33).

``quick`` searches 10 s; in the paper's cell a pose costs the surrogate several nominal ones (its cell term,
:mod:`optipose.search.cell_terms`), so the seconds buy few poses. Two savings, each measured against the
way without it:

- ``trig``: the form field's features (:meth:`~optipose.search.cell_terms.CellModel.part_columns`), cos and sin
  in float32 on the phase reduced in float64, against both in float64 (the way before, written out here), on
  the same points in the same process; and the largest difference of the features over their RMS;
- ``heap``: the same ``--poses`` random poses of part B scored by a new :class:`SurrogateProblem`, and one
  verdict draw (hand + ``results/reference/part_b/layouts/found_k3.toml``, ``--scans`` scans, ``--jobs``
  workers), in child processes with and without glibc's thresholds raised (:mod:`optipose.heap`),
  interleaved in ``--repeats`` rounds: the medians and their ratios.

    .venv/bin/python benchmarks/bench_cell_pose.py [--poses 300] [--scans 6] [--repeats 3] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def trig() -> None:
    from optipose.evaluate.objective import load_objective
    from optipose.model.part import load_part
    from optipose.search.cell_terms import _FORM_FEATURES
    from optipose.search.problem import SurrogateProblem
    from optipose.search.budgets import config_from_budget

    part = load_part("part_b")
    model = SurrogateProblem(part, load_objective("paper"), config_from_budget("quick", (1,), cell=True)).surrogate.cell
    rng = np.random.default_rng(0)
    lo, hi = part.mesh.bounds
    x = lo + (hi - lo) * rng.random((4000, 3))  # a large turn's voxel centroids
    n = np.tile([0.0, 0.0, 1.0], (len(x), 1))

    def float64() -> np.ndarray:
        phase = x @ model.k.T
        return model.process.form_rms / np.sqrt(_FORM_FEATURES) * np.hstack([np.cos(phase), np.sin(phase)])

    walls = {"float32": [], "float64": []}
    for _ in range(20):
        for name, fn in (("float32", lambda: model.part_columns(x, n)[:, : 2 * _FORM_FEATURES]), ("float64", float64)):
            t0 = time.perf_counter()
            fn()
            walls[name].append(time.perf_counter() - t0)
    new, old = model.part_columns(x, n)[:, : 2 * _FORM_FEATURES], float64()
    a, b = (float(np.median(walls[k])) for k in ("float32", "float64"))
    print(
        f"form features at {len(x):,} points x {_FORM_FEATURES} frequencies: float32 {1e3 * a:.2f} ms, float64 {1e3 * b:.2f} ms, "
        f"ratio {b / a:.1f}x; largest difference {np.abs(new - old).max() / old.std():.1e} of their RMS"
    )


def child(poses: int, scans: int, jobs: int) -> None:
    """One round in this process (its heap as the environment set it): the poses, then the draw."""
    from threadpoolctl import threadpool_limits

    from optipose.evaluate.evaluator import Evaluator
    from optipose.parallel.executors import make_executor
    from optipose.evaluate.objective import load_objective
    from optipose.model.baseline import baseline
    from optipose.model.layout import load_layout
    from optipose.model.part import load_part
    from optipose.search.budgets import config_from_budget
    from optipose.search.objectives import stage_objective
    from optipose.search.problem import SurrogateProblem
    from optipose.seeds import verdict_seed

    part, paper = load_part("part_b"), load_objective("paper")
    with threadpool_limits(limits=1, user_api="blas"):  # as the search runs it
        problem = SurrogateProblem(part, paper, config_from_budget("quick", (1,), cell=True))
        problem.surrogate.ready()
        us = np.random.default_rng(0).random((poses, 6))
        t0 = time.perf_counter()
        feasible = sum(not hasattr(problem.sensor(u), "constraint") for u in us)
        pose = (time.perf_counter() - t0) / max(feasible, 1)
    objective = stage_objective(paper, "validation", "reduced")
    hand, found = baseline(part), load_layout(ROOT / "results/reference/part_b/layouts/found_k3.toml")
    executor = make_executor(jobs)
    try:
        walls = []
        for i in range(2):  # the first warms the workers up
            t0 = time.perf_counter()
            with Evaluator(
                part, objective, seed=verdict_seed(0, i + 1), quiet=True, executor=executor, scans=scans
            ) as ev:
                ev(hand), ev(found)
            walls.append(time.perf_counter() - t0)
    finally:
        executor.close()
    print(json.dumps({"pose_ms": 1e3 * pose, "feasible": int(feasible), "draw_s": walls[-1]}))


def heap(poses: int, scans: int, repeats: int, jobs: int) -> None:
    from optipose.heap import HEAP_VARIABLES

    plain = {k: v for k, v in os.environ.items() if k not in HEAP_VARIABLES}
    raised = plain | {k: str(v) for k, v in HEAP_VARIABLES.items()}
    rows: dict[str, list[dict]] = {"default": [], "raised": []}
    command = [sys.executable, __file__, "--child", "--poses", str(poses), "--scans", str(scans), "--jobs", str(jobs)]
    for _ in range(repeats):
        for name, env in (("default", plain), ("raised", raised)):
            done = subprocess.run(command, env=env, capture_output=True, text=True, check=True, cwd=ROOT)
            rows[name].append(json.loads(done.stdout.strip().splitlines()[-1]))
    med = {
        name: {key: float(np.median([r[key] for r in rs])) for key in ("pose_ms", "draw_s")}
        for name, rs in rows.items()
    }
    d, r = med["default"], med["raised"]
    print(
        f"part_b, {rows['raised'][0]['feasible']} feasible of {poses} poses, median of {repeats}: a surrogate pose "
        f"{d['pose_ms']:.1f} ms with glibc's thresholds, {r['pose_ms']:.1f} ms raised, ratio {d['pose_ms'] / r['pose_ms']:.2f}x; "
        f"a draw of {scans} scans (hand + found k=3, {jobs} workers) {d['draw_s']:.2f} s, {r['draw_s']:.2f} s, "
        f"ratio {d['draw_s'] / r['draw_s']:.2f}x"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=300)
    ap.add_argument("--scans", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.poses, args.scans, args.jobs)
        return
    trig()
    heap(args.poses, args.scans, args.repeats, args.jobs)


if __name__ == "__main__":
    main()
