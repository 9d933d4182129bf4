"""Stage: the space-filling screen before each greedy stage.

DIRECT-L refines around one basin; the screen finds the others. It scores ``screen_samples`` scrambled
Sobol poses of the new sensor on the surrogate and polishes locally the best ``screen_starts`` of them
that lie apart; every evaluation is recorded, so the ICP selection sees those basins too. After k = 1 the
poses' information is cached, so later greedy stages re-score the same points nearly free.
"""

from __future__ import annotations

import numpy as np

from optipose.search.config import SearchConfig
from optipose.search.driver import SubProblem, apart, local_best
from optipose.search.records import PENALTY

__all__ = ["screen"]

_CHUNK = 64  # poses computed ahead on the threads between the study's clock checks


def screen(sub: SubProblem, config: SearchConfig, k: int, seed: int) -> list[np.ndarray]:
    """The polished bests (6,) of the screen of the k-th sensor, best first (none when the budget has no screen).

    sub : the new sensor's sub-problem of the study (:class:`~optipose.search.driver.SubProblem`).
    """
    if config.surrogate.screen_samples <= 0:
        return []
    from scipy.stats import qmc

    study = sub.study
    with study.stage_named(f"screen:k={k}"):
        points = qmc.Sobol(6, scramble=True, seed=seed).random(int(config.surrogate.screen_samples))
        values = []
        for start in range(0, len(points), _CHUNK):  # each chunk's poses on every core, then recorded in order
            block = points[start : start + _CHUNK]
            study.prefetch(block)
            values += [sub(u) for u in block]  # the clock ends the screen here, as without the prefetch
        values = np.array(values)
    picked: list[np.ndarray] = []
    for i in np.argsort(values, kind="stable"):
        if values[i] >= PENALTY or len(picked) >= config.surrogate.screen_starts:
            break
        if apart(points[i], picked, 0.1):
            picked.append(points[i])
    bests = []
    with study.stage_named(f"screen-polish:k={k}"):
        for j, start in enumerate(picked):
            best = local_best(
                sub, config.surrogate.local_algorithm, start, config.surrogate.screen_evals, seed + 10 + j
            )
            if best is not None:
                bests.append((best.value, np.asarray(best.u, dtype=float)[-6:]))
    return [u for _, u in sorted(bests, key=lambda t: t[0])]
