"""The draws searches stored, raced again at another confidence or spending: would a laxer reading of "95 %", or
looks that spend more early, answer more or sooner?

Each BUY or KEEP test reads one side of a two-sided interval, so at the shipped 95 % it is one-sided at 97.5 %
(:mod:`optipose.verdict.confidence`). Read one-sided at 95 % (the two-sided 90 % interval), each look decides
sooner. Per search folder given, its verdict's draws (``verdict/draw-*``) are raced again in their order, with
the choices the search made, by :func:`optipose.verdict.racing.race_many` (first look at three, looks planned
for every stored draw, no clock) at each ``--confidence``: the decision per k and the draw it came at. With
``--rho``, at the shipped confidence and each spending ρ (:func:`optipose.verdict.racing.spent`), the looks planned
for the budget's draws (``--draws``) as the search plans them, up to the draws stored.

    .venv/bin/python benchmarks/bench_verdict_reread.py FOLDER [FOLDER ...] [--confidence 0.95,0.90]
    .venv/bin/python benchmarks/bench_verdict_reread.py FOLDER [FOLDER ...] --rho 3,2 [--draws 40]
    .venv/bin/python benchmarks/bench_verdict_reread.py FOLDER [FOLDER ...] --ranges cobot

``--ranges CELL``: per k, for each range of the cell the folders' draws were drawn in, the t statistic of the slope and
the share of the draws' log-ratio variance the ruling's fit (:mod:`optipose.verdict.ruling`) explains: why a decision
has, or has not, a range that rules it.
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path

from optipose.verdict.confidence import Decision, paired_draw
from optipose.verdict.rules import Rules
from optipose.evaluate.objective import objective_from_table
from optipose.verdict.racing import SPENDING, race_many
from optipose.io.load import load_result
from optipose.search.draws import sides


def stored_draws(folder: Path, result) -> list[dict]:
    """The folder's verdict draws in order, each k → its paired draw (the search's choices; ``result`` the
    folder's, read back)."""
    v, side = result.validation, sides(result.layouts, result.validation, result.baseline)
    draws = []
    for d in sorted((folder / "verdict").glob("draw-*"), key=lambda d: int(d.name[5:])):
        stored = {
            n: load_result(d / n) for n in {"hand", *(s.evaluation for s in side.values())} if (d / n).is_dir()
        }  # each once
        draws.append(
            {
                k: paired_draw(stored[s.evaluation], s.choice, stored["hand"], v.baseline[k])
                for k, s in side.items()
                if s.evaluation in stored
            }
        )
    return draws


def reraced(result, draws: list[dict], confidence: float, rho: float = SPENDING, plan: int = 0) -> dict:
    """The draws raced again at ``confidence`` and spending ``rho``, as the search raced them but without its clock;
    ``plan``: the looks planned for that many draws (0: the draws stored). A race that would need a draw beyond
    those stored is raced again with its looks planned for the draws stored."""
    statistic = objective_from_table(tomllib.loads(result.config.objective_file)).statistic

    def next_draws(i: int, keys) -> dict:
        return {k: p for k, p in draws[i].items() if keys is None or k in keys} if i < len(draws) else {}

    rules = Rules(confidence=confidence, seed=int(result.config.seed), statistic=statistic)
    try:
        return race_many(next_draws, rules, min_draws=3, max_draws=plan or len(draws), rho=rho)
    except ValueError:  # the stored draws ended before the race: its verdicts at the last of them
        return race_many(next_draws, rules, min_draws=3, max_draws=len(draws), rho=rho)


def ranges_spread(folder: Path, result, cell: str) -> None:
    """Per k, each range of ``cell``: the slope's t statistic and the share of the draws' log-ratio variance that its
    magnitude's place explains (:mod:`optipose.verdict.ruling`'s fit, on the folder's stored draws)."""
    import numpy as np

    from optipose.cell.config import load_cell
    from optipose.cell.ranges import draws as cell_draws
    from optipose.verdict.ruling import draw_ratio, line_fit, place

    ranges = load_cell(cell).ranges
    s = objective_from_table(tomllib.loads(result.config.objective_file)).statistic
    stored = stored_draws(folder, result)
    for k in sorted(stored[0]):
        pairs = [d[k] for d in stored if k in d]
        y = np.log([draw_ratio(p, s.weights, s.median_weight, s.p75_weight) for p in pairs])
        cells = []
        for key, low, high in ranges:
            u = np.array([place(cell_draws(ranges, p.seed)[key], low, high) for p in pairs])
            if len(y) < 3 or np.ptp(u) == 0:
                continue
            slope, _, share, se = line_fit(u, y)
            cells.append(f"{key.split('.')[-1]} t {slope / se:+.1f} {100 * share:.0f} %")
        print(f"{folder} k={k} ({len(y)} draws, sd of the log-ratio {y.std():.2f}): " + "; ".join(cells))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--ranges", default="", help="a cell of ranges: per k and range, the t and share of the ruling fit")
    ap.add_argument("--confidence", default="0.95,0.90")
    ap.add_argument("--rho", default="", help="spendings to compare at 95 %%, e.g. 3,2 (instead of --confidence)")
    ap.add_argument("--draws", type=int, default=40, help="with --rho: the budget's draws the looks are planned for")
    args = ap.parse_args()
    if args.ranges:
        for folder in args.folders:
            ranges_spread(folder, load_result(folder), args.ranges)
        return
    if args.rho:
        runs = [(0.95, float(r), args.draws) for r in args.rho.split(",")]
        heads = [f"ρ = {rho:g}" for _, rho, _ in runs]
    else:
        runs = [(float(c), SPENDING, 0) for c in args.confidence.split(",")]
        heads = [f"two-sided {100 * c:.0f} % (one-sided {100 * (1 + c) / 2:.1f} %)" for c, _, _ in runs]
    print("| folder | draws | " + " | ".join(heads) + " |")
    print("| --- | ---: |" + " --- |" * len(runs))
    answered = [0] * len(runs)
    for folder in args.folders:
        result = load_result(folder)
        draws, cells = stored_draws(folder, result), []
        for j, (c, rho, plan) in enumerate(runs):
            verdicts = reraced(result, draws, c, rho, plan)
            answered[j] += any(v.decision != Decision.UNDECIDED for v in verdicts.values())
            cells.append(
                ", ".join(
                    f"k={k} {v.decision} ({v.n_draws})" for k, v in sorted(verdicts.items(), key=lambda kv: str(kv[0]))
                )
            )
        print(f"| {folder} | {len(draws)} | " + " | ".join(cells) + " |")
    print("answered some k: " + ", ".join(f"{n} of {len(args.folders)} at {h}" for n, h in zip(answered, heads)))


if __name__ == "__main__":
    main()
