"""Stage: joint placement, all 6k numbers at once, from the greedy layout and the best hand-placed k-subset."""

from __future__ import annotations

import numpy as np

from optipose.search.config import SearchConfig
from optipose.search.driver import local_best
from optipose.search.records import Found
from optipose.search.study import SurrogateStudy

__all__ = ["joint_stage"]


def joint_stage(
    study: SurrogateStudy,
    config: SearchConfig,
    k: int,
    greedy: Found | None,
    baseline: Found | None,
    rng: np.random.Generator,
    seed: int,
) -> Found:
    """The best layout of a local polish of all k sensors from each start (a random one when there is none)."""
    best = None
    starts = [s for s in (greedy, baseline) if s is not None] or [Found(k, "random", rng.random(6 * k), [], np.inf)]
    with study.stage_named(f"joint:k={k}"):
        for start in starts:
            row = local_best(
                study,
                config.surrogate.local_algorithm,
                start.u,
                config.surrogate.joint_evals // (2 if baseline and greedy else 1),
                seed,
            )
            if row is not None:
                u = np.asarray(row.u)
                if best is None or row.value < best.score:
                    best = Found(
                        k, "joint", u, study.problem.space.to_poses(u), row.value, study.problem.score(u).stats
                    )
    return best or Found(k, "joint", greedy.u if greedy else np.zeros(6 * k), [], np.inf, {})
