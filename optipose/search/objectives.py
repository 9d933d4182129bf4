"""The objective each stage of the search scores with, derived in one place from the search's objective.

The search is given one objective (protocol, registration, statistic, and the cell it runs in); each stage runs
it at the fidelity its number of evaluations affords:

| stage | objective (:func:`stage_objective`) | protocol |
| --- | --- | --- |
| ``surrogate`` (screen, greedy, joint, candidates) | the objective as given | its turns (:func:`optipose.search.surrogate.protocol_turns`) |
| ``selection``, ``polish`` | :func:`reduced_objective` | each sequence at its two ends |
| ``confirmation`` | the objective as given | the full protocol |
| ``validation`` | :func:`validation_objective` | the full protocol (``quick``: the reduced one) |

The ICP stages' noise seeds are not part of the objective: :mod:`optipose.seeds` derives them. ``reduced_objective``
is :mod:`optipose.evaluate.objective`'s (``evaluate`` never imports ``search``).
"""

from __future__ import annotations

from optipose.evaluate.objective import Objective, reduced_objective

__all__ = ["STAGES", "stage_objective", "reduced_objective", "validation_objective"]

STAGES = ("surrogate", "selection", "polish", "confirmation", "validation")


def stage_objective(objective: Objective, stage: str, protocol: str = "full") -> Objective:
    """The objective ``stage`` (one of :data:`STAGES`) scores with, from the search's ``objective``.

    protocol : the validation's, ``full`` or ``reduced`` (``SearchConfig.validation.protocol``).
    """
    if stage in ("surrogate", "confirmation"):
        return objective
    if stage in ("selection", "polish"):
        return reduced_objective(objective)
    if stage == "validation":
        return validation_objective(objective, protocol)
    raise ValueError(f"no stage '{stage}' (stages: {', '.join(STAGES)})")


def validation_objective(objective: Objective, protocol: str = "full") -> Objective:
    """The objective the validation evaluates with: the objective's own, or (``reduced``) its reduced protocol."""
    return reduced_objective(objective) if protocol == "reduced" else objective
