"""The middle fidelity: pick each k's finalist by real ICP on a reduced protocol, and polish it there.

The surrogate (:mod:`optipose.search.surrogate`) predicts the noise and the voxel-centroid bias of a
registration from one nominal scan turned in place; it ranks well but its optimum is where its errors
favour it most. So the search ends by running the objective's own registration: every candidate of k
sensors (the greedy and joint winners, the best hand-placed k-subset, and the best distinct layouts of
the surrogate history) is evaluated on a reduced protocol — each sequence at its two end angles, 14 scans
instead of 77 — with a *selection* noise seed. The kept one is, among the candidates no worse than the
hand-placed layout on any axis, the lowest score (else simply the lowest score). For k ≥ 2 one candidate
is the (k−1) finalist plus one sensor, so nested layouts keep the smaller choices.

When the finalist is not yet no worse than the hand-placed layout on every axis and twice as good in sum
(the product's promise), an **ICP polish** runs a local NLopt search (``polish_algorithm``) on the
reduced protocol itself, for ``polish_evals`` evaluations (half for k ≥ 2) shared by its starts: the
finalist, the candidate closest to beating the hand layout on every axis, and for one sensor the
hand-placed sensor. It scores the sum plus ``polish_weight`` × every axis's median and 75th percentile
above ``polish_margin`` × the hand layout's (constraints as in the search).

A 14-scan median and 75th percentile are noisy: a polish tuned on them can win there and lose on a fresh
seed. So when the best of a k beats the hand layout by less than ``polish_margin`` on some axis or
``clear_ratio`` in sum, or when a polish ran (it minimised those very statistics, so its winner's are
biased low), its ``confirm_candidates`` best distinct layouts and the hand layout re-run the
objective's full protocol (still the selection seed) and the best there is kept, together with the
candidate whose axes exceed the hand layout's least. The hand layout's own 14-scan statistics are just as
noisy, so with confirmation on, the bar every candidate and the polish are measured against is the hand
layout on the full protocol. The full protocol with the held-out seed then reports the finalist.
"""

from __future__ import annotations

import itertools
import logging
import time
from dataclasses import replace

import numpy as np

from optipose.seeds import selection_seed
from optipose.search.core import Found, SearchOutcome, SurrogateProblem, apart

__all__ = ["reduced_objective", "select_finalists", "selection_seed"]

log = logging.getLogger(__name__)


def reduced_objective(objective):
    """The objective with each sequence cut to its two end angles (start and stop)."""
    p = objective.protocol
    if p.kind != "sequences":
        return replace(objective, protocol=replace(p, count=max(4, p.count // 5)))
    return replace(objective, protocol=replace(p, step=max(p.stop - p.start, 1e-9)))


def _distinct(candidates: list[Found], min_distance: float = 0.05, key=None) -> list[Found]:
    """Drop candidates whose parameters lie within ``min_distance`` (in [0, 1] units) of a better one
    (better: lower ``key(candidate)``, by default the surrogate score)."""
    kept: list[Found] = []
    for c in sorted(candidates, key=key or (lambda f: f.score)):
        if apart(c.u, [k.u for k in kept if len(k.u) == len(c.u)], min_distance):
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


def _extended(problem: SurrogateProblem, base: Found, others: list[Found]) -> Found | None:
    """``base`` (k-1 sensors) plus the one sensor of ``others`` that the surrogate likes best with it.
    Nested layouts keep every smaller choice available to the per-axis assignment, so k sensors never
    do worse than the k-1 they contain."""
    best = None
    for other in others:
        for i in range(other.k):
            u = np.concatenate([base.u, other.u[6 * i : 6 * i + 6]])
            value, stats = problem.evaluate(u)
            if stats is not None and (best is None or value < best.score):
                best = Found(base.k + 1, f"k={base.k} finalist + 1", u, problem.space.to_poses(u), value, stats)
    return best


def _row(k: int, origin: str, surrogate_deg: float, choice, protocol: str, dominates: bool) -> dict:
    """One line of ``selection.csv``: where a layout came from, its surrogate score, and its ICP score and
    per-axis median / 75th percentile (degrees, with the subset used) on the reduced or full protocol."""
    row = {"k": k, "origin": origin, "surrogate_deg": surrogate_deg, "protocol": protocol,
           "score_deg": float(np.rad2deg(choice.score)), "dominates_hand": dominates}  # fmt: skip
    for a in choice.axes:
        row |= {f"{a.axis}_median_deg": float(np.rad2deg(a.median)), f"{a.axis}_p75_deg": float(np.rad2deg(a.p75)), f"{a.axis}_subset": a.subset}
    return row


def _dominates(choice, reference) -> bool:
    """Every axis's median and 75th percentile at most the reference's."""
    return all(a.median <= b.median and a.p75 <= b.p75 for a, b in zip(choice.axes, reference.axes))


def _rank(choice, reference) -> tuple[bool, float]:
    """Sort key of a choice against the hand-placed reference: those no worse on every axis first, then
    the lower score (no reference: every choice counts as no worse)."""
    return (reference is not None and not _dominates(choice, reference), choice.score)


def _excess(choice, reference, margin: float) -> float:
    """How far (rad, summed) the choice's per-axis medians and 75th percentiles exceed margin × the reference's."""
    return float(sum(max(0.0, a.median - margin * b.median) + max(0.0, a.p75 - margin * b.p75) for a, b in zip(choice.axes, reference.axes)))


def polish(problem: SurrogateProblem, evaluator, start: Found, reference, config, max_evals: int, max_time: float, on_stage=None):
    """Local NLopt search from ``start`` on the reduced-protocol ICP score plus the hand-dominance penalty,
    ``max_evals`` evaluations (``max_time`` s is a safety net: evaluations, not the clock, should end it,
    so that a seed gives the same layout on a busy machine).

    Returns the best feasible layout seen that is no worse than ``reference`` on any axis (or the lowest
    penalised score when none is) as a :class:`Found`, its choice, and one row per evaluation.
    """
    import nlopt

    from optipose.search.core import PENALTY, _algorithm

    k, rows, best = start.k, [], [None, None, None]  # key, u, choice
    deadline = time.monotonic() + max_time

    def f(u, grad=None):
        if time.monotonic() > deadline:
            raise nlopt.ForcedStop
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        value, stats = problem.evaluate(u)
        if stats is None:
            return float(value)  # PENALTY + violation: infeasible, never a result
        choice = evaluator(problem.space.to_poses(u)).table[k - 1]
        excess = _excess(choice, reference, config.polish_margin) if reference is not None else 0.0
        score = float(np.rad2deg(choice.score + config.polish_weight * excess))
        dominates = reference is None or _dominates(choice, reference)
        rows.append(_row(k, "ICP polish", value, choice, "reduced", dominates))
        key = (not dominates, float(np.rad2deg(choice.score)) if dominates else score)
        if best[0] is None or key < best[0]:
            best[:] = [key, u.copy(), choice]
        if on_stage:
            on_stage(f"ICP polish k={k}: {len(rows)} evaluations, best {best[0][1] * 1e3:.3f} mdeg"
                     f"{'' if not best[0][0] else ' (not yet no worse than hand on every axis)'}")  # fmt: skip
        return score if score < PENALTY else PENALTY

    n = len(start.u)
    opt = nlopt.opt(_algorithm(config.polish_algorithm), n)
    opt.set_lower_bounds(np.zeros(n))
    opt.set_upper_bounds(np.ones(n))
    opt.set_min_objective(f)
    opt.set_maxeval(int(max_evals))
    opt.set_initial_step(np.full(n, config.polish_step))
    opt.set_xtol_abs(1e-4)
    try:
        opt.optimize(np.clip(start.u, 0.0, 1.0))
    except (nlopt.ForcedStop, nlopt.RoundoffLimited):
        pass
    except RuntimeError as exc:
        log.warning("ICP polish stopped: %s", exc)
    if best[1] is None:
        return None, None, rows
    u = best[1]
    value, stats = problem.evaluate(u)
    return Found(k, "ICP polish", u, problem.space.to_poses(u), value, stats or {}), best[2], rows


def _hand_start(problem: SurrogateProblem, part, reference) -> list[Found]:
    """The hand-placed sensors of the reference choice (e.g. ``S3``) as a polish start: it is no worse than
    itself on every axis, so a local search from it that keeps that while lowering the sum is what a user
    who already owns these mounts wants."""
    from optipose.evaluate.assignment import subset_name

    hand = part.layouts["hand"]
    combos = [c for c in itertools.combinations(range(len(hand.names)), reference.k) if subset_name(c, hand.names) == reference.sensors]
    if not combos:
        return []
    picked = combos[0]
    u = np.concatenate([problem.space.from_pose(hand.poses[i]) for i in picked])
    return [Found(reference.k, "hand start", u, problem.space.to_poses(u), problem.evaluate(u)[0], {})]


def _clear(choice, reference, config) -> bool:
    """The choice beats the reference with room to spare: every axis at most ``polish_margin`` × the
    reference's and the sum at most ``clear_ratio`` × its sum. A win that wide on a 14-scan sample needs
    no confirmation (unless a polish produced it); anything less does."""
    return _excess(choice, reference, config.polish_margin) == 0.0 and choice.score <= config.clear_ratio * reference.score


def _candidates(problem: SurrogateProblem, outcome: SearchOutcome, k: int, per_k: int, finalists: dict[int, Found]) -> list[Found]:
    """The k-sensor layouts worth an ICP look: the surrogate's winners, the best distinct layouts of its
    history, k-subsets of the larger layouts and the (k-1) finalist plus one sensor."""
    candidates = [f for f in (outcome.found.get(k), outcome.greedy.get(k), outcome.joint.get(k)) if f and f.stats]
    n = per_k * (4 if k == 1 else 2 if k == 2 else 1)  # a one-sensor candidate costs a third of a three-sensor one
    candidates = _distinct(candidates + _history_candidates(problem, k, n), 0.02)[:n]
    candidates += _sub_layouts(problem, outcome, k, candidates)
    if k - 1 in finalists:
        nested = _extended(problem, finalists[k - 1], candidates)
        candidates += [nested] if nested is not None else []
    return candidates


def select_finalists(part, objective, outcome: SearchOutcome, problem: SurrogateProblem, seed: int,
                     per_k: int = 3, max_time: float = np.inf, on_stage=None, jobs: int = 1) -> tuple[dict[int, Found], list[dict]]:  # fmt: skip
    """For every k, evaluate the candidates on the reduced protocol, polish the best when it does not yet
    beat the hand-placed layout, confirm the leaders on the full protocol when the win is narrow, and keep
    the best: among those no worse than the hand-placed layout on any axis, the lowest score; when none is,
    the lowest score. Every ICP run here uses the selection noise seed; the validation's seed stays unseen.

    Returns the finalists per k (``strategy`` tells where each came from) and one row per evaluation
    (k, origin, surrogate score, reduced- or full-protocol score in degrees, whether it dominates the hand
    layout on that protocol).
    """
    from optipose.evaluate.evaluator import Evaluator

    deadline = time.monotonic() + max_time
    config = problem.config
    finalists, rows = {}, []
    confirmer = _Confirmer(part, objective, selection_seed(seed), jobs) if config.confirm_candidates > 0 else None
    with Evaluator(part, reduced_objective(objective), seed=selection_seed(seed), jobs=jobs, quiet=True) as evaluator:
        hand = evaluator(part.layouts["hand"]) if "hand" in part.layouts else None
        for k in sorted(outcome.found):
            reference = hand.table[k - 1] if hand is not None and k <= len(hand.table) else None
            if reference is not None:
                rows.append(_row(k, "hand", np.nan, reference, "reduced", True))
                if confirmer is not None:
                    # the bar to clear is the hand layout's full-protocol statistics (selection seed): on 14
                    # scans it is itself a noisy draw (B's S1 pitch median 0.059 mdeg there, 0.098 on all 77),
                    # and a polish aimed at a lucky low chases noise instead of the axis
                    reference = confirmer.reference(on_stage).table[k - 1]
                    rows.append(_row(k, "hand", np.nan, reference, "full", True))
            pool: list[tuple[tuple, Found, object]] = []  # (key, layout, its choice) of every ICP evaluation here
            for cand in _candidates(problem, outcome, k, per_k, finalists):
                if time.monotonic() > deadline and pool:
                    log.info("selection for k=%d stopped by the time budget", k)
                    break
                if on_stage:
                    on_stage(f"selecting k={k} on the reduced protocol ({cand.strategy})")
                choice = evaluator(cand.poses).table[k - 1]
                rank = _rank(choice, reference)
                pool.append((rank, cand, choice))
                rows.append(_row(k, cand.strategy, cand.score, choice, "reduced", not rank[0]))
            if not pool:
                continue
            key, best, choice = min(pool, key=lambda t: t[0])
            short = reference is not None and (key[0] or key[1] > reference.score / 2)
            polished = short and config.polish_evals > 0
            if polished:  # not yet no worse on every axis and 2x better in sum
                # from the finalist, from the candidate closest to beating the hand layout on every axis and,
                # for one sensor, from the hand-placed sensor, sharing the evaluations; more sensors (2-3x the
                # scans per evaluation) get half the evaluations
                starts = [best] + _nearest(pool, reference, best) + (_hand_start(problem, part, reference) if k == 1 else [])
                evals = config.polish_evals if k == 1 else config.polish_evals // 2
                for start in starts:
                    found, p_choice, polish_rows = polish(
                        problem, evaluator, start, reference, config, evals // len(starts), config.polish_time / len(starts), on_stage
                    )
                    rows += polish_rows
                    if found is not None:
                        pool.append((_rank(p_choice, reference), found, p_choice))
                key, best, choice = min(pool, key=lambda t: t[0])
            # a polish minimised these very 14-scan statistics, so its winner's are biased low (B's one sensor:
            # pitch 0.086 / 0.191 mdeg there, 0.115 / 0.234 on the held-out seed): after a polish, always confirm
            if confirmer is not None and reference is not None and (polished or not _clear(choice, reference, config)):
                near = _closest(pool, reference)
                best = confirmer.pick(k, [(kk, f) for kk, f, _ in pool], config.confirm_candidates, rows, on_stage, near)
            finalists[k] = best
    if confirmer is not None:
        confirmer.adopt_subsets(problem, finalists, rows, on_stage)
    return finalists, rows


def _closest(pool: list[tuple[tuple, Found, object]], reference) -> Found:
    """The candidate whose per-axis statistics exceed the reference's least (ties: the better rank)."""
    return min(pool, key=lambda t: (_excess(t[2], reference, 1.0), t[0]))[1]


def _nearest(pool: list[tuple[tuple, Found, object]], reference, best: Found) -> list[Found]:
    """The closest candidate (:func:`_closest`), when that is not ``best``: the lowest sum can sit far from
    dominance while a slightly worse sum is one axis away from it."""
    near = _closest(pool, reference)
    return [] if near is best else [near]


class _Confirmer:
    """Re-runs the leading candidates of a k on the objective's full protocol (selection seed) and picks
    the best there: a 14-scan median and 75th percentile are noisy enough that a polish tuned on them
    can win there and lose on a fresh seed (part C did)."""

    def __init__(self, part, objective, seed: int, jobs: int):
        from optipose.evaluate.evaluator import Evaluator

        self.part, self.evaluator = part, Evaluator(part, objective, seed=seed, jobs=jobs, quiet=True)
        self._hand = None
        self._results: dict[bytes, object] = {}  # layout parameters -> its full-protocol evaluation
        self.chosen: dict[int, tuple] = {}  # k -> key of the confirmed finalist

    def reference(self, on_stage=None):
        if self._hand is None:
            if on_stage:
                on_stage("confirming on the full protocol: the hand-placed layout")
            self._hand = self.evaluator(self.part.layouts["hand"])
        return self._hand

    def evaluate(self, layout: Found):
        key = np.asarray(layout.u, dtype=float).tobytes()
        if key not in self._results:
            self._results[key] = self.evaluator(layout.poses)
        return self._results[key]

    def pick(self, k: int, pool: list[tuple[tuple, Found]], n: int, rows: list[dict], on_stage=None, near: Found | None = None) -> Found:
        """The best on the full protocol of the n leaders of ``pool`` (by their reduced-protocol rank) and
        ``near``, the one whose axes exceed the hand layout's least there: on 14 scans a layout that truly
        beats the hand one on every axis can miss on one axis and rank below wider but lopsided wins (B's
        one sensor did)."""
        reference = self.reference(on_stage).table[k - 1]
        keys = {id(f): key for key, f in pool}
        leaders = _distinct([f for _, f in pool], 0.02, key=lambda f: keys[id(f)])[:n]
        if near is not None and apart(near.u, [f.u for f in leaders], 0.02):
            leaders.append(near)
        best, best_key = None, None
        for cand in leaders:
            if on_stage:
                on_stage(f"confirming k={k} on the full protocol ({cand.strategy})")
            choice = self.evaluate(cand).table[k - 1]
            rank = _rank(choice, reference)
            rows.append(_row(k, f"confirm: {cand.strategy}", cand.score, choice, "full", not rank[0]))
            if best_key is None or rank < best_key:
                best, best_key = cand, rank
        self.chosen[k] = best_key
        return best

    def adopt_subsets(self, problem: SurrogateProblem, finalists: dict[int, Found], rows: list[dict], on_stage=None) -> None:
        """A confirmed k finalist gives way to the best k sensors of a larger finalist when those do better
        on the full protocol: the per-axis assignment of a triple's evaluation is a pair result as well,
        and the validation evaluates such a nested layout inside the larger one, as here."""
        from optipose.evaluate.assignment import subset_name

        for k, key in sorted(self.chosen.items()):
            reference = self.reference(on_stage).table[k - 1]
            for big in [finalists[kk] for kk in sorted(finalists) if kk > k]:
                if on_stage:
                    on_stage(f"confirming k={k}: the best {k} of the k={big.k} finalist")
                result = self.evaluate(big)
                choice = result.table[k - 1]
                combo = next(c for c in itertools.combinations(range(big.k), k) if subset_name(c, result.layout.names) == choice.sensors)
                u = np.concatenate([big.u[6 * i : 6 * i + 6] for i in combo])
                value, stats = problem.evaluate(u)
                rank = _rank(choice, reference)
                rows.append(_row(k, f"best {k} of the k={big.k} finalist", value, choice, "full", not rank[0]))
                if stats is not None and rank < key:
                    finalists[k] = Found(k, f"best {k} of the k={big.k} finalist", u, problem.space.to_poses(u), value, stats)
                    key = self.chosen[k] = rank
