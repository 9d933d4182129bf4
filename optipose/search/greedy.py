"""Stage: greedy placement, one more sensor given the ones already placed.

A space-filling screen (:mod:`optipose.search.screen`), a global NLopt stage over the new sensor's six
numbers from the best start (the hand-placed sensors, random points, the screen's best), then a local
polish; when a hand-placed sensor was the best start, it is polished too.
"""

from __future__ import annotations

import numpy as np

from optipose.search.config import SearchConfig
from optipose.search.driver import SubProblem, optimize
from optipose.search.screen import screen
from optipose.search.study import SurrogateStudy

__all__ = ["greedy_stage"]


def greedy_stage(
    study: SurrogateStudy,
    config: SearchConfig,
    placed: np.ndarray,
    baseline_u: list[np.ndarray],
    rng: np.random.Generator,
    seed: int,
) -> np.ndarray:
    """The layout (6k,) of ``placed`` (6(k-1),) plus the best new sensor found."""
    k = len(placed) // 6 + 1
    sub = SubProblem(study, placed)
    screened = screen(sub, config, k, seed - k)  # the same points at every k: cached
    starts = [u for u in baseline_u] + [rng.random(6) for _ in range(config.surrogate.random_starts)] + screened[:1]
    scored = sorted(
        ((study.problem.score(np.concatenate([placed, u])).objective, i) for i, u in enumerate(starts)),
        key=lambda t: t[0],
    )
    x0 = starts[scored[0][1]] if scored else rng.random(6)
    with study.stage_named(f"greedy:k={k}"):
        optimize(
            sub,
            config.surrogate.global_algorithm,
            x0,
            config.surrogate.global_evals,
            seed,
            config.surrogate.local_algorithm,
        )
    best = study.best(k)
    best_u6 = (best[1] if best else np.concatenate([placed, x0]))[-6:]
    with study.stage_named(f"greedy-polish:k={k}"):
        optimize(sub, config.surrogate.local_algorithm, best_u6, config.surrogate.local_evals, seed + 1)
        if len(starts) and scored[0][1] < len(baseline_u):  # also polish the best hand start, when it led
            optimize(sub, config.surrogate.local_algorithm, x0, config.surrogate.local_evals // 2, seed + 2)
    best = study.best(k)
    return best[1].copy() if best else np.concatenate([placed, x0])
