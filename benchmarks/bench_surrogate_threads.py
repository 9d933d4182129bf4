"""The surrogate's time per sensor pose with one BLAS thread and with the library's default, while other processes
keep every core busy — as the hand layout's validation does beside a search's surrogate (optipose/search/pipeline.py
caps this process's BLAS at one thread for that reason).

    .venv/bin/python benchmarks/bench_surrogate_threads.py [--part part_b] [--cell ur10e] [--poses 30] [--busy 2] [--rounds 3]

Each round scores ``--poses`` new sensor poses (seeded draws near the hand layout's first sensor: none is cached)
once capped and once not, in turn, so a load that comes and goes hits both; printed: the median time per pose of
each and their ratio, and the ratio with nothing beside it (``--busy 0``) for comparison.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time

import numpy as np


def _spin(stop) -> None:
    """Keep one core busy until ``stop`` is set."""
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x += 1


def _per_pose(problem, poses: list[np.ndarray]) -> float:
    t0 = time.perf_counter()
    for x in poses:
        problem.score(x, constrained=False)
    return (time.perf_counter() - t0) / len(poses)


def main() -> None:
    from threadpoolctl import threadpool_limits

    from optipose.evaluate.objective import load_objective
    from optipose.model.part import load_part
    from optipose.search.config import SearchConfig
    from optipose.search.problem import SurrogateProblem

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--part", default="part_b")
    ap.add_argument("--cell", default="ur10e")
    ap.add_argument("--poses", type=int, default=30)
    ap.add_argument("--busy", type=int, default=2, help="processes spinning beside the surrogate")
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    part = load_part(a.part)
    problem = SurrogateProblem(part, load_objective("paper").in_cell(a.cell), SearchConfig())
    hand = problem.space.from_pose(part.layouts["hand"].poses[0]) if "hand" in part.layouts else np.full(6, 0.5)
    rng = np.random.default_rng(0)
    draw = lambda: [np.clip(hand + rng.normal(scale=0.05, size=6), 0.0, 1.0) for _ in range(a.poses)]  # noqa: E731
    problem.score(hand, constrained=False)  # warm: the scanner, the reference, the cell model
    stop = mp.Event()
    spinners = [mp.Process(target=_spin, args=(stop,), daemon=True) for _ in range(a.busy)]
    for p in spinners:
        p.start()
    times: dict = {"one thread": [], "default": []}
    try:
        for _ in range(a.rounds):
            with threadpool_limits(limits=1, user_api="blas"):
                times["one thread"].append(_per_pose(problem, draw()))
            times["default"].append(_per_pose(problem, draw()))
    finally:
        stop.set()
        for p in spinners:
            p.join()
    one, default = np.median(times["one thread"]), np.median(times["default"])
    print(
        f"{a.part}, cell {a.cell}, {a.busy} busy processes beside it, median of {a.rounds} rounds of {a.poses} poses: "
        f"one BLAS thread {one * 1e3:.0f} ms a pose, the default {default * 1e3:.0f} ms: {default / one:.2f}x "
        f"(rounds: one {np.round(np.array(times['one thread']) * 1e3).tolist()}, default {np.round(np.array(times['default']) * 1e3).tolist()})"
    )


if __name__ == "__main__":
    main()
