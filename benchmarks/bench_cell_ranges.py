"""What a cell of ranges costs a draw of the verdict (issue #53: "a range costs nothing extra per draw").

A draw of the verdict (:mod:`optipose.search.draws`) is an evaluator on a seed of its own: in a cell of ranges each
worker's cell instance (:class:`optipose.cell.scans.LiveCell`) first draws its magnitudes from the ranges
(:meth:`optipose.cell.config.Cell.instance`, a few generators and dict look-ups), then its realisations as a cell of
points does. Part B's three hand sensors on one draw as the default budget's race evaluates it in a real cell (the
validation's reduced protocol, ``--scans`` of its scans drawn by the seed, every sensor subset registered), a new
evaluator per draw on a shared pool of ``--jobs`` workers, in three cells:

- ``points``: the cell of the ranges' middles (``load_cell(CELL).middle()``), the same magnitudes every draw;
- ``ranges``: the cell itself (``load_cell(CELL)``), its magnitudes drawn anew by each draw's seed;
- ``drawn as points``: each draw's instance of the ranges given as a cell of points (``cell.instance(seed)``): the
  same magnitudes as ``ranges`` without the draw, so ``ranges`` against it is the range's own cost, and the two must
  give the same per-scan rows to the last bit (the script asserts it).

Interleaved rounds after a warm-up (round 0), the cells' order rotated from round to round: the median wall time of
a draw in each and the ratios; then the draw of the magnitudes alone (``Cell.instance``), timed in this process.

    .venv/bin/python benchmarks/bench_cell_ranges.py [--cell cobot] [--scans 3] [--repeats 15] [--jobs 2]
"""

from __future__ import annotations

import argparse
import time
import timeit

import numpy as np

from optipose.cell.config import load_cell
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective
from optipose.model.baseline import baseline
from optipose.model.part import load_part
from optipose.parallel.executors import make_executor
from optipose.search.objectives import stage_objective
from optipose.seeds import verdict_seed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", default="cobot")
    ap.add_argument("--scans", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    part = load_part("part_b")
    hand = baseline(part)
    objective = stage_objective(load_objective("paper"), "validation", "reduced")
    cell = load_cell(args.cell)
    assert cell.ranges, f"cell '{args.cell}' has no range"
    cells = {
        "points": lambda seed: cell.middle(),
        "ranges": lambda seed: cell,
        "drawn as points": lambda seed: cell.instance(seed),
    }
    walls: dict[str, list[float]] = {name: [] for name in cells}
    executor = make_executor(args.jobs)
    try:
        for i in range(args.repeats + 1):  # round 0 warms the workers up
            seed = verdict_seed(0, i + 1)
            names = list(cells)
            names = names[i % 3 :] + names[: i % 3]  # each cell first, second and last in turn
            rows = {}
            for name in names:
                t0 = time.perf_counter()
                with Evaluator(
                    part,
                    objective.in_cell(cells[name](seed)),
                    seed=seed,
                    quiet=True,
                    executor=executor,
                    scans=args.scans,
                ) as ev:
                    rows[name] = ev(hand).per_scan
                if i:
                    walls[name].append(time.perf_counter() - t0)
            assert rows["ranges"].equals(rows["drawn as points"]), (
                f"round {i}: the ranges' draw differs from its points"
            )
            print(f"round {i}: " + ", ".join(f"{n} {walls[n][-1]:.2f} s" for n in cells if i), flush=True)
    finally:
        executor.close()
    med = {name: float(np.median(w)) for name, w in walls.items()}
    print(
        f"\npart_b hand, '{cell.name}', validation objective '{objective.name}' (reduced), {args.scans} scans a draw, "
        f"--jobs {args.jobs}, median of {args.repeats} rounds after a warm-up:"
    )
    for name, w in walls.items():
        print(f"  {name:16s} {med[name]:.3f} s a draw (rounds {np.round(w, 2).tolist()})")
    print(
        f"  ranges / points {med['ranges'] / med['points']:.3f}x; ranges / drawn as points "
        f"{med['ranges'] / med['drawn as points']:.3f}x (the same rows, bit for bit, in every round)"
    )
    n = 2000
    per = timeit.timeit(lambda: cell.instance(12345), number=n) / n
    print(f"  the draw of the magnitudes alone (Cell.instance, {len(cell.ranges)} ranges): {per * 1e6:.0f} us")


if __name__ == "__main__":
    main()
