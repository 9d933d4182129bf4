"""The results :func:`optipose.io.load_result` reads back from a result folder, in one place.

- :class:`~optipose.evaluate.evaluator.EvaluationResult` — an ``optipose evaluate`` folder: the same record
  the live :class:`~optipose.evaluate.evaluator.Evaluator` returns (its tables as written, Table 1
  recomputed from the statistics), re-exported here.
- :class:`SearchResult` — an ``optipose search`` folder: the found layouts and their validation against the
  hand layout (the frozen record of a finished :class:`~optipose.search.pipeline.SearchReport`).
- :class:`RobustnessResult` — an ``optipose robustness`` folder: every figure of its check across cell instances.

``verdicts()`` is a ``list[Verdict]`` in each (a robustness result's is empty); ``config`` is the folder's :class:`~optipose.io.config.RunConfig`.
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
    confident : the verdicts with confidence (``verdict.csv``; none for a search without one).
    kinds : cell → its BUYs raced again in a common kind of cell (``kinds.csv``; a search in a cell the user did not name).
    """

    folder: Path | None
    part: str
    seed: int
    budget: str
    config: RunConfig = field(repr=False)
    layouts: dict[int, Layout] = field(default_factory=dict, repr=False)
    baseline: Layout | None = field(default=None, repr=False)
    validation: Validation | None = None
    confident: Verdicts = field(default_factory=Verdicts)
    kinds: dict[str, Verdicts] = field(default_factory=dict)

    def verdicts(self) -> list[Verdict]:
        """Found vs. hand per k (empty when there is no hand layout or no validation)."""
        return self.validation.verdicts() if self.validation is not None else []

    @property
    def unchecked(self) -> bool:
        """The answer holds for the ideal cell only: a search in the ideal cell."""
        return self.config.cell_name == "ideal" and self.validation is not None

    def verdict_lines(self) -> list[str]:
        """:meth:`Validation.verdict_lines`, the baseline named as the folder's ``layouts/hand.toml`` (or ``conventional.toml``) says."""
        from optipose.model.baseline import baseline_label

        return self.validation.verdict_lines(baseline_label(self.baseline)) if self.validation is not None else []


@dataclass(frozen=True)
class RobustnessResult:
    """A robustness folder read back (:func:`optipose.io.load_result`): the layouts checked and every figure of the
    check (``robustness.csv``: one row per cell, instance, layout, k and axis, degrees; :mod:`optipose.io.robustness`).

    layouts : name → Layout (the hand layout under ``hand``); rows : the table of ``robustness.csv``.
    """

    folder: Path
    part: str
    seed: int
    config: RunConfig = field(repr=False)
    layouts: dict[str, Layout] = field(default_factory=dict, repr=False)
    rows: pd.DataFrame = field(default_factory=pd.DataFrame, repr=False)

    def ratios(self) -> pd.DataFrame:
        """One row per (layout, k, cell, instance): hand / layout of the score and whether the layout holds."""
        keys = ["layout", "k", "cell", "instance"]
        return self.rows.groupby(keys, sort=False)[["ratio", "holds", "sensors", "hand_sensors"]].first().reset_index()

    def holds(self) -> pd.DataFrame:
        """Per (layout, k): in how many instances it holds, of how many, and its smallest ratio."""
        by = self.ratios().groupby(["layout", "k"], sort=False)
        return by.agg(held=("holds", "sum"), instances=("holds", "size"), weakest=("ratio", "min")).reset_index()

    def verdicts(self) -> list:
        """None: a robustness check says where a layout holds, not a verdict on one draw."""
        return []
