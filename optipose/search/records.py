"""The search's records: what one evaluation gave, and what a stage found.

In the spirit of optuna's ``FrozenTrial`` / ``TrialState``: a :class:`LayoutScore` is the frozen answer of
the surrogate for one layout, with its :class:`EvalState` (feasible, or infeasible with the constraint it
violates and by how much); an :class:`Evaluation` is one row of the search's history; a :class:`Found` is a
layout a stage proposes; a :class:`Validation` is found vs. hand on the held-out seed (a search read back
from its folder, :class:`optipose.io.results.SearchResult`, holds its validations). Sensors are identified by
their place in the layout (``u[6i:6i+6]``); names (F1, F2, …) are given only when a layout is written.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from optipose.evaluate.assignment import Choice
from optipose.verdict.compare import Verdict
from optipose.verdict.words import one_versus_many, unmeasured_line, verdict_line

if TYPE_CHECKING:  # importing the surrogate loads the scanner; the records only name its type
    from optipose.search.surrogate import Prediction

__all__ = [
    "EvalState",
    "LayoutScore",
    "Evaluation",
    "Found",
    "IcpEvaluation",
    "SearchOutcome",
    "Validation",
    "Side",
    "PENALTY",
]

# what an optimiser sees for an infeasible layout: PENALTY + violation (the global NLopt algorithms worth
# using here take no constraints, so infeasibility is a wall that slopes back toward feasibility)
PENALTY = 1e3


class EvalState(enum.Enum):
    FEASIBLE = "feasible"
    INFEASIBLE = "infeasible"  # a constraint is violated: never a result
    FAILED = "failed"  # the evaluation itself gave no answer (e.g. every registration of an axis failed)


@dataclass(frozen=True)
class LayoutScore:
    """The surrogate's answer for one layout.

    value : deg, the predicted score plus the per-axis shortfall against the hand layout (NaN when infeasible).
    stats : the surrogate's Table 1 (:class:`optipose.search.surrogate.Prediction`), None when infeasible.
    violation : ≥ 0, normalised, how far the layout is from feasible; constraint : which one (first found).
    """

    value: float
    stats: Prediction | None = field(default=None, repr=False)
    violation: float = 0.0
    constraint: str = ""

    @property
    def state(self) -> EvalState:
        return EvalState.FEASIBLE if self.stats is not None else EvalState.INFEASIBLE

    @property
    def feasible(self) -> bool:
        return self.stats is not None

    @property
    def objective(self) -> float:
        """What an optimiser minimises: the value, or PENALTY + violation for an infeasible layout."""
        return self.value if self.stats is not None else PENALTY + self.violation


@dataclass(frozen=True)
class Evaluation:
    """One evaluation of the search's history (``history.csv``)."""

    number: int
    stage: str
    k: int
    u: tuple[float, ...]  # (6k,) in [0, 1], rounded to 9 decimals
    state: EvalState
    value: float  # what the optimiser saw (LayoutScore.objective)
    best: float  # the best feasible value of k sensors so far (NaN before the first)
    constraint: str = ""

    @property
    def feasible(self) -> bool:
        return self.state is EvalState.FEASIBLE


@dataclass(frozen=True)
class Found:
    """A layout of k sensors that a stage proposes, with its surrogate score.

    strategy : where it came from (greedy, joint, history, ICP polish, …); u : (6k,) in [0, 1];
    poses : k 4×4 ``T_O_S``; score : deg (LayoutScore.objective); stats : the surrogate's Table 1
    (:class:`optipose.search.surrogate.Prediction`), None when the stage has none (an ICP start).
    """

    k: int
    strategy: str
    u: np.ndarray = field(repr=False)
    poses: list[np.ndarray] = field(repr=False)
    score: float
    stats: Prediction | None = field(default=None, repr=False)

    def sensor(self, i: int) -> np.ndarray:
        """The six numbers of sensor ``i``."""
        return self.u[6 * i : 6 * i + 6]


@dataclass(frozen=True)
class IcpEvaluation:
    """One ICP evaluation of a candidate in the selection, polish or confirmation (``selection.csv``).

    origin : where the layout came from; surrogate : its surrogate score (deg, NaN for the hand layout);
    protocol : reduced | full; choice : its best choice of k sensors; dominates : no worse than the hand
    layout on every axis on that protocol.
    """

    k: int
    origin: str
    surrogate: float
    protocol: str
    choice: object = field(repr=False)
    dominates: bool

    @property
    def state(self) -> EvalState:
        """FAILED when some axis had no subset that registered reliably (it is then unobservable)."""
        return EvalState.FEASIBLE if all(a.observable for a in self.choice.axes) else EvalState.FAILED


@dataclass
class SearchOutcome:
    """What the surrogate search found: per k the winner of greedy and joint, both, and the hand layout."""

    found: dict[int, Found]
    greedy: dict[int, Found]
    joint: dict[int, Found]
    baseline: dict[int, Found]  # k -> the best hand-placed k-subset on the surrogate
    history: list[Evaluation]
    interrupted: bool = False
    seconds: float = 0.0
    # the stages a clock ended before their evaluations (``SurrogateStudy.cut``): where there are any, the layouts
    # are the machine's speed's as well as the seed's
    clock_cut: tuple[str, ...] = ()


@dataclass(frozen=True)
class Validation:
    """Found vs. hand-placed on the held-out noise seed: per k the found layout's best choice of k sensors
    and the hand layout's (a nested found layout is evaluated inside the larger one that holds it).

    found : k → choice, in the order the layouts were evaluated; baseline : k → choice, k ascending.
    """

    protocol: str  # full | reduced
    seed: int
    found: dict = field(default_factory=dict)
    baseline: dict = field(default_factory=dict)

    def verdicts(self) -> list[Verdict]:
        """Found vs. hand for every k that has both."""
        return [Verdict(k, self.found[k], self.baseline[k]) for k in sorted(self.found) if k in self.baseline]

    def by_k(self) -> dict[int, Verdict]:
        """:meth:`verdicts` by k."""
        return {v.k: v for v in self.verdicts()}

    def unmeasured_lines(self, reference: str = "hand") -> list[str]:
        """Per k whose found choice leaves an axis unmeasured, one line saying so
        (:func:`~optipose.verdict.words.unmeasured_line`): no found layout of k sensors observes it."""
        lines = (unmeasured_line(k, self.found[k], self.baseline.get(k), reference) for k in sorted(self.found))
        return [line for line in lines if line]

    def verdict_lines(self, reference: str = "hand") -> list[str]:
        """One line per k (:func:`~optipose.verdict.words.verdict_line`), then the axes a found layout does not measure
        (:meth:`unmeasured_lines`), then whether one found sensor beats the hand's largest choice;
        ``reference`` names the baseline (``hand``, ``conventional``)."""
        lines = [verdict_line(v, reference) for v in self.verdicts()] + self.unmeasured_lines(reference)
        ks = sorted(self.found)
        top = max(ks, default=0)
        if 1 in self.found and top in self.baseline and top > 1:
            lines.append(
                one_versus_many(self.found[1], self.baseline[top], "hand-placed" if reference == "hand" else reference)
            )
        return lines


@dataclass(frozen=True)
class Side:
    """The found side of a k's verdict draw (:func:`optipose.search.draws.sides`): the evaluation it is read from
    (``hand``: the hand layout's own, for a k the search answered with the hand sensors; else ``found_k<m>``, the
    largest found layout that holds the k one) and the choice (its subset per axis) read from it."""

    evaluation: str
    choice: Choice

    @property
    def kept(self) -> bool:
        """The search answered this k with the hand layout's own choice: an exact TIE with it."""
        return self.evaluation == "hand"
