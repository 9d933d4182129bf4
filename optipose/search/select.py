"""Stage: pick each k's finalist by real ICP on a reduced protocol, polish it there, confirm it on the full one.

The surrogate (:mod:`optipose.search.surrogate`) predicts the noise and the voxel-centroid bias of a
registration from one nominal scan turned in place; it ranks well but its optimum is where its errors
favour it most. So the search ends by running the objective's own registration: every candidate of k
sensors (:mod:`optipose.search.candidates`) is evaluated on a reduced protocol — each sequence at its two
end angles, 14 scans instead of 77 — with the *selection* noise seed. The kept one is, among the
candidates no worse than the hand-placed layout on any axis, the lowest score (else simply the lowest).

When the finalist is not yet no worse than the hand-placed layout on every axis and twice as good in sum
(the product's promise), the ICP polish (:mod:`optipose.search.polish`) runs from the finalist, from the
candidate closest to beating the hand layout on every axis and, for one sensor, from the hand-placed
sensor, sharing ``polish_evals`` evaluations (half for k ≥ 2).

When the best of a k beats the hand layout by less than ``polish_margin`` on some axis or ``clear_ratio``
in sum, or when a polish ran (it minimised those very statistics, so its winner's are biased low), the
confirmation (:mod:`optipose.search.confirm`) decides on the full protocol; with confirmation on, the bar
every candidate and the polish are measured against is the hand layout on the full protocol. The full
protocol with the held-out seed then reports the finalist (:mod:`optipose.search.validate`).

The objective given here is the search's; the selection and the polish score with its reduced protocol,
the confirmation with its full one (:func:`optipose.search.objectives.stage_objective`).
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from optipose.verdict.compare import excess, rank
from optipose.evaluate.evaluator import Evaluator
from optipose.search.candidates import anchored, candidates
from optipose.search.confirm import Confirmer
from optipose.search.objectives import stage_objective
from optipose.search.polish import baseline_start, polish
from optipose.search.records import Found, IcpEvaluation, SearchOutcome
from optipose.search.study import SurrogateStudy
from optipose.seeds import selection_seed
from optipose.model.baseline import baseline

__all__ = ["select_finalists", "clear_win", "closest", "nearest"]

log = logging.getLogger(__name__)

Pool = list[tuple[tuple, Found, object]]  # (rank, layout, its choice) of every ICP evaluation of a k


def select_finalists(
    part,
    objective,
    outcome: SearchOutcome,
    study: SurrogateStudy,
    seed: int,
    per_k: int = 3,
    max_time: float = np.inf,
    on_stage=None,
    jobs: int = 1,
) -> tuple[dict[int, Found], list[IcpEvaluation]]:
    """The finalist per k (``strategy`` tells where each came from) and one record per ICP evaluation.

    Every ICP run here uses the selection noise seed; the validation's seed stays unseen.
    """
    end = time.monotonic() + max_time
    config = study.problem.config
    finalists, records = {}, []
    confirmer = (
        Confirmer(part, stage_objective(objective, "confirmation"), selection_seed(seed), jobs)
        if config.selection.confirm_candidates > 0
        else None
    )
    with Evaluator(
        part,
        stage_objective(objective, "selection"),
        seed=selection_seed(seed),
        jobs=jobs,
        quiet=True,
        scans=config.selection.scans,
    ) as evaluator:
        baseline_result = evaluator(baseline(part)) if baseline(part) is not None else None
        ks = sorted(outcome.found)
        for n, k in enumerate(ks):
            reference = _reference(k, baseline_result, confirmer, records, on_stage)
            deadline = time.monotonic() + max(0.0, end - time.monotonic()) / (
                len(ks) - n
            )  # a fair share of what is left
            pool = _screen_candidates(
                part, study, outcome, k, per_k, finalists, evaluator, reference, records, deadline, on_stage
            )
            if not pool:
                continue
            key, best, choice = min(pool, key=lambda t: t[0])  # no worse on every axis first, then the lower sum
            polished = (
                reference is not None and (key[0] or key[1] > reference.score / 2) and config.selection.polish_evals > 0
            )
            if polished:  # not yet no worse on every axis and 2x better in sum
                best, choice = _polish(study, part, evaluator, pool, best, reference, records, on_stage)
            # a polish minimised these very 14-scan statistics, so its winner's are biased low: after a
            # polish, always confirm
            if (
                confirmer is not None
                and reference is not None
                and (polished or not clear_win(choice, reference, config))
            ):
                pool_layouts = [(kk, f) for kk, f, _ in pool]
                best = confirmer.pick(
                    k, pool_layouts, config.selection.confirm_candidates, records, on_stage, closest(pool, reference)
                )
            finalists[k] = best
    if confirmer is not None:
        confirmer.adopt_subsets(study.problem, finalists, records, on_stage)
    return finalists, records


def _reference(k: int, baseline_result, confirmer: Confirmer | None, records: list[IcpEvaluation], on_stage):
    """The bar of a k: the hand layout's choice, on the full protocol when confirmation is on (on 14 scans it
    is itself a noisy draw, and a polish aimed at a lucky low chases noise instead of the axis)."""
    reference = (
        baseline_result.table[k - 1] if baseline_result is not None and k <= len(baseline_result.table) else None
    )
    if reference is None:
        return None
    records.append(IcpEvaluation(k, "hand", np.nan, "reduced", reference, True))
    if confirmer is not None:
        reference = confirmer.reference(on_stage).table[k - 1]
        records.append(IcpEvaluation(k, "hand", np.nan, "full", reference, True))
    return reference


def _screen_candidates(
    part, study, outcome, k, per_k, finalists, evaluator, reference, records, deadline, on_stage
) -> Pool:
    """Every candidate of k on the reduced protocol, until the time is up (the best hand-anchored one and the
    surrogate's best at least): first the hand layout's used sensors with found ones in the other places
    (:func:`optipose.search.candidates.anchored`)."""
    pool: Pool = []
    first = []
    if reference is not None:
        used = reference.used
        cfg = study.problem.config
        first = anchored(
            study.problem,
            baseline(part).poses,
            used,
            outcome,
            k,
            evals=cfg.surrogate.anchor_evals,
            until=time.monotonic() + (deadline - time.monotonic()) / 2,
        )
    rest = candidates(study.problem, study.history, outcome, k, per_k, finalists)
    # whatever the clock says, the best hand-anchored layout and the surrogate's own best are evaluated: a
    # selection cut after the first of them would make the answer the machine's load, not the search's
    required = {0, len(first)}
    for n, cand in enumerate(first + rest):
        if time.monotonic() > deadline and pool and n not in required:
            if f"selection:k={k}" not in study.cut:  # what the user's clock cut, which the answer says
                study.cut.append(f"selection:k={k}")
            if n > len(first):
                log.info("selection for k=%d stopped by the clock", k)
                break
            continue
        if on_stage:
            on_stage(f"selecting k={k} on the reduced protocol ({cand.strategy})")
        choice = evaluator(cand.poses).table[k - 1]
        key = rank(choice, reference)
        pool.append((key, cand, choice))
        records.append(IcpEvaluation(k, cand.strategy, cand.score, "reduced", choice, not key[0]))
    return pool


def _polish(study, part, evaluator, pool: Pool, best: Found, reference, records, on_stage) -> tuple[Found, object]:
    """Polish from the finalist, the candidate closest to beating the hand layout and, for one sensor, the
    hand-placed sensor, sharing the evaluations; the polished layouts join ``pool``. Returns the new best."""
    config, k = study.problem.config, best.k
    starts = [best] + nearest(pool, reference, best)
    if k == 1:  # a reference means the part has a hand layout
        starts += baseline_start(study.problem, baseline(part), reference)
    evals = config.selection.polish_evals if k == 1 else config.selection.polish_evals // 2
    starts = starts[: evals // (6 * k + 2)]  # COBYLA needs 6k + 1 evaluations before its first step
    for start in starts:
        found, choice, polish_records = polish(
            study.problem,
            evaluator,
            start,
            reference,
            config,
            evals // len(starts),
            (config.selection.polish_time or math.inf) / len(starts),
            on_stage,
        )
        records += polish_records
        if found is not None:
            pool.append((rank(choice, reference), found, choice))
    _, best, choice = min(pool, key=lambda t: t[0])
    return best, choice


def clear_win(choice, reference, config) -> bool:
    """The choice beats the reference with room to spare: every axis at most ``polish_margin`` × the
    reference's and the sum at most ``clear_ratio`` × its sum. A win that wide on a 14-scan sample needs
    no confirmation (unless a polish produced it); anything less does."""
    return (
        excess(choice, reference, config.selection.polish_margin) == 0.0
        and choice.score <= config.selection.clear_ratio * reference.score
    )


def closest(pool: Pool, reference) -> Found:
    """The candidate whose per-axis statistics exceed the reference's least (ties: the better rank)."""
    return min(pool, key=lambda t: (excess(t[2], reference, 1.0), t[0]))[1]


def nearest(pool: Pool, reference, best: Found) -> list[Found]:
    """The closest candidate (:func:`closest`), when that is not ``best``: the lowest sum can sit far from
    dominance while a slightly worse sum is one axis away from it."""
    near = closest(pool, reference)
    return [] if near is best else [near]
