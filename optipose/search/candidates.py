"""Which k-sensor layouts get an ICP look: the surrogate's winners, the best distinct layouts of its
history, k-subsets of the larger layouts found, and the (k−1) finalist plus one sensor (nested layouts
keep every smaller choice available to the per-axis assignment, so k sensors never do worse than the
k−1 they contain)."""

from __future__ import annotations

import itertools

import numpy as np

from optipose.search.driver import apart
from optipose.search.problem import SurrogateProblem
from optipose.search.records import Evaluation, Found, SearchOutcome

__all__ = ["candidates", "distinct"]


def candidates(problem: SurrogateProblem, history: list[Evaluation], outcome: SearchOutcome, k: int, per_k: int,
               finalists: dict[int, Found]) -> list[Found]:  # fmt: skip
    """The k-sensor candidates, ``per_k`` of the surrogate's (four times that for one sensor, twice for two:
    a one-sensor candidate costs a third of a three-sensor one), then the nested and subset ones."""
    found = [f for f in (outcome.found.get(k), outcome.greedy.get(k), outcome.joint.get(k)) if f and f.stats]
    n = per_k * (4 if k == 1 else 2 if k == 2 else 1)
    found = distinct(found + _from_history(problem, history, k, n), 0.02)[:n]
    found += _sub_layouts(problem, outcome, k, found)
    if k - 1 in finalists:
        nested = _extended(problem, finalists[k - 1], found)
        found += [nested] if nested is not None else []
    return found


def distinct(found: list[Found], min_distance: float = 0.05, key=None) -> list[Found]:
    """Drop layouts whose parameters lie within ``min_distance`` (in [0, 1] units) of a better one
    (better: lower ``key(layout)``, by default the surrogate score)."""
    kept: list[Found] = []
    for c in sorted(found, key=key or (lambda f: f.score)):
        if apart(c.u, [k.u for k in kept if len(k.u) == len(c.u)], min_distance):
            kept.append(c)
    return kept


def _from_history(problem: SurrogateProblem, history: list[Evaluation], k: int, n: int) -> list[Found]:
    rows = sorted((r for r in history if r.k == k and r.feasible), key=lambda r: r.value)
    out = []
    for r in rows[: 40 * n]:
        u = np.asarray(r.u, dtype=float)
        out.append(Found(k, "history", u, problem.space.to_poses(u), r.value, {}))
    return distinct(out)[:n]


def _sub_layouts(problem: SurrogateProblem, outcome: SearchOutcome, k: int, have: list[Found]) -> list[Found]:
    """k-sensor subsets of the larger layouts found: a sensor placed for a pair can be the best single one.
    Scored on the surrogate, distinct from what is already a candidate; at most two."""
    out = []
    for big in [f for kk, f in outcome.found.items() if kk > k and f.stats]:
        for combo in itertools.combinations(range(big.k), k):
            u = np.concatenate([big.sensor(i) for i in combo])
            score = problem.score(u)
            if score.feasible:
                out.append(Found(k, f"subset of k={big.k}", u, problem.space.to_poses(u), score.value, score.stats))
    fresh = [c for c in distinct(out, 0.02) if apart(c.u, [h.u for h in have], 0.02)]
    return fresh[:2]


def _extended(problem: SurrogateProblem, base: Found, others: list[Found]) -> Found | None:
    """``base`` (k−1 sensors) plus the one sensor of ``others`` that the surrogate likes best with it."""
    best = None
    for other in others:
        for i in range(other.k):
            u = np.concatenate([base.u, other.sensor(i)])
            score = problem.score(u)
            if score.feasible and (best is None or score.value < best.score):
                best = Found(base.k + 1, f"k={base.k} finalist + 1", u, problem.space.to_poses(u), score.value, score.stats)
    return best
