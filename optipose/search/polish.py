"""Stage: the ICP polish of a finalist that does not yet beat the hand-placed layout clearly.

A local NLopt search (``polish_algorithm``) on the reduced-protocol ICP score itself: the sum plus
``polish_weight`` × every axis's median and 75th percentile above ``polish_margin`` × the hand layout's
(constraints as in the search). It ends on evaluations (``polish_evals``; ``polish_time`` is only a safety
net), so a seed gives the same layout on a busy machine.
"""

from __future__ import annotations

import time

import numpy as np

from optipose.verdict.compare import dominates, excess
from optipose.search.config import SearchConfig
from optipose.search.driver import optimize
from optipose.search.problem import SurrogateProblem
from optipose.search.records import PENALTY, Found, IcpEvaluation

__all__ = ["polish", "baseline_start"]


def polish(
    problem: SurrogateProblem,
    evaluator,
    start: Found,
    reference,
    config: SearchConfig,
    max_evals: int,
    max_time: float,
    on_stage=None,
) -> tuple[Found | None, object, list[IcpEvaluation]]:
    """Polish ``start`` against ``reference`` (the hand layout's choice of k, or None).

    Returns the best feasible layout seen that is no worse than ``reference`` on any axis (or the lowest
    penalised score when none is), its choice, and one record per evaluation.
    """
    import nlopt

    k, records, best = start.k, [], [None, None, None]  # key, u, choice
    deadline = time.monotonic() + max_time

    def f(u, grad=None):
        if time.monotonic() > deadline:
            raise nlopt.ForcedStop
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        score = problem.score(u)
        if not score.feasible:
            return float(score.objective)  # PENALTY + violation: infeasible, never a result
        choice = evaluator(problem.space.to_poses(u)).table[k - 1]
        over = excess(choice, reference, config.selection.polish_margin) if reference is not None else 0.0
        value = float(np.rad2deg(choice.score + config.selection.polish_weight * over))
        wins = reference is None or dominates(choice, reference)
        records.append(IcpEvaluation(k, "ICP polish", score.objective, "reduced", choice, wins))
        key = (not wins, float(np.rad2deg(choice.score)) if wins else value)
        if best[0] is None or key < best[0]:
            best[:] = [key, u.copy(), choice]
        if on_stage:
            on_stage(
                f"ICP polish k={k}: {len(records)} evaluations, best {best[0][1] * 1e3:.3f} mdeg"
                f"{'' if not best[0][0] else ' (not yet no worse than hand on every axis)'}"
            )
        return value if value < PENALTY else PENALTY

    # its own step and an absolute tolerance; NLopt's seed is left alone (the local algorithms draw none)
    optimize(
        f,
        config.selection.polish_algorithm,
        start.u,
        max_evals,
        None,
        step=config.selection.polish_step,
        xtol_rel=None,
        xtol_abs=1e-4,
    )
    if best[1] is None:
        return None, None, records
    u = best[1]
    score = problem.score(u)
    return Found(k, "ICP polish", u, problem.space.to_poses(u), score.objective, score.stats), best[2], records


def baseline_start(problem: SurrogateProblem, baseline_layout, reference) -> list[Found]:
    """The hand-placed sensors of the reference choice (e.g. ``S3``) as a polish start: it is no worse than
    itself on every axis, so a local search from it that keeps that while lowering the sum is what a user
    who already owns these mounts wants."""
    u = np.concatenate([problem.space.from_pose(baseline_layout.poses[i]) for i in reference.sensors])
    return [Found(reference.k, "hand start", u, problem.space.to_poses(u), problem.score(u).objective)]
