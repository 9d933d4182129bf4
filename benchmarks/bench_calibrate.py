"""Calibration against the paper (docs/calibration.md): calibrated on part A's real figures alone, how many of parts B's
and C's 24 real figures the calibrated cell's predicted intervals cover, and how wide they are.

    .venv/bin/python benchmarks/bench_calibrate.py paper [--cell cobot] [--icp 4] [--seeds 10] [--jobs 2] [--out DIR]
    .venv/bin/python benchmarks/bench_calibrate.py roundtrip [--part part_a] [--cell cobot] [--hidden 8] [--icp 4] [--jobs 2]
    .venv/bin/python benchmarks/bench_calibrate.py medians [--part part_a] [--cell cobot] [--hidden 8] [--instances 4] [--jobs 2]
    .venv/bin/python benchmarks/bench_calibrate.py found [--part part_a] [--cell cobot] [--hidden 8] [--instances 5]
        [--found results/reference/PART/layouts] [--k 1 2 3] [--prior-too] [--jobs 2]

Calibrates ``--cell`` on part A's rows of docs/figures/paper_table1.csv (``optipose calibrate``'s library call, timed),
writes the cell to DIR/part_a-calibrated.toml, then predicts B's and C's figures of the paper's subsets, each as the
central 90 % across the calibrated cell's instances (5 % and 95 %):

* ``surrogate``: the emulator of B's and C's hand layouts at 2000 instances of the calibrated cell (its ranges drawn as
  an evaluation draws them, per seed), without a correction to ICP (A's correction is per subset of A's layout);
* ``predictive``: the same times A's mean ICP / emulator ratio over its figures, and times exp(ε) with ε the noise the
  calibration gave A's figures (the correction's pooled spread: one ICP instance about the emulator; the finite
  scans'): the posterior predictive of a figure of one real cell;
* ``ICP`` (``--seeds N`` > 0): the hand layouts evaluated by ICP in the calibrated cell at seeds 0 … N − 1 (one
  instance each), each figure's 5 % and 95 % over them;

and the same intervals under the uncalibrated prior for comparison. Covered: the real figure within [5 %, 95 %];
width: 95 % / 5 %. Tables to stdout and DIR/paper.txt.

``roundtrip``: ``--hidden`` cells drawn across the prior's ranges (every range at its low end, at its high end, and
instances between), each the hand layout's Table 1 by ICP (a seed of its own), calibrated on it with one emulator and
one set of ICP runs for all; each hidden magnitude against the calibrated file's range, and the hand layout's medians
by ICP in the calibrated cell (a seed the fit never saw) against the hidden cell's. To DIR/roundtrip-PART.txt.

``found``: the same hidden cells, each with the cell ``roundtrip`` calibrated for it (DIR/roundtrip-<i>.toml, read, not
remade); the search's found layouts (``--found``: found_k<k>.toml, the shipped reference search's by default) evaluated
by ICP at ``--instances`` N seeds of the calibrated cell (400 + 10 i + j) and at one of the hidden cell (500 + i). Per
axis a layout's error is the median of the subset its Table 1 chooses at its full k. Predicted per (k, axis): the
the verdict's interval of one cell from the N values (:func:`optipose.verdict.confidence.one_cell`: the log-normal
90 % prediction interval of one new instance, mean ± t(0.95, N − 1) · sd · √(1 + 1/N) of the logs), and their plain min-max; covered: the hidden cell's error inside. An axis no subset measures (unobservable,
or its registrations failed) in any of those evaluations gets no interval and is counted apart. ``--prior-too``: the
same intervals from N instances of the uncalibrated ``--cell`` (seeds 600 + j, one set for all hidden cells). To
DIR/found-PART.txt.

``medians``: the hand layout's 21 medians (every subset and axis) as each calibrated cell predicts them, the geometric
mean over ``--instances`` N ICP instances (seeds 700 + 10 i + j), against the hidden cell's over N instances (800 +
10 i + j), and, for what no calibration can beat with N instances, the hidden cell's over N others (900 + 10 i + j):
how many within 1.5×. To DIR/medians-PART.txt.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from bench_cell import PAPER

FIGURES = Path(__file__).resolve().parents[1] / "docs" / "figures" / "paper_table1.csv"
AXES = ("roll", "pitch", "yaw")


class _Lines(list):
    """A mode's printed lines, each printed as it comes and kept for its result file."""

    def __call__(self, text: str = "") -> None:
        print(text, flush=True)
        self.append(text)


def _rows(part: str) -> list[tuple[str, str, int, float]]:
    """(subset, axis, stat index, real figure in degrees) of a part's paper rows."""
    out = []
    for (p, _, axis, subset), (_, _, median, p75) in PAPER.items():
        if p == part:
            out += [(subset, axis, 0, median), (subset, axis, 1, p75)]
    return out


def _instances(cell, emulator, n: int) -> np.ndarray:
    from optipose.calibrate.emulator import field_value

    return np.array([[field_value(cell.instance(s), k) for k in emulator.keys] for s in range(n)])


def surrogate_intervals(
    part_name: str, cell, objective, n: int = 2000, shift: float = 0.0, spread: float = 0.0
) -> np.ndarray:
    """(figures, 2) degrees: 5 % and 95 % of each of the part's paper figures over ``n`` instances of ``cell``, each
    times exp(shift + ε), ε ~ N(0, spread² + the figure's finite-scan variance) when ``spread`` > 0 (the predictive)."""
    from optipose.calibrate.emulator import Emulator
    from optipose.calibrate.summaries import PAPER_SCANS, Figure, Summaries
    from optipose.model.part import load_part

    part = load_part(part_name)
    emulator = Emulator(part, part.layouts["hand"], objective.in_cell(cell))
    stats = emulator.stats(_instances(cell, emulator, n))
    rows = _rows(part_name)
    logs = np.column_stack([np.log(stats[sub][:, s, AXES.index(ax)]) for sub, ax, s, _ in rows]) + shift
    if spread > 0:
        figures = [Figure(sub, ax, ("median", "p75")[s], 1.0, PAPER_SCANS) for sub, ax, s, _ in rows]
        cov = Summaries(part_name, tuple(figures), "").noise() + np.eye(len(rows)) * spread**2
        logs = logs + np.random.default_rng(0).multivariate_normal(np.zeros(len(rows)), cov, size=n)
    return np.rad2deg(np.exp(np.percentile(logs, [5, 95], axis=0).T))


def icp_intervals(part_name: str, cell, objective, seeds: int, jobs: int) -> np.ndarray:
    from optipose.evaluate.evaluator import Evaluator
    from optipose.model.part import load_part

    part = load_part(part_name)
    values = []
    for seed in range(seeds):
        with Evaluator(part, objective.in_cell(cell), seed=seed, jobs=jobs, quiet=True) as evaluator:
            stats = evaluator(part.layouts["hand"]).stats
        row = []
        for sub, ax, s, _ in _rows(part_name):
            hit = stats[(stats["subset"] == sub) & (stats["axis"] == ax)]
            row.append(np.rad2deg(float(hit[["median", "p75"][s]].iloc[0])))
        values.append(row)
        print(f"  ICP {part_name} seed {seed} done", flush=True)
    return np.percentile(np.array(values), [5, 95], axis=0).T


def _require(paths: list[Path], hint: str) -> None:
    """Exit 2 with one line naming the files of ``paths`` that are missing (``hint``: how to make them)."""
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        print(f"missing ({hint}): {', '.join(missing)}", file=sys.stderr)
        sys.exit(2)


def hidden_cells(prior, n: int) -> list:
    """The round trip's ``n`` hidden cells of ``prior``, (name, cell): every range at its low end, at its high end,
    then instances 1000, 1001, ..."""
    hidden = [("low", prior.at("low")), ("high", prior.at("high"))]
    hidden += [(f"instance {s}", prior.instance(s)) for s in range(1000, 1000 + n - 2)]
    return hidden[:n]


def score(intervals: np.ndarray, real: np.ndarray) -> tuple[int, float, float]:
    """Covered figures, the median and the largest width (high / low)."""
    covered = int(np.sum((real >= intervals[:, 0]) & (real <= intervals[:, 1])))
    width = intervals[:, 1] / intervals[:, 0]
    return covered, float(np.median(width)), float(width.max())


def paper(args) -> None:
    from optipose.calibrate.calibration import calibrate
    from optipose.calibrate.cellfile import write_cell
    from optipose.calibrate.summaries import read_figures
    from optipose.cell.config import load_cell
    from optipose.evaluate.objective import load_objective
    from optipose.model.part import load_part

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    say = _Lines()

    objective = load_objective(args.objective).in_cell(args.cell)
    part = load_part("part_a")
    start = time.perf_counter()
    result = calibrate(
        part, part.layouts["hand"], objective, read_figures(FIGURES, "part_a"), icp=args.icp, jobs=args.jobs, seed=0
    )
    path = write_cell(result, out / "part_a-calibrated.toml")
    say(f"calibrated '{args.cell}' on part A's 10 real figures: {time.perf_counter() - start:.0f} s wall")
    say(
        f"  of it ICP ({args.icp} instances): {result.correction.seconds:.0f} s; effective samples {result.posterior.ess:.0f}"
    )
    say(f"  out of the ranges: {'; '.join(result.out) or 'none'}")
    for key in result.keys:
        say(f"  {key}: {result.posterior.interval(key)}")
    say(f"  A's ICP / emulator log-ratio per figure: {np.round(result.correction.log_ratio, 2).tolist()}")
    shift = float(result.correction.log_ratio.mean())
    spread = float(np.sqrt(np.mean(np.diag(result.correction.cov))))
    say(f"  A's mean log-ratio {shift:.2f} (x{np.exp(shift):.2f}), the correction's spread {spread:.2f} (log)")
    calibrated, prior = load_cell(path), load_cell(args.cell)
    say()
    say(
        "part  subset axis  stat    real    "
        + "  ".join(f"{n:>17s}" for n in ("prior surrogate", "surrogate", "predictive", "ICP"))
    )
    totals = {}
    for name in ("part_b", "part_c"):
        rows = _rows(name)
        real = np.array([r[3] for r in rows])
        found = {
            "prior surrogate": surrogate_intervals(name, prior, objective),
            "surrogate": surrogate_intervals(name, calibrated, objective),
        }
        found["predictive"] = surrogate_intervals(name, calibrated, objective, shift=shift, spread=spread)
        if args.seeds:
            found["ICP"] = icp_intervals(name, calibrated, objective, args.seeds, args.jobs)
        for i, (sub, ax, s, value) in enumerate(rows):
            cells = [
                f"{found[k][i, 0]:7.4f}-{found[k][i, 1]:7.4f}{'*' if found[k][i, 0] <= value <= found[k][i, 1] else ' '}"
                for k in found
            ]
            say(f"{name[-1].upper():5s} {sub:6s} {ax:5s} {['median', 'p75'][s]:6s} {value:7.3f} " + " ".join(cells))
        for k, v in found.items():
            totals.setdefault(k, []).append((v, real))
    say()
    for k, parts in totals.items():
        intervals = np.vstack([v for v, _ in parts])
        real = np.concatenate([r for _, r in parts])
        covered, median, most = score(intervals, real)
        say(f"{k:16s}: covers {covered} of {len(real)}; width median {median:.2f}x, largest {most:.2f}x")
    (out / "paper.txt").write_text("\n".join(say) + "\n")


def roundtrip(args) -> None:
    """Hidden cells across the prior's ranges (both ends, and instances between), each the hand layout's figures by
    ICP; calibrated on them (one emulator and one set of ICP runs for all); each hidden magnitude against its
    posterior's 5-95 %, and the calibrated cell's ICP medians (a seed the fit never saw) against the hidden cell's."""
    from optipose.calibrate.calibration import calibrate, icp_runs
    from optipose.calibrate.cellfile import narrowed, write_cell
    from optipose.calibrate.emulator import Emulator, field_value
    from optipose.calibrate.summaries import from_evaluation
    from optipose.cell.config import load_cell
    from optipose.evaluate.evaluator import Evaluator
    from optipose.evaluate.objective import load_objective
    from optipose.model.part import load_part

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    say = _Lines()

    part, prior = load_part(args.part), load_cell(args.cell)
    layout, objective = part.layouts["hand"], load_objective(args.objective).in_cell(prior)

    def table1(cell, seed: int):
        with Evaluator(part, objective.in_cell(cell), seed=seed, jobs=args.jobs, quiet=True) as evaluator:
            return evaluator(layout)

    start = time.perf_counter()
    emulator = Emulator(part, layout, objective)
    runs = icp_runs(part, layout, objective, emulator, args.icp, 0, args.jobs)
    say(f"{args.part} in '{args.cell}': emulator and {args.icp} ICP runs {time.perf_counter() - start:.0f} s")
    hidden = hidden_cells(prior, args.hidden)
    inside, total, close, medians, same, t1, t1_all = 0, 0, 0, 0, 0, 0, 0
    for i, (name, cell) in enumerate(hidden):
        measured = table1(cell, 100 + i)
        result = calibrate(
            part, layout, objective, from_evaluation(measured, f"scans {name}"), emulator=emulator, runs=runs, seed=i
        )
        path = write_cell(result, out / f"roundtrip-{i}.toml")
        keys = []
        for key in result.keys:
            lo, hi, _ = narrowed(result, key)  # the cell file's range
            value = field_value(cell, key)
            hit = lo * 0.999 <= value <= hi * 1.001
            inside, total = inside + hit, total + 1
            keys.append(f"{key.split('.')[-1]} {'in' if hit else 'OUT'}")
        check = table1(load_cell(path), 200 + i).stats
        again = table1(cell, 300 + i).stats  # the hidden cell itself, another instance: what no calibration beats
        ratios, floor = _ratios(measured.stats, check), _ratios(measured.stats, again)
        chosen = [(a.name, axis) for a, axis in zip(measured.table[-1].axes, AXES) if a.name]
        table = _ratios(measured.stats, check, chosen)
        close, medians = close + int(np.sum(ratios <= 1.5)), medians + len(ratios)
        same = same + int(np.sum(floor <= 1.5))
        t1, t1_all = t1 + int(np.sum(table <= 1.5)), t1_all + len(table)
        say(
            f"{name:13s} out: {len(result.out)}; medians within 1.5x: calibrated {int(np.sum(ratios <= 1.5))} of "
            f"{len(ratios)} (worst {ratios.max():.2f}x), the hidden cell again {int(np.sum(floor <= 1.5))}; Table 1 "
            f"k=3 {int(np.sum(table <= 1.5))} of {len(table)}; " + ", ".join(keys)
        )
    say(f"hidden magnitudes within the posterior's 5-95 %: {inside} of {total}")
    say(f"calibrated cell's ICP medians within 1.5x of the hidden cell's: {close} of {medians}")
    say(f"... Table 1's k = 3 subsets only: {t1} of {t1_all}")
    say(f"the hidden cell's own ICP medians at another seed within 1.5x: {same} of {medians}")
    say(f"wall {time.perf_counter() - start:.0f} s")
    (out / f"roundtrip-{args.part}.txt").write_text("\n".join(say) + "\n")


def found(args) -> None:
    """The found layouts' predicted intervals from the calibrated cell of each hidden cell against their errors in the
    hidden cell (``roundtrip``'s hidden cells and calibrated files); optionally the prior's intervals beside them."""
    from optipose.verdict.confidence import one_cell

    from optipose.cell.config import load_cell
    from optipose.evaluate.evaluator import Evaluator
    from optipose.evaluate.objective import load_objective
    from optipose.model.layout import load_layout
    from optipose.model.part import load_part

    out = Path(args.out)
    folder = Path(args.found or f"results/reference/{args.part}/layouts")
    _require(
        [out / f"roundtrip-{i}.toml" for i in range(args.hidden)] + [folder / f"found_k{k}.toml" for k in args.k],
        "run roundtrip first, or give --found",
    )
    say = _Lines()

    part, prior = load_part(args.part), load_cell(args.cell)
    objective = load_objective(args.objective).in_cell(prior)
    layouts = {k: load_layout(folder / f"found_k{k}.toml") for k in args.k}
    hidden = hidden_cells(prior, args.hidden)
    times = []

    def errors(cell, seed: int) -> dict[int, np.ndarray]:
        """Per found layout k, (3,) degrees: each axis's median in the subset Table 1 chooses at k (NaN: none)."""
        row = {}
        with Evaluator(part, objective.in_cell(cell), seed=seed, jobs=args.jobs, quiet=True) as evaluator:
            for k, layout in layouts.items():
                start = time.perf_counter()
                result = evaluator(layout)
                times.append((len(layout), time.perf_counter() - start))
                axes = result.table[-1].axes
                row[k] = np.array([np.rad2deg(a.median) if a.observable else np.nan for a in axes])
                blind = [f"{a.axis} {a.label}" for a in axes if not a.observable]
                if blind:
                    say(f"  seed {seed} k={k}: not measured: {', '.join(blind)}")
        return row

    def intervals(rows: list[dict]) -> dict[int, np.ndarray]:
        """Per k, (3 axes, 4): the log-normal prediction interval's ends, then the min and the max (NaN: an axis
        some evaluation did not measure)."""
        out = {}
        for k in layouts:
            values = np.array([r[k] for r in rows])  # (n, 3)
            cells = [one_cell(values[:, a]) for a in range(len(AXES))]  # the verdict's own interval of one cell
            out[k] = np.column_stack([[c.low for c in cells], [c.high for c in cells], values.min(0), values.max(0)])
        return out

    start = time.perf_counter()
    say(
        f"{args.part} in '{args.cell}': found layouts {', '.join(f'k={k}' for k in layouts)} from {folder}; "
        f"{args.instances} instances per calibrated cell"
    )
    kinds = ["log-normal", "min-max"] + ["prior log-normal", "prior min-max"] * args.prior_too
    from_prior = intervals([errors(prior, 600 + j) for j in range(args.instances)]) if args.prior_too else {}
    tally = {kind: [] for kind in kinds}  # (covered, width) per measured (cell, k, axis) and kind
    unmeasured = []
    for i, (name, cell) in enumerate(hidden):
        calibrated = load_cell(out / f"roundtrip-{i}.toml")
        predicted = intervals([errors(calibrated, 400 + 10 * i + j) for j in range(args.instances)])
        truth = errors(cell, 500 + i)
        for k in layouts:
            by_kind = np.hstack([predicted[k]] + ([from_prior[k]] if from_prior else []))  # (3, 2 per kind)
            words = []
            for a, axis in enumerate(AXES):
                value, ends = truth[k][a], by_kind[a].reshape(-1, 2)
                if not np.isfinite(value) or not np.all(np.isfinite(ends)):
                    unmeasured.append(f"{name} k={k} {axis}")
                    words.append(f"{axis} not measured (hidden {value:.4f}; predicted {_span(ends[0])})")
                    continue
                hits = (ends[:, 0] <= value) & (value <= ends[:, 1])
                for kind, (lo, hi), hit in zip(kinds, ends, hits):
                    tally[kind].append((hit, hi / lo))
                words.append(
                    f"{axis} {value:.4f} in " + " ".join(f"{_span(e)}{'*' if h else ' '}" for e, h in zip(ends, hits))
                )
            say(f"{name:13s} k={k}: " + "; ".join(words))
    say()
    say(f"intervals per axis: {' / '.join(kinds)} ('*': the hidden cell's median inside); degrees")
    total = len(hidden) * len(layouts) * len(AXES)
    for kind, rows in tally.items():
        hits, widths = np.array([h for h, _ in rows], bool), np.array([w for _, w in rows])
        say(
            f"{kind:16s}: covers {int(hits.sum())} of {total} (cell, k, axis)"
            + (f" ({hits.mean():.0%} of the {len(rows)} measured)" if len(rows) else "")
            + (f"; width median {np.median(widths):.2f}x, largest {widths.max():.2f}x" if len(rows) else "")
        )
    say(
        f"not measured (no interval or no hidden value): {len(unmeasured)}{': ' if unmeasured else ''}{', '.join(unmeasured)}"
    )
    seconds = np.array([s for _, s in times])
    for n in sorted({n for n, _ in times}):
        mine = np.array([s for m, s in times if m == n])
        say(f"ICP evaluation of {n} sensor(s): {mine.mean():.1f} s mean ({len(mine)} evaluations)")
    say(f"{len(seconds)} ICP evaluations {seconds.sum():.0f} s; wall {time.perf_counter() - start:.0f} s")
    (out / f"found-{args.part}.txt").write_text("\n".join(say) + "\n")


def medians(args) -> None:
    """The hand layout's medians per (subset, axis) as a cell predicts them, not one instance: the geometric mean over
    ``--instances`` N ICP instances of each calibrated cell (DIR/roundtrip-<i>.toml) against the same over N instances
    of its hidden cell, and, for the floor, over N more instances of the hidden cell itself."""
    from optipose.cell.config import load_cell
    from optipose.evaluate.evaluator import Evaluator
    from optipose.evaluate.objective import load_objective
    from optipose.model.part import load_part

    out = Path(args.out)
    _require([out / f"roundtrip-{i}.toml" for i in range(args.hidden)], "run roundtrip first")
    say = _Lines()
    part, prior = load_part(args.part), load_cell(args.cell)
    layout, objective = part.layouts["hand"], load_objective(args.objective).in_cell(prior)
    hidden = hidden_cells(prior, args.hidden)

    def mean_medians(cell, seeds) -> dict:
        """(subset, axis) → the geometric mean of its median (degrees) over the seeds' instances."""
        logs: dict = {}
        for seed in seeds:
            with Evaluator(part, objective.in_cell(cell), seed=seed, jobs=args.jobs, quiet=True) as evaluator:
                stats = evaluator(layout).stats
            for row in stats.itertuples(index=False):
                logs.setdefault((row.subset, row.axis), []).append(np.log(np.rad2deg(row.median)))
        return {key: float(np.exp(np.mean(v))) for key, v in logs.items()}

    def within(a: dict, b: dict) -> np.ndarray:
        return np.array([max(a[key] / b[key], b[key] / a[key]) for key in a])

    start, n = time.perf_counter(), args.instances
    say(f"{args.part}'s hand layout in '{args.cell}': geometric means over {n} ICP instances per cell")
    close, floor, total = 0, 0, 0
    for i, (name, cell) in enumerate(hidden):
        predicted = mean_medians(load_cell(out / f"roundtrip-{i}.toml"), [700 + 10 * i + j for j in range(n)])
        truth = mean_medians(cell, [800 + 10 * i + j for j in range(n)])
        again = mean_medians(cell, [900 + 10 * i + j for j in range(n)])
        ratios, own = within(predicted, truth), within(again, truth)
        close, floor, total = close + int(np.sum(ratios <= 1.5)), floor + int(np.sum(own <= 1.5)), total + len(ratios)
        worst = max(predicted, key=lambda key: max(predicted[key] / truth[key], truth[key] / predicted[key]))
        say(
            f"{name:13s} calibrated within 1.5x: {int(np.sum(ratios <= 1.5))} of {len(ratios)} (median ratio "
            f"{np.median(ratios):.2f}x, worst {ratios.max():.2f}x: {worst[0]} {worst[1]} {predicted[worst]:.4f} vs "
            f"{truth[worst]:.4f}); the hidden cell's other {n} instances {int(np.sum(own <= 1.5))}"
        )
    say(f"the calibrated cell's mean medians within 1.5x of the hidden cell's: {close} of {total}")
    say(f"the hidden cell's own other {n} instances within 1.5x: {floor} of {total}")
    say(f"wall {time.perf_counter() - start:.0f} s")
    (out / f"medians-{args.part}.txt").write_text("\n".join(say) + "\n")


def _span(ends) -> str:
    return f"{ends[0]:.4f}-{ends[1]:.4f}"


def _ratios(stats, other, only=None) -> np.ndarray:
    """max(a / b, b / a) of two evaluations' medians per (subset, axis) (``only``: those (subset, axis) pairs)."""
    out = []
    for row in stats.itertuples(index=False):
        if only is not None and (row.subset, row.axis) not in only:
            continue
        b = other[(other["subset"] == row.subset) & (other["axis"] == row.axis)]["median"].iloc[0]
        out.append(max(b / row.median, row.median / b))
    return np.array(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    both = argparse.ArgumentParser(add_help=False)  # the options both modes take
    both.add_argument("--cell", default="cobot")
    both.add_argument("--objective", default="paper")
    both.add_argument("--jobs", type=int, default=2)
    both.add_argument("--out", default="benchmarks/results/calibrate")
    p = sub.add_parser("paper", parents=[both])
    p.add_argument("--icp", type=int, default=4)
    p.add_argument("--seeds", type=int, default=0)
    r = sub.add_parser("roundtrip", parents=[both])
    r.add_argument("--icp", type=int, default=4)
    r.add_argument("--part", default="part_a")
    r.add_argument("--hidden", type=int, default=8)
    f = sub.add_parser("found", parents=[both])
    f.add_argument("--part", default="part_a")
    f.add_argument("--hidden", type=int, default=8)
    f.add_argument("--instances", type=int, default=5, help="seeds of the calibrated cell per hidden cell (2-10)")
    f.add_argument("--found", default=None, help="folder of found_k<k>.toml (default results/reference/PART/layouts)")
    f.add_argument("--k", type=int, nargs="+", default=[1, 2, 3], help="the found layouts to evaluate")
    f.add_argument("--prior-too", action="store_true", help="also the uncalibrated --cell's intervals")
    m = sub.add_parser("medians", parents=[both])
    m.add_argument("--part", default="part_a")
    m.add_argument("--hidden", type=int, default=8)
    m.add_argument("--instances", type=int, default=4, help="ICP instances per cell (2-10)")
    args = parser.parse_args()
    if args.what in ("found", "medians") and not 1 <= args.hidden <= 9:
        parser.error("--hidden: 1 to 9 (each hidden cell's seeds stay apart from the next block's)")
    if args.what == "medians" and not 2 <= args.instances <= 10:
        parser.error("--instances: 2 to 10 (seeds 700/800/900 + 10 i + j stay apart)")
    if args.what == "found" and not 2 <= args.instances <= 10:
        parser.error("--instances: 2 to 10 (a prediction interval needs two; seeds 400 + 10 i + j stay apart)")
    {"paper": paper, "roundtrip": roundtrip, "found": found, "medians": medians}[args.what](args)


if __name__ == "__main__":
    main()
