"""The NLopt search over sensor poses on the surrogate (docs/method.md, "The search"): greedy, then joint, for k = 1, 2, 3 …

For every k, **greedy** places one more sensor given the ones already placed (:mod:`optipose.search.greedy`)
and **joint** re-optimises all 6k variables at once from the greedy layout and from the best hand-placed
k-subset (:mod:`optipose.search.joint`). The better of the two is kept per k; both are reported. Start
points include the hand-placed sensors, so the search never ends worse than them on the surrogate.
"""

from __future__ import annotations

import itertools
import logging
import math
import time

import numpy as np

from optipose.search.config import SearchConfig
from optipose.search.greedy import greedy_stage
from optipose.search.joint import joint_stage
from optipose.search.problem import SurrogateProblem
from optipose.search.records import Found, SearchOutcome
from optipose.search.study import Share, Stop, SurrogateStudy
from optipose.model.baseline import baseline

__all__ = ["run_search", "best_baseline_subsets"]

log = logging.getLogger(__name__)


def run_search(
    part,
    objective,
    config: SearchConfig,
    seed: int = 0,
    study: SurrogateStudy | None = None,
    seconds: float | None = None,
) -> SearchOutcome:
    """Greedy then joint NLopt search for every k in ``config.sensors`` (see the module doc).

    study : the live search to record into (e.g. with a resumed cache and callbacks); default a new one.
    seconds : a clock on the search (default ``config.surrogate.max_time``, 0: none; inf: none); without one its
    evaluations end it, and a seed gives its layouts on any machine.
    Its problem is measured against the hand layout's targets from here on.
    """
    t0 = time.monotonic()
    study = study or SurrogateStudy(SurrogateProblem(part, objective, config))
    rng = np.random.default_rng(seed)
    baseline_poses = baseline(part).poses if baseline(part) is not None else []
    baseline_u = [study.problem.space.from_pose(T) for T in baseline_poses]
    ks = sorted(set(config.sensors))
    baseline_subsets = best_baseline_subsets(study.problem, baseline_u, [k for k in ks if k <= len(baseline_u)])
    study.measure_against({k: f.stats.level_axis_score for k, f in baseline_subsets.items()})
    if seconds is None:
        seconds = config.surrogate.max_time if config.surrogate.max_time > 0 else math.inf
    study.start_clock(seconds)  # after the hand layout is scored: that first scan also compiles the kernels
    greedy, joint, unplaced = {}, {}, []
    try:
        _place(study, config, max(ks), baseline_u, baseline_subsets, rng, seed, greedy, joint)
    except Stop as why:
        unplaced = [k for k in ks if study.best(k) is None]
        cut = f", the clock having ended the surrogate's {', '.join(study.cut)}" if study.cut and unplaced else ""
        (log.warning if unplaced else log.info)(
            "search stopped: %s%s",
            why,
            f"; no layout of {unplaced} sensor(s) yet{cut} (a larger --max-time, or none)" if unplaced else "",
        )
    if (
        study.cut and not unplaced
    ):  # the layouts are then the machine's speed's as well as the seed's: say so where the user reads
        log.warning(
            "the clock ended the surrogate's %s before its evaluations: another run of this seed may place other "
            "sensors (without --max-time the seed gives its own answer)",
            ", ".join(study.cut),
        )
    found = {}
    for k in ks:
        options = [f for f in (greedy.get(k), joint.get(k), _as_found(study, k)) if f and f.stats]
        if options:
            found[k] = min(options, key=lambda f: f.score)
    return SearchOutcome(
        found,
        greedy,
        joint,
        baseline_subsets,
        study.history,
        study.interrupted,
        time.monotonic() - t0,
        tuple(study.cut),
    )


def _place(study, config, n, baseline_u, baseline_subsets, rng, seed, greedy: dict, joint: dict) -> None:
    """Fill ``greedy`` and ``joint`` for k = 1 … n (as far as the clock allows).

    Each k gets its share of what is left of the clock, by the work its stages ask for (the sensor poses
    they scan, :func:`_scans`), and what it does not use passes on; a k whose share runs out keeps its
    best layout so far, so a tight budget still gives every k an answer instead of spending it all on k = 1.
    """
    placed = np.zeros(0)
    work = {k: _scans(config, k) for k in range(1, n + 1)}
    for k in range(1, n + 1):
        with study.share(study.seconds_left() * work[k] / sum(work[j] for j in range(k, n + 1))):
            try:
                if config.surrogate.strategy in ("greedy", "both") or k == 1:
                    placed = greedy_stage(study, config, placed, baseline_u, rng, seed * 1000 + k)
                    if study.best(k) is None:  # no feasible layout of k sensors: more sensors will not help
                        log.warning("no feasible layout of %d sensor(s) found; stopping", k)
                        break
                    greedy[k] = _found(study, k, "greedy", placed)
                if k > 1 and config.surrogate.strategy in ("joint", "both"):
                    joint[k] = joint_stage(
                        study, config, k, greedy.get(k), baseline_subsets.get(k), rng, seed * 1000 + 100 + k
                    )
                    if config.surrogate.strategy == "joint":
                        placed = joint[k].u
            except Share as why:
                best = study.best(k)
                log.info("k=%d: %s; it keeps its best layout so far", k, why)
                if best is None:
                    log.warning("no feasible layout of %d sensor(s) found in its share of the time; stopping", k)
                    break
                if k not in greedy and k not in joint:
                    placed = best[1].copy()
                    greedy[k] = _found(study, k, "greedy", placed)


def _scans(config: SearchConfig, k: int) -> int:
    """The new sensor poses the stages of k sensors scan: a greedy evaluation moves one sensor (the placed
    ones are cached), a joint one all k; the screen's poses are the same at every k, so only k = 1 scans
    them. (Counting evaluations times k instead gave k = 1 a sixth of the default budget's clock, less than
    its 4,096 screen poses take: on a busy machine the clock, not the seed, decided B's k = 1.)"""
    s = config.surrogate
    greedy = s.global_evals + s.local_evals + s.random_starts + s.screen_starts * s.screen_evals
    greedy += s.screen_samples if k == 1 else 0
    return (greedy if s.strategy in ("greedy", "both") or k == 1 else 0) + (
        k * s.joint_evals if k > 1 and s.strategy != "greedy" else 0
    )


def _found(study, k: int, stage: str, u: np.ndarray) -> Found:
    score = study.problem.score(u)
    return Found(k, stage, u.copy(), study.problem.space.to_poses(u), score.objective, score.stats)


def best_baseline_subsets(problem: SurrogateProblem, baseline_u: list[np.ndarray], ks) -> dict[int, Found]:
    """The best k of the hand-placed sensors on the surrogate, scored as given (no constraint checks:
    they are the baseline, e.g. the paper's three heads overlap in our default head-box model)."""
    out = {}
    for k in ks:
        best = None
        for combo in itertools.combinations(range(len(baseline_u)), k):
            u = np.concatenate([baseline_u[i] for i in combo])
            score = problem.score(u, constrained=False)
            if score.stats is not None and (best is None or score.value < best.score):
                best = Found(k, "hand", u, problem.space.to_poses(u), score.value, score.stats)
        if best:
            out[k] = best
    return out


def _as_found(study: SurrogateStudy, k: int) -> Found | None:
    """The best feasible layout of k sensors seen anywhere (covers a search cut short mid-stage)."""
    best = study.best(k)
    if best is None:
        return None
    value, u = best
    stats = study.problem.score(u).stats
    return Found(k, study.stage.split(":")[0] or "search", u, study.problem.space.to_poses(u), value, stats)
