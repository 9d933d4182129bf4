"""Which k-sensor layouts get an ICP look: the hand-placed sensors the hand layout's choice uses with a
found sensor in place of the others (:func:`anchored`), the surrogate's winners, the best distinct layouts
of its history, k-subsets of the larger layouts found, and the (k−1) finalist plus one sensor (nested
layouts keep every smaller choice available to the per-axis assignment, so k sensors never do worse than
the k−1 they contain)."""

from __future__ import annotations

import itertools

import numpy as np

from optipose.model.collision import heads_clearance
from optipose.search.driver import apart
from optipose.search.problem import SurrogateProblem, Violation
from optipose.search.records import Evaluation, Found, SearchOutcome

__all__ = ["candidates", "distinct", "anchored"]


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


def anchored(problem: SurrogateProblem, hand_poses: list[np.ndarray], used: tuple[int, ...], outcome: SearchOutcome,
             k: int, n: int = 2) -> list[Found]:  # fmt: skip
    """Layouts of k sensors that keep hand-placed sensors the hand layout's k-choice uses (``used``, their
    indices) in their own places and put a found sensor in each other place; the ``n`` best on the surrogate.

    A kept sensor keeps its index, so every evaluation gives it the hand layout's own noise draws and
    bracket errors: each axis the hand layout measures on kept sensors alone is measured exactly as well,
    and the found sensors can only add subsets. Such a layout is no worse than the hand one on those axes by
    construction and better wherever a found sensor helps — an answer the user acts on by moving only the
    other brackets. A layout of k sensors has places 0 … k−1, so only used sensors at those indices can be
    kept, and at most k − 1 of them (one place at least is the search's): when the choice uses more, each
    way of leaving one out is tried. The found sensors must clear the part and keep-outs on their own and
    the other heads by ``head_gap`` (the kept hand heads are the baseline, whatever their gaps).
    """
    keepable = [i for i in used if i < k]
    if not hand_poses or k < 2 or not keepable:
        return []
    size = min(len(keepable), k - 1)
    pool = [f for f in (*outcome.found.values(), *outcome.greedy.values(), *outcome.joint.values()) if f and f.stats]
    sensors = distinct_sensors([f.sensor(i) for f in pool for i in range(f.k)])
    sensors = [u6 for u6 in sensors if not isinstance(problem.sensor(u6), Violation)]  # feasible alone
    out = []
    for keep in itertools.combinations(keepable, size):
        free = [i for i in range(k) if i not in keep]
        for fill in itertools.permutations(sensors, len(free)):
            u6s = {i: problem.space.from_pose(hand_poses[i]) for i in keep} | dict(zip(free, fill))
            found = _anchored_layout(problem, np.concatenate([u6s[i] for i in range(k)]), free, k)
            if found is not None:
                out.append(found)
    return distinct(out, 0.02)[:n]


def _anchored_layout(problem: SurrogateProblem, u: np.ndarray, free: list[int], k: int) -> Found | None:
    poses = problem.space.to_poses(u)
    model = problem.collision.sensor
    gaps = [heads_clearance(model, poses[a], model, poses[b]) for a in free for b in range(k) if b != a]
    if min(gaps, default=np.inf) < problem.config.head_gap:
        return None
    score = problem.score(u, constrained=False)  # the kept heads are the baseline's
    return Found(k, "hand-anchored", u, poses, score.value, score.stats) if score.stats is not None else None


def distinct_sensors(sensors: list[np.ndarray], min_distance: float = 0.02) -> list[np.ndarray]:
    """The sensors (6,) each, without repeats within ``min_distance`` (in [0, 1] units), in their order."""
    kept: list[np.ndarray] = []
    for u6 in sensors:
        if apart(u6, kept, min_distance):
            kept.append(np.asarray(u6, dtype=float))
    return kept
