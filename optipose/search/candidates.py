"""Which k-sensor layouts get an ICP look: the hand-placed sensors the hand layout's choice uses with a
found sensor in place of the others (:func:`anchored`), the surrogate's winners, the best distinct layouts
of its history, k-subsets of the larger layouts found, and the (k−1) finalist plus one sensor (nested
layouts keep every smaller choice available to the per-axis assignment, so k sensors never do worse than
the k−1 they contain)."""

from __future__ import annotations

import contextlib
import itertools
import time

import numpy as np

from optipose.model.collision import heads_clearance
from optipose.search.driver import apart, optimize
from optipose.search.problem import SurrogateProblem, Violation
from optipose.search.records import PENALTY, Evaluation, Found, SearchOutcome
from optipose.search.surrogate import predicted_stats
from optipose.search.study import Stop

__all__ = ["candidates", "distinct", "anchored"]


def candidates(
    problem: SurrogateProblem,
    history: list[Evaluation],
    outcome: SearchOutcome,
    k: int,
    per_k: int,
    finalists: dict[int, Found],
) -> list[Found]:
    """The k-sensor candidates, ``per_k`` of the surrogate's (four times that for one sensor, twice for two:
    a one-sensor candidate costs a third of a three-sensor one), then the nested and subset ones."""
    found = [f for f in (outcome.found.get(k), outcome.greedy.get(k), outcome.joint.get(k)) if f and f.stats]
    n = per_k * (4 if k == 1 else 2 if k == 2 else 1)
    found = distinct(found + _from_history(problem, history, k, n), 0.02)[:n]
    found += _sub_layouts(problem, outcome, k, found)
    if k - 1 in finalists:
        nested = _extended(problem, finalists[k - 1], found)
        # the same layout as a candidate already in (a subset's sensors, in their order) would be evaluated twice
        found += [nested] if nested is not None and apart(nested.u, [f.u for f in found], 1e-12) else []
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
                best = Found(
                    base.k + 1, f"k={base.k} finalist + 1", u, problem.space.to_poses(u), score.value, score.stats
                )
    return best


def anchored(
    problem: SurrogateProblem,
    baseline_poses: list[np.ndarray],
    used: tuple[int, ...],
    outcome: SearchOutcome,
    k: int,
    n: int = 2,
    evals: int = 0,
    until: float = np.inf,
) -> list[Found]:
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

    evals : when > 0, each way of keeping sensors then moves its best layout's found sensors by a local
    NLopt search on the surrogate (``evals`` evaluations, until ``time.monotonic()`` passes ``until``), the
    kept ones fixed, scored with the hand-margin penalty noise level by noise level: the found sensors are
    placed *for* the kept ones, not borrowed from layouts placed without them. The hand-placed sensor of a
    free place is one more start (with its own noise draws, as in the hand layout: a small move of it is
    compared with common random numbers); a found head may come as close to a kept one as the hand heads
    of those places do; layouts are ranked with that penalty too. One sensor keeps nothing and is refined
    from the best of the found sensors and the hand one in place 0; only the refined layout comes back.
    """
    keepable = [i for i in used if i < k]
    if not baseline_poses or (not keepable and k > 1) or (k < 2 and evals <= 0):
        return []
    size = min(len(keepable), k - 1)  # one sensor, refined: nothing is kept, and the hand one in its place is a start
    pool = [f for f in (*outcome.found.values(), *outcome.greedy.values(), *outcome.joint.values()) if f and f.stats]
    sensors = distinct_sensors([f.sensor(i) for f in pool for i in range(f.k)])
    sensors = [u6 for u6 in sensors if not isinstance(problem.sensor(u6), Violation)]  # feasible alone
    baseline_u = [problem.space.from_pose(T) for T in baseline_poses]
    floors = _gap_floors(problem, baseline_poses, k) if evals > 0 else {}
    out, values = [], {}
    for keep in itertools.combinations(keepable, size):
        free = [i for i in range(k) if i not in keep]
        these = []
        # each free place: a found sensor, or (refined only) the hand-placed sensor of that place when it is
        # feasible alone, a start the local search can move from; a sensor fills one place at most
        starts = [
            [baseline_u[i]]
            if evals > 0 and i < len(baseline_u) and not isinstance(problem.sensor(baseline_u[i]), Violation)
            else []
            for i in free
        ]
        for fill in itertools.product(*[sensors + extra for extra in starts]):
            if evals > 0 and time.monotonic() > until:
                break
            if len(fill) > 1 and not all(apart(a, [b], 1e-9) for a, b in itertools.combinations(fill, 2)):
                continue
            u6s = {i: baseline_u[i] for i in keep} | dict(zip(free, fill))
            found = _anchored_layout(problem, [u6s[i] for i in range(k)], free, floors, baseline_poses)
            if found is not None:
                these.append(found)
        if evals > 0 and these:
            kept = {i: problem.info(baseline_u[i]) for i in keep}  # whatever their clearances
            for found in these:
                values[id(found)] = _anchored_value(problem, found.u, kept, k, floors)
            if time.monotonic() < until:
                refined = _refined(
                    problem, min(these, key=lambda f: values[id(f)]), kept, k, evals, until, floors, baseline_poses
                )
                values[id(refined)] = _anchored_value(problem, refined.u, kept, k, floors)
                these = (
                    these + [refined] if keep else [refined]
                )  # nothing kept: the others are the search's own candidates
            elif not keep:
                these = []
        out += these
    if evals <= 0:  # as before the refinement existed: ranked by the surrogate's score alone
        return distinct(out, 0.02)[:n]
    return distinct([f for f in out if values[id(f)] < PENALTY], 0.02, key=lambda f: values[id(f)])[:n]


def _anchored_layout(
    problem: SurrogateProblem, u6s: list[np.ndarray], free: list[int], floors: dict, baseline_poses: list[np.ndarray]
) -> Found | None:
    """The layout of these sensors (one (6,) per place) scored on the surrogate as given (the kept heads are
    the baseline's); None when a found head is too close to another."""
    u, k = np.concatenate(u6s), len(u6s)
    if _gap_violation(problem, u, free, k, floors) > 0:
        return None
    score = problem.score(u, constrained=False)
    return Found(k, "hand-anchored", u, problem.space.to_poses(u), score.value, score.stats)


def _gap_floors(problem: SurrogateProblem, baseline_poses: list[np.ndarray], k: int) -> dict:
    """The gap (m) two heads of places a, b must keep: ``head_gap``, or the hand-placed heads' own gap at
    those places when that is smaller (the hand cell exists; our head box is a conservative model of it)."""
    model, n = problem.collision.sensor, min(k, len(baseline_poses))
    floors = {}
    for a, b in itertools.permutations(range(n), 2):
        floors[a, b] = min(
            problem.config.constraints.head_gap, heads_clearance(model, baseline_poses[a], model, baseline_poses[b])
        )
    return floors


def _gap_violation(problem: SurrogateProblem, u: np.ndarray, free: list[int], k: int, floors: dict) -> float:
    """How far (m) the found heads come within their floor (:func:`_gap_floors`) of the others (0: far enough)."""
    poses = problem.space.to_poses(u)
    model = problem.collision.sensor
    short = [
        floors.get((a, b), problem.config.constraints.head_gap) - heads_clearance(model, poses[a], model, poses[b])
        for a in free
        for b in range(k)
        if b != a
    ]
    return max(0.0, max(short, default=0.0))


def _anchored_value(problem: SurrogateProblem, u: np.ndarray, kept: dict, k: int, floors: dict) -> float:
    """What the refinement minimises: the surrogate's score plus the hand-margin penalty, the kept sensors'
    information ``kept`` (place → :class:`SensorInfo`) given; the found sensors' own violations (each alone,
    then their head gaps) as the optimisers' ``PENALTY + violation``."""
    free = [i for i in range(k) if i not in kept]
    infos = dict(kept) | {i: problem.sensor(u[6 * i : 6 * i + 6]) for i in free}
    violation = sum(v.amount for v in infos.values() if isinstance(v, Violation))
    if violation == 0.0 and (gap := _gap_violation(problem, u, free, k, floors)) > 0:
        violation = 1.0 + 10.0 * min(gap, 0.1)
    if violation > 0:
        return PENALTY + violation
    stats = predicted_stats([infos[i] for i in range(k)], *problem.weights)
    return stats.score + problem.shortfall(k, stats)


def _refined(
    problem: SurrogateProblem,
    start: Found,
    kept: dict,
    k: int,
    evals: int,
    until: float,
    floors: dict,
    baseline_poses: list[np.ndarray],
) -> Found:
    """``start`` with its found sensors moved by the local algorithm on :func:`_anchored_value`, the kept
    ones fixed; the best layout it met (``start`` itself when it met none better)."""
    slots = np.concatenate([np.arange(6 * i, 6 * i + 6) for i in range(k) if i not in kept])
    best = {"value": _anchored_value(problem, start.u, kept, k, floors), "u": start.u}

    def value(x, grad=None) -> float:
        if time.monotonic() > until:
            raise Stop("the selection's time is up")
        u = start.u.copy()
        u[slots] = x
        v = _anchored_value(problem, u, kept, k, floors)
        if v < best["value"]:
            best.update(value=v, u=u)
        return v

    with contextlib.suppress(Stop):
        optimize(value, problem.config.surrogate.local_algorithm, start.u[slots], evals, seed=None, step=0.03)
    u = best["u"]
    infos = [kept[i] if i in kept else problem.sensor(u[6 * i : 6 * i + 6]) for i in range(k)]
    infos = [problem.info(u[6 * i : 6 * i + 6]) if isinstance(x, Violation) else x for i, x in enumerate(infos)]
    stats = predicted_stats(infos, *problem.weights)
    return Found(
        k,
        "hand-anchored, refined",
        u,
        problem.space.to_poses(u),
        stats.score,
        stats,
    )


def distinct_sensors(sensors: list[np.ndarray], min_distance: float = 0.02) -> list[np.ndarray]:
    """The sensors (6,) each, without repeats within ``min_distance`` (in [0, 1] units), in their order."""
    kept: list[np.ndarray] = []
    for u6 in sensors:
        if apart(u6, kept, min_distance):
            kept.append(np.asarray(u6, dtype=float))
    return kept
