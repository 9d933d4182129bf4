"""Stage: the verdict with confidence. Found vs. hand per k on paired draws, raced until it is clear.

In the ideal cell the validation's evaluations (the held-out seed) are the first draw; in a real cell they are
not, since each layout's choice was made on them (:func:`choice_draw_counts`). Each further draw is one seed of its own
(:func:`optipose.seeds.verdict_seed`, never seen by the search or the validation) on which every found layout
and the hand one are evaluated with the validation's objective: one evaluator per draw, so both sides get the
same cell instance (the part as made, the calibration), the same protocol orientations, robot paths and
scan noise (common random numbers). Each layout keeps the choice the validation made for it (its subset per
axis); a draw gives that choice's per-scan errors (:func:`optipose.verdict.confidence.scan_errors`), and
registers only the subsets the choices use (``Evaluator(...)(layout, subsets=...)``). A k the search answered with
the hand layout's own choice (:func:`optipose.search.validate.baseline_where_better`) is not evaluated: its side is the
hand layout's evaluation with that choice, an exact TIE that rides along without holding the race (when every k is
one, they are the race, decided at one look at its last draw: the draws go to the hand layout's predicted error, at
most :data:`KEPT_DRAWS`).

Draws are added (:func:`optipose.verdict.racing.race_many`) until every k is BUY, KEEP or TIE, or
``SearchConfig.verdict.draws`` are in, or another draw would end past ``SearchConfig.verdict.time``. In the
ideal cell a draw differs from the next only in its noise and orientations, which the scans' own spread
already measures: the first look is at one draw. In a real cell each draw is another instance of the cell,
whose spread only draws show: the first look is at three, and a draw may evaluate a seeded
share of the protocol's scans (``SearchConfig.verdict.scans``): more instances of fewer scans (docs/method.md,
"The verdict with confidence").
"""

from __future__ import annotations

import logging
import math
import string
import time
from dataclasses import replace

from optipose.cell.ranges import draws as cell_draws
from optipose.evaluate.evaluator import EvaluationResult, Evaluator, evaluate_many
from optipose.model.baseline import baseline, baseline_label
from optipose.model.layout import Layout, is_part_of
from optipose.parallel.executors import make_executor
from optipose.search.objectives import stage_objective
from optipose.search.records import Side, Validation
from optipose.search.validate import indices_in, nested_groups
from optipose.seeds import verdict_seed
from optipose.verdict.confidence import Rules, Verdicts, paired_draw
from optipose.verdict.racing import race_many
from optipose.verdict.ruling import draw_ratio, ruling

__all__ = ["choice_draw_counts", "confident_verdicts", "first_look", "sides"]

log = logging.getLogger(__name__)

# the draws of a race in which the search answered every k with the hand layout's own choice: each k is an exact TIE,
# so the draws only measure the hand layout's predicted error per axis (its interval's width ∝ 1/√draws)
KEPT_DRAWS = 20


def first_look(objective) -> int:
    """The draws the first look of the race waits for: one in the ideal cell, three in a real one."""
    return 1 if objective.cell.ideal else 3


def choice_draw_counts(objective) -> bool:
    """Whether the validation's draw, on which each layout's choice (its subset per axis) was made, is the
    race's first draw: in the ideal cell, where every draw is the one part and calibration and differs only in
    its noise and orientations; not in a real cell, where the choice fits that draw's instance of the cell (the
    part as made, the calibration) and flatters it (docs/method.md, "The verdict with confidence")."""
    return objective.cell.ideal


def confident_verdicts(
    part,
    objective,
    layouts: dict[int, Layout],
    validation: Validation,
    first: dict[str, EvaluationResult],
    seed: int,
    config,
    jobs: int = 1,
    on_draw=None,
) -> Verdicts:
    """The confident verdicts: per k ``layouts[k]`` against the part's baseline layout, and ``fewer``: one found
    sensor against the baseline's largest choice (on the same draws, without holding the race).

    first : the validation's evaluations by name (``found_k<k>`` of each nested group's largest k, ``hand``), the
    race's first draw where :func:`choice_draw_counts` (else not read);
    on_draw(i, name, result) : told of each further draw's evaluations as they end. Empty when the part has no
    baseline, the validation has no hand choice, or ``first`` lacks one the race needs."""
    baseline_layout = baseline(part)
    side = sides(layouts, validation, baseline_layout)
    ks = sorted(side)
    kept = {k for k, s in side.items() if s.kept}
    evaluated = {s.evaluation: layouts[int(s.evaluation.removeprefix("found_k"))] for s in side.values() if not s.kept}
    names = ["hand", *evaluated]
    objective = stage_objective(objective, "validation", config.validation.protocol)
    counted = choice_draw_counts(objective)
    missing = counted and not all(isinstance(first.get(n), EvaluationResult) for n in names)
    if baseline_layout is None or not ks or missing:
        return Verdicts()
    rules = config.verdict.rules(int(seed), objective.statistic)
    label = baseline_label(baseline_layout)
    labels = {
        (k, k): dict(
            k=k,
            found_name=validation.baseline[k].name,
            baseline_name=validation.baseline[k].name,
            reference=label,
            kept=True,
        )
        if k in kept
        else dict(
            k=k,
            found_name=_found_name(layouts[k], s.choice, evaluated[s.evaluation]),
            baseline_name=validation.baseline[k].name,
            reference=label,
        )
        for k, s in side.items()
    }
    done = on_draw or (lambda i, name, result: None)

    # the race's keys, (found k, hand k): each k against the hand's choice of as many, and one found sensor against
    # the hand's largest choice (``fewer``), which rides along
    top = max(validation.baseline)
    fewer = frozenset({(1, top)} if 1 in ks and top > 1 else ())
    compared = [(k, k) for k in ks] + sorted(fewer)
    for key in fewer:
        labels[key] = dict(labels[(1, 1)], baseline_name=validation.baseline[top].name, baseline_k=top)

    seen: dict = {}  # key → every paired draw the race was given, for what rules it across a cell's ranges

    def pairs(results: dict[str, EvaluationResult]) -> dict:
        out = {
            (f, h): paired_draw(results[side[f].evaluation], side[f].choice, results["hand"], validation.baseline[h])
            for f, h in compared
            if side[f].evaluation in results
        }
        for key, pair in out.items():
            seen.setdefault(key, []).append(pair)
        return out

    draws = {k: [p] for k, p in pairs(first).items()} if counted else None
    if counted and config.verdict.draws <= 1:
        return _verdicts(
            race_many(
                lambda i, keys: {},
                rules,
                min_draws=1,
                max_draws=1,
                draws=draws,
                names=labels,
                passengers=fewer,
            )
        )
    executor = make_executor(jobs)

    # a draw registers only the subsets the choices use (of the 2^n - 1 a layout has)
    used = {"hand": _used(validation.baseline[h] for _, h in compared)}
    used |= {name: _used(s.choice for s in side.values() if s.evaluation == name) for name in evaluated}

    ahead: dict[int, dict] = {}  # draws evaluated before the race asked for them (up to its next look)

    def evaluate(first_draw: int, count: int, keys) -> None:
        """Draws ``first_draw`` … ``first_draw + count - 1`` of the layouts the ``keys`` still need, in one map of
        the workers (a draw's few scans of one layout would leave a worker idle), into ``ahead``."""
        t0 = time.perf_counter()
        # a decided k's layout is not evaluated again
        wanted = ["hand"] + [
            name for name in evaluated if keys is None or any(side[f].evaluation == name for f, h in keys if f == h)
        ]
        layouts = {"hand": baseline_layout} | evaluated
        draws = range(first_draw, first_draw + count)
        evaluators = [
            Evaluator(
                part, objective, seed=verdict_seed(seed, i), quiet=True, executor=executor, scans=config.verdict.scans
            )
            for i in draws
        ]
        try:
            results = iter(evaluate_many([(ev, layouts[name], used[name]) for ev in evaluators for name in wanted]))
            for i in draws:
                ahead[i] = {name: next(results) for name in wanted}
        finally:
            for ev in evaluators:
                ev.close()
        log.info("verdict draws %d-%d in %.1f s", draws[0], draws[-1], time.perf_counter() - t0)

    def next_draws(n: int, keys) -> dict:
        i = n + (not counted)  # draw i's seed and folder: 0 is the validation's
        if i not in ahead:
            # the race looks first at its first look's draws (every draw, when every k is kept): no draw before it
            # can change what the race asks for, so they are evaluated together; later draws one at a time
            upto = (most if every_kept else first_look(objective)) if math.isinf(seconds) else 0
            evaluate(i, max(1, upto - n), keys)
        results = ahead.pop(i)
        for name, result in results.items():
            done(i, name, result)
        return pairs(results)

    # a k answered with the baseline's own choice is an exact TIE from the first draw: it rides along without
    # holding the race, and when every k is one, no draw can change a decision: the draws go to its predicted error
    # (one look, at the end), at most KEPT_DRAWS of them
    every_kept = kept == set(ks)
    riders = fewer | (frozenset((k, k) for k in kept) if not every_kept else frozenset())
    most = min(config.verdict.draws, KEPT_DRAWS) if every_kept else config.verdict.draws
    seconds = config.verdict.time if config.verdict.time > 0 else math.inf
    try:
        raced = race_many(
            next_draws,
            rules,
            min_draws=most if every_kept else first_look(objective),
            max_draws=most,
            seconds=seconds,
            draws=draws,
            names=labels,
            passengers=riders,
        )
    finally:
        executor.close()
    return _verdicts(_ruled(raced, seen, objective))


def _ruled(raced: dict, seen: dict, objective) -> dict:
    """The race's verdicts, each with the range of the objective's cell that rules it (:mod:`optipose.verdict.ruling`;
    none in a cell of points, or for a k the search answered with the hand layout's own choice)."""
    ranges = objective.cell.ranges
    if not ranges:
        return raced
    s = objective.statistic
    out = {}
    for key, v in raced.items():
        pairs = seen.get(key, []) if not v.kept else []
        ratios = [draw_ratio(p, s.weights, s.median_weight, s.p75_weight) for p in pairs]
        found = ruling(ratios, [cell_draws(ranges, p.seed) for p in pairs], ranges)
        out[key] = replace(v, ruling=found) if found else v
    return out


def _verdicts(raced: dict) -> Verdicts:
    """The race's verdicts by key, (found k, hand k), as one record: by k, and one found sensor against more."""
    fewer = [v for (f, h), v in raced.items() if f != h]
    return Verdicts({f: v for (f, h), v in raced.items() if f == h}, fewer[0] if fewer else None)


def sides(layouts: dict[int, Layout], validation: Validation, baseline_layout: Layout | None) -> dict[int, Side]:
    """k (each with a found and a hand choice) → the :class:`~optipose.search.records.Side` a draw pairs with the
    hand layout's evaluation for it: the evaluation ``hand`` and the hand's choice for a k the search answered with
    the hand layout's own sensors (:func:`optipose.search.validate.baseline_where_better`), else ``found_k<m>`` (the
    largest found layout that holds it, evaluated once for its nested group) and its found choice. The one rule the
    verdict and the benchmarks that read its stored draws pair by."""
    ks = [k for k in sorted(validation.found) if k in validation.baseline]
    kept = {k for k in ks if is_part_of(layouts[k], baseline_layout)}
    big = {k: max(g) for g in nested_groups({k: lay for k, lay in layouts.items() if k not in kept}) for k in g}
    return {
        k: Side("hand", validation.baseline[k]) if k in kept else Side(f"found_k{big[k]}", validation.found[k])
        for k in ks
    }


def _used(choices) -> list[tuple[int, ...]] | None:
    """The sensor subsets (index tuples) the choices' axes use, each once (None: no axis measured, every subset)."""
    return list(dict.fromkeys(a.subset for c in choices for a in c.axes if a.observable)) or None


def _found_name(layout: Layout, choice, big: Layout) -> str:
    """The found sensors the choice's axes use, in the k layout's own sensor names (F1 … Fk as its file and the
    report's poses say, not those of the larger layout it was evaluated inside): a sensor of the k layout that
    no axis measures on is not one to buy (what a BUY mounts is these, :func:`optipose.verdict.words.mount_line`).
    The choice's k sensors when no axis is measured."""
    own = {big.names[i]: name for i, name in zip(indices_in(layout, big), layout.names)}
    return "".join(sorted((own.get(big.names[i], big.names[i]) for i in choice.used or choice.sensors), key=_natural))


def _natural(name: str) -> tuple:
    """``F10`` after ``F9``: a name's letters, then its number."""
    head = name.rstrip(string.digits)
    return (head, int(name[len(head) :] or 0))
