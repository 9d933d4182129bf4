"""The objective each stage of the search scores with, derived in one place from the search's objective.

The search is given one objective (protocol, registration, statistic and, perhaps, a band of conditions);
each stage runs it at the fidelity its number of evaluations affords:

| stage | objective (:func:`stage_objective`) | protocol | conditions |
| --- | --- | --- | --- |
| ``surrogate`` (screen, greedy, joint, candidates) | the objective as given | its turns (:func:`optipose.search.surrogate.protocol_turns`) | every noise level and the brackets, predicted without ICP |
| ``selection``, ``polish`` | :func:`reduced_objective` of :func:`search_objective` | each sequence at its two ends | the band's ends |
| ``confirmation`` | :func:`search_objective` | the full protocol | the band's ends |
| ``validation`` | :func:`validation_objective` | the full protocol (``quick``: the reduced one) | the whole band |
| ``band`` (the check after a nominal search) | :func:`band_objective`, then validated as above | as the validation | another objective's band |

The ICP stages' noise seeds are not part of the objective: :mod:`optipose.seeds` derives them. ``reduced_objective``
is :mod:`optipose.evaluate.objective`'s (the evaluator's sensitivity study uses it too; ``evaluate`` never imports
``search``).
"""

from __future__ import annotations

from dataclasses import replace

from optipose.evaluate.conditions import band_ends
from optipose.evaluate.objective import Objective, load_objective, reduced_objective

__all__ = [
    "STAGES",
    "stage_objective",
    "search_objective",
    "reduced_objective",
    "validation_objective",
    "band_objective",
]

STAGES = ("surrogate", "selection", "polish", "confirmation", "validation", "band")


def stage_objective(objective: Objective, stage: str, protocol: str = "full", band: str = "") -> Objective | None:
    """The objective ``stage`` (one of :data:`STAGES`) scores with, from the search's ``objective``.

    protocol : the validation's, ``full`` or ``reduced`` (``SearchConfig.validation.protocol``); band : the name or
    TOML path of the objective whose band the found layouts are checked under (``SearchConfig.validation.band_objective``). Only
    ``band`` can be None: no check (see :func:`band_objective`).
    """
    if stage == "surrogate":
        return objective
    if stage in ("selection", "polish"):
        return reduced_objective(search_objective(objective))
    if stage == "confirmation":
        return search_objective(objective)
    if stage == "validation":
        return validation_objective(objective, protocol)
    if stage == "band":
        return band_objective(objective, band)
    raise ValueError(f"no stage '{stage}' (stages: {', '.join(STAGES)})")


def search_objective(objective: Objective) -> Objective:
    """The objective the ICP stages (selection, polish, confirmation) score with: under a band, the band's
    ends (:func:`optipose.evaluate.conditions.band_ends`); validation runs the whole band."""
    return objective if objective.conditions.trivial else replace(objective, conditions=band_ends(objective.conditions))


def validation_objective(objective: Objective, protocol: str = "full") -> Objective:
    """The objective the validation evaluates with: the objective's own, or (``reduced``) its reduced protocol."""
    return reduced_objective(objective) if protocol == "reduced" else objective


def band_objective(objective: Objective, band: str) -> Objective | None:
    """The objective the found layouts are checked under after the validation (``SearchConfig.validation.band_objective``): the
    search's own, with the ``[conditions]`` of the objective ``band`` (a shipped name or a TOML path); None
    when there is no check (``band`` empty, or the search's objective has a band of its own, under which it
    validates already). A bad name is a ConfigError."""
    if not band or not objective.conditions.trivial:
        return None
    given = load_objective(band)
    if given.conditions.trivial:
        return None
    return replace(objective, name=f"{objective.name} under the band of {given.name}", conditions=given.conditions)
