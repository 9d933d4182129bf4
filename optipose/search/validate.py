"""Stage: validation. The found layouts and the hand-placed one on the objective's protocol (``quick``: the
reduced one) with a noise seed the search never saw (:func:`optipose.seeds.validation_seed`); these are
the numbers reported. Under a band of conditions every layout is evaluated at each of them (the bracket
errors drawn from the held-out seed too), and each choice carries its statistics per noise level (the
worst over that level's bracket draws: :func:`optipose.evaluate.robust.by_level`)."""

from __future__ import annotations

import numpy as np

from optipose.evaluate.robust import choice_of, make_evaluator
from optipose.evaluate.objective import reduced_objective
from optipose.model.layout import Layout
from optipose.search.records import Validation
from optipose.seeds import validation_seed
from optipose.model.baseline import baseline

__all__ = ["validate", "nested_groups", "indices_in"]


def validate(part, objective, layouts: dict[int, Layout], seed: int, jobs: int = 1, protocol: str = "full",
             on_evaluation=None) -> Validation:  # fmt: skip
    """Evaluate ``layouts`` (k → found layout) and the part's hand layout on the held-out seed of ``seed``.

    on_evaluation(name, result) : told of each evaluation as it ends (``found_k3``, ``hand``), so it can
    be saved before the next one starts.
    """
    vseed = validation_seed(seed)
    if protocol == "reduced":
        objective = reduced_objective(objective)
    done = on_evaluation or (lambda name, result: None)
    found, hand = {}, {}
    with make_evaluator(part, objective, seed=vseed, jobs=jobs) as evaluator:
        for members in nested_groups(layouts):
            big = layouts[max(members)]
            result = evaluator(big)
            done(f"found_k{max(members)}", result)
            for k in members:
                found[k] = choice_of(result, tuple(indices_in(layouts[k], big)))
        if baseline(part) is not None:
            result = evaluator(baseline(part))
            done("hand", result)
            hand = {choice.k: choice for choice in result.table if choice.k in layouts}
    return Validation(protocol, vseed, found, hand)


def nested_groups(layouts: dict[int, Layout]) -> list[list[int]]:
    """Which found layouts can share one evaluation: a layout whose poses all belong to a larger one.
    Each group lists the largest k first."""
    groups: list[tuple[list[np.ndarray], list[int]]] = []
    for k in sorted(layouts, reverse=True):
        poses = layouts[k].poses
        for pool, members in groups:
            if all(any(np.allclose(T, P) for P in pool) for T in poses):
                members.append(k)
                break
        else:
            groups.append((list(poses), [k]))
    return [members for _, members in groups]


def indices_in(layout: Layout, big: Layout) -> list[int]:
    """Indices in ``big`` of the poses of ``layout``."""
    return [next(i for i, P in enumerate(big.poses) if np.allclose(T, P)) for T in layout.poses]
