"""What one draw of the verdict costs in a real cell (issue #33), and what its two savings buy.

A draw of the verdict (:mod:`optipose.search.draws`) is a new cell instance: an evaluator on its own seed
that evaluates the hand layout and a found one. Two things make it cheaper than a plain evaluation:

- ``form``: the part as made's form field on its grid (:meth:`optipose.cell.asmade.AsMade.form_grid`), which each
  worker builds once a draw: as a product of each plane wave over the axes, against the sum of cosines at every
  node (:meth:`~optipose.cell.asmade.AsMade.form_exact`), in the same process on the same instance; and the
  largest difference between the two grids;
- ``draw``: part B's hand layout and ``results/reference/part_b/layouts/found_k3.toml`` on one draw of the
  reduced protocol's scans (``--scans``), every sensor subset registered against only the subsets the verdict's
  choices use (hand S2 and S1S2S3, found every subset but the singles F2, F3), interleaved in ``--repeats`` rounds
  after a warm-up, on ``--jobs`` worker processes: the median wall time of each, their ratio, and that the used
  subsets' rows are the same numbers either way.

    .venv/bin/python benchmarks/bench_verdict_draw.py [--scans 6,14] [--repeats 3] [--jobs 2]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from optipose.cell.asmade import AsMade
from optipose.cell.scans import CellSetup
from optipose.evaluate.evaluator import Evaluator
from optipose.parallel.executors import make_executor
from optipose.evaluate.objective import load_objective
from optipose.model.baseline import baseline
from optipose.model.layout import load_layout
from optipose.model.part import load_part
from optipose.search.objectives import stage_objective
from optipose.seeds import verdict_seed

ROOT = Path(__file__).resolve().parents[1]
HAND_USED = [(1,), (0, 1, 2)]  # S2 for k = 1, 2; S1S2S3 and S2 for k = 3 (the validation's choices on B)
FOUND_USED = [(0,), (0, 1), (0, 2), (1, 2), (0, 1, 2)]


def form(part) -> None:
    v, f = np.asarray(part.mesh.vertices, float), np.asarray(part.mesh.faces)
    process = CellSetup.of(load_objective("paper").cell, part).process
    times = {}
    for name in ("product", "cosines"):
        made = AsMade(process, v, f, 7)
        t0 = time.perf_counter()
        if name == "product":
            grid, first, step = made.form_grid()
        else:
            axes = [first[j] + step[j] * np.arange(grid.shape[j]) for j in range(3)]
            exact = made.form_exact(np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)).reshape(
                grid.shape
            )
        times[name] = time.perf_counter() - t0
    print(
        f"form grid of part_b as made ({process.name}, {grid.size:,} nodes): product {times['product']:.3f} s, "
        f"cosines {times['cosines']:.3f} s, ratio {times['cosines'] / times['product']:.0f}x, "
        f"largest difference {np.abs(grid - exact).max():.1e} m of an RMS {exact.std():.1e} m"
    )


def draw(part, scans: int, repeats: int, jobs: int) -> None:
    objective = stage_objective(load_objective("paper"), "validation", "reduced")
    hand, found = baseline(part), load_layout(ROOT / "results/reference/part_b/layouts/found_k3.toml")
    executor = make_executor(jobs)
    walls: dict[str, list[float]] = {"every subset": [], "used subsets": []}
    try:
        for i in range(repeats + 1):  # round 0 warms the workers up
            results = {}
            for name in walls:
                subsets = {"every subset": (None, None), "used subsets": (HAND_USED, FOUND_USED)}[name]
                t0 = time.perf_counter()
                with Evaluator(
                    part, objective, seed=verdict_seed(0, i + 1), quiet=True, executor=executor, scans=scans
                ) as ev:
                    results[name] = (ev(hand, subsets=subsets[0]), ev(found, subsets=subsets[1]))
                if i:
                    walls[name].append(time.perf_counter() - t0)
            for whole, some in zip(results["every subset"], results["used subsets"]):
                rows = whole.per_scan[whole.per_scan["subset_index"].isin(some.per_scan["subset_index"])].reset_index(
                    drop=True
                )
                assert rows.equals(some.per_scan), "the used subsets' rows differ from the whole evaluation's"
    finally:
        executor.close()
    every, used = (float(np.median(walls[n])) for n in walls)
    print(
        f"a draw of {scans} scans, hand + found k=3, {jobs} workers, median of {repeats}: every subset {every:.2f} s, "
        f"used subsets {used:.2f} s, ratio {every / used:.2f}x; the used rows identical"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", default="6,14")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    part = load_part("part_b")
    form(part)
    for n in (int(s) for s in args.scans.split(",")):
        draw(part, n, args.repeats, args.jobs)


if __name__ == "__main__":
    main()
