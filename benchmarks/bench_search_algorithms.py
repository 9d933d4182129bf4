"""NLopt global algorithms against random search on the surrogate, on the same evaluation budget (docs/method.md, "The search").

Problems: one sensor (6 variables) on part_a, part_b and part_c, and two sensors placed jointly (12
variables) on part_b, scored by :class:`optipose.search.problem.SurrogateProblem` with the ``paper`` objective and
the default :class:`~optipose.search.config.SearchConfig` constraints (penalty ``PENALTY + violation`` when
infeasible). Every run gets a fresh problem (empty pose cache), the same start point per seed (NLopt's x0,
and random search's first draw), ``nlopt.srand(seed)`` through ``optipose.search.driver.optimize``, and exactly
``--evals`` evaluations. Runs are interleaved (the algorithm order rotates per seed) so that background
load on a shared machine hits all algorithms alike.

    .venv/bin/python benchmarks/bench_search_algorithms.py [--evals 400] [--seeds 3]

Prints per problem the best feasible score (deg, lower is better) after 25, 50, 100, 200, 400 evaluations,
median over seeds, the share of infeasible evaluations, wall time per run and the number of distinct
sensor poses the run paid for; then a summary over problems. Writes
``benchmarks/results/search_algorithms.csv`` (one row per run) and ``search_algorithms.png``.
"""

from __future__ import annotations

import argparse
import csv
import os
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
PROBLEMS = [("part_a", 1), ("part_b", 1), ("part_c", 1), ("part_b", 2)]  # (part, sensors placed jointly)
# (label, NLopt algorithm or None for random search, local optimiser for MLSL)
ALGORITHMS = [
    ("random", None, None),
    ("GN_DIRECT_L", "GN_DIRECT_L", None),
    ("GN_CRS2_LM", "GN_CRS2_LM", None),
    ("GN_MLSL_LDS+BOBYQA", "GN_MLSL_LDS", "LN_BOBYQA"),
    ("GN_ISRES", "GN_ISRES", None),
    ("GN_ESCH", "GN_ESCH", None),
]
CHECKPOINTS = (25, 50, 100, 200, 400)


class _Budgeted:
    """Hands NLopt the problem but stops it (nlopt.ForcedStop, which ``optimize`` swallows) at the budget,
    so no algorithm gets more evaluations than another."""

    def __init__(self, problem, evals: int):
        self.problem, self.evals = problem, evals

    def __call__(self, u, grad=None):
        import nlopt

        if len(self.problem.history) >= self.evals:
            raise nlopt.ForcedStop("evaluation budget used up")
        return self.problem(u, grad)


def run_one(part, objective, surrogate, algorithm, local, k: int, seed: int, evals: int) -> dict:
    """One run from a fresh problem; returns its best-so-far curve (evals,) and counters."""
    from optipose.search.config import SearchConfig
    from optipose.search.driver import optimize
    from optipose.search.problem import SurrogateProblem
    from optipose.search.study import SurrogateStudy

    problem = SurrogateStudy(SurrogateProblem(part, objective, SearchConfig(), surrogate=surrogate))
    rng = np.random.default_rng(seed)
    x0 = rng.random(6 * k)  # the same start for every algorithm of this seed
    t0 = time.perf_counter()
    if algorithm is None:
        problem(x0)
        while len(problem.history) < evals:
            problem(rng.random(6 * k))
    else:
        with problem.stage_named(algorithm or "random"):
            optimize(_Budgeted(problem, evals), algorithm, x0, evals, seed, local)
    wall = time.perf_counter() - t0
    rows = problem.history[:evals]
    values = np.array([r.value if r.feasible else np.inf for r in rows])
    curve = np.minimum.accumulate(values) if len(values) else np.full(evals, np.inf)
    curve = np.concatenate([curve, np.full(evals - len(curve), curve[-1] if len(curve) else np.inf)])
    return {
        "curve": curve,
        "evals_done": len(rows),
        "infeasible": float(np.mean([not r.feasible for r in rows])) if rows else np.nan,
        "first_feasible": next((i + 1 for i, r in enumerate(rows) if r.feasible), None),
        "wall_s": wall,
        "new_poses": len(problem.problem.cache),
    }


def run_problem(part_name: str, k: int, objective, evals: int, seeds: int) -> dict[str, list[dict]]:
    """All algorithms × seeds on one problem, interleaved; label -> runs in seed order."""
    from optipose.model.part import load_part
    from optipose.search.config import SearchConfig
    from optipose.search.problem import SurrogateProblem
    from optipose.search.surrogate import Surrogate

    part = load_part(part_name)
    surrogate = Surrogate(part, voxel=objective.registration.voxel_size)
    warm = SurrogateProblem(part, objective, SearchConfig(), surrogate=surrogate)
    for u in np.random.default_rng(12345).random((4, 6)):  # JIT and ray-caster set-up, outside the timing
        warm.score(u)
    runs: dict[str, list[dict]] = {label: [] for label, _, _ in ALGORITHMS}
    for seed in range(seeds):
        order = ALGORITHMS[seed % len(ALGORITHMS) :] + ALGORITHMS[: seed % len(ALGORITHMS)]
        for label, algorithm, local in order:
            runs[label].append(run_one(part, objective, surrogate, algorithm, local, k, seed, evals))
    return runs


def _fmt(x: float) -> str:
    return "—" if not np.isfinite(x) else f"{x:.4g}"


def table(title: str, runs: dict[str, list[dict]], checkpoints) -> list[str]:
    """The per-problem table: median over seeds of the best feasible score at each checkpoint."""
    head = f"{'algorithm':<20}" + "".join(f"{'@' + str(c):>11}" for c in checkpoints)
    head += f"{'infeas%':>9}{'wall s':>8}{'poses':>7}{'1st ok':>7}"
    lines = [title, head, "-" * len(head)]
    for label, rs in runs.items():
        curves = np.array([r["curve"] for r in rs])
        cells = "".join(f"{_fmt(np.median(curves[:, c - 1])):>11}" for c in checkpoints)
        first = [r["first_feasible"] or np.inf for r in rs]
        lines.append(
            f"{label:<20}{cells}{100 * np.median([r['infeasible'] for r in rs]):>9.1f}"
            f"{np.median([r['wall_s'] for r in rs]):>8.2f}{np.median([r['new_poses'] for r in rs]):>7.0f}"
            f"{(f'{np.median(first):.0f}' if np.isfinite(np.median(first)) else '—'):>7}"
        )
    return lines


def summary(all_runs: dict[str, dict[str, list[dict]]], evals: int) -> list[str]:
    """Over problems: the median final best relative to the best any run found on that problem, and the
    mean rank (1 = best median) after 100 evaluations (the ``quick`` budget's scale) and at the end."""
    labels = [label for label, _, _ in ALGORITHMS]
    early = min(100, evals)
    ratios = {label: [] for label in labels}
    ranks = {label: ([], []) for label in labels}
    for runs in all_runs.values():
        best_known = min(r["curve"][-1] for rs in runs.values() for r in rs)
        for j, at in enumerate((early, evals)):
            medians = {label: float(np.median([r["curve"][at - 1] for r in runs[label]])) for label in labels}
            order = sorted(labels, key=lambda lab: medians[lab])
            for label in labels:
                ranks[label][j].append(order.index(label) + 1)
        for label in labels:
            ratios[label].append(float(np.median([r["curve"][-1] for r in runs[label]])) / best_known)
    width = max(len(p) for p in all_runs) + 2
    head = (
        f"{'algorithm':<20}"
        + "".join(f"{p:>{width}}" for p in all_runs)
        + f"{'rank@' + str(early):>10}{'rank@' + str(evals):>10}"
    )
    lines = [
        f"Summary: median best @{evals} / best of all runs on that problem (1.00 = best found); mean rank over problems",
        head,
        "-" * len(head),
    ]
    for label in labels:
        cells = "".join(f"{x:>{width}.2f}" for x in ratios[label])
        lines.append(f"{label:<20}{cells}{np.mean(ranks[label][0]):>10.2f}{np.mean(ranks[label][1]):>10.2f}")
    return lines


def write_csv(path: Path, all_runs, checkpoints) -> None:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            ["problem", "algorithm", "seed", "evals_done"]
            + [f"best_at_{c}" for c in checkpoints]
            + ["infeasible_frac", "first_feasible_eval", "wall_s", "new_poses"]
        )
        for problem, runs in all_runs.items():
            for label, rs in runs.items():
                for seed, r in enumerate(rs):
                    best = [f"{r['curve'][c - 1]:.6g}" for c in checkpoints]
                    w.writerow(
                        [
                            problem,
                            label,
                            seed,
                            r["evals_done"],
                            *best,
                            f"{r['infeasible']:.4f}",
                            r["first_feasible"] or "",
                            f"{r['wall_s']:.3f}",
                            r["new_poses"],
                        ]
                    )


def plot(path: Path, all_runs, evals: int, seeds: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5), constrained_layout=True)
    colours = dict(
        zip([a[0] for a in ALGORITHMS], ["black", "tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"])
    )
    x = np.arange(1, evals + 1)
    for ax, (problem, runs) in zip(axes.flat, all_runs.items()):
        for label, rs in runs.items():
            curves = np.array([r["curve"] for r in rs])
            style = "--" if label == "random" else "-"
            name = f"{label} (deterministic)" if label == "GN_DIRECT_L" else label
            ax.plot(x, np.median(curves, axis=0), style, color=colours[label], lw=1.8, label=name)
            lo, hi = curves.min(axis=0), curves.max(axis=0)
            ax.fill_between(x, lo, np.where(np.isfinite(hi), hi, np.nan), color=colours[label], alpha=0.12, lw=0)
        ax.set_yscale("log")
        # the first few evaluations score up to ~10 deg; cut there so the differences that matter show
        medians = np.array([np.median([r["curve"] for r in rs], axis=0) for rs in runs.values()])
        finite = medians[np.isfinite(medians)]
        top = np.nanmax(np.where(np.isfinite(medians[:, min(19, evals - 1)]), medians[:, min(19, evals - 1)], np.nan))
        ax.set_ylim(0.9 * finite.min(), 1.5 * top)
        ax.set_title(problem)
        ax.set_xlabel("evaluations")
        ax.set_ylabel("best feasible score so far (deg, lower is better)")
        ax.grid(True, which="both", alpha=0.3)
    axes.flat[0].legend(fontsize=9)
    fig.suptitle(f"Surrogate search: best-so-far vs evaluations, median (line) and min–max (band) over {seeds} seeds")
    fig.savefig(path, dpi=110)


def _revision() -> str:
    """The commit the surrogate comes from (its scale has changed between commits), '+dirty' if edited."""
    import subprocess

    root = Path(__file__).resolve().parents[1]
    git = lambda *a: subprocess.run(["git", *a], cwd=root, capture_output=True, text=True).stdout.strip()  # noqa: E731
    head = git("rev-parse", "--short", "HEAD") or "unknown"
    return head + ("+dirty" if git("status", "--porcelain", "--", "optipose") else "")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--evals", type=int, default=400, help="evaluations per run")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per algorithm and problem")
    args = ap.parse_args()

    from optipose.evaluate.objective import load_objective

    objective = load_objective("paper").in_cell("ideal")
    checkpoints = tuple(c for c in CHECKPOINTS if c < args.evals) + (args.evals,)
    print(
        f"bench_search_algorithms: --evals {args.evals} --seeds {args.seeds}, objective 'paper', "
        f"optipose at {_revision()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"
    )
    t0 = time.perf_counter()
    all_runs = {}
    for part_name, k in PROBLEMS:
        name = f"{part_name} k={k} ({6 * k} var)"
        all_runs[name] = run_problem(part_name, k, objective, args.evals, args.seeds)
        print()
        print(
            "\n".join(
                table(
                    f"{name}: best feasible score (deg) after n evaluations, median of {args.seeds} seeds",
                    all_runs[name],
                    checkpoints,
                )
            )
        )
    print()
    print("\n".join(summary(all_runs, args.evals)))
    print(f"\ntotal {time.perf_counter() - t0:.0f} s, load {os.getloadavg()[0]:.1f}")
    RESULTS.mkdir(exist_ok=True)
    write_csv(RESULTS / "search_algorithms.csv", all_runs, checkpoints)
    plot(RESULTS / "search_algorithms.png", all_runs, args.evals, args.seeds)
    print(f"wrote {RESULTS / 'search_algorithms.csv'} and {RESULTS / 'search_algorithms.png'}")


if __name__ == "__main__":
    main()
