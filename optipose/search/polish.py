"""Stage: the ICP polish of a finalist that does not yet beat the hand-placed layout clearly.

A local NLopt search (``polish_algorithm``) on the reduced-protocol ICP score itself: the sum plus
``polish_weight`` × every axis's median and 75th percentile above ``polish_margin`` × the hand layout's
(constraints as in the search). It ends on evaluations (``polish_evals``; ``polish_time`` is only a safety
net), so a seed gives the same layout on a busy machine.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from optipose.evaluate.compare import dominates, excess
from optipose.search.config import SearchConfig, algorithm_code
from optipose.search.problem import SurrogateProblem
from optipose.search.records import PENALTY, Found, IcpEvaluation

__all__ = ["polish", "hand_start"]

log = logging.getLogger(__name__)


def polish(problem: SurrogateProblem, evaluator, start: Found, reference, config: SearchConfig, max_evals: int,
           max_time: float, on_stage=None) -> tuple[Found | None, object, list[IcpEvaluation]]:  # fmt: skip
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
        over = excess(choice, reference, config.polish_margin) if reference is not None else 0.0
        value = float(np.rad2deg(choice.score + config.polish_weight * over))
        wins = reference is None or dominates(choice, reference)
        records.append(IcpEvaluation(k, "ICP polish", score.objective, "reduced", choice, wins))
        key = (not wins, float(np.rad2deg(choice.score)) if wins else value)
        if best[0] is None or key < best[0]:
            best[:] = [key, u.copy(), choice]
        if on_stage:
            on_stage(f"ICP polish k={k}: {len(records)} evaluations, best {best[0][1] * 1e3:.3f} mdeg"
                     f"{'' if not best[0][0] else ' (not yet no worse than hand on every axis)'}")  # fmt: skip
        return value if value < PENALTY else PENALTY

    _run_local(f, config, start.u, max_evals)
    if best[1] is None:
        return None, None, records
    u = best[1]
    score = problem.score(u)
    return Found(k, "ICP polish", u, problem.space.to_poses(u), score.objective, score.stats or {}), best[2], records


def _run_local(f, config: SearchConfig, x0: np.ndarray, max_evals: int) -> None:
    """The polish's NLopt run: its own initial step and absolute tolerance, stopped by ``f`` or the budget."""
    import nlopt

    n = len(x0)
    opt = nlopt.opt(algorithm_code(config.polish_algorithm), n)
    opt.set_lower_bounds(np.zeros(n))
    opt.set_upper_bounds(np.ones(n))
    opt.set_min_objective(f)
    opt.set_maxeval(int(max_evals))
    opt.set_initial_step(np.full(n, config.polish_step))
    opt.set_xtol_abs(1e-4)
    try:
        opt.optimize(np.clip(x0, 0.0, 1.0))
    except (nlopt.ForcedStop, nlopt.RoundoffLimited):
        pass
    except RuntimeError as exc:
        log.warning("ICP polish stopped: %s", exc)


def hand_start(problem: SurrogateProblem, hand_layout, reference) -> list[Found]:
    """The hand-placed sensors of the reference choice (e.g. ``S3``) as a polish start: it is no worse than
    itself on every axis, so a local search from it that keeps that while lowering the sum is what a user
    who already owns these mounts wants."""
    if len(reference.sensors) != reference.k or max(reference.sensors, default=-1) >= len(hand_layout):
        return []
    u = np.concatenate([problem.space.from_pose(hand_layout.poses[i]) for i in reference.sensors])
    return [Found(reference.k, "hand start", u, problem.space.to_poses(u), problem.score(u).objective, {})]
