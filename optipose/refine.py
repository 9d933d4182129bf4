"""The middle fidelity: pick each k's finalist by real ICP on a reduced protocol.

The surrogate (:mod:`optipose.surrogate`) sees only the variance of a registration. Measured on the
shipped parts, the ICP error is dominated instead by a *bias* that noise creates near edges (a noisy
point beyond a convex edge is matched to the edge, not the face) and by how voxel cells cut the rotated
faces: on part B, the paper's S1 has a roll error of −1.2 mdeg at the nominal orientation for every noise
seed, twenty times its predicted spread, while S2, whose pocket edges cancel, stays at 0.08 mdeg. So the
search ends by running the objective's own registration: every candidate of k sensors (the greedy and
joint winners, the best hand-placed k-subset, and the best distinct layouts of the surrogate history) is
evaluated on a reduced protocol — each sequence at its two end angles, 14 scans instead of 77 — with a
*selection* noise seed, and the best is kept. The full protocol with the held-out seed then reports it.
"""

from __future__ import annotations

import itertools
import logging
import time
from dataclasses import replace

import numpy as np

from optipose.search import Found, SearchOutcome, SurrogateProblem

__all__ = ["reduced_objective", "select_finalists", "selection_seed"]

log = logging.getLogger(__name__)


def selection_seed(seed: int) -> int:
    """The noise seed of the selection stage: neither the search's nor the validation's."""
    return int(np.random.SeedSequence([int(seed), 0x5E1EC7]).generate_state(1)[0])


def reduced_objective(objective):
    """The objective with each sequence cut to its two end angles (start and stop)."""
    p = objective.protocol
    if p.kind != "sequences":
        return replace(objective, protocol=replace(p, count=max(4, p.count // 5)))
    return replace(objective, protocol=replace(p, step=max(p.stop - p.start, 1e-9)))


def _distinct(candidates: list[Found], min_distance: float = 0.05) -> list[Found]:
    """Drop candidates whose parameters lie within ``min_distance`` (in [0, 1] units) of a better one."""
    kept: list[Found] = []
    for c in sorted(candidates, key=lambda f: f.score):
        if all(np.max(np.abs(c.u - k.u)) > min_distance for k in kept if len(k.u) == len(c.u)):
            kept.append(c)
    return kept


def _history_candidates(problem: SurrogateProblem, k: int, n: int) -> list[Found]:
    rows = [r for r in problem.history if r["k"] == k and r["feasible"]]
    rows.sort(key=lambda r: r["value"])
    out = []
    for r in rows[: 40 * n]:
        u = np.asarray(r["u"], dtype=float)
        out.append(Found(k, "history", u, problem.space.to_poses(u), r["value"], {}))
    return _distinct(out)[:n]


def _sub_layouts(problem: SurrogateProblem, outcome: SearchOutcome, k: int, have: list[Found]) -> list[Found]:
    """k-sensor subsets of the larger layouts found: a sensor placed for a pair can be the best single one.
    Scored on the surrogate, distinct from what is already a candidate; at most two."""
    out = []
    for big in [f for kk, f in outcome.found.items() if kk > k and f.stats]:
        for combo in itertools.combinations(range(big.k), k):
            u = np.concatenate([big.u[6 * i : 6 * i + 6] for i in combo])
            value, stats = problem.evaluate(u)
            if stats is not None:
                out.append(Found(k, f"subset of k={big.k}", u, problem.space.to_poses(u), value, stats))
    fresh = [c for c in _distinct(out, 0.02) if all(np.max(np.abs(c.u - h.u)) > 0.02 for h in have)]
    return fresh[:2]


def select_finalists(part, objective, outcome: SearchOutcome, problem: SurrogateProblem, seed: int,
                     per_k: int = 3, max_time: float = np.inf, on_stage=None) -> tuple[dict[int, Found], list[dict]]:  # fmt: skip
    """For every k, evaluate the candidates on the reduced protocol and keep the best.

    Returns the finalists per k (``strategy`` tells where each came from) and one row per candidate
    (k, origin, surrogate score, reduced-protocol score in degrees).
    """
    from optipose.evaluate import Evaluator

    deadline = time.monotonic() + max_time
    reduced = reduced_objective(objective)
    finalists, rows = {}, []
    with Evaluator(part, reduced, seed=selection_seed(seed)) as evaluator:
        for k in sorted(outcome.found):
            candidates = [f for f in (outcome.found.get(k), outcome.greedy.get(k), outcome.joint.get(k)) if f and f.stats]
            n = per_k * (2 if k == 1 else 1)  # a one-sensor candidate costs a third of a three-sensor one
            candidates = _distinct(candidates + _history_candidates(problem, k, n), 0.02)[:n]
            candidates += _sub_layouts(problem, outcome, k, candidates)
            hand = outcome.hand.get(k)
            best, best_score = None, np.inf
            for cand in candidates + ([hand] if hand else []):
                if time.monotonic() > deadline and best is not None:
                    log.info("selection for k=%d stopped by the time budget", k)
                    break
                if on_stage:
                    on_stage(f"selecting k={k} on the reduced protocol ({cand.strategy})")
                result = evaluator(cand.poses)
                score = float(np.rad2deg(result.table[k - 1].score))
                rows.append({"k": k, "origin": cand.strategy, "surrogate_deg": cand.score, "reduced_protocol_deg": score})
                if cand is not hand and score < best_score:
                    best, best_score = cand, score
            if best is not None:
                finalists[k] = best
    return finalists, rows
