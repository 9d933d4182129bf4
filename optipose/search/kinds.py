"""Stage: a search's BUYs raced again where the user's cell may lie: in the common kinds of cell, for a user who
named none, or at the ends of the ranges of the cell the search ran in.

A search runs in its objective's cell (the paper's, ``ur10e``: one cell's points, fitted on part A) unless the user
names theirs. A BUY there is better in that cell; whether it is in the user's depends on magnitudes the user did not
give (docs/results.md, "The answer across a cell's ranges": a BUY of part A's single sensor in one cell was a KEEP
on a linear axis). So where the user named no cell, each BUY is raced again, with the choices of subsets the search
made, in each cell of ``SearchConfig.verdict.kinds`` (the presets of the common kinds: a cobot, an industrial arm, a
precision linear axis; each magnitude a range, each instance drawing its own). In a cell of ranges a BUY is better
across the draws of its magnitudes, on average; where it holds at one end and not at the other it depends on where
the user's cell lies, so there the kinds are the cell with every range at its low end and at its high end
(``NAME:low``, ``NAME:high``: :meth:`optipose.cell.config.Cell.at`). Each race is on draws of its own
(:func:`optipose.seeds.kind_seed`: none the search, its validation or its verdict saw), at most
``SearchConfig.verdict.kinds_draws`` of them (:func:`optipose.search.draws.confident_verdicts`, the same race). The
answer then says, per BUY, that it holds in each, or where it depends (:func:`optipose.verdict.words.kinds_line`);
a BUY not borne out in every one of them is UNDECIDED (:func:`qualified`): a user who names no cell is bought only
what holds across the common kinds. Nothing is raced for a TIE or a KEEP: there is nothing to buy.
"""

from __future__ import annotations

from dataclasses import replace

from optipose.search.draws import confident_verdicts
from optipose.seeds import kind_seed
from optipose.verdict.confidence import Decision, Verdicts, at_ends, borne_out

__all__ = ["COMMON_KINDS", "kinds_of", "buys", "across_kinds", "qualified"]

COMMON_KINDS = ("cobot", "industrial-arm", "linear-axis")  # cells/*.toml: the presets of the common kinds


def kinds_of(config) -> list[str]:
    """The cells a search config races its BUYs again in (``verdict.kinds``, comma-separated)."""
    return [name.strip() for name in config.verdict.kinds.split(",") if name.strip()]


def buys(verdicts: Verdicts) -> list[int]:
    """The k a search's verdicts BUY at."""
    return sorted(k for k, v in verdicts.by_k.items() if v.decision == Decision.BUY)


def across_kinds(
    part, objective, layouts, validation, verdicts: Verdicts, seed: int, config, jobs: int = 1, on_kind=None
) -> dict[str, Verdicts]:
    """Kind (a cell name) → the verdicts of the search's BUYs raced again in it, with their choices of subsets;
    empty when nothing was bought or no kinds are asked for. ``on_kind(name)`` is told as each kind starts."""
    ks, kinds = buys(verdicts), kinds_of(config)
    if not ks or not kinds:
        return {}
    bought = replace(
        validation,
        found={k: validation.found[k] for k in ks},
        baseline={k: validation.baseline[k] for k in ks},
    )
    raced = replace(config, verdict=replace(config.verdict, draws=config.verdict.kinds_draws))
    out = {}
    for i, name in enumerate(kinds):
        if on_kind:
            on_kind(name)
        # the race never reads the validation's evaluations in a real cell: its draws are all of the kind's own
        out[name] = confident_verdicts(
            part, objective.in_cell(name), layouts, bought, {}, kind_seed(seed, i), raced, jobs
        )
    return out


def qualified(verdicts: Verdicts, kinds: dict[str, Verdicts]) -> Verdicts:
    """The search's verdicts, each BUY that its races again did not bear out made UNDECIDED: at the ends of the
    cell's ranges (``ended = "ends"``: better across the ranges' draws on average, not shown at an end of them, it
    depends on where the user's cell lies) or in the common kinds of cell (``ended = "kinds"``: better in the
    objective's cell of points, which the user did not name, not in every kind: it depends on the user's kind of
    cell, and ``--cell`` answers for theirs). Their lines say where it holds
    (:func:`optipose.verdict.words.kinds_line`)."""
    if not kinds:
        return verdicts
    ended = "ends" if at_ends(kinds) else "kinds"
    open_ = [k for k in buys(verdicts) if not borne_out(k, kinds)]
    by_k = verdicts.by_k | {k: replace(verdicts.by_k[k], decision=Decision.UNDECIDED, ended=ended) for k in open_}
    fewer = verdicts.fewer
    if fewer is not None and fewer.decision == Decision.BUY and 1 in open_:  # its one sensor is k = 1's
        fewer = replace(fewer, decision=Decision.UNDECIDED, ended=ended)
    return replace(verdicts, by_k=by_k, fewer=fewer)
