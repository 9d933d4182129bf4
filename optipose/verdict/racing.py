"""Racing: paired draws added until a verdict is clear or a budget ends (issue #33).

:func:`race` adds draws until the decision (:func:`optipose.verdict.confidence.compare_draws`) is not
UNDECIDED or a budget ends, deciding only at a few :func:`looks`, planned at the first from the draws the
time holds, each at the share of the error rate :func:`spent` gives it; :func:`race_many` does it for several k at once (one draw
evaluates every found layout and the hand one).
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Callable, Sequence

from optipose.verdict.confidence import ConfidentVerdict, Decision, PairedDraw, compare_draws
from optipose.verdict.rules import Rules

__all__ = ["SPENDING", "looks", "race", "race_many", "spent"]

# the error rate spent by a share t of the planned draws, α·t^ρ (Kim & DeMets 1987, Biometrika 74:149; Jennison &
# Turnbull 2000, §7.2): ρ = 3 is close to O'Brien & Fleming's boundaries, ρ = 1 to Pocock's. At 2 a middle look
# spends enough for a layout that cannot gain the tolerance to be turned away there (the futility stop) while the
# last look, where a close gap is decided, still keeps most of the 5 % (docs/method.md, "The verdict with confidence")
SPENDING = 2.0


def looks(min_draws: int, max_draws: int) -> tuple[int, ...]:
    """The draw counts at which :func:`race` decides: ``min_draws``, then half as many again each time, and
    ``max_draws``. Each look spends its share of the error rate (:func:`spent`), the shares summing to it
    (Bonferroni), so that racing does not buy more often than one fixed comparison."""
    out, n = [], max(1, min_draws)
    while n < max_draws:
        out.append(n)
        n = max(n + 1, math.ceil(1.5 * n))
    return tuple(out + [max_draws])


def spent(n: int, plan: Sequence[int], rho: float = SPENDING) -> float:
    """The share of the error rate the looks of ``plan`` up to and including the one at ``n`` draws spend:
    (n / the plan's last) ** ``rho``, 1 from the last on. Fixed by the plan, never by the draws' errors."""
    return 1.0 if n >= plan[-1] else (n / plan[-1]) ** rho


def _planned(n: int, max_draws: int, seconds_left: float, per_draw: float) -> int:
    """The draws a race plans for at its first look (``n`` draws in): ``max_draws``, or as many as the time
    left holds at the seconds a draw took (not fewer than ``n``). Set from the clock, never from the draws'
    errors, so that each look's share of the error rate is fixed before its draws are seen."""
    if not math.isfinite(seconds_left) or not per_draw > 0:
        return max_draws
    return max(n, min(max_draws, n + int(seconds_left // per_draw)))


def race(
    next_draw: Callable[[int], PairedDraw],
    rules: Rules = Rules(),
    *,
    min_draws: int = 3,
    max_draws: int = 20,
    seconds: float = math.inf,
    clock: Callable[[], float] = time.monotonic,
    draws: Sequence[PairedDraw] = (),
    rho: float = SPENDING,
    **names,
) -> ConfidentVerdict:
    """Add draws (``next_draw(i)``: the paired draw at position i, the ``draws`` given first) until the
    decision at one of the :func:`looks` is not UNDECIDED, or ``max_draws`` are in, or another draw would end
    past ``seconds`` (at the mean time a draw took so far; then a last look at the draws in). The looks are
    planned at the first: up to ``max_draws``, or to the draws the ``seconds`` left hold at the time a draw took
    (:func:`_planned`). Each look's intervals are at confidence 1 − (1 − ``rules.confidence``) · its share
    (:func:`spent`), and a last look the time forces early spends what the looks it leaves unmade would; the verdict carries its
    confidence, with the seconds a draw took. ``names``: ``k``, ``found_name``, ``baseline_name``, ``reference`` for :func:`compare_draws`."""
    verdicts = race_many(
        lambda i, keys: {0: next_draw(i)},
        rules,
        min_draws=min_draws,
        max_draws=max_draws,
        seconds=seconds,
        clock=clock,
        draws={0: list(draws)} if draws else None,
        names={0: names},
        rho=rho,
    )
    return verdicts[0]


def race_many(
    next_draws: Callable[[int, frozenset], dict],
    rules: Rules = Rules(),
    *,
    min_draws: int = 3,
    max_draws: int = 20,
    seconds: float = math.inf,
    clock: Callable[[], float] = time.monotonic,
    draws: dict | None = None,
    names: dict | None = None,
    passengers: frozenset = frozenset(),
    rho: float = SPENDING,
) -> dict:
    """:func:`race` for comparisons that share their draws: ``next_draws(i, keys)`` gives key → the paired draw at
    position i for at least the ``keys`` not yet decided (None before any draw: every key; a decided key's
    layouts need not be evaluated again), ``draws`` the draws in hand per key, ``names`` per key what
    :func:`compare_draws` takes. Draws are added until every key is decided (keeping the verdict of the look
    that decided it), or the draws or the ``seconds`` end. ``passengers``: keys that ride along without
    holding the race, compared at the look it ends on; ``rho``: the looks' spending (:func:`spent`). Returns key →
    :class:`ConfidentVerdict`."""
    taken = {key: list(v) for key, v in (draws or {}).items()}
    names = names or {}
    done: dict = {}
    plan: tuple[int, ...] = ()  # the looks, fixed at the first from the draws the time budget holds
    used, start, added = 0.0, clock(), 0  # used: the share of the error rate the looks made have spent
    while True:
        n = min((len(taken[key]) for key in (taken.keys() - done.keys() - passengers) or taken), default=0)
        elapsed = clock() - start
        per_draw = elapsed / added if added else math.nan
        out_of_time = bool(added) and elapsed + per_draw > seconds
        if n and not plan and (n >= min_draws or n >= max_draws or out_of_time):
            plan = looks(n, _planned(n, max_draws, seconds - elapsed, per_draw))
        last = n >= max_draws or out_of_time or bool(plan) and n >= plan[-1]
        if n and (n in plan or last):
            # each look spends its share of the error rate; the last spends what the plan's unmade looks leave
            share = (1.0 if last else spent(n, plan, rho)) - used
            each = replace(rules, confidence=1.0 - (1.0 - rules.confidence) * share)
            used += share
            for key in taken.keys() - done.keys() - passengers:
                verdict = compare_draws(taken[key], each, seconds_per_draw=per_draw, **names.get(key, {}))
                if verdict.decision == Decision.UNDECIDED and last:  # open: say whether draws or a clock ended it
                    verdict = replace(verdict, ended="draws" if n >= max_draws else "clock")
                if verdict.decision != Decision.UNDECIDED or last:
                    done[key] = verdict
            if not taken.keys() - done.keys() - passengers:
                riders = {
                    key: compare_draws(taken[key], each, seconds_per_draw=per_draw, **names.get(key, {}))
                    for key in passengers & taken.keys()
                }
                return {key: (done | riders)[key] for key in taken}
        pending = taken.keys() - done.keys() - passengers  # after this look's decisions
        given = next_draws(n, frozenset(pending) if taken else None)
        if not given or pending - given.keys():  # a key no draw comes for would hold the race forever
            raise ValueError(
                f"next_draws gave no paired draw for {sorted(map(str, pending - given.keys())) or 'any key'} at position {n}"
            )
        for key, pair in given.items():
            taken.setdefault(key, []).append(pair)
        added += 1
