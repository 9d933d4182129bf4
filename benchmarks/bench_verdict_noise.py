"""How well the verdict "no worse on any axis" can resolve: one layout compared with itself on other seeds.

The search's verdict compares a found layout with the hand-placed one on a held-out seed: every axis's
median and 75th percentile must be at most the hand layout's. Both are single draws: the noise of 77 scans and,
in a cell, one instance of it. This script evaluates the *same* layout (default: the part's hand layout) at
several seeds and applies the product's own test (``verdict.compare.dominates``) to every ordered pair of
seeds: how often a layout is "no worse" than an exact copy of itself, and how much better on every
statistic a layout must be to pass. Only the evaluations' total time is printed, for the record.

    .venv/bin/python benchmarks/bench_verdict_noise.py [--part part_b] [--objective paper] [--cell ideal] [--seeds 1,2,3] [--jobs 2]
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np

from optipose.verdict.compare import dominates
from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.objective import load_objective
from optipose.model.baseline import baseline
from optipose.model.layout import load_layout
from optipose.model.part import load_part

STATS = ("median", "p75")


def _pairs(choice) -> list:
    """(label, choice): the choice alone (one cell, one noise level)."""
    return [("nominal", choice)]


def _ratios(a, b) -> np.ndarray:
    """b's statistic over a's, per level, axis and statistic (levels, 3, 2)."""
    return np.array(
        [
            [[getattr(y, s) / getattr(x, s) for s in STATS] for x, y in zip(ca.axes, cb.axes)]
            for (_, ca), (_, cb) in zip(_pairs(a), _pairs(b))
        ]
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="part_b", help="a part, or several separated by commas")
    ap.add_argument("--objective", default="paper")
    ap.add_argument("--cell", default=None, help="the cell (default: the objective's)")
    ap.add_argument("--layout", default=None, help="a layout TOML (default: the part's hand layout)")
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    print(f"bench_verdict_noise: objective {args.objective}, seeds {seeds}; a layout against itself on another seed")
    print(f"{'part':8} {'k':>2} {'passes':>8} {'spread':>7} {'margin':>7}")
    for name in args.part.split(","):
        part = load_part(name)
        layout = load_layout(args.layout) if args.layout else baseline(part)
        tables, t0 = {}, time.perf_counter()
        for seed in seeds:
            objective = load_objective(args.objective).in_cell(args.cell)
            with Evaluator(part, objective, seed=seed, jobs=args.jobs, quiet=True) as evaluator:
                tables[seed] = evaluator(layout).table
        took = time.perf_counter() - t0
        for k in range(1, len(layout.sensors) + 1):
            ordered = list(itertools.permutations(seeds, 2))
            passes = sum(dominates(tables[j][k - 1], tables[i][k - 1]) for i, j in ordered)
            ratios = np.array([_ratios(tables[i][k - 1], tables[j][k - 1]) for i, j in ordered])
            spread = float(np.exp(np.median(np.abs(np.log(ratios)))))  # a statistic's typical factor between seeds
            margin = float(np.median(np.max(ratios.reshape(len(ordered), -1), axis=1)))  # per pair: the largest
            print(f"{name:8} {k:>2} {passes:>4}/{len(ordered):<3} {spread:>7.2f} {margin:>7.2f}")
        print(f"{name:8} {len(seeds)} evaluations of {layout.name} in {took:.0f} s")
    print(
        "passes: ordered seed pairs (i, j) where seed j's choice is no worse than seed i's on every statistic at every"
    )
    print(
        "level (the search's test of a found layout against the hand one); spread: a statistic's typical factor between"
    )
    print(
        "two seeds (exp of the median |ln(j / i)|); margin: the median over pairs of the largest ratio j / i, i.e. how much"
    )
    print("better than the hand layout on every statistic a layout must be to pass the test half the time")


if __name__ == "__main__":
    main()
