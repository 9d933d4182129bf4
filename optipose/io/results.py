"""The results :func:`optipose.io.load_result` reads back from a result folder, in one place.

- :class:`~optipose.evaluate.evaluator.EvaluationResult` — an ``optipose evaluate`` folder: the same record
  the live :class:`~optipose.evaluate.evaluator.Evaluator` returns (its tables as written, Table 1
  recomputed from the statistics), re-exported here.
- :class:`SearchResult` — an ``optipose search`` folder: the found layouts and their validation against the
  hand layout (the frozen record of a finished :class:`~optipose.search.pipeline.SearchReport`).
- :class:`RobustnessResult` — an ``optipose robustness`` folder: the frozen record of the live
  :class:`~optipose.evaluate.robust.RobustResult` of each layout it evaluated.

``verdicts()`` is a ``list[Verdict]`` in each that has one (a robustness result's verdicts name their
layout, ``Verdict.layout``); ``config`` is the folder's :class:`~optipose.io.config.RunConfig`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from optipose.verdict.compare import Verdict
from optipose.verdict.confidence import Verdicts
from optipose.evaluate.evaluator import EvaluationResult
from optipose.io.config import RunConfig
from optipose.model.layout import Layout
from optipose.search.records import Validation

__all__ = ["EvaluationResult", "SearchResult", "RobustnessResult"]


@dataclass(frozen=True)
class SearchResult:
    """A search as saved in its result folder (:func:`optipose.io.load_result`).

    layouts : k → the found layout (sensors F1 … Fk); baseline : the hand-placed layout, when the part has one,
    else the conventional placement;
    validation : found vs. hand on the held-out seed (None when the search was interrupted before it);
    band : the same under the band of the check after a nominal search (``SearchConfig.validation.band_objective``), or None;
    confident : the verdicts with confidence (``verdict.csv``; none for a search without one).
    """

    folder: Path | None
    part: str
    seed: int
    budget: str
    config: RunConfig = field(repr=False)
    layouts: dict[int, Layout] = field(default_factory=dict, repr=False)
    baseline: Layout | None = field(default=None, repr=False)
    validation: Validation | None = None
    band: Validation | None = None
    confident: Verdicts = field(default_factory=Verdicts)

    def verdicts(self) -> list[Verdict]:
        """Found vs. hand per k (empty when there is no hand layout or no validation)."""
        return self.validation.verdicts() if self.validation is not None else []

    def band_verdicts(self) -> dict[int, Verdict]:
        """k → found vs. hand under the band of the check after a nominal search (empty without one); with
        :meth:`verdicts`, what :func:`optipose.verdict.compare.bought` decides on."""
        return self.band.by_k() if self.band is not None else {}

    @property
    def band_pending(self) -> bool:
        """The search was to check its answer under a band but has no such check (it stopped before it; a
        search with nothing to compare its layouts with has no check to miss)."""
        return (
            self.config.band is not None
            and self.band is None
            and self.validation is not None
            and bool(self.validation.baseline)
        )

    @property
    def unchecked(self) -> bool:
        """The answer holds for the ideal cell only: a nominal search (one noise level, exact brackets) in the
        ideal cell that was not to check it under a band (``--budget quick``, or ``[search] band = ""``)."""
        nominal = self.config.searched_conditions().trivial and self.config.cell_name == "ideal"
        return nominal and self.config.band is None and self.validation is not None

    def verdict_lines(self) -> list[str]:
        """:meth:`Validation.verdict_lines`, the baseline named as the folder's ``layouts/hand.toml`` (or ``conventional.toml``) says."""
        from optipose.model.baseline import baseline_label

        return self.validation.verdict_lines(baseline_label(self.baseline)) if self.validation is not None else []


@dataclass(frozen=True)
class RobustnessResult:
    """A robustness folder read back (:func:`optipose.io.load_result`): the frozen record of what
    ``optipose robustness`` found with one live :class:`~optipose.evaluate.robust.RobustResult` per layout.
    It keeps each layout's robust choices (as ``robustness.csv`` wrote them), not the per-condition
    evaluations a ``RobustResult`` holds.

    layouts : name → Layout (the hand layout under ``hand``); choices : (name, k) → the layout's robust
    choice of k sensors carrying its statistics per condition (``Choice.under``), the hand layout's under
    ``("hand", k)``; brackets, bracket_sensors : the tables of ``brackets.csv`` and
    ``bracket_sensors.csv`` (None without a bracket sensitivity).
    """

    folder: Path
    part: str
    seed: int
    config: RunConfig = field(repr=False)
    layouts: dict[str, Layout] = field(default_factory=dict, repr=False)
    choices: dict = field(default_factory=dict, repr=False)
    brackets: pd.DataFrame | None = field(default=None, repr=False)
    bracket_sensors: pd.DataFrame | None = field(default=None, repr=False)

    def verdicts(self) -> list[Verdict]:
        """Per given layout (``Verdict.layout``, in file order), its robust choice against the hand layout's
        choice of as many sensors."""
        return [
            Verdict(k, choice, self.choices[("hand", k)], layout=name)
            for (name, k), choice in self.choices.items()
            if name != "hand" and ("hand", k) in self.choices
        ]
