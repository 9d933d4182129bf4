"""The confident verdict's calibration (issue #33): how often an exact copy of the hand layout is bought, and
how often a layout better by 1.3x on every statistic is.

Part B's hand layout is evaluated under a real cell (default ``--cell ur10e``, objective ``paper``) at a pool
of seeds (each a cell draw: the part as made and the calibration from the evaluator's seed, the robot path,
set orientation and noise from each scan's seed), and once more per seed as its *twin*: the same cell
instance with the scans' own draws of seed + 1000. All of it is cached to ``--cache``. Each of ``--trials``
trials then compares, per k, the hand layout's k-sensor choice (that of the first seed, held fixed) with a
"found" side on paired draws picked from the pool by the trial's seed
(:func:`optipose.verdict.confidence.compare_draws`, or :func:`~optipose.verdict.racing.race`):

- ``copy, same draws``: the hand layout itself on the same draws (common random numbers: an exact tie);
- ``copy, own scans``: its twin, the same cell with other scan draws (what a second, equal layout would
  share with the hand one under common random numbers, less its scans);
- ``copy, other cells``: the hand layout at another seed of the pool (no common random numbers at all);
- ``1.3x, …``: the same three with the found side's per-scan errors divided by 1.3 (a layout built to be
  1.3x better on every statistic; not a real layout).

Trials share the pool's evaluations, so they are not independent draws of the cell. Prints the count of
trials per decision, case, number of draws and k, and the median point estimate of hand / found in sum.

    .venv/bin/python benchmarks/bench_verdict_calibration.py [--seeds 1-20] [--trials 40] [--draws 1,4,10] [--race 10] [--cell ur10e] [--scans 5]
"""

from __future__ import annotations

import argparse
import pickle
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from optipose.evaluate.evaluator import Evaluator
from optipose.evaluate.protocol import perturbations
from optipose.evaluate.objective import load_objective
from optipose.model.baseline import baseline
from optipose.model.part import load_part


TWIN = 1000  # the scans' own seeds of a twin evaluation: those of seed + TWIN


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = (int(x) for x in text.split("-"))
        return list(range(a, b + 1))
    return [int(s) for s in text.split(",")]


def hand_results(
    part_name: str, cell: str, objective: str, seeds: list[int], cache: Path, jobs: int, twin: bool = False
) -> dict:
    """The hand layout's EvaluationResult per seed, each read from ``cache`` or evaluated and written there.
    ``twin``: in the cell instance of the seed (the part as made, the calibration: drawn from the evaluator's
    seed) but with the scans' own draws (noise, robot path, set orientation: drawn from each scan's seed) of
    seed + TWIN, the protocol's orientations unchanged."""
    part = load_part(part_name)
    layout = baseline(part)
    cache.mkdir(parents=True, exist_ok=True)
    out = {}
    for seed in seeds:
        path = cache / f"{part_name}-{cell}-{objective}-seed{seed}{'-twin' if twin else ''}.pkl"
        if not path.exists():
            t0 = time.perf_counter()
            with Evaluator(
                part, load_objective(objective).in_cell(cell), seed=seed, jobs=jobs, quiet=True
            ) as evaluator:
                if twin:
                    other = perturbations(evaluator.objective.protocol, seed + TWIN)
                    evaluator.perturbations = replace(evaluator.perturbations, seeds=other.seeds)
                result = evaluator(layout)
            path.write_bytes(pickle.dumps(result))
            print(f"  evaluated seed {seed} in {time.perf_counter() - t0:.0f} s", flush=True)
        out[seed] = pickle.loads(path.read_bytes())
    return out


def _found_seeds(rng: np.random.Generator, hand: list[int], seeds: list[int]) -> list[int]:
    """For each hand seed another seed of the pool (all distinct): the found side's cells, unpaired."""
    while True:
        found = [int(s) for s in rng.choice(seeds, len(hand), replace=False)]
        if all(h != f for h, f in zip(hand, found)):
            return found


def main() -> None:
    from optipose.verdict.confidence import Decision, PairedDraw, compare_draws, scan_errors
    from optipose.verdict.rules import Rules
    from optipose.verdict.racing import race

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="part_b")
    ap.add_argument("--cell", default="ur10e")
    ap.add_argument("--objective", default="paper")
    ap.add_argument("--seeds", default="1-20", help="the pool of cell draws: 1-20 or 1,2,3")
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--draws", default="1,4,10", help="paired draws per trial, several separated by commas")
    ap.add_argument("--race", type=int, default=10, help="also race up to this many draws (0: not)")
    ap.add_argument("--better", type=float, default=1.3)
    ap.add_argument("--replicates", type=int, default=1000)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/optipose_verdict_cache"))
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument(
        "--scans",
        type=int,
        default=0,
        help="each draw's scans: this many of the protocol's, drawn per trial and draw (0: all)",
    )
    args = ap.parse_args()
    seeds = _seeds(args.seeds)
    t0 = time.perf_counter()
    results = hand_results(args.part, args.cell, args.objective, seeds, args.cache, args.jobs)
    twins = hand_results(args.part, args.cell, args.objective, seeds, args.cache, args.jobs, twin=True)
    print(
        f"bench_verdict_calibration: {args.part} hand layout, cell {args.cell}, objective {args.objective}, "
        f"{len(seeds)} seeds {seeds[0]}..{seeds[-1]} and their twins ({time.perf_counter() - t0:.0f} s to evaluate or read)"
        + (f"; each draw {args.scans} of the scans" if args.scans else "")
    )
    layout = results[seeds[0]].layout
    sources = {"same draws": "same", "own scans": "twin", "other cells": "other"}
    cases = [
        (f"{what}, {where}", how, better)
        for what, better in (("copy", 1.0), (f"{args.better:g}x", args.better))
        for where, how in sources.items()
    ]
    print(
        f"{'case':23} {'draws':>6} {'k':>2} {'BUY':>6} "
        + " ".join(f"{d:>4}" for d in tuple(Decision)[1:3])
        + " UNDEC  ratio"
    )
    spread = []
    for k in range(1, len(layout) + 1):
        choice = results[seeds[0]].table[k - 1]  # the hand's k-sensor choice, held fixed over draws
        errors = {s: scan_errors(results[s], choice) for s in seeds}
        twin = {s: scan_errors(twins[s], choice) for s in seeds}
        scores = np.array([np.quantile(e, (0.5, 0.75), axis=0).sum() for e in errors.values()])
        spread.append(f"k={k} {choice.name} {float(np.std(np.log(scores), ddof=1)):.2f}")
        for name, how, better in cases:
            for n_draws in [int(d) for d in args.draws.split(",")] + ([-args.race] if args.race else []):
                counts, ratios, used = dict.fromkeys(Decision, 0), [], []
                for trial in range(args.trials):
                    rng = np.random.default_rng([trial, abs(n_draws)])
                    hand = [int(s) for s in rng.permutation(seeds)]
                    other = _found_seeds(rng, hand, seeds) if how == "other" else hand
                    found = twin if how == "twin" else errors

                    def draw(i: int) -> PairedDraw:
                        f, h = found[other[i]] / better, errors[hand[i]]
                        if args.scans:  # a draw of a share of the scans, as a search's verdict draws after the first
                            rows = np.random.default_rng([trial, i, 0x5CA]).choice(len(h), args.scans, replace=False)
                            f, h = f[rows], h[rows]
                        return PairedDraw(hand[i], f, h)

                    rules = Rules(seed=trial, replicates=args.replicates)
                    names = dict(k=k, found_name=choice.name, baseline_name=choice.name)
                    if n_draws > 0:
                        verdict = compare_draws([draw(i) for i in range(n_draws)], rules, **names)
                    else:
                        verdict = race(draw, rules, min_draws=3, max_draws=-n_draws, **names)
                    counts[verdict.decision] += 1
                    ratios.append(verdict.score.estimate)
                    used.append(verdict.n_draws)
                label = str(n_draws) if n_draws > 0 else f"{np.mean(used):.1f}r"
                rest = " ".join(f"{counts[d]:>4}" for d in tuple(Decision)[1:])
                print(
                    f"{name:23} {label:>6} {k:>2} {counts[Decision.BUY]:>3}/{args.trials:<2} {rest:>4}  {np.median(ratios):.2f}",
                    flush=True,
                )
    print(f"the hand's score from seed to seed, sd of its log: {'; '.join(spread)}")
    print(
        f"({args.trials} trials per row, each a verdict on paired draws picked from the pool by the trial's seed; 'r': "
        f"racing up to {args.race} draws, their mean number; the found side is the hand layout's own per-scan errors, divided "
        f"by {args.better:g} in the '{args.better:g}x' rows; {time.perf_counter() - t0:.0f} s)"
    )


if __name__ == "__main__":
    main()
